#!/usr/bin/env bash
# Idempotent set-up: install the Debian packages demcal needs (only those missing;
# apt-get update only when something is missing), then configure and build.
#   BUILD_DIR   build folder (default: build)
#   BUILD_TYPE  CMake build type (default: Release)
#   DEMCAL_SKIP_BUILD=1  install packages only
#   BUILD_TARGETS  what to build (default: everything, tests and benchmarks included)
#   BUILD_LOG      the compiler's output goes to this file instead of the terminal
#                  (its last lines are shown if the build fails)
set -euo pipefail
cd "$(dirname "$0")/.."

PACKAGES=(build-essential cmake pkg-config
  libeigen3-dev libnlopt-cxx-dev libhdf5-dev libsqlite3-dev nlohmann-json3-dev
  libgtest-dev libgmock-dev libbenchmark-dev libcli11-dev gnuplot-nox
  libopenmpi-dev openmpi-bin hdf5-tools sqlite3)

missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "setup: installing missing packages: ${missing[*]}" >&2
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
else
  echo "setup: all Debian packages present" >&2
fi

[ "${DEMCAL_SKIP_BUILD:-0}" = 1 ] && exit 0

BUILD_DIR=${BUILD_DIR:-build}
BUILD_TYPE=${BUILD_TYPE:-Release}
JOBS=${JOBS:-$(nproc)}
cmake -S . -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE="$BUILD_TYPE" ${CMAKE_ARGS:-} >/dev/null
build=(cmake --build "$BUILD_DIR" -j "$JOBS")
[ -n "${BUILD_TARGETS:-}" ] && build+=(--target ${BUILD_TARGETS})
if [ -n "${BUILD_LOG:-}" ]; then
  echo "setup: building ${BUILD_TARGETS:-everything} in $BUILD_DIR (a few minutes the first time; output in $BUILD_LOG)" >&2
  if ! "${build[@]}" > "$BUILD_LOG" 2>&1; then
    tail -n 40 "$BUILD_LOG" >&2
    echo "setup: the build failed; the whole output is in $BUILD_LOG" >&2
    exit 1
  fi
else
  "${build[@]}"
fi
