// The sculpt subsystem: a Sculptor runs a scene frame by frame on the automaton (Sculpt.h).
//
// Files. FramePolicy.{h,cc}: every per-frame decision (which transport runs, the sweep's sub-steps,
// the automaton's bounded try before the global layer, the layer's reach and seeds, where the tools'
// cells are marked), each one function called here and by the memory estimate. MemoryEstimate.cc (the
// model) and EstimateGeometry.cc (its boxes and leaf counts): what a run will need, checked against
// the scene's budget before any grid is built.
//
// The constructor checks the budget, builds the clay (or reads the start file), rasterises the
// obstacles and places the tools. A frame (runFrame): the push (pushTools: sub-steps with
// Scene::sweep), then with the global transport the automaton's try (settleBounded) and, if that did
// not end the frame, the layer (transportGlobally, its arrays kept from frame to frame and freed after
// the last one), then the automaton settles the rest within the scene's step budget
// (settleOpenFrame), and last the scene's surface tension smooths the surface the frame changed, the
// whole surface in the scene's first frame (endFrame; SurfaceTension.h: the automaton records the
// frame's changes into changedClay, which a checkpoint inside a frame carries). A stop request ends a frame
// only after a step from which a checkpoint resumes exactly (checkpointMeta: the frame's steps so far; the
// push, the try and the layer are never repeated). Every stage is deterministic and thread-count independent,
// so a run's clay and hashes are the same on any number of threads and across a checkpoint.
//
// The tools' cells. While clay settles, the voxels a tool occupies are obstacles (otherwise clay
// would flow back into the tool that just pushed it out). Only the tool voxels the automaton can read
// need to be obstacles: those in a Margolus block with clay, and those the no-room flood reaches. So
// the tools are marked where the clay is, ahead of it, not over their whole bounds (placeTools,
// cover):
// - at placement, in every leaf slot (8^3) of the tools' bounds within one slot of a mass leaf
//   (clay lies in leaves; a block reaches one voxel beyond its cell), evaluated in parallel over
//   slots and merged in slot order, tool by tool (the same cells as the whole bounds gave, where
//   they are needed; thread-count independent);
// - before each settle (the push may have put clay in new leaves) and after every step that
//   created a leaf (a step moves clay at most one voxel, into a slot already covered), the slots
//   near the new leaves; before the no-room flood (Automaton::kNoRoomCheckSteps, then doublings)
//   also the slots the flood can reach through empty cells (ceil(overload / Tc) + 1 voxels
//   beyond the clay). These go through Automaton::extendObstacles: cells no step has read yet,
//   so nothing is woken and the quiet-step count is kept;
// - all of the bounds when that is fewer slots, or with the global transport
//   (frame_policy::toolCellsOverWholeBounds: it moves clay far).
// The clay, the step counts and the hashes are those of marking the whole bounds every frame.
#include "vdbclay/Sculpt.h"

#include "vdbclay/Deposit.h"
#include "vdbclay/IO.h"
#include "vdbclay/Metrics.h"
#include "vdbclay/Smooth.h"

#include "automaton/AutomatonInternal.h"
#include "automaton/Tiles.h"
#include "push/ClayLeaves.h"
#include "core/CoordHash.h"
#include "shapes/InsideBox.h"
#include "core/Format.h"
#include "core/LeafSlots.h"
#include "sculpt/MemoryEstimate.h"
#include "sculpt/MemoryWatchdog.h"
#include "core/ParallelFor.h"
#include "shapes/Rasterize.h"
#include "sculpt/FramePolicy.h"
#include "sculpt/SurfaceTension.h"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <climits>
#include <cmath>
#include <cstring>
#include <iterator>
#include <optional>
#include <sstream>
#include <thread>
#include <unordered_set>

