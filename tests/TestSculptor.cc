// The sculpting pipeline (vdbclay/Sculpt.h) on whole runs of scenes (data/scenes/test): the clay a
// scene's shapes add up to, the incompressible limit with every rule, clay trapped with no room,
// plates closing to one voxel, arata's alpha near 0 and 1, the smallest scenes, 600 frames with flat
// memory, and the tools' cells as obstacles: marked only near the clay, each frame, with pinned
// results on any thread count and a cost that follows the clay, not the tools' bounds. Each case
// states its expected outcome; the figures in comments were measured with these scenes (results are
// identical on any thread count, so they do not depend on the machine).
#include <vdbclay/Automaton.h>
#include <vdbclay/Metrics.h>
#include <vdbclay/Scene.h>
#include <vdbclay/Sculpt.h>
#include <vdbclay/Shapes.h>

#include <openvdb/openvdb.h>

#include "AllocationCounter.h"
#include "Builders.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

using namespace vdbclay;
using openvdb::Coord;
using vdbclay_test::allClay;
using vdbclay_test::expectError;
using vdbclay_test::kAllRules;
using vdbclay_test::loadTestScene;
using vdbclay_test::runScene;
using vdbclay_test::runSceneJson;
using vdbclay_test::testSceneWithRule;

namespace {

class SculptorTest : public ::testing::Test {
protected:
    static void SetUpTestSuite() { openvdb::initialize(); }
};

} // namespace

// ---- the clay of a scene ------------------------------------------------------------------------

TEST_F(SculptorTest, OverlappingClayAddsLeafByLeafAndRefusesOverflow)
{
    // Two boxes overlapping across leaf boundaries (new leaves, shared leaves): the overlap holds the sum.
    const Scene scene =
        parseScene(R"({"clay": [{"shape": "box", "min": [-5,-5,-5], "max": [9,9,9], "mass": 300},
                                {"shape": "box", "min": [3,3,3], "max": [20,20,20], "mass": 500}],
                       "frames": 1})",
                   "s.json", "");
    Sculptor sculptor(scene, 1);
    auto acc = sculptor.mass()->getConstAccessor();
    EXPECT_EQ(acc.getValue(Coord(-5, -5, -5)), 300);
    EXPECT_EQ(acc.getValue(Coord(3, 3, 3)), 800);
    EXPECT_EQ(acc.getValue(Coord(9, 9, 9)), 800);
    EXPECT_EQ(acc.getValue(Coord(10, 9, 9)), 500);
    EXPECT_EQ(acc.getValue(Coord(20, 20, 20)), 500);
    EXPECT_TRUE(acc.isValueOn(Coord(20, 20, 20)));
    EXPECT_EQ(acc.getValue(Coord(21, 20, 20)), 0);
    EXPECT_EQ(totalMass(*sculptor.mass()), int64_t(15 * 15 * 15) * 300 + int64_t(18 * 18 * 18) * 500);

    const Scene over =
        parseScene(R"({"clay": [{"shape": "box", "min": [0,0,0], "max": [3,3,3], "mass": 2000000000},
                                {"shape": "box", "min": [2,2,2], "max": [5,5,5], "mass": 2000000000}],
                       "threshold": 2147483647, "frames": 1})",
                   "s.json", "");
    expectError([&] { Sculptor bad(over, 1); }, "overlapping clay at voxel (2, 2, 2) adds up to 4000000000");
}

// ---- whole runs at the limits -------------------------------------------------------------------

