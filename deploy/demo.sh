#!/usr/bin/env bash
# README command 1: install what is missing, build, and run the main job on
# the embedded default: generate a dense synthetic light field (480 frames, one
# loop), summarise it, estimate sparse depth (§3.1) for a few views and
# measure it against the generator's exact depth.
set -euo pipefail
cd "$(dirname "$0")/.."
./deploy/install_deps.sh
./deploy/build.sh
OUT="${OUT:-out/demo}"
./build/bin/lfrecon synth --out "$OUT/dataset" --frames 480
./build/bin/lfrecon info --dataset "$OUT/dataset"
./build/bin/lfrecon depth --dataset "$OUT/dataset" --out "$OUT/depth" --views 240:288:8 --stage sparse
./build/bin/lfrecon eval-depth --dataset "$OUT/dataset" --depth "$OUT/depth/depth"
