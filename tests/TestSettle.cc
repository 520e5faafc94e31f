// The automaton brought to rest (Automaton::settle and run) at the edges of what it accepts: one cell
// holding up to 2^31 - 1, masses whose block would overflow a cell, Tc = 1, arata's alpha near 0 and
// near 1, a closed box with no room, an empty grid, and 10^6 steps that must keep mass and memory
// flat. Each case states its expected outcome; the figures in comments were measured with these
// grids (results are identical on any thread count, so they do not depend on the machine).
#include <vdbclay/Automaton.h>
#include <vdbclay/Metrics.h>

#include <openvdb/openvdb.h>

#include "AllocationCounter.h"
#include "Builders.h"

#include <gtest/gtest.h>

#include <climits>
#include <cstdint>
#include <string>
#include <utility>

using namespace vdbclay;
using openvdb::Coord;
using openvdb::CoordBBox;
using vdbclay_test::automatonOptions;
using vdbclay_test::expectError;
using vdbclay_test::kAllRules;

namespace {

class SettleTest : public ::testing::Test {
protected:
    static void SetUpTestSuite() { openvdb::initialize(); }
};

/// Every leaf of @a g holds clay (the automaton never leaves an empty leaf behind).
bool noEmptyLeaf(const MassGrid& g)
{
    for (auto it = g.tree().cbeginLeaf(); it; ++it)
        if (it->onVoxelCount() == 0) return false;
    return true;
}

/// A single cell holding @a m at the origin, settled alone in empty space.
struct Lone {
    openvdb::Int32Grid::Ptr grid = openvdb::Int32Grid::create(0);
    StepReport report;
    ClayMetrics metrics;
};
Lone settleLoneCell(int32_t m, int32_t tc, Rule rule, int dims, uint64_t budget, double alpha = 0.5)
{
    Lone l;
    l.grid->tree().setValue(Coord(0, 0, 0), m);
    AutomatonOptions o = automatonOptions(rule, tc, dims, 2);
    o.rule.alpha = alpha;
    Automaton a(l.grid, o);
    l.report = a.settle(budget);
    l.metrics = measureClay(*l.grid, tc, nullptr, dims);
    return l;
}

} // namespace

// One cell holding 2^24 (Tc 1000: ~16800 cells of clay) or 2^31 - 1 (Tc 2^20) in empty space.
// Expected: it spreads until no cell is over Tc; mass exact; no overflow (no Error); every leaf
// holds clay. Measured steps, 2^24 3D / 2D: arata 276 / 4711, bingham 222 / 1466, sorted 226 /
// 1392, prorata 240 / 1237.
TEST_F(SettleTest, HugeOverloadInOneCellSpreadsExactly)
{
    for (Rule rule : kAllRules) {
        for (int dims : {3, 2}) {
            for (const auto& mt : {std::pair<int32_t, int32_t>{1 << 24, 1000}, {INT32_MAX, 1 << 20}}) {
                const Lone l = settleLoneCell(mt.first, mt.second, rule, dims, 200000);
                const std::string what = std::string(ruleName(rule)) + " " + std::to_string(dims) + "D m " +
                                         std::to_string(mt.first);
                EXPECT_EQ(l.report.reason, StopReason::Settled) << what;
                EXPECT_EQ(l.metrics.mass, mt.first) << what;
                EXPECT_EQ(l.metrics.residualOverload, 0) << what;
                EXPECT_LE(l.metrics.maxCell, mt.second) << what;
                EXPECT_GE(l.metrics.compaction, 1.0) << what;
                EXPECT_TRUE(noEmptyLeaf(*l.grid)) << what;
            }
        }
    }
}

