// Inline bodies of the block rules (see vdbclay/Rules.h for the contract). Included by Rules.cc
// and by the automaton's kernel, so the per-block work inlines into the hot loop.
#pragma once

#include "vdbclay/Rules.h"

#include <algorithm>
#include <cstdint>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

// Fixed-trip loops over a block's cells, fully unrolled (GCC and Clang both read this pragma).
#define VDBCLAY_UNROLL _Pragma("GCC unroll 8")

namespace vdbclay {
namespace rules_internal {

inline uint64_t mix64(uint64_t z)
{
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

/// The part of a block's hash that depends only on the step and the seed: the kernel computes it
/// once per step and finishes it per block (finishHash), two mixes instead of four.
inline uint64_t stepPrefix(uint64_t step, uint64_t seed)
{
    const uint64_t h = mix64(seed + 0x9E3779B97F4A7C15ull);
    return mix64(h ^ (step * 0xD1B54A32D192ED03ull));
}

__attribute__((always_inline)) inline uint64_t finishHash(uint64_t prefix, int32_t x, int32_t y, int32_t z)
{
    const uint64_t h = mix64(prefix ^ uint64_t(uint32_t(x)));
    return mix64(h ^ ((uint64_t(uint32_t(y)) << 32) | uint64_t(uint32_t(z))));
}

__attribute__((always_inline)) inline uint64_t hashKey(const BlockKey& k)
{
    return finishHash(stepPrefix(k.step, k.seed), k.x, k.y, k.z);
}

/// Where a rule gets its block's hash, computed only when a remainder or a tie needs it.
struct KeyHash { // from a whole BlockKey (the public repartitionBlock)
    const BlockKey& key;
    uint64_t operator()() const { return hashKey(key); }
};
struct PrefixHash { // from the step's prefix and the block's corner (the automaton's kernel)
    uint64_t prefix;
    int32_t x, y, z;
    uint64_t operator()() const { return finishHash(prefix, x, y, z); }
};

/// Bits set in a block's cell mask (at most 8 bits; no popcnt instruction needed).
inline int popcount8(uint32_t m)
{
    static constexpr uint8_t kBits[16] = {0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4};
    return kBits[m & 15u] + kBits[(m >> 4) & 15u];
}

/// The cells of @a cells (mask of N bits) whose value in @a out is below @a tc.
template <int N>
__attribute__((always_inline)) inline uint32_t below(const int64_t* out, uint32_t cells, int64_t tc)
{
    uint32_t m = 0;
    VDBCLAY_UNROLL
    for (int i = 0; i < N; ++i)
        m |= uint32_t(out[i] < tc) << i;
    return m & cells;
}

/// Gives one unit to each of the first @a r cells of @a cells in the rotation that starts at cell
/// @a start; returns how many units are left (r minus the cells there were).
template <int N>
__attribute__((always_inline)) inline int64_t giveInRotation(int64_t r, uint32_t cells, int start,
                                                             int64_t* out)
{
    constexpr uint32_t kAll = (1u << N) - 1;
    // Rotate right by start: bit k is cell (start + k) mod N, so ascending bits follow the rotation.
    uint32_t rot = ((cells >> start) | (cells << ((N - start) & (N - 1)))) & kAll;
    while (rot && r > 0) {
        const int k = __builtin_ctz(rot);
        rot &= rot - 1;
        ++out[(start + k) & (N - 1)];
        --r;
    }
    return r;
}

/// Gives one unit to each of r distinct cells of @a under, visiting cells in a rotation that starts
/// at hash mod N (N is 4 or 8: a mask): first the cells whose new mass is still below Tc, then the
/// others (those at or above Tc after the first pass, which may include cells the first pass
/// filled to Tc).
template <int N>
__attribute__((always_inline)) inline void giveRemainder(int64_t r, uint32_t under, int64_t tc, uint64_t hash,
                                                         int64_t* out)
{
    if (r <= 0) return;
    const int start = int(hash & uint64_t(N - 1));
    r = giveInRotation<N>(r, below<N>(out, under, tc), start, out);
    if (r > 0) giveInRotation<N>(r, under & ~below<N>(out, under, tc), start, out);
}

/// a / b for non-negative operands, in 32 bits when both fit (several times cheaper than a 64-bit
/// division on common x86 cores, and the usual case: masses around Tc = 1000).
inline int64_t divide(int64_t a, int64_t b)
{
    if (uint64_t(a) <= UINT32_MAX && uint64_t(b) <= UINT32_MAX) return int64_t(uint32_t(a) / uint32_t(b));
    return int64_t(uint64_t(a) / uint64_t(b));
}

/// floor(a / d) for a cell count d in 1..8 without a division: a * ceil(2^35 / d) >> 35 is exact for
/// a < 2^32 (the error a * (M d - 2^35) / 2^35 stays below 1 / d... see TestRules), and a < 2^28
/// keeps the product in 64 bits. Larger amounts divide.
inline int64_t divideBySmall(int64_t a, int d)
{
    static constexpr uint64_t kMagic[9] = {0,
                                           (1ull << 35),
                                           (1ull << 35) / 2,
                                           ((1ull << 35) + 2) / 3,
                                           (1ull << 35) / 4,
                                           ((1ull << 35) + 4) / 5,
                                           ((1ull << 35) + 5) / 6,
                                           ((1ull << 35) + 6) / 7,
                                           (1ull << 35) / 8};
    if (uint64_t(a) < (1ull << 28)) return int64_t((uint64_t(a) * kMagic[d]) >> 35);
    return int64_t(uint64_t(a) / uint64_t(d));
}

/// Shares @a amount equally among the cells of @a under (nu of them), remainder by hash.
template <int N, typename Hash>
__attribute__((always_inline)) inline void shareEqually(int64_t amount, uint32_t under, int nu, int64_t tc,
                                                        const Hash& hash, int64_t* out)
{
    const int64_t share = divideBySmall(amount, nu);
    const int64_t r = amount - share * nu;
    VDBCLAY_UNROLL
    for (int i = 0; i < N; ++i) {
        if ((under >> i) & 1u) out[i] += share;
    }
    if (r) giveRemainder<N>(r, under, tc, hash(), out);
}

/// The cells of a block holding more than @a tc (bit i = cell i): SSE2 compares where the target
/// has it (every x86-64), a plain loop elsewhere.
template <int N> __attribute__((always_inline)) inline uint32_t overMask(const int32_t* mass, int32_t tc)
{
#if defined(__SSE2__)
    const __m128i t = _mm_set1_epi32(tc);
    uint32_t m = uint32_t(_mm_movemask_ps(
        _mm_castsi128_ps(_mm_cmpgt_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(mass)), t))));
    if constexpr (N == 8) {
        m |= uint32_t(_mm_movemask_ps(_mm_castsi128_ps(
                 _mm_cmpgt_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(mass + 4)), t))))
             << 4;
    }
    return m;
