// The tools' actions (vdbclay/Deposit.h, Scene "action"): add deposits clay into the free voxels a
// tool covers, remove takes the clay inside a tool away, both coverage-weighted at the boundary;
// every unit accounted for (mass_final = mass_initial + mass_added - mass_removed) on any thread
// count, in 2D and 3D, across a checkpoint; every malformed action field refused with its path.
#include <vdbclay/Automaton.h>
#include <vdbclay/Deposit.h>
#include <vdbclay/IO.h>
#include <vdbclay/MemoryEstimate.h>
#include <vdbclay/Metrics.h>
#include <vdbclay/RunReport.h>
#include <vdbclay/Scene.h>
#include <vdbclay/Sculpt.h>
#include <vdbclay/Shapes.h>

#include <openvdb/openvdb.h>

#include "shapes/Voxels.h"

#include "Builders.h"
#include "TempDirTest.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

using namespace vdbclay;
using openvdb::Coord;
using vdbclay_test::clayBox;
using vdbclay_test::expectError;

namespace {

class ToolsTest : public ::testing::Test {
protected:
    static void SetUpTestSuite() { openvdb::initialize(); }
};
using ToolsFileTest = vdbclay_test::TempDirTest;

AutomatonOptions options(int dims = 3, int threads = 1)
{
    return vdbclay_test::automatonOptions(Rule::Prorata, 1000, dims, threads);
}

Scene scene(const std::string& json)
{
    return parseScene(json, "s.json", "");
}

/// A 3D scene: a 24^3 box of clay at 800 on a floor, an add sphere laying a bead across its top,
/// a remove cylinder drilling down into it, a push plate pressing one side; 12 frames.
const char* kMixedScene = R"({
  "threshold": 1000, "rule": "prorata",
  "clay": [{"shape": "box", "min": [0,0,0], "max": [23,23,23], "mass": 800}],
  "tools": [
    {"shape": "sphere", "center": [-4,26.3,11.5], "radius": 2.6, "action": "add",
     "path": [{"translate": [2.5,0,0], "frames": 12}]},
    {"shape": "cylinder", "center": [6,30,6], "radius": 2.2, "height": 8, "axis": 1, "action": "remove",
     "path": [{"translate": [0,-1.5,0], "frames": 12}]},
    {"shape": "box", "min": [-6,0,14], "max": [-1,23,20], "path": [{"translate": [0.5,0,0], "frames": 12}]}
  ],
  "obstacles": [{"shape": "box", "min": [-40,-4,-40], "max": [60,-1,60]}],
  "settle": {"max_steps": 400}
})";

/// The same in 2D: a 48 x 24 slab at 800, a disc laying a bead, a disc carving a groove, a plate
/// pressing; 16 frames.
const char* kMixedScene2D = R"({
  "dimensions": 2, "threshold": 1000, "rule": "prorata",
  "clay": [{"shape": "box", "min": [0,0,0], "max": [47,23,0], "mass": 800}],
  "tools": [
    {"shape": "sphere", "center": [-4,26.2,0], "radius": 2.4, "action": "add", "path": [{"translate": [2,0,0], "frames": 16}]},
    {"shape": "sphere", "center": [30,27,0], "radius": 3, "action": "remove", "path": [{"translate": [0,-1,0], "frames": 16}]},
    {"shape": "box", "min": [-6,0,0], "max": [-1,20,0], "path": [{"translate": [0.5,0,0], "frames": 16}]}
  ],
  "obstacles": [{"shape": "box", "min": [-40,-4,0], "max": [80,-1,0]}],
  "settle": {"max_steps": 400}
})";

} // namespace

// ---- the scene's fields -------------------------------------------------------------------------

