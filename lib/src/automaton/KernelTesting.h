// Test hooks of the kernel: run a pass on a path the run-time dispatch would not choose, so that
// tests (tests/TestKernel.cc) and benchmarks (bench/bench_kernels.cc) can compare every path on the
// same input. The library never calls them: processRange (Kernel.h) always takes the default paths.
#pragma once

#include "automaton/Kernel.h"
#include "automaton/OverFilter.h"

#include <cstddef>

namespace vdbclay {
namespace automaton_internal {
namespace kernel_testing {

/// Which paths a pass takes. The defaults are processRange's.
struct Paths {
    bool portable = false; // no SIMD: the plain C++ path
    bool avx2 = true;      // the pass's AVX2 build where the CPU has it; false: the baseline (SSE2) build
    OverFilter filter = OverFilter::Auto; // the over-cell filter (None on the portable path)
};

/// processRange on @a paths. Every choice gives the same result.
void processRange(const PassInput& in, const Paths& paths, WorkItem* work, size_t begin, size_t end,
                  PassTotals& tot);

/// Whether a pass with Paths::avx2 on runs its AVX2 build on this machine: the CPU has AVX2, BMI1,
/// BMI2 and POPCNT and the build is for x86-64 with GCC or Clang.
bool avx2Pass();

} // namespace kernel_testing
} // namespace automaton_internal
} // namespace vdbclay