#else
    uint32_t m = 0;
    VDBCLAY_UNROLL
    for (int i = 0; i < N; ++i)
        m |= uint32_t(mass[i] > tc) << i;
    return m;
#endif
}

/// The rule @a R on one block of N cells (see vdbclay/Rules.h). The kernel instantiates it per rule
/// and dimension, so no switch runs per block. Unlike repartitionBlock, @a out is left unwritten
/// when the block has no over or no under cell (the result is then 0 and out is not needed).
template <Rule R, int N, typename Hash>
__attribute__((always_inline)) inline uint32_t repartitionT(const CompiledRule& rule, const int32_t* mass,
                                                            uint32_t valid, const Hash& hash, int64_t* out)
{
    const int64_t tc = rule.threshold;
    const uint32_t over = overMask<N>(mass, int32_t(rule.threshold)) & valid;
    const uint32_t under = valid & ~over;
    if (!over || !under) return 0;
    VDBCLAY_UNROLL
    for (int i = 0; i < N; ++i)
        out[i] = mass[i];
    const int nu = popcount8(under);

    if constexpr (R == Rule::Arata) {
        int64_t d = 0;
        VDBCLAY_UNROLL
        for (int i = 0; i < N; ++i) {
            if (!((over >> i) & 1u)) continue;
            // floor(alpha * m) in 32.32 fixed point; m < 2^31 and alpha < 2^32 so no wrap.
            int64_t dm = int64_t((uint64_t(mass[i]) * rule.alphaQ32) >> 32);
            if (dm < 1) dm = 1;
            out[i] -= dm;
            d += dm;
        }
        shareEqually<N>(d, under, nu, tc, hash, out);
    } else if constexpr (R == Rule::Bingham) {
        int64_t d = 0;
        VDBCLAY_UNROLL
        for (int i = 0; i < N; ++i) {
            if (!((over >> i) & 1u)) continue;
            d += out[i] - tc;
            out[i] = tc;
        }
        shareEqually<N>(d, under, nu, tc, hash, out);
    } else {
        int64_t e = 0, a = 0;
        VDBCLAY_UNROLL
        for (int i = 0; i < N; ++i) {
            if ((over >> i) & 1u) {
                e += out[i] - tc;
                out[i] = tc;
            } else if ((under >> i) & 1u) {
                a += tc - out[i];
            }
        }
        if (e > a) {
            // More excess than room (A may be 0): fill every room, share the surplus equally.
            VDBCLAY_UNROLL
            for (int i = 0; i < N; ++i) {
                if ((under >> i) & 1u) out[i] = tc;
            }
            shareEqually<N>(e - a, under, nu, tc, hash, out);
        } else if constexpr (R == Rule::Sorted) {
            // Fill the emptiest under cells first; equal masses in an order rotated by the hash.
            int order[8];
            int cnt = 0;
            const int start = int(hash() & uint64_t(N - 1));
            for (int k = 0; k < N; ++k) {
                const int i = (start + k) & (N - 1);
                if ((under >> i) & 1u) order[cnt++] = i;
            }
            for (int s = 1; s < cnt; ++s) { // stable insertion sort by mass
                const int v = order[s];
                int t = s;
                while (t > 0 && out[order[t - 1]] > out[v]) {
                    order[t] = order[t - 1];
                    --t;
                }
                order[t] = v;
            }
            for (int s = 0; s < cnt && e > 0; ++s) {
                const int i = order[s];
                const int64_t take = std::min(tc - out[i], e);
                out[i] += take;
                e -= take;
            }
        } else {
            // Pro rata of room. E <= A and room <= Tc, so E * room <= A * Tc, which is at most
            // about 1.2 * 2^62 for int32 masses and n <= 8 (see Rules.cc): uint64 never wraps.
            // Common case (E * Tc < 2^32): one reciprocal of A for the block, each share from a
            // multiply, corrected to the exact floor (double's error is far below one unit there).
            int64_t given = 0;
            if (uint64_t(e) * uint64_t(tc) <= UINT32_MAX) {
                const double inv = 1.0 / double(a);
                VDBCLAY_UNROLL
                for (int i = 0; i < N; ++i) {
                    if (!((under >> i) & 1u)) continue;
                    const uint64_t x = uint64_t(e) * uint64_t(tc - out[i]);
                    uint64_t q = uint64_t(double(x) * inv);
                    if (q * uint64_t(a) > x)
                        --q;
                    else if ((q + 1) * uint64_t(a) <= x)
                        ++q;
                    out[i] += int64_t(q);
                    given += int64_t(q);
                }
            } else {
                VDBCLAY_UNROLL
                for (int i = 0; i < N; ++i) {
                    if (!((under >> i) & 1u)) continue;
                    const int64_t room = tc - out[i];
                    const int64_t share = divide(int64_t(uint64_t(e) * uint64_t(room)), a);
                    out[i] += share;
                    given += share;
                }
            }
            if (e - given) giveRemainder<N>(e - given, under, tc, hash(), out);
        }
    }

    uint32_t changed = 0;
    VDBCLAY_UNROLL
    for (int i = 0; i < N; ++i)
        changed |= uint32_t(out[i] != mass[i]) << i;
    return changed;
}

