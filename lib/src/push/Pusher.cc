// The push's sources and their targets (Pusher.h: the design).

#include "push/Pusher.h"
#include "push/ClayLeaves.h"
#include "core/ParallelFor.h"

#include "vdbclay/Automaton.h"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <cmath>
#include <deque>

namespace vdbclay {
namespace push_internal {

namespace {

using openvdb::CoordBBox;

Vec3 centre(const Coord& c)
{
    return {{double(c.x()), double(c.y()), double(c.z())}};
}

} // namespace

Pusher::Pusher(const Automaton& a, const std::vector<ShapePtr>& tools, int maxSearch)
    : mTools(tools), mMaxSearch(maxSearch), mIs2D(a.options().dimensions == 2), mMass(a.mass()->constTree()),
      mObs(a.obstacles() ? &a.obstacles()->constTree() : nullptr)
{
    for (const ShapePtr& t : tools)
        mBounds.push_back(t->bounds());
}

Box Pusher::toolBounds() const
{
    Box u;
    for (const Box& b : mBounds)
        u = unite(u, b);
    if (mIs2D) u = intersect(u, Box{{{INT32_MIN, INT32_MIN, 0}}, {{INT32_MAX, INT32_MAX, 0}}});
    return u;
}

std::vector<Source> Pusher::sources(const Box& u, int threads) const
{
    const std::vector<const clay_internal::MassLeafT*> leaves = clay_internal::leavesNear(mMass, u);
    const CoordBBox ub(Coord(u.min[0], u.min[1], u.min[2]), Coord(u.max[0], u.max[1], u.max[2]));
    std::vector<std::vector<Source>> perLeaf(leaves.size());
    parallel_internal::forEachIndex(leaves.size(), threads, [&](size_t i) {
        const auto* leaf = leaves[i];
        CoordBBox b = leaf->getNodeBoundingBox();
        b.intersect(ub);
        std::vector<Source>& out = perLeaf[i];
        for (auto it = b.begin(); it; ++it) {
            const Coord c = *it;
            const int32_t m = leaf->getValue(c);
            if (m == 0) continue;
            size_t best = SIZE_MAX;
            double bestD = 0;
            for (size_t t = 0; t < mTools.size(); ++t) {
                if (!inside(mBounds[t], c)) continue;
                const double d = mTools[t]->distance(centre(c));
                if (d < 0 && (best == SIZE_MAX || d < bestD)) {
                    best = t;
                    bestD = d;
                }
            }
            if (best != SIZE_MAX) out.push_back(Source{c, m, best, bestD});
        }
    });
    std::vector<Source> out;
    for (const std::vector<Source>& l : perLeaf)
        out.insert(out.end(), l.begin(), l.end());
    std::sort(out.begin(), out.end(), [](const Source& a, const Source& b) { return a.c < b.c; });
    return out;
}

Vec3 Pusher::unitNormal(const Source& s) const
{
    Vec3 n = mTools[s.tool]->normal(centre(s.c));
    if (mIs2D) n[2] = 0;
    const double l = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    if (!(l > 0) || !std::isfinite(l)) return {{0, 1, 0}};
    return {{n[0] / l, n[1] / l, n[2] / l}};
}

bool Pusher::inAnyTool(const Coord& c) const
{
    for (size_t t = 0; t < mTools.size(); ++t) {
        if (inside(mBounds[t], c) && mTools[t]->distance(centre(c)) < 0) return true;
    }
    return false;
}

Pusher::Reader::Reader(const Pusher& p) : mPusher(p), mMass(p.mMass), mAdded(p.mAdded)
{
    if (p.mObs)
        mObs =
            std::make_unique<openvdb::tree::ValueAccessor<const Tree543<openvdb::ValueMask>, false>>(*p.mObs);
}

Found Pusher::find(const Source& s, bool planned, Reader& r) const
{
    Found f;
    const Vec3 n = unitNormal(s);
    const double start = -s.distance + 0.5;
    const int steps = 2 * mMaxSearch;
    for (int k = 0; k <= steps; ++k) {
        const double t = start + 0.5 * k;
        const Coord c = along(s, n, t);
        if (c == s.c) continue;
        if (r.isFree(c, s.mass, mRegion, planned)) {
            f.ok = true;
            f.to = c;
            f.normal = n;
            f.t = t;
            f.byMarch = true;
            return f;
        }
        if (r.isWall(c)) break; // clay does not pass through obstacles
    }
    // The flood: breadth-first from the source through passable voxels, neighbours in a fixed order.
    openvdb::MaskTree seen(false);
    openvdb::tree::ValueAccessor<openvdb::MaskTree> acc(seen);
    std::deque<Coord> queue;
    queue.push_back(s.c);
    acc.setValueOn(s.c);
    static const int kDir[6][3] = {{-1, 0, 0}, {1, 0, 0}, {0, -1, 0}, {0, 1, 0}, {0, 0, -1}, {0, 0, 1}};
    const int dirs = mIs2D ? 4 : 6;
    while (!queue.empty()) {
        const Coord c = queue.front();
        queue.pop_front();
        for (int d = 0; d < dirs; ++d) {
            const Coord q = c.offsetBy(kDir[d][0], kDir[d][1], kDir[d][2]);
            if (std::abs(q.x() - s.c.x()) > mMaxSearch || std::abs(q.y() - s.c.y()) > mMaxSearch ||
                std::abs(q.z() - s.c.z()) > mMaxSearch) {
                continue;
            }
            if (acc.isValueOn(q)) continue;
            acc.setValueOn(q);
            if (r.isFree(q, s.mass, mRegion, planned)) {
                f.ok = true;
                f.to = q;
                return f;
            }
            if (!r.isWall(q) && inside(mRegion, q)) queue.push_back(q);
        }
    }
    return f;
}

} // namespace push_internal
} // namespace vdbclay
