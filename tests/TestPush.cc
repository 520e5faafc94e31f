// The push (vdbclay/Push.h): a tool moves the clay it covers out past its surface. Tools through a
// sheet one voxel thick, a tool that jumps over it, a tool moving 6 voxels a frame into a cube (whole
// runs of the scenes in data/scenes/test, with every rule), and a push next to a cell near 2^31.
#include <vdbclay/Automaton.h>
#include <vdbclay/IO.h>
#include <vdbclay/Metrics.h>
#include <vdbclay/Push.h>
#include <vdbclay/Shapes.h>

#include <openvdb/openvdb.h>

#include "Builders.h"

#include <gtest/gtest.h>

#include <climits>
#include <cstdint>
#include <string>
#include <vector>

using namespace vdbclay;
using openvdb::Coord;
using openvdb::CoordBBox;
using vdbclay_test::allClay;
using vdbclay_test::errorOf;
using vdbclay_test::expectError;
using vdbclay_test::kAllRules;
using vdbclay_test::loadTestScene;
using vdbclay_test::runScene;
using vdbclay_test::testSceneWithRule;

namespace {

class PushTest : public ::testing::Test {
protected:
    static void SetUpTestSuite() { openvdb::initialize(); }
};

/// @a value in every voxel of @a box, as the push tests' clay (a grid named "mass").
openvdb::Int32Grid::Ptr clayBox(const CoordBBox& box, int32_t value)
{
    auto g = vdbclay_test::clayBox(box.min(), box.max(), value);
    g->setName("mass");
    return g;
}

/// Prorata, Tc 100, one thread.
AutomatonOptions opts(int dims = 3)
{
    return vdbclay_test::automatonOptions(Rule::Prorata, 100, dims, 1);
}

Vec3 v3(const Coord& c)
{
    return {{double(c.x()), double(c.y()), double(c.z())}};
}

/// Clay voxels whose centre is inside one of @a tools.
int64_t clayInside(const openvdb::Int32Grid& g, const std::vector<ShapePtr>& tools)
{
    int64_t n = 0;
    for (auto it = g.tree().cbeginValueOn(); it; ++it) {
        if (*it == 0) continue;
        for (const ShapePtr& t : tools)
            if (t->distance(v3(it.getCoord())) < 0) {
                ++n;
                break;
            }
    }
    return n;
}

} // namespace

// A tool passing through a sheet one voxel thick. At one voxel per frame (a sphere of radius 3):
// it punches a hole (the 4 x 4 cells under its path are empty at the end), mass exact, settled.
// Jumping 20 voxels in one frame from above the sheet to below it, the box never overlaps the
// sheet at a frame and leaves it untouched: push acts on the tool's placement at each frame, not
// on the volume swept between frames (a known limitation; move tools at most their thickness
// per frame, or set "sweep"). Moving 6 voxels per frame into a cube (an 8 x 8 x 15 box): each frame
// pushes every clay voxel it then covers (384 voxels) all the way out, traps nothing and the cube
// settles.
TEST_F(PushTest, ToolsThroughThinSheetsAndManyVoxelsPerFrame)
{
    for (const Rule rule : kAllRules) {
        const char* name = ruleName(rule);
        MassGridPtr clay;
        RunSummary s = runScene(testSceneWithRule("sphere-through-sheet.json", rule), nullptr, &clay);
        EXPECT_EQ(s.massDrift, 0) << name;
        EXPECT_TRUE(s.settled) << name;
        auto acc = clay->getConstAccessor();
        for (int x = 6; x <= 9; ++x)
            for (int z = 6; z <= 9; ++z)
                EXPECT_EQ(acc.getValue(Coord(x, 0, z)), 0) << name << " " << x << "," << z;

        const MassGridPtr before = makeClay(*makeBox({{0, 0, 0}}, {{15, 0, 15}}), 100, 3);
        s = runScene(testSceneWithRule("box-jumps-over-sheet.json", rule), nullptr, &clay);
        EXPECT_EQ(contentHash(*clay), contentHash(*before)) << name << ": the jump went through the sheet";
        EXPECT_EQ(s.steps, 0u) << name;

        std::vector<FrameReport> frames;
        s = runScene(testSceneWithRule("box-into-cube-6-per-frame.json", rule), &frames, &clay);
        ASSERT_EQ(frames.size(), 2u);
        for (const FrameReport& f : frames) {
            EXPECT_EQ(f.push.voxelsPushed, 384u) << name;
            EXPECT_EQ(f.push.voxelsTrapped, 0u) << name;
            EXPECT_EQ(f.settle.reason, StopReason::Settled) << name;
        }
        EXPECT_EQ(s.massDrift, 0) << name;
        // The tool ends at y 4..18 over x, z 4..11: no clay there.
        EXPECT_TRUE(allClay(*clay, [](const Coord& c) {
            return !(c.x() >= 4 && c.x() <= 11 && c.z() >= 4 && c.z() <= 11 && c.y() >= 4);
        })) << name;
    }
}

