// The virtual-clay automaton on a sparse OpenVDB grid.
//
// Design
// ======
// Blocks and anchors. OpenVDB leaves are 8^3 voxels. On even steps a Margolus block starts at even
// coordinates, so the 4x4x4 = 64 even blocks of a leaf lie inside it. On odd steps blocks start at
// odd coordinates, (2i-1, 2i), and the blocks whose maximum corner lies in a leaf L are again 64:
// their minimum corners sit at local -1, 1, 3, 5 along each axis, so the blocks with local -1 reach
// into L's lower neighbours (-x, -y, -z and their combinations: the 7 "straddling" leaves). Every
// block therefore has one anchor leaf (the leaf of its maximum corner; for even blocks the leaf that
// holds it whole) and one bit in a 64-bit mask per anchor: bit = bx + 4 by + 16 bz. In 2D the clay
// lives in z = 0, blocks are 2x2, and only the 16 bits with bz = 0 are used.
//
// What is examined. A block can change only if one of its cells changed in the previous two steps:
// otherwise it is exactly as it was two steps ago, when it could not change (or it would have been
// updated). So the candidates of step t are the blocks changed at t-2 (same phase, same masks) plus
// the blocks of this phase that overlap a block changed at t-1: each block of one phase overlaps 8
// (2D: 4) blocks of the other, which is a shift-and-or on the 64-bit masks, with bits that fall off
// a face going to the neighbouring anchor (dilateAcrossPhase). After construction, resync() or
// edit(), the region concerned is scanned whole for two steps. When no cell is over Tc nothing is
// examined at all. The cost of a step follows the blocks that changed recently, not the volume.
//
// Stages of step(), each timed into StageSeconds:
//   gather       candidates from the last two steps' changes, in order of anchor (y, z, x), one entry
//                per anchor: a sequence of horizontal layers, y up, as in the paper's p layers. The
//                inputs are already sorted runs, so they are merged, not sorted.
//   repartition  tbb::parallel_reduce over contiguous ranges of that list (layers of blocks).
//                Blocks of one phase are disjoint, so tasks write disjoint voxels; they write values
//                only into leaves that exist, and read missing leaves as background 0. The only
//                shared words are leaf value masks (active bits), set with atomic OR when a cell
//                goes from 0 to positive. No topology changes happen in the pass.
//   grow         a block that must write into a missing leaf is not written in the pass but queued;
//                afterwards, serially, its leaves are created (touchLeaf) and the block is updated.
//                Since blocks of a phase are disjoint, doing it later gives the identical result.
//   bookkeeping  the changed masks become the next steps' candidates; counters are reduced.
// The automaton never empties a cell (over cells keep at least Tc, or m - floor(alpha m) > 0 for
// arata, and under cells only gain), and a leaf is only created to receive clay, so no pruning is
// needed after a step; edit() prunes leaves a tool emptied.
//
// Determinism. Each block's result depends only on its cells and on blockHash(origin, step, seed).
// Blocks of a phase are disjoint, so neither the partition nor the order matters; the reductions are
// integer sums and maxima. Results are bit-identical for any thread count and for threads = 1,
// which runs the same body without TBB.
//
// Overflow. No result can exceed the sum of its block, which is at most 8 times the largest cell.
// The automaton tracks an upper bound of the largest cell; while 8 x bound fits in int32 nothing can
// overflow. Above that, each step first runs the pass read-only and refuses (throws) before writing
// if any block's result would not fit in int32.

#include "vdbclay/Automaton.h"
#include "vdbclay/Metrics.h"

#include "Format.h"
#include "RulesImpl.h"

#include <openvdb/openvdb.h>
#include <openvdb/tree/ValueAccessor.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <climits>
#include <sstream>
#include <type_traits>
#include <vector>

