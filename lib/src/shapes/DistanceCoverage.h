/// @file DistanceCoverage.h
/// @brief Private: the part of each voxel a shape covers, estimated from its signed distance at
/// voxel centres (DistanceCoverage.cc), for shapes that keep their volume but have no exact
/// coverage of their own (level sets, open meshes).
#pragma once

#include "vdbclay/Shapes.h"

#include <cstdint>
#include <functional>

namespace vdbclay {
namespace shapes_internal {

/// One half-space n.x <= d, with |n| = 1, in coordinates relative to a voxel's centre.
struct HalfSpace {
    Vec3 n;
    double d;
};

/// The volume of the unit cube centred on the origin inside all @a count half-spaces (exact up to
/// rounding: the polytope's faces clipped against each other, then the divergence theorem).
double clippedCubeVolume(const HalfSpace* halfSpaces, int count);

/// Calls @a covered(x, y, z, fraction) for every voxel of @a box (in x, then y, then z order) of
/// which @a shape covers a fraction in (0, 1], estimated from shape.distance() at voxel centres:
/// exact where the distance field is, near the voxel, a plane or the max (convex edge, corner) or
/// the min (concave edge) of planes; elsewhere clamp(1/2 - distance, 0, 1). 3D only.
void distanceCoverage(const Shape& shape, const Box& box,
                      const std::function<void(int32_t, int32_t, int32_t, double)>& covered);

} // namespace shapes_internal
} // namespace vdbclay
