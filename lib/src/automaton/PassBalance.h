// How a pass's candidate blocks are shared among its chunks: by each chunk's measured speed.
//
// Why. Cut into chunks of equal candidate blocks, a pass's chunks still do not finish together,
// because a block does not cost the same in every chunk: the items differ (press 128^3 at 0.8 Tc on
// 2 threads: 4.9 candidate blocks per item in the lower chunk, 5.6 in the upper; an item's leaves
// cost the same however few of its blocks are candidates), and so do the lanes (the caller gathered
// the work list and predrains after its chunk; the helper's chunk reads lines the caller wrote; and
// a virtual machine's CPUs need not run at one speed: one vCPU of the 2-vCPU development VM runs at
// 0.54-0.73x of the other for long stretches, docs/PERFORMANCE.md). With equal shares, logged per pass
// on that VM, the two chunks finish apart by 26 % of the passes' time, the caller's mostly last (95
// TSC ticks per candidate block against the helper's 67 in one run; 94 against 82-87 in two more):
// a lane idle for that long every step.
//
// How. Per phase (even and odd steps touch different leaves) and per chunk, PassBalance keeps an
// estimate of the chunk's seconds per candidate block: its whole time (its items, and chunk 0's
// predrain) over its candidate blocks, an exponential average with weight 1/8 of each new pass,
// each measure first clamped to [1/2, 2] x the estimate so that one interrupted pass cannot swing
// it. The next pass of that phase gives chunk c a share of the blocks proportional to 1/estimate,
// so that all would finish together; each share stays within [1/4, 4] x an even share. Until a
// phase has an estimate for every chunk (its first pass, or the chunk count changed), chunk 0 gets
// firstShare % of an even share and the others the rest evenly (fixedCuts: chunk 0 also predrains).
// Chunks of fewer than kMinMeasured blocks measure little but overhead: they leave their estimate
// as it was.
//
// Only where the work list is cut depends on the measures, that is on time: every item still runs
// once, in one chunk, and the results of a pass do not depend on its partition
// (tests/TestAutomaton.cc, ThePassGivesTheSameStepsOnAnyThreadCount). No OpenVDB here;
// tests/TestPassBalance.cc tests it alone.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace vdbclay {
namespace automaton_internal {

class PassBalance {
public:
    /// Measures from chunks with fewer candidate blocks than this leave their estimate unchanged.
    static constexpr uint64_t kMinMeasured = 16;

    /// What a chunk of a pass measured: its candidate blocks and its seconds in all.
    struct Measure {
        uint64_t blocks = 0;
        double seconds = 0;
    };

    /// Fills @a cuts with chunks + 1 cumulative block counts: chunk c should take the items from the
    /// one whose running block count first exceeds cuts[c] to the one that reaches cuts[c + 1];
    /// cuts[0] = 0, cuts[chunks] = @a total, nondecreasing. @a phase: 0 or 1. @a firstShare: chunk
    /// 0's share, in percent of an even share, while the phase has no estimates (1-100).
    void cuts(int phase, size_t chunks, uint64_t total, int firstShare, std::vector<uint64_t>& cuts) const;

    /// The cuts without estimates: chunk 0 @a firstShare % of an even share, the others the rest
    /// evenly (cuts() while a phase has no estimates).
    static void fixedCuts(size_t chunks, uint64_t total, int firstShare, std::vector<uint64_t>& cuts);

    /// What a pass of @a phase measured, chunk by chunk (@a chunks of them). A pass with another
    /// chunk count than the last starts the phase over.
    void measured(int phase, size_t chunks, const Measure* measures);

    /// Forgets every estimate (the next passes use firstShare).
    void reset();

    /// The estimate of chunk @a c's seconds per candidate block in @a phase; 0 where none.
    double secondsPerBlock(int phase, size_t c) const;

private:
    struct Phase {
        std::vector<double> perBlock; // per chunk; 0: not measured yet
    };
    Phase mPhase[2];
};

} // namespace automaton_internal
} // namespace vdbclay
