#!/usr/bin/env bash
# Sequences: an output named with a run of '#' (-o, --png, --mesh, or the scene's outputs) writes one
# file per frame, numbered by frame and zero-padded to the run's width; --every K writes every K-th
# frame and the last; each frame holds the whole mass; a run stopped inside a frame leaves whole
# frames only, and its continuation writes the rest.
# usage: sequences.sh VDBCLAY WORKDIR
set -uo pipefail
source "$(dirname "$0")/lib.sh"
cli_setup "$1" "$2"
# A 10^3 cube at 0.8 Tc pressed 1 voxel a frame for 5 frames: 800000 units of clay.
cat > s.json <<'JSON'
{"dimensions": 3, "threshold": 1000,
 "clay": [{"shape": "box", "min": [0,0,0], "max": [9,9,9], "mass": 800}],
 "tools": [{"shape": "box", "min": [-4,10,-4], "max": [13,13,13], "path": [{"translate": [0,-1,0], "frames": 5}]}],
 "obstacles": [{"shape": "box", "min": [-8,-2,-8], "max": [18,-1,18]}]}
JSON
mass=800000
files() { (cd "$1" && ls | tr '\n' ' '); }
# mass_of FILE: the mass grid's total mass as `vdbclay info` reads it.
mass_of() { "$bin" info "$1" | sed -n 's/^  total mass: //p' | head -1; }
frames_of() { "$bin" info "$1" | sed -n 's/.*vdbclay_frames (int64) = //p' | head -1; }

# 1. Every frame: clay.0001.vdb .. clay.0005.vdb, each the whole mass, its frame counter its number.
mkdir a
"$bin" run s.json -o 'a/clay.####.vdb' --mesh 'a/m#.obj' --png 'a/p.##.png' --quiet > out.txt 2> err.txt ||
  fail "sequence run: $(cat err.txt)"
expect="clay.0001.vdb clay.0002.vdb clay.0003.vdb clay.0004.vdb clay.0005.vdb m1.obj m2.obj m3.obj m4.obj m5.obj p.01.png p.02.png p.03.png p.04.png p.05.png "
[ "$(files a)" = "$expect" ] || fail "every frame: expected files '$expect', got '$(files a)'"
for f in 1 2 3 4 5; do
  [ "$(mass_of a/clay.000$f.vdb)" = $mass ] || fail "frame $f: mass $(mass_of a/clay.000$f.vdb), expected $mass"
  [ "$(frames_of a/clay.000$f.vdb)" = $f ] || fail "frame $f: vdbclay_frames $(frames_of a/clay.000$f.vdb)"
done
grep -q "^wrote a/clay.0001.vdb .. a/clay.0005.vdb (5 frames)$" out.txt || fail "every frame: no 'wrote' line: $(cat out.txt)"
# The frames differ (the tool moved) and the last is the run's result.
cmp -s a/clay.0001.vdb a/clay.0005.vdb && fail "frames 1 and 5 are the same file"
"$bin" run s.json -o last.vdb --quiet > /dev/null || fail "single-file run"
[ "$("$bin" info last.vdb | grep 'content hash' | head -1)" = "$("$bin" info a/clay.0005.vdb | grep 'content hash' | head -1)" ] ||
  fail "the last frame differs from a single-file run's result"
no_temp_files sequence

# 2. --every 2: frames 2, 4 and the last (5).
mkdir b
"$bin" run s.json -o 'b/c_##.vdb' --every 2 --quiet > /dev/null 2> err.txt || fail "--every 2: $(cat err.txt)"
[ "$(files b)" = "c_02.vdb c_04.vdb c_05.vdb " ] || fail "--every 2: got '$(files b)'"
for f in b/*.vdb; do [ "$(mass_of "$f")" = $mass ] || fail "--every 2: $f mass $(mass_of "$f")"; done
# --frames 3 --every 2: frames 2 and 3 (the run's last).
mkdir c
"$bin" run s.json -o 'c/#.vdb' --every 2 --frames 3 --quiet > /dev/null 2> err.txt || fail "--frames 3: $(cat err.txt)"
[ "$(files c)" = "2.vdb 3.vdb " ] || fail "--every 2 --frames 3: got '$(files c)'"

# 3. The scene's outputs may name sequences too.
mkdir d
sed 's/^{/{"outputs": {"vdb": "d\/s.###.vdb"},/' s.json > scene-out.json
"$bin" run scene-out.json --quiet > /dev/null 2> err.txt || fail "scene sequence: $(cat err.txt)"
[ "$(files d)" = "s.001.vdb s.002.vdb s.003.vdb s.004.vdb s.005.vdb " ] || fail "scene sequence: got '$(files d)'"

# 4. Stopped inside frame 3 (the first step of frame 3 is past step 2 frames' worth): frames 1 and 2
#    whole, no frame 3, the checkpoint beside them named without the '#'s; the continuation writes
#    frames 3..5, each the whole mass, frame 5 as the uninterrupted run's.
mkdir e
steps2=$("$bin" run s.json --frames 2 --quiet --stats st.json > /dev/null && sed -n 's/.*"steps": \([0-9]*\).*/\1/p' st.json | head -1)
VDBCLAY_TEST_RAISE="INT@$((steps2 + 1))" "$bin" run s.json -o 'e/clay.####.vdb' --quiet > out.txt 2> err.txt
rc=$?
[ $rc -eq 130 ] || fail "interrupted: rc $rc, expected 130: $(cat err.txt)"
[ "$(files e)" = "clay.0001.vdb clay.0002.vdb clay.checkpoint.vdb " ] || fail "interrupted: got '$(files e)'"
grep -q "continue: vdbclay run s.json --resume e/clay.checkpoint.vdb -o 'e/clay.####.vdb'" err.txt ||
  fail "interrupted: no continue command: $(cat err.txt)"
"$bin" run s.json --resume e/clay.checkpoint.vdb -o 'e/clay.####.vdb' --quiet > /dev/null 2> err.txt ||
  fail "resumed: $(cat err.txt)"
for f in 1 2 3 4 5; do
  [ "$(mass_of e/clay.000$f.vdb)" = $mass ] || fail "resumed frame $f: mass $(mass_of e/clay.000$f.vdb)"
done
[ "$("$bin" info e/clay.0005.vdb | grep 'content hash' | head -1)" = "$("$bin" info last.vdb | grep 'content hash' | head -1)" ] ||
  fail "the resumed run's last frame differs from the uninterrupted run's"
no_temp_files interrupted

# 5. Refused before any work.
refused two-runs "-o a#b#.vdb: more than one run of '#' in the file name" "$bin" run s.json -o 'a#b#.vdb'
refused stats-hash "--stats r#.json: '#' numbers the frames of -o, --png and --mesh; this output is one file" \
  "$bin" run s.json -o 'x.#.vdb' --stats 'r#.json'
refused every-no-sequence "--every 2: no output is a sequence" "$bin" run s.json -o x.vdb --every 2
refused every-zero "--every: expected an integer in .1, 100000000., got 0" "$bin" run s.json -o 'x.#.vdb' --every 0
ls x*.vdb > /dev/null 2>&1 && fail "a refused run wrote $(ls x*.vdb)"

[ $fails -eq 0 ] || { echo "$fails failed"; exit 1; }
echo "SEQUENCES OK"