// The voxel next to the tool holds 2^31 - 6, so 10 more would not fit: push never fills a cell past
// INT32_MAX, and the clay goes one voxel further along the normal instead.
TEST_F(PushTest, NeverFillsACellPastInt32Max)
{
    auto g = openvdb::Int32Grid::create(0);
    g->tree().setValue(Coord(0, 0, 0), INT32_MAX - 5);
    g->tree().setValue(Coord(1, 0, 0), 10);
    AutomatonOptions o;
    o.dimensions = 2;
    Automaton a(g, o);
    const PushReport r = push(a, {makeBox({{1, -1, 0}}, {{3, 1, 0}})});
    EXPECT_EQ(r.voxelsPushed, 1u);
    EXPECT_EQ(g->tree().getValue(Coord(0, 0, 0)), INT32_MAX - 5);
    EXPECT_EQ(g->tree().getValue(Coord(-1, 0, 0)), 10);
    EXPECT_EQ(totalMass(*g), int64_t(INT32_MAX) + 5);
}

// ---- the push, tool by tool --------------------------------------------------------------------

TEST_F(PushTest, SphereIntoClayBox)
{
    auto mass = clayBox(CoordBBox(Coord(0), Coord(15)), 100);
    Automaton a(mass, opts());
    const int64_t m0 = a.totalMass();
    const std::vector<ShapePtr> tools = {makeSphere({{8, 8, 1}}, 4.5)};
    const int64_t before = clayInside(*mass, tools);
    ASSERT_GT(before, 50);
    const PushReport r = push(a, tools);
    EXPECT_EQ(r.voxelsPushed, uint64_t(before));
    EXPECT_EQ(r.massMoved, 100 * before);
    EXPECT_EQ(r.voxelsTrapped, 0u);
    EXPECT_EQ(r.massTrapped, 0);
    EXPECT_FALSE(r.region.empty());
    EXPECT_EQ(clayInside(*mass, tools), 0);
    EXPECT_EQ(a.totalMass(), m0);
    EXPECT_EQ(totalMass(*mass), m0);
    EXPECT_GT(a.residualOverload(), 0); // the pushed clay piles up around the tool
    // A second push has nothing to do.
    const PushReport again = push(a, tools);
    EXPECT_EQ(again.voxelsPushed, 0u);
    EXPECT_TRUE(again.region.empty());
}

TEST_F(PushTest, ToolMovedFiveVoxelsPushesAllOut)
{
    auto mass = clayBox(CoordBBox(Coord(0), Coord(19)), 100);
    Automaton a(mass, opts());
    const int64_t m0 = a.totalMass();
    const ShapePtr tool = makeSphere({{10, 10, -4}}, 4); // touches the clay, holds none
    EXPECT_EQ(push(a, {tool}).voxelsPushed, 0u);
    Pose pose;
    pose.translation = {{0, 0, 5}};
    const std::vector<ShapePtr> moved = {makeTransformed(tool, pose)};
    const int64_t inside = clayInside(*mass, moved);
    ASSERT_GT(inside, 30);
    const PushReport r = push(a, moved);
    EXPECT_EQ(r.voxelsPushed, uint64_t(inside));
    EXPECT_EQ(r.voxelsTrapped, 0u);
    EXPECT_EQ(clayInside(*mass, moved), 0);
    EXPECT_EQ(a.totalMass(), m0);
    EXPECT_EQ(totalMass(*mass), m0);
}

