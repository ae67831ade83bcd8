#!/usr/bin/env bash
# README command 1: install what is missing, build, and run the main job on
# the embedded default: generate a synthetic light field and summarise it.
set -euo pipefail
cd "$(dirname "$0")/.."
./deploy/install_deps.sh
./deploy/build.sh
OUT="${OUT:-out/demo}"
./build/bin/lfrecon synth --out "$OUT/dataset" --frames 120
./build/bin/lfrecon info --dataset "$OUT/dataset"
