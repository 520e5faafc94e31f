#!/usr/bin/env bash
# The device run's scripts keep working (a lent device gives 15 minutes: no time to debug there):
# bench/thread-curve.sh reads --stats and compares the content hashes; scripts/device-bundle.sh
# makes a bundle that runs with an empty environment and gives the same clay; bench/device-curve.sh
# runs end to end on it. Checks results, not times.
# usage: thread_curve.sh VDBCLAY SOURCE_DIR BUILD_DIR WORKDIR
set -euo pipefail
bin=$(cd "$(dirname "$1")" && pwd)/$(basename "$1"); src=$2; build=$3; work=$4
rm -rf "$work"; mkdir -p "$work"
work=$(cd "$work" && pwd)
cd "$src"
scene=data/scenes/paper/cube-small-plate.json
fail() { echo "FAIL: $*"; exit 1; }

# 1. The curve on 1 and 2 threads, two rounds: a row per thread count, every hash equal.
bench/thread-curve.sh -b "$bin" -t 1,2 -r 2 -c "$work/curve.csv" "$scene" > "$work/curve.txt" 2> "$work/curve.log" ||
  { cat "$work/curve.txt" "$work/curve.log"; fail "thread-curve.sh exited non-zero"; }
[ "$(wc -l < "$work/curve.csv")" = 5 ] || { cat "$work/curve.csv"; fail "the CSV should hold a header and 4 runs"; }
hashes=$(cut -d, -f11 "$work/curve.csv" | tail -n +2 | sort -u)
[[ $hashes =~ ^[0-9a-f]{16}$ ]] || fail "runs' content hashes: '$hashes'"
grep -q "cube-small-plate (content hash $hashes)" "$work/curve.txt" || { cat "$work/curve.txt"; fail "no summary"; }
for t in 1 2; do
  grep -Eq "^ +$t +[0-9.]+ +[0-9.]+ +[0-9.]+ +[0-9.]+% +[0-9.]+x" "$work/curve.txt" || { cat "$work/curve.txt"; fail "no row for $t threads"; }
done
awk -F, 'NR > 1 && !($5 > 0 && $10 > 0) { bad = 1 } END { exit bad }' "$work/curve.csv" ||
  { cat "$work/curve.csv"; fail "a run without repartition time or updated blocks"; }

# 2. A vdbclay whose clay differs on 2 threads is caught: exit 1, naming the hashes.
cat > "$work/differs" <<EOF
#!/usr/bin/env bash
"$bin" "\$@" || exit
[ "\$4" = 2 ] && sed -i 's/"content_hash": "[0-9a-f]*"/"content_hash": "00000000000000ff"/' "\$7"
exit 0
EOF
chmod +x "$work/differs"
if bench/thread-curve.sh -b "$work/differs" -t 1,2 -r 1 "$scene" > "$work/differs.txt" 2>&1; then
  cat "$work/differs.txt"; fail "a differing hash was not caught"
fi
grep -q "content hashes differ from $hashes: 2t:00000000000000ff" "$work/differs.txt" || { cat "$work/differs.txt"; fail "no message"; }

# 3. The bundle (Release builds only: the script refuses others, whose timings would mislead).
if grep -q '^CMAKE_BUILD_TYPE:STRING=Release$' "$build/CMakeCache.txt"; then
  scripts/device-bundle.sh "$build" "$work/bundle.tar.gz" > "$work/bundle.log" || { cat "$work/bundle.log"; fail "device-bundle.sh"; }
  mkdir -p "$work/b"; tar xzf "$work/bundle.tar.gz" -C "$work/b"
  env -i "$work/b/vdbclay" run "$scene" --threads 2 --quiet --stats "$work/b.json" > /dev/null || fail "the bundled vdbclay"
  grep -q "\"content_hash\": \"$hashes\"" "$work/b.json" || { cat "$work/b.json"; fail "the bundle's clay differs"; }
  # 4. The device run itself, made small (bench_scenes is in the bundle only from bench builds).
  BUNDLE="$work/bundle.tar.gz" THREADS=1,2 ROUNDS=1 PRESS=16 PRESS_STEPS=20 \
    bash bench/device-curve.sh "$work/device" > "$work/device.log" 2>&1 || { cat "$work/device.log"; fail "device-curve.sh"; }
  for f in machine.txt curve.txt curve.csv; do [ -s "$work/device/$f" ] || fail "device-curve.sh wrote no $f"; done
  grep -q "press128-0.8tc (content hash 99120b0961446514)" "$work/device/curve.txt" || { cat "$work/device/curve.txt"; fail "press128's hash"; }
  echo "bundle: runs with an empty environment, same clay; device-curve.sh ran"
else
  echo "bundle: skipped (not a Release build)"
fi
echo "THREAD CURVE OK"
