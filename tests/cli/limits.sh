#!/usr/bin/env bash
# Every integer option of every subcommand, given values just past its limits, past 2^64 and not
# integers at all: refused with one line naming the option and its range, never clamped. The
# options come from each subcommand's --help, so a new option is walked too, and an integer option
# with no range is itself a failure. In range, the extremes are taken exactly: a seed of 2^64 - 1
# is recorded as 2^64 - 1.
# usage: limits.sh VDBCLAY WORKDIR
set -uo pipefail
source "$(dirname "$0")/lib.sh"
cli_setup "$1" "$2"
printf 'not a vdb at all' > notvdb.vdb

# What each subcommand needs besides the option under test (refused before any of it is read).
declare -A needs=(
  [run]="" [info]="notvdb.vdb" [mesh]="notvdb.vdb -o result.obj" [render]="notvdb.vdb -o result.png"
  [import]="notvdb.vdb -o result.vdb" [demo]=""
)
walked=0
for sub in run info mesh render import demo; do
  "$bin" "$sub" --help > help.txt 2>&1 || { fail "$sub --help: exit $?"; continue; }
  # "--frames INT:INT in [1, 100000000]": option, type, range (none when the option has no range).
  python3 - help.txt > options.txt <<'PY' || fail "$sub --help: cannot read its options"
import re, sys
for line in open(sys.argv[1]):
    m = re.match(r'\s+(?:-\w, )?(--[\w-]+)(?:,\s*-\w)?\s+(INT|UINT)\b(\S*)', line)
    if not m:
        continue
    r = re.search(r'in \[(-?\d+), (\d+)\]', m.group(3) + line)
    print(m.group(1), m.group(2), r.group(1) if r else '-', r.group(2) if r else '-')
PY
  while read -r opt type lo hi; do
    walked=$((walked + 1))
    if [ "$lo" = - ]; then
      fail "$sub $opt: an integer option ($type) with no range in --help"
      continue
    fi
    below=$(python3 -c "print($lo - 1)"); above=$(python3 -c "print($hi + 1)")
    needle="$opt: expected an integer in \[$lo, $hi\], got"
    # shellcheck disable=SC2086
    for v in "$below" "$above" 18446744073709551616 -18446744073709551617 1e3 0x10 12abc ""; do
      refused "$sub $opt $v" "$needle" "$bin" "$sub" ${needs[$sub]} "$opt" "$v"
      [ -e result.vdb ] || [ -e result.obj ] || [ -e result.png ] && fail "$sub $opt $v: wrote a file"
      rm -f result.vdb result.obj result.png
    done
  done < options.txt
done
[ "$walked" -ge 15 ] || fail "only $walked integer options found in the --help texts"

# In range, the largest values are taken as given, not clamped on the way (a seed is at most
# 2^63 - 1 everywhere: scenes, run and demo).
"$bin" run --frames 1 --quiet --seed 9223372036854775807 -o seed.vdb > out.txt 2> err.txt || fail "run --seed 2^63-1: $(cat err.txt)"
"$bin" info seed.vdb | grep -q "vdbclay_seed.*= 9223372036854775807" ||
  fail "run --seed 2^63-1 recorded: $("$bin" info seed.vdb | grep seed)"
"$bin" demo --size 4 --seed 9223372036854775807 --max-steps 18446744073709551615 > out.txt 2> err.txt ||
  fail "demo at its largest seed and step budget: $(cat err.txt)"

if [ "$fails" -eq 0 ]; then echo "LIMITS REFUSED ($walked integer options)"; else echo "$fails failures"; exit 1; fi
