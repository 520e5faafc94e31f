#!/usr/bin/env bash
# Builds vdbclay with AddressSanitizer + UndefinedBehaviorSanitizer in build-asan/ and runs the
# test suite there; any sanitizer report fails the run. (ThreadSanitizer needs a TSan-instrumented
# oneTBB, which Debian does not ship: see docs/ROBUSTNESS.md.)
set -euo pipefail
cd "$(dirname "$0")/.."
export BUILD_DIR=${ASAN_BUILD_DIR:-build-asan}
bash scripts/build.sh -DVDBCLAY_SANITIZE=address,undefined -DCMAKE_BUILD_TYPE=RelWithDebInfo
export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1
export UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1
export LSAN_OPTIONS=suppressions=$PWD/tests/sanitizers/lsan.supp
cd "$BUILD_DIR"
# The install/find_package tests check packaging, not memory: the main run covers them.
ctest --output-on-failure --parallel "${JOBS:-2}" --timeout 1800 -E '^package_'
