// A Margolus block of 4 or 8 cells in two SSE2 registers (corners 0-3 and 4-7), and prorata's and
// sorted's branches computed there (no OpenVDB in this header; every x86-64 has SSE2).
//
// A settling press spends most of its updates in prorata's and sorted's E > A branch (every room
// filled, the surplus shared equally). There the block stays in two SSE2 registers from load to
// store (surplusBranch): the compare with Tc that found the over cells is the over lanes (no lane
// table unless an obstacle blocks a cell), E and S = E - A come out of one reduction, the result is
// Tc + share on the under lanes (+1 on the remainder's), and the overload delta is -A and the
// largest value Tc + share (+1), both without a per-cell loop. Prorata's room branch (E <= A)
// follows in roomBranch. The cells go to memory only when the scalar rule runs, and no scalar store
// is reloaded as a vector (that would stall on store forwarding). Each branch gives exactly
// repartitionT's result (RulesImpl.h); tests/TestKernel.cc compares them on the same grids.
#pragma once

#include "automaton/RulesImpl.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include <algorithm>
#include <cstdint>

namespace vdbclay {
namespace automaton_internal {

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

/// What a branch in registers did: Done when it applied its branch, Unchanged when the block has no
/// over or no under cell (the rule would change nothing), Rule when the block is in another branch
/// (the caller runs the rule). The surplus branch (E > A: every room filled, the surplus E - A shared
/// equally among the under cells, the remainder to the first under cells of the hash's rotation) is
/// exactly repartitionT's result in int32 lanes (Kernel.cc, processRangeBody, says when int32 cannot wrap).
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

} // namespace automaton_internal
} // namespace vdbclay
