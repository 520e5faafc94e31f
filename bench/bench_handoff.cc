// bench_handoff: what it costs this machine to hand work between threads, the floor under a pass on
// several threads (docs/PERFORMANCE.md).
//
// Three measures, no vdbclay code:
// - each CPU's own speed, one at a time (the others idle), on two loops: passes over a 16 KiB buffer
//   (loads, adds and stores, all in L1, as the automaton's kernel mostly is) and spin()'s add
//   chain through one volatile variable (a store-to-load forwarding chain). On a virtual machine the CPUs
//   need not be equal: a vCPU whose physical core serves another guest's thread too runs memory-bound code
//   slower, and then no split of a pass can reach the CPUs' count as its speed-up;
// - the round trip of one cache line between two threads pinned to CPUs 0 and k (one thread stores
//   a flag, the other answers; half of it is what each line a thread reads after another wrote it
//   costs at least), for every k the process may run on;
// - a TBB fork/join of T equal tasks in a task_arena of T threads, as the automaton's pass forks one
//   task per thread every step: the time per fork/join beyond the tasks' own work (each task spins
//   for a fixed number of iterations, timed alone first);
// - T threads at once on CPUs 0..T-1, each on data of its own (a kernel-like loop of 8-int reads
//   and writes at scattered places in a private 512 KiB buffer), meeting at a spin barrier every
//   ~10 us as the pass's lanes do; each thread's work per pass against the same loop alone on its
//   CPU. Nothing is shared but the barrier, so a slowdown here is the machine's (shared cores,
//   caches, bandwidth or clock), and what a pass loses beyond it on T threads is the data its
//   threads share.
// usage: bench_handoff [T (default 2)] [work per task in us (default 20)]
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>
#include <tbb/task_arena.h>

#include <pthread.h>
#include <sched.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <thread>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;

bool pinTo(int cpu)
{
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(cpu, &set);
    return pthread_setaffinity_np(pthread_self(), sizeof(set), &set) == 0;
}

/// Mean round trip (ns) of a flag between this thread pinned to @a a and another pinned to @a b.
double roundTripNs(int a, int b, int trips)
{
    alignas(64) std::atomic<int> flag{0};
    std::atomic<bool> ready{false};
    std::thread other([&] {
        pinTo(b);
        ready.store(true);
        for (int i = 0; i < trips; ++i) {
            while (flag.load(std::memory_order_acquire) != 1) {
            }
            flag.store(0, std::memory_order_release);
        }
    });
    pinTo(a);
    while (!ready.load()) {
    }
    const auto t0 = Clock::now();
    for (int i = 0; i < trips; ++i) {
        flag.store(1, std::memory_order_release);
        while (flag.load(std::memory_order_acquire) != 0) {
        }
    }
    const auto t1 = Clock::now();
    other.join();
    return std::chrono::duration<double, std::nano>(t1 - t0).count() / trips;
}

/// Spins @a n iterations; returns something the compiler cannot drop.
uint64_t spin(uint64_t n)
{
    volatile uint64_t x = 0;
    for (uint64_t i = 0; i < n; ++i)
        x = x + i;
    return x;
}

/// Best of 3 (seconds) of a thread pinned to @a cpu running @a loop; negative where it cannot pin.
template <typename Loop> double pinnedSeconds(int cpu, Loop loop)
{
    double best = -1;
    std::thread t([&] {
        if (!pinTo(cpu)) return;
        for (int r = 0; r < 3; ++r) {
            const auto t0 = Clock::now();
            loop();
            const double s = std::chrono::duration<double>(Clock::now() - t0).count();
            best = best < 0 ? s : std::min(best, s);
        }
    });
    t.join();
    return best;
}

/// 20,000 passes over 16 KiB: a load, an add and a store per int, all in L1.
uint64_t l1Passes()
{
    static std::vector<uint32_t> buf(4096, 1);
    uint64_t sum = 0;
    for (int pass = 0; pass < 20000; ++pass) {
        for (uint32_t& v : buf) {
            sum += v;
            v += uint32_t(sum);
        }
        __asm__ volatile("" : : "r"(buf.data()) : "memory");
    }
    return sum;
}

