// Fixed-chunk loops for the global transport's row arrays (its solver, routing and multigrid).
//
// Every loop runs over fixed chunks of kChunk rows, whatever the thread count: a chunk is the unit
// of parallel work, and a reduction adds its per-chunk partial sums in chunk order. So each
// floating-point operation, and each list selected, is the same on 1 thread or many, and the layer's
// results are identical on any thread count. Serial (serial = true, or one chunk) runs the same body
// on the calling thread. No OpenVDB here: these work on plain arrays.
#pragma once

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace vdbclay {
namespace transport_internal {

constexpr size_t kChunk = 4096;

/// Runs @a fn(begin, end) over fixed chunks of [0, n), in parallel unless serial.
template <typename Fn> void forChunks(size_t n, bool serial, const Fn& fn)
{
    const size_t chunks = (n + kChunk - 1) / kChunk;
    if (serial || chunks < 2) {
        for (size_t c = 0; c < chunks; ++c)
            fn(c * kChunk, std::min(n, (c + 1) * kChunk));
        return;
    }
    tbb::parallel_for(tbb::blocked_range<size_t>(0, chunks, 1), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t c = r.begin(); c != r.end(); ++c)
            fn(c * kChunk, std::min(n, (c + 1) * kChunk));
    });
}

/// sum_i f(i) over [0, n): per-chunk partial sums, added in chunk order (thread-count independent).
template <typename Fn> double chunkedSum(size_t n, bool serial, std::vector<double>& partial, const Fn& f)
{
    const size_t chunks = (n + kChunk - 1) / kChunk;
    partial.assign(chunks, 0.0);
    forChunks(n, serial, [&](size_t b, size_t e) {
        double s = 0;
        for (size_t i = b; i < e; ++i)
            s += f(i);
        partial[b / kChunk] = s;
    });
    double s = 0;
    for (double v : partial)
        s += v;
    return s;
}

/// @a out = the indices i in [0, n) with keep(i), ascending: counted and written per fixed chunk (parallel
/// unless serial), the same list on any thread count. @a counts is scratch.
template <typename Pred>
void selectIndices(size_t n, bool serial, std::vector<size_t>& counts, std::vector<int32_t>& out,
                   const Pred& keep)
{
    const size_t chunks = (n + kChunk - 1) / kChunk;
    counts.assign(chunks + 1, 0);
    forChunks(n, serial, [&](size_t lo, size_t hi) {
        size_t c = 0;
        for (size_t i = lo; i < hi; ++i)
            c += keep(i) ? 1 : 0;
        counts[lo / kChunk + 1] = c;
    });
    for (size_t c = 0; c < chunks; ++c)
        counts[c + 1] += counts[c];
    out.resize(counts[chunks]);
    forChunks(n, serial, [&](size_t lo, size_t hi) {
        size_t o = counts[lo / kChunk];
        for (size_t i = lo; i < hi; ++i)
            if (keep(i)) out[o++] = int32_t(i);
    });
}

} // namespace transport_internal
} // namespace vdbclay
