// The push operation: clay inside a tool moves to the nearest free voxel outside every tool.
//
// 1. U = union of the tools' bounds (2D: clipped to z = 0). Only leaves of the mass grid that meet
//    U are visited (in parallel, one leaf per task, merged in leaf order), and in them only clay
//    voxels are tested against the tools; the clay voxels whose centre is inside a tool are the
//    sources, sorted in coordinate order (x, then y, then z). A voxel inside a tool is a source even if it is
//    an obstacle: a Sculptor makes the tools' voxels obstacles while clay settles around them.
// 2. Each source is given the tool that holds it most deeply (smallest distance; ties: the first
//    tool) and that tool's normal at its centre (2D: z dropped).
// 3. Target: march from the centre along the normal to (-distance + 0.5) past the surface, then on
//    in half-voxel steps for up to maxSearch voxels, until the voxel at the rounded point is free:
//    outside every tool, not an obstacle, inside the region and able to take the clay without
//    exceeding INT32_MAX; the march stops at an obstacle that is not part of a tool. Failing that,
//    a breadth-first flood from the source through passable voxels (inside a tool or not an
//    obstacle) within Chebyshev distance maxSearch takes the first free voxel it reaches, so clay
//    never crosses an obstacle, however thin. Failing that, the clay is trapped. The searches run in
//    parallel against the grid alone, then are checked in source order against the clay planned
//    before (the room test), and searched again serially where it no longer fits: the same targets.
// 4. The plan (sources emptied, targets increased) is computed read-only first, then written as the
//    cells' new masses (Automaton::setMasses: an edit that reads only those cells) over the region U
//    grown by maxSearch + 2, cut to the part near clay (ClayLeaves.h: the same clay blocks are
//    woken, the cost follows the clay), so nothing is written if a tool throws.
// Sources are inside a tool and targets outside all tools, so no voxel is both; the plan depends only
// on the grid, the tools and the source order: deterministic.
//
// The compress push (PushMode::Compress) changes step 3 only. When the march's target is clay
// (m * 10 >= 3 Tc, in the grid before the push: "full" below), the march goes on along the normal,
// collecting the contiguous full voxels (free, not obstacles, outside every tool) up to the tool's
// depth: the chain. The depth depends on whether the tool covers the clay it entered: no source of it
// has a full, free face neighbour beside or behind it (relative to the tool's mean normal over its
// sources). A tool that does not cover (a small tool poking a large block, a plate narrower than the
// clay) goes as deep as its contact is wide, round(sqrt(voxels it entered this push)) in 3D, their
// number in 2D, at least 1; the source's clay m is shared over its own chain, m / k each, the
// remainder +1 to the voxels nearest the tool: a local rim, the far faces untouched. A tool that covers
// the clay (a plate wider than it) compresses every column under it all the way (up to 1024 voxels:
// the plastic zone of a flat punch spans the whole body once the contact covers its width), and its
// sources' clay is pooled and shared evenly over the union of their chains (each cell the same,
// the remainder +1 to the cells nearest the tool), so a body whose columns differ in length still
// gets a uniform source: the global layer then moves it out evenly (straight sides, docs/ACCURACY.md
// section 6); spread per column, short columns would get more per cell and the clay would leave next
// to the plate. The chains may reach beyond the surface push's region (U grown by maxSearch + 2); the
// report's region and the edit cover them. The full test reads the grid as it was before this push, so
// the plan does not depend on the order of the sources. A source whose target is not full, or was found
// by the flood, is pushed as by the surface push.

#include "vdbclay/Push.h"
#include "vdbclay/Automaton.h"

#include "push/ClayLeaves.h"
#include "core/CoordHash.h"
#include "core/ParallelFor.h"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <climits>
#include <cmath>
#include <deque>
#include <memory>
#include <unordered_map>
#include <utility>
#include <vector>

