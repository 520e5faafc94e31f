// Clay from a shape (makeClay, Shapes.h; with a stop poll, MakeClay.h): the voxels whose centre lies inside
// an analytic shape, rasterised leaf by leaf on every core (Rasterize.h); for shapes that keep their volume
// (meshes, level sets), each voxel by the part of it the shape covers (Voxels.h, Coverage.cc). Uniform
// clay is held as tiles: interior slots of convex shapes are tiles from the start, and leaves whose
// voxels all hold one value collapse into tiles at the end (automaton/Tiles.h). A stop poll
// runs between the rasteriser's chunks, or every 4096 covered voxels.
#include "vdbclay/MakeClay.h"
#include "vdbclay/Shapes.h"

#include "automaton/Tiles.h"
#include "shapes/Rasterize.h"
#include "shapes/Voxels.h"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <string>

namespace vdbclay {

using shapes_internal::forEachVoxelCovered;

MassGridPtr makeClay(const Shape& shape, int32_t massPerVoxel, int dimensions)
{
    return makeClay(shape, massPerVoxel, dimensions, std::function<bool()>());
}

namespace {
/// Thrown out of the coverage callback when the stop poll asks to stop.
struct Stopped {};
} // namespace

MassGridPtr makeClay(const Shape& shape, int32_t massPerVoxel, int dimensions,
                     const std::function<bool()>& stop)
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
        uint64_t seen = 0;
        try {
            forEachVoxelCovered(shape, dimensions, [&](int32_t x, int32_t y, int32_t z, double fraction) {
                const int64_t m = std::llround(double(massPerVoxel) * fraction);
                if (m > 0)
                    acc.setValueOn(openvdb::Coord(x, y, z), int32_t(std::min<int64_t>(m, massPerVoxel)));
                if (stop && ++seen % 4096 == 0 && stop()) throw Stopped();
            });
        } catch (const Stopped&) {
            return nullptr;
        }
        if (grid->activeVoxelCount() == 0) {
            throw Error(shape.describe() + " covers no voxel" +
                        (dimensions == 2 ? " of the z = 0 layer" : "") + " enough to hold a unit of mass (" +
                        std::to_string(massPerVoxel) + " per voxel)");
        }
    } else {
        // The voxels forEachVoxelInside (Voxels.h) visits, leaf by leaf on every core (Rasterize.h).
        bool stopped = false;
        raster_internal::rasterizeInside(
            grid->tree(), shape, dimensions, massPerVoxel, /*threads=*/0,
            [&] { return stopped = stop && stop(); }, /*tiles=*/true);
        if (stopped) return nullptr;
    }
    // Uniform clay as tiles: the interior's leaves (meshes, level sets) and slots collapse into
    // tiles, and whole nodes of them into larger tiles (automaton/Tiles.h).
    automaton_internal::collapseUniformLeaves(grid->tree(), massPerVoxel);
    if (grid->activeVoxelCount() == 0) {
        throw Error("no voxel centre lies inside " + shape.describe() +
                    (dimensions == 2 ? " in the z = 0 layer" : ""));
    }
    return grid;
}

} // namespace vdbclay
