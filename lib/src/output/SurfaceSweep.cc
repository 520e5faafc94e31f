// The fast sweeping method from a fog volume to a signed distance field, leaf by leaf.
//
// fogToSdfByLeaves() returns exactly (bit for bit) what openvdb::tools::fogToSdf(fog, iso) returns
// for a fog without tiles, in a fraction of its time: OpenVDB computes, for each of its 8 sweeps,
// the voxel diagonals (x+y+z = k ...) of every leaf into maps of node masks, then runs one parallel
// loop per diagonal with a tree accessor per neighbour read. Here the same values are computed in
// flat per-leaf buffers with a table of face-neighbour leaves:
//
// - Initialisation (OpenVDB's InitSdf): a voxel next to the isosurface (a face neighbour on the other
//   side of the isovalue) gets the distance from the crossings on its axes, h / sqrt(sum 1/d^2);
//   every other voxel +-FLT_MAX by its side; the same expressions in the same order. A leaf whose
//   values and whose face neighbours' layers facing it all lie on one side has no voxel next to the
//   isosurface: one test of its values, not six neighbours' per voxel (most leaves of a large lump).
// - Sweeps (SweepingKernel::sweep): OpenVDB orders a sweep by the diagonal key (e.g. x+y-z
//   ascending), so when a voxel is updated its three upwind face neighbours have been updated in
//   this sweep and its three downwind ones have not; voxels of one key are never face neighbours.
//   Any order with that property reads the same values, so gives the same result: here the leaves
//   go by their own diagonal key (leaf coordinates, same signs), leaves of one key in parallel (they
//   share no face), and inside a leaf the voxels in nested loops running along the sweep's signs.
//   The Godunov update is OpenVDB's, expression for expression (three cases, same tests).
// - Updates that cannot change a value are skipped. A voxel's update reads only its own value and its
//   six face neighbours', and only its own update changes its value; updated again with none of those
//   neighbours changed since, it gives the same candidate and changes nothing. So each sweep updates
//   only the voxels one of whose face neighbours changed in the sweep before or in this one (a change
//   two sweeps back came before the voxel's update in the sweep between): each leaf records the voxels
//   each sweep changed (by the sweep's parity), a leaf none of whose voxels and face neighbours' voxels
//   changed is passed over whole, and inside a leaf the changes of this sweep are followed as they
//   happen. Before the first sweep only the voxels next to the isosurface hold finite values (an update
//   reading only +-FLT_MAX returns early), so they count as the changes before it. Every value is the
//   one the full sweep computes; after the first sweeps most of the band holds still and costs a test.
// - Finalisation (MinMaxKernel, PruneMinMaxFltKernel): every value left at +-FLT_MAX (voxels
//   active or not, tiles, the background) takes the largest / smallest finite active value, as
//   OpenVDB's pass leaves them (checked bit for bit by tests/TestSurface.cc).
//
// Results do not depend on the thread count (each voxel's update reads only values fixed by the
// order above). A fog with tiles goes to OpenVDB's own fogToSdf; the narrow band of a density with
// tiles (uniform clay) is swept over the leaves near its isosurface alone (SurfaceTiles.cc), reading
// the tiles' values where a leaf of the sweep lies over one.
//
// The narrow band (narrowBandSdfFromDensity, what surfaceLevelSet keeps: |value| < band). A voxel's
// update that yields u < band reads only neighbours holding less than u, and compares u with the
// others (u <= d2, u <= d3), which hold as long as those are at least band: the Godunov update's
// three cases all give u > every neighbour they use (1: d1 + h; 2: u > d2 is tested; 3: taken only
// when the 2-case u > d3, and then its root exceeds d3). So, update by update in the same order,
// the values below band are the same whichever voxels holding band or more are swept. And each
// such update adds at least h / sqrt(3) to its smallest neighbour (u - d1 >= h, h / sqrt 2, h / sqrt 3
// in the three cases), so a value below band lies fewer than band sqrt(3) / h face steps from a
// voxel next to the isosurface (at most 5 for the surface's band of 3 voxels): sweeping the voxels
// within ceil(band sqrt(3) / h) steps (6: one to spare) gives every value below band bit for bit,
// and the voxels deeper inside or further out (most of a large lump) are not swept. Those keep
// +-FLT_MAX, which the finalisation turns into the extreme finite values: of band or more whenever
// some swept value is (checked; otherwise, clay thinner than the band, the whole fog is swept), as
// in the full sweep; clipped to the band, they are what the full sweep gives. Nor is a voxel updated
// while none of its face neighbours holds less than band: the update would exceed them all, so it
// keeps a value of band or more, the band once clipped, as it would be updated. The clipping itself
// (clipToNarrowBand's) is done in the finalisation's pass over the values. tests/TestSurface.cc
// checks the band against OpenVDB's fogToSdf, clipped alike, bit for bit.
//
// Memory. The masks come first (which voxels lie next to the isosurface, read from the fog alone;
// which lie within reach), the values after, allocated only in the leaves holding such a voxel: a
// leaf with none keeps +-FLT_MAX throughout (its neighbours read it as a missing leaf: the update
// takes absolute values) and ends inactive at +-band by its side, so where its voxels all lie on
// one side it becomes that tile (as pruning would make it) and its values never exist.
#include "output/Surface.h"

