// The automaton subsystem: the virtual-clay cellular automaton on a sparse OpenVDB grid, and the
// public Automaton (Automaton.h) that drives it.
//
// Margolus phases on 8^3 leaves
// =============================
// A step applies the rule (Rules.h) to every block of its phase that can change: even steps use the
// 2x2x2 blocks (2D: 2x2 in z = 0) whose minimum corner has even coordinates, odd steps the blocks
// shifted by one voxel along every axis. The blocks of one phase are disjoint, so they can be
// updated in any order and in parallel. OpenVDB leaves are 8^3 voxels: the 64 even blocks of a leaf
// lie inside it; on odd steps the 64 blocks whose maximum corner lies in a leaf (its anchor) reach
// into its lower neighbours (-x, -y, -z and their combinations) when they start at local -1. So
// every block has one anchor leaf and one bit in a 64-bit mask per anchor (BlockMasks.h), and a
// step's work list is one item per anchor: its candidate blocks.
//
// Candidate blocks
// ================
// A block can change only if one of its cells changed in the previous two steps (Candidates.h):
// the candidates of a step are the blocks changed two steps ago plus the blocks of this phase that
// overlap one changed on the last step, pruned further to those whose cells can let them change.
// After construction, resync() or an edit the region concerned is examined whole for two steps. The
// cost of a step follows the blocks that changed recently, not the volume; a settled region costs
// nothing. Two ways to build the list, same blocks: dense mode, while the flat leaf table
// (LeafTable.h) is valid (nearly every step of a settling run), accumulates per table anchor and
// is filled by the pass itself; merged mode (after edits) merges sorted lists.
//
// Stages of step(), each timed into StageSeconds
// ==============================================
//   gather       Candidates::gather: one entry per anchor, in the leaf table's column order (x,
//                then y, then z) in dense mode, in layer order (y, z, x: the paper's horizontal
//                layers) in merged mode.
//   repartition  the pass over the work list (PassEngine.h, Kernel.h), leaf table builds included.
//   grow         a block that must write into a missing leaf is not written in the pass but queued;
//                afterwards, serially, its leaves are created (touchLeaf) and the block is updated.
//                Since blocks of a phase are disjoint, doing it later gives the identical result.
//   bookkeeping  the changed masks become the next steps' candidates (dense mode: only kept as
//                lists, for a return to merged mode); counters are reduced.
// The automaton never empties a cell (over cells keep at least Tc, or m - floor(alpha m) > 0 for
// arata, and under cells only gain), and a leaf is only created to receive clay, so no pruning is
// needed after a step; edit() prunes leaves a tool emptied.
//
// The pass engine's threading model
// =================================
// On one thread (threads = 1) the calling thread runs the whole work list through processRange.
// On n threads (PassEngine.h):
//   chunks    the list is cut into n contiguous chunks, one per thread (in dense mode slabs of
//             columns, which meet on small y-z faces); each item runs in exactly one chunk.
//   crew      the chunks run on a PassCrew (PassCrew.h): helper threads kept from one pass to the
//             next, a pass published by one atomic store, so a step pays no fork/join. Crew lane l
//             records its items' changes into its own lane of the next steps' candidates
//             (Candidates::lanes): plain ORs, no word written by two threads.
//   balance   the cuts follow each chunk's measured seconds per candidate block in this phase
//             (PassBalance.h), so that the chunks finish together.
//   predrain  chunk 0, once done, drains the next step's candidates that the later chunks cannot
//             reach (Candidates::predrain): that part of the serial gather runs while the other
//             threads still work (chunk 0 starts with a smaller share for it).
// What a task of the pass may write, and why that is safe, is Kernel.h's contract. The passes'
// thread-seconds, busy and idle, are reported (StageSeconds::passBusy, passIdle).
//
// Determinism
// ===========
// Each block's result depends only on its cells and on blockHash(origin, step, seed). Blocks of a
// phase are disjoint, so neither the cuts nor the order matter; the reductions are integer sums and
// maxima, and the candidates' lanes are ORed (commutative and idempotent). Only where the list is
// cut depends on time. Results are bit-identical for any thread count and for threads = 1, which
// runs the same kernel on the calling thread; tests/TestAutomaton.cc runs one scene on 1, 2, 3 and 8
// threads and tests/TestGolden.cc pins whole runs per rule and dimension.
//
// Overflow. No result can exceed the sum of its block, which is at most 8 times the largest cell.
// The automaton tracks an upper bound of the largest cell; while 8 x bound fits in int32 nothing can
// overflow. Above that, each step first runs the pass read-only and refuses (throws) before writing
// if any block's result would not fit in int32.
//
// Files, lower first: BlockMasks.h (block masks and addressing, pure), Rules.cc and RulesImpl.h
// (the rules), Candidates.* (which blocks a step examines), LeafTable.* (an anchor's leaves by one
// lookup), Cpu.* (run-time instruction-set dispatch), OverFilter.* (the over-cell filter),
// BlockSimd.h (a block in SSE2 registers), Kernel.* (the pass over a range), PassCrew.*,
// PassBalance.* and PassEngine.* (the pass on several threads), NoRoom.* (the no-room flood), and
// this file: the state (mass, overload, bounds), the stages of a step, validation and scans, edits
// and settle().