namespace vdbclay {

static_assert(std::is_same<MassGrid, openvdb::Int32Grid>::value, "MassGrid must be openvdb::Int32Grid");
static_assert(std::is_same<ObstacleGrid, openvdb::MaskGrid>::value, "ObstacleGrid must be openvdb::MaskGrid");

namespace {

using openvdb::Coord;
using MassTree = openvdb::Int32Tree;
using MassLeaf = MassTree::LeafNodeType;
using ObsTree = openvdb::MaskTree;
using ObsLeaf = ObsTree::LeafNodeType;
static_assert(MassLeaf::DIM == 8, "vdbclay's block masks assume 8^3 leaves");

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point t0)
{
    return std::chrono::duration<double>(Clock::now() - t0).count();
}

// ---- Block masks -------------------------------------------------------------------------------
// bit = bx + 4 by + 16 bz, each in 0..3.
constexpr uint64_t kX0 = 0x1111111111111111ull, kX3 = 0x8888888888888888ull;
constexpr uint64_t kY0 = 0x000F000F000F000Full, kY3 = 0xF000F000F000F000ull;
constexpr uint64_t kZ0 = 0x000000000000FFFFull, kZ3 = 0xFFFF000000000000ull;

uint64_t fullMask(bool is3D) { return is3D ? ~0ull : 0xFFFFull; }

/// A set of candidate (or changed) blocks anchored at one leaf.
struct Anchor {
    Coord origin;
    uint64_t mask;
};

/// Horizontal layers: order by y, then z, then x.
inline bool layerLess(const Coord& a, const Coord& b)
{
    if (a.y() != b.y()) return a.y() < b.y();
    if (a.z() != b.z()) return a.z() < b.z();
    return a.x() < b.x();
}

/// The blocks of the other phase that overlap the blocks in @a a, which belong to phase
/// @a fromPhase. Even block b overlaps odd blocks b and b+1 along each axis (b+1 = 4 is block 0 of
/// the +axis neighbour); odd block c overlaps even blocks c-1 and c (c-1 = -1 is block 3 of the
/// -axis neighbour). Writes up to 8 anchors to @a buf, and to @a shift[i] which neighbour leaf
/// buf[i] is (bit 0 = x, 1 = y, 2 = z; 0 = a's own leaf). Returns how many.
int dilateAcrossPhase(const Anchor& a, int fromPhase, bool is3D, Anchor buf[8], int shift[8])
{
    int n = 1;
    buf[0] = a;
    shift[0] = 0;
    const uint64_t lo[3] = {kX0, kY0, kZ0}, hi[3] = {kX3, kY3, kZ3};
    const int unit[3] = {1, 4, 16};
    const int axes = is3D ? 3 : 2;
    for (int ax = 0; ax < axes; ++ax) {
        const int cnt = n;
        for (int i = 0; i < cnt; ++i) {
            const uint64_t m = buf[i].mask;
            uint64_t within, spill;
            Coord nb = buf[i].origin;
            if (fromPhase == 0) {
                within = m | ((m & ~hi[ax]) << unit[ax]);
                spill = (m & hi[ax]) >> (3 * unit[ax]);
                nb[ax] += 8;
            } else {
                within = m | ((m & ~lo[ax]) >> unit[ax]);
                spill = (m & lo[ax]) << (3 * unit[ax]);
                nb[ax] -= 8;
            }
            buf[i].mask = within;
            if (spill) {
                shift[n] = shift[i] | (1 << ax);
                buf[n++] = Anchor{nb, spill};
            }
        }
    }
    return n;
}

/// Appends to @a out the merge of two runs sorted by layerLess with distinct origins; anchors with
/// the same origin in both become one, their masks ORed. The result has distinct origins too.
void mergeOr(const Anchor* a, const Anchor* ae, const Anchor* b, const Anchor* be, std::vector<Anchor>& out)
{
    while (a != ae && b != be) {
        if (layerLess(a->origin, b->origin)) {
            out.push_back(*a++);
        } else if (layerLess(b->origin, a->origin)) {
            out.push_back(*b++);
        } else {
            out.push_back(Anchor{a->origin, a->mask | b->mask});
            ++a, ++b;
        }
    }
    out.insert(out.end(), a, ae);
    out.insert(out.end(), b, be);
}

// ---- Per-block addressing tables ---------------------------------------------------------------
// For phase p, block bit b and corner c (c = dx + 2 dy + 4 dz): which of the anchor's 8 leaves
// (0 = anchor, bit 0 = -x, bit 1 = -y, bit 2 = -z neighbour) holds the cell, and its offset there.
struct Tables {
    uint16_t offset[2][2][64][8];
    uint8_t leaf[2][2][64][8];
    uint64_t needLeaf[2][8]; // [dims3][leaf]: blocks (odd phase) that touch that neighbour leaf
    Tables()
    {
        for (int d3 = 0; d3 < 2; ++d3) {
            for (int p = 0; p < 2; ++p) {
                for (int b = 0; b < 64; ++b) {
                    const int bx = b & 3, by = (b >> 2) & 3, bz = b >> 4;
                    for (int c = 0; c < 8; ++c) {
                        const int dx = c & 1, dy = (c >> 1) & 1, dz = c >> 2;
                        int lx = 2 * bx - p + dx, ly = 2 * by - p + dy;
                        int lz = d3 ? 2 * bz - p + dz : 0;
                        const int which = (lx < 0 ? 1 : 0) | (ly < 0 ? 2 : 0) | (lz < 0 ? 4 : 0);
                        lx &= 7, ly &= 7, lz &= 7;
                        leaf[d3][p][b][c] = uint8_t(which);
                        offset[d3][p][b][c] = uint16_t((lx << 6) | (ly << 3) | lz);
                    }
                }
            }
            for (int w = 0; w < 8; ++w) {
                uint64_t m = ~0ull;
                if (w & 1) m &= kX0;
                if (w & 2) m &= kY0;
                if (w & 4) m &= (d3 ? kZ0 : 0ull);
                needLeaf[d3][w] = (w == 0) ? ~0ull : m;
            }
        }
    }
};
const Tables& tables()
{
    static const Tables t;
    return t;
}

/// Leaf origin offsets of an anchor's 8 leaves.
inline Coord leafOrigin(const Coord& anchor, int which)
{
    return Coord(anchor.x() - ((which & 1) ? 8 : 0), anchor.y() - ((which & 2) ? 8 : 0),
                 anchor.z() - ((which & 4) ? 8 : 0));
}

/// The leaves an anchor's blocks touch: mass data (null when the leaf is missing) and obstacles.
struct LeafSet {
    MassLeaf* leaf[8] = {};
    int32_t* data[8] = {};
    const int32_t* read[8] = {}; // data, or zeros for a missing leaf: reads need no null test
    const ObsLeaf* obs[8] = {};
    bool obsTile[8] = {}; // obstacle state of the whole region when obs[i] is null
    bool anyMissing = false; // a leaf the mask's blocks touch does not exist
    bool anyObs = false;     // a leaf they touch holds obstacles or lies in an obstacle tile
};

/// What a missing leaf reads as: background 0.
alignas(64) const int32_t kZeroLeaf[MassLeaf::SIZE] = {};

template<typename MassAcc>
void fetchLeaves(LeafSet& ls, const Coord& anchor, uint64_t mask, int phase, bool is3D,
                 MassAcc& acc, const ObsTree* obsTree)
{
    const Tables& t = tables();
    const int count = (phase == 1) ? (is3D ? 8 : 4) : 1;
    ls.anyMissing = false;
    ls.anyObs = false;
    for (int w = 0; w < count; ++w) {
        ls.leaf[w] = nullptr;
        ls.data[w] = nullptr;
        ls.read[w] = kZeroLeaf;
        ls.obs[w] = nullptr;
        ls.obsTile[w] = false;
        if (w && !(mask & t.needLeaf[is3D][w])) continue;
        const Coord o = leafOrigin(anchor, w);
        ls.leaf[w] = acc.probeLeaf(o);
        if (ls.leaf[w]) ls.read[w] = ls.data[w] = ls.leaf[w]->buffer().data();
        else ls.anyMissing = true;
        if (obsTree) {
            ls.obs[w] = obsTree->probeConstLeaf(o);
            if (!ls.obs[w]) ls.obsTile[w] = obsTree->isValueOn(o);
            ls.anyObs |= ls.obs[w] || ls.obsTile[w];
        }
    }
}

/// What one range of the repartition pass accumulates.
struct PassTotals {
    uint64_t visited = 0, updated = 0;
    int64_t overloadDelta = 0;
    int64_t maxWritten = 0;
    bool overflow = false;
    size_t overflowItem = SIZE_MAX;
    int overflowBit = 0;
    struct Deferred {
        uint32_t item;
        uint8_t bit;
        uint8_t cells; // cells the update changes (bit c = corner c)
    };
    std::vector<Deferred> deferred;

