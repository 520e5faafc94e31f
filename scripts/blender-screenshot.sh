#!/usr/bin/env bash
# The add-on's panel as docs/images/blender-addon-panel.png: Blender with a window under Xvfb
# (Debian: xvfb, xauth), Blender's user folders in a temporary directory.
# usage: scripts/blender-screenshot.sh [BUILD_DIR]   (the add-on zip: BUILD_DIR/python/vdbclay_blender_addon.zip)
set -euo pipefail
cd "$(dirname "$0")/.."
build=${1:-build}
zip=$PWD/$build/python/vdbclay_blender_addon.zip
[ -f "$zip" ] || { echo "blender-screenshot: no $zip (build first)" >&2; exit 2; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
export BLENDER_USER_CONFIG=$tmp/config BLENDER_USER_SCRIPTS=$tmp/scripts BLENDER_USER_DATAFILES=$tmp/datafiles
here=scripts/blender-screenshot
blender -b --factory-startup --python "$here/scene.py" -- "$zip" "$tmp/shot.blend" > "$tmp/scene.log"
xvfb-run -a -s "-screen 0 1300x1350x24" blender "$tmp/shot.blend" --python "$here/shot.py" -- "$tmp/panel.png" \
  > "$tmp/shot.log" 2>&1
blender -b --factory-startup --python "$here/crop.py" -- "$tmp/panel.png" "$PWD/docs/images/blender-addon-panel.png" \
  > "$tmp/crop.log"
echo "wrote docs/images/blender-addon-panel.png"