// Masses near the int32 limit: a block whose result cannot fit in a cell is refused with a clear
// Error and the grid left unchanged; totals beyond 2^31 are exact.
TEST_F(SettleTest, MassesNearTheInt32LimitAreRefusedOrExact)
{
    {
        // 2D block of three cells at 2^31 - 1 and one empty cell: the empty one would receive them all.
        auto g = openvdb::Int32Grid::create(0);
        for (const Coord& c : {Coord(0, 0, 0), Coord(1, 0, 0), Coord(0, 1, 0)})
            g->tree().setValue(c, INT32_MAX);
        Automaton a(g, automatonOptions(Rule::Bingham, 1000, 2));
        EXPECT_EQ(a.totalMass(), 3 * int64_t(INT32_MAX)); // 6442450941, exact in 64 bits
        const uint64_t before = contentHash(*g);
        expectError([&] { a.step(); }, "the block at (0, 0, 0) would put more than INT32_MAX (2147483647)");
        EXPECT_EQ(contentHash(*g), before);
        EXPECT_EQ(totalMass(*g), 3 * int64_t(INT32_MAX));
    }
    for (Rule rule : kAllRules) {
        // Two neighbours at 2^31 - 1 with room around them: handled exactly (2^32 - 2 in all).
        auto g = openvdb::Int32Grid::create(0);
        g->tree().setValue(Coord(0, 0, 0), INT32_MAX);
        g->tree().setValue(Coord(1, 0, 0), INT32_MAX);
        Automaton a(g, automatonOptions(rule, 1 << 24));
        const StepReport r = a.settle(100000);
        EXPECT_EQ(r.reason, StopReason::Settled) << ruleName(rule);
        EXPECT_EQ(totalMass(*g), (int64_t(1) << 32) - 2) << ruleName(rule);
        EXPECT_LE(measureClay(*g, 1 << 24, nullptr, 3).maxCell, 1 << 24) << ruleName(rule);
    }
}

// A closed 3D box full to Tc plus 7 units. No state without overload exists; every rule's settle
// says so (NoRoom) after 8192 steps instead of running its budget.
TEST_F(SettleTest, AClosedBoxFullToTcStopsWithNoRoom)
{
    auto g = openvdb::Int32Grid::create(0);
    auto walls = openvdb::MaskGrid::create(false);
    walls->tree().fill(CoordBBox(Coord(-1), Coord(4)), true, true);
    walls->tree().fill(CoordBBox(Coord(0), Coord(3)), false, false);
    g->tree().fill(CoordBBox(Coord(0), Coord(3)), 100, true);
    g->tree().voxelizeActiveTiles();
    g->tree().setValue(Coord(1, 2, 3), 107);
    for (const Rule rule : kAllRules) {
        auto copy = g->deepCopy();
        Automaton a(copy, automatonOptions(rule, 100), walls);
        const StepReport r = a.settle(100000);
        EXPECT_EQ(r.reason, StopReason::NoRoom) << ruleName(rule);
        EXPECT_EQ(r.steps, 8192u) << ruleName(rule);
        // The least overload possible is 7; rules 1-3 get there, arata keeps moving whole
        // fractions of cells about (well above 7 when the check stops it).
        if (rule == Rule::Arata)
            EXPECT_GT(r.residualOverload, 7);
        else
            EXPECT_EQ(r.residualOverload, 7) << ruleName(rule);
        EXPECT_EQ(totalMass(*copy), 64 * 100 + 7) << ruleName(rule);
    }
}

// arata with alpha at the ends of (0, 1). alpha is quantised to 2^-32 and clamped into
// [2^-32, 1 - 2^-32]; an over cell gives at least 1 unit. So near 0 it moves one unit per over
// cell per step: a lone cell of 10000 at Tc 100 settles in exactly 9901 steps, and 2^24 would take
// ~1.7e7 steps: the budget stops it (StepBudget, exact mass), the one case here where a rule
// cannot settle in practical time. Near 1 an over cell keeps 1 unit and settles in 5 steps,
// spread thin (compaction 3.08).
TEST_F(SettleTest, ArataAlphaNearZeroAndNearOne)
{
    Lone l = settleLoneCell(10000, 100, Rule::Arata, 3, 200000, 1e-12);
    EXPECT_EQ(l.report.reason, StopReason::Settled);
    EXPECT_EQ(l.report.steps, 9901u);
    EXPECT_EQ(l.metrics.mass, 10000);
    l = settleLoneCell(10000, 100, Rule::Arata, 3, 200000, 1 - 1e-12);
    EXPECT_EQ(l.report.reason, StopReason::Settled);
    EXPECT_EQ(l.report.steps, 5u);
    EXPECT_EQ(l.metrics.mass, 10000);
    EXPECT_EQ(l.metrics.compaction, 3.08);
    l = settleLoneCell(1 << 24, 1000, Rule::Arata, 3, 20000, 1e-12);
    EXPECT_EQ(l.report.reason, StopReason::StepBudget);
    EXPECT_EQ(l.metrics.mass, 1 << 24);
    EXPECT_GT(l.report.residualOverload, (1 << 24) - 1000 - 20000);
}

