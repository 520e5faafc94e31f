// The stages of a run outside the automaton, made parallel: the surface level set's fast sweeping by
// leaves (lib/src/SurfaceSweep.cc) against OpenVDB's own fogToSdf, and measureClay against a serial
// reference (the previous implementation): bit-identical results on 1, 2, 3 and 8 threads; clay
// shapes added into the scene's grid leaf by leaf.
#include "shapes/Rasterize.h"
#include "output/Surface.h"
#include "TestRng.h"

#include "vdbclay/Metrics.h"
#include "vdbclay/Scene.h"
#include "vdbclay/Sculpt.h"
#include "vdbclay/Types.h"

#include <gtest/gtest.h>

#include <openvdb/openvdb.h>
#include <openvdb/tools/FastSweeping.h>
#include <openvdb/tools/Morphology.h>

#include <tbb/global_control.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <memory>

using namespace vdbclay;
using openvdb::Coord;

namespace {

class SurfaceSweepTest : public ::testing::Test {
protected:
    static void SetUpTestSuite() { openvdb::initialize(); }
};

/// The fog the surface is swept over: the density of @a mass grown by 4 voxels, as surfaceLevelSet.
openvdb::FloatGrid::Ptr fogOf(const openvdb::Int32Grid& mass, double voxelSize = 1.0)
{
    auto fog = io_internal::densityGrid(mass, 1000, voxelSize);
    openvdb::tools::dilateActiveValues(fog->tree(), 4, openvdb::tools::NN_FACE_EDGE_VERTEX,
                                       openvdb::tools::IGNORE_TILES);
    return fog;
}

uint32_t bitsOf(float v)
{
    uint32_t b;
    std::memcpy(&b, &v, sizeof b);
    return b;
}

/// Every value (active or not, every leaf), the active states and the tiles of @a a and @a b agree
/// bit for bit; returns the number of active voxels compared.
uint64_t expectSameBits(const openvdb::FloatGrid& a, const openvdb::FloatGrid& b)
{
    EXPECT_EQ(a.tree().leafCount(), b.tree().leafCount());
    EXPECT_EQ(a.tree().activeVoxelCount(), b.tree().activeVoxelCount());
    EXPECT_EQ(bitsOf(a.tree().background()), bitsOf(b.tree().background()));
    uint64_t active = 0, mismatches = 0;
    auto bacc = b.getConstAccessor();
    for (auto it = a.tree().cbeginValueAll(); it; ++it) {
        const Coord c = it.getCoord();
        if (bitsOf(*it) != bitsOf(bacc.getValue(c)) || it.isValueOn() != bacc.isValueOn(c)) {
            if (++mismatches <= 5) {
                ADD_FAILURE() << "at " << c << ": " << *it << (it.isValueOn() ? " on" : " off") << " vs "
                              << bacc.getValue(c) << (bacc.isValueOn(c) ? " on" : " off");
            }
        }
        if (it.isValueOn()) ++active;
    }
    EXPECT_EQ(mismatches, 0u);
    return active;
}

void expectLikeOpenVdb(const openvdb::Int32Grid& mass, double voxelSize = 1.0)
{
    auto fog = fogOf(mass, voxelSize);
    auto expected = openvdb::tools::fogToSdf(*fog, 0.5f);
    for (int threads : {1, 2, 3, 8}) {
        tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
        auto got = io_internal::fogToSdfByLeaves(*fog, 0.5f);
        EXPECT_GT(expectSameBits(*expected, *got), 0u) << threads << " threads";
    }
}

/// surfaceLevelSet (the band's sweep) against OpenVDB's fogToSdf over the whole fog, clipped alike,
/// bit for bit, on 1, 2, 3 and 8 threads. Returns how many voxels the band's sweep updated, and in
/// @a all how many the whole fog's sweep does.
uint64_t expectBandLikeOpenVdb(const openvdb::Int32Grid& mass, double voxelSize, uint64_t& all)
{
    const float background = float(3 * voxelSize);
    auto expected = openvdb::tools::fogToSdf(*fogOf(mass, voxelSize), 0.5f);
    io_internal::clipToNarrowBand(*expected, background);
    auto density = io_internal::densityGrid(mass, 1000, voxelSize);
    uint64_t swept = 0;
    for (int threads : {1, 2, 3, 8}) {
        tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
        auto got = io_internal::surfaceLevelSet(*density, 0.5);
        expectSameBits(*expected, *got);
        EXPECT_EQ(got->tree().activeVoxelCount(), expected->tree().activeVoxelCount()) << threads;
        io_internal::narrowBandSdfFromDensity(*density, 4, 0.5f, background, &swept);
    }
    io_internal::narrowBandSdfFromDensity(*density, 4, 0.5f, 0.f, &all); // band 0: everything
    return swept;
}

} // namespace

