#!/usr/bin/env bash
# Builds vdbclay and runs the main job on the default scene. Extra arguments go to `vdbclay`.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/build.sh
exec "${BUILD_DIR:-build}/apps/vdbclay" "$@"
