// The fog a surface level set is swept over: the density with its active voxels grown by a band.
//
// surfaceFog() returns exactly what density.deepCopy() and then
// openvdb::tools::dilateActiveValues(tree, radius, NN_FACE_EDGE_VERTEX, IGNORE_TILES) give, for a
// density without tiles (the automaton voxelizes its clay; a fog with tiles goes to OpenVDB): the same
// leaves, values and active states, bit for bit (tests/TestSurface.cc). radius iterations of the
// 26-neighbour dilation make a box: a voxel is active when one within Chebyshev distance radius was,
// and a box is separable, so here it is three passes over flat leaf masks, one per axis, each ORing
// shifted copies of a leaf's mask words and of its two neighbours' along that axis (radius < 8:
// only adjacent leaves are reached). OpenVDB instead runs radius passes of the 26-neighbour stencil over
// every leaf, rebuilding its leaf array each time; on a settled lump most leaves are full and gain
// nothing. The leaves the box reaches are the density's and their 26 neighbours; each pass is
// parallel over them and writes only its own masks; the tree is assembled serially afterwards. The
// mask shifts (maskGrownAlong) and the leaves' face-neighbour table (leafFaceNeighbours) also serve
// the band's reach in SurfaceSweep.cc (a face step is one voxel along each axis, united), and the
// box grows the sweep's leaves of a density with tiles too (SurfaceTiles.cc: its leaves and the tile
// slots near its isosurface).
#include "output/Surface.h"

#include <openvdb/tools/Morphology.h>
#include <openvdb/tree/ValueAccessor.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <utility>
#include <vector>

namespace vdbclay {
namespace io_internal {

namespace {

using FloatTree = openvdb::FloatTree;
using LeafT = FloatTree::LeafNodeType;
using MaskT = LeafT::NodeMaskType;
using openvdb::Coord;
using openvdb::Index;

constexpr int kDim = int(LeafT::DIM); // 8: a mask word is one x, its bit y * 8 + z
constexpr uint64_t kByte0 = 0x0101010101010101ull;

/// Each byte's bits below @a k (k in 0..8).
constexpr uint64_t lowBits(int k)
{
    return k >= 8 ? ~uint64_t(0) : kByte0 * ((uint64_t(1) << k) - 1);
}

uint64_t word(const std::vector<MaskT>& masks, int64_t leaf, int x)
{
    return leaf >= 0 ? masks[size_t(leaf)].template getWord<uint64_t>(Index(x)) : 0;
}

} // namespace

MaskT maskGrownAlong(const std::vector<MaskT>& in, size_t li, int64_t lo, int64_t hi, int axis, int r)
{
    MaskT out;
    const int64_t self = int64_t(li);
    for (int x = 0; x < kDim; ++x) {
        uint64_t d = word(in, self, x);
        if (axis == 0) {
            for (int k = 1; k <= r; ++k) {
                d |= x - k >= 0 ? word(in, self, x - k) : word(in, lo, x - k + kDim);
                d |= x + k < kDim ? word(in, self, x + k) : word(in, hi, x + k - kDim);
            }
        } else if (axis == 1) {
            const uint64_t m = d, mlo = word(in, lo, x), mhi = word(in, hi, x);
            for (int k = 1; k <= r; ++k) {
                d |= (m << (8 * k)) | (m >> (8 * k));
                d |= mlo >> (8 * (kDim - k)); // rows y' >= 8 - k of the -y leaf, k rows away
                d |= mhi << (8 * (kDim - k)); // rows y' < k of the +y leaf
            }
        } else {
            const uint64_t m = d, mlo = word(in, lo, x), mhi = word(in, hi, x);
            for (int k = 1; k <= r; ++k) {
                d |= ((m << k) & ~lowBits(k)) | ((m >> k) & lowBits(kDim - k));
                d |= (mlo >> (kDim - k)) & lowBits(k);         // z' >= 8 - k of the -z leaf, into z < k
                d |= (mhi << (kDim - k)) & ~lowBits(kDim - k); // z' < k of the +z leaf, into z >= 8 - k
            }
        }
        out.template getWord<uint64_t>(Index(x)) = d;
    }
    return out;
}

std::vector<std::array<int64_t, 6>> leafFaceNeighbours(const std::vector<Coord>& keys)
{
    // Each key's index, in a tree over the keys (a key's neighbours lie in its leaf or the next one:
    // an accessor finds them without a search from the root).
    openvdb::Int64Tree index(-1);
    {
        openvdb::tree::ValueAccessor<openvdb::Int64Tree> acc(index);
        for (size_t i = 0; i < keys.size(); ++i)
            acc.setValueOn(keys[i], int64_t(i));
    }
    const size_t n = keys.size();
    std::vector<std::array<int64_t, 6>> out(n);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n), [&](const tbb::blocked_range<size_t>& r) {
        openvdb::tree::ValueAccessor<const openvdb::Int64Tree> acc(index);
        for (size_t i = r.begin(); i != r.end(); ++i) {
            for (int f = 0; f < 6; ++f) {
                Coord k = keys[i];
                k[f / 2] += (f & 1) ? 1 : -1;
                out[i][size_t(f)] = acc.getValue(k);
            }
        }
    });
    return out;
}

