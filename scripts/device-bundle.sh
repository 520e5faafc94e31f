#!/usr/bin/env bash
# Packs a Release build's vdbclay (and bench_handoff, bench_scenes where built) with every shared
# library they load, the C library and its loader included, into one tarball that runs on a bare
# x86-64 Linux machine with nothing installed: the lent device machine (the `device` tool's run),
# which cannot reach a package mirror and may have another distribution's libraries. Each program
# runs through the bundled loader (`lib/ld-linux-x86-64.so.2 --library-path lib bin/PROG`), by a
# wrapper of the program's name at the bundle's top.
#
# usage: scripts/device-bundle.sh [BUILD_DIR (default build-bench)] [TARBALL (default .device/vdbclay-bench.tar.gz)]
#   BUILD_DIR: a Release build; with -DVDBCLAY_BUILD_BENCH=ON it also holds the benchmarks.
# On the device (docs/PERFORMANCE.md, "The 16-thread curve, ready for a device"):
#   mkdir -p /tmp/b && tar xzf .device/vdbclay-bench.tar.gz -C /tmp/b &&
#   bench/thread-curve.sh -b /tmp/b/vdbclay -t 1,2,4,8,12,16 -r 3 -c $OUT/curve.csv
set -euo pipefail
build=${1:-build-bench}
tarball=${2:-.device/vdbclay-bench.tar.gz}
[[ -x $build/apps/vdbclay ]] || { echo "device-bundle: $build/apps/vdbclay: not built (cmake -S . -B $build -DCMAKE_BUILD_TYPE=Release -DVDBCLAY_BUILD_BENCH=ON && ninja -C $build)" >&2; exit 2; }
grep -q '^CMAKE_BUILD_TYPE:STRING=Release$' "$build/CMakeCache.txt" ||
    { echo "device-bundle: $build is not a Release build: its timings would mislead" >&2; exit 2; }
progs=("$build/apps/vdbclay")
for p in bench_handoff bench_scenes; do
    [[ -x $build/bench/$p ]] && progs+=("$build/bench/$p")
done
stage=$(mktemp -d)
trap 'rm -rf "$stage"' EXIT
mkdir -p "$stage/bin" "$stage/lib"
loader=
for p in "${progs[@]}"; do
    cp "$p" "$stage/bin/"
    # ldd's lines: "name => /path (addr)", and the loader's "/path (addr)".
    while read -r lib; do
        [[ -n $lib ]] || continue
        cp -L -n "$lib" "$stage/lib/"
        [[ $(basename "$lib") == ld-linux* ]] && loader=$(basename "$lib")
    done < <(ldd "$p" | awk '$2 == "=>" && $3 ~ /^\// { print $3 } $1 ~ /^\// { print $1 }')
done
[[ -n $loader ]] || { echo "device-bundle: ldd named no loader (ld-linux*) for ${progs[*]}" >&2; exit 1; }
# Libraries loaded later by name (dlopen), where present: TBB's allocator.
for extra in libtbbmalloc.so.2 libtbbmalloc_proxy.so.2; do
    f=$(ldconfig -p 2>/dev/null | awk -v n="$extra" '$1 == n && /x86-64/ && !f { f = $NF } END { if (f) print f }')
    [[ -n $f ]] && cp -L -n "$f" "$stage/lib/"
done
for p in "${progs[@]}"; do
    name=$(basename "$p")
    cat >"$stage/$name" <<EOF
#!/bin/sh
# $name through the bundle's own loader and libraries (scripts/device-bundle.sh).
here=\$(cd "\$(dirname "\$0")" && pwd)
exec "\$here/lib/$loader" --library-path "\$here/lib" "\$here/bin/$name" "\$@"
EOF
    chmod +x "$stage/$name"
done
# Smoke test: the bundle runs with no library path of this machine's.
env -i "$stage/vdbclay" --version >/dev/null || { echo "device-bundle: the bundled vdbclay does not start" >&2; exit 1; }
mkdir -p "$(dirname "$tarball")"
tar czf "$tarball.tmp" -C "$stage" .
mv "$tarball.tmp" "$tarball"
echo "device-bundle: $tarball ($(du -h "$tarball" | cut -f1); $(ls "$stage/bin" | tr '\n' ' ')+ $(ls "$stage/lib" | wc -l) libraries)"
