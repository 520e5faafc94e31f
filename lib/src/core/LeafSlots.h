// The leaf slots of a box: the 8^3-aligned cubes of voxels an OpenVDB leaf covers, which the tree
// code (the automaton's scans and collapses, the push's clay leaves, the memory estimate) counts to
// choose between probing a box's slots and walking the tree's leaves.
#pragma once

#include "vdbclay/Types.h"

#include <climits>
#include <cstdint>

namespace vdbclay {

/// Number of leaf slots (8^3 aligned) that @a b meets (0 if empty); saturates at INT64_MAX / 4.
inline int64_t leafSlotCount(const Box& b)
{
    if (b.empty()) return 0;
    int64_t n = 1;
    for (int i = 0; i < 3; ++i) {
        n *= (int64_t(b.max[i]) >> 3) - (int64_t(b.min[i]) >> 3) + 1;
        if (n > INT64_MAX / (int64_t(1) << 30)) return INT64_MAX / 4;
    }
    return n;
}

} // namespace vdbclay
