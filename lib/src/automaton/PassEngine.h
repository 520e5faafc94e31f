// The pass over a step's work list on the automaton's threads (see Automaton.cc for the model).
//
// One thread (threads = 1, or an arena of one): the calling thread runs the whole list through
// processRange. Several: the list (index order: slabs of columns in dense mode, layers otherwise) is
// cut into one chunk per thread, contiguous ranges of items; the cuts follow the chunks' measured
// speed (PassBalance.h), so that all finish together. The chunks run on a PassCrew (PassCrew.h: the
// helper threads are kept from one pass to the next, a pass is published by one atomic store), and
// crew lane l records its items' changes into sink lane l (Candidates::lanes). Chunk 0, once its
// items are done, predrains the next step's candidates that the later chunks cannot reach
// (Candidates::predrain): that part of the next gather runs while the other threads still work, so
// chunk 0's first share is kFirstShare % of an even one.
//
// Every item runs exactly once, in one chunk, and the chunks' totals are joined order-free (sums,
// maxima, the first overflow, deferred blocks sorted by the caller): the result does not depend on
// the cuts, the thread count or which lane ran which chunk. Only the cuts depend on time.
#pragma once

#include "automaton/Candidates.h"
#include "automaton/Kernel.h"
#include "automaton/PassBalance.h"
#include "automaton/PassCrew.h"

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

namespace vdbclay {
namespace automaton_internal {

/// What a step's passes did with their threads (StageSeconds::passBusy and passIdle).
struct PassSeconds {
    double busy = 0; ///< thread-seconds the chunks ran (chunk 0's predrain included)
    double idle = 0; ///< threads x the passes' time, less busy
};

class PassEngine {
public:
    /// Chunk 0's share of the candidate blocks while a phase has no speed estimates, in percent of
    /// an even share: it also predrains the next step's candidates.
    static constexpr int kFirstShare = 92;

    /// Runs the pass @a in over @a work on @a lanes threads (1: the calling thread alone). @a sinks:
    /// null, or one DenseSink per lane (Candidates::lanes(lanes)); the kernel's PassInput::sink is
    /// set per chunk from it. Adds the pass's thread-seconds to @a seconds.
    PassTotals run(const PassInput& in, const DenseSink* sinks, std::vector<WorkItem>& work, int lanes,
                   Candidates& candidates, PassSeconds& seconds);

    /// Forgets the threads and the speed estimates (the thread count changed).
    void reset();

private:
    /// run() on several lanes: cut, run on the crew, join. Adds to @a busy the chunks' seconds.
    PassTotals runChunks(const PassInput& in, const DenseSink* sinks, std::vector<WorkItem>& work, int lanes,
                         Candidates& candidates, double& busy);

    std::unique_ptr<PassCrew> mCrew; // made at the first pass on several lanes
    PassBalance mBalance;
    // scratch, reused between passes
    std::vector<uint64_t> mBlockSums;  // candidate blocks up to each item
    std::vector<uint64_t> mCutTargets; // cumulative block counts per cut
    std::vector<size_t> mBounds;       // the chunks' first items
    std::vector<PassTotals> mChunkTotals;
    std::vector<PassBalance::Measure> mChunkMeasures;
};

} // namespace automaton_internal
} // namespace vdbclay