bool boxGrowable(const openvdb::FloatGrid& density, int radius)
{
    return radius > 0 && radius < kDim && !holdsTiles(density.tree());
}

GrownLeaves growByBox(GrownLeaves g, int radius)
{
    // The seeds' leaves, then every leaf next to one holding an active voxel (the box reaches no
    // further).
    std::vector<Coord> keys;        // leaf keys (origin / 8)
    openvdb::MaskTree added(false); // which keys are in, as they are added
    openvdb::tree::ValueAccessor<openvdb::MaskTree> acc(added);
    auto add = [&](const Coord& key) {
        if (acc.isValueOn(key)) return;
        acc.setValueOn(key);
        keys.push_back(key);
    };
    for (const Coord& o : g.origins)
        add(o >> 3);
    const size_t n0 = keys.size();
    for (size_t i = 0; i < n0; ++i) {
        if (g.masks[i].isOff()) continue; // no active voxel: grows nothing
        const Coord k = keys[i];
        for (int dx = -1; dx <= 1; ++dx)
            for (int dy = -1; dy <= 1; ++dy)
                for (int dz = -1; dz <= 1; ++dz)
                    add(k.offsetBy(dx, dy, dz));
    }
    const size_t n = keys.size();
    g.source.resize(n, nullptr);
    const std::vector<std::array<int64_t, 6>> neighbour = leafFaceNeighbours(keys);

    // The box, an axis at a time.
    std::vector<MaskT>& masks = g.masks;
    masks.resize(n);
    std::vector<MaskT> next(n);
    for (int axis = 0; axis < 3; ++axis) {
        tbb::parallel_for(tbb::blocked_range<size_t>(0, n), [&](const tbb::blocked_range<size_t>& r) {
            for (size_t i = r.begin(); i != r.end(); ++i)
                next[i] = maskGrownAlong(masks, i, neighbour[i][size_t(2 * axis)],
                                         neighbour[i][size_t(2 * axis + 1)], axis, radius);
        });
        masks.swap(next);
    }

    // Kept: the seeds' leaves and the new ones holding a grown voxel.
    size_t kept = 0;
    g.origins.resize(n);
    for (size_t i = 0; i < n; ++i) {
        if (i >= n0 && masks[i].isOff()) continue;
        g.origins[kept] =
            Coord(keys[i].x() * kDim, keys[i].y() * kDim, keys[i].z() * kDim); // not << 3 (UB if < 0)
        g.masks[kept] = masks[i];
        g.source[kept] = g.source[i];
        ++kept;
    }
    g.origins.resize(kept);
    g.masks.resize(kept);
    g.source.resize(kept);
    return g;
}

GrownLeaves growByBox(const openvdb::FloatGrid& density, int radius)
{
    GrownLeaves seeds;
    for (auto it = density.tree().cbeginLeaf(); it; ++it) {
        seeds.origins.push_back(it->origin());
        seeds.masks.push_back(it->getValueMask());
        seeds.source.push_back(&*it);
    }
    return growByBox(std::move(seeds), radius);
}

openvdb::FloatGrid::Ptr surfaceFog(const openvdb::FloatGrid& density, int radius)
{
    if (!boxGrowable(density, radius)) {
        openvdb::FloatGrid::Ptr fog = density.deepCopy();
        if (radius > 0)
            openvdb::tools::dilateActiveValues(fog->tree(), radius, openvdb::tools::NN_FACE_EDGE_VERTEX,
                                               openvdb::tools::IGNORE_TILES);
        return fog;
    }
    const GrownLeaves g = growByBox(density, radius);
    // The fog: the density's leaves (values kept) and the new leaves (the background), each with its
    // grown mask.
    const size_t n = g.origins.size();
    std::vector<LeafT*> made(n, nullptr);
    const float background = density.tree().background();
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i != r.end(); ++i) {
            made[i] = g.source[i] ? new LeafT(*g.source[i]) : new LeafT(g.origins[i], background, false);
            made[i]->setValueMask(g.masks[i]);
        }
    });
    auto tree = std::make_shared<FloatTree>(background);
    for (LeafT* leaf : made)
        tree->addLeaf(leaf);
    openvdb::FloatGrid::Ptr fog = density.copyWithNewTree();
    fog->setTree(tree);
    return fog;
}

} // namespace io_internal
} // namespace vdbclay