namespace vdbclay {

namespace {

using openvdb::Coord;
using openvdb::CoordBBox;

constexpr int kMaxSearchLimit = 1024;

/// The clay planned into voxels so far (step 3's room test, step 4's edit): a hash map from voxel to
/// its entry, the entries in the order of their first add (source order: deterministic, and near
/// coordinate order, so the edit's accessor walks the tree in order). A std::map did the same at
/// ~2.5x the cost (a tree node per voxel, log n compares per lookup).
class PlannedClay {
public:
    int64_t get(const Coord& c) const
    {
        const auto it = mIndex.find(c);
        return it != mIndex.end() ? mEntries[it->second].second : 0;
    }
    void add(const Coord& c, int64_t m)
    {
        const auto r = mIndex.emplace(c, uint32_t(mEntries.size()));
        if (r.second)
            mEntries.emplace_back(c, m);
        else
            mEntries[r.first->second].second += m;
    }
    void reserve(size_t n)
    {
        mIndex.reserve(n);
        mEntries.reserve(n);
    }
    using Entries = std::vector<std::pair<Coord, int64_t>>;
    const Entries& entries() const { return mEntries; }

private:
    std::unordered_map<Coord, uint32_t, CoordHash> mIndex;
    Entries mEntries;
};

bool inside(const Box& b, const Coord& c)
{
    return c.x() >= b.min[0] && c.x() <= b.max[0] && c.y() >= b.min[1] && c.y() <= b.max[1] &&
           c.z() >= b.min[2] && c.z() <= b.max[2];
}

Box grow(const Box& a, int64_t by, bool is2D)
{
    Box r = a;
    for (int i = 0; i < 3; ++i) {
        if (is2D && i == 2) continue;
        r.min[i] = int32_t(std::max<int64_t>(int64_t(a.min[i]) - by, INT32_MIN / 2));
        r.max[i] = int32_t(std::min<int64_t>(int64_t(a.max[i]) + by, INT32_MAX / 2));
    }
    return r;
}

struct Source {
    Coord c;
    int32_t mass;
    size_t tool;
    double distance;
};

class Pusher {
public:
    Pusher(Automaton& a, const std::vector<ShapePtr>& tools, int maxSearch)
        : mTools(tools), mMaxSearch(maxSearch), mIs2D(a.options().dimensions == 2),
          mMass(a.mass()->constTree()), mObs(a.obstacles() ? &a.obstacles()->constTree() : nullptr)
    {
        for (const ShapePtr& t : tools)
            mBounds.push_back(t->bounds());
    }

    Box toolBounds() const
    {
        Box u;
        for (const Box& b : mBounds)
            u = unite(u, b);
        if (mIs2D) u = intersect(u, Box{{{INT32_MIN, INT32_MIN, 0}}, {{INT32_MAX, INT32_MAX, 0}}});
        return u;
    }

    void setRegion(const Box& r) { mRegion = mChainRegion = r; }
    /// Compress: the region the chains may reach (at least the push's region).
    void setChainRegion(const Box& r) { mChainRegion = r; }

    /// Clay voxels inside a tool, in coordinate order. Only the mass leaves that meet @a u are
    /// visited, each in parallel (@a threads as the automaton's), its sources collected apart and
    /// merged in leaf order: the cost follows the clay inside the tools' bounds, and the result does
    /// not depend on the thread count.
    std::vector<Source> sources(const Box& u, int threads) const
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

    /// The unit normal of @a s's tool at its centre (2D: z dropped; up when undefined).
    Vec3 unitNormal(const Source& s) const
    {
        Vec3 n = mTools[s.tool]->normal(centre(s.c));
        if (mIs2D) n[2] = 0;
        const double l = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        if (!(l > 0) || !std::isfinite(l)) return {{0, 1, 0}};
        return {{n[0] / l, n[1] / l, n[2] / l}};
    }

    /// What target() found for one source, kept apart (Found) so that sources can be searched in
    /// parallel against the grid alone and their plans applied in source order (adopt()).
    struct Found {
        bool ok = false;
        Coord to;
        Vec3 normal{{0, 1, 0}};
        double t = 0;
        bool byMarch = false;
    };

    /// Where the clay of @a s goes; false if nowhere (trapped). Counts the clay planned so far.
    bool target(const Source& s, Coord& out) const
    {
        const Found f = find(s, /*planned=*/true);
        if (f.ok) adopt(f, out);
        mLastByMarch = f.byMarch;
        return f.ok;
    }

