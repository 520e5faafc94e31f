// Shapes: signed distance fields in the clay's index space (Shapes.h), and clay made from them.
//
// Shapes.cc holds the analytic shapes (sphere, box, cylinder, capsule) and the placements (a rigid
// pose, a transform with scale). ShapesLevelSet.cc reads level sets from .vdb files (their layout
// checked first, core/VdbCheck.h) and ShapesMesh.cc turns meshes (OBJ, STL, PLY) into level sets;
// both are sampled by LevelSetShape.h. A voxel is inside a shape when the distance at its centre is
// < 0 (Voxels.h, forEachVoxelInside); Rasterize.h sets those voxels leaf by leaf on several threads,
// and InsideBox.h finds them with no distance at all for unrotated boxes. Shapes that keep their
// volume (meshes, level sets) give each voxel the part of it they cover instead: exactly for closed
// meshes (Coverage.cc), from the distance field otherwise (DistanceCoverage.cc). MakeClay.cc turns
// either into clay. shapes/ stands on core/ only.
//
// Every analytic shape computes its bounds once, at construction, as the smallest voxel box that
// contains the whole shape taken as a continuous solid (not only the voxel centres inside it):
// makeTransformed relies on that to bound a rotated shape from the corners of its inner bounds.

#include "vdbclay/Shapes.h"

#include "shapes/InsideBox.h"
#include "shapes/ShapeMath.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