namespace vdbclay {

namespace {

/// Adds every active voxel of @a src into @a dst, refusing sums that overflow a cell. Leaf by leaf
/// (no accessor per voxel): a leaf slot that @a dst lacks gets a new leaf holding @a src's active
/// values; one it has gets them added, the first overflow in tree order refused as before. A tile of
/// @a src goes in slot by slot: a tile where @a dst holds nothing, added voxel by voxel where it does.
void addClay(openvdb::Int32Grid& dst, const openvdb::Int32Grid& src, const std::string& field)
{
    using Leaf = openvdb::Int32Tree::LeafNodeType;
    auto addTo = [&](Leaf* out, openvdb::Index pos, int32_t v) {
        const int64_t sum = int64_t(out->getValue(pos)) + int64_t(v);
        if (sum > INT32_MAX) {
            throw Error(field + ": overlapping clay at voxel " + coordStr(out->offsetToGlobalCoord(pos)) +
                        " adds up to " + std::to_string(sum) + ", more than a voxel holds (" +
                        std::to_string(INT32_MAX) + ")");
        }
        out->setValueOn(pos, int32_t(sum));
    };
    auto tile = src.tree().cbeginValueOn();
    tile.setMaxDepth(tile.getLeafDepth() - 1);
    for (; tile; ++tile) {
        if (*tile == 0) continue;
        openvdb::CoordBBox bb;
        tile.getBoundingBox(bb);
        for (int64_t x = bb.min().x(); x <= bb.max().x(); x += 8)
            for (int64_t y = bb.min().y(); y <= bb.max().y(); y += 8)
                for (int64_t z = bb.min().z(); z <= bb.max().z(); z += 8) {
                    const openvdb::Coord o{int32_t(x), int32_t(y), int32_t(z)};
                    Leaf* out = dst.tree().probeLeaf(o);
                    if (!out && dst.tree().getValue(o) == 0) {
                        dst.tree().addTile(1, o, *tile, true);
                        continue;
                    }
                    if (!out) out = dst.tree().touchLeaf(o);
                    for (openvdb::Index i = 0; i < Leaf::SIZE; ++i)
                        addTo(out, i, *tile);
                }
    }
    for (auto it = src.tree().cbeginLeaf(); it; ++it) {
        const Leaf& in = *it;
        if (in.isEmpty()) continue;
        Leaf* out = dst.tree().probeLeaf(in.origin());
        if (!out) {
            // An absent leaf reads as the background (0) or a tile: fall back on one voxel at a time.
            if (dst.tree().getValue(in.origin()) != 0 || dst.tree().isValueOn(in.origin())) {
                out = dst.tree().touchLeaf(in.origin());
            } else {
                auto fresh = std::make_unique<Leaf>(in.origin(), 0, false);
                for (auto v = in.cbeginValueOn(); v; ++v)
                    fresh->setValueOn(v.pos(), *v);
                dst.tree().addLeaf(fresh.release());
                continue;
            }
        }
        for (auto v = in.cbeginValueOn(); v; ++v)
            addTo(out, v.pos(), *v);
    }
}

/// Every voxel whose centre lies inside @a shape (only z = 0 in 2D) becomes an obstacle; leaf by
/// leaf on @a threads (Rasterize.h: the voxels of forEachVoxelInside).
void rasterize(openvdb::MaskGrid& mask, const Shape& shape, int dims, int threads)
{
    raster_internal::rasterizeInside(mask.tree(), shape, dims, true, threads);
}

/// The first voxel (in tree order) of @a mass holding clay that is on in @a obstacles, if any: the
/// two trees' topologies intersected (tiles stay tiles), then that intersection's voxels read.
std::optional<openvdb::Coord> clayInObstacles(const openvdb::Int32Tree& mass,
                                              const openvdb::MaskTree& obstacles)
{
    openvdb::MaskTree both(mass, false, openvdb::TopologyCopy());
    both.topologyIntersection(obstacles);
    openvdb::tree::ValueAccessor<const openvdb::Int32Tree> macc(mass);
    for (auto it = both.cbeginValueOn(); it; ++it) {
        openvdb::CoordBBox bb;
        it.getBoundingBox(bb);
        for (auto c = bb.begin(); c; ++c)
            if (macc.getValue(*c) != 0) return *c;
    }
    return std::nullopt;
}

/// A start file written in the middle of a frame continues that frame: only the scene that wrote it
/// can do that exactly, so its rule, Tc, alpha, seed, dimensions and frame must fit the scene.
void checkResumable(const Scene& scene, const ClayMeta& m)
{
    const std::string where = scene.source + ": start: " + scene.start + " was written during frame " +
                              std::to_string(m.frames + 1) + " ";
    auto differs = [&](const std::string& what, const std::string& file, const std::string& here) {
        throw Error(where + "with " + what + " " + file + ", but the scene has " + here +
                    "; a frame can only be finished by the scene that began it");
    };
    if (m.dimensions != scene.dimensions)
        differs("dimensions", std::to_string(m.dimensions), std::to_string(scene.dimensions));
    if (m.rule.rule != scene.rule.rule) differs("rule", ruleName(m.rule.rule), ruleName(scene.rule.rule));
    if (m.rule.threshold != scene.rule.threshold)
        differs("Tc", std::to_string(m.rule.threshold), std::to_string(scene.rule.threshold));
    if (m.rule.rule == Rule::Arata && m.rule.alpha != scene.rule.alpha)
        differs("alpha", std::to_string(m.rule.alpha), std::to_string(scene.rule.alpha));
    if (m.seed != scene.seed) differs("seed", std::to_string(m.seed), std::to_string(scene.seed));
    if (m.frames >= scene.frames) {
        throw Error(where + "but the scene has only " + std::to_string(scene.frames) + " frames");
    }
}

} // namespace

struct Sculptor::Impl {
    Scene scene;
    MassGridPtr mass;
    openvdb::MaskGrid::Ptr obstacles; ///< static obstacles only
    std::unique_ptr<Automaton> automaton;
    GlobalTransportWorkspace transportWorkspace; ///< the global layer's arrays, reused frame to frame
    uint64_t frame = 0;                          ///< frames finished
    bool open = false;                           ///< frame + 1 is pushed and partly settled
    uint64_t openSteps = 0;                      ///< its settling steps so far
    /// cells that are obstacles because a tool is there: per leaf slot (origin), a mask of them
    std::vector<std::pair<openvdb::Coord, openvdb::MaskTree::LeafNodeType::NodeMaskType>> toolCells;
    Box toolRegion; ///< bounds of the tools as placed now
    // Where the tools' cells are marked (file comment): slots and leaves by origin >> 3.
    std::vector<ShapePtr> placed; ///< the tools as placed now
    // Sets, not MaskTrees: a few hundred slots a frame, where a tree cleared every frame allocated
    // and zeroed its upper nodes again (~1 ms a frame on the 48^3 press).
    std::unordered_set<openvdb::Coord, CoordHash>
        coveredSlots; ///< slots of toolRegion whose tool cells are marked
    std::unordered_set<openvdb::Coord, CoordHash>
        seenLeaves;                     ///< mass leaves whose neighbouring slots are covered
    bool coveredAll = false;            ///< every slot of toolRegion is covered
    openvdb::Index64 leavesAtCover = 0; ///< the mass tree's leaf count at the last cover
    std::function<bool()> stopPoll;
    bool stopped = false;
    ClayMeta startMeta;
    std::unique_ptr<MemoryEstimate> estimate; ///< estimateSceneMemory(scene), once computed
    // The memory watchdog (none without a budget), and what the run needed when it last asked to
    // stop (0 when the last stop poll was the caller's, or asked nothing).
    std::unique_ptr<sculpt_internal::MemoryWatchdog> watchdog;
    uint64_t budgetStop = 0;
    /// Clay the add tools put in and the remove tools took away since the scene's frame 0 (a start
    /// file's counts included): checkpointMeta() records them.
    int64_t massAdded = 0, massRemoved = 0;
    int64_t massSmoothed = 0; ///< clay the smooth tools moved (this Sculptor's frames)
    /// With the scene's surface tension: where the open frame's clay has changed (the automaton
    /// records into it; emptied when a frame opens, a checkpoint's read back).
    automaton_internal::ChangedClay changedClay;

