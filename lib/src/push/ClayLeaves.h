// The clay near a box: the push and the tools' placement visit only these leaves, so their cost
// follows the clay a tool's bounds hold, not the volume of those bounds.
//
// Clay lies in leaves and in tiles (uniform clay, automaton/Tiles.h). claySlotsNear() gives the leaf
// slots holding clay either way, and clayInSlotsNear() their clay and voxel counts: what the slots'
// leaves would give if the tiles were voxelized, so decisions taken on them do not depend on the
// tree's layout. leavesNear() gives leaves alone, for code that walks their voxels (the push densifies
// its tools' bounds first: Automaton::densify).
//
// leavesNear() finds the mass leaves that overlap a box by probing the box's leaf slots or by
// walking every leaf, whichever is fewer (so the cost is min(slots of the box, leaves of the
// tree)); the result is in slot order (x, then y, then z, of the leaf origins), the same on every
// call and thread count.
//
// narrowedEditRegion() shrinks a region that an Automaton::edit() or editObstacles() would rescan
// and wake to the part near the clay, waking exactly the same clay blocks: the automaton wakes every
// block anchored in a leaf slot within one voxel of the region (Candidates::addPending), and only a
// block holding clay can change; such a block's anchor slot lies within one slot of a clay leaf. So
// the region cut to the clay leaves near it, grown by 16 voxels, wakes the same blocks that hold
// clay (blocks without clay change nothing: the same state, only fewer blocks examined) and rescans
// the same clay leaves (every clay leaf that meets the region lies inside the cut).
#pragma once

#include "vdbclay/Types.h"

#include "core/LeafSlots.h"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <climits>
#include <cstdint>
#include <vector>