namespace vdbclay {

using namespace shapes_internal;

namespace {

// ---- analytic shapes -----------------------------------------------------------------------------

class Sphere final : public Shape {
public:
    Sphere(const Vec3& c, double r) : mC(c), mR(r)
    {
        mBounds = boxOf({{c[0] - r, c[1] - r, c[2] - r}}, {{c[0] + r, c[1] + r, c[2] + r}}, describe());
    }
    double distance(const Vec3& p) const override { return length(sub(p, mC)) - mR; }
    Box bounds() const override { return mBounds; }
    bool convex() const override { return true; }
    std::string describe() const override
    {
        return "sphere (center " + vecStr(mC) + ", radius " + num(mR) + ")";
    }

private:
    Vec3 mC;
    double mR;
    Box mBounds;
};

class BoxShape final : public Shape {
public:
    BoxShape(const Vec3& lo, const Vec3& hi)
    {
        for (int i = 0; i < 3; ++i) {
            mCenter[i] = 0.5 * (lo[i] + hi[i]);
            mHalf[i] = 0.5 * (hi[i] - lo[i]) + 0.5;
        }
        mLo = lo;
        mHi = hi;
        mBounds = boxOf({{lo[0] - 0.5, lo[1] - 0.5, lo[2] - 0.5}}, {{hi[0] + 0.5, hi[1] + 0.5, hi[2] + 0.5}},
                        describe());
    }
    double distance(const Vec3& p) const override
    {
        double outside2 = 0, inside = -std::numeric_limits<double>::infinity();
        for (int i = 0; i < 3; ++i) {
            const double q = std::abs(p[i] - mCenter[i]) - mHalf[i];
            if (q > 0) outside2 += q * q;
            inside = std::max(inside, q);
        }
        return std::sqrt(outside2) + std::min(inside, 0.0);
    }
    Box bounds() const override { return mBounds; }
    bool convex() const override { return true; }
    std::string describe() const override { return "box (min " + vecStr(mLo) + ", max " + vecStr(mHi) + ")"; }
    /// Whether coordinate @a v lies inside on axis @a i: distance() < 0 exactly when it does on all
    /// three (its q's, compared as distance() compares them: all below 0 gives max q < 0, any above 0
    /// a positive sqrt or a zero).
    bool insideOnAxis(int i, double v) const { return std::abs(v - mCenter[i]) - mHalf[i] < 0; }

private:
    Vec3 mLo, mHi, mCenter, mHalf;
    Box mBounds;
};

class Cylinder final : public Shape {
public:
    Cylinder(const Vec3& c, double r, double h, int axis) : mC(c), mR(r), mH(h), mAxis(axis)
    {
        Vec3 lo, hi;
        for (int i = 0; i < 3; ++i) {
            const double e = i == axis ? 0.5 * h : r;
            lo[i] = c[i] - e;
            hi[i] = c[i] + e;
        }
        mBounds = boxOf(lo, hi, describe());
    }
    double distance(const Vec3& p) const override
    {
        double radial2 = 0;
        for (int i = 0; i < 3; ++i)
            if (i != mAxis) radial2 += (p[i] - mC[i]) * (p[i] - mC[i]);
        const double dr = std::sqrt(radial2) - mR;
        const double da = std::abs(p[mAxis] - mC[mAxis]) - 0.5 * mH;
        const double a = std::max(dr, 0.0), b = std::max(da, 0.0);
        return std::min(std::max(dr, da), 0.0) + std::sqrt(a * a + b * b);
    }
    Box bounds() const override { return mBounds; }
    bool convex() const override { return true; }
    std::string describe() const override
    {
        return "cylinder (center " + vecStr(mC) + ", radius " + num(mR) + ", height " + num(mH) + ", axis " +
               std::to_string(mAxis) + ")";
    }

private:
    Vec3 mC;
    double mR, mH;
    int mAxis;
    Box mBounds;
};

class Capsule final : public Shape {
public:
    Capsule(const Vec3& a, const Vec3& b, double r) : mA(a), mB(b), mR(r)
    {
        Vec3 lo, hi;
        for (int i = 0; i < 3; ++i) {
            lo[i] = std::min(a[i], b[i]) - r;
            hi[i] = std::max(a[i], b[i]) + r;
        }
        mBounds = boxOf(lo, hi, describe());
    }
    double distance(const Vec3& p) const override
    {
        const Vec3 ab = sub(mB, mA), ap = sub(p, mA);
        const double l2 = dot(ab, ab);
        const double t = l2 > 0 ? std::clamp(dot(ap, ab) / l2, 0.0, 1.0) : 0.0;
        const Vec3 d{{ap[0] - t * ab[0], ap[1] - t * ab[1], ap[2] - t * ab[2]}};
        return length(d) - mR;
    }
    Box bounds() const override { return mBounds; }
    bool convex() const override { return true; }
    std::string describe() const override
    {
        return "capsule (a " + vecStr(mA) + ", b " + vecStr(mB) + ", radius " + num(mR) + ")";
    }

private:
    Vec3 mA, mB;
    double mR;
    Box mBounds;
};

class Transformed final : public Shape {
public:
    Transformed(ShapePtr inner, const Pose& pose) : mInner(std::move(inner)), mPose(pose)
    {
        mRot = rotation(pose.rotationDeg);
        const Box ib = mInner->bounds();
        if (ib.empty()) {
            mBounds = Box();
            return;
        }
        Vec3 lo{{kMaxCoord * 4, kMaxCoord * 4, kMaxCoord * 4}},
            hi{{-kMaxCoord * 4, -kMaxCoord * 4, -kMaxCoord * 4}};
        for (int corner = 0; corner < 8; ++corner) {
            Vec3 c;
            for (int i = 0; i < 3; ++i)
                c[i] = ((corner >> i) & 1) ? ib.max[i] + 0.5 : ib.min[i] - 0.5;
            const Vec3 w = mPose.apply(c);
            for (int i = 0; i < 3; ++i) {
                lo[i] = std::min(lo[i], w[i]);
                hi[i] = std::max(hi[i], w[i]);
            }
        }
        // Rounding of the rotation: widen by a hair before rounding outward.
        for (int i = 0; i < 3; ++i) {
            lo[i] -= 1e-9 * (1 + std::abs(lo[i]));
            hi[i] += 1e-9 * (1 + std::abs(hi[i]));
        }
        mBounds = boxOf(lo, hi, describe());
    }
    double distance(const Vec3& p) const override { return mInner->distance(toInner(p)); }
    Vec3 normal(const Vec3& p) const override { return mul(mRot, mInner->normal(toInner(p))); }
    const Shape& inner() const { return *mInner; }
    /// No rotation: the matrix is exactly the identity (sin 0 and cos 0 are exact), so toInner's
    /// coordinate @a i depends on p[i] alone (the zeros add nothing), as toInnerAxis() computes it.
    bool unrotated() const
    {
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j)
                if (mRot[i][j] != (i == j ? 1.0 : 0.0)) return false;
        return true;
    }
    /// toInner(p)[i] for any p with p[i] = @a v, when unrotated(): the same operations in the same order.
    double toInnerAxis(int i, double v) const
    {
        return (v - mPose.translation[i] - mPose.pivot[i]) + mPose.pivot[i];
    }
    bool convex() const override { return mInner->convex(); } // an affine map keeps it
    Box bounds() const override { return mBounds; }
    std::string describe() const override
    {
        return mInner->describe() + " moved by (translation " + vecStr(mPose.translation) + ", rotation " +
               vecStr(mPose.rotationDeg) + " deg, pivot " + vecStr(mPose.pivot) + ")";
    }

private:
    /// Pose::applyInverse with the rotation computed once, at construction: the same floating-point
    /// operations in the same order, so the same bits (sin/cos were recomputed for every point).
    Vec3 toInner(const Vec3& p) const
    {
        const Vec3& t = mPose.translation;
        const Vec3& c = mPose.pivot;
        const Vec3 q{{p[0] - t[0] - c[0], p[1] - t[1] - c[1], p[2] - t[2] - c[2]}};
        const Vec3 r = mulT(mRot, q);
        return {{r[0] + c[0], r[1] + c[1], r[2] + c[2]}};
    }

