// The memory estimate of a scene (estimateSceneMemory, checkMemoryBudget; MemoryEstimate.h), computed
// before any grid is built, and what a run's clay takes as it grows (clayMemoryInUse).
//
// What is counted. Each part follows what the run allocates, in bytes of OpenVDB nodes as allocated
// (TreeBytes.h: sizeof of each node plus glibc's overhead) or of the arrays the automaton, the push,
// the global layer and the output keep per leaf, per anchor, per tool slot, per source or per cell,
// each figure documented where it is defined (kAutomatonBytesPerLeaf ... kTransportBytesPerCell):
// - the program (kProcessBytes: its code, libraries and threads, measured);
// - clay: the Int32 mass tree over the leaves the clay may reach (clayLeavesGrown), and the
//   automaton's lists per leaf and its leaf table per anchor (anchorLeaves: the leaves within one
//   leaf of those);
// - obstacles (two masks), the tools' cells (a mask per leaf slot of their bounds: all of them with
//   the global layer, frame_policy::toolCellsOverWholeBounds, else those near the clay, no more);
// - then the larger of: a push's scratch (per clay voxel inside a tool; the compress push's pool,
//   an Int32 tree over the clay, for a tool that may cover the clay) with the global layer's arrays
//   (kept from frame to frame: they are there during the next push), and writing the output (of the
//   grids the scene's outputs name: the float density on the clay's leaves and the surface level set
//   on those and its band, with its scratch; the layer's arrays are freed after the last frame,
//   Sculpt.cc).
//
// The clay's leaves. At the start: those of the shapes (an analytic shape, whose distance is exact
// or a lower bound: the leaves within its tightened bounds whose centre lies less than a leaf's
// half-diagonal from it, decided a 128^3 node at a time where a node's centre settles it; a convex
// one in 3D at most Tc is tiles inside, so only the leaves that close to its surface, on either side;
// other shapes: their bounds), and of files (their walked topology, VdbCheck.h). Growth, group by group of
// touching clay boxes and tool sweeps (each grown by a leaf): clay no tool reaches, at most Tc, keeps
// its leaves; clay a tool pokes spreads within a leaf of itself and of the tools' sweeps (what a push
// moves lands beside the tool, the global layer writes only the cells its domain touches, next to the
// clay); where the global layer moves all of a push's overload within its bound (no try before it,
// no obstacle near, no surface tension: changesNearTools), an analytic shape's clay spreads so only within
// the layer's reach of a tool and keeps its own leaves elsewhere; clay a tool covers (a sweep spanning its
// box on two axes: squeezed over the whole footprint), clay over Tc and clay from files that may hold some
// spread over the group's box. Never more than 27 leaves per initial leaf (a step moves clay one voxel), a
// leaf per unit of mass, and clay over Tc at least over its settled volume.
//
// The global layer's domain (transport/Domain.cc; frame_policy::layerRuns, layerOptions). A frame whose tools
// touch clay runs the layer with reach r0 = frame_policy::layerReach(contact) (contact: sqrt of the
// voxels a tool entered, 2D their number; at most those inside the tool at one frame, and at most sqrt
// of the largest face of its bounds at one pose, 2D the longest side) on the cells
// over Tc within the push's region. Its cells are the full cells within `reach` face steps of those
// seeds (an inner seed floods a margin of 2 x 2^k < reach) and their face neighbours; where a part the
// reach cut has no room the reach doubles, stopping first at the Sculptor's bound on the room
// (frame_policy::roomWithin, GlobalTransportOptions::roomWithin): a tool entering the clay from its
// surface has room within its extent E (the diagonal of its bounds: around the tool to where it sticks
// out, or to the cells it left), so the reach ends at most max(r0, that bound). So the layer's seeds
// lie within a tool's sweep grown by S voxels (on every axis), and its cells within F face steps of
// those seeds (layerReach):
// - compress push: S = its chains' depth (as deep as the contact is wide); F = max(r0, E), 4 for an
//   inner seed's margin, 1 for the Dirichlet cells;
// - surface push: its targets (within maxSearch + 2 of the tool: the push's region), then the
//   automaton's try (frame_policy::tryAfterPush ...), which may run c steps before the layer, moving
//   the overload a voxel per axis (three face steps) a step, while the layer looks for its seeds in
//   the push's region only. So a seed lies within the region, moved at most c = min(steps, maxSearch
//   + 2) voxels from its target, and room lies E + 3c face steps away: S = region, F = max(r0, E +
//   3c) + 4 + 1. The try's steps before the layer: frame_policy::tryStepsBeforeLayer (0 under a step
//   budget of at most 16, then 16 up to 32, then 18 whatever the budget); none where the try never
//   runs: after a compress push, and on clay whose shapes all start saturated
//   (frame_policy::trySaturated), which pushes move but do not thin.
// The cells counted are the clay's (the leaves the grown clay may hold) within F face steps of the
// sweep grown by S (an octahedron's corners around the box, voxelsWithinFaceSteps), for the frame that
// holds most (layerCellsAlong: each frame's push lies between the tool's bounds at that frame and the
// one before; the layer's arrays serve one frame at a time); and never more than 7 per full cell (a
// full cell and its faces: the mass over Tc). The whole body where the bound does not hold: a tool's
// sweep spanning a clay shape's box on two axes (it covers the clay: compressed all the way, a contact
// as wide as the body); a sweep with no corner outside every clay shape (the tool starts inside the
// clay: no room near it); an obstacle within the grown sweep (clay walled in: the reach doubles up to
// the whole body); clay over Tc (it overflows anywhere, no tool near), or from a file that does not
// record its largest cell at most Tc (vdbclay_max_mass, written by writeClayFile and the checkpoint;
// read from the file's metadata, never its voxels; a file whose voxels exceed it is refused when the
// run reads it). A tool's corner inside a file's bounds counts as inside its clay (its voxels are not
// read). A frame whose tools touch no clay runs the layer with no reach (over every over cell) only as
// the scene's first frame (frame_policy::layerRuns): its over cells are clay that starts over Tc,
// counted above (a shape over Tc, two shapes that overlap and add up over Tc, a file that does not
// record its largest cell at most Tc).
//
// Cost. Proportional to the shapes, tools and files named and to the clay's surface, not to its
// volume: bounds are tightened within a budget of distance evaluations (kTightenBudget; a large face
// sampled first, a tool's pose moved by whole voxels from one tightened before takes that box, moved),
// leaves are counted by distance near a shape's surface only, within kCoverBudget evaluations (else
// on boxes), a file's voxels are read only when it lacks OpenVDB's grid statistics; the layer's cells
// a leaf at a time over the clay's leaves near each frame (at most kFrameLeavesMax, else the rows of
// the grown sweep, at most kFaceStepRowsMax, else the leaves' voxels).
#include "vdbclay/MemoryEstimate.h"
#include "vdbclay/Sculpt.h"

