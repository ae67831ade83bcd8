#!/bin/sh
# The growing plan under a live camera (issue 14 §1): `lfrecon stream` paced at
# RATE frames/s with --max-frame-gap GAP to a stack of an aggregator, an ingest
# daemon and one depth and one propagate worker (ipc:// in OUT), then `lfrecon
# run` on the same frames with the same gap. Prints frames/s pushed and fused,
# the latency from a frame's arrival in the store to its view being fused
# (fused.log, polled every 0.2 s), views fused before the end of the stream,
# store bytes a frame, peak RSS and CPU-s of every daemon, and wall / CPU-s
# against `lfrecon run`, whose mesh_raw.ply is compared with the job's.
#   tests/bench/stream_latency_bench.sh OUT DATASET GAP RATE [VOXEL_MM]
# WAIT_S: give up waiting for DONE after this long (the figures are then of the
# views fused so far); RUN_TIMEOUT_S: the same for lfrecon run (0: none).
set -eu
BIN=${BIN:-$(dirname "$0")/../../build/bin}
OUT=$1; DATA=$2; GAP=$3; RATE=$4; VOX=${5:-0}
mkdir -p "$OUT"; chmod 700 "$OUT"; rm -rf "$OUT/store" "$OUT/run"
AGG="ipc://$OUT/agg.sock"; ING="ipc://$OUT/ing.sock"; ST="$OUT/store"
"$BIN/lfrecon-aggregate" --bind "$AGG" --store "$ST" >"$OUT/agg.log" 2>&1 & A=$!
"$BIN/lfrecon-ingest" --bind "$ING" --aggregate "$AGG" --store "$ST" >"$OUT/ing.log" 2>&1 & I=$!
"$BIN/lfrecon-depth" --aggregate "$AGG" --store "$ST" >"$OUT/depth.log" 2>&1 & D=$!
"$BIN/lfrecon-propagate" --aggregate "$AGG" --store "$ST" >"$OUT/prop.log" 2>&1 & P=$!
POLL=""
trap 'kill $A $I $D $P $POLL 2>/dev/null || true' EXIT
sleep 1
VOXFLAG=""; [ "$VOX" != 0 ] && VOXFLAG="--voxel-mm $VOX"
# Each view's fusion time: fused.log's new lines, stamped when seen.
( while :; do
    for f in "$ST"/*/fused.log; do
      [ -f "$f" ] || continue
      n=$(wc -l < "$f"); seen=$(cat "$OUT/fused.seen" 2>/dev/null || echo 0)
      if [ "$n" -gt "$seen" ]; then
        now=$(date +%s.%N)
        tail -n +"$((seen + 1))" "$f" | head -n "$((n - seen))" | sed "s/\$/ $now/" >> "$OUT/fused.times"
        echo "$n" > "$OUT/fused.seen"
      fi
    done
    sleep 0.2
  done ) & POLL=$!
t0=$(date +%s.%N)
"$BIN/lfrecon" -q stream --ingest "$ING" --aggregate "$AGG" --dataset "$DATA" --max-frame-gap "$GAP" --rate "$RATE" \
  $VOXFLAG --stats "$OUT/stats.json" --wait --wait-s "${WAIT_S:-3600}" > "$OUT/stream.out" || echo "stream: not DONE"
t1=$(date +%s.%N)
JOB=$(head -n 1 "$OUT/stream.out")
sleep 0.5
TCK=$(getconf CLK_TCK)
for p in agg:$A ingest:$I depth:$D propagate:$P; do
  pid=${p#*:}
  echo "${p%%:*} $(awk '/VmHWM/{print $2}' /proc/$pid/status) $(awk -v t="$TCK" '{print ($14 + $15) / t}' /proc/$pid/stat)"
done > "$OUT/daemons.txt"
kill $POLL 2>/dev/null || true
timeout "${RUN_TIMEOUT_S:-0}" /usr/bin/time -f "%e %M %U %S" -o "$OUT/run.time" "$BIN/lfrecon" -q run --dataset "$DATA" --no-refine-poses \
  --no-refine --max-frame-gap "$GAP" $VOXFLAG --out "$OUT/run" > /dev/null || echo "lfrecon run: did not finish"
python3 - "$OUT" "$ST/$JOB" "$t0" "$t1" "$RATE" <<'EOF'
import json, os, statistics, sys
out, job, t0, t1 = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4])
st = json.load(open(os.path.join(out, "stats.json")))
n = st["frames"]
arrive = {int(f[:-3]): os.stat(os.path.join(job, "frames", f)).st_mtime
          for f in os.listdir(os.path.join(job, "frames")) if f.endswith(".pb")}
fused = {}
times = os.path.join(out, "fused.times")
for line in open(times) if os.path.exists(times) else []:
    v, t = line.split()
    fused.setdefault(int(v), float(t))
lat = sorted(fused[v] - arrive[v] for v in fused) or [float("nan")]
end_of_stream = max(arrive.values())
before_end = sum(1 for v in fused if fused[v] < end_of_stream)
q = lambda p: lat[min(len(lat) - 1, int(p * len(lat)))]
print("stream: %d frames pushed in %.1f s (%.2f frames/s, rate %s), %.0f bytes a frame stored (%.2f B/px)" % (
    n, st["seconds"], st["frames_per_second"], sys.argv[5], st["bytes_stored"] / n,
    st["bytes_per_pixel"]))
print("fused: %d views, %d before the end of the stream; first frame to DONE %.1f s (%.2f views/s fused), "
      "last frame pushed to DONE %.1f s" % (len(fused), before_end, t1 - t0, len(fused) / (t1 - t0),
                                            t1 - t0 - st["seconds"]))
print("latency from a frame's arrival to its view fused: median %.1f s, 90%% %.1f s, max %.1f s, min %.1f s" % (
    statistics.median(lat), q(0.9), lat[-1], lat[0]))
cpu = 0
for line in open(os.path.join(out, "daemons.txt")):
    name, hwm, c = line.split()
    cpu += float(c)
    print("  %s: peak RSS %d MiB, %.1f CPU-s" % (name, int(hwm) // 1024, float(c)))
run_time = open(os.path.join(out, "run.time")).read().split() if os.path.exists(os.path.join(out, "run.time")) else []
if len(run_time) != 4 or not os.path.exists(os.path.join(job, "mesh_raw.ply")):
    print("service: %.1f CPU-s (all daemons); no comparison with lfrecon run (one of them did not finish)" % cpu)
    sys.exit(0)
e, m, u, s = run_time
print("lfrecon run: %.1f s wall, %.1f CPU-s, peak RSS %d MiB; service: %.1f s wall (first frame to DONE), %.1f CPU-s "
      "(all daemons): wall %+.0f %%, CPU %+.0f %%" % (float(e), float(u) + float(s), int(m) // 1024, t1 - t0, cpu,
      100 * ((t1 - t0) / float(e) - 1), 100 * (cpu / (float(u) + float(s)) - 1)))
a, b = open(os.path.join(out, "run", "mesh_raw.ply"), "rb").read(), open(os.path.join(job, "mesh_raw.ply"), "rb").read()
print("mesh_raw.ply: %s" % ("byte-identical to lfrecon run's" if a == b else "differs from lfrecon run's"))
EOF
