#!/usr/bin/env bash
# Installs what the library and the CLI need, builds them (nothing else), then runs the main job.
# With no arguments: the built-in default scene (a 32^3 cube pressed by a plate), written to
# build/default.vdb with a picture, a mesh and statistics beside it.
# With arguments: `vdbclay ARGS...` (e.g. scripts/run.sh run data/scenes/paper/cube-big-plate.json -o out.vdb).
set -euo pipefail
cd "$(dirname "$0")/.."
DEPS=cli TARGETS=vdbclay_cli bash scripts/build.sh
bin="${BUILD_DIR:-build}/apps/vdbclay"
if [ $# -gt 0 ]; then exec "$bin" "$@"; fi
out="${BUILD_DIR:-build}/default"
"$bin" run -o "$out.vdb" --png "$out.png" --mesh "$out.obj" --stats "$out-stats.json"
"$bin" info "$out.vdb"
