// The clay's metrics (vdbclay/Metrics.h): measureClay and compareShapes on hand-built grids, with
// exact expectations, and measureClay over leaves in parallel against a serial reference, bit for bit
// on any thread count.
#include <vdbclay/IO.h>
#include <vdbclay/Metrics.h>
#include <vdbclay/Shapes.h>

#include <openvdb/openvdb.h>

#include <tbb/global_control.h>

#include "Builders.h"
#include "TestRng.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <climits>
#include <cmath>
#include <cstdint>
#include <memory>
#include <random>
#include <string>
#include <vector>

using namespace vdbclay;
using openvdb::Coord;
using openvdb::CoordBBox;
using vdbclay_test::clayBox;
using vdbclay_test::expectError;

namespace {

class MetricsTest : public ::testing::Test {
protected:
    static void SetUpTestSuite() { openvdb::initialize(); }
};

} // namespace

// ---- measureClay --------------------------------------------------------------------------------

TEST_F(MetricsTest, FullCubeOfThreeHasOneInteriorCellNoSpreadAndIsCompact)
{
    const auto g = clayBox(Coord(0, 0, 0), Coord(2, 2, 2), 100);
    const ClayMetrics m = measureClay(*g, 100, nullptr, 3);
    EXPECT_EQ(m.mass, 2700);
    EXPECT_EQ(m.residualOverload, 0);
    EXPECT_EQ(m.maxCell, 100);
    EXPECT_EQ(m.clayVoxels, 27u);
    EXPECT_EQ(m.occupiedVoxels, 27u);
    EXPECT_EQ(m.interiorCells, 1u);
    EXPECT_EQ(m.interiorMeanDensity, 1.0);
    EXPECT_EQ(m.heterogeneityCV, 0.0);
    EXPECT_EQ(m.compaction, 1.0);
}

TEST_F(MetricsTest, InteriorIn2DUsesTheFourNeighboursInTheZ0Layer)
{
    const auto g = clayBox(Coord(0, 0, 0), Coord(3, 2, 0), 7); // 4 x 3 square
    const ClayMetrics m = measureClay(*g, 10, nullptr, 2);
    EXPECT_EQ(m.interiorCells, 2u); // (1,1) and (2,1)
    EXPECT_EQ(m.clayVoxels, 12u);
    // 84 units in cells of 10: at least 9 cells; 12 used.
    EXPECT_EQ(m.compaction, 12.0 / 9.0);
    // The same square read as 3D has no interior cell (nothing above or below).
    EXPECT_EQ(measureClay(*g, 10, nullptr, 3).interiorCells, 0u);
}

TEST_F(MetricsTest, HeterogeneityIsTheCoefficientOfVariationOverInteriorCells)
{
    // 3 x 3 x 4: interior cells (1,1,1) and (1,1,2). They hold 60 and 100: mean 80, sd 20, CV 1/4.
    auto g = clayBox(Coord(0, 0, 0), Coord(2, 2, 3), 100);
    g->tree().setValue(Coord(1, 1, 1), 60);
    // A surface cell's value does not enter the CV.
    g->tree().setValue(Coord(0, 0, 0), 1);
    const ClayMetrics m = measureClay(*g, 100, nullptr, 3);
    EXPECT_EQ(m.interiorCells, 2u);
    EXPECT_EQ(m.interiorMeanDensity, 0.8);
    EXPECT_EQ(m.heterogeneityCV, 0.25);
    EXPECT_EQ(m.mass, 34 * 100 + 60 + 1);
    // 3461 units: at least 35 cells; 36 used.
    EXPECT_EQ(m.compaction, 36.0 / 35.0);
    EXPECT_EQ(m.occupiedVoxels, 35u); // (0,0,0) holds 1 < Tc / 2
}