    /// target() without the clay planned so far (thread-safe: reads the grid and the tools only).
    /// Exact where it matters: the planned clay only makes voxels less free (isFree's room test) and
    /// changes neither walls nor passability, so with it the march and the flood visit the same
    /// voxels up to this one and stop here iff it still has room (fits()); and a source trapped
    /// without it is trapped with it.
    Found findAlone(const Source& s) const { return find(s, /*planned=*/false); }
    /// Whether @a m more clay still fits at @a c with the clay planned so far.
    bool fits(const Coord& c, int32_t m) const { return planned(c) + m <= INT32_MAX; }
    /// Takes @a f as target()'s result (what fullChain() continues from).
    void adopt(const Found& f, Coord& out) const
    {
        out = f.to;
        mLastNormal = f.normal;
        mLastT = f.t;
        mLastByMarch = f.byMarch;
    }

    Found find(const Source& s, bool planned) const
    {
        Found f;
        const Vec3 n = unitNormal(s);

        const Vec3 p = centre(s.c);
        const double start = -s.distance + 0.5;
        const int steps = 2 * mMaxSearch;
        for (int k = 0; k <= steps; ++k) {
            const double t = start + 0.5 * k;
            const Coord c = rounded({{p[0] + t * n[0], p[1] + t * n[1], p[2] + t * n[2]}});
            if (c == s.c) continue;
            if (isFree(c, s.mass, mRegion, planned)) {
                f.ok = true;
                f.to = c;
                f.normal = n;
                f.t = t;
                f.byMarch = true;
                return f;
            }
            if (isWall(c)) break; // clay does not pass through obstacles
        }
        // Breadth-first flood from the source through passable voxels (inside a tool, or not an
        // obstacle), 6-connected (4 in 2D), within Chebyshev distance maxSearch: the first free
        // voxel reached. Neighbours are visited in a fixed order, so the choice is deterministic,
        // and clay never crosses an obstacle, however thin.
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
                if (isFree(q, s.mass, mRegion, planned)) {
                    f.ok = true;
                    f.to = q;
                    return f;
                }
                if (!isWall(q) && inside(mRegion, q)) queue.push_back(q);
            }
        }
        return f;
    }

    /// Compress push: after target() found @a first by the march, the contiguous full voxels along
    /// the same normal starting at @a first, at most @a depth of them (empty if @a first is not full
    /// or was found by the flood).
    std::vector<Coord> fullChain(const Source& s, const Coord& first, int depth, int32_t threshold) const
    {
        std::vector<Coord> chain;
        if (!mLastByMarch || !isFull(first, threshold)) return chain;
        chain.push_back(first);
        const Vec3 p = centre(s.c);
        const Vec3& n = mLastNormal;
        // March on in half-voxel steps; at most 2 depth + 2 more points reach depth voxels.
        for (int k = 1; int(chain.size()) < depth && k <= 2 * depth + 2; ++k) {
            const double t = mLastT + 0.5 * k;
            const Coord c = rounded({{p[0] + t * n[0], p[1] + t * n[1], p[2] + t * n[2]}});
            if (c == chain.back()) continue;
            const int32_t share = s.mass / int32_t(chain.size() + 1) + 1;
            if (!isFree(c, share, mChainRegion) || !isFull(c, threshold)) break;
            chain.push_back(c);
        }
        // The shares must fit every voxel of the chain (isFree checked the first with all of m).
        return chain;
    }

    /// Compress: for each tool, whether it covers the clay it entered, i.e. no source of it has a
    /// face neighbour beside or behind it (direction d with d . N <= 1/2, N the mean of the tool's
    /// unit normals over its sources: the way it pushes) that is clay (full), outside every tool and
    /// not an obstacle. A plate wider than the clay covers it (its plastic zone is the whole body
    /// under it); a tool in a larger block does not (the clay goes on beside it: a local rim). The
    /// mean, not each source's own normal: at a plate's edge the normal tilts outward, and the clay
    /// beside the edge would count as ahead. Reads the grid before the push.
    std::vector<char> covering(const std::vector<Source>& sources, int32_t threshold) const
    {
        static const int kDir[6][3] = {{-1, 0, 0}, {1, 0, 0}, {0, -1, 0}, {0, 1, 0}, {0, 0, -1}, {0, 0, 1}};
        std::vector<Vec3> mean(mTools.size(), Vec3{{0, 0, 0}});
        for (const Source& s : sources) {
            const Vec3 n = unitNormal(s);
            for (int i = 0; i < 3; ++i)
                mean[s.tool][i] += n[i];
        }
        for (Vec3& n : mean) {
            const double l = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
            for (int i = 0; i < 3; ++i)
                n[i] = l > 0 ? n[i] / l : 0.0;
        }
        std::vector<char> covers(mTools.size(), 1);
        for (const Source& s : sources) {
            if (!covers[s.tool]) continue;
            const Vec3& n = mean[s.tool];
            for (int d = 0; d < (mIs2D ? 4 : 6); ++d) {
                if (kDir[d][0] * n[0] + kDir[d][1] * n[1] + kDir[d][2] * n[2] > 0.5) continue; // ahead
                const Coord q = s.c.offsetBy(kDir[d][0], kDir[d][1], kDir[d][2]);
                if (inAnyTool(q) || (mObs && mObs->isValueOn(q)) || !isFull(q, threshold)) continue;
                covers[s.tool] = 0;
                break;
            }
        }
        return covers;
    }

