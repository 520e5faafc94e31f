#!/usr/bin/env bash
# The thread-scaling curve of whole scenes: runs `vdbclay run SCENE --threads T` for every T of a
# list, ROUNDS times, the thread counts in a different order each round (so a slow spell of a
# shared machine does not fall on one T), each run pinned to CPUs 0..T-1 (taskset, where present).
# Prints per scene and T the median whole-run time, the automaton's repartition, nanoseconds per
# updated block, the fraction of the pass's thread time left idle (pass_idle / (busy + idle)) and
# the speed-up against the smallest T, taken round by round (the same state of the machine), as
# median and range. Every run of a scene must end with the same content hash (--stats'
# content_hash): a difference is reported and the script exits 1. Needs only bash, awk and sed, so
# it runs on a bare machine (a device: scripts/device-bundle.sh, docs/PERFORMANCE.md).
#
# usage: bench/thread-curve.sh [-t 1,2,4,8,16] [-r ROUNDS] [-b VDBCLAY] [-c CSV] [SCENE ...]
#   -t  thread counts (default 1,2 and every power of two up to the CPUs here, then the CPU count)
#   -r  rounds (default 3)
#   -b  the vdbclay to run (default build/apps/vdbclay); a wrapper script is fine
#   -c  also write every run as CSV to this file
#   SCENE  default: data/scenes/bench/press48-0.8tc.json data/scenes/bench/press128-0.8tc.json
set -euo pipefail
cpus=$(getconf _NPROCESSORS_ONLN 2>/dev/null || echo 1)
threads=
rounds=3
bin=build/apps/vdbclay
csv=
while getopts "t:r:b:c:h" opt; do
    case $opt in
    t) threads=$OPTARG ;;
    r) rounds=$OPTARG ;;
    b) bin=$OPTARG ;;
    c) csv=$OPTARG ;;
    *)
        sed -n '2,17p' "$0" >&2
        exit 2
        ;;
    esac
