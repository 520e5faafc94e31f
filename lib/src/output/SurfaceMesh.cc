// The clay surface as a mesh file (SurfaceMesh.h): volumeToMesh of the density (Surface.h), in
// world units through the grid's transform, optionally moved along its normals to enclose the clay's
// volume, written as ASCII OBJ or PLY or binary STL (triangles only) atomically (core/AtomicFile.h).
#include "vdbclay/SurfaceMesh.h"

#include "vdbclay/Metrics.h"
#include "vdbclay/Types.h"

#include "core/AtomicFile.h"
#include "output/Surface.h"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <iomanip>
#include <ostream>
#include <vector>

#ifndef VDBCLAY_VERSION
#define VDBCLAY_VERSION "unknown"
#endif

namespace vdbclay {

using namespace io_internal;

namespace {

/// Moves every vertex of @a mesh (index space, outward faces) along its normal by one distance,
/// so that the mesh encloses @a target voxels: marching cubes cuts convex edges and rounds convex
/// surfaces inward. Two Newton steps (volume' = area); the move is at most half a voxel.
void keepVolume(SurfaceMesh& mesh, double target)
{
    std::vector<std::array<uint32_t, 3>> tris;
    tris.reserve(mesh.triangles.size() + 2 * mesh.quads.size());
    for (const auto& t : mesh.triangles)
        tris.push_back({{t[0], t[1], t[2]}});
    for (const auto& q : mesh.quads) {
        tris.push_back({{q[0], q[1], q[2]}});
        tris.push_back({{q[0], q[2], q[3]}});
    }
    for (int iteration = 0; iteration < 2; ++iteration) {
        std::vector<openvdb::Vec3d> normals(mesh.points.size(), openvdb::Vec3d(0.0));
        double volume = 0, area = 0;
        for (const auto& t : tris) {
            const openvdb::Vec3d a(mesh.points[t[0]]), b(mesh.points[t[1]]), c(mesh.points[t[2]]);
            const openvdb::Vec3d n = (b - a).cross(c - a); // twice the area, outward
            volume += a.dot(b.cross(c)) / 6;
            area += n.length() / 2;
            for (int i = 0; i < 3; ++i)
                normals[t[i]] += n;
        }
        if (!(area > 0)) return;
        const double shift = std::max(-0.5, std::min(0.5, (target - volume) / area));
        for (size_t i = 0; i < mesh.points.size(); ++i) {
            const double l = normals[i].length();
            if (l > 0)
                mesh.points[i] = openvdb::Vec3s(openvdb::Vec3d(mesh.points[i]) + normals[i] * (shift / l));
        }
    }
}

/// Binary STL (little endian): an 80-byte header, the triangle count, then per triangle its unit
/// normal, its three vertices (float32) and a zero attribute word.
void writeBinaryStl(std::ostream& os, const SurfaceMesh& mesh, size_t faces, double isovalue,
                    double voxelSize)
{
    char header[80] = {};
    std::snprintf(header, sizeof header, "vdbclay %s clay surface at density %g (world units, voxel size %g)",
                  VDBCLAY_VERSION, isovalue, voxelSize);
    os.write(header, sizeof header);
    const uint32_t n = uint32_t(faces);
    os.write(reinterpret_cast<const char*>(&n), 4);
    auto triangle = [&](uint32_t a, uint32_t b, uint32_t c) {
        const openvdb::Vec3s &pa = mesh.points[a], &pb = mesh.points[b], &pc = mesh.points[c];
        openvdb::Vec3s normal = (pb - pa).cross(pc - pa);
        const float l = normal.length();
        normal = l > 0 ? normal / l : openvdb::Vec3s(0.f);
        float v[12];
        for (int i = 0; i < 3; ++i) {
            v[i] = normal[i];
            v[3 + i] = pa[i];
            v[6 + i] = pb[i];
            v[9 + i] = pc[i];
        }
        char rec[50] = {};
        std::memcpy(rec, v, sizeof v);
        os.write(rec, sizeof rec);
    };
    for (const auto& t : mesh.triangles)
        triangle(t[0], t[1], t[2]);
    for (const auto& q : mesh.quads) {
        triangle(q[0], q[1], q[2]);
        triangle(q[0], q[2], q[3]);
    }
}

} // namespace

void writeSurfaceMesh(const std::string& path, const MassGrid& mass, int32_t threshold, double isovalue,
                      bool keepClayVolume)
{
    openvdb::initialize();
    const std::string ext = extensionOf(path);
    if (ext != ".obj" && ext != ".ply" && ext != ".stl") {
        throw Error("cannot write " + path + ": unknown mesh format \"" + ext +
                    "\" (use .obj, .ply or .stl)");
    }
    if (!(isovalue > 0) || !std::isfinite(isovalue)) {
        throw Error("cannot write " + path + ": the isovalue must be positive and finite");
    }
    if (clayVoxelCount(mass) == 0) throw Error("cannot write " + path + ": the grid holds no clay");

    SurfaceMesh mesh;
    try {
        auto density = densityGrid(mass, threshold, 1.0);
        mesh = surfaceMesh(*density, isovalue);
        if (keepClayVolume && !mesh.points.empty()) {
            // The clay's volume: each cell counts for its fill, up to 1.
            double volume = 0;
            for (auto it = mass.cbeginValueOn(); it; ++it)
                volume += std::min(1.0, double(*it) / double(threshold)) * double(it.getVoxelCount());
            keepVolume(mesh, volume);
        }
    } catch (const Error& e) {
        throw Error("cannot write " + path + ": " + e.what());
    }
    if (mesh.points.empty() || (mesh.triangles.empty() && mesh.quads.empty())) {
        throw Error("cannot write " + path + ": no surface at density " + std::to_string(isovalue) +
                    " (no cell is that full)");
    }
    // World units: the vertices go through the grid's transform (voxel size, up axis), so the mesh
    // lies where the .vdb's grids lie in Blender or Houdini, and loadMesh with the same voxel size
    // and up axis puts it back on the same voxels.
    const openvdb::math::Transform& xform = mass.transform();
    for (auto& p : mesh.points)
        p = openvdb::Vec3s(xform.indexToWorld(openvdb::Vec3d(p)));

    // Quads are split into two triangles, so both formats hold triangles only.
    const size_t faces = mesh.triangles.size() + 2 * mesh.quads.size();
    writeAtomically(path, [&](std::ostream& os) {
        os << std::setprecision(9);
        if (ext == ".obj") {
            os << "# vdbclay " << VDBCLAY_VERSION << " clay surface at density " << isovalue
               << " (world units, voxel size " << xform.voxelSize()[0] << ")\n";
            os << "# " << mesh.points.size() << " vertices, " << faces << " triangles\n";
            for (const auto& p : mesh.points)
                os << "v " << p[0] << ' ' << p[1] << ' ' << p[2] << '\n';
            for (const auto& t : mesh.triangles) {
                os << "f " << t[0] + 1 << ' ' << t[1] + 1 << ' ' << t[2] + 1 << '\n';
            }
            for (const auto& q : mesh.quads) {
                os << "f " << q[0] + 1 << ' ' << q[1] + 1 << ' ' << q[2] + 1 << '\n';
                os << "f " << q[0] + 1 << ' ' << q[2] + 1 << ' ' << q[3] + 1 << '\n';
            }
        } else if (ext == ".stl") {
            writeBinaryStl(os, mesh, faces, isovalue, xform.voxelSize()[0]);
        } else {
            os << "ply\nformat ascii 1.0\n";
            os << "comment vdbclay " << VDBCLAY_VERSION << " clay surface at density " << isovalue
               << " (world units, voxel size " << xform.voxelSize()[0] << ")\n";
            os << "element vertex " << mesh.points.size() << "\n";
            os << "property float x\nproperty float y\nproperty float z\n";
            os << "element face " << faces << "\n";
            os << "property list uchar int vertex_indices\nend_header\n";
            for (const auto& p : mesh.points)
                os << p[0] << ' ' << p[1] << ' ' << p[2] << '\n';
            for (const auto& t : mesh.triangles) {
                os << "3 " << t[0] << ' ' << t[1] << ' ' << t[2] << '\n';
            }
            for (const auto& q : mesh.quads) {
                os << "3 " << q[0] << ' ' << q[1] << ' ' << q[2] << '\n';
                os << "3 " << q[0] << ' ' << q[2] << ' ' << q[3] << '\n';
            }
        }
    });
}

} // namespace vdbclay
