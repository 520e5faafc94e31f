// A deliberate data race under TBB: scripts/test-tsan.sh builds this with -fsanitize=thread against
// the instrumented oneTBB and requires ThreadSanitizer to report it, so a broken harness (TSan not
// seeing TBB's threads, or the uninstrumented libtbb loaded) cannot pass silently. Not a unit test.
//
// Two TBB tasks meet at a barrier (both wait until both are running), so they run on two threads.
// Then task 0 writes gCounter and says so, and task 1 waits for that and writes it too. Every
// signal is a relaxed atomic, which orders nothing for TSan (no happens-before), so the two writes
// race; and they come one after the other in real time, so TSan's shadow memory holds the first
// when it checks the second (two writes at the same instant can slip past it). No sleep: each wait
// is on an event. max_allowed_parallelism 2 lets TBB lend the second thread on a one-core machine.
#include <tbb/blocked_range.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <atomic>
#include <cstdio>
#include <thread>

static long gCounter = 0; // written by two TBB threads without synchronisation: the race

int main()
{
    tbb::global_control parallelism(tbb::global_control::max_allowed_parallelism, 2);
    std::atomic<int> arrived{0};
    std::atomic<bool> written{false};
    constexpr auto relaxed = std::memory_order_relaxed;
    tbb::task_arena arena(2);
    arena.execute([&] {
        tbb::parallel_for(tbb::blocked_range<int>(0, 2, 1), [&](const tbb::blocked_range<int>& r) {
            arrived.fetch_add(1, relaxed);
            while (arrived.load(relaxed) < 2)
                std::this_thread::yield(); // the other task is not running yet: it is on another thread
            if (r.begin() == 0) {
                ++gCounter;
                written.store(true, relaxed);
            } else {
                while (!written.load(relaxed))
                    std::this_thread::yield();
                ++gCounter;
            }
        });
    });
    std::printf("canary: counter %ld\n", gCounter);
    return 0;
}
