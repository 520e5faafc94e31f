// The automaton's per-block kernel (see Kernel.h for the contract and its thread-safety).
//
// Per anchor: its leaves are found once (even steps: the anchor's leaf alone, whose 64 blocks it
// holds whole; odd steps: also the lower neighbours that the straddling blocks reach): the flat leaf
// table's entry when the Automaton has one (read in place through a pointer, LeafSet), otherwise
// through value accessors (only the leaves the mask's blocks touch). In 3D the over-cell filter then
// drops the candidates holding no cell over Tc, a column of 4 blocks at a time (AVX2 or SSE2, chosen
// at run time; see "The over-cell filter" below). Both are done one item ahead (a software
// pipeline: the filter's loads, the first touch of the item's cells, are issued before the previous
// item's block loop, not behind its branches). Then for each candidate block left:
// load its cells (even: at constant offsets from the block's first cell; odd: through the addressing tables),
// skip it unless a cell is over Tc, apply the rule (inlined, instantiated for this rule and cell
// count), and write back only the cells that changed. The overload changes only where a cell
// changed, so its delta is summed over those cells alone. Checks that can fire only rarely (a result
// over INT32_MAX, a write into a missing leaf) run only when the pass or the anchor allows them.
//
// The surplus branch in registers (SSE2, every x86-64). A settling press spends most of its updates
// in prorata's and sorted's E > A branch (every room filled, the surplus shared equally). There the
// block stays in two SSE2 registers from load to store (surplusBranch): the compare with Tc that
// found the over cells is the over lanes (no lane table unless an obstacle blocks a cell), E and
// S = E - A come out of one reduction, the result is Tc + share on the under lanes (+1 on the
// remainder's), all 8 cells written by four 8-byte stores for blocks inside one leaf; the overload
// delta is -A and the largest value Tc + share (+1), both without a per-cell loop. The cells go to
// memory only when the scalar rule runs; no scalar store is reloaded as a vector (the
// store-forwarding stall that made an earlier int32 variant slower). Every other case (E <= A, the
// other rules, a pass that may overflow, Tc > 2^27) runs the scalar rule as before; the result is
// bit-identical either way (tests/TestKernel.cc runs both paths, PassInput::portable, on the same
// grids; tests/TestGolden.cc pins whole runs).
//
// Two builds of the pass (processRangeBody, always inlined): the baseline one (processRangeT), and one
// compiled for AVX2 + BMI1/2 + POPCNT (processRangeAvx2, a target attribute on the wrapper alone),
// chosen at run time where the CPU has them (PassInput::avx2 turns it off; avx2Pass() says which runs).
// The source is the same: the AVX2 build gains three-operand VEX forms (no register copies), BMI2
// shifts and POPCNT, about 9 % of the pass's instructions. Only code inlined into the wrapper is
// compiled for AVX2; out-of-line OpenVDB and library functions stay baseline code.

#include "automaton/Kernel.h"

#include "automaton/BlockMasks.h"
#include "automaton/RulesImpl.h"

#include <openvdb/openvdb.h>
#include <openvdb/tree/ValueAccessor.h>

#include <tbb/task_arena.h>

#if defined(__x86_64__) || defined(__SSE2__)
#include <immintrin.h>
#endif

#include <algorithm>
#include <climits>
#include <optional>
#include <type_traits>

namespace vdbclay {
namespace automaton_internal {

static_assert(std::is_same<MassTree, openvdb::Int32Tree>::value, "MassTree must be openvdb::Int32Tree");
static_assert(std::is_same<ObsTree, openvdb::MaskTree>::value, "ObsTree must be openvdb::MaskTree");

namespace {

using openvdb::Coord;
using MassLeaf = MassTree::LeafNodeType;
using ObsLeaf = ObsTree::LeafNodeType;
static_assert(MassLeaf::DIM == 8, "vdbclay's block masks assume 8^3 leaves");
using MassAcc = openvdb::tree::ValueAccessor<MassTree, false>;
using ObsAcc = openvdb::tree::ValueAccessor<const ObsTree, false>;

/// What a missing leaf reads as: background 0.
alignas(64) const int32_t kZeroLeaf[MassLeaf::SIZE] = {};

} // namespace

/// The leaves an anchor's blocks touch (slot w: leafOrigin(anchor, w)), as the pass reads them: a
/// leaf table's entry, or what fetchLeaves found through accessors. The pass reads it through a
/// pointer, never a copy, so an item touches only the lines of the slots its blocks use: read[]
/// (the filter and the loads) first, then data[] (the stores), leaf[] (a voxel turned active) and
/// obs[] (only where obstacles are).
struct LeafSet {
    const int32_t* read[8]; // data, or kZeroLeaf for a missing leaf: reads need no null test
    int32_t* data[8];       // null for a missing leaf
    MassLeaf* leaf[8];
    const ObsLeaf* obs[8];
    uint8_t missing; // slots whose mass leaf is missing
    uint8_t obsAny;  // slots holding obstacles: an obstacle leaf, or an active obstacle tile
    uint8_t obsTile; // slots inside an active obstacle tile (no obstacle leaf)
};

// ---- The leaf table ------------------------------------------------------------------------------

struct LeafTable::Impl {
    /// One anchor's leaves, as the pass reads them.
    using Entry = LeafSet;
    struct Slot {
        int32_t x, y, z;
        uint32_t index; // into entries; kEmpty: a free slot
    };
    static constexpr uint32_t kEmpty = UINT32_MAX;
    std::vector<Entry> entries;
    std::vector<Origin> keys;       // entries[i]'s anchor, in column order (indexLess)
    std::vector<uint32_t> up, down; // AnchorIndex's neighbours, 8 per entry
    std::vector<Slot> slots;        // open addressing, linear probing, at most half full
    int shift = 64;

