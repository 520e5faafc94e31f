// Uniform clay as tiles (lib/src/automaton/Tiles.h): the automaton on a grid holding tiles gives the
// clay, voxel for voxel, of the same grid in leaves, step by step, on any thread count; tiles are
// densified only where a block that can change reads them, collapse back deterministically, and the
// metrics read them as their voxels.
#include <vdbclay/Automaton.h>
#include <vdbclay/Metrics.h>
#include <vdbclay/Scene.h>
#include <vdbclay/Sculpt.h>
#include <vdbclay/Shapes.h>

#include "Builders.h"
#include "automaton/Tiles.h"
#include "shapes/Voxels.h"

#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include <string>
#include <vector>

using namespace vdbclay;
using openvdb::Coord;
using openvdb::CoordBBox;

namespace {

const Rule kAll[] = {Rule::Arata, Rule::Bingham, Rule::Sorted, Rule::Prorata};

class TilesTest : public ::testing::Test {
protected:
    static void SetUpTestSuite() { openvdb::initialize(); }
};

constexpr int32_t kTc = 1000;

AutomatonOptions options(Rule r, int threads, int32_t tc = kTc)
{
    AutomatonOptions o;
    o.dimensions = 3;
    o.rule.rule = r;
    o.rule.threshold = tc;
    o.rule.alpha = 0.3;
    o.seed = 7;
    o.threads = threads;
    return o;
}

uint64_t tileCount(const openvdb::Int32Tree& tree)
{
    uint64_t n = 0;
    auto it = tree.cbeginValueOn();
    it.setMaxDepth(it.getLeafDepth() - 1);
    for (; it; ++it)
        if (*it != 0) ++n;
    return n;
}

/// A lump of clay: a 128^3 block at Tc (one level-2 tile) beside a 64^3 block at 0.5 Tc (level-1
/// tiles), a leaf-sized pocket of over cells inside the full block touching both, a thin layer of
/// over cells on top of the loose block, and an obstacle slab through part of the loose block. As
/// tiles where fill() makes them, leaves elsewhere.
openvdb::Int32Grid::Ptr tiledLump()
{
    auto g = openvdb::Int32Grid::create(0);
    g->setName("mass");
    auto& t = g->tree();
    t.fill(CoordBBox(Coord(0, 0, 0), Coord(127, 127, 127)), kTc, true);
    t.fill(CoordBBox(Coord(128, 0, 0), Coord(191, 63, 63)), kTc / 2, true);
    for (int x = 120; x < 136; ++x)
        for (int y = 40; y < 44; ++y)
            for (int z = 40; z < 46; ++z)
                t.setValueOn(Coord(x, y, z), 3 * kTc + x + y + z);
    for (int x = 130; x < 180; ++x)
        for (int z = 10; z < 50; ++z)
            t.setValueOn(Coord(x, 64, z), 2 * kTc + 17);
    return g;
}

openvdb::MaskGrid::Ptr slabObstacle()
{
    auto m = openvdb::MaskGrid::create(false);
    m->tree().fill(CoordBBox(Coord(150, 20, 0), Coord(151, 63, 63)), true, true);
    m->tree().setValueOff(Coord(150, 30, 30)); // a hole
    m->tree().setValueOff(Coord(151, 30, 30));
    return m;
}

openvdb::Int32Grid::Ptr voxelized(const openvdb::Int32Grid& g)
{
    auto d = g.deepCopy();
    d->tree().voxelizeActiveTiles();
    return d;
}

TEST_F(TilesTest, AutomatonOnTilesMatchesLeavesStepByStepOnAnyThreadCount)
{
    for (Rule rule : kAll) {
        auto denseGrid = voxelized(*tiledLump());
        Automaton dense(denseGrid, options(rule, 1), slabObstacle());
        ASSERT_EQ(tileCount(denseGrid->tree()), 0u);
        std::vector<uint64_t> hashes;
        std::vector<uint64_t> updated;
        for (int i = 0; i < 40; ++i) {
            updated.push_back(dense.step().blocksUpdated);
            hashes.push_back(contentHash(*denseGrid));
        }
        for (int threads : {1, 2, 3, 8}) {
            const std::string what =
                std::string(ruleName(rule)) + ", " + std::to_string(threads) + " threads";
            auto grid = tiledLump();
            Automaton tiled(grid, options(rule, threads), slabObstacle());
            EXPECT_EQ(tiled.totalMass(), dense.totalMass()) << what;
            EXPECT_GT(tileCount(grid->tree()), 0u) << what;
            for (int i = 0; i < 40; ++i) {
                const StepReport r = tiled.step();
                ASSERT_EQ(r.blocksUpdated, updated[size_t(i)]) << what << ", step " << i;
                ASSERT_EQ(contentHash(*grid), hashes[size_t(i)]) << what << ", step " << i;
            }
            EXPECT_EQ(tiled.residualOverload(), dense.residualOverload()) << what;
            EXPECT_EQ(totalMass(*grid), dense.totalMass()) << what;
            // Only the leaves near the moving clay were made: the 128^3 tile's inside stays a tile.
            EXPECT_GT(tileCount(grid->tree()), 0u) << what;
            EXPECT_LT(grid->tree().leafCount(), denseGrid->tree().leafCount() / 4) << what;
        }
    }
}

TEST_F(TilesTest, CollapsedLeavesKeepTheClayAndTheRunGoesOnIdentically)
{
    auto denseGrid = voxelized(*tiledLump());
    Automaton dense(denseGrid, options(Rule::Prorata, 1), slabObstacle());
    auto grid = tiledLump();
    Automaton tiled(grid, options(Rule::Prorata, 2), slabObstacle());
    for (int round = 0; round < 4; ++round) {
        dense.run(25);
        tiled.run(25);
        const uint64_t hash = contentHash(*grid);
        const uint64_t leaves = grid->tree().leafCount();
        const uint64_t removed = tiled.collapseUniformLeaves();
        EXPECT_EQ(grid->tree().leafCount(), leaves - removed);
        EXPECT_EQ(contentHash(*grid), hash);
        ASSERT_EQ(contentHash(*grid), contentHash(*denseGrid)) << "round " << round;
        EXPECT_EQ(tiled.residualOverload(), dense.residualOverload());
    }
    // A uniform leaf becomes a tile, and a uniform node a tile of its parent.
    auto g = openvdb::Int32Grid::create(0);
    g->tree().fill(CoordBBox(Coord(0, 0, 0), Coord(127, 127, 127)), kTc, true);
    g->tree().voxelizeActiveTiles();
    g->tree().setValueOn(Coord(200, 0, 0), kTc + 5); // over Tc: never a tile
    ASSERT_EQ(g->tree().leafCount(), 4097u);
    EXPECT_EQ(automaton_internal::collapseUniformLeaves(g->tree(), kTc), 4096u);
    EXPECT_EQ(g->tree().leafCount(), 1u);
    EXPECT_EQ(tileCount(g->tree()), 1u); // one 128^3 tile
    EXPECT_EQ(totalMass(*g), int64_t(kTc) * 128 * 128 * 128 + kTc + 5);
}

TEST_F(TilesTest, AFramesCollapseOfTheRegionsItWroteLeavesTheTreeOfTheWholeWalk)
{
    // After every frame (the Sculptor collapses only what the frame wrote: edits, setMasses, densify,
    // the steps' changed blocks), a collapse of the whole tree finds nothing more to do: the same
    // tree, node for node. Scenes with steps (the paper's push), the global layer at Tc on tiles, add
    // and remove tools, smoothing and the scene's surface tension.
    std::vector<Scene> scenes;
    scenes.push_back(parseScene(R"({"dimensions": 3, "threshold": 1000, "rule": "prorata", "seed": 1,
        "push": "compress", "transport": "global",
        "clay": [{"shape": "sphere", "center": [40, 40, 40], "radius": 40, "mass": 1000}],
        "tools": [{"shape": "sphere", "center": [40, 86, 40], "radius": 6,
                   "path": [{"translate": [0, -9, 0], "frames": 1}, {"translate": [2, 0, 0], "frames": 5}]}]})",
                                "stroke.json", ""));
    for (const char* name :
         {"test/sphere-through-sheet.json", "studies/add-bead.json", "studies/remove-hole.json",
          "studies/smooth-bumps.json", "studies/surface-tension.json"})
        scenes.push_back(vdbclay_test::loadTestScene(name));
    uint64_t tilesSeen = 0;
    for (Scene& scene : scenes) {
        if (scene.frames > 6) scene.frames = 6;
        Sculptor sc(scene, 2);
        sc.run(0, [&](const FrameReport& f) {
            auto whole = sc.mass()->deepCopy();
            const auto nodes = whole->tree().nodeCount();
            const uint64_t tiles = tileCount(whole->tree());
            EXPECT_EQ(automaton_internal::collapseUniformLeaves(whole->tree(), scene.rule.threshold), 0u)
                << scene.source << ", frame " << f.frame;
            EXPECT_EQ(whole->tree().nodeCount(), nodes) << scene.source << ", frame " << f.frame;
            EXPECT_EQ(tileCount(whole->tree()), tiles) << scene.source << ", frame " << f.frame;
            tilesSeen += tiles;
        });
    }
    EXPECT_GT(tilesSeen, 0u); // clay held as tiles between frames: the check is not vacuous

    // A leaf that steps alone make uniform, among 511 that stay mixed (one cell under Tc in each):
    // Tc everywhere but one cell over and one under, in one block. The collapse after the steps finds
    // it (the steps' changed blocks are recorded).
    auto g = openvdb::Int32Grid::create(0);
    g->tree().fill(CoordBBox(Coord(0, 0, 0), Coord(63, 63, 63)), kTc, true);
    g->tree().voxelizeActiveTiles();
    for (int x = 0; x < 64; x += 8)
        for (int y = 0; y < 64; y += 8)
            for (int z = 0; z < 64; z += 8)
                if (x + y + z > 0) g->tree().setValueOn(Coord(x + 7, y + 7, z + 7), kTc - 1);
    g->tree().setValueOn(Coord(2, 2, 2), kTc + 1);
    g->tree().setValueOn(Coord(3, 2, 2), kTc - 1);
    Automaton a(g, options(Rule::Prorata, 1));
    EXPECT_EQ(a.collapseUniformLeaves(), 0u);
    a.settle(100, 0);
    ASSERT_EQ(a.residualOverload(), 0);
    EXPECT_EQ(a.collapseUniformLeaves(), 1u);
    EXPECT_EQ(g->tree().leafCount(), 511u);
}

