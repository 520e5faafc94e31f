// Rasterising an analytic shape into a tree leaf by leaf, on several threads.
//
// forEachVoxelInside (Voxels.h) visits the shape's bounds voxel by voxel; writing each voxel through
// a tree accessor, the 128^3 clay box and the scene's floor would take ~3.4 M distance evaluations
// and accessor writes, all on one core before the first step. Here the leaf slots (8^3, aligned) of
// the same bounds are cut into chunks; within a chunk every slot is evaluated in parallel (the same
// voxels, the same test: distance at the voxel centre < 0) into a leaf of its own, and the chunk's
// leaves then go into the tree serially, in slot order. The voxels set, their values and the tree's
// topology are those of the voxel loop, whatever the thread count: a slot with no voxel inside makes
// no leaf, a slot whose leaf the tree lacks gets the new leaf (its other voxels inactive background,
// as an accessor write leaves them), and a slot the tree already holds (a leaf, or a tile) is written
// voxel by voxel through the accessor. With @a tiles (clay in 3D), a slot lying inside the shape
// whole is one active tile of the value, not a leaf: the bounds' slots are then tested at their eight
// corner voxels alone where the shape is convex (Shape::convex) or an unrotated box, and a slot whose
// centre lies farther outside than its half-diagonal holds none, so the interior and the outside cost
// a few distances a slot, and memory follows the surface.
#pragma once

#include "shapes/InsideBox.h"
#include "core/ParallelFor.h"

#include "vdbclay/Shapes.h"
#include "vdbclay/Types.h"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

