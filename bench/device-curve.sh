#!/usr/bin/env bash
# The thread-scaling curve in one command, for a machine with more cores than this project's
# CI and development VMs (the lent device: 16 cores, bare, no network). It unpacks the bundle that
# scripts/device-bundle.sh made (a Release build with its own libraries and loader), then writes to
# OUTDIR:
#   handoff.txt       bench_handoff: each CPU's speed, the cache-line round trip from CPU 0 to every
#                     other CPU, a fork/join of THREADS_MAX tasks (the floor under a pass), and
#                     THREADS_MAX threads at once on private data (what the machine itself costs a
#                     CPU while the others work: the rest of a pass's loss is shared data)
#   curve.txt, .csv   bench/thread-curve.sh on its default scenes (press48 and press128 at 0.8 Tc,
#                     settled every frame: small active sets, 130-670 blocks a step)
#   press.txt, .csv   bench_scenes' press, first PRESS_STEPS steps (large active sets: ~130,000
#                     updates a step at N = 128), vdbclay alone, every thread count
# Every run of a scene must end with the same content hash on every thread count; the script exits
# non-zero otherwise.
#
# usage: bench/device-curve.sh [OUTDIR (default $OUT, else device-curve)]
#   env: BUNDLE (default .device/vdbclay-bench.tar.gz), THREADS (default 1,2,4,8,12,16, capped at the
#        CPUs here), ROUNDS (default 3), PRESS (default 128,256), PRESS_STEPS (default 300)
# The device call (docs/PERFORMANCE.md, "The thread curve, ready for a device"):
#   scripts/device-bundle.sh build-bench            # here, once, after a Release bench build
#   run(command="bash bench/device-curve.sh", carry=[".device"], timeout_s=540)
set -euo pipefail
out=${1:-${OUT:-device-curve}}
bundle=${BUNDLE:-.device/vdbclay-bench.tar.gz}
rounds=${ROUNDS:-3}
press=${PRESS:-128,256}
pressSteps=${PRESS_STEPS:-300}
[[ -r $bundle ]] || { echo "device-curve: $bundle: no bundle (make it with scripts/device-bundle.sh)" >&2; exit 2; }
cpus=$(getconf _NPROCESSORS_ONLN 2>/dev/null || echo 1)
threads=
IFS=, read -r -a want <<<"${THREADS:-1,2,4,8,12,16}"
for t in "${want[@]}"; do
    [[ $t -le $cpus ]] && threads+=${threads:+,}$t
done
[[ -n $threads ]] || threads=1
mkdir -p "$out"
b=$(mktemp -d)
trap 'rm -rf "$b"' EXIT
tar xzf "$bundle" -C "$b"
{
    echo "device-curve: $(date -u +%FT%TZ), $cpus CPUs, threads $threads, $rounds rounds"
    uname -srm
    grep -m1 "model name" /proc/cpuinfo || true
    "$b/vdbclay" --version
} | tee "$out/machine.txt"
max=${threads##*,}
if [[ -x $b/bench_handoff ]]; then
    "$b/bench_handoff" "$max" 20 2>&1 | tee "$out/handoff.txt"
fi
status=0
bench/thread-curve.sh -b "$b/vdbclay" -t "$threads" -r "$rounds" -c "$out/curve.csv" 2>"$out/curve.log" |
    tee "$out/curve.txt" || status=1
if [[ -x $b/bench_scenes ]]; then
    "$b/bench_scenes" --press "$press" --stroke "" --threads "$threads" --no-baselines --press-steps "$pressSteps" \
        --repeats "$rounds" --csv "$out/press.csv" 2>&1 | tee "$out/press.txt" || status=1
    # bench_scenes marks a run whose clay differs from one thread's (identical: no).
    if grep -q " no *$" "$out/press.txt"; then
        echo "device-curve: bench_scenes: a thread count's clay differs from one thread's" >&2
        status=1
    fi
fi
exit $status
