// The automaton's candidate blocks: which blocks a step examines (no OpenVDB here).
//
// A block can change only if one of its cells changed in the previous two steps: otherwise it is
// exactly as it was two steps ago, when it could not change (or it would have been updated). So the
// candidates of step t are the blocks changed at t-2 (same phase, same masks) plus the blocks of this
// phase that overlap a block changed at t-1 (dilateAcrossPhase). After construction, resync() or an
// edit, the region concerned is examined whole for two steps: after resync() only the leaves holding
// an over cell (only blocks with an over cell can change), after an edit every block touching the
// edited box. The cost of a step follows the blocks that changed recently, not the volume.
//
// Pruned (dense mode, the pass's sink: sinkActive). Sharper: a block can change exactly
// when it holds an over cell and a valid cell that is not over (every rule then changes it). A cell
// that changed from not over to not over (it received clay and stayed at or below Tc: most cells
// a settling step touches) changes neither set of its block, so it wakes nothing; the blocks of the
// other phase are woken only through cells that were or went over Tc, and an updated block is
// looked at again two steps on only if it still holds both kinds of cell. By induction on the steps
// every block that can change is still a candidate: the same results, fewer blocks examined
// (press128 at 0.8 Tc: 72 M instead of 199 M). The merged lists, record() and a pass with
// pruning off (automaton_internal::setPruneCandidates) keep the full rule above; the two may alternate,
// since each keeps every block that can change.
//
// Two ways to build the list, same blocks:
// - Dense (while the Automaton holds a valid leaf table, nearly every step of a settling run): the
//   table's anchors, sorted in column order (indexLess: x, y, z), are numbered 0..n-1 (AnchorIndex, with each
//   anchor's upper and lower neighbours). record() ORs each changed mask into a per-anchor accumulator of the
//   step two steps on (same phase), and its dilation into the next step's, marking the anchors in a
//   bit set; gather() scans that bit set in index order (column order: the pass's chunks are slabs
//   of columns, which meet on small faces). No merge, no sort:
//   the cost follows the changed anchors (plus n / 64 words of bit set). Anchors outside the table
//   have no leaf within reach: their blocks read zeros, never hold an over cell, never change, and
//   are dropped (so blocksVisited counts a few blocks fewer than the merged lists would).
// - Merged (no table: after edits, until the Automaton rebuilds it): the list is built in layer
//   order (y, z, x; one entry per anchor) by merging already-sorted runs: changedPrev2 (in layer
//   order, as every work list), and changedPrev dilated across the phase, which splits into one run
//   per neighbour shift (each is changedPrev moved by one constant vector, so still in layer order).
// Either way an edited region gives one run per neighbour shift, generated in layer order, and only
// the hot leaves after a reset need a sort; in dense mode those steps merge the dense run with them.
// The changed lists (changedPrev, changedPrev2) hold in both modes (in dense mode, the last two
// work lists are kept and turned into them on detach), so switching costs only the accumulators'
// fill. A pass on several threads records into one lane (accumulators and bit sets) per thread,
// so no cache line is written by two threads; the gather ORs the lanes as it scans (lanes()).
// All scratch is kept in members: a step allocates nothing once buffers have grown.
#pragma once

#include "automaton/BlockMasks.h"

#include "vdbclay/Types.h"

#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

