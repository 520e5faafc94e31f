#!/usr/bin/env bash
# Runs python/blender_import.py in a headless Blender: the scene runs through the vdbclay module,
# and the .vdb and the OBJ are imported and checked upright. Skipped (exit 77, ctest's
# SKIP_RETURN_CODE) when blender is not on PATH.
# usage: blender_import.sh SCRIPT OUTDIR   (PYTHONPATH must hold the built vdbclay package)
set -uo pipefail
script=$1; out=$2
if ! command -v blender > /dev/null 2>&1; then
  echo "blender is not on PATH: skipped"
  exit 77
fi
rm -rf "$out"; mkdir -p "$out"
# --python-exit-code: a Python error (a failed check) fails the run instead of exiting 0.
blender -b --python-exit-code 1 --python "$script" -- --out "$out" --frames 2 2>&1 | tee "$out/blender.log"
status=${PIPESTATUS[0]}
[ "$status" -eq 0 ] || { echo "FAIL: blender exited with $status"; exit 1; }
grep -q "vdbclay-blender: ok" "$out/blender.log" || { echo "FAIL: no \"vdbclay-blender: ok\" line"; exit 1; }
echo "BLENDER IMPORT OK"
