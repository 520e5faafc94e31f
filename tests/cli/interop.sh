#!/usr/bin/env bash
# --up for run, mesh and import; import's --grid and its default voxel size (the level set's own).
# usage: interop.sh VDBCLAY WORKDIR
set -euo pipefail
bin=$1; work=$2
rm -rf "$work"; mkdir -p "$work"; cd "$work"
fail() { echo "FAIL: $*"; exit 1; }
printf '{"voxel_size": 0.25, "clay": [{"shape": "box", "min": [0,0,0], "max": [7,15,3], "mass": 1000}]}' > tall.json
"$bin" run tall.json --quiet --up z -o z.vdb --mesh z.obj > /dev/null
"$bin" info z.vdb | grep -q 'vdbclay_up (string) = z' || fail "run --up z: no vdbclay_up in the file"
# The box is 16 voxels tall along index y: with up z the mesh's z spans 16 * 0.25 = 4 world units.
zspan=$(awk '$1 == "v" { if (min == "" || $4 < min) min = $4; if (max == "" || $4 > max) max = $4 } END { printf "%.3f", max - min }' z.obj)
[ "$zspan" = "4.000" ] || fail "run --up z: mesh z span $zspan, expected 4.000"
"$bin" mesh z.vdb -o y.obj --up y > /dev/null
yspan=$(awk '$1 == "v" { if (min == "" || $3 < min) min = $3; if (max == "" || $3 > max) max = $3 } END { printf "%.3f", max - min }' y.obj)
[ "$yspan" = "4.000" ] || fail "mesh --up y: mesh y span $yspan, expected 4.000"
# Import the file's own surface level set: its voxel size (0.25) by default, read z-up.
"$bin" import z.vdb --grid surface --up z -o back.vdb --mass 1000 > import.log
"$bin" info back.vdb | grep -q 'voxel size: 0.25' || fail "import: voxel size not the level set's"
grep -q 'wrote back.vdb: 512 voxels' import.log || fail "import: $(cat import.log), expected 512 voxels"
# Without --grid: the first level set, at its own voxel size (this path once read a freed vector).
"$bin" import z.vdb --up z -o back2.vdb --mass 1000 > import2.log || fail "import without --grid: exit $?"
grep -q 'wrote back2.vdb: 512 voxels' import2.log || fail "import without --grid: $(cat import2.log)"
"$bin" info back2.vdb | grep -q 'voxel size: 0.25' || fail "import without --grid: voxel size not the level set's"
if "$bin" run tall.json --quiet --up x -o x.vdb 2> err.txt; then fail "--up x accepted"; fi
grep -q -- '--up' err.txt || fail "--up x: $(cat err.txt)"
if "$bin" import tall.json --grid a -o g.vdb --mass 1 2> err.txt; then fail "--grid on a mesh accepted"; fi
grep -q -- '--grid' err.txt || fail "--grid: $(cat err.txt)"
# mesh --keep-volume: the box's mesh read back as mesh clay holds the box's 8 x 16 x 4 = 512 voxels
# of volume within 0.5 % (without it, marching cubes cuts the box's edges: 2 % less).
"$bin" mesh z.vdb -o kept.obj --keep-volume > /dev/null
"$bin" import kept.obj --voxel-size 0.25 --up z -o kept.vdb --mass 1000 > kept.log
mass=$(sed -n 's/.*mass \([0-9]*\).*/\1/p' kept.log)
[ -n "$mass" ] && [ "$mass" -ge 509440 ] && [ "$mass" -le 514560 ] || fail "mesh --keep-volume: $(cat kept.log), expected mass 512000 +- 0.5 %"
# A fog volume: the clay file's own density grid gives its mass back, with a note naming the class.
"$bin" import z.vdb --grid density -o fog.vdb --mass 1000 > fog.log
grep -q 'fog volume' fog.log || fail "import of a fog volume: no note: $(cat fog.log)"
grep -q 'mass 512000' fog.log || fail "import of a fog volume: $(cat fog.log), expected mass 512000"
# A PLY written by vdbclay mesh reads back as mesh clay.
"$bin" mesh z.vdb -o z.ply > /dev/null
"$bin" import z.ply --voxel-size 0.25 --up z -o ply.vdb --mass 1000 > ply.log
grep -q 'wrote ply.vdb' ply.log || fail "import of a PLY: $(cat ply.log)"
echo "INTEROP CLI OK"
