// How the automaton cuts a pass on several threads (Automaton.cc, runPass).
//
// Default: tbb::parallel_reduce with its auto partitioner over the work items (grain 4), which
// splits ranges as threads steal them. The alternative, "weighted", is experimental and off unless
// the environment sets VDBCLAY_PASS_SPLIT=weighted[:K[:MIN]] (read at the first pass): the work
// list (layer order) is cut into K chunks per thread of about equal candidate blocks (a pass's cost
// follows them), one task each under a simple partitioner, so a step pays for one task per chunk
// and each thread keeps about the same layers from step to step; a pass with fewer than MIN
// candidate blocks runs on the calling thread alone (no fork/join). Defaults K = 1, MIN = 0.
// Either way every item is processed exactly once and the totals are joined order-free, so the
// results are identical (tests/TestAutomaton.cc). docs/PERFORMANCE.md, round 5: why, and that its
// speed was not measured on a quiet machine.
#pragma once

#include <cstdint>

namespace vdbclay {
namespace automaton_internal {

struct PassSplit {
    bool weighted = false;
    int perThread = 1;      ///< K: chunks per thread
    uint64_t minBlocks = 0; ///< MIN: fewer candidate blocks than this run serially
};

/// The process's setting: VDBCLAY_PASS_SPLIT at the first call; tests may assign it.
PassSplit& passSplit();

} // namespace automaton_internal
} // namespace vdbclay
