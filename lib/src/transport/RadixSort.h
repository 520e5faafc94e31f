// The global transport's sorts of cell lists: by coordinate (MIC(0)'s row order, Poisson.h) and by
// decreasing potential (the routing's order, Routing.h). Both orders are strict total orders on the
// cells (ties broken by coordinate, and no two cells share one), so every sort gives one sequence:
// a stable LSD radix sort on a packed key, in O(n), or a comparison sort, alike.
//
// Threaded, a long list is radix-sorted in fixed blocks of kSortBlock entries: per digit, each
// block's counts, their offsets in (digit value, block) order, then each block scattered in its own
// order, the blocks in parallel. A stable sort of the same keys: the same sequence on any thread
// count, and as the serial sort's.
#pragma once

#include "transport/CellCoord.h"

#include <cstddef>
#include <cstdint>
#include <vector>

namespace vdbclay {
namespace transport_internal {

/// The sorts' keys and scratch, kept in a workspace (every entry written before it is read).
struct RadixScratch {
    std::vector<uint64_t> key, keyTmp;
    std::vector<int32_t> tmp, part;
    std::vector<size_t> count;
};

/// Lists of at least 2 x kSortBlock entries are radix-sorted by blocks in parallel when threaded.
constexpr size_t kSortBlock = size_t(1) << 16;

/// A stable LSD radix sort of @a order by @a s.key (one key per entry), 11 bits a digit: the digits
/// counted in one pass, then a pass per digit, skipped where every key has the same digit (threaded
/// and long: per digit, the blocks counted, then scattered, in parallel unless @a serial). Leaves the
/// keys sorted in @a s.key.
void radixSort(std::vector<int32_t>& order, RadixScratch& s, bool serial);

/// Sorts the cells @a order[from, end) by their coordinates @a at (x, then y, then z). Their
/// coordinates relative to the smallest, packed into one 64-bit key when they fit (21 bits an
/// axis), are radix-sorted; otherwise (or under 64 cells) std::sort.
void sortByCoord(std::vector<int32_t>& order, size_t from, const std::vector<CellCoord>& at, RadixScratch& s);

/// The routing's order of cells: decreasing potential @a p, ties by coordinate @a at.
struct HigherPotential {
    const std::vector<double>& p;
    const std::vector<CellCoord>& at;
    bool operator()(int32_t a, int32_t b) const
    {
        if (p[size_t(a)] != p[size_t(b)]) return p[size_t(a)] > p[size_t(b)];
        return at[size_t(a)] < at[size_t(b)];
    }
};

/// Sorts @a order (cells) as @a higher does: a radix sort on p's bits (in parallel unless @a serial),
/// then each run of equal p by coordinate.
void sortByPotential(std::vector<int32_t>& order, const HigherPotential& higher, RadixScratch& s,
                     bool serial);

} // namespace transport_internal
} // namespace vdbclay
