// The surface level set's fast sweeping by leaves (lib/src/SurfaceSweep.cc) against OpenVDB's own
// fogToSdf: bit-identical values and topology on clay of several shapes, on 1, 2, 3 and 8 threads.
#include "Surface.h"
#include "TestRng.h"

#include <gtest/gtest.h>

#include <openvdb/openvdb.h>
#include <openvdb/tools/FastSweeping.h>
#include <openvdb/tools/Morphology.h>

#include <tbb/global_control.h>

#include <cmath>
#include <cstdint>
#include <cstring>

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

} // namespace

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
