#!/usr/bin/env bash
# The whole test suite under the compiler's run-time checkers, in a build folder of
# its own (the Release build in build/ is left alone). Slow: on 2 cores about 20
# minutes to build and 20 to test (checks: longer); for a change to memory handling, indices or
# anything the engine's hot loops touch, not for every commit (CI runs test.sh).
#   bash scripts/sanitize.sh                  AddressSanitizer + UndefinedBehaviorSanitizer (build-asan)
#   SANITIZE=checks bash scripts/sanitize.sh  Debug -O1 with libstdc++'s and Eigen's assertions, and UBSan
#                                             with float-to-int overflow (build-checks)
#   DEMCAL_LONG=1 ...                         also the long physics validations
# Any report stops the test that made it, so a report is a failed test; ctest prints
# its output.
set -euo pipefail
cd "$(dirname "$0")/.."

mode=${SANITIZE:-address}
case "$mode" in
  address)
    dir=build-asan
    type=RelWithDebInfo
    flags="-fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=all"
    ;;
  checks)
    # Not float-divide-by-zero: IEEE division is defined, and a job with a zero
    # density reaches the step forecast as an infinite frequency, which it refuses.
    dir=build-checks
    type=Debug
    flags="-O1 -g -D_GLIBCXX_ASSERTIONS -fsanitize=undefined,float-cast-overflow -fno-sanitize-recover=all"
    ;;
  *)
    echo "sanitize: SANITIZE is '$mode'; it takes address (the default) or checks" >&2
    exit 2
    ;;
esac

# CMake takes CXXFLAGS and LDFLAGS when it first configures a folder: to change the
# flags of an existing one, remove it. The benchmarks are not built: their timings
# mean nothing under the checkers.
export BUILD_DIR=${BUILD_DIR:-$dir} BUILD_TYPE=$type
export CMAKE_ARGS="-DDEMCAL_BUILD_BENCH=OFF ${CMAKE_ARGS:-}"
CXXFLAGS="$flags" LDFLAGS="$flags" BUILD_LOG=${BUILD_LOG:-$BUILD_DIR/build.log} bash scripts/setup.sh

export UBSAN_OPTIONS=print_stacktrace=1
JOBS=${JOBS:-$(nproc)}
args=(--test-dir "$BUILD_DIR" --output-on-failure -j "$JOBS" --timeout 1800)
skip="mpi"
if [ "${DEMCAL_LONG:-0}" != 1 ]; then skip="long|mpi"; fi
status=0
ASAN_OPTIONS=detect_leaks=1 ctest "${args[@]}" -LE "$skip" || status=$?
# OpenMPI's own allocations outlive MPI_Finalize: leak checks off for the MPI farm.
if grep -q '^DEMCAL_MPI:BOOL=ON' "$BUILD_DIR/CMakeCache.txt"; then
  ASAN_OPTIONS=detect_leaks=0 ctest "${args[@]}" -L mpi || status=$?
fi
exit "$status"
