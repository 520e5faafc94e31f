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
# Clay imported from a .vdb ("shape": "vdb"): the message names the scene and the field.
printf '{"clay": [{"shape": "box", "min": [0,0,0], "max": [1,1,1], "mass": 5}, {"shape": "vdb", "file": "missing.vdb"}]}' > vdbmissing.json
printf '{"clay": [{"shape": "vdb", "file": "notvdb.vdb"}]}' > vdbdamaged.json
expect_refused vdb-clay-missing "vdbmissing.json: clay\[1\]: missing.vdb: no such file" run vdbmissing.json -o result.vdb
expect_refused vdb-clay-damaged "vdbdamaged.json: clay\[0\]: notvdb.vdb is not a .vdb file" run vdbdamaged.json -o result.vdb
expect_refused info-missing "missing.vdb" info missing.vdb
expect_refused render-not-vdb "notvdb.vdb" render notvdb.vdb -o result.png
expect_refused unknown-option "--bogus" run --bogus
expect_refused import-bad-mass "mass" import notvdb.vdb -o result.vdb --mass 0
# the allocator policy's variable (vdbclay/BatchHeap.h): refused before any work
VDBCLAY_HEAP=huge expect_refused heap-choice 'VDBCLAY_HEAP must be "batch" or "system", got "huge"' run -o result.vdb --frames 1 --quiet
# an unwritable output: the error names it and nothing is left behind
expect_refused unwritable "/nonexistent-dir/out.vdb" run -o /nonexistent-dir/out.vdb --frames 1 --quiet

# Unbounded and odd inputs: refused with the reason, before reading far.
mkdir adir
expect_refused scene-dev-zero "/dev/zero: more than 16.0 MiB" run /dev/zero -o result.vdb
expect_refused scene-directory "adir: is a directory, expected a scene file" run adir -o result.vdb
ln -s loop1 loop2; ln -s loop2 loop1
expect_refused scene-symlink-loop "loop1: cannot open scene file: Too many levels of symbolic links" run loop1 -o result.vdb
expect_refused vdb-symlink-loop "loop1: Too many levels of symbolic links" info loop1
expect_refused vdb-device "/dev/zero is not a regular file" info /dev/zero
expect_refused vdb-directory "adir is a directory" render adir -o result.png
if [ "$(id -u)" -ne 0 ]; then
  printf 'x' > unreadable.vdb; chmod 000 unreadable.vdb
  expect_refused vdb-unreadable "unreadable.vdb: cannot open it: Permission denied" info unreadable.vdb
fi
# A scene read from a pipe (process substitution) is a scene like any other.
"$bin" run <(printf '{"frames": 1}') --quiet > /dev/null 2> err.txt || { echo "FAIL scene from a pipe: $(cat err.txt)"; fails=$((fails+1)); }

# Options: every number range-checked with the option named and a short message.
expect_refused frames-zero "--frames: expected an integer in \[1, 100000000\], got 0" run --frames 0 -o result.vdb
expect_refused frames-negative "--frames" run --frames -3 -o result.vdb
expect_refused threads-negative "--threads: expected an integer in \[0, 256\], got -1" run --threads -1 -o result.vdb
expect_refused threads-huge "--threads: expected an integer in \[0, 256\], got 10000" run --threads 10000 -o result.vdb
expect_refused render-width-zero "--width: expected an integer in \[1, 16384\], got 0" render notvdb.vdb -o result.png --width 0
expect_refused render-azimuth-nan "--azimuth: expected a number in \[-1e+06, 1e+06\], got nan" render notvdb.vdb -o result.png --azimuth nan
expect_refused render-elevation-pole "--elevation: expected a number in \[-89.9, 89.9\], got 90" render notvdb.vdb -o result.png --elevation 90
expect_refused import-voxel-size "--voxel-size: expected a number in \[0.0001, 1e+06\], got 1e-300" import notvdb.vdb -o result.vdb --mass 1 --voxel-size 1e-300
expect_refused demo-seed-negative "--seed: expected an integer in \[0, 9223372036854775807\], got -3" demo --seed -3
expect_refused demo-max-steps-negative "--max-steps: expected an integer in \[0, 18446744073709551615\], got -1" demo --max-steps -1
expect_refused mesh-isovalue-nan "--isovalue: expected a number" mesh notvdb.vdb -o result.obj --isovalue nan
expect_refused unknown-subcommand "unknown subcommand \"bogus\" (expected one of: run, info" bogus
expect_refused run-rule-bogus "--rule: unknown rule \"bogus\"" run --rule bogus -o result.vdb
expect_refused demo-rule-bogus "--rule: unknown rule \"bogus\"" demo --rule bogus
expect_refused demo-too-big "demo --size 4096: needs about .* more than the memory budget" demo --size 4096
# Empty strings are refused, not taken as "none".
expect_refused empty-output "--output: expected a file name, got an empty string" run -o "" --frames 1
expect_refused empty-rule "--rule: expected a rule name, got an empty string" run --rule "" -o result.vdb
expect_refused empty-scene "scene: expected a file name, got an empty string" run ""
# No message spans lines or carries terminal escapes from input.
cat > escape.json <<'JSON'
{"thr\neshold\u001b[31m": 5}
JSON
expect_refused escaped-key 'thr\\neshold\\x1b\[31m: unknown field' run escape.json -o result.vdb
expect_refused escaped-name 'nothere\\n.json' run "$(printf 'nothere\n.json')" -o result.vdb
expect_refused escaped-subcommand 'unknown subcommand "a\\x1b\[2Jb"' "$(printf 'a\033[2Jb')"

