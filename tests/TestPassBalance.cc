// PassBalance (lib/src/PassBalance.h): the chunks' shares from their measured seconds per block.
// Exact expectations: the measures below are powers of two, so the estimates are exact doubles.
#include "automaton/PassBalance.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <random>
#include <vector>

using vdbclay::automaton_internal::PassBalance;

namespace {

std::vector<uint64_t> cutsOf(const PassBalance& b, int phase, size_t chunks, uint64_t total,
                             int firstShare = 92)
{
    std::vector<uint64_t> cuts;
    b.cuts(phase, chunks, total, firstShare, cuts);
    return cuts;
}

void measure(PassBalance& b, int phase, std::vector<uint64_t> blocks, std::vector<double> seconds)
{
    ASSERT_EQ(blocks.size(), seconds.size());
    std::vector<PassBalance::Measure> measures(blocks.size());
    for (size_t c = 0; c < blocks.size(); ++c)
        measures[c] = {blocks[c], seconds[c]};
    b.measured(phase, measures.size(), measures.data());
}

} // namespace

TEST(PassBalance, WithoutEstimatesChunkZeroGetsFirstShareAndTheRestEvenly)
{
    const PassBalance b;
    // 2 chunks, 92 % of an even share: 460 of 1,000 blocks.
    EXPECT_EQ(cutsOf(b, 0, 2, 1000), (std::vector<uint64_t>{0, 460, 1000}));
    // 4 chunks: chunk 0 92 % of 250 = 230, the other 770 in thirds (floor of 256.67 x c).
    EXPECT_EQ(cutsOf(b, 1, 4, 1000), (std::vector<uint64_t>{0, 230, 486, 743, 1000}));
    EXPECT_EQ(cutsOf(b, 0, 2, 1000, 100), (std::vector<uint64_t>{0, 500, 1000}));
    EXPECT_EQ(cutsOf(b, 0, 1, 1000), (std::vector<uint64_t>{0, 1000}));
    EXPECT_EQ(cutsOf(b, 0, 3, 0), (std::vector<uint64_t>{0, 0, 0, 0}));
}

TEST(PassBalance, SharesFollowTheMeasuredSpeed)
{
    PassBalance b;
    // Chunk 0 took twice the seconds per block of chunk 1: it gets a third of the blocks.
    measure(b, 0, {64, 64}, {0.5, 0.25});
    EXPECT_EQ(b.secondsPerBlock(0, 0), 1.0 / 128);
    EXPECT_EQ(b.secondsPerBlock(0, 1), 1.0 / 256);
    EXPECT_EQ(cutsOf(b, 0, 2, 3000), (std::vector<uint64_t>{0, 1000, 3000}));
    // Phases are separate: phase 1 has no estimates yet.
    EXPECT_EQ(cutsOf(b, 1, 2, 1000), (std::vector<uint64_t>{0, 460, 1000}));
    // Equal speeds: even shares (firstShare applies only without estimates).
    measure(b, 1, {128, 32}, {1.0, 0.25});
    EXPECT_EQ(cutsOf(b, 1, 2, 1000), (std::vector<uint64_t>{0, 500, 1000}));
    // Three chunks at 1, 2 and 4 units per block: shares 4/7, 2/7, 1/7.
    PassBalance three;
    measure(three, 0, {64, 64, 64}, {0.25, 0.5, 1.0});
    EXPECT_EQ(cutsOf(three, 0, 3, 7000), (std::vector<uint64_t>{0, 4000, 6000, 7000}));
}

TEST(PassBalance, EstimatesMoveAnEighthOfTheWayAndAtMostToTwice)
{
    PassBalance b;
    measure(b, 0, {64, 64}, {0.5, 0.5}); // 1/128 s per block each
    // A measure of 3/256 (1.5 x): the estimate moves 1/8 of the way, to 1/128 + (1/256) / 8 = 17/2048.
    measure(b, 0, {64, 64}, {0.75, 0.5});
    EXPECT_EQ(b.secondsPerBlock(0, 0), 17.0 / 2048);
    EXPECT_EQ(b.secondsPerBlock(0, 1), 1.0 / 128);
    // One pass 64 times slower (an interrupt) counts as twice: 17/2048 + (17/2048) / 8 = 153/16384.
    measure(b, 0, {64, 64}, {64 * 64 * 153.0 / 16384, 0.5});
    EXPECT_EQ(b.secondsPerBlock(0, 0), 153.0 / 16384);
    // And one 64 times faster as half: 153/16384 - (153/32768) / 8 = 2295/262144.
    measure(b, 0, {64, 64}, {153.0 / 16384, 0.5});
    EXPECT_EQ(b.secondsPerBlock(0, 0), 2295.0 / 262144);
}

