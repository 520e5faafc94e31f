#!/usr/bin/env bash
# Builds vdbclay and runs the main job. With no arguments: the built-in default scene (a 32^3 cube
# pressed by a plate), written to build/default.vdb with a picture, a mesh and statistics beside it.
# With arguments: `vdbclay ARGS...` (e.g. scripts/run.sh run data/scenes/cube-big-plate.json -o out.vdb).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/build.sh
bin="${BUILD_DIR:-build}/apps/vdbclay"
if [ $# -gt 0 ]; then exec "$bin" "$@"; fi
out="${BUILD_DIR:-build}/default"
"$bin" run -o "$out.vdb" --png "$out.png" --mesh "$out.obj" --stats "$out-stats.json"
"$bin" info "$out.vdb"