// Tc = 1 with a lone cell; a single voxel at or under Tc; an empty grid.
TEST_F(SettleTest, TcOneSingleVoxelAndEmptyGrid)
{
    for (const Rule rule : kAllRules) {
        // 1000 units at Tc = 1 end as 1000 cells of 1: perfectly compact.
        const Lone l = settleLoneCell(1000, 1, rule, 3, 100000);
        EXPECT_EQ(l.report.reason, StopReason::Settled) << ruleName(rule);
        EXPECT_EQ(l.metrics.clayVoxels, 1000u) << ruleName(rule);
        EXPECT_EQ(l.metrics.compaction, 1.0) << ruleName(rule);
        // A single voxel at or under Tc: nothing to do.
        const Lone one = settleLoneCell(7, 7, rule, 2, 100000);
        EXPECT_EQ(one.report.steps, 0u);
        EXPECT_EQ(one.report.reason, StopReason::Settled);
        EXPECT_EQ(one.metrics.clayVoxels, 1u);
    }
    auto empty = openvdb::Int32Grid::create(0);
    Automaton a(empty);
    const StepReport r = a.settle(1000);
    EXPECT_EQ(r.steps, 0u);
    EXPECT_EQ(r.reason, StopReason::Settled);
}

// A long run: 10^6 steps of a state that never comes to rest (a closed 2D box full to Tc plus 5
// units that wander for ever). Expected: mass exact throughout, blocks still changing at the end,
// the leaf count and the grid's bytes constant, and no heap allocation at all in the automaton's
// steps once its buffers have grown (the first 10^5 steps).
TEST_F(SettleTest, LongRunKeepsMassExactAndAllocatesNothing)
{
    auto g = openvdb::Int32Grid::create(0);
    auto walls = openvdb::MaskGrid::create(false);
    walls->tree().fill(CoordBBox(Coord(-1, -1, 0), Coord(6, 6, 0)), true, true);
    walls->tree().fill(CoordBBox(Coord(0, 0, 0), Coord(5, 5, 0)), false, false);
    g->tree().fill(CoordBBox(Coord(0, 0, 0), Coord(5, 5, 0)), 100, true);
    g->tree().voxelizeActiveTiles();
    g->tree().setValue(Coord(2, 3, 0), 105);
    Automaton a(g, automatonOptions(Rule::Bingham, 100, 2, 1), walls);
    const int64_t m0 = 36 * 100 + 5;
    const size_t leaves = g->tree().leafCount();
    const openvdb::Index64 bytes = g->tree().memUsage();
    int64_t allocationsInSteps = 0; // in the steps after the first 10^5
    for (int chunk = 1; chunk <= 10; ++chunk) {
        const int64_t before = alloc_counter::newCalls.load();
        const StepReport r = a.run(100000);
        if (chunk > 1) allocationsInSteps += alloc_counter::newCalls.load() - before;
        ASSERT_GT(r.blocksUpdated, 0u) << "the state came to rest at chunk " << chunk;
        ASSERT_EQ(a.totalMass(), m0);
        ASSERT_EQ(totalMass(*g), m0);
        ASSERT_EQ(r.residualOverload, 5);
        ASSERT_EQ(g->tree().leafCount(), leaves);
        ASSERT_EQ(g->tree().memUsage(), bytes);
    }
    EXPECT_EQ(a.stepCount(), 1000000u);
    EXPECT_EQ(allocationsInSteps, 0) << "heap allocations in 9 x 10^5 steps";
}
