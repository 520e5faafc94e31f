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
using vdbclay_test::allClay;
using vdbclay_test::kAllRules;
using vdbclay_test::loadTestScene;
using vdbclay_test::runScene;

namespace {

class PushTest : public ::testing::Test {
protected:
    static void SetUpTestSuite() { openvdb::initialize(); }
};

/// The scene data/scenes/test/@a name, run with @a rule.
Scene withRule(const std::string& name, Rule rule)
{
    Scene s = loadTestScene("test/" + name);
    s.rule.rule = rule;
    return s;
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
        RunSummary s = runScene(withRule("sphere-through-sheet.json", rule), nullptr, &clay);
        EXPECT_EQ(s.massDrift, 0) << name;
        EXPECT_TRUE(s.settled) << name;
        auto acc = clay->getConstAccessor();
        for (int x = 6; x <= 9; ++x)
            for (int z = 6; z <= 9; ++z)
                EXPECT_EQ(acc.getValue(Coord(x, 0, z)), 0) << name << " " << x << "," << z;

        const MassGridPtr before = makeClay(*makeBox({{0, 0, 0}}, {{15, 0, 15}}), 100, 3);
        s = runScene(withRule("box-jumps-over-sheet.json", rule), nullptr, &clay);
        EXPECT_EQ(contentHash(*clay), contentHash(*before)) << name << ": the jump went through the sheet";
        EXPECT_EQ(s.steps, 0u) << name;

        std::vector<FrameReport> frames;
        s = runScene(withRule("box-into-cube-6-per-frame.json", rule), &frames, &clay);
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