TEST_F(TilesTest, EditsAndDensifyTurnOnlyTheRegionsTilesIntoLeaves)
{
    auto box = [] {
        auto g = openvdb::Int32Grid::create(0);
        g->tree().fill(CoordBBox(Coord(0, 0, 0), Coord(255, 127, 127)), kTc, true);
        return g;
    };
    auto grid = box();
    auto denseGrid = voxelized(*box());
    Automaton a(grid, options(Rule::Sorted, 2));
    Automaton dense(denseGrid, options(Rule::Sorted, 1));
    EXPECT_EQ(grid->tree().leafCount(), 0u);
    a.densify(Box{{{10, 10, 10}}, {{20, 12, 12}}});
    EXPECT_EQ(grid->tree().leafCount(), 2u); // slots x 8 and 16
    EXPECT_EQ(a.totalMass(), int64_t(kTc) * 256 * 128 * 128);
    auto poke = [](MassGrid& g) { g.tree().setValueOn(Coord(100, 100, 100), 3 * kTc); };
    a.edit(Box{{{100, 100, 100}}, {{100, 100, 100}}}, poke);
    dense.edit(Box{{{100, 100, 100}}, {{100, 100, 100}}}, poke);
    EXPECT_EQ(grid->tree().leafCount(), 3u);
    EXPECT_EQ(a.totalMass(), int64_t(kTc) * 256 * 128 * 128 + 2 * kTc);
    EXPECT_EQ(a.residualOverload(), 2 * kTc);
    for (int i = 0; i < 4; ++i) {
        a.run(50);
        dense.run(50);
        ASSERT_EQ(contentHash(*grid), contentHash(*denseGrid)) << "after " << 50 * (i + 1) << " steps";
        EXPECT_EQ(a.residualOverload(), dense.residualOverload());
    }
    // Leaves only where the overload wandered (the 2^22 voxels fill 8192 leaves).
    EXPECT_LT(grid->tree().leafCount(), 8192u / 4);
    EXPECT_EQ(totalMass(*grid), a.totalMass());
}

