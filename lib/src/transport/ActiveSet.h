// The active set (Transport.cc, step 3): the obstacle problem's rounds. Each round solves the Poisson
// problem on the unknown cells (Poisson.h), then a Dirichlet cell whose inflow (the sum of p over its
// unknown faces) exceeds its room joins the unknowns (its right-hand side is then negative: it
// absorbs its room), and what it cannot hold cascades to its neighbours with room, which join too if
// it overflows them; a joined cell with p < 0 leaves again. Repeat until nothing changes (or
// SolverTuning::maxRounds): the unknown cells end exactly full.
//
// Tolerances. The rounds solve to SolverTuning::roundTolerance while the set changes (they only
// locate the rim), then to SolverTuning::tolerance: at once when a round changes at most 1/1000 of
// the rows (the rim has settled to a few cells), else by one more solve of the same set once it
// stops changing (and on, if that changes it).
//
// Determinism. The inflow is gathered in parallel through the links back, each cell's added in
// increasing cell order (as a serial scatter over the unknowns would); the joined and leaving cells
// are selected in fixed chunks; the cascade is serial, in join order.
#pragma once

#include "transport/Domain.h"
#include "transport/Poisson.h"
#include "transport/SolverTuning.h"

#include <cstddef>
#include <cstdint>
#include <vector>

namespace vdbclay {
namespace transport_internal {

/// The rounds' arrays, kept in a workspace from one call to the next.
struct ActiveSetArrays {
    std::vector<double> p;      ///< the potential, one entry per cell (0 on the Dirichlet cells)
    std::vector<double> inflow; ///< per cell: a Dirichlet cell's inflow (0 elsewhere)
    std::vector<int32_t> joined, left;
    std::vector<size_t> counts;
};

/// Runs the rounds on @a domain (built, its singular parts frozen), solving by @a solver; leaves the
/// potential in @a arrays.p. Counts into @a rep (solves and their counts; noRoom and massNoRoom when
/// a joined cell walls in a part).
void solveActiveSet(Domain& domain, PoissonSolver& solver, const SolverTuning& tuning, bool serial,
                    ActiveSetArrays& arrays, GlobalTransportReport& rep);

} // namespace transport_internal
} // namespace vdbclay