/// A private buffer and the work the automaton's kernel does to it, roughly: 64 blocks a call, each
/// 8 ints read at a scattered place and written back (a mostly-L2 working set).
struct PrivateWork {
    std::vector<int32_t> buf = std::vector<int32_t>(128 * 1024, 1);
    uint64_t state = 1;
    void run(int calls)
    {
        int32_t* b = buf.data();
        const size_t n = buf.size() - 8;
        for (int c = 0; c < calls; ++c) {
            for (int k = 0; k < 64; ++k) {
                state = state * 6364136223846793005ULL + 1442695040888963407ULL;
                int32_t* p = b + (state >> 33) % n;
                int32_t sum = 0;
                for (int j = 0; j < 8; ++j)
                    sum += p[j];
                for (int j = 0; j < 8; ++j)
                    p[j] = sum - p[j];
            }
        }
        __asm__ volatile("" : : "r"(b) : "memory");
    }
};

/// Microseconds of work per pass on each of @a cpus, over @a passes passes of @a calls each: with
/// @a together, all threads at once, meeting at a spin barrier after every pass; otherwise one CPU
/// at a time (the others idle). Negative where a thread could not pin.
std::vector<double> privateWorkUs(const std::vector<int>& cpus, int passes, int calls, bool together)
{
    const size_t t = cpus.size();
    std::vector<double> busy(t, 0);
    std::vector<char> pinned(t, 1);
    std::vector<PrivateWork> work(t);
    alignas(64) std::atomic<int> arrived{0};
    alignas(64) std::atomic<int> generation{0};
    auto lane = [&](size_t i) {
        pinned[i] = pinTo(cpus[i]); // unpinned, it still runs (the barrier counts every thread)
        work[i].run(calls);         // warm the buffer
        for (int p = 0; p < passes; ++p) {
            const auto t0 = Clock::now();
            work[i].run(calls);
            busy[i] += std::chrono::duration<double, std::micro>(Clock::now() - t0).count();
            if (!together) continue;
            // A barrier: the last to arrive starts the next generation.
            const int g = generation.load(std::memory_order_acquire);
            if (arrived.fetch_add(1, std::memory_order_acq_rel) + 1 == int(t)) {
                arrived.store(0, std::memory_order_relaxed);
                generation.store(g + 1, std::memory_order_release);
            } else {
                while (generation.load(std::memory_order_acquire) == g) {
                }
            }
        }
    };
    if (together) {
        std::vector<std::thread> threads;
        for (size_t i = 0; i < t; ++i)
            threads.emplace_back(lane, i);
        for (std::thread& th : threads)
            th.join();
    } else {
        for (size_t i = 0; i < t; ++i)
            std::thread(lane, i).join();
    }
    for (size_t i = 0; i < t; ++i)
        busy[i] = pinned[i] ? busy[i] / passes : -1;
    return busy;
}

} // namespace

