/// @file Surface.h
/// @brief Private: the fields derived from clay that files, meshes and pictures share: the density
/// m / Tc (a fog volume) and the clay surface where a cell is half full (a level set).
#pragma once

#include "vdbclay/Fwd.h"

#include <openvdb/openvdb.h>

#include <array>
#include <memory>
#include <cstdint>
#include <vector>

namespace vdbclay {
namespace io_internal {

/// The density m / Tc of every voxel or tile holding nonzero mass, active or not (all of it is clay),
/// active there over a zero background: a GRID_FOG_VOLUME named "density" with a linear transform of
/// @a voxelSize. Built leaf by leaf in parallel on the mass tree's topology.
/// @throw Error if threshold <= 0 or voxelSize is not positive and finite.
openvdb::FloatGrid::Ptr densityGrid(const MassGrid& mass, int32_t threshold, double voxelSize);

/// The surface of @a density at @a isovalue as a narrow-band level set (GRID_LEVEL_SET, named
/// "surface", same transform): negative inside (density > isovalue), positive outside, half band
/// width 3 voxels each side. Built directly from the density by the fast sweeping method over the
/// density's voxels grown by the band, swept only within reach of the band
/// (narrowBandSdfFromDensity), in parallel; its cost follows the clay's surface. Empty (no active
/// voxels) if no cell exceeds the isovalue.
openvdb::FloatGrid::Ptr surfaceLevelSet(const openvdb::FloatGrid& density, double isovalue);

/// True if @a tree holds any tile (active or not) whose value is not 0, or any active tile: a fog the
/// leaf-by-leaf code hands to OpenVDB.
bool holdsTiles(const openvdb::FloatTree& tree);

/// For each leaf key (origin / 8) of @a keys, the indices in @a keys of its face neighbours, in the
/// order -x, +x, -y, +y, -z, +z (-1 where there is none).
std::vector<std::array<int64_t, 6>> leafFaceNeighbours(const std::vector<openvdb::Coord>& keys);

/// Leaf @a li of @a masks (active masks of leaves) grown by @a r voxels (0 < r < 8) along @a axis
/// (0 x, 1 y, 2 z), reading the leaves @a lo at -axis and @a hi at +axis (-1: none, all off).
openvdb::FloatTree::LeafNodeType::NodeMaskType
maskGrownAlong(const std::vector<openvdb::FloatTree::LeafNodeType::NodeMaskType>& masks, size_t li,
               int64_t lo, int64_t hi, int axis, int r);

/// The leaves of a density grown by a box of @a radius voxels (SurfaceFog.cc): each leaf's origin,
/// grown active mask, and the density's leaf there (null for a new leaf, all background).
struct GrownLeaves {
    std::vector<openvdb::Coord> origins;
    std::vector<openvdb::FloatTree::LeafNodeType::NodeMaskType> masks;
    std::vector<const openvdb::FloatTree::LeafNodeType*> source;
};
/// Whether growByBox can grow @a density: no tiles, and 0 < radius < 8.
bool boxGrowable(const openvdb::FloatGrid& density, int radius);
/// @a seeds' leaves (distinct origins) with their active voxels grown by a box of @a radius voxels
/// (0 < radius < 8), bit for bit what openvdb::tools::dilateActiveValues(NN_FACE_EDGE_VERTEX,
/// IGNORE_TILES) makes of a tree of those leaves: the seeds' leaves (sources kept) and the new
/// leaves holding a grown voxel (null sources).
GrownLeaves growByBox(GrownLeaves seeds, int radius);
/// The leaves surfaceFog(density, radius) has, without building them (requires boxGrowable).
GrownLeaves growByBox(const openvdb::FloatGrid& density, int radius);

/// A deep copy of @a density with its active voxels grown by @a radius voxels in every direction
/// (a box: radius iterations of the 26-neighbour dilation), bit for bit what deepCopy() and
/// openvdb::tools::dilateActiveValues(NN_FACE_EDGE_VERTEX, IGNORE_TILES) give, by three passes over
/// flat leaf masks, in parallel (SurfaceFog.cc). A density with tiles, or radius 8 or more, goes to
/// OpenVDB.
openvdb::FloatGrid::Ptr surfaceFog(const openvdb::FloatGrid& density, int radius);

/// openvdb::tools::fogToSdf(fog, isoValue) (one iteration), bit for bit, computed leaf by leaf with a
/// flat neighbour table and in parallel over each sweep's leaf diagonals (SurfaceSweep.cc); the same
/// result on any thread count. A fog holding tiles goes to OpenVDB's fogToSdf itself.
openvdb::FloatGrid::Ptr fogToSdfByLeaves(const openvdb::FloatGrid& fog, float isoValue);

/// The narrow band of half width @a band (world units) of fogToSdf(surfaceFog(density, radius),
/// isoValue), clipped and pruned: bit for bit what clipToNarrowBand gives from OpenVDB's fogToSdf.
/// Sweeps only the voxels within reach of the band (see SurfaceSweep.cc), so a lump's deep inside
/// costs nothing, builds the fog's leaves without copying the density's values into them, and clips
/// in the same pass as the sweeps' finalisation. @a band 0: fogToSdfByLeaves(surfaceFog(...)),
/// unclipped. @a swept, if given, receives the number of voxels each sweep updated (the whole fog's
/// sweepable voxels when the band could not be told apart; 0 if no sweep ran). A fog holding tiles
/// goes to OpenVDB's fogToSdf.
openvdb::FloatGrid::Ptr narrowBandSdfFromDensity(const openvdb::FloatGrid& density, int radius,
                                                 float isoValue, float band, uint64_t* swept = nullptr);

/// The tree a sweep runs over: a leaf at each of @a g's origins with its mask, its values not
/// allocated (sweepFogTree allocates and writes those of the leaves it needs), over @a background.
std::shared_ptr<openvdb::FloatTree> sweepTreeOf(const GrownLeaves& g, float background);

/// The fast sweeping method over @a tree, whose leaves and active voxels are the fog's and whose
/// values become the distances; the fog's values are read from @a source (the fog itself, or the
/// density it was grown from: a leaf of @a tree where @a source has none reads the tile or the
/// background there). @a band 0: every voxel swept, fogToSdf's values bit for bit. @a band > 0: only
/// the voxels within reach of the band (SurfaceSweep.cc), or everything where that cannot be told
/// apart (after sweeping all when the band's sweep left no value of band or more), and the result
/// clipped to the band as clipToNarrowBand does (not pruned); a leaf with no voxel next to the
/// isosurface or within reach, all on one side, becomes an inactive tile of +-band (its values,
/// allocated only where needed, are never written). Returns the number of voxels the sweeps updated
/// (each once per sweep), 0 if no sweep ran.
uint64_t sweepFogTree(openvdb::FloatTree& tree, const openvdb::FloatTree& source, float isoValue, float h,
                      float band, bool reachOnly = true);

/// The leaf keys (origin / 8) of @a density's tile slots that lie within one slot of a slot where its
/// isovalue @a isoValue may be crossed: a leaf, or a tile slot next to one on the other side of it
/// (SurfaceTiles.cc). The band's values depend on these slots' voxels and on none deeper.
std::vector<openvdb::Coord> tileSlotsNearIsosurface(const openvdb::FloatGrid& density, float isoValue);

/// narrowBandSdfFromDensity for a density holding tiles (uniform clay, 0 < radius < 8, band > 0): the
/// leaves grown by the box and the tile slots near the isosurface (tileSlotsNearIsosurface, every voxel
/// active) are swept, reading the tiles' values; the tiles deeper inside become inactive tiles of
/// -band. The band's active values are those of the density with its tiles voxelized, bit for bit, and
/// every other value has the same sign (SurfaceTiles.cc).
openvdb::FloatGrid::Ptr narrowBandSdfFromTiledDensity(const openvdb::FloatGrid& density, int radius,
                                                      float isoValue, float band, uint64_t* swept = nullptr);

/// The narrow band of @a sdf, in place: values at or beyond +-@a background become inactive and
/// exactly +-background, the background +background, inactive values +-background by their sign,
/// then pruned (what surfaceLevelSet returns, less name and class). The reference for
/// narrowBandSdfFromDensity.
void clipToNarrowBand(openvdb::FloatGrid& sdf, float background);

/// The surface of @a density at @a isovalue as polygons in index space (the density's voxel
/// centres at integer points), oriented outwards.
struct SurfaceMesh {
    std::vector<openvdb::Vec3s> points;
    std::vector<openvdb::Vec3I> triangles;
    std::vector<openvdb::Vec4I> quads;
};
SurfaceMesh surfaceMesh(const openvdb::FloatGrid& density, double isovalue);

} // namespace io_internal
} // namespace vdbclay