TEST_F(ToolsTest, ActionsParseWithTheirFieldsAndDefaults)
{
    const Scene s = scene(R"({"threshold": 700, "tools": [
        {"shape": "sphere", "center": [0,0,0], "radius": 2, "path": [{}]},
        {"shape": "sphere", "center": [0,0,0], "radius": 2, "path": [{}], "action": "push"},
        {"shape": "sphere", "center": [0,0,0], "radius": 2, "path": [{}], "action": "add"},
        {"shape": "sphere", "center": [0,0,0], "radius": 2, "path": [{}], "action": "add", "mass": 250},
        {"shape": "sphere", "center": [0,0,0], "radius": 2, "path": [{}], "action": "remove"},
        {"shape": "sphere", "center": [0,0,0], "radius": 2, "path": [{}], "action": "smooth", "strength": 0.25}]})");
    ASSERT_EQ(s.tools.size(), 6u);
    EXPECT_EQ(s.tools[0].action, ToolAction::Push);
    EXPECT_EQ(s.tools[1].action, ToolAction::Push);
    EXPECT_EQ(s.tools[2].action, ToolAction::Add);
    EXPECT_EQ(s.tools[2].mass, 700); // Tc
    EXPECT_EQ(s.tools[3].mass, 250);
    EXPECT_EQ(s.tools[4].action, ToolAction::Remove);
    EXPECT_EQ(s.tools[5].action, ToolAction::Smooth);
    EXPECT_DOUBLE_EQ(s.tools[5].strength, 0.25);
    EXPECT_STREQ(toolActionName(ToolAction::Remove), "remove");
    EXPECT_EQ(parseToolAction("smooth"), ToolAction::Smooth);
    EXPECT_TRUE(toolIsSolid(ToolAction::Push));
    EXPECT_TRUE(toolIsSolid(ToolAction::Remove));
    EXPECT_FALSE(toolIsSolid(ToolAction::Add));
    EXPECT_FALSE(toolIsSolid(ToolAction::Smooth));
}

TEST_F(ToolsTest, EveryBadActionFieldIsRefusedWithItsPath)
{
    const std::string pre =
        R"({"tools": [{"shape": "sphere", "center": [0,0,0], "radius": 2, "path": [{}], )";
    auto bad = [&](const std::string& fields, const std::string& needle) {
        expectError([&] { scene(pre + fields + "}]}"); }, needle);
        expectError([&] { scene(pre + fields + "}]}"); }, "s.json: tools[0].");
    };
    bad(R"("action": "carve")",
        "tools[0].action: unknown action \"carve\" (expected one of: push, add, remove, smooth)");
    bad(R"("action": 3)", "tools[0].action: expected a string");
    bad(R"("action": "")", "tools[0].action: expected a non-empty string");
    bad(R"("action": "add", "mass": -5)", "tools[0].mass: must be > 0, got -5");
    bad(R"("action": "add", "mass": 0)", "tools[0].mass: must be > 0, got 0");
    bad(R"("action": "add", "mass": 2.5)", "tools[0].mass: expected an integer, got 2.5");
    bad(R"("action": "add", "mass": 3000000000)", "tools[0].mass: exceeds the most clay a voxel holds");
    bad(R"("mass": 10)", "tools[0].mass: only an \"add\" tool has a mass (this tool's action is \"push\")");
    bad(R"("action": "remove", "mass": 10)", "tools[0].mass: only an \"add\" tool has a mass");
    bad(R"("action": "smooth", "strength": 0)", "tools[0].strength: must lie in (0, 1], got 0");
    bad(R"("action": "smooth", "strength": 1.5)", "tools[0].strength: must lie in (0, 1], got 1.5");
    bad(R"("action": "smooth", "strength": "high")", "tools[0].strength: expected a number");
    bad(R"("action": "add", "strength": 0.5)",
        "tools[0].strength: only a \"smooth\" tool has a strength (this tool's action is \"add\")");
    // Obstacles and clay take no action.
    expectError(
        [&] {
            scene(R"({"obstacles": [{"shape": "sphere", "center": [0,0,0], "radius": 2, "action": "add"}]})");
        },
        "s.json: obstacles[0].action: unknown field");
    expectError(
        [&] {
            scene(
                R"({"clay": [{"shape": "sphere", "center": [0,0,0], "radius": 2, "mass": 5, "action": "add"}]})");
        },
        "s.json: clay[0].action: unknown field");
}

// ---- remove and add, exactly --------------------------------------------------------------------

