#!/usr/bin/env bash
# The measurement of `lfrecon poses` (issue 17): a generated loop rendered to a
# video file, posed by COLMAP through `lfrecon poses`, its cameras aligned to
# the true ones (similarity, Umeyama) and, with MESH=1, the mesh from those
# poses against the mesh from the true poses: the SfM-world mesh is mapped by
# the same similarity into the true metric world and scored there by
# `lfrecon eval` (the "scaled evaluation").
#   tests/bench/poses_bench.sh                      # 240 frames 320x180, poses + meshes
#   FRAMES=480 MESH=0 tests/bench/poses_bench.sh    # time for 480 frames
# Env: OUT (/tmp/poses_bench), FRAMES (240), WIDTH/HEIGHT (320/180), STEP (0: automatic), MESH (1),
#      POSES_ARGS (extra lfrecon poses flags), BUILD (build).
set -euo pipefail
cd "$(dirname "$0")/../.."
BUILD=${BUILD:-build}
OUT=${OUT:-/tmp/poses_bench}
FRAMES=${FRAMES:-240}
WIDTH=${WIDTH:-320}
HEIGHT=${HEIGHT:-180}
STEP=${STEP:-0}
MESH=${MESH:-1}
LF=$BUILD/bin/lfrecon
B=$BUILD/bench/sfm_poses_bench
mkdir -p "$OUT"

rm -rf "$OUT/gen"
"$LF" -q synth --out "$OUT/gen" --frames "$FRAMES" --width "$WIDTH" --height "$HEIGHT" --depth-every 8
rm -f "$OUT/loop.mkv" "$OUT/loop.avi"
"$B" video --dataset "$OUT/gen" --out "$OUT/loop" > /dev/null
video="$OUT/loop.mkv"
[ -f "$video" ] || video="$OUT/loop.avi"
rm -rf "$OUT/posed"
start=$(date +%s.%N)
# shellcheck disable=SC2086
"$LF" poses --video "$video" --out "$OUT/posed" --step "$STEP" ${POSES_ARGS:-} 2> "$OUT/poses.log"
end=$(date +%s.%N)
echo "poses: $FRAMES frames ${WIDTH}x${HEIGHT} --step $STEP (0: automatic; the step used is in $OUT/posed/scene.json) in $(echo "$end - $start" | bc) s wall"
"$B" align --estimated "$OUT/posed" --truth "$OUT/gen" --json "$OUT/align.json"

if [ "$MESH" = 1 ]; then
  "$LF" -q run --dataset "$OUT/gen" --out "$OUT/run_true"
  "$LF" -q run --dataset "$OUT/posed" --out "$OUT/run_sfm"
  "$B" align --estimated "$OUT/posed" --truth "$OUT/gen" --mesh "$OUT/run_sfm/mesh.ply" \
      --mesh-out "$OUT/run_sfm/mesh_true_world.ply" > /dev/null
  "$LF" eval --dataset "$OUT/gen" --mesh "$OUT/run_true/mesh.ply" --json > "$OUT/eval_true.json"
  "$LF" eval --dataset "$OUT/gen" --mesh "$OUT/run_sfm/mesh_true_world.ply" --json > "$OUT/eval_sfm.json"
  echo "mesh from the true poses:  $(jq -c '.' "$OUT/eval_true.json" | head -c 600)"
  echo "mesh from lfrecon poses:   $(jq -c '.' "$OUT/eval_sfm.json" | head -c 600)"
fi
