// PassCrew (lib/src/PassCrew.h): every chunk of every pass runs exactly once, on the caller and the
// helpers, whether they spin or sleep; a chunk's exception reaches the caller after the others
// finish. No test waits on time: where a test needs the helpers to take part, a chunk waits until
// another lane has started a chunk of the same pass, which only a helper can do while the caller
// is inside that chunk (so a crew whose helpers never ran would hang, and ctest's timeout fails it).
#include "automaton/PassCrew.h"
#include "SanitizerBuild.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <memory>
#include <mutex>
#include <new>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

using vdbclay::automaton_internal::PassCrew;

namespace {

/// Spins until @a started reaches @a n (the chunks of this pass that began).
void awaitStarted(const std::atomic<int>& started, int n)
{
    while (started.load(std::memory_order_acquire) < n)
        std::this_thread::yield();
}

} // namespace

TEST(PassCrewTest, EveryChunkRunsExactlyOnceOnEveryPass)
{
    for (int helpers : {0, 1, 2, 3, 7}) {
        PassCrew crew(helpers);
        ASSERT_EQ(crew.lanes(), helpers + 1);
        std::vector<std::atomic<int>> runs(40);
        std::vector<int> laneOf(40);
        for (int pass = 0; pass < 3000; ++pass) {
            const size_t chunks = 1 + size_t(pass * 7 % 37); // 1-37, in a scrambled order
            for (auto& r : runs)
                r.store(0, std::memory_order_relaxed);
            crew.run(chunks, [&](size_t c, int lane) {
                runs[c].fetch_add(1, std::memory_order_relaxed);
                laneOf[c] = lane; // each chunk's own element
            });
            for (size_t c = 0; c < runs.size(); ++c) {
                ASSERT_EQ(runs[c].load(), c < chunks ? 1 : 0)
                    << helpers << " helpers, pass " << pass << ", chunk " << c << " of " << chunks;
                if (c < chunks) {
                    ASSERT_TRUE(laneOf[c] >= 0 && laneOf[c] < crew.lanes()) << laneOf[c];
                }
            }
        }
        if (helpers == 0) {
            EXPECT_EQ(crew.helperChunks(), 0u);
        }
    }
}

TEST(PassCrewTest, HelpersTakeChunksWhileTheCallerIsBusy)
{
    // Two chunks, each waiting until both have started: done only if a helper takes one. With
    // three chunks and two helpers, all three lanes must be inside the pass at once.
    for (int helpers : {1, 2}) {
        PassCrew crew(helpers);
        for (int pass = 0; pass < 200; ++pass) {
            const int chunks = helpers + 1;
            std::atomic<int> started{0};
            std::vector<int> laneOf(size_t(chunks), -1);
            crew.run(size_t(chunks), [&](size_t c, int lane) {
                laneOf[c] = lane;
                started.fetch_add(1, std::memory_order_acq_rel);
                awaitStarted(started, chunks);
            });
            std::vector<int> lanes = laneOf;
            std::sort(lanes.begin(), lanes.end());
            for (int l = 0; l < chunks; ++l)
                ASSERT_EQ(lanes[size_t(l)], l) << "pass " << pass << ": every lane took one chunk";
        }
        EXPECT_EQ(crew.helperChunks(), uint64_t(200 * helpers));
    }
}

TEST(PassCrewTest, APassWakesSleepingHelpers)
{
    PassCrew crew(2);
    for (int round = 0; round < 5; ++round) {
        // The helpers go to sleep once idle (after a short spin): wait for the event, not a time.
        while (crew.sleepers() != 2)
            std::this_thread::yield();
        std::atomic<int> started{0};
        crew.run(3, [&](size_t, int) {
            started.fetch_add(1, std::memory_order_acq_rel);
            awaitStarted(started, 3);
        });
        EXPECT_EQ(started.load(), 3);
    }
}

TEST(PassCrewTest, TheLowestChunksExceptionIsRethrownAfterEveryChunkFinished)
{
    for (int helpers : {0, 1, 3}) {
        PassCrew crew(helpers);
        std::vector<std::atomic<int>> runs(12);
        try {
            crew.run(12, [&](size_t c, int) {
                runs[c].fetch_add(1, std::memory_order_relaxed);
                if (c == 5 || c == 9) throw std::runtime_error("chunk " + std::to_string(c));
            });
            FAIL() << "run() returned normally";
        } catch (const std::runtime_error& e) {
            EXPECT_STREQ(e.what(), "chunk 5");
        }
        for (size_t c = 0; c < runs.size(); ++c)
            EXPECT_EQ(runs[c].load(), 1) << "chunk " << c;
        // The crew still works after a failed pass.
        std::atomic<int> total{0};
        crew.run(9, [&](size_t, int) { total.fetch_add(1); });
        EXPECT_EQ(total.load(), 9);
    }
}