TEST_F(SurfaceSweepTest, NarrowBandSweepsOnlyNearTheSurfaceAndMatchesTheWholeSweep)
{
    // A ball of radius 14 (full cells inside, a graded shell): its centre lies 14 voxels deep, past
    // the band's reach, so the band's sweep leaves the inside out and must still agree.
    auto ball = openvdb::Int32Grid::create(0);
    for (int x = -16; x <= 16; ++x)
        for (int y = -16; y <= 16; ++y)
            for (int z = -16; z <= 16; ++z) {
                const double r = std::sqrt(double(x * x + y * y + z * z));
                if (r <= 14.5)
                    ball->tree().setValue(Coord(x, y, z), r <= 13.5 ? 1000 : int32_t(1000 * (14.5 - r)));
            }
    for (double voxelSize : {1.0, 0.25, 7.5}) {
        uint64_t all = 0;
        const uint64_t swept = expectBandLikeOpenVdb(*ball, voxelSize, all);
        EXPECT_GT(swept, 0u) << voxelSize;
        EXPECT_LT(swept, all * 9 / 10) << voxelSize; // the inside beyond the band is not swept
    }

    // A box of clay pressed on top (uneven densities over a full core), across leaf boundaries.
    vdbclay_test::Rng rng(7);
    auto pressed = openvdb::Int32Grid::create(0);
    for (int x = -13; x <= 20; ++x)
        for (int y = 0; y <= 27; ++y)
            for (int z = -5; z <= 26; ++z)
                pressed->tree().setValue(Coord(x, y, z), y < 22 ? 1000 : rng.range(1, 1000));
    uint64_t all = 0;
    EXPECT_LT(expectBandLikeOpenVdb(*pressed, 1.0, all), all);

    // Clay thinner than the band (a slab one voxel thick, random sparse clay): nothing reaches the
    // band on the inside, so the whole fog is swept, as fogToSdf does.
    auto slab = openvdb::Int32Grid::create(0);
    slab->tree().fill(openvdb::CoordBBox(Coord(0, 0, 0), Coord(19, 19, 0)), 1000, true);
    slab->tree().voxelizeActiveTiles();
    EXPECT_EQ(expectBandLikeOpenVdb(*slab, 1.0, all), all);
    auto sparse = openvdb::Int32Grid::create(0);
    for (int i = 0; i < 6000; ++i)
        sparse->tree().setValue(Coord(rng.range(-14, 14), rng.range(-10, 20), rng.range(-14, 14)),
                                rng.range(1, 1000));
    expectBandLikeOpenVdb(*sparse, 1.0, all);

    // Clay holding a tile (a file may): the density holds a tile too, so the fog is grown and swept
    // by OpenVDB itself, and the band is still clipped alike.
    auto tiled = openvdb::Int32Grid::create(0);
    tiled->tree().addTile(1, Coord(0, 0, 0), 1000, true);
    tiled->tree().setValue(Coord(8, 3, 3), 700);
    tiled->tree().setValue(Coord(-1, 4, 2), 400);
    EXPECT_EQ(expectBandLikeOpenVdb(*tiled, 1.0, all), 0u); // no sweep of ours ran
}