    void join(const PassTotals& o)
    {
        visited += o.visited;
        updated += o.updated;
        overloadDelta += o.overloadDelta;
        maxWritten = std::max(maxWritten, o.maxWritten);
        if (o.overflow && (!overflow || o.overflowItem < overflowItem ||
                           (o.overflowItem == overflowItem && o.overflowBit < overflowBit))) {
            overflow = true;
            overflowItem = o.overflowItem;
            overflowBit = o.overflowBit;
        }
        deferred.insert(deferred.end(), o.deferred.begin(), o.deferred.end());
    }
};

struct WorkItem {
    Coord anchor;
    uint64_t mask;    // candidate blocks
    uint64_t changed; // output: blocks updated
};

} // namespace

// ---- Impl ---------------------------------------------------------------------------------------

struct Automaton::Impl {
    AutomatonOptions opts;
    CompiledRule rule;
    MassGridPtr massGrid;
    ObstacleGridPtr obsGrid;
    std::unique_ptr<tbb::task_arena> arena;

    uint64_t stepCount = 0;
    int64_t totalMass = 0;
    int64_t overload = 0;
    int64_t maxBound = 0;     // upper bound of the largest cell value
    int quietSteps = 0;       // consecutive steps that changed nothing
    int fullScanSteps = 0;    // upcoming steps that must examine every leaf holding an over cell
    std::vector<Coord> hotLeaves; // those leaves, found by the last resync()
    struct Pending {
        Box box;
        int steps;
    };
    std::vector<Pending> pending; // edited regions to examine whole for the next two steps
    std::vector<Anchor> changedPrev;  // blocks changed at t-1 (phase of t-1)
    std::vector<Anchor> changedPrev2; // blocks changed at t-2 (phase of t)

    // scratch, reused between steps
    std::vector<WorkItem> work;

    bool is3D() const { return opts.dimensions == 3; }
    int cells() const { return is3D() ? 8 : 4; }
    MassTree& tree() { return massGrid->tree(); }
    const ObsTree* obsTree() const { return obsGrid ? &obsGrid->tree() : nullptr; }

    void setThreads(int threads)
    {
        if (threads < 0) throw Error("threads must be >= 0, got " + std::to_string(threads));
        opts.threads = threads;
        arena.reset();
        if (threads > 1) arena = std::make_unique<tbb::task_arena>(threads);
    }

    template<typename F>
    void inArena(F&& f)
    {
        if (arena) arena->execute(f);
        else f();
    }

    bool obstacleAt(const openvdb::tree::ValueAccessor<const ObsTree, false>* acc, const Coord& c) const
    {
        return acc && acc->isValueOn(c);
    }

