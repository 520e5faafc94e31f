// A pass's threads kept from one step to the next (see PassCrew.h for the protocol and why).

#include "automaton/PassCrew.h"

#include <chrono>
#include <stdexcept>
#include <string>

#include <pthread.h>

#if defined(__x86_64__) || defined(__SSE2__)
#include <immintrin.h>
#endif

namespace vdbclay {
namespace automaton_internal {

namespace {

inline void cpuRelax()
{
#if defined(__x86_64__) || defined(__SSE2__)
    _mm_pause();
#else
    std::this_thread::yield();
#endif
}

/// How long a helper spins for the next pass before it sleeps: far longer than the gap between
/// two passes of a settling run (a few microseconds), far shorter than a frame's push.
constexpr std::chrono::microseconds kSpinBeforeSleep(200);
/// Spins with pause before each wait loop turns to yielding the CPU: a pass's chunk usually ends
/// within microseconds, but where there are more threads than cores (threads = 8 on 2 cores), a
/// spinning thread must let the working ones run.
constexpr unsigned kPausesBeforeYield = 2048;

inline void backOff(unsigned spins)
{
    if (spins < kPausesBeforeYield)
        cpuRelax();
    else
        std::this_thread::yield();
}

/// How many fork()s this process descends from (since the first crew): a fork handler counts them
/// in the child, so forked() is one load, not a getpid() system call on every pass.
std::atomic<uint32_t> gForks{0};

uint32_t forksSoFar()
{
    static const bool registered = [] {
        return pthread_atfork(nullptr, nullptr, [] { gForks.fetch_add(1, std::memory_order_relaxed); }) == 0;
    }();
    (void)registered; // (without a handler, forked() stays false: a fork is not detected)
    return gForks.load(std::memory_order_relaxed);
}

} // namespace

PassCrew::PassCrew(int helpers) : mParking(new Parking), mForks(forksSoFar())
{
    mHelpers.reserve(size_t(helpers > 0 ? helpers : 0));
    try {
        for (int i = 0; i < helpers; ++i)
            mHelpers.emplace_back([this, lane = i + 1] { helperLoop(lane); });
    } catch (...) { // a thread could not start: stop those that did (no destructor runs), rethrow
        stop();
        throw;
    }
}

PassCrew::~PassCrew()
{
    if (forked()) {
        // A child of fork(): the helpers are the parent's threads, absent here. Joining them would
        // wait forever, destroying a joinable std::thread terminates, and the condition variable
        // may count a parent's sleeping helper as a waiter (destroying it would wait for that one
        // too). So the handles and the parking are left behind: a few hundred bytes, once a fork.
        new std::vector<std::thread>(std::move(mHelpers));
        (void)mParking.release();
        return;
    }
    stop();
}

bool PassCrew::forked() const
{
    return gForks.load(std::memory_order_relaxed) != mForks;
}

void PassCrew::stop()
{
    {
        std::lock_guard<std::mutex> lock(mParking->mutex);
        mIdle.quit.store(true, std::memory_order_seq_cst);
    }
    mParking->wake.notify_all();
    for (std::thread& t : mHelpers)
        t.join();
}

size_t PassCrew::work(uint64_t t, int lane)
{
    size_t ran = 0;
    for (;;) {
        if (nextOf(t) >= countOf(t)) return ran;
        // Success means chunk nextOf(t) of this epoch is ours; failure reloads t (another lane took
        // a chunk, or the epoch moved on, which the test above or the next CAS then sees).
        if (!mPub.ticket.compare_exchange_weak(t, t + (uint64_t(1) << 16), std::memory_order_acquire,
                                               std::memory_order_acquire))
            continue;
        const size_t chunk = nextOf(t);
        try {
            (*mPub.body)(chunk, lane);
        } catch (...) {
            mErrors[chunk] = std::current_exception();
        }
        ++ran;
        if (lane != 0) mDone.fetch_add(1, std::memory_order_release);
        t = mPub.ticket.load(std::memory_order_acquire);
    }
}

void PassCrew::helperLoop(int lane)
{
    uint32_t seen = 0; // the last epoch this helper looked at
    for (;;) {
        // Spin for a new pass with a chunk left, then sleep until the ticket changes.
        auto idleSince = std::chrono::steady_clock::now();
        uint64_t t = mPub.ticket.load(std::memory_order_acquire);
        for (unsigned spins = 0; epochOf(t) == seen || nextOf(t) >= countOf(t); ++spins) {
            if (mIdle.quit.load(std::memory_order_acquire)) return;
            if (epochOf(t) != seen) seen = epochOf(t); // a pass whose chunks are all taken
            backOff(spins);
            if ((spins & 255) == 255 && std::chrono::steady_clock::now() - idleSince > kSpinBeforeSleep) {
                std::unique_lock<std::mutex> lock(mParking->mutex);
                mIdle.sleepers.fetch_add(1, std::memory_order_seq_cst);
                mParking->wake.wait(lock, [&] {
                    return mIdle.quit.load(std::memory_order_seq_cst) ||
                           epochOf(mPub.ticket.load(std::memory_order_seq_cst)) != seen;
                });
                mIdle.sleepers.fetch_sub(1, std::memory_order_relaxed);
                idleSince = std::chrono::steady_clock::now();
            }
            t = mPub.ticket.load(std::memory_order_acquire);
        }
        seen = epochOf(t);
        work(t, lane);
    }
}

void PassCrew::run(size_t chunks, const Body& body)
{
    if (chunks == 0) return;
    if (chunks > kMaxChunks) // the ticket holds 16 bits of count: refused, never silently cut short
        throw std::length_error("PassCrew::run: " + std::to_string(chunks) + " chunks, at most " +
                                std::to_string(kMaxChunks));
    mErrors.assign(chunks, nullptr);
    mPub.body = &body;
    const uint64_t epoch = uint64_t(epochOf(mPub.ticket.load(std::memory_order_relaxed)) + 1) & 0xFFFFFFFFu;
    const uint64_t t = ticketOf(epoch, 0, chunks);
    // Published with everything above (release); seq_cst against a helper's going to sleep: either
    // it sees the new epoch before it waits, or this sees it counted among the sleepers.
    mPub.ticket.store(t, std::memory_order_seq_cst);
    if (mIdle.sleepers.load(std::memory_order_seq_cst) > 0) {
        std::lock_guard<std::mutex> lock(mParking->mutex);
        mParking->wake.notify_all();
    }
    const size_t mine = work(t, 0);
    // Every chunk is claimed; those on other lanes are running. Wait for them.
    const uint64_t target = mDoneSeen + (chunks - mine);
    for (unsigned spins = 0; mDone.load(std::memory_order_acquire) != target; ++spins)
        backOff(spins);
    mDoneSeen = target;
    mHelperChunks += chunks - mine;
    for (std::exception_ptr& e : mErrors)
        if (e) std::rethrow_exception(e);
}

} // namespace automaton_internal
} // namespace vdbclay