int main(int argc, char** argv)
{
    const int threads = argc > 1 ? std::max(1, std::atoi(argv[1])) : 2;
    const double workUs = argc > 2 ? std::atof(argv[2]) : 20.0;

    cpu_set_t allowed;
    CPU_ZERO(&allowed);
    sched_getaffinity(0, sizeof(allowed), &allowed);
    std::vector<int> cpus;
    for (int c = 0; c < CPU_SETSIZE; ++c)
        if (CPU_ISSET(c, &allowed)) cpus.push_back(c);
    std::printf("each CPU alone, best of 3 (s; and its speed relative to CPU %d):\n", cpus[0]);
    std::atomic<uint64_t> keep{0};
    double l1Base = 0, aluBase = 0;
    for (int cpu : cpus) {
        const double l1 = pinnedSeconds(cpu, [&] { keep.fetch_add(l1Passes()); });
        const double alu = pinnedSeconds(cpu, [&] { keep.fetch_add(spin(200000000)); });
        if (l1 < 0 || alu < 0) {
            std::printf("  CPU %d: could not pin a thread to it\n", cpu);
            continue;
        }
        if (l1Base == 0) l1Base = l1, aluBase = alu;
        std::printf("  CPU %d: L1 passes %.3f (%.2fx), add chain %.3f (%.2fx)\n", cpu, l1, l1Base / l1, alu,
                    aluBase / alu);
    }
    std::printf("cache-line round trip from CPU %d (ns, best of 3 runs of 100000):\n", cpus[0]);
    for (size_t k = 1; k < cpus.size(); ++k) {
        double best = 1e30;
        for (int r = 0; r < 3; ++r)
            best = std::min(best, roundTripNs(cpus[0], cpus[k], 100000));
        std::printf("  CPU %d: %.0f\n", cpus[k], best);
    }
    if (cpus.size() < 2) std::printf("  (one CPU only)\n");
    pinTo(cpus[0]);
    // Calibrate the task's spin to workUs on one thread.
    uint64_t n = 1000;
    for (;;) {
        const auto t0 = Clock::now();
        spin(n);
        const double us = std::chrono::duration<double, std::micro>(Clock::now() - t0).count();
        if (us > 2000) {
            n = uint64_t(double(n) * workUs / us);
            break;
        }
        n *= 2;
    }
    CPU_ZERO(&allowed);
    for (int c : cpus)
        CPU_SET(c, &allowed);
    pthread_setaffinity_np(pthread_self(), sizeof(allowed), &allowed);
    tbb::task_arena arena(threads);
    const int iterations = 20000;
    std::atomic<uint64_t> sink{0};
    for (int r = 0; r < 3; ++r) {
        const auto t0 = Clock::now();
        for (int i = 0; i < iterations; ++i) {
            arena.execute([&] {
                tbb::parallel_for(
                    tbb::blocked_range<int>(0, threads, 1),
                    [&](const tbb::blocked_range<int>&) {
                        sink.fetch_add(spin(n), std::memory_order_relaxed);
                    },
                    tbb::simple_partitioner());
            });
        }
        const double us = std::chrono::duration<double, std::micro>(Clock::now() - t0).count() / iterations;
        std::printf("fork/join of %d tasks of %.1f us each: %.2f us per step (%.2f us beyond the work; "
                    "%.2fx of one thread doing them all)\n",
                    threads, workUs, us, us - workUs, threads * workUs / us);
    }
    // Threads at once on data of their own: does the machine slow a CPU while its neighbours work?
    std::vector<int> team(cpus.begin(),
                          cpus.begin() + std::ptrdiff_t(std::min<size_t>(cpus.size(), size_t(threads))));
    if (team.size() >= 2) {
        const int calls = 64; // ~10 us a pass on the 2-vCPU VM this was written on
        std::printf("%zu threads at once on private data, a barrier every pass (us of work per pass; "
                    "alone -> together, best of 3):\n",
                    team.size());
        std::vector<double> alone(team.size(), 1e30), together(team.size(), 1e30);
        for (int r = 0; r < 3; ++r) {
            const std::vector<double> a = privateWorkUs(team, 20000, calls, false);
            const std::vector<double> b = privateWorkUs(team, 20000, calls, true);
            for (size_t i = 0; i < team.size(); ++i) {
                alone[i] = std::min(alone[i], a[i]);
                together[i] = std::min(together[i], b[i]);
            }
        }
        for (size_t i = 0; i < team.size(); ++i) {
            if (alone[i] < 0 || together[i] < 0) {
                std::printf("  CPU %d: could not pin a thread to it\n", team[i]);
                continue;
            }
            std::printf("  CPU %d: %.2f -> %.2f (%.2fx)\n", team[i], alone[i], together[i],
                        together[i] / alone[i]);
        }
    }
    return sink.load() + keep.load() == 42 ? 1 : 0;
}