// Clay filled exactly to Tc everywhere (a cell at Tc is "under" with no room) and pressed by a
// plate: the pushed layer overloads full cells, and the excess has to travel through full clay to
// the free surface. Expected and measured: every rule settles, with no overload left, no cell over
// Tc and exact mass; none of the four fails here. Steps (3D cube / 2D square / 2D tube / 3D tube):
// arata 61 / 275 / 1777 / 1355, bingham 100 / 697 / 12312 / 7761, sorted 97 / 629 / 12453 / 7018,
// prorata 84 / 651 / 11666 / 7762. Final heterogeneity CV (3D cube): arata 0.20, bingham 0.16,
// sorted 0.17, prorata 0.18; in the 2D tube arata 0.20 against 0.00-0.01 for rules 1-3.
TEST_F(SculptorTest, IncompressibleLimitEveryRuleSettles)
{
    struct Case {
        const char* scene;
        bool (*beyond)(const Coord&); // where the excess must have arrived
    };
    const Case cases[] = {
        {"incompressible-cube.json",
         [](const Coord& c) { return c.x() < 0 || c.x() > 7 || c.z() < 0 || c.z() > 7; }},
        {"incompressible-square2d.json", [](const Coord& c) { return c.x() < 0 || c.x() > 15; }},
        {"incompressible-tube2d.json", [](const Coord& c) { return c.y() > 15 - 4 && c.x() >= 12; }},
        {"incompressible-tube3d.json", [](const Coord& c) { return c.y() > 7 - 3 && c.x() >= 6; }},
    };
    for (const Rule rule : kAllRules) {
        for (const Case& k : cases) {
            std::vector<FrameReport> frames;
            MassGridPtr clay;
            const RunSummary s = runScene(testSceneWithRule(k.scene, rule), &frames, &clay);
            const std::string what = std::string(ruleName(rule)) + " " + k.scene;
            EXPECT_EQ(s.massDrift, 0) << what;
            EXPECT_TRUE(s.settled) << what;
            EXPECT_EQ(s.framesUnsettled, 0u) << what;
            EXPECT_EQ(s.residualOverload, 0) << what;
            EXPECT_EQ(s.massTrapped, 0) << what;
            EXPECT_LE(s.metrics.maxCell, 100) << what;
            for (const FrameReport& f : frames)
                EXPECT_EQ(f.settle.reason, StopReason::Settled) << what;
            EXPECT_FALSE(allClay(*clay, [&](const Coord& c) { return !k.beyond(c); }))
                << what << ": the excess never left";
        }
    }
}

// The same with Tc = 1: a cell holds 0 or 1, so at rest the clay is perfectly compact and uniform.
TEST_F(SculptorTest, IncompressibleLimitWithTcOne)
{
    for (const Rule rule : kAllRules) {
        const RunSummary s = runScene(testSceneWithRule("incompressible-cube-tc1.json", rule));
        EXPECT_EQ(s.massDrift, 0) << ruleName(rule);
        EXPECT_TRUE(s.settled) << ruleName(rule);
        EXPECT_EQ(s.metrics.maxCell, 1) << ruleName(rule);
        EXPECT_EQ(s.metrics.clayVoxels, 512u) << ruleName(rule);
        EXPECT_EQ(s.metrics.compaction, 1.0) << ruleName(rule);
        EXPECT_EQ(s.metrics.heterogeneityCV, 0.0) << ruleName(rule);
    }
}

// Clay trapped between a tool and obstacles with no room: a 2D piston, 27 voxels tall (more than
// push's 16-voxel search, so clay cannot hop over it), descends into a closed tube 8 wide holding
// 4 rows at Tc. Expected and measured, every rule:
// - frame 1 presses a row into 3 rows that cannot hold it: the excess moves but can never vanish;
//   settle stops after 8192 steps with NoRoom (without that check, the frames would run the whole
//   step budget, 100000 steps by default);
// - frames 2 and 3 squeeze further: NoRoom again, at once when every clay cell is over Tc and
//   nothing can move (2 or 3 steps), else at the 8192-step check (rules 1-3 in frame 2);
// - frame 4 closes the tube: all 3200 units sit inside the piston, reported trapped, 400 per
//   cell; mass exact throughout.
TEST_F(SculptorTest, ClayTrappedBetweenToolAndObstacleIsConservedAndReported)
{
    for (const Rule rule : kAllRules) {
        const char* name = ruleName(rule);
        std::vector<FrameReport> frames;
        const RunSummary s = runScene(testSceneWithRule("trapped-piston2d.json", rule), &frames);
        ASSERT_EQ(frames.size(), 4u) << name;
        EXPECT_EQ(frames[0].settle.reason, StopReason::NoRoom) << name;
        EXPECT_EQ(frames[0].settle.steps, 8192u) << name;
        EXPECT_EQ(frames[0].settle.residualOverload, 800) << name;
        for (int f = 1; f < 3; ++f) {
            EXPECT_EQ(frames[f].settle.reason, StopReason::NoRoom) << name << " frame " << f + 1;
            EXPECT_EQ(frames[f].settle.residualOverload, 800 * (f + 1)) << name << " frame " << f + 1;
            EXPECT_LE(frames[f].settle.steps, 8192u) << name << " frame " << f + 1;
        }
        EXPECT_EQ(frames[3].push.massTrapped, 3200) << name;
        EXPECT_EQ(frames[3].push.voxelsTrapped, 8u) << name;
        EXPECT_EQ(frames[3].settle.reason, StopReason::Settled) << name;
        EXPECT_EQ(s.massDrift, 0) << name;
        EXPECT_EQ(s.massTrapped, 3200) << name;
        EXPECT_EQ(s.framesNoRoom, 3u) << name;
        EXPECT_EQ(s.framesUnsettled, 3u) << name;
        EXPECT_EQ(s.residualOverload, 0) << name; // the clay is in the piston's (obstacle) cells
        EXPECT_EQ(s.metrics.maxCell, 400) << name;
    }
}

