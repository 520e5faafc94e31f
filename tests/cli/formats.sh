#!/usr/bin/env bash
# Outputs are named for what they hold (a .vdb, a PNG, a mesh; STL written too); import's
# --resolution and its warning for a coarse mesh; a fog volume imported where it lies, z up kept;
# --as density; info's world bounds; run's set-up time.
# usage: formats.sh VDBCLAY WORKDIR
set -uo pipefail
source "$(dirname "$0")/lib.sh"
cli_setup "$1" "$2"
"$bin" demo --size 8 -o c.vdb > /dev/null || fail "demo -o c.vdb"

# 1. An output named for another format is refused before any work; no extension is written as is.
refused render-exr "-o x.exr: this output is a PNG picture; name it .png (\".exr\" names another format)" \
  "$bin" render c.vdb -o x.exr
refused run-usdc "-o x.usdc: this output is a clay .vdb (OpenVDB); name it .vdb (\".usdc\" names another format)" \
  "$bin" run --frames 1 -o x.usdc
refused run-png-jpg "--png x.jpg: this output is a PNG picture; name it .png" "$bin" run --frames 1 --png x.jpg
refused run-checkpoint "--checkpoint x.json: this output is a clay .vdb (OpenVDB); name it .vdb" \
  "$bin" run --frames 1 --checkpoint x.json
refused demo-txt "-o x.txt: this output is a clay .vdb (OpenVDB); name it .vdb" "$bin" demo --size 8 -o x.txt
refused import-abc "-o x.abc: this output is a clay .vdb (OpenVDB); name it .vdb" \
  "$bin" import c.vdb --grid density -o x.abc --mass 10
refused mesh-fbx "-o x.fbx: unknown mesh format \".fbx\" (use .obj, .ply or .stl)" "$bin" mesh c.vdb -o x.fbx
ls x.* > /dev/null 2>&1 && fail "a refused output was written: $(ls x.*)"
"$bin" render c.vdb -o NOEXT > /dev/null 2> err.txt || fail "render to a name without extension: $(cat err.txt)"
[ "$(head -c 4 NOEXT | tail -c 3)" = "PNG" ] || fail "render -o NOEXT: not a PNG"

# 2. STL: binary, 84 bytes + 50 per triangle, the same surface as the OBJ.
"$bin" mesh c.vdb -o c.stl > out.txt 2> err.txt || fail "mesh -o c.stl: $(cat err.txt)"
grep -q "^wrote c.stl$" out.txt || fail "mesh -o c.stl: $(cat out.txt)"
"$bin" mesh c.vdb -o c.obj > /dev/null || fail "mesh -o c.obj"
n=$(od -An -tu4 -j80 -N4 c.stl | tr -d ' ')
[ "$(stat -c %s c.stl)" = $((84 + 50 * n)) ] || fail "c.stl: $(stat -c %s c.stl) bytes for $n triangles"
[ "$n" = "$(grep -c '^f ' c.obj)" ] || fail "c.stl: $n triangles, the OBJ has $(grep -c '^f ' c.obj)"
"$bin" run --frames 1 --mesh 'r.stl' --quiet > /dev/null 2> err.txt || fail "run --mesh r.stl: $(cat err.txt)"
[ -s r.stl ] || fail "run --mesh r.stl wrote nothing"

# 3. import --resolution N: N voxels across the longest side. A 2 x 1 x 2 box (world units) at
#    --resolution 32 has voxel size 0.0625 and holds its volume exactly: 32 x 16 x 32 x 1000.
cat > box.obj <<'OBJ'
v 0 0 0
v 2 0 0
v 2 1 0
v 0 1 0
v 0 0 2
v 2 0 2
v 2 1 2
v 0 1 2
f 1 4 3 2
f 5 6 7 8
f 1 2 6 5
f 4 8 7 3
f 1 5 8 4
f 2 3 7 6
OBJ
"$bin" import box.obj --resolution 32 -o r32.vdb --mass 1000 > out.txt 2> err.txt || fail "--resolution 32: $(cat err.txt)"
[ -s err.txt ] && fail "--resolution 32: a warning: $(cat err.txt)"
grep -q "mass 16384000$" out.txt || fail "--resolution 32: $(cat out.txt), expected mass 16384000"
"$bin" info r32.vdb > info.txt
grep -q "^  voxel size: 0.0625$" info.txt || fail "--resolution 32: $(grep 'voxel size' info.txt | head -1)"
# info's world bounds: the outer faces of the voxels, half a voxel past the box's faces.
[ "$(grep -m1 'world bounds' info.txt)" = "  world bounds: [-0.03125, -0.03125, -0.03125] .. [2.03125, 1.03125, 2.03125] (the outer faces of its voxels)" ] ||
  fail "info's world bounds: $(grep -m1 'world bounds' info.txt)"
