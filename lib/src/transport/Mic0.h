// MIC(0): the modified incomplete Cholesky preconditioner of the global transport's smaller solves
// (Poisson.h picks it below SolverTuning::multigridMin rows).
//
// A ~ (D + L) D^-1 (D + L)^T with L the strictly lower part of A (all -1) and D the pivots: eliminating
// row j leaves fill-in 1/d_j between each pair of its later neighbours; MIC adds the dropped fill-in
// of row k to its pivot (Bridson's tuning 0.97, safety 0.25). The rows must be in coordinate order
// (x, y, z), the factor's natural order: with kDir's -x, +x, -y, +y, -z, +z a row's even faces are its
// lower neighbours and its odd faces its upper ones, so the factor and the triangular solves read
// only those. Serial (triangular solves): the same on any thread count.
#pragma once

#include "transport/Pcg.h"

#include <cstddef>
#include <cstdint>
#include <vector>

namespace vdbclay {
namespace transport_internal {

class Mic0 final : public Preconditioner {
public:
    /// Factors the matrix of @a n rows given by @a nb (6 per row, the neighbour row or -1; off-diagonals
    /// -1) and @a faces (the diagonal), its rows in coordinate order.
    void factor(size_t n, const std::vector<int32_t>& nb, const std::vector<uint8_t>& faces);
    /// @a out = (D + L)^-T D (D + L)^-1 @a in. @a out gets n + 1 entries, the last -0 (the backward
    /// solve's sentinel).
    void apply(const std::vector<double>& in, std::vector<double>& out) override;
    /// The rows at a fixed width: 6 per row, the neighbour row or n (none).
    const std::vector<int32_t>& rows() const { return mRows; }
    /// Frees the factor (the rows stay).
    void release();

private:
    size_t mN = 0;
    std::vector<int32_t> mRows;
    std::vector<double> mInv; ///< 1 / pivot
    std::vector<double> mW;   ///< the forward solve's result, n + 1 (the last -0, its sentinel)
};

} // namespace transport_internal
} // namespace vdbclay
