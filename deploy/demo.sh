#!/usr/bin/env bash
# README command 1: install what is missing, build, and run the main job on
# the embedded default: generate a dense synthetic light field (240 frames,
# 320x180, one loop), reconstruct it with `lfrecon run` (depth, filtering,
# densification, fusion, refinement) and score the mesh against the
# generator's ground truth.
set -euo pipefail
cd "$(dirname "$0")/.."
./deploy/install_deps.sh
# Only the lfrecon executable and the libraries it links: the tests and benchmarks
# are built by deploy/test.sh.
TARGET=lfrecon ./deploy/build.sh
OUT="${OUT:-out/demo}"
./build/bin/lfrecon synth --out "$OUT/dataset" --frames 240 --width 320 --height 180
./build/bin/lfrecon info --dataset "$OUT/dataset"
./build/bin/lfrecon run --dataset "$OUT/dataset" --out "$OUT/run"
./build/bin/lfrecon eval --dataset "$OUT/dataset" --mesh "$OUT/run/mesh.ply"
echo "demo: mesh, fused mesh, grid, report and turntable render in $OUT/run"
