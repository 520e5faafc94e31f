// One solve of the pressure's Poisson problem (Transport.cc, step 3): the Laplacian on the unknown
// cells (Laplacian.h), its preconditioner, and conjugate gradients (Pcg.h) warm-started from p.
//
// The preconditioner. Under SolverTuning::multigridMin rows, MIC(0) (Mic0.h) with the rows in
// coordinate order: every cell of the domain is kept in that order across the active set's rounds,
// only the cells added since the last round sorted and merged in (the rounds add a thin rim); the rows
// are its unknown cells. From multigridMin rows, the aggregation multigrid (Multigrid.h), the rows in
// cell order (the flood's): the hierarchy of the call's first multigrid solve is rebound to the later
// rounds' matrices while they keep at least 95 % of its rows (cells are only ever appended, and the
// matrices change only at the rim).
#pragma once

#include "transport/Domain.h"
#include "transport/Laplacian.h"
#include "transport/Mic0.h"
#include "transport/Multigrid.h"
#include "transport/Pcg.h"
#include "transport/RadixSort.h"

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

namespace vdbclay {
namespace transport_internal {

/// The solves' arrays, kept in a workspace from one call to the next.
struct PoissonArrays {
    Laplacian laplacian;
    std::vector<int32_t> byCoord; ///< every cell in coordinate order (MIC(0)'s rows)
    std::vector<int32_t> mgRow;   ///< cell -> its row in the multigrid's finest level, or -1
    std::vector<int32_t> oldRow;  ///< row -> its row in the multigrid's finest level, or -1
    std::vector<CellCoord> coord; ///< row -> its cell's coordinates (the multigrid's colours)
    Mic0 mic;
    std::unique_ptr<Multigrid> mg;
    PcgVectors pcg;
};

class PoissonSolver {
public:
    /// Solves on @a cells (the domain, built), its arrays in @a arrays; @a sort: the coordinate sort's
    /// scratch. No hierarchy is kept from an earlier call.
    PoissonSolver(const Cells& cells, PoissonArrays& arrays, RadixScratch& sort, int32_t threshold,
                  uint64_t multigridMin, bool serial);

    /// Solves L p = m0 - Tc on the unknown cells to @a tolerance, from @a p (one entry per cell; the
    /// unknowns' entries are written). @a same: the set is that of the last solve (a tighter pass after
    /// a loose one): the matrix and the preconditioner are kept. Counts into @a rep (solves, unknowns,
    /// iterations, multigridSolves, multigridReused).
    void solve(std::vector<double>& p, double tolerance, bool same, GlobalTransportReport& rep);

    size_t rows() const { return mB.laplacian.rows(); } ///< the last solve's unknowns

    /// Frees what the solves kept across rounds (hierarchy, matrix, work vectors), unless @a keep
    /// (the arrays outlive the call: a workspace).
    void release(bool keep);

private:
    void setUp(GlobalTransportReport& rep);

    const Cells& mCells;
    PoissonArrays& mB;
    RadixScratch& mSort;
    int32_t mTc;
    uint64_t mMultigridMin;
    bool mSerial;
    Multigrid* mMg = nullptr; ///< the last set-up's multigrid (mB.mg), or none: MIC(0) (mB.mic)
    bool mMgBuilt = false;    ///< mB.mg holds this call's hierarchy (of an earlier round)
    size_t mByCoordCells = 0; ///< mB.byCoord lists the cells [0, this)
};

} // namespace transport_internal
} // namespace vdbclay