TEST_F(ToolsTest, RemovingABoxFromABoxLeavesExactlyTheDifference)
{
    auto clay = clayBox(Coord(0, 0, 0), Coord(15, 15, 15), 1000);
    Automaton a(clay, options());
    const DepositReport r = carve(a, *makeBox({{4, 6, -3}}, {{11, 20, 9}}));
    EXPECT_EQ(r.mass, int64_t(8 * 10 * 10) * 1000);
    EXPECT_EQ(r.voxels, uint64_t(8 * 10 * 10));
    EXPECT_EQ(a.totalMass(), int64_t(16 * 16 * 16 - 8 * 10 * 10) * 1000);
    auto acc = a.mass()->getConstAccessor();
    for (int x = -2; x <= 17; ++x)
        for (int y = -2; y <= 17; ++y)
            for (int z = -2; z <= 17; ++z) {
                const bool inClay = x >= 0 && x <= 15 && y >= 0 && y <= 15 && z >= 0 && z <= 15;
                const bool inTool = x >= 4 && x <= 11 && y >= 6 && y <= 20 && z >= -3 && z <= 9;
                ASSERT_EQ(acc.getValue(Coord(x, y, z)), inClay && !inTool ? 1000 : 0)
                    << x << " " << y << " " << z;
                ASSERT_EQ(acc.isValueOn(Coord(x, y, z)), inClay && !inTool);
            }
    // A second carve finds nothing: nothing written.
    EXPECT_EQ(carve(a, *makeBox({{4, 6, -3}}, {{11, 20, 9}})).voxels, 0u);
}

TEST_F(ToolsTest, RemoveTakesABoundaryVoxelInProportionToCoverage)
{
    // A box whose faces (half a voxel outside min and max: x = 2.75 and 8.25) cover three quarters of
    // voxels x = 3 and x = 8: those keep a quarter of 800.
    auto clay = clayBox(Coord(0, 0, 0), Coord(11, 3, 3), 800);
    Automaton a(clay, options());
    const DepositReport r = carve(a, *makeBox({{3.25, -2, -2}}, {{7.75, 6, 6}}));
    auto acc = a.mass()->getConstAccessor();
    EXPECT_EQ(acc.getValue(Coord(2, 1, 1)), 800);
    EXPECT_EQ(acc.getValue(Coord(3, 1, 1)), 200);
    EXPECT_EQ(acc.getValue(Coord(5, 1, 1)), 0);
    EXPECT_EQ(acc.getValue(Coord(8, 1, 1)), 200);
    EXPECT_EQ(acc.getValue(Coord(9, 1, 1)), 800);
    EXPECT_EQ(r.mass, int64_t(16) * (600 + 600 + 4 * 800));
    EXPECT_EQ(a.totalMass(), int64_t(12 * 16) * 800 - r.mass);
}

TEST_F(ToolsTest, AddingASphereIntoEmptySpaceHoldsItsCoverageWeightedMass)
{
    for (const int dims : {3, 2}) {
        Automaton a(openvdb::Int32Grid::create(0), options(dims));
        const ShapePtr ball = makeSphere({{0.3, -0.2, dims == 2 ? 0.0 : 0.1}}, 6.3);
        const DepositReport r = deposit(a, *ball, 1000);
        // Exactly the coverage makeClay gives a volume-keeping shape, voxel by voxel.
        int64_t expected = 0;
        uint64_t voxels = 0;
        auto acc = a.mass()->getConstAccessor();
        shapes_internal::forEachVoxelCovered(*ball, dims, [&](int32_t x, int32_t y, int32_t z, double f) {
            const int64_t m = std::llround(1000.0 * f);
            EXPECT_EQ(acc.getValue(Coord(x, y, z)), m) << x << " " << y << " " << z;
            expected += m;
            voxels += m > 0;
        });
        EXPECT_EQ(r.mass, expected);
        EXPECT_EQ(r.voxels, voxels);
        EXPECT_EQ(a.totalMass(), expected);
        EXPECT_EQ(totalMass(*a.mass()), expected);
        // The ball's volume (area in 2D) within the coverage's error (docs/INTEROP.md, "Coverage").
        const double exact = dims == 3 ? 4.0 / 3.0 * M_PI * std::pow(6.3, 3) * 1000 : M_PI * 6.3 * 6.3 * 1000;
        EXPECT_NEAR(double(expected) / exact, 1.0, dims == 3 ? 0.002 : 0.01) << dims;
        // A second deposit of the same tool adds nothing (the voxels hold their share already).
        EXPECT_EQ(deposit(a, *ball, 1000).mass, 0);
        // A larger mass per voxel tops up to it.
        EXPECT_GT(deposit(a, *ball, 1500).mass, expected / 3);
    }
}