# Scene fields: types, duplicates, ranges, 2D planes, start with clay.
scene() { printf '%s' "$2" > "$1.json"; }
scene desc-object '{"description": {"a": [1]}}'
expect_refused description-type "desc-object.json: description: expected a string, got object" run desc-object.json -o result.vdb
scene dup '{"threshold": 1000, "threshold": 5}'
expect_refused duplicate-key "dup.json: threshold: duplicate field" run dup.json -o result.vdb
scene start-empty '{"start": ""}'
expect_refused start-empty "start-empty.json: start: expected a non-empty string" run start-empty.json -o result.vdb
scene start-and-clay '{"start": "x.vdb", "clay": [{"shape": "box", "min": [0,0,0], "max": [3,3,3], "mass": 5}]}'
expect_refused start-and-clay "start-and-clay.json: start: a scene starts either from a file" run start-and-clay.json -o result.vdb
scene voxel-tiny '{"voxel_size": 1e-300}'
expect_refused voxel-size-tiny "voxel-tiny.json: voxel_size: expected a number in \[0.0001, 1e+06\]" run voxel-tiny.json -o result.vdb
tool='"shape": "box", "min": [0,10,0], "max": [4,12,4]'
scene rotate-huge "{\"tools\": [{$tool, \"path\": [{\"rotate\": [1e308,0,0], \"frames\": 2}]}]}"
expect_refused rotate-huge "rotate-huge.json: tools\[0\].path\[0\].rotate\[0\]: the tool turns at most" run rotate-huge.json -o result.vdb
scene translate-huge "{\"tools\": [{$tool, \"path\": [{\"translate\": [0,3e9,0]}]}]}"
expect_refused translate-huge "translate-huge.json: tools\[0\].path\[0\].translate\[1\]: the tool's movement" run translate-huge.json -o result.vdb
scene tool2d-z '{"dimensions": 2, "tools": [{"shape": "box", "min": [0,10,3], "max": [4,12,5], "path": [{"translate": [0,-1]}]}]}'
expect_refused tool-2d-off-plane "tool2d-z.json: tools\[0\]: a 2D scene happens in the z = 0 layer" run tool2d-z.json -o result.vdb
scene tool2d-move '{"dimensions": 2, "tools": [{"shape": "box", "min": [0,10,0], "max": [4,12,0], "path": [{"translate": [0,0,1]}]}]}'
expect_refused tool-2d-moves-in-z "tools\[0\].path\[0\].translate\[2\]: a 2D scene's tools move in the z = 0 plane" run tool2d-move.json -o result.vdb
scene tool2d-rot '{"dimensions": 2, "tools": [{"shape": "box", "min": [0,10,0], "max": [4,12,0], "path": [{"rotate": [10,0,0]}]}]}'
expect_refused tool-2d-rotates-out "tools\[0\].path\[0\].rotate: a 2D scene's tools turn about z only" run tool2d-rot.json -o result.vdb
scene obst2d '{"dimensions": 2, "obstacles": [{"shape": "box", "min": [0,-4,2], "max": [9,-1,4]}]}'
expect_refused obstacle-2d-off-plane "obstacles\[0\]: a 2D scene happens in the z = 0 layer" run obst2d.json -o result.vdb
[ $fails -eq 0 ] && echo "all refused cleanly" || { echo "$fails failed"; exit 1; }
