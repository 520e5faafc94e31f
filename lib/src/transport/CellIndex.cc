// The global transport's cell index over a box (CellIndex.h: the design).

#include "transport/CellIndex.h"

namespace vdbclay {
namespace transport_internal {

bool CellIndex::reset(const CellCoord& lo, const CellCoord& hi, int64_t maxSlots)
{
    mCovers = false;
    int64_t slots = 1;
    for (int a = 0; a < 3; ++a) {
        // The bricks that meet [lo, hi]: from the multiple of 8 at or below lo to the one above hi.
        const int64_t first = int64_t(lo[a]) & ~int64_t(7), end = (int64_t(hi[a]) | 7) + 1;
        mLo[a] = first;
        mDim[a] = uint64_t(end - first);
        slots *= (end - first) >> 3;
        if (slots > maxSlots) return false;
    }
    mA.slot.assign(size_t(slots), -1);
    mA.table.clear();
    mCovers = true;
    return true;
}

} // namespace transport_internal
} // namespace vdbclay
