// The push operation: clay inside a tool moves to the nearest free voxel outside every tool.
//
// 1. U = union of the tools' bounds (2D: clipped to z = 0). Only leaves of the mass grid that meet
//    U are visited, and in them only clay voxels are tested against the tools; the clay voxels whose
//    centre is inside a tool are the sources, in coordinate order (Pusher.h). A voxel inside a tool
//    is a source even if it is an obstacle: a Sculptor makes the tools' voxels obstacles while clay
//    settles around them.
// 2. Each source is given the tool that holds it most deeply and that tool's normal at its centre
//    (2D: z dropped).
// 3. Target (Pusher.h): a march along the normal past the surface, then a flood through passable
//    voxels within maxSearch, the first free voxel found; failing both, the clay is trapped. The
//    searches run in parallel against the grid alone, then are checked in source order against the
//    clay planned before (the room test), and searched again serially where it no longer fits: the
//    same targets as a serial search. The compress push (Compress.h) spreads a source whose target is
//    full clay over the chain of clay ahead of it instead.
// 4. The plan (sources emptied, targets increased, pools shared) is computed read-only first, then
//    written as the cells' new masses (Automaton::setMasses: an edit that reads only those cells)
//    over the region U grown by maxSearch + 2 (and the chains), cut to the part near clay
//    (ClayLeaves.h: the same clay blocks are woken, the cost follows the clay), so nothing is written
//    if a tool throws or a pooled share would not fit. The planned clay and the pools are dense arrays
//    per 8^3 leaf (LeafArrays.h): the pools are shared, and the cells written are gathered, leaf by
//    leaf in parallel, merged in leaf order (the same cells on any thread count).
// Sources are inside a tool and targets outside all tools, so no voxel is both; the plan depends only
// on the grid, the tools and the source order: deterministic.

#include "vdbclay/Push.h"
#include "vdbclay/Automaton.h"

#include "push/ClayLeaves.h"
#include "push/Compress.h"
#include "push/Pusher.h"
#include "core/ParallelFor.h"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <array>
#include <climits>
#include <cmath>
#include <memory>
#include <utility>
#include <vector>

namespace vdbclay {

using namespace push_internal;

namespace {

using openvdb::CoordBBox;

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