    std::vector<ShapePtr> toolsAt(uint64_t f) const
    {
        std::vector<ShapePtr> tools;
        for (const ToolSpec& t : scene.tools)
            tools.push_back(makeTransformed(t.shape.shape, t.poseAt(f)));
        return tools;
    }

    /// Of @a tools (placed scene.tools, in order), those whose action is @a action.
    std::vector<ShapePtr> withAction(const std::vector<ShapePtr>& tools, ToolAction action) const
    {
        std::vector<ShapePtr> out;
        for (size_t i = 0; i < tools.size(); ++i)
            if (scene.tools[i].action == action) out.push_back(tools[i]);
        return out;
    }
    /// Of @a tools, the solid ones (toolIsSolid: push and remove): their voxels are obstacles while
    /// clay settles. A scene of push tools only: all of them.
    std::vector<ShapePtr> solid(const std::vector<ShapePtr>& tools) const
    {
        std::vector<ShapePtr> out;
        for (size_t i = 0; i < tools.size(); ++i)
            if (toolIsSolid(scene.tools[i].action)) out.push_back(tools[i]);
        return out;
    }

    /// The caller's stop poll, then the memory watchdog (budgetStop says whether it asked).
    bool stopRequested()
    {
        budgetStop = 0;
        if (stopPoll && stopPoll()) return true;
        if (!watchdog || !watchdog->outgrown(*mass)) return false;
        budgetStop = watchdog->needs();
        return true;
    }

    /// Closes the open frame. After the scene's last frame the global layer's arrays are freed: no
    /// later call needs them, and what follows a run (writing its output) has that memory back
    /// (estimateSceneMemory counts the layer and the output apart, not added).
    void finishFrame()
    {
        open = false;
        openSteps = 0;
        ++frame;
        // Uniform leaves back to tiles, so memory and the walks of later frames follow the surface.
        automaton->collapseUniformLeaves();
        if (frame >= scene.frames) transportWorkspace.release();
    }

    /// Ends the open frame: the scene's surface tension over the surface the frame changed (the whole
    /// surface in the scene's first frame; sculpt/SurfaceTension.h), then finishFrame().
    void endFrame(FrameReport& rep)
    {
        if (scene.surfaceTension > 0) {
            const auto t0 = std::chrono::steady_clock::now();
            if (rep.frame == 1) sculpt_internal::addWholeSurface(*mass, scene.dimensions, changedClay);
            const std::vector<Box> boxes =
                sculpt_internal::tensionBoxes(changedClay.entries(), scene.dimensions, kSurfaceTensionMargin);
            // Solid tools as placed now are never entered (their cells are obstacles near the clay).
            const sculpt_internal::TensionReport t =
                sculpt_internal::smoothBoxes(*automaton, boxes, scene.surfaceTension, placed);
            massSmoothed += t.massMoved;
            rep.massSmoothed += t.massMoved;
            rep.tensionBoxes = t.boxes;
            rep.tensionVoxels = t.visited;
            rep.tensionSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
            // The smoothing woke every block it touched (the whole surface in the first frame), but
            // it made no cell overloaded: with none over Tc, the next frame's steps need examine
            // none of them.
            automaton_internal::forgetWakesWhenSettled(*automaton);
        }
        finishFrame();
    }

    /// The voxels placeTools(@a tools) would edit: the tools' bounds (2D: only z = 0).
    Box regionOf(const std::vector<ShapePtr>& tools) const
    {
        Box region;
        for (const ShapePtr& t : tools)
            region = unite(region, t->bounds());
        if (scene.dimensions == 2) {
            region.min[2] = std::max(region.min[2], 0);
            region.max[2] = std::min(region.max[2], 0);
        }
        return region;
    }

    /// Whether a checkpoint taken between frames resumes exactly: the automaton's quiet-step count
    /// is 0 (as a resumed one's, which restarts at 0), or it cannot matter: nothing is overloaded,
    /// or the next frame starts with an edit (placing the tools), which restarts the count in both
    /// runs. Otherwise the resumed run would settle at a different step, so no checkpoint is taken.
    bool boundaryResumesExactly() const
    {
        if (automaton->quietSteps() == 0 || automaton->residualOverload() == 0) return true;
        if (scene.tools.empty() || frame >= scene.frames) return false;
        return !unite(regionOf(solid(toolsAt(frame + 1))), toolRegion).empty();
    }

    /// Settles the open frame through Automaton::settle with the rest of its step budget: the
    /// frame's steps so far are settle's stepsDone, so the budget and the no-room check's schedule
    /// count in frame steps and a resumed frame stops exactly where an unbroken one does. The stop
    /// hook keeps the tools' cells ahead of the clay (keepToolsAhead) and ends the settle after a
    /// step when the stop poll asks and the state resumes exactly (no quiet step is pending: a
    /// resumed automaton restarts its quiet count at 0). @a finished is false when the poll cut the
    /// frame short (StopReason::Stopped).
    StepReport settleOpenFrame(bool& finished)
    {
        const StepReport r = settleFrameUpTo(scene.settle.maxSteps, /*honourStop=*/true);
        finished = r.reason != StopReason::Stopped;
        return r;
    }

