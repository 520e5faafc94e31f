#!/usr/bin/env bash
# Builds vdbclay and runs the whole test suite through ctest.
set -euo pipefail
cd "$(dirname "$0")/.."
# The tests and the Python module on, whatever an earlier scripts/run.sh found installed.
bash scripts/build.sh -DVDBCLAY_BUILD_TESTS=ON -DVDBCLAY_BUILD_PYTHON=ON
cd "${BUILD_DIR:-build}"
ctest --output-on-failure --parallel "${JOBS:-2}" --timeout 900
