#!/usr/bin/env bash
# Runs each libFuzzer target of build-asan/ (built by scripts/test-sanitizers.sh) for a bounded
# time over its seed corpus (tests/fuzz/corpus/*); any crash, leak, sanitizer report or timeout
# fails. FUZZ_SECONDS per target (default 60). New inputs go to a scratch corpus in the build
# directory, crashes to build-asan/fuzz-crashes/ (see docs/ROBUSTNESS.md).
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=${ASAN_BUILD_DIR:-build-asan}
seconds=${FUZZ_SECONDS:-60}
source scripts/sanitizer-env.sh
crashes="$PWD/$BUILD_DIR/fuzz-crashes"
mkdir -p "$crashes"
status=0
for target in scene vdb mesh; do
  bin="$BUILD_DIR/tests/fuzz/fuzz_$target"
  [ -x "$bin" ] || { echo "test-fuzz: $bin is missing: run scripts/test-sanitizers.sh first" >&2; exit 2; }
  scratch="$BUILD_DIR/fuzz-corpus/$target"
  mkdir -p "$scratch"
  echo "test-fuzz: fuzz_$target for ${seconds} s"
  # -timeout: one input may take 10 s at most; -rss_limit_mb: 2 GB in all. The final stats line
  # (exec/s, coverage) is kept in the log.
  if ! "$bin" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 \
       -artifact_prefix="$crashes/$target-" "$scratch" "tests/fuzz/corpus/$target" \
       > "$BUILD_DIR/fuzz-$target.log" 2>&1; then
    echo "test-fuzz: fuzz_$target FAILED; its log:" >&2
    grep -v '^#[0-9]' "$BUILD_DIR/fuzz-$target.log" | tail -60 >&2
    status=1
  else
    grep -E '^#[0-9]+[[:space:]]+DONE|stat::(number_of_executed_units|average_exec_per_sec|peak_rss_mb)' \
      "$BUILD_DIR/fuzz-$target.log" || true
  fi
done
[ $status -eq 0 ] && echo "test-fuzz: no crash" || echo "test-fuzz: crashes in $crashes" >&2
exit $status
