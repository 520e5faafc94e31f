#!/usr/bin/env bash
# Where a run's CPU time goes, by part of the automaton and by thread: samples `vdbclay run` with
# perf (2000 Hz, every thread), then sums the samples of each part, per thread and in all:
#   kernel  the pass's blocks (processRange*, overBlocks*: the filter and the rules)
#   sink    the pass recording its changes into the next steps' candidates (sinkActive, sinkNext)
#   gather  the serial gather (Candidates::gather, drainInto)
#   wait    a pass's lanes waiting for each other (PassCrew::helperLoop, PassCrew::run, yield)
#   os      the kernel's and the hypervisor's ([k]: page faults, interrupts)
#   other   the rest (push, output, loader, setup)
# One sample is 0.5 ms of one thread's time. Comparing one thread with two shows which part the
# second thread makes more expensive (docs/PERFORMANCE.md). Needs perf (linux-perf); with no hardware counters (a VM) perf samples the CPU clock.
#
# usage: bench/profile-parts.sh SCENE THREADS [ROUNDS (default 1)] [VAR=VALUE ...]
#   BIN (default build-bench/apps/vdbclay, else build/apps/vdbclay) is the vdbclay to run; CPU
#   (default 0-(THREADS-1)) the CPUs to pin to. VAR=VALUE words set the run's environment.
# example: bench/profile-parts.sh data/scenes/bench/press128-0.8tc.json 2 2
#          CPU=1 bench/profile-parts.sh data/scenes/bench/press128-0.8tc.json 1 2
set -euo pipefail
if [[ $# -lt 2 ]]; then
    sed -n '2,18p' "$0" >&2
    exit 2
fi
scene=$1 threads=$2 rounds=${3:-1}
shift $(($# >= 3 ? 3 : 2))
command -v perf >/dev/null || { echo "profile-parts: perf not found (apt-get install linux-perf)" >&2; exit 2; }
[[ -f $scene ]] || { echo "profile-parts: $scene: no such scene" >&2; exit 2; }
bin=${BIN:-build-bench/apps/vdbclay}
[[ -n ${BIN:-} || -x $bin ]] || bin=build/apps/vdbclay
[[ -x $bin ]] || { echo "profile-parts: $bin: not built (set BIN)" >&2; exit 2; }
cpus=${CPU:-0-$((threads - 1))}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
for ((r = 1; r <= rounds; ++r)); do
    env "$@" perf record -q -F 2000 -o "$tmp/perf.data" taskset -c "$cpus" "$bin" run "$scene" \
        --threads "$threads" --quiet -o "$tmp/out.vdb" >/dev/null 2>&1 ||
        { echo "profile-parts: perf record or the run failed (perf_event_paranoid?)" >&2; exit 1; }
    perf report -i "$tmp/perf.data" --no-children --sort pid,sym -n --stdio 2>/dev/null |
        awk -v round="$r" -v threads="$threads" '
        /^#/ || !/%/ { next }
        {
            n = $2; tid = $3; sym = $0
            part = "other"
            if (sym ~ /overBlocks|processRange/) part = "kernel"
            else if (sym ~ /sinkActive|sinkNext|sinkChanges/) part = "sink"
            else if (sym ~ /drainInto|Candidates::gather/) part = "gather"
            else if (sym ~ /helperLoop|PassCrew::run|sched_yield/) part = "wait"
            else if (sym ~ /\[k\]/) part = "os"
            all[part] += n; mine[tid, part] += n; tids[tid] = 1; total += n
        }
        END {
            split("kernel sink gather wait os other", parts, " ")
            printf "round %d, %d thread(s): %d samples:", round, threads, total
            for (i = 1; i <= 6; ++i) printf " %s %d", parts[i], all[parts[i]]
            printf "\n"
            for (t in tids) {
                line = ""; sum = 0
                for (i = 1; i <= 6; ++i) { line = line sprintf(" %s %d", parts[i], mine[t, parts[i]]); sum += mine[t, parts[i]] }
                if (sum >= 0.02 * total) printf "  thread %s:%s\n", t, line
            }
        }'
done
