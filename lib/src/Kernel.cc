// The automaton's per-block kernel (see Kernel.h for the contract and its thread-safety).
//
// Per anchor: its leaves are fetched once through value accessors (even steps: the anchor's leaf
// alone, whose 64 blocks it holds whole; odd steps: also the lower neighbours that the straddling
// blocks reach, only those the mask's blocks touch). Then for each candidate block: load its cells
// (even: at constant offsets from the block's first cell; odd: through the addressing tables),
// skip it unless a cell is over Tc, apply the rule (inlined, instantiated for this rule and cell
// count), and write back only the cells that changed. The overload changes only where a cell
// changed, so its delta is summed over those cells alone. Checks that can fire only rarely (a result
// over INT32_MAX, a write into a missing leaf) run only when the pass or the anchor allows them.
#include "Kernel.h"

#include "BlockMasks.h"
#include "RulesImpl.h"

#include <openvdb/openvdb.h>
#include <openvdb/tree/ValueAccessor.h>

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

/// Offsets of a block's corners c = dx + 2 dy + 4 dz from its first cell, in one leaf.
constexpr int kCornerOffset[8] = {0, 64, 8, 72, 1, 65, 9, 73};

/// Odd blocks that lie inside the anchor leaf (no local coordinate at -1): read like even blocks.
constexpr uint64_t kInsideOdd3 = ~(kX0 | kY0 | kZ0), kInsideOdd2 = ~(kX0 | kY0) & 0xFFFFull;

/// Bits set in a 64-bit mask (SWAR; the build targets no popcnt instruction).
inline uint64_t popcount64(uint64_t x)
{
    x = x - ((x >> 1) & 0x5555555555555555ull);
    x = (x & 0x3333333333333333ull) + ((x >> 2) & 0x3333333333333333ull);
    x = (x + (x >> 4)) & 0x0F0F0F0F0F0F0F0Full;
    return (x * 0x0101010101010101ull) >> 56;
}

/// Loads the N cells of a block lying inside one leaf, first cell at @a d, into @a m (in corner
/// order); returns whether one is over @a tc.
template <int N>
__attribute__((always_inline)) inline bool loadInside(const int32_t* d, int32_t tc, int32_t* m)
{
#if defined(__SSE2__)
    // Corners (dx, dy) pairs along z are adjacent in the leaf: four 8-byte loads, two shuffles.
    // In 2D (z = 0) the z = 1 neighbours are read (inside the leaf) and ignored.
    const __m128i p0 = _mm_loadl_epi64(reinterpret_cast<const __m128i*>(d));
    const __m128i p1 = _mm_loadl_epi64(reinterpret_cast<const __m128i*>(d + 64));
    const __m128i p2 = _mm_loadl_epi64(reinterpret_cast<const __m128i*>(d + 8));
    const __m128i p3 = _mm_loadl_epi64(reinterpret_cast<const __m128i*>(d + 72));
    const __m128i a01 = _mm_unpacklo_epi32(p0, p1);  // d0 d64 d1 d65
    const __m128i a23 = _mm_unpacklo_epi32(p2, p3);  // d8 d72 d9 d73
    const __m128i lo = _mm_unpacklo_epi64(a01, a23); // corners 0-3
    const __m128i t = _mm_set1_epi32(tc);
    _mm_storeu_si128(reinterpret_cast<__m128i*>(m), lo);
    int any = _mm_movemask_epi8(_mm_cmpgt_epi32(lo, t));
    if constexpr (N == 8) {
        const __m128i hi = _mm_unpackhi_epi64(a01, a23); // corners 4-7
        _mm_storeu_si128(reinterpret_cast<__m128i*>(m + 4), hi);
        any |= _mm_movemask_epi8(_mm_cmpgt_epi32(hi, t));
    }
    return any != 0;
#else
    int32_t top = d[0];
    VDBCLAY_UNROLL
    for (int c = 0; c < N; ++c) {
        m[c] = d[kCornerOffset[c]];
        top = std::max(top, m[c]);
    }
    return top > tc;
#endif
}

/// The leaves an anchor's blocks touch: mass data (null when the leaf is missing) and obstacles.
struct LeafSet {
    MassLeaf* leaf[8] = {};
    int32_t* data[8] = {};
    const int32_t* read[8] = {}; // data, or zeros for a missing leaf: reads need no null test
    const ObsLeaf* obs[8] = {};
    bool obsTile[8] = {};    // obstacle state of the whole region when obs[i] is null
    bool anyMissing = false; // a leaf the mask's blocks touch does not exist
    bool anyObs = false;     // a leaf they touch holds obstacles or lies in an obstacle tile
};

template <bool D3, int P>
inline void fetchLeaves(LeafSet& ls, const Origin& anchor, uint64_t mask, MassAcc& acc, ObsAcc* oacc)
{
    const BlockTables& t = blockTables();
    constexpr int kCount = (P == 1) ? (D3 ? 8 : 4) : 1;
    ls.anyMissing = false;
    ls.anyObs = false;
    for (int w = 0; w < kCount; ++w) {
        ls.leaf[w] = nullptr;
        ls.data[w] = nullptr;
        ls.read[w] = kZeroLeaf;
        ls.obs[w] = nullptr;
        ls.obsTile[w] = false;
        if (w && !(mask & t.needLeaf[D3][w])) continue;
        const Origin lo = leafOrigin(anchor, w);
        const Coord o(lo.x(), lo.y(), lo.z());
        ls.leaf[w] = acc.probeLeaf(o);
        if (ls.leaf[w])
            ls.read[w] = ls.data[w] = ls.leaf[w]->buffer().data();
        else
            ls.anyMissing = true;
        if (oacc) {
            ls.obs[w] = oacc->probeConstLeaf(o);
            if (!ls.obs[w]) ls.obsTile[w] = oacc->isValueOn(o);
            ls.anyObs |= ls.obs[w] || ls.obsTile[w];
        }
    }
}

