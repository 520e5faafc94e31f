// The routing (Transport.cc, step 4): the potential turned into integer moves, exactly. The unknown
// cells, in order of decreasing p (ties: coordinate order), send their current integer excess (their
// own plus what higher cells sent them) to their lower-p non-wall face neighbours, pro rata of the
// drop p_i - p_j, largest remainder first. So every unknown cell with excess ends at exactly Tc, the
// Dirichlet cells receive, mass is exact by construction, and walls are never crossed. A cell with no
// lower neighbour (only from solver error) keeps its excess for the automaton's cleanup. The changed
// cells are written through Automaton::setMasses() (their bounding box is woken as by an edit of it;
// only the cells are read).
//
// Determinism. The order is a strict total order: the radix sort (threaded, in parallel by fixed
// blocks: RadixSort.h) gives one sequence. Each cell's lower neighbours and drops depend on p
// and the kinds only, so they are gathered in parallel, a block of the order at a time; the integer
// split is serial, in that order. Both read the cells at random (the order is p's, not the cells'):
// they prefetch what the cells a few places ahead read, so the misses overlap.
#pragma once

#include "transport/Domain.h"
#include "transport/RadixSort.h"

#include "vdbclay/Automaton.h"

#include <cstddef>
#include <cstdint>
#include <vector>

namespace vdbclay {
namespace transport_internal {

/// The routing's arrays, kept in a workspace from one call to the next.
struct RoutingArrays {
    std::vector<int32_t> order; ///< the unknown cells, by decreasing p
    std::vector<int64_t> cur;   ///< each cell's mass as the routing goes
    std::vector<int32_t> outJ;  ///< a block's gathered lower neighbours (6 per cell) and drops
    std::vector<double> outW, outSum;
    std::vector<uint8_t> outN;
    std::vector<int32_t> changed;           ///< the changed cells
    std::vector<Automaton::CellMass> write; ///< their new masses
    std::vector<size_t> counts;
};

/// Routes the excess of @a cells by the potential @a p (one entry per cell) and writes the changed
/// cells to @a automaton. Counts into @a rep (massMoved, region, overloadAfter). @a dirs: faces per
/// cell. Writes nothing (and leaves region empty) if a cell would exceed INT32_MAX.
void route(Automaton& automaton, const Cells& cells, const std::vector<double>& p, int32_t threshold,
           int dirs, bool serial, RoutingArrays& arrays, RadixScratch& sort, GlobalTransportReport& rep);

} // namespace transport_internal
} // namespace vdbclay