TEST_F(SurfaceSweepTest, SurfaceFogIsOpenVdbsDilationBitForBit)
{
    // Clay of every kind (a ball, far lumps, a slab, random scattered cells with holes, across leaf
    // boundaries and negative coordinates), grown by every radius the flat masks handle.
    std::vector<openvdb::Int32Grid::Ptr> clays;
    auto ball = openvdb::Int32Grid::create(0);
    for (int x = -12; x <= 12; ++x)
        for (int y = -12; y <= 12; ++y)
            for (int z = -12; z <= 12; ++z)
                if (x * x + y * y + z * z <= 110) ball->tree().setValue(Coord(x, y, z), 900);
    clays.push_back(ball);
    auto lumps = openvdb::Int32Grid::create(0);
    for (int x = 0; x < 3; ++x)
        for (int y = 0; y < 3; ++y)
            for (int z = 0; z < 3; ++z) {
                lumps->tree().setValue(Coord(x + 6, y - 1, z + 7), 1000);
                lumps->tree().setValue(Coord(1000000 + x, y - 9, z - 17), 300);
            }
    clays.push_back(lumps);
    auto slab = openvdb::Int32Grid::create(0);
    slab->tree().fill(openvdb::CoordBBox(Coord(-9, 3, -9), Coord(19, 3, 12)), 1000, true);
    slab->tree().voxelizeActiveTiles();
    clays.push_back(slab);
    vdbclay_test::Rng rng(11);
    auto scattered = openvdb::Int32Grid::create(0);
    for (int i = 0; i < 400; ++i)
        scattered->tree().setValue(Coord(rng.range(-30, 30), rng.range(-30, 30), rng.range(-30, 30)),
                                   rng.range(1, 1000));
    clays.push_back(scattered);
    for (size_t c = 0; c < clays.size(); ++c) {
        auto density = io_internal::densityGrid(*clays[c], 1000, 0.5);
        for (int radius = 1; radius <= 7; ++radius) {
            auto expected = density->deepCopy();
            openvdb::tools::dilateActiveValues(expected->tree(), radius, openvdb::tools::NN_FACE_EDGE_VERTEX,
                                               openvdb::tools::IGNORE_TILES);
            for (int threads : {1, 3}) {
                tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
                auto got = io_internal::surfaceFog(*density, radius);
                SCOPED_TRACE("clay " + std::to_string(c) + ", radius " + std::to_string(radius));
                EXPECT_GT(expectSameBits(*expected, *got), 0u);
                EXPECT_EQ(got->transform(), density->transform());
                EXPECT_EQ(got->getName(), density->getName());
            }
        }
    }
}

TEST_F(SurfaceSweepTest, BallOfClayMatchesOpenVdbBitForBit)
{
    auto g = openvdb::Int32Grid::create(0);
    for (int x = -12; x <= 12; ++x)
        for (int y = -12; y <= 12; ++y)
            for (int z = -12; z <= 12; ++z) {
                const double r = std::sqrt(double(x * x + y * y + z * z));
                if (r <= 10.5)
                    g->tree().setValue(Coord(x, y, z), r <= 9.5 ? 1000 : int32_t(1000 * (10.5 - r)));
            }
    expectLikeOpenVdb(*g);
    expectLikeOpenVdb(*g, 0.25); // distances in world units
}

