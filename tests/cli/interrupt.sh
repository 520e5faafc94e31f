#!/usr/bin/env bash
# SIGINT and SIGTERM during `vdbclay run`: exit 130 / 143, one line on stderr naming the checkpoint,
# a valid checkpoint (vdbclay info), and resuming from it gives the clay and step count of an
# unbroken run. A checkpoint that cannot be written (file size limit: a full disk) leaves the old
# one untouched and no temporary file.
# usage: interrupt.sh VDBCLAY WORKDIR
set -uo pipefail
bin=$1; work=$2
rm -rf "$work"; mkdir -p "$work"; cd "$work"
set -m # job control: background jobs get their own process group and do not ignore SIGINT
fails=0
fail() { echo "FAIL $*"; fails=$((fails+1)); }
meta() { "$bin" info "$1" | sed -n "s/.*$2 ([a-z0-9]*) = //p" | head -1; }
hash() { "$bin" info "$1" | sed -n 's/.*content hash: \([0-9a-f]*\).*/\1/p' | head -1; }

# One long frame: a saturated cube whose overloaded core must diffuse out (~4000 steps).
cat > lump.json <<'EOF'
{"threshold": 100, "rule": "prorata", "seed": 7, "frames": 1,
 "clay": [{"shape": "box", "min": [0,0,0], "max": [63,63,63], "mass": 100},
          {"shape": "box", "min": [16,16,16], "max": [47,47,47], "mass": 100}],
 "obstacles": [{"shape": "box", "min": [-64,-4,-64], "max": [128,-1,128]}]}
EOF

"$bin" run lump.json --threads 2 -o whole.vdb > whole.log 2>&1 || fail "the unbroken run: $(cat whole.log)"
whole_hash=$(hash whole.vdb); whole_steps=$(meta whole.vdb vdbclay_steps)
echo "unbroken: hash $whole_hash, $whole_steps steps"

# interrupt SIGNAL STEP LOG ARGS...: runs until the automaton's step count reaches STEP, where the
# run sends itself SIGNAL through its own handler (VDBCLAY_TEST_RAISE), and returns its exit code.
# An event, not a delay: the same point on a quiet machine and a loaded one.
interrupt() {
  local sig=$1 step=$2 log=$3; shift 3
  VDBCLAY_TEST_RAISE="$sig@$step" "$bin" run lump.json --threads 2 "$@" > "$log" 2> "$log.err"
}
[ -n "$whole_steps" ] && [ "$whole_steps" -ge 400 ] || { echo "FAIL the unbroken run took '$whole_steps' steps"; exit 1; }
at1=$((whole_steps / 4)); at2=$((whole_steps / 2)); at3=$((3 * whole_steps / 4))

# 1. SIGINT: a checkpoint inside the frame (its settling cut short), beside -o by default.
interrupt INT $at1 run1.log -o out.vdb; rc=$?
[ $rc -eq 130 ] || fail "SIGINT: exit code $rc, expected 130"
[ "$(wc -l < run1.log.err)" -eq 1 ] || fail "SIGINT: stderr is not one line: $(cat run1.log.err)"
grep -q 'interrupted by SIGINT in frame 1/1 .*checkpoint written to out.checkpoint.vdb' run1.log.err ||
  fail "SIGINT: stderr: $(cat run1.log.err)"
[ -e out.vdb ] && fail "SIGINT: the output was written though the run did not finish"
s1=$(meta out.checkpoint.vdb vdbclay_steps); f1=$(meta out.checkpoint.vdb vdbclay_frame_steps)
grids=$("$bin" info out.checkpoint.vdb | sed -n 's/^grid "\([a-z]*\)".*/\1/p' | tr '\n' ' ')
[ "$grids" = "mass " ] || fail "SIGINT: the checkpoint holds grids '$grids', not the mass alone"
[ -n "$s1" ] && [ "$f1" = "$s1" ] && [ "$s1" -ge "$at1" ] && [ "$s1" -lt "$whole_steps" ] ||
  fail "SIGINT: checkpoint steps '$s1', frame steps '$f1' (unbroken: $whole_steps)"
echo "SIGINT: $(cat run1.log.err)"

# 2. SIGTERM while resuming: a second checkpoint, further on.
interrupt TERM $at2 run2.log --resume out.checkpoint.vdb --checkpoint second.vdb; rc=$?
[ $rc -eq 143 ] || fail "SIGTERM: exit code $rc, expected 143"
[ "$(wc -l < run2.log.err)" -eq 1 ] && grep -q 'interrupted by SIGTERM.*checkpoint written to second.vdb' run2.log.err ||
  fail "SIGTERM: stderr: $(cat run2.log.err)"
s2=$(meta second.vdb vdbclay_steps)
[ -n "$s2" ] && [ "$s2" -ge "$at2" ] && [ "$s2" -lt "$whole_steps" ] || fail "SIGTERM: checkpoint at step '$s2', not after $s1"
echo "SIGTERM: $(cat run2.log.err)"

# 3. A checkpoint that cannot be written (the file size limit stands for a full disk): exit 130,
#    one line saying so, the previous checkpoint byte for byte, no temporary file.
cp second.vdb second.copy
(set -m; ulimit -f 64; trap '' XFSZ; interrupt INT $at3 run3.log --resume second.vdb --checkpoint second.vdb); rc=$?
[ $rc -eq 130 ] || fail "full disk: exit code $rc, expected 130"
[ "$(wc -l < run3.log.err)" -eq 1 ] && grep -q 'no checkpoint written: cannot write second.vdb' run3.log.err ||
  fail "full disk: stderr: $(cat run3.log.err)"
cmp -s second.vdb second.copy || fail "full disk: the previous checkpoint changed"
ls ./*.tmp-* > /dev/null 2>&1 && fail "full disk: temporary files left: $(ls ./*.tmp-*)"
echo "full disk: $(cat run3.log.err)"

# 4. Resume to the end: the unbroken run's clay and step count.
"$bin" run lump.json --threads 2 --resume second.vdb -o out.vdb > run4.log 2>&1 || fail "resume: $(cat run4.log)"
h=$(hash out.vdb); s=$(meta out.vdb vdbclay_steps)
echo "resumed: hash $h, $s steps"
[ "$h" = "$whole_hash" ] && [ "$s" = "$whole_steps" ] || fail "resumed run differs: hash $h, $s steps"
[ -z "$(meta out.vdb vdbclay_frame_steps)" ] || fail "the finished output still records an open frame"

# 5. --resume with other parameters than the run it came from is refused.
"$bin" run lump.json --seed 8 --resume second.vdb -o x.vdb > /dev/null 2> err.txt && fail "resumed with another seed"
grep -q 'seed' err.txt || fail "other seed: $(cat err.txt)"

[ $fails -eq 0 ] && echo "INTERRUPTS OK" || { echo "$fails failed"; exit 1; }