#include <openvdb/math/Math.h>
#include <openvdb/tools/FastSweeping.h>
#include <openvdb/tools/Prune.h>
#include <openvdb/tree/LeafManager.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <utility>
#include <vector>

namespace vdbclay {
namespace io_internal {

namespace {

using FloatTree = openvdb::FloatTree;
using LeafT = FloatTree::LeafNodeType;
using openvdb::Coord;
using openvdb::Index;

constexpr int kDim = int(LeafT::DIM); // 8
constexpr float kMax = std::numeric_limits<float>::max();

inline Index offsetOf(int x, int y, int z)
{
    return Index((x << (2 * LeafT::LOG2DIM)) + (y << LeafT::LOG2DIM) + z);
}

/// Distance to the isosurface of a voxel next to it, or +-FLT_MAX (OpenVDB's InitSdf, fog input).
/// @a nb holds the six face neighbours' fog values in the order -x, +x, -y, +y, -z, +z.
inline float initValue(float value, const float nb[6], float isoValue, float h, bool& boundary)
{
    // InitSdf with mAboveSign = -1 (a fog): above = -FLT_MAX, h = -voxelSize.
    const float above = -kMax;
    const bool isAbove = value > isoValue;
    const bool less = value < isoValue;
    bool mask[6];
    bool any = false;
    for (int i = 0; i < 6; ++i) {
        mask[i] = less ^ (nb[i] < isoValue);
        any = any || mask[i];
    }
    boundary = any;
    if (!any) return isAbove ? above : -above;
    const float delta = value - isoValue;
    if (openvdb::math::isApproxZero(delta)) return 0;
    float sum = 0;
    for (int i = 0; i < 6;) {
        float d = kMax, d2;
        if (mask[i]) d = openvdb::math::Abs(delta / (value - nb[i]));
        ++i;
        if (mask[i]) {
            d2 = openvdb::math::Abs(delta / (value - nb[i]));
            if (d2 < d) d = d2;
        }
        ++i;
        if (d < kMax) sum += 1 / (d * d);
    }
    return isAbove ? h / openvdb::math::Sqrt(sum) : -h / openvdb::math::Sqrt(sum);
}

/// One leaf's state for the sweeps: its values (the output leaf's buffer), the voxels the sweeps
/// update, its face neighbours.
struct SweepLeaf {
    float* values;
    LeafT::NodeMaskType sweep;        // active and not next to the isosurface
    std::array<int32_t, 6> neighbour; // leaf index at -x, +x, -y, +y, -z, +z, or -1 (2^31 leaves: 4 TiB)
    /// The voxels each sweep changed, by the sweep's parity. Before the sweeps, changed[1] holds the
    /// voxels next to the isosurface (active), which count as changed before the first sweep (below).
    LeafT::NodeMaskType changed[2];
    LeafT::NodeMaskType& boundary() { return changed[1]; }
    const LeafT::NodeMaskType& boundary() const { return changed[1]; }
    /// The voxels changed in the sweep before and in this one so far.
    LeafT::NodeMaskType recent() const { return changed[0] | changed[1]; }
};

/// OpenVDB's bound on a neighbour's |value| for the Godunov update to read it (kValid and over: none).
constexpr float kValid = 1000.f;

/// The Godunov update of OpenVDB's SweepingKernel::sweep for one voxel (the SDF part only). No update
/// when every neighbour's |value| is @a valid or more: OpenVDB's kValid, or the band when only the
/// band's values are kept (the update would exceed every neighbour, so the band).
inline void updateVoxel(float& value, float n0, float n1, float n2, float n3, float n4, float n5, float h,
                        float sqrt2h, float valid)
{
    // NN: |neighbour value|; std::min keeps the first of equals.
    auto pick = [](float a, float b) { return b < a ? b : a; };
    float d1 = pick(openvdb::math::Abs(n0), openvdb::math::Abs(n1));
    float d2 = pick(openvdb::math::Abs(n2), openvdb::math::Abs(n3));
    float d3 = pick(openvdb::math::Abs(n4), openvdb::math::Abs(n5));
    if (!(d1 < valid || d2 < valid || d3 < valid)) return;
    const float sign = value >= 0.f ? 1.f : -1.f;
    const float absV = openvdb::math::Abs(value);
    if (d2 < d1) std::swap(d1, d2);
    if (d3 < d2) std::swap(d2, d3);
    if (d2 < d1) std::swap(d1, d2);
    float update = d1 + h;
    if (update <= d2) {
        if (update < absV) value = sign * update;
        return;
    }
    if (d2 <= sqrt2h + d1) {
        const float D = 2.f * h * h - openvdb::math::Pow2(d1 - d2);
        update = 0.5f * (d1 + d2 + std::sqrt(D));
        if (update > d2 && update <= d3) {
            if (update < absV) value = sign * update;
            return;
        }
    }
    const float d123 = d1 + d2 + d3;
    const float D = d123 * d123 - 3.f * (d1 * d1 + d2 * d2 + d3 * d3 - h * h);
    if (D >= 0.f) {
        update = float(1.0 / 3.0) * (d123 + std::sqrt(D));
        if (update < absV) value = sign * update;
    }
}

/// Leaf @a li's voxels of @a masks grown by one face step, within the leaf and from its face
/// neighbours @a nb (-x, +x, -y, +y, -z, +z; -1: none): one voxel along each axis, united.
LeafT::NodeMaskType faceDilated(const std::vector<LeafT::NodeMaskType>& masks,
                                const std::array<int32_t, 6>& nb, size_t li)
{
    LeafT::NodeMaskType out = maskGrownAlong(masks, li, nb[0], nb[1], 0, 1);
    out |= maskGrownAlong(masks, li, nb[2], nb[3], 1, 1);
    out |= maskGrownAlong(masks, li, nb[4], nb[5], 2, 1);
    return out;
}

/// Sweep @a index (0..7) with signs (sx, sy, sz) over every leaf, in the order described at the top,
/// updating only the voxels a face neighbour of which changed since their last update (see the top).
void sweepOnce(std::vector<SweepLeaf>& leaves, const std::vector<std::pair<int64_t, size_t>>& order,
               const std::vector<size_t>& sliceStart, int index, int sx, int sy, int sz, float h,
               float sqrt2h, float valid, bool reverse)
{
    const int now = index & 1;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, leaves.size()), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t li = r.begin(); li != r.end(); ++li)
            leaves[li].changed[now].setOff(); // the sweep two before: read by none from here on
    });
    const size_t slices = sliceStart.size() - 1;
    for (size_t s = 0; s < slices; ++s) {
        const size_t slice = reverse ? slices - 1 - s : s;
        tbb::parallel_for(
            tbb::blocked_range<size_t>(sliceStart[slice], sliceStart[slice + 1]),
            [&](const tbb::blocked_range<size_t>& r) {
                // A leaf's recent changes and its face neighbours' (index 1 + f, empty where there is no
                // leaf), for faceDilated.
                std::vector<LeafT::NodeMaskType> recent(7);
                std::array<int32_t, 6> across;
                for (int f = 0; f < 6; ++f)
                    across[size_t(f)] = 1 + f;
                for (size_t k = r.begin(); k != r.end(); ++k) {
                    // The leaves of a slice lie apart in memory: the values of the one two ahead are
                    // fetched while this one is swept (the sweep waits on memory more than it computes).
                    if (k + 2 < r.end()) {
                        const SweepLeaf& ahead = leaves[order[k + 2].second];
                        if (ahead.values && !ahead.sweep.isOff())
                            for (Index i = 0; i < LeafT::SIZE; i += 64 / sizeof(float))
                                __builtin_prefetch(ahead.values + i);
                    }
                    SweepLeaf& leaf = leaves[order[k].second];
                    if (leaf.sweep.isOff()) continue;
                    // The voxels next to a recent change: in this leaf or across a face (the leaves across
                    // a face lie in other slices, done or not yet begun; this leaf's own changes in this
                    // sweep are added as they happen, in `pending`).
                    recent[0] = leaf.recent();
                    bool anyRecent = !recent[0].isOff();
                    for (int f = 0; f < 6; ++f) {
                        const int64_t nbLeaf = leaf.neighbour[size_t(f)];
                        recent[size_t(1 + f)] =
                            nbLeaf >= 0 ? leaves[size_t(nbLeaf)].recent() : LeafT::NodeMaskType();
                        anyRecent = anyRecent || !recent[size_t(1 + f)].isOff();
                    }
                    if (!anyRecent) continue; // no voxel of it can change
                    const LeafT::NodeMaskType next = faceDilated(recent, across, 0);
                    LeafT::NodeMaskType pending;
                    LeafT::NodeMaskType& changed = leaf.changed[now];
                    float* v = leaf.values;
                    const float* nb[6]; // -x, +x, -y, +y, -z, +z (null: no leaf)
                    for (int f = 0; f < 6; ++f)
                        nb[f] = leaf.neighbour[f] >= 0 ? leaves[leaf.neighbour[f]].values : nullptr;
                    auto at = [](const float* b, Index i) { return b ? b[i] : kMax; };
                    for (int a = 0; a < kDim; ++a) {
                        const int x = sx > 0 ? a : kDim - 1 - a;
                        const uint64_t word = leaf.sweep.template getWord<uint64_t>(Index(x));
                        if (!word) continue; // no voxel of this x to update (the order of the others holds)
                        for (int b = 0; b < kDim; ++b) {
                            const int y = sy > 0 ? b : kDim - 1 - b;
                            if (!((word >> (kDim * y)) & 0xFFu)) continue;
                            for (int c = 0; c < kDim; ++c) {
                                const int z = sz > 0 ? c : kDim - 1 - c;
                                const Index i = offsetOf(x, y, z);
                                if (!leaf.sweep.isOn(i) || !(next.isOn(i) || pending.isOn(i))) continue;
                                const float vx0 =
                                    x > 0 ? v[i - kDim * kDim] : at(nb[0], offsetOf(kDim - 1, y, z));
                                const float vx1 =
                                    x < kDim - 1 ? v[i + kDim * kDim] : at(nb[1], offsetOf(0, y, z));
                                const float vy0 = y > 0 ? v[i - kDim] : at(nb[2], offsetOf(x, kDim - 1, z));
                                const float vy1 = y < kDim - 1 ? v[i + kDim] : at(nb[3], offsetOf(x, 0, z));
                                const float vz0 = z > 0 ? v[i - 1] : at(nb[4], offsetOf(x, y, kDim - 1));
                                const float vz1 = z < kDim - 1 ? v[i + 1] : at(nb[5], offsetOf(x, y, 0));
                                const float old = v[i];
                                updateVoxel(v[i], vx0, vx1, vy0, vy1, vz0, vz1, h, sqrt2h, valid);
                                if (v[i] == old) continue;
                                changed.setOn(i);
                                if (x > 0) pending.setOn(i - kDim * kDim);
                                if (x < kDim - 1) pending.setOn(i + kDim * kDim);
                                if (y > 0) pending.setOn(i - kDim);
                                if (y < kDim - 1) pending.setOn(i + kDim);
                                if (z > 0) pending.setOn(i - 1);
                                if (z < kDim - 1) pending.setOn(i + 1);
                            }
                        }
                    }
                }
            });
    }
}

} // namespace