TEST_F(SurfaceSweepTest, BoxSlabAndFarLumpsMatchOpenVdb)
{
    auto box = openvdb::Int32Grid::create(0);
    box->tree().fill(openvdb::CoordBBox(Coord(-6), Coord(6)), 1000, true);
    box->tree().voxelizeActiveTiles();
    expectLikeOpenVdb(*box);

    auto slab = openvdb::Int32Grid::create(0); // 2D clay: one voxel thick
    slab->tree().fill(openvdb::CoordBBox(Coord(0, 0, 0), Coord(19, 19, 0)), 1000, true);
    slab->tree().voxelizeActiveTiles();
    expectLikeOpenVdb(*slab);

    auto lumps = openvdb::Int32Grid::create(0); // far apart, and one lump across leaf boundaries
    for (int x = 0; x < 4; ++x)
        for (int y = 0; y < 4; ++y)
            for (int z = 0; z < 4; ++z) {
                lumps->tree().setValue(Coord(x, y, z), 1000);
                lumps->tree().setValue(Coord(1000000 + x - 2, y - 2, z - 2), 700);
            }
    expectLikeOpenVdb(*lumps);
}

TEST_F(SurfaceSweepTest, RandomClayMatchesOpenVdb)
{
    // Cells of every density in a noisy blob with holes, crossing many leaves: every branch of the
    // Godunov update is taken.
    for (uint64_t seed = 1; seed <= 3; ++seed) {
        vdbclay_test::Rng rng(seed);
        auto g = openvdb::Int32Grid::create(0);
        for (int i = 0; i < 6000; ++i) {
            const Coord c(rng.range(-14, 14), rng.range(-10, 20), rng.range(-14, 14));
            g->tree().setValue(c, rng.range(1, 1000));
        }
        expectLikeOpenVdb(*g);
    }
}

TEST_F(SurfaceSweepTest, FogWithTilesGoesToOpenVdb)
{
    auto fog = openvdb::FloatGrid::create(0.f);
    fog->tree().addTile(1, Coord(0, 0, 0), 1.f, true); // an 8^3 tile of full density
    openvdb::tools::dilateActiveValues(fog->tree(), 2, openvdb::tools::NN_FACE_EDGE_VERTEX,
                                       openvdb::tools::EXPAND_TILES);
    auto expected = openvdb::tools::fogToSdf(*fog, 0.5f);
    auto got = io_internal::fogToSdfByLeaves(*fog, 0.5f);
    EXPECT_GT(expectSameBits(*expected, *got), 0u);
}

namespace {

/// measureClay as it was before it ran over leaves in parallel: one pass in tree order, the same
/// sums, the spread of the interior cells about their mean summed in the same order.
ClayMetrics serialMeasure(const openvdb::Int32Grid& mass, int32_t tc, const openvdb::MaskGrid* obstacles,
                          int dims)
{
    const Coord faces[6] = {Coord(1, 0, 0),  Coord(-1, 0, 0), Coord(0, 1, 0),
                            Coord(0, -1, 0), Coord(0, 0, 1),  Coord(0, 0, -1)};
    const int nf = dims == 3 ? 6 : 4;
    auto acc = mass.getConstAccessor();
    std::unique_ptr<openvdb::MaskGrid::ConstAccessor> oacc;
    if (obstacles) oacc = std::make_unique<openvdb::MaskGrid::ConstAccessor>(obstacles->getConstAccessor());
    auto interior = [&](const Coord& c) {
        if (dims == 2 && c.z() != 0) return false;
        if (oacc && oacc->isValueOn(c)) return false;
        for (int f = 0; f < nf; ++f)
            if (acc.getValue(c + faces[f]) == 0) return false;
        return true;
    };
    ClayMetrics r;
    int64_t interiorSum = 0;
    for (auto it = mass.tree().cbeginValueAll(); it; ++it) {
        const int32_t m = *it;
        if (m == 0) continue;
        const Coord c = it.getCoord();
        r.mass += m;
        r.maxCell = std::max(r.maxCell, m);
        ++r.clayVoxels;
        if (2 * int64_t(m) >= tc) ++r.occupiedVoxels;
        if (!(oacc && oacc->isValueOn(c)) && m > tc) r.residualOverload += int64_t(m) - tc;
        if (interior(c)) {
            ++r.interiorCells;
            interiorSum += m;
        }
    }
    if (r.mass > 0) r.compaction = double(r.clayVoxels) / double((r.mass + tc - 1) / tc);
    if (r.interiorCells == 0) return r;
    const double mean = double(interiorSum) / double(r.interiorCells);
    double squares = 0;
    for (auto it = mass.tree().cbeginValueAll(); it; ++it) {
        if (*it == 0 || !interior(it.getCoord())) continue;
        const double d = double(*it) - mean;
        squares += d * d;
    }
    r.interiorMeanDensity = mean / double(tc);
    r.heterogeneityCV = std::sqrt(squares / double(r.interiorCells)) / mean;
    return r;
}

void expectSameMetrics(const ClayMetrics& a, const ClayMetrics& b, const std::string& what)
{
    EXPECT_EQ(a.mass, b.mass) << what;
    EXPECT_EQ(a.residualOverload, b.residualOverload) << what;
    EXPECT_EQ(a.maxCell, b.maxCell) << what;
    EXPECT_EQ(a.clayVoxels, b.clayVoxels) << what;
    EXPECT_EQ(a.occupiedVoxels, b.occupiedVoxels) << what;
    EXPECT_EQ(a.interiorCells, b.interiorCells) << what;
    EXPECT_EQ(a.interiorMeanDensity, b.interiorMeanDensity) << what; // exact: the same bits
    EXPECT_EQ(a.heterogeneityCV, b.heterogeneityCV) << what;
    EXPECT_EQ(a.compaction, b.compaction) << what;
}

} // namespace