TEST_F(TilesTest, TilesOverTcAreVoxelizedAndBadTilesRefused)
{
    auto over = openvdb::Int32Grid::create(0);
    over->tree().fill(CoordBBox(Coord(0, 0, 0), Coord(15, 7, 7)), kTc + 1, true);
    over->tree().setValueOn(Coord(16, 0, 0), 1);
    Automaton a(over, options(Rule::Prorata, 1));
    EXPECT_EQ(tileCount(over->tree()), 0u);
    EXPECT_EQ(a.residualOverload(), 16 * 8 * 8);
    a.settle(10000, 0);
    EXPECT_EQ(a.residualOverload(), 0);
    EXPECT_EQ(a.totalMass(), int64_t(kTc + 1) * 16 * 8 * 8 + 1);

    auto flat = openvdb::Int32Grid::create(0);
    flat->tree().fill(CoordBBox(Coord(0, 0, 0), Coord(7, 7, 7)), 5, true);
    AutomatonOptions o2 = options(Rule::Prorata, 1);
    o2.dimensions = 2;
    try {
        Automaton b(flat, o2);
        FAIL() << "a tile of clay in 2D was accepted";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("2D clay must lie in the z = 0 layer, but tile"),
                  std::string::npos)
            << e.what();
    }
    auto negative = openvdb::Int32Grid::create(0);
    negative->tree().fill(CoordBBox(Coord(0, 0, 0), Coord(7, 7, 7)), -5, true);
    EXPECT_THROW(Automaton(negative, options(Rule::Prorata, 1)), Error);
    auto inactive = openvdb::Int32Grid::create(0);
    inactive->tree().fill(CoordBBox(Coord(0, 0, 0), Coord(7, 7, 7)), 5, false);
    EXPECT_THROW(Automaton(inactive, options(Rule::Prorata, 1)), Error);
}