    ShapePtr mInner;
    Pose mPose;
    Mat3 mRot;
    Box mBounds;
};

class Scaled final : public Shape {
public:
    Scaled(ShapePtr inner, const Vec3& scale, const Vec3& pivot)
        : mInner(std::move(inner)), mScale(scale), mPivot(pivot)
    {
        mMin = std::min({scale[0], scale[1], scale[2]});
        const Box ib = mInner->bounds();
        if (ib.empty()) return;
        Vec3 lo, hi;
        for (int i = 0; i < 3; ++i) {
            lo[i] = (ib.min[i] - 0.5 - pivot[i]) * scale[i] + pivot[i];
            hi[i] = (ib.max[i] + 0.5 - pivot[i]) * scale[i] + pivot[i];
            lo[i] -= 1e-9 * (1 + std::abs(lo[i]));
            hi[i] += 1e-9 * (1 + std::abs(hi[i]));
        }
        mBounds = boxOf(lo, hi, describe());
    }
    double distance(const Vec3& p) const override
    {
        Vec3 q;
        for (int i = 0; i < 3; ++i)
            q[i] = (p[i] - mPivot[i]) / mScale[i] + mPivot[i];
        return mInner->distance(q) * mMin;
    }
    Vec3 normal(const Vec3& p) const override
    {
        // The inner normal through the inverse transpose of the scale, renormalised.
        Vec3 q;
        for (int i = 0; i < 3; ++i)
            q[i] = (p[i] - mPivot[i]) / mScale[i] + mPivot[i];
        const Vec3 n = mInner->normal(q);
        Vec3 m{{n[0] / mScale[0], n[1] / mScale[1], n[2] / mScale[2]}};
        const double l = length(m);
        if (!(l > 0) || !std::isfinite(l)) return n;
        return {{m[0] / l, m[1] / l, m[2] / l}};
    }
    bool convex() const override { return mInner->convex(); } // an affine map keeps it
    Box bounds() const override { return mBounds; }
    std::string describe() const override
    {
        return mInner->describe() + " scaled by " + vecStr(mScale) + " about " + vecStr(mPivot);
    }

private:
    ShapePtr mInner;
    Vec3 mScale, mPivot;
    double mMin = 1;
    Box mBounds;
};

} // namespace

// ---- Boxes ---------------------------------------------------------------------------------------