#include "vdbclay/IO.h"
#include "vdbclay/Smooth.h"

#include "io/ClayFileMeta.h"
#include "core/Format.h"
#include "core/LeafSlots.h"
#include "core/InputFile.h"
#include "sculpt/EstimateGeometry.h"
#include "sculpt/MemoryEstimate.h"
#include "sculpt/SurfaceTension.h"
#include "sculpt/FramePolicy.h"
#include "transport/SolverTuning.h"
#include "core/TreeBytes.h"
#include "core/VdbCheck.h"

#include <openvdb/openvdb.h>

#include <unistd.h>

#include <algorithm>
#include <array>
#include <climits>
#include <cmath>
#include <fstream>
#include <thread>
#include <utility>
#include <vector>

namespace vdbclay {

namespace {

using tree_bytes::kMallocOverhead;
using tree_bytes::leafBytes;

using MassTreeT = openvdb::Int32Tree;
using MaskTreeT = openvdb::MaskTree;
using FloatTreeT = openvdb::FloatTree;

/// The two internal levels (16^3 children of 8^3 leaves: 128^3 voxels; 32^3 of those: 4096^3) and
/// the root's map entry for each upper node.
template <typename TreeT> constexpr uint64_t lowerNodeBytes()
{
    return sizeof(typename TreeT::RootNodeType::ChildNodeType::ChildNodeType) + kMallocOverhead;
}
template <typename TreeT> constexpr uint64_t upperNodeBytes()
{
    return sizeof(typename TreeT::RootNodeType::ChildNodeType) + kMallocOverhead + 64;
}

using frame_policy::growBox;
using namespace memory_internal; // the byte figures (MemoryEstimate.h), the geometry (EstimateGeometry.h)
using transport_internal::kCellIndexSlotsMax;

/// Bytes of a tree of type T whose leaves are @a leaves, lying in the boxes @a boxes (which give the
/// internal nodes).
/// Internal nodes are at most @a lowerCap and @a upperCap where more is known (clay from files).
template <typename TreeT>
uint64_t treeBytes(uint64_t leaves, const std::vector<Box>& boxes, uint64_t lowerCap = UINT64_MAX,
                   uint64_t upperCap = UINT64_MAX)
{
    const uint64_t lower = std::min({distinctNodes(boxes, 7), std::max<uint64_t>(leaves, 1), lowerCap});
    const uint64_t upper = std::min({distinctNodes(boxes, 12), std::max<uint64_t>(leaves, 1), upperCap});
    return leaves * leafBytes<TreeT>() + lower * lowerNodeBytes<TreeT>() + upper * upperNodeBytes<TreeT>();
}

/// What a .vdb file's grid statistics (written by OpenVDB beside every grid) say about a grid,
/// read without its voxels.
struct FileGrid {
    Box bounds;
    uint64_t voxels = 0;
    uint64_t leaves = 0; ///< leaves its topology really holds (VdbCheck), whatever its metadata says
    uint64_t lowerNodes = 0, upperNodes = 0; ///< its internal nodes, likewise (0 if not walked)
    uint64_t memBytes = 0; ///< the tree's in-memory size when it was written (0 if not recorded)
    /// Its largest cell as the writer recorded it (vdbclay_max_mass, io/ClayFile.cc: readClayFile refuses a
    /// file whose voxels exceed it, so a run never holds more); -1 when not recorded.
    int64_t maxMass = -1;
};
FileGrid fileGridMetadata(const std::string& path, const std::string& gridName);

/// The grid @a gridName of @a path as the estimate sees it, without reading its voxels.
FileGrid fileGridStats(const std::string& path, const std::string& gridName)
{
    FileGrid out = fileGridMetadata(path, gridName);
    // Metadata is only what the writer claimed (a forged voxel count or bounding box would shrink
    // the estimate): the leaves come from the topology itself, walked by the layout check.
    std::vector<io_internal::VdbGridLayout> layout;
    try {
        layout = io_internal::checkVdbLayout(path);
    } catch (const Error&) {
        (void)readClayFile(path, gridName); // throws, naming the file and what is wrong with it
    }
    bool found = false;
    for (const auto& g : layout) {
        if (g.baseName() == gridName && g.treeChecked) {
            out.leaves = g.leaves;
            out.lowerNodes = g.lowerNodes;
            out.upperNodes = g.upperNodes;
            found = true;
        }
    }
    if (!found) out.leaves = std::min(nodesIn(out.bounds, 3), out.voxels);
    return out;
}

FileGrid fileGridMetadata(const std::string& path, const std::string& gridName)
{
    FileGrid out;
    io_internal::requireSeekableFile(path, "a .vdb file"); // before OpenVDB opens it: a FIFO would block
    openvdb::GridBase::Ptr g;
    try {
        openvdb::io::File file(path);
        file.open(false);
        g = file.readGridMetadata(gridName);
        file.close();
    } catch (const std::exception&) {
        g.reset();
    }
    if (!g) {
        // Let the reader say what is wrong with the file, in its words; if it can read it after
        // all, measure the grid it read.
        const ClayFile f = readClayFile(path, gridName);
        const openvdb::CoordBBox bb = f.mass->evalActiveVoxelBoundingBox();
        if (!bb.empty())
            out.bounds = Box{{{bb.min().x(), bb.min().y(), bb.min().z()}},
                             {{bb.max().x(), bb.max().y(), bb.max().z()}}};
        out.voxels = f.mass->activeVoxelCount();
        out.memBytes = f.mass->memUsage();
        return out;
    }
    const auto lo = g->getMetadata<openvdb::Vec3IMetadata>(openvdb::GridBase::META_FILE_BBOX_MIN);
    const auto hi = g->getMetadata<openvdb::Vec3IMetadata>(openvdb::GridBase::META_FILE_BBOX_MAX);
    const auto n = g->getMetadata<openvdb::Int64Metadata>(openvdb::GridBase::META_FILE_VOXEL_COUNT);
    const auto mem = g->getMetadata<openvdb::Int64Metadata>(openvdb::GridBase::META_FILE_MEM_BYTES);
    if (lo && hi) {
        out.bounds = Box{{{lo->value()[0], lo->value()[1], lo->value()[2]}},
                         {{hi->value()[0], hi->value()[1], hi->value()[2]}}};
    }
    if (n) out.voxels = uint64_t(std::max<int64_t>(0, n->value()));
    if (mem) out.memBytes = uint64_t(std::max<int64_t>(0, mem->value()));
    if (const auto mx = g->getMetadata<openvdb::Int64Metadata>(io_internal::kMetaMaxMass))
        out.maxMass = std::max<int64_t>(0, mx->value());
    if (!lo || !hi || !n) {
        // A file without statistics: read it (the estimate must not be a guess).
        const ClayFile f = readClayFile(path, gridName);
        const openvdb::CoordBBox bb = f.mass->evalActiveVoxelBoundingBox();
        out.bounds = bb.empty() ? Box()
                                : Box{{{bb.min().x(), bb.min().y(), bb.min().z()}},
                                      {{bb.max().x(), bb.max().y(), bb.max().z()}}};
        out.voxels = f.mass->activeVoxelCount();
        out.memBytes = f.mass->memUsage();
    }
    return out;
}

/// What the global layer's domain bound (file comment) depends on.
struct LayerBound {
    PushMode push = PushMode::Surface;
    int dims = 3;
    uint64_t toolInside = 0; ///< the most voxels inside a tool at one frame (a push enters no more)
    double toolFace = 0;    ///< the largest face of a tool's bounds at one pose (2D: side; a contact's width)
    int64_t toolExtent = 0; ///< the largest tool's diagonal, rounded up (frame_policy::toolExtent)
    uint64_t maxSteps = 0;  ///< the scene's step budget per frame
    bool trySkipped = false; ///< the automaton's try never runs before the layer (FramePolicy.h)
    bool clayMoves = false;  ///< clay from a file or over Tc: it may overflow with no tool near
    bool covers = false;     ///< a tool's sweep spans a clay shape's box on two axes
    bool buried = false;     ///< no corner of a tool's sweep lies outside the clay: it starts inside
};

/// Where the global layer's domain lies around a tool's sweep (file comment): its seeds within the
/// sweep grown by `seeds` voxels on every axis, its cells within `faceSteps` face steps of a seed.
struct LayerReach {
    bool bounded = false; ///< false: no bound holds (the whole body)
    int64_t seeds = 0;
    int64_t faceSteps = 0;
};

LayerReach layerReach(const LayerBound& b)
{
    LayerReach r;
    if (b.clayMoves || b.covers || b.buried) return r;
    r.bounded = true;
    const double contact = b.dims == 2 ? std::min(double(b.toolInside), b.toolFace)
                                       : std::sqrt(std::min(double(b.toolInside), b.toolFace));
    const int64_t reach = frame_policy::layerReach(contact);
    const int64_t room = b.toolExtent; // an over cell's face steps to room (frame_policy::roomWithin)
    // The reach doubles while a part it cut has no room, stopping at the room's bound first
    // (GlobalTransportOptions::roomWithin): it ends at most max(r0, room).
    if (b.push == PushMode::Compress) {
        r.seeds = int64_t(std::ceil(contact)); // the chains' depth
        r.faceSteps = std::max(reach, room) + 4 + 1;
        return r;
    }
    // The surface push: targets within the push's region (maxSearch + 2 past the tool), then the
    // try's steps, each moving clay one voxel (three face steps) at most; the layer's seeds stay in
    // the region (frame_policy::layerOptions), so the try moved them at most `region` voxels from the
    // tool, whatever its steps.
    const int64_t region = int64_t(PushOptions().maxSearch) + 2;
    const int64_t steps =
        b.trySkipped ? 0 : std::min(int64_t(frame_policy::tryStepsBeforeLayer(b.maxSteps)), region);
    r.seeds = region;
    r.faceSteps = std::max(reach, room + 3 * steps) + 4 + 1;
    return r;
}

/// Leaves ClayCover may visit for the global layer's domain of one tool's frames together
/// (layerCellsAlong).
constexpr uint64_t kFrameLeavesMax = uint64_t(1) << 22;

/// The cells of the global layer's domain at the frame that holds most, for a tool whose bounds
/// frame by frame are @a frames: the clay's voxels (in the leaves @a clay may hold, within @a extent)
/// within @a reach of the seeds. A frame's layer runs after its push, whose region lies within the
/// tool's bounds at this frame and the one before (the sub-steps of a sweep move between them), and
/// the layer's arrays are reused from frame to frame, so its peak is the largest frame's, not the
/// whole @a sweep's. The whole sweep where the frames are sampled or counting them all would visit
/// more than kFrameLeavesMax leaves (or @a budget ran out): then the voxels of @a extent itself.
uint64_t layerCellsAlong(const std::vector<Box>& frames, const Box& sweep, const LayerReach& reach,
                         const Box& extent, const ClayCover& clay, uint64_t& budget, int dims)
{
    const auto whole = [&]() {
        return voxelsWithinFaceSteps(growBox(sweep, reach.seeds, dims), reach.faceSteps, extent, dims);
    };
    if (frames.empty()) return whole();
    uint64_t visited = 0, most = 0;
    Box last;
    for (size_t k = 0; k < frames.size(); ++k) {
        const Box pair = k ? unite(frames[k - 1], frames[k]) : frames[k];
        if (k && pair.min == last.min && pair.max == last.max) continue; // the tool stood still
        last = pair;
        if (pair.empty()) continue;
        const Box seeds = growBox(pair, reach.seeds, dims);
        const Box around = intersect(clip2D(growBox(seeds, reach.faceSteps, dims), dims), extent);
        visited += nodesIn(around, 3);
        if (visited > kFrameLeavesMax) return whole();
        uint64_t n = 0;
        if (!clay.forEachLeaf(around, false, budget, [&](const Box& leaf) {
                n += voxelsWithinFaceSteps(seeds, reach.faceSteps, leaf, dims);
            }))
            return whole();
        most = std::max(most, n);
    }
    return most;
}

} // namespace

namespace memory_internal {

uint64_t voxelsWithinFaceSteps(const Box& b, int64_t r, Box within, int dims)
{
    if (dims == 2) {
        within.min[2] = std::max(within.min[2], 0);
        within.max[2] = std::min(within.max[2], 0);
    }
    if (b.empty() || within.empty() || r < 0) return 0;
    int64_t lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
        lo[a] = std::max<int64_t>(within.min[a], int64_t(b.min[a]) - r);
        hi[a] = std::min<int64_t>(within.max[a], int64_t(b.max[a]) + r);
        if (lo[a] > hi[a]) return 0;
    }
    if ((hi[0] - lo[0] + 1) > kFaceStepRowsMax / (hi[1] - lo[1] + 1)) return UINT64_MAX;
    auto outside = [&](int a, int64_t v) -> int64_t { // face steps from v to b's range on axis a
        return v < b.min[a] ? b.min[a] - v : v > b.max[a] ? v - b.max[a] : 0;
    };
    uint64_t n = 0;
    for (int64_t x = lo[0]; x <= hi[0]; ++x) {
        const int64_t dx = outside(0, x);
        for (int64_t y = lo[1]; y <= hi[1]; ++y) {
            const int64_t left = r - dx - outside(1, y);
            if (left < 0) continue;
            const int64_t z0 = std::max<int64_t>(lo[2], int64_t(b.min[2]) - left);
            const int64_t z1 = std::min<int64_t>(hi[2], int64_t(b.max[2]) + left);
            if (z0 <= z1) n += uint64_t(z1 - z0 + 1);
        }
    }
    return n;
}

} // namespace memory_internal

