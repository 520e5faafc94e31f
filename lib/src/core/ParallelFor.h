// Index loops for the push and the tools' placement, run on the caller's thread count.
//
// threads == 1 runs the loop on the calling thread (the serial path, as the automaton's); 0 lets TBB
// use every core; n > 1 caps the loop at n workers in a task arena. The body must only write data
// owned by its index (e.g. a per-leaf result vector), so that the caller can merge the results in
// index order and get the same answer on any thread count.
#pragma once

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <cstddef>

namespace vdbclay {
namespace parallel_internal {

template <typename F> void forEachIndex(size_t n, int threads, F&& body)
{
    if (n == 0) return;
    if (threads == 1 || n == 1) {
        for (size_t i = 0; i < n; ++i)
            body(i);
        return;
    }
    auto loop = [&] {
        tbb::parallel_for(tbb::blocked_range<size_t>(0, n), [&](const tbb::blocked_range<size_t>& r) {
            for (size_t i = r.begin(); i != r.end(); ++i)
                body(i);
        });
    };
    if (threads > 1) {
        tbb::task_arena arena(threads);
        arena.execute(loop);
    } else {
        loop();
    }
}

} // namespace parallel_internal
} // namespace vdbclay
