# Shared by the CLI test scripts (sourced, not run): a fresh work directory, a failure counter, and
# the check that a command is refused with one clear line.
# usage (after `set -uo pipefail`): source "$(dirname "$0")/lib.sh"; cli_setup VDBCLAY WORKDIR
cli_setup() {
  bin=$1; work=$2
  rm -rf "$work"; mkdir -p "$work"; cd "$work" || exit 2
  fails=0
}
fail() { echo "FAIL $*"; fails=$((fails+1)); }
# refused NAME NEEDLE COMMAND...: the command exits non-zero with exactly one stderr line holding NEEDLE.
refused() {
  local name=$1 needle=$2; shift 2
  "$@" > out.txt 2> err.txt; local rc=$?
  if [ $rc -eq 0 ] || [ "$(wc -l < err.txt)" -ne 1 ] || ! grep -q -- "$needle" err.txt; then
    fail "$name: rc=$rc, needle '$needle', stderr: $(cat err.txt)"
  else
    echo "PASS $name: $(cat err.txt)"
  fi
}
# no_temp_files NAME: no temporary output file is left in the work directory or one level below.
no_temp_files() {
  ls ./*.tmp* ./*/*.tmp* > /dev/null 2>&1 && fail "$1: temporary files left: $(ls ./*.tmp* ./*/*.tmp* 2>/dev/null)"
}
