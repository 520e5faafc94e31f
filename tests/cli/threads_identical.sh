#!/usr/bin/env bash
# A whole scene (pushes and settling) gives the same clay on 1, 2 and 3 threads.
# usage: threads_identical.sh VDBCLAY SCENE.json WORKDIR
set -euo pipefail
bin=$1; scene=$2; work=$3
mkdir -p "$work"
hashes=()
for t in 1 2 3; do
  "$bin" run "$scene" --quiet --threads $t -o "$work/t$t.vdb" > /dev/null
  hashes+=("$("$bin" info "$work/t$t.vdb" | sed -n 's/.*content hash: \([0-9a-f]*\).*/\1/p')")
done
echo "hashes: ${hashes[*]}"
[ -n "${hashes[0]}" ] && [ "${hashes[0]}" = "${hashes[1]}" ] && [ "${hashes[0]}" = "${hashes[2]}" ] && echo IDENTICAL
