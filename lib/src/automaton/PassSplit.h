// How the automaton cuts a pass on several threads (Automaton.cc, runPass).
//
// Default, "weighted": the work list (index order: slabs of columns) is cut into K chunks per thread of about
// equal candidate blocks (a pass's cost follows them), one task each under a simple partitioner, so a step
// pays for one task per chunk and each thread keeps about the same layers from step to step; a pass with
// fewer than MIN candidate blocks runs on the calling thread alone (no fork/join). Defaults K = 1, MIN = 0;
// the environment may set VDBCLAY_PASS_SPLIT=weighted[:K[:MIN]] (read at the first pass).
// VDBCLAY_PASS_SPLIT=auto restores round 4's split: tbb::parallel_reduce with its auto partitioner over the
// work items (grain 4), which splits ranges as threads steal them. On a quiet 2-core machine the weighted
// split ran the 128^3 compressible press on 2 threads in 1.80-1.92 s (median 1.82; user CPU 3.16-3.39 s)
// against 1.82-1.88 s (median 1.865; 3.26-3.36 s), six runs of each alternated (docs/PERFORMANCE.md, "Round
// 5, merged"): a small gain, within the noise of one run. Round 7: chunk 0, once done, predrains the next
// step's candidates out of the other chunks' reach (Candidates::predrain: part of the serial gather done
// while the other threads still run), so it gets FIRST = 92 % of an even share of the candidate blocks
// (VDBCLAY_PASS_SPLIT=weighted:K:MIN:FIRST; VDBCLAY_PASS_PREDRAIN=0 turns the predrain off). Shared 2-core
// machine, 2 threads, medians of 6-7 alternated runs: 2.14-2.26 s against 2.21-2.37 s without
// (docs/PERFORMANCE.md, "Round 7"). Round 13: the weighted split's chunks run on a PassCrew (PassCrew.h: the
// helper threads kept from one pass to the next, a pass published by one atomic store) instead of a TBB
// fork/join per step; VDBCLAY_PASS_CREW=0 restores the TBB tasks. Same chunks, same lanes (lane l records
// into sink lane l). 2 threads on the 2-vCPU VM, alternated runs, per round against one thread: press 48^3's
// repartition 0.89x -> 0.99x, sphere-over-lump's 1.01x -> 1.18x, press 128^3's level to 7 % faster
// (docs/PERFORMANCE.md, "Round 13"): the smaller the steps, the more the fork/join weighed.
// Round 14: the shares follow the chunks' measured speed (PassBalance.h): per phase and chunk, an
// average of seconds per candidate block, and chunk c gets blocks in proportion to its speed (FIRST
// sets only a phase's first pass); VDBCLAY_PASS_BALANCE=0 restores FIRST's fixed shares. Press
// 128^3 at 0.8 Tc on 2 threads: the time one lane waits for the other at the end of a pass fell
// from 8-9 % of the chunks' time to 5 % (docs/PERFORMANCE.md, "Round 14").
// Either way every item is processed exactly once and the totals are joined order-free, so the
// results are identical (tests/TestAutomaton.cc). docs/PERFORMANCE.md, round 5: why, and that its
// speed was not measured on a quiet machine.
#pragma once

#include <cstdint>

namespace vdbclay {
namespace automaton_internal {

struct PassSplit {
    bool weighted = true;
    int perThread = 1;      ///< K: chunks per thread
    uint64_t minBlocks = 0; ///< MIN: fewer candidate blocks than this run serially
    int firstShare = 92;    ///< FIRST: chunk 0's candidate blocks, in percent of an even share
    bool predrain = true;   ///< chunk 0 then drains the next step's candidates out of the others' reach
    bool crew = true;       ///< the chunks run on a PassCrew (threads kept between passes), not TBB
    bool balance = true;    ///< shares from the chunks' measured speed (PassBalance.h), not FIRST alone
};

/// The process's setting: VDBCLAY_PASS_SPLIT at the first call; tests may assign it.
PassSplit& passSplit();

} // namespace automaton_internal
} // namespace vdbclay