uint64_t MemoryEstimate::total() const
{
    // Saturating: parts of a huge scene reach exabytes, and a wrapped sum would fit any budget.
    auto add = [](uint64_t a, uint64_t b) { return a > UINT64_MAX - b ? UINT64_MAX : a + b; };
    return add(add(add(add(add(processBytes, clayBytes), obstacleBytes), toolBytes), automatonBytes),
               std::max(add(pushBytes, transportBytes), outputBytes));
}

std::string MemoryEstimate::describe() const
{
    return "about " + formatBytes(total()) + " (program " + formatBytes(processBytes) + "; clay " +
           formatBytes(clayBytes) + " for up to " + std::to_string(clayLeavesGrown) +
           " leaves of 8^3 voxels, " + std::to_string(clayLeaves) + " at the start; obstacles " +
           formatBytes(obstacleBytes) + "; tools " + formatBytes(toolBytes) + "; automaton " +
           formatBytes(automatonBytes) + "; then the larger of push " + formatBytes(pushBytes) +
           (transportBytes ? " with global transport " + formatBytes(transportBytes) : std::string()) +
           ", and output grids " + formatBytes(outputBytes) + ")";
}

MemoryEstimate estimateSceneMemory(const Scene& scene)
{
    openvdb::initialize();
    const int dims = scene.dimensions;
    const int64_t tc = scene.rule.threshold;
    MemoryEstimate e;
    e.processBytes = kProcessBytes;
    uint64_t budget = kTightenBudget, toolBudget = kTightenBudget; // clay and obstacles; tools
    uint64_t coverBudget = kCoverBudget;                           // clay leaves and the layer's cells
    uint64_t voxelBudget = kTightenBudget;                         // clay voxels, for its mass
    struct Area {
        Box box;
        bool clay;                    ///< holds clay (else: a tool's sweep)
        bool moves;                   ///< may move: a tool, clay from a file, clay above Tc
        bool file = false;            ///< clay from a file
        const Shape* shape = nullptr; ///< clay of an analytic shape: its distance is exact
        bool overTc = false;          ///< clay that starts over Tc, or a file that may hold some
        bool tiled = false;           ///< clay of a convex analytic shape in 3D at most Tc: tiles inside
        uint64_t tiledVoxels = 0;     ///< its voxels, when tiled
    };
    std::vector<Box> fileBoxes; // of clay from files: where a tool's corner may lie inside clay
    std::vector<Area> areas;
    uint64_t massBound = 0; // units of clay, an upper bound; UINT64_MAX when unknown
    uint64_t fileTreeBytes = 0;
    uint64_t fileLower = 0, fileUpper = 0; // internal nodes of clay from files
    std::vector<Box> clayBoxes;            // of the shapes' clay
    std::vector<int64_t> clayMasses;       // their masses per voxel
    uint64_t fileLeaves = 0;               // of clay from files
    uint64_t settledVoxels = 0;            // voxels the clay fills at Tc per voxel, once its overload spread
    uint64_t tiledVoxels = 0;              // voxels inside shapes held as tiles
    // Of those, the voxels clayLeavesGrown leaves out (it counts their leaves near the surface).
    uint64_t tiledApart = 0;
    auto addFileClay = [&](const std::string& path, const std::string& grid) {
        const FileGrid g = fileGridStats(path, grid);
        const Box b = clip2D(g.bounds, dims);
        const uint64_t leaves = g.leaves;
        fileLeaves += leaves;
        // Its real nodes when the topology was walked; else from its bounds.
        const uint64_t real = g.upperNodes ? leaves * leafBytes<MassTreeT>() +
                                                 g.lowerNodes * lowerNodeBytes<MassTreeT>() +
                                                 g.upperNodes * upperNodeBytes<MassTreeT>()
                                           : treeBytes<MassTreeT>(leaves, {b});
        fileTreeBytes += std::max(g.memBytes, real);
        fileLower += g.upperNodes ? g.lowerNodes : UINT64_MAX / 4;
        fileUpper += g.upperNodes ? g.upperNodes : UINT64_MAX / 4;
        // It may overflow with no tool near unless it records its largest cell at most Tc.
        const bool over = g.maxMass < 0 || g.maxMass > tc;
        Area a{b, true, over, true};
        a.overTc = over;
        areas.push_back(a);
        fileBoxes.push_back(b);
        massBound = UINT64_MAX;
    };
    if (!scene.start.empty()) {
        addFileClay(scene.start, "mass");
    } else {
        for (const ClaySpec& c : scene.clay) {
            if (c.shape.kind == "vdb") {
                try {
                    addFileClay(c.shape.file, c.shape.grid);
                } catch (const Error& e) {
                    throw Error(scene.source + ": " + c.shape.field + ": " + e.what()); // the scene and field
                }
                continue;
            }
            const Box b = tighten(*c.shape.shape, clip2D(c.shape.shape->bounds(), dims), dims, budget);
            clayBoxes.push_back(b);
            clayMasses.push_back(c.mass);
            Area a{b, true, c.mass > tc};
            a.overTc = c.mass > tc;
            // The analytic shapes (a voxel is clay by its centre, and the distance is exact or, scaled,
            // a lower bound): their leaves are counted by distance; other shapes by their bounds.
            if (!c.shape.shape->keepsVolume() && (c.shape.kind == "sphere" || c.shape.kind == "box" ||
                                                  c.shape.kind == "cylinder" || c.shape.kind == "capsule"))
                a.shape = c.shape.shape.get();
            // Its inside is tiles from the start (makeClay, automaton/Tiles.h): only the leaves near its
            // surface hold voxels, until a tool reaches them (the tools' sweeps are counted apart).
            a.tiled = a.shape && dims == 3 && !a.overTc && a.shape->convex();
            areas.push_back(a);
            // Its mass: the voxels of an analytic shape counted (while the budget lasts), else its box's.
            const uint64_t voxels = a.shape ? voxelsInsideShape(*a.shape, b, voxelBudget) : voxelsIn(b);
            const double m = double(c.mass) * double(voxels);
            if (a.tiled) {
                tiledVoxels = voxels >= UINT64_MAX - tiledVoxels ? UINT64_MAX : tiledVoxels + voxels;
                areas.back().tiledVoxels = voxels;
            }
            if (massBound != UINT64_MAX)
                massBound = m >= 1.8e19 - double(massBound) ? UINT64_MAX : massBound + uint64_t(m);
            // Clay above Tc spreads until no cell holds more: over mass / Tc voxels at least.
            const double settled = c.mass > tc ? std::ceil(m / double(tc)) : 0.0;
            settledVoxels =
                settled >= 1.8e19 - double(settledVoxels) ? UINT64_MAX : settledVoxels + uint64_t(settled);
        }
    }
    const size_t clayAreas = areas.size();
    // The tools: each one's bounds frame by frame, the voxels inside it at once (the pushes place it at
    // the frames' poses, or with Scene::sweep between them: its bounds), the slots where its cells are
    // marked (frame_policy::toolCellsOverWholeBounds: all of its bounds with the global layer, else
    // those near the clay, at most the same).
    std::vector<ToolSweep> sweeps;
    std::vector<Box> toolBoxes;
    uint64_t toolInside = 0; // voxels inside the largest tool at one frame
    double toolFace = 0;     // the largest face of a tool's bounds at one pose (2D: the longest side)
    for (const ToolSpec& t : scene.tools) {
        sweeps.push_back(sweep(t, scene.frames, dims, !scene.sweep, toolBudget));
        const ToolSweep& sw = sweeps.back();
        areas.push_back({sw.all, false, true});
        e.toolVoxels += sw.most;
        e.toolSlots += sw.slotsMost;
        toolBoxes.push_back(sw.all);
        toolInside = std::max(toolInside, sw.inside);
        const Box b = t.shape.shape->bounds(); // its diagonal: any pose's extent
        if (!b.empty()) {
            // With Scene::sweep the pushes place the tool between the frames' poses too, where its
            // bounds may be wider (a turning box): any pose's bounds are no wider than its diagonal.
            const double side = double(frame_policy::diagonalOf(b));
            toolFace = std::max(toolFace, scene.sweep ? (dims == 2 ? side : side * side) : double(sw.face));
        } else {
            toolFace = std::max(toolFace, double(sw.face));
        }
    }
    // An add tool may put clay anywhere its sweep (grown by the voxel its coverage reaches) passes:
    // clay that moves, up to the tool's mass in every voxel of it (over Tc: an overload that spreads).
    for (size_t t = 0; t < scene.tools.size(); ++t) {
        const ToolSpec& spec = scene.tools[t];
        if (spec.action != ToolAction::Add || sweeps[t].all.empty()) continue;
        const int64_t mass = spec.mass > 0 ? spec.mass : tc;
        Area a{growBox(sweeps[t].all, 1, dims), true, true};
        a.overTc = mass > tc;
        areas.push_back(a);
        const double m = double(mass) * double(voxelsIn(a.box));
        if (massBound != UINT64_MAX)
            massBound = m >= 1.8e19 - double(massBound) ? UINT64_MAX : massBound + uint64_t(m);
        const double settled = mass > tc ? std::ceil(m / double(tc)) : 0.0;
        settledVoxels =
            settled >= 1.8e19 - double(settledVoxels) ? UINT64_MAX : settledVoxels + uint64_t(settled);
    }
    // Tools that overlap share their cells (a cell is an obstacle once): no more voxels and slots
    // than their sweeps hold together.
    if (!toolBoxes.empty()) {
        Box all;
        for (const Box& b : toolBoxes)
            all = unite(all, b);
        e.toolVoxels = std::min(e.toolVoxels, voxelsIn(all));
        e.toolSlots = std::min(e.toolSlots, distinctNodes(toolBoxes, 3));
    }
    // Whether tool @a t's sweep spans clay area @a a's box on two axes: it covers that clay (a plate
    // wider than it), compresses all of it and squeezes it out over its whole footprint.
    auto covers = [&](const Box& t, const Box& a) {
        int spans = 0;
        for (int ax = 0; ax < 3; ++ax)
            spans += t.min[ax] <= a.min[ax] && t.max[ax] >= a.max[ax] ? 1 : 0;
        return spans >= 2; // in 2D z spans trivially: one more axis
    };
    std::vector<Box> obsBoxes;
    for (const ShapeSpec& o : scene.obstacles) {
        const Box b = tighten(*o.shape, clip2D(o.shape->bounds(), dims), dims, budget);
        e.obstacleLeaves += nodesIn(b, 3);
        obsBoxes.push_back(b);
    }
    // The global layer's domain (file comment): where its bound holds, its cells lie within
    // `layerNear` voxels of a tool's bounds (its seeds within reach.seeds, its cells reach.faceSteps
    // from those), and no obstacle lies that near (clay walled in: the reach doubles up to the whole
    // body).
    LayerBound lb;
    lb.push = scene.push;
    lb.dims = dims;
    lb.toolInside = toolInside;
    lb.toolFace = toolFace;
    lb.toolExtent = frame_policy::toolExtent(scene);
    lb.maxSteps = scene.settle.maxSteps;
    // The try runs after a surface push on clay that is not saturated near it: clay whose shapes
    // all start saturated (pushes move clay, they do not thin it) is taken to stay so.
    lb.trySkipped = !frame_policy::tryAfterPush(scene) ||
                    (fileLeaves == 0 && !clayMasses.empty() &&
                     std::all_of(clayMasses.begin(), clayMasses.end(),
                                 [&](int64_t m) { return frame_policy::trySaturated(scene, m, 1); }));
    lb.clayMoves = std::any_of(areas.begin(), areas.end(), [](const Area& a) { return a.clay && a.moves; });
    // Shapes that overlap add up: over Tc where two of them do.
    if (!lb.clayMoves) {
        std::vector<size_t> shapes(clayBoxes.size());
        for (size_t i = 0; i < shapes.size(); ++i)
            shapes[i] = i;
        lb.clayMoves = anyTouchingPair(
            shapes, [&](size_t i) -> const Box& { return clayBoxes[i]; },
            [&](size_t i, size_t j) { return clayMasses[i] + clayMasses[j] > tc; });
    }
    for (const Box& t : toolBoxes) {
        for (size_t a = 0; a < clayAreas; ++a)
            lb.covers |= covers(t, areas[a].box);
        // A tool that enters the clay from its surface has a corner of its sweep outside every clay
        // shape (where it sticks out); one with none starts inside the clay.
        bool out = false;
        for (int corner = 0; corner < 8 && !out; ++corner) {
            const Vec3 p{{double(corner & 1 ? t.max[0] : t.min[0]), double(corner & 2 ? t.max[1] : t.min[1]),
                          double(corner & 4 ? t.max[2] : t.min[2])}};
            const bool inShape = std::any_of(scene.clay.begin(), scene.clay.end(), [&](const ClaySpec& c) {
                return c.shape.shape && c.shape.shape->distance(p) < 0;
            });
            // Clay from a file: its voxels are not read, so a corner within its bounds may be in it.
            const Box at{{{int32_t(p[0]), int32_t(p[1]), int32_t(p[2])}},
                         {{int32_t(p[0]), int32_t(p[1]), int32_t(p[2])}}};
            const bool inFile =
                std::any_of(fileBoxes.begin(), fileBoxes.end(), [&](const Box& f) { return touches(f, at); });
            out = !inShape && !inFile;
        }
        lb.buried |= !out;
    }
    const LayerReach reach = layerReach(lb);
    const int64_t layerNear = reach.seeds + reach.faceSteps;
    bool walled = false;
    for (const Box& t : toolBoxes)
        for (const Box& o : obsBoxes)
            walled |= !intersect(growBox(t, layerNear, 3), o).empty();
    // Clay changes only near the tools where the global layer moves all of a push's overload and
    // its bound holds: the compress push and the layer move clay within layerNear of a tool's bounds
    // (the Dirichlet cells included), no try carries overload out of the push's region first, and the
    // automaton then finds none to move (frame_policy); the smooth tools move clay inside their
    // bounds. Elsewhere the clay at most Tc keeps its leaves, unless the scene's surface tension
    // smooths the whole surface (its first frame).
    const bool changesNearTools = frame_policy::usesGlobalLayer(scene) && reach.bounded && lb.trySkipped &&
                                  !walled && !toolBoxes.empty() && !(scene.surfaceTension > 0);
    // The clay's leaves, group by group (clay boxes and tool sweeps that touch, each grown by a leaf):
    // at the start (the shapes' own), grown (as far as the run may move them), and within one leaf of
    // those (grownPlus: the automaton's anchors, the surface's band).
    //  - a group no tool reaches, at most Tc per voxel, never moves (nothing is overloaded), unless its
    //    shapes overlap and add up: it keeps its own leaves;
    //  - a group whose tools poke the clay (none covers it, no clay over Tc, no file that may be): the
    //    clay spreads a leaf around itself and around the tools' sweeps (what the tools push out lands
    //    beside them; the global layer writes only the cells its domain touches);
    //  - otherwise (a tool covers the clay and squeezes it out, or clay over Tc overflows) the clay may
    //    spread over the group's box, grown by a leaf.
    uint64_t startLeaves = 0, grown = 0, grownPlus = 0;
    std::vector<Box> boxes, grownBoxes;
    for (const Area& a : areas)
        boxes.push_back(growBox(a.box, 8, dims));
    // Area @a i as a member of a cover: an analytic shape by its distance, anything else by its box.
    auto add = [&](ClayCover& c, size_t i) {
        if (areas[i].shape)
            c.addShape(areas[i].shape, areas[i].box, areas[i].tiled);
        else
            c.addBox(areas[i].box);
    };
    // The cover of group @a g's leaves (files too when @a files) and, when @a sweeps, its tools' sweeps:
    // tiled clay by the leaves near its surface. With @a nearTools, an analytic shape's clay spreads
    // by the margin only near the tools (changesNearTools): elsewhere it keeps its own leaves.
    auto coverOf = [&](const std::vector<size_t>& g, int64_t margin, bool files, bool sweeps,
                       bool nearTools = false) {
        ClayCover c;
        c.margin = margin;
        c.dims = dims;
        c.tilesAsTiles = true;
        for (size_t i : g) {
            if (!(areas[i].clay ? files || !areas[i].file : sweeps)) continue;
            if (!nearTools || !areas[i].shape) {
                add(c, i);
                continue;
            }
            c.addShape(areas[i].shape, areas[i].box, areas[i].tiled, 0);
            for (const Box& t : toolBoxes) {
                const Box near = intersect(areas[i].box, growBox(t, layerNear + 8, dims));
                if (!near.empty()) c.addShape(areas[i].shape, near, areas[i].tiled);
            }
        }
        return c;
    };
    // A group counted by its cover holds its tiled clay's leaves near the surface only: the voxels inside
    // are counted apart. A group counted by its boxes' leaves holds them all.
    auto countTiledApart = [&](const std::vector<size_t>& g) {
        for (size_t i : g)
            tiledApart = areas[i].tiledVoxels >= UINT64_MAX - tiledApart ? UINT64_MAX
                                                                         : tiledApart + areas[i].tiledVoxels;
    };
    ClayCover everywhere; // the grown clay of every group: where the global layer's cells may lie
    everywhere.margin = 8;
    everywhere.dims = dims;
    for (const std::vector<size_t>& g : groupsOfTouching(boxes)) {
        if (std::none_of(g.begin(), g.end(), [&](size_t i) { return areas[i].clay; })) continue;
        std::vector<Box> own, members;
        Box ownRegion;
        for (size_t i : g) {
            members.push_back(boxes[i]);
            if (areas[i].clay && !areas[i].file) {
                own.push_back(areas[i].box);
                ownRegion = unite(ownRegion, areas[i].box);
            }
        }
        uint64_t start = 0;
        if (!coverOf(g, 0, false, false).count(ownRegion, false, coverBudget, start))
            start = distinctNodes(own, 3);
        startLeaves += start;
        bool moves = std::any_of(g.begin(), g.end(), [&](size_t i) { return areas[i].moves; });
        bool overlaps = false;
        if (!moves) // overlaps
            overlaps = anyTouchingPair(
                g, [&](size_t i) -> const Box& { return areas[i].box; }, [](size_t, size_t) { return true; });
        if (!moves && !overlaps) {
            const ClayCover still = coverOf(g, 0, true, false);
            Box region;
            for (size_t i : g)
                region = unite(region, areas[i].box);
            uint64_t n = 0, plus = 0;
            if (still.count(region, false, coverBudget, n) &&
                still.count(growBox(region, 14, dims), true, coverBudget, plus)) {
                grown += n;
                grownPlus += plus;
                countTiledApart(g);
            } else {
                grown += distinctNodes(own, 3);
                std::vector<Box> around;
                for (const Box& b : own)
                    around.push_back(neighbourhood(b, true, dims));
                grownPlus += distinctNodes(around, 3);
            }
            grownBoxes.insert(grownBoxes.end(), own.begin(), own.end());
            for (size_t i : g)
                add(everywhere, i);
            continue;
        }
        bool spreads = overlaps;
        for (size_t i : g) {
            if (areas[i].clay && (areas[i].file || areas[i].overTc)) spreads = true;
            if (areas[i].clay) continue;
            for (size_t j : g)
                if (areas[j].clay && covers(areas[i].box, areas[j].box)) spreads = true;
        }
        grownBoxes.insert(grownBoxes.end(), members.begin(), members.end());
        if (!spreads) {
            const ClayCover poked = coverOf(g, 8, true, true, changesNearTools);
            Box region;
            for (const Box& b : members)
                region = unite(region, b);
            uint64_t n = 0, plus = 0;
            if (poked.count(region, false, coverBudget, n) &&
                poked.count(growBox(region, 14, dims), true, coverBudget, plus)) {
                grown += n;
                grownPlus += plus;
                countTiledApart(g);
                everywhere.members.insert(everywhere.members.end(), poked.members.begin(),
                                          poked.members.end());
                continue;
            }
        }
        grown += unionLeaves(members);
        std::vector<Box> around;
        for (const Box& b : members)
            around.push_back(neighbourhood(b, true, dims));
        grownPlus += unionLeaves(around);
        for (size_t i : g)
            everywhere.addBox(areas[i].box);
    }
    e.clayLeaves = startLeaves + fileLeaves;
    // Leaves, not boxes: settling grows clay by at most one leaf on every side of each leaf it holds
    // (27 per leaf, a bound that counts scattered voxels for what they are, not their bounding box),
    // and overloaded clay spreads over its settled volume (with a leaf of margin all round).
    const uint64_t leafArea = dims == 2 ? 64 : 512; // voxels of a leaf that clay can fill
    const uint64_t aroundLeaves = e.clayLeaves > UINT64_MAX / 27 ? UINT64_MAX : 27 * e.clayLeaves;
    const uint64_t settledLeaves =
        settledVoxels == UINT64_MAX ? UINT64_MAX : 2 * ((settledVoxels + leafArea - 1) / leafArea);
    e.clayLeavesGrown = std::max(
        {e.clayLeaves, std::min({grown, massBound, aroundLeaves}), std::min(settledLeaves, massBound)});
    // Within one leaf of those: at most 27 per leaf, and the grown leaves' own band.
    e.anchorLeaves = std::max(
        std::min(grownPlus, e.clayLeavesGrown > UINT64_MAX / 27 ? UINT64_MAX : 27 * e.clayLeavesGrown),
        e.clayLeavesGrown);
    if (e.clayLeavesGrown > std::min(grown, massBound)) {
        // Spreading past the boxes: its internal nodes, as for a cube of that many leaves, and a band
        // of a leaf around that cube.
        const double side =
            (dims == 2 ? std::sqrt(double(e.clayLeavesGrown)) : std::cbrt(double(e.clayLeavesGrown))) * 8;
        Box spread;
        for (int a = 0; a < 3; ++a) {
            spread.min[a] = 0;
            spread.max[a] = int32_t(std::min(side, 1e9));
        }
        if (dims == 2) spread.max[2] = 0;
        grownBoxes.push_back(spread);
        e.anchorLeaves = std::max(e.anchorLeaves, nodesIn(neighbourhood(spread, true, dims), 3));
    }
    // With clay from files, the nodes grown clay needs: the files' own, twice (growth by a leaf
    // rarely crosses into another internal node), and those of the shapes' and tools' areas.
    uint64_t lowerCap = UINT64_MAX, upperCap = UINT64_MAX;
    if (fileLeaves > 0 && fileLower < UINT64_MAX / 8 && fileUpper < UINT64_MAX / 8) {
        std::vector<Box> others;
        for (const Area& a : areas) {
            if (!a.file) {
                others.push_back(growBox(a.box, 8, dims));
            }
        }
        lowerCap = 2 * fileLower + distinctNodes(others, 7);
        upperCap = 2 * fileUpper + distinctNodes(others, 12);
    }
    // A file's own figure (its tree's size when written) when that is more.
    e.clayBytes =
        std::max(treeBytes<MassTreeT>(e.clayLeavesGrown, grownBoxes, lowerCap, upperCap), fileTreeBytes);

    // The static mask, and the automaton's copy, which also holds the tools' cells.
    e.obstacleBytes = 2 * treeBytes<MaskTreeT>(e.obstacleLeaves, obsBoxes);
    e.toolBytes = e.toolSlots * kToolBytesPerSlot + treeBytes<MaskTreeT>(e.toolSlots, toolBoxes);
    const uint64_t lanes = std::max(1u, std::thread::hardware_concurrency()) - 1; // at most one per thread
    e.automatonBytes = e.clayLeavesGrown * kAutomatonBytesPerLeaf +
                       e.anchorLeaves * (kAutomatonBytesPerAnchor + lanes * kAutomatonLaneBytesPerAnchor);
    // A push: each tool's clay voxels inside it (no more than the clay has), and with the compress push
    // a tool that covers the clay pools its clay over every column under it, in an Int32 tree per tool
    // (push/Compress.cc) that can reach every leaf of the clay.
    // A clay voxel inside several tools is one source (of the tool it lies deepest in).
    const uint64_t clayVoxels = e.clayLeavesGrown > UINT64_MAX / 512 ? UINT64_MAX : e.clayLeavesGrown * 512;
    uint64_t sources = 0;
    for (const ToolSweep& sw : sweeps)
        sources = std::min(sources + sw.inside, e.toolVoxels);
    e.pushBytes = std::min(sources, clayVoxels) * kPushBytesPerSource;
    // Surface tension (Smooth.cc) copies a smooth tool's bounds grown by two voxels into dense arrays
    // (kSmoothBytesPerVoxel), one at a time; a frame's bounds hold at most sw.most voxels. The scene's
    // "surface_tension" smooths boxes of at most tensionBlockVoxels (sculpt/SurfaceTension.h), a box
    // on each of its threads at once (tensionLanes on every core), and holds the changed cells of
    // tensionBoxesHeld boxes until they are written (kSmoothCellBytes a voxel at most); it holds
    // where the frame's clay changed: per slot of the whole surface in the first frame (the clay's
    // leaves and about as many tile slots beside them, as the output's sweep below) or of a later
    // frame's change (the clay's leaves and the tools' slots at most), kChangedClayBytesPerSlot.
    {
        uint64_t most = 0;
        auto grownCube = [&](uint64_t voxels, double by) {
            const double side = (dims == 2 ? std::sqrt(double(voxels)) : std::cbrt(double(voxels))) + 2 * by;
            const double v = dims == 2 ? side * side : side * side * side;
            return v >= 1.8e19 ? UINT64_MAX : uint64_t(std::ceil(v));
        };
        for (size_t t = 0; t < sweeps.size(); ++t)
            if (scene.tools[t].action == ToolAction::Smooth)
                most = std::max(most, grownCube(sweeps[t].most, 2));
        uint64_t bytes = most > UINT64_MAX / kSmoothBytesPerVoxel ? UINT64_MAX : most * kSmoothBytesPerVoxel;
        if (scene.surfaceTension > 0) {
            const uint64_t lanes = uint64_t(sculpt_internal::tensionLanes(0));
            const uint64_t held = sculpt_internal::tensionBoxesHeld(int(lanes));
            const uint64_t perBlock =
                lanes * kSmoothBytesPerVoxel + (held - std::min(held, lanes)) * kSmoothCellBytes;
            bytes = std::max(bytes, sculpt_internal::tensionBlockVoxels(dims) * perBlock);
            const uint64_t slots =
                e.clayLeavesGrown > UINT64_MAX / 4 ? UINT64_MAX : 2 * e.clayLeavesGrown + e.toolSlots;
            const uint64_t journal =
                slots > UINT64_MAX / kChangedClayBytesPerSlot ? UINT64_MAX : slots * kChangedClayBytesPerSlot;
            bytes = bytes > UINT64_MAX - journal ? UINT64_MAX : bytes + journal;
        }
        e.pushBytes = e.pushBytes > UINT64_MAX - bytes ? UINT64_MAX : e.pushBytes + bytes;
    }
    for (size_t t = 0; t < sweeps.size(); ++t) {
        if (scene.push != PushMode::Compress) continue;
        bool pools = false;
        for (size_t a = 0; a < clayAreas; ++a)
            pools |= covers(toolBoxes[t], areas[a].box);
        if (pools) e.pushBytes += treeBytes<MassTreeT>(e.clayLeavesGrown, grownBoxes, lowerCap, upperCap);
    }
    // The global layer (transport/): kTransportBytesPerCell per cell of its domain. Its
    // domain holds the full cells (at least Tc each: no more than the mass over Tc) it reaches and
    // their face neighbours: at most 7 cells per full cell; and at most the clay's leaves' voxels.
    // Near the tools' sweeps, where the bound of the file comment (the layer's domain) holds, it is at
    // most the clay's voxels (in the leaves the grown clay may hold) within the reach's face steps of
    // the seeds' box, at the frame that holds most; the index is then a slot per 8^3 brick of the
    // seeds' bounds grown by the reach + 2 (at most kCellIndexSlotsMax slots) and a table per brick or tree
    // leaf that holds cells, in the box or beyond it, counted as every voxel of those leaves.
    e.clayVoxels = clayVoxels >= UINT64_MAX - tiledApart ? UINT64_MAX : clayVoxels + tiledApart;
    if (frame_policy::usesGlobalLayer(scene)) {
        const uint64_t fullCells = massBound == UINT64_MAX ? UINT64_MAX : massBound / uint64_t(tc);
        uint64_t cells = std::min(e.clayVoxels, fullCells > UINT64_MAX / 7 ? UINT64_MAX : 7 * fullCells);
        // A layer seeded in a push's region has a bounded reach, and indexes the box it can flood by
        // bricks when that holds at most kCellIndexSlotsMax of them.
        uint64_t bytes =
            cells * kTransportBytesPerCell + (toolBoxes.empty() ? 0 : 4 * uint64_t(kCellIndexSlotsMax));
        uint64_t counted = cells; // the domain's cells counted
        if (reach.bounded && !toolBoxes.empty()) {
            Box extent; // where the clay can be
            for (const Box& b : grownBoxes)
                extent = unite(extent, b);
            uint64_t nearLeaves = 0, nearCells = 0; // voxels of the leaves meeting the grown boxes; cells
            Box indexBox;                           // where the cell index's box may lie
            for (size_t i = 0; i < toolBoxes.size(); ++i) {
                const Box& t = toolBoxes[i];
                const Box b = intersect(growBox(t, layerNear, 3), extent);
                const uint64_t leaves = b.empty() ? 0 : uint64_t(leafSlotCount(b)) * 512;
                nearLeaves += leaves;
                nearCells += std::min(leaves, layerCellsAlong(sweeps[i].frames, t, reach, extent, everywhere,
                                                              coverBudget, dims));
                indexBox = unite(indexBox, growBox(t, layerNear + 2, dims));
            }
            if (!walled) {
                const uint64_t slots =
                    std::min<uint64_t>(uint64_t(leafSlotCount(indexBox)), uint64_t(kCellIndexSlotsMax));
                counted = std::min(cells, nearCells);
                bytes = std::min(bytes, counted * (kTransportBytesPerCell - 4) +
                                            4 * (std::min(cells, nearLeaves) + slots));
            }
        }
        e.transportBytes = bytes;
        e.transportCells = counted;
    }
    // Writing a .vdb (io/ClayFile.cc, writeClayFile): the float density grid on the clay's leaves, and the
    // surface level set swept over the density's leaves and those of its band around them
    // (output/SurfaceSweep.cc), with its per-leaf scratch; both held until the file is written.
    std::vector<Box> aroundBoxes;
    for (const Box& b : grownBoxes)
        aroundBoxes.push_back(neighbourhood(b, true, dims));
    // Clay held as tiles is swept over its tile slots next to the leaves too (output/SurfaceTiles.cc):
    // a layer of slots inside the surface's leaves, about one a leaf, each with the sweep's scratch.
    // Only the slots within the band's reach get values (output/SurfaceSweep.cc): measured, 20 % of
    // the grown leaves counted here on a 128-wide sphere at Tc, 27 % on a 512-wide one, while those
    // grown leaves are twice the leaves such a sphere holds: the density's count covers them.
    // Only the grids the scene's output names (OutputSpec::grids): the surface is swept from the
    // density, so either takes the density; the mass alone takes neither.
    const uint64_t tileSlotsSwept = tiledVoxels > 0 ? e.clayLeavesGrown : 0;
    const ClayGrids& grids = scene.outputs.grids;
    e.outputBytes = kOutputWriteBytes + e.clayLeavesGrown * kOutputWriteBytesPerLeaf;
    if (grids.density || grids.surface)
        e.outputBytes += treeBytes<FloatTreeT>(e.clayLeavesGrown, grownBoxes, lowerCap, upperCap);
    if (grids.surface)
        e.outputBytes += treeBytes<FloatTreeT>(e.anchorLeaves, aroundBoxes, lowerCap, upperCap) +
                         tileSlotsSwept * kOutputScratchPerLeaf + e.anchorLeaves * kOutputScratchPerLeaf;
    return e;
}

