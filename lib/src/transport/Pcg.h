// Preconditioned conjugate gradients on the pressure's Poisson problem (Laplacian.h), its rows at a
// fixed width (6 neighbour rows per row, n for a missing face: the preconditioner's copy of them).
//
// Determinism. The vector operations run over fixed chunks (Chunks.h); each dot product adds its
// per-chunk partial sums in chunk order, and A p is formed with its dot product in the same pass. So
// every floating-point operation, and the iteration count, is the same on any thread count.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace vdbclay {
namespace transport_internal {

/// A symmetric positive definite approximation M of A, applied as its inverse.
class Preconditioner {
public:
    virtual ~Preconditioner() = default;
    /// @a out = M^-1 @a in (the first n entries; @a out may be resized).
    virtual void apply(const std::vector<double>& in, std::vector<double>& out) = 0;
};

/// The solver's vectors, kept across solves (every entry is written before it is read).
struct PcgVectors {
    std::vector<double> x, r, z, p, q;
    void release();
};

/// Solves A x = b by conjugate gradients preconditioned by @a m, from the first n entries of @a v.x
/// (the warm start; the solution on return), until the residual is at most @a tolerance times |b|
/// (or 20,000 iterations, or a breakdown). A's row k: @a faces[k] x_k minus x over @a rows[6k, 6k + 6)
/// (n: a missing face). Returns the iterations.
uint64_t conjugateGradients(size_t n, const int32_t* rows, const std::vector<uint8_t>& faces,
                            const std::vector<double>& b, Preconditioner& m, double tolerance, bool serial,
                            PcgVectors& v);

} // namespace transport_internal
} // namespace vdbclay