#include "vdbclay/Automaton.h"
#include "vdbclay/Metrics.h"

#include "automaton/AutomatonInternal.h"
#include "automaton/BlockMasks.h"
#include "automaton/Candidates.h"
#include "automaton/ChangedClay.h"
#include "automaton/Kernel.h"
#include "automaton/LeafTable.h"
#include "automaton/NoRoom.h"
#include "automaton/PassEngine.h"
#include "automaton/Tiles.h"
#include "core/Format.h"
#include "core/LeafSlots.h"

#include <openvdb/openvdb.h>
#include <openvdb/tree/ValueAccessor.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
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
using namespace automaton_internal; // MassTree, MassLeaf, ObsTree, ObsLeaf (LeafTable.h) among them

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point t0)
{
    return std::chrono::duration<double>(Clock::now() - t0).count();
}

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
    int64_t maxBound = 0; // upper bound of the largest cell value
    int quietSteps = 0;   // consecutive steps that changed nothing
    Candidates candidates;
    LeafTable leafTable;           // cleared whenever a leaf may appear or vanish, or the obstacles change
    uint64_t workWithoutTable = 0; // anchors passed through the accessors since the last build
    bool prune = true;             // automaton_internal::setPruneCandidates
    PassEngine engine;             // the pass on the automaton's threads
    PassSeconds passSeconds;       // this step's passes so far: StageSeconds::passBusy, passIdle
    ChangedClay* changedClay = nullptr; // records where the clay changes (setChangedClay), or null
    /// Where a node may have become uniform since the last collapseUniformLeaves(), which examines
    /// only these (collapseUniformLeavesIn): the regions of edits, setMasses, densify and
    /// editObstacles, and the bounds of the blocks each step changed; or the whole tree
    /// (collapseAll) after a resync or a voxelization, and once the steps' work lists read for their
    /// bounds hold more items than the tree held leaves at the last collapse (the whole walk then
    /// costs less than reading more of them: a step's bounds cost at most a walk of its list).
    std::vector<Box> written;
    bool collapseAll = true;
    uint64_t boundedItems = 0, leavesAtCollapse = 0;

    std::vector<WorkItem> work; // the step's work list, reused between steps

    bool is3D() const { return opts.dimensions == 3; }
    /// Adds @a region to `written`; many regions (a frame of many edits) become their bounds.
    void noteWritten(const Box& region)
    {
        if (collapseAll || region.empty()) return;
        written.push_back(region);
        if (written.size() > 64) {
            Box all = written.front();
            for (const Box& b : written)
                all = unite(all, b);
            written.assign(1, all);
        }
    }
    /// The threads a pass may use: the Automaton's arena's, or (threads = 0) the caller's arena's.
    int passLanes() const
    {
        return arena ? arena->max_concurrency() : tbb::this_task_arena::max_concurrency();
    }
    int cells() const { return is3D() ? 8 : 4; }
    MassTree& tree() { return massGrid->tree(); }
    const ObsTree* obsTree() const { return obsGrid ? &obsGrid->tree() : nullptr; }

    void setThreads(int threads)
    {
        if (threads < 0) throw Error("threads must be >= 0, got " + std::to_string(threads));
        opts.threads = threads;
        engine.reset();
        arena.reset();
        if (threads > 1) arena = std::make_unique<tbb::task_arena>(threads);
    }

    template <typename F> void inArena(F&& f)
    {
        if (arena)
            arena->execute(f);
        else
            f();
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
    /// The leaves are scanned in parallel (one task per leaf: each writes only its own leaf and
    /// result) and the results folded in leaf order, so the sums, the hot list and the error
    /// reported (the first bad voxel in leaf order) are those of a serial scan.
    Scan scanLeaves(const Box* region, const char* context, std::vector<Origin>* hot = nullptr)
    {
        const int64_t tc = rule.threshold;
        const ObsTree* ot = obsTree();
        std::vector<MassLeaf*> leaves;
        if (!region) {
            leaves.reserve(tree().leafCount());
            for (auto it = tree().beginLeaf(); it; ++it)
                leaves.push_back(&*it);
        } else if (region->empty()) {
            return Scan();
        } else {
            if (leafSlotCount(*region) <= int64_t(tree().leafCount())) {
                const Coord lo(region->min[0] & ~7, region->min[1] & ~7, region->min[2] & ~7);
                for (int64_t x = lo.x(); x <= region->max[0]; x += 8)
                    for (int64_t y = lo.y(); y <= region->max[1]; y += 8)
                        for (int64_t z = lo.z(); z <= region->max[2]; z += 8)
                            if (MassLeaf* leaf = tree().probeLeaf(Coord(int32_t(x), int32_t(y), int32_t(z))))
                                leaves.push_back(leaf);
            } else {
                // Fewer leaves than slots: walk them, in the slot loop's order (x, then y, then z).
                const openvdb::CoordBBox rb(Coord(region->min[0], region->min[1], region->min[2]),
                                            Coord(region->max[0], region->max[1], region->max[2]));
                for (auto it = tree().beginLeaf(); it; ++it)
                    if (it->getNodeBoundingBox().hasOverlap(rb)) leaves.push_back(&*it);
                std::sort(leaves.begin(), leaves.end(),
                          [](const MassLeaf* a, const MassLeaf* b) { return a->origin() < b->origin(); });
            }
        }
        struct One {
            Scan s;
            std::string error;
        };
        std::vector<One> per(leaves.size());
        auto visit = [&](size_t k) {
            MassLeaf& leaf = *leaves[k];
            Scan& s = per[k].s;
            const ObsLeaf* ol = ot ? ot->probeConstLeaf(leaf.origin()) : nullptr;
            const bool tileObs = ot && !ol && ot->isValueOn(leaf.origin());
            int32_t* d = leaf.buffer().data();
            for (openvdb::Index i = 0; i < MassLeaf::SIZE; ++i) {
                const int32_t v = d[i];
                if (v == 0) {
                    leaf.setValueOff(i);
                    continue;
                }
                if (v < 0) {
                    per[k].error = std::string(context) + ": voxel " + coordStr(leaf.offsetToGlobalCoord(i)) +
                                   " holds negative mass " + std::to_string(v);
                    return;
                }
                if (!is3D() && leaf.offsetToGlobalCoord(i).z() != 0) { // (its coordinate only when needed)
                    per[k].error = std::string(context) +
                                   ": 2D clay must lie in the z = 0 layer, but voxel " +
                                   coordStr(leaf.offsetToGlobalCoord(i)) + " holds mass " + std::to_string(v);
                    return;
                }
                leaf.setValueOn(i);
                s.mass += v;
                s.maxValue = std::max<int64_t>(s.maxValue, v);
                const bool isObs = ol ? ol->isValueOn(i) : tileObs;
                if (!isObs && v > tc) s.overload += v - tc;
            }
        };
        if (opts.threads == 1 || leaves.size() < 64) {
            for (size_t k = 0; k < leaves.size(); ++k) {
                visit(k);
                if (!per[k].error.empty()) break;
            }
        } else {
            inArena([&] {
                tbb::parallel_for(tbb::blocked_range<size_t>(0, leaves.size(), 16),
                                  [&](const tbb::blocked_range<size_t>& r) {
                                      for (size_t k = r.begin(); k != r.end(); ++k)
                                          visit(k);
                                  });
            });
        }
        Scan s;
        for (size_t k = 0; k < leaves.size(); ++k) {
            if (!per[k].error.empty()) throw Error(per[k].error);
            s.mass += per[k].s.mass;
            s.overload += per[k].s.overload;
            s.maxValue = std::max(s.maxValue, per[k].s.maxValue);
            if (hot && per[k].s.overload != 0) {
                const Coord o = leaves[k]->origin();
                hot->push_back(Origin(o.x(), o.y(), o.z()));
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
        const TileScan tiles = scanTiles(t, rule.threshold, is3D(), massGrid->getName());
        std::vector<Origin> hot;
        const Scan s = scanLeaves(nullptr, "mass grid", &hot);
        if (__builtin_add_overflow(s.mass, tiles.mass, &totalMass)) {
            throw Error("mass grid \"" + massGrid->getName() + "\": the total mass exceeds " +
                        std::to_string(INT64_MAX));
        }
        overload = s.overload; // tiles hold no cell over Tc
        maxBound = std::max(s.maxValue, tiles.maxValue);
        quietSteps = 0;
        clearLeafTable();
        candidates.reset(std::move(hot));
        collapseAll = true;
        written.clear();
    }

    /// Forgets the leaf table (a leaf may appear or vanish, or the obstacles change); the candidates
    /// leave its index for the merged lists.
    void clearLeafTable()
    {
        leafTable.clear();
        candidates.detach();
    }

    /// After an edit of @a region (edit(), setMasses()): prunes the region's leaves it emptied (the grid
    /// holds active exactly its nonzero cells), then wakes every block touching the region.
    void pruneAndWake(const Box& region)
    {
        std::vector<Coord> empty;
        const Coord lo(region.min[0] & ~7, region.min[1] & ~7, region.min[2] & ~7);
        for (int x = lo.x(); x <= region.max[0]; x += 8)
            for (int y = lo.y(); y <= region.max[1]; y += 8)
                for (int z = lo.z(); z <= region.max[2]; z += 8)
                    if (const MassLeaf* l = tree().probeConstLeaf(Coord(x, y, z)))
                        if (l->isEmpty()) empty.push_back(l->origin());
        for (const Coord& c : empty)
            delete tree().stealNode<MassLeaf>(c, 0, false);
        candidates.addRegion(region);
        quietSteps = 0;
    }

    PassInput passInput(int phase, bool dryRun)
    {
        PassInput in;
        in.tree = &tree();
        in.obstacles = obsTree();
        in.rule = rule;
        in.is3D = is3D();
        in.phase = phase;
        in.step = stepCount;
        in.seed = opts.seed;
        in.mayOverflow = maxBound > INT32_MAX / 8;
        in.dryRun = dryRun;
        in.table = leafTable.valid() ? &leafTable : nullptr;
        in.prune = prune;
        return in;
    }

    /// The step's pass (or its overflow check, @a dryRun) over the work list, on the pass engine.
    PassTotals runPass(int phase, bool dryRun)
    {
        if (work.empty()) return PassTotals();
        const PassInput in = passInput(phase, dryRun);
        const int lanes = opts.threads == 1 ? 1 : passLanes();
        // In dense mode the pass records its items' changes as it goes, each thread into its own
        // lane (atomic ORs into shared words cost the pass its second thread, and recording
        // serially after the pass costs a fifth of a step on one core).
        const DenseSink* sinks = !dryRun && in.table ? candidates.lanes(lanes) : nullptr;
        return engine.run(in, sinks, work, lanes, candidates, passSeconds);
    }

    [[noreturn]] void throwOverflow(const PassTotals& tot, int phase)
    {
        const Origin o = blockOrigin(work[tot.overflowItem].anchor, tot.overflowBit, phase, is3D());
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
            candidates.clearChanges();
            finishStep(rep, 0);
            return rep;
        }

        if (maxBound > INT32_MAX / 8 && tree().activeTileCount() > 0) {
            // The read-only overflow check cannot see the blocks that read tiles (the pass defers
            // them): with cells this large the clay is held in leaves alone.
            tree().voxelizeActiveTiles();
            clearLeafTable();
            collapseAll = true;
        }
        auto t0 = Clock::now();
        double buildSeconds = 0; // counted in the repartition, as the accessor fetches it replaces
        if (!leafTable.valid() && workWithoutTable >= 4 * tree().leafCount()) {
            // Rebuilt only once the passes since the last build have fetched at least 4 anchors per
            // leaf through the accessors: a build costs about what fetching a few anchors per leaf
            // saves, so frequent edits of a large grid cost at most a constant factor more than
            // without a table, and settling runs use it for nearly every step.
            leafTable.build(tree(), obsTree(), is3D());
            workWithoutTable = 0;
            buildSeconds = secondsSince(t0);
            t0 = Clock::now();
        }
        if (leafTable.valid() && !candidates.attached())
            candidates.attach(leafTable.anchorIndex(), phase, is3D());
        candidates.gather(phase, is3D(), work);
        if (!leafTable.valid()) workWithoutTable += work.size();
        rep.seconds.gather = secondsSince(t0);

        t0 = Clock::now();
        passSeconds = PassSeconds();
        if (maxBound > INT32_MAX / 8) {
            const PassTotals check = runPass(phase, /*dryRun=*/true);
            if (check.overflow) throwOverflow(check, phase);
        }
        PassTotals tot = runPass(phase, /*dryRun=*/false);
        rep.seconds.repartition = buildSeconds + secondsSince(t0);
        rep.seconds.passBusy = passSeconds.busy;
        rep.seconds.passIdle = passSeconds.idle;
        if (tot.overflow) throwOverflow(tot, phase); // unreachable while maxBound holds

        t0 = Clock::now();
        if (!tot.deferred.empty()) {
            std::sort(tot.deferred.begin(), tot.deferred.end(),
                      [](const PassTotals::Deferred& a, const PassTotals::Deferred& b) {
                          return a.item != b.item ? a.item < b.item : a.bit < b.bit;
                      });
            uint64_t grown = 0;
            for (const PassTotals::Deferred& d : tot.deferred) {
                rep.leavesCreated += growAndUpdate(d, phase, tot, grown);
            }
            rep.blocksGrown = grown;
        }
        rep.seconds.grow = secondsSince(t0);

        t0 = Clock::now();
        if (changedClay) recordChangedBlocks(phase);
        if (tot.updated > 0 && !collapseAll) {
            boundedItems += work.size();
            if (boundedItems > leavesAtCollapse)
                collapseAll = true;
            else
                noteWritten(changedBounds(phase));
        }
        if (tot.sinkMissed) candidates.sinkMissed();
        candidates.record(work);
        rep.blocksVisited = tot.examined;
        rep.blocksOverTc = tot.overTc;
        rep.blocksUpdated = tot.updated;
        overload += tot.overloadDelta;
        maxBound = std::max(maxBound, tot.maxWritten);
        rep.seconds.bookkeeping = secondsSince(t0);
        finishStep(rep, tot.updated);
        return rep;
    }

    /// The bounds of the blocks this step changed (empty if none): an anchor's blocks lie within one
    /// voxel below it and seven above.
    Box changedBounds(int phase) const
    {
        int32_t lo[3] = {INT32_MAX, INT32_MAX, INT32_MAX}, hi[3] = {INT32_MIN, INT32_MIN, INT32_MIN};
        for (const WorkItem& w : work) {
            if (!w.changed) continue;
            for (int a = 0; a < 3; ++a) {
                lo[a] = std::min(lo[a], w.anchor[a]);
                hi[a] = std::max(hi[a], w.anchor[a]);
            }
        }
        if (lo[0] > hi[0]) return Box();
        const int32_t dz = is3D() ? 1 : 0;
        return Box{{{lo[0] - phase, lo[1] - phase, lo[2] - dz * phase}},
                   {{hi[0] + 7, hi[1] + 7, hi[2] + dz * 7}}};
    }

    /// Records the blocks this step changed (each item's changed mask) into changedClay.
    void recordChangedBlocks(int phase)
    {
        const int32_t dz = is3D() ? 1 : 0;
        for (const WorkItem& w : work)
            for (uint64_t bits = w.changed; bits; bits &= bits - 1) {
                const Origin o = blockOrigin(w.anchor, __builtin_ctzll(bits), phase, is3D());
                changedClay->add(Box{{{o.x(), o.y(), o.z()}}, {{o.x() + 1, o.y() + 1, o.z() + dz}}});
            }
    }

    /// Records the part of @a region in each of its leaves into changedClay (an edit's clay can
    /// have changed anywhere in them).
    void recordLeavesIn(const Box& region)
    {
        if (!changedClay || region.empty()) return;
        const Coord lo(region.min[0] & ~7, region.min[1] & ~7, region.min[2] & ~7);
        for (int64_t x = lo.x(); x <= region.max[0]; x += 8)
            for (int64_t y = lo.y(); y <= region.max[1]; y += 8)
                for (int64_t z = lo.z(); z <= region.max[2]; z += 8) {
                    const Coord o{int32_t(x), int32_t(y), int32_t(z)};
                    if (!tree().probeConstLeaf(o)) continue;
                    changedClay->add(
                        intersect(region, Box{{{o.x(), o.y(), o.z()}}, {{o.x() + 7, o.y() + 7, o.z() + 7}}}));
                }
    }

    void finishStep(StepReport& rep, uint64_t updated)
    {
        ++stepCount;
        quietSteps = updated ? 0 : quietSteps + 1;
        candidates.endStep();
        rep.residualOverload = overload;
        rep.settled = settled();
    }

    /// A block whose update flows into missing leaves: create the leaves of the cells it changes
    /// (each receives clay, so no leaf is left empty), then update it. Serial. Returns leaves made.
    /// A block that reads a tile (cells 0) is first read through the tree: with no cell over Tc it
    /// cannot change; otherwise the leaves of its tile slots are created (the tile's value in each
    /// voxel), and it is updated as any other (its update may then flow into missing leaves).
    /// @a grown counts the blocks whose update flowed into a missing leaf (as in a grid without tiles).
    uint64_t growAndUpdate(const PassTotals::Deferred& d, int phase, PassTotals& tot, uint64_t& grown)
    {
        WorkItem& w = work[d.item];
        const BlockTables& tab = blockTables();
        const int n = cells();
        const uint8_t* lf = tab.leaf[is3D()][phase][d.bit];
        uint64_t created = 0;
        auto touch = [&](uint32_t cellMask, bool tilesOnly) {
            for (int c = 0; c < n; ++c) {
                if (!((cellMask >> c) & 1u)) continue;
                const Origin lo = leafOrigin(w.anchor, lf[c]);
                const Coord o(lo.x(), lo.y(), lo.z());
                if (tree().probeLeaf(o) || (tilesOnly && tree().getValue(o) == 0)) continue;
                tree().touchLeaf(o);
                clearLeafTable(); // the pass below must see the new leaf
                noteWritten(Box{{{o.x(), o.y(), o.z()}}, {{o.x() + 7, o.y() + 7, o.z() + 7}}});
                ++created;
            }
        };
        if (d.cells == 0) {
            const Origin bo = blockOrigin(w.anchor, d.bit, phase, is3D());
            bool over = false;
            for (int c = 0; c < n && !over; ++c)
                over = tree().getValue(Coord(bo.x() + (c & 1), bo.y() + ((c >> 1) & 1), bo.z() + (c >> 2))) >
                       rule.threshold;
            if (!over) return 0;
            touch((1u << n) - 1, /*tilesOnly=*/true);
        } else {
            touch(d.cells, /*tilesOnly=*/false);
        }
        // Re-run the block through the same kernel, restricted to this one block; once more if its
        // update flows from a tile's new leaf into a missing one.
        const uint64_t savedMask = w.mask, savedChanged = w.changed;
        w.mask = uint64_t(1) << d.bit;
        bool intoMissing = d.cells != 0; // as a grid without tiles would have deferred it
        PassTotals one;
        for (int round = 0;; ++round) {
            one = PassTotals();
            processRange(passInput(phase, false), work.data(), d.item, d.item + 1, one);
            if (one.overflow || round == 1 || one.deferred.empty() || one.deferred[0].cells == 0) break;
            touch(one.deferred[0].cells, /*tilesOnly=*/false);
            intoMissing = true;
        }
        grown += intoMissing;
        if (d.cells == 0) tot.overTc += one.overTc; // the pass could not read it
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

    bool overloadHasNoRoom()
    {
        return automaton_internal::overloadHasNoRoom(tree(), obsTree(), rule.threshold, overload, totalMass,
                                                     is3D());
    }
};

// ---- the library's own hooks (AutomatonInternal.h) -------------------------------------------------

namespace automaton_internal {

struct AutomatonAccess {
    static Automaton::Impl& impl(Automaton& a) { return *a.mImpl; }
    static const Automaton::Impl& impl(const Automaton& a) { return *a.mImpl; }
};

void setPruneCandidates(Automaton& automaton, bool on)
{
    AutomatonAccess::impl(automaton).prune = on;
}

bool pruneCandidates(const Automaton& automaton)
{
    return AutomatonAccess::impl(automaton).prune;
}

void setChangedClay(Automaton& automaton, ChangedClay* changed)
{
    AutomatonAccess::impl(automaton).changedClay = changed;
}

bool forgetWakesWhenSettled(Automaton& automaton)
{
    auto& im = AutomatonAccess::impl(automaton);
    if (im.overload != 0) return false;
    im.candidates.reset({});
    return true;
}

} // namespace automaton_internal

// ---- public API ----------------------------------------------------------------------------------

const char* stopReasonName(StopReason r)
{
    switch (r) {
    case StopReason::Settled: return "settled";
    case StopReason::Tolerance: return "tolerance";
    case StopReason::StepBudget: return "step-budget";
    case StopReason::NoRoom: return "no-room";
    case StopReason::Stopped: return "stopped";
    }
    return "unknown";
}

StepReport& StepReport::operator+=(const StepReport& o)
{
    steps += o.steps;
    blocksVisited += o.blocksVisited;
    blocksOverTc += o.blocksOverTc;
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

StepReport Automaton::step()
{
    return mImpl->step();
}

StepReport Automaton::run(uint64_t n)
{
    StepReport total;
    total.residualOverload = mImpl->overload;
    total.settled = mImpl->settled();
    for (uint64_t i = 0; i < n; ++i)
        total += mImpl->step();
    return total;
}

bool Automaton::overloadHasNoRoom()
{
    return mImpl->overloadHasNoRoom();
}

StepReport Automaton::settle(uint64_t maxSteps, int64_t tolerance)
{
    SettleOptions o;
    o.maxSteps = maxSteps;
    o.tolerance = tolerance;
    return settle(o);
}

StepReport Automaton::settle(const SettleOptions& so)
{
    StepReport total;
    total.residualOverload = mImpl->overload;
    total.settled = mImpl->settled();
    // After 8192 steps of one settle (counted with so.stepsDone), then at each doubling: is there
    // room for the overload at all? A flood can cost as much as a few hundred steps of a large lump
    // (measured: 0.17 s for a 48^3 lump, ~500 steps' worth), so it waits until settling is long;
    // callers settling in short chunks never pay it (noRoomCheckDue).
    const uint64_t tolerance = uint64_t(std::max<int64_t>(so.tolerance, 0));
    for (;;) {
        const uint64_t done = so.stepsDone + total.steps;
        if (mImpl->settled()) {
            // Quiet with overload left: every over cell is walled in by obstacles and over cells.
            total.reason = mImpl->overload > 0 ? StopReason::NoRoom : StopReason::Settled;
            break;
        }
        if (tolerance > 0 && uint64_t(mImpl->overload) <= tolerance) {
            total.reason = StopReason::Tolerance;
            break;
        }
        if (noRoomCheckDue(done)) {
            if (mImpl->overloadHasNoRoom()) {
                total.reason = StopReason::NoRoom;
                break;
            }
        }
        if (done >= so.maxSteps) {
            total.reason = StopReason::StepBudget;
            break;
        }
        total += mImpl->step();
        if (so.stop && so.stop(*this)) {
            total.reason = StopReason::Stopped;
            break;
        }
    }
    total.residualOverload = mImpl->overload;
    total.settled = mImpl->settled();
    return total;
}

void Automaton::edit(const Box& region, const std::function<void(MassGrid&)>& fn)
{
    if (region.empty()) return;
    Impl& im = *mImpl;
    im.clearLeafTable(); // leaves or obstacles may change (even if fn or a check throws)
    // The region's clay in leaves, before and after (fn may have made tiles): the scans see it all.
    im.noteWritten(region);
    densifyTiles(im.tree(), region);
    const Impl::Scan before = im.scanLeaves(&region, "edit");
    im.recordLeavesIn(region); // the leaves fn may empty and delete
    fn(*im.massGrid);
    densifyTiles(im.tree(), region);
    const Impl::Scan after = im.scanLeaves(&region, "edit");
    im.recordLeavesIn(region); // and those it made
    im.totalMass += after.mass - before.mass;
    im.overload += after.overload - before.overload;
    im.maxBound = std::max(im.maxBound, after.maxValue);
    im.pruneAndWake(region);
}

void Automaton::densify(const Box& region)
{
    if (densifyTiles(mImpl->tree(), region) > 0) {
        mImpl->clearLeafTable();
        mImpl->noteWritten(region);
    }
}

uint64_t Automaton::collapseUniformLeaves()
{
    Impl& im = *mImpl;
    const uint64_t removed =
        im.collapseAll
            ? automaton_internal::collapseUniformLeaves(im.tree(), im.rule.threshold)
            : automaton_internal::collapseUniformLeavesIn(im.tree(), im.rule.threshold, im.written);
    im.collapseAll = false;
    im.written.clear();
    im.boundedItems = 0;
    im.leavesAtCollapse = im.tree().leafCount();
    im.clearLeafTable();
    return removed;
}

void Automaton::setMasses(const Box& region, const std::vector<CellMass>& cells)
{
    Impl& im = *mImpl;
    for (const CellMass& c : cells) { // validate first: nothing half-written
        const Coord at(c.at[0], c.at[1], c.at[2]);
        for (int a = 0; a < 3; ++a)
            if (c.at[size_t(a)] < region.min[size_t(a)] || c.at[size_t(a)] > region.max[size_t(a)])
                throw Error("setMasses: voxel " + coordStr(at) + " lies outside the region");
        if (c.mass < 0)
            throw Error("setMasses: voxel " + coordStr(at) + " would hold negative mass " +
                        std::to_string(c.mass));
        if (!im.is3D() && c.at[2] != 0)
            throw Error("setMasses: 2D clay must lie in the z = 0 layer, but voxel " + coordStr(at) +
                        " would hold mass " + std::to_string(c.mass));
    }
    if (cells.empty()) return;
    im.clearLeafTable(); // leaves may appear or vanish
    im.noteWritten(region);
    const int64_t tc = im.rule.threshold;
    const ObsTree* ot = im.obsTree();
    std::unique_ptr<openvdb::tree::ValueAccessor<const ObsTree, false>> oacc;
    if (ot) oacc = std::make_unique<openvdb::tree::ValueAccessor<const ObsTree, false>>(*ot);
    int64_t mass = 0, overload = 0, maxValue = 0;
    {
        openvdb::tree::ValueAccessor<MassTree> acc(im.tree()); // gone before the pruning below
        for (const CellMass& c : cells) {
            const Coord at(c.at[0], c.at[1], c.at[2]);
            const int64_t before = acc.getValue(at), after = c.mass;
            if (after > 0)
                acc.setValueOn(at, c.mass);
            else
                acc.setValueOff(at, 0);
            mass += after - before;
            maxValue = std::max(maxValue, after);
            if (im.changedClay && after != before) im.changedClay->addVoxel(at.x(), at.y(), at.z());
            if (!im.obstacleAt(oacc.get(), at))
                overload += std::max<int64_t>(0, after - tc) - std::max<int64_t>(0, before - tc);
        }
    }
    im.totalMass += mass;
    im.overload += overload;
    im.maxBound = std::max(im.maxBound, maxValue);
    im.pruneAndWake(region);
}

void Automaton::editObstacles(const Box& region, const std::function<void(ObstacleGrid&)>& fn)
{
    if (region.empty()) return;
    Impl& im = *mImpl;
    im.clearLeafTable(); // leaves or obstacles may change (even if fn or a check throws)
    if (!im.obsGrid) {
        im.obsGrid = openvdb::MaskGrid::create(false);
        im.obsGrid->setName("obstacles");
    }
    // The overload counts only cells that are not obstacles: re-derive it over the region.
    im.noteWritten(region); // its scans set the leaves' states
    const Impl::Scan before = im.scanLeaves(&region, "editObstacles");
    fn(*im.obsGrid);
    const Impl::Scan after = im.scanLeaves(&region, "editObstacles");
    im.overload += after.overload - before.overload;
    im.candidates.addRegion(region);
    im.quietSteps = 0;
}

void Automaton::extendObstacles(const std::function<void(ObstacleGrid&)>& fn)
{
    Impl& im = *mImpl;
    im.clearLeafTable(); // leaves or obstacles may change (even if fn or a check throws)
    if (!im.obsGrid) {
        im.obsGrid = openvdb::MaskGrid::create(false);
        im.obsGrid->setName("obstacles");
    }
    // No cell turned on holds clay (no overload changes) or shares a block with clay (no block
    // that can change sees it before the next wake-up reaches it): nothing to rescan or wake.
    fn(*im.obsGrid);
}

void Automaton::resync()
{
    mImpl->resync();
}

void Automaton::setRule(const RuleParams& rule)
{
    mImpl->rule = compileRule(rule);
    mImpl->opts.rule = rule;
    mImpl->resync();
}

void Automaton::setSeed(uint64_t seed)
{
    mImpl->opts.seed = seed;
}
void Automaton::setStepCount(uint64_t steps)
{
    mImpl->stepCount = steps;
    mImpl->resync();
}
void Automaton::setThreads(int threads)
{
    mImpl->setThreads(threads);
}
const AutomatonOptions& Automaton::options() const
{
    return mImpl->opts;
}
uint64_t Automaton::stepCount() const
{
    return mImpl->stepCount;
}
int64_t Automaton::totalMass() const
{
    return mImpl->totalMass;
}
int64_t Automaton::residualOverload() const
{
    return mImpl->overload;
}
bool Automaton::settled() const
{
    return mImpl->settled();
}
int Automaton::quietSteps() const
{
    return mImpl->quietSteps;
}
const MassGridPtr& Automaton::mass() const
{
    return mImpl->massGrid;
}
const ObstacleGridPtr& Automaton::obstacles() const
{
    return mImpl->obsGrid;
}

} // namespace vdbclay