TEST_F(MetricsTest, OverloadCompactionAndOccupancyAtTheHalfThreshold)
{
    // Eight cells of Tc / 2 = 50: occupied (2 m >= Tc), 400 units fit in 4 cells: compaction 2.
    auto g = clayBox(Coord(0, 0, 0), Coord(1, 1, 1), 50);
    ClayMetrics m = measureClay(*g, 100, nullptr, 3);
    EXPECT_EQ(m.occupiedVoxels, 8u);
    EXPECT_EQ(m.compaction, 2.0);
    EXPECT_EQ(m.interiorCells, 0u);
    EXPECT_EQ(m.heterogeneityCV, 0.0);
    // Odd Tc: 2 x 50 = 100 < 101, not occupied.
    EXPECT_EQ(measureClay(*g, 101, nullptr, 3).occupiedVoxels, 0u);
    // Everything in one cell: 400 at Tc 100 is 300 over; 1 cell against 4: compaction 1/4.
    auto one = clayBox(Coord(5, 5, 5), Coord(5, 5, 5), 400);
    m = measureClay(*one, 100, nullptr, 3);
    EXPECT_EQ(m.residualOverload, 300);
    EXPECT_EQ(m.maxCell, 400);
    EXPECT_EQ(m.compaction, 0.25);
}

TEST_F(MetricsTest, ObstacleCellsAreNeverInteriorAndCarryNoOverload)
{
    auto g = clayBox(Coord(0, 0, 0), Coord(2, 2, 2), 100);
    g->tree().setValue(Coord(1, 1, 1), 500);
    g->tree().setValue(Coord(0, 0, 0), 300);
    auto obs = openvdb::MaskGrid::create(false);
    obs->tree().setValueOn(Coord(1, 1, 1));
    const ClayMetrics m = measureClay(*g, 100, obs.get(), 3);
    EXPECT_EQ(m.interiorCells, 0u);
    EXPECT_EQ(m.residualOverload, 200); // (0,0,0) only; (1,1,1) is an obstacle
    EXPECT_EQ(m.mass, 25 * 100 + 500 + 300);
    EXPECT_EQ(measureClay(*g, 100, nullptr, 3).residualOverload, 600);
}

TEST_F(MetricsTest, EmptyGridMeasuresZeroAndBadArgumentsAreRefused)
{
    auto g = openvdb::Int32Grid::create(0);
    const ClayMetrics m = measureClay(*g, 100, nullptr, 3);
    EXPECT_EQ(m.mass, 0);
    EXPECT_EQ(m.clayVoxels, 0u);
    EXPECT_EQ(m.compaction, 0.0);
    EXPECT_EQ(m.heterogeneityCV, 0.0);
    expectError([&] { measureClay(*g, 0, nullptr, 3); }, "threshold Tc must be > 0");
    expectError([&] { measureClay(*g, 100, nullptr, 4); }, "dimensions must be 2 or 3");
}

// ---- compareShapes ------------------------------------------------------------------------------

TEST_F(MetricsTest, IdenticalShapesHaveIoUOneAndNoSurfaceDistance)
{
    const auto a = clayBox(Coord(0, 0, 0), Coord(3, 3, 3), 100);
    const ShapeError e = compareShapes(*a, 100, *a, 100, 3);
    EXPECT_EQ(e.iou, 1.0);
    EXPECT_EQ(e.intersection, 64u);
    EXPECT_EQ(e.claySurface, 56u); // 64 - the 2^3 inside
    EXPECT_EQ(e.meanSurfaceDistance, 0.0);
    EXPECT_EQ(e.maxSurfaceDistance, 0.0);
    // The same box as an analytic shape, rasterised on the voxels.
    const ShapeError s = compareShapes(*a, 100, *makeBox({{0, 0, 0}}, {{3, 3, 3}}), 3);
    EXPECT_EQ(s.iou, 1.0);
    EXPECT_EQ(s.meanSurfaceDistance, 0.0);
    // Clay made from a sphere matches the sphere exactly.
    const ShapePtr ball = makeSphere({{0.3, -1.2, 2.5}}, 6.4);
    const MassGridPtr clay = makeClay(*ball, 100, 3);
    EXPECT_EQ(compareShapes(*clay, 100, *ball, 3).iou, 1.0);
}