template <Rule R, bool D3, int P>
void processRangeT(const PassInput& in, WorkItem* work, size_t begin, size_t end, PassTotals& tot)
{
    constexpr int N = D3 ? 8 : 4;
    const BlockTables& tab = blockTables();
    const CompiledRule rule = in.rule;
    const int64_t tc = rule.threshold;
    const int32_t tc32 = int32_t(std::min<int64_t>(tc, INT32_MAX));
    const uint64_t prefix = rules_internal::stepPrefix(in.step, in.seed);
    const bool mayOverflow = in.mayOverflow, dryRun = in.dryRun;
    const uint64_t insideOdd = D3 ? kInsideOdd3 : kInsideOdd2;
    MassAcc acc(*in.tree);
    std::optional<ObsAcc> oacc;
    if (in.obstacles) oacc.emplace(*in.obstacles);
    LeafSet ls;
    // Totals in locals (registers), added to tot once at the end.
    uint64_t examined = 0, overTc = 0, updated = 0;
    int64_t overloadDelta = 0, maxWritten = 0;
    for (size_t wi = begin; wi < end; ++wi) {
        WorkItem& w = work[wi];
        w.changed = 0;
        examined += popcount64(w.mask);
        fetchLeaves<D3, P>(ls, w.anchor, w.mask, acc, oacc ? &*oacc : nullptr);
        if (P == 0 && !ls.data[0]) continue; // even blocks of a missing leaf: all 0
        const int32_t ax = w.anchor.x() - P, ay = w.anchor.y() - P, az = D3 ? w.anchor.z() - P : 0;
        uint64_t bits = w.mask;
        while (bits) {
            const int b = __builtin_ctzll(bits);
            bits &= bits - 1;
            const uint16_t* off = tab.offset[D3][P][b];
            const uint8_t* lf = tab.leaf[D3][P][b];
            // Even blocks, and odd blocks not reaching into a lower neighbour, lie in the anchor's
            // leaf at constant offsets; the others go through the tables.
            const bool inside = P == 0 || ((insideOdd >> b) & 1u);
            alignas(16) int32_t m[8];
            if (inside) {
                if (!loadInside<N>(ls.read[0] + off[0], tc32, m)) continue;
            } else {
                int32_t top = 0;
                VDBCLAY_UNROLL
                for (int c = 0; c < N; ++c) {
                    m[c] = ls.read[lf[c]][off[c]];
                    top = std::max(top, m[c]);
                }
                if (top <= tc32) continue;
            }
            uint32_t valid = (1u << N) - 1;
            if (ls.anyObs) {
                for (int c = 0; c < N; ++c) {
                    const ObsLeaf* ol = ls.obs[lf[c]];
                    if (ol ? ol->isValueOn(off[c]) : ls.obsTile[lf[c]]) valid &= ~(1u << c);
                }
            }
            ++overTc;
            const rules_internal::PrefixHash hash{prefix, ax + 2 * (b & 3), ay + 2 * ((b >> 2) & 3),
                                                  D3 ? az + 2 * (b >> 4) : 0};
            int64_t out[8];
            const uint32_t changed = rules_internal::repartitionT<R, N>(rule, m, valid, hash, out);
            if (!changed) continue;
            // Both checks can only fire rarely: a result over INT32_MAX needs a cell over
            // INT32_MAX / 8 somewhere (mayOverflow), and a write into a missing leaf needs one of
            // the fetched leaves to be missing (clay flowing into space the grid has not grown;
            // never on even steps, whose blocks lie in the anchor's leaf, which exists).
            bool fits = true, missing = false;
            if (mayOverflow || (P == 1 && ls.anyMissing)) {
                for (int c = 0; c < N; ++c) {
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
            // Only changed cells move the overload (an unchanged cell contributes 0).
            uint32_t ch = changed;
            while (ch) {
                const int c = __builtin_ctz(ch);
                ch &= ch - 1;
                overloadDelta += std::max<int64_t>(out[c] - tc, 0) - std::max<int64_t>(m[c] - tc, 0);
                const int li = inside ? 0 : lf[c];
                const int o = inside ? off[0] + kCornerOffset[c] : off[c];
                ls.data[li][o] = int32_t(out[c]);
                maxWritten = std::max(maxWritten, out[c]);
                if (m[c] == 0) {
                    // 0 -> positive: the voxel becomes active. Other tasks may set bits in the
                    // same mask word (straddling blocks), hence the atomic OR.
                    auto& word = ls.leaf[li]->getValueMask().template getWord<uint64_t>(o >> 6);
                    __atomic_fetch_or(&word, uint64_t(1) << (o & 63), __ATOMIC_RELAXED);
                }
            }
            ++updated;
            w.changed |= uint64_t(1) << b;
        }
    }
    tot.examined += examined;
    tot.overTc += overTc;
    tot.updated += updated;
    tot.overloadDelta += overloadDelta;
    tot.maxWritten = std::max(tot.maxWritten, maxWritten);
}

template <Rule R>
void dispatch(const PassInput& in, WorkItem* work, size_t begin, size_t end, PassTotals& tot)
{
    if (in.is3D) {
        if (in.phase)
            processRangeT<R, true, 1>(in, work, begin, end, tot);
        else
            processRangeT<R, true, 0>(in, work, begin, end, tot);
    } else {
        if (in.phase)
            processRangeT<R, false, 1>(in, work, begin, end, tot);
        else
            processRangeT<R, false, 0>(in, work, begin, end, tot);
    }
}

} // namespace

void PassTotals::join(const PassTotals& o)
{
    examined += o.examined;
    overTc += o.overTc;
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
