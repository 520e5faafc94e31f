// PassCrew (lib/src/PassCrew.h): every chunk of every pass runs exactly once, on the caller and the
// helpers, whether they spin or sleep; a chunk's exception reaches the caller after the others
// finish. No test waits on time: where a test needs the helpers to take part, a chunk waits until
// another lane has started a chunk of the same pass, which only a helper can do while the caller
// is inside that chunk (so a crew whose helpers never ran would hang, and ctest's timeout fails it).
#include "PassCrew.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

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