    bool inAnyTool(const Coord& c) const
    {
        for (size_t t = 0; t < mTools.size(); ++t) {
            if (inside(mBounds[t], c) && mTools[t]->distance(centre(c)) < 0) return true;
        }
        return false;
    }

    bool isFull(const Coord& c, int32_t threshold) const
    {
        return int64_t(mMass.getValue(c)) * kCompressFullDen >= int64_t(threshold) * kCompressFullNum;
    }

    /// The value of @a c after the moves planned so far (pooled shares excluded).
    int64_t planned(const Coord& c) const { return int64_t(mMass.getValue(c)) + mAdded.get(c); }

    void add(const Coord& c, int32_t m) { mAdded.add(c, m); }
    void reserve(size_t voxels) { mAdded.reserve(voxels); }
    const PlannedClay::Entries& added() const { return mAdded.entries(); }

private:
    static Vec3 centre(const Coord& c) { return {{double(c.x()), double(c.y()), double(c.z())}}; }

    Coord rounded(const Vec3& p) const
    {
        int32_t v[3];
        for (int i = 0; i < 3; ++i) {
            const double r = std::floor(p[i] + 0.5);
            v[i] = int32_t(std::clamp(r, double(INT32_MIN / 2), double(INT32_MAX / 2)));
        }
        if (mIs2D) v[2] = 0;
        return Coord(v[0], v[1], v[2]);
    }

    /// An obstacle that is not part of a tool: clay can neither stop in it nor pass through it.
    bool isWall(const Coord& c) const { return mObs && mObs->isValueOn(c) && !inAnyTool(c); }

    bool isFree(const Coord& c, int32_t m) const { return isFree(c, m, mRegion); }
    bool isFree(const Coord& c, int32_t m, const Box& region, bool planned = true) const
    {
        if (!inside(region, c)) return false;
        if (mIs2D && c.z() != 0) return false;
        if (mObs && mObs->isValueOn(c)) return false;
        if (inAnyTool(c)) return false;
        const int64_t now = planned ? this->planned(c) : int64_t(mMass.getValue(c));
        return now + m <= INT32_MAX;
    }

    const std::vector<ShapePtr>& mTools;
    std::vector<Box> mBounds;
    int mMaxSearch;
    bool mIs2D;
    const openvdb::Int32Tree& mMass;
    const openvdb::MaskTree* mObs;
    Box mRegion, mChainRegion;
    PlannedClay mAdded;
    // What the last successful target() found: by the march (normal, parameter) or by the flood.
    mutable Vec3 mLastNormal{{0, 1, 0}};
    mutable double mLastT = 0;
    mutable bool mLastByMarch = false;
};

/// Compress, a covering tool: its pooled clay @a mass shared evenly over its zone @a pool (each
/// cell's value: its place in the nearest chain + 1), mass / cells each, the remainder +1 to the
/// cells nearest the tool (smallest place, then tree order). On return each value is the cell's
/// share. @a earlier: the pools already shared (their shares count toward a cell's value too).
/// @throw Error (before anything is written) if a share does not fit a cell (int32).
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

} // namespace

const char* pushModeName(PushMode mode)
{
    return mode == PushMode::Compress ? "compress" : "surface";
}

PushMode parsePushMode(const std::string& name)
{
    if (name == "surface") return PushMode::Surface;
    if (name == "compress") return PushMode::Compress;
    throw Error("unknown push \"" + name + "\" (expected one of: surface, compress)");
}

