#!/usr/bin/env bash
# Builds vdbclay with clang, AddressSanitizer + UndefinedBehaviorSanitizer and the libFuzzer targets
# in build-asan/, then runs the test suite there (any sanitizer report fails the run). The same
# build serves scripts/test-fuzz.sh. (ThreadSanitizer needs a TSan-instrumented oneTBB, which
# Debian does not ship: see docs/ROBUSTNESS.md.) scripts/build.sh uses ccache when it is installed.
set -euo pipefail
cd "$(dirname "$0")/.."
export BUILD_DIR=${ASAN_BUILD_DIR:-build-asan}
# A build-asan/ configured by an earlier gcc build of this script cannot switch compilers in place.
if [ -f "$BUILD_DIR/CMakeCache.txt" ] &&
   ! grep -q '^CMAKE_CXX_COMPILER:[A-Z]*=.*clang++' "$BUILD_DIR/CMakeCache.txt"; then
  echo "test-sanitizers: $BUILD_DIR was configured with another compiler; starting it afresh" >&2
  rm -rf "$BUILD_DIR"
fi
# No Python module here: an ASan-built extension cannot load into an uninstrumented python3.
bash scripts/build.sh -DCMAKE_CXX_COMPILER=clang++ -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DVDBCLAY_SANITIZE=address,undefined -DVDBCLAY_BUILD_FUZZERS=ON -DVDBCLAY_BUILD_PYTHON=OFF
source scripts/sanitizer-env.sh
cd "$BUILD_DIR"
# The install/find_package tests check packaging, not memory: the main run covers them.
# The long runs (10^5 and 10^6 steps) stay in the normal stage: under ASan they cost minutes and
# fill its quarantine, and they test conservation and flat memory, which the normal build checks.
ctest --output-on-failure --parallel "${JOBS:-2}" --timeout 1800 \
  -E '^package_|^SettleTest.LongRunKeepsMassExactAndAllocatesNothing$|^SculptorTest.LongRunKeepsMassExactAndMemoryFlat$|^AutomatonTest.MassIsExactOverHundredThousandStepsWithObstacles$'
