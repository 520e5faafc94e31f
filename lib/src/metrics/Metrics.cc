// Whole-grid measurements (Metrics.h), whatever the tree's layout.
//
// totalMass, residualOverload and clayVoxelCount walk every value once, tiles included, in 64-bit
// integers; contentHash adds a hash of each voxel's coordinate and value (the automaton's block
// hash, rules_internal::hashKey), so the order of the walk does not matter. measureClay takes each
// leaf's integer sums and interior mask in parallel, then adds them up: exact, so the same numbers on
// any thread count. compareShapes compares occupied sets as masks and measures the distances between
// their surface voxels with a static 3D tree of voxel centres (exact integer squared distances).
// metrics/ stands on core/, automaton/ (the hash) and shapes/ (rasterised reference shapes).
#include "vdbclay/Metrics.h"

#include "vdbclay/Shapes.h"
#include "vdbclay/Types.h"

#include "automaton/RulesImpl.h"
#include "core/ParallelFor.h"
#include "shapes/Voxels.h"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <array>
#include <climits>
#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace vdbclay {

int64_t totalMass(const MassGrid& mass)
{
    int64_t sum = 0;
    for (auto it = mass.tree().cbeginValueAll(); it; ++it) {
        if (*it == 0) continue;
        // A tile of 4096^3 voxels holding 2^31 each is ~2^67: a file can ask for that.
        int64_t part = 0;
        if (__builtin_mul_overflow(int64_t(*it), int64_t(it.getVoxelCount()), &part) ||
            __builtin_add_overflow(sum, part, &sum)) {
            throw Error("totalMass: the total mass exceeds " +
                        std::to_string(std::numeric_limits<int64_t>::max()));
        }
    }
    return sum;
}

int64_t residualOverload(const MassGrid& mass, int32_t threshold, const ObstacleGrid* obstacles)
{
    int64_t sum = 0;
    openvdb::MaskGrid::ConstAccessor* oacc = nullptr;
    std::unique_ptr<openvdb::MaskGrid::ConstAccessor> holder;
    if (obstacles) {
        holder = std::make_unique<openvdb::MaskGrid::ConstAccessor>(obstacles->getConstAccessor());
        oacc = holder.get();
    }
    for (auto it = mass.tree().cbeginValueAll(); it; ++it) {
        if (*it <= threshold) continue;
        if (!it.isVoxelValue()) {
            throw Error("residualOverload: the grid holds an over-threshold tile; voxelize it first");
        }
        if (oacc && oacc->isValueOn(it.getCoord())) continue;
        sum += int64_t(*it) - threshold;
    }
    return sum;
}

uint64_t clayVoxelCount(const MassGrid& mass)
{
    uint64_t n = 0;
    for (auto it = mass.tree().cbeginValueAll(); it; ++it) {
        if (*it != 0) n += it.getVoxelCount();
    }
    return n;
}

uint64_t contentHash(const MassGrid& mass)
{
    // Order-independent: a sum of per-voxel hashes, so the tree's layout does not matter.
    uint64_t h = 0, count = 0;
    for (auto it = mass.tree().cbeginValueAll(); it; ++it) {
        if (*it == 0) continue;
        if (!it.isVoxelValue()) {
            throw Error("contentHash: the grid holds a nonzero tile; voxelize it first");
        }
        const openvdb::Coord c = it.getCoord();
        BlockKey k;
        k.x = c.x();
        k.y = c.y();
        k.z = c.z();
        k.step = uint64_t(uint32_t(*it));
        h += rules_internal::hashKey(k);
        ++count;
    }
    return rules_internal::mix64(h ^ rules_internal::mix64(count));
}

// ---- Accuracy metrics ---------------------------------------------------------------------------