TEST(PassBalance, SmallChunksAndZeroTimesLeaveTheirEstimate)
{
    PassBalance b;
    measure(b, 0, {64, 64}, {0.5, 0.5});
    // Below kMinMeasured blocks, or no time measured: unchanged.
    measure(b, 0, {PassBalance::kMinMeasured - 1, 64}, {8.0, 1.0});
    EXPECT_EQ(b.secondsPerBlock(0, 0), 1.0 / 128);
    EXPECT_EQ(b.secondsPerBlock(0, 1), 1.0 / 128 + (1.0 / 128) / 8);
    measure(b, 0, {64, 64}, {0.0, 0.5});
    EXPECT_EQ(b.secondsPerBlock(0, 0), 1.0 / 128);
    // A chunk never measured leaves the phase on the firstShare cuts.
    PassBalance partial;
    measure(partial, 0, {64, 8}, {0.5, 0.5});
    EXPECT_EQ(partial.secondsPerBlock(0, 1), 0.0);
    EXPECT_EQ(cutsOf(partial, 0, 2, 1000), (std::vector<uint64_t>{0, 460, 1000}));
}

TEST(PassBalance, AnotherChunkCountOrResetStartsOver)
{
    PassBalance b;
    measure(b, 0, {64, 64}, {0.5, 0.25});
    measure(b, 1, {64, 64}, {0.5, 0.25});
    // Asked for three chunks, the phase has estimates for two: the firstShare cuts.
    EXPECT_EQ(cutsOf(b, 0, 3, 3000), (std::vector<uint64_t>{0, 920, 1960, 3000}));
    // Measured with three chunks: phase 0 starts over from this pass; phase 1 keeps its two.
    measure(b, 0, {64, 64, 64}, {0.25, 0.25, 0.25});
    EXPECT_EQ(cutsOf(b, 0, 3, 3000), (std::vector<uint64_t>{0, 1000, 2000, 3000}));
    EXPECT_EQ(cutsOf(b, 1, 2, 3000), (std::vector<uint64_t>{0, 1000, 3000}));
    b.reset();
    EXPECT_EQ(b.secondsPerBlock(1, 0), 0.0);
    EXPECT_EQ(cutsOf(b, 1, 2, 1000), (std::vector<uint64_t>{0, 460, 1000}));
}

TEST(PassBalance, SharesStayWithinAQuarterAndFourTimesAnEvenShare)
{
    PassBalance b;
    // Chunk 0 1,024 times slower per block: by speed its share would be 1/1025, but it keeps a
    // quarter of an even share, 1/8; chunk 1's 1024/1025 stands. Scaled to the total, chunk 0 gets
    // (1/8) / (1/8 + 1024/1025) = 11.12 % of 100,000 blocks.
    measure(b, 0, {1024, 1024}, {1024.0, 1.0});
    EXPECT_EQ(cutsOf(b, 0, 2, 100000), (std::vector<uint64_t>{0, 11121, 100000}));
    // Eight chunks, chunk 3 1,024 times faster: capped at 4 x an even share (1/2), the others
    // raised to a quarter of one (1/32). Scaled: chunk 3 gets 16/23, the others 1/23 each.
    PassBalance eight;
    std::vector<uint64_t> blocks(8, 1024);
    std::vector<double> seconds(8, 1024.0);
    seconds[3] = 1.0;
    measure(eight, 1, blocks, seconds);
    EXPECT_EQ(cutsOf(eight, 1, 8, 1000000),
              (std::vector<uint64_t>{0, 43478, 86957, 130435, 826087, 869565, 913043, 956522, 1000000}));
}

TEST(PassBalance, CutsAreMonotoneAndEndAtTheTotalForAnyEstimates)
{
    std::mt19937_64 rng(7);
    for (int trial = 0; trial < 2000; ++trial) {
        PassBalance b;
        const size_t chunks = 1 + rng() % 9;
        std::vector<uint64_t> blocks(chunks);
        std::vector<double> seconds(chunks);
        for (size_t c = 0; c < chunks; ++c) {
            blocks[c] = rng() % 200;
            seconds[c] = double(rng() % 1000) * 1e-6;
        }
        const int phase = int(rng() % 2);
        measure(b, phase, blocks, seconds);
        const uint64_t total = rng() % 100000;
        const std::vector<uint64_t> cuts = cutsOf(b, phase, chunks, total, 1 + int(rng() % 100));
        ASSERT_EQ(cuts.size(), chunks + 1);
        EXPECT_EQ(cuts.front(), 0u);
        EXPECT_EQ(cuts.back(), total);
        for (size_t c = 0; c < chunks; ++c)
            EXPECT_LE(cuts[c], cuts[c + 1]) << "trial " << trial << " cut " << c;
    }
}