TEST_F(TilesTest, TheContentHashOfTilesAnywhereIsThatOfTheirVoxels)
{
    // Tiles of 8^3 and 128^3 on both sides of zero on every axis, of several values: the hash's sums
    // over tiles (in AVX-512 where the CPU has it) against the voxel-by-voxel sums over leaves.
    auto g = openvdb::Int32Grid::create(0);
    g->tree().fill(CoordBBox(Coord(-128, -128, -128), Coord(-1, -1, -1)), kTc, true);
    g->tree().fill(CoordBBox(Coord(-24, 0, -8), Coord(15, 23, 7)), 7, true);
    g->tree().fill(CoordBBox(Coord(8, -16, 128), Coord(23, -1, 255)), kTc + 3, true);
    g->tree().fill(CoordBBox(Coord(1 << 20, -(1 << 20), 0), Coord((1 << 20) + 7, -(1 << 20) + 7, 7)), 1,
                   true);
    ASSERT_GE(tileCount(g->tree()), 4u);
    auto dense = voxelized(*g);
    ASSERT_EQ(tileCount(dense->tree()), 0u);
    EXPECT_EQ(contentHash(*g), contentHash(*dense));
    EXPECT_EQ(clayVoxelCount(*g), clayVoxelCount(*dense));
}

TEST_F(TilesTest, MetricsReadTilesAsTheirVoxels)
{
    auto grid = tiledLump();
    auto dense = voxelized(*grid);
    ASSERT_GT(tileCount(grid->tree()), 0u);
    EXPECT_EQ(contentHash(*grid), contentHash(*dense));
    EXPECT_EQ(totalMass(*grid), totalMass(*dense));
    EXPECT_EQ(clayVoxelCount(*grid), clayVoxelCount(*dense));
    EXPECT_EQ(residualOverload(*grid, kTc, nullptr), residualOverload(*dense, kTc, nullptr));
    auto obstacles = slabObstacle();
    for (int threads : {1, 2, 3}) {
        for (const openvdb::MaskGrid* obs : std::vector<const openvdb::MaskGrid*>{nullptr, obstacles.get()}) {
            const ClayMetrics a = measureClay(*grid, kTc, obs, 3, threads);
            const ClayMetrics b = measureClay(*dense, kTc, obs, 3, threads);
            EXPECT_EQ(a.mass, b.mass);
            EXPECT_EQ(a.residualOverload, b.residualOverload);
            EXPECT_EQ(a.maxCell, b.maxCell);
            EXPECT_EQ(a.clayVoxels, b.clayVoxels);
            EXPECT_EQ(a.occupiedVoxels, b.occupiedVoxels);
            EXPECT_EQ(a.interiorCells, b.interiorCells);
            EXPECT_EQ(a.interiorMeanDensity, b.interiorMeanDensity); // exact sums: the same bits
            EXPECT_EQ(a.heterogeneityCV, b.heterogeneityCV);
            EXPECT_EQ(a.compaction, b.compaction);
        }
    }
    // A tile over Tc counts its voxels' overload, less its obstacles.
    auto over = openvdb::Int32Grid::create(0);
    over->tree().fill(CoordBBox(Coord(0, 0, 0), Coord(7, 7, 7)), kTc + 3, true);
    auto one = openvdb::MaskGrid::create(false);
    one->tree().setValueOn(Coord(1, 2, 3));
    EXPECT_EQ(residualOverload(*over, kTc, one.get()), 3 * 511);
}

