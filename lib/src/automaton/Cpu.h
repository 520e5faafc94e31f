// Which of the kernel's instruction-set builds this CPU runs: the automaton's run-time dispatch.
//
// The pass and the over-cell filter exist in a baseline build (SSE2 on x86-64) and, for x86-64 with
// GCC or Clang, in builds for AVX2 (target attributes on single functions: nothing AVX2 leaks into
// code other translation units share); the content hash's sums over tiles (metrics/Metrics.cc) also in
// a build for AVX-512 (F and DQ: 64-bit multiplies in vectors). The CPU is asked once; every build
// gives the same result.
#pragma once

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define VDBCLAY_HAVE_AVX2_BUILD 1
#define VDBCLAY_HAVE_AVX512_BUILD 1
#endif

namespace vdbclay {
namespace automaton_internal {

/// The CPU has AVX2 (the over-cell filter's AVX2 build). False where the build has none.
bool cpuHasAvx2();
/// The CPU has AVX2, BMI1, BMI2 and POPCNT (the pass's AVX2 build). False where the build has none.
bool cpuHasKernelAvx2();
/// The CPU has AVX-512 F and DQ (the content hash's AVX-512 build). False where the build has none.
bool cpuHasAvx512dq();

} // namespace automaton_internal
} // namespace vdbclay
