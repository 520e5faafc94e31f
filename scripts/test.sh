#!/usr/bin/env bash
# Builds vdbclay and runs the whole test suite through ctest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/build.sh
cd "${BUILD_DIR:-build}"
ctest --output-on-failure --parallel "${JOBS:-2}" --timeout 900
