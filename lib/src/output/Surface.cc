// The fields derived from clay that clay files, meshes and pictures share (Surface.h).
//
// The density m / Tc is a fog volume on the mass tree's own topology, its leaves filled in parallel
// (each leaf by one task; no topology changes in the pass). The clay surface, where a cell is half
// full, is a narrow-band level set computed from the density directly, with no mesh between: the
// density's topology grown by the band (SurfaceFog.cc), then the fast sweeping method over the voxels
// within reach of the band only (SurfaceSweep.cc), bit for bit what OpenVDB's fogToSdf and a clip to
// the band give, on any thread count. Its cost follows the clay's surface, not its bounding box. The
// surface as polygons is openvdb::tools::volumeToMesh of the density, its faces turned outward.
//
// On these stand the writers: io/ClayFile.cc (the "density" and "surface" grids of a clay file),
// SurfaceMesh.cc (OBJ and PLY files), Render.cc (PNG pictures, through Png.cc). output/ stands on
// core/ and metrics/ only.
#include "output/Surface.h"

#include "vdbclay/Types.h"

#include <openvdb/tools/ChangeBackground.h>
#include <openvdb/tools/Prune.h>
#include <openvdb/tree/LeafManager.h>
#include <openvdb/tools/VolumeToMesh.h>

#include <cmath>
#include <memory>
#include <utility>

namespace vdbclay {
namespace io_internal {

openvdb::FloatGrid::Ptr densityGrid(const MassGrid& mass, int32_t threshold, double voxelSize)
{
    if (threshold <= 0) throw Error("density: the threshold Tc must be > 0");
    if (!(voxelSize > 0) || !std::isfinite(voxelSize)) {
        throw Error("density: the voxel size must be positive and finite");
    }
    const double tc = double(threshold);
    // The mass tree's topology (every leaf and tile), then each leaf's 512 values in parallel: a
    // leaf is written by one task only, and no topology changes in the pass.
    auto tree = std::make_shared<openvdb::FloatTree>(mass.tree(), 0.f, openvdb::TopologyCopy());
    openvdb::tree::LeafManager<openvdb::FloatTree> leaves(*tree);
    leaves.foreach ([&mass, tc](openvdb::FloatTree::LeafNodeType& leaf, size_t) {
        const MassGrid::TreeType::LeafNodeType* in = mass.tree().probeConstLeaf(leaf.origin());
        for (openvdb::Index i = 0; i < openvdb::FloatTree::LeafNodeType::SIZE; ++i) {
            const int32_t m = in->getValue(i);
            if (m == 0) {
                leaf.setValueOff(i, 0.f);
            } else {
                leaf.setValueOn(i, float(double(m) / tc));
            }
        }
    });
    // Tiles holding mass (the automaton voxelizes them; a file may hold some), active or not: every
    // non-zero value is clay. Only the levels above the leaves are visited, and only non-zero tiles
    // are filled.
    auto it = mass.tree().cbeginValueAll();
    it.setMaxDepth(it.getLeafDepth() - 1); // tiles only: the voxels were done above
    for (; it; ++it) {
        if (*it == 0) continue;
        openvdb::CoordBBox box;
        it.getBoundingBox(box);
        tree->fill(box, float(double(*it) / tc), /*active=*/true);
    }
    openvdb::tools::pruneInactive(*tree); // leaves that held no clay (inactive or zero values only)
    auto density = openvdb::FloatGrid::create(tree);
    density->setName("density");
    density->setGridClass(openvdb::GRID_FOG_VOLUME);
    density->setTransform(openvdb::math::Transform::createLinearTransform(voxelSize));
    return density;
}

openvdb::FloatGrid::Ptr surfaceLevelSet(const openvdb::FloatGrid& density, double isovalue)
{
    constexpr int kHalfWidth = 3; // voxels on each side of the surface
    const float background = float(kHalfWidth * density.voxelSize()[0]);
    bool anyInside = false;
    for (auto it = density.tree().cbeginValueOn(); it && !anyInside; ++it)
        anyInside = *it > isovalue;
    openvdb::FloatGrid::Ptr surface;
    if (!anyInside) {
        surface = openvdb::FloatGrid::create(background);
        surface->setTransform(density.transform().copy());
    } else {
        // Directly from the fog, no mesh round trip: the density's topology grown by the band (the
        // new voxels hold 0, outside), then the fast sweeping method solves the eikonal equation
        // from the isosurface over those voxels. The cost follows the clay's voxels, not the span
        // of its bounding box (far-apart lumps cost what each lump costs).
        // Only the band is kept, so only the voxels within its reach are swept (narrowBandSdfFromDensity:
        // the same band as sweeping the whole fog, bit for bit).
        surface = narrowBandSdfFromDensity(density, kHalfWidth + 1, float(isovalue), background);
    }
    surface->setName("surface");
    surface->setGridClass(openvdb::GRID_LEVEL_SET);
    return surface;
}

void clipToNarrowBand(openvdb::FloatGrid& sdf, float background)
{
    // Values beyond the half width become inactive, signed background values.
    openvdb::tree::LeafManager<openvdb::FloatTree> leaves(sdf.tree());
    leaves.foreach ([background](openvdb::FloatTree::LeafNodeType& leaf, size_t) {
        for (auto v = leaf.beginValueOn(); v; ++v) {
            if (*v >= background) {
                v.setValueOff();
                v.setValue(background);
            } else if (*v <= -background) {
                v.setValueOff();
                v.setValue(-background);
            }
        }
    });
    openvdb::tools::changeLevelSetBackground(sdf.tree(), background);
    openvdb::tools::pruneLevelSet(sdf.tree());
}

SurfaceMesh surfaceMesh(const openvdb::FloatGrid& density, double isovalue)
{
    SurfaceMesh mesh;
    // Mesh in index space: a unit transform copy sharing the tree.
    openvdb::FloatGrid::ConstPtr indexGrid = density.copyReplacingMetadataAndTransform(
        density, openvdb::math::Transform::createLinearTransform(1.0));
    openvdb::tools::volumeToMesh(*indexGrid, mesh.points, mesh.triangles, mesh.quads, isovalue);
    // volumeToMesh winds fog-volume faces inwards (measured: the signed volume of the mesh of a
    // ball of full cells is negative); reverse them so normals point out of the clay.
    for (auto& t : mesh.triangles)
        std::swap(t[1], t[2]);
    for (auto& q : mesh.quads)
        std::swap(q[1], q[3]);
    return mesh;
}

} // namespace io_internal
} // namespace vdbclay