TEST(PassCrewTest, MoreChunksThanTheTicketHoldsAreRefusedBeforeAnyRuns)
{
    PassCrew crew(1);
    std::atomic<int> ran{0};
    EXPECT_THROW(crew.run(PassCrew::kMaxChunks + 1, [&](size_t, int) { ran.fetch_add(1); }),
                 std::length_error);
    EXPECT_EQ(ran.load(), 0);
    crew.run(PassCrew::kMaxChunks, [&](size_t, int) { ran.fetch_add(1); });
    EXPECT_EQ(ran.load(), int(PassCrew::kMaxChunks));
}

TEST(PassCrewTest, DestroyedWhileSpinningOrAsleepOrNeverUsed)
{
    for (int i = 0; i < 50; ++i) {
        auto crew = std::make_unique<PassCrew>(1 + i % 3);
        if (i % 2) crew->run(4, [](size_t, int) {}); // helpers spinning right after a pass
        crew.reset();                                // must join, whatever they were doing
    }
    PassCrew crew(2);
    while (crew.sleepers() != 2)
        std::this_thread::yield();
    // (destroyed asleep at the end of scope)
}

TEST(PassCrewTest, ACrewMadeBeforeAForkIsLeftAloneInTheChild)
{
#if defined(VDBCLAY_TSAN) || defined(VDBCLAY_ASAN)
    GTEST_SKIP() << "a sanitizer runtime is not fork-safe with threads running";
#else
    // The child has the crew's memory but not its helpers (fork copies the calling thread only), and
    // a sleeping helper's wait is copied into the condition variable. Destroying the crew there used
    // to wait forever for them (PassCrew.h, "fork()"). Three states at the fork: helpers asleep,
    // spinning, and the sleep lock held by a thread that the child does not have (a helper going to
    // sleep holds it for a moment: then the child's copy of it stays locked for ever).
    for (const char* state : {"asleep", "spinning", "locked"}) {
        const bool asleep = state[0] == 'a', locked = state[0] == 'l';
        PassCrew crew(2);
        crew.run(3, [](size_t, int) {});
        if (asleep) {
            while (crew.sleepers() != 2)
                std::this_thread::yield();
        }
        std::atomic<int> lockState{0}; // 1: held, 2: may be released
        std::thread holder;
        if (locked) {
            holder = std::thread([&] {
                std::lock_guard<std::mutex> hold(crew.parkingLock());
                lockState.store(1, std::memory_order_release);
                while (lockState.load(std::memory_order_acquire) != 2)
                    std::this_thread::yield();
            });
            while (lockState.load(std::memory_order_acquire) != 1)
                std::this_thread::yield();
        }
        EXPECT_FALSE(crew.forked());
        const pid_t child = fork();
        if (locked) {
            lockState.store(2, std::memory_order_release);
            holder.join();
        }
        ASSERT_GE(child, 0);
        if (child == 0) {
            alarm(120); // a hang ends the child (SIGALRM), which the parent reports
            int code = crew.forked() ? 0 : 10;
            {
                // A new crew in the child has helpers of its own: all three chunks start together.
                PassCrew fresh(2);
                std::atomic<int> started{0};
                fresh.run(3, [&](size_t, int) {
                    started.fetch_add(1, std::memory_order_acq_rel);
                    awaitStarted(started, 3);
                });
                if (started.load() != 3) code = 11;
            }
            crew.~PassCrew();        // what the owner's destructor does in the child: must return
            new (&crew) PassCrew(0); // (the scope's end destroys it once more)
            _exit(code);
        }
        int status = 0;
        ASSERT_EQ(waitpid(child, &status, 0), child);
        ASSERT_TRUE(WIFEXITED(status))
            << state << ": the child died of signal " << (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
        EXPECT_EQ(WEXITSTATUS(status), 0) << state;
        // The parent's crew is untouched: its helpers still take chunks.
        std::atomic<int> started{0};
        crew.run(3, [&](size_t, int) {
            started.fetch_add(1, std::memory_order_acq_rel);
            awaitStarted(started, 3);
        });
        EXPECT_EQ(started.load(), 3);
    }
#endif
}
