#!/usr/bin/env bash
# Inputs that are not regular files. Every reader refuses a FIFO nobody writes to at once (a
# `timeout` turns a hang into a failure instead of a stuck test); a .vdb that is not a regular file
# is refused as `info` refuses it; streamable inputs (scene JSON, meshes) come from standard input
# (`run -`), a pipe or a FIFO whose writer is there, and give the clay a regular file gives. No
# sleeps: the FIFO's writer is held open by this shell, and the reader is waited for by its open
# file, an event.
# usage: inputs.sh VDBCLAY WORKDIR
set -uo pipefail
source "$(dirname "$0")/lib.sh"
cli_setup "$1" "$2"
t() { timeout 60 "$bin" "$@"; } # a read that never returns would end the test here

mkfifo scene.fifo mesh.obj levelset.vdb clay.vdb
printf '{"frames": 1}' > one.json
"$bin" run --frames 1 --quiet -o start.vdb > /dev/null || fail "a start file"
printf 'solid s\nendsolid s\n' > empty.stl

fifo="a FIFO with no writer, nothing to read"
notreg="is not a regular file"
refused scene-fifo "scene.fifo: $fifo" t run scene.fifo -o result.vdb
refused mesh-clay-fifo "mesh.obj: $fifo" t run <(printf '{"clay": [{"shape": "mesh", "file": "%s/mesh.obj", "mass": 10}]}' "$PWD") -o result.vdb
refused mesh-tool-fifo "mesh.obj: $fifo" t run <(printf '{"tools": [{"shape": "mesh", "file": "%s/mesh.obj", "path": [{"translate": [0,0,1]}]}]}' "$PWD") -o result.vdb
refused levelset-fifo "levelset.vdb $notreg" t run <(printf '{"obstacles": [{"shape": "levelset", "file": "%s/levelset.vdb"}]}' "$PWD") -o result.vdb
refused vdb-clay-fifo "clay.vdb $notreg" t run <(printf '{"clay": [{"shape": "vdb", "file": "%s/clay.vdb"}]}' "$PWD") -o result.vdb
refused start-fifo "clay.vdb $notreg" t run <(printf '{"start": "%s/clay.vdb"}' "$PWD") -o result.vdb
refused resume-fifo "clay.vdb $notreg" t run one.json --resume clay.vdb -o result.vdb
refused import-mesh-fifo "mesh.obj: $fifo" t import mesh.obj -o result.vdb --mass 10
refused import-vdb-fifo "levelset.vdb $notreg" t import levelset.vdb -o result.vdb --mass 10
refused info-fifo "clay.vdb $notreg" t info clay.vdb
refused render-fifo "clay.vdb $notreg" t render clay.vdb -o result.png
refused mesh-fifo "clay.vdb $notreg" t mesh clay.vdb -o result.obj
[ -e result.vdb ] || [ -e result.png ] || [ -e result.obj ] && fail "a refused input left an output"
printf '' > empty.json
refused scene-empty "empty.json" t run empty.json -o result.vdb

# A scene from standard input: the clay of the same scene from a file, names relative to here.
"$bin" run one.json --quiet -o from-file.vdb > /dev/null 2> err.txt || fail "scene from a file: $(cat err.txt)"
printf '{"frames": 1}' | t run - --quiet -o from-stdin.vdb > out.txt 2> err.txt || fail "run -: $(cat err.txt)"
hash() { "$bin" info "$1" | grep 'content hash'; }
[ -n "$(hash from-stdin.vdb)" ] && [ "$(hash from-stdin.vdb)" = "$(hash from-file.vdb)" ] ||
  fail "run -: other clay than the same scene from a file"
printf '{"start": "start.vdb", "frames": 1}' | t run - --quiet -o continued.vdb > /dev/null 2> err.txt ||
  fail "run - with a start file relative to the current directory: $(cat err.txt)"
printf '{"frames": 1}' | t run - > out.txt 2> err.txt || fail "run - without outputs: $(cat err.txt)"
grep -q "^vdbclay: standard input: 3D" out.txt || fail "run -: the scene is not named standard input: $(head -1 out.txt)"

# A FIFO whose writer is there: the writer (this shell, fd 9, not inherited by vdbclay) holds it open
# until vdbclay has opened it (on another fd: until the fork has run the redirection and exec'd,
# fd 9 is still the shell's), then closes it, so vdbclay reads the whole scene and its end.
mkfifo written.fifo
exec 9<> written.fifo
printf '{"frames": 1}' >&9
"$bin" run written.fifo --quiet -o from-fifo.vdb > out.txt 2> err.txt 9>&- &
reader=$!
until ls -l "/proc/$reader/fd" 2> /dev/null | grep -v ' 9 -> ' | grep -q written.fifo ||
  ! kill -0 "$reader" 2> /dev/null; do :; done
exec 9>&-
wait "$reader" || fail "scene from a FIFO with its writer: $(cat err.txt)"
[ "$(hash from-fifo.vdb)" = "$(hash from-file.vdb)" ] || fail "scene from a FIFO: other clay than from a file"

# A mesh from a pipe is a mesh like any other.
cat > cube.obj <<'OBJ'
v 0 0 0
v 6 0 0
v 6 6 0
v 0 6 0
v 0 0 6
v 6 0 6
v 6 6 6
v 0 6 6
f 1 3 2
f 1 4 3
f 5 6 7
f 5 7 8
f 1 2 6
f 1 6 5
f 2 3 7
f 2 7 6
f 3 4 8
f 3 8 7
f 4 1 5
f 4 5 8
OBJ
"$bin" import cube.obj -o cube-file.vdb --mass 10 > /dev/null 2> err.txt || fail "import a mesh file: $(cat err.txt)"
"$bin" import <(cat cube.obj) -o cube-pipe.vdb --mass 10 > /dev/null 2> err.txt || fail "import a mesh from a pipe: $(cat err.txt)"
[ -n "$(hash cube-pipe.vdb)" ] && [ "$(hash cube-pipe.vdb)" = "$(hash cube-file.vdb)" ] ||
  fail "a mesh from a pipe: other clay than from a file"

if [ "$fails" -eq 0 ]; then echo "INPUTS HANDLED"; else echo "$fails failures"; exit 1; fi