    size_t slotOf(int32_t x, int32_t y, int32_t z) const
    {
        uint64_t k = uint64_t(uint32_t(x) >> 3) * 0x9E3779B97F4A7C15ull;
        k += uint64_t(uint32_t(y) >> 3) * 0xC2B2AE3D27D4EB4Full +
             uint64_t(uint32_t(z) >> 3) * 0x165667B19E3779F9ull;
        k ^= k >> 29;
        k *= 0xBF58476D1CE4E5B9ull;
        return size_t(k >> shift);
    }
    const Entry* find(const Origin& o) const
    {
        const size_t mask = slots.size() - 1;
        for (size_t i = slotOf(o.x(), o.y(), o.z());; i = (i + 1) & mask) {
            const Slot& s = slots[i];
            if (s.index == kEmpty) return nullptr;
            if (s.x == o.x() && s.y == o.y() && s.z == o.z()) return &entries[s.index];
        }
    }
    void resize(size_t count) // count: a power of two, at least twice the keys
    {
        shift = 64;
        for (size_t c = count; c > 1; c >>= 1)
            --shift;
        slots.assign(count, Slot{0, 0, 0, kEmpty});
        const size_t mask = count - 1;
        for (uint32_t k = 0; k < keys.size(); ++k) {
            const Origin& o = keys[k];
            size_t i = slotOf(o.x(), o.y(), o.z());
            while (slots[i].index != kEmpty)
                i = (i + 1) & mask;
            slots[i] = Slot{o.x(), o.y(), o.z(), k};
        }
    }
    void insert(const Origin& o)
    {
        if (2 * (keys.size() + 1) > slots.size()) resize(std::max<size_t>(64, 2 * slots.size()));
        const size_t mask = slots.size() - 1;
        size_t i = slotOf(o.x(), o.y(), o.z());
        for (;; i = (i + 1) & mask) {
            const Slot& s = slots[i];
            if (s.index == kEmpty) break;
            if (s.x == o.x() && s.y == o.y() && s.z == o.z()) return;
        }
        slots[i] = Slot{o.x(), o.y(), o.z(), uint32_t(keys.size())};
        keys.push_back(o);
    }
};

LeafTable::LeafTable() = default;
LeafTable::~LeafTable() = default;

size_t LeafTable::size() const
{
    return mValid ? mImpl->keys.size() : 0;
}

AnchorIndex LeafTable::anchorIndex() const
{
    AnchorIndex ix;
    if (!mValid) return ix;
    ix.keys = mImpl->keys.data();
    ix.up = mImpl->up.data();
    ix.down = mImpl->down.data();
    ix.size = mImpl->keys.size();
    return ix;
}

void LeafTable::clear()
{
    mValid = false;
}

void LeafTable::build(MassTree& tree, const ObsTree* obstacles, bool is3D)
{
    if (!mImpl) mImpl = std::make_unique<Impl>();
    Impl& t = *mImpl;
    t.keys.clear();
    t.slots.clear();
    t.shift = 64;
    // The anchors whose blocks can read a leaf: its origin and, on odd steps, the origins of the
    // upper neighbours whose straddling blocks reach down into it.
    const int nd = is3D ? 8 : 4;
    for (auto it = tree.cbeginLeaf(); it; ++it) {
        const Coord o = it->origin();
        for (int d = 0; d < nd; ++d)
            t.insert(Origin(o.x() + ((d & 1) ? 8 : 0), o.y() + ((d & 2) ? 8 : 0), o.z() + ((d & 4) ? 8 : 0)));
    }
    // Entries in column order (Candidates' dense mode relies on it), then the hash re-filled.
    std::sort(t.keys.begin(), t.keys.end(), [](const Origin& a, const Origin& b) { return indexLess(a, b); });
    t.resize(std::max<size_t>(64, t.slots.size())); // find() needs a free slot
    t.entries.resize(t.keys.size());
    t.up.assign(8 * t.keys.size(), kNoEntry);
    t.down.assign(8 * t.keys.size(), kNoEntry);
    for (size_t k = 0; k < t.keys.size(); ++k) {
        const Origin& a = t.keys[k];
        for (int s = 0; s < nd; ++s) {
            const int dx = (s & 1) ? 8 : 0, dy = (s & 2) ? 8 : 0, dz = (s & 4) ? 8 : 0;
            const Impl::Entry* u = t.find(Origin(a.x() + dx, a.y() + dy, a.z() + dz));
            const Impl::Entry* d = t.find(Origin(a.x() - dx, a.y() - dy, a.z() - dz));
            if (u) t.up[8 * k + s] = uint32_t(u - t.entries.data());
            if (d) t.down[8 * k + s] = uint32_t(d - t.entries.data());
        }
    }
    openvdb::tree::ValueAccessor<MassTree, false> acc(tree);
    std::optional<openvdb::tree::ValueAccessor<const ObsTree, false>> oacc;
    if (obstacles) oacc.emplace(*obstacles);
    for (size_t k = 0; k < t.keys.size(); ++k) {
        Impl::Entry& e = t.entries[k];
        e.missing = e.obsAny = e.obsTile = 0;
        for (int w = 0; w < 8; ++w) {
            const Origin lo = leafOrigin(t.keys[k], w);
            const Coord c(lo.x(), lo.y(), lo.z());
            e.leaf[w] = acc.probeLeaf(c);
            e.data[w] = e.leaf[w] ? e.leaf[w]->buffer().data() : nullptr;
            e.read[w] = e.leaf[w] ? e.data[w] : kZeroLeaf;
            if (!e.leaf[w]) e.missing |= uint8_t(1u << w);
            e.obs[w] = oacc ? oacc->probeConstLeaf(c) : nullptr;
            const bool tile = oacc && !e.obs[w] && oacc->isValueOn(c);
            if (tile) e.obsTile |= uint8_t(1u << w);
            if (e.obs[w] || tile) e.obsAny |= uint8_t(1u << w);
        }
    }
    mValid = true;
}

namespace {

/// Offsets of a block's corners c = dx + 2 dy + 4 dz from its first cell, in one leaf.
constexpr int kCornerOffset[8] = {0, 64, 8, 72, 1, 65, 9, 73};

/// Odd blocks that lie inside the anchor leaf (no local coordinate at -1): read like even blocks.
constexpr uint64_t kInsideOdd3 = ~(kX0 | kY0 | kZ0), kInsideOdd2 = ~(kX0 | kY0) & 0xFFFFull;

#if defined(__SSE2__)
/// Loads the N cells of a block into @a lo (corners 0-3) and @a hi (corners 4-7; 3D only), given
/// where corner k (k = 0-3) lies: corner k + 4 (one voxel up in z) is the next int32. True of every
/// block that does not straddle a z boundary between leaves: four 8-byte loads, two shuffles. In 2D
/// (z = 0) the z = 1 neighbours are read (inside the leaf) and ignored.
template <int N>
__attribute__((always_inline)) inline void loadPairs(const int32_t* c0, const int32_t* c1, const int32_t* c2,
                                                     const int32_t* c3, __m128i& lo, __m128i& hi)
{
    const __m128i p0 = _mm_loadl_epi64(reinterpret_cast<const __m128i*>(c0));
    const __m128i p1 = _mm_loadl_epi64(reinterpret_cast<const __m128i*>(c1));
    const __m128i p2 = _mm_loadl_epi64(reinterpret_cast<const __m128i*>(c2));
    const __m128i p3 = _mm_loadl_epi64(reinterpret_cast<const __m128i*>(c3));
    const __m128i a01 = _mm_unpacklo_epi32(p0, p1);                   // c0 c1 c4 c5
    const __m128i a23 = _mm_unpacklo_epi32(p2, p3);                   // c2 c3 c6 c7
    lo = _mm_unpacklo_epi64(a01, a23);                                // corners 0-3
    hi = N == 8 ? _mm_unpackhi_epi64(a01, a23) : _mm_setzero_si128(); // corners 4-7
}

/// Bit c of the result: lane c of @a a (c = 0-3) or @a b (c = 4-7; 3D only) is all ones, for
/// lanes that are compare results (0 or -1): two packs and one byte movemask.
template <int N> __attribute__((always_inline)) inline uint32_t laneBits(__m128i a, __m128i b)
{
    if constexpr (N == 8)
        return uint32_t(_mm_movemask_epi8(_mm_packs_epi16(_mm_packs_epi32(a, b), _mm_setzero_si128())));
    (void)b;
    return uint32_t(_mm_movemask_ps(_mm_castsi128_ps(a)));
}

/// Stores the block's N corners (lo: 0-3, hi: 4-7) into @a m (16-byte aligned).
template <int N> __attribute__((always_inline)) inline void storeCorners(__m128i lo, __m128i hi, int32_t* m)
{
    _mm_store_si128(reinterpret_cast<__m128i*>(m), lo);
    if constexpr (N == 8) _mm_store_si128(reinterpret_cast<__m128i*>(m + 4), hi);
}

/// kLaneMasks.v[m]: lane c is -1 where bit c of the 4-bit mask m is set, else 0.
struct LaneMaskTable {
    alignas(16) int32_t v[16][4];
    constexpr LaneMaskTable() : v{}
    {
        for (int m = 0; m < 16; ++m)
            for (int c = 0; c < 4; ++c)
                v[m][c] = ((m >> c) & 1) ? -1 : 0;
    }
};
alignas(64) constexpr LaneMaskTable kLaneMasks;

/// Lanes of -1 where bit c of @a mask4 is set (c = 0-3; the high register takes mask >> 4): one load
/// from kLaneMasks.
__attribute__((always_inline)) inline __m128i lanesOf(uint32_t mask4)
{
    return _mm_load_si128(reinterpret_cast<const __m128i*>(kLaneMasks.v[mask4 & 15u]));
}

__attribute__((always_inline)) inline int32_t hsum(__m128i x)
{
    x = _mm_add_epi32(x, _mm_shuffle_epi32(x, 0x4E));
    x = _mm_add_epi32(x, _mm_shuffle_epi32(x, 0xB1));
    return _mm_cvtsi128_si32(x);
}

/// kFirstBits.t[x][r]: the first (lowest) r set bits of the 8-bit mask x, r = 0-7.
struct FirstBitsTable {
    uint8_t t[256][8];
    constexpr FirstBitsTable() : t{}
    {
        for (int x = 0; x < 256; ++x) {
            int rest = x;
            for (int r = 0; r < 8; ++r) {
                t[x][r] = uint8_t(x & ~rest);
                rest &= rest - 1;
            }
        }
    }
};
constexpr FirstBitsTable kFirstBits;

/// Notes for sinkActive that block @a b was updated: its cells @a active (those that were or went
/// over Tc, or a superset) into @a act[corner], and the block into @a again when it may still hold
/// an over and a not-over cell (@a mayChange).
__attribute__((always_inline)) inline void noteUpdated(int b, uint32_t active, bool mayChange,
                                                       uint64_t act[8], uint64_t& again)
{
    for (uint32_t x = active; x; x &= x - 1)
        act[__builtin_ctz(x)] |= uint64_t(1) << b;
    again |= uint64_t(mayChange) << b;
}

/// What a branch in registers did: Done when it applied its branch, Unchanged when the block has no
/// over or no under cell (the rule would change nothing), Rule when the block is in another branch
/// (the caller runs the rule). The surplus branch (E > A: every room filled, the surplus E - A shared
/// equally among the under cells, the remainder to the first under cells of the hash's rotation) is
/// exactly repartitionT's result in int32 lanes (see processRangeT for why int32 cannot wrap there).
enum class Branch { Unchanged, Done, Rule };
struct Surplus {
    __m128i lo, hi;    // the block's new cells
    uint32_t grow;     // cells that may go from 0 to positive: those that changed, or a superset of them
                       // holding no other zero cell (surplusBranch: the under cells)
    int64_t overDelta; // change of the overload: -A (E before, E - A after)
    int64_t maxOut;    // the largest value written
    int64_t e, a;      // the block's excess and room (set when the result is Rule)
    uint32_t active;   // cells that were or went over Tc, or a superset of them (sinkActive)
    bool again;        // the block may still hold an over and a not-over cell: false only if not
};

/// Rotations of an N-bit cell mask (N = 4 or 8): bit k of rotr(x, s) is cell (s + k) mod N; rotl
/// undoes it. The mask doubled (x | x << N) makes each a shift and a mask.
template <int N> __attribute__((always_inline)) inline uint32_t rotr(uint32_t x, int s)
{
    return ((x | (x << N)) >> s) & ((1u << N) - 1);
}
template <int N> __attribute__((always_inline)) inline uint32_t rotl(uint32_t x, int s)
{
    return (((x | (x << N)) << s) >> N) & ((1u << N) - 1);
}

/// The cells whose value differs between (lo, hi) and (nlo, nhi).
template <int N>
__attribute__((always_inline)) inline uint32_t changedCells(__m128i lo, __m128i hi, __m128i nlo, __m128i nhi)
{
    return ~laneBits<N>(_mm_cmpeq_epi32(lo, nlo), _mm_cmpeq_epi32(hi, nhi)) & ((1u << N) - 1);
}

/// The surplus branch of prorata and sorted on the block in registers: (lo, hi) its cells, (gtLo,
/// gtHi) the compare of each with Tc (lanes of -1 where over; obstacles not excluded), overCells the
/// same as bits, valid the cells not blocked by an obstacle. E and the sum S = E - A of (m - Tc) over
/// the valid cells come out of one reduction; E > A iff S > 0, and the surplus is S. Without
/// obstacles the over lanes are the compare itself, and the result Tc + (share on the under lanes) +
/// (one unit on the remainder's cells) needs no lane table but the remainder's.
template <int N, typename Hash>
__attribute__((always_inline)) inline Branch surplusBranch(__m128i lo, __m128i hi, __m128i gtLo, __m128i gtHi,
                                                           uint32_t overCells, uint32_t valid, int32_t tc,
                                                           const Hash& hash, Surplus& s)
{
    constexpr uint32_t kAll = (1u << N) - 1;
    const uint32_t over = overCells & valid, under = valid & ~overCells & kAll;
    if (!over || !under) return Branch::Unchanged;
    const bool blocked = valid != kAll;
    const __m128i t = _mm_set1_epi32(tc);
    __m128i vLo = _mm_setzero_si128(), vHi = vLo; // valid lanes (set only when blocked)
    if (blocked) {
        vLo = lanesOf(valid & 15u);
        gtLo = _mm_and_si128(gtLo, vLo);
        if constexpr (N == 8) {
            vHi = lanesOf(valid >> 4);
            gtHi = _mm_and_si128(gtHi, vHi);
        }
    }
    // e = sum of (m - Tc) over the over cells, sum = the same over every valid cell (E - A).
    const __m128i xLo = _mm_sub_epi32(lo, t);
    __m128i eV = _mm_and_si128(xLo, gtLo), sV = blocked ? _mm_and_si128(xLo, vLo) : xLo;
    if constexpr (N == 8) {
        const __m128i xHi = _mm_sub_epi32(hi, t);
        eV = _mm_add_epi32(eV, _mm_and_si128(xHi, gtHi));
        sV = _mm_add_epi32(sV, blocked ? _mm_and_si128(xHi, vHi) : xHi);
    }
    // Both reductions at once: lanes (e0+e2, e1+e3, s0+s2, s1+s3), then pairs: E in lane 0, S in lane 2.
    const __m128i p = _mm_add_epi32(_mm_unpacklo_epi64(eV, sV), _mm_unpackhi_epi64(eV, sV));
    const __m128i q = _mm_add_epi32(p, _mm_shuffle_epi32(p, 0xB1));
    const int64_t e = _mm_cvtsi128_si32(q), sum = _mm_cvtsi128_si32(_mm_unpackhi_epi64(q, q));
    s.e = e;
    s.a = e - sum;
    if (sum <= 0) return Branch::Rule;
    const int nu = rules_internal::popcount8(under);
    const int64_t share = rules_internal::divideBySmall(sum, nu);
    const int64_t r = sum - share * nu;
    // Over lanes to Tc, the others to Tc + share (obstacle lanes put back below).
    const __m128i shareV = _mm_set1_epi32(int32_t(share));
    __m128i oLo = _mm_add_epi32(t, _mm_andnot_si128(gtLo, shareV));
    __m128i oHi = N == 8 ? _mm_add_epi32(t, _mm_andnot_si128(gtHi, shareV)) : _mm_setzero_si128();
    uint32_t extra = 0;
    if (r) {
        // One unit to each of the first r under cells of the rotation starting at the hash.
        const int start = int(hash() & uint64_t(N - 1));
        extra = rotl<N>(kFirstBits.t[rotr<N>(under, start)][r], start); // r < nu <= N <= 8
        oLo = _mm_sub_epi32(oLo, lanesOf(extra & 15u));                 // lanes of -1: one more unit
        if constexpr (N == 8) oHi = _mm_sub_epi32(oHi, lanesOf(extra >> 4));
    }
    if (blocked) {
        oLo = _mm_or_si128(_mm_and_si128(vLo, oLo), _mm_andnot_si128(vLo, lo));
        if constexpr (N == 8) oHi = _mm_or_si128(_mm_and_si128(vHi, oHi), _mm_andnot_si128(vHi, hi));
    }
    s.lo = oLo;
    s.hi = oHi;
    // Every under cell ends at Tc or more (> 0): the zero cells that change are the zero under cells.
    s.grow = under;
    // Over cells end at Tc, under cells at Tc + share (+ 1 for the remainder's): over Tc where that
    // is positive, and since the surplus is, some are.
    s.active = over | (share ? under : extra);
    s.again = true;
    s.overDelta = -(e - sum);
    s.maxOut = tc + share + (r ? 1 : 0);
    return Branch::Done;
}

/// Prorata's room branch (0 < E <= A: every over cell to Tc, each under cell i gets
/// floor(E room_i / A), the remainder one unit per cell in the hash's rotation, first to cells still
/// below Tc, then to the others) on the block in registers, as repartitionT computes it: the shares
/// by double-precision reciprocal and a one-step correction to the exact floor, under the same
/// condition (E Tc < 2^32; otherwise returns false and the caller runs the rule). Takes E and A
/// from surplusBranch (@a s).
template <int N, typename Hash>
__attribute__((always_inline)) inline bool roomBranch(__m128i lo, __m128i hi, uint32_t overCells,
                                                      uint32_t valid, int32_t tc, const Hash& hash,
                                                      Surplus& s)
{
    const int64_t e = s.e, a = s.a;
    if (uint64_t(e) * uint64_t(tc) > UINT32_MAX) return false;
    constexpr uint32_t kAll = (1u << N) - 1;
    const uint32_t over = overCells & valid, under = valid & ~overCells & kAll;
    const __m128i t = _mm_set1_epi32(tc);
    const __m128d eD = _mm_set1_pd(double(e)), aD = _mm_set1_pd(double(a)),
                  inv = _mm_set1_pd(1.0 / double(a));
    const __m128d one = _mm_set1_pd(1.0);
    // floor(E room / A) for lanes 0 and 1 of @a room (exact: x < 2^32, q A <= x + A < 2^53).
    auto share2 = [&](__m128i room) {
        const __m128d x = _mm_mul_pd(eD, _mm_cvtepi32_pd(room));
        __m128d q = _mm_cvtepi32_pd(_mm_cvttpd_epi32(_mm_mul_pd(x, inv)));
        const __m128d qa = _mm_mul_pd(q, aD);
        q = _mm_sub_pd(q, _mm_and_pd(_mm_cmpgt_pd(qa, x), one));
        q = _mm_add_pd(q, _mm_and_pd(_mm_cmple_pd(_mm_add_pd(qa, aD), x), one));
        return _mm_cvttpd_epi32(q);
    };
    // Over cells to Tc, under cells plus their share; obstacle cells as they are.
    auto fill = [&](__m128i m, uint32_t over4, uint32_t under4, __m128i& q) {
        const __m128i room = _mm_and_si128(_mm_sub_epi32(t, m), lanesOf(under4));
        q = _mm_unpacklo_epi64(share2(room), share2(_mm_shuffle_epi32(room, 0xEE)));
        const __m128i ov = lanesOf(over4);
        return _mm_add_epi32(_mm_or_si128(_mm_and_si128(ov, t), _mm_andnot_si128(ov, m)), q);
    };
    __m128i qLo, qHi = _mm_setzero_si128();
    __m128i oLo = fill(lo, over & 15u, under & 15u, qLo), oHi = _mm_setzero_si128();
    if constexpr (N == 8) oHi = fill(hi, over >> 4, under >> 4, qHi);
    int64_t r = e - hsum(_mm_add_epi32(qLo, qHi));
    uint32_t extra2 = 0;
    if (r > 0) {
        const int start = int(hash() & uint64_t(N - 1));
        auto addOne = [&](uint32_t cells) {
            oLo = _mm_sub_epi32(oLo, lanesOf(cells & 15u));
            if constexpr (N == 8) oHi = _mm_sub_epi32(oHi, lanesOf(cells >> 4));
        };
        // First the under cells still below Tc, then the others (giveRemainder); r < nu <= 8.
        uint32_t below = uint32_t(_mm_movemask_ps(_mm_castsi128_ps(_mm_cmpgt_epi32(t, oLo))));
        if constexpr (N == 8)
            below |= uint32_t(_mm_movemask_ps(_mm_castsi128_ps(_mm_cmpgt_epi32(t, oHi)))) << 4;
        below &= under;
        const int64_t k1 = std::min<int64_t>(r, rules_internal::popcount8(below));
        addOne(rotl<N>(kFirstBits.t[rotr<N>(below, start)][k1], start));
        r -= k1;
        // (Never taken when E <= A: r is the sum of the shares' fractional parts, at most the number
        // of cells with one, and each of those is still below Tc. Kept to mirror giveRemainder.)
        if (r > 0) {
            uint32_t below2 = uint32_t(_mm_movemask_ps(_mm_castsi128_ps(_mm_cmpgt_epi32(t, oLo))));
            if constexpr (N == 8)
                below2 |= uint32_t(_mm_movemask_ps(_mm_castsi128_ps(_mm_cmpgt_epi32(t, oHi)))) << 4;
            const uint32_t cells = under & ~below2;
            const int64_t k2 = std::min<int64_t>(r, rules_internal::popcount8(cells));
            extra2 = rotl<N>(kFirstBits.t[rotr<N>(cells, start)][k2], start);
            addOne(extra2);
        }
    }
    s.lo = oLo;
    s.hi = oHi;
    s.grow = changedCells<N>(lo, hi, oLo, oHi);
    // Only the second remainder pass lifts cells over Tc (extra2); the others end at or below it.
    s.active = overCells | extra2;
    s.again = extra2 != 0;
    // Shares and the first remainder pass keep every under cell at or below Tc (E <= A); the second
    // pass lifts cells at Tc to Tc + 1: the overload goes from E to the number of those cells.
    s.overDelta = -e + rules_internal::popcount8(extra2);
    s.maxOut = tc + (extra2 ? 1 : 0);
    return true;
}
#endif

/// Loads the N cells of a block lying inside one leaf, first cell at @a d, into @a m (in corner
/// order); returns whether one is over @a tc. (The portable path.)
template <int N>
__attribute__((always_inline)) inline bool loadInsideScalar(const int32_t* d, int32_t tc, int32_t* m)
{
    int32_t top = d[0];
    VDBCLAY_UNROLL
    for (int c = 0; c < N; ++c) {
        m[c] = d[kCornerOffset[c]];
        top = std::max(top, m[c]);
    }
    return top > tc;
}

// ---- The over-cell filter ------------------------------------------------------------------------
//
// Most candidate blocks hold no cell over Tc (press48: 4.4 M of 5.7 M examined), and the block loop
// spends ~40 instructions on each before it finds that out. The filter decides the item's candidates
// a column at a time (BlockMasks.h, ColumnTables: the 4 blocks with the same bx, by lie in 4 z-rows of
// 8 consecutive cells): 4 row compares against Tc ORed, one movemask, one fold table lookup give the
// column's blocks holding an over cell; on the odd phase the cells z = -1 of the block bz = 0 come
// from the -z neighbours (4 scalar loads, only when that block is a candidate). The result is exact
// (a block is kept iff one of its cells is over Tc, obstacles not excluded, as the block loop tests),
// so the loop skips exactly the blocks it skipped before; blocksVisited still counts every candidate.
// AVX2 (one row per register) where the CPU has it, chosen at run time; SSE2 (two registers a row)
// otherwise; 3D only (a 2D block's cells are 8 int32 apart: no row to compare).
//
// Only the item's own cells are read, as in the block loop: on the odd phase a row's z = 7 cell
// belongs to the +z anchor's block, which another task may be writing at the same time, so it is
// left out of the load (AVX2: a masked load, whose masked lane is not accessed; SSE2: z = 4-6 loaded
// as 8 + 4 bytes), and of the -z rows only the z = 7 cells are read.

/// The 4 z-rows of column @a col (phase P) in @a r. Columns with bx, by >= 1 lie in the anchor's leaf
/// at constant offsets (every column on the even phase); the others go through the tables.
template <int P>
__attribute__((always_inline)) inline void columnRows(const int32_t* const read[8], int col,
                                                      const int32_t* r[4])
{
    if (P == 0 || ((col & 3) && (col >> 2))) {
        const int32_t* d = read[0] + kColumns.rowOffset[P][col][0];
        r[0] = d, r[1] = d + 64, r[2] = d + 8, r[3] = d + 72;
    } else {
        for (int k = 0; k < 4; ++k)
            r[k] = read[kColumns.rowLeaf[1][col][k]] + kColumns.rowOffset[1][col][k];
    }
}

/// Whether a cell z = -1 of block bz = 0 of column @a col (odd phase) is over @a tc: the z = 7 cells
/// of the rows below the column's, in the -z neighbours.
__attribute__((always_inline)) inline bool lowerZOver(const int32_t* const read[8], int col, int32_t tc)
{
    if ((col & 3) && (col >> 2)) { // the rows lie in the anchor's leaf: the cells below in the -z one
        const int32_t* d = read[4] + kColumns.rowOffset[1][col][0] + 7;
        return std::max(std::max(d[0], d[64]), std::max(d[8], d[72])) > tc;
    }
    const uint16_t* off = kColumns.rowOffset[1][col];
    const uint8_t* lf = kColumns.rowLeaf[1][col];
    const int32_t a = std::max(read[lf[0] | 4][off[0] + 7], read[lf[1] | 4][off[1] + 7]);
    const int32_t b = std::max(read[lf[2] | 4][off[2] + 7], read[lf[3] | 4][off[3] + 7]);
    return std::max(a, b) > tc;
}

#if defined(__SSE2__)
template <int P>
__attribute__((noinline)) uint64_t overBlocksSse2(const int32_t* const read[8], uint64_t mask, int32_t tc)
{
    const __m128i t = _mm_set1_epi32(tc);
    auto lo = [&](const int32_t* p) { // z = 0-3
        return _mm_cmpgt_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(p)), t);
    };
    auto hi = [&](const int32_t* p) { // z = 4-7; odd phase z = 4-6 (lane 3 reads as 0)
        if (P == 0) return _mm_cmpgt_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(p + 4)), t);
        const __m128i v = _mm_unpacklo_epi64(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(p + 4)),
                                             _mm_cvtsi32_si128(p[6]));
        return _mm_cmpgt_epi32(v, t);
    };
    uint32_t cols = columnsOf(mask);
    uint64_t out = 0;
    while (cols) {
        const int col = __builtin_ctz(cols);
        cols &= cols - 1;
        const int32_t* r[4];
        columnRows<P>(read, col, r);
        const __m128i l = _mm_or_si128(_mm_or_si128(lo(r[0]), lo(r[1])), _mm_or_si128(lo(r[2]), lo(r[3])));
        const __m128i h = _mm_or_si128(_mm_or_si128(hi(r[0]), hi(r[1])), _mm_or_si128(hi(r[2]), hi(r[3])));
        const uint32_t z = uint32_t(_mm_movemask_ps(_mm_castsi128_ps(l))) |
                           (uint32_t(_mm_movemask_ps(_mm_castsi128_ps(h))) << 4);
        uint64_t blocks = kColumns.zFold[P][z];
        if (P == 1 && ((mask >> col) & 1u) && !(blocks & 1u) && lowerZOver(read, col, tc)) blocks |= 1u;
        out |= blocks << col;
    }
    return out & mask;
}
#endif

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define VDBCLAY_HAVE_AVX2_FILTER 1
template <int P>
__attribute__((noinline, target("avx2"))) uint64_t overBlocksAvx2(const int32_t* const read[8], uint64_t mask,
                                                                  int32_t tc)
{
    const __m256i t = _mm256_set1_epi32(tc);
    const __m256i lanes = _mm256_setr_epi32(-1, -1, -1, -1, -1, -1, -1, P == 0 ? -1 : 0); // odd: not z = 7
    uint32_t cols = columnsOf(mask);
    uint64_t out = 0;
    while (cols) {
        const int col = __builtin_ctz(cols);
        cols &= cols - 1;
        const int32_t* r[4];
        columnRows<P>(read, col, r);
        __m256i v[4];
        for (int k = 0; k < 4; ++k) { // (no lambda: it would not inherit the target)
            const __m256i x = P == 0 ? _mm256_loadu_si256(reinterpret_cast<const __m256i*>(r[k]))
                                     : _mm256_maskload_epi32(r[k], lanes); // lane 7 not read: 0
            v[k] = _mm256_cmpgt_epi32(x, t);
        }
        const __m256i any = _mm256_or_si256(_mm256_or_si256(v[0], v[1]), _mm256_or_si256(v[2], v[3]));
        uint64_t blocks = kColumns.zFold[P][_mm256_movemask_ps(_mm256_castsi256_ps(any))];
        if (P == 1 && ((mask >> col) & 1u) && !(blocks & 1u) && lowerZOver(read, col, tc)) blocks |= 1u;
        out |= blocks << col;
    }
    return out & mask;
}