namespace vdbclay {
namespace automaton_internal {

/// No index: an anchor the leaf table does not hold (or no table).
constexpr uint32_t kNoEntry = UINT32_MAX;

/// One anchor of a step's work list: its candidate blocks, and (output of the pass) those updated.
struct WorkItem {
    Origin anchor;
    uint64_t mask;             // candidate blocks
    uint64_t changed;          // output: blocks updated
    uint32_t entry = kNoEntry; // the anchor's index in the leaf table (AnchorIndex), when known
};

/// The leaf table's anchors numbered in column order (indexLess), with their neighbours (no OpenVDB here).
/// up[8 e + s] is the index of keys[e] moved by +8 along each axis in bit set s (bit 0 = x, 1 = y,
/// 2 = z), down[8 e + s] moved by -8; kNoEntry when the table lacks that anchor; slot 0 is e itself.
struct AnchorIndex {
    const Origin* keys = nullptr;
    const uint32_t* up = nullptr;
    const uint32_t* down = nullptr;
    size_t size = 0;
    /// The index of @a o (binary search in column order), or kNoEntry.
    uint32_t find(const Origin& o) const;
};

/// Dense mode's accumulators as a pass sees them (Candidates::sink(), or one lane of lanes()): the
/// pass ORs each item's changed blocks in as soon as the item is done, in its own task, instead of
/// record() doing it serially after the pass. OR is commutative and idempotent, so the result does
/// not depend on the order or the partition. With several threads each writes its own lane (plain
/// ORs, nothing shared: atomic ORs into shared words measure slower).
struct DenseSink {
    uint64_t* acc[2] = {nullptr, nullptr};
    uint64_t* touched[2] = {nullptr, nullptr};
    const uint32_t* nb = nullptr; // AnchorIndex::up for a step of phase 0, down for phase 1
};

/// ORs @a out[k], blocks of the other phase in neighbour anchor k of anchor @a e (dilateAll's
/// order), into the next step's slot (1 - P) of this thread's sink.
template <int P, bool D3> inline void sinkNext(const DenseSink& s, uint32_t e, const uint64_t out[8])
{
    const uint32_t* nb = s.nb + 8 * size_t(e);
    for (int k = 0; k < (D3 ? 8 : 4); ++k) {
        const uint32_t t = nb[k];
        if (!out[k] || t == kNoEntry) continue; // no entry: no leaf within reach, cannot change
        if (std::exchange(s.acc[1 - P][t], s.acc[1 - P][t] | out[k]) == 0)
            s.touched[1 - P][t >> 6] |= uint64_t(1) << (t & 63);
    }
}

/// Records that the blocks @a changed of anchor @a e changed at a step of phase P (see DenseSink):
/// into slot P for the step after next, dilated into slot 1 - P for the next step.
template <int P, bool D3> inline void sinkChanges(const DenseSink& s, uint32_t e, uint64_t changed)
{
    // The sink is this thread's alone (one lane per thread): plain ORs.
    s.acc[P][e] |= changed;
    s.touched[P][e >> 6] |= uint64_t(1) << (e & 63);
    uint64_t out[8];
    dilateAll<P, D3>(changed, out);
    sinkNext<P, D3>(s, e, out);
}

/// sinkChanges for what the pass knows cell by cell (the kernel): a block can change only while it
/// holds an over cell and a valid cell that is not over (every rule then changes it). So after its
/// update, block b of anchor @a e needs examining two steps on only if it still holds both
/// (@a again), and a block of the other phase needs examining next step only if one of its cells
/// that changed went over Tc or came down from over it (@a act[k]: the blocks whose corner k did;
/// a cell that changed from not over to not over leaves both sets of its block as they were, and
/// the block could not change before). Cells that only received clay below Tc, the common case,
/// wake nothing. A subset of sinkChanges(e, changed), which it equals when again and every act[k]
/// are @a changed.
template <int P, bool D3>
inline void sinkActive(const DenseSink& s, uint32_t e, uint64_t again, const uint64_t act[8])
{
    if (again) {
        s.acc[P][e] |= again;
        s.touched[P][e >> 6] |= uint64_t(1) << (e & 63);
    }
    uint64_t out[8];
    dilateCorners<P, D3>(act, out);
    sinkNext<P, D3>(s, e, out);
}

class Candidates {
public:
    /// Forgets every change; the next two steps examine the leaves in @a hotLeaves whole (the
    /// leaves holding an over cell, found by a full scan).
    void reset(std::vector<Origin> hotLeaves);
    /// The next two steps examine every block that touches @a region (grown by one voxel).
    void addRegion(const Box& region);
    /// Fills @a work with the candidates of a step of phase @a phase: in index order while attached
    /// (dense mode), else in layer order.
    void gather(int phase, bool is3D, std::vector<WorkItem>& work);
    /// After a step's pass: its updated blocks (work[i].changed) become the next steps' input. In
    /// dense mode, when the pass recorded every item (sink()), @a work is swapped with an older list
    /// (the caller's next gather clears it) instead of being read.
    void record(std::vector<WorkItem>& work);
    /// After a step in which nothing could change (no over cell): no change to follow.
    void clearChanges();
    /// Counts a step down for the whole-region scans.
    void endStep();
    /// Switches to the dense accumulators of @a index (which must outlive the attachment) before the
    /// gather of a step of phase @a phase; the changes recorded so far carry over.
    void attach(const AnchorIndex& index, int phase, bool is3D);
    /// Back to merged lists (the index is about to change); nothing recorded is lost.
    void detach();
    bool attached() const { return mDense; }
    /// In dense mode, the accumulators for the pass of the step just gathered (null otherwise):
    /// the pass records its items' changes there (sinkChanges), record() then only the items that
    /// carry no index. One thread only (several: lanes()).
    const DenseSink* sink();
    /// In dense mode, @a n private sinks for a pass on up to n threads (null otherwise): thread i of
    /// the pass records into sink i only, with plain ORs (no word is shared between threads); lane 0
    /// is sink()'s, lanes 1.. are copies that the next gathers OR in (OR is commutative and
    /// idempotent: the candidates do not depend on which thread recorded which item).
    const DenseSink* lanes(int n);
    /// The pass did not record every item it was given a sink for: record() records them all.
    void sinkMissed() { mSunk = false; }
    /// During the pass of a step of phase @a passPhase (dense mode, lanes given), once every item
    /// below entry @a first is done and recorded and the items from @a first on may still be running
    /// on other threads: drains the next step's slot over the anchors those items cannot reach (see
    /// Candidates.cc), ahead of the next gather, which takes them first. Undone (the masks put back)
    /// if the next step does not gather densely.
    void predrain(int passPhase, uint32_t first);
    /// The anchors predrain() holds for the next gather (tests).
    size_t predrained() const { return mPre.size(); }

private:
    struct Pending {
        Box box;
        int steps;
    };
    struct Run {
        const Anchor *b, *e;
    };
    /// Dense mode, after a pass that did not record its items: records them.
    void sinkAll(const std::vector<WorkItem>& work);
    /// Empties dense slot @a slot of every lane, calling f(entry, mask) for each nonzero entry in
    /// index order (the masks of all lanes ORed).
    template <typename F> void drain(int slot, F&& f, size_t fromWord = 0, size_t toWord = SIZE_MAX);
    /// drain() over words [@a fromWord, @a toWord), appending a work item per entry to @a out.
    void drainInto(int slot, std::vector<WorkItem>& out, size_t fromWord, size_t toWord);
    /// Puts predrain()'s masks back into their slot (lane 0), or drops them when @a keep is false.
    void undoPredrain(bool keep = true);
    void addExtra(const Anchor& a, int anchorPhase, int phase, bool is3D);
    void addPending(const Pending& p, int phase, bool is3D);
    void addDense(int slot, uint32_t e, uint64_t mask);
    void addDenseDilated(int slot, uint32_t e, const Anchor& a, int fromPhase, bool is3D);
    void clearSlot(int slot);
    void materialize();
    void recordLists(const std::vector<WorkItem>& work, bool listsOnly = false);