namespace {

using openvdb::Coord;

void checkArgs(const char* what, int32_t threshold, int dims)
{
    if (threshold <= 0) {
        throw Error(std::string(what) + ": the threshold Tc must be > 0, not " + std::to_string(threshold));
    }
    if (dims != 2 && dims != 3) {
        throw Error(std::string(what) + ": dimensions must be 2 or 3, not " + std::to_string(dims));
    }
}

/// The face neighbour offsets: the first 4 in 2D, all 6 in 3D.
const Coord kFaces[6] = {Coord(1, 0, 0),  Coord(-1, 0, 0), Coord(0, 1, 0),
                         Coord(0, -1, 0), Coord(0, 0, 1),  Coord(0, 0, -1)};
int faceCount(int dims)
{
    return dims == 3 ? 6 : 4;
}

/// 2 m >= Tc, in 64 bits.
inline bool occupied(int32_t m, int32_t threshold)
{
    return 2 * int64_t(m) >= int64_t(threshold);
}

/// Calls @a fn(coord, mass) for every voxel holding clay; refuses nonzero tiles.
template <typename Fn> void forEachClayVoxel(const MassGrid& mass, const char* what, Fn&& fn)
{
    for (auto it = mass.tree().cbeginValueAll(); it; ++it) {
        if (*it == 0) continue;
        if (!it.isVoxelValue())
            throw Error(std::string(what) + ": the grid holds a nonzero tile; voxelize it first");
        fn(it.getCoord(), *it);
    }
}

} // namespace

ClayMetrics measureClay(const MassGrid& mass, int32_t threshold, const ObstacleGrid* obstacles, int dims,
                        int threads)
{
    checkArgs("measureClay", threshold, dims);
    // Tiles first (only the levels above the leaves): a nonzero one is refused before any sum.
    {
        auto it = mass.tree().cbeginValueAll();
        it.setMaxDepth(it.getLeafDepth() - 1);
        for (; it; ++it) {
            if (*it != 0) throw Error("measureClay: the grid holds a nonzero tile; voxelize it first");
        }
    }
    // First pass, leaf by leaf in parallel: each leaf's integer sums (exact, so their total does not
    // depend on the order) and the mask of its interior cells.
    using MassLeaf = MassGrid::TreeType::LeafNodeType;
    std::vector<const MassLeaf*> leaves;
    leaves.reserve(mass.tree().leafCount());
    for (auto it = mass.tree().cbeginLeaf(); it; ++it)
        leaves.push_back(&*it);
    struct LeafSums {
        int64_t mass = 0, residualOverload = 0, interiorSum = 0;
        uint64_t clayVoxels = 0, occupiedVoxels = 0, interiorCells = 0;
        int32_t maxCell = 0;
        MassLeaf::NodeMaskType interior;
    };
    std::vector<LeafSums> sums(leaves.size());
    const int faces = faceCount(dims);
    parallel_internal::forEachIndex(leaves.size(), threads, [&](size_t li) {
        const MassLeaf& leaf = *leaves[li];
        LeafSums& out = sums[li];
        auto acc = mass.getConstAccessor();
        // The leaf's obstacles once (a leaf, an active tile or none), and face neighbours inside the
        // leaf read from its buffer: only the voxels on the leaf's faces read through the accessor.
        const openvdb::MaskTree::LeafNodeType* ol = nullptr;
        bool obstacleTile = false;
        if (obstacles) {
            ol = obstacles->tree().probeConstLeaf(leaf.origin());
            obstacleTile = !ol && obstacles->tree().isValueOn(leaf.origin());
        }
        const int32_t* d = leaf.buffer().data();
        constexpr int kDim = int(MassLeaf::DIM);
        // offset steps of the faces in kFaces' order: +-x (DIM^2), +-y (DIM), +-z (1)
        const int step[6] = {kDim * kDim, -kDim * kDim, kDim, -kDim, 1, -1};
        for (openvdb::Index i = 0; i < MassLeaf::SIZE; ++i) {
            const int32_t m = d[i];
            if (m == 0) continue;
            const Coord c = leaf.offsetToGlobalCoord(i);
            out.mass += m;
            out.maxCell = std::max(out.maxCell, m);
            ++out.clayVoxels;
            if (occupied(m, threshold)) ++out.occupiedVoxels;
            const bool obstacle = ol ? ol->isValueOn(i) : obstacleTile;
            if (!obstacle && m > threshold) out.residualOverload += int64_t(m) - threshold;
            bool interior = !obstacle && !(dims == 2 && c.z() != 0);
            const int local[3] = {int(i >> (2 * MassLeaf::LOG2DIM)), int(i >> MassLeaf::LOG2DIM) & (kDim - 1),
                                  int(i) & (kDim - 1)};
            for (int f = 0; f < faces && interior; ++f) {
                const int axis = f >> 1, to = local[axis] + ((f & 1) ? -1 : 1);
                if (to >= 0 && to < kDim)
                    interior = d[int(i) + step[f]] != 0;
                else
                    interior = acc.getValue(c + kFaces[f]) != 0;
            }
            if (interior) {
                out.interior.setOn(i);
                ++out.interiorCells;
                out.interiorSum += m;
            }
        }
    });
    ClayMetrics r;
    int64_t interiorSum = 0;
    for (const LeafSums& l : sums) {
        r.mass += l.mass;
        r.maxCell = std::max(r.maxCell, l.maxCell);
        r.clayVoxels += l.clayVoxels;
        r.occupiedVoxels += l.occupiedVoxels;
        r.residualOverload += l.residualOverload;
        r.interiorCells += l.interiorCells;
        interiorSum += l.interiorSum;
    }
    if (r.mass > 0) {
        const int64_t cellsAtRest = (r.mass + threshold - 1) / threshold;
        r.compaction = double(r.clayVoxels) / double(cellsAtRest);
    }
    if (r.interiorCells == 0) return r;

    // Second pass: the spread about the mean (two passes: no cancellation in a sum of squares), one
    // sum in the tree's voxel order (leaves in order, voxels in offset order): the same bits on any
    // thread count.
    const double mean = double(interiorSum) / double(r.interiorCells);
    double squares = 0;
    for (size_t li = 0; li < leaves.size(); ++li) {
        for (auto it = sums[li].interior.beginOn(); it; ++it) {
            const double d = double(leaves[li]->getValue(it.pos())) - mean;
            squares += d * d;
        }
    }
    r.interiorMeanDensity = mean / double(threshold);
    r.heterogeneityCV = std::sqrt(squares / double(r.interiorCells)) / mean;
    return r;
}

