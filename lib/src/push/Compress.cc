// The compress push (Compress.h: the design).

#include "push/Compress.h"

#include "core/ParallelFor.h"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <cmath>

namespace vdbclay {
namespace push_internal {

std::vector<char> covering(const Pusher& pusher, const std::vector<Source>& sources, int32_t threshold)
{
    static const int kDir[6][3] = {{-1, 0, 0}, {1, 0, 0}, {0, -1, 0}, {0, 1, 0}, {0, 0, -1}, {0, 0, 1}};
    std::vector<Vec3> mean(pusher.toolCount(), Vec3{{0, 0, 0}});
    for (const Source& s : sources) {
        const Vec3 n = pusher.unitNormal(s);
        for (int i = 0; i < 3; ++i)
            mean[s.tool][i] += n[i];
    }
    for (Vec3& n : mean) {
        const double l = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        for (int i = 0; i < 3; ++i)
            n[i] = l > 0 ? n[i] / l : 0.0;
    }
    std::vector<char> covers(pusher.toolCount(), 1);
    Pusher::Reader r(pusher);
    for (const Source& s : sources) {
        if (!covers[s.tool]) continue;
        const Vec3& n = mean[s.tool];
        for (int d = 0; d < (pusher.is2D() ? 4 : 6); ++d) {
            if (kDir[d][0] * n[0] + kDir[d][1] * n[1] + kDir[d][2] * n[2] > 0.5) continue; // ahead
            const Coord q = s.c.offsetBy(kDir[d][0], kDir[d][1], kDir[d][2]);
            if (pusher.inAnyTool(q) || r.isObstacle(q) || !isFull(r.massAt(q), threshold)) continue;
            covers[s.tool] = 0;
            break;
        }
    }
    return covers;
}

void fullChain(Pusher::Reader& r, const Source& s, const Found& found, int depth, int32_t threshold,
               std::vector<Coord>& chain)
{
    chain.clear();
    if (!found.byMarch || !isFull(r.massAt(found.to), threshold)) return;
    const Pusher& pusher = r.pusher();
    chain.push_back(found.to);
    // March on in half-voxel steps; at most 2 depth + 2 more points reach depth voxels.
    for (int k = 1; int(chain.size()) < depth && k <= 2 * depth + 2; ++k) {
        const double t = found.t + 0.5 * k;
        const Coord c = pusher.along(s, found.normal, t);
        if (c == chain.back()) continue;
        const int32_t share = s.mass / int32_t(chain.size() + 1) + 1;
        if (!r.isFree(c, share, pusher.chainRegion()) || !isFull(r.massAt(c), threshold)) break;
        chain.push_back(c);
    }
    // The shares must fit every voxel of the chain (the target's search checked it with all of m).
}

void sharePool(Pool& pool, int64_t mass, const Pusher& pusher, const std::vector<const Pool*>& earlier,
               int threads)
{
    pool.sortTreeOrder();
    const size_t leaves = pool.leafCount();
    std::vector<int64_t> perPlace(size_t(kMaxSearchLimit) + 2, 0);
    int64_t cells = 0;
    for (size_t l = 0; l < leaves; ++l)
        for (const int32_t v : pool.leaf(l).v)
            if (v) ++perPlace[size_t(v)];
    for (const int64_t n : perPlace)
        cells += n;
    if (cells == 0) return;
    const int64_t q = mass / cells;
    int64_t r = mass % cells;
    // Places below `last` all get +1; at `last`, the first `atLast` cells in tree order.
    size_t last = 0;
    while (last < perPlace.size() && r >= perPlace[last]) {
        r -= perPlace[last];
        ++last;
    }
    // Each leaf's cells at `last` that get +1: those of the first `atLast` in tree order.
    std::vector<int64_t> plusAtLast(leaves, 0);
    for (size_t l = 0; l < leaves && r > 0; ++l) {
        int64_t n = 0;
        for (const int32_t v : pool.leaf(l).v)
            n += size_t(v) == last ? 1 : 0;
        plusAtLast[l] = std::min(n, r);
        r -= plusAtLast[l];
    }
    std::vector<char> overflow(leaves, 0);
    parallel_internal::forEachIndex(leaves, threads, [&](size_t l) {
        Pool::Leaf& leaf = pool.leaf(l);
        Pusher::Reader reader(pusher);
        std::vector<const Pool::Leaf*> other;
        for (const Pool* e : earlier)
            if (const Pool::Leaf* o = e->find(leaf.origin)) other.push_back(o);
        int64_t atLast = plusAtLast[l];
        for (uint32_t i = 0; i < kSlotVoxels; ++i) {
            const size_t place = size_t(leaf.v[i]);
            if (!place) continue;
            int64_t share = q;
            if (place < last)
                share += 1;
            else if (place == last && atLast > 0) {
                share += 1;
                --atLast;
            }
            int64_t now = reader.planned(slotVoxel(leaf.origin, i));
            for (const Pool::Leaf* o : other)
                now += o->v[i];
            if (now + share > INT32_MAX) overflow[l] = 1;
            leaf.v[i] = int32_t(share);
        }
    });
    for (const char o : overflow)
        if (o) throw Error("push: compressing would put more than INT32_MAX clay in a voxel");
}

} // namespace push_internal
} // namespace vdbclay