PushReport push(Automaton& automaton, const std::vector<ShapePtr>& tools, int maxSearch)
{
    PushOptions o;
    o.maxSearch = maxSearch;
    return push(automaton, tools, o);
}

PushReport push(Automaton& automaton, const std::vector<ShapePtr>& tools, const PushOptions& options)
{
    const int maxSearch = options.maxSearch;
    const int32_t threshold = options.threshold > 0 ? options.threshold : automaton.options().rule.threshold;
    if (maxSearch < 0 || maxSearch > kMaxSearchLimit) {
        throw Error("push: maxSearch must lie in [0, " + std::to_string(kMaxSearchLimit) + "], got " +
                    std::to_string(maxSearch));
    }
    for (size_t i = 0; i < tools.size(); ++i) {
        if (!tools[i]) throw Error("push: tools[" + std::to_string(i) + "] is null");
    }
    PushReport report;
    if (tools.empty()) return report;

    Pusher pusher(automaton, tools, maxSearch);
    const Box u = pusher.toolBounds();
    if (u.empty()) return report;
    const bool is2D = automaton.options().dimensions == 2;
    const Box region = grow(u, int64_t(maxSearch) + 2, is2D);
    pusher.setRegion(region);

    struct Move {
        Coord from, to;
        int32_t mass;
    };
    std::vector<Move> moves;
    const std::vector<Source> sources = pusher.sources(u, automaton.options().threads);
    // Voxels each tool entered: the contact size (and the compress push's depth).
    std::vector<uint64_t> entered(tools.size(), 0);
    for (const Source& s : sources)
        ++entered[s.tool];
    std::vector<int> depth(tools.size(), 1);
    for (size_t t = 0; t < tools.size(); ++t) {
        const double size = is2D ? double(entered[t]) : std::sqrt(double(entered[t]));
        report.contactSize = std::max(report.contactSize, size);
        depth[t] = std::max(1, int(std::lround(std::min(size, double(kMaxSearchLimit)))));
    }
    // Compress: a tool that covers the clay it entered compresses the whole column ahead and pools
    // its sources (design comment); the chains may reach beyond the surface push's region.
    const bool compress = options.mode == PushMode::Compress;
    std::vector<char> covers(tools.size(), 0);
    std::vector<std::unique_ptr<openvdb::Int32Tree>> pools(tools.size());
    std::vector<int64_t> pooled(tools.size(), 0);
    if (compress) {
        covers = pusher.covering(sources, threshold);
        int deepest = 1;
        for (size_t t = 0; t < tools.size(); ++t) {
            if (covers[t] && entered[t] > 0) depth[t] = kMaxSearchLimit;
            if (entered[t] > 0) deepest = std::max(deepest, depth[t]);
        }
        pusher.setChainRegion(grow(u, int64_t(std::max(deepest, maxSearch)) + 2, is2D));
    }
    // Step 3 in parallel against the grid alone, then in source order: a found target is kept iff
    // the clay planned before it still leaves room there, else searched again with that clay
    // (Pusher::findAlone: the same targets as a serial search, on any thread count).
    std::vector<Pusher::Found> found(sources.size());
    pusher.reserve(sources.size());
    parallel_internal::forEachIndex(sources.size(), automaton.options().threads,
                                    [&](size_t i) { found[i] = pusher.findAlone(sources[i]); });
    for (size_t si = 0; si < sources.size(); ++si) {
        const Source& s = sources[si];
        Coord to;
        bool ok = found[si].ok; // trapped alone: trapped with the planned clay too
        if (ok && pusher.fits(found[si].to, s.mass))
            pusher.adopt(found[si], to);
        else if (ok)
            ok = pusher.target(s, to);
        if (ok) {
            std::vector<Coord> chain;
            if (compress) chain = pusher.fullChain(s, to, depth[s.tool], threshold);
            if (covers[s.tool] && !chain.empty()) {
                // Pooled: the zone keeps each cell's smallest distance (in chain places) from the tool, + 1.
                if (!pools[s.tool]) pools[s.tool] = std::make_unique<openvdb::Int32Tree>(0);
                openvdb::tree::ValueAccessor<openvdb::Int32Tree> zone(*pools[s.tool]);
                for (size_t i = 0; i < chain.size(); ++i) {
                    const int32_t v = zone.getValue(chain[i]);
                    if (v == 0 || v > int32_t(i) + 1) zone.setValueOn(chain[i], int32_t(i) + 1);
                }
                pooled[s.tool] += s.mass;
                moves.push_back(Move{s.c, to, 0}); // the source is emptied below; its clay is pooled
                ++report.voxelsCompressed;
            } else if (chain.size() > 1) {
                const int32_t k = int32_t(chain.size());
                const int32_t q = s.mass / k, r = s.mass % k;
                for (int32_t i = 0; i < k; ++i) {
                    const int32_t share = q + (i < r ? 1 : 0);
                    if (share) pusher.add(chain[size_t(i)], share);
                }
                moves.push_back(Move{s.c, to, 0}); // the source is emptied below; its clay is added above
                ++report.voxelsCompressed;
            } else {
                pusher.add(to, s.mass);
                moves.push_back(Move{s.c, to, s.mass});
            }
            ++report.voxelsPushed;
            report.massMoved += s.mass;
        } else {
            ++report.voxelsTrapped;
            report.massTrapped += s.mass;
        }
    }
    if (moves.empty()) return report;

    Box targets;
    for (const auto& a : pusher.added())
        targets = unite(targets, Box{{{a.first.x(), a.first.y(), a.first.z()}},
                                     {{a.first.x(), a.first.y(), a.first.z()}}});
    std::vector<const openvdb::Int32Tree*> shared;
    for (size_t t = 0; t < tools.size(); ++t) {
        if (!pools[t]) continue;
        sharePool(*pools[t], pooled[t], pusher, shared);
        shared.push_back(pools[t].get());
        CoordBBox b;
        pools[t]->evalActiveVoxelBoundingBox(b);
        targets = unite(targets, Box{{{b.min().x(), b.min().y(), b.min().z()}},
                                     {{b.max().x(), b.max().y(), b.max().z()}}});
    }
    // Compress chains may end beyond the surface push's region: the report (the global layer's
    // seeds) and the edit cover them. For the surface push the targets lie inside the region.
    report.region = unite(region, targets);
    // The edit rescans and wakes only the part of the region near clay (ClayLeaves.h): the same
    // clay blocks as the whole region, at a cost that follows the clay, not the tools' bounds.
    const Box editRegion =
        clay_internal::narrowedEditRegion(automaton.mass()->constTree(), report.region, targets);
    // Written as the cells' new masses (Automaton::setMasses): the same grid and automaton state as
    // an edit() of the region that empties the sources and adds the targets' and pools' clay, without
    // edit()'s two scans of the region (round 8: 9 % of a surface stroke's frame).
    std::vector<Automaton::CellMass> cells;
    cells.reserve(moves.size() + pusher.added().size());
    {
        auto acc = automaton.mass()->getConstAccessor();
        // Sources lie inside a tool and targets outside every tool, and each is listed once: no voxel
        // twice. The pools' voxels may be targets too (or another pool's): those are merged by a map.
        for (const Move& m : moves)
            cells.push_back(Automaton::CellMass{{{m.from.x(), m.from.y(), m.from.z()}}, 0});
        for (const auto& a : pusher.added()) {
            const Coord& c = a.first;
            cells.push_back(
                Automaton::CellMass{{{c.x(), c.y(), c.z()}}, int32_t(int64_t(acc.getValue(c)) + a.second)});
        }
        if (!shared.empty()) {
            std::unordered_map<Coord, size_t, CoordHash> index;
            for (size_t k = moves.size(); k < cells.size(); ++k)
                index.emplace(Coord(cells[k].at[0], cells[k].at[1], cells[k].at[2]), k);
            for (const auto& pool : pools) {
                if (!pool) continue;
                for (auto it = pool->cbeginValueOn(); it; ++it) {
                    if (!*it) continue;
                    const Coord& c = it.getCoord();
                    const auto [at, fresh] = index.emplace(c, cells.size());
                    if (fresh) cells.push_back(Automaton::CellMass{{{c.x(), c.y(), c.z()}}, acc.getValue(c)});
                    Automaton::CellMass& cell = cells[at->second];
                    cell.mass = int32_t(int64_t(cell.mass) + *it);
                }
            }
        }
    } // the accessor goes before the write
    automaton.setMasses(editRegion, cells);
    return report;
}

} // namespace vdbclay