namespace vdbclay {
namespace clay_internal {

using MassLeafT = openvdb::Int32Tree::LeafNodeType;

inline bool originLess(const openvdb::Coord& a, const openvdb::Coord& b)
{
    return a < b; // x, then y, then z
}

/// The leaves of @a tree that overlap @a b, in origin order.
inline std::vector<const MassLeafT*> leavesNear(const openvdb::Int32Tree& tree, const Box& b)
{
    std::vector<const MassLeafT*> out;
    if (b.empty()) return out;
    const openvdb::CoordBBox bb(openvdb::Coord(b.min[0], b.min[1], b.min[2]),
                                openvdb::Coord(b.max[0], b.max[1], b.max[2]));
    if (leafSlotCount(b) <= int64_t(tree.leafCount())) {
        for (int64_t x = b.min[0] & ~7; x <= b.max[0]; x += 8)
            for (int64_t y = b.min[1] & ~7; y <= b.max[1]; y += 8)
                for (int64_t z = b.min[2] & ~7; z <= b.max[2]; z += 8)
                    if (const MassLeafT* l =
                            tree.probeConstLeaf(openvdb::Coord(int32_t(x), int32_t(y), int32_t(z))))
                        out.push_back(l);
        return out;
    }
    for (auto it = tree.cbeginLeaf(); it; ++it)
        if (it->getNodeBoundingBox().hasOverlap(bb)) out.push_back(&*it);
    std::sort(out.begin(), out.end(),
              [](const MassLeafT* p, const MassLeafT* q) { return originLess(p->origin(), q->origin()); });
    return out;
}

/// @a b grown by @a by voxels on every side (clamped far from the int32 limits).
inline Box grownBy(const Box& b, int32_t by)
{
    if (b.empty()) return b;
    Box r = b;
    for (int i = 0; i < 3; ++i) {
        r.min[i] = int32_t(std::max<int64_t>(int64_t(b.min[i]) - by, INT32_MIN / 2));
        r.max[i] = int32_t(std::min<int64_t>(int64_t(b.max[i]) + by, INT32_MAX / 2));
    }
    return r;
}

/// The origins of the leaf slots (8^3, aligned) that meet @a b and hold clay in a leaf or in a tile
/// holding clay, in origin order; by probing the box's slots or walking the leaves and tiles,
/// whichever is fewer.
inline std::vector<openvdb::Coord> claySlotsNear(const openvdb::Int32Tree& tree, const Box& b)
{
    std::vector<openvdb::Coord> out;
    if (b.empty()) return out;
    const openvdb::CoordBBox bb(openvdb::Coord(b.min[0], b.min[1], b.min[2]),
                                openvdb::Coord(b.max[0], b.max[1], b.max[2]));
    if (leafSlotCount(b) <= int64_t(tree.leafCount()) + 4096) {
        openvdb::tree::ValueAccessor<const openvdb::Int32Tree> acc(tree);
        for (int64_t x = b.min[0] & ~7; x <= b.max[0]; x += 8)
            for (int64_t y = b.min[1] & ~7; y <= b.max[1]; y += 8)
                for (int64_t z = b.min[2] & ~7; z <= b.max[2]; z += 8) {
                    const openvdb::Coord o{int32_t(x), int32_t(y), int32_t(z)};
                    if (acc.probeConstLeaf(o) || acc.getValue(o) != 0) out.push_back(o);
                }
        return out;
    }
    for (auto it = tree.cbeginLeaf(); it; ++it)
        if (it->getNodeBoundingBox().hasOverlap(bb)) out.push_back(it->origin());
    auto tile = tree.cbeginValueOn();
    tile.setMaxDepth(tile.getLeafDepth() - 1);
    for (; tile; ++tile) {
        if (*tile == 0) continue;
        openvdb::CoordBBox tb;
        tile.getBoundingBox(tb);
        if (!tb.hasOverlap(bb)) continue;
        tb.intersect(bb);
        for (int64_t x = tb.min().x() & ~7; x <= tb.max().x(); x += 8)
            for (int64_t y = tb.min().y() & ~7; y <= tb.max().y(); y += 8)
                for (int64_t z = tb.min().z() & ~7; z <= tb.max().z(); z += 8)
                    out.emplace_back(int32_t(x), int32_t(y), int32_t(z));
    }
    std::sort(out.begin(), out.end(), originLess);
    return out;
}

/// The clay and the voxels holding it in the leaf slots that meet @a b (whole slots, tiles counted as
/// their voxels).
inline void clayInSlotsNear(const openvdb::Int32Tree& tree, const Box& b, uint64_t& voxels, int64_t& clay)
{
    voxels = 0;
    clay = 0;
    openvdb::tree::ValueAccessor<const openvdb::Int32Tree> acc(tree);
    for (const openvdb::Coord& o : claySlotsNear(tree, b)) {
        if (const MassLeafT* leaf = acc.probeConstLeaf(o)) {
            voxels += leaf->onVoxelCount();
            const int32_t* d = leaf->buffer().data();
            int64_t sum = 0;
            for (openvdb::Index i = 0; i < MassLeafT::SIZE; ++i)
                sum += d[i];
            clay += sum;
        } else {
            voxels += MassLeafT::SIZE;
            clay += int64_t(acc.getValue(o)) * int64_t(MassLeafT::SIZE);
        }
    }
}

/// The voxels of the slots at @a origins (empty box if none).
inline Box slotBounds(const std::vector<openvdb::Coord>& origins)
{
    Box b;
    for (const openvdb::Coord& o : origins)
        b = unite(b, Box{{{o.x(), o.y(), o.z()}}, {{o.x() + 7, o.y() + 7, o.z() + 7}}});
    return b;
}

/// @a region cut to the clay near it, in leaves or tiles (see the file comment); @a alsoNear (e.g. where a
/// push puts clay in leaves that do not exist yet) is kept as if it were clay. With no clay near, the single
/// voxel region.min: an edit of a non-empty region still happens (and restarts the automaton's
/// quiet-step count, as the whole region would), waking only blocks without clay.
inline Box narrowedEditRegion(const openvdb::Int32Tree& tree, const Box& region, const Box& alsoNear = Box())
{
    if (region.empty()) return region;
    const Box near = unite(slotBounds(claySlotsNear(tree, grownBy(region, 16))), alsoNear);
    const Box cut = intersect(region, grownBy(near, 16));
    return cut.empty() ? Box{region.min, region.min} : cut;
}

} // namespace clay_internal
} // namespace vdbclay
