/// @file ShapeMath.h
/// @brief Private: the small vector helpers, checks and rotations the shape files share.
#pragma once

#include "vdbclay/Shapes.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <string>

namespace vdbclay {
namespace shapes_internal {

/// Coordinates of shape bounds must stay well inside int32 (callers add search margins).
inline constexpr double kMaxCoord = 1 << 30;

inline std::string num(double v)
{
    std::ostringstream os;
    os.precision(17);
    os << v;
    return os.str();
}

inline std::string vecStr(const Vec3& v)
{
    return "[" + num(v[0]) + "," + num(v[1]) + "," + num(v[2]) + "]";
}

inline void requireFinite(const Vec3& v, const std::string& what, const char* name)
{
    for (int i = 0; i < 3; ++i) {
        if (!std::isfinite(v[i])) {
            throw Error(what + ": " + name + "[" + std::to_string(i) + "] must be finite, got " + num(v[i]));
        }
    }
}

inline void requirePositive(double v, const std::string& what, const char* name)
{
    if (!std::isfinite(v) || !(v > 0.0)) {
        throw Error(what + ": " + name + " must be finite and > 0, got " + num(v));
    }
}

/// A scene "transform": finite translate, rotate and pivot, each scale factor finite and > 0.
/// @throw Error "transform: FIELD ..." naming the first bad value.
inline void requireValidPlacement(const Placement& placement)
{
    requireFinite(placement.translate, "transform", "translate");
    requireFinite(placement.rotateDeg, "transform", "rotate");
    requireFinite(placement.pivot, "transform", "pivot");
    for (int i = 0; i < 3; ++i) {
        if (!std::isfinite(placement.scale[i]) || !(placement.scale[i] > 0)) {
            throw Error("transform: scale[" + std::to_string(i) + "] must be finite and > 0, got " +
                        num(placement.scale[i]));
        }
    }
}

/// The voxel box [floor(lo), ceil(hi)]; throws if it leaves the coordinate range.
inline Box boxOf(const Vec3& lo, const Vec3& hi, const std::string& what)
{
    Box b;
    for (int i = 0; i < 3; ++i) {
        const double a = std::floor(lo[i]), z = std::ceil(hi[i]);
        if (!(a >= -kMaxCoord) || !(z <= kMaxCoord)) {
            throw Error(what + ": bounds [" + num(a) + ", " + num(z) + "] along axis " + std::to_string(i) +
                        " exceed the coordinate range +-2^30");
        }
        b.min[i] = int32_t(a);
        b.max[i] = int32_t(z);
    }
    return b;
}

inline double dot(const Vec3& a, const Vec3& b)
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
inline Vec3 sub(const Vec3& a, const Vec3& b)
{
    return {{a[0] - b[0], a[1] - b[1], a[2] - b[2]}};
}
inline double length(const Vec3& a)
{
    return std::sqrt(dot(a, a));
}

/// sin and cos of an angle in degrees; exact for multiples of 90.
inline void sinCosDeg(double deg, double& s, double& c)
{
    const double r = std::fmod(deg, 360.0);
    const double q = r / 90.0;
    if (q == std::floor(q)) {
        const int k = ((int(q) % 4) + 4) % 4;
        const double S[4] = {0, 1, 0, -1}, C[4] = {1, 0, -1, 0};
        s = S[k];
        c = C[k];
        return;
    }
    const double rad = r * (M_PI / 180.0);
    s = std::sin(rad);
    c = std::cos(rad);
}

using Mat3 = std::array<std::array<double, 3>, 3>;

/// R = Rz Ry Rx: rotate about x first, then y, then z (fixed axes).
inline Mat3 rotation(const Vec3& deg)
{
    double sx, cx, sy, cy, sz, cz;
    sinCosDeg(deg[0], sx, cx);
    sinCosDeg(deg[1], sy, cy);
    sinCosDeg(deg[2], sz, cz);
    Mat3 r;
    r[0] = {{cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx}};
    r[1] = {{sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx}};
    r[2] = {{-sy, cy * sx, cy * cx}};
    return r;
}

inline Vec3 mul(const Mat3& m, const Vec3& v)
{
    return {{dot(m[0], v), dot(m[1], v), dot(m[2], v)}};
}

inline Vec3 mulT(const Mat3& m, const Vec3& v)
{
    return {{m[0][0] * v[0] + m[1][0] * v[1] + m[2][0] * v[2],
             m[0][1] * v[0] + m[1][1] * v[1] + m[2][1] * v[2],
             m[0][2] * v[0] + m[1][2] * v[1] + m[2][2] * v[2]}};
}

} // namespace shapes_internal
} // namespace vdbclay