TEST_F(PushTest, SqueezedClayIsTrappedAndConserved)
{
    // Clay 0..9 fills a cavity in a thick obstacle; a tool fills the cavity. Nowhere to go.
    auto mass = clayBox(CoordBBox(Coord(0), Coord(9)), 50);
    auto obs = openvdb::MaskGrid::create(false);
    obs->tree().fill(CoordBBox(Coord(-10), Coord(20)), true, true);
    obs->tree().fill(CoordBBox(Coord(0), Coord(9)), false, false);
    obs->tree().voxelizeActiveTiles();
    Automaton a(mass, opts(), obs);
    const int64_t m0 = a.totalMass();
    const uint64_t h0 = contentHash(*mass);
    const std::vector<ShapePtr> tools = {makeBox({{0, 0, 0}}, {{9, 9, 9}})};
    const PushReport r = push(a, tools, 4);
    EXPECT_EQ(r.voxelsPushed, 0u);
    EXPECT_EQ(r.massMoved, 0);
    EXPECT_EQ(r.voxelsTrapped, 1000u);
    EXPECT_EQ(r.massTrapped, 50 * 1000);
    EXPECT_EQ(a.totalMass(), m0);
    EXPECT_EQ(contentHash(*mass), h0);

    // A smaller tool: the clay it holds goes to the free part of the cavity.
    const std::vector<ShapePtr> small = {makeBox({{0, 0, 0}}, {{9, 4, 9}})};
    const PushReport s = push(a, small, 6);
    EXPECT_EQ(s.voxelsPushed, 500u);
    EXPECT_EQ(s.voxelsTrapped, 0u);
    EXPECT_EQ(clayInside(*mass, small), 0);
    EXPECT_EQ(a.totalMass(), m0);
    EXPECT_EQ(totalMass(*mass), m0);
    for (auto it = mass->tree().cbeginValueOn(); it; ++it)
        EXPECT_FALSE(obs->tree().isValueOn(it.getCoord()));
}

TEST_F(PushTest, NeverOverflowsATarget)
{
    // Cell (0,0,0) in a one-voxel tool; around it only (1,0,0), nearly full, and (2,0,0), empty.
    auto mass = openvdb::Int32Grid::create(0);
    mass->tree().setValue(Coord(0, 0, 0), 10);
    mass->tree().setValue(Coord(1, 0, 0), INT32_MAX - 5);
    auto obs = openvdb::MaskGrid::create(false);
    obs->tree().fill(CoordBBox(Coord(-3), Coord(3)), true, true);
    obs->tree().voxelizeActiveTiles();
    for (int x = 0; x <= 2; ++x)
        obs->tree().setValueOff(Coord(x, 0, 0));
    Automaton a(mass, opts(), obs);
    const PushReport r = push(a, {makeBox({{0, 0, 0}}, {{0, 0, 0}})}, 2);
    EXPECT_EQ(r.voxelsPushed, 1u);
    EXPECT_EQ(mass->tree().getValue(Coord(0, 0, 0)), 0);
    EXPECT_EQ(mass->tree().getValue(Coord(1, 0, 0)), INT32_MAX - 5);
    EXPECT_EQ(mass->tree().getValue(Coord(2, 0, 0)), 10);
    // With no room at all, the clay is trapped.
    mass->tree().setValue(Coord(2, 0, 0), INT32_MAX);
    mass->tree().setValue(Coord(0, 0, 0), 10);
    a.resync();
    const PushReport t = push(a, {makeBox({{0, 0, 0}}, {{0, 0, 0}})}, 2);
    EXPECT_EQ(t.voxelsTrapped, 1u);
    EXPECT_EQ(mass->tree().getValue(Coord(0, 0, 0)), 10);
}

TEST_F(PushTest, KeepsTheZeroLayerIn2D)
{
    auto mass = clayBox(CoordBBox(Coord(0, 0, 0), Coord(23, 23, 0)), 100);
    Automaton a(mass, opts(2));
    const int64_t m0 = a.totalMass();
    // A sphere centred off the plane: its normals have z components, which 2D ignores.
    const std::vector<ShapePtr> tools = {makeSphere({{11.3, 12.1, 2}}, 5.5)};
    const int64_t inside = clayInside(*mass, tools);
    ASSERT_GT(inside, 20);
    const PushReport r = push(a, tools);
    EXPECT_EQ(r.voxelsPushed, uint64_t(inside));
    EXPECT_EQ(r.voxelsTrapped, 0u);
    EXPECT_EQ(r.region.min[2], 0);
    EXPECT_EQ(r.region.max[2], 0);
    EXPECT_EQ(clayInside(*mass, tools), 0);
    for (auto it = mass->tree().cbeginValueOn(); it; ++it)
        EXPECT_EQ(it.getCoord().z(), 0);
    EXPECT_EQ(a.totalMass(), m0);
    const StepReport s = a.settle(100000);
    EXPECT_TRUE(s.settled);
    EXPECT_EQ(totalMass(*mass), m0);
}