namespace shapes_internal {

bool insideVoxelBox(const Shape& shape, Box& voxels)
{
    const auto* moved = dynamic_cast<const Transformed*>(&shape);
    if (moved && !moved->unrotated()) return false;
    const auto* box = dynamic_cast<const BoxShape*>(moved ? &moved->inner() : &shape);
    if (!box) return false;
    const Box b = shape.bounds();
    if (b.empty()) {
        voxels = Box();
        return true;
    }
    Box out;
    for (int i = 0; i < 3; ++i) {
        // The inside coordinates of axis i within the bounds: one interval (|v' - c| < h with v'
        // monotonic in v), checked.
        int64_t lo = INT64_MAX, hi = INT64_MIN, count = 0;
        for (int64_t v = b.min[i]; v <= b.max[i]; ++v) {
            if (!box->insideOnAxis(i, moved ? moved->toInnerAxis(i, double(v)) : double(v))) continue;
            lo = std::min(lo, v);
            hi = std::max(hi, v);
            ++count;
        }
        if (count == 0) { // no voxel inside
            voxels = Box();
            return true;
        }
        if (count != hi - lo + 1) return false;
        out.min[i] = int32_t(lo);
        out.max[i] = int32_t(hi);
    }
    voxels = out;
    return true;
}

} // namespace shapes_internal

// ---- Pose, Shape ---------------------------------------------------------------------------------

Vec3 Pose::apply(const Vec3& p) const
{
    const Vec3 r = mul(rotation(rotationDeg), sub(p, pivot));
    return {{r[0] + pivot[0] + translation[0], r[1] + pivot[1] + translation[1],
             r[2] + pivot[2] + translation[2]}};
}

Vec3 Pose::applyInverse(const Vec3& p) const
{
    const Vec3 q{{p[0] - translation[0] - pivot[0], p[1] - translation[1] - pivot[1],
                  p[2] - translation[2] - pivot[2]}};
    const Vec3 r = mulT(rotation(rotationDeg), q);
    return {{r[0] + pivot[0], r[1] + pivot[1], r[2] + pivot[2]}};
}

bool Pose::isIdentity() const
{
    for (int i = 0; i < 3; ++i) {
        if (translation[i] != 0.0) return false;
        if (std::fmod(rotationDeg[i], 360.0) != 0.0) return false;
    }
    return true;
}

Vec3 Shape::normal(const Vec3& p) const
{
    constexpr double h = 0.5;
    Vec3 g;
    for (int i = 0; i < 3; ++i) {
        Vec3 a = p, b = p;
        a[i] += h;
        b[i] -= h;
        g[i] = distance(a) - distance(b);
    }
    const double l = length(g);
    if (!(l > 0.0) || !std::isfinite(l)) return {{0, 1, 0}};
    return {{g[0] / l, g[1] / l, g[2] / l}};
}

// ---- up axis -------------------------------------------------------------------------------------

UpAxis parseUpAxis(const std::string& text)
{
    if (text == "y" || text == "Y") return UpAxis::Y;
    if (text == "z" || text == "Z") return UpAxis::Z;
    throw Error("unknown up axis \"" + text + "\" (expected \"y\" or \"z\")");
}

const char* upAxisName(UpAxis up)
{
    return up == UpAxis::Z ? "z" : "y";
}

Vec3 worldToIndex(const Vec3& w, double voxelSize, UpAxis up)
{
    if (up == UpAxis::Z) return {{w[0] / voxelSize, w[2] / voxelSize, -w[1] / voxelSize}};
    return {{w[0] / voxelSize, w[1] / voxelSize, w[2] / voxelSize}};
}

Vec3 indexToWorld(const Vec3& p, double voxelSize, UpAxis up)
{
    if (up == UpAxis::Z) return {{p[0] * voxelSize, -p[2] * voxelSize, p[1] * voxelSize}};
    return {{p[0] * voxelSize, p[1] * voxelSize, p[2] * voxelSize}};
}

// ---- factories -----------------------------------------------------------------------------------

