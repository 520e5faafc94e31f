// The scene's surface tension (SurfaceTension.h): the surface's slots (the whole surface, or the
// frame's changed clay), cut into boxes by halving, the boxes smoothed level by level.
#include "sculpt/SurfaceTension.h"

#include "core/CoordHash.h"
#include "core/ParallelFor.h"
#include "sculpt/SmoothInternal.h"

#include "vdbclay/Automaton.h"
#include "vdbclay/Smooth.h"

#include <openvdb/openvdb.h>

#include <tbb/info.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <unordered_map>

namespace vdbclay {
namespace sculpt_internal {

namespace {

using automaton_internal::ChangedClay;
using Entry = ChangedClay::Entry;

/// Cuts entries [@a begin, @a end) into boxes (SurfaceTension.h), appending them to @a out in order.
void cut(std::vector<Entry>& e, size_t begin, size_t end, int dims, int margin, std::vector<Box>& out)
{
    std::array<int32_t, 3> lo = e[begin].slot, hi = e[begin].slot;
    for (size_t i = begin + 1; i < end; ++i)
        for (int a = 0; a < 3; ++a) {
            lo[size_t(a)] = std::min(lo[size_t(a)], e[i].slot[size_t(a)]);
            hi[size_t(a)] = std::max(hi[size_t(a)], e[i].slot[size_t(a)]);
        }
    uint64_t volume = 1;
    int longest = 0;
    bool small = true;
    for (int a = 0; a < 3; ++a) {
        const int64_t extent = int64_t(hi[size_t(a)]) - lo[size_t(a)] + 1;
        volume *= uint64_t(extent);
        small = small && extent <= kTensionBoxSlots;
        if (extent > int64_t(hi[size_t(longest)]) - lo[size_t(longest)] + 1) longest = a;
    }
    const uint64_t n = end - begin;
    if (n == 1 || (small && volume <= 2 * n)) {
        Box b;
        for (size_t i = begin; i < end; ++i)
            b = unite(b, e[i].voxels);
        for (int a = 0; a < (dims == 2 ? 2 : 3); ++a) {
            b.min[size_t(a)] -= margin;
            b.max[size_t(a)] += margin;
        }
        out.push_back(b);
        return;
    }
    // Halve at the median slot along the longest axis (ties in slot order: a total order, so the
    // cut does not depend on the order the entries came in).
    std::sort(e.begin() + std::ptrdiff_t(begin), e.begin() + std::ptrdiff_t(end),
              [longest](const Entry& x, const Entry& y) {
                  const int32_t a = x.slot[size_t(longest)], b = y.slot[size_t(longest)];
                  return a != b ? a < b : x.slot < y.slot;
              });
    const size_t mid = begin + n / 2;
    cut(e, begin, mid, dims, margin, out);
    cut(e, mid, end, dims, margin, out);
}

} // namespace

uint64_t tensionBlockVoxels(int dims)
{
    const uint64_t side = 8 * kTensionBoxSlots + 2 * (kSurfaceTensionMargin + 2);
    return dims == 2 ? side * side : side * side * side;
}

void addWholeSurface(const MassGrid& mass, int dims, ChangedClay& out)
{
    using openvdb::Coord;
    const openvdb::Int32Tree& tree = mass.constTree();
    for (auto it = tree.cbeginLeaf(); it; ++it) {
        const Coord o = it->origin();
        out.add(Box{{{o.x(), o.y(), o.z()}}, {{o.x() + 7, o.y() + 7, dims == 2 ? 0 : o.z() + 7}}});
    }
    // A tile's border slots that meet another value or empty space (26 neighbours) with no leaf
    // between: a leaf's box grown by the margin reaches 4 voxels into the tile slots beside it, and a
    // tile's voxels farther from any other value cannot change (their shelters are the interior's,
    // and no face of theirs is an edge). 2D clay lies in z = 0, so it holds no tile.
    openvdb::tree::ValueAccessor<const openvdb::Int32Tree> acc(tree);
    auto tile = tree.cbeginValueOn();
    tile.setMaxDepth(tile.getLeafDepth() - 1);
    for (; tile; ++tile) {
        openvdb::CoordBBox bb;
        tile.getBoundingBox(bb);
        const int32_t v = *tile;
        const Coord lo(bb.min().x() >> 3, bb.min().y() >> 3, bb.min().z() >> 3);
        const Coord hi(bb.max().x() >> 3, bb.max().y() >> 3, bb.max().z() >> 3);
        for (int32_t x = lo.x(); x <= hi.x(); ++x)
            for (int32_t y = lo.y(); y <= hi.y(); ++y)
                for (int32_t z = lo.z(); z <= hi.z(); ++z) {
                    const bool border = x == lo.x() || x == hi.x() || y == lo.y() || y == hi.y() ||
                                        z == lo.z() || z == hi.z();
                    if (!border) {
                        z = hi.z() - 1; // on to the far face
                        continue;
                    }
                    bool meets = false;
                    for (int dx = -1; dx <= 1 && !meets; ++dx)
                        for (int dy = -1; dy <= 1 && !meets; ++dy)
                            for (int dz = -1; dz <= 1 && !meets; ++dz) {
                                const Coord n(x + dx, y + dy, z + dz);
                                if (n.x() >= lo.x() && n.x() <= hi.x() && n.y() >= lo.y() &&
                                    n.y() <= hi.y() && n.z() >= lo.z() && n.z() <= hi.z())
                                    continue;
                                const Coord o(n.x() * 8, n.y() * 8, n.z() * 8);
                                meets = acc.probeConstLeaf(o) == nullptr && acc.getValue(o) != v;
                            }
                    if (meets) out.add(Box{{{x * 8, y * 8, z * 8}}, {{x * 8 + 7, y * 8 + 7, z * 8 + 7}}});
                }
    }
}

std::vector<Box> tensionBoxes(const std::vector<Entry>& changed, int dims, int margin)
{
    std::vector<Box> out;
    if (changed.empty()) return out;
    std::vector<Entry> e = changed;
    cut(e, 0, e.size(), dims, margin, out);
    return out;
}

int tensionLanes(int threads)
{
    const int cores = std::max(1, tbb::info::default_concurrency());
    return threads == 0 ? cores : std::max(1, std::min(threads, cores));
}

size_t tensionBoxesHeld(int lanes)
{
    return lanes <= 1 ? 1 : size_t(lanes) * kTensionBoxesPerLane;
}

std::vector<uint32_t> tensionLevels(const std::vector<Box>& boxes, int dims)
{
    // Each box is listed in the cells (kLevelCell voxels a side) it meets; a box's reads meet an
    // earlier box only where they share a cell, so a box looks at the few boxes listed in the
    // cells its reads meet, not at every earlier box.
    constexpr int kLevelCellLog2 = 6;
    std::unordered_map<openvdb::Coord, std::vector<uint32_t>, CoordHash> listed;
    auto cells = [](const Box& b, auto&& f) {
        for (int32_t x = b.min[0] >> kLevelCellLog2; x <= b.max[0] >> kLevelCellLog2; ++x)
            for (int32_t y = b.min[1] >> kLevelCellLog2; y <= b.max[1] >> kLevelCellLog2; ++y)
                for (int32_t z = b.min[2] >> kLevelCellLog2; z <= b.max[2] >> kLevelCellLog2; ++z)
                    f(openvdb::Coord(x, y, z));
    };
    std::vector<uint32_t> level(boxes.size(), 0);
    for (size_t i = 0; i < boxes.size(); ++i) {
        Box reads = boxes[i];
        for (size_t a = 0; a < (dims == 2 ? 2u : 3u); ++a) {
            reads.min[a] -= smooth_internal::kShelterReach;
            reads.max[a] += smooth_internal::kShelterReach;
        }
        uint32_t l = 0;
        cells(reads, [&](const openvdb::Coord& c) {
            const auto it = listed.find(c);
            if (it == listed.end()) return;
            for (const uint32_t j : it->second)
                if (level[j] >= l && !intersect(reads, boxes[j]).empty()) l = level[j] + 1;
        });
        level[i] = l;
        cells(boxes[i], [&](const openvdb::Coord& c) { listed[c].push_back(uint32_t(i)); });
    }
    return level;
}

TensionReport smoothBoxes(Automaton& automaton, const std::vector<Box>& boxes, double strength,
                          const std::vector<ShapePtr>& solids)
{
    TensionReport r;
    if (boxes.empty()) return r;
    // The boxes level by level, each level's in their order.
    const std::vector<uint32_t> level = tensionLevels(boxes, automaton.options().dimensions);
    r.levels = 1 + *std::max_element(level.begin(), level.end());
    std::vector<size_t> start(r.levels + 1, 0);
    for (const uint32_t l : level)
        ++start[l + 1];
    for (size_t l = 0; l < r.levels; ++l)
        start[l + 1] += start[l];
    std::vector<uint32_t> order(boxes.size());
    {
        std::vector<size_t> next(start.begin(), start.end() - 1);
        for (size_t i = 0; i < boxes.size(); ++i)
            order[next[level[i]]++] = uint32_t(i);
    }
    const int lanes = tensionLanes(automaton.options().threads);
    const size_t held = tensionBoxesHeld(lanes);
    auto pass = [&] {
        // A level's boxes in groups of `held`: a group's boxes computed in parallel (each reads the
        // grid only), then written one after the other in their order.
        std::vector<smooth_internal::Smoothed> done(held);
        for (size_t l = 0; l < r.levels; ++l)
            for (size_t at = start[l]; at < start[l + 1]; at += held) {
                const size_t n = std::min(held, start[l + 1] - at);
                parallel_internal::forEachIndex(n, lanes == 1 ? 1 : 0, [&](size_t k) {
                    done[k] =
                        smooth_internal::smoothedRegion(automaton, boxes[order[at + k]], strength, 1, solids);
                });
                for (size_t k = 0; k < n; ++k) {
                    smooth_internal::write(automaton, done[k]);
                    r.massMoved += done[k].report.massMoved;
                    r.visited += done[k].report.visited;
                    ++r.boxes;
                    done[k] = smooth_internal::Smoothed();
                }
            }
    };
    if (lanes > 1 && r.levels < boxes.size()) { // some level holds several boxes
        tbb::task_arena arena(lanes);
        arena.execute(pass);
    } else {
        pass();
    }
    return r;
}

} // namespace sculpt_internal
} // namespace vdbclay
