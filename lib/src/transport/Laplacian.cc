// The pressure's Poisson problem (Laplacian.h: the design).

#include "transport/Laplacian.h"
#include "transport/Chunks.h"

#include <algorithm>

namespace vdbclay {
namespace transport_internal {

void Laplacian::selectRows(const Cells& cells, bool serial)
{
    row.resize(cells.size());
    forChunks(cells.size(), serial, [&](size_t lo, size_t hi) { std::fill(&row[lo], &row[0] + hi, -1); });
    selectIndices(cells.size(), serial, counts, rowCell, [&](size_t i) { return cells.kind[i] == kUnknown; });
}

void Laplacian::orderRows(const std::vector<int32_t>& order, const Cells& cells)
{
    rowCell.clear();
    for (const int32_t i : order)
        if (cells.kind[size_t(i)] == kUnknown) rowCell.push_back(i);
}

void Laplacian::assemble(const Cells& cells, int32_t threshold, bool serial)
{
    forChunks(rowCell.size(), serial, [&](size_t lo, size_t hi) {
        for (size_t k = lo; k < hi; ++k)
            row[size_t(rowCell[k])] = int32_t(k);
    });
    const size_t n = rowCell.size();
    if (n == 0) return;
    // Every entry written: a neighbour's row is row's (-1 for a Dirichlet or frozen cell, and the
    // cells' nb holds -1 past their faces); the diagonal counts the faces to non-frozen cells.
    nb.resize(n * 6);
    faces.resize(n);
    b.resize(n);
    forChunks(n, serial, [&](size_t lo, size_t hi) {
        for (size_t k = lo; k < hi; ++k) {
            const size_t i = size_t(rowCell[k]);
            uint8_t count = 0;
            for (int d = 0; d < 6; ++d) {
                const int32_t j = cells.nb[i * 6 + size_t(d)];
                int32_t r = -1;
                if (j >= 0) {
                    count += cells.kind[size_t(j)] != kFrozen ? 1 : 0;
                    r = row[size_t(j)];
                }
                nb[k * 6 + size_t(d)] = r;
            }
            faces[k] = count;
            b[k] = double(cells.m0[i] - threshold);
        }
    });
}

void Laplacian::release()
{
    std::vector<int32_t>().swap(nb);
    std::vector<uint8_t>().swap(faces);
    std::vector<double>().swap(b);
}

} // namespace transport_internal
} // namespace vdbclay
