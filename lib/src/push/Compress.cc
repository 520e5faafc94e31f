// The compress push (Compress.h: the design).

#include "push/Compress.h"

#include <openvdb/openvdb.h>

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
    for (const Source& s : sources) {
        if (!covers[s.tool]) continue;
        const Vec3& n = mean[s.tool];
        for (int d = 0; d < (pusher.is2D() ? 4 : 6); ++d) {
            if (kDir[d][0] * n[0] + kDir[d][1] * n[1] + kDir[d][2] * n[2] > 0.5) continue; // ahead
            const Coord q = s.c.offsetBy(kDir[d][0], kDir[d][1], kDir[d][2]);
            if (pusher.inAnyTool(q) || pusher.isObstacle(q) || !isFull(pusher.massAt(q), threshold)) continue;
            covers[s.tool] = 0;
            break;
        }
    }
    return covers;
}

std::vector<Coord> fullChain(const Pusher& pusher, const Source& s, const Found& found, int depth,
                             int32_t threshold)
{
    std::vector<Coord> chain;
    if (!found.byMarch || !isFull(pusher.massAt(found.to), threshold)) return chain;
    chain.push_back(found.to);
    // March on in half-voxel steps; at most 2 depth + 2 more points reach depth voxels.
    for (int k = 1; int(chain.size()) < depth && k <= 2 * depth + 2; ++k) {
        const double t = found.t + 0.5 * k;
        const Coord c = pusher.along(s, found.normal, t);
        if (c == chain.back()) continue;
        const int32_t share = s.mass / int32_t(chain.size() + 1) + 1;
        if (!pusher.isFree(c, share, pusher.chainRegion()) || !isFull(pusher.massAt(c), threshold)) break;
        chain.push_back(c);
    }
    // The shares must fit every voxel of the chain (the target's search checked it with all of m).
    return chain;
}

void sharePool(openvdb::Int32Tree& pool, int64_t mass, const Pusher& pusher,
               const std::vector<const openvdb::Int32Tree*>& earlier)
{
    const int64_t cells = int64_t(pool.activeVoxelCount());
    const int64_t q = mass / cells;
    int64_t r = mass % cells;
    std::vector<int64_t> perPlace(size_t(kMaxSearchLimit) + 2, 0);
    for (auto it = pool.cbeginValueOn(); it; ++it)
        ++perPlace[size_t(*it)];
    // Places below `last` all get +1; at `last`, the first `atLast` cells in tree order.
    size_t last = 0;
    while (last < perPlace.size() && r >= perPlace[last]) {
        r -= perPlace[last];
        ++last;
    }
    int64_t atLast = r;
    for (auto it = pool.beginValueOn(); it; ++it) {
        const size_t place = size_t(*it);
        int64_t share = q;
        if (place < last)
            share += 1;
        else if (place == last && atLast > 0) {
            share += 1;
            --atLast;
        }
        int64_t now = pusher.planned(it.getCoord());
        for (const openvdb::Int32Tree* e : earlier)
            now += e->getValue(it.getCoord());
        if (now + share > INT32_MAX) {
            throw Error("push: compressing would put more than INT32_MAX clay in a voxel");
        }
        it.setValue(int32_t(share));
    }
}

} // namespace push_internal
} // namespace vdbclay
