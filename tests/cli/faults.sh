#!/usr/bin/env bash
# Faults outside the scene: a full disk (simulated with the file size limit, RLIMIT_FSIZE, and
# SIGXFSZ ignored so write() fails with EFBIG), an unwritable directory, a scene over its memory
# budget. Each: a non-zero exit, one line on stderr naming the cause, existing files byte for byte
# as they were, no temporary file left.
# usage: faults.sh VDBCLAY WORKDIR
set -uo pipefail
bin=$1; work=$2
rm -rf "$work"; mkdir -p "$work"; cd "$work"
fails=0
fail() { echo "FAIL $*"; fails=$((fails+1)); }
# refused NAME NEEDLE COMMAND...: the command fails with one stderr line holding NEEDLE.
refused() {
  local name=$1 needle=$2; shift 2
  "$@" > out.txt 2> err.txt; local rc=$?
  if [ $rc -eq 0 ] || [ "$(wc -l < err.txt)" -ne 1 ] || ! grep -q -- "$needle" err.txt; then
    fail "$name: rc=$rc, needle '$needle', stderr: $(cat err.txt)"
  else
    echo "PASS $name: $(cat err.txt)"
  fi
}
no_temp_files() { ls ./*.tmp* ./*/*.tmp* > /dev/null 2>&1 && fail "$1: temporary files left: $(ls ./*.tmp* ./*/*.tmp* 2>/dev/null)"; }
# full LIMIT_KB ARGS...: vdbclay with writes limited to LIMIT_KB kilobytes, as on a full disk.
full() { local kb=$1; shift; (ulimit -f "$kb"; trap '' XFSZ; exec "$bin" "$@"); }

# Earlier results that a failed run must leave alone.
"$bin" run --frames 2 --quiet -o old.vdb --stats old.json --mesh old.obj --png old.png > /dev/null ||
  fail "setting up: $?"
for f in old.vdb old.json old.obj old.png; do cp "$f" "$f.copy"; done

# 1. A full disk while writing each kind of output: named, the old file intact, no temporary file.
refused full-disk-vdb "cannot write old.vdb: write failed: File too large" full 16 run --frames 2 --quiet -o old.vdb
refused full-disk-mesh "cannot write old.obj" full 16 run --frames 2 --quiet --mesh old.obj
refused full-disk-png "cannot write old.png" full 4 run --frames 2 --quiet --png old.png
# The stats file is under 1 KiB, ulimit's unit: prlimit sets the limit in bytes (300: the error
# line still fits on stderr, the 557-byte stats do not).
if command -v prlimit > /dev/null; then
  refused full-disk-stats "cannot write old.json: File too large" \
    bash -c 'trap "" XFSZ; exec prlimit --fsize=300 "$0" "$@"' "$bin" run --frames 2 --quiet --stats old.json
else
  echo "SKIP full-disk-stats: no prlimit"
fi
for f in old.vdb old.json old.obj old.png; do cmp -s "$f" "$f.copy" || fail "full disk: $f changed"; done
no_temp_files full-disk

# 2. The scene's own start file as the output, on a full disk: the input survives.
printf '{"start": "old.vdb", "frames": 4, "clay": [],
  "tools": [{"shape": "box", "min": [-8,32,-8], "max": [39,40,39], "path": [{"translate": [0,-1,0], "frames": 8}]}]}' > cont.json
refused full-disk-over-input "cannot write old.vdb" full 16 run cont.json --quiet -o old.vdb
cmp -s old.vdb old.vdb.copy || fail "full disk: the start file changed"
no_temp_files full-disk-over-input
"$bin" run cont.json --quiet -o cont.vdb > /dev/null || fail "the same run with room failed"

# 3. An unwritable directory. Root writes anywhere, so as root the runs drop to user nobody
#    (setpriv, util-linux); without setpriv they are skipped.
mkdir ro && cp old.vdb ro/old.vdb && chmod 555 ro
as_user=()
if [ "$(id -u)" -eq 0 ]; then
  command -v setpriv > /dev/null && as_user=(setpriv --reuid=65534 --regid=65534 --clear-groups)
  # nobody must reach the binary and this directory (not so under a private home directory)
  [ ${#as_user[@]} -gt 0 ] && ! "${as_user[@]}" "$bin" info old.vdb > /dev/null 2>&1 && as_user=()
fi
if [ "$(id -u)" -ne 0 ] || [ ${#as_user[@]} -gt 0 ]; then
  refused unwritable-dir "cannot write ro/out.vdb" "${as_user[@]}" "$bin" run --frames 1 --quiet -o ro/out.vdb
  refused unwritable-dir-existing "ro/old.vdb" "${as_user[@]}" "$bin" run --frames 1 --quiet -o ro/old.vdb
  cmp -s ro/old.vdb old.vdb.copy || fail "unwritable dir: ro/old.vdb changed"
  refused unwritable-checkpoint "cannot write ro/c.vdb" "${as_user[@]}" "$bin" run --frames 1 --quiet --checkpoint ro/c.vdb
else
  echo "SKIP unwritable-dir: running as root, and user nobody cannot run $bin here"
fi
chmod 755 ro

# 4. The memory budget: refused before any work, with the estimate; "none" lifts it.
printf '{"clay": [{"shape": "sphere", "center": [0,0,0], "radius": 3000, "mass": 800}]}' > huge.json
refused budget-cli "needs about .* more than the memory budget of 1.00 GiB" "$bin" run huge.json --memory-budget 1G -o big.vdb
refused budget-default "more than the memory budget of .* (the default" "$bin" run huge.json -o big.vdb
printf '{"memory_budget": "1M", "clay": [{"shape": "box", "min": [0,0,0], "max": [63,63,63], "mass": 800}]}' > small.json
refused budget-scene "more than the memory budget of 1.00 MiB;" "$bin" run small.json -o big.vdb
refused budget-bad "--memory-budget: \"lots\" is not a size" "$bin" run small.json --memory-budget lots
[ -e big.vdb ] && fail "budget: an output was written"
"$bin" run small.json --memory-budget none --quiet > /dev/null 2> err.txt || fail "--memory-budget none: $(cat err.txt)"
"$bin" run small.json --memory-budget 64M --quiet > /dev/null 2> err.txt || fail "--memory-budget 64M: $(cat err.txt)"
no_temp_files budget

[ $fails -eq 0 ] && echo "FAULTS HANDLED" || { echo "$fails failed"; exit 1; }
