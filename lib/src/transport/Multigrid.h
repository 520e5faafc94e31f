// Aggregation multigrid: the preconditioner of the global transport's large solves (Poisson.h picks it
// from SolverTuning::multigridMin rows).
//
// Level 0 is the solve's matrix (a graph Laplacian, Dirichlet faces on the diagonal: SPD). Each
// coarser level aggregates the face-connected rows of one 2x2x2 block of the level below (2x2 in 2D:
// z is 0) and takes the Galerkin product P^T A P for piecewise-constant P (integer weights, exact in
// float). One application is a symmetric V-cycle: a red-black Gauss-Seidel sweep from zero (red,
// black), the coarse correction (times alpha: piecewise-constant transfers leave the coarse operator
// too stiff), a sweep in the adjoint order (black, red); the coarsest level by dense Cholesky (or
// damped Jacobi sweeps if coarsening stalls). The colours are the parity of the rows' cell (block)
// coordinates: rows of one colour are never coupled, so a half-sweep runs in parallel, in place.
//
// Determinism. The smoothers and the transfers run on fixed chunks (Chunks.h) and the restriction adds
// an aggregate's members in row order, so every floating-point operation is the same on any thread
// count. The coarsening and the dense factor are serial.
//
// Data. It works on row arrays alone (6 neighbour rows per row, the diagonal, each row's cell), no
// grids: the caller (PoissonSolver) numbers the cells. The finest level's smoothing and transfers run
// on its rows laid out by colour (ColourOrder: the red rows, then the black), so each half-sweep streams
// its own colour's rows alone, with the same operations in the same order as by row; its diagonal is
// read as face counts (Laplacian.h), a byte a row: the values of its double diagonal and inverse. The
// levels' arrays are kept from one build to the next (no fresh pages each frame); nothing of an earlier
// build is read.
#pragma once

#include "transport/CellCoord.h"
#include "transport/Pcg.h"

#include <cstddef>
#include <cstdint>
#include <vector>

namespace vdbclay {
namespace transport_internal {

class Multigrid final : public Preconditioner {
public:
    static constexpr size_t kDense = 512;
    /// The coarsest level's damped Jacobi sweeps (when coarsening stalls), their omega, and the
    /// coarse correction's alpha. Measured on the 64^3 press (MG iterations, 10 frames, tolerance
    /// 1e-4 every active-set round): red-black Gauss-Seidel smoothing 286 (alpha 1.5; 1.0: 393, 1.3:
    /// 286, 1.8: 310), damped Jacobi smoothing (omega 0.8) 370; with roundTolerance 1e-2: 192.
    static constexpr int kCoarseSweeps = 8;
    static constexpr double kOmega = 0.8, kAlpha = 1.5;

    /// Builds the hierarchy of a matrix. @a nb: 6 per row, the neighbour row or -1; @a faces: the
    /// diagonal (Laplacian::faces); @a coord: the rows' cells. The levels' arrays of an earlier build are
    /// reused (their capacity kept: no fresh pages each frame); nothing of the earlier build is read.
    void build(size_t n, const std::vector<int32_t>& nb, const std::vector<uint8_t>& faces,
               const std::vector<CellCoord>& coord, bool serial);

    /// Re-targets the hierarchy to a new finest matrix (the next active-set round: rows join and
    /// leave at the rim, < 2 % of them) without coarsening again: row k keeps the aggregate of the
    /// old row @a oldRow[k]; a new row (-1) gets none (only the smoother corrects it). The coarse
    /// levels keep their matrices (the old rows' couplings are unchanged: a joined neighbour adds
    /// an off-diagonal, a leaving one removes a row, no diagonal changes); the V-cycle stays a
    /// fixed symmetric preconditioner, so conjugate gradients stay correct, and every operation is
    /// still in fixed chunks and row order. Needs levels() >= 2.
    void rebind(size_t n, const std::vector<int32_t>& nb, const std::vector<uint8_t>& faces,
                const std::vector<CellCoord>& coord, const std::vector<int32_t>& oldRow, bool serial);

    /// out = M^-1 in (one V-cycle).
    void apply(const std::vector<double>& in, std::vector<double>& out) override;

    size_t levels() const { return mUsed; }
    /// The finest level's rows at a fixed width: 6 per row, the neighbour row or n (none).
    const std::vector<int32_t>& finestRows() const { return mLevels.front().nb6; }

private:
    struct Level {
        size_t n = 0;
        std::vector<uint32_t> start;
        std::vector<int32_t> col;
        std::vector<float> w; ///< off-diagonal weights (the matrix holds -w); empty: all 1 (level 0)
        std::vector<double> diag, invDiag;
        std::vector<CellCoord> block;      ///< the rows' coordinates on this level's grid
        std::vector<int32_t> agg;          ///< row -> its aggregate (a row of the next level)
        std::vector<uint32_t> memberStart; ///< the rows of the level above in each row (CSR)
        std::vector<int32_t> members;      ///<   in row order
        std::vector<double> x, r, t, chol; ///< work vectors; the dense Cholesky factor
        const double* rhs = nullptr;       ///< the right-hand side a V-cycle reads: r, or apply()'s input
        /// The rows by colour (red-black Gauss-Seidel): the red ones [0, red), then the black, each in
        /// row order.
        std::vector<int32_t> byColour;
        size_t red = 0;
        /// The finest level's rows at a fixed width (conjugate gradients' A p, and the colour order's
        /// source): 6 per row, the neighbour row or n for a missing face.
        std::vector<int32_t> nb6;
        bool dense = false;
    };

