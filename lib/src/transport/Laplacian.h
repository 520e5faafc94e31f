// The pressure's Poisson problem on the unknown cells (Transport.cc, step 3): L p = m - Tc, with L's
// row for a cell its faces to non-frozen cells on the diagonal and -1 for each unknown neighbour
// (a Dirichlet neighbour has p = 0; a frozen one, or a wall, passes no flux). The caller orders the
// rows (selectRows(), then optionally orderRows()); assemble() numbers them and fills the matrix.
// Set-up in fixed chunks (Chunks.h): the same rows and entries on any thread count.
#pragma once

#include "transport/Domain.h"

#include <cstddef>
#include <cstdint>
#include <vector>

namespace vdbclay {
namespace transport_internal {

struct Laplacian {
    std::vector<int32_t> row;     ///< cell -> its row, or -1 (not an unknown); read by assemble() only
    std::vector<int32_t> rowCell; ///< row -> its cell
    std::vector<int32_t> nb;      ///< 6 per row: the neighbour's row, or -1 (Dirichlet, frozen, a wall)
    std::vector<double> diag;     ///< the faces to non-frozen cells
    std::vector<double> b;        ///< m0 - Tc
    std::vector<size_t> counts;   ///< scratch of selectRows()

    size_t rows() const { return rowCell.size(); }
    /// The rows: the unknown cells of @a cells, in cell order.
    void selectRows(const Cells& cells, bool serial);
    /// The rows: the unknown cells of @a order (cells), in its order.
    void orderRows(const std::vector<int32_t>& order, const Cells& cells);
    /// Numbers the rows and, if there are any, fills nb, diag and b (every entry written).
    void assemble(const Cells& cells, int32_t threshold, bool serial);
    /// Frees the matrix (nb, diag, b).
    void release();
};

} // namespace transport_internal
} // namespace vdbclay