TEST_F(SurfaceSweepTest, MeasureClayOverLeavesIsTheSerialSumOnAnyThreadCount)
{
    for (int dims : {2, 3}) {
        vdbclay_test::Rng rng{uint64_t(dims)};
        auto g = openvdb::Int32Grid::create(0);
        // A dense block of uneven cells (many interior cells, spread across leaves) and scattered ones.
        for (int x = -20; x < 20; ++x)
            for (int y = -9; y < 30; ++y)
                for (int z = (dims == 3 ? -11 : 0); z < (dims == 3 ? 13 : 1); ++z)
                    g->tree().setValue(Coord(x, y, z), rng.range(1, 1700));
        for (int i = 0; i < 500; ++i)
            g->tree().setValue(
                Coord(rng.range(-200, 200), rng.range(-200, 200), dims == 3 ? rng.range(-200, 200) : 0),
                rng.range(1, 3000));
        auto obstacles = openvdb::MaskGrid::create(false);
        obstacles->tree().fill(openvdb::CoordBBox(Coord(-3, -3, -3), Coord(4, 40, 4)), true, true);
        const ClayMetrics expected = serialMeasure(*g, 1000, obstacles.get(), dims);
        EXPECT_GT(expected.interiorCells, 1000u);
        EXPECT_GT(expected.residualOverload, 0);
        for (int threads : {1, 2, 3, 8}) {
            tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
            expectSameMetrics(measureClay(*g, 1000, obstacles.get(), dims, threads), expected,
                              std::to_string(dims) + "D, " + std::to_string(threads) + " threads");
            expectSameMetrics(measureClay(*g, 1000, obstacles.get(), dims, 0), expected, "threads 0");
        }
    }
    auto tiled = openvdb::Int32Grid::create(0);
    tiled->tree().addTile(1, Coord(0, 0, 0), 5, true);
    EXPECT_THROW(measureClay(*tiled, 1000, nullptr, 3, 2), Error);
}

TEST_F(SurfaceSweepTest, OverlappingClayAddsLeafByLeafAndRefusesOverflow)
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
    try {
        Sculptor bad(over, 1);
        ADD_FAILURE() << "overflow not refused";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("overlapping clay at voxel (2, 2, 2) adds up to 4000000000"),
                  std::string::npos)
            << e.what();
    }
}