/// The rule picked at run time (the public repartitionBlock, tests and benchmarks). @a n is 4 or 8.
inline uint32_t repartition(const CompiledRule& rule, int n, const int32_t* mass, uint32_t valid,
                            const BlockKey& key, int64_t* out)
{
    for (int i = 0; i < n; ++i)
        out[i] = mass[i]; // the result when nothing moves
    const KeyHash h{key};
    const bool n8 = n == 8;
    switch (rule.rule) {
    case Rule::Arata:
        return n8 ? repartitionT<Rule::Arata, 8>(rule, mass, valid, h, out)
                  : repartitionT<Rule::Arata, 4>(rule, mass, valid, h, out);
    case Rule::Bingham:
        return n8 ? repartitionT<Rule::Bingham, 8>(rule, mass, valid, h, out)
                  : repartitionT<Rule::Bingham, 4>(rule, mass, valid, h, out);
    case Rule::Sorted:
        return n8 ? repartitionT<Rule::Sorted, 8>(rule, mass, valid, h, out)
                  : repartitionT<Rule::Sorted, 4>(rule, mass, valid, h, out);
    case Rule::Prorata:
        return n8 ? repartitionT<Rule::Prorata, 8>(rule, mass, valid, h, out)
                  : repartitionT<Rule::Prorata, 4>(rule, mass, valid, h, out);
    }
    return 0;
}

} // namespace rules_internal
} // namespace vdbclay
