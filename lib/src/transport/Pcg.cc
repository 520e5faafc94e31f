// Preconditioned conjugate gradients (Pcg.h: the design).

#include "transport/Pcg.h"
#include "transport/Chunks.h"

#include <algorithm>
#include <cmath>

namespace vdbclay {
namespace transport_internal {

void PcgVectors::release()
{
    for (std::vector<double>* w : {&x, &r, &z, &p, &q})
        std::vector<double>().swap(*w);
}

uint64_t conjugateGradients(size_t n, const int32_t* rows, const std::vector<uint8_t>& faces,
                            const std::vector<double>& b, Preconditioner& m, double tolerance, bool serial,
                            PcgVectors& v)
{
    std::vector<double>& x = v.x;
    std::vector<double>& r = v.r;
    std::vector<double>& z = v.z;
    std::vector<double>& p = v.p;
    std::vector<double>& q = v.q;
    for (std::vector<double>* w : {&r, &z, &p, &q})
        w->resize(n);
    // Row k of A v (v[n] must be +0: a missing face subtracts it, and v - (+0) is v, a zero's sign
    // too: the same values as a loop over the present faces).
    auto rowOfA = [&](const std::vector<double>& w, size_t k) {
        const int32_t* row = rows + k * 6;
        double s = double(faces[k]) * w[k];
        s -= w[size_t(row[0])];
        s -= w[size_t(row[1])];
        s -= w[size_t(row[2])];
        s -= w[size_t(row[3])];
        s -= w[size_t(row[4])];
        s -= w[size_t(row[5])];
        return s;
    };
    auto apply = [&](std::vector<double>& w, std::vector<double>& out) {
        w.resize(n + 1);
        w[n] = 0.0;
        forChunks(n, serial, [&](size_t lo, size_t hi) {
            for (size_t k = lo; k < hi; ++k)
                out[k] = rowOfA(w, k);
        });
    };
    std::vector<double> partial;
    apply(x, q);
    forChunks(n, serial, [&](size_t lo, size_t hi) {
        for (size_t k = lo; k < hi; ++k) {
            r[k] = b[k] - q[k];
        }
    });
    m.apply(r, z);
    p = z;
    p.resize(n + 1); // A p below: the sentinel, as in apply()
    p[n] = 0.0;
    const double bnorm = std::sqrt(chunkedSum(n, serial, partial, [&](size_t k) { return b[k] * b[k]; }));
    const double stop = tolerance * std::max(bnorm, 1e-300);
    double rz = chunkedSum(n, serial, partial, [&](size_t k) { return r[k] * z[k]; });
    double rr = chunkedSum(n, serial, partial, [&](size_t k) { return r[k] * r[k]; });
    // Each pass below also forms its dot product, per chunk, added in chunk order.
    auto pass = [&](const auto& fn) {
        const size_t chunks = (n + kChunk - 1) / kChunk;
        partial.assign(chunks, 0.0);
        forChunks(n, serial, [&](size_t lo, size_t hi) { partial[lo / kChunk] = fn(lo, hi); });
        double sum = 0;
        for (double w : partial)
            sum += w;
        return sum;
    };
    const uint64_t maxIt = 20000;
    uint64_t iterations = 0;
    for (uint64_t it = 0; it < maxIt; ++it) {
        if (std::sqrt(rr) <= stop) break;
        const double pq = pass([&](size_t lo, size_t hi) { // q = A p, and p . q
            double sum = 0;
            for (size_t k = lo; k < hi; ++k) {
                const double w = rowOfA(p, k);
                q[k] = w;
                sum += p[k] * w;
            }
            return sum;
        });
        if (!(pq > 0)) break;
        const double alpha = rz / pq;
        rr = pass([&](size_t lo, size_t hi) {
            double sum = 0;
            for (size_t k = lo; k < hi; ++k) {
                x[k] += alpha * p[k];
                r[k] -= alpha * q[k];
                sum += r[k] * r[k];
            }
            return sum;
        });
        m.apply(r, z);
        const double rzNew = chunkedSum(n, serial, partial, [&](size_t k) { return r[k] * z[k]; });
        const double beta = rzNew / rz;
        rz = rzNew;
        forChunks(n, serial, [&](size_t lo, size_t hi) {
            for (size_t k = lo; k < hi; ++k)
                p[k] = z[k] + beta * p[k];
        });
        ++iterations;
    }
    return iterations;
}

} // namespace transport_internal
} // namespace vdbclay