namespace {

using Point = std::array<int32_t, 3>;

int64_t squaredDistance(const Point& a, const Point& b)
{
    int64_t s = 0;
    for (int i = 0; i < 3; ++i) {
        const int64_t d = int64_t(a[i]) - int64_t(b[i]);
        s += d * d;
    }
    return s;
}

/// A static 3D tree for exact nearest-neighbour queries on voxel centres (integer distances).
class PointTree {
public:
    explicit PointTree(std::vector<Point> points) : mPoints(std::move(points))
    {
        build(0, mPoints.size(), 0);
    }

    /// The squared distance from @a q to the nearest point; the tree must not be empty.
    int64_t nearest(const Point& q) const
    {
        int64_t best = INT64_MAX;
        search(0, mPoints.size(), 0, q, best);
        return best;
    }

private:
    // The median of [lo, hi) along axis (depth % 3) sits at the middle; each half is a subtree.
    void build(size_t lo, size_t hi, int depth)
    {
        if (hi - lo <= 1) return;
        const size_t mid = lo + (hi - lo) / 2;
        const int axis = depth % 3;
        std::nth_element(mPoints.begin() + lo, mPoints.begin() + mid, mPoints.begin() + hi,
                         [axis](const Point& a, const Point& b) { return a[axis] < b[axis]; });
        build(lo, mid, depth + 1);
        build(mid + 1, hi, depth + 1);
    }

    void search(size_t lo, size_t hi, int depth, const Point& q, int64_t& best) const
    {
        if (lo >= hi) return;
        const size_t mid = lo + (hi - lo) / 2;
        const Point& p = mPoints[mid];
        best = std::min(best, squaredDistance(p, q));
        const int axis = depth % 3;
        const int64_t d = int64_t(q[axis]) - int64_t(p[axis]);
        // Near side first; the far side only if the splitting plane is closer than the best.
        if (d < 0) {
            search(lo, mid, depth + 1, q, best);
            if (d * d < best) search(mid + 1, hi, depth + 1, q, best);
        } else {
            search(mid + 1, hi, depth + 1, q, best);
            if (d * d < best) search(lo, mid, depth + 1, q, best);
        }
    }

