#!/usr/bin/env bash
# Faults outside the scene: a full disk (simulated with the file size limit, RLIMIT_FSIZE, and
# SIGXFSZ ignored so write() fails with EFBIG), an unwritable directory, a scene over its memory
# budget. Each: a non-zero exit, one line on stderr naming the cause, existing files byte for byte
# as they were, no temporary file left.
# usage: faults.sh VDBCLAY WORKDIR
set -uo pipefail
source "$(dirname "$0")/lib.sh"
cli_setup "$1" "$2"
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
  refused full-disk-stats "cannot write old.json: write failed: File too large" \
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

# 5. Meshes are checked before they are voxelized: a 12-triangle cube of side 5000
#    (its level set alone needs tens of GiB) and one spanning 0..8e9 are refused at once, as clay,
#    as a tool and in import. Each names a budget: the default one depends on the machine.
cube() { # SIDE FILE: a closed cube of 12 triangles
  local s=$1
  printf 'v 0 0 0\nv %s 0 0\nv %s %s 0\nv 0 %s 0\nv 0 0 %s\nv %s 0 %s\nv %s %s %s\nv 0 %s %s\n' \
    "$s" "$s" "$s" "$s" "$s" "$s" "$s" "$s" "$s" "$s" "$s" "$s" > "$2"
  printf 'f 1 3 2\nf 1 4 3\nf 5 6 7\nf 5 7 8\nf 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\nf 3 4 8\nf 3 8 7\nf 4 1 5\nf 4 5 8\n' >> "$2"
}
cube 5000 big-cube.obj
cube 8e9 far-cube.obj
printf '{"memory_budget": "1G", "clay": [{"shape": "mesh", "file": "big-cube.obj", "mass": 800}]}' > mesh-clay.json
printf '{"memory_budget": "1G", "tools": [{"shape": "mesh", "file": "big-cube.obj", "path": [{"translate": [0,-1,0]}]}]}' > mesh-tool.json
printf '{"clay": [{"shape": "mesh", "file": "far-cube.obj", "mass": 800}]}' > mesh-far.json
refused mesh-clay-too-big "clay\[0\]: big-cube.obj: turning the mesh into a level set needs about" "$bin" run mesh-clay.json -o big.vdb
refused mesh-tool-too-big "tools\[0\]: big-cube.obj: turning the mesh into a level set" "$bin" run mesh-tool.json -o big.vdb
refused mesh-far "far-cube.obj: the mesh spans 0 .. 8e+09 voxels along axis 0 (at voxel size 1), outside the coordinate range" \
  "$bin" run mesh-far.json -o big.vdb
refused import-too-big "big-cube.obj: turning the mesh into a level set" "$bin" import big-cube.obj -o big.vdb --mass 100 --memory-budget 1G
[ -e big.vdb ] && fail "mesh checks: an output was written"
# --memory-budget replaces the scene's budget for the mesh check too: it lifts a scene's small budget
# and lowers the default one (a 40^3 mesh cube needs about 1.5 MiB to become a level set).
cube 40 c40.obj
printf '{"memory_budget": "1M", "clay": [{"shape": "mesh", "file": "c40.obj", "mass": 800}]}' > mesh-1m.json
printf '{"clay": [{"shape": "mesh", "file": "c40.obj", "mass": 800}]}' > mesh-default.json
refused mesh-scene-budget "memory budget of 1.00 MiB" "$bin" run mesh-1m.json --frames 1 -o m.vdb
"$bin" run mesh-1m.json --frames 1 --quiet -o m.vdb --memory-budget 64M > /dev/null 2> err.txt ||
  fail "--memory-budget 64M over a scene's 1M: $(cat err.txt)"
[ -s m.vdb ] || fail "--memory-budget 64M over a scene's 1M: no output"
rm -f m.vdb
refused mesh-cli-budget "mesh-default.json: clay\[0\]: c40.obj: .* memory budget of 1.00 MiB" \
  "$bin" run mesh-default.json --frames 1 -o m.vdb --memory-budget 1M
[ -e m.vdb ] && fail "mesh-cli-budget: an output was written"
# The check is on the mesh as placed, whatever its format: a PLY file, and a small cube scaled up.
{ printf 'ply\nformat ascii 1.0\nelement vertex 8\nproperty float x\nproperty float y\nproperty float z\n'
  printf 'element face 12\nproperty list uchar int vertex_indices\nend_header\n'
  grep '^v ' big-cube.obj | cut -c3-
  grep '^f ' big-cube.obj | awk '{print 3, $2-1, $3-1, $4-1}'; } > big-cube.ply
printf '{"memory_budget": "1G", "clay": [{"shape": "mesh", "file": "big-cube.ply", "mass": 800}]}' > mesh-ply.json
refused mesh-ply-too-big "clay\[0\]: big-cube.ply: turning the mesh into a level set needs about" "$bin" run mesh-ply.json -o big.vdb
refused import-ply-too-big "big-cube.ply: turning the mesh into a level set" "$bin" import big-cube.ply -o big.vdb --mass 100 --memory-budget 1G
printf '{"memory_budget": "1G", "clay": [{"shape": "mesh", "file": "c40.obj", "mass": 800, "transform": {"scale": 125}}]}' > mesh-scaled.json
refused mesh-scaled-too-big "clay\[0\]: c40.obj: turning the mesh into a level set needs about" "$bin" run mesh-scaled.json -o big.vdb
[ -e big.vdb ] && fail "placed mesh checks: an output was written"

# 6. The budget is kept while the run goes on: clay read from a file at 2^31 - 1 per voxel
#    spreads far beyond what the estimate can see in the file, and the run stops with a checkpoint
#    once its grids outgrow the budget, instead of growing until the machine runs out.
cube 3 small-cube.obj
"$bin" import small-cube.obj -o dense.vdb --mass 2147483647 > /dev/null || fail "import of dense clay"
printf '{"memory_budget": "56M", "settle": {"max_steps": 400}, "clay": [{"shape": "vdb", "file": "dense.vdb"}]}' > dense.json
refused budget-while-running "stopped: the clay outgrew the memory budget of 56.0 MiB" "$bin" run dense.json -q -o dense-out.vdb
[ -e dense-out.vdb ] && fail "budget while running: the output was written"
"$bin" info dense-out.checkpoint.vdb > /dev/null 2>&1 || fail "budget while running: no checkpoint"
no_temp_files budget-while-running

[ $fails -eq 0 ] && echo "FAULTS HANDLED" || { echo "$fails failed"; exit 1; }
