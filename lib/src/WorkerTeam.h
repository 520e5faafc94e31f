// A fixed team of threads for the automaton's steps: cheap jobs of a few tasks each.
//
// Why not TBB here: a settling run takes ~50,000 steps of a few hundred blocks each, and every step
// paid a tbb fork/join (task spawn, wake-up, join) plus a serial gather. A team keeps n - 1 threads
// of its own, which wait between jobs; run(tasks, body) runs body(task, member) once for every task
// of a job, each task claimed by one member (the caller is member 0), and returns when all are done.
//
// Claiming. The tasks come in rounds of n; member m claims task m of a round first (so, step after
// step, the same member runs the same share: its data stays in its core's cache), then any other
// task of the round left unclaimed, then goes on to the next round. So no task of a round is
// claimed before every task of the earlier rounds is, a task may wait for the earlier rounds
// (waitDone: the automaton's pass waits for the pieces of its gather), and no member ever waits
// for one that has not claimed anything: a member the system does not schedule (an oversubscribed
// machine) only leaves its tasks to the others, as TBB's work stealing would. A claim is a
// compare-and-swap of the task's slot from an older job's number to this job's, so a member that
// wakes late from an earlier job claims nothing of a later one.
//
// Waiting. A member waiting for a job, a task or the join spins with a pause instruction for about
// 50 us, then yields its core on every try; a member with no job for about 0.2 ms (e.g. while the
// caller pushes the tools) sleeps on a condition variable until the next one. Timing only decides
// how a member waits, never what is computed: every handoff is an atomic with acquire/release
// ordering.
//
// A task's exception is kept and the first (in task order) rethrown by run() after all are done.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <exception>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

namespace vdbclay {
namespace automaton_internal {

class WorkerTeam {
public:
    using Body = std::function<void(size_t task, int member)>;

    /// A team of @a n members (n >= 1): the caller and n - 1 threads started here.
    explicit WorkerTeam(int n);
    ~WorkerTeam();
    WorkerTeam(const WorkerTeam&) = delete;
    WorkerTeam& operator=(const WorkerTeam&) = delete;

    /// Tasks a job may have: a fixed number per member, so the per-task slots are never moved (a
    /// member late from an earlier job may still read them).
    static constexpr size_t kTasksPerMember = 16;
    size_t maxTasks() const { return size_t(mSize) * kTasksPerMember; }
    int size() const { return mSize; }
    /// Runs body(task, member) once for every task in [0, tasks) (at most maxTasks(); more throw
    /// std::invalid_argument before anything runs), on the members that claim them
    /// (member 0: the calling thread; see the claiming order above); returns when every task is
    /// done. Rethrows the first task's exception. Not reentrant.
    void run(size_t tasks, const Body& body);
    /// Inside a task of run(): returns once tasks [0, k) are done; k must be a multiple of size()
    /// no greater than the calling task's round start.
    void waitDone(size_t k);

private:
    struct alignas(64) Slot {
        std::atomic<uint32_t> job{0};  // the last job that claimed this task
        std::atomic<uint32_t> done{0}; // the last job that finished it
    };
    void memberLoop(int member);
    /// Claims and runs tasks of job @a job, in member @a member's order, while any is left.
    void work(uint32_t job, size_t tasks, int member);

    int mSize;
    std::vector<std::thread> mThreads;
    const Body* mBody = nullptr;
    std::vector<std::exception_ptr> mErrors; // per task (maxTasks())
    std::unique_ptr<Slot[]> mSlots;          // per task (maxTasks()), never reallocated
    uint32_t mJob = 0;                       // the caller's: the current job's number
    // job (32 bits) | task count (32 bits): the job members pick up
    alignas(64) std::atomic<uint64_t> mState{0};
    alignas(64) std::atomic<size_t> mDone{0};
    alignas(64) std::atomic<int> mSleepers{0};
    std::atomic<bool> mStop{false}; // set before the last job number bump
    std::mutex mMutex;
    std::condition_variable mWake;
};

} // namespace automaton_internal
} // namespace vdbclay
