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
// The list is built in layer order (y, z, x; one entry per anchor) by merging already-sorted runs:
// changedPrev2 (in layer order, as every work list), and changedPrev dilated across the phase, which
// splits into one run per neighbour shift (each is changedPrev moved by one constant vector, so
// still in layer order). An edited region gives one run per neighbour shift, generated in layer
// order; only the hot leaves after a reset need a sort. All scratch
// is kept in members, so a step allocates nothing once the buffers have grown.
#pragma once

#include "BlockMasks.h"

#include "vdbclay/Types.h"

#include <cstdint>
#include <utility>
#include <vector>

namespace vdbclay {
namespace automaton_internal {

/// One anchor of a step's work list: its candidate blocks, and (output of the pass) those updated.
struct WorkItem {
    Origin anchor;
    uint64_t mask;    // candidate blocks
    uint64_t changed; // output: blocks updated
};

class Candidates {
public:
    /// Forgets every change; the next two steps examine the leaves in @a hotLeaves whole (the
    /// leaves holding an over cell, found by a full scan).
    void reset(std::vector<Origin> hotLeaves);
    /// The next two steps examine every block that touches @a region (grown by one voxel).
    void addRegion(const Box& region);
    /// Fills @a work with the candidates of a step of phase @a phase, in layer order.
    void gather(int phase, bool is3D, std::vector<WorkItem>& work);
    /// After a step's pass: its updated blocks (work[i].changed) become the next steps' input.
    void record(const std::vector<WorkItem>& work);
    /// After a step in which nothing could change (no over cell): no change to follow.
    void clearChanges();
    /// Counts a step down for the whole-region scans.
    void endStep();

private:
    struct Pending {
        Box box;
        int steps;
    };
    struct Run {
        const Anchor *b, *e;
    };
    void addExtra(const Anchor& a, int anchorPhase, int phase, bool is3D);
    void addPending(const Pending& p, int phase, bool is3D);

    int mFullScanSteps = 0;            // upcoming steps that must examine every hot leaf
    std::vector<Origin> mHot;          // leaves holding an over cell at the last reset()
    std::vector<Pending> mPending;     // edited regions to examine whole
    std::vector<Anchor> mChangedPrev;  // blocks changed at t-1 (phase of t-1)
    std::vector<Anchor> mChangedPrev2; // blocks changed at t-2 (phase of t)
    // scratch
    std::vector<Anchor> mStreams[8];
    std::vector<Anchor> mExtras;                          // hot leaves (sorted)
    std::vector<Anchor> mPendingAnchors;                  // edited regions: runs in layer order
    std::vector<std::pair<size_t, size_t>> mPendingSpans; // the runs in mPendingAnchors
    std::vector<Anchor> mMergeBuf[2];
    std::vector<Run> mRuns;
    std::vector<std::pair<size_t, size_t>> mSpans;
};

} // namespace automaton_internal
} // namespace vdbclay
