#!/usr/bin/env bash
# Installs missing dependencies, then configures and builds vdbclay (Release) in ${BUILD_DIR:-build}.
# Extra arguments go to CMake's configure step, e.g. scripts/build.sh -DVDBCLAY_SANITIZE=thread.
# TARGETS (space-separated) builds only those targets, e.g. TARGETS=vdbclay_cli (the library and
# the CLI); unset, everything the configuration enables.
set -euo pipefail
cd "$(dirname "$0")/.."
# DEPS=cli installs only what the library and the CLI need (scripts/run.sh).
bash scripts/install-deps.sh ${DEPS:-}
BUILD_DIR=${BUILD_DIR:-build}
generator=()
if command -v ninja >/dev/null 2>&1; then generator=(-G Ninja); fi
launcher=() # ccache (installed by install-deps.sh); paths relative to the checkout, so clones share hits
if command -v ccache >/dev/null 2>&1; then
  launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
  export CCACHE_BASEDIR=${CCACHE_BASEDIR:-$PWD}
  export CCACHE_NOHASHDIR=${CCACHE_NOHASHDIR:-1} # -g builds: do not hash the build directory, so clones share hits
fi
if [ ! -f "$BUILD_DIR/CMakeCache.txt" ]; then
  cmake -S . -B "$BUILD_DIR" "${generator[@]}" "${launcher[@]}" -DCMAKE_BUILD_TYPE=Release "$@" >/dev/null
elif [ $# -gt 0 ]; then
  cmake "$BUILD_DIR" "$@" >/dev/null
fi
# OpenVDB-heavy translation units take ~0.7 GB each; two jobs fit any machine we build on.
targets=()
for t in ${TARGETS:-}; do targets+=(--target "$t"); done
cmake --build "$BUILD_DIR" --parallel "${JOBS:-2}" "${targets[@]}"