done
shift $((OPTIND - 1))
scenes=("$@")
[[ ${#scenes[@]} -gt 0 ]] || scenes=(data/scenes/bench/press48-0.8tc.json data/scenes/bench/press128-0.8tc.json)
if [[ -z $threads ]]; then
    threads=1
    for ((t = 2; t < cpus; t *= 2)); do threads+=",$t"; done
    [[ $cpus -gt 1 ]] && threads+=",$cpus"
fi
IFS=, read -r -a tlist <<<"$threads"
for t in "${tlist[@]}"; do
    [[ $t =~ ^[1-9][0-9]*$ ]] || { echo "thread-curve: -t: '$t' is not a thread count" >&2; exit 2; }
done
[[ $rounds =~ ^[1-9][0-9]*$ ]] || { echo "thread-curve: -r: '$rounds' is not a round count" >&2; exit 2; }
[[ -x $bin ]] || { echo "thread-curve: -b: '$bin' is not an executable" >&2; exit 2; }
for s in "${scenes[@]}"; do
    [[ -r $s ]] || { echo "thread-curve: scene '$s' cannot be read" >&2; exit 2; }
done
pin=
command -v taskset >/dev/null && pin=taskset
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
runs=$tmp/runs.csv
echo "scene,threads,round,seconds,repartition_s,gather_s,push_s,pass_busy_s,pass_idle_s,blocks_updated,content_hash" >"$runs"

# A value of the --stats JSON (nlohmann's dump(2): one key per line).
stat() { sed -n "s/^ *\"$1\": \"\\{0,1\\}\\([^\",]*\\)\"\\{0,1\\},\\{0,1\\}$/\\1/p" "$2" | head -1; }

echo "thread-curve: ${#scenes[@]} scene(s), threads ${threads}, $rounds round(s), $cpus CPU(s)${pin:+, pinned}" >&2
n=${#tlist[@]}
for ((r = 0; r < rounds; ++r)); do
    for ((k = 0; k < n; ++k)); do
        t=${tlist[$(((k + r) % n))]} # each round starts one thread count later
        for s in "${scenes[@]}"; do
            cmd=("$bin" run "$s" --threads "$t" --quiet --stats "$tmp/s.json")
            if [[ -n $pin && $t -le $cpus ]]; then cmd=(taskset -c "0-$((t - 1))" "${cmd[@]}"); fi
            "${cmd[@]}" >"$tmp/log" 2>&1 || { echo "thread-curve: failed: ${cmd[*]}" >&2; cat "$tmp/log" >&2; exit 1; }
            f=$tmp/s.json
            echo "$(basename "$s" .json),$t,$((r + 1)),$(stat seconds "$f"),$(stat repartition "$f"),$(stat gather "$f"),$(stat push_seconds "$f"),$(stat pass_busy_seconds "$f"),$(stat pass_idle_seconds "$f"),$(stat blocks_updated "$f"),$(stat content_hash "$f")" >>"$runs"
            echo "  round $((r + 1)), $t thread(s), $(basename "$s"): $(stat seconds "$f") s" >&2
        done
    done
done
[[ -z $csv ]] || cp "$runs" "$csv"

# The summary, and the content hashes checked per scene.
awk -F, -v tl="$threads" '
function median(list,   a, m, i, j, x) {
    m = split(list, a, " ")
    for (i = 2; i <= m; ++i) { x = a[i]; for (j = i - 1; j >= 1 && a[j] > x; --j) a[j + 1] = a[j]; a[j + 1] = x }
    return m % 2 ? a[(m + 1) / 2] : (a[m / 2] + a[m / 2 + 1]) / 2
}
function lo(list,   a, m, i, v) { m = split(list, a, " "); v = a[1]; for (i = 2; i <= m; ++i) if (a[i] < v) v = a[i]; return v }
function hi(list,   a, m, i, v) { m = split(list, a, " "); v = a[1]; for (i = 2; i <= m; ++i) if (a[i] > v) v = a[i]; return v }
NR == 1 { next }
{
    key = $1 SUBSEP $2
    if (!($1 in seen)) { seen[$1] = 1; order[++ns] = $1; hash[$1] = $11 }
    if ($11 != hash[$1]) { bad[$1] = bad[$1] " " $2 "t:" $11 }
    whole[key] = whole[key] " " $4
    rep[key] = rep[key] " " $5
    ns_up[key] = ns_up[key] " " ($10 > 0 ? 1e9 * $5 / $10 : 0)
    idle[key] = idle[key] " " ($8 + $9 > 0 ? $9 / ($8 + $9) : 0)
    at[$1, $2, $3] = $4
    rounds[$3] = 1
}
END {
    nt = split(tl, t, ",")
    base = t[1]; for (i = 2; i <= nt; ++i) if (t[i] + 0 < base + 0) base = t[i]
    status = 0
    for (s = 1; s <= ns; ++s) {
        sc = order[s]
        printf "\n%s (content hash %s)\n", sc, hash[sc]
        printf "%8s %10s %14s %14s %12s %26s\n", "threads", "run s", "repartition s", "ns/update", "idle", "speed-up vs " base " (range)"
        for (i = 1; i <= nt; ++i) {
            key = sc SUBSEP t[i]
            sp = ""
            for (r in rounds) if ((sc, t[i], r) in at && (sc, base, r) in at && at[sc, t[i], r] > 0)
                sp = sp " " at[sc, base, r] / at[sc, t[i], r]
            printf "%8s %10.3f %14.3f %14.1f %11.1f%% %12.2fx (%.2f-%.2f)\n", t[i], median(whole[key]), median(rep[key]),
                   median(ns_up[key]), 100 * median(idle[key]), median(sp), lo(sp), hi(sp)
        }
        if (sc in bad) { printf "thread-curve: %s: content hashes differ from %s:%s\n", sc, hash[sc], bad[sc] > "/dev/stderr"; status = 1 }
    }
    exit status
}' "$runs"
