// The automaton's per-block kernel: one pass over a range of a step's work list (Kernel.cc).
//
// The pass reads each anchor's leaves once (the anchor's own leaf, and on odd steps the lower
// neighbours its straddling blocks reach into), drops (3D) the candidates that hold no cell over Tc
// with a vector filter (overBlocks), then runs the rest through the rule.
// The rule, the dimension and the phase are template parameters of the loop (Kernel.cc picks one of
// 16 instantiations per pass), so no switch runs per block; the step's part of the block hash is
// computed once per pass (rules_internal::stepPrefix).
//
// Thread-safety. Tasks of one pass get disjoint ranges of the work list; blocks of one phase are
// disjoint, so tasks write disjoint voxels. Values are written only into leaves that exist (a block
// whose result would flow into a missing leaf is deferred, see PassTotals::deferred); missing leaves
// read as 0. The only shared words are leaf value masks (active bits), set with an atomic OR when a
// cell goes from 0 to positive, and, in dense mode, the candidates' accumulators and bit sets
// (PassInput::sink: with several threads, each thread records into its own lane,
// Candidates::lanes(), chosen by its slot in the task arena). Nothing in the pass changes the tree's
// topology.
#pragma once

#include "automaton/Candidates.h"

#include "vdbclay/Fwd.h"
#include "vdbclay/Rules.h"

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

namespace vdbclay {
namespace automaton_internal {

using MassTree = Tree543<int32_t>;
using ObsTree = Tree543<openvdb::ValueMask>;

/// The flat leaf table: for every anchor that can reach a mass leaf (a leaf's origin, or one of its
/// upper neighbours' origins), the 8 leaves leafOrigin(anchor, w) its blocks read (null when
/// missing) and their obstacle leaves or tiles, found by one hash lookup instead of up to 16
/// accessor probes per anchor (none when the work item carries its index). Entries are numbered in
/// column order (indexLess; Candidates' dense mode scans them in that order). It describes the topology of
/// both trees when build() ran: the Automaton clears it whenever a leaf may have been created or removed, or
/// the obstacles changed (edits, resync, grown leaves), and rebuilds it before a later pass. An anchor the
/// table does not hold (all its mass leaves missing) is fetched through accessors, as without a table.
class LeafTable {
public:
    LeafTable();
    ~LeafTable();
    LeafTable(const LeafTable&) = delete;
    LeafTable& operator=(const LeafTable&) = delete;

    /// Indexes every leaf of @a tree (and the obstacles of @a obstacles, which may be null).
    void build(MassTree& tree, const ObsTree* obstacles, bool is3D);
    /// Forgets the table: no pass uses it until the next build().
    void clear();
    bool valid() const { return mValid; }
    size_t size() const; // anchors indexed
    /// The anchors in column order with their neighbours; WorkItem::entry indexes them (valid tables).
    AnchorIndex anchorIndex() const;

    struct Impl;
    const Impl* impl() const { return mImpl.get(); }

private:
    std::unique_ptr<Impl> mImpl;
    bool mValid = false;
};

/// The over-cell filter (Kernel.cc, overBlocks): which instructions find an item's candidate blocks
/// that hold a cell over Tc before the per-block work. Every choice gives the same result.
enum class OverFilter : uint8_t {
    Auto, // AVX2 where the CPU has it, else SSE2 (x86-64), else none
    Avx2, // AVX2 (falls back to SSE2 where the CPU lacks it)
    Sse2, // SSE2 (none where the build has no SSE2)
    None  // no filter: every candidate block is loaded and checked on its own
};

/// The filter Auto resolves to on this machine (Avx2, Sse2 or None).
OverFilter bestOverFilter();

/// The blocks of @a mask (phase @a phase, 3D) that hold a cell over @a tc, found by @a f column by
/// column; read[w] is leaf leafOrigin(anchor, w)'s values (512 int32, OpenVDB's order; on the even
/// phase only read[0] is used). In 2D, and with OverFilter::None, returns @a mask: the filter is 3D only.
uint64_t overBlocks(const int32_t* const read[8], uint64_t mask, int32_t tc, bool is3D, int phase,
                    OverFilter f);

/// Whether processRange runs its AVX2 build on this machine (with PassInput::avx2 on): the CPU has AVX2,
/// BMI1, BMI2 and POPCNT and the build is for x86-64 with GCC or Clang. Every build gives the same result.
bool avx2Pass();

/// What a pass needs to know about the step.
struct PassInput {
    MassTree* tree = nullptr;
    const ObsTree* obstacles = nullptr; // null: no obstacles
    CompiledRule rule;
    bool is3D = true;
    int phase = 0;
    uint64_t step = 0, seed = 0;
    bool mayOverflow = false; // a result may exceed INT32_MAX: check every written cell
    bool dryRun = false;      // check for overflow only, write nothing
    bool portable = false;    // no SIMD: the plain C++ path (tests compare both on the same grids)
    bool avx2 = true;         // the pass's AVX2 build where the CPU has it; false: the baseline (SSE2) build
    OverFilter filter = OverFilter::Auto; // the over-cell filter (None on the portable path)
    const LeafTable* table = nullptr;     // valid leaf table of both trees, or null: accessors
    const DenseSink* sink = nullptr; // dense candidates: record each item's changes here (not in dry runs)
    int sinkLanes = 1;               // sink[0..sinkLanes): one per thread of the pass's arena (lanes())
    bool prune = true;               // record through sinkActive (else sinkChanges: every neighbour)
};

/// What one range of the pass accumulates.
struct PassTotals {
    uint64_t examined = 0; // candidate blocks examined (every bit of every mask in the range)
    uint64_t overTc = 0;   // those holding a cell over Tc (the rule ran on them)
    uint64_t updated = 0;  // those the rule changed
    int64_t overloadDelta = 0;
    int64_t maxWritten = 0;
    bool overflow = false;
    bool sinkMissed = false; // a range ran on a thread without a lane: its items were not recorded
    size_t overflowItem = SIZE_MAX;
    int overflowBit = 0;
    struct Deferred {
        uint32_t item;
        uint8_t bit;
        uint8_t cells; // cells the update changes (bit c = corner c)
    };
    std::vector<Deferred> deferred; // blocks whose update writes into a missing leaf

    void join(const PassTotals& o);
};

/// Updates (or, when in.dryRun, only checks) the candidate blocks of work[begin, end); sets each
/// item's `changed` mask.
void processRange(const PassInput& in, WorkItem* work, size_t begin, size_t end, PassTotals& tot);

} // namespace automaton_internal
} // namespace vdbclay
