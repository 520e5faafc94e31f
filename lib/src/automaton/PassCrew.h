// A pass's threads kept from one step to the next: the automaton's chunks without a fork/join.
//
// Why. A settling press runs tens of thousands of steps of a few hundred blocks each (press 128^3:
// 49,813 steps, ~38 us of one-thread work each). A TBB fork/join of two equal tasks costs 1.6-3.7 us
// beyond their work on the 2-vCPU machine this was measured on (bench/bench_handoff), a tenth of a
// split step, paid every step. A crew keeps its helper threads between passes: a pass is published
// by one atomic store and picked up by helpers spinning on it, so a step pays for a few cache-line
// transfers (about 0.25 us each there) instead of the fork/join.
//
// How. run(chunks, body) calls body(chunk, lane) once for every chunk in [0, chunks). The caller is
// lane 0, helper i is lane i; any lane may take any chunk: each is claimed from one atomic ticket
// (epoch, next chunk, chunk count) by compare-and-swap, so no chunk runs twice and none is lost,
// whether the helpers are spinning, asleep or slow to start. The caller claims chunks too, and then
// waits only for chunks already claimed, which are running: run() never waits on a helper that has
// not started. Helpers spin for a while after each pass (the next one is usually microseconds
// away): with pause at first, then yielding the CPU (where there are more threads than cores, the
// working lanes must get it), then, after 200 us idle, asleep on a condition variable until the
// next pass or the crew's end; a pass finding a helper asleep wakes it and does not wait for it. A
// chunk's exception is caught on its lane and the lowest chunk's is rethrown by run() once every
// chunk has finished.
//
// The helpers are the crew's own threads (std::thread), made at the automaton's first pass on
// several threads and joined with it; TBB's workers serve the other parallel stages (push, scans,
// output) and sleep while a settle runs, as the crew's helpers sleep during those stages.
//
// fork(). A child process has the crew's memory but none of its helpers (fork copies only the
// calling thread), so a crew made before a fork must not be used or stopped in the child: forked()
// says so, the automaton then makes a new crew there, and the destructor leaves the parent's
// helpers unjoined (Python's multiprocessing forks processes holding automata).
//
// What the body may do: what a task of tbb::parallel_for may do (Kernel.h's processRange contract):
// write only what its chunk owns, or its lane's own data. run()'s return happens after every chunk's
// writes (release on the done count, acquire in run()), as a fork/join would.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

namespace vdbclay {
namespace automaton_internal {

class PassCrew {
public:
    /// Starts @a helpers threads (lanes 1..helpers), which sleep until the first pass.
    explicit PassCrew(int helpers);
    /// Stops and joins the helpers. Not while a run() is in progress.
    ~PassCrew();
    PassCrew(const PassCrew&) = delete;
    PassCrew& operator=(const PassCrew&) = delete;

    /// Whether this process is not the one that made the crew (a child of fork()): its helpers are
    /// not here, so no run() may start; make a new crew (the destructor is safe).
    bool forked() const;
    /// Lanes: the caller and the helpers.
    int lanes() const { return int(mHelpers.size()) + 1; }

    using Body = std::function<void(size_t chunk, int lane)>;
    /// Runs body(c, lane) for every c in [0, chunks) exactly once across the lanes; returns when all
    /// have finished, rethrowing the lowest chunk's exception if any threw. More than kMaxChunks
    /// chunks: std::length_error, before any runs. One run() at a time per crew.
    void run(size_t chunks, const Body& body);

    static constexpr size_t kMaxChunks = 0xFFFF;

    /// Chunks the helpers (not the caller) have run so far (tests: whether helpers take part).
    uint64_t helperChunks() const { return mHelperChunks; }
    /// The lock sleeping helpers take (tests: a fork while another thread holds it).
    std::mutex& parkingLock() { return mParking->mutex; }
    /// Helpers asleep now (tests: that a pass wakes them).
    int sleepers() const { return mIdle.sleepers.load(std::memory_order_acquire); }

private:
    // The ticket: epoch (32 bits) | next chunk (16) | chunk count (16). A lane claims chunk `next`
    // by a CAS that adds 1 to it, which succeeds only for the epoch it read.
    static uint64_t ticketOf(uint64_t epoch, uint64_t next, uint64_t count)
    {
        return (epoch << 32) | (next << 16) | count;
    }
    static uint32_t epochOf(uint64_t t) { return uint32_t(t >> 32); }
    static size_t nextOf(uint64_t t) { return size_t((t >> 16) & 0xFFFF); }
    static size_t countOf(uint64_t t) { return size_t(t & 0xFFFF); }

    /// Claims and runs chunks of the pass whose ticket @a t was read, until none is left; returns
    /// how many it ran.
    size_t work(uint64_t t, int lane);
    void helperLoop(int lane);
    /// Tells the helpers to quit, wakes and joins them.
    void stop();

    // Cache lines by who writes them, since every line both sides touch per pass costs a transfer
    // between cores (~0.25 us on a VM): the ticket and the body (the caller, once per pass; a helper
    // reads both once it has a chunk), the done count (helpers only; never reset, the caller keeps
    // its own target), the sleep and quit state (rarely written, read by spinning helpers).
    struct alignas(64) Published {
        std::atomic<uint64_t> ticket{0};
        const Body* body = nullptr;
    } mPub;
    alignas(64) std::atomic<uint64_t> mDone{0}; // chunks the helpers have finished, ever
    struct alignas(64) Idle {
        std::atomic<int> sleepers{0};
        std::atomic<bool> quit{false};
    } mIdle;
    alignas(64) uint64_t mDoneSeen = 0; // the caller's: mDone when the last pass ended
    uint64_t mHelperChunks = 0;
    std::vector<std::exception_ptr> mErrors; // per chunk, written by the lane that ran it
    struct Parking { // for sleeping helpers; on the heap, so that a fork's child can leave it
        std::mutex mutex;
        std::condition_variable wake;
    };
    std::unique_ptr<Parking> mParking;
    std::vector<std::thread> mHelpers;
    uint32_t mForks; // the process's fork count when the crew was made (forked())
};

} // namespace automaton_internal
} // namespace vdbclay
