#!/usr/bin/env bash
# End to end through the CLI: run a scene, then check exact mass (added and removed counted), settling, the PNG, and that
# `vdbclay info` reads the output back with the same total mass.
# usage: scene_e2e.sh VDBCLAY SCENE.json WORKDIR
set -euo pipefail
bin=$1; scene=$2; work=$3
name=$(basename "$scene" .json)
mkdir -p "$work"; out="$work/$name"
"$bin" run "$scene" -o "$out.vdb" --stats "$out.json" --png "$out.png" --mesh "$out.obj" --quiet --threads 2 > "$out.log"
num() { sed -n "s/^  \"$1\": \\([-0-9]*\\).*/\\1/p" "$out.json"; }
m0=$(num mass_initial); m1=$(num mass_final); unsettled=$(num frames_unsettled)
added=$(num mass_added); removed=$(num mass_removed)
# Every unit accounted for: the final mass is the initial one plus what add tools put in, less what
# remove tools took away.
[ -n "$m0" ] && [ -n "$added" ] && [ -n "$removed" ] && [ "$((m0 + added - removed))" = "$m1" ] \
  || { echo "FAIL $name: mass $m0 + $added - $removed -> $m1"; exit 1; }
grep -q '"settled": true' "$out.json" || { echo "FAIL $name: not settled"; cat "$out.json"; exit 1; }
[ "$unsettled" = 0 ] || { echo "FAIL $name: $unsettled frames hit the step budget"; exit 1; }
[ "$(num mass_drift)" = 0 ] && grep -q '"heterogeneity_cv": ' "$out.json" && grep -q '"compaction": ' "$out.json" \
  || { echo "FAIL $name: stats lack mass_drift 0, heterogeneity_cv or compaction"; cat "$out.json"; exit 1; }
# The command's stages outside the run: set-up and the outputs, in seconds (values not checked).
for k in seconds push_seconds setup_seconds output_seconds; do
  grep -q "^  \"$k\": [0-9]" "$out.json" || { echo "FAIL $name: stats lack $k"; cat "$out.json"; exit 1; }
done
grep -q '^  "heap": "\(batch\|system\) (' "$out.json" || { echo "FAIL $name: stats lack the heap policy"; cat "$out.json"; exit 1; }
[ "$(head -c 8 "$out.png" | od -An -tx1 | tr -d ' \n')" = 89504e470d0a1a0a ] || { echo "FAIL $name: not a PNG"; exit 1; }
grep -q '^f ' "$out.obj" || { echo "FAIL $name: mesh has no faces"; exit 1; }
"$bin" info "$out.vdb" > "$out.info"
grep -q "total mass:\? $m1" "$out.info" || { echo "FAIL $name: info does not report total mass $m1"; cat "$out.info"; exit 1; }
for g in mass density surface; do grep -q "\"$g\"" "$out.info" || { echo "FAIL $name: no grid $g"; exit 1; }; done
# The stats' content hash is the written clay's, as info reads it back from the file.
h=$(sed -n 's/^  "content_hash": "\([0-9a-f]\{16\}\)",\?$/\1/p' "$out.json")
[ -n "$h" ] || { echo "FAIL $name: stats lack a 16-digit content_hash"; cat "$out.json"; exit 1; }
grep -q "content hash: $h " "$out.info" || { echo "FAIL $name: stats' content_hash $h is not the file's"; cat "$out.info"; exit 1; }
grep -q "heterogeneity CV" "$out.info" || { echo "FAIL $name: info does not report the clay metrics"; cat "$out.info"; exit 1; }
# Other tools read it: OpenVDB's own vdb_print (libopenvdb-tools) lists the three grids.
if command -v vdb_print >/dev/null; then
  vdb_print "$out.vdb" > "$out.vdbprint"
  for g in mass density surface; do grep -q "^$g " "$out.vdbprint" || { echo "FAIL $name: vdb_print lacks $g"; cat "$out.vdbprint"; exit 1; }; done
fi
# The surface mesh is closed: it imports back as clay.
"$bin" import "$out.obj" -o "$out-imported.vdb" --mass 500 --dims "$(grep -q '"dimensions": 2' "$scene" && echo 2 || echo 3)" > /dev/null
"$bin" info "$out-imported.vdb" | grep -q "total mass" || { echo "FAIL $name: import of the surface mesh"; exit 1; }
echo "PASS $name: mass $m1 exact, settled, png + mesh + info ok"
