#!/usr/bin/env bash
# Configures and builds lfrecon (Release) into ${BUILD_DIR:-build}: every target, or only
# ${TARGET} (and what it needs) when set, e.g. TARGET=lfrecon (deploy/demo.sh).
# A unity build (CMAKE_UNITY_BUILD: each library's sources compiled a few per
# translation unit, so the OpenCV/Eigen/OpenVDB headers are parsed once per
# batch) by default: a clean build is what CI and a new user run.
# LFRECON_UNITY=OFF for a development tree that rebuilds one file at a time.
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR="${BUILD_DIR:-build}"
JOBS="${JOBS:-2}"
cmake -S . -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release "-DCMAKE_UNITY_BUILD=${LFRECON_UNITY:-ON}" "$@"
cmake --build "$BUILD_DIR" -j"$JOBS" ${TARGET:+--target "$TARGET"}
