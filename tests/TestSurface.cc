// The surface level set written with the clay (lib/src/output/Surface.h): the fog grown by the
// flat masks against OpenVDB's dilateActiveValues, the fast sweeping by leaves against OpenVDB's own
// fogToSdf, and the narrow band's sweep against the whole fog's, bit for bit on 1, 2, 3 and 8
// threads.
#include "output/Surface.h"
#include "TestRng.h"

#include "vdbclay/Types.h"

#include <gtest/gtest.h>

#include <openvdb/openvdb.h>
#include <openvdb/tools/FastSweeping.h>
#include <openvdb/tools/Morphology.h>

#include <tbb/global_control.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

using namespace vdbclay;
using openvdb::Coord;

namespace {

class SurfaceTest : public ::testing::Test {
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

TEST_F(SurfaceTest, NarrowBandSweepsOnlyNearTheSurfaceAndMatchesTheWholeSweep)
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
}

namespace {

/// The narrow bands @a got (from a density with tiles) and @a expected (from the same clay in
/// leaves) agree: the same active voxels with the same bits, and every other value (voxels and
/// tiles, each side's) of the same sign and magnitude (+-band: outside or inside).
void expectSameBand(const openvdb::FloatGrid& expected, const openvdb::FloatGrid& got)
{
    EXPECT_EQ(got.tree().activeVoxelCount(), expected.tree().activeVoxelCount());
    EXPECT_EQ(bitsOf(got.tree().background()), bitsOf(expected.tree().background()));
    uint64_t mismatches = 0;
    auto check = [&](const openvdb::FloatGrid& a, const openvdb::FloatGrid& b) {
        auto bacc = b.getConstAccessor();
        for (auto it = a.tree().cbeginValueAll(); it; ++it) {
            openvdb::CoordBBox bb;
            it.getBoundingBox(bb);
            for (const Coord& c : std::vector<Coord>{bb.min(), bb.max(),
                                                     Coord((bb.min().x() + bb.max().x()) / 2,
                                                           (bb.min().y() + bb.max().y()) / 2,
                                                           (bb.min().z() + bb.max().z()) / 2)}) {
                const bool same = it.isValueOn()
                                      ? (bacc.isValueOn(c) && bitsOf(*it) == bitsOf(bacc.getValue(c)))
                                      : (!bacc.isValueOn(c) && *it == bacc.getValue(c));
                if (!same && ++mismatches <= 5) {
                    ADD_FAILURE() << "at " << c << ": " << *it << (it.isValueOn() ? " on" : " off") << " vs "
                                  << bacc.getValue(c) << (bacc.isValueOn(c) ? " on" : " off");
                }
            }
        }
    };
    check(expected, got);
    check(got, expected);
    EXPECT_EQ(mismatches, 0u);
}

/// surfaceLevelSet of @a mass (holding tiles) against that of the same clay in leaves, on 1, 2, 3
/// and 8 threads; returns the voxels the tiled band's sweep updated.
uint64_t expectTiledBandLikeLeaves(const openvdb::Int32Grid& mass)
{
    auto leaves = mass.deepCopy();
    leaves->tree().voxelizeActiveTiles();
    auto expected = io_internal::surfaceLevelSet(*io_internal::densityGrid(*leaves, 1000, 1.0), 0.5);
    auto density = io_internal::densityGrid(mass, 1000, 1.0);
    EXPECT_TRUE(io_internal::holdsTiles(density->tree()));
    uint64_t swept = 0;
    for (int threads : {1, 2, 3, 8}) {
        tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
        expectSameBand(*expected, *io_internal::surfaceLevelSet(*density, 0.5));
        io_internal::narrowBandSdfFromDensity(*density, 4, 0.5f, 3.f, &swept);
    }
    return swept;
}

} // namespace

TEST_F(SurfaceTest, TheBandOfClayHeldAsTilesIsThatOfItsVoxels)
{
    // A tile beside voxels (a file may hold one).
    auto small = openvdb::Int32Grid::create(0);
    small->tree().addTile(1, Coord(0, 0, 0), 1000, true);
    small->tree().setValue(Coord(8, 3, 3), 700);
    small->tree().setValue(Coord(-1, 4, 2), 400);
    EXPECT_GT(expectTiledBandLikeLeaves(*small), 0u);

    // A large block of full clay (a 128^3 tile and 8^3 tiles, faces on slot boundaries: the surface
    // runs between tiles and empty space), a block of thin clay below the isovalue beside it, a block
    // at the isovalue, a graded shell of leaves on part of it and a cavity.
    auto block = openvdb::Int32Grid::create(0);
    block->tree().fill(openvdb::CoordBBox(Coord(0, 0, 0), Coord(135, 127, 143)), 1000, true);
    block->tree().fill(openvdb::CoordBBox(Coord(136, 0, 0), Coord(167, 31, 31)), 300, true);
    block->tree().fill(openvdb::CoordBBox(Coord(-32, 0, 0), Coord(-1, 15, 15)), 500, true);
    for (int x = 20; x < 60; ++x)
        for (int z = 30; z < 70; ++z)
            for (int y = 128; y < 131; ++y)
                block->tree().setValue(Coord(x, y, z), 1000 - 300 * (y - 128));
    block->tree().fill(openvdb::CoordBBox(Coord(60, 60, 60), Coord(70, 66, 75)), 0, false);
    const uint64_t swept = expectTiledBandLikeLeaves(*block);
    EXPECT_GT(swept, 0u);
    EXPECT_LT(swept, 8 * 136ull * 128 * 144 / 10); // 8 sweeps, each of under a tenth of the block
}

TEST_F(SurfaceTest, SurfaceFogIsOpenVdbsDilationBitForBit)
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

TEST_F(SurfaceTest, BallOfClayMatchesOpenVdbBitForBit)
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

TEST_F(SurfaceTest, BoxSlabAndFarLumpsMatchOpenVdb)
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

TEST_F(SurfaceTest, RandomClayMatchesOpenVdb)
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

TEST_F(SurfaceTest, FogWithTilesGoesToOpenVdb)
{
    auto fog = openvdb::FloatGrid::create(0.f);
    fog->tree().addTile(1, Coord(0, 0, 0), 1.f, true); // an 8^3 tile of full density
    openvdb::tools::dilateActiveValues(fog->tree(), 2, openvdb::tools::NN_FACE_EDGE_VERTEX,
                                       openvdb::tools::EXPAND_TILES);
    auto expected = openvdb::tools::fogToSdf(*fog, 0.5f);
    auto got = io_internal::fogToSdfByLeaves(*fog, 0.5f);
    EXPECT_GT(expectSameBits(*expected, *got), 0u);
}

TEST_F(SurfaceTest, LeavesFullToTheirFacesOnTheBackgroundMatchOpenVdb)
{
    // Leaves whose every value lies over the isovalue, with no leaf beside some of their faces: the
    // voxels on those faces lie next to the isosurface (the background across them is outside), as
    // next to a leaf under it.
    auto fog = openvdb::FloatGrid::create(0.f);
    fog->tree().fill(openvdb::CoordBBox(Coord(0), Coord(7)), 1.f, true);                  // one leaf, alone
    fog->tree().fill(openvdb::CoordBBox(Coord(64, 0, 0), Coord(79, 7, 7)), 1.f, true);    // two, side by side
    fog->tree().fill(openvdb::CoordBBox(Coord(64, 8, 0), Coord(71, 15, 7)), 0.25f, true); // one under
    fog->tree().voxelizeActiveTiles();
    auto expected = openvdb::tools::fogToSdf(*fog, 0.5f);
    for (int threads : {1, 2}) {
        tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
        auto got = io_internal::fogToSdfByLeaves(*fog, 0.5f);
        EXPECT_GT(expectSameBits(*expected, *got), 0u) << threads << " threads";
    }
}
