#!/usr/bin/env bash
# Large sparse volumes: the whole `vdbclay run` of data/scenes/bench/sparse-stroke.json.in (a sphere of
# clay at Tc, D wide, stroked by a radius-6 tool: a 9-voxel dip, then 9 frames sliding 2 voxels) at each
# width given (default 128 512 1024 2048), one thread, the default memory budget. Prints, per width:
# the command's wall time, the set-up, the frames (mean over every frame, the first included, and the
# first alone), the output, the peak resident set (GNU time's Maximum resident set size), the memory
# estimate, and the .vdb's size. docs/PERFORMANCE.md has the figures.
#   bench/sparse-volumes.sh [WIDTH ...]     (BIN: the vdbclay binary, default build/apps/vdbclay;
#                                            RUN_OPTIONS: more options for vdbclay run, e.g. "--grids mass")
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${BIN:-build/apps/vdbclay}
[ -x "$BIN" ] || { echo "sparse-volumes: no vdbclay at $BIN (build it, or set BIN)" >&2; exit 1; }
[ -x /usr/bin/time ] || { echo "sparse-volumes: needs GNU time (apt-get install time)" >&2; exit 1; }
widths=("$@")
[ ${#widths[@]} -gt 0 ] || widths=(128 512 1024 2048)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
printf '%-6s %8s %8s %10s %10s %8s %9s %10s %9s %s\n' width wall_s setup_s frames_ms first_ms output_s peak_MiB estimate_MiB file_MiB hash
for d in "${widths[@]}"; do
  c=$((d / 2))
  sed -e "s/{{c}}/$c/g" -e "s/{{tool_y}}/$((d + 6))/g" data/scenes/bench/sparse-stroke.json.in >"$work/scene.json"
  # shellcheck disable=SC2086 # RUN_OPTIONS: words
  /usr/bin/time -v -o "$work/time.txt" "$BIN" run "$work/scene.json" -o "$work/out.vdb" --threads 1 \
    --stats "$work/stats.json" ${RUN_OPTIONS:-} >"$work/log.txt" 2>&1 ||
    { echo "sparse-volumes: width $d failed:" >&2; cat "$work/log.txt" >&2; exit 1; }
  python3 - "$d" "$work" <<'PY'
import json, os, re, sys
d, work = sys.argv[1], sys.argv[2]
s = json.load(open(os.path.join(work, "stats.json")))
t = open(os.path.join(work, "time.txt")).read()
wall = t.split("Elapsed (wall clock) time (h:mm:ss or m:ss): ")[1].split("\n")[0].split(":")
wall_s = sum(float(x) * 60 ** i for i, x in enumerate(reversed(wall)))
peak = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", t).group(1)) / 1024
secs = s["frame_seconds"]
log = open(os.path.join(work, "log.txt")).read()
est = re.search(r"memory: about ([0-9.]+) (MiB|GiB|KiB)", log)
est_mib = float(est.group(1)) * {"KiB": 1 / 1024, "MiB": 1, "GiB": 1024}[est.group(2)] if est else float("nan")
size = os.path.getsize(os.path.join(work, "out.vdb")) / 2**20
print(f"{d:<6} {wall_s:8.2f} {s['setup_seconds']:8.2f} {1000 * sum(secs) / len(secs):10.1f} "
      f"{1000 * secs[0]:10.1f} {s['output_seconds']:8.2f} {peak:9.1f} {est_mib:10.1f} {size:9.2f} {s['content_hash']}")
PY
done
