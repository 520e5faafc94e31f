// The pass over a range of a step's work list (see Kernel.h for the contract and its thread-safety).
//
// Per item (an anchor and its candidate blocks), prepareItem finds its leaves once (even steps: the
// anchor's leaf alone, whose 64 blocks it holds whole; odd steps: also the lower neighbours that the
// straddling blocks reach): the flat leaf table's entry when the Automaton has one (LeafTable.h, read
// in place through a pointer), otherwise through value accessors (fetchLeaves: only the leaves the
// mask's blocks touch). In 3D the over-cell filter (OverFilter.h) then drops the candidates holding
// no cell over Tc. Both are done one item ahead (a software pipeline: the filter's loads, the first
// touch of the item's cells, are issued before the previous item's block loop, not behind its
// branches). Then runItem takes each candidate block left through runBlock:
//   loadRegisters      its cells (even: at constant offsets from the block's first cell; odd: through
//                      the addressing tables) in two SSE2 registers, or loadScalar in memory on the
//                      portable path; a block with no cell over Tc stops here
//   validCells         the cells not blocked by an obstacle (only where the item's leaves hold any);
//                      on the SIMD paths a block without a valid over cell and a valid under cell
//                      stops here too (every rule leaves it unchanged)
//   updateInRegisters  prorata's and sorted's branches in registers (BlockSimd.h), written back by
//                      storeRegisters: all 8 cells by four 8-byte stores for blocks in one leaf
//   updateScalar       every other case (E <= A outside prorata's room branch, the other rules, a pass
//                      that may overflow, Tc > 2^27, the portable path): the rule (RulesImpl.h,
//                      inlined, instantiated for this rule and cell count), then only the cells that
//                      changed are written
// The overload changes only where a cell changed, so its delta is summed over those cells alone.
// Checks that can fire only rarely (a result over INT32_MAX, a write into a missing leaf) run only
// when the pass or the anchor allows them. The helpers are always inlined: the pass is one loop per
// instantiation, with the pass's totals in registers. The result is bit-identical on every path
// (tests/TestKernel.cc runs each on the same grids; tests/TestGolden.cc pins whole runs).
//
// Two builds of the pass (processRangeBody): the baseline one (processRangeT), and one compiled for
// AVX2 + BMI1/2 + POPCNT (processRangeAvx2, a target attribute on the wrapper alone), chosen at run
// time where the CPU has them (Cpu.h). The source is the same: the AVX2 build gains three-operand VEX
// forms (no register copies), BMI2 shifts and POPCNT, about 9 % of the pass's instructions. Only code
// inlined into the wrapper is compiled for AVX2; out-of-line OpenVDB and library functions stay
// baseline code. Tests and benchmarks may force a path (KernelTesting.h); the library never does.

#include "automaton/Kernel.h"

#include "automaton/BlockMasks.h"
#include "automaton/BlockSimd.h"
#include "automaton/Cpu.h"
#include "automaton/KernelTesting.h"
#include "automaton/OverFilter.h"
#include "automaton/RulesImpl.h"

#include <openvdb/openvdb.h>
#include <openvdb/tree/ValueAccessor.h>

#include <algorithm>
#include <climits>
#include <optional>

