#!/usr/bin/env bash
# Installs missing dependencies, then configures and builds vdbclay (Release) in ${BUILD_DIR:-build}.
# Extra arguments go to CMake's configure step, e.g. scripts/build.sh -DVDBCLAY_SANITIZE=thread
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
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
cmake --build "$BUILD_DIR" --parallel "${JOBS:-2}"
