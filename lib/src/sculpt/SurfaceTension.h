// The scene's surface tension ("surface_tension", docs/SCENES.md): Dewaele and Cani's third layer,
// one pass of the smoothing of Smooth.h a frame over the surface that frame changed, after the clay
// settles.
//
// Which surface. In the scene's first frame, the whole surface of the clay: every leaf slot (the
// clay's surface lies in leaves; interior clay is held in tiles and never read), and every slot of a
// tile's border that meets empty space or another tile value with no leaf between (a face of clay
// held in tiles, where a box of clay meets empty space). In every later frame, the voxels whose clay changed
// in that frame (the ChangedClay the Automaton records into: the tools' edits, the global layer's cells and
// every block a step changed), each leaf slot's changed voxels grown by kSurfaceTensionMargin (4: the
// threshold step's reach, which is more than the shelters' 2). A surface at rest is not visited again: a
// frame's work follows the surface that changed, not the model. What is smoothed depends only on the frame
// index and on what changed within the frame, so a checkpoint taken inside a frame carries the frame's
// changes so far (ClayMeta::changedClay) and a resumed run smooths what the unbroken one does.
//
// How. Smooth.h's smoothing works on a dense block over one box; the surface of a large model is not
// one box, and its boxes' bounds would hold the model's volume. So the slots to smooth are cut into
// boxes (tensionBoxes): the slots' bounds, halved along their longest axis (at the median slot)
// until at least half of the box's slots are in the set and it spans at most kTensionBoxSlots slots
// along each axis; each box is the union of its slots' voxels grown by the margin. The clay ends as
// smoothRegion over each box in that order, each reading what the ones before it left, leaves it:
// integer and in a fixed order, so the result does not depend on the thread count. A box grown by
// the margin overlaps its neighbours, so clay moves across the cuts; inside one box, as in any
// smoothRegion, it does not leave the box. A box's dense block holds at most
// (8 kTensionBoxSlots + 2 (margin + 2))^3 voxels.
//
// In parallel. A box's smoothing reads the masses of the box grown by the shelters' reach (its
// reads) and writes inside the box only (sculpt/SmoothInternal.h); two boxes where neither's reads
// meet the other box give the same clay in either order. So each box has a level (tensionLevels): 0
// when its reads meet no earlier box, else one more than the highest level of the earlier boxes
// they meet. The boxes of one level meet none of each other's reads, and every earlier box a box's
// reads meet lies on a lower level, so smoothing level after level gives the clay of the order
// above. A level's boxes are taken in groups (tensionBoxesHeld: kTensionBoxesPerLane a thread, one
// on one thread): the group's boxes are computed in parallel (tensionLanes threads at most), each
// on its own dense block, reading the grid only; then their results are written one after the other
// in their order (the writes add and prune leaves, which no reader may overlap). Each write is the
// one smoothRegion makes (the automaton's records of changed clay, wakes and written regions follow
// it), in the boxes' order within a level. The memory estimate counts a dense block a thread and the
// changed cells of a group: tensionLanes(0) and tensionBoxesHeld of it.
#pragma once

#include "automaton/ChangedClay.h"

#include "vdbclay/Fwd.h"
#include "vdbclay/Shapes.h"
#include "vdbclay/Types.h"

#include <cstdint>
#include <vector>

namespace vdbclay {

class Automaton;

namespace sculpt_internal {

/// A box spans at most this many slots along each axis (before the margin).
constexpr int kTensionBoxSlots = 4;

/// The voxels of a tension box's dense block at most (the box grown by the margin and the
/// shelters' reach), @a dims 2 or 3: what the memory estimate counts.
uint64_t tensionBlockVoxels(int dims);

/// Records into @a out every slot of the clay's surface in @a mass (file comment: leaves, and tile
/// border slots meeting another value), each whole.
void addWholeSurface(const MassGrid& mass, int dims, automaton_internal::ChangedClay& out);

/// The boxes (file comment) covering @a changed (compacted entries), each grown by @a margin voxels
/// (2D: in x and y only), in the order they are smoothed.
std::vector<Box> tensionBoxes(const std::vector<automaton_internal::ChangedClay::Entry>& changed, int dims,
                              int margin);

/// A level's boxes are computed in groups of this many a thread (file comment): enough that the
/// threads rarely wait on the group's largest box.
constexpr size_t kTensionBoxesPerLane = 4;

/// The threads the surface tension computes on with the automaton's @a threads (0: every core): at
/// most the machine's cores (TBB's default concurrency), at least 1.
int tensionLanes(int threads);

/// The boxes whose results are held at once on @a lanes threads (file comment): kTensionBoxesPerLane
/// a thread, 1 on one thread.
size_t tensionBoxesHeld(int lanes);

/// Each box's level (file comment) of @a boxes (in the order they are smoothed), @a dims 2 or 3 (2D:
/// the reads grow in x and y only). Work: each box against the boxes listed in the 64^3 cells its
/// reads meet.
std::vector<uint32_t> tensionLevels(const std::vector<Box>& boxes, int dims);

/// What one frame's surface tension did.
struct TensionReport {
    int64_t massMoved = 0; ///< clay moved (each unit once)
    uint64_t boxes = 0;    ///< boxes smoothed
    uint64_t levels = 0;   ///< their levels (tensionLevels)
    uint64_t visited = 0;  ///< voxels read into the boxes' dense blocks: its work
};

/// One pass of smoothRegion of @a strength over each box of @a boxes, never inside one of @a solids
/// nor an obstacle of @a automaton: the clay of smoothing them one after the other in order, on the
/// automaton's threads, level by level (file comment).
TensionReport smoothBoxes(Automaton& automaton, const std::vector<Box>& boxes, double strength,
                          const std::vector<ShapePtr>& solids);

} // namespace sculpt_internal
} // namespace vdbclay