TEST_F(PushTest, IsDeterministic)
{
    auto run = [](PushReport& rep) {
        auto mass = clayBox(CoordBBox(Coord(-5, 0, -3), Coord(14, 9, 12)), 80);
        mass->tree().setValue(Coord(3, 4, 5), 0);
        Automaton a(mass, opts());
        Pose pose;
        pose.rotationDeg = {{20, 35, 10}};
        pose.translation = {{2, 5, 4}};
        const std::vector<ShapePtr> tools = {
            makeTransformed(makeCylinder({{0, 0, 0}}, 3, 12, 0), pose),
            makeCapsule({{-6, 9, 0}}, {{6, 3, 9}}, 2.5),
        };
        rep = push(a, tools);
        return contentHash(*mass);
    };
    PushReport r1, r2;
    const uint64_t h1 = run(r1), h2 = run(r2);
    EXPECT_EQ(h1, h2);
    EXPECT_GT(r1.voxelsPushed, 0u);
    EXPECT_EQ(r1.voxelsPushed, r2.voxelsPushed);
    EXPECT_EQ(r1.massMoved, r2.massMoved);
}

// The targets are searched in parallel against the grid alone, then checked in source order against
// the clay planned before them: where that clay leaves no room, the source must search again.
TEST_F(PushTest, TargetsAreTheSameOnAnyThreadCountWhenRoomRunsOut)
{
    for (int threads : {1, 2, 3, 8}) {
        // Two sources (0,0,0) and (1,0,0) in a corridor walled by obstacles; (2,0,0) has room for one
        // source's clay only, (3,0,0) is empty.
        auto mass = openvdb::Int32Grid::create(0);
        mass->tree().setValue(Coord(0, 0, 0), 10);
        mass->tree().setValue(Coord(1, 0, 0), 10);
        mass->tree().setValue(Coord(2, 0, 0), INT32_MAX - 15);
        auto obs = openvdb::MaskGrid::create(false);
        obs->tree().fill(CoordBBox(Coord(-3), Coord(6)), true, true);
        obs->tree().voxelizeActiveTiles();
        for (int x = 0; x <= 3; ++x)
            obs->tree().setValueOff(Coord(x, 0, 0));
        AutomatonOptions o = opts();
        o.threads = threads;
        Automaton a(mass, o, obs);
        const PushReport r = push(a, {makeBox({{0, 0, 0}}, {{1, 0, 0}})}, 3);
        EXPECT_EQ(r.voxelsPushed, 2u) << threads;
        EXPECT_EQ(r.voxelsTrapped, 0u) << threads;
        EXPECT_EQ(mass->tree().getValue(Coord(0, 0, 0)), 0) << threads;
        EXPECT_EQ(mass->tree().getValue(Coord(1, 0, 0)), 0) << threads;
        EXPECT_EQ(mass->tree().getValue(Coord(2, 0, 0)), INT32_MAX - 5) << threads;
        EXPECT_EQ(mass->tree().getValue(Coord(3, 0, 0)), 10) << threads;
    }
    // A larger push (rotated cylinder and capsule in a box of clay, floods included): the same clay on
    // 1, 2, 3 and 8 threads.
    std::vector<uint64_t> hashes, pushed;
    for (int threads : {1, 2, 3, 8}) {
        auto mass = clayBox(CoordBBox(Coord(-5, 0, -3), Coord(14, 9, 12)), 80);
        AutomatonOptions o = opts();
        o.threads = threads;
        Automaton a(mass, o);
        Pose pose;
        pose.rotationDeg = {{20, 35, 10}};
        pose.translation = {{2, 5, 4}};
        const PushReport r = push(a, {makeTransformed(makeCylinder({{0, 0, 0}}, 3, 12, 0), pose),
                                      makeCapsule({{-6, 9, 0}}, {{6, 3, 9}}, 2.5)});
        hashes.push_back(contentHash(*mass));
        pushed.push_back(r.voxelsPushed);
    }
    EXPECT_GT(pushed[0], 100u);
    for (size_t i = 1; i < hashes.size(); ++i) {
        EXPECT_EQ(hashes[i], hashes[0]) << i;
        EXPECT_EQ(pushed[i], pushed[0]) << i;
    }
}

