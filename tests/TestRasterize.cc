// Shapes rasterised into grids by leaves (lib/src/shapes/Rasterize.h, behind makeClay and the
// scene's obstacles): the voxels, values and leaves of a plain loop over every voxel inside, on any
// thread count, into empty trees and into trees that already hold leaves and tiles.
#include "shapes/Rasterize.h"
#include "shapes/Voxels.h"

#include "vdbclay/Shapes.h"
#include "vdbclay/Types.h"

#include <gtest/gtest.h>

#include <openvdb/openvdb.h>

#include <tbb/global_control.h>

#include <cstdint>
#include <string>
#include <vector>

using namespace vdbclay;
using openvdb::Coord;

namespace {

class RasterizeTest : public ::testing::Test {
protected:
    static void SetUpTestSuite() { openvdb::initialize(); }
};

} // namespace

TEST_F(RasterizeTest, InsideByLeavesSetsTheVoxelsOfTheVoxelLoopOnAnyThreadCount)
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
                    shapes_internal::forEachVoxelInside(shape, dims, [&](int32_t x, int32_t y, int32_t z) {
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
