#include "Surface.h"

#include "vdbclay/Types.h"

#include <openvdb/tools/LevelSetRebuild.h>
#include <openvdb/tools/VolumeToMesh.h>

#include <cmath>
#include <utility>

namespace vdbclay {
namespace io_internal {

openvdb::math::Transform::Ptr clayTransform(double voxelSize, UpAxis up)
{
    if (!(voxelSize > 0) || !std::isfinite(voxelSize)) {
        throw Error("the voxel size must be positive and finite");
    }
    if (up == UpAxis::Y) return openvdb::math::Transform::createLinearTransform(voxelSize);
    // Rx(+90 deg) exactly (no rounding in sin and cos): (x, y, z) -> (x, -z, y), then scaled.
    // OpenVDB maps row vectors (world = index * M): row i is the image of index axis i.
    const double v = voxelSize;
    return openvdb::math::Transform::createLinearTransform(
        openvdb::Mat4d(v, 0., 0., 0., /**/ 0., 0., v, 0., /**/ 0., -v, 0., 0., /**/ 0., 0., 0., 1.));
}

openvdb::FloatGrid::Ptr densityGrid(const MassGrid& mass, int32_t threshold, double voxelSize)
{
    if (threshold <= 0) throw Error("density: the threshold Tc must be > 0");
    if (!(voxelSize > 0) || !std::isfinite(voxelSize)) {
        throw Error("density: the voxel size must be positive and finite");
    }
    auto density = openvdb::FloatGrid::create(0.f);
    density->setName("density");
    density->setGridClass(openvdb::GRID_FOG_VOLUME);
    density->setTransform(openvdb::math::Transform::createLinearTransform(voxelSize));
    auto acc = density->getAccessor();
    const double tc = double(threshold);
    for (auto it = mass.tree().cbeginValueAll(); it; ++it) {
        const int32_t m = *it;
        if (m == 0) continue;
        const float d = float(double(m) / tc);
        if (it.isVoxelValue()) {
            acc.setValueOn(it.getCoord(), d);
        } else {
            openvdb::CoordBBox box;
            it.getBoundingBox(box);
            density->tree().fill(box, d, /*active=*/true);
        }
    }
    return density;
}

openvdb::FloatGrid::Ptr surfaceLevelSet(const openvdb::FloatGrid& density, double isovalue)
{
    openvdb::FloatGrid::Ptr surface;
    if (density.tree().activeVoxelCount() == 0) {
        surface = openvdb::FloatGrid::create(float(3 * density.voxelSize()[0]));
        surface->setTransform(density.transform().copy());
    } else {
        // levelSetRebuild meshes the fog volume (outward faces: volumeToMesh knows fog volumes
        // are inside above the isovalue) and converts the closed mesh back; meshToVolume decides
        // the sign by flood fill, so it is negative inside whatever the face orientation.
        surface = openvdb::tools::levelSetRebuild(density, float(isovalue), 3.f, 3.f,
                                                  &density.transform());
    }
    surface->setName("surface");
    surface->setGridClass(openvdb::GRID_LEVEL_SET);
    return surface;
}

SurfaceMesh surfaceMesh(const openvdb::FloatGrid& density, double isovalue)
{
    SurfaceMesh mesh;
    // Mesh in index space: a unit transform copy sharing the tree.
    openvdb::FloatGrid::ConstPtr indexGrid =
        density.copyReplacingMetadataAndTransform(density, openvdb::math::Transform::createLinearTransform(1.0));
    openvdb::tools::volumeToMesh(*indexGrid, mesh.points, mesh.triangles, mesh.quads, isovalue);
    // volumeToMesh winds fog-volume faces inwards (measured: the signed volume of the mesh of a
    // ball of full cells is negative); reverse them so normals point out of the clay.
    for (auto& t : mesh.triangles) std::swap(t[1], t[2]);
    for (auto& q : mesh.quads) std::swap(q[1], q[3]);
    return mesh;
}

} // namespace io_internal
} // namespace vdbclay
