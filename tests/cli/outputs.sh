#!/usr/bin/env bash
# Outputs that are not plain new files: devices, FIFOs and symbolic links are written through and
# never replaced; an output that is an input, or another output, is refused before any work; a bad
# output is found before the run, not after it; a file size limit (SIGXFSZ not ignored) and a signal
# during a write end the run with a message and no temporary file. No sleeps: every wait is on an
# event (a FIFO's reader, a pipe that fills).
# usage: outputs.sh VDBCLAY WORKDIR
set -uo pipefail
source "$(dirname "$0")/lib.sh"
cli_setup "$1" "$2"
run1() { "$bin" run --frames 1 --quiet "$@"; }

# 1. A FIFO as an output is written through (a reader gets a complete .vdb) and stays a FIFO.
mkfifo pipe.vdb
cat pipe.vdb > through-fifo.vdb &
reader=$!
run1 -o pipe.vdb > /dev/null 2> err.txt || fail "fifo output: $(cat err.txt)"
wait $reader
[ -p pipe.vdb ] || fail "fifo output: pipe.vdb is no longer a FIFO"
"$bin" info through-fifo.vdb > info.txt 2>&1 && grep -q 'grid "mass"' info.txt || fail "fifo output: the reader got no .vdb: $(head -3 info.txt)"
run1 -o direct.vdb > /dev/null || fail "direct output"
# --version needs no subcommand, and names the version the files record.
ver=$("$bin" --version) || fail "--version: exit $?"
recorded=$("$bin" info direct.vdb | sed -n 's/.*vdbclay_version (string) = //p' | head -1)
[ "$ver" = "vdbclay $recorded" ] || fail "--version printed '$ver', the file records '$recorded'"
[ "$(grep 'content hash' info.txt)" = "$("$bin" info direct.vdb | grep 'content hash')" ] || fail "fifo output: other clay"
# A full device: the write fails and says so (the path is not replaced, nothing reports success).
if [ -w /dev/full ]; then
  refused full-device-vdb "cannot write /dev/full: write failed: No space left on device" run1 -o /dev/full
  refused full-device-stats "cannot write /dev/full: write failed: No space left on device" run1 --stats /dev/full
  refused full-device-png "cannot write /dev/full" run1 --png /dev/full
  refused full-device-demo "cannot write /dev/full" "$bin" demo --size 8 -o /dev/full
  refused full-device-render "cannot write /dev/full" "$bin" render direct.vdb -o /dev/full
fi
# A character device made here (as root): several outputs may go to it, and it stays a device.
if [ "$(id -u)" -eq 0 ] && mknod null c 1 3 2> /dev/null; then
  run1 -o null --png null --stats null --mesh null.obj > /dev/null 2> err.txt || fail "device output: $(cat err.txt)"
  [ -c null ] || fail "device output: ./null is no longer a character device"
else
  echo "SKIP device output: not root"
fi
# A symbolic link stays a link; the file it points to is replaced.
mkdir real && cp direct.vdb real/target.vdb && ln -s real/target.vdb link.vdb
"$bin" run --frames 2 --quiet -o link.vdb > /dev/null || fail "symlink output"
[ -L link.vdb ] || fail "symlink output: link.vdb is no longer a link"
cmp -s real/target.vdb direct.vdb && fail "symlink output: the target was not rewritten"
no_temp_files devices

# 2. Writing over an input, or two outputs to one file, is refused before any work.
printf '{"frames": 1}' > s.json
cp s.json s.json.copy
refused over-scene "-o s.json: that is the scene file s.json; refusing to write over an input" "$bin" run s.json -o s.json
refused over-scene-stats "--stats s.json: that is the scene file" "$bin" run s.json --stats s.json
refused over-scene-checkpoint "--checkpoint s.json: that is the scene file" "$bin" run s.json --checkpoint s.json
refused over-scene-link "that is the scene file" "$bin" run s.json -o ./real/../s.json
cmp -s s.json s.json.copy || fail "the scene file changed"
refused vdb-and-png "--png X: the same file as -o X" run1 -o X --png X
[ -e X ] && fail "vdb-and-png: X was written"
refused png-and-stats "--png same: the same file as --stats same" run1 --png same --stats same
printf 'v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n' > m.obj
cp m.obj m.obj.copy
refused import-over-input "-o m.obj: that is the input file m.obj; refusing to write over an input" "$bin" import m.obj -o m.obj --mass 100
cp direct.vdb clay.obj
refused mesh-over-input "-o clay.obj: that is the input file clay.obj" "$bin" mesh clay.obj -o clay.obj
cmp -s clay.obj direct.vdb || fail "mesh over its input: clay.obj changed"
refused render-over-input "-o direct.vdb: that is the input file direct.vdb" "$bin" render direct.vdb -o direct.vdb
cmp -s m.obj m.obj.copy || fail "m.obj changed"
printf '{"clay": [{"shape": "mesh", "file": "m.obj", "mass": 100}], "frames": 1}' > ms.json
refused over-shape-file "--mesh m.obj: that is the file of clay\[0\]" "$bin" run ms.json --mesh m.obj
# The start file may be continued in place (-o over it): that is a legitimate use.
run1 -o cont.vdb > /dev/null
printf '{"start": "cont.vdb", "frames": 2}' > cont.json
"$bin" run cont.json --quiet -o cont.vdb > /dev/null 2> err.txt || fail "continue in place: $(cat err.txt)"

