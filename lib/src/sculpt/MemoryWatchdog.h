// The memory watchdog of a run (Sculptor): the budget is kept while the clay grows, not only checked
// before the run. The estimate may fall short (clay from a file that spreads far), so the clay is
// measured as it grows, and a run that outgrows its budget stops where a checkpoint resumes exactly,
// as on a stop request.
#pragma once

#include "vdbclay/Fwd.h"

#include <cstdint>

namespace vdbclay {
namespace sculpt_internal {

class MemoryWatchdog {
public:
    /// Every kPollsPerCheck-th poll checks the clay against the budget.
    static constexpr uint64_t kPollsPerCheck = 64;

    /// @a budget in bytes (not kNoMemoryBudget: a run without a budget has no watchdog);
    /// @a fixedBytes: what the run needs beside the clay, which does not grow (the estimate's
    /// program, obstacle and tool bytes).
    MemoryWatchdog(uint64_t budget, uint64_t fixedBytes) : mBudget(budget), mFixedBytes(fixedBytes) {}

    /// Called with each of the run's stop polls: every kPollsPerCheck-th call compares what
    /// @a mass takes now (clayMemoryInUse, measured again only when the tree's leaf or internal
    /// node count changed since the last measure) plus the fixed bytes with the budget. True when
    /// they exceed it; needs() then says by how much.
    bool outgrown(const MassGrid& mass);

    uint64_t budget() const { return mBudget; }
    /// What the run needed at the last poll that returned true (bytes); 0 before any.
    uint64_t needs() const { return mNeeds; }

private:
    uint64_t mBudget;
    uint64_t mFixedBytes;
    uint64_t mPolls = 0;
    uint64_t mNeeds = 0;
    // The grid's size changes only with its nodes: it is measured again (a walk of every node) only
    // when its leaf or internal node count changed (a walk of the internal nodes; the 128^3 press:
    // ~780 polls, 0.04 s of one core when each measured the tree).
    uint64_t mLastLeaves = UINT64_MAX;
    uint64_t mLastInternal = UINT64_MAX;
    uint64_t mLastBytes = 0;
};

} // namespace sculpt_internal
} // namespace vdbclay