    /// Automaton::settle on the open frame until frame step @a maxSteps (see settleOpenFrame), the
    /// tools kept ahead of the clay; a stop request ends it only if @a honourStop.
    StepReport settleFrameUpTo(uint64_t maxSteps, bool honourStop)
    {
        SettleOptions so;
        so.maxSteps = maxSteps;
        so.tolerance = scene.settle.tolerance;
        so.stepsDone = openSteps;
        const uint64_t step0 = automaton->stepCount();
        keepToolsAhead(openSteps, true);
        so.stop = [this, step0, honourStop](const Automaton& a) {
            keepToolsAhead(openSteps + (a.stepCount() - step0), false);
            return honourStop && a.quietSteps() == 0 && stopRequested();
        };
        const StepReport r = automaton->settle(so);
        openSteps += r.steps;
        return r;
    }

    /// The global transport's first try: the automaton alone, in chunks, on the clay near the
    /// overload, under the frame policy's rules (FramePolicy.h: after a surface push only, not on
    /// saturated clay, within a work and a step cap). The clay near the overload: the clay leaves
    /// meeting @a near, in leaves or tiles (frame_policy::tryNear: the push's region grown by the layer's
    /// reach), the whole body when @a near is empty (no tool touched clay): a frame costs the tool's zone,
    /// not the model, and a saturated lump beside a loose one is judged by itself. @a finished: the frame
    /// ended here (settled, tolerance, no room, the scene's step budget); otherwise the global layer
    /// runs on what is left. No stop request is honoured here (the try is bounded, as the layer is):
    /// a frame saved open is always past its global layer, so a resumed frame never repeats or skips
    /// it, with no new checkpoint field.
    StepReport settleBounded(bool& finished, const Box& near)
    {
        StepReport total;
        finished = false;
        if (automaton->residualOverload() == 0) return total; // the layer would do nothing either
        if (!frame_policy::tryAfterPush(scene)) return total;
        uint64_t voxels = 0;
        int64_t clay = 0;
        if (near.empty()) {
            voxels = mass->activeVoxelCount();
            clay = automaton->totalMass();
        } else { // exact integers (a voxel is active exactly when it holds clay: Automaton::edit)
            clay_internal::clayInSlotsNear(mass->constTree(), near, voxels, clay);
        }
        if (frame_policy::trySaturated(scene, clay, voxels)) return total;
        const double work = frame_policy::tryWork(scene, voxels);
        // The cap counts the blocks the automaton visits. With the candidates pruned that count
        // would depend on how the automaton's bookkeeping started (a resumed run begins from merged
        // lists): the try visits every block near a change, so that a resumed run gives up where the
        // unbroken one does.
        struct FullVisits {
            Automaton& a;
            const bool was;
            explicit FullVisits(Automaton& x) : a(x), was(automaton_internal::pruneCandidates(x))
            {
                automaton_internal::setPruneCandidates(a, false);
            }
            ~FullVisits() { automaton_internal::setPruneCandidates(a, was); }
        } fullVisits(*automaton);
        for (;;) {
            const StepReport r =
                settleFrameUpTo(frame_policy::tryChunkEnd(scene, openSteps), /*honourStop=*/false);
            total += r;
            total.reason = r.reason;
            total.residualOverload = r.residualOverload;
            total.settled = r.settled;
            if (r.reason != StopReason::StepBudget || openSteps >= scene.settle.maxSteps) {
                finished = true;
                return total;
            }
            if (frame_policy::tryGivesUp(openSteps, total.blocksVisited, work)) return total;
        }
    }

    /// Before the automaton's next step, with @a frameSteps steps of the frame run: marks the
    /// tools' cells near leaves created since the last cover (always when @a afterPush), and, when
    /// settle's next check is the no-room flood, as far as the flood can reach.
    void keepToolsAhead(uint64_t frameSteps, bool afterPush)
    {
        if (placed.empty() || coveredAll) return;
        const bool floodNext = Automaton::noRoomCheckDue(frameSteps);
        const openvdb::Index64 leaves = mass->constTree().leafCount();
        if (!afterPush && !floodNext && leaves == leavesAtCover) return;
        int64_t reach = 1;
        if (floodNext) {
            // The flood gives up once the empty cells it reached have room for the overload, so it
            // reads obstacles at most ceil(overload / Tc) + 1 voxels beyond the clay.
            const int64_t tc = scene.rule.threshold;
            const int64_t voxels = (automaton->residualOverload() + tc - 1) / tc + 2;
            reach = std::max<int64_t>(1, (voxels + 7) / 8 + 1);
        }
        automaton->extendObstacles([&](ObstacleGrid& grid) { cover(grid, reach); });
    }