# 3. Every output is checked before the work: nothing is written when the last one is bad.
refused mesh-format-first "--mesh out.fbx: unknown mesh format \".fbx\"" run1 -o first.vdb --mesh out.fbx
[ -e first.vdb ] && fail "mesh-format-first: first.vdb was written before the mesh was refused"
mkdir adir
refused output-dir-first "--stats adir: is a directory" run1 -o first.vdb --stats adir
[ -e first.vdb ] && fail "output-dir-first: first.vdb was written"
refused png-missing-dir-first "cannot write nodir/x.png" run1 -o first.vdb --png nodir/x.png
[ -e first.vdb ] && fail "png-missing-dir-first: first.vdb was written"
refused mesh-subcommand-format "-o out.fbx: unknown mesh format" "$bin" mesh direct.vdb -o out.fbx

# 4. A file size limit with SIGXFSZ at its default action: reported, nothing left behind.
cp direct.vdb before.vdb
refused sigxfsz "cannot write before.vdb: write failed: File too large" bash -c 'ulimit -f 16; exec "$0" run --frames 1 --quiet -o before.vdb' "$bin"
cmp -s before.vdb direct.vdb || fail "sigxfsz: before.vdb changed"
no_temp_files sigxfsz

# 5. SIGTERM while an output is written ends the process at once (it is not swallowed while the
#    write goes on). The output is a FIFO: once the reader has some bytes, the write is under way,
#    and it cannot finish while the reader waits.
mkfifo slow.vdb
"$bin" run --frames 1 --quiet -o slow.vdb > /dev/null 2> sig-err.txt &
writer=$!
exec 3< slow.vdb
head -c 4096 <&3 > /dev/null
kill -TERM $writer
wait $writer; rc=$?
exec 3<&-
[ $rc -eq 143 ] || fail "signal during write: exit code $rc, expected 143"
grep -q "interrupted while writing an output" sig-err.txt || fail "signal during write: no message: $(cat sig-err.txt)"
echo "PASS signal during write: rc $rc, $(tr '\n' ' ' < sig-err.txt)"

# 6. The continue hint of an interrupted run names -o (and the other outputs), so that running it
#     as printed writes them. The run's stdout is a pipe of 4 KiB that is read up to the first
#     frame's line and then left full: the signal arrives while the run is still in its frames.
printf '{"clay": [{"shape": "box", "min": [0,0,0], "max": [7,7,7], "mass": 900}], "frames": 400,
  "tools": [{"shape": "box", "min": [-2,9,-2], "max": [9,10,9], "path": [{"translate": [0,0,0], "frames": 400}]}]}' > long.json
/usr/bin/python3 - "$bin" > hint.txt 2>&1 <<'EOF' || fail "continue hint: $(cat hint.txt)"
import fcntl, os, shlex, signal, subprocess, sys
binary = sys.argv[1]
r, w = os.pipe()
fcntl.fcntl(w, 1031, 4096)  # F_SETPIPE_SZ: the pipe fills after a few frame lines
p = subprocess.Popen([binary, "run", "long.json", "-o", "long.vdb", "--stats", "long-stats.json"],
                     stdout=w, stderr=subprocess.PIPE)
os.close(w)
out = os.fdopen(r, "rb")
while not out.readline().startswith(b"frame 1/"):
    pass