// Two plates closing until a single voxel layer (y = 4) is left between them. Expected: the clay
// squeezes out sideways, none stays inside a plate, inside their footprint it lies only in the gap;
// mass exact, settled, nothing trapped.
TEST_F(SculptorTest, TwoPlatesClosingToOneVoxel)
{
    for (const Rule rule : kAllRules) {
        const char* name = ruleName(rule);
        MassGridPtr clay;
        const RunSummary s = runScene(testSceneWithRule("two-plates-one-voxel.json", rule), nullptr, &clay);
        EXPECT_EQ(s.massDrift, 0) << name;
        EXPECT_TRUE(s.settled) << name;
        EXPECT_EQ(s.residualOverload, 0) << name;
        EXPECT_EQ(s.massTrapped, 0) << name;
        EXPECT_TRUE(allClay(*clay, [](const Coord& c) {
            const bool footprint = c.x() >= -10 && c.x() <= 19 && c.z() >= -10 && c.z() <= 19;
            return !footprint || c.y() == 4;
        })) << name;
    }
}

// arata with alpha at the ends of (0, 1) (TestSettle.cc has the lone cells): in the pressed cube
// both ends settle, with exact mass and no overload left.
TEST_F(SculptorTest, ArataAlphaNearZeroAndNearOneSettleThePressedCube)
{
    for (const double alpha : {1e-9, 0.999999999}) {
        Scene scene = loadTestScene("test/pressed-cube-arata.json");
        scene.rule.alpha = alpha;
        const RunSummary s = runScene(scene);
        EXPECT_EQ(s.massDrift, 0) << alpha;
        EXPECT_TRUE(s.settled) << alpha;
        EXPECT_EQ(s.residualOverload, 0) << alpha;
    }
}

// A single voxel pressed by a plate; a scene with no clay at all.
TEST_F(SculptorTest, SingleVoxelPressedAndEmptyScene)
{
    // A single voxel pressed by a plate: pushed out, exact, settled.
    RunSummary s = runSceneJson(
        R"({"threshold": 100, "clay": [{"shape": "box", "min": [0,0,0], "max": [0,0,0], "mass": 100}],
        "tools": [{"shape": "box", "min": [-2,2,-2], "max": [2,4,2], "path": [{"translate": [0,-1,0], "frames": 3}]}]})");
    EXPECT_EQ(s.massDrift, 0);
    EXPECT_EQ(s.massFinal, 100);
    EXPECT_TRUE(s.settled);
    EXPECT_EQ(s.metrics.clayVoxels, 1u);
    // No clay at all: frames run, nothing moves, every metric is 0.
    s = runSceneJson(
        R"({"tools": [{"shape": "box", "min": [0,0,0], "max": [3,3,3], "path": [{"translate": [0,-1,0], "frames": 3}]}]})");
    EXPECT_EQ(s.frames, 3u);
    EXPECT_EQ(s.steps, 0u);
    EXPECT_EQ(s.massFinal, 0);
    EXPECT_TRUE(s.settled);
    EXPECT_EQ(s.metrics.clayVoxels, 0u);
    EXPECT_EQ(s.metrics.compaction, 0.0);
}

