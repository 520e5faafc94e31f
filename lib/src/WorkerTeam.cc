// A fixed team of threads for the automaton's steps (see WorkerTeam.h).
#include "WorkerTeam.h"

#include <chrono>
#include <stdexcept>
#include <string>

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#endif

namespace vdbclay {
namespace automaton_internal {

namespace {

inline void cpuRelax()
{
#if defined(__x86_64__) || defined(__i386__)
    _mm_pause();
#endif
}

/// Spins (a pause instruction per try) for about 50 us, then yields on every further try until
/// ready(). Returns false instead once @a sleepAfter (> 0) has passed (the caller then sleeps).
/// Yielding early costs dearly on a loaded machine: the scheduler may run another process for its
/// whole slice, while the task waited for usually ends within microseconds on the other core.
constexpr std::chrono::microseconds kSpinFor(50);
template <typename Ready> bool spinThenYield(Ready&& ready, std::chrono::microseconds sleepAfter)
{
    using Clock = std::chrono::steady_clock;
    const auto t0 = Clock::now();
    for (unsigned k = 0;; ++k) {
        if (ready()) return true;
        cpuRelax();
        if ((k & 255) == 255 && Clock::now() - t0 > kSpinFor) break;
    }
    for (unsigned k = 0;; ++k) {
        if (ready()) return true;
        std::this_thread::yield();
        if (sleepAfter.count() > 0 && (k & 15) == 15 && Clock::now() - t0 > sleepAfter) return false;
    }
}

constexpr uint32_t jobOf(uint64_t s)
{
    return uint32_t(s >> 32);
}
constexpr size_t tasksOf(uint64_t s)
{
    return size_t(uint32_t(s));
}

} // namespace

WorkerTeam::WorkerTeam(int n)
    : mSize(n < 1 ? 1 : n), mErrors(size_t(mSize) * kTasksPerMember),
      mSlots(new Slot[size_t(mSize) * kTasksPerMember])
{
    mThreads.reserve(size_t(mSize - 1));
    for (int i = 1; i < mSize; ++i)
        mThreads.emplace_back([this, i] { memberLoop(i); });
}

WorkerTeam::~WorkerTeam()
{
    {
        std::lock_guard<std::mutex> lock(mMutex);
        mStop.store(true);
        mState.store(uint64_t(mJob + 1) << 32);
    }
    mWake.notify_all();
    for (std::thread& t : mThreads)
        t.join();
}

void WorkerTeam::run(size_t tasks, const Body& body)
{
    if (tasks == 0) return;
    if (tasks > maxTasks()) {
        throw std::invalid_argument("WorkerTeam::run: " + std::to_string(tasks) + " tasks, at most " +
                                    std::to_string(maxTasks()));
    }
    const uint32_t job = ++mJob;
    for (size_t t = 0; t < tasks; ++t) {
        mErrors[t] = nullptr;
        // Stamped "claimed by the job before" (a member late from that job finds nothing to claim),
        // so a slot unused for 2^31 jobs cannot look newer than this one when the numbers wrap.
        mSlots[t].job.store(job - 1, std::memory_order_relaxed);
    }
    mBody = &body;
    mDone.store(0, std::memory_order_relaxed);
    mState.store((uint64_t(job) << 32) | uint64_t(tasks)); // seq_cst: against the sleepers' count below
    if (mSize > 1 && mSleepers.load() > 0) {
        {
            std::lock_guard<std::mutex> lock(mMutex);
        }
        mWake.notify_all();
    }
    work(job, tasks, 0);
    spinThenYield([&] { return mDone.load(std::memory_order_acquire) >= tasks; },
                  std::chrono::microseconds(0));
    mBody = nullptr;
    for (size_t t = 0; t < tasks; ++t)
        if (mErrors[t]) std::rethrow_exception(mErrors[t]);
}

void WorkerTeam::work(uint32_t job, size_t tasks, int member)
{
    const size_t n = size_t(mSize);
    for (size_t round = 0; round < tasks; round += n) {
        for (size_t k = 0; k < n; ++k) {
            const size_t t = round + (size_t(member) + k) % n; // its own task first
            if (t >= tasks) continue;
            uint32_t seen = mSlots[t].job.load(std::memory_order_relaxed);
            // Claimed when the slot moves from an older job to this one (job numbers only grow; a
            // member late from an older job finds every slot at its job or later and claims nothing).
            if (int32_t(job - seen) <= 0 ||
                !mSlots[t].job.compare_exchange_strong(seen, job, std::memory_order_acq_rel))
                continue;
            try {
                (*mBody)(t, member);
            } catch (...) {
                mErrors[t] = std::current_exception();
            }
            mSlots[t].done.store(job, std::memory_order_release);
            mDone.fetch_add(1, std::memory_order_acq_rel);
        }
    }
}

void WorkerTeam::waitDone(size_t k)
{
    const uint32_t job = jobOf(mState.load(std::memory_order_acquire));
    for (size_t t = 0; t < k; ++t)
        spinThenYield([&] { return mSlots[t].done.load(std::memory_order_acquire) == job; },
                      std::chrono::microseconds(0));
}

void WorkerTeam::memberLoop(int member)
{
    uint32_t seen = 0;
    for (;;) {
        // Between steps the caller's serial part takes microseconds: spin and yield; when no job
        // comes for a while (a push, the end of a settle), sleep until one does.
        auto fresh = [&] { return jobOf(mState.load(std::memory_order_acquire)) != seen; };
        if (!spinThenYield(fresh, std::chrono::microseconds(200))) {
            std::unique_lock<std::mutex> lock(mMutex);
            mSleepers.fetch_add(1); // seq_cst: run() either sees it or we see its job
            mWake.wait(lock, fresh);
            mSleepers.fetch_sub(1);
        }
        if (mStop.load()) return;
        const uint64_t s = mState.load(std::memory_order_acquire);
        seen = jobOf(s);
        work(seen, tasksOf(s), member);
    }
}

} // namespace automaton_internal
} // namespace vdbclay