p.send_signal(signal.SIGINT)      # the run is in its frames: it cannot print 400 lines into 4 KiB
rest = out.read()
err = p.stderr.read().decode()
rc = p.wait()
if rc != 130: sys.exit("rc %d, expected 130: %s" % (rc, err))
if "continue: " not in err: sys.exit("no continue hint: " + err)
hint = err.split("continue: ", 1)[1].rsplit(")", 1)[0]
args = shlex.split(hint)
for need in ["-o", "long.vdb", "--stats", "long-stats.json", "--resume"]:
    if need not in args: sys.exit("the hint lacks %s: %s" % (need, hint))
if os.path.exists("long.vdb"): sys.exit("long.vdb written by the interrupted run")
args[0] = binary
done = subprocess.run(args + ["--quiet"], capture_output=True)
if done.returncode != 0: sys.exit("the hint as printed failed: " + done.stderr.decode())
if not (os.path.exists("long.vdb") and os.path.exists("long-stats.json")):
    sys.exit("the hint as printed wrote no output")
print("hint ok:", hint)
EOF
grep -q "hint ok" hint.txt && echo "PASS continue hint: $(cat hint.txt)"
no_temp_files end

# A scene writes only inside the current directory: absolute paths, a ".." that leaves it and a link
# that points out of it are refused before any work (nothing written anywhere); the command line
# names files anywhere, and --scene-outputs-anywhere lets the scene's own outputs out.
top=$PWD
mkdir -p inside/sub outside
ln -sfn "$top/outside" inside/out-link
escape() { # NAME FIELD PATH
  printf '{"frames": 1, "outputs": {"%s": "%s"}}' "$2" "$3" > inside/escape.json
  (cd inside && refused "$1" "the scene's outputs.$2 $3: outside the current directory" "$bin" run escape.json --quiet)
  [ -z "$(ls outside)" ] || fail "$1: wrote $(ls outside)"
}
escape escape-absolute stats "$top/outside/stats.json"
escape escape-dotdot vdb "../outside/clay.vdb"
escape escape-deep-dotdot png "sub/../../outside/clay.png"
escape escape-link mesh "out-link/clay.obj"
printf '{"frames": 1, "outputs": {"stats": "sub/../stats.json"}}' > inside/within.json
(cd inside && "$bin" run within.json --quiet > /dev/null 2> ../err.txt) || fail "an output inside by way of ..: $(cat err.txt)"
[ -s inside/stats.json ] || fail "an output inside by way of ..: nothing written"
printf '{"frames": 1, "outputs": {"stats": "%s/outside/stats.json"}}' "$top" > inside/away.json
(cd inside && "$bin" run away.json --quiet --stats "$top/outside/cli-stats.json" > /dev/null 2> ../err.txt) ||
  fail "the command line's output outside: $(cat err.txt)"
(cd inside && "$bin" run away.json --quiet --scene-outputs-anywhere > /dev/null 2> ../err.txt) ||
  fail "--scene-outputs-anywhere: $(cat err.txt)"
[ -s outside/cli-stats.json ] && [ -s outside/stats.json ] || fail "outputs outside when allowed: $(ls outside)"

# 5. The grids the .vdb holds: --grids, else the scene's outputs.grids; a wrong name is refused before
# any work; "start" needs the mass.
grids_of() { "$bin" info "$1" | sed -n 's/^grid "\([a-z]*\)".*/\1/p' | sort | tr '\n' ' '; }
run1 -o fog.vdb --grids density > /dev/null || fail "--grids density"
[ "$(grids_of fog.vdb)" = "density " ] || fail "--grids density wrote: $(grids_of fog.vdb)"
printf '{"frames": 1, "outputs": {"vdb": "chosen.vdb", "grids": ["surface", "mass"]}}' > grids.json
"$bin" run grids.json --quiet > /dev/null || fail "outputs.grids"
[ "$(grids_of chosen.vdb)" = "mass surface " ] || fail "outputs.grids wrote: $(grids_of chosen.vdb)"
"$bin" run grids.json --quiet --grids mass > /dev/null || fail "--grids over outputs.grids"
[ "$(grids_of chosen.vdb)" = "mass " ] || fail "--grids over outputs.grids wrote: $(grids_of chosen.vdb)"
refused grids-unknown '--grids: "fog" is not a grid of a clay file (mass, density or surface)' run1 -o never.vdb --grids mass,fog
[ -e never.vdb ] && fail "grids-unknown: never.vdb was written"
printf '{"frames": 1, "start": "fog.vdb"}' > from-fog.json
refused start-without-mass 'fog.vdb has no grid named "mass" (grids: "density")' "$bin" run from-fog.json --quiet

[ $fails -eq 0 ] && echo "OUTPUTS HANDLED" || { echo "$fails failed"; exit 1; }
