#!/usr/bin/env bash
# Bad input through the CLI: non-zero exit, exactly one line on stderr, nothing written.
# usage: bad_input.sh VDBCLAY WORKDIR
set -uo pipefail
bin=$1; work=$2
rm -rf "$work"; mkdir -p "$work"; cd "$work"
fails=0
expect_refused() { # NAME NEEDLE ARGS...
  local name=$1 needle=$2; shift 2
  "$bin" "$@" > out.txt 2> err.txt; local rc=$?
  local lines; lines=$(wc -l < err.txt)
  if [ $rc -eq 0 ] || [ "$lines" -ne 1 ] || ! grep -q -- "$needle" err.txt || [ -e result.vdb ] || ls ./*.tmp* >/dev/null 2>&1; then
    echo "FAIL $name: rc=$rc, $lines stderr lines, needle '$needle':"; cat err.txt; fails=$((fails+1))
  else
    echo "PASS $name: $(cat err.txt)"
  fi
  rm -f result.vdb
}
printf '{"threshold": 100,\n "clay": [}' > invalid.json
printf '{"threshold": 100, "rule": "rule4"}' > badrule.json
printf '{"clay": [{"shape": "box", "min": [0,0,0], "max": [3,3,3], "mass": -1}]}' > negative.json
printf '{"start": "missing.vdb"}' > nostart.json
printf 'not a vdb at all' > notvdb.vdb
expect_refused missing-scene "nothere.json" run nothere.json -o result.vdb
expect_refused invalid-json "invalid JSON" run invalid.json -o result.vdb
expect_refused unknown-rule "rule4" run badrule.json -o result.vdb
expect_refused negative-mass "clay\[0\].mass" run negative.json -o result.vdb
expect_refused missing-start "missing.vdb" run nostart.json -o result.vdb
expect_refused info-not-vdb "notvdb.vdb" info notvdb.vdb
expect_refused info-missing "missing.vdb" info missing.vdb
expect_refused render-not-vdb "notvdb.vdb" render notvdb.vdb -o result.png
expect_refused unknown-option "--bogus" run --bogus
expect_refused import-bad-mass "mass" import notvdb.vdb -o result.vdb --mass 0
# an unwritable output: the error names it and nothing is left behind
expect_refused unwritable "/nonexistent-dir/out.vdb" run -o /nonexistent-dir/out.vdb --frames 1 --quiet
[ $fails -eq 0 ] && echo "all refused cleanly" || { echo "$fails failed"; exit 1; }