uint64_t sweepFogTree(FloatTree& tree, const FloatTree& source, float isoValue, float h, float band,
                      bool reachOnly)
{
    openvdb::tree::LeafManager<FloatTree> manager(tree);
    const size_t n = manager.leafCount();
    std::vector<SweepLeaf> leaves(n);
    std::vector<const float*> input(n); // each leaf's fog values: its source leaf's, or the background
    std::array<float, LeafT::SIZE> background;
    background.fill(source.background());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i != r.end(); ++i) {
            leaves[i].values = nullptr; // set once the leaf is known to be needed (below)
            const LeafT* in = source.probeConstLeaf(manager.leaf(i).origin());
            input[i] = in ? in->buffer().data() : background.data();
        }
    });
    // A leaf over a tile of the source reads the tile's value in every voxel (one buffer per value).
    std::map<float, std::array<float, LeafT::SIZE>> tileInputs;
    {
        openvdb::tree::ValueAccessor<const FloatTree> acc(source);
        for (size_t i = 0; i < n; ++i) {
            if (input[i] != background.data()) continue;
            const float t = acc.getValue(manager.leaf(i).origin());
            if (t == source.background()) continue;
            auto at = tileInputs.find(t);
            if (at == tileInputs.end()) {
                at = tileInputs.emplace(t, std::array<float, LeafT::SIZE>()).first;
                at->second.fill(t);
            }
            input[i] = at->second.data();
        }
    }

    // Leaf keys (origin / 8) and the face-neighbour table.
    std::vector<Coord> keys(n);
    for (size_t i = 0; i < n; ++i)
        keys[i] = Coord(manager.leaf(i).origin().x() >> 3, manager.leaf(i).origin().y() >> 3,
                        manager.leaf(i).origin().z() >> 3);
    std::vector<std::array<int64_t, 6>> neighbours = leafFaceNeighbours(keys);

    // Initialisation, leaf by leaf in parallel (each task writes its own leaf's values only, and
    // reads the fog's from the source). A face neighbour in this leaf or a neighbouring one is read
    // from its input; one in a missing leaf through an accessor (the source's tile or background).
    // First the masks alone (which voxels are next to the isosurface, which are swept), then the
    // values, only in the leaves the sweeps need (all of them unless only the band's reach is swept).
    const Coord dirs[6] = {Coord(-1, 0, 0), Coord(1, 0, 0),  Coord(0, -1, 0),
                           Coord(0, 1, 0),  Coord(0, 0, -1), Coord(0, 0, 1)};
    // Calls fn(i, value, nb) for each voxel i of @a mask in leaf li with its six face neighbours' fog values.
    auto forEachOn = [&](size_t li, const LeafT::NodeMaskType& mask,
                         openvdb::tree::ValueAccessor<const FloatTree>& acc, auto&& fn) {
        const std::array<int64_t, 6>& nbLeaf = neighbours[li];
        const float* nbData[6];
        for (int d = 0; d < 6; ++d)
            nbData[d] = nbLeaf[d] >= 0 ? input[size_t(nbLeaf[d])] : nullptr;
        const LeafT& in = manager.leaf(li);
        const float* v = input[li];
        for (auto it = mask.beginOn(); it; ++it) {
            const Index i = it.pos();
            const int x = int(i >> (2 * LeafT::LOG2DIM)), y = int((i >> LeafT::LOG2DIM) & (kDim - 1)),
                      z = int(i & (kDim - 1));
            // The neighbour across face d at offset j of leaf nbData[d], or through the accessor.
            auto across = [&](int d, Index j) {
                return nbData[d] ? nbData[d][j] : acc.getValue(in.offsetToGlobalCoord(i) + dirs[d]);
            };
            float nb[6];
            nb[0] = x > 0 ? v[i - kDim * kDim] : across(0, offsetOf(kDim - 1, y, z));
            nb[1] = x < kDim - 1 ? v[i + kDim * kDim] : across(1, offsetOf(0, y, z));
            nb[2] = y > 0 ? v[i - kDim] : across(2, offsetOf(x, kDim - 1, z));
            nb[3] = y < kDim - 1 ? v[i + kDim] : across(3, offsetOf(x, 0, z));
            nb[4] = z > 0 ? v[i - 1] : across(4, offsetOf(x, y, kDim - 1));
            nb[5] = z < kDim - 1 ? v[i + 1] : across(5, offsetOf(x, y, 0));
            fn(i, v[i], nb);
        }
    };
    // Whether leaf li's fog values and its face neighbours' across its faces all lie on one side of
    // the isovalue (< or not), so that none of its voxels is next to the isosurface (most leaves of a
    // large lump: a test of its values instead of six neighbours' per voxel). A face without a leaf
    // of the sweep reads the fog through the accessor: a tile or the background, one value, unless
    // the fog holds a leaf there (then no).
    auto oneSide = [&](size_t li, openvdb::tree::ValueAccessor<const FloatTree>& acc) {
        const float* v = input[li];
        const bool less = v[0] < isoValue;
        for (Index i = 1; i < LeafT::SIZE; ++i)
            if ((v[i] < isoValue) != less) return false;
        for (int d = 0; d < 6; ++d) {
            const int64_t nbLeaf = neighbours[li][size_t(d)];
            if (nbLeaf < 0) {
                const Coord& at = manager.leaf(li).origin();
                const Coord o(at.x() + kDim * dirs[d].x(), at.y() + kDim * dirs[d].y(),
                              at.z() + kDim * dirs[d].z());
                if (acc.probeConstLeaf(o) || (acc.getValue(o) < isoValue) != less) return false;
                continue;
            }
            const float* w = input[size_t(nbLeaf)];
            const int side = (d & 1) ? 0 : kDim - 1; // the neighbour's layer facing this leaf
            for (int a = 0; a < kDim; ++a)
                for (int b = 0; b < kDim; ++b) {
                    const Index j = d < 2   ? offsetOf(side, a, b)
                                    : d < 4 ? offsetOf(a, side, b)
                                            : offsetOf(a, b, side);
                    if ((w[j] < isoValue) != less) return false;
                }
        }
        return true;
    };
    std::atomic<uint64_t> boundaryCount{0}, sweepCount{0};
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n), [&](const tbb::blocked_range<size_t>& r) {
        openvdb::tree::ValueAccessor<const FloatTree> acc(source);
        uint64_t boundary = 0, sweeping = 0;
        for (size_t li = r.begin(); li != r.end(); ++li) {
            SweepLeaf& out = leaves[li];
            for (int f = 0; f < 6; ++f)
                out.neighbour[size_t(f)] = int32_t(neighbours[li][size_t(f)]);
            out.sweep.setOff();
            out.boundary().setOff();
            if (oneSide(li, acc)) { // no voxel next to the isosurface: every active voxel is swept
                out.sweep = manager.leaf(li).getValueMask();
                sweeping += out.sweep.countOn();
                continue;
            }
            forEachOn(li, manager.leaf(li).getValueMask(), acc, [&](Index i, float value, const float nb[6]) {
                // initValue's test: a face neighbour on the other side of the isovalue.
                const bool less = value < isoValue;
                bool any = false;
                for (int d = 0; d < 6; ++d)
                    any = any || (less ^ (nb[d] < isoValue));
                if (any) {
                    out.boundary().setOn(i);
                    ++boundary;
                } else {
                    out.sweep.setOn(i);
                    ++sweeping;
                }
            });
        }
        boundaryCount += boundary;
        sweepCount += sweeping;
    });
    const bool sweeps = boundaryCount.load() > 0 && sweepCount.load() > 0;
    // The leaves whose values matter: with only the band's reach swept, a leaf with no voxel next to
    // the isosurface and none within reach keeps +-FLT_MAX everywhere (read by its neighbours as a
    // missing leaf is), and ends as inactive +-band by its side: it becomes a tile of that value and
    // its values are never allocated (unless its voxels lie on both sides: then it is kept).
    std::vector<char> needed(n, 1);
    std::vector<char> insideTile(n, 0); // the side of a leaf that becomes a tile: 1 inside (-band)
    if (sweeps && band > 0 && reachOnly) {
        const int steps = int(std::ceil(double(band) * std::sqrt(3.0) / double(h)));
        std::vector<LeafT::NodeMaskType> reach(n), next(n);
        for (size_t li = 0; li < n; ++li)
            reach[li] = leaves[li].boundary();
        for (int step = 0; step < steps; ++step) {
            tbb::parallel_for(tbb::blocked_range<size_t>(0, n), [&](const tbb::blocked_range<size_t>& r) {
                for (size_t li = r.begin(); li != r.end(); ++li)
                    next[li] = faceDilated(reach, leaves[li].neighbour, li);
            });
            reach.swap(next);
        }
        tbb::parallel_for(tbb::blocked_range<size_t>(0, n), [&](const tbb::blocked_range<size_t>& r) {
            for (size_t li = r.begin(); li != r.end(); ++li) {
                SweepLeaf& leaf = leaves[li];
                leaf.sweep &= reach[li];
                if (!leaf.sweep.isOff() || !leaf.boundary().isOff()) continue;
                const float* v = input[li];
                const bool in0 = v[0] > isoValue;
                bool oneSide = true;
                for (Index i = 1; i < LeafT::SIZE && oneSide; ++i)
                    oneSide = (v[i] > isoValue) == in0;
                if (!oneSide) continue;
                needed[li] = 0;
                insideTile[li] = in0 ? 1 : 0;
            }
        });
    }
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n), [&](const tbb::blocked_range<size_t>& r) {
        openvdb::tree::ValueAccessor<const FloatTree> acc(source);
        for (size_t li = r.begin(); li != r.end(); ++li) {
            if (!needed[li]) continue;
            LeafT& leaf = manager.leaf(li);
            if (!leaf.buffer().isOutOfCore() && leaf.buffer().empty()) leaf.buffer().allocate();
            float* values = leaf.buffer().data();
            leaves[li].values = values;
            const float* v = input[li];
            // By its side: what initValue gives every voxel but those next to the isosurface.
            for (Index i = 0; i < LeafT::SIZE; ++i)
                values[i] = v[i] > isoValue ? -kMax : kMax;
            forEachOn(li, leaves[li].boundary(), acc, [&](Index i, float value, const float nb[6]) {
                bool isBoundary = false;
                values[i] = initValue(value, nb, isoValue, -h, isBoundary);
            });
        }
    });
    // The fog's values and the neighbour table are read no more (each leaf keeps its own neighbours):
    // freed before the sweeps, while the values are at their largest.
    std::vector<std::array<int64_t, 6>>().swap(neighbours);
    std::vector<const float*>().swap(input);

    // fogToSdf sweeps only when it found voxels to sweep and voxels to sweep from.
    float tileValue = kMax;
    uint64_t swept = 0;
    if (sweeps) {
        for (const SweepLeaf& leaf : leaves)
            swept += leaf.sweep.countOn();
        // The leaves of each sweep direction's diagonals, in key order (ties: leaf index).
        const float sqrt2h = openvdb::math::Sqrt(2.f) * h;
        // With only the band's reach swept, a voxel none of whose neighbours lies within the band is
        // not updated: its value would be the band or more, which reads as the band (see the top).
        const float valid = band > 0 && reachOnly ? std::min(band, kValid) : kValid;
        const int signs[4][3] = {{1, 1, 1}, {1, 1, -1}, {1, -1, 1}, {1, -1, -1}};
        // Before the first sweep the only finite values are those next to the isosurface (changed[1]): as
        // if a sweep before it had changed them (an update whose neighbours are all +-FLT_MAX changes
        // nothing).
        int index = 0;
        for (const auto& s : signs) {
            std::vector<std::pair<int64_t, size_t>> order(n);
            for (size_t i = 0; i < n; ++i) {
                const Coord& k = keys[i];
                order[i] = {int64_t(s[0]) * k.x() + int64_t(s[1]) * k.y() + int64_t(s[2]) * k.z(), i};
            }
            std::sort(order.begin(), order.end());
            std::vector<size_t> sliceStart;
            for (size_t i = 0; i < n; ++i) {
                if (i == 0 || order[i].first != order[i - 1].first) sliceStart.push_back(i);
            }
            sliceStart.push_back(n);
            sweepOnce(leaves, order, sliceStart, index++, s[0], s[1], s[2], h, sqrt2h, valid, false);
            sweepOnce(leaves, order, sliceStart, index++, -s[0], -s[1], -s[2], h, sqrt2h, valid, true);
        }
        // Finalisation: active voxels still at +-FLT_MAX take the extreme finite active values.
        struct MinMax {
            float lo = kMax, hi = -kMax;
        };
        const MinMax e = tbb::parallel_reduce(
            tbb::blocked_range<size_t>(0, n), MinMax(),
            [&](const tbb::blocked_range<size_t>& r, MinMax m) {
                for (size_t li = r.begin(); li != r.end(); ++li) {
                    if (!leaves[li].values) continue;
                    const LeafT& leaf = manager.leaf(li);
                    for (auto it = leaf.getValueMask().beginOn(); it; ++it) {
                        const float v = leaves[li].values[it.pos()];
                        if (v != -kMax && v < m.lo) m.lo = v;
                        if (v != kMax && v > m.hi) m.hi = v;
                    }
                }
                return m;
            },
            [](MinMax a, const MinMax& b) {
                a.lo = std::min(a.lo, b.lo);
                a.hi = std::max(a.hi, b.hi);
                return a;
            });
        // The unswept voxels must end beyond the band on their side, as in the full sweep: not
        // so when no swept value reached the band (clay thinner than it): sweep everything.
        if (band > 0 && reachOnly && !(e.lo <= -band && e.hi >= band))
            return sweepFogTree(tree, source, isoValue, h, band, /*reachOnly=*/false);
        tbb::parallel_for(tbb::blocked_range<size_t>(0, n), [&](const tbb::blocked_range<size_t>& r) {
            for (size_t li = r.begin(); li != r.end(); ++li) {
                if (!leaves[li].values) continue;
                for (float* v = leaves[li].values; v != leaves[li].values + LeafT::SIZE; ++v) {
                    if (*v == -kMax) *v = e.lo;
                    if (*v == kMax) *v = e.hi;
                }
            }
        });
        tileValue = e.hi;
    }
    if (band > 0) {
        // The band, as clipToNarrowBand leaves it: active values at or beyond +-band become inactive
        // +-band, inactive ones +-band by their sign (changeLevelSetBackground), the tiles likewise.
        tbb::parallel_for(tbb::blocked_range<size_t>(0, n), [&](const tbb::blocked_range<size_t>& r) {
            for (size_t li = r.begin(); li != r.end(); ++li) {
                float* v = leaves[li].values;
                if (!v) continue;
                LeafT::NodeMaskType& active = manager.leaf(li).getValueMask();
                for (Index i = 0; i < LeafT::SIZE; ++i) {
                    if (!active.isOn(i)) {
                        v[i] = v[i] < 0 ? -band : band;
                    } else if (v[i] >= band) {
                        v[i] = band;
                        active.setOff(i);
                    } else if (v[i] <= -band) {
                        v[i] = -band;
                        active.setOff(i);
                    }
                }
            }
        });
        tileValue = tileValue < 0 ? -band : band;
    }
    // Tiles (only the fog's zero background here) are outside: +FLT_MAX after InitSdf, then the largest
    // finite value if the sweeps ran (the root's background too; the band's outside when clipped).
    auto it = tree.beginValueAll();
    it.setMaxDepth(it.getLeafDepth() - 1);
    for (; it; ++it)
        it.setValue(tileValue);
    tree.root().setBackground(band > 0 ? band : tileValue, /*updateChildNodes=*/false);
    // The leaves left without values: inactive tiles of +-band by their side (replacing the leaves).
    // Listed first: a tile replaces its leaf, which the leaf manager still points at.
    std::vector<std::pair<Coord, float>> tiles;
    for (size_t li = 0; li < n; ++li)
        if (!needed[li]) tiles.emplace_back(manager.leaf(li).origin(), insideTile[li] ? -band : band);
    for (const auto& t : tiles)
        tree.addTile(1, t.first, t.second, false);
    return swept;
}