    int mFullScanSteps = 0;            // upcoming steps that must examine every hot leaf
    std::vector<Origin> mHot;          // leaves holding an over cell at the last reset()
    std::vector<Pending> mPending;     // edited regions to examine whole
    std::vector<Anchor> mChangedPrev;  // blocks changed at t-1 (phase of t-1)
    std::vector<Anchor> mChangedPrev2; // blocks changed at t-2 (phase of t)
    // dense mode: per-anchor candidates of the next step of each phase, and which are nonzero
    bool mDense = false;
    AnchorIndex mIndex;
    std::vector<uint64_t> mAcc[2];
    std::vector<uint64_t> mTouched[2]; // bit set over mIndex's anchors
    int mPhase = 0;                    // the phase of the last gather (record's step)
    DenseSink mSink;
    bool mSunk = false; // the pass got mSink: items with an index are recorded already
    // Lanes 1.. of lanes() (lane 0 is mAcc/mTouched): a pass's threads' private accumulators.
    struct Lane {
        std::vector<uint64_t> acc[2];
        std::vector<uint64_t> touched[2];
    };
    std::vector<Lane> mLanes;
    std::vector<DenseSink> mLaneSinks;
    bool mLanesDirty[2] = {false, false}; // a slot of some lane 1.. may be nonzero
    bool mIs3D = true;
    // The last steps' work lists, kept instead of changed lists while the pass records (mLazy of
    // them, newest first): detach() turns them into mChangedPrev/mChangedPrev2.
    std::vector<WorkItem> mPrevWork[2];
    int mLazy = 0;
    // scratch
    std::vector<Anchor> mDenseRun;
    std::vector<Anchor> mStreams[8];
    std::vector<Anchor> mExtras;                          // hot leaves (sorted)
    std::vector<Anchor> mPendingAnchors;                  // edited regions: runs in layer order
    std::vector<std::pair<size_t, size_t>> mPendingSpans; // the runs in mPendingAnchors
    std::vector<Anchor> mMergeBuf[2];
    std::vector<Run> mRuns;
    std::vector<std::pair<size_t, size_t>> mSpans;
    std::pair<const WorkItem*, size_t> mGathered{nullptr, 0}; // the last list gathered in dense mode
    std::vector<WorkItem> mPre; // predrain(): slot mPreSlot's words below mPreWords, drained
    int mPreSlot = -1;          // -1: nothing predrained
    size_t mPreWords = 0;
};

} // namespace automaton_internal
} // namespace vdbclay
