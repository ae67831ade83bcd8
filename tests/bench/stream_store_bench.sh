#!/bin/sh
# Job store bytes per frame and frames/s pushed by `lfrecon stream` (issue 14 §1):
# an aggregator and an ingest daemon (no workers: only storing is measured) on
# ipc:// sockets in a temporary folder; each input is submitted (ingest reads
# the paths) and streamed (the client pushes the frames), and the frames'
# bytes in the store are counted.
#   tests/bench/stream_store_bench.sh OUT INPUT...
# INPUT: a dataset folder, or VIDEO:POSES (a video file and its COLMAP model).
set -eu
BIN=${BIN:-$(dirname "$0")/../../build/bin}
OUT=$1; shift
mkdir -p "$OUT"; chmod 700 "$OUT"
AGG="ipc://$OUT/agg.sock"; ING="ipc://$OUT/ing.sock"
"$BIN/lfrecon-aggregate" --bind "$AGG" --store "$OUT/store" >"$OUT/agg.log" 2>&1 & A=$!
"$BIN/lfrecon-ingest" --bind "$ING" --aggregate "$AGG" --store "$OUT/store" >"$OUT/ing.log" 2>&1 & I=$!
trap 'kill $A $I 2>/dev/null' EXIT
sleep 1
frames_bytes() { find "$OUT/store/$1/frames" -name '*.pb' -printf '%s\n' | awk '{s+=$1; n++} END {printf "%d frames, %.0f bytes a frame", n, s/n}'; }
for input in "$@"; do
  case "$input" in
    *:*) src="--video ${input%%:*} --colmap ${input#*:}";;
    *) src="--dataset $input";;
  esac
  job=$("$BIN/lfrecon" -q submit --ingest "$ING" $src)
  while [ ! -f "$OUT/store/$job/ingest.done" ]; do sleep 0.5; done
  echo "$input submit: $(frames_bytes "$job")"
  job=$("$BIN/lfrecon" -q stream --ingest "$ING" --aggregate "$AGG" $src --stats "$OUT/stats.json")
  echo "$input stream: $(frames_bytes "$job"); $(tr -d '\n ' < "$OUT/stats.json")"
done
