// Running a scene frame by frame: move the tools, push clay out of them, settle.
//
// While clay settles, the voxels a tool occupies are obstacles (otherwise clay would flow back into
// the tool that just pushed it out). Only the tool voxels the automaton can read need to be
// obstacles: those in a Margolus block with clay, and those the no-room flood reaches. So the tools
// are marked where the clay is, ahead of it, not over their whole bounds (placeTools, cover):
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
// - all of the bounds when that is fewer slots, or with the global transport (it moves clay far).
// The clay, the step counts and the hashes are those of marking the whole bounds every frame.
#include "vdbclay/Sculpt.h"

#include "vdbclay/IO.h"
#include "vdbclay/Metrics.h"

#include "ClayLeaves.h"
#include "Format.h"
#include "ParallelFor.h"
#include "Rasterize.h"
#include "TreeBytes.h"
#include "VdbCheck.h"

#include <openvdb/openvdb.h>

#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <climits>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <sstream>
#include <thread>

namespace vdbclay {

namespace {

/// Adds every active voxel of @a src into @a dst, refusing sums that overflow a cell. Leaf by leaf
/// (no accessor per voxel): a leaf slot that @a dst lacks gets a new leaf holding @a src's active
/// values; one it has gets them added, the first overflow in tree order refused as before.
void addClay(openvdb::Int32Grid& dst, const openvdb::Int32Grid& src, const std::string& field)
{
    auto tile = src.tree().cbeginValueOn();
    tile.setMaxDepth(tile.getLeafDepth() - 1);
    if (tile) throw Error(field + ": clay tiles are not supported; voxelize the grid");
    using Leaf = openvdb::Int32Tree::LeafNodeType;
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
        for (auto v = in.cbeginValueOn(); v; ++v) {
            const int64_t sum = int64_t(out->getValue(v.pos())) + int64_t(*v);
            if (sum > INT32_MAX) {
                throw Error(field + ": overlapping clay at voxel " + coordStr(v.getCoord()) + " adds up to " +
                            std::to_string(sum) + ", more than a voxel holds (" + std::to_string(INT32_MAX) +
                            ")");
            }
            out->setValueOn(v.pos(), int32_t(sum));
        }
    }
}

/// Every voxel whose centre lies inside @a shape (only z = 0 in 2D) becomes an obstacle; leaf by
/// leaf on @a threads (Rasterize.h: the voxels of forEachVoxelInside).
void rasterize(openvdb::MaskGrid& mask, const Shape& shape, int dims, int threads)
{
    raster_internal::rasterizeInside(mask.tree(), shape, dims, true, threads);
}

/// Whether any voxel of @a mass holding clay (active and nonzero) is on in @a obstacles: leaf masks
/// ANDed (a tile of either tree falls back on its voxels). Only says whether; the caller finds the
/// first such voxel (in value-iterator order) for its message.
bool clayMeetsObstacles(const openvdb::Int32Tree& mass, const openvdb::MaskTree& obstacles)
{
    auto tile = mass.cbeginValueOn();
    tile.setMaxDepth(tile.getLeafDepth() - 1);
    for (; tile; ++tile)
        if (*tile != 0) return true; // rare (a start file's tiles): the caller's voxel walk decides
    openvdb::tree::ValueAccessor<const openvdb::MaskTree> oacc(obstacles);
    for (auto it = mass.cbeginLeaf(); it; ++it) {
        const openvdb::Coord o = it->origin();
        if (const auto* ol = oacc.probeConstLeaf(o)) {
            auto both = it->getValueMask();
            both &= ol->getValueMask();
            for (auto on = both.beginOn(); on; ++on)
                if (it->getValue(on.pos()) != 0) return true;
        } else if (oacc.isValueOn(o)) {
            for (auto on = it->cbeginValueOn(); on; ++on)
                if (*on != 0) return true;
        }
    }
    return false;
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

// ---- memory estimate ------------------------------------------------------------------------------

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

/// Per clay leaf, the automaton's lists (lib/src/Automaton.cc): the leaf in hotLeaves (a Coord, 12
/// bytes), its changed-block masks of the last two steps (two Anchors of 24 bytes), up to 10
/// candidate contributions (the leaf's own, 8 from dilating the other phase, an edited region) and
/// one WorkItem (40 bytes); doubled for vector growth. Plus the kernel's leaf table (Kernel.h):
/// an entry of 264 bytes, up to 64 bytes of hash slots, 64 bytes of neighbour indices and the
/// candidates' two 8-byte accumulators (Candidates.h, dense mode) per anchor that reaches a leaf, at
/// most 8 anchors per leaf (isolated leaves; compact clay has ~1.3).
constexpr uint64_t kAutomatonBytesPerLeaf = 2 * (12 + 2 * 24 + 10 * 24 + 40) + 8 * (264 + 64 + 64 + 16);
/// Per clay leaf and thread beyond the first: the thread's own lane of those two accumulators and their
/// bit sets (Candidates::lanes), for up to 8 anchors.
constexpr uint64_t kAutomatonLaneBytesPerLeaf = 8 * (16 + 1);
/// Per tool voxel: its cell in Sculptor's toolCells (12 bytes, doubled for growth) and, for clay
/// inside a tool, push's scratch: a Source (32 bytes), a Move (28) and a std::map node (~64).
constexpr uint64_t kToolBytesPerVoxel = 24 + 32 + 28 + 64;

/// Scene::sweep: at most this many sub-steps per frame.
constexpr int kMaxSweepSubsteps = 256;
/// Scene::transport global: the reach (plastic zone) in contact sizes of the push.
constexpr double kReachPerContact = 1.0;
/// Scene::transport global, the automaton's try before the layer (Sculptor::Impl::settleBounded).
/// Measured on the 48^3 press at 0.8 Tc (surface push): its frames need up to ~200 visited blocks
/// per block of the clay (~600 steps); with 256 and 4096 every frame settles in the try (as local);
/// with 64 or 128 two or three frames gave up and the layer made the run 2x slower. Mean density
/// (mass / (Tc x voxels with clay)) after each push: that press 0.817-0.920, the 64^3 press at Tc
/// (surface push) 0.968-0.995, which skips the try; the 0.95 Tc stroke 0.95.
constexpr uint64_t kTryChunk = 16;
constexpr uint64_t kTrySteps = 4096;
constexpr double kTryWork = 256;
constexpr double kTrySaturated = 0.96;

constexpr uint64_t kTransportBytesPerCell = 2 * 90 + 4 + 88 + 88;

int64_t leafIndex(int32_t v, int log2)
{
    return int64_t(v) >> log2;
} // floor division

/// Number of nodes of side 2^log2 voxels that @a b touches (2D boxes are clipped to z = 0 first).
uint64_t nodesIn(const Box& b, int log2)
{
    if (b.empty()) return 0;
    uint64_t n = 1;
    for (int a = 0; a < 3; ++a)
        n *= uint64_t(leafIndex(b.max[a], log2) - leafIndex(b.min[a], log2) + 1);
    return n;
}
uint64_t voxelsIn(const Box& b)
{
    if (b.empty()) return 0;
    uint64_t n = 1;
    for (int a = 0; a < 3; ++a)
        n *= uint64_t(int64_t(b.max[a]) - int64_t(b.min[a]) + 1);
    return n;
}
Box clip2D(Box b, int dims)
{
    if (dims == 2) {
        b.min[2] = std::max(b.min[2], 0);
        b.max[2] = std::min(b.max[2], 0);
    }
    return b;
}
Box growBox(Box b, int64_t by, int dims)
{
    if (b.empty()) return b;
    for (int a = 0; a < (dims == 2 ? 2 : 3); ++a) {
        b.min[a] = int32_t(std::max<int64_t>(INT32_MIN, int64_t(b.min[a]) - by));
        b.max[a] = int32_t(std::min<int64_t>(INT32_MAX, int64_t(b.max[a]) + by));
    }
    return b;
}
/// @a b (a shape's bounds) without the faces that hold no voxel centre inside @a shape: bounds()
/// may be a voxel or two larger than the voxels inside, which at leaf boundaries counts whole extra
/// layers of leaves. Spends at most @a budget distance evaluations (shared by all calls of one
/// estimate, so that huge or many shapes cost well under a second); a face it cannot afford stays.
Box tighten(const Shape& shape, Box b, int dims, uint64_t& budget)
{
    auto anyInside = [&](const Box& face) {
        for (int x = face.min[0]; x <= face.max[0]; ++x)
            for (int y = face.min[1]; y <= face.max[1]; ++y)
                for (int z = face.min[2]; z <= face.max[2]; ++z) {
                    --budget;
                    if (shape.distance(Vec3{{double(x), double(y), double(z)}}) < 0) return true;
                }
        return false;
    };
    for (int a = 0; a < (dims == 2 ? 2 : 3); ++a) {
        for (int side = 0; side < 2; ++side) {
            for (int k = 0; k < 4 && b.min[a] < b.max[a]; ++k) {
                Box face = b;
                if (side == 0)
                    face.max[a] = b.min[a];
                else
                    face.min[a] = b.max[a];
                if (voxelsIn(face) > budget || anyInside(face)) break;
                if (side == 0)
                    ++b.min[a];
                else
                    --b.max[a];
            }
        }
    }
    return b;
}

/// Distance evaluations one estimate may spend tightening bounds (~0.1 s).
constexpr uint64_t kTightenBudget = uint64_t(1) << 21;

bool touches(const Box& a, const Box& b)
{
    return !intersect(a, b).empty();
}

/// Distinct nodes of side 2^@a log2 voxels that @a boxes touch: counted one by one while there are
/// at most 2^20 of them (boxes that share a node count it once: 20000 copies of one tool, or
/// 100000 one-voxel boxes in a few leaves), else bounded by their sum and by their bounding box.
uint64_t distinctNodes(const std::vector<Box>& boxes, int log2)
{
    uint64_t sum = 0;
    Box all;
    for (const Box& b : boxes) {
        sum += nodesIn(b, log2);
        all = unite(all, b);
    }
    if (sum > (uint64_t(1) << 20)) return std::min(sum, nodesIn(all, log2));
    std::vector<std::array<int64_t, 3>> keys;
    keys.reserve(size_t(sum));
    for (const Box& b : boxes) {
        if (b.empty()) continue;
        for (int64_t x = leafIndex(b.min[0], log2); x <= leafIndex(b.max[0], log2); ++x)
            for (int64_t y = leafIndex(b.min[1], log2); y <= leafIndex(b.max[1], log2); ++y)
                for (int64_t z = leafIndex(b.min[2], log2); z <= leafIndex(b.max[2], log2); ++z)
                    keys.push_back({{x, y, z}});
    }
    std::sort(keys.begin(), keys.end());
    return uint64_t(std::unique(keys.begin(), keys.end()) - keys.begin());
}

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

/// Groups boxes that touch (directly or through others); returns each group's box indices.
std::vector<std::vector<size_t>> groupsOfTouching(const std::vector<Box>& boxes)
{
    std::vector<size_t> parent(boxes.size());
    for (size_t i = 0; i < parent.size(); ++i)
        parent[i] = i;
    auto root = [&](size_t i) {
        while (parent[i] != i)
            i = parent[i] = parent[parent[i]];
        return i;
    };
    // Pairwise: beyond 4000 boxes (16 million pairs) they are taken as one group.
    for (size_t i = 0; i < boxes.size(); ++i)
        for (size_t j = i + 1; j < boxes.size(); ++j)
            if (boxes.size() > 4000 || touches(boxes[i], boxes[j])) parent[root(j)] = root(i);
    std::vector<std::vector<size_t>> groups(boxes.size());
    for (size_t i = 0; i < boxes.size(); ++i)
        groups[root(i)].push_back(i);
    groups.erase(
        std::remove_if(groups.begin(), groups.end(), [](const std::vector<size_t>& g) { return g.empty(); }),
        groups.end());
    return groups;
}

/// Leaves (8^3 voxels) touched by the union of @a boxes, counted exactly on the grid the boxes'
/// leaf-aligned faces cut (at most 40 boxes; more: distinctNodes()).
uint64_t unionLeaves(const std::vector<Box>& boxes)
{
    struct LeafBox {
        int64_t lo[3], hi[3]; // half-open, in leaves
    };
    std::vector<LeafBox> lb;
    Box all;
    for (const Box& b : boxes) {
        if (b.empty()) continue;
        all = unite(all, b);
        LeafBox l;
        for (int a = 0; a < 3; ++a) {
            l.lo[a] = leafIndex(b.min[a], 3);
            l.hi[a] = leafIndex(b.max[a], 3) + 1;
        }
        lb.push_back(l);
    }
    if (lb.size() > 40) return distinctNodes(boxes, 3);
    std::vector<int64_t> cuts[3];
    for (int a = 0; a < 3; ++a) {
        for (const LeafBox& l : lb) {
            cuts[a].push_back(l.lo[a]);
            cuts[a].push_back(l.hi[a]);
        }
        std::sort(cuts[a].begin(), cuts[a].end());
        cuts[a].erase(std::unique(cuts[a].begin(), cuts[a].end()), cuts[a].end());
    }
    uint64_t n = 0;
    for (size_t i = 0; i + 1 < cuts[0].size(); ++i)
        for (size_t j = 0; j + 1 < cuts[1].size(); ++j)
            for (size_t k = 0; k + 1 < cuts[2].size(); ++k) {
                const int64_t c[3] = {cuts[0][i], cuts[1][j], cuts[2][k]};
                const bool in = std::any_of(lb.begin(), lb.end(), [&](const LeafBox& l) {
                    return l.lo[0] <= c[0] && c[0] < l.hi[0] && l.lo[1] <= c[1] && c[1] < l.hi[1] &&
                           l.lo[2] <= c[2] && c[2] < l.hi[2];
                });
                if (in) {
                    n += uint64_t(cuts[0][i + 1] - c[0]) * uint64_t(cuts[1][j + 1] - c[1]) *
                         uint64_t(cuts[2][k + 1] - c[2]);
                }
            }
    return n;
}

/// The bounds of @a tool over frames 0..@a frames (every frame up to 100000 of them, else 100000
/// evenly spaced ones and the path's segment ends), and the most voxels its bounds hold at once.
/// Each frame's bounds are tightened while @a budget lasts (tighten()).
std::pair<Box, uint64_t> sweep(const ToolSpec& tool, uint64_t frames, int dims, uint64_t& budget)
{
    const uint64_t end = std::min(frames, tool.pathFrames()); // then the tool stays where it is
    Box all;
    uint64_t most = 0;
    auto at = [&](uint64_t f) {
        const ShapePtr s = makeTransformed(tool.shape.shape, tool.poseAt(f));
        Box b = clip2D(s->bounds(), dims);
        b = tighten(*s, b, dims, budget);
        all = unite(all, b);
        most = std::max(most, voxelsIn(b));
    };
    const uint64_t stride = std::max<uint64_t>(1, end / 100000);
    for (uint64_t f = 0; f <= end; f += stride)
        at(f);
    if (stride > 1) {
        uint64_t f = 0;
        for (const PathSegment& seg : tool.path) {
            f += seg.frames;
            if (f <= end) at(f);
        }
        at(end);
    }
    return {all, most};
}

} // namespace

uint64_t MemoryEstimate::total() const
{
    return clayBytes + obstacleBytes + toolBytes + automatonBytes + outputBytes + transportBytes;
}

std::string MemoryEstimate::describe() const
{
    return "about " + formatBytes(total()) + " (clay " + formatBytes(clayBytes) + " for up to " +
           std::to_string(clayLeavesGrown) + " leaves of 8^3 voxels, " + std::to_string(clayLeaves) +
           " at the start; obstacles " + formatBytes(obstacleBytes) + "; tools " + formatBytes(toolBytes) +
           "; automaton " + formatBytes(automatonBytes) + "; output grids " + formatBytes(outputBytes) +
           (transportBytes ? "; global transport " + formatBytes(transportBytes) : std::string()) + ")";
}

MemoryEstimate estimateSceneMemory(const Scene& scene)
{
    openvdb::initialize();
    const int dims = scene.dimensions;
    MemoryEstimate e;
    uint64_t budget = kTightenBudget, toolBudget = kTightenBudget; // clay and obstacles; tools
    struct Area {
        Box box;
        bool clay;         ///< holds clay (else: a tool's sweep)
        bool moves;        ///< may move: a tool, clay from a file, clay above Tc
        bool file = false; ///< clay from a file
    };
    std::vector<Area> areas;
    uint64_t massBound = 0; // units of clay, an upper bound; UINT64_MAX when unknown
    uint64_t fileTreeBytes = 0;
    uint64_t fileLower = 0, fileUpper = 0; // internal nodes of clay from files
    std::vector<Box> clayBoxes;            // of the shapes' clay
    uint64_t fileLeaves = 0;               // of clay from files
    uint64_t settledVoxels = 0;            // voxels the clay fills at Tc per voxel, once its overload spread
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
        areas.push_back({b, true, true, true});
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
            areas.push_back({b, true, c.mass > scene.rule.threshold});
            const double m = double(c.mass) * double(voxelsIn(b));
            if (massBound != UINT64_MAX)
                massBound = m >= 1.8e19 - double(massBound) ? UINT64_MAX : massBound + uint64_t(m);
            // Clay above Tc spreads until no cell holds more: over mass / Tc voxels at least.
            const double settled =
                c.mass > scene.rule.threshold ? std::ceil(m / double(scene.rule.threshold)) : 0.0;
            settledVoxels =
                settled >= 1.8e19 - double(settledVoxels) ? UINT64_MAX : settledVoxels + uint64_t(settled);
        }
    }
    e.clayLeaves = distinctNodes(clayBoxes, 3) + fileLeaves;
    uint64_t toolLeaves = 0;
    std::vector<Box> toolBoxes;
    uint64_t toolMost = 0; // voxels of the largest tool's bounds at one frame
    double toolExtent = 0; // the largest tool's diagonal
    for (const ToolSpec& t : scene.tools) {
        const auto sw = sweep(t, scene.frames, dims, toolBudget);
        areas.push_back({sw.first, false, true});
        e.toolVoxels += sw.second;
        toolLeaves += (sw.second + 511) / 512 + 1; // the densest frame, in leaves (at least)
        toolBoxes.push_back(sw.first);
        toolMost = std::max(toolMost, sw.second);
        const Box b = t.shape.shape->bounds(); // its diagonal: any pose's extent
        if (!b.empty()) {
            double d2 = 0;
            for (int a = 0; a < 3; ++a)
                d2 += double(int64_t(b.max[a]) - b.min[a] + 1) * double(int64_t(b.max[a]) - b.min[a] + 1);
            toolExtent = std::max(toolExtent, std::sqrt(d2));
        }
    }
    // Tools that overlap share their cells (a cell is an obstacle once): no more voxels and leaves
    // than their sweeps hold together.
    if (!toolBoxes.empty()) {
        Box all;
        for (const Box& b : toolBoxes)
            all = unite(all, b);
        e.toolVoxels = std::min(e.toolVoxels, voxelsIn(all));
        toolLeaves = std::min(toolLeaves, distinctNodes(toolBoxes, 3));
    }
    // Clay spreads around itself and where tools push it: over the clay's boxes and the tools'
    // sweeps that touch clay (directly or through other such boxes), each grown by one leaf.
    uint64_t grown = 0;
    std::vector<Box> boxes, grownBoxes;
    for (const Area& a : areas)
        boxes.push_back(growBox(a.box, 8, dims));
    for (const std::vector<size_t>& g : groupsOfTouching(boxes)) {
        if (std::none_of(g.begin(), g.end(), [&](size_t i) { return areas[i].clay; })) continue;
        // Clay no tool reaches, at most Tc per voxel, never moves (nothing is overloaded), unless
        // shapes overlap and add up: it keeps its own leaves.
        bool moves = std::any_of(g.begin(), g.end(), [&](size_t i) { return areas[i].moves; });
        if (!moves) { // overlaps, found by a sweep along x
            std::vector<size_t> order(g);
            std::sort(order.begin(), order.end(),
                      [&](size_t a, size_t b) { return areas[a].box.min[0] < areas[b].box.min[0]; });
            for (size_t i = 0; i < order.size() && !moves; ++i)
                for (size_t j = i + 1;
                     j < order.size() && areas[order[j]].box.min[0] <= areas[order[i]].box.max[0] && !moves;
                     ++j)
                    moves = touches(areas[order[i]].box, areas[order[j]].box);
        }
        if (!moves) {
            std::vector<Box> own;
            for (size_t i : g)
                own.push_back(areas[i].box);
            grown += distinctNodes(own, 3);
            grownBoxes.insert(grownBoxes.end(), own.begin(), own.end());
            continue;
        }
        std::vector<Box> members;
        for (size_t i : g)
            members.push_back(boxes[i]);
        grown += unionLeaves(members);
        grownBoxes.insert(grownBoxes.end(), members.begin(), members.end());
    }
    // Leaves, not boxes: settling grows clay by at most one leaf on every side of each leaf it holds
    // (27 per leaf, a bound that counts scattered voxels for what they are, not their bounding box),
    // and overloaded clay spreads over its settled volume (with a leaf of margin all round).
    const uint64_t leafArea = dims == 2 ? 64 : 512; // voxels of a leaf that clay can fill
    const uint64_t aroundLeaves = e.clayLeaves > UINT64_MAX / 27 ? UINT64_MAX : 27 * e.clayLeaves;
    const uint64_t settledLeaves =
        settledVoxels == UINT64_MAX ? UINT64_MAX : 2 * ((settledVoxels + leafArea - 1) / leafArea);
    e.clayLeavesGrown = std::max(
        {e.clayLeaves, std::min({grown, massBound, aroundLeaves}), std::min(settledLeaves, massBound)});
    if (e.clayLeavesGrown > std::min(grown, massBound)) {
        // Spreading past the boxes: its internal nodes, as for a cube of that many leaves.
        const double side =
            (dims == 2 ? std::sqrt(double(e.clayLeavesGrown)) : std::cbrt(double(e.clayLeavesGrown))) * 8;
        Box spread;
        for (int a = 0; a < 3; ++a) {
            spread.min[a] = 0;
            spread.max[a] = int32_t(std::min(side, 1e9));
        }
        if (dims == 2) spread.max[2] = 0;
        grownBoxes.push_back(spread);
    }
    // A file's own figure (its tree's size when written) when that is more.
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
    e.clayBytes =
        std::max(treeBytes<MassTreeT>(e.clayLeavesGrown, grownBoxes, lowerCap, upperCap), fileTreeBytes);

    std::vector<Box> obsBoxes;
    for (const ShapeSpec& o : scene.obstacles) {
        const Box b = tighten(*o.shape, clip2D(o.shape->bounds(), dims), dims, budget);
        e.obstacleLeaves += nodesIn(b, 3);
        obsBoxes.push_back(b);
    }
    // The static mask, and the automaton's copy, which also holds the tools' cells.
    e.obstacleBytes = 2 * treeBytes<MaskTreeT>(e.obstacleLeaves, obsBoxes);
    e.toolBytes = e.toolVoxels * kToolBytesPerVoxel + treeBytes<MaskTreeT>(toolLeaves, toolBoxes);
    // The compress push: a tool that covers the clay pools its clay over every column under it, in
    // an Int32 tree per tool (Push.cc) that can reach every leaf of the clay.
    if (scene.push == PushMode::Compress)
        e.toolBytes +=
            scene.tools.size() * treeBytes<MassTreeT>(e.clayLeavesGrown, grownBoxes, lowerCap, upperCap);
    const uint64_t lanes = std::max(1u, std::thread::hardware_concurrency()) - 1; // at most one per thread
    e.automatonBytes = e.clayLeavesGrown * (kAutomatonBytesPerLeaf + lanes * kAutomatonLaneBytesPerLeaf);
    // The global layer (lib/src/Transport.cc) holds, per cell of its domain: its coordinate,
    // mass, kind, six neighbours, distance, potential, row maps (~90 bytes, doubled for vector
    // growth), the index tree (4 bytes a voxel) and the solver's seven vectors and neighbour table
    // (~88 bytes), and the multigrid preconditioner of large solves (row lists, diagonal, three
    // work vectors, coordinates, aggregates, members over every level: ~88 bytes). Its domain is at
    // most the clay's leaves' voxels, and (round 5) with the compress push and tools that cover no
    // clay shape, the clay near the tools' sweeps: the over cells lie within the contact depth of a
    // tool (the chains go as deep as the contact is wide: contact <= sqrt(the tool's voxels at a
    // frame), 2D their number), the flood goes reach = ceil(contact) + 2 beyond them, or, where a
    // part the reach cut has no room and the reach doubles, up to twice the distance to room, which a
    // tool entering from the clay's surface finds within its extent, an inner seed 2 x 2 more, and
    // the Dirichlet cells one more; counted as every voxel of the leaves meeting those boxes. The
    // whole body otherwise: a tool that covers the clay compresses it all the way down; an obstacle
    // near the tool may wall the clay in (the reach then doubles up to the whole body); the surface
    // push's try may carry the overload up to kTrySteps voxels before the layer; clay over Tc or
    // from a file may overflow anywhere, with no tool near.
    if (scene.transport == Transport::Global) {
        uint64_t cells = e.clayLeavesGrown * 512;
        const bool clayMoves =
            std::any_of(areas.begin(), areas.end(), [](const Area& a) { return a.clay && a.moves; });
        if (scene.push == PushMode::Compress && !toolBoxes.empty() && !clayMoves) {
            bool covers = false;
            for (const Box& t : toolBoxes)
                for (const Area& a : areas) {
                    if (!a.clay) continue;
                    int spans = 0;
                    for (int ax = 0; ax < 3; ++ax)
                        spans += t.min[ax] <= a.box.min[ax] && t.max[ax] >= a.box.max[ax] ? 1 : 0;
                    covers |= spans >= 2; // in 2D z spans trivially: one more axis
                }
            if (!covers) {
                Box extent; // where the clay can be
                for (const Box& b : grownBoxes)
                    extent = unite(extent, b);
                const double contact = dims == 2 ? double(toolMost) : std::sqrt(double(toolMost));
                const int64_t reach = int64_t(std::ceil(kReachPerContact * contact)) + 2;
                const int64_t depth = int64_t(std::ceil(contact));
                const int64_t d = std::max(reach, 2 * int64_t(std::ceil(toolExtent))) + depth + 4 + 1;
                uint64_t near = 0;
                bool walled = false;
                for (const Box& t : toolBoxes) {
                    const Box g = growBox(t, d, 3);
                    for (const Box& o : obsBoxes)
                        walled |= !intersect(g, o).empty();
                    const Box b = intersect(g, extent);
                    near += b.empty() ? 0 : uint64_t(clay_internal::slotCount(b)) * 512;
                }
                if (!walled) cells = std::min(cells, near);
            }
        }
        e.transportBytes = cells * kTransportBytesPerCell;
    }
    // Writing a .vdb: a float density grid on the clay's leaves, and the surface level set, built
    // by levelSetRebuild through a mesh and meshToVolume (a float distance and an Int32 index grid
    // over a band around the surface): counted as three float grids on the clay's leaves, plus
    // the partial trees meshToVolume's worker threads build (each starts with its own upper nodes).
    const uint64_t workers = std::max(1u, std::thread::hardware_concurrency());
    e.outputBytes =
        3 * treeBytes<FloatTreeT>(e.clayLeavesGrown, grownBoxes, lowerCap, upperCap) +
        workers * 2 * upperNodeBytes<FloatTreeT>() *
            std::min(std::max<uint64_t>(1, distinctNodes(grownBoxes, 12)), std::max<uint64_t>(1, upperCap));
    return e;
}

