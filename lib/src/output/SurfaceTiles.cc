// The clay surface of a density holding tiles (uniform clay): swept over the leaves near its isosurface.
//
// A voxel of the surface's band (|value| < band) depends only on the fog's voxels within a few face
// steps of the isosurface (SurfaceSweep.cc: the band of 3 voxels, within 7 of a voxel next to the
// isosurface). The isosurface of a density with tiles passes only through its leaves and between
// slots on opposite sides of the isovalue (value < iso against value >= iso), since a tile holds one
// value. So the slots where it may pass are the leaves and the tile slots next to a slot on the other
// side (found a slot at a time on masks of slot keys: the side's tiles minus their erosion, the other
// side's tiles within their dilation), and every voxel the band depends on lies within one slot of
// them. The sweep runs over the density's active voxels and every voxel of those tile slots (as in the
// voxelized density, whose tile voxels are all active clay), grown by the box as the density's fog is
// grown (surfaceFog), reading each leaf's fog values from the density: a leaf over a tile reads the
// tile's value. The voxels of the deeper tiles are never swept: where their value is over
// the isovalue they are inside, so the result holds them as inactive tiles of -band (the voxelized
// density's clipped values there); elsewhere the background (+band) says outside. The band's values
// are those of the voxelized density's, bit for bit (tests/TestSurface.cc), at the cost of the
// clay's surface rather than its volume.
#include "output/Surface.h"

#include <openvdb/tools/Morphology.h>
#include <openvdb/tools/Prune.h>

#include <algorithm>
#include <set>
#include <vector>