TEST_F(MetricsTest, OffsetBoxesHaveIoUOneThird)
{
    // 4^3 boxes two voxels apart along x: 32 shared voxels of 96.
    const auto a = clayBox(Coord(0, 0, 0), Coord(3, 3, 3), 100);
    const auto b = clayBox(Coord(2, 0, 0), Coord(5, 3, 3), 100);
    const ShapeError e = compareShapes(*a, 100, *b, 100, 3);
    EXPECT_EQ(e.intersection, 32u);
    EXPECT_EQ(e.unionVoxels, 96u);
    EXPECT_EQ(e.iou, 1.0 / 3.0);
    EXPECT_EQ(compareShapes(*a, 100, *makeBox({{2, 0, 0}}, {{5, 3, 3}}), 3).iou, 1.0 / 3.0);
    // 2D: 4 x 4 squares two apart, 8 shared of 24; clay outside z = 0 does not count.
    auto a2 = clayBox(Coord(0, 0, 0), Coord(3, 3, 0), 100);
    a2->tree().setValue(Coord(0, 0, 5), 100);
    const auto b2 = clayBox(Coord(2, 0, 0), Coord(5, 3, 0), 100);
    const ShapeError e2 = compareShapes(*a2, 100, *b2, 100, 2);
    EXPECT_EQ(e2.unionVoxels, 24u);
    EXPECT_EQ(e2.iou, 1.0 / 3.0);
}

TEST_F(MetricsTest, OccupancyIsDensityAtLeastOneHalfOnEachSide)
{
    auto a = clayBox(Coord(0, 0, 0), Coord(1, 0, 0), 50); // 2 voxels at Tc / 2
    a->tree().setValue(Coord(2, 0, 0), 49);               // under half: not occupied
    const auto b = clayBox(Coord(0, 0, 0), Coord(2, 0, 0), 1000);
    ShapeError e = compareShapes(*a, 100, *b, 1000, 3);
    EXPECT_EQ(e.clayVoxels, 2u);
    EXPECT_EQ(e.referenceVoxels, 3u);
    EXPECT_EQ(e.iou, 2.0 / 3.0);
    // The reference's own threshold decides its occupancy: at Tc 2001, 1000 is under half.
    e = compareShapes(*a, 100, *b, 2001, 3);
    EXPECT_EQ(e.referenceVoxels, 0u);
    EXPECT_EQ(e.iou, 0.0);
    EXPECT_TRUE(std::isinf(e.meanSurfaceDistance));
}

TEST_F(MetricsTest, MeanSurfaceDistanceIsSymmetricAndExactOnHandCases)
{
    // Two single voxels (3, 4, 0) apart: each its own surface, 5 away from the other.
    const auto p = clayBox(Coord(0, 0, 0), Coord(0, 0, 0), 10);
    const auto q = clayBox(Coord(3, 4, 0), Coord(3, 4, 0), 10);
    ShapeError e = compareShapes(*p, 10, *q, 10, 3);
    EXPECT_EQ(e.iou, 0.0);
    EXPECT_EQ(e.meanSurfaceDistance, 5.0);
    EXPECT_EQ(e.maxSurfaceDistance, 5.0);

    // A 4^3 box against the same box one voxel longer in x (5 x 4 x 4). The box's 56 surface
    // voxels all lie on the longer box's surface except the 4 in the middle of its x = 3 face
    // (1 away from x = 4); of the longer box's 68, the 16 at x = 4 are 1 away from x = 3 and
    // the rest are on the box's surface. Mean: (4 + 16) / (56 + 68) = 5 / 31.
    const auto a = clayBox(Coord(0, 0, 0), Coord(3, 3, 3), 10);
    const auto b = clayBox(Coord(0, 0, 0), Coord(4, 3, 3), 10);
    e = compareShapes(*a, 10, *b, 10, 3);
    EXPECT_EQ(e.claySurface, 56u);
    EXPECT_EQ(e.referenceSurface, 68u);
    EXPECT_DOUBLE_EQ(e.meanSurfaceDistance, 5.0 / 31.0);
    EXPECT_EQ(e.maxSurfaceDistance, 1.0);
    EXPECT_EQ(e.iou, 64.0 / 80.0);
    // Symmetric: swapping the two gives the same distances.
    const ShapeError r = compareShapes(*b, 10, *a, 10, 3);
    EXPECT_EQ(r.meanSurfaceDistance, e.meanSurfaceDistance);
    EXPECT_EQ(r.maxSurfaceDistance, e.maxSurfaceDistance);

    // Both empty: IoU 1, no distance.
    const auto empty = openvdb::Int32Grid::create(0);
    e = compareShapes(*empty, 10, *empty, 10, 3);
    EXPECT_EQ(e.iou, 1.0);
    EXPECT_EQ(e.meanSurfaceDistance, 0.0);
}

