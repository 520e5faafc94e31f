#!/usr/bin/env bash
# An install works in any prefix: a copy of the installed prefix, moved elsewhere, runs its CLI and
# imports its Python module, each binding the libvdbclay of that copy (found relative to itself,
# $ORIGIN; no ldconfig, no LD_LIBRARY_PATH), and libvdbclay carries a versioned SONAME.
# usage: installed.sh PREFIX WORKDIR BINDIR LIBDIR SONAME [PYTHON PYDIR]
#   BINDIR, LIBDIR, PYDIR relative to PREFIX; SONAME e.g. libvdbclay.so.0.1; PYTHON the interpreter.
set -uo pipefail
prefix=$1; work=$2; bindir=$3; libdir=$4; soname=$5; python=${6:-}; pydir=${7:-}
fails=0
fail() { echo "FAIL $*"; fails=$((fails+1)); }
rm -rf "$work"; mkdir -p "$work"
moved="$work/elsewhere/prefix"
mkdir -p "$(dirname "$moved")"
cp -a "$prefix" "$moved" || { echo "FAIL cannot copy $prefix"; exit 1; }
unset LD_LIBRARY_PATH PYTHONPATH
cli="$moved/$bindir/vdbclay"

# The CLI runs from the moved prefix.
out=$("$cli" demo --size 8 --threads 1 2>&1) || fail "installed CLI: $out"
grep -q "settled yes" <<< "$out" || fail "installed CLI demo: $out"
"$cli" --version | grep -q "^vdbclay " || fail "installed CLI --version: $("$cli" --version 2>&1)"

lib=$(ls "$moved/$libdir"/libvdbclay.so.* 2>/dev/null | head -1)
if [ -n "$lib" ]; then
  # A shared build: the SONAME is versioned, the CLI binds the moved copy's library.
  real=$(readlink -f "$moved/$libdir/$soname")
  [ -f "$real" ] || fail "no $soname in $moved/$libdir: $(ls "$moved/$libdir")"
  got=$(readelf -d "$real" | sed -n 's/.*Library soname: \[\(.*\)\]/\1/p')
  [ "$got" = "$soname" ] || fail "SONAME: expected $soname, got '$got'"
  bound=$(ldd "$cli" | awk '/libvdbclay/ {print $3}')
  [ "$(readlink -f "$bound")" = "$real" ] || fail "the moved CLI binds '$bound', expected $real"
  readelf -d "$cli" | grep -q 'R.*PATH.*\$ORIGIN' || fail "the CLI's RUNPATH has no \$ORIGIN: $(readelf -d "$cli" | grep PATH)"
  echo "PASS the moved CLI binds $bound ($soname)"
else
  echo "PASS the CLI runs from the moved prefix (libvdbclay is static in this build)"
fi

if [ -n "$python" ]; then
  # The Python module imports from the moved prefix's dist-packages and binds the same library.
  out=$(PYTHONPATH="$moved/$pydir" "$python" - "$moved" <<'PY' 2>&1
import os, sys
import vdbclay
moved = os.path.realpath(sys.argv[1])
assert os.path.realpath(vdbclay.__file__).startswith(moved + "/"), vdbclay.__file__
libs = {line.split()[-1] for line in open("/proc/self/maps") if "libvdbclay" in line}
for lib in libs:
    assert os.path.realpath(lib).startswith(moved + "/"), "bound " + lib
c = vdbclay.from_array(__import__("numpy").full((2, 2, 2), 1000, dtype="int32"))
assert c.total_mass() == 8000, c.total_mass()
print("python ok", vdbclay.__version__, sorted(libs) or "static")
PY
) || fail "installed Python module: $out"
  grep -q "^python ok" <<< "$out" && echo "PASS $out"
fi

[ $fails -eq 0 ] || { echo "$fails failed"; exit 1; }
echo "INSTALL ANYWHERE OK"
