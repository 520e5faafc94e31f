/// @file Coverage.h
/// @brief Private: the exact volume of a closed triangle mesh inside each voxel (Coverage.cc).
#pragma once

#include "vdbclay/Shapes.h"

#include <array>
#include <cstdint>
#include <functional>
#include <vector>

namespace vdbclay {
namespace shapes_internal {

/// True when every undirected edge is traversed as often in one direction as in the other: the
/// triangles form a closed, consistently oriented surface (manifold or not), whose winding number is
/// an integer everywhere off the surface. Then meshCoverage is exact.
bool isOrientedClosed(const std::vector<std::array<uint32_t, 3>>& triangles);

/// For a closed, consistently oriented mesh (isOrientedClosed) in index space (voxel (i, j, k) is
/// the cube of side 1 centred on (i, j, k)): calls @a covered(x, y, z, fraction) for every voxel with
/// fraction > 0, in x, then y, then z order, where fraction is the volume of the voxel inside the
/// mesh (clamped to 1 where the mesh overlaps itself). An inside-out mesh is treated as outward.
void meshCoverage(const std::vector<Vec3>& points, const std::vector<std::array<uint32_t, 3>>& triangles,
                  const std::function<void(int32_t, int32_t, int32_t, double)>& covered);

} // namespace shapes_internal
} // namespace vdbclay