TEST_F(MetricsTest, SurfaceDistanceMatchesBruteForceOnRandomBlobs)
{
    std::mt19937 rng(7);
    for (int trial = 0; trial < 6; ++trial) {
        auto a = openvdb::Int32Grid::create(0), b = openvdb::Int32Grid::create(0);
        std::uniform_int_distribution<int> coord(0, 11), coin(0, 2);
        for (int i = 0; i < 300; ++i) {
            a->tree().setValue(Coord(coord(rng), coord(rng), coord(rng)), 10);
            b->tree().setValue(Coord(coord(rng) + 3, coord(rng), coord(rng) - 2), 10);
        }
        const ShapeError e = compareShapes(*a, 10, *b, 10, 3);
        // Brute force: surface voxels and nearest distances by looking at every pair.
        auto surface = [](const openvdb::Int32Grid& g) {
            std::vector<Coord> s;
            auto acc = g.getConstAccessor();
            for (auto it = g.tree().cbeginValueOn(); it; ++it) {
                const Coord c = it.getCoord();
                const Coord n[6] = {c.offsetBy(1, 0, 0),  c.offsetBy(-1, 0, 0), c.offsetBy(0, 1, 0),
                                    c.offsetBy(0, -1, 0), c.offsetBy(0, 0, 1),  c.offsetBy(0, 0, -1)};
                for (const Coord& x : n)
                    if (acc.getValue(x) == 0) {
                        s.push_back(c);
                        break;
                    }
            }
            return s;
        };
        const std::vector<Coord> sa = surface(*a), sb = surface(*b);
        double sum = 0, max = 0;
        for (int dir = 0; dir < 2; ++dir) {
            const std::vector<Coord>& from = dir ? sb : sa;
            const std::vector<Coord>& to = dir ? sa : sb;
            for (const Coord& p : from) {
                int64_t best = INT64_MAX;
                for (const Coord& q : to)
                    best = std::min<int64_t>(best, (p - q).asVec3d().lengthSqr());
                sum += std::sqrt(double(best));
                max = std::max(max, std::sqrt(double(best)));
            }
        }
        EXPECT_EQ(e.claySurface, sa.size());
        EXPECT_EQ(e.referenceSurface, sb.size());
        EXPECT_DOUBLE_EQ(e.meanSurfaceDistance, sum / double(sa.size() + sb.size()));
        EXPECT_EQ(e.maxSurfaceDistance, max);
    }
}

// ---- measureClay over leaves ---------------------------------------------------------------------