    /// Validates and measures the voxels of the leaves overlapping @a region (all leaves when
    /// region is null); makes active exactly the nonzero voxels. Returns mass, overload, max.
    struct Scan {
        int64_t mass = 0, overload = 0, maxValue = 0;
    };
    /// When @a hot is given, the origins of the leaves holding an over cell are appended to it.
    Scan scanLeaves(const Box* region, const char* context, std::vector<Coord>* hot = nullptr)
    {
        Scan s;
        const int64_t tc = rule.threshold;
        const ObsTree* ot = obsTree();
        std::unique_ptr<openvdb::tree::ValueAccessor<const ObsTree, false>> oacc;
        if (ot) oacc = std::make_unique<openvdb::tree::ValueAccessor<const ObsTree, false>>(*ot);
        auto visit = [&](MassLeaf& leaf) {
            const int64_t overloadBefore = s.overload;
            const ObsLeaf* ol = ot ? ot->probeConstLeaf(leaf.origin()) : nullptr;
            const bool tileObs = ot && !ol && ot->isValueOn(leaf.origin());
            int32_t* d = leaf.buffer().data();
            for (openvdb::Index i = 0; i < MassLeaf::SIZE; ++i) {
                const int32_t v = d[i];
                if (v == 0) {
                    leaf.setValueOff(i);
                    continue;
                }
                const Coord c = leaf.offsetToGlobalCoord(i);
                if (v < 0) {
                    throw Error(std::string(context) + ": voxel " + coordStr(c) +
                                " holds negative mass " + std::to_string(v));
                }
                if (!is3D() && c.z() != 0) {
                    throw Error(std::string(context) + ": 2D clay must lie in the z = 0 layer, but voxel " +
                                coordStr(c) + " holds mass " + std::to_string(v));
                }
                leaf.setValueOn(i);
                s.mass += v;
                s.maxValue = std::max<int64_t>(s.maxValue, v);
                const bool isObs = ol ? ol->isValueOn(i) : tileObs;
                if (!isObs && v > tc) s.overload += v - tc;
            }
            if (hot && s.overload != overloadBefore) hot->push_back(leaf.origin());
        };
        if (!region) {
            for (auto it = tree().beginLeaf(); it; ++it) visit(*it);
        } else {
            const Coord lo(region->min[0] & ~7, region->min[1] & ~7, region->min[2] & ~7);
            for (int x = lo.x(); x <= region->max[0]; x += 8) {
                for (int y = lo.y(); y <= region->max[1]; y += 8) {
                    for (int z = lo.z(); z <= region->max[2]; z += 8) {
                        if (MassLeaf* leaf = tree().probeLeaf(Coord(x, y, z))) visit(*leaf);
                    }
                }
            }
        }
        return s;
    }

    void resync()
    {
        MassTree& t = tree();
        if (t.background() != 0) {
            throw Error("mass grid \"" + massGrid->getName() + "\": background must be 0, got " +
                        std::to_string(t.background()));
        }
        t.voxelizeActiveTiles();
        auto it = t.cbeginValueOff();
        it.setMaxDepth(MassTree::ValueOffCIter::LEAF_DEPTH - 1); // tiles only
        for (; it; ++it) {
            if (*it != 0) {
                openvdb::CoordBBox bb;
                it.getBoundingBox(bb);
                throw Error("mass grid \"" + massGrid->getName() + "\": inactive tile " +
                            coordStr(bb.min()) + "-" + coordStr(bb.max()) + " holds mass " +
                            std::to_string(*it) + "; voxelize it or make it active");
            }
        }
        hotLeaves.clear();
        const Scan s = scanLeaves(nullptr, "mass grid", &hotLeaves);
        totalMass = s.mass;
        overload = s.overload;
        maxBound = s.maxValue;
        quietSteps = 0;
        fullScanSteps = 2;
        pending.clear();
        changedPrev.clear();
        changedPrev2.clear();
    }

    // ---- gather ----
    // The candidates come as sorted runs with distinct origins, merged instead of sorted:
    // changedPrev2 (in layer order, as every work list), and changedPrev dilated across the phase,
    // which splits into one run per neighbour shift (streams[w]): each is changedPrev moved by one
    // constant vector, so still in layer order. Only the rare extras (hot leaves after resync(),
    // edited regions) need a sort.
    // All scratch, members so that a step allocates nothing once the buffers have grown.
    struct Run {
        const Anchor *b, *e;
    };
    std::vector<Anchor> streams[8];
    std::vector<Anchor> extras;
    std::vector<Anchor> mergeBuf[2];
    std::vector<Run> runs;
    std::vector<std::pair<size_t, size_t>> spans;

    void addExtra(const Anchor& a, int anchorPhase, int phase)
    {
        if (anchorPhase == phase) {
            extras.push_back(a);
            return;
        }
        Anchor buf[8];
        int shift[8];
        const int n = dilateAcrossPhase(a, anchorPhase, is3D(), buf, shift);
        extras.insert(extras.end(), buf, buf + n);
    }

    /// Every block overlapping an edited region (grown by one voxel).
    void addPending(const Pending& p, int phase)
    {
        const uint64_t full = fullMask(is3D());
        const Coord lo((p.box.min[0] - 1) & ~7, (p.box.min[1] - 1) & ~7, is3D() ? ((p.box.min[2] - 1) & ~7) : 0);
        const int zmax = is3D() ? p.box.max[2] + 1 : 0;
        for (int x = lo.x(); x <= p.box.max[0] + 1; x += 8) {
            for (int y = lo.y(); y <= p.box.max[1] + 1; y += 8) {
                for (int z = lo.z(); z <= zmax; z += 8) addExtra(Anchor{Coord(x, y, z), full}, 0, phase);
            }
        }
    }

