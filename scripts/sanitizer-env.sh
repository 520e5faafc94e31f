# Sourced by test-sanitizers.sh and test-fuzz.sh: what the sanitizers do on a report (abort, so a
# test fails and a fuzzer keeps the input) and what they ignore (leaks inside dependencies).
_vdbclay_root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-halt_on_error=1:print_stacktrace=1:suppressions=$_vdbclay_root/tests/sanitizers/ubsan.supp}
export LSAN_OPTIONS=${LSAN_OPTIONS:-suppressions=$_vdbclay_root/tests/sanitizers/lsan.supp}
unset _vdbclay_root