TEST_F(ToolsTest, AddNeverWritesIntoObstaclesOrSolidToolsAndKeepsFullerClay)
{
    auto obstacles = openvdb::MaskGrid::create(false);
    obstacles->tree().fill(openvdb::CoordBBox(Coord(-10, -10, -10), Coord(10, -3, 10)), true, true);
    obstacles->tree().voxelizeActiveTiles();
    auto clay = clayBox(Coord(2, 2, 2), Coord(3, 3, 3), 1700); // over Tc: kept
    Automaton a(clay, options(), obstacles);
    const ShapePtr solid = makeBox({{-10, -10, 5}}, {{10, 10, 10}});
    const DepositReport r = deposit(a, *makeSphere({{0, 0, 0}}, 7.0), 1000, {solid});
    EXPECT_GT(r.mass, 0);
    auto acc = a.mass()->getConstAccessor();
    EXPECT_EQ(acc.getValue(Coord(0, 0, 0)), 1000);
    EXPECT_EQ(acc.getValue(Coord(2, 2, 2)), 1700);
    for (int x = -8; x <= 8; ++x)
        for (int y = -8; y <= 8; ++y)
            for (int z = -8; z <= 8; ++z) {
                if (y <= -3 || z >= 5) {
                    ASSERT_EQ(acc.getValue(Coord(x, y, z)), 0) << x << " " << y << " " << z;
                }
            }
    EXPECT_EQ(a.totalMass(), int64_t(8) * 1700 + r.mass);
    expectError([&] { deposit(a, *makeSphere({{0, 0, 0}}, 2.0), 0); }, "mass per voxel must be > 0");
}

// ---- whole runs: every unit accounted for --------------------------------------------------------

TEST_F(ToolsTest, MixedToolsAccountForEveryUnitOnAnyThreadCount)
{
    for (const Scene& s : {scene(kMixedScene), scene(kMixedScene2D)}) {
        uint64_t hash0 = 0;
        int64_t added0 = 0, removed0 = 0;
        for (const int threads : {1, 2, 3, 8}) {
            Sculptor sc(s, threads);
            int64_t framesAdded = 0, framesRemoved = 0;
            const RunSummary r = sc.run(0, [&](const FrameReport& f) {
                framesAdded += f.massAdded;
                framesRemoved += f.massRemoved;
            });
            EXPECT_EQ(r.massInitial,
                      s.dimensions == 3 ? int64_t(24 * 24 * 24) * 800 : int64_t(48 * 24) * 800);
            EXPECT_GT(r.massAdded, 0);
            EXPECT_GT(r.massRemoved, 0);
            EXPECT_EQ(r.massAdded, framesAdded);
            EXPECT_EQ(r.massRemoved, framesRemoved);
            EXPECT_EQ(r.massFinal, r.massInitial + r.massAdded - r.massRemoved);
            EXPECT_EQ(r.massDrift, 0);
            EXPECT_EQ(sc.massAdded(), r.massAdded);
            EXPECT_EQ(sc.massRemoved(), r.massRemoved);
            EXPECT_EQ(totalMass(*sc.mass()), r.massFinal);
            const uint64_t hash = contentHash(*sc.mass());
            if (threads == 1) {
                hash0 = hash;
                added0 = r.massAdded;
                removed0 = r.massRemoved;
            } else {
                EXPECT_EQ(hash, hash0) << threads;
                EXPECT_EQ(r.massAdded, added0) << threads;
                EXPECT_EQ(r.massRemoved, removed0) << threads;
            }
            // The run's report carries the counts.
            const std::string json = runReportJson(makeRunReport(sc, r, threads));
            EXPECT_NE(json.find("\"mass_added\": " + std::to_string(r.massAdded)), std::string::npos);
            EXPECT_NE(json.find("\"mass_removed\": " + std::to_string(r.massRemoved)), std::string::npos);
            EXPECT_NE(json.find("\"mass_drift\": 0"), std::string::npos);
        }
    }
}

