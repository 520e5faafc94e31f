// The global transport's sorts of cell lists: by coordinate (MIC(0)'s row order, Poisson.h) and by
// decreasing potential (the routing's order, Routing.h). Both orders are strict total orders on the
// cells (ties broken by coordinate, and no two cells share one), so every sort gives one sequence:
// a stable LSD radix sort on a packed key, in O(n), or a comparison sort, alike.
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

/// A stable LSD radix sort of @a order by @a s.key (one key per entry), 11 bits a digit: the digits
/// counted in one pass, then a pass per digit, skipped where every key has the same digit. Leaves
/// the keys sorted in @a s.key.
void radixSort(std::vector<int32_t>& order, RadixScratch& s);

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

/// Sorts @a order (cells) as @a higher does: a radix sort on p's bits, then each run of equal p by
/// coordinate.
void sortByPotential(std::vector<int32_t>& order, const HigherPotential& higher, RadixScratch& s);

} // namespace transport_internal
} // namespace vdbclay