namespace {

/// A serial reference for measureClay: one pass in tree order, the same sums, the spread of the
/// interior cells about their mean summed in the same order.
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
    // The spread from exact sums: sqrt(n sum m^2 - (sum m)^2) / n (the values here fit 128 bits).
    const double mean = double(interiorSum) / double(r.interiorCells);
    unsigned __int128 squares = 0;
    for (auto it = mass.tree().cbeginValueAll(); it; ++it) {
        if (*it == 0 || !interior(it.getCoord())) continue;
        squares += (unsigned __int128)(uint64_t(int64_t(*it) * *it));
    }
    const unsigned __int128 n = r.interiorCells, s1 = uint64_t(interiorSum);
    r.interiorMeanDensity = mean / double(tc);
    r.heterogeneityCV = std::sqrt(double(n * squares - s1 * s1)) / double(r.interiorCells) / mean;
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

TEST_F(MetricsTest, MeasureClayOverLeavesIsTheSerialSumOnAnyThreadCount)
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
        if (dims == 2) // clay off the plane z = 0 (a 2D grid read from a file may hold some): never interior
            for (int x = -15; x < 15; ++x)
                for (int y = -5; y < 25; ++y)
                    g->tree().setValue(Coord(x, y, 1), rng.range(1, 1700));
        auto obstacles = openvdb::MaskGrid::create(false);
        obstacles->tree().fill(openvdb::CoordBBox(Coord(-3, -3, -3), Coord(4, 40, 4)), true, true);
        obstacles->tree().fill(openvdb::CoordBBox(Coord(8, 8, 0), Coord(15, 15, 7)), true, true); // a tile
        EXPECT_EQ(obstacles->tree().activeTileCount(), 1u);
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
    // A tile is measured as its voxels (tests/TestTiles.cc compares whole grids).
    auto tiled = openvdb::Int32Grid::create(0);
    tiled->tree().addTile(1, Coord(0, 0, 0), 5, true);
    const ClayMetrics t = measureClay(*tiled, 1000, nullptr, 3, 2);
    EXPECT_EQ(t.mass, 5 * 512);
    EXPECT_EQ(t.clayVoxels, 512u);
    EXPECT_EQ(t.interiorCells, 6u * 6 * 6);
}

TEST_F(MetricsTest, TilesNextToTilesLeavesAndNothingMeasureAsTheirVoxels)
{
    // 8^3 tiles whose faces meet tiles of clay, a 128^3 tile, a tile of another value, a leaf with a
    // hole on the shared face, a leaf of full clay, and nothing: each measured as its voxels.
    auto g = openvdb::Int32Grid::create(0);
    openvdb::Int32Tree& t = g->tree();
    t.addTile(2, Coord(0, 0, 0), 700, true); // 128^3
    for (int i = 0; i < 4; ++i)
        t.addTile(1, Coord(128 + 8 * i, 0, 0), 1000, true); // a row of 8^3 tiles off its +x face
    t.addTile(1, Coord(128, 8, 0), 900, true);
    t.addTile(1, Coord(136, 8, 0), 1000, true);
    for (int x = 144; x < 152; ++x) // a leaf of clay over the tile at (144, 0, 0) ...
        for (int y = 8; y < 16; ++y)
            for (int z = 0; z < 8; ++z)
                t.setValue(Coord(x, y, z), 1000);
    t.setValue(Coord(147, 8, 3), 0); // ... with a hole on the shared face
    t.addTile(1, Coord(152, 8, 0), 1000, true);
    for (int x = 152; x < 160; ++x) // a full leaf over the tile at (152, 8, 0)
        for (int y = 16; y < 24; ++y)
            for (int z = 0; z < 8; ++z)
                t.setValue(Coord(x, y, z), 1000);
    // Two 3x3x3 blocks of 8^3 tiles: their centres' faces all meet clay, in one block through tiles
    // alone, in the other through a full leaf on one side.
    for (int block : {512, 640})
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j)
                for (int k = 0; k < 3; ++k)
                    t.addTile(1, Coord(block + 8 * i, 8 * j, 8 * k), 1000, true);
    for (int x = 656; x < 664; ++x)
        for (int y = 8; y < 16; ++y)
            for (int z = 8; z < 16; ++z)
                t.setValue(Coord(x, y, z), 1000);
    auto dense = g->deepCopy();
    dense->tree().voxelizeActiveTiles();
    ASSERT_EQ(dense->tree().activeTileCount(), 0u);
    const ClayMetrics expected = serialMeasure(*dense, 1000, nullptr, 3);
    EXPECT_EQ(expected.clayVoxels, uint64_t(128 * 128 * 128 + (7 + 2 * 27) * 512 + 2 * 512 - 1));
    for (int threads : {1, 2, 3, 8}) {
        tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
        expectSameMetrics(measureClay(*g, 1000, nullptr, 3, threads), expected,
                          "tiled, " + std::to_string(threads) + " threads");
    }
}
