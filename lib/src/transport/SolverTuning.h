// The global transport's tuning: what the layer's work (and, within the solver's tolerance, its
// result) depends on but a user does not choose; GlobalTransportOptions holds what a user chooses.
// transportGlobally() uses SolverTuning's defaults; the tests vary them through the overload below.
// The memory estimate (MemoryEstimate.cc) follows kCellIndexSlotsMax.
#pragma once

#include "vdbclay/Transport.h"

#include <cstdint>

namespace vdbclay {
namespace transport_internal {

struct SolverTuning {
    /// The reach counts from the over cells on the clay's boundary (a face on an obstacle, a tool or a
    /// cell with room: where the tool touched), not from every over cell: the over cells a compress
    /// push spread down its chains add no reach of their own (one the reach misses still starts its
    /// own flood, kInnerMargin steps deep). false: `reach` from every over cell (the domain of the
    /// 128-wide compress stroke is then 2.5x larger).
    bool reachFromContact = true;
    /// Active-set rounds (each one Poisson solve) at most.
    int maxRounds = 12;
    /// Conjugate gradients stop at this residual, relative to the right-hand side. The routing is
    /// exact whatever it is; 1e-5 and 1e-3 give the same squeezed shape (docs/TRANSPORT.md).
    double tolerance = 1e-4;
    /// The active-set rounds solve to this looser residual until the set stops changing (they only
    /// locate the rim), then once more to `tolerance` from there (and on, if that changes the set).
    /// At most `tolerance`: every round to `tolerance`. 64^3 press: 192 CG iterations, against 286
    /// with every round to `tolerance`.
    double roundTolerance = 1e-2;
    /// Solves with at least this many unknowns are preconditioned by an aggregation multigrid
    /// V-cycle (iterations nearly flat in N); smaller ones by MIC(0) (cheaper per iteration).
    /// 0: always multigrid. At 16,000 the compress strokes' domains (19,000-24,500 unknowns) take the
    /// multigrid (13 iterations a frame, against 36-49 with MIC(0)) and the surface strokes'
    /// (11,800-14,400) MIC(0).
    uint64_t multigridMin = 16000;
    /// The flood looks at a whole layer of its queue (one distance) together, its faces probed in
    /// parallel (Domain.h), when the queue holds just that layer, at least this many cells, and the
    /// call has more than one thread; else one by one. The same domain either way. 8192: two of Chunks.h's
    /// chunks (the 128^3 press's layers hold 16,384 cells; a stroke's domain, ~20,000 cells in all, stays one
    /// by one).
    uint64_t floodBatchMin = 8192;
};

/// The cell index over the flood's box (CellIndex.h) has at most this many slots of 4 bytes (32 MiB),
/// one per 8^3 brick; a larger box uses the tree alone.
constexpr int64_t kCellIndexSlotsMax = int64_t(1) << 23;

/// vdbclay::transportGlobally() with the solver's tuning given.
/// @throw Error naming the field if @a options or @a tuning are invalid (maxRounds < 1, tolerance
///        outside (0, 1), roundTolerance outside [0, 1)); nothing is changed then.
GlobalTransportReport transportGlobally(Automaton& automaton, const GlobalTransportOptions& options,
                                        const SolverTuning& tuning,
                                        GlobalTransportWorkspace* workspace = nullptr);

} // namespace transport_internal
} // namespace vdbclay
