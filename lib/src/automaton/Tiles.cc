// Uniform clay as tiles (see Tiles.h).
#include "automaton/Tiles.h"

#include "core/Format.h"
#include "core/LeafSlots.h"

#include <openvdb/openvdb.h>
#include <openvdb/tree/ValueAccessor.h>

#include <algorithm>
#include <limits>
#include <type_traits>
#include <utility>
#include <vector>

namespace vdbclay {
namespace automaton_internal {

namespace {

using openvdb::Coord;
using openvdb::CoordBBox;

std::string bboxStr(const CoordBBox& b)
{
    return coordStr(b.min()) + "-" + coordStr(b.max());
}

/// densifyTiles probes a region's slots one by one up to this many (else it walks the tiles).
constexpr uint64_t kProbedSlotsMax = 4096;

/// The tiles holding clay (active, nonzero) that meet @a rb, by their bounds.
std::vector<CoordBBox> clayTilesMeeting(const MassTree& tree, const CoordBBox& rb)
{
    std::vector<CoordBBox> out;
    auto it = tree.cbeginValueOn();
    it.setMaxDepth(it.getLeafDepth() - 1); // tiles only
    for (; it; ++it) {
        if (*it == 0) continue;
        CoordBBox bb;
        it.getBoundingBox(bb);
        if (bb.hasOverlap(rb)) out.push_back(bb);
    }
    return out;
}

} // namespace

TileScan scanTiles(MassTree& tree, int64_t tc, bool is3D, const std::string& grid)
{
    TileScan s;
    bool overTc = false;
    auto it = tree.beginValueAll();
    it.setMaxDepth(it.getLeafDepth() - 1); // tiles only
    for (; it; ++it) {
        const int32_t v = *it;
        if (v == 0) {
            if (it.isValueOn()) it.setValueOff();
            continue;
        }
        CoordBBox bb;
        it.getBoundingBox(bb);
        if (!it.isValueOn()) {
            throw Error("mass grid \"" + grid + "\": inactive tile " + bboxStr(bb) + " holds mass " +
                        std::to_string(v) + "; voxelize it or make it active");
        }
        if (v < 0) {
            throw Error("mass grid \"" + grid + "\": tile " + bboxStr(bb) + " holds negative mass " +
                        std::to_string(v));
        }
        if (!is3D) {
            throw Error("mass grid \"" + grid + "\": 2D clay must lie in the z = 0 layer, but tile " +
                        bboxStr(bb) + " holds mass " + std::to_string(v));
        }
        if (int64_t(v) > tc) {
            overTc = true;
            continue;
        }
        int64_t part = 0;
        if (__builtin_mul_overflow(int64_t(v), int64_t(it.getVoxelCount()), &part) ||
            __builtin_add_overflow(s.mass, part, &s.mass)) {
            throw Error("mass grid \"" + grid + "\": the total mass exceeds " +
                        std::to_string(std::numeric_limits<int64_t>::max()));
        }
        s.maxValue = std::max<int64_t>(s.maxValue, v);
    }
    // Tiles over Tc hold cells that can move: leaves, as everywhere else clay is over Tc.
    if (overTc) {
        tree.voxelizeActiveTiles();
        return scanTiles(tree, tc, is3D, grid);
    }
    return s;
}

uint64_t densifyTiles(MassTree& tree, const Box& region)
{
    if (region.empty()) return 0;
    const CoordBBox rb(Coord(region.min[0], region.min[1], region.min[2]),
                       Coord(region.max[0], region.max[1], region.max[2]));
    uint64_t made = 0;
    // A small region (a tool's bounds): its slots probed, rather than every tile of the tree walked.
    const CoordBBox slots(Coord(rb.min().x() >> 3, rb.min().y() >> 3, rb.min().z() >> 3),
                          Coord(rb.max().x() >> 3, rb.max().y() >> 3, rb.max().z() >> 3));
    if (slots.volume() <= kProbedSlotsMax) {
        openvdb::tree::ValueAccessor<MassTree> acc(tree);
        for (auto k = slots.begin(); k; ++k) {
            const Coord o((*k).x() * 8, (*k).y() * 8, (*k).z() * 8);
            if (acc.probeConstLeaf(o) || acc.getValue(o) == 0) continue;
            acc.touchLeaf(o);
            ++made;
        }
        return made;
    }
    for (const CoordBBox& tile : clayTilesMeeting(tree, rb)) {
        CoordBBox part = tile;
        part.intersect(rb);
        const Coord lo(part.min().x() & ~7, part.min().y() & ~7, part.min().z() & ~7);
        for (int64_t x = lo.x(); x <= part.max().x(); x += 8)
            for (int64_t y = lo.y(); y <= part.max().y(); y += 8)
                for (int64_t z = lo.z(); z <= part.max().z(); z += 8) {
                    tree.touchLeaf(Coord(int32_t(x), int32_t(y), int32_t(z)));
                    ++made;
                }
    }
    return made;
}

namespace {

/// Turns each of @a nodes (of one level) that holds one value and state a tile may hold (at most Tc,
/// active exactly when nonzero) into a tile of its parent at @a level. The nodes are all read before
/// any tile is added.
template <typename NodeT>
uint64_t collapseConstantNodes(MassTree& tree, int64_t tc, const std::vector<const NodeT*>& nodes,
                               openvdb::Index level)
{
    std::vector<std::pair<Coord, int32_t>> todo; // origin, value
    for (const NodeT* n : nodes) {
        int32_t v = 0;
        bool on = false;
        if (n->isConstant(v, on, 0) && int64_t(v) <= tc && on == (v != 0) && v >= 0)
            todo.emplace_back(n->origin(), v);
    }
    for (const auto& c : todo)
        tree.addTile(level, c.first, c.second, c.second != 0);
    return uint64_t(todo.size());
}

/// Collapses the leaves, then the lower, then the upper internal nodes that @a nodesOf lists for each
/// level (a collapsed lower node can make its upper node constant), and erases the root's inactive
/// background tiles, as Tree::prune does. Returns the leaves collapsed.
template <typename NodesOf> uint64_t collapseLevels(MassTree& tree, int64_t tc, NodesOf&& nodesOf)
{
    using Upper = MassTree::RootNodeType::ChildNodeType;
    using Lower = Upper::ChildNodeType;
    using Leaf = MassTree::LeafNodeType;
    const uint64_t removed = collapseConstantNodes(tree, tc, nodesOf(static_cast<const Leaf*>(nullptr)), 1);
    collapseConstantNodes(tree, tc, nodesOf(static_cast<const Lower*>(nullptr)), 2);
    collapseConstantNodes(tree, tc, nodesOf(static_cast<const Upper*>(nullptr)), 3);
    tree.root().eraseBackgroundTiles();
    return removed;
}

} // namespace

uint64_t collapseUniformLeaves(MassTree& tree, int64_t tc)
{
    return collapseLevels(tree, tc, [&](auto* tag) {
        using NodeT = std::remove_pointer_t<decltype(tag)>;
        std::vector<const NodeT*> nodes;
        static_cast<const MassTree&>(tree).getNodes(nodes);
        return nodes;
    });
}

uint64_t collapseUniformLeavesIn(MassTree& tree, int64_t tc, const std::vector<Box>& regions)
{
    // The leaf slots the regions hold, counted with their overlaps: more than the tree's leaves,
    // and the whole walk costs less.
    uint64_t slots = 0;
    for (const Box& r : regions) {
        slots += uint64_t(leafSlotCount(r));
        if (slots > tree.leafCount()) return collapseUniformLeaves(tree, tc);
    }
    // The nodes of one level meeting the regions, each once, in the order of their origins.
    return collapseLevels(tree, tc, [&](auto* tag) {
        using NodeT = std::remove_const_t<std::remove_pointer_t<decltype(tag)>>;
        const int64_t dim = int64_t(NodeT::DIM), mask = ~(dim - 1);
        std::vector<Coord> origins;
        for (const Box& r : regions) {
            if (r.empty()) continue;
            for (int64_t x = int64_t(r.min[0]) & mask; x <= r.max[0]; x += dim)
                for (int64_t y = int64_t(r.min[1]) & mask; y <= r.max[1]; y += dim)
                    for (int64_t z = int64_t(r.min[2]) & mask; z <= r.max[2]; z += dim)
                        origins.emplace_back(int32_t(x), int32_t(y), int32_t(z));
        }
        std::sort(origins.begin(), origins.end());
        origins.erase(std::unique(origins.begin(), origins.end()), origins.end());
        std::vector<const NodeT*> nodes;
        for (const Coord& o : origins)
            if (const NodeT* n = static_cast<const MassTree&>(tree).template probeConstNode<NodeT>(o))
                nodes.push_back(n);
        return nodes;
    });
}

} // namespace automaton_internal
} // namespace vdbclay