std::shared_ptr<FloatTree> sweepTreeOf(const GrownLeaves& g, float background)
{
    const size_t n = g.origins.size();
    std::vector<LeafT*> made(n);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i != r.end(); ++i) {
            made[i] = new LeafT(openvdb::PartialCreate(), g.origins[i], 0.f, false);
            made[i]->setValueMask(g.masks[i]);
        }
    });
    auto tree = std::make_shared<FloatTree>(background);
    for (LeafT* leaf : made)
        tree->addLeaf(leaf);
    return tree;
}

bool holdsTiles(const FloatTree& tree)
{
    auto it = tree.cbeginValueAll();
    it.setMaxDepth(it.getLeafDepth() - 1);
    for (; it; ++it) {
        if (*it != 0.f || it.isValueOn()) return true;
    }
    return false;
}

openvdb::FloatGrid::Ptr fogToSdfByLeaves(const openvdb::FloatGrid& fog, float isoValue)
{
    if (holdsTiles(fog.tree())) return openvdb::tools::fogToSdf(fog, isoValue);
    openvdb::FloatGrid::Ptr sdf = fog.deepCopy();
    sweepFogTree(sdf->tree(), fog.tree(), isoValue, float(fog.voxelSize()[0]), 0.f);
    return sdf;
}

openvdb::FloatGrid::Ptr narrowBandSdfFromDensity(const openvdb::FloatGrid& density, int radius,
                                                 float isoValue, float band, uint64_t* swept)
{
    if (band > 0 && radius > 0 && radius < kDim && holdsTiles(density.tree()))
        return narrowBandSdfFromTiledDensity(density, radius, isoValue, band, swept);
    if (!boxGrowable(density, radius)) {
        openvdb::FloatGrid::Ptr fog = surfaceFog(density, radius);
        if (holdsTiles(fog->tree())) {
            openvdb::FloatGrid::Ptr sdf = openvdb::tools::fogToSdf(*fog, isoValue);
            if (band > 0) clipToNarrowBand(*sdf, band);
            return sdf;
        }
        openvdb::FloatGrid::Ptr sdf = fog->deepCopy();
        const uint64_t count =
            sweepFogTree(sdf->tree(), fog->tree(), isoValue, float(fog->voxelSize()[0]), band);
        if (swept) *swept = count;
        if (band > 0) openvdb::tools::pruneLevelSet(sdf->tree());
        return sdf;
    }
    // The fog's leaves and active voxels, with room for the distances: no value is copied, the
    // initialisation reads the fog's values from the density (the grown voxels hold its background).
    const GrownLeaves g = growByBox(density, radius);
    std::shared_ptr<FloatTree> tree = sweepTreeOf(g, density.tree().background());
    openvdb::FloatGrid::Ptr sdf = density.copyWithNewTree();
    sdf->setTree(tree);
    const uint64_t count = sweepFogTree(*tree, density.tree(), isoValue, float(density.voxelSize()[0]), band);
    if (swept) *swept = count;
    if (band > 0) openvdb::tools::pruneLevelSet(*tree);
    return sdf;
}

} // namespace io_internal
} // namespace vdbclay