bool cpuHasAvx2()
{
    static const bool has = [] {
        __builtin_cpu_init();
        return __builtin_cpu_supports("avx2") != 0;
    }();
    return has;
}

/// Whether the CPU runs the pass's AVX2 build (kKernelTarget: AVX2 with BMI1, BMI2 and POPCNT).
bool cpuHasKernelAvx2()
{
    static const bool has = [] {
        __builtin_cpu_init();
        return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("bmi") &&
               __builtin_cpu_supports("bmi2") && __builtin_cpu_supports("popcnt");
    }();
    return has;
}
#else
bool cpuHasAvx2()
{
    return false;
}
bool cpuHasKernelAvx2()
{
    return false;
}
#endif

/// The filter @a f stands for on this machine and build.
OverFilter resolveFilter(OverFilter f)
{
    if (f == OverFilter::Auto || f == OverFilter::Avx2) {
        if (cpuHasAvx2()) return OverFilter::Avx2;
        f = OverFilter::Sse2;
    }
#if defined(__SSE2__)
    return f;
#else
    return OverFilter::None;
#endif
}

template <int P>
inline uint64_t filterBlocks(OverFilter f, const int32_t* const read[8], uint64_t mask, int32_t tc)
{
#if defined(VDBCLAY_HAVE_AVX2_FILTER)
    if (f == OverFilter::Avx2) return overBlocksAvx2<P>(read, mask, tc);
#endif
#if defined(__SSE2__)
    if (f == OverFilter::Sse2) return overBlocksSse2<P>(read, mask, tc);
#endif
    (void)f, (void)read, (void)tc;
    return mask;
}