    /// Marks the tools' cells (placed, within toolRegion) in the slots within @a reach slots of a
    /// mass leaf that are not covered yet; in every slot of toolRegion when that is fewer, or with
    /// the global transport. The tools are evaluated one after the other, each in parallel over
    /// the slots, and merged in slot order: the cells marked and toolCells do not depend on the
    /// thread count, and a cell already an obstacle is not evaluated (as forEachVoxelInside's
    /// skip did over the whole bounds).
    void cover(ObstacleGrid& grid, int64_t reach)
    {
        leavesAtCover = mass->constTree().leafCount();
        const Box box = toolRegion;
        if (placed.empty() || box.empty() || coveredAll) return;
        using openvdb::Coord;
        const bool is2D = scene.dimensions == 2;
        const Coord lo(box.min[0] >> 3, box.min[1] >> 3, box.min[2] >> 3);
        const Coord hi(box.max[0] >> 3, box.max[1] >> 3, box.max[2] >> 3);
        const int64_t boxSlots = leafSlotCount(box);
        bool all = frame_policy::toolCellsOverWholeBounds(scene) || reach > 64;
        std::vector<Coord> leaves; // the slots holding clay, in leaves or tiles
        if (!all) {
            leaves = clay_internal::claySlotsNear(mass->constTree(),
                                                  clay_internal::grownBy(box, int32_t(8 * reach)));
            const int64_t side = 2 * reach + 1;
            const int64_t around = side * side * (is2D ? 1 : side);
            all = int64_t(leaves.size()) > boxSlots / around;
        }
        std::vector<Coord> slots;
        if (all) {
            for (int32_t x = lo.x(); x <= hi.x(); ++x)
                for (int32_t y = lo.y(); y <= hi.y(); ++y)
                    for (int32_t z = lo.z(); z <= hi.z(); ++z)
                        if (!coveredSlots.count(Coord(x, y, z))) slots.emplace_back(x, y, z);
            coveredAll = true;
        } else {
            const int r = int(reach), rz = is2D ? 0 : r;
            for (const Coord& origin : leaves) {
                const Coord o(origin.x() >> 3, origin.y() >> 3, origin.z() >> 3);
                if (reach == 1 && !seenLeaves.insert(o).second) continue;
                for (int dx = -r; dx <= r; ++dx)
                    for (int dy = -r; dy <= r; ++dy)
                        for (int dz = -rz; dz <= rz; ++dz) {
                            const Coord c = o.offsetBy(dx, dy, dz);
                            if (c.x() < lo.x() || c.x() > hi.x() || c.y() < lo.y() || c.y() > hi.y() ||
                                c.z() < lo.z() || c.z() > hi.z() || coveredSlots.count(c))
                                continue;
                            slots.push_back(c);
                        }
            }
            // In coordinate order, each once (as the MaskTree of slots wanted gave them before).
            std::sort(slots.begin(), slots.end());
            slots.erase(std::unique(slots.begin(), slots.end()), slots.end());
        }
        coveredSlots.insert(slots.begin(), slots.end());
        if (slots.empty()) return;
        auto acc = grid.getAccessor();
        using MaskLeaf = openvdb::MaskTree::LeafNodeType;
        for (const ShapePtr& t : placed) {
            Box tb = t->bounds();
            if (is2D) tb = intersect(tb, Box{{{INT32_MIN, INT32_MIN, 0}}, {{INT32_MAX, INT32_MAX, 0}}});
            // An unrotated box tool (a plate): its cells are a box (InsideBox.h), no distance per cell.
            Box cellsBox;
            const bool boxed = shapes_internal::insideVoxelBox(*t, cellsBox);
            if (boxed) tb = intersect(tb, cellsBox);
            // Per slot, the mask of its cells inside the tool (merged whole leaves at a time below,
            // instead of a cell at a time through the accessor: press 128^3, ~0.1 M cells a frame).
            std::vector<MaskLeaf::NodeMaskType> inside(slots.size());
            parallel_internal::forEachIndex(slots.size(), automaton->options().threads, [&](size_t i) {
                const Coord o = slots[i];
                const Box sb = intersect(tb, Box{{{o.x() * 8, o.y() * 8, o.z() * 8}},
                                                 {{o.x() * 8 + 7, o.y() * 8 + 7, o.z() * 8 + 7}}});
                if (sb.empty()) return;
                openvdb::tree::ValueAccessor<const openvdb::MaskTree, false> ro(grid.constTree());
                for (int32_t x = sb.min[0]; x <= sb.max[0]; ++x)
                    for (int32_t y = sb.min[1]; y <= sb.max[1]; ++y)
                        for (int32_t z = sb.min[2]; z <= sb.max[2]; ++z) {
                            const Coord c(x, y, z);
                            if (ro.isValueOn(c)) continue;
                            if (boxed || t->distance(Vec3{{double(x), double(y), double(z)}}) < 0)
                                inside[i].setOn(MaskLeaf::coordToOffset(c));
                        }
            });
            for (size_t i = 0; i < slots.size(); ++i) {
                if (inside[i].isOff()) continue;
                // Cells not on yet, so the slot is no active tile: touchLeaf gives its leaf.
                const Coord origin(slots[i].x() * 8, slots[i].y() * 8, slots[i].z() * 8);
                acc.touchLeaf(origin)->getValueMask() |= inside[i];
                toolCells.emplace_back(origin, inside[i]);
            }
        }
    }

