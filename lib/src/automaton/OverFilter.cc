// The over-cell filter (see OverFilter.h for what it decides and why it is exact).
#include "automaton/OverFilter.h"

#include "automaton/BlockMasks.h"

#if defined(__x86_64__) || defined(__SSE2__)
#include <immintrin.h>
#endif

#include <algorithm>

namespace vdbclay {
namespace automaton_internal {

namespace {

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

} // namespace

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
template uint64_t overBlocksSse2<0>(const int32_t* const read[8], uint64_t mask, int32_t tc);
template uint64_t overBlocksSse2<1>(const int32_t* const read[8], uint64_t mask, int32_t tc);
#endif

#if defined(VDBCLAY_HAVE_AVX2_BUILD)
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
template uint64_t overBlocksAvx2<0>(const int32_t* const read[8], uint64_t mask, int32_t tc);
template uint64_t overBlocksAvx2<1>(const int32_t* const read[8], uint64_t mask, int32_t tc);
#endif

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

uint64_t overBlocks(const int32_t* const read[8], uint64_t mask, int32_t tc, bool is3D, int phase,
                    OverFilter f)
{
    if (!is3D) return mask;
    f = resolveFilter(f);
    return phase ? filterBlocks<1>(f, read, mask, tc) : filterBlocks<0>(f, read, mask, tc);
}

} // namespace automaton_internal
} // namespace vdbclay
