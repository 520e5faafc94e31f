// The geometry the memory estimate (MemoryEstimate.cc) counts on: boxes and the nodes they touch,
// shapes' bounds tightened to their voxels, the tools' bounds along their paths, and where clay may
// lie, leaf by leaf (ClayCover). No policy here (that is FramePolicy.h) and no OpenVDB: boxes in
// voxels, leaves of 8^3, internal nodes of 128^3 and 4096^3.
#pragma once

#include "sculpt/FramePolicy.h"

#include "vdbclay/Scene.h"
#include "vdbclay/Shapes.h"
#include "vdbclay/Types.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace vdbclay {
namespace memory_internal {

/// Floor of @a v / 2^@a log2: the index of the node of side 2^log2 voxels holding coordinate v.
int64_t leafIndex(int32_t v, int log2);
/// Number of nodes of side 2^log2 voxels that @a b touches (2D boxes are clipped to z = 0 first).
uint64_t nodesIn(const Box& b, int log2);
/// Voxels of @a b.
uint64_t voxelsIn(const Box& b);
/// @a b cut to the z = 0 layer when @a dims is 2.
Box clip2D(Box b, int dims);
/// Whether @a a and @a b share a voxel.
bool touches(const Box& a, const Box& b);

/// @a b (a shape's bounds) without the faces that hold no voxel centre inside @a shape: bounds()
/// may be a voxel or two larger than the voxels inside, which at leaf boundaries counts whole extra
/// layers of leaves. Spends at most @a budget distance evaluations (shared by all calls of one
/// estimate, so that huge or many shapes cost well under a second); a face it cannot afford stays.
/// A large face (over 4 kFaceSamples voxels) is tried first at its centre and on a coarse lattice
/// (kFaceSamples points: a convex shape's voxels on a face lie around its middle), then voxel by
/// voxel: the same faces dropped.
Box tighten(const Shape& shape, Box b, int dims, uint64_t& budget);
/// Distance evaluations one estimate may spend tightening bounds (~0.1 s).
constexpr uint64_t kTightenBudget = uint64_t(1) << 21;

/// The voxels of @a b (an analytic shape's tightened bounds, 2D: clipped to z = 0) whose centre lies
/// inside @a shape, counted a leaf at a time (a leaf whose centre lies a half-diagonal inside or
/// outside is decided at once, the others voxel by voxel) while @a budget lasts; voxelsIn(@a b) when
/// it does not.
uint64_t voxelsInsideShape(const Shape& shape, const Box& b, uint64_t& budget);

/// Distinct nodes of side 2^@a log2 voxels that @a boxes touch: counted one by one while there are
/// at most 2^20 of them (boxes that share a node count it once: 20000 copies of one tool, or
/// 100000 one-voxel boxes in a few leaves), else bounded by their sum and by their bounding box.
uint64_t distinctNodes(const std::vector<Box>& boxes, int log2);
/// Groups boxes that touch (directly or through others); returns each group's box indices.
std::vector<std::vector<size_t>> groupsOfTouching(const std::vector<Box>& boxes);
/// Leaves (8^3 voxels) touched by the union of @a boxes, counted exactly on the grid the boxes'
/// leaf-aligned faces cut (at most 40 boxes; more: distinctNodes()).
uint64_t unionLeaves(const std::vector<Box>& boxes);

/// Whether two of the boxes @a boxOf(i), i in @a ids, touch while @a pair(i, j) holds for them (a
/// sweep along x: a box meets only those that start before it ends).
template <typename BoxOf, typename Pair>
bool anyTouchingPair(std::vector<size_t> ids, const BoxOf& boxOf, const Pair& pair)
{
    std::sort(ids.begin(), ids.end(), [&](size_t a, size_t b) { return boxOf(a).min[0] < boxOf(b).min[0]; });
    for (size_t i = 0; i < ids.size(); ++i)
        for (size_t j = i + 1; j < ids.size() && boxOf(ids[j]).min[0] <= boxOf(ids[i]).max[0]; ++j)
            if (touches(boxOf(ids[i]), boxOf(ids[j])) && pair(ids[i], ids[j])) return true;
    return false;
}

/// What sweep() finds of a tool's path.
struct ToolSweep {
    Box all;             ///< the bounds over every frame
    uint64_t most = 0;   ///< the most voxels its bounds hold at one frame
    uint64_t inside = 0; ///< the most voxels inside it at one frame (at most `most`)
    /// The largest face of its bounds at one frame, in voxels (3D; in 2D the longest side): a push's
    /// contact is no wider (PushReport::contactSize)
    uint64_t face = 0;
    uint64_t slotsMost = 0;  ///< the most leaf slots its bounds at two consecutive frames hold
    std::vector<Box> frames; ///< every frame's bounds in frame order (empty when frames were sampled)
};

/// The bounds of @a tool over frames 0..@a frames (every frame up to 100000 of them, else 100000
/// evenly spaced ones and the path's segment ends), the most voxels its bounds hold at once, and the
/// most voxels inside it at once (counted when @a countInside: the pushes place the tool at the
/// frames' poses only, no sweep's sub-steps between them). Each frame's bounds are tightened (and its
/// voxels counted) while @a budget lasts (tighten()); a frame whose pose is one tightened before moved
/// by whole voxels (a press, a stroke: every frame) takes that box, moved, and its count.
ToolSweep sweep(const ToolSpec& tool, uint64_t frames, int dims, bool countInside, uint64_t& budget);

/// The leaves within one leaf of those meeting @a b (with @a neighbours; else @a b): the automaton's
/// anchors reach a leaf below (its origin's lower neighbours: 8 voxels towards -x, -y, -z), the
/// surface's band 4 voxels (output/Surface.cc: a half width of 3, swept one voxel further).
Box neighbourhood(Box b, bool neighbours, int dims);

/// Distance evaluations one estimate may spend counting clay leaves (ClayCover: a 2048-wide sphere's
/// surface, its inside tiles, takes ~3 10^7 with the leaves around them), and the members one count
/// may try against nodes and leaves (many shapes, or boxes, near each leaf; a leaf a member holds
/// whole counts one): ~0.1 to 0.3 s each.
constexpr uint64_t kCoverBudget = uint64_t(1) << 25;
constexpr uint64_t kCoverTests = uint64_t(1) << 26;

/// Where clay may lie during a run, leaf by leaf: within a margin (a member's own, else `margin`) of
/// a clay shape's voxels (an analytic shape, whose distance is exact: a leaf whose centre is at least
/// kLeafHalfDiagonal + the margin from it holds no such voxel; other shapes: their bounds), or of a box
/// (clay from a file, a tool's sweep). Counting leaves costs a distance per leaf near a shape's
/// surface (whole 128^3 nodes are decided from their centre), within a budget of evaluations and of
/// tests; past either the count gives up and the caller counts boxes.
struct ClayCover {
    struct Member {
        const Shape* shape = nullptr; ///< an analytic shape, or null: the box alone
        Box box;                      ///< the shape's tightened bounds, or the box
        bool tiled = false;           ///< the shape's clay is tiles inside (automaton/Tiles.h)
        int64_t margin = -1;          ///< how far its clay may spread; -1: the cover's margin
    };
    std::vector<Member> members;
    int64_t margin = 0;
    int dims = 3;
    /// Whether a tiled member's leaves are those near its surface alone (|distance| instead of the
    /// distance: its inside is tiles), as the clay's leaves are; false where the cells inside count
    /// too (the global layer's domain runs through full clay).
    bool tilesAsTiles = false;