TEST_F(ToolsTest, AMovingAddToolLaysABeadAlongItsPath)
{
    for (const int dims : {3, 2}) {
        // A ball of radius 1.7 moving 3 voxels a frame over a floor: with "sweep" every x it passed
        // holds clay; its cells are no obstacle, and the bead (at most Tc a voxel) stays as laid.
        const std::string json = std::string(R"({"dimensions": )") + std::to_string(dims) +
                                 R"(, "threshold": 1000, "sweep": true,
            "tools": [{"shape": "sphere", "center": [0,2,0], "radius": 1.7, "action": "add",
                       "path": [{"translate": [3,0,0], "frames": 10}]}],
            "obstacles": [{"shape": "box", "min": [-10,-3,-5], "max": [50,0,5]}]})";
        MassGridPtr out;
        const RunSummary r = vdbclay_test::runSceneJson(json, nullptr, &out, 2);
        EXPECT_EQ(r.massInitial, 0);
        EXPECT_GT(r.massAdded, 0);
        EXPECT_EQ(r.massFinal, r.massAdded);
        EXPECT_EQ(r.massDrift, 0);
        EXPECT_TRUE(r.settled);
        auto acc = out->getConstAccessor();
        for (int x = 0; x <= 30; ++x)
            EXPECT_EQ(acc.getValue(Coord(x, 2, 0)), 1000) << dims << " x " << x;
        EXPECT_EQ(acc.getValue(Coord(33, 2, 0)), 0);
        EXPECT_EQ(acc.getValue(Coord(15, 0, 0)), 0); // the floor
    }
}

TEST_F(ToolsFileTest, ACheckpointKeepsTheCountsAndTheResumedRunEndsAsTheUnbrokenOne)
{
    const Scene s = scene(kMixedScene);
    Sculptor whole(s, 2);
    const RunSummary all = whole.run();
    ASSERT_EQ(all.frames, 12u);

    Sculptor first(s, 2);
    const RunSummary a = first.run(5);
    ASSERT_EQ(first.frame(), 5u);
    const ClayMeta meta = first.checkpointMeta();
    EXPECT_EQ(meta.massAdded, a.massAdded);
    EXPECT_EQ(meta.massRemoved, a.massRemoved);
    writeClayFile(file("five.vdb"), *first.mass(), meta);
    const ClayFile back = readClayFile(file("five.vdb"));
    EXPECT_EQ(back.meta.massAdded, a.massAdded);
    EXPECT_EQ(back.meta.massRemoved, a.massRemoved);

    std::string json = kMixedScene;
    json.replace(json.find("\"clay\""), json.find("\"tools\"") - json.find("\"clay\""),
                 "\"start\": \"five.vdb\",\n  ");
    const Scene rest = parseScene(json, file("s.json"), dir);
    Sculptor second(rest, 3);
    const RunSummary b = second.run();
    EXPECT_EQ(b.frames, 7u);
    EXPECT_EQ(contentHash(*second.mass()), contentHash(*whole.mass()));
    EXPECT_EQ(second.massAdded(), whole.massAdded());
    EXPECT_EQ(second.massRemoved(), whole.massRemoved());
    EXPECT_EQ(a.massAdded + b.massAdded, all.massAdded);
    EXPECT_EQ(a.massRemoved + b.massRemoved, all.massRemoved);
    EXPECT_EQ(b.massDrift, 0);
    EXPECT_EQ(second.checkpointMeta().massAdded, whole.checkpointMeta().massAdded);
    EXPECT_EQ(second.automaton().stepCount(), whole.automaton().stepCount());
}

TEST_F(ToolsTest, TheMemoryEstimateCoversTheClayAnAddToolCreates)
{
    // A bead laid in empty space (no clay at the start), one into a slab, one at 3 Tc that spreads,
    // and the study scene: the estimate's leaves and clay bytes cover what the run built.
    const std::string bead =
        R"("tools": [{"shape": "sphere", "center": [0,20,0], "radius": 3, "action": "add",
        "path": [{"translate": [2,0,1], "frames": 20}]}])";
    const std::vector<std::string> scenes = {
        "{" + bead + "}",
        R"({"clay": [{"shape": "box", "min": [-8,0,-8], "max": [40,17,30], "mass": 1000}], )" + bead + "}",
        R"({"tools": [{"shape": "sphere", "center": [0,20,0], "radius": 3, "action": "add", "mass": 3000,
            "path": [{"translate": [2,0,1], "frames": 20}]}]})",
    };
    for (const std::string& json : scenes) {
        const Scene s = scene(json);
        const MemoryEstimate e = estimateSceneMemory(s);
        Sculptor sc(s, 2);
        const RunSummary r = sc.run();
        EXPECT_GT(r.massAdded, 0) << json;
        EXPECT_GE(e.clayLeavesGrown, uint64_t(sc.mass()->tree().leafCount())) << json;
        EXPECT_GE(e.clayBytes, uint64_t(sc.mass()->memUsage())) << json;
    }
    const Scene study = vdbclay_test::loadTestScene("studies/add-bead.json");
    const MemoryEstimate e = estimateSceneMemory(study);
    Sculptor sc(study, 2);
    sc.run();
    EXPECT_GE(e.clayLeavesGrown, uint64_t(sc.mass()->tree().leafCount()));
    EXPECT_GE(e.clayBytes, uint64_t(sc.mass()->memUsage()));
}