ShapePtr makeSphere(const Vec3& center, double radius)
{
    requireFinite(center, "makeSphere", "center");
    requirePositive(radius, "makeSphere", "radius");
    return std::make_shared<Sphere>(center, radius);
}

ShapePtr makeBox(const Vec3& min, const Vec3& max)
{
    requireFinite(min, "makeBox", "min");
    requireFinite(max, "makeBox", "max");
    for (int i = 0; i < 3; ++i) {
        if (min[i] > max[i]) {
            throw Error("makeBox: min[" + std::to_string(i) + "] = " + num(min[i]) + " exceeds max[" +
                        std::to_string(i) + "] = " + num(max[i]));
        }
    }
    return std::make_shared<BoxShape>(min, max);
}

ShapePtr makeCylinder(const Vec3& center, double radius, double height, int axis)
{
    requireFinite(center, "makeCylinder", "center");
    requirePositive(radius, "makeCylinder", "radius");
    requirePositive(height, "makeCylinder", "height");
    if (axis < 0 || axis > 2) {
        throw Error("makeCylinder: axis must be 0 (x), 1 (y) or 2 (z), got " + std::to_string(axis));
    }
    return std::make_shared<Cylinder>(center, radius, height, axis);
}

ShapePtr makeCapsule(const Vec3& a, const Vec3& b, double radius)
{
    requireFinite(a, "makeCapsule", "a");
    requireFinite(b, "makeCapsule", "b");
    requirePositive(radius, "makeCapsule", "radius");
    return std::make_shared<Capsule>(a, b, radius);
}

Vec3 Placement::apply(const Vec3& p) const
{
    Vec3 q;
    for (int i = 0; i < 3; ++i)
        q[i] = (p[i] - pivot[i]) * scale[i] + pivot[i];
    Pose pose;
    pose.translation = translate;
    pose.rotationDeg = rotateDeg;
    pose.pivot = pivot;
    return pose.apply(q);
}

bool Placement::isIdentity() const
{
    Pose pose;
    pose.translation = translate;
    pose.rotationDeg = rotateDeg;
    return scale == Vec3{{1, 1, 1}} && pose.isIdentity();
}

namespace {
/// A placed level set keeps its volume (coverage-weighted clay) as the shape it places does.
class KeepsVolume final : public Shape {
public:
    explicit KeepsVolume(ShapePtr inner) : mInner(std::move(inner)) {}
    double distance(const Vec3& p) const override { return mInner->distance(p); }
    Vec3 normal(const Vec3& p) const override { return mInner->normal(p); }
    Box bounds() const override { return mInner->bounds(); }
    std::string describe() const override { return mInner->describe(); }
    bool keepsVolume() const override { return true; }

private:
    ShapePtr mInner;
};
} // namespace

ShapePtr makePlaced(ShapePtr shape, const Placement& placement)
{
    if (!shape) throw Error("transform: shape is null");
    const bool keepsVolume = shape->keepsVolume();
    requireValidPlacement(placement);
    if (placement.scale != Vec3{{1, 1, 1}}) {
        shape = std::make_shared<Scaled>(std::move(shape), placement.scale, placement.pivot);
    }
    Pose pose;
    pose.translation = placement.translate;
    pose.rotationDeg = placement.rotateDeg;
    pose.pivot = placement.pivot;
    ShapePtr placed = makeTransformed(std::move(shape), pose);
    if (keepsVolume && !placed->keepsVolume()) placed = std::make_shared<KeepsVolume>(std::move(placed));
    return placed;
}

ShapePtr makeTransformed(ShapePtr shape, const Pose& pose)
{
    if (!shape) throw Error("makeTransformed: shape is null");
    requireFinite(pose.translation, "makeTransformed", "pose.translation");
    requireFinite(pose.rotationDeg, "makeTransformed", "pose.rotationDeg");
    requireFinite(pose.pivot, "makeTransformed", "pose.pivot");
    if (pose.isIdentity()) return shape;
    return std::make_shared<Transformed>(std::move(shape), pose);
}

} // namespace vdbclay
