// One solve of the pressure's Poisson problem (Poisson.h: the design).

#include "transport/Poisson.h"
#include "transport/Chunks.h"

#include <algorithm>

namespace vdbclay {
namespace transport_internal {

PoissonSolver::PoissonSolver(const Cells& cells, PoissonArrays& arrays, RadixScratch& sort, int32_t threshold,
                             uint64_t multigridMin, bool serial)
    : mCells(cells), mB(arrays), mSort(sort), mTc(threshold), mMultigridMin(multigridMin), mSerial(serial)
{
    mB.byCoord.clear();
    mB.mgRow.clear();
}

void PoissonSolver::setUp(GlobalTransportReport& rep)
{
    Laplacian& lap = mB.laplacian;
    lap.selectRows(mCells, mSerial);
    const bool multigrid = lap.rows() >= mMultigridMin;
    if (!multigrid) {
        // Every cell in coordinate order, kept across the rounds: only the cells added since the
        // last round are sorted and merged in; the rows are the unknown cells of that list (the same
        // order a sort of the rows would give).
        std::vector<int32_t>& byCoord = mB.byCoord;
        const auto before = [&](int32_t a, int32_t b) { return mCells.at[size_t(a)] < mCells.at[size_t(b)]; };
        const size_t old = byCoord.size();
        for (size_t i = mByCoordCells; i < mCells.size(); ++i)
            byCoord.push_back(int32_t(i));
        sortByCoord(byCoord, old, mCells.at, mSort);
        std::inplace_merge(byCoord.begin(), byCoord.begin() + std::ptrdiff_t(old), byCoord.end(), before);
        mByCoordCells = mCells.size();
        lap.orderRows(byCoord, mCells);
    }
    lap.assemble(mCells, mTc, mSerial);
    const size_t n = lap.rows();
    mMg = nullptr;
    if (n == 0) return;
    if (!multigrid) {
        mB.mic.factor(n, lap.nb, lap.faces);
        return;
    }
    // The hierarchy of the call's first multigrid round serves the later rounds (rebind) while they
    // keep most of its rows; rows are in cell order, and cells are only ever appended.
    std::vector<int32_t>& oldRow = mB.oldRow;
    std::vector<CellCoord>& coord = mB.coord;
    oldRow.resize(n);
    coord.resize(n);
    if (!mB.mg) mB.mg = std::make_unique<Multigrid>();
    Multigrid& mg = *mB.mg;
    const bool reusable = mMgBuilt && mg.levels() >= 2;
    std::vector<double> partial;
    const double kept = chunkedSum(n, mSerial, partial, [&](size_t k) {
        const size_t i = size_t(lap.rowCell[k]);
        coord[k] = mCells.at[i];
        oldRow[k] = reusable && i < mB.mgRow.size() ? mB.mgRow[i] : -1;
        return oldRow[k] >= 0 ? 1.0 : 0.0;
    });
    if (reusable && kept >= double(n - n / 20) && kept > 0) {
        mg.rebind(n, lap.nb, lap.faces, coord, oldRow, mSerial);
        ++rep.multigridReused;
    } else {
        mg.build(n, lap.nb, lap.faces, coord, mSerial);
        mMgBuilt = true;
    }
    mB.mgRow.swap(lap.row); // the next set-up writes the Laplacian's rows afresh
    mMg = &mg;
}

void PoissonSolver::solve(std::vector<double>& p, double tolerance, bool same, GlobalTransportReport& rep)
{
    ++rep.solves;
    if (!same) setUp(rep);
    const Laplacian& lap = mB.laplacian;
    const size_t n = lap.rows();
    rep.unknowns = n;
    if (n == 0) return;
    if (mMg) ++rep.multigridSolves;
    Preconditioner& m = mMg ? static_cast<Preconditioner&>(*mMg) : mB.mic;
    // A p reads the preconditioner's fixed-width rows (the multigrid's finest level's, or MIC(0)'s).
    const int32_t* rows = mMg ? mMg->finestRows().data() : mB.mic.rows().data();
    std::vector<double>& x = mB.pcg.x;
    x.resize(n);
    forChunks(n, mSerial, [&](size_t lo, size_t hi) {
        for (size_t k = lo; k < hi; ++k)
            x[k] = p[size_t(lap.rowCell[k])];
    });
    rep.iterations += conjugateGradients(n, rows, lap.faces, lap.b, m, tolerance, mSerial, mB.pcg);
    forChunks(n, mSerial, [&](size_t lo, size_t hi) {
        for (size_t k = lo; k < hi; ++k)
            p[size_t(lap.rowCell[k])] = x[k];
    });
}

void PoissonSolver::release(bool keep)
{
    mMgBuilt = false;
    mMg = nullptr;
    if (keep) return;
    mB.mg.reset();
    std::vector<int32_t>().swap(mB.mgRow);
    mB.laplacian.release();
    mB.mic.release();
    mB.pcg.release();
}

} // namespace transport_internal
} // namespace vdbclay