TEST_F(ToolsTest, ARemoveToolPushesNothingAndItsCellsAreSolid)
{
    // A drill going down into a block: every frame it takes clay, none is pushed, and the clay
    // settles around it (its cells are obstacles: no clay flows back into the hole while it is there).
    const Scene s = scene(R"({"threshold": 1000, "rule": "prorata",
        "clay": [{"shape": "box", "min": [0,0,0], "max": [15,15,15], "mass": 1000}],
        "tools": [{"shape": "cylinder", "center": [8,20,8], "radius": 3, "height": 8, "axis": 1, "action": "remove",
                   "path": [{"translate": [0,-2,0], "frames": 8}]}]})");
    Sculptor sc(s, 2);
    uint64_t frames = 0;
    const RunSummary r = sc.run(0, [&](const FrameReport& f) {
        ++frames;
        EXPECT_EQ(f.push.voxelsPushed, 0u) << f.frame;
        EXPECT_EQ(f.push.massMoved, 0) << f.frame;
    });
    EXPECT_EQ(frames, 8u);
    EXPECT_GT(r.massRemoved, 0);
    EXPECT_EQ(r.massDrift, 0);
    // The drill's axis, below the top and above its tip (y = 20 - 16 - 4 = 0): emptied.
    auto acc = sc.mass()->getConstAccessor();
    for (int y = 1; y <= 15; ++y)
        EXPECT_EQ(acc.getValue(Coord(8, y, 8)), 0) << y;
}

TEST_F(ToolsTest, AnAddIntoFullClayIsAnOverloadTheGlobalLayerMovesOut)
{
    // A slab at Tc on a floor, global transport; a ball adding 3000 a voxel dips into its top: the
    // clay it adds over Tc is moved by the layer out to the free surface, every unit accounted for,
    // no cell left over Tc, the same clay on any thread count.
    const char* json = R"({
      "threshold": 1000, "rule": "prorata", "transport": "global",
      "clay": [{"shape": "box", "min": [0,0,0], "max": [31,7,31], "mass": 1000}],
      "tools": [{"shape": "sphere", "center": [16,10,16], "radius": 3, "action": "add", "mass": 3000,
                 "path": [{"translate": [0,-2,0], "frames": 1}, {"translate": [0,0,0], "frames": 1}]}],
      "obstacles": [{"shape": "box", "min": [-8,-3,-8], "max": [40,-1,40]}],
      "settle": {"max_steps": 100000}
    })";
    uint64_t hash0 = 0;
    for (const int threads : {1, 2, 3, 8}) {
        std::vector<FrameReport> frames;
        MassGridPtr out;
        const RunSummary r = vdbclay_test::runSceneJson(json, &frames, &out, threads);
        EXPECT_EQ(r.massInitial, int64_t(32 * 8 * 32) * 1000);
        EXPECT_GT(r.massAdded, 0);
        EXPECT_EQ(r.massFinal, r.massInitial + r.massAdded);
        EXPECT_EQ(totalMass(*out), r.massFinal);
        EXPECT_EQ(r.massDrift, 0);
        EXPECT_TRUE(r.settled);
        EXPECT_EQ(residualOverload(*out, 1000, nullptr), 0);
        ASSERT_FALSE(frames.empty());
        EXPECT_GT(frames[0].transport.massMoved, 0) << "the layer moved the added overload";
        EXPECT_GT(r.transportSolves, 0u);
        // The added clay ends at most Tc a voxel: the layer and the automaton took it out to room.
        const ClayMetrics m = measureClay(*out, 1000, nullptr, 3);
        EXPECT_LE(m.maxCell, 1000);
        const uint64_t hash = contentHash(*out);
        if (threads == 1)
            hash0 = hash;
        else
            EXPECT_EQ(hash, hash0) << threads;
    }
}