namespace vdbclay {
namespace raster_internal {

/// Sets on, with @a value, every voxel of @a tree whose centre lies inside @a shape (only z = 0 when
/// @a dims == 2): the voxels forEachVoxelInside(shape, dims, ...) visits. Runs on @a threads
/// (ParallelFor.h: 1 serial, 0 every core). Returns the number of voxels set. @a stop, when not
/// empty, is called on the calling thread before each chunk of leaf slots; once it returns true the
/// rasterising ends there, the tree holding the chunks done so far. With @a tiles (3D only), each slot
/// inside the shape whole becomes an active tile (file comment).
template <typename TreeT>
uint64_t rasterizeInside(TreeT& tree, const Shape& shape, int dims, const typename TreeT::ValueType& value,
                         int threads, const std::function<bool()>& stop = {}, bool tiles = false)
{
    using LeafT = typename TreeT::LeafNodeType;
    Box b = shape.bounds();
    if (dims == 2) {
        b.min[2] = std::max(b.min[2], 0);
        b.max[2] = std::min(b.max[2], 0);
    }
    // An unrotated box: its inside voxels are a box, every voxel of it inside (InsideBox.h).
    Box cells;
    const bool boxed = shapes_internal::insideVoxelBox(shape, cells);
    if (boxed) b = intersect(b, cells);
    if (b.empty()) return 0;
    const int64_t lo[3] = {int64_t(b.min[0]) >> 3, int64_t(b.min[1]) >> 3, int64_t(b.min[2]) >> 3};
    const int64_t n[3] = {(int64_t(b.max[0]) >> 3) - lo[0] + 1, (int64_t(b.max[1]) >> 3) - lo[1] + 1,
                          (int64_t(b.max[2]) >> 3) - lo[2] + 1};
    const uint64_t slots = uint64_t(n[0]) * uint64_t(n[1]) * uint64_t(n[2]);
    constexpr uint64_t kChunk = uint64_t(1) << 14; // slots per chunk: bounds the leaves held at once
    std::vector<std::unique_ptr<LeafT>> made;
    std::vector<uint32_t> counts;
    std::vector<char> whole; // slots inside the shape whole (with tiles): one tile each
    const bool tileSlots = tiles && dims == 3 && (boxed || shape.convex());
    // A slot holds no voxel centre inside an analytic shape when the distance at its centre (exact, or
    // scaled a lower bound of it) exceeds the half-diagonal of its voxel centres (3.5 sqrt 3).
    auto outsideWhole = [&](const openvdb::Coord& o) {
        if (!tileSlots || boxed) return false;
        const Vec3 c{{double(o.x()) + 3.5, double(o.y()) + 3.5, double(o.z()) + 3.5}};
        return shape.distance(c) > 6.0622 + 1e-6;
    };
    // A slot of voxel centres is inside a convex shape when its eight corner voxels are, each by a
    // margin far beyond the distance's rounding (a slot closer than that is tested voxel by voxel).
    auto insideWhole = [&](const openvdb::Coord& o) {
        if (!tileSlots) return false;
        for (int a = 0; a < 3; ++a)
            if (o[a] < b.min[size_t(a)] || o[a] + 7 > b.max[size_t(a)]) return false;
        if (boxed) return true;
        for (int c = 0; c < 8; ++c) {
            const Vec3 p{{double(o.x() + 7 * (c & 1)), double(o.y() + 7 * ((c >> 1) & 1)),
                          double(o.z() + 7 * (c >> 2))}};
            if (!(shape.distance(p) < -1e-6)) return false;
        }
        return true;
    };
    uint64_t total = 0;
    for (uint64_t first = 0; first < slots; first += kChunk) {
        if (stop && stop()) break;
        const size_t m = size_t(std::min(kChunk, slots - first));
        made.clear();
        made.resize(m);
        counts.assign(m, 0);
        whole.assign(m, 0);
        parallel_internal::forEachIndex(m, threads, [&](size_t i) {
            // slot order: x, then y, then z (as the voxel loop's order of leaves)
            const uint64_t s = first + i;
            const int64_t sz = int64_t(s % uint64_t(n[2])), sy = int64_t(s / uint64_t(n[2]) % uint64_t(n[1])),
                          sx = int64_t(s / uint64_t(n[2]) / uint64_t(n[1]));
            const openvdb::Coord origin(int32_t((lo[0] + sx) * 8), int32_t((lo[1] + sy) * 8),
                                        int32_t((lo[2] + sz) * 8));
            const int32_t x0 = std::max(b.min[0], origin.x()), x1 = std::min(b.max[0], origin.x() + 7);
            const int32_t y0 = std::max(b.min[1], origin.y()), y1 = std::min(b.max[1], origin.y() + 7);
            const int32_t z0 = std::max(b.min[2], origin.z()), z1 = std::min(b.max[2], origin.z() + 7);
            if (outsideWhole(origin)) return;
            if (insideWhole(origin)) {
                whole[i] = 1;
                counts[i] = uint32_t(LeafT::SIZE);
                return;
            }
            std::unique_ptr<LeafT> leaf;
            uint32_t count = 0;
            for (int32_t x = x0; x <= x1; ++x)
                for (int32_t y = y0; y <= y1; ++y)
                    for (int32_t z = z0; z <= z1; ++z) {
                        if (!boxed && !(shape.distance(Vec3{{double(x), double(y), double(z)}}) < 0))
                            continue;
                        if (!leaf) leaf = std::make_unique<LeafT>(origin, tree.background(), false);
                        leaf->setValueOn(LeafT::coordToOffset(openvdb::Coord(x, y, z)), value);
                        ++count;
                    }
            made[i] = std::move(leaf);
            counts[i] = count;
        });
        openvdb::tree::ValueAccessor<TreeT> acc(tree);
        for (size_t i = 0; i < m; ++i) {
            if (whole[i]) {
                total += counts[i];
                const uint64_t sidx = first + i;
                const int64_t sz = int64_t(sidx % uint64_t(n[2])),
                              sy = int64_t(sidx / uint64_t(n[2]) % uint64_t(n[1])),
                              sx = int64_t(sidx / uint64_t(n[2]) / uint64_t(n[1]));
                const openvdb::Coord o(int32_t((lo[0] + sx) * 8), int32_t((lo[1] + sy) * 8),
                                       int32_t((lo[2] + sz) * 8));
                if (!acc.probeConstLeaf(o) && !acc.isValueOn(o) && acc.getValue(o) == tree.background()) {
                    acc.addTile(1, o, value, true);
                } else { // the tree holds this slot already: voxel by voxel
                    const openvdb::CoordBBox sb = openvdb::CoordBBox::createCube(o, 8);
                    for (auto c = sb.begin(); c; ++c)
                        acc.setValueOn(*c, value);
                }
                continue;
            }
            if (!made[i]) continue;
            total += counts[i];
            LeafT* leaf = made[i].release();
            const openvdb::Coord o = leaf->origin();
            if (!acc.probeConstLeaf(o) && !acc.isValueOn(o) && acc.getValue(o) == tree.background()) {
                acc.addLeaf(leaf); // an empty slot: the leaf as the accessor writes would make it
                continue;
            }
            // The tree holds this slot already (a leaf or a tile): voxel by voxel.
            std::unique_ptr<LeafT> own(leaf);
            for (auto it = own->cbeginValueOn(); it; ++it)
                acc.setValueOn(it.getCoord(), value);
        }
    }
    return total;
}

} // namespace raster_internal
} // namespace vdbclay
