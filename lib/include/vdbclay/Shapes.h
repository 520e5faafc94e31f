/// @file Shapes.h
/// @brief Signed distance fields for tools, obstacles and clay: analytic shapes, level sets, meshes;
///        clay made from a shape (makeClay).
///
/// All coordinates are in the clay grid's index space: voxel (i, j, k) has its centre at (i, j, k)
/// and a voxel is inside a shape when the shape's distance at its centre is < 0. Distances are in
/// voxel units. A shape evaluates itself only near itself: bounds() is a box outside of which the
/// distance is known to be >= 0, and callers never evaluate a shape outside it.
#pragma once

#include "vdbclay/Fwd.h"
#include "vdbclay/Types.h"

#include <array>
#include <functional>
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
    /// True for shapes that stand for a volume given in world units (meshes, level sets): makeClay
    /// gives their boundary voxels mass in proportion to the part of each voxel they cover, so that
    /// the clay keeps their volume. False (the analytic shapes, in voxel indices): a voxel is in or
    /// out by its centre.
    virtual bool keepsVolume() const { return false; }
    /// True when the points where distance() < 0 form a convex set (the analytic shapes and their
    /// poses): a box of voxel centres whose eight corners lie inside lies inside whole, so clay fills
    /// such an 8^3 slot as one tile without testing its other voxels.
    virtual bool convex() const { return false; }
    /// For shapes that know the part of each voxel they cover better than makeClay's estimate from
    /// distance() (closed meshes: exactly): calls @a covered(x, y, z, fraction) for every voxel (only
    /// the z = 0 layer when @a dimensions == 2) of which the shape covers a fraction in (0, 1], each
    /// voxel once, in x, then y, then z order, and returns true; returns false (calling nothing)
    /// otherwise.
    virtual bool coverage(int dimensions,
                          const std::function<void(int32_t, int32_t, int32_t, double)>& covered) const
    {
        (void)dimensions;
        (void)covered;
        return false;
    }
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

/// Where a shape is put: scaled (uniformly or per axis) about @a pivot, then rotated about @a pivot
/// (degrees about x, then y, then z), then translated. Scenes: "transform" on any shape.
struct Placement {
    Vec3 translate{{0, 0, 0}};
    Vec3 rotateDeg{{0, 0, 0}};
    Vec3 scale{{1, 1, 1}};
    Vec3 pivot{{0, 0, 0}};
    /// The placed position of @a p.
    Vec3 apply(const Vec3& p) const;
    bool isIdentity() const;
};
/// @a shape placed by @a placement. A scaled shape's distance is the inner distance times the
/// smallest scale factor: exact in sign (which voxels are inside), a lower bound on the distance.
/// @throw Error naming the field if a value is not finite or a scale factor is not > 0.
ShapePtr makePlaced(ShapePtr shape, const Placement& placement);

/// Which world axis is up in files (meshes, level sets, the .vdb transform). vdbclay's index space
/// is always y up; with UpAxis::Z, world = Rx(+90 deg) * index * voxelSize: index y (up) is world z
/// and index z is world -y (Blender's convention: its OBJ importer applies the same rotation).
enum class UpAxis { Y, Z };
/// "y" or "z". @throw Error naming @a text and the valid names otherwise.
UpAxis parseUpAxis(const std::string& text);
const char* upAxisName(UpAxis up);
/// The index-space point of world point @a w (divided by @a voxelSize, rotated for @a up).
Vec3 worldToIndex(const Vec3& w, double voxelSize, UpAxis up);
/// The world point of index-space point @a p.
Vec3 indexToWorld(const Vec3& p, double voxelSize, UpAxis up);

/// A level set (openvdb::FloatGrid of class GRID_LEVEL_SET) read from a .vdb file. Its own
/// transform maps it to world space; @a voxelSize and @a up (the clay's) bring world space into the
/// clay's index space. @a gridName empty: the first level set.
/// @throw Error naming the file if it is missing, unreadable, truncated, not a .vdb, or has no
///        FloatGrid level set (of that name).
ShapePtr loadLevelSet(const std::string& path, double voxelSize = 1.0, const std::string& gridName = "",
                      UpAxis up = UpAxis::Y);
/// A triangle mesh (OBJ; STL, ASCII or binary; PLY, ASCII or binary little endian, vertex x y z and
/// face vertex_indices), in world units with @a up as its up
/// axis, brought into index space (@a voxelSize), its vertices placed by @a placement (in index
/// space), then converted with openvdb::tools::meshToLevelSet. Before that conversion the placed
/// vertices must lie within +-2^30 voxels, and the level set's narrow band (taken as the surface of
/// their bounding box, 6 voxels thick) must fit in @a memoryBudget bytes (0: the default budget,
/// defaultMemoryBudget(); UINT64_MAX: no limit), whatever the format.
/// @throw Error naming the file if it is unreadable, empty, malformed (with the line), not closed,
/// out of range, or over the budget (with the estimate).
ShapePtr loadMesh(const std::string& path, double voxelSize = 1.0, UpAxis up = UpAxis::Y,
                  const Placement& placement = Placement(), uint64_t memoryBudget = 0);

// ---- Clay from a shape ---------------------------------------------------------------------------

/// Clay of @a massPerVoxel in every voxel whose centre lies inside @a shape (2D: only z = 0), for
/// the analytic shapes. Shapes that keepsVolume() (meshes, level sets) give every voxel
/// round(massPerVoxel x the fraction of it they cover) instead, so that the clay's mass is their
/// volume x massPerVoxel; boundary voxels are under-full clay. The fraction is the shape's own
/// coverage() when it has one (closed meshes: the exact volume of the mesh inside the voxel, by
/// column integrals), else estimated from distance() at voxel centres: exact where the distance
/// field shows planes near the voxel (a face, a convex edge or corner as the max of planes, a
/// concave edge as their min), else clamp(0.5 - distance(centre), 0, 1), the part of the voxel
/// below a plane at that distance averaged over the plane's orientations, corrected for curvature
/// on curved surfaces (a ball of radius 4 voxels within 0.1 %); 2D: the plain ramp.
/// docs/INTEROP.md, "Coverage". The grid is named "mass", one world unit per voxel (setClayTransform
/// in IO.h gives it a clay file's transform).
/// @throw Error if massPerVoxel <= 0, dimensions is not 2 or 3, or the clay would hold no voxel (no
///        voxel centre inside the shape, or none covered enough to hold a unit of mass).
MassGridPtr makeClay(const Shape& shape, int32_t massPerVoxel, int dimensions = 3);

} // namespace vdbclay
