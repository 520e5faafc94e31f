#!/usr/bin/env bash
# Installs what vdbclay needs, from Debian packages: `install-deps.sh cli` only what the library and
# the CLI need to build (scripts/run.sh); with no argument, everything the tests, the Python module
# and the sanitizer builds need too. Idempotent: quiet and quick when everything is already there.
#   libboost-iostreams-dev: Debian's FindOpenVDB.cmake requires its CMake config.
#   nlohmann-json3-dev:     header-only JSON for scene files (saves a hand-written parser).
#   libpng-dev:             PNG output for `vdbclay render`.
#   libcli11-dev:           header-only command-line parsing for the CLI (subcommands, --help).
#   libopenvdb-tools:       vdb_print, used by the tests to check our .vdb files open in OpenVDB's tools.
#   curl, xz-utils:         scripts/test-tsan.sh fetches Debian's oneTBB source to build it with TSan.
#   ccache:                 compiler cache for every build script (clean clones share its hits).
#   pybind11-dev, python3-dev, python3-numpy: the Python module `vdbclay` (python/, docs/INTEROP.md).
#   python3-openvdb:        OpenVDB's own Python module; a test proves it reads Tc and mass back.
#   blender:                the Blender add-on's test and python_blender_import run it headless
#                           (skipped where it is missing, e.g. after `install-deps.sh cli`).
#   clang, libclang-rt-dev: the sanitizer and fuzzing build (scripts/test-sanitizers.sh): libFuzzer
#                           and the sanitizer runtimes come with clang's runtime libraries.
set -euo pipefail

PKGS=(
  cmake g++ ninja-build pkg-config ccache
  libopenvdb-dev libtbb-dev libboost-dev libboost-iostreams-dev libblosc-dev
  nlohmann-json3-dev libpng-dev libcli11-dev
)
case "${1:-all}" in
  cli) ;;
  all)
    PKGS+=(
      libgtest-dev googletest libopenvdb-tools
      curl ca-certificates xz-utils
      clang libclang-rt-dev
      pybind11-dev python3-dev python3-numpy python3-openvdb
      blender
    )
    ;;
  *) echo "install-deps: unknown set '$1' (expected cli or nothing)" >&2; exit 2 ;;
esac

missing=()
for p in "${PKGS[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done
[ ${#missing[@]} -eq 0 ] && exit 0

echo "install-deps: installing ${missing[*]}" >&2
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
