/// @file SurfaceMesh.h
/// @brief The clay surface as a polygon mesh file (OBJ, PLY, STL) in world units.
#pragma once

#include "vdbclay/Fwd.h"

#include <cstdint>
#include <string>

namespace vdbclay {

/// Writes the clay surface (openvdb::tools::volumeToMesh of the density at isovalue 0.5, i.e. where
/// a cell is half full) as OBJ or PLY (ASCII) or STL (binary), chosen by @a path's extension, in world units:
/// the vertices go through @a mass's transform (as read from a clay file, or set by setClayTransform in
/// IO.h), so the mesh lies on the .vdb and loadMesh() with the same voxel size and up axis puts it
/// back on the same voxels. With @a keepClayVolume, every vertex then moves along its normal by one
/// distance (at most half a voxel) so that the mesh encloses the clay's volume (the sum of
/// min(mass / Tc, 1) over the cells): marching cubes cuts convex edges and rounds convex surfaces
/// inward, and mesh clay made from the mesh then keeps the clay's volume. Atomic like writeClayFile.
/// @param threshold Tc, the mass of a full cell (> 0).
/// @param isovalue the density of the surface (positive and finite; 0.5 by default).
/// @throw Error on an unknown extension, an isovalue that is not positive and finite, a grid holding
///        no clay, no cell as full as @a isovalue, or a write failure.
void writeSurfaceMesh(const std::string& path, const MassGrid& mass, int32_t threshold, double isovalue = 0.5,
                      bool keepClayVolume = false);

} // namespace vdbclay
