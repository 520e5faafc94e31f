// The memory watchdog of a run (MemoryWatchdog.h).
#include "sculpt/MemoryWatchdog.h"

#include "vdbclay/MemoryEstimate.h"

#include <openvdb/openvdb.h>

namespace vdbclay {
namespace sculpt_internal {

bool MemoryWatchdog::outgrown(const MassGrid& mass)
{
    if (++mPolls % kPollsPerCheck != 0) return false;
    const auto& tree = mass.constTree();
    const uint64_t leaves = tree.leafCount(), internal = tree.nonLeafCount();
    if (leaves != mLastLeaves || internal != mLastInternal) {
        mLastBytes = clayMemoryInUse(mass);
        mLastLeaves = leaves;
        mLastInternal = internal;
    }
    const uint64_t now = mLastBytes + mFixedBytes;
    if (now <= mBudget) return false;
    mNeeds = now;
    return true;
}

} // namespace sculpt_internal
} // namespace vdbclay