// A long run: 600 frames of a tool going up and down in a lump, on one thread. Expected: mass exact
// and every frame settled throughout, and no more live heap blocks after each later 6-frame cycle
// of the tool than at the end of the first 50 cycles: nothing accumulates.
TEST_F(SculptorTest, LongRunKeepsMassExactAndMemoryFlat)
{
    Sculptor sc(loadTestScene("test/tool-up-and-down-600-frames2d.json"), 1);
    const int64_t lump = 16 * 8 * 100;
    int64_t liveAt300 = 0, liveMaxAfter = 0;
    while (!sc.done()) {
        const FrameReport f = sc.runFrame();
        ASSERT_EQ(totalMass(*sc.mass()), lump) << "frame " << f.frame;
        ASSERT_EQ(f.settle.reason, StopReason::Settled) << "frame " << f.frame;
        if (f.frame == 300) liveAt300 = alloc_counter::liveBlocks.load();
        if (f.frame > 300 && f.frame % 6 == 0)
            liveMaxAfter = std::max(liveMaxAfter, alloc_counter::liveBlocks.load());
    }
    EXPECT_EQ(sc.frame(), 600u);
    EXPECT_LE(liveMaxAfter, liveAt300) << "live heap blocks grew over frames 301..600";
}

// ---- the tools' cells as obstacles --------------------------------------------------------------
// The tools' cells are marked as obstacles, and the push tests clay voxels, only where the clay is
// (the leaf slots next to its leaves, extended while it spreads), not over the tools' bounds; the
// results are those of marking and scanning every voxel of the bounds each frame.

namespace {

/// Counts its distance() calls (normal() goes through distance()); thread-safe.
class CountingShape final : public Shape {
public:
    CountingShape(ShapePtr inner, std::atomic<uint64_t>& count) : mInner(std::move(inner)), mCount(count) {}
    double distance(const Vec3& p) const override
    {
        mCount.fetch_add(1, std::memory_order_relaxed);
        return mInner->distance(p);
    }
    Box bounds() const override { return mInner->bounds(); }
    std::string describe() const override { return "counted " + mInner->describe(); }

private:
    ShapePtr mInner;
    std::atomic<uint64_t>& mCount;
};

struct Pinned {
    const char* scene; ///< in data/scenes
    uint64_t hash;
    uint64_t steps;
};

// Each scene has a tool whose bounds are far larger than the clay near it, so only part of them
// is marked: the first needs the marks extended ahead of the clay while it settles (the clay
// spreads under the sphere into leaves that did not exist at placement: without the extension the
// result differs), the second is 2D with a turning tool, the third stops with NoRoom (the no-room
// flood reads obstacles) under a piston 408 voxels wide. The hashes and step counts are those of
// marking every voxel of every tool's bounds each frame.
const Pinned kPinned[] = {
    {"bench/sphere-over-lump.json", 0xfaa7c00f890ea6d0ull, 2029},
    {"test/turning-disc2d.json", 0x7fbf09f6137cf2dcull, 1272},
    {"test/wide-piston-no-room2d.json", 0x470effc72e68bfd9ull, 16386},
};

} // namespace

TEST_F(SculptorTest, ToolCellsMarkedNearTheClayGiveThePinnedClayAndStepsOnAnyThreadCount)
{
    for (const Pinned& p : kPinned) {
        const Scene s = loadTestScene(p.scene);
        for (int threads : {1, 2, 3, 8}) {
            Sculptor sc(s, threads);
            const RunSummary r = sc.run();
            EXPECT_EQ(contentHash(*sc.mass()), p.hash) << p.scene << ", " << threads << " threads";
            EXPECT_EQ(sc.automaton().stepCount(), p.steps) << p.scene << ", " << threads << " threads";
            EXPECT_EQ(r.massDrift, 0) << p.scene;
        }
    }
}

