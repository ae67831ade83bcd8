#!/usr/bin/env bash
# Configures and builds lfrecon (Release) into ${BUILD_DIR:-build}: every target, or only
# ${TARGET} (and what it needs) when set, e.g. TARGET=lfrecon (deploy/demo.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR="${BUILD_DIR:-build}"
JOBS="${JOBS:-2}"
cmake -S . -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release "$@"
cmake --build "$BUILD_DIR" -j"$JOBS" ${TARGET:+--target "$TARGET"}
