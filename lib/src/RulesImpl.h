// Inline bodies of the block rules (see vdbclay/Rules.h for the contract). Included by Rules.cc
// and by the automaton's kernel, so the per-block work inlines into the hot loop.
#pragma once

#include "vdbclay/Rules.h"

#include <algorithm>
#include <cstdint>

namespace vdbclay {
namespace rules_internal {

inline uint64_t mix64(uint64_t z)
{
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

__attribute__((always_inline)) inline uint64_t hashKey(const BlockKey& k)
{
    uint64_t h = mix64(k.seed + 0x9E3779B97F4A7C15ull);
    h = mix64(h ^ (k.step * 0xD1B54A32D192ED03ull));
    h = mix64(h ^ uint64_t(uint32_t(k.x)));
    h = mix64(h ^ ((uint64_t(uint32_t(k.y)) << 32) | uint64_t(uint32_t(k.z))));
    return h;
}

/// Gives one unit to each of r distinct cells of @a under, visiting cells in a rotation that starts
/// at hash % n: first the cells whose new mass is still below Tc, then the others.
__attribute__((always_inline)) inline void giveRemainder(int64_t r, uint32_t under, int n, int64_t tc, uint64_t hash, int64_t* out)
{
    if (r <= 0) return;
    const int start = int(hash % uint64_t(n));
    for (int pass = 0; pass < 2 && r > 0; ++pass) {
        for (int k = 0; k < n && r > 0; ++k) {
            int i = start + k;
            if (i >= n) i -= n;
            if (!((under >> i) & 1u)) continue;
            const bool hasRoom = out[i] < tc;
            if (hasRoom == (pass == 0)) {
                ++out[i];
                --r;
            }
        }
    }
}

/// a / b for non-negative operands, in 32 bits when both fit (several times cheaper than a 64-bit
/// division on common x86 cores, and the usual case: masses around Tc = 1000).
inline int64_t divide(int64_t a, int64_t b)
{
    if (uint64_t(a) <= UINT32_MAX && uint64_t(b) <= UINT32_MAX) return int64_t(uint32_t(a) / uint32_t(b));
    return int64_t(uint64_t(a) / uint64_t(b));
}

/// Shares @a amount equally among the cells of @a under (nu of them), remainder by hash.
__attribute__((always_inline)) inline void shareEqually(int64_t amount, uint32_t under, int nu, int n, int64_t tc,
                         const BlockKey& key, int64_t* out)
{
    const int64_t share = divide(amount, nu);
    const int64_t r = amount - share * nu;
    for (int i = 0; i < n; ++i) {
        if ((under >> i) & 1u) out[i] += share;
    }
    if (r) giveRemainder(r, under, n, tc, hashKey(key), out);
}

// Forced inline: the kernel calls this once per candidate block; as a call it was 61 % of a
// profile of the press benchmark (docs/PERFORMANCE.md).
__attribute__((always_inline)) inline uint32_t repartition(const CompiledRule& rule, int n,
                                                           const int32_t* mass, uint32_t valid,
                                                           const BlockKey& key, int64_t* out)
{
    const int64_t tc = rule.threshold;
    uint32_t over = 0, under = 0;
    int nu = 0;
    for (int i = 0; i < n; ++i) {
        out[i] = mass[i];
        if (!((valid >> i) & 1u)) continue;
        if (mass[i] > tc) {
            over |= 1u << i;
        } else {
            under |= 1u << i;
            ++nu;
        }
    }
    if (!over || !under) return 0;

    switch (rule.rule) {
    case Rule::Arata: {
        int64_t d = 0;
        for (int i = 0; i < n; ++i) {
            if (!((over >> i) & 1u)) continue;
            // floor(alpha * m) in 32.32 fixed point; m < 2^31 and alpha < 2^32 so no wrap.
            int64_t dm = int64_t((uint64_t(mass[i]) * rule.alphaQ32) >> 32);
            if (dm < 1) dm = 1;
            out[i] -= dm;
            d += dm;
        }
        shareEqually(d, under, nu, n, tc, key, out);
        break;
    }
    case Rule::Bingham: {
        int64_t d = 0;
        for (int i = 0; i < n; ++i) {
            if (!((over >> i) & 1u)) continue;
            d += out[i] - tc;
            out[i] = tc;
        }
        shareEqually(d, under, nu, n, tc, key, out);
        break;
    }
    case Rule::Sorted:
    case Rule::Prorata: {
        int64_t e = 0, a = 0;
        for (int i = 0; i < n; ++i) {
            if ((over >> i) & 1u) {
                e += out[i] - tc;
                out[i] = tc;
            } else if ((under >> i) & 1u) {
                a += tc - out[i];
            }
        }
        if (e > a) {
            // More excess than room (A may be 0): fill every room, share the surplus equally.
            for (int i = 0; i < n; ++i) {
                if ((under >> i) & 1u) out[i] = tc;
            }
            shareEqually(e - a, under, nu, n, tc, key, out);
        } else if (rule.rule == Rule::Sorted) {
            // Fill the emptiest under cells first; equal masses in an order rotated by the hash.
            int order[8];
            int cnt = 0;
            const uint64_t h = hashKey(key);
            const int start = int(h % uint64_t(n));
            for (int k = 0; k < n; ++k) {
                int i = start + k;
                if (i >= n) i -= n;
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
            int64_t given = 0;
            for (int i = 0; i < n; ++i) {
                if (!((under >> i) & 1u)) continue;
                const int64_t room = tc - out[i];
                const int64_t share = divide(int64_t(uint64_t(e) * uint64_t(room)), a);
                out[i] += share;
                given += share;
            }
            if (e - given) giveRemainder(e - given, under, n, tc, hashKey(key), out);
        }
        break;
    }
    }

    uint32_t changed = 0;
    for (int i = 0; i < n; ++i) {
        if (out[i] != mass[i]) changed |= 1u << i;
    }
    return changed;
}

} // namespace rules_internal
} // namespace vdbclay