TEST_F(SurfaceSweepTest, RasterizeByLeavesSetsTheVoxelsOfTheVoxelLoopOnAnyThreadCount)
{
    // raster_internal::rasterizeInside (makeClay, the scene's obstacles) against forEachVoxelInside
    // through an accessor: the same voxels, values and leaves; into an empty tree and into one that
    // already holds leaves and a tile where the shape lies (those slots go voxel by voxel).
    Pose pose;
    pose.rotationDeg = {{20, 35, -10}};
    pose.translation = {{3.25, -1.5, 7}};
    pose.pivot = {{2, 2, 2}};
    const std::vector<ShapePtr> shapes = {
        makeSphere({{1.5, -2, 3}}, 13.3), makeBox({{-20, -3, -5}}, {{37, 4, 18}}),
        makeTransformed(makeBox({{-9, -4, -6}}, {{11, 5, 8}}), pose), makeCylinder({{0, 0, 0}}, 6.5, 30, 1)};
    for (int dims : {2, 3}) {
        for (size_t k = 0; k < shapes.size(); ++k) {
            const Shape& shape = *shapes[k];
            for (bool prefilled : {false, true}) {
                auto prefill = [&](openvdb::Int32Tree& t) {
                    if (!prefilled) return;
                    t.setValueOn(Coord(0, 0, 0), 7);           // a leaf the shape meets
                    t.setValueOn(Coord(-17, 2, 0), 9);         // another
                    t.addTile(1, Coord(8, 0, 0), 5, true);     // an active tile it meets
                    t.addTile(1, Coord(-8, -8, -8), 0, false); // an inactive tile
                };
                openvdb::Int32Tree expected(0);
                prefill(expected);
                uint64_t inside = 0;
                {
                    openvdb::tree::ValueAccessor<openvdb::Int32Tree> acc(expected);
                    forEachVoxelInside(shape, dims, [&](int32_t x, int32_t y, int32_t z) {
                        acc.setValueOn(Coord(x, y, z), 42);
                        ++inside;
                    });
                }
                ASSERT_GT(inside, 50u);
                for (int threads : {1, 2, 3, 8, 0}) {
                    tbb::global_control limit(tbb::global_control::max_allowed_parallelism,
                                              size_t(threads ? threads : 8));
                    openvdb::Int32Tree got(0);
                    prefill(got);
                    const std::string what = shape.describe() + ", " + std::to_string(dims) + "D, " +
                                             std::to_string(threads) + " threads" +
                                             (prefilled ? ", prefilled" : "");
                    EXPECT_EQ(raster_internal::rasterizeInside(got, shape, dims, 42, threads), inside)
                        << what;
                    EXPECT_EQ(got.leafCount(), expected.leafCount()) << what;
                    EXPECT_EQ(got.activeVoxelCount(), expected.activeVoxelCount()) << what;
                    EXPECT_EQ(got.activeTileCount(), expected.activeTileCount()) << what;
                    // every value, active or not, of both trees
                    for (auto it = expected.cbeginValueAll(); it; ++it) {
                        const Coord c = it.getCoord();
                        if (it.isVoxelValue()) {
                            ASSERT_EQ(got.getValue(c), *it) << what << " at " << c;
                            ASSERT_EQ(got.isValueOn(c), it.isValueOn()) << what << " at " << c;
                        }
                    }
                    for (auto it = got.cbeginValueOn(); it; ++it)
                        ASSERT_EQ(expected.getValue(it.getCoord()), *it) << what << " at " << it.getCoord();
                    // a mask tree (the obstacles) as well
                    openvdb::MaskTree mask(false);
                    raster_internal::rasterizeInside(mask, shape, dims, true, threads);
                    EXPECT_EQ(mask.activeVoxelCount(), inside) << what;
                }
            }
        }
    }
}