    /// Voxel centres of a leaf (of a 128^3 node) lie within this of its centre.
    static constexpr double kLeafHalfDiagonal = 6.0622; // 3.5 sqrt 3
    static constexpr double kNodeLeafSpread = 103.9231; // 60 sqrt 3: leaf centres from the node's
    static constexpr double kAnchorSpread = 6.9283; // 4 sqrt 3: a leaf centre + (4, 4, 4) to its 8 corners

    void addShape(const Shape* analytic, const Box& bounds, bool tiled = false, int64_t ownMargin = -1)
    {
        members.push_back({analytic, bounds, tiled, ownMargin});
    }
    void addBox(const Box& b) { members.push_back({nullptr, b, false, -1}); }
    int64_t marginOf(const Member& mb) const { return mb.margin >= 0 ? mb.margin : margin; }

    /// The leaves (8^3, leaf-aligned) of @a region that may hold clay (with @a neighbours: those
    /// and their 26 neighbours); false (and @a out untouched) when @a budget ran out.
    bool count(const Box& region, bool neighbours, uint64_t& budget, uint64_t& out) const
    {
        uint64_t n = 0;
        if (!forEachLeaf(region, neighbours, budget, [&](const Box&) { ++n; })) return false;
        out = n;
        return true;
    }

    /// Calls @a fn(the leaf's box within @a region) for each leaf of @a region that may hold clay
    /// (with @a neighbours: or is a neighbour of one: a leaf centre within 8 sqrt 3 more of a shape,
    /// in the neighbourhood() of a box); false when @a budget ran out (some leaves were passed over).
    template <typename Fn> bool forEachLeaf(Box region, bool neighbours, uint64_t& budget, const Fn& fn) const
    {
        region = clip2D(region, dims);
        if (region.empty()) return true;
        // A leaf holds clay when its centre lies within kLeafHalfDiagonal + m of a shape (m: the
        // member's margin). With @a neighbours, also when one of its voxels lies within the band's 4
        // voxels of such a voxel (its centre within kLeafHalfDiagonal + 4 + m), or one of the 7 leaves
        // above it (+8 along some axes: it is their anchor) holds clay; those 8 centres lie within
        // kAnchorSpread of the leaf's centre moved by (4, 4, 4).
        struct Within {
            double m, holds, band, anchor, leaf;
        };
        std::vector<Within> within(members.size());
        std::vector<Box> grown(members.size());
        for (size_t i = 0; i < members.size(); ++i) {
            const int64_t mi = marginOf(members[i]);
            Within& w = within[i];
            w.m = double(mi);
            w.holds = w.m + kLeafHalfDiagonal;
            w.band = w.holds + 4;
            w.anchor = w.holds + kAnchorSpread;
            w.leaf = neighbours ? std::max(w.band, w.anchor + kAnchorSpread) : w.holds;
            grown[i] = clip2D(
                neighbourhood(frame_policy::growBox(members[i].box, mi, dims), neighbours, dims), dims);
        }
        // A tiled member's clay lies in leaves only near its surface: outside, as for any shape, within
        // the margin (where it may spread); inside, within a leaf's half-diagonal of the surface, the
        // rest being tiles. So inside the distance counts as margin - distance (the magnitude is a
        // lower bound of the distance to the surface, as the distance is outside).
        auto distanceAt = [&](const Member& mb, const Within& w, double x, double y, double z) {
            if (budget > 0) --budget;
            const double d = mb.shape->distance(Vec3{{x, y, z}});
            return mb.tiled && tilesAsTiles && d < 0 ? w.m - d : d;
        };
        // Whether leaf (x, y, z) holds clay of shape member @a i (or, with neighbours, is a neighbour).
        auto shapeHolds = [&](size_t i, int64_t x, int64_t y, int64_t z) {
            const Member& mb = members[i];
            const Within& w = within[i];
            const double holdsWithin = w.holds, anchorWithin = w.anchor;
            const double cx = double(x) + 3.5, cy = double(y) + 3.5, cz = double(z) + 3.5;
            const double d = distanceAt(mb, w, cx, cy, cz);
            if (d < (neighbours ? w.band : holdsWithin)) return true;
            if (!neighbours || distanceAt(mb, w, cx + 4, cy + 4, cz + 4) >= anchorWithin) return false;
            for (int k = 1; k < 8; ++k)
                if (distanceAt(mb, w, cx + (k & 1 ? 8 : 0), cy + (k & 2 ? 8 : 0), cz + (k & 4 ? 8 : 0)) <
                    holdsWithin)
                    return true;
            return false;
        };
        const int64_t lo[3] = {int64_t(region.min[0]) >> 7, int64_t(region.min[1]) >> 7,
                               int64_t(region.min[2]) >> 7};
        const int64_t hi[3] = {int64_t(region.max[0]) >> 7, int64_t(region.max[1]) >> 7,
                               int64_t(region.max[2]) >> 7};
        std::vector<size_t> near;
        uint64_t tests = 0; // members tried against nodes and leaves: at most kCoverTests
        for (int64_t nx = lo[0]; nx <= hi[0]; ++nx)
            for (int64_t ny = lo[1]; ny <= hi[1]; ++ny)
                for (int64_t nz = lo[2]; nz <= hi[2]; ++nz) {
                    // Node origins by multiplication: a left shift of a negative value is undefined.
                    const Box node{
                        {{int32_t(nx * 128), int32_t(ny * 128), int32_t(nz * 128)}},
                        {{int32_t(nx * 128 + 127), int32_t(ny * 128 + 127), int32_t(nz * 128 + 127)}}};
                    const Box part = intersect(node, region);
                    if (part.empty()) continue;
                    // The members that may hold a leaf of this node, and one that holds all of them.
                    near.clear();
                    bool whole = false;
                    if ((tests += members.size()) > kCoverTests) return false;
                    for (size_t i = 0; i < members.size() && !whole; ++i) {
                        const Box in = intersect(part, grown[i]);
                        if (in.empty()) continue;
                        const bool all = in.min == part.min && in.max == part.max;
                        if (!members[i].shape) {
                            whole = all;
                            near.push_back(i);
                            continue;
                        }
                        if (budget == 0) return false;
                        const double d = distanceAt(members[i], within[i], double(node.min[0]) + 63.5,
                                                    double(node.min[1]) + 63.5, double(node.min[2]) + 63.5);
                        if (d >= kNodeLeafSpread + within[i].leaf) continue; // no leaf of it
                        whole = all && d < within[i].holds - kNodeLeafSpread &&
                                !(members[i].tiled && tilesAsTiles);
                        near.push_back(i);
                    }
                    if (near.empty()) continue;
                    for (int64_t x = int64_t(part.min[0]) & ~int64_t(7); x <= part.max[0]; x += 8)
                        for (int64_t y = int64_t(part.min[1]) & ~int64_t(7); y <= part.max[1]; y += 8)
                            for (int64_t z = int64_t(part.min[2]) & ~int64_t(7); z <= part.max[2]; z += 8) {
                                const Box leaf{{{int32_t(x), int32_t(y), int32_t(z)}},
                                               {{int32_t(x + 7), int32_t(y + 7), int32_t(z + 7)}}};
                                bool holds = whole;
                                // A leaf held whole counts one test: huge boxes give up too.
                                if ((tests += whole ? 1 : near.size()) > kCoverTests) return false;
                                for (size_t k = 0; k < near.size() && !holds; ++k) {
                                    const Member& mb = members[near[k]];
                                    if (!touches(leaf, grown[near[k]])) continue;
                                    if (mb.shape && budget < 9) return false;
                                    holds = !mb.shape || shapeHolds(near[k], x, y, z);
                                }
                                if (holds) fn(intersect(leaf, region));
                            }
                }
        return true;
    }
};

} // namespace memory_internal
} // namespace vdbclay