TEST_F(PushTest, FollowedBySettlingConservesMass)
{
    auto mass = clayBox(CoordBBox(Coord(0), Coord(11)), 100);
    auto obs = openvdb::MaskGrid::create(false);
    obs->tree().fill(CoordBBox(Coord(-20, -3, -20), Coord(30, -1, 30)), true, true); // a floor
    Automaton a(mass, opts(), obs);
    const int64_t m0 = a.totalMass();
    for (int frame = 0; frame < 3; ++frame) {
        const std::vector<ShapePtr> tools = {makeSphere({{6, 14.0 - 2 * frame, 6}}, 4)};
        push(a, tools);
        EXPECT_EQ(clayInside(*mass, tools), 0) << frame;
        EXPECT_EQ(a.totalMass(), m0);
        const StepReport s = a.settle(200000);
        EXPECT_TRUE(s.settled) << frame;
        EXPECT_EQ(totalMass(*mass), m0) << frame;
        EXPECT_EQ(a.totalMass(), m0) << frame;
    }
}

TEST_F(PushTest, ArgumentErrors)
{
    auto mass = clayBox(CoordBBox(Coord(0), Coord(3)), 10);
    Automaton a(mass, opts());
    const std::string negative = errorOf([&] { push(a, {makeSphere({{0, 0, 0}}, 2)}, -1); });
    EXPECT_NE(negative.find("maxSearch"), std::string::npos) << negative;
    EXPECT_NE(negative.find("-1"), std::string::npos) << negative;
    expectError([&] { push(a, {makeSphere({{0, 0, 0}}, 2), nullptr}); }, "tools[1]");
    const PushReport r = push(a, {});
    EXPECT_EQ(r.voxelsPushed, 0u);
    EXPECT_TRUE(r.region.empty());
}

TEST_F(PushTest, LeavesFarClayAlone)
{
    auto mass = clayBox(CoordBBox(Coord(0), Coord(7)), 10);
    mass->tree().setValue(Coord(1000, 1000, 1000), 33);
    Automaton a(mass, opts());
    const PushReport r = push(a, {makeSphere({{3, 3, 3}}, 2)}, 4);
    EXPECT_GT(r.voxelsPushed, 0u);
    EXPECT_EQ(mass->tree().getValue(Coord(1000, 1000, 1000)), 33);
    EXPECT_LT(r.region.max[0], 20);
    EXPECT_EQ(a.totalMass(), totalMass(*mass));
}

TEST_F(PushTest, NeverCrossesAThinWall)
{
    // Clay fills x = 0..4 (y, z = -3..3) against a one-voxel wall at x = 5. A sphere reaching the
    // wall pushes the clay at x = 4 towards +x: the march along the normal meets the wall at once
    // (and the next point, x = 6, lies beyond it); the clay must find room on the near side.
    auto mass = clayBox(CoordBBox(Coord(0, -3, -3), Coord(4, 3, 3)), 100);
    auto obs = openvdb::MaskGrid::create(false);
    obs->tree().fill(CoordBBox(Coord(5, -20, -20), Coord(5, 20, 20)), true, true);
    Automaton a(mass, opts(), obs);
    const int64_t m0 = a.totalMass();
    const std::vector<ShapePtr> tools = {makeSphere({{0, 0, 0}}, 4.6)};
    ASSERT_GT(clayInside(*mass, tools), 20);
    const PushReport r = push(a, tools);
    EXPECT_GT(r.voxelsPushed, 20u);
    EXPECT_EQ(r.voxelsTrapped, 0u);
    EXPECT_EQ(clayInside(*mass, tools), 0);
    EXPECT_EQ(totalMass(*mass), m0);
    for (auto it = mass->tree().cbeginValueOn(); it; ++it) {
        EXPECT_LT(it.getCoord().x(), 5) << "clay crossed the wall at " << it.getCoord();
    }
}