    void gather(int phase)
    {
        runs.clear();
        for (auto& st : streams) st.clear();
        extras.clear();
        const uint64_t full = fullMask(is3D());
        if (fullScanSteps > 0) {
            // After resync() only blocks holding an over cell can change, and those cells lie in
            // hotLeaves (an over cell that moved at the first step is followed by changedPrev).
            for (const Coord& o : hotLeaves) addExtra(Anchor{o, full}, 0, phase);
        } else {
            runs.push_back(Run{changedPrev2.data(), changedPrev2.data() + changedPrev2.size()});
        }
        for (const Pending& p : pending) addPending(p, phase);
        Anchor buf[8];
        int shift[8];
        for (const Anchor& a : changedPrev) {
            const int n = dilateAcrossPhase(a, 1 - phase, is3D(), buf, shift);
            for (int i = 0; i < n; ++i) streams[shift[i]].push_back(buf[i]);
        }
        for (const auto& st : streams) runs.push_back(Run{st.data(), st.data() + st.size()});
        if (!extras.empty()) {
            std::sort(extras.begin(), extras.end(),
                      [](const Anchor& x, const Anchor& y) { return layerLess(x.origin, y.origin); });
            size_t k = 0; // fold equal origins
            for (size_t i = 1; i < extras.size(); ++i) {
                if (extras[i].origin == extras[k].origin) extras[k].mask |= extras[i].mask;
                else extras[++k] = extras[i];
            }
            extras.resize(k + 1);
            runs.push_back(Run{extras.data(), extras.data() + extras.size()});
        }
        runs.erase(std::remove_if(runs.begin(), runs.end(), [](const Run& r) { return r.b == r.e; }),
                   runs.end());

        // Merge pairwise, level by level, ping-ponging between two buffers.
        size_t total = 0;
        for (const Run& r : runs) total += size_t(r.e - r.b);
        for (int level = 0; runs.size() > 1; ++level) {
            std::vector<Anchor>& out = mergeBuf[level & 1];
            out.clear();
            out.reserve(total); // no reallocation below: the offsets stay valid
            spans.clear();
            for (size_t i = 0; i < runs.size(); i += 2) {
                const size_t start = out.size();
                if (i + 1 < runs.size()) mergeOr(runs[i].b, runs[i].e, runs[i + 1].b, runs[i + 1].e, out);
                else out.insert(out.end(), runs[i].b, runs[i].e);
                spans.emplace_back(start, out.size());
            }
            runs.clear();
            for (const auto& sp : spans) runs.push_back(Run{out.data() + sp.first, out.data() + sp.second});
        }
        work.clear();
        if (!runs.empty()) {
            work.reserve(size_t(runs[0].e - runs[0].b));
            for (const Anchor* a = runs[0].b; a != runs[0].e; ++a) work.push_back(WorkItem{a->origin, a->mask, 0});
        }
    }

    // ---- the per-block kernel ----
    /// Updates (or, when @a dryRun, only checks) the candidate blocks of work items [begin, end).
    void processRange(size_t begin, size_t end, int phase, bool dryRun, PassTotals& tot)
    {
        const Tables& tab = tables();
        const bool d3 = is3D();
        const int n = cells();
        const int64_t tc = rule.threshold;
        const ObsTree* ot = obsTree();
        const bool mayOverflow = maxBound > INT32_MAX / 8;
        openvdb::tree::ValueAccessor<MassTree, false> acc(tree());
        LeafSet ls;
        // Totals in locals (registers), added to tot once at the end.
        uint64_t visited = 0, updated = 0;
        int64_t overloadDelta = 0, maxWritten = 0;
        for (size_t wi = begin; wi < end; ++wi) {
            WorkItem& w = work[wi];
            w.changed = 0;
            fetchLeaves(ls, w.anchor, w.mask, phase, d3, acc, ot);
            if (phase == 0 && !ls.data[0]) continue; // even blocks of a missing leaf: all 0
            const int odd = phase;
            uint64_t bits = w.mask;
            while (bits) {
                const int b = __builtin_ctzll(bits);
                bits &= bits - 1;
                const uint16_t* off = tab.offset[d3][phase][b];
                const uint8_t* lf = tab.leaf[d3][phase][b];
                int32_t m[8];
                bool anyOver = false;
                for (int c = 0; c < n; ++c) {
                    m[c] = ls.read[lf[c]][off[c]];
                    anyOver |= (m[c] > tc);
                }
                if (!anyOver) continue;
                uint32_t valid = (1u << n) - 1;
                if (ls.anyObs) {
                    for (int c = 0; c < n; ++c) {
                        const ObsLeaf* ol = ls.obs[lf[c]];
                        if (ol ? ol->isValueOn(off[c]) : ls.obsTile[lf[c]]) valid &= ~(1u << c);
                    }
                }
                ++visited;
                BlockKey key;
                key.x = w.anchor.x() + 2 * (b & 3) - odd;
                key.y = w.anchor.y() + 2 * ((b >> 2) & 3) - odd;
                key.z = d3 ? w.anchor.z() + 2 * (b >> 4) - odd : 0;
                key.step = stepCount;
                key.seed = opts.seed;
                int64_t out[8];
                const uint32_t changed = rules_internal::repartition(rule, n, m, valid, key, out);
                if (!changed) continue;
                // Both checks can only fire rarely: a result over INT32_MAX needs a cell over
                // INT32_MAX / 8 somewhere (maxBound), and a write into a missing leaf needs one of
                // the fetched leaves to be missing (clay flowing into space the grid has not grown).
                bool fits = true, missing = false;
                if (mayOverflow || ls.anyMissing) {
                    for (int c = 0; c < n; ++c) {
                        if (!((changed >> c) & 1u)) continue;
                        if (out[c] > INT32_MAX) fits = false;
                        if (!ls.data[lf[c]]) missing = true;
                    }
                }
                if (!fits) {
                    if (!tot.overflow || wi < tot.overflowItem) {
                        tot.overflow = true;
                        tot.overflowItem = wi;
                        tot.overflowBit = b;
                    }
                    continue;
                }
                if (dryRun) continue;
                if (missing) {
                    tot.deferred.push_back(PassTotals::Deferred{uint32_t(wi), uint8_t(b), uint8_t(changed)});
                    continue;
                }
                for (int c = 0; c < n; ++c) {
                    if (!((valid >> c) & 1u)) continue;
                    overloadDelta += std::max<int64_t>(out[c] - tc, 0) - std::max<int64_t>(m[c] - tc, 0);
                    if (!((changed >> c) & 1u)) continue;
                    ls.data[lf[c]][off[c]] = int32_t(out[c]);
                    maxWritten = std::max(maxWritten, out[c]);
                    if (m[c] == 0) {
                        // 0 -> positive: the voxel becomes active. Other tasks may set bits in the
                        // same mask word (straddling blocks), hence the atomic OR.
                        auto& word = ls.leaf[lf[c]]->getValueMask().template getWord<uint64_t>(off[c] >> 6);
                        __atomic_fetch_or(&word, uint64_t(1) << (off[c] & 63), __ATOMIC_RELAXED);
                    }
                }
                ++updated;
                w.changed |= uint64_t(1) << b;
            }
        }
        tot.visited += visited;
        tot.updated += updated;
        tot.overloadDelta += overloadDelta;
        tot.maxWritten = std::max(tot.maxWritten, maxWritten);
    }

