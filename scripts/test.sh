#!/usr/bin/env bash
# Installs what is missing, builds, and runs the whole test suite.
# Long physics validations are labelled "long" and run only with DEMCAL_LONG=1.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
BUILD_DIR=${BUILD_DIR:-build}
JOBS=${JOBS:-$(nproc)}
args=(--test-dir "$BUILD_DIR" --output-on-failure -j "$JOBS" --timeout 900)
if [ "${DEMCAL_LONG:-0}" != 1 ]; then args+=(-LE long); fi
ctest "${args[@]}"
