// The over-cell filter: which of an item's candidate blocks hold a cell over Tc, found a column of
// 4 blocks at a time before the per-block work (3D; no OpenVDB in this header).
//
// Most candidate blocks hold no cell over Tc (press48: 4.4 M of 5.7 M examined), and the block loop
// spends ~40 instructions on each before it finds that out. The filter decides the item's candidates
// a column at a time (BlockMasks.h, ColumnTables: the 4 blocks with the same bx, by lie in 4 z-rows of
// 8 consecutive cells): 4 row compares against Tc ORed, one movemask, one fold table lookup give the
// column's blocks holding an over cell; on the odd phase the cells z = -1 of the block bz = 0 come
// from the -z neighbours (4 scalar loads, only when that block is a candidate). The result is exact
// (a block is kept iff one of its cells is over Tc, obstacles not excluded, as the block loop tests),
// so the loop skips exactly the blocks it would find without an over cell; blocksVisited still
// counts every candidate. AVX2 (one row per register) where the CPU has it, chosen at run time (Cpu.h);
// SSE2 (two registers a row) otherwise; 3D only (a 2D block's cells are 8 int32 apart: no row to compare).
//
// Only the item's own cells are read, as in the block loop: on the odd phase a row's z = 7 cell
// belongs to the +z anchor's block, which another task may be writing at the same time, so it is
// left out of the load (AVX2: a masked load, whose masked lane is not accessed; SSE2: z = 4-6 loaded
// as 8 + 4 bytes), and of the -z rows only the z = 7 cells are read.
#pragma once

#include "automaton/Cpu.h"

#include <cstdint>

namespace vdbclay {
namespace automaton_internal {

/// Which instructions the filter uses. Every choice gives the same result; the pass uses Auto, the
/// others are for tests and benchmarks (kernel_testing::Paths).
enum class OverFilter : uint8_t {
    Auto, // AVX2 where the CPU has it, else SSE2 (x86-64), else none
    Avx2, // AVX2 (falls back to SSE2 where the CPU lacks it)
    Sse2, // SSE2 (none where the build has no SSE2)
    None  // no filter: every candidate block is loaded and checked on its own
};

/// The filter @a f stands for on this machine and build (Avx2, Sse2 or None).
OverFilter resolveFilter(OverFilter f);

/// The filter Auto resolves to on this machine (Avx2, Sse2 or None).
inline OverFilter bestOverFilter()
{
    return resolveFilter(OverFilter::Auto);
}

/// The blocks of @a mask (phase @a phase, 3D) that hold a cell over @a tc, found by @a f column by
/// column; read[w] is leaf leafOrigin(anchor, w)'s values (512 int32, OpenVDB's order; on the even
/// phase only read[0] is used). In 2D, and with OverFilter::None, returns @a mask: the filter is 3D only.
uint64_t overBlocks(const int32_t* const read[8], uint64_t mask, int32_t tc, bool is3D, int phase,
                    OverFilter f);

// The filters of phase P, out of line (OverFilter.cc); the pass calls them through filterBlocks.
#if defined(__SSE2__)
template <int P> uint64_t overBlocksSse2(const int32_t* const read[8], uint64_t mask, int32_t tc);
#endif
#if defined(VDBCLAY_HAVE_AVX2_BUILD)
template <int P>
__attribute__((target("avx2"))) uint64_t overBlocksAvx2(const int32_t* const read[8], uint64_t mask,
                                                        int32_t tc);
#endif

/// overBlocks for phase P (3D) with @a f already resolved (resolveFilter).
template <int P>
inline uint64_t filterBlocks(OverFilter f, const int32_t* const read[8], uint64_t mask, int32_t tc)
{
#if defined(VDBCLAY_HAVE_AVX2_BUILD)
    if (f == OverFilter::Avx2) return overBlocksAvx2<P>(read, mask, tc);
#endif
#if defined(__SSE2__)
    if (f == OverFilter::Sse2) return overBlocksSse2<P>(read, mask, tc);
#endif
    (void)f, (void)read, (void)tc;
    return mask;
}

} // namespace automaton_internal
} // namespace vdbclay
