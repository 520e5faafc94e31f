#!/usr/bin/env bash
# Compares builds of vdbclay on one scene, side by side: runs them in turn, ROUNDS times, each on one
# thread pinned to one CPU (or as THREADS says), and prints the automaton's repartition time per
# updated block (from --stats: stage_seconds.repartition / blocks_updated) and the whole run's time,
# as median and range.
# Alternating the builds is what makes the ratio trustworthy on a shared, noisy machine (see
# docs/PERFORMANCE.md); a single pair of runs is not.
#
# usage: bench/ab-repartition.sh SCENE ROUNDS NAME=[VAR=VALUE ...]BINARY[:LIBDIR] ...
#   LIBDIR, when given, goes first on LD_LIBRARY_PATH (a copy of an older libvdbclay.so runs under
#   the same binary). VAR=VALUE words before the binary set its environment (quote the spec).
#   THREADS (default 1) is the --threads of every run, THREADS=N among a spec's words of its own;
#   CPU (default 1, or 0-(THREADS-1)) the CPUs to pin to, CPU=LIST among a spec's words of its own
#   (a virtual machine's CPUs need not be equal: bench_handoff measures each; compare one thread on
#   each CPU with THREADS=1 CPU=0 and THREADS=1 CPU=1). Last, each build's ratio to the first,
#   round by round (the same state of the machine), as median and range.
# example: bench/ab-repartition.sh data/scenes/bench/press48-0.8tc.json 10 \
#            old=build/apps/vdbclay:/tmp/old-lib new=build/apps/vdbclay
#          bench/ab-repartition.sh data/scenes/bench/press128-0.8tc.json 8 \
#            'one=THREADS=1 build/apps/vdbclay' 'two=THREADS=2 build/apps/vdbclay'
set -euo pipefail
if [[ $# -lt 3 ]]; then
    sed -n '2,18p' "$0" >&2
    exit 2
fi
scene=$1 rounds=$2
shift 2
py=/usr/bin/python3
[[ -x $py ]] || py=python3
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
# parse SPEC: sets name, vars (array of VAR=VALUE), bin, lib
parse() {
    local spec=$1 words
    name=${spec%%=*}
    read -r -a words <<<"${spec#*=}"
    vars=() threads=${THREADS:-1}
    local w own=
    for w in "${words[@]:0:${#words[@]}-1}"; do
        if [[ $w == THREADS=* ]]; then
            threads=${w#THREADS=}
        elif [[ $w == CPU=* ]]; then
            own=${w#CPU=}
        else
            vars+=("$w")
        fi
    done
    if [[ $threads == 1 ]]; then cpu=${CPU:-1}; else cpu=${CPU:-0-$((threads - 1))}; fi
    [[ -n $own ]] && cpu=$own
    local last=${words[${#words[@]}-1]}
    bin=${last%%:*} lib=
    [[ $last == *:* ]] && lib=${last#*:}
    return 0
}
for spec in "$@"; do
    [[ $spec == *=* ]] || { echo "ab-repartition: '$spec' is not NAME=[VAR=VALUE ...]BINARY[:LIBDIR]" >&2; exit 2; }
    parse "$spec"
    [[ -x $bin ]] || { echo "ab-repartition: '$bin' is not an executable" >&2; exit 2; }
done
for ((r = 1; r <= rounds; ++r)); do
    for spec in "$@"; do
        parse "$spec"
        env ${vars[@]+"${vars[@]}"} LD_LIBRARY_PATH=$lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH} \
            taskset -c "$cpu" "$bin" run "$scene" --threads "$threads" --quiet --stats "$tmp/s.json" >/dev/null
        "$py" -c 'import json,sys; s=json.load(open(sys.argv[1])); print(sys.argv[2], s["stage_seconds"]["repartition"], s["blocks_updated"], s["seconds"])' \
            "$tmp/s.json" "$name" >>"$tmp/rows"
    done
done
"$py" - "$tmp/rows" "$@" <<'PY'
import statistics, sys
rows = [l.split() for l in open(sys.argv[1])]
for spec in sys.argv[2:]:
    name = spec.split('=')[0]
    mine = [r for r in rows if r[0] == name]
    per = sorted(float(r[1]) * 1e9 / int(r[2]) for r in mine)
    run = sorted(float(r[3]) for r in mine)
    print(f"{name:8s} n={len(per)} repartition/update median {statistics.median(per):.1f} ns "
          f"({per[0]:.1f}-{per[-1]:.1f}); run median {statistics.median(run):.3f} s "
          f"({run[0]:.3f}-{run[-1]:.3f}); updated blocks {mine[0][2]}")
# Round by round against the first build (same round, so the same state of the machine).
names = [spec.split('=')[0] for spec in sys.argv[2:]]
base = [r for r in rows if r[0] == names[0]]
for name in names[1:]:
    mine = [r for r in rows if r[0] == name]
    rep = sorted(float(b[1]) / float(m[1]) for b, m in zip(base, mine))
    run = sorted(float(b[3]) / float(m[3]) for b, m in zip(base, mine))
    print(f"{names[0]}/{name} per round: repartition median {statistics.median(rep):.2f}x "
          f"({rep[0]:.2f}-{rep[-1]:.2f}), run median {statistics.median(run):.2f}x ({run[0]:.2f}-{run[-1]:.2f})")
PY