TEST_F(TilesTest, ConvexShapesAreRasterisedAsTilesWithTheSameVoxels)
{
    const std::vector<ShapePtr> shapes = {
        makeSphere({{40.3, 41.7, 39.2}}, 37.6),
        makeBox({{-20, 3, 5}}, {{70, 60, 90}}),
        makeCylinder({{10, 10, 10}}, 30, 50, 2),
        makeCapsule({{0, 0, 0}}, {{60, 30, 20}}, 19.5),
        makeTransformed(makeBox({{-30, -30, -30}}, {{30, 30, 30}}),
                        Pose{{{2, 3, -1}}, {{20, 35, 10}}, {{0, 0, 0}}}),
        makePlaced(makeSphere({{0, 0, 0}}, 25),
                   Placement{{{3, 1, 2}}, {{10, 20, 30}}, {{1.3, 0.9, 1.1}}, {{0, 0, 0}}}),
    };
    for (const ShapePtr& s : shapes) {
        auto clay = makeClay(*s, kTc, 3);
        EXPECT_GT(tileCount(clay->tree()), 0u) << s->describe();
        auto reference = openvdb::Int32Grid::create(0);
        shapes_internal::forEachVoxelInside(*s, 3, [&](int32_t x, int32_t y, int32_t z) {
            reference->tree().setValueOn(Coord(x, y, z), kTc);
        });
        EXPECT_EQ(contentHash(*clay), contentHash(*reference)) << s->describe();
        EXPECT_EQ(totalMass(*clay), totalMass(*reference)) << s->describe();
        EXPECT_LT(clay->tree().leafCount(), reference->tree().leafCount()) << s->describe();
    }
}

} // namespace
