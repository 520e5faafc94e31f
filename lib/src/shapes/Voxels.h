/// @file Voxels.h
/// @brief Private: the voxels of a shape, one at a time: those whose centre lies inside it
///        (forEachVoxelInside, the definition rasterizeInside and the accuracy metrics follow) and
///        the part of each that a volume-keeping shape covers (forEachVoxelCovered, for makeClay).
#pragma once

#include "vdbclay/Shapes.h"
#include "vdbclay/Types.h"

#include <cstdint>
#include <functional>

namespace vdbclay {
namespace shapes_internal {

/// Calls @a inside(x, y, z) for every voxel whose centre lies inside @a shape (distance < 0), in x,
/// then y, then z order, within shape.bounds() (only the z = 0 layer when @a dimensions == 2).
template <typename Inside> void forEachVoxelInside(const Shape& shape, int dimensions, Inside&& inside)
{
    Box b = shape.bounds();
    if (dimensions == 2) {
        b.min[2] = b.min[2] > 0 ? b.min[2] : 0;
        b.max[2] = b.max[2] < 0 ? b.max[2] : 0;
    }
    if (b.empty()) return;
    for (int32_t x = b.min[0]; x <= b.max[0]; ++x)
        for (int32_t y = b.min[1]; y <= b.max[1]; ++y)
            for (int32_t z = b.min[2]; z <= b.max[2]; ++z) {
                if (shape.distance(Vec3{{double(x), double(y), double(z)}}) < 0) inside(x, y, z);
            }
}

/// The coverage variant of forEachVoxelInside, for shapes that keepsVolume(): calls
/// @a covered(x, y, z, fraction) for every voxel (only the z = 0 layer when @a dimensions == 2) of
/// which the shape covers a fraction in (0, 1], each voxel once, in x, then y, then z order: the
/// shape's own coverage() when it has one, else estimated from distance() (makeClay in Shapes.h
/// says how; Coverage.cc).
void forEachVoxelCovered(const Shape& shape, int dimensions,
                         const std::function<void(int32_t, int32_t, int32_t, double)>& covered);

} // namespace shapes_internal
} // namespace vdbclay
