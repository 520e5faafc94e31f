// Clay from a shape (makeClay, Shapes.h): the voxels whose centre lies inside an analytic shape,
// rasterised leaf by leaf on every core (Rasterize.h); for shapes that keep their volume (meshes,
// level sets), each voxel by the part of it the shape covers (Voxels.h, Coverage.cc).
#include "vdbclay/Shapes.h"

#include "shapes/Rasterize.h"
#include "shapes/Voxels.h"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <cmath>
#include <string>

namespace vdbclay {

using shapes_internal::forEachVoxelCovered;

MassGridPtr makeClay(const Shape& shape, int32_t massPerVoxel, int dimensions)
{
    openvdb::initialize();
    if (massPerVoxel <= 0) {
        throw Error("the mass per voxel must be > 0, not " + std::to_string(massPerVoxel));
    }
    if (dimensions != 2 && dimensions != 3) {
        throw Error("clay: dimensions must be 2 or 3, not " + std::to_string(dimensions));
    }
    auto grid = openvdb::Int32Grid::create(0);
    grid->setName("mass");
    auto acc = grid->getAccessor();
    if (shape.keepsVolume()) {
        // Meshes and level sets: each voxel holds round(m0 x the fraction of it the shape covers)
        // (Voxels.h), so the clay's mass is the shape's volume x m0. A boundary voxel holding
        // less than Tc is under-full clay, which the automaton may fill like any other.
        forEachVoxelCovered(shape, dimensions, [&](int32_t x, int32_t y, int32_t z, double fraction) {
            const int64_t m = std::llround(double(massPerVoxel) * fraction);
            if (m > 0) acc.setValueOn(openvdb::Coord(x, y, z), int32_t(std::min<int64_t>(m, massPerVoxel)));
        });
        if (grid->activeVoxelCount() == 0) {
            throw Error(shape.describe() + " covers no voxel" +
                        (dimensions == 2 ? " of the z = 0 layer" : "") + " enough to hold a unit of mass (" +
                        std::to_string(massPerVoxel) + " per voxel)");
        }
    } else {
        // The voxels forEachVoxelInside (Voxels.h) visits, leaf by leaf on every core (Rasterize.h).
        raster_internal::rasterizeInside(grid->tree(), shape, dimensions, massPerVoxel, /*threads=*/0);
    }
    if (grid->activeVoxelCount() == 0) {
        throw Error("no voxel centre lies inside " + shape.describe() +
                    (dimensions == 2 ? " in the z = 0 layer" : ""));
    }
    return grid;
}

} // namespace vdbclay
