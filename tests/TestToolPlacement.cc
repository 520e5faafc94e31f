// The tools as obstacles and the push follow the clay, not the tools' bounds (issue 13), and give
// the results of marking and scanning the whole bounds: content hashes and step counts computed
// with the previous Sculptor (main at 0a174b5, which evaluated every voxel of every tool's bounds
// every frame), on 1, 2, 3 and 8 threads.
#include <vdbclay/Automaton.h>
#include <vdbclay/Metrics.h>
#include <vdbclay/Scene.h>
#include <vdbclay/Sculpt.h>
#include <vdbclay/Shapes.h>

#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include <atomic>
#include <memory>
#include <string>

using namespace vdbclay;

namespace {

class ToolPlacementTest : public ::testing::Test {
protected:
    static void SetUpTestSuite() { openvdb::initialize(); }
};

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

struct Golden {
    const char* name;
    const char* json;
    uint64_t hash;
    uint64_t steps;
};

// Each scene has a tool whose bounds are far larger than the clay near it, so only part of them
// is marked: the first needs the marks extended ahead of the clay while it settles (the clay
// spreads under the sphere into leaves that did not exist at placement: without the extension the
// result differs), the second is 2D with a turning tool, the third stops with NoRoom (the no-room
// flood reads obstacles) under a piston 400 voxels wide.
const Golden kGolden[] = {
    {"sphere over a lump",
     R"({"threshold": 1000, "rule": "prorata", "seed": 7,
        "clay": [{"shape": "box", "min": [0,0,0], "max": [11,11,11], "mass": 3000}],
        "tools": [{"shape": "sphere", "center": [6, 80, 6], "radius": 70, "path": [{"translate": [0,-2,0], "frames": 3}]}],
        "obstacles": [{"shape": "box", "min": [-100,-3,-100], "max": [100,-1,100]}],
        "settle": {"max_steps": 20000}})",
     0xfaa7c00f890ea6d0ull, 2029},
    {"2d turning disc",
     R"({"dimensions": 2, "threshold": 1000, "rule": "bingham", "seed": 2,
        "clay": [{"shape": "box", "min": [0,0], "max": [9,9], "mass": 2500}],
        "tools": [{"shape": "sphere", "center": [5, 130, 0], "radius": 120, "path": [{"translate": [1,-1,0], "rotate": [0,0,3], "frames": 4}]}],
        "obstacles": [{"shape": "box", "min": [-200,-3], "max": [200,-1]}],
        "settle": {"max_steps": 20000}})",
     0x7fbf09f6137cf2dcull, 1272},
    {"wide piston, no room",
     R"({"dimensions": 2, "threshold": 100, "rule": "prorata",
        "clay": [{"shape": "box", "min": [0,0], "max": [7,3], "mass": 100}],
        "tools": [{"shape": "box", "min": [-200,4], "max": [207,200], "path": [{"translate": [0,-1], "frames": 3}]}],
        "obstacles": [{"shape": "box", "min": [-3,-3], "max": [10,-1]}, {"shape": "box", "min": [-3,0], "max": [-1,40]},
                      {"shape": "box", "min": [8,0], "max": [10,40]}]})",
     0x470effc72e68bfd9ull, 16386},
};

} // namespace

TEST_F(ToolPlacementTest, SameClayAndStepsAsMarkingTheWholeBoundsOnAnyThreadCount)
{
    for (const Golden& g : kGolden) {
        const Scene s = parseScene(g.json, g.name, "");
        for (int threads : {1, 2, 3, 8}) {
            Sculptor sc(s, threads);
            const RunSummary r = sc.run();
            EXPECT_EQ(contentHash(*sc.mass()), g.hash) << g.name << ", " << threads << " threads";
            EXPECT_EQ(sc.automaton().stepCount(), g.steps) << g.name << ", " << threads << " threads";
            EXPECT_EQ(r.massDrift, 0) << g.name;
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
// the old placement evaluated all 241^3 voxels twice (28 M).
TEST_F(ToolPlacementTest, AHugeToolOverASmallLumpCostsEvaluationsNearTheLumpOnly)
{
    for (int threads : {1, 2, 3, 8}) {
        Scene s = parseScene(R"({"threshold": 1000, "memory_budget": "none",
            "clay": [{"shape": "box", "min": [0,0,0], "max": [3,3,3], "mass": 900}],
            "tools": [{"shape": "sphere", "center": [2, 130, 2], "radius": 120, "path": [{"translate": [0,-1,0], "frames": 1}]}]})",
                             "huge.json", "");
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
TEST_F(ToolPlacementTest, APushedLumpCostsEvaluationsBoundedByItsLeaves)
{
    Scene s = parseScene(R"({"threshold": 1000, "seed": 3, "memory_budget": "none",
        "clay": [{"shape": "box", "min": [0,0,0], "max": [11,11,11], "mass": 990}],
        "tools": [{"shape": "sphere", "center": [6, 132, 6], "radius": 120, "path": [{"translate": [0,-6,0], "frames": 1}]}],
        "obstacles": [{"shape": "box", "min": [-40,-3,-40], "max": [50,-1,50]}]})",
                         "pushed.json", "");
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
    EXPECT_LT(bound, 2ull * 241ull * 241ull * 241ull / 50u); // the old placement: every voxel, twice
}
