// The pressure's Poisson problem on the unknown cells (Transport.cc, step 3): L p = m - Tc, with L's
// row for a cell its faces to non-frozen cells on the diagonal and -1 for each unknown neighbour
// (a Dirichlet neighbour has p = 0; a frozen one, or a wall, passes no flux). The caller orders the
// rows (selectRows(), then optionally orderRows()); assemble() numbers them and fills the matrix.
// Set-up in fixed chunks (Chunks.h): the same rows and entries on any thread count.
//
// The diagonal is stored as what it is, a face count (0-6) in a byte: the solves' hot loops read it
// as double(faces) and its inverse from kInverseFaces, the very values (exact integers, and 1.0 /
// their double) a double diagonal held, in 1 byte a row instead of 8 (16 with the multigrid's inverse).
#pragma once

#include "transport/Domain.h"

#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

namespace vdbclay {
namespace transport_internal {

/// 1.0 / double(f) for a diagonal of f faces (a row with none: 1.0 / 0.0, infinity).
constexpr double kInverseFaces[7] = {std::numeric_limits<double>::infinity(),
                                     1.0 / 1.0,
                                     1.0 / 2.0,
                                     1.0 / 3.0,
                                     1.0 / 4.0,
                                     1.0 / 5.0,
                                     1.0 / 6.0};

struct Laplacian {
    std::vector<int32_t> row;     ///< cell -> its row, or -1 (not an unknown); read by assemble() only
    std::vector<int32_t> rowCell; ///< row -> its cell
    std::vector<int32_t> nb;      ///< 6 per row: the neighbour's row, or -1 (Dirichlet, frozen, a wall)
    std::vector<uint8_t> faces;   ///< the diagonal: the faces to non-frozen cells
    std::vector<double> b;        ///< m0 - Tc
    std::vector<size_t> counts;   ///< scratch of selectRows()

    size_t rows() const { return rowCell.size(); }
    /// The rows: the unknown cells of @a cells, in cell order.
    void selectRows(const Cells& cells, bool serial);
    /// The rows: the unknown cells of @a order (cells), in its order.
    void orderRows(const std::vector<int32_t>& order, const Cells& cells);
    /// Numbers the rows and, if there are any, fills nb, faces and b (every entry written).
    void assemble(const Cells& cells, int32_t threshold, bool serial);
    /// Frees the matrix (nb, faces, b).
    void release();
};

} // namespace transport_internal
} // namespace vdbclay