    /// Places the tools at frame @a f and pushes clay out of them. With Scene::sweep, the move from
    /// frame f - 1 is split into frame_policy::sweepSubsteps() sub-steps (at most a quarter voxel of
    /// a corner of any tool's bounds each), each placed and pushed in turn, so the push acts on the
    /// volume the tools sweep and clay never passes through a thin or fast tool.
    PushReport pushTools(uint64_t f)
    {
        PushOptions po;
        po.mode = scene.push;
        const std::vector<ShapePtr> tools = toolsAt(f);
        const int substeps = frame_policy::sweepSubsteps(scene, f);
        PushReport total;
        for (int k = 1; k <= substeps; ++k) {
            std::vector<ShapePtr> sub;
            if (k == substeps) {
                sub = tools;
            } else {
                const double w = double(k) / double(substeps);
                for (const ToolSpec& t : scene.tools) {
                    const Pose a = t.poseAt(f - 1), b = t.poseAt(f);
                    Pose p = b;
                    for (int i = 0; i < 3; ++i) {
                        p.translation[i] = a.translation[i] + w * (b.translation[i] - a.translation[i]);
                        p.rotationDeg[i] = a.rotationDeg[i] + w * (b.rotationDeg[i] - a.rotationDeg[i]);
                    }
                    sub.push_back(makeTransformed(t.shape.shape, p));
                }
            }
            const std::vector<ShapePtr> solids = solid(sub);
            placeTools(solids);
            // Remove tools take their clay first, push tools then move theirs, add tools last fill
            // what is left free (never a solid tool's voxel): a scene of push tools only is the push.
            for (const ShapePtr& t : withAction(sub, ToolAction::Remove))
                massRemoved += carve(*automaton, *t).mass;
            const PushReport r = push(*automaton, withAction(sub, ToolAction::Push), po);
            for (size_t i = 0; i < sub.size(); ++i) {
                const ToolSpec& spec = scene.tools[i];
                if (spec.action != ToolAction::Add) continue;
                const DepositReport d =
                    deposit(*automaton, *sub[i], spec.mass > 0 ? spec.mass : scene.rule.threshold, solids);
                massAdded += d.mass;
                if (d.voxels == 0) continue;
                // Clay added over Tc (into clay) is an overload: the global layer seeds there.
                total.region = unite(total.region, d.region);
                total.contactSize =
                    std::max(total.contactSize,
                             scene.dimensions == 2 ? double(d.voxels) : std::sqrt(double(d.voxels)));
            }
            // Smooth tools last, on the clay as the other tools left it (one pass a sub-step).
            for (size_t i = 0; i < sub.size(); ++i) {
                if (scene.tools[i].action != ToolAction::Smooth) continue;
                massSmoothed += smooth(*automaton, *sub[i], scene.tools[i].strength, 1, solids).massMoved;
            }
            total.voxelsPushed += r.voxelsPushed;
            total.massMoved += r.massMoved;
            total.voxelsTrapped = r.voxelsTrapped; // clay inside the tools as they end
            total.massTrapped = r.massTrapped;
            total.region = unite(total.region, r.region);
            total.contactSize = std::max(total.contactSize, r.contactSize);
            total.voxelsCompressed += r.voxelsCompressed;
        }
        return total;
    }

