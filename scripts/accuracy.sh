#!/usr/bin/env bash
# The accuracy study (docs/ACCURACY.md), regenerated in one command from the repository root:
#   scripts/accuracy.sh            # ~5 min on the 2-core development machine
#   scripts/accuracy.sh --quick    # a smoke test into build-bench/accuracy-quick (seconds)
# Builds bench/accuracy_study in build-bench/ (Release, -DVDBCLAY_BUILD_BENCH=ON, needs
# libbenchmark-dev like the other benchmarks), runs it into docs/accuracy/ (CSVs), then
# scripts/accuracy_plots.py draws docs/accuracy/sweep-*.png and writes docs/accuracy/tables.md.
# Plots need Debian's python3-matplotlib (apt-get install python3-matplotlib).
set -euo pipefail
cd "$(dirname "$0")/.."

OUT=docs/accuracy
ARGS=()
if [ "${1:-}" = "--quick" ]; then
  OUT=build-bench/accuracy-quick
  ARGS+=(--quick)
fi

if [ ! -f build-bench/CMakeCache.txt ]; then
  cmake -S . -B build-bench -G Ninja -DCMAKE_BUILD_TYPE=Release -DVDBCLAY_BUILD_BENCH=ON \
        -DCMAKE_CXX_COMPILER_LAUNCHER="$(command -v ccache || true)"
fi
cmake --build build-bench --target accuracy_study --parallel "${JOBS:-1}"

mkdir -p "$OUT"
start=$(date +%s)
build-bench/bench/accuracy_study "${ARGS[@]}" --out "$OUT" --scenes data/scenes 2>&1 | tee "$OUT/study.log"
/usr/bin/python3 scripts/accuracy_plots.py "$OUT"
echo "accuracy.sh: study and plots in $(( $(date +%s) - start )) s; results in $OUT/"