    std::vector<Point> mPoints;
};

/// The surface voxels of the active set of @a set: active voxels with an inactive face neighbour.
std::vector<Point> surfaceVoxels(const openvdb::MaskGrid& set, int dims)
{
    std::vector<Point> out;
    auto acc = set.getConstAccessor();
    const int faces = faceCount(dims);
    for (auto it = set.tree().cbeginValueOn(); it; ++it) {
        openvdb::CoordBBox box;
        it.getBoundingBox(box); // a voxel, or an active tile of the mask
        for (auto c = box.begin(); c; ++c) {
            for (int f = 0; f < faces; ++f) {
                if (!acc.isValueOn(*c + kFaces[f])) {
                    const Coord v = *c;
                    out.push_back(Point{{v.x(), v.y(), v.z()}});
                    break;
                }
            }
        }
    }
    return out;
}

/// Sum and maximum over @a from of the distance to the nearest point of @a to (not empty).
void accumulateDistances(const std::vector<Point>& from, const PointTree& to, double& sum, double& max)
{
    for (const Point& p : from) {
        const double d = std::sqrt(double(to.nearest(p)));
        sum += d;
        max = std::max(max, d);
    }
}

openvdb::MaskGrid::Ptr occupiedSet(const MassGrid& mass, int32_t threshold, int dims, const char* what)
{
    auto set = openvdb::MaskGrid::create(false);
    auto acc = set->getAccessor();
    forEachClayVoxel(mass, what, [&](const Coord& c, int32_t m) {
        if (dims == 2 && c.z() != 0) return;
        if (occupied(m, threshold)) acc.setValueOn(c);
    });
    return set;
}

ShapeError compareSets(const openvdb::MaskGrid& clay, const openvdb::MaskGrid& reference, int dims)
{
    ShapeError e;
    e.clayVoxels = clay.tree().activeVoxelCount();
    e.referenceVoxels = reference.tree().activeVoxelCount();
    openvdb::MaskTree both(clay.tree());
    both.topologyIntersection(reference.tree());
    e.intersection = both.activeVoxelCount();
    e.unionVoxels = e.clayVoxels + e.referenceVoxels - e.intersection;
    e.iou = e.unionVoxels == 0 ? 1.0 : double(e.intersection) / double(e.unionVoxels);

    std::vector<Point> a = surfaceVoxels(clay, dims), b = surfaceVoxels(reference, dims);
    e.claySurface = a.size();
    e.referenceSurface = b.size();
    if (a.empty() && b.empty()) return e;
    if (a.empty() || b.empty()) {
        e.meanSurfaceDistance = e.maxSurfaceDistance = std::numeric_limits<double>::infinity();
        return e;
    }
    double sum = 0, max = 0;
    {
        const PointTree tb(b);
        accumulateDistances(a, tb, sum, max);
    }
    const PointTree ta(std::move(a));
    accumulateDistances(b, ta, sum, max);
    e.meanSurfaceDistance = sum / double(e.claySurface + e.referenceSurface);
    e.maxSurfaceDistance = max;
    return e;
}

} // namespace

ShapeError compareShapes(const MassGrid& clay, int32_t threshold, const MassGrid& reference,
                         int32_t referenceThreshold, int dims)
{
    checkArgs("compareShapes", threshold, dims);
    checkArgs("compareShapes (reference)", referenceThreshold, dims);
    return compareSets(*occupiedSet(clay, threshold, dims, "compareShapes"),
                       *occupiedSet(reference, referenceThreshold, dims, "compareShapes (reference)"), dims);
}

ShapeError compareShapes(const MassGrid& clay, int32_t threshold, const Shape& reference, int dims)
{
    checkArgs("compareShapes", threshold, dims);
    auto ref = openvdb::MaskGrid::create(false);
    auto acc = ref->getAccessor();
    shapes_internal::forEachVoxelInside(
        reference, dims, [&](int32_t x, int32_t y, int32_t z) { acc.setValueOn(Coord(x, y, z)); });
    return compareSets(*occupiedSet(clay, threshold, dims, "compareShapes"), *ref, dims);
}

} // namespace vdbclay