    /// While clay settles, the voxels a tool occupies are obstacles: otherwise clay would flow back
    /// into the tool that just pushed it out. Moves those obstacle cells to @a tools' placement,
    /// where the clay can read them (file comment). The edit rescans and wakes the tools' old and
    /// new bounds, cut to the part near clay (ClayLeaves.h: the same clay blocks).
    void placeTools(const std::vector<ShapePtr>& tools)
    {
        const Box region = regionOf(tools);
        const Box both = unite(region, toolRegion);
        if (both.empty()) return;
        const Box edited = clay_internal::narrowedEditRegion(mass->constTree(), both);
        automaton->editObstacles(edited, [&](ObstacleGrid& grid) {
            auto acc = grid.getAccessor();
            auto fixed = obstacles->getConstAccessor();
            for (const auto& cells : toolCells) {
                // The tool's cells less the static obstacles' (none, in fact: cover skips cells
                // already on), off a leaf at a time; one pruned into a tile, a cell at a time.
                auto off = cells.second;
                if (const auto* fl = fixed.probeConstLeaf(cells.first))
                    off -= fl->getValueMask();
                else if (fixed.isValueOn(cells.first))
                    continue;
                if (auto* leaf = acc.probeLeaf(cells.first)) {
                    leaf->getValueMask() -= off;
                } else {
                    for (auto it = off.beginOn(); it; ++it)
                        acc.setValueOff(cells.first +
                                        openvdb::MaskTree::LeafNodeType::offsetToLocalCoord(it.pos()));
                }
            }
            toolCells.clear();
            placed = tools;
            toolRegion = region;
            coveredSlots.clear();
            seenLeaves.clear();
            coveredAll = false;
            cover(grid, 1);
            grid.tree().prune();
        });
        toolRegion = region;
    }
};

Sculptor::Sculptor(const Scene& scene, int threads) : mImpl(std::make_unique<Impl>())
{
    openvdb::initialize();
    Impl& im = *mImpl;
    if (scene.memoryBudget != kNoMemoryBudget) {
        im.estimate = std::make_unique<MemoryEstimate>(estimateSceneMemory(scene));
        checkMemoryBudget(scene, *im.estimate);
        im.watchdog = std::make_unique<sculpt_internal::MemoryWatchdog>(
            scene.memoryBudget ? scene.memoryBudget : defaultMemoryBudget(),
            im.estimate->processBytes + im.estimate->obstacleBytes + im.estimate->toolBytes);
    }
    im.scene = scene;
    AutomatonOptions opt;
    opt.dimensions = scene.dimensions;
    opt.rule = scene.rule;
    opt.seed = scene.seed;
    opt.threads = threads;

    uint64_t steps = 0;
    if (!scene.start.empty()) {
        ClayFile f = readClayFile(scene.start);
        if (f.hasMeta && f.meta.dimensions != scene.dimensions) {
            throw Error(scene.source + ": start: " + scene.start + " holds " +
                        std::to_string(f.meta.dimensions) + "D clay but the scene is " +
                        std::to_string(scene.dimensions) + "D");
        }
        if (f.hasMeta && f.meta.rule.threshold != scene.rule.threshold) {
            // Clay at rest holds up to Tc per voxel: continuing under another Tc would silently
            // reshape it (a Tc = 250 file under Tc = 1000 reads as a quarter-full fog).
            throw Error(scene.source + ": start: " + scene.start + " was made with Tc " +
                        std::to_string(f.meta.rule.threshold) + " but the scene has Tc " +
                        std::to_string(scene.rule.threshold) +
                        " (1000 when it sets none); set \"threshold\": " +
                        std::to_string(f.meta.rule.threshold) + " in the scene to continue it");
        }
        if (f.meta.frameSteps > 0) checkResumable(scene, f.meta);
        im.startMeta = f.meta;
        im.mass = f.mass;
        steps = f.meta.steps;
        im.frame = f.meta.frames;
        im.open = f.meta.frameSteps > 0;
        im.openSteps = f.meta.frameSteps;
        im.massAdded = f.meta.massAdded;
        im.massRemoved = f.meta.massRemoved;
    } else {
        im.mass = openvdb::Int32Grid::create(0);
        for (const ClaySpec& c : scene.clay) {
            const std::string field = scene.source + ": " + c.shape.field;
            if (c.shape.kind == "vdb") {
                ClayFile f;
                try {
                    f = readClayFile(c.shape.file, c.shape.grid);
                } catch (const Error& e) {
                    throw Error(field + ": " + e.what()); // names the scene and the field
                }
                addClay(*im.mass, *f.mass, field);
            } else {
                MassGridPtr g;
                try {
                    g = makeClay(*c.shape.shape, c.mass, scene.dimensions);
                } catch (const Error& e) {
                    throw Error(field + ": " + e.what());
                }
                // The first clay into an empty grid: makeClay's grid is what addClay would copy
                // (active voxels only, no tiles), so it is taken as it is.
                if (im.mass->tree().empty())
                    im.mass = g;
                else
                    addClay(*im.mass, *g, field);
            }
        }
    }
    im.mass->setName("mass");
    setClayTransform(*im.mass, scene.voxelSize, scene.up);
    // Uniform clay as tiles, whatever made it (files, several shapes added up).
    automaton_internal::collapseUniformLeaves(im.mass->tree(), scene.rule.threshold);

    im.obstacles = openvdb::MaskGrid::create(false);
    im.obstacles->setName("obstacles");
    for (const ShapeSpec& o : scene.obstacles)
        rasterize(*im.obstacles, *o.shape, scene.dimensions, threads);
    if (!scene.obstacles.empty()) {
        if (const std::optional<openvdb::Coord> at = clayInObstacles(im.mass->tree(), im.obstacles->tree())) {
            const openvdb::Coord c = *at;
            std::string which;
            for (const ShapeSpec& o : scene.obstacles) {
                if (o.shape->distance(Vec3{{double(c.x()), double(c.y()), double(c.z())}}) < 0) {
                    which = o.field;
                    break;
                }
            }
            throw Error(scene.source + ": clay at voxel " + coordStr(c) + " lies inside " + which +
                        "; obstacles are cells clay never enters");
        }
    }
    // The automaton's obstacles: the static ones, plus the tools' voxels (placeTools).
    im.automaton = std::make_unique<Automaton>(im.mass, opt, im.obstacles->deepCopy());
    if (steps) im.automaton->setStepCount(steps);
    if (scene.surfaceTension > 0) {
        // An open frame's changes so far (its checkpoint's), then everything the automaton changes.
        if (im.open) {
            for (const Box& b : im.startMeta.changedClay)
                im.changedClay.push(automaton_internal::ChangedClay::Entry{
                    {{b.min[0] >> 3, b.min[1] >> 3, b.min[2] >> 3}}, b});
        }
        automaton_internal::setChangedClay(*im.automaton, &im.changedClay);
    }
    // An open frame's tools are where its push left them; that push is not repeated.
    if (!scene.tools.empty()) im.placeTools(im.solid(im.toolsAt(im.open ? im.frame + 1 : im.frame)));
}

Sculptor::~Sculptor() = default;

const MemoryEstimate& Sculptor::memoryEstimate()
{
    Impl& im = *mImpl;
    if (!im.estimate) im.estimate = std::make_unique<MemoryEstimate>(estimateSceneMemory(im.scene));
    return *im.estimate;
}

bool Sculptor::done() const
{
    return mImpl->frame >= mImpl->scene.frames;
}
uint64_t Sculptor::frame() const
{
    return mImpl->frame;
}
bool Sculptor::frameOpen() const
{
    return mImpl->open;
}
uint64_t Sculptor::totalFrames() const
{
    return mImpl->scene.frames;
}
const Scene& Sculptor::scene() const
{
    return mImpl->scene;
}
Automaton& Sculptor::automaton()
{
    return *mImpl->automaton;
}
const MassGridPtr& Sculptor::mass() const
{
    return mImpl->mass;
}
void Sculptor::setStopRequest(std::function<bool()> poll)
{
    mImpl->stopPoll = std::move(poll);
}
bool Sculptor::stopped() const
{
    return mImpl->stopped;
}
uint64_t Sculptor::memoryBudget() const
{
    return mImpl->watchdog ? mImpl->watchdog->budget() : kNoMemoryBudget;
}
uint64_t Sculptor::outgrewBudget() const
{
    return mImpl->stopped ? mImpl->budgetStop : 0;
}
const ClayMeta& Sculptor::startMeta() const
{
    return mImpl->startMeta;
}
int64_t Sculptor::massAdded() const
{
    return mImpl->massAdded;
}
int64_t Sculptor::massRemoved() const
{
    return mImpl->massRemoved;
}

ClayMeta Sculptor::checkpointMeta() const
{
    const Impl& im = *mImpl;
    if (im.open && im.openSteps == 0) {
        // Only an exception between a frame's push and its first step leaves this state.
        throw Error("frame " + std::to_string(im.frame + 1) +
                    " was pushed but not settled; it cannot be saved");
    }
    ClayMeta m;
    m.dimensions = im.scene.dimensions;
    m.rule = im.automaton->options().rule;
    m.seed = im.automaton->options().seed;
    m.steps = im.automaton->stepCount();
    m.frames = im.frame;
    m.frameSteps = im.open ? im.openSteps : 0;
    m.voxelSize = im.scene.voxelSize;
    m.up = im.scene.up;
    m.massAdded = im.massAdded;
    m.massRemoved = im.massRemoved;
    if (im.open && im.scene.surfaceTension > 0) {
        for (const automaton_internal::ChangedClay::Entry& e : im.changedClay.compacted())
            m.changedClay.push_back(e.voxels);
    }
    return m;
}

FrameReport Sculptor::runFrame()
{
    Impl& im = *mImpl;
    if (done())
        throw Error("the scene has no frame left to run (" + std::to_string(im.scene.frames) + " run)");
    im.stopped = false;
    const auto t0 = std::chrono::steady_clock::now();
    FrameReport rep;
    rep.frame = im.frame + 1;
    // The frame's wall time, on every way out.
    struct Timed {
        FrameReport& r;
        std::chrono::steady_clock::time_point t0;
        ~Timed() { r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); }
    } timed{rep, t0};
    if (!im.open) {
        // The push, the global transport's try and its layer run once, when the frame opens: a
        // frame resumed from a checkpoint (im.open) is past them and goes straight on settling.
        const int64_t added0 = im.massAdded, removed0 = im.massRemoved, smoothed0 = im.massSmoothed;
        im.changedClay.clear();
        if (!im.scene.tools.empty()) rep.push = im.pushTools(rep.frame);
        rep.massSmoothed = im.massSmoothed - smoothed0;
        rep.massAdded = im.massAdded - added0;
        rep.massRemoved = im.massRemoved - removed0;
        // The global layer (frame_policy::layerRuns), after the automaton's try: compressible clay
        // settles in a few cheap steps, as with the local transport; the layer runs only on what the
        // try leaves in the push's region (frame_policy::layerOptions).
        if (frame_policy::layerRuns(im.scene, rep.frame, rep.push)) {
            GlobalTransportOptions go = frame_policy::layerOptions(rep.push, im.automaton->options().threads);
            im.open = true;
            im.openSteps = 0;
            rep.settle = im.settleBounded(rep.finished, frame_policy::tryNear(go));
            rep.trySteps = rep.settle.steps;
            if (rep.finished) {
                im.endFrame(rep);
                return rep;
            }
            if (go.reach > 0) go.roomWithin = frame_policy::roomWithin(im.scene, rep.trySteps);
            rep.transport = transportGlobally(*im.automaton, go, &im.transportWorkspace);
        } else {
            im.open = true;
            im.openSteps = 0;
        }
    }
    const StepReport rest = im.settleOpenFrame(rep.finished);
    rep.settle += rest; // after the try, if any
    rep.settle.reason = rest.reason;
    if (rep.finished) {
        im.endFrame(rep);
    } else {
        im.stopped = true;
    }
    return rep;
}

