// The automaton's per-block kernel: one pass over a range of a step's work list (Kernel.cc).
//
// The pass reads each anchor's leaves once (the anchor's own leaf, and on odd steps the lower
// neighbours its straddling blocks reach into), drops (3D) the candidates that hold no cell over Tc
// with a vector filter (OverFilter.h), then runs the rest through the rule.
// The rule, the dimension and the phase are template parameters of the loop (Kernel.cc picks one of
// 16 instantiations per pass), so no switch runs per block; the step's part of the block hash is
// computed once per pass (rules_internal::stepPrefix).
//
// Thread-safety. Tasks of one pass get disjoint ranges of the work list; blocks of one phase are
// disjoint, so tasks write disjoint voxels. Values are written only into leaves that exist (a block
// whose result would flow into a missing leaf is deferred, see PassTotals::deferred); missing leaves
// read as 0. The only shared words are leaf value masks (active bits), set with an atomic OR when a
// cell goes from 0 to positive, and, in dense mode, the candidates' accumulators and bit sets, which
// each task writes through its own lane (PassInput::sink, one of Candidates::lanes()). Nothing in
// the pass changes the tree's topology.
#pragma once

#include "automaton/Candidates.h"
#include "automaton/LeafTable.h"

#include "vdbclay/Rules.h"

#include <cstddef>
#include <cstdint>
#include <vector>

namespace vdbclay {
namespace automaton_internal {

/// What a pass needs to know about the step.
struct PassInput {
    MassTree* tree = nullptr;
    const ObsTree* obstacles = nullptr; // null: no obstacles
    CompiledRule rule;
    bool is3D = true;
    int phase = 0;
    uint64_t step = 0, seed = 0;
    bool mayOverflow = false;         // a result may exceed INT32_MAX: check every written cell
    bool dryRun = false;              // check for overflow only, write nothing
    const LeafTable* table = nullptr; // valid leaf table of both trees, or null: accessors
    /// Dense candidates: record each item's changes here (ignored in dry runs). This range's lane
    /// alone: no other task of the pass may write it.
    const DenseSink* sink = nullptr;
    bool prune = true; // record through sinkActive (else sinkChanges: every neighbour)
};

/// What one range of the pass accumulates.
struct PassTotals {
    uint64_t examined = 0; // candidate blocks examined (every bit of every mask in the range)
    uint64_t overTc = 0;   // those holding a cell over Tc (the rule ran on them)
    uint64_t updated = 0;  // those the rule changed
    int64_t overloadDelta = 0;
    int64_t maxWritten = 0;
    bool overflow = false;
    bool sinkMissed = false; // a range was given no lane: its items were not recorded
    size_t overflowItem = SIZE_MAX;
    int overflowBit = 0;
    struct Deferred {
        uint32_t item;
        uint8_t bit;
        uint8_t cells; // cells the update changes (bit c = corner c); 0: the block reads a tile
    };
    /// Blocks whose update writes into a missing leaf, and (cells 0) blocks that read a leaf slot
    /// inside a tile (LeafSet::tile), whose cells the pass cannot read.
    std::vector<Deferred> deferred;

    void join(const PassTotals& o);
};

/// Updates (or, when in.dryRun, only checks) the candidate blocks of work[begin, end); sets each
/// item's `changed` mask. Runs the pass's AVX2 build where the CPU has it (Cpu.h), else its
/// baseline build; both give the same result.
void processRange(const PassInput& in, WorkItem* work, size_t begin, size_t end, PassTotals& tot);

} // namespace automaton_internal
} // namespace vdbclay
