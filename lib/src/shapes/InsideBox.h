// Shapes whose inside voxels form a box: an unrotated box shape, moved by any translation. Their
// voxels are found exactly, an axis at a time, so rasterising or marking them needs no distance
// evaluation per voxel (Rasterize.h, the Sculptor's tool cells).
#pragma once

#include "vdbclay/Shapes.h"

namespace vdbclay {
namespace shapes_internal {

/// When the voxels whose centre lies inside @a shape (distance() < 0, exactly as
/// forEachVoxelInside tests it) are the voxels of one box, sets @a voxels to that box (empty when
/// there are none) and returns true; otherwise returns false and leaves @a voxels alone. True for
/// makeBox and makeBox moved by makeTransformed with no rotation (any translation and pivot).
bool insideVoxelBox(const Shape& shape, Box& voxels);

} // namespace shapes_internal
} // namespace vdbclay
