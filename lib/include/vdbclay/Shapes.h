/// @file Shapes.h
/// @brief Signed distance fields for tools, obstacles and clay: analytic shapes, level sets, meshes.
///
/// All coordinates are in the clay grid's index space: voxel (i, j, k) has its centre at (i, j, k)
/// and a voxel is inside a shape when the shape's distance at its centre is < 0. Distances are in
/// voxel units. A shape evaluates itself only near itself: bounds() is a box outside of which the
/// distance is known to be >= 0, and callers never evaluate a shape outside it.
#pragma once

#include "vdbclay/Types.h"

#include <array>
#include <memory>
#include <string>
#include <vector>

namespace vdbclay {

using Vec3 = std::array<double, 3>;

/// A rigid placement: rotate by Euler angles (degrees, about x then y then z) around @a pivot,
/// then translate.
struct Pose {
    Vec3 translation{{0, 0, 0}};
    Vec3 rotationDeg{{0, 0, 0}};
    Vec3 pivot{{0, 0, 0}};
    /// Applies the pose to a point.
    Vec3 apply(const Vec3& p) const;
    /// The inverse mapping (world to shape space).
    Vec3 applyInverse(const Vec3& p) const;
    bool isIdentity() const;
};

class Shape {
public:
    virtual ~Shape() = default;
    /// Signed distance at @a p (index space, voxel units): negative inside, positive outside. For
    /// non-analytic shapes (level sets, meshes) an approximation that is exact in sign.
    virtual double distance(const Vec3& p) const = 0;
    /// The outward normal at @a p (unit length); by default the normalised central-difference
    /// gradient of distance() with step 0.5.
    virtual Vec3 normal(const Vec3& p) const;
    /// A voxel box containing every voxel whose centre is inside the shape. (The built-in shapes
    /// return a box that contains the whole shape as a continuous solid, which transformed shapes
    /// rely on; other shapes are given half a voxel of margin when transformed.)
    virtual Box bounds() const = 0;
    /// A short description for messages, e.g. "sphere (center [1,2,3], radius 4)".
    virtual std::string describe() const = 0;
};
using ShapePtr = std::shared_ptr<const Shape>;

/// @throw Error (naming the parameter) on NaN/infinite values, radius/height <= 0, min > max,
/// an axis other than 0, 1, 2.
ShapePtr makeSphere(const Vec3& center, double radius);
/// The box of voxels min..max, inclusive: its faces lie half a voxel outside those centres.
ShapePtr makeBox(const Vec3& min, const Vec3& max);
/// A cylinder of @a radius and total @a height centred at @a center along @a axis (0 = x, 1 = y, 2 = z).
ShapePtr makeCylinder(const Vec3& center, double radius, double height, int axis);
/// A capsule: all points within @a radius of segment a-b.
ShapePtr makeCapsule(const Vec3& a, const Vec3& b, double radius);
/// @a shape moved by @a pose (returns @a shape itself for the identity pose).
ShapePtr makeTransformed(ShapePtr shape, const Pose& pose);

/// A level set (openvdb::FloatGrid of class GRID_LEVEL_SET) read from a .vdb file. Its own
/// transform maps it to world space; @a voxelSize is the clay grid's voxel size (world units per
/// voxel) used to bring it into the clay's index space. @a gridName empty: the first level set.
/// @throw Error naming the file if it is missing, unreadable, truncated, not a .vdb, or has no
///        FloatGrid level set (of that name).
ShapePtr loadLevelSet(const std::string& path, double voxelSize = 1.0, const std::string& gridName = "");
/// A closed triangle mesh (OBJ or STL, ASCII or binary STL), in world units, converted with
/// openvdb::tools::meshToLevelSet at @a voxelSize.
/// @throw Error naming the file if it is unreadable, empty, malformed (with the line), or not closed.
ShapePtr loadMesh(const std::string& path, double voxelSize = 1.0);

} // namespace vdbclay