    /// The finest level laid out by colour, for its smoothing and transfers (the V-cycle's hottest
    /// loops): place i holds row byColour[i], so a half-sweep streams its own colour's places alone
    /// (in row order its rows interleave with the other colour's, and each pass reads both). The
    /// values and the operations are those of row order, in the same order: a row's residual adds
    /// the same neighbours' x in the same face order, an aggregate's restriction its members in row
    /// order; only where the values lie changes. The V-cycle's first passes copy its input in by
    /// place, its last passes write its output back by row.
    struct ColourOrder {
        std::vector<int32_t> nb6;   ///< 6 per place: the neighbour's place, or n (x[n] = -0)
        std::vector<uint8_t> faces; ///< the diagonal as face counts (Laplacian.h), by place
        std::vector<int32_t> agg;   ///< place -> its aggregate (a row of level 1)
        /// Level 1's red members as places, in row order (CSR): the restriction's terms. A black
        /// row's residual after the pre-smoothing is 0, and adding +0 to a sum that starts at +0
        /// leaves it as it is, so the black members are left out.
        std::vector<uint32_t> redStart;
        std::vector<int32_t> redMembers;
        std::vector<double> rhs, x, t; ///< t: the red rows' residual
    };

    /// The finest level @a f holds the matrix given by @a nb (6 per row, -1: none; off-diagonals -1),
    /// @a faces: its fixed-width rows, and the CSR rows when @a csr (only coarsen() reads them).
    void setMatrix(Level& f, size_t n, const std::vector<int32_t>& nb, const std::vector<uint8_t>& faces,
                   bool csr);
    void setCsr(Level& f, size_t n, const std::vector<int32_t>& nb);
    /// Splits the rows by the parity of their cell (or block) coordinates: rows of one colour are
    /// never coupled (a level's couplings join face-adjacent blocks only: face-connected rows of one
    /// block are one aggregate), so a colour's Gauss-Seidel half-sweep runs in parallel, in place.
    /// Both colours in one count and one write pass (per fixed chunk: the lists of two selectIndices).
    void colour(Level& l, const std::vector<CellCoord>& block);
    /// Lays the finest level out by colour (mFine), from its rows, faces, aggregates and level 1's
    /// members.
    void layOutByColour(const std::vector<uint8_t>& faces);
    void finish(Level& l);
    static int32_t find(std::vector<int32_t>& parent, int32_t a);
    /// Builds the next level; false if it would not shrink the problem enough.
    bool coarsen();
    static void factor(Level& l);
    /// (r - A x) at row @a k (A's off-diagonal entries are -1, or -w on coarse levels), with @a own
    /// as x_k.
    static double residual(const Level& l, size_t k, double own);
    /// residual() on the finest level at place @a i, through its fixed-width rows and face counts: the
    /// same operations in the same order (a missing face adds x[n] = -0, which leaves every sum
    /// unchanged, a zero's sign too).
    double residualByPlace(size_t i, double own) const;
    /// x = x + omega D^-1 (r - A x), one Jacobi sweep.
    void sweep(Level& l);
    /// x_k = x_k + D^-1 (r - A x)_k for the rows of colour @a c: a Gauss-Seidel half-sweep (rows of
    /// one colour do not read each other). @a fromZero: the first sweep of a V-cycle's level, whose
    /// rows of colour @a c hold no x yet (as if 0); their t is set to 0.
    void halfSweep(Level& l, int c, bool fromZero);
    /// The residual restricted to @a c: c.r[i] = the sum of @a t over row i's terms (@a members
    /// [start[i], start[i + 1])), in their order.
    void restrictTo(Level& c, const uint32_t* start, const int32_t* members, const double* t);
    /// The V-cycle from level @a li (> 0, or the finest when it is the only level).
    void cycle(size_t li);
    /// The V-cycle from the finest level, by place (mFine), over at least two levels: out = M^-1 in,
    /// both by row.
    void cycleFinest(const double* in, double* out);

    bool mSerial = true;
    std::vector<Level> mLevels; ///< the first mUsed are this build's; the rest keep their arrays for reuse
    ColourOrder mFine;          ///< the finest level by colour, when mUsed >= 2
    size_t mUsed = 0;
    std::vector<size_t> mCounts; ///< scratch: per-chunk counts
    /// Scratch: coarsen()'s union-find, rebind()'s aggregates, layOutByColour()'s places.
    std::vector<int32_t> mScratch;
    std::vector<int32_t> mWhere;  ///< scratch of coarsen(): a coarse row's place in the row being built
    std::vector<uint8_t> mParity; ///< scratch of colour(): each row's colour
};

} // namespace transport_internal
} // namespace vdbclay