namespace vdbclay {
namespace automaton_internal {

namespace {

using openvdb::Coord;
using MassAcc = openvdb::tree::ValueAccessor<MassTree, false>;
using ObsAcc = openvdb::tree::ValueAccessor<const ObsTree, false>;

#define VDBCLAY_INLINE __attribute__((always_inline)) inline

/// Offsets of a block's corners c = dx + 2 dy + 4 dz from its first cell, in one leaf.
constexpr int kCornerOffset[8] = {0, 64, 8, 72, 1, 65, 9, 73};

/// Odd blocks that lie inside the anchor leaf (no local coordinate at -1): read like even blocks.
constexpr uint64_t kInsideOdd3 = ~(kX0 | kY0 | kZ0), kInsideOdd2 = ~(kX0 | kY0) & 0xFFFFull;

/// Loads the N cells of a block lying inside one leaf, first cell at @a d, into @a m (in corner
/// order); returns whether one is over @a tc. (The portable path.)
template <int N> VDBCLAY_INLINE bool loadInsideScalar(const int32_t* d, int32_t tc, int32_t* m)
{
    int32_t top = d[0];
    VDBCLAY_UNROLL
    for (int c = 0; c < N; ++c) {
        m[c] = d[kCornerOffset[c]];
        top = std::max(top, m[c]);
    }
    return top > tc;
}

/// Notes for sinkActive that block @a b was updated: its cells @a active (those that were or went
/// over Tc, or a superset) into @a act[corner], and the block into @a again when it may still hold
/// an over and a not-over cell (@a mayChange).
VDBCLAY_INLINE void noteUpdated(int b, uint32_t active, bool mayChange, uint64_t act[8], uint64_t& again)
{
    for (uint32_t x = active; x; x &= x - 1)
        act[__builtin_ctz(x)] |= uint64_t(1) << b;
    again |= uint64_t(mayChange) << b;
}

/// The cell at offset @a o of @a leaf went from 0 to positive: its voxel becomes active. Other
/// tasks may set bits in the same mask word (straddling blocks), hence the atomic OR.
VDBCLAY_INLINE void activate(MassLeaf* leaf, int o)
{
    auto& word = leaf->getValueMask().template getWord<uint64_t>(o >> 6);
    __atomic_fetch_or(&word, uint64_t(1) << (o & 63), __ATOMIC_RELAXED);
}

// ---- An item's leaves -----------------------------------------------------------------------------

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
    ls.missing = ls.tile = ls.obsAny = ls.obsTile = 0;
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
            if (ps.tile & from) ls.tile |= to;
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
            if (acc.getValue(o) != 0) ls.tile |= bit;
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

/// An item made ready one ahead of its block loop.
struct Prepared {
    const LeafSet* set;
    uint32_t need;     // the leaf slots its candidate blocks touch
    uint64_t bits;     // the candidates left by the filter; 0: nothing to do
    uint64_t tileBits; // the candidates that read a slot inside a tile: deferred, not run
};

/// The odd-phase blocks of an anchor that read a cell of leaf slot @a w (leafOrigin(anchor, w)):
/// those at local -1 along each axis whose bit @a w sets (BlockMasks.h).
constexpr uint64_t blocksReadingSlot(int w)
{
    return ((w & 1) ? kX0 : ~uint64_t(0)) & ((w & 2) ? kY0 : ~uint64_t(0)) & ((w & 4) ? kZ0 : ~uint64_t(0));
}

/// The odd-phase blocks reading any slot of @a slots.
inline uint64_t blocksReadingSlots(uint32_t slots)
{
    uint64_t m = 0;
    for (; slots; slots &= slots - 1)
        m |= blocksReadingSlot(__builtin_ctz(slots));
    return m;
}

/// The leaves of item @a w (the table's entry, or fetched into @a buf; @a prevBuf holds the previous
/// item's) and its candidates that hold a cell over Tc (@a filter, 3D). It reads only that item's own
/// cells, which no other item of the pass writes (blocks of one phase are disjoint), so preparing it
/// ahead gives the same result.
template <bool D3, int P>
VDBCLAY_INLINE Prepared prepareItem(const WorkItem& w, const LeafTable* table, FetchedLeaves& buf,
                                    const FetchedLeaves& prevBuf, MassAcc& acc, ObsAcc* oacc, bool portable,
                                    OverFilter filter, int32_t tc32)
{
    Prepared p;
    p.need = P == 1 ? neededLeaves<D3>(w.mask) : 1u;
    p.set = nullptr;
    if (table) p.set = w.entry != kNoEntry ? &table->entry(w.entry) : table->find(w.anchor);
    if (p.set) {
        buf.fetched = 0; // the next item cannot reuse this one's leaves from the buffer
    } else {
        p.set = fetchLeaves<D3, P>(buf, prevBuf, w.anchor, p.need, acc, oacc, !portable);
    }
    p.bits = w.mask;
    p.tileBits = 0;
    // Even blocks of a missing leaf: all 0, or all one tile's value (never over Tc: Automaton.cc), so
    // none can change.
    if (P == 0 && !p.set->data[0]) p.bits = 0;
    if (P == 1 && (p.set->tile & p.need)) {
        p.tileBits = p.bits & blocksReadingSlots(p.set->tile & p.need);
        p.bits &= ~p.tileBits;
    }
    if (D3 && filter != OverFilter::None && p.bits)
        p.bits = filterBlocks<P>(filter, p.set->read, p.bits, tc32);
    return p;
}

// ---- The pieces of the pass -----------------------------------------------------------------------

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

/// What every block of one range shares.
struct PassConsts {
    const BlockTables* tab;
    CompiledRule rule;
    int64_t tc;
    int32_t tc32; // Tc clamped to int32 (a cell over it is over Tc)
    uint64_t prefix;
    bool mayOverflow, dryRun, portable;
    bool simd;   // the branches in registers may run (see processRangeBody)
    bool noting; // the sink records through sinkActive: per updated block, what it needs
#if defined(__SSE2__)
    __m128i tcV; // Tc in every lane
#endif
};

/// The pass's counts, in registers until the range ends.
struct Tally {
    uint64_t examined = 0, overTc = 0, updated = 0;
    int64_t overloadDelta = 0, maxWritten = 0;
};

/// The item whose blocks are running (scalars only, so that it lives in registers). Its leaves'
/// pointers and what its updated blocks leave for the sink are runItem's locals, passed to the
/// helpers by reference.
struct Item {
    size_t wi; // its index in the work list
    const LeafSet* ls;
    bool anyMissing;    // a leaf the mask's blocks touch is missing
    bool anyObs;        // one holds obstacles or lies in an obstacle tile
    int32_t ax, ay, az; // the anchor's first block corner
};

/// An item's leaves' pointers, read and written (LeafSet::read, data), copied into runItem's locals.
using ReadSlots = const int32_t* [8];
using DataSlots = int32_t* [8];

/// Per corner, the updated blocks of an item whose cell at that corner was or went over Tc (sinkActive).
using ActiveCorners = uint64_t[8];

/// Where a block's cells lie in the item's leaves.
struct BlockCells {
    const uint16_t* off; // corner c at offset off[c] of leaf slot lf[c] (the addressing tables)
    const uint8_t* lf;
    bool inside; // in the anchor's leaf: corner c at off[0] + kCornerOffset[c]
    bool pairs;  // corner k + 4 (one voxel up in z) is the int32 after corner k (no z boundary crossed)
    int slot(int c) const { return inside ? 0 : lf[c]; }
    int offset(int c) const { return inside ? off[0] + kCornerOffset[c] : off[c]; }
};

#if defined(__SSE2__)
/// A block in registers: its cells (corners 0-3, 4-7) and their compare with Tc.
struct Regs {
    __m128i lo, hi, gtLo, gtHi;
};
#endif

#if defined(__SSE2__)
/// Loads block @a at's cells into @a r (the SIMD paths); returns the corners over Tc (obstacles not
/// excluded), 0 when the block cannot change.
template <int N>
VDBCLAY_INLINE uint32_t loadRegisters(const PassConsts& k, const ReadSlots& read, const BlockCells& at,
                                      Regs& r)
{
    const uint16_t* off = at.off;
    const uint8_t* lf = at.lf;
    if (at.pairs) {
        if (at.inside) {
            const int32_t* d = read[0] + off[0];
            loadPairs<N>(d, d + 64, d + 8, d + 72, r.lo, r.hi);
        } else {
            loadPairs<N>(read[lf[0]] + off[0], read[lf[1]] + off[1], read[lf[2]] + off[2],
                         read[lf[3]] + off[3], r.lo, r.hi);
        }
    } else {
        // Straddling a z boundary: corner k and k + 4 lie in different leaves.
        r.lo = _mm_setr_epi32(read[lf[0]][off[0]], read[lf[1]][off[1]], read[lf[2]][off[2]],
                              read[lf[3]][off[3]]);
        if constexpr (N == 8)
            r.hi = _mm_setr_epi32(read[lf[4]][off[4]], read[lf[5]][off[5]], read[lf[6]][off[6]],
                                  read[lf[7]][off[7]]);
    }
    r.gtLo = _mm_cmpgt_epi32(r.lo, k.tcV);
    if constexpr (N == 8) r.gtHi = _mm_cmpgt_epi32(r.hi, k.tcV);
    return laneBits<N>(r.gtLo, r.gtHi);
}
#endif

/// Loads block @a at's cells into @a m (the portable path); false when none is over Tc (the block
/// cannot change).
template <int N>
VDBCLAY_INLINE bool loadScalar(const PassConsts& k, const ReadSlots& read, const BlockCells& at, int32_t* m)
{
    if (at.inside) return loadInsideScalar<N>(read[0] + at.off[0], k.tc32, m);
    int32_t top = 0;
    VDBCLAY_UNROLL
    for (int c = 0; c < N; ++c) {
        m[c] = read[at.lf[c]][at.off[c]];
        top = std::max(top, m[c]);
    }
    return top > k.tc32;
}

/// The cells of block @a at not blocked by an obstacle (bit c: corner c).
template <int N>
VDBCLAY_INLINE uint32_t validCells(const PassConsts& k, const LeafSet& ls, const BlockCells& at)
{
    uint32_t valid = (1u << N) - 1;
    if (at.pairs && !k.portable) {
        // Corner k and k + 4 are neighbouring bits of one word of the obstacle mask.
        uint32_t blocked = 0;
        VDBCLAY_UNROLL
        for (int c = 0; c < 4; ++c) {
            const ObsLeaf* ol = ls.obs[at.lf[c]];
            const int o = at.off[c];
            const uint32_t two =
                ol ? uint32_t(ol->getValueMask().template getWord<uint64_t>(o >> 6) >> (o & 63)) & 3u
                   : (((ls.obsTile >> at.lf[c]) & 1u) ? 3u : 0u);
            blocked |= ((two & 1u) << c) | ((two >> 1) << (c + 4));
        }
        valid &= ~blocked;
    } else {
        for (int c = 0; c < N; ++c) {
            const ObsLeaf* ol = ls.obs[at.lf[c]];
            if (ol ? ol->isValueOn(at.off[c]) : ((ls.obsTile >> at.lf[c]) & 1u)) valid &= ~(1u << c);
        }
    }
    return valid;
}

#if defined(__SSE2__)
/// Writes the block's new cells (@a s) back and turns active those that went from 0 to positive.
template <int N>
VDBCLAY_INLINE void storeRegisters(const Item& item, const DataSlots& data, const BlockCells& at,
                                   const Regs& r, const Surplus& s)
{
    if (N == 8 && at.pairs && (at.inside || !item.anyMissing)) {
        // Every cell of the block is this task's: write all 8, two to a store.
        int32_t* d0 = data[0] + at.off[0];
        int32_t *p0 = d0, *p1 = d0 + 64, *p2 = d0 + 8, *p3 = d0 + 72;
        if (!at.inside) {
            p0 = data[at.lf[0]] + at.off[0], p1 = data[at.lf[1]] + at.off[1];
            p2 = data[at.lf[2]] + at.off[2], p3 = data[at.lf[3]] + at.off[3];
        }
        const __m128i t01 = _mm_unpacklo_epi32(s.lo, s.hi); // c0 c4 c1 c5
        const __m128i t23 = _mm_unpackhi_epi32(s.lo, s.hi); // c2 c6 c3 c7
        _mm_storel_epi64(reinterpret_cast<__m128i*>(p0), t01);
        _mm_storel_epi64(reinterpret_cast<__m128i*>(p1), _mm_unpackhi_epi64(t01, t01));
        _mm_storel_epi64(reinterpret_cast<__m128i*>(p2), t23);
        _mm_storel_epi64(reinterpret_cast<__m128i*>(p3), _mm_unpackhi_epi64(t23, t23));
    } else {
        alignas(16) int32_t o32[8];
        storeCorners<N>(s.lo, s.hi, o32);
        uint32_t ch = changedCells<N>(r.lo, r.hi, s.lo, s.hi);
        while (ch) {
            const int c = __builtin_ctz(ch);
            ch &= ch - 1;
            data[at.slot(c)][at.offset(c)] = o32[c];
        }
    }
    // 0 -> positive: the voxel becomes active (rare: clay flowing into empty cells).
    const __m128i z = _mm_setzero_si128();
    uint32_t fresh = laneBits<N>(_mm_cmpeq_epi32(r.lo, z), _mm_cmpeq_epi32(r.hi, z)) & s.grow;
    while (fresh) {
        const int c = __builtin_ctz(fresh);
        fresh &= fresh - 1;
        activate(item.ls->leaf[at.slot(c)], at.offset(c));
    }
}

/// Block @a b in registers through prorata's or sorted's branches (BlockSimd.h). True when it is
/// done with (unchanged, written, or deferred: its update flows into a missing leaf); false when it
/// is in a branch only the scalar rule runs.
template <Rule R, int N, int P, typename Hash>
VDBCLAY_INLINE bool updateInRegisters(const PassConsts& k, const Item& item, const DataSlots& data,
                                      const BlockCells& at, const Regs& r, uint32_t overCells, uint32_t valid,
                                      const Hash& hash, int b, uint64_t& changed, uint64_t& again,
                                      ActiveCorners& act, Tally& t, PassTotals& tot)
{
    Surplus sp;
    Branch br = surplusBranch<N>(r.lo, r.hi, r.gtLo, r.gtHi, overCells, valid, k.tc32, hash, sp);
    if (br == Branch::Unchanged) return true;
    if constexpr (R == Rule::Prorata) {
        if (br == Branch::Rule && roomBranch<N>(r.lo, r.hi, overCells, valid, k.tc32, hash, sp))
            br = Branch::Done;
    }
    if (br != Branch::Done) return false;
    if (P == 1 && item.anyMissing && !at.inside) {
        const uint32_t ch = changedCells<N>(r.lo, r.hi, sp.lo, sp.hi);
        bool missing = false;
        for (int c = 0; c < N; ++c)
            if (((ch >> c) & 1u) && !data[at.lf[c]]) missing = true;
        if (missing) {
            tot.deferred.push_back(PassTotals::Deferred{uint32_t(item.wi), uint8_t(b), uint8_t(ch)});
            return true;
        }
    }
    storeRegisters<N>(item, data, at, r, sp);
    t.overloadDelta += sp.overDelta;
    t.maxWritten = std::max(t.maxWritten, sp.maxOut);
    ++t.updated;
    changed |= uint64_t(1) << b;
    if (k.noting) noteUpdated(b, sp.active, sp.again, act, again);
    return true;
}
#endif

/// Block @a b (cells @a m, in memory) through the scalar rule: checked, deferred, or written back.
template <Rule R, int N, int P, typename Hash>
VDBCLAY_INLINE void updateScalar(const PassConsts& k, const Item& item, const DataSlots& data,
                                 const BlockCells& at, const int32_t* m, uint32_t valid, const Hash& hash,
                                 int b, uint64_t& changedBlocks, uint64_t& again, ActiveCorners& act,
                                 Tally& t, PassTotals& tot)
{
    int64_t out[8];
    const uint32_t changed = rules_internal::repartitionT<R, N>(k.rule, m, valid, hash, out);
    if (!changed) return;
    // Both checks can only fire rarely: a result over INT32_MAX needs a cell over INT32_MAX / 8
    // somewhere (mayOverflow), and a write into a missing leaf needs one of the fetched leaves to
    // be missing (clay flowing into space the grid has not grown; never on even steps, whose blocks
    // lie in the anchor's leaf, which exists).
    bool fits = true, missing = false;
    if (k.mayOverflow || (P == 1 && item.anyMissing)) {
        for (int c = 0; c < N; ++c) {
            if (!((changed >> c) & 1u)) continue;
            if (out[c] > INT32_MAX) fits = false;
            if (!data[at.lf[c]]) missing = true;
        }
    }
    if (!fits) {
        if (!tot.overflow || item.wi < tot.overflowItem) {
            tot.overflow = true;
            tot.overflowItem = item.wi;
            tot.overflowBit = b;
        }
        return;
    }
    if (k.dryRun) return;
    if (missing) {
        tot.deferred.push_back(PassTotals::Deferred{uint32_t(item.wi), uint8_t(b), uint8_t(changed)});
        return;
    }
    // Only changed cells move the overload (an unchanged cell contributes 0).
    uint32_t ch = changed;
    while (ch) {
        const int c = __builtin_ctz(ch);
        ch &= ch - 1;
        t.overloadDelta += std::max<int64_t>(out[c] - k.tc, 0) - std::max<int64_t>(m[c] - k.tc, 0);
        const int li = at.slot(c), o = at.offset(c);
        data[li][o] = int32_t(out[c]);
        t.maxWritten = std::max(t.maxWritten, out[c]);
        if (m[c] == 0) activate(item.ls->leaf[li], o);
    }
    ++t.updated;
    changedBlocks |= uint64_t(1) << b;
    if (k.noting) {
        uint32_t overBefore = 0, overAfter = 0;
        for (int c = 0; c < N; ++c) {
            overBefore |= uint32_t(m[c] > k.tc) << c;
            overAfter |= uint32_t(out[c] > k.tc) << c;
        }
        noteUpdated(b, overBefore | overAfter, (overAfter & valid) && (valid & ~overAfter & ((1u << N) - 1)),
                    act, again);
    }
}

/// Candidate block @a b of the item: loaded, skipped unless a cell is over Tc, updated.
template <Rule R, bool D3, int P>
VDBCLAY_INLINE void runBlock(const PassConsts& k, const Item& item, const ReadSlots& read,
                             const DataSlots& data, int b, uint64_t& changed, uint64_t& again,
                             ActiveCorners& act, Tally& t, PassTotals& tot)
{
    constexpr int N = D3 ? 8 : 4;
    constexpr uint64_t kInsideOdd = D3 ? kInsideOdd3 : kInsideOdd2;
    BlockCells at;
    at.off = k.tab->offset[D3][P][b];
    at.lf = k.tab->leaf[D3][P][b];
    // Even blocks, and odd blocks not reaching into a lower neighbour, lie in the anchor's leaf at
    // constant offsets; the others go through the tables.
    at.inside = P == 0 || ((kInsideOdd >> b) & 1u);
    // Blocks that do not straddle a z boundary (all but the odd blocks with bz = 0 in 3D) hold each
    // corner k's z + 1 neighbour (corner k + 4) in the next int32.
    at.pairs = at.inside || !D3 || (b >> 4) != 0;
    alignas(16) int32_t m[8];
    uint32_t overCells = 0; // corners over Tc (obstacles not yet excluded); 0 on the portable path
    uint32_t valid;
#if defined(__SSE2__)
    Regs r;
    r.lo = r.hi = r.gtLo = r.gtHi = _mm_setzero_si128();
    if (!k.portable) {
        overCells = loadRegisters<N>(k, read, at, r);
        if (!overCells) return;
        valid = item.anyObs ? validCells<N>(k, *item.ls, at) : (1u << N) - 1;
        ++t.overTc;
        // A block with no valid over cell or no valid under cell is unchanged under every rule
        // (Rules.h): the compare already tells, before the hash or the rule is set up.
        if (!(overCells & valid) || !(valid & ~overCells & ((1u << N) - 1))) return;
    } else
#endif
    {
        if (!loadScalar<N>(k, read, at, m)) return;
        valid = item.anyObs ? validCells<N>(k, *item.ls, at) : (1u << N) - 1;
        ++t.overTc;
    }
    const BlockHash<D3> hash{k.prefix, item.ax, item.ay, item.az, b};
#if defined(__SSE2__)
    constexpr bool kSurplusRule = R == Rule::Prorata || R == Rule::Sorted;
    if (kSurplusRule && k.simd &&
        updateInRegisters<R, N, P>(k, item, data, at, r, overCells, valid, hash, b, changed, again, act, t,
                                   tot))
        return;
    if (!k.portable) storeCorners<N>(r.lo, r.hi, m); // the rule reads the cells from memory
#endif
    updateScalar<R, N, P>(k, item, data, at, m, valid, hash, b, changed, again, act, t, tot);
}

/// Item @a w's candidate blocks (@a cur, prepared): updated, then its changes recorded in @a sink.
template <Rule R, bool D3, int P>
VDBCLAY_INLINE void runItem(const PassConsts& k, WorkItem& w, size_t wi, const Prepared& cur,
                            const DenseSink* sink, Tally& t, PassTotals& tot)
{
    constexpr int kSlots = P == 1 ? (D3 ? 8 : 4) : 1;
    const LeafSet& ls = *cur.set;
    // The slots' pointers in locals (two cache lines of the set; one slot on the even phase): the
    // loop's stores may alias memory, so read through the set they would be reloaded.
    const int32_t* read[8];
    int32_t* data[8];
    for (int s = 0; s < kSlots; ++s) {
        read[s] = ls.read[s];
        data[s] = ls.data[s];
    }
    Item item;
    item.wi = wi;
    item.ls = &ls;
    item.anyMissing = (ls.missing & cur.need) != 0;
    item.anyObs = (ls.obsAny & cur.need) != 0;
    item.ax = w.anchor.x() - P;
    item.ay = w.anchor.y() - P;
    item.az = D3 ? w.anchor.z() - P : 0;
    // The blocks updated; for the sink (sinkActive) those that may still hold an over and a not-over
    // cell, and per updated block its cells that were or went over Tc (corners: their union).
    uint64_t changed = 0, again = 0, act[8] = {0, 0, 0, 0, 0, 0, 0, 0};
    for (uint64_t bits = cur.bits; bits; bits &= bits - 1)
        runBlock<R, D3, P>(k, item, read, data, __builtin_ctzll(bits), changed, again, act, t, tot);
    w.changed = changed;
    if (changed && sink && w.entry != kNoEntry) {
        if (k.noting)
            sinkActive<P, D3>(*sink, w.entry, again, act);
        else
            sinkChanges<P, D3>(*sink, w.entry, changed);
    }
}

/// The instructions a build of the pass may use: the target's baseline (SSE2 on x86-64), or AVX2 with
/// BMI1, BMI2 and POPCNT (processRangeAvx2, chosen at run time where the CPU has them).
enum class Isa { Base, Avx2 };

/// The pass (see the top of this file). Inlined into one function per instruction set below; it
/// calls nothing that needs more than the baseline, so the same source compiles for both.
template <Rule R, bool D3, int P, Isa I>
VDBCLAY_INLINE void processRangeBody(const PassInput& in, const kernel_testing::Paths& paths, WorkItem* work,
                                     size_t begin, size_t end, PassTotals& tot)
{
    PassConsts k;
    k.tab = &blockTables();
    k.rule = in.rule;
    k.tc = k.rule.threshold;
    k.tc32 = int32_t(std::min<int64_t>(k.tc, INT32_MAX));
    k.prefix = rules_internal::stepPrefix(in.step, in.seed);
    k.mayOverflow = in.mayOverflow;
    k.dryRun = in.dryRun;
    k.portable = paths.portable;
#if defined(__SSE2__)
    // The surplus branch in int32 lanes (surplusBranch) is exact when no sum can wrap: with no cell
    // over INT32_MAX / 8 (!mayOverflow), E < 8 * 2^28 = 2^31; with Tc <= 2^27, A <= 8 Tc <= 2^30;
    // every result is at most the block's sum. Otherwise, and on the portable path, the rule runs.
    k.simd = !k.portable && !k.mayOverflow && !k.dryRun && k.tc <= (int64_t(1) << 27);
    k.tcV = _mm_set1_epi32(k.tc32);
#else
    k.simd = false;
#endif
    const OverFilter filter = (D3 && !k.portable) ? resolveFilter(paths.filter) : OverFilter::None;
    MassAcc acc(*in.tree);
    const LeafTable* table = in.table && in.table->valid() ? in.table : nullptr;
    std::optional<ObsAcc> oacc;
    if (in.obstacles) oacc.emplace(*in.obstacles);
    ObsAcc* obsAcc = oacc ? &*oacc : nullptr;
    // Two buffers for the accessor path: the next item's leaves are fetched while this item's are in use.
    FetchedLeaves fetched[2];
    const DenseSink* sink = k.dryRun ? nullptr : in.sink;
    // Per updated block, what sinkActive needs: only when it records (a sink, pruning on).
    k.noting = sink && in.prune;
    Tally t;
    // Item wi + 1 is prepared before item wi's blocks run (a software pipeline): the filter's loads
    // are the first touch of the item's cells (from L2, or L3 when the clay is spread wide), and
    // issued ahead of item wi's block loop they do not wait behind its branches.
    Prepared next{};
    if (begin < end)
        next = prepareItem<D3, P>(work[begin], table, fetched[0], fetched[1], acc, obsAcc, k.portable, filter,
                                  k.tc32);
    for (size_t wi = begin; wi < end; ++wi) {
        WorkItem& w = work[wi];
        const Prepared cur = next;
        if (wi + 1 < end) {
            const size_t b = (wi + 1 - begin) & 1;
            next = prepareItem<D3, P>(work[wi + 1], table, fetched[b], fetched[1 - b], acc, obsAcc,
                                      k.portable, filter, k.tc32);
        }
        w.changed = 0;
        if constexpr (I == Isa::Avx2)
            t.examined += uint64_t(__builtin_popcountll(w.mask)); // one POPCNT
        else
            t.examined += popcount64(w.mask);
        if (cur.bits) runItem<R, D3, P>(k, w, wi, cur, sink, t, tot);
        if (P == 1 && cur.tileBits && !k.dryRun) {
            for (uint64_t bits = cur.tileBits; bits; bits &= bits - 1)
                tot.deferred.push_back(PassTotals::Deferred{uint32_t(wi), uint8_t(__builtin_ctzll(bits)), 0});
        }
    }
    tot.examined += t.examined;
    tot.overTc += t.overTc;
    tot.updated += t.updated;
    tot.overloadDelta += t.overloadDelta;
    tot.maxWritten = std::max(tot.maxWritten, t.maxWritten);
}

template <Rule R, bool D3, int P>
__attribute__((noinline)) void processRangeT(const PassInput& in, const kernel_testing::Paths& paths,
                                             WorkItem* work, size_t begin, size_t end, PassTotals& tot)
{
    processRangeBody<R, D3, P, Isa::Base>(in, paths, work, begin, end, tot);
}

#if defined(VDBCLAY_HAVE_AVX2_BUILD)
// The same pass compiled for AVX2 (three-operand VEX forms: no register copies; BMI2 shifts; POPCNT).
// The target attribute covers only this function and what is inlined into it: OpenVDB's and the
// standard library's out-of-line functions stay baseline code, so nothing AVX2 leaks into symbols
// other translation units share.
template <Rule R, bool D3, int P>
__attribute__((noinline, target("avx2,bmi,bmi2,popcnt"))) void
processRangeAvx2(const PassInput& in, const kernel_testing::Paths& paths, WorkItem* work, size_t begin,
                 size_t end, PassTotals& tot)
{
    processRangeBody<R, D3, P, Isa::Avx2>(in, paths, work, begin, end, tot);
}
#endif

template <Rule R, bool D3, int P>
void runPass(const PassInput& in, const kernel_testing::Paths& paths, WorkItem* work, size_t begin,
             size_t end, PassTotals& tot)
{
#if defined(VDBCLAY_HAVE_AVX2_BUILD)
    if (paths.avx2 && !paths.portable && cpuHasKernelAvx2())
        return processRangeAvx2<R, D3, P>(in, paths, work, begin, end, tot);
#endif
    processRangeT<R, D3, P>(in, paths, work, begin, end, tot);
}

template <Rule R>
void dispatch(const PassInput& in, const kernel_testing::Paths& paths, WorkItem* work, size_t begin,
              size_t end, PassTotals& tot)
{
    if (in.is3D) {
        if (in.phase)
            runPass<R, true, 1>(in, paths, work, begin, end, tot);
        else
            runPass<R, true, 0>(in, paths, work, begin, end, tot);
    } else {
        if (in.phase)
            runPass<R, false, 1>(in, paths, work, begin, end, tot);
        else
            runPass<R, false, 0>(in, paths, work, begin, end, tot);
    }
}

void processRangeOn(const PassInput& in, const kernel_testing::Paths& paths, WorkItem* work, size_t begin,
                    size_t end, PassTotals& tot)
{
    switch (in.rule.rule) {
    case Rule::Arata: dispatch<Rule::Arata>(in, paths, work, begin, end, tot); break;
    case Rule::Bingham: dispatch<Rule::Bingham>(in, paths, work, begin, end, tot); break;
    case Rule::Sorted: dispatch<Rule::Sorted>(in, paths, work, begin, end, tot); break;
    case Rule::Prorata: dispatch<Rule::Prorata>(in, paths, work, begin, end, tot); break;
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
    processRangeOn(in, kernel_testing::Paths(), work, begin, end, tot);
}

namespace kernel_testing {

void processRange(const PassInput& in, const Paths& paths, WorkItem* work, size_t begin, size_t end,
                  PassTotals& tot)
{
    processRangeOn(in, paths, work, begin, end, tot);
}

bool avx2Pass()
{
    return cpuHasKernelAvx2();
}

} // namespace kernel_testing

} // namespace automaton_internal
} // namespace vdbclay