    PassTotals runPass(int phase, bool dryRun)
    {
        PassTotals tot;
        if (work.empty()) return tot;
        if (opts.threads == 1) {
            processRange(0, work.size(), phase, dryRun, tot);
            return tot;
        }
        struct Body {
            Impl* self;
            int phase;
            bool dryRun;
            PassTotals tot;
            Body(Impl* s, int p, bool d) : self(s), phase(p), dryRun(d) {}
            Body(Body& o, tbb::split) : self(o.self), phase(o.phase), dryRun(o.dryRun) {}
            void operator()(const tbb::blocked_range<size_t>& r)
            {
                self->processRange(r.begin(), r.end(), phase, dryRun, tot);
            }
            void join(Body& o) { tot.join(o.tot); }
        };
        Body body(this, phase, dryRun);
        inArena([&] { tbb::parallel_reduce(tbb::blocked_range<size_t>(0, work.size(), 4), body); });
        return std::move(body.tot);
    }

    [[noreturn]] void throwOverflow(const PassTotals& tot, int phase)
    {
        const WorkItem& w = work[tot.overflowItem];
        const int b = tot.overflowBit;
        const Coord o(w.anchor.x() + 2 * (b & 3) - phase, w.anchor.y() + 2 * ((b >> 2) & 3) - phase,
                      is3D() ? w.anchor.z() + 2 * (b >> 4) - phase : 0);
        throw Error("step " + std::to_string(stepCount) + ": the block at " + coordStr(o) +
                    " would put more than INT32_MAX (" + std::to_string(INT32_MAX) +
                    ") clay in one cell; the state was refused and left unchanged "
                    "(lower the masses or raise the threshold)");
    }

    StepReport step()
    {
        StepReport rep;
        rep.steps = 1;
        const int phase = int(stepCount & 1);
        if (overload == 0) {
            // No cell is over Tc: no block can change.
            changedPrev2.clear();
            changedPrev.clear();
            finishStep(rep, 0);
            return rep;
        }

        auto t0 = Clock::now();
        gather(phase);
        rep.seconds.gather = secondsSince(t0);

        t0 = Clock::now();
        if (maxBound > INT32_MAX / 8) {
            const PassTotals check = runPass(phase, /*dryRun=*/true);
            if (check.overflow) throwOverflow(check, phase);
        }
        PassTotals tot = runPass(phase, /*dryRun=*/false);
        rep.seconds.repartition = secondsSince(t0);
        if (tot.overflow) throwOverflow(tot, phase); // unreachable while maxBound holds

        t0 = Clock::now();
        if (!tot.deferred.empty()) {
            std::sort(tot.deferred.begin(), tot.deferred.end(),
                      [](const PassTotals::Deferred& a, const PassTotals::Deferred& b) {
                          return a.item != b.item ? a.item < b.item : a.bit < b.bit;
                      });
            for (const PassTotals::Deferred& d : tot.deferred) {
                rep.leavesCreated += growAndUpdate(d, phase, tot);
            }
            rep.blocksGrown = tot.deferred.size();
        }
        rep.seconds.grow = secondsSince(t0);

        t0 = Clock::now();
        changedPrev2.swap(changedPrev);
        changedPrev.clear();
        for (const WorkItem& w : work) {
            if (w.changed) changedPrev.push_back(Anchor{w.anchor, w.changed});
        }
        rep.blocksVisited = tot.visited;
        rep.blocksUpdated = tot.updated;
        overload += tot.overloadDelta;
        maxBound = std::max(maxBound, tot.maxWritten);
        rep.seconds.bookkeeping = secondsSince(t0);
        finishStep(rep, tot.updated);
        return rep;
    }

