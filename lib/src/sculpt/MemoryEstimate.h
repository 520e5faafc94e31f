// The memory estimate's parts used inside the library and by its tests (MemoryEstimate.cc): the budget
// check with an estimate already computed, the bytes the run's parts take per leaf, anchor, tool slot,
// push source and layer cell, and the count of the global layer's domain bound.
#pragma once

#include "vdbclay/MemoryEstimate.h"

#include <cstdint>

namespace vdbclay {

/// checkMemoryBudget(scene) with estimateSceneMemory(scene) at hand (Sculptor's constructor keeps it).
/// @throw Error as checkMemoryBudget(scene).
void checkMemoryBudget(const Scene& scene, const MemoryEstimate& e);

namespace memory_internal {

// The bytes the run's parts take per leaf, anchor, slot, source or cell (estimateSceneMemory).

/// The program, its libraries, its threads' stacks and the allocator's slack, besides the grids and
/// arrays counted below: vdbclay run on a one-voxel scene peaks at 41 MB resident (x86-64, glibc,
/// OpenVDB 10: /usr/bin/time -v), of which ~4 MB are the few nodes counted below; the 2D scenes of
/// data/scenes, whose heap peaks at 6 MiB, at 48 MB.
constexpr uint64_t kProcessBytes = uint64_t(48) << 20;
/// Per clay leaf, the automaton's lists (automaton/Candidates.h, Automaton.cc): the leaf among the
/// hot leaves (a Coord, 12 bytes), its changed-block masks of the last two steps (two Anchors of 24
/// bytes), up to 10 candidate contributions (the leaf's own, 8 from dilating the other phase, an edited
/// region) and the 8 dilation streams' entries (Anchors), the two merge buffers' entries, and its
/// WorkItems (32 bytes) in the step's list and the last two steps'; half again for vector growth. A
/// long settle of a 160-wide sphere at Tc (the table built) holds ~1.4 KB a leaf with the table.
constexpr uint64_t kAutomatonBytesPerLeaf = 3 * (12 + 2 * 24 + 10 * 24 + 8 * 24 + 2 * 24 + 3 * 32) / 2;
/// Per anchor (a leaf's origin, or one of its upper neighbours' origins: anchorLeaves bounds them),
/// the kernel's leaf table (automaton/LeafTable.h: built over every leaf once the work
/// without it reaches four times the leaves): an entry of 264 bytes, its key (12), its 16 neighbour
/// indices (64) and up to 4 hash slots of 16 bytes; and the candidates' two 8-byte accumulators
/// (Candidates.h, dense mode) with their bit sets.
constexpr uint64_t kAutomatonBytesPerAnchor = 264 + 12 + 64 + 64 + 16 + 1;
/// Per anchor and thread beyond the first: the thread's own lane of those accumulators and bit sets
/// (Candidates::lanes).
constexpr uint64_t kAutomatonLaneBytesPerAnchor = 16 + 1;
/// Per leaf slot of a tool's bounds: its mask in Sculptor's toolCells (an origin and a 64-byte mask,
/// 80 bytes, doubled for growth), its entries in the covered-slot and seen-leaf hash sets (~48 bytes
/// each), the per-slot mask cover() fills (64) and the obstacle leaf it goes into (the mask tree's
/// leaf is counted with the tree).
constexpr uint64_t kToolBytesPerSlot = 2 * 80 + 2 * 48 + 64;
/// Per clay voxel inside a tool at one push (push/Pusher.h): its Source (32 bytes) and the per-leaf
/// copy it is gathered from (32), what its search found (56), its Move (28), its target's part of
/// the planned clay (push/LeafArrays.h: a 2 KB array per leaf the targets touch, 32 bytes a target
/// where a tool's face fills 64 voxels of a leaf; 104 allowed for sparser targets) and the two cell
/// masses written (16 each).
constexpr uint64_t kPushBytesPerSource = 32 + 32 + 56 + 28 + 48 + 8 + 2 * 24 + 2 * 16;
/// Per voxel of surface tension's changed cells written back (sculpt/Smooth.cc: a CellMass, 16).
constexpr uint64_t kSmoothCellBytes = 16;
/// Per voxel surface tension copies (sculpt/Smooth.cc): its mass (8), the mass before (8), its
/// shelter, the separable pass's scratch and the fills (3 x 8), obstacle and member flags (2), and
/// the changed cells written back (kSmoothCellBytes).
constexpr uint64_t kSmoothBytesPerVoxel = 8 + 8 + 3 * 8 + 2 + kSmoothCellBytes;
/// Per slot of a frame's changed clay (automaton/ChangedClay.h, an entry of 36 bytes): the journal grown
/// to twice its compacted entries, the copy tensionBoxes() sorts (sculpt/SurfaceTension.h) and a box
/// per entry at most (24).
constexpr uint64_t kChangedClayBytesPerSlot = 3 * 36 + 24;
/// Writing a .vdb, whatever grids it holds (io/ClayFile.cc): the clay's leaves listed for its largest
/// cell (8 bytes a leaf) and OpenVDB's node lists for the grid statistics it records (~9 a leaf), and
/// the file stream's and compressor's buffers: measured writing the mass alone of spheres 32 to 512
/// wide, 287 to 566 KB, ~280 KB and 17 bytes a leaf.
constexpr uint64_t kOutputWriteBytesPerLeaf = 24;
constexpr uint64_t kOutputWriteBytes = uint64_t(512) << 10;
/// Per leaf of the surface level set writing a .vdb builds (output/SurfaceFog.cc, SurfaceSweep.cc),
/// besides the leaf itself, as the sweep allocates the leaves' values (the output's peak; the box's
/// masks and the reach's, 2 x 64 each, are freed by then): the grown leaves' origins (12), the leaf
/// made and the leaf manager's pointer to it (16), the sweep's per-leaf record (224), input (8), key
/// (12), face neighbours (48), and whether the leaf needs values and its side (2).
constexpr uint64_t kOutputScratchPerLeaf = 12 + 16 + 224 + 8 + 12 + 48 + 2;
/// Scene::transport global: per cell of the layer's domain (transport/Domain.h: the workspace's arrays): its
/// coordinates (twice, 24 bytes), mass, distance and current mass (24), kinds and flags (10), six
/// neighbours and the solver's (48), row maps and parts (36), the potential, inflow, right-hand side
/// and inverse (32) and the diagonal (a face count, 1), six work vectors (48), the routing's lists and
/// sort (~60), MIC(0)'s rows (24), and the flood's open-cell list and per-seed boundary flag (5; its
/// batches' finds, 12 bytes each, a few per cell of one layer): ~334 bytes at their size, held at the
/// capacity the largest frame grew them to; the multigrid preconditioner of large solves (~110 bytes over
/// every level: the finest level's rows twice, by row for conjugate gradients and by colour for its
/// smoothing, ~30 bytes more than by row alone); and its index (4 bytes). Measured beside the dense index,
/// with the finest level by row alone: ~290 bytes a cell (the squeezed cylinder), ~510 bytes per unknown
/// (the 512-wide compress stroke's first frame, 20,077 unknowns: the colour copy adds ~0.6 MB there).
constexpr uint64_t kTransportBytesPerCell = 512;

/// Rows (x, y) voxelsWithinFaceSteps counts before it gives up: ~10 ms.
constexpr int64_t kFaceStepRowsMax = int64_t(1) << 23;

/// The voxels of @a within (2D, @a dims 2: of its z = 0 plane) at most @a r face steps from @a b
/// (the L1 distance to the box: an octahedron's corners, not a cube's), one z run per row (x, y); or
/// UINT64_MAX when that is more than kFaceStepRowsMax rows. The global layer's domain bound
/// (estimateSceneMemory).
uint64_t voxelsWithinFaceSteps(const Box& b, int64_t r, Box within, int dims);

} // namespace memory_internal
} // namespace vdbclay
