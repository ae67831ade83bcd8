#!/usr/bin/env bash
# Throughput of the streaming service against `lfrecon run` on the same data:
#   deploy/bench_service.sh DATASET [VOXEL_MM] [WORKERS...]
# Prints frames/s end to end (submit -> DONE), the F-score of both meshes, and
# the peak RSS (VmHWM) of every daemon. Uses ipc:// endpoints in a temp dir.
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
BIN="${LFRECON_BIN:-$ROOT/build/bin}"
DATA="$1"; VOX="${2:-5}"; shift 2 || true
WORKERS=("$@"); [ ${#WORKERS[@]} -eq 0 ] && WORKERS=(1 2)
TMP="$(mktemp -d /tmp/lfrecon_bench.XXXXXX)"
trap 'deploy_stop; rm -rf "$TMP"' EXIT
deploy_stop() { LFRECON_RUN="$TMP/run" "$ROOT/deploy/stack.sh" stop >/dev/null 2>&1 || true; }
N=$(ls "$DATA/images" | wc -l)
fscore() { "$BIN/lfrecon" eval --dataset "$DATA" --mesh "$1" --json 2>/dev/null | python3 -c "
import json,sys; d=json.load(sys.stdin); print(' '.join('F@%gmm %.4f'%(x['threshold_mm'],x['fscore']) for x in d['scores']))"; }
echo "dataset $DATA ($N frames), voxel $VOX mm, load average $(cut -d' ' -f1-3 /proc/loadavg)"
t0=$(date +%s.%N)
/usr/bin/time -f "%M %U %S" -o "$TMP/run_rss" "$BIN/lfrecon" -q run --dataset "$DATA" --voxel-mm "$VOX" --out "$TMP/embedded" >/dev/null
t1=$(date +%s.%N)
REF=$(python3 -c "
import json; r=json.load(open('$TMP/embedded/report.json'))['seconds']; print(r.get('refine', 0.0))")
# The stack's job ends with the fused mesh (refinement is a separate `lfrecon export --refine`):
# compare with run's time without its refine step.
echo "lfrecon run: $(python3 -c "w=$t1-$t0; r=$REF; print('%.1f s wall, %.1f s refine, %.1f s without refine: %.2f frames/s'%(w, r, w-r, $N/(w-r)))"), peak RSS $(( $(cut -d" " -f1 "$TMP/run_rss") / 1024 )) MiB, CPU $(awk '{printf "%.1f", $2+$3}' "$TMP/run_rss") s (with refine), fused mesh (mesh_raw.ply) $(fscore "$TMP/embedded/mesh_raw.ply")"
for W in "${WORKERS[@]}"; do
  export LFRECON_RUN="$TMP/run" LFRECON_BIN="$BIN"
  export LFRECON_INGEST="ipc://$TMP/ingest.sock" LFRECON_AGGREGATE="ipc://$TMP/aggregate.sock"
  rm -rf "$TMP/run"
  "$ROOT/deploy/stack.sh" start -n "$W" >/dev/null
  t0=$(date +%s.%N)
  JOB=$("$BIN/lfrecon" -q submit --dataset "$DATA" --voxel-mm "$VOX")
  "$BIN/lfrecon" -q status "$JOB" --wait >/dev/null
  t1=$(date +%s.%N)
  "$BIN/lfrecon" -q export "$JOB" -o "$TMP/stack_$W.ply" >/dev/null
  rss=""; cpu=0
  TCK=$(getconf CLK_TCK)
  for f in "$TMP"/run/pids/*.pid; do
    p=$(cat "$f")
    rss="$rss $(basename "$f" .pid)=$(( $(awk '/VmHWM/{print $2}' /proc/$p/status) / 1024 ))MiB"
    cpu=$(( cpu + $(awk '{print $14 + $15}' /proc/$p/stat) ))
  done
  echo "stack, $W worker(s) per stage: $(python3 -c "print('%.1f s, %.2f frames/s'%($t1-$t0, $N/($t1-$t0)))"), $(fscore "$TMP/stack_$W.ply")"
  echo "  peak RSS:$rss; CPU of all daemons $(python3 -c "print('%.1f' % ($cpu / $TCK))") s"
  "$ROOT/deploy/stack.sh" stop >/dev/null
done
