// Coverage: how much of each voxel a shape covers, for clay that keeps a mesh's or level set's volume.
//
// Analytic shapes (spheres, boxes, ... in voxel indices) fill a voxel by its centre
// (forEachVoxelInside). Meshes and level sets stand for a volume in world units; clay made from them
// gives each boundary voxel round(m0 x covered fraction) (makeClay, MakeClay.cc), so its mass is the
// volume x m0 however the surface falls between voxel centres.
//
// Closed meshes: exact, by column integrals. Along a vertical line the inside of a closed,
// consistently oriented mesh is a union of intervals, entered through faces whose normal points down
// and left through faces whose normal points up; the inside length of voxel k's slab
// [k - 1/2, k + 1/2] is the sum over the crossings z_i below its top t of -s_i min(t - z_i, 1)
// (s_i = +1 for an upward face). Integrated over the voxel's column square this is, for each
// triangle clipped to that square (a polygon P, signed projected area A), I(t) - I(t - 1) with
// I(t) = integral over the part of P below t of (t - z) = t A(P ∩ z<t) - integral of z over it, and
// -A for every voxel above the triangle (a running sum up the column). Triangles contribute only to
// the columns and slabs they pass through; the interior is filled by the running sum. The same sum
// over a non-manifold but consistently oriented mesh is the winding number's integral, clamped to 1.
// A trilinear level set cannot give this: interpolating the distance across a convex edge or corner
// rounds it inward (4^3 sign samples of the mesh's level set lose 2.4 % at edges; tests/TestInterop.cc
// measures them against this).
//
// Everything else (level sets, meshes that are open or inconsistently oriented, shapes placed by a
// transform, 2D clay): clamp(1/2 - d, 0, 1) from the signed distance d at the voxel centre, the part
// of the voxel below a plane at distance d, averaged over the plane's orientations (Shapes.h, makeClay).

#include "shapes/Coverage.h"
#include "shapes/DistanceCoverage.h"
#include "shapes/Voxels.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <unordered_map>
#include <utility>