uint64_t clayMemoryInUse(const MassGrid& mass)
{
    // The automaton's anchors and the surface's band: two leaves a leaf (compact clay has ~1.3).
    const uint64_t leaves = mass.tree().leafCount();
    return uint64_t(mass.tree().memUsage()) +
           leaves * (kAutomatonBytesPerLeaf + 2 * kAutomatonBytesPerAnchor + 3 * leafBytes<FloatTreeT>() +
                     2 * kOutputScratchPerLeaf);
}

void checkMemoryBudget(const Scene& scene, const MemoryEstimate& e)
{
    if (scene.memoryBudget == kNoMemoryBudget) return;
    const uint64_t budget = scene.memoryBudget ? scene.memoryBudget : defaultMemoryBudget();
    if (e.total() <= budget) return;
    throw Error(scene.source + ": needs " + e.describe() + ", more than the memory budget of " +
                formatBytes(budget) +
                (scene.memoryBudget ? "" : " (the default: 3/4 of this machine's memory)") +
                "; shrink the scene or raise the budget (\"memory_budget\" in the scene, --memory-budget)");
}

void checkMemoryBudget(const Scene& scene)
{
    if (scene.memoryBudget == kNoMemoryBudget) return;
    checkMemoryBudget(scene, estimateSceneMemory(scene));
}
} // namespace vdbclay