# Without --resolution or --voxel-size: one warning, and the clay still written.
"$bin" import box.obj -o r1.vdb --mass 1000 > out.txt 2> err.txt || fail "import at the default voxel size: $(cat err.txt)"
[ "$(cat err.txt)" = "vdbclay: warning: box.obj is only 3 voxels across at the default voxel size 1; give --resolution N (voxels across its longest side) or --voxel-size" ] ||
  fail "no coarse-mesh warning: '$(cat err.txt)'"
"$bin" import box.obj --voxel-size 0.5 -o r2.vdb --mass 1000 > /dev/null 2> err.txt
[ -s err.txt ] && fail "--voxel-size: a warning: $(cat err.txt)"
refused resolution-and-voxel-size "excludes" "$bin" import box.obj --resolution 8 --voxel-size 0.5 -o r.vdb --mass 1
refused resolution-zero "--resolution: expected an integer in .1, 1048576., got 0" "$bin" import box.obj --resolution 0 -o r.vdb --mass 1
refused resolution-levelset "--resolution: for meshes" "$bin" import c.vdb --grid surface --resolution 8 -o r.vdb --mass 1

# 4. A fog volume keeps where it lies: vdbclay's own z-up density comes back z up, the same clay.
printf '{"voxel_size": 0.25, "up": "z", "clay": [{"shape": "box", "min": [0,0,0], "max": [3,7,1], "mass": 1000}]}' > z.json
"$bin" run z.json --quiet -o z.vdb > /dev/null || fail "run z.json"
"$bin" import z.vdb --grid density -o zfog.vdb --mass 1000 > out.txt 2> err.txt || fail "import z.vdb --grid density: $(cat err.txt)"
grep -q "(z up)" out.txt || fail "fog import: no z up in the note: $(cat out.txt)"
"$bin" info zfog.vdb | grep -q 'vdbclay_up (string) = z' || fail "fog import: no vdbclay_up z"
[ "$("$bin" info zfog.vdb | grep -m1 'content hash')" = "$("$bin" info z.vdb | grep -m1 'content hash')" ] ||
  fail "fog import: other clay than the file's"
[ "$("$bin" info zfog.vdb | grep -m1 'world bounds')" = "$("$bin" info z.vdb | grep -m1 'world bounds')" ] ||
  fail "fog import: other world bounds: $("$bin" info zfog.vdb | grep -m1 'world bounds')"
# --as density reads a fog volume too; other values are refused.
"$bin" import z.vdb --grid density --as density -o zas.vdb --mass 1000 > /dev/null 2> err.txt || fail "--as density: $(cat err.txt)"
refused as-levelset "--as: expected density, got \"levelset\"" "$bin" import z.vdb --as levelset -o r.vdb --mass 1
refused as-surface "grid \"surface\" is a level set, not a density FloatGrid; import it without --as density" \
  "$bin" import z.vdb --grid surface --as density -o r.vdb --mass 1

# 5. run's summary says how long the set-up before the frames took.
"$bin" run --frames 1 > out.txt 2> err.txt || fail "run --frames 1: $(cat err.txt)"
grep -Eq "^frames 1, steps [0-9]+, time [0-9.]+ s \(push [0-9.]+ s, settle [0-9.]+ s\); set-up before the frames [0-9.]+ s$" out.txt ||
  fail "run's summary: $(grep '^frames' out.txt)"

no_temp_files formats
[ $fails -eq 0 ] || { echo "$fails failed"; exit 1; }
echo "FORMATS OK"
