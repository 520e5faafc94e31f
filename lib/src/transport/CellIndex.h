// The global transport's cell index over a box (Domain.h): a coordinate's cell, or -1.
//
// Two levels, as a tree's leaves without its upper nodes: a slot per 8^3 brick of the box (bricks
// aligned to multiples of 8, as OpenVDB's leaves are), holding -1 or the brick's table, and a table of
// 512 cells per brick that holds a cell, made when its first cell is set. A lookup is two loads, and
// inline. The box's slots are 1/512 of its cells (a box of 392 x 265 x 392 cells: 80,000 slots) and
// only the bricks the domain touches hold a table, so a box far larger than the domain costs little.
// Cells outside the box are the caller's (Domain.cc keeps a tree for them).
#pragma once

#include "transport/CellCoord.h"

#include <cstddef>
#include <cstdint>
#include <vector>

namespace vdbclay {
namespace transport_internal {

/// The index's arrays, kept in a workspace from one call to the next (reset() clears them).
struct CellIndexArrays {
    std::vector<int32_t> slot;  ///< per brick of the box: its table, or -1
    std::vector<int32_t> table; ///< 512 cells per brick with a table: the cell, or -1
};

class CellIndex {
public:
    explicit CellIndex(CellIndexArrays& arrays) : mA(arrays) {}

    /// Covers the cells [@a lo, @a hi] (each axis) if their bricks number at most @a maxSlots, and
    /// clears the index; else covers nothing. Returns whether it covers the box.
    bool reset(const CellCoord& lo, const CellCoord& hi, int64_t maxSlots);
    /// Covers nothing.
    void clear() { mCovers = false; }
    bool covers() const { return mCovers; }

    /// @a c's cell (-1: none) if @a c lies in the box (@a inside set); else -1, @a inside false.
    int32_t get(const CellCoord& c, bool& inside) const
    {
        size_t brick, at;
        inside = locate(c, brick, at);
        if (!inside) return -1;
        const int32_t t = mA.slot[brick];
        return t < 0 ? -1 : mA.table[size_t(t) * kBrickCells + at];
    }

    /// Sets @a c's cell to @a i if @a c lies in the box; returns whether it does.
    bool set(const CellCoord& c, int32_t i)
    {
        size_t brick, at;
        if (!locate(c, brick, at)) return false;
        int32_t t = mA.slot[brick];
        if (t < 0) {
            t = int32_t(mA.table.size() / kBrickCells);
            mA.slot[brick] = t;
            mA.table.resize(mA.table.size() + kBrickCells, -1);
        }
        mA.table[size_t(t) * kBrickCells + at] = i;
        return true;
    }

private:
    static constexpr size_t kBrickCells = 512;

    /// @a c's brick and its place in the brick's table; false if @a c lies outside the box.
    bool locate(const CellCoord& c, size_t& brick, size_t& at) const
    {
        if (!mCovers) return false;
        // One unsigned comparison per axis: a negative offset wraps past every dimension.
        const uint64_t x = uint64_t(int64_t(c.x) - mLo[0]), y = uint64_t(int64_t(c.y) - mLo[1]),
                       z = uint64_t(int64_t(c.z) - mLo[2]);
        if (x >= mDim[0] || y >= mDim[1] || z >= mDim[2]) return false;
        brick = size_t(((x >> 3) * (mDim[1] >> 3) + (y >> 3)) * (mDim[2] >> 3) + (z >> 3));
        at = size_t((x & 7) << 6 | (y & 7) << 3 | (z & 7));
        return true;
    }

    CellIndexArrays& mA;
    bool mCovers = false;
    int64_t mLo[3] = {0, 0, 0};   ///< the box's first cell, a multiple of 8 on each axis
    uint64_t mDim[3] = {0, 0, 0}; ///< its cells along each axis, a multiple of 8
};

} // namespace transport_internal
} // namespace vdbclay