/// The accessor path's leaves (no table, or an anchor it lacks): the set, and what it was fetched for.
struct FetchedLeaves {
    LeafSet set{};        // slots past the phase's count stay null: fetchLeaves never writes them
    Origin anchor;        // the anchor these leaves were fetched for
    uint32_t fetched = 0; // which of the 8 slots were fetched (0: none yet)
};

// Out of line on purpose: inlined into the block loop it costs more than the call (register
// pressure; callgrind, press 32: 20 M more instructions in the pass).
/// The leaves of @a anchor whose slots are in @a need, through accessors, into @a f; the other
/// slots read as missing leaves. @a prev holds the previous item's leaves (fetched == 0: none).
/// Returns @a f's set.
template <bool D3, int P>
__attribute__((noinline)) const LeafSet* fetchLeaves(FetchedLeaves& f, const FetchedLeaves& prev,
                                                     const Origin& anchor, uint32_t need, MassAcc& acc,
                                                     ObsAcc* oacc, bool reuse)
{
    constexpr int kCount = (P == 1) ? (D3 ? 8 : 4) : 1;
    LeafSet& ls = f.set;
    const LeafSet& ps = prev.set;
    ls.missing = ls.obsAny = ls.obsTile = 0;
    // A merged-mode list runs along x (layer order): when the previous anchor is this one's -x
    // neighbour, this anchor's -x leaves (odd slots) are its leaves (even slots), fetched already.
    uint32_t reused = 0;
    if (P == 1 && reuse && prev.fetched && prev.anchor == Origin(anchor.x() - 8, anchor.y(), anchor.z())) {
        for (int w = 1; w < kCount; w += 2) {
            if (!((need >> w) & 1u) || !((prev.fetched >> (w - 1)) & 1u)) continue;
            ls.leaf[w] = ps.leaf[w - 1];
            ls.data[w] = ps.data[w - 1];
            ls.read[w] = ps.read[w - 1];
            ls.obs[w] = ps.obs[w - 1];
            const uint8_t from = uint8_t(1u << (w - 1)), to = uint8_t(1u << w);
            if (ps.missing & from) ls.missing |= to;
            if (ps.obsAny & from) ls.obsAny |= to;
            if (ps.obsTile & from) ls.obsTile |= to;
            reused |= 1u << w;
        }
    }
    ls.missing |= uint8_t(0xFFu << kCount); // slots the phase never reads
    for (int w = 0; w < kCount; ++w) {
        if ((reused >> w) & 1u) continue;
        ls.leaf[w] = nullptr;
        ls.data[w] = nullptr;
        ls.read[w] = kZeroLeaf;
        ls.obs[w] = nullptr;
        const uint8_t bit = uint8_t(1u << w);
        if (!((need >> w) & 1u)) {
            ls.missing |= bit;
            continue;
        }
        const Origin lo = leafOrigin(anchor, w);
        const Coord o(lo.x(), lo.y(), lo.z());
        ls.leaf[w] = acc.probeLeaf(o);
        if (ls.leaf[w]) {
            ls.read[w] = ls.data[w] = ls.leaf[w]->buffer().data();
        } else {
            ls.missing |= bit;
        }
        if (oacc) {
            ls.obs[w] = oacc->probeConstLeaf(o);
            if (!ls.obs[w] && oacc->isValueOn(o)) ls.obsTile |= bit;
            if (ls.obs[w] || ((ls.obsTile >> w) & 1u)) ls.obsAny |= bit;
        }
    }
    f.anchor = anchor;
    f.fetched = need;
    return &ls;
}