namespace vdbclay {

namespace shapes_internal {

namespace {

constexpr int kMaxPolygon = 16; // a triangle clipped by 5 planes has at most 8 corners

struct Polygon {
    Vec3 v[kMaxPolygon];
    int n = 0;
};

/// The part of @a in where p[axis] <= c (@a below) or p[axis] >= c (Sutherland-Hodgman); new corners
/// lie exactly on the plane.
Polygon clip(const Polygon& in, int axis, double c, bool below)
{
    Polygon out;
    for (int i = 0; i < in.n; ++i) {
        const Vec3& a = in.v[i];
        const Vec3& b = in.v[(i + 1) % in.n];
        const double da = below ? a[axis] - c : c - a[axis];
        const double db = below ? b[axis] - c : c - b[axis];
        if (da <= 0) out.v[out.n++] = a;
        if ((da < 0 && db > 0) || (da > 0 && db < 0)) {
            const double t = da / (da - db);
            Vec3 m;
            for (int k = 0; k < 3; ++k)
                m[k] = a[k] + t * (b[k] - a[k]);
            m[axis] = c;
            out.v[out.n++] = m;
        }
    }
    return out;
}

/// The signed area of @a q projected on xy (positive when it turns counter-clockwise seen from +z,
/// i.e. faces up) and the integral of z over that projection.
void areaAndZ(const Polygon& q, double& area, double& zIntegral)
{
    area = 0;
    zIntegral = 0;
    for (int i = 1; i + 1 < q.n; ++i) {
        const Vec3 &o = q.v[0], &a = q.v[i], &b = q.v[i + 1];
        const double s = 0.5 * ((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]));
        area += s;
        zIntegral += s * (o[2] + a[2] + b[2]) / 3.0;
    }
}

int32_t slabOf(double v)
{
    return int32_t(std::floor(v + 0.5));
}

} // namespace

bool isOrientedClosed(const std::vector<std::array<uint32_t, 3>>& triangles)
{
    std::unordered_map<uint64_t, int64_t> balance; // key: smaller, larger vertex; +1 for small -> large
    balance.reserve(triangles.size() * 3);
    for (const auto& t : triangles) {
        for (int i = 0; i < 3; ++i) {
            const uint32_t a = t[i], b = t[(i + 1) % 3];
            if (a < b)
                ++balance[(uint64_t(a) << 32) | b];
            else
                --balance[(uint64_t(b) << 32) | a];
        }
    }
    for (const auto& e : balance)
        if (e.second != 0) return false;
    return true;
}

void meshCoverage(const std::vector<Vec3>& points, const std::vector<std::array<uint32_t, 3>>& triangles,
                  const std::function<void(int32_t, int32_t, int32_t, double)>& covered)
{
    // Outward (positive signed volume): the inside length is minus the sum over crossings.
    double volume6 = 0;
    for (const auto& t : triangles) {
        const Vec3 &a = points[t[0]], &b = points[t[1]], &c = points[t[2]];
        volume6 += a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
                   a[2] * (b[0] * c[1] - b[1] * c[0]);
    }
    const double sign = volume6 > 0 ? -1.0 : 1.0;

    // Per column (x, y), per slab z: {direct contribution, step of the running sum}.
    std::map<std::pair<int32_t, int32_t>, std::map<int32_t, std::array<double, 2>>> columns;
    for (const auto& t : triangles) {
        Polygon tri;
        tri.n = 3;
        Vec3 lo = points[t[0]], hi = points[t[0]];
        for (int i = 0; i < 3; ++i) {
            tri.v[i] = points[t[i]];
            for (int k = 0; k < 3; ++k) {
                lo[k] = std::min(lo[k], tri.v[i][k]);
                hi[k] = std::max(hi[k], tri.v[i][k]);
            }
        }
        for (int32_t x = slabOf(lo[0]); x <= slabOf(hi[0]); ++x) {
            const Polygon px = clip(clip(tri, 0, x - 0.5, false), 0, x + 0.5, true);
            if (px.n < 3) continue;
            for (int32_t y = slabOf(lo[1]); y <= slabOf(hi[1]); ++y) {
                const Polygon p = clip(clip(px, 1, y - 0.5, false), 1, y + 0.5, true);
                if (p.n < 3) continue;
                double area, zIntegral;
                areaAndZ(p, area, zIntegral);
                if (area == 0) continue; // vertical: no crossing
                double zMin = p.v[0][2], zMax = p.v[0][2];
                for (int i = 1; i < p.n; ++i) {
                    zMin = std::min(zMin, p.v[i][2]);
                    zMax = std::max(zMax, p.v[i][2]);
                }
                auto& column = columns[{x, y}];
                double below = 0; // I(k - 1/2); 0 under the polygon
                const int32_t k0 = slabOf(zMin), k1 = slabOf(zMax);
                for (int32_t k = k0; k <= k1; ++k) {
                    const double top = k + 0.5;
                    double a = area, z = zIntegral;
                    if (top < zMax) areaAndZ(clip(p, 2, top, true), a, z);
                    const double upTo = top * a - z;
                    column[k][0] += sign * (upTo - below);
                    below = upTo;
                }
                column[k1 + 1][1] += sign * area; // every slab above the polygon: its whole area
            }
        }
    }
    for (const auto& [xy, column] : columns) {
        if (column.empty()) continue;
        double running = 0;
        auto it = column.begin();
        const int32_t last = column.rbegin()->first;
        for (int32_t z = column.begin()->first; z <= last; ++z) {
            double direct = 0;
            if (it != column.end() && it->first == z) {
                direct = it->second[0];
                running += it->second[1];
                ++it;
            }
            const double f = std::min(running + direct, 1.0);
            if (f > 0) covered(xy.first, xy.second, z, f);
        }
    }
}

void forEachVoxelCovered(const Shape& shape, int dimensions,
                         const std::function<void(int32_t, int32_t, int32_t, double)>& covered)
{
    if (shape.coverage(dimensions, covered)) return;
    Box b = shape.bounds();
    if (b.empty()) return;
    // A voxel whose centre lies up to half a voxel outside holds a part: one voxel of margin.
    for (int i = 0; i < 3; ++i) {
        b.min[i] -= 1;
        b.max[i] += 1;
    }
    if (dimensions == 2) {
        b.min[2] = b.min[2] > 0 ? b.min[2] : 0;
        b.max[2] = b.max[2] < 0 ? b.max[2] : 0;
    }
    if (b.empty()) return;
    if (dimensions == 3) {
        // Planes, edges and corners recognised in the distance field (DistanceCoverage.cc).
        distanceCoverage(shape, b, covered);
        return;
    }
    // 2D: the z = 0 layer by the ramp (the 3D distance's planes do not bound a 2D section).
    for (int32_t x = b.min[0]; x <= b.max[0]; ++x)
        for (int32_t y = b.min[1]; y <= b.max[1]; ++y)
            for (int32_t z = b.min[2]; z <= b.max[2]; ++z) {
                const double f = 0.5 - shape.distance(Vec3{{double(x), double(y), double(z)}});
                if (f > 0) covered(x, y, z, std::min(f, 1.0));
            }
}

} // namespace shapes_internal
} // namespace vdbclay