RunSummary Sculptor::run(uint64_t maxFrames, const std::function<void(const FrameReport&)>& onFrame)
{
    using Clock = std::chrono::steady_clock;
    Impl& im = *mImpl;
    im.stopped = false;
    RunSummary s;
    s.massInitial = im.automaton->totalMass();
    const int64_t added0 = im.massAdded, removed0 = im.massRemoved;
    const auto t0 = Clock::now();
    while (!done() && (maxFrames == 0 || s.frames < maxFrames)) {
        if (!im.open && im.stopRequested() && im.boundaryResumesExactly()) {
            im.stopped = true;
            break;
        }
        const bool resumedOpen = im.open; // its push happened before this call
        const auto tf = Clock::now();
        const FrameReport r = runFrame();
        const double frameSecs = std::chrono::duration<double>(Clock::now() - tf).count();
        s.frameSeconds.push_back(r.seconds);
        s.pushSeconds += frameSecs - r.settle.seconds.total() - r.transport.seconds;
        ++s.frames;
        s.steps += r.settle.steps;
        s.blocksVisited += r.settle.blocksVisited;
        s.blocksOverTc += r.settle.blocksOverTc;
        s.blocksUpdated += r.settle.blocksUpdated;
        if (!resumedOpen) s.massTrapped = r.push.massTrapped; // clay inside tools now (retried every frame)
        if (r.finished &&
            (r.settle.reason == StopReason::StepBudget || r.settle.reason == StopReason::NoRoom))
            ++s.framesUnsettled;
        if (r.finished && r.settle.reason == StopReason::NoRoom) ++s.framesNoRoom;
        s.stages += r.settle.seconds;
        s.transportSeconds += r.transport.seconds;
        s.transportSolves += r.transport.solves;
        s.transportIterations += r.transport.iterations;
        s.transportMassMoved += r.transport.massMoved;
        if (r.transport.noRoom) ++s.framesTransportNoRoom;
        s.massSmoothed += r.massSmoothed;
        s.tensionSeconds += r.tensionSeconds;
        s.tensionBoxes += r.tensionBoxes;
        s.tensionVoxels += r.tensionVoxels;
        if (onFrame) onFrame(r);
        if (!r.finished) break; // stopped() is set
    }
    s.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
    // The final mass is measureClay's sum (leaves and tiles, in parallel): totalMass()'s walk over
    // every value, without a second walk.
    s.metrics = measureClay(*im.mass, im.scene.rule.threshold, im.automaton->obstacles().get(),
                            im.scene.dimensions, im.automaton->options().threads);
    s.massFinal = s.metrics.mass;
    s.massAdded = im.massAdded - added0;
    s.massRemoved = im.massRemoved - removed0;
    s.massDrift = s.massFinal - (s.massInitial + s.massAdded - s.massRemoved);
    s.residualOverload = im.automaton->residualOverload();
    s.settled = im.automaton->settled();
    return s;
}

} // namespace vdbclay