/// A block's hash from the step's prefix, computed only when a remainder or a tie needs it (its
/// coordinates too: most updated blocks need no hash).
template <bool D3> struct BlockHash {
    uint64_t prefix;
    int32_t ax, ay, az; // the anchor's first block corner
    int b;
    uint64_t operator()() const
    {
        return rules_internal::finishHash(prefix, ax + 2 * (b & 3), ay + 2 * ((b >> 2) & 3),
                                          D3 ? az + 2 * (b >> 4) : 0);
    }
};

/// The instructions a build of the pass may use: the target's baseline (SSE2 on x86-64), or AVX2 with
/// BMI1, BMI2 and POPCNT (processRangeAvx2, chosen at run time where the CPU has them).
enum class Isa { Base, Avx2 };

/// The pass (see the top of this file). Inlined into one function per instruction set below; it
/// calls nothing that needs more than the baseline, so the same source compiles for both.
template <Rule R, bool D3, int P, Isa I>
__attribute__((always_inline)) inline void processRangeBody(const PassInput& in, WorkItem* work, size_t begin,
                                                            size_t end, PassTotals& tot)
{
    constexpr int N = D3 ? 8 : 4;
    const BlockTables& tab = blockTables();
    const CompiledRule rule = in.rule;
    const int64_t tc = rule.threshold;
    const int32_t tc32 = int32_t(std::min<int64_t>(tc, INT32_MAX));
    const uint64_t prefix = rules_internal::stepPrefix(in.step, in.seed);
    const bool mayOverflow = in.mayOverflow, dryRun = in.dryRun, portable = in.portable;
    const uint64_t insideOdd = D3 ? kInsideOdd3 : kInsideOdd2;
#if defined(__SSE2__)
    // The surplus branch in int32 lanes (surplusBranch) is exact when no sum can wrap: with no cell
    // over INT32_MAX / 8 (!mayOverflow), E < 8 * 2^28 = 2^31; with Tc <= 2^27, A <= 8 Tc <= 2^30;
    // every result is at most the block's sum. Otherwise, and on the portable path, the rule runs.
    constexpr bool kSurplusRule = R == Rule::Prorata || R == Rule::Sorted;
    const bool simd = !portable && !mayOverflow && !dryRun && tc <= (int64_t(1) << 27);
    const __m128i tcV = _mm_set1_epi32(tc32);
#else
    const bool simd = false;
#endif
    const OverFilter filter = (D3 && !portable) ? resolveFilter(in.filter) : OverFilter::None;
    MassAcc acc(*in.tree);
    const LeafTable::Impl* table = in.table && in.table->valid() ? in.table->impl() : nullptr;
    std::optional<ObsAcc> oacc;
    if (in.obstacles) oacc.emplace(*in.obstacles);
    // Two buffers for the accessor path: the next item's leaves are fetched while this item's are in use.
    FetchedLeaves fetched[2];
    const DenseSink* sink = dryRun ? nullptr : in.sink;
    if (sink && in.sinkLanes > 1) {
        // This thread's lane: its slot in the pass's arena, which has sinkLanes slots.
        // Should it lie outside (not expected), the range records nothing and says so: record()
        // then records every item again (ORs are idempotent).
        const int lane = tbb::this_task_arena::current_thread_index();
        if (lane >= 0 && lane < in.sinkLanes) {
            sink += lane;
        } else {
            sink = nullptr;
            tot.sinkMissed = true;
        }
    }
    // Per updated block, what sinkActive needs: only when it records (a sink, pruning on).
    const bool noting = sink && in.prune;
    // Totals in locals (registers), added to tot once at the end.
    uint64_t examined = 0, overTc = 0, updated = 0;
    int64_t overloadDelta = 0, maxWritten = 0;
    // Item wi + 1 is looked up and filtered before item wi's blocks run (a software pipeline): the
    // filter's loads are the first touch of the item's cells (from L2, or L3 when the clay is spread
    // wide), and issued ahead of item wi's block loop they no longer wait behind its branches. It reads only
    // that item's own cells, which no other item of the pass writes (blocks of one phase are disjoint), so
    // its result is the same either way.
    struct Prepared {
        const LeafSet* set;
        uint32_t need;
        uint64_t bits; // the candidates left by the filter; 0: nothing to do
    };
    auto prepare = [&](size_t wi, FetchedLeaves& buf, const FetchedLeaves& prevBuf) {
        const WorkItem& w = work[wi];
        Prepared p;
        p.need = P == 1 ? neededLeaves<D3>(w.mask) : 1u;
        p.set = nullptr;
        if (table) p.set = w.entry != kNoEntry ? &table->entries[w.entry] : table->find(w.anchor);
        if (p.set) {
            buf.fetched = 0; // the next item cannot reuse this one's leaves from the buffer
        } else {
            p.set =
                fetchLeaves<D3, P>(buf, prevBuf, w.anchor, p.need, acc, oacc ? &*oacc : nullptr, !portable);
        }
        p.bits = w.mask;
        if (P == 0 && !p.set->data[0]) p.bits = 0; // even blocks of a missing leaf: all 0
        if (D3 && filter != OverFilter::None && p.bits)
            p.bits = filterBlocks<P>(filter, p.set->read, p.bits, tc32);
        return p;
    };
    Prepared next{};
    if (begin < end) next = prepare(begin, fetched[0], fetched[1]);
    for (size_t wi = begin; wi < end; ++wi) {
        WorkItem& w = work[wi];
        const Prepared cur = next;
        if (wi + 1 < end) {
            const size_t k = (wi + 1 - begin) & 1;
            next = prepare(wi + 1, fetched[k], fetched[1 - k]);
        }
        w.changed = 0;
        uint64_t itemChanged = 0; // stored into w.changed once per item
        // For the sink (sinkActive): the updated blocks that may still hold an over and a not-over
        // cell, and per updated block its cells that were or went over Tc (corners: their union).
        uint64_t again = 0, act[8] = {0, 0, 0, 0, 0, 0, 0, 0};
        if constexpr (I == Isa::Avx2)
            examined += uint64_t(__builtin_popcountll(w.mask)); // one POPCNT
        else
            examined += popcount64(w.mask);
        uint64_t bits = cur.bits;
        if (!bits) continue;
        const LeafSet& ls = *cur.set;
        // The slots' pointers in locals (two cache lines of the set; one slot on the even phase):
        // the loop's stores may alias memory, so read through the set they would be reloaded.
        constexpr int kSlots = P == 1 ? (D3 ? 8 : 4) : 1;
        const int32_t* read[8];
        int32_t* data[8];
        for (int k = 0; k < kSlots; ++k) {
            read[k] = ls.read[k];
            data[k] = ls.data[k];
        }
        // A leaf the mask's blocks touch is missing; one holds obstacles or lies in an obstacle tile.
        const uint32_t need = cur.need;
        const bool anyMissing = (ls.missing & need) != 0, anyObs = (ls.obsAny & need) != 0;
        const int32_t ax = w.anchor.x() - P, ay = w.anchor.y() - P, az = D3 ? w.anchor.z() - P : 0;
        while (bits) {
            const int b = __builtin_ctzll(bits);
            bits &= bits - 1;
            const uint16_t* off = tab.offset[D3][P][b];
            const uint8_t* lf = tab.leaf[D3][P][b];
            // Even blocks, and odd blocks not reaching into a lower neighbour, lie in the anchor's
            // leaf at constant offsets; the others go through the tables.
            const bool inside = P == 0 || ((insideOdd >> b) & 1u);
            // Blocks that do not straddle a z boundary (all but the odd blocks with bz = 0 in 3D)
            // hold each corner k's z + 1 neighbour (corner k + 4) in the next int32.
            const bool pairs = inside || !D3 || (b >> 4) != 0;
            alignas(16) int32_t m[8];
            uint32_t overCells = 0; // corners over Tc (obstacles not yet excluded); 0 on the portable path
#if defined(__SSE2__)
            // The block in registers (every non-portable load): cells and their compare with Tc.
            __m128i lo = _mm_setzero_si128(), hi = _mm_setzero_si128(), gtLo = hi, gtHi = hi;
            if (pairs && !portable) {
                if (inside) {
                    const int32_t* d = read[0] + off[0];
                    loadPairs<N>(d, d + 64, d + 8, d + 72, lo, hi);
                } else {
                    loadPairs<N>(read[lf[0]] + off[0], read[lf[1]] + off[1], read[lf[2]] + off[2],
                                 read[lf[3]] + off[3], lo, hi);
                }
                gtLo = _mm_cmpgt_epi32(lo, tcV);
                if constexpr (N == 8) gtHi = _mm_cmpgt_epi32(hi, tcV);
                overCells = laneBits<N>(gtLo, gtHi);
                if (!overCells) continue;
            } else
#endif
                if (inside) {
                if (!loadInsideScalar<N>(read[0] + off[0], tc32, m)) continue;
            } else {
#if defined(__SSE2__)
                if (!portable) {
                    // Straddling a z boundary: corner k and k + 4 lie in different leaves.
                    lo = _mm_setr_epi32(read[lf[0]][off[0]], read[lf[1]][off[1]], read[lf[2]][off[2]],
                                        read[lf[3]][off[3]]);
                    if constexpr (N == 8)
                        hi = _mm_setr_epi32(read[lf[4]][off[4]], read[lf[5]][off[5]], read[lf[6]][off[6]],
                                            read[lf[7]][off[7]]);
                    gtLo = _mm_cmpgt_epi32(lo, tcV);
                    if constexpr (N == 8) gtHi = _mm_cmpgt_epi32(hi, tcV);
                    overCells = laneBits<N>(gtLo, gtHi);
                    if (!overCells) continue;
                } else
#endif
                {
                    int32_t top = 0;
                    VDBCLAY_UNROLL
                    for (int c = 0; c < N; ++c) {
                        m[c] = read[lf[c]][off[c]];
                        top = std::max(top, m[c]);
                    }
                    if (top <= tc32) continue;
                }
            }
            uint32_t valid = (1u << N) - 1;
            if (anyObs) {
                if (pairs && !portable) {
                    // Corner k and k + 4 are neighbouring bits of one word of the obstacle mask.
                    uint32_t blocked = 0;
                    VDBCLAY_UNROLL
                    for (int k = 0; k < 4; ++k) {
                        const ObsLeaf* ol = ls.obs[lf[k]];
                        const int o = off[k];
                        const uint32_t two =
                            ol ? uint32_t(ol->getValueMask().template getWord<uint64_t>(o >> 6) >> (o & 63)) &
                                     3u
                               : (((ls.obsTile >> lf[k]) & 1u) ? 3u : 0u);
                        blocked |= ((two & 1u) << k) | ((two >> 1) << (k + 4));
                    }
                    valid &= ~blocked;
                } else {
                    for (int c = 0; c < N; ++c) {
                        const ObsLeaf* ol = ls.obs[lf[c]];
                        if (ol ? ol->isValueOn(off[c]) : ((ls.obsTile >> lf[c]) & 1u)) valid &= ~(1u << c);
                    }
                }
            }
            ++overTc;
            const BlockHash<D3> hash{prefix, ax, ay, az, b};
            int64_t out[8];
            uint32_t changed;
#if defined(__SSE2__)
            if (kSurplusRule && simd) {
                Surplus sp;
                Branch br = surplusBranch<N>(lo, hi, gtLo, gtHi, overCells, valid, tc32, hash, sp);
                if (br == Branch::Unchanged) continue;
                if constexpr (R == Rule::Prorata) {
                    if (br == Branch::Rule && roomBranch<N>(lo, hi, overCells, valid, tc32, hash, sp))
                        br = Branch::Done;
                }
                if (br == Branch::Done) {
                    if (P == 1 && anyMissing && !inside) {
                        const uint32_t ch = changedCells<N>(lo, hi, sp.lo, sp.hi);
                        bool missing = false;
                        for (int c = 0; c < N; ++c)
                            if (((ch >> c) & 1u) && !data[lf[c]]) missing = true;
                        if (missing) {
                            tot.deferred.push_back(
                                PassTotals::Deferred{uint32_t(wi), uint8_t(b), uint8_t(ch)});
                            continue;
                        }
                    }
                    if (N == 8 && pairs && (inside || !anyMissing)) {
                        // Every cell of the block is this task's: write all 8, two to a store.
                        int32_t* d0 = data[0] + off[0];
                        int32_t *p0 = d0, *p1 = d0 + 64, *p2 = d0 + 8, *p3 = d0 + 72;
                        if (!inside) {
                            p0 = data[lf[0]] + off[0], p1 = data[lf[1]] + off[1];
                            p2 = data[lf[2]] + off[2], p3 = data[lf[3]] + off[3];
                        }
                        const __m128i t01 = _mm_unpacklo_epi32(sp.lo, sp.hi); // c0 c4 c1 c5
                        const __m128i t23 = _mm_unpackhi_epi32(sp.lo, sp.hi); // c2 c6 c3 c7
                        _mm_storel_epi64(reinterpret_cast<__m128i*>(p0), t01);
                        _mm_storel_epi64(reinterpret_cast<__m128i*>(p1), _mm_unpackhi_epi64(t01, t01));
                        _mm_storel_epi64(reinterpret_cast<__m128i*>(p2), t23);
                        _mm_storel_epi64(reinterpret_cast<__m128i*>(p3), _mm_unpackhi_epi64(t23, t23));
                    } else {
                        alignas(16) int32_t o32[8];
                        storeCorners<N>(sp.lo, sp.hi, o32);
                        uint32_t ch = changedCells<N>(lo, hi, sp.lo, sp.hi);
                        while (ch) {
                            const int c = __builtin_ctz(ch);
                            ch &= ch - 1;
                            const int li = inside ? 0 : lf[c];
                            const int o = inside ? off[0] + kCornerOffset[c] : off[c];
                            data[li][o] = o32[c];
                        }
                    }
                    // 0 -> positive: the voxel becomes active (rare: clay flowing into empty cells).
                    const __m128i z = _mm_setzero_si128();
                    uint32_t fresh = laneBits<N>(_mm_cmpeq_epi32(lo, z), _mm_cmpeq_epi32(hi, z)) & sp.grow;
                    while (fresh) {
                        const int c = __builtin_ctz(fresh);
                        fresh &= fresh - 1;
                        const int li = inside ? 0 : lf[c];
                        const int o = inside ? off[0] + kCornerOffset[c] : off[c];
                        auto& word = ls.leaf[li]->getValueMask().template getWord<uint64_t>(o >> 6);
                        __atomic_fetch_or(&word, uint64_t(1) << (o & 63), __ATOMIC_RELAXED);
                    }
                    overloadDelta += sp.overDelta;
                    maxWritten = std::max(maxWritten, sp.maxOut);
                    ++updated;
                    itemChanged |= uint64_t(1) << b;
                    if (noting) noteUpdated(b, sp.active, sp.again, act, again);
                    continue;
                }
            }
            if (!portable) storeCorners<N>(lo, hi, m); // the rule reads the cells from memory
#endif
            changed = rules_internal::repartitionT<R, N>(rule, m, valid, hash, out);
            if (!changed) continue;
            // Both checks can only fire rarely: a result over INT32_MAX needs a cell over
            // INT32_MAX / 8 somewhere (mayOverflow), and a write into a missing leaf needs one of
            // the fetched leaves to be missing (clay flowing into space the grid has not grown;
            // never on even steps, whose blocks lie in the anchor's leaf, which exists).
            bool fits = true, missing = false;
            if (mayOverflow || (P == 1 && anyMissing)) {
                for (int c = 0; c < N; ++c) {
                    if (!((changed >> c) & 1u)) continue;
                    if (out[c] > INT32_MAX) fits = false;
                    if (!data[lf[c]]) missing = true;
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
            // Only changed cells move the overload (an unchanged cell contributes 0).
            uint32_t ch = changed;
            while (ch) {
                const int c = __builtin_ctz(ch);
                ch &= ch - 1;
                overloadDelta += std::max<int64_t>(out[c] - tc, 0) - std::max<int64_t>(m[c] - tc, 0);
                const int li = inside ? 0 : lf[c];
                const int o = inside ? off[0] + kCornerOffset[c] : off[c];
                data[li][o] = int32_t(out[c]);
                maxWritten = std::max(maxWritten, out[c]);
                if (m[c] == 0) {
                    // 0 -> positive: the voxel becomes active. Other tasks may set bits in the
                    // same mask word (straddling blocks), hence the atomic OR.
                    auto& word = ls.leaf[li]->getValueMask().template getWord<uint64_t>(o >> 6);
                    __atomic_fetch_or(&word, uint64_t(1) << (o & 63), __ATOMIC_RELAXED);
                }
            }
            ++updated;
            itemChanged |= uint64_t(1) << b;
            if (noting) {
                uint32_t overBefore = 0, overAfter = 0;
                for (int c = 0; c < N; ++c) {
                    overBefore |= uint32_t(m[c] > tc) << c;
                    overAfter |= uint32_t(out[c] > tc) << c;
                }
                noteUpdated(b, overBefore | overAfter,
                            (overAfter & valid) && (valid & ~overAfter & ((1u << N) - 1)), act, again);
            }
        }
        w.changed = itemChanged;
        if (itemChanged && sink && w.entry != kNoEntry) {
            if (noting)
                sinkActive<P, D3>(*sink, w.entry, again, act);
            else
                sinkChanges<P, D3>(*sink, w.entry, itemChanged);
        }
    }
    tot.examined += examined;
    tot.overTc += overTc;
    tot.updated += updated;
    tot.overloadDelta += overloadDelta;
    tot.maxWritten = std::max(tot.maxWritten, maxWritten);
}

template <Rule R, bool D3, int P>
__attribute__((noinline)) void processRangeT(const PassInput& in, WorkItem* work, size_t begin, size_t end,
                                             PassTotals& tot)
{
    processRangeBody<R, D3, P, Isa::Base>(in, work, begin, end, tot);
}

#if defined(VDBCLAY_HAVE_AVX2_FILTER)
// The same pass compiled for AVX2 (three-operand VEX forms: no register copies; BMI2 shifts; POPCNT).
// The target attribute covers only this function and what is inlined into it: OpenVDB's and the
// standard library's out-of-line functions stay baseline code, so nothing AVX2 leaks into symbols
// other translation units share.
template <Rule R, bool D3, int P>
__attribute__((noinline, target("avx2,bmi,bmi2,popcnt"))) void
processRangeAvx2(const PassInput& in, WorkItem* work, size_t begin, size_t end, PassTotals& tot)
{
    processRangeBody<R, D3, P, Isa::Avx2>(in, work, begin, end, tot);
}
#endif

template <Rule R, bool D3, int P>
void runPass(const PassInput& in, WorkItem* work, size_t begin, size_t end, PassTotals& tot)
{
#if defined(VDBCLAY_HAVE_AVX2_FILTER)
    if (in.avx2 && !in.portable && cpuHasKernelAvx2())
        return processRangeAvx2<R, D3, P>(in, work, begin, end, tot);
#endif
    processRangeT<R, D3, P>(in, work, begin, end, tot);
}

template <Rule R>
void dispatch(const PassInput& in, WorkItem* work, size_t begin, size_t end, PassTotals& tot)
{
    if (in.is3D) {
        if (in.phase)
            runPass<R, true, 1>(in, work, begin, end, tot);
        else
            runPass<R, true, 0>(in, work, begin, end, tot);
    } else {
        if (in.phase)
            runPass<R, false, 1>(in, work, begin, end, tot);
        else
            runPass<R, false, 0>(in, work, begin, end, tot);
    }
}

} // namespace

bool avx2Pass()
{
#if defined(VDBCLAY_HAVE_AVX2_FILTER)
    return cpuHasKernelAvx2();
#else
    return false;
#endif
}

OverFilter bestOverFilter()
{
    return resolveFilter(OverFilter::Auto);
}

uint64_t overBlocks(const int32_t* const read[8], uint64_t mask, int32_t tc, bool is3D, int phase,
                    OverFilter f)
{
    if (!is3D) return mask;
    f = resolveFilter(f);
    return phase ? filterBlocks<1>(f, read, mask, tc) : filterBlocks<0>(f, read, mask, tc);
}

void PassTotals::join(const PassTotals& o)
{
    examined += o.examined;
    overTc += o.overTc;
    updated += o.updated;
    overloadDelta += o.overloadDelta;
    maxWritten = std::max(maxWritten, o.maxWritten);
    sinkMissed = sinkMissed || o.sinkMissed;
    if (o.overflow && (!overflow || o.overflowItem < overflowItem ||
                       (o.overflowItem == overflowItem && o.overflowBit < overflowBit))) {
        overflow = true;
        overflowItem = o.overflowItem;
        overflowBit = o.overflowBit;
    }
    deferred.insert(deferred.end(), o.deferred.begin(), o.deferred.end());
}

void processRange(const PassInput& in, WorkItem* work, size_t begin, size_t end, PassTotals& tot)
{
    switch (in.rule.rule) {
    case Rule::Arata: dispatch<Rule::Arata>(in, work, begin, end, tot); break;
    case Rule::Bingham: dispatch<Rule::Bingham>(in, work, begin, end, tot); break;
    case Rule::Sorted: dispatch<Rule::Sorted>(in, work, begin, end, tot); break;
    case Rule::Prorata: dispatch<Rule::Prorata>(in, work, begin, end, tot); break;
    }
}

} // namespace automaton_internal
} // namespace vdbclay