// A sphere of radius 120 (bounds 241^3 voxels, 14 M) held over a 4^3 lump below Tc (nothing
// settles): the tools' cells are marked only in the leaf slots next to the lump's leaf (slot
// 0,0,0), i.e. the 3 x 3 slots of y-slot 1 (y 8..15) that the bounds reach, and the push tests only
// the clay voxels inside the bounds (none). Exactly:
// - at construction (frame 0, bounds y >= 10): 9 slots x 64 columns x 6 rows (y 10..15) = 3456;
// - frame 1 (moved down 1: a moved shape's bounds hold its continuous solid, y >= 8.5, so
//   y >= 8): 9 x 64 x 8 (y 8..15) = 4608;
// marking the whole bounds would evaluate all 241^3 voxels twice (28 M).
TEST_F(SculptorTest, AHugeToolOverASmallLumpCostsEvaluationsNearTheLumpOnly)
{
    for (int threads : {1, 2, 3, 8}) {
        Scene s = loadTestScene("test/huge-sphere-over-small-lump.json");
        std::atomic<uint64_t> count{0};
        s.tools[0].shape.shape = std::make_shared<CountingShape>(s.tools[0].shape.shape, count);
        ASSERT_EQ(s.tools[0].shape.shape->bounds().min[1], 10);
        ASSERT_EQ(s.tools[0].shape.shape->bounds().max[1], 250);
        Pose moved;
        moved.translation = {{0, -1, 0}};
        ASSERT_EQ(makeTransformed(s.tools[0].shape.shape, moved)->bounds().min[1], 8);
        Sculptor sc(s, threads);
        EXPECT_EQ(count.load(), 9u * 64u * 6u) << threads << " threads";
        count = 0;
        const FrameReport f = sc.runFrame();
        EXPECT_EQ(f.push.voxelsPushed, 0u);
        EXPECT_EQ(f.settle.steps, 0u);
        EXPECT_EQ(count.load(), 9u * 64u * 8u) << threads << " threads";
        // The marked cells are the sphere's cells in those slots: its lowest voxels, right above
        // the lump, are obstacles; cells of the sphere far from the clay are not marked.
        const auto& obs = sc.automaton().obstacles();
        ASSERT_TRUE(obs);
        EXPECT_TRUE(obs->tree().isValueOn(openvdb::Coord(2, 10, 2)));
        EXPECT_FALSE(obs->tree().isValueOn(openvdb::Coord(2, 9, 2))); // the surface: distance 0
        EXPECT_FALSE(obs->tree().isValueOn(openvdb::Coord(2, 100, 2)));
    }
}

// The same sphere pressed 6 voxels into a 12^3 lump above Tc: clay is pushed, settles and spreads
// into new leaves. Every evaluation is bounded by the clay: at most 512 per slot next to a final
// leaf per placement (2 placements), plus per clay voxel in the bounds one test and, per source,
// 6 for its normal and 2 per march point (33 points, isFree and isWall).
TEST_F(SculptorTest, APushedLumpCostsEvaluationsBoundedByItsLeaves)
{
    Scene s = loadTestScene("test/huge-sphere-pushed-into-lump.json");
    std::atomic<uint64_t> count{0};
    s.tools[0].shape.shape = std::make_shared<CountingShape>(s.tools[0].shape.shape, count);
    Sculptor sc(s, 2);
    const FrameReport f = sc.runFrame();
    EXPECT_GT(f.push.voxelsPushed, 0u);
    EXPECT_GT(f.settle.steps, 0u);
    const uint64_t leaves = sc.mass()->tree().leafCount();
    const uint64_t clayVoxels = 12u * 12u * 12u; // a bound on clay voxels inside the bounds
    const uint64_t bound = 2u * 27u * 512u * leaves + clayVoxels * (1u + 6u + 2u * 33u);
    EXPECT_LE(count.load(), bound) << leaves << " leaves";
    EXPECT_LT(bound, 2ull * 241ull * 241ull * 241ull / 50u); // the whole bounds: every voxel, twice
}