uint64_t clayMemoryInUse(const MassGrid& mass)
{
    const uint64_t leaves = mass.tree().leafCount();
    return uint64_t(mass.tree().memUsage()) + leaves * (kAutomatonBytesPerLeaf + 3 * leafBytes<FloatTreeT>());
}

uint64_t defaultMemoryBudget()
{
    uint64_t avail = uint64_t(::sysconf(_SC_PHYS_PAGES)) * uint64_t(::sysconf(_SC_PAGE_SIZE));
    // A container's limit (cgroup v2, then v1) where it is lower than the machine's memory.
    for (const char* f : {"/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"}) {
        std::ifstream in(f);
        uint64_t limit = 0;
        if (in >> limit && limit > 0) avail = std::min(avail, limit);
    }
    if (avail == 0) avail = uint64_t(16) << 30; // sysconf failed: assume 16 GiB
    return avail / 4 * 3;
}

namespace {
/// checkMemoryBudget with the estimate at hand.
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
} // namespace

void checkMemoryBudget(const Scene& scene)
{
    if (scene.memoryBudget == kNoMemoryBudget) return;
    checkMemoryBudget(scene, estimateSceneMemory(scene));
}

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
    std::vector<ShapePtr> placed;          ///< the tools as placed now
    openvdb::MaskTree coveredSlots{false}; ///< slots of toolRegion whose tool cells are marked
    openvdb::MaskTree seenLeaves{false};   ///< mass leaves whose neighbouring slots are covered
    bool coveredAll = false;               ///< every slot of toolRegion is covered
    openvdb::Index64 leavesAtCover = 0;    ///< the mass tree's leaf count at the last cover
    std::function<bool()> stopPoll;
    bool stopped = false;
    ClayMeta startMeta;
    std::unique_ptr<MemoryEstimate> estimate; ///< estimateSceneMemory(scene), once computed

    std::vector<ShapePtr> toolsAt(uint64_t f) const
    {
        std::vector<ShapePtr> tools;
        for (const ToolSpec& t : scene.tools)
            tools.push_back(makeTransformed(t.shape.shape, t.poseAt(f)));
        return tools;
    }

    bool stopRequested() const { return stopPoll && stopPoll(); }

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
        return !unite(regionOf(toolsAt(frame + 1)), toolRegion).empty();
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

    /// The global transport's first try (docs/TRANSPORT.md, round 4b): the automaton alone, in chunks
    /// of kTryChunk steps, after a surface push only, unless the clay near the overload is saturated
    /// on average (kTrySaturated: saturated clay has room only at its surface, the automaton's random
    /// walk would not settle it), while the blocks it visits stay within kTryWork per 2x2x2 block of
    /// that clay (about what the global layer costs a frame on it) and the frame within kTrySteps
    /// steps. The clay near the overload: the clay leaves meeting @a near (the push's region grown
    /// by the layer's reach: its plastic zone; round 5), the whole body when @a near is empty (no tool
    /// touched clay): a frame costs the tool's zone, not the model, and a saturated lump beside a
    /// loose one is judged by itself. @a finished: the frame ended here (settled, tolerance, no
    /// room, the scene's step budget); otherwise the global layer runs on what is left. No stop
    /// request is honoured here (the try is bounded, as the layer is): a frame saved open is always
    /// past its global layer, so a resumed frame never repeats or skips it, with no new checkpoint
    /// field.
    StepReport settleBounded(bool& finished, const Box& near)
    {
        StepReport total;
        finished = false;
        if (automaton->residualOverload() == 0) return total; // the layer would do nothing either
        // The compress push leaves overload only where the clay ahead of the tool had no room (on
        // compressible clay it leaves none: the 48^3 press at 0.8 Tc), and global + compress is the
        // setting for clay at Tc: its results stay those of the layer alone.
        if (scene.push != PushMode::Surface) return total;
        uint64_t voxels = 0;
        int64_t clay = 0;
        if (near.empty()) {
            voxels = mass->activeVoxelCount();
            clay = automaton->totalMass();
        } else { // exact integers (a voxel is active exactly when it holds clay: Automaton::edit)
            for (const clay_internal::MassLeafT* leaf : clay_internal::leavesNear(mass->constTree(), near)) {
                voxels += leaf->onVoxelCount();
                const int32_t* d = leaf->buffer().data();
                int64_t sum = 0;
                for (openvdb::Index i = 0; i < clay_internal::MassLeafT::SIZE; ++i)
                    sum += d[i];
                clay += sum;
            }
        }
        const double tc = double(scene.rule.threshold);
        if (double(clay) >= kTrySaturated * tc * double(voxels)) return total;
        const double work = kTryWork * double(voxels) / (scene.dimensions == 2 ? 4.0 : 8.0);
        for (;;) {
            const StepReport r =
                settleFrameUpTo(std::min<uint64_t>(scene.settle.maxSteps, openSteps + kTryChunk),
                                /*honourStop=*/false);
            total += r;
            total.reason = r.reason;
            total.residualOverload = r.residualOverload;
            total.settled = r.settled;
            if (r.reason != StopReason::StepBudget || openSteps >= scene.settle.maxSteps) {
                finished = true;
                return total;
            }
            if (openSteps >= kTrySteps || double(total.blocksVisited) > work) return total;
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
        const int64_t boxSlots = clay_internal::slotCount(box);
        bool all = scene.transport == Transport::Global || reach > 64;
        std::vector<const clay_internal::MassLeafT*> leaves;
        if (!all) {
            leaves =
                clay_internal::leavesNear(mass->constTree(), clay_internal::grownBy(box, int32_t(8 * reach)));
            const int64_t side = 2 * reach + 1;
            const int64_t around = side * side * (is2D ? 1 : side);
            all = int64_t(leaves.size()) > boxSlots / around;
        }
        std::vector<Coord> slots;
        openvdb::tree::ValueAccessor<openvdb::MaskTree> covered(coveredSlots);
        if (all) {
            for (int32_t x = lo.x(); x <= hi.x(); ++x)
                for (int32_t y = lo.y(); y <= hi.y(); ++y)
                    for (int32_t z = lo.z(); z <= hi.z(); ++z)
                        if (!covered.isValueOn(Coord(x, y, z))) slots.emplace_back(x, y, z);
            coveredAll = true;
        } else {
            openvdb::tree::ValueAccessor<openvdb::MaskTree> seen(seenLeaves);
            openvdb::MaskTree want(false);
            openvdb::tree::ValueAccessor<openvdb::MaskTree> wacc(want);
            const int r = int(reach), rz = is2D ? 0 : r;
            for (const auto* leaf : leaves) {
                const Coord o(leaf->origin().x() >> 3, leaf->origin().y() >> 3, leaf->origin().z() >> 3);
                if (reach == 1) {
                    if (seen.isValueOn(o)) continue;
                    seen.setValueOn(o);
                }
                for (int dx = -r; dx <= r; ++dx)
                    for (int dy = -r; dy <= r; ++dy)
                        for (int dz = -rz; dz <= rz; ++dz) {
                            const Coord c = o.offsetBy(dx, dy, dz);
                            if (c.x() < lo.x() || c.x() > hi.x() || c.y() < lo.y() || c.y() > hi.y() ||
                                c.z() < lo.z() || c.z() > hi.z() || covered.isValueOn(c))
                                continue;
                            wacc.setValueOn(c);
                        }
            }
            for (auto it = want.cbeginValueOn(); it; ++it)
                slots.push_back(it.getCoord());
            std::sort(slots.begin(), slots.end());
        }
        for (const Coord& c : slots)
            covered.setValueOn(c);
        if (slots.empty()) return;
        auto acc = grid.getAccessor();
        using MaskLeaf = openvdb::MaskTree::LeafNodeType;
        for (const ShapePtr& t : placed) {
            Box tb = t->bounds();
            if (is2D) tb = intersect(tb, Box{{{INT32_MIN, INT32_MIN, 0}}, {{INT32_MAX, INT32_MAX, 0}}});
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
                            if (t->distance(Vec3{{double(x), double(y), double(z)}}) < 0)
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
    /// frame f - 1 is split into sub-steps of at most a quarter voxel (the largest displacement of
    /// a corner of any tool's bounds), each placed and pushed in turn, so the push acts on the
    /// volume the tools sweep and clay never passes through a thin or fast tool.
    PushReport pushTools(uint64_t f)
    {
        PushOptions po;
        po.mode = scene.push;
        const std::vector<ShapePtr> tools = toolsAt(f);
        int substeps = 1;
        if (scene.sweep && f > 0) {
            double most = 0;
            for (const ToolSpec& t : scene.tools) {
                const Pose a = t.poseAt(f - 1), b = t.poseAt(f);
                const Box bb = t.shape.shape->bounds();
                if (bb.empty()) continue;
                for (int corner = 0; corner < 8; ++corner) {
                    const Vec3 p{{double(corner & 1 ? bb.max[0] : bb.min[0]),
                                  double(corner & 2 ? bb.max[1] : bb.min[1]),
                                  double(corner & 4 ? bb.max[2] : bb.min[2])}};
                    const Vec3 pa = a.apply(p), pb = b.apply(p);
                    const double d =
                        std::sqrt((pa[0] - pb[0]) * (pa[0] - pb[0]) + (pa[1] - pb[1]) * (pa[1] - pb[1]) +
                                  (pa[2] - pb[2]) * (pa[2] - pb[2]));
                    most = std::max(most, d);
                }
            }
            substeps = int(std::min(std::ceil(most * 4), double(kMaxSweepSubsteps)));
            substeps = std::max(substeps, 1);
        }
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
            placeTools(sub);
            const PushReport r = push(*automaton, sub, po);
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

    im.obstacles = openvdb::MaskGrid::create(false);
    im.obstacles->setName("obstacles");
    for (const ShapeSpec& o : scene.obstacles)
        rasterize(*im.obstacles, *o.shape, scene.dimensions, threads);
    if (!scene.obstacles.empty() && clayMeetsObstacles(im.mass->tree(), im.obstacles->tree())) {
        auto oacc = im.obstacles->getConstAccessor();
        for (auto it = im.mass->tree().cbeginValueOn(); it; ++it) {
            if (*it != 0 && oacc.isValueOn(it.getCoord())) {
                std::string which;
                const openvdb::Coord c = it.getCoord();
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
    }
    // The automaton's obstacles: the static ones, plus the tools' voxels (placeTools).
    im.automaton = std::make_unique<Automaton>(im.mass, opt, im.obstacles->deepCopy());
    if (steps) im.automaton->setStepCount(steps);
    // An open frame's tools are where its push left them; that push is not repeated.
    if (!scene.tools.empty()) im.placeTools(im.toolsAt(im.open ? im.frame + 1 : im.frame));
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
const ClayMeta& Sculptor::startMeta() const
{
    return mImpl->startMeta;
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
    return m;
}

FrameReport Sculptor::runFrame()
{
    Impl& im = *mImpl;
    if (done())
        throw Error("the scene has no frame left to run (" + std::to_string(im.scene.frames) + " run)");
    im.stopped = false;
    FrameReport rep;
    rep.frame = im.frame + 1;
    if (!im.open) {
        // The push, the global transport's try and its layer run once, when the frame opens: a
        // frame resumed from a checkpoint (im.open) is past them and goes straight on settling.
        if (!im.scene.tools.empty()) rep.push = im.pushTools(rep.frame);
        if (im.scene.transport == Transport::Global) {
            GlobalTransportOptions go;
            go.threads = im.automaton->options().threads;
            // The plastic zone: a few contact sizes around the over cells; the whole body when no
            // tool touched clay this frame.
            go.reach = rep.push.contactSize > 0
                           ? int64_t(std::ceil(kReachPerContact * rep.push.contactSize)) + 2
                           : 0;
            // The overload the push made lies in its region: look for it there only (a frame
            // costs the tool's region, not the model's size).
            if (rep.push.contactSize > 0) go.seedRegion = rep.push.region;
            // The automaton's try first (compressible clay settles in a few cheap steps, as with
            // local); the layer only on what it leaves, its seeds looked for as far as the try's
            // steps can have carried the overload (a Margolus step moves clay one voxel at most).
            im.open = true;
            im.openSteps = 0;
            rep.settle =
                im.settleBounded(rep.finished, go.reach > 0 ? growBox(go.seedRegion, go.reach, 3) : Box());
            rep.trySteps = rep.settle.steps;
            if (rep.finished) {
                im.open = false;
                im.openSteps = 0;
                ++im.frame;
                return rep;
            }
            if (rep.push.contactSize > 0)
                go.seedRegion = growBox(go.seedRegion, int64_t(rep.settle.steps), 3);
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
        im.open = false;
        im.openSteps = 0;
        ++im.frame;
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
        if (onFrame) onFrame(r);
        if (!r.finished) break; // stopped() is set
    }
    s.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
    // The final mass is measureClay's sum (leaf by leaf, in parallel): the automaton keeps no tiles
    // (it voxelizes them), so it is totalMass()'s walk over every value, without a second walk.
    s.metrics = measureClay(*im.mass, im.scene.rule.threshold, im.automaton->obstacles().get(),
                            im.scene.dimensions, im.automaton->options().threads);
    s.massFinal = s.metrics.mass;
    s.massDrift = s.massFinal - s.massInitial;
    s.residualOverload = im.automaton->residualOverload();
    s.settled = im.automaton->settled();
    return s;
}

} // namespace vdbclay
