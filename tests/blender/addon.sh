#!/usr/bin/env bash
# The Blender add-on in a headless Blender (tests/blender/addon_test.py): skipped (exit 77, ctest's
# SKIP_RETURN_CODE) when blender is not on PATH. Blender's user folders go to the work directory.
# usage: addon.sh ADDON.zip VDBCLAY WORKDIR
set -uo pipefail
zip=$1; cli=$2; work=$3
if ! command -v blender > /dev/null 2>&1; then
  echo "blender is not on PATH: skipped"
  exit 77
fi
rm -rf "$work"; mkdir -p "$work/out" "$work/user"
export BLENDER_USER_CONFIG="$work/user/config" BLENDER_USER_SCRIPTS="$work/user/scripts"
export BLENDER_USER_DATAFILES="$work/user/datafiles"
blender -b --factory-startup --python-exit-code 1 --python "$(dirname "$0")/addon_test.py" -- \
  --zip "$zip" --cli "$cli" --out "$work/out" > "$work/blender.log" 2>&1
status=$?
cat "$work/blender.log"
[ "$status" -eq 0 ] || { echo "FAIL: blender exited with $status"; exit 1; }
grep -q "vdbclay-addon: ok" "$work/blender.log" || { echo "FAIL: no \"vdbclay-addon: ok\" line"; exit 1; }
echo "BLENDER ADDON OK"