namespace vdbclay {
namespace io_internal {

namespace {

using FloatTree = openvdb::FloatTree;
using LeafT = FloatTree::LeafNodeType;
using openvdb::Coord;
using openvdb::CoordBBox;

constexpr int kDim = int(LeafT::DIM);

/// Floor of @a v / 8: the key of the slot holding coordinate v.
inline int32_t keyOf(int32_t v)
{
    return v >= 0 ? v / kDim : -((-v + kDim - 1) / kDim);
}
inline Coord keyOf(const Coord& c)
{
    return Coord(keyOf(c.x()), keyOf(c.y()), keyOf(c.z()));
}

/// The active values of @a mask, voxel by voxel (tiles expanded), in tree order.
std::vector<Coord> voxelsOf(const openvdb::MaskTree& mask)
{
    std::vector<Coord> out;
    for (auto it = mask.cbeginValueOn(); it; ++it) {
        CoordBBox bb;
        it.getBoundingBox(bb);
        for (auto c = bb.begin(); c; ++c)
            out.push_back(*c);
    }
    return out;
}

} // namespace

std::vector<Coord> tileSlotsNearIsosurface(const openvdb::FloatGrid& density, float isoValue)
{
    using openvdb::tools::EXPAND_TILES;
    using openvdb::tools::NN_FACE_EDGE_VERTEX;
    openvdb::MaskTree leafSlots(false), above(false), below(false); // by slot key
    for (auto it = density.tree().cbeginLeaf(); it; ++it)
        leafSlots.setValueOn(keyOf(it->origin()));
    auto tile = density.tree().cbeginValueAll();
    tile.setMaxDepth(tile.getLeafDepth() - 1);
    for (; tile; ++tile) {
        if (*tile == density.tree().background() && !tile.isValueOn()) continue;
        CoordBBox bb;
        tile.getBoundingBox(bb);
        (*tile < isoValue ? below : above).fill(CoordBBox(keyOf(bb.min()), keyOf(bb.max())), true, true);
    }
    // Where the isovalue may be crossed: the leaves, the tile slots above it next to a slot that is
    // neither above it nor a leaf (a crossing with a leaf's voxel lies within a slot of the leaf), and
    // the tile slots below it next to one above.
    openvdb::MaskTree aboveInside(above);
    aboveInside.topologyUnion(leafSlots);
    openvdb::tools::erodeActiveValues(aboveInside, 1, NN_FACE_EDGE_VERTEX, EXPAND_TILES);
    openvdb::MaskTree crossing(above);
    crossing.topologyDifference(aboveInside);
    openvdb::MaskTree aboveGrown(above);
    openvdb::tools::dilateActiveValues(aboveGrown, 1, NN_FACE_EDGE_VERTEX, EXPAND_TILES);
    openvdb::MaskTree belowEdge(below);
    belowEdge.topologyIntersection(aboveGrown);
    crossing.topologyUnion(belowEdge);
    crossing.topologyUnion(leafSlots);
    // Grown by a slot, cut to the tiles' slots.
    openvdb::tools::dilateActiveValues(crossing, 1, NN_FACE_EDGE_VERTEX, EXPAND_TILES);
    openvdb::MaskTree tiles(above);
    tiles.topologyUnion(below);
    crossing.topologyIntersection(tiles);
    return voxelsOf(crossing);
}

openvdb::FloatGrid::Ptr narrowBandSdfFromTiledDensity(const openvdb::FloatGrid& density, int radius,
                                                      float isoValue, float band, uint64_t* swept)
{
    // The sweep's voxels: the density's active voxels and every voxel of the tile slots near the
    // isosurface (as in the voxelized density, whose tiles' voxels are all active), grown by the box
    // surfaceFog grows the density by (growByBox), kept in the leaves holding one.
    GrownLeaves seeds;
    for (auto it = density.tree().cbeginLeaf(); it; ++it) {
        seeds.origins.push_back(it->origin());
        seeds.masks.push_back(it->getValueMask());
    }
    for (const Coord& key : tileSlotsNearIsosurface(density, isoValue)) {
        seeds.origins.emplace_back(key.x() * kDim, key.y() * kDim, key.z() * kDim);
        seeds.masks.emplace_back(true);
    }
    seeds.source.resize(seeds.origins.size(), nullptr);
    GrownLeaves g = growByBox(std::move(seeds), radius);
    size_t kept = 0; // the leaves holding a voxel of the sweep
    for (size_t i = 0; i < g.origins.size(); ++i) {
        if (g.masks[i].isOff()) continue;
        g.origins[kept] = g.origins[i];
        g.masks[kept] = g.masks[i];
        ++kept;
    }
    g.origins.resize(kept);
    g.masks.resize(kept);
    g.source.resize(kept);
    std::shared_ptr<FloatTree> tree = sweepTreeOf(g, density.tree().background());
    // The tree holds the masks now; freed before the sweep, which holds the peak.
    decltype(g.masks)().swap(g.masks);
    decltype(g.source)().swap(g.source);
    const uint64_t count = sweepFogTree(*tree, density.tree(), isoValue, float(density.voxelSize()[0]), band);
    if (swept) *swept = count;

    // The tiles over the isovalue, inside: inactive -band, as whole tiles where no leaf of the sweep
    // lies in them, slot by slot where one does.
    std::set<Coord> split; // origins of density tiles holding a leaf of the sweep
    {
        openvdb::tree::ValueAccessor<const FloatTree> acc(density.tree());
        for (const Coord& o : g.origins) {
            const int depth = acc.getValueDepth(o);
            if (depth < 0 || depth == int(FloatTree::DEPTH) - 1) continue; // background or a leaf
            const int level = int(FloatTree::DEPTH) - 1 - depth;           // 1: 8^3, 2: 128^3, 3: 4096^3
            const int32_t side = level == 1 ? 8 : level == 2 ? 128 : 4096;
            auto floorTo = [side](int32_t v) {
                return v >= 0 ? v / side * side : -((-v + side - 1) / side) * side;
            };
            split.insert(Coord(floorTo(o.x()), floorTo(o.y()), floorTo(o.z())));
        }
    }
    auto tile = density.tree().cbeginValueAll();
    tile.setMaxDepth(tile.getLeafDepth() - 1);
    std::vector<std::pair<CoordBBox, openvdb::Index>> inside; // bounds and level
    for (; tile; ++tile) {
        if (!(*tile > isoValue)) continue;
        CoordBBox bb;
        tile.getBoundingBox(bb);
        inside.emplace_back(bb, tile.getLevel());
    }
    for (const auto& t : inside) {
        const CoordBBox& bb = t.first;
        if (!split.count(bb.min())) {
            tree->addTile(t.second, bb.min(), -band, false);
            continue;
        }
        for (int32_t x = bb.min().x(); x <= bb.max().x(); x += kDim)
            for (int32_t y = bb.min().y(); y <= bb.max().y(); y += kDim)
                for (int32_t z = bb.min().z(); z <= bb.max().z(); z += kDim) {
                    const Coord o(x, y, z);
                    if (!tree->probeConstLeaf(o)) tree->addTile(1, o, -band, false);
                }
    }
    openvdb::tools::pruneLevelSet(*tree);
    openvdb::FloatGrid::Ptr sdf = density.copyWithNewTree();
    sdf->setTree(tree);
    return sdf;
}

} // namespace io_internal
} // namespace vdbclay