    void finishStep(StepReport& rep, uint64_t updated)
    {
        ++stepCount;
        quietSteps = updated ? 0 : quietSteps + 1;
        if (fullScanSteps > 0) --fullScanSteps;
        for (Pending& p : pending) --p.steps;
        pending.erase(std::remove_if(pending.begin(), pending.end(),
                                     [](const Pending& p) { return p.steps <= 0; }),
                      pending.end());
        rep.residualOverload = overload;
        rep.settled = settled();
    }

    /// A block whose update flows into missing leaves: create the leaves of the cells it changes
    /// (each receives clay, so no leaf is left empty), then update it. Serial. Returns leaves made.
    uint64_t growAndUpdate(const PassTotals::Deferred& d, int phase, PassTotals& tot)
    {
        WorkItem& w = work[d.item];
        const Tables& tab = tables();
        const int n = cells();
        const uint8_t* lf = tab.leaf[is3D()][phase][d.bit];
        uint64_t created = 0;
        for (int c = 0; c < n; ++c) {
            if (!((d.cells >> c) & 1u)) continue;
            const Coord o = leafOrigin(w.anchor, lf[c]);
            if (!tree().probeLeaf(o)) {
                tree().touchLeaf(o);
                ++created;
            }
        }
        // Re-run the block through the same kernel, restricted to this one block.
        const uint64_t savedMask = w.mask, savedChanged = w.changed;
        w.mask = uint64_t(1) << d.bit;
        PassTotals one;
        processRange(d.item, d.item + 1, phase, false, one);
        w.mask = savedMask;
        w.changed = savedChanged | w.changed;
        if (!one.deferred.empty() || one.overflow) {
            throw Error("internal error: a grown block could not be updated");
        }
        tot.updated += one.updated;
        tot.overloadDelta += one.overloadDelta;
        tot.maxWritten = std::max(tot.maxWritten, one.maxWritten);
        return created;
    }

    bool settled() const { return overload == 0 || quietSteps >= 2; }

    /// True when the overload provably cannot vanish: flooding from every over cell through the
    /// non-obstacle cells (face neighbours; 2D: in z = 0) closes on walled-in regions that hold more
    /// than Tc per cell. Gives up (false) as soon as the cells reached have room for the whole
    /// overload, or are more than ceil(total mass / Tc) (they could hold all the clay there is):
    /// the cost is bounded by the clay's volume.
    bool overloadHasNoRoom()
    {
        if (overload == 0) return false;
        const int64_t tc = rule.threshold;
        const uint64_t limit = uint64_t((totalMass + tc - 1) / tc);
        const ObsTree* ot = obsTree();
        std::unique_ptr<openvdb::tree::ValueAccessor<const ObsTree, false>> oacc;
        if (ot) oacc = std::make_unique<openvdb::tree::ValueAccessor<const ObsTree, false>>(*ot);
        openvdb::MaskTree seen(false);
        openvdb::tree::ValueAccessor<openvdb::MaskTree> sacc(seen);
        openvdb::tree::ValueAccessor<const MassTree, false> macc(tree());
        std::vector<Coord> stack;
        for (auto it = tree().cbeginValueOn(); it; ++it) {
            if (int64_t(*it) <= tc || obstacleAt(oacc.get(), it.getCoord())) continue;
            stack.push_back(it.getCoord());
            sacc.setValueOn(it.getCoord());
        }
        static const Coord kFace[6] = {Coord(1, 0, 0), Coord(-1, 0, 0), Coord(0, 1, 0),
                                       Coord(0, -1, 0), Coord(0, 0, 1), Coord(0, 0, -1)};
        const int faces = is3D() ? 6 : 4;
        uint64_t cellsSeen = 0;
        int64_t massSeen = 0, room = 0;
        while (!stack.empty()) {
            const Coord c = stack.back();
            stack.pop_back();
            if (++cellsSeen > limit) return false;
            const int64_t m = macc.getValue(c);
            massSeen += m;
            if (m < tc && (room += tc - m) >= overload) return false;
            for (int f = 0; f < faces; ++f) {
                const Coord q = c + kFace[f];
                if (sacc.isValueOn(q) || obstacleAt(oacc.get(), q)) continue;
                sacc.setValueOn(q);
                stack.push_back(q);
            }
        }
        return massSeen > tc * int64_t(cellsSeen);
    }
};

// ---- public API ----------------------------------------------------------------------------------

const char* stopReasonName(StopReason r)
{
    switch (r) {
    case StopReason::Settled: return "settled";
    case StopReason::Tolerance: return "tolerance";
    case StopReason::StepBudget: return "step-budget";
    case StopReason::NoRoom: return "no-room";
    }
    return "unknown";
}

StepReport& StepReport::operator+=(const StepReport& o)
{
    steps += o.steps;
    blocksVisited += o.blocksVisited;
    blocksUpdated += o.blocksUpdated;
    blocksGrown += o.blocksGrown;
    leavesCreated += o.leavesCreated;
    residualOverload = o.residualOverload;
    settled = o.settled;
    seconds += o.seconds;
    return *this;
}

Automaton::Automaton(MassGridPtr mass, const AutomatonOptions& options, ObstacleGridPtr obstacles)
    : mImpl(std::make_unique<Impl>())
{
    if (!mass) throw Error("Automaton: the mass grid is null");
    if (options.dimensions != 2 && options.dimensions != 3) {
        throw Error("dimensions must be 2 or 3, got " + std::to_string(options.dimensions));
    }
    mImpl->opts = options;
    mImpl->rule = compileRule(options.rule);
    mImpl->massGrid = std::move(mass);
    mImpl->obsGrid = std::move(obstacles);
    mImpl->setThreads(options.threads);
    mImpl->resync();
}