    // The sources are the clay voxels of the leaves in the tools' bounds: clay held there as tiles
    // becomes leaves first (the clay is unchanged).
    {
        Box bounds;
        for (const ShapePtr& t : tools)
            bounds = unite(bounds, t->bounds());
        automaton.densify(bounds);
    }
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
    // The voxels each tool entered, and their bounds: the contact size (and the compress push's
    // depth) is the contact's width, the square root of their count (3D; the count in 2D), at most
    // that of the bounds' largest face (the longest side in 2D): a tool dipped deep enters many
    // voxels over a contact no wider than itself.
    std::vector<uint64_t> entered(tools.size(), 0);
    std::vector<openvdb::CoordBBox> enteredBounds(tools.size());
    for (const Source& s : sources) {
        ++entered[s.tool];
        enteredBounds[s.tool].expand(s.c);
    }
    std::vector<int> depth(tools.size(), 1);
    for (size_t t = 0; t < tools.size(); ++t) {
        const openvdb::Coord e = entered[t] > 0 ? enteredBounds[t].dim() : openvdb::Coord(0);
        const double face = is2D ? double(std::max(e.x(), e.y()))
                                 : std::sqrt(double(std::max({int64_t(e.x()) * e.y(), int64_t(e.y()) * e.z(),
                                                              int64_t(e.x()) * e.z()})));
        const double size = std::min(is2D ? double(entered[t]) : std::sqrt(double(entered[t])), face);
        report.contactSize = std::max(report.contactSize, size);
        depth[t] = std::max(1, int(std::lround(std::min(size, double(kMaxSearchLimit)))));
    }
    // Compress: a tool that covers the clay it entered compresses the whole column ahead and pools
    // its sources (Compress.h); the chains may reach beyond the surface push's region.
    const bool compress = options.mode == PushMode::Compress;
    std::vector<char> covers(tools.size(), 0);
    std::vector<std::unique_ptr<Pool>> pools(tools.size());
    std::vector<int64_t> pooled(tools.size(), 0);
    if (compress) {
        covers = covering(pusher, sources, threshold);
        int deepest = 1;
        for (size_t t = 0; t < tools.size(); ++t) {
            if (covers[t] && entered[t] > 0) depth[t] = kMaxSearchLimit;
            if (entered[t] > 0) deepest = std::max(deepest, depth[t]);
        }
        pusher.setChainRegion(grow(u, int64_t(std::max(deepest, maxSearch)) + 2, is2D));
    }
    // Step 3 in parallel against the grid alone, then in source order: a found target is kept iff
    // the clay planned before it still leaves room there, else searched again with that clay
    // (Pusher.h: the same targets as a serial search, on any thread count).
    std::vector<Found> found(sources.size());
    parallel_internal::forEachIndex(sources.size(), automaton.options().threads,
                                    [&](size_t i) { found[i] = pusher.findAlone(sources[i]); });
    Pusher::Reader reader(pusher);
    std::vector<Coord> chain;
    for (size_t si = 0; si < sources.size(); ++si) {
        const Source& s = sources[si];
        Found f = found[si]; // trapped alone: trapped with the planned clay too
        if (f.ok && !reader.fits(f.to, s.mass)) f = pusher.target(s, reader);
        if (f.ok) {
            const Coord to = f.to;
            chain.clear();
            if (compress) fullChain(reader, s, f, depth[s.tool], threshold, chain);
            if (covers[s.tool] && !chain.empty()) {
                // Pooled: the zone keeps each cell's smallest distance (in chain places) from the tool, + 1.
                if (!pools[s.tool]) pools[s.tool] = std::make_unique<Pool>();
                Pool::Accessor zone(*pools[s.tool]);
                for (size_t i = 0; i < chain.size(); ++i) {
                    int32_t& v = zone.ref(chain[i]);
                    if (v == 0 || v > int32_t(i) + 1) v = int32_t(i) + 1;
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

    const int threads = automaton.options().threads;
    Box targets = nonZeroBounds(pusher.added());
    std::vector<const Pool*> shared;
    for (size_t t = 0; t < tools.size(); ++t) {
        if (!pools[t]) continue;
        targets = unite(targets, nonZeroBounds(*pools[t])); // every cell of the zone, before the shares
        sharePool(*pools[t], pooled[t], pusher, shared, threads);
        shared.push_back(pools[t].get());
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
    // edit()'s two scans of the region (9 % of a surface stroke's frame).
    // The cells: the sources emptied, then the voxels given clay (planned or pooled), leaf by leaf in
    // parallel, each leaf's cells in offset order, the leaves in origin order (any order of the cells
    // gives setMasses() the same result; this one is the same on any thread count).
    std::vector<const PlannedClay*> given{&pusher.added()};
    given.insert(given.end(), shared.begin(), shared.end());
    std::vector<Coord> origins;
    for (const PlannedClay* g : given)
        for (size_t l = 0; l < g->leafCount(); ++l)
            origins.push_back(g->leaf(l).origin);
    std::sort(origins.begin(), origins.end());
    origins.erase(std::unique(origins.begin(), origins.end()), origins.end());
    const Tree543<int32_t>& massTree = automaton.mass()->constTree();
    std::vector<std::vector<Automaton::CellMass>> perLeaf(origins.size());
    parallel_internal::forEachIndex(origins.size(), threads, [&](size_t l) {
        const Coord& o = origins[l];
        std::array<int32_t, kSlotVoxels> delta{};
        for (const PlannedClay* g : given)
            if (const PlannedClay::Leaf* leaf = g->find(o))
                for (uint32_t i = 0; i < kSlotVoxels; ++i)
                    delta[i] += leaf->v[i]; // fits: the mass with every share passed the room test
        openvdb::tree::ValueAccessor<const Tree543<int32_t>, false> acc(massTree);
        const auto* massLeaf = acc.probeConstLeaf(o);
        const int32_t uniform = massLeaf ? 0 : acc.getValue(o);
        std::vector<Automaton::CellMass>& out = perLeaf[l];
        for (uint32_t i = 0; i < kSlotVoxels; ++i) {
            if (!delta[i]) continue;
            const Coord c = slotVoxel(o, i);
            const int32_t before = massLeaf ? massLeaf->getValue(i) : uniform;
            out.push_back(Automaton::CellMass{{{c.x(), c.y(), c.z()}}, int32_t(int64_t(before) + delta[i])});
        }
    });
    size_t count = moves.size();
    for (const auto& l : perLeaf)
        count += l.size();
    std::vector<Automaton::CellMass> cells;
    cells.reserve(count);
    // Sources lie inside a tool and the voxels given clay outside every tool: no voxel twice.
    for (const Move& m : moves)
        cells.push_back(Automaton::CellMass{{{m.from.x(), m.from.y(), m.from.z()}}, 0});
    for (const auto& l : perLeaf)
        cells.insert(cells.end(), l.begin(), l.end());
    automaton.setMasses(editRegion, cells);
    return report;
}

} // namespace vdbclay