Automaton::~Automaton() = default;
Automaton::Automaton(Automaton&&) noexcept = default;
Automaton& Automaton::operator=(Automaton&&) noexcept = default;

StepReport Automaton::step() { return mImpl->step(); }

StepReport Automaton::run(uint64_t n)
{
    StepReport total;
    total.residualOverload = mImpl->overload;
    total.settled = mImpl->settled();
    for (uint64_t i = 0; i < n; ++i) total += mImpl->step();
    return total;
}

bool Automaton::overloadHasNoRoom() { return mImpl->overloadHasNoRoom(); }

StepReport Automaton::settle(uint64_t maxSteps, int64_t tolerance)
{
    StepReport total;
    total.residualOverload = mImpl->overload;
    total.settled = mImpl->settled();
    // After 8192 steps of one call, then at each doubling: is there room for the overload at all?
    // A flood can cost as much as a few hundred steps of a large lump (measured: 0.17 s for a 48^3
    // lump, ~500 steps' worth), so it waits until settling is long; callers settling in short
    // chunks never pay it.
    uint64_t roomCheck = kNoRoomCheckSteps;
    for (;;) {
        if (mImpl->settled()) {
            // Quiet with overload left: every over cell is walled in by obstacles and over cells.
            total.reason = mImpl->overload > 0 ? StopReason::NoRoom : StopReason::Settled;
            break;
        }
        if (tolerance > 0 && mImpl->overload <= tolerance) {
            total.reason = StopReason::Tolerance;
            break;
        }
        if (total.steps >= roomCheck) {
            roomCheck *= 2;
            if (mImpl->overloadHasNoRoom()) {
                total.reason = StopReason::NoRoom;
                break;
            }
        }
        if (total.steps >= maxSteps) {
            total.reason = StopReason::StepBudget;
            break;
        }
        total += mImpl->step();
    }
    total.residualOverload = mImpl->overload;
    total.settled = mImpl->settled();
    return total;
}

void Automaton::edit(const Box& region, const std::function<void(MassGrid&)>& fn)
{
    if (region.empty()) return;
    Impl& im = *mImpl;
    const Impl::Scan before = im.scanLeaves(&region, "edit");
    fn(*im.massGrid);
    im.tree().voxelizeActiveTiles();
    const Impl::Scan after = im.scanLeaves(&region, "edit");
    im.totalMass += after.mass - before.mass;
    im.overload += after.overload - before.overload;
    im.maxBound = std::max(im.maxBound, after.maxValue);
    // Prune leaves the edit emptied, then forget changes anchored there (they hold no clay now).
    std::vector<Coord> empty;
    const Coord lo(region.min[0] & ~7, region.min[1] & ~7, region.min[2] & ~7);
    for (int x = lo.x(); x <= region.max[0]; x += 8)
        for (int y = lo.y(); y <= region.max[1]; y += 8)
            for (int z = lo.z(); z <= region.max[2]; z += 8)
                if (const MassLeaf* l = im.tree().probeConstLeaf(Coord(x, y, z)))
                    if (l->isEmpty()) empty.push_back(l->origin()); // scanLeaves: active == nonzero
    for (const Coord& c : empty) {
        delete im.tree().stealNode<MassLeaf>(c, 0, false);
    }
    im.pending.push_back(Impl::Pending{region, 2});
    im.quietSteps = 0;
}

void Automaton::editObstacles(const Box& region, const std::function<void(ObstacleGrid&)>& fn)
{
    if (region.empty()) return;
    Impl& im = *mImpl;
    if (!im.obsGrid) {
        im.obsGrid = openvdb::MaskGrid::create(false);
        im.obsGrid->setName("obstacles");
    }
    // The overload counts only cells that are not obstacles: re-derive it over the region.
    const Impl::Scan before = im.scanLeaves(&region, "editObstacles");
    fn(*im.obsGrid);
    const Impl::Scan after = im.scanLeaves(&region, "editObstacles");
    im.overload += after.overload - before.overload;
    im.pending.push_back(Impl::Pending{region, 2});
    im.quietSteps = 0;
}

void Automaton::resync() { mImpl->resync(); }

void Automaton::setRule(const RuleParams& rule)
{
    mImpl->rule = compileRule(rule);
    mImpl->opts.rule = rule;
    mImpl->resync();
}

void Automaton::setSeed(uint64_t seed) { mImpl->opts.seed = seed; }
void Automaton::setStepCount(uint64_t steps)
{
    mImpl->stepCount = steps;
    mImpl->resync();
}
void Automaton::setThreads(int threads) { mImpl->setThreads(threads); }
const AutomatonOptions& Automaton::options() const { return mImpl->opts; }
uint64_t Automaton::stepCount() const { return mImpl->stepCount; }
int64_t Automaton::totalMass() const { return mImpl->totalMass; }
int64_t Automaton::residualOverload() const { return mImpl->overload; }
bool Automaton::settled() const { return mImpl->settled(); }
int Automaton::quietSteps() const { return mImpl->quietSteps; }
const MassGridPtr& Automaton::mass() const { return mImpl->massGrid; }
const ObstacleGridPtr& Automaton::obstacles() const { return mImpl->obsGrid; }

} // namespace vdbclay
