#!/usr/bin/env bash
# The aggregator's threads under ThreadSanitizer (not part of CI: a third build).
#   deploy/tsan_aggregate.sh [DATASET]
# Builds lfrecon-aggregate with -fsanitize=thread in ${TSAN_BUILD_DIR:-build-tsan}
# (only it and its libraries; the other daemons are build/'s), runs it in a
# stack over ipc:// with 2 workers per stage and slow fusion, and drives every
# thread it has: the serving thread, each job's fusion thread, the plain and the
# refined export lanes: status polls and mid-stream exports (plain and --refine)
# while views fuse, a second job cancelled mid-fusion, a finished job's refined
# export, SIGTERM with maps queued. Fails if ThreadSanitizer reported anything
# (its reports: $TMP/tsan.*).
# Run 2026-12-03 at 5510138 (aggregator from a clean export of that commit; the
# other daemons from build/): no report; configure + build 10 min, run 38 s, 2 shared cores.
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
cd "$ROOT"
BUILD="${TSAN_BUILD_DIR:-build-tsan}"
cmake -S . -B "$BUILD" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DLFRECON_BUILD_TESTS=OFF \
  "-DCMAKE_CXX_FLAGS=-fsanitize=thread -fno-omit-frame-pointer" >"$BUILD.configure.log" 2>&1 \
  || { cat "$BUILD.configure.log"; exit 1; }
cmake --build "$BUILD" -j"${JOBS:-2}" --target lfrecon-aggregate
BIN="$ROOT/build/bin"
TMP="$(mktemp -d /tmp/lfrecon_tsan.XXXXXX)"
DATA="${1:-}"
if [ -z "$DATA" ]; then
  DATA="$TMP/dataset"
  "$BIN/lfrecon" -q synth --scene sphere --frames 90 --width 96 --height 54 --out "$DATA" >/dev/null
fi
AGG="ipc://$TMP/agg.sock"; ING="ipc://$TMP/ing.sock"; STORE="$TMP/store"
mkdir -p "$STORE"
pids=()
cleanup() { for p in "${pids[@]}"; do kill -KILL "$p" 2>/dev/null || true; done; }
trap cleanup EXIT
# Only our own threads are checked. The libraries' runtimes are not built with
# -fsanitize=thread, so ThreadSanitizer cannot see their synchronisation and
# reports their hand-offs as races (the first run, on 2 CPUs: 813 reports, every
# one with libtbb, libzmq or libgdal in it, none between two of our threads):
# - TBB (OpenVDB's and the fusion's parallel loops): run on one CPU (taskset),
#   TBB's arena has no worker thread and each loop runs on the thread that
#   calls it; the serving thread, the fusion threads and the export lanes still
#   run concurrently (preempted), and ThreadSanitizer's happens-before check
#   does not depend on timing.
# - ZeroMQ's I/O thread: its allocations and copies of message buffers are not
#   tracked (called_from_lib).
# - GDAL (behind OpenCV's imdecode): a lock order inside GDAL's own mutexes.
printf 'called_from_lib:libzmq.so.5\ndeadlock:libgdal.so\n' >"$TMP/suppressions.txt"
TSAN_OPTIONS="halt_on_error=0 second_deadlock_stack=1 log_path=$TMP/tsan suppressions=$TMP/suppressions.txt" \
  taskset -c 0 "$BUILD/bin/lfrecon-aggregate" --bind "$AGG" --store "$STORE" --fusion-delay-ms 150 \
  >"$TMP/aggregate.log" 2>&1 &
agg=$!; pids+=("$agg")
"$BIN/lfrecon-ingest" --bind "$ING" --aggregate "$AGG" --store "$STORE" >"$TMP/ingest.log" 2>&1 & pids+=($!)
for i in 1 2; do
  "$BIN/lfrecon-depth" --aggregate "$AGG" --store "$STORE" >"$TMP/depth$i.log" 2>&1 & pids+=($!)
  "$BIN/lfrecon-propagate" --aggregate "$AGG" --store "$STORE" >"$TMP/propagate$i.log" 2>&1 & pids+=($!)
done
L="$BIN/lfrecon -q"
A=(--aggregate "$AGG" --timeout-ms 120000)
job=$($L submit --ingest "$ING" --dataset "$DATA" --voxel-mm 8)
job2=$($L submit --ingest "$ING" --dataset "$DATA" --voxel-mm 8)
for i in $(seq 1 20); do $L status "$job" "${A[@]}" >/dev/null; sleep 0.2; done
$L export "$job" "${A[@]}" -o "$TMP/mid.ply" >/dev/null &
e1=$!
$L export "$job" --refine "${A[@]}" -o "$TMP/mid_refined.ply" >/dev/null &
e2=$!
$L export "$job2" "${A[@]}" -o "$TMP/mid2.ply" >/dev/null
$L cancel "$job2" "${A[@]}" >/dev/null
wait $e1 $e2
$L status "$job" --wait --wait-s 600 "${A[@]}"
$L export "$job" --refine "${A[@]}" -o "$TMP/refined.ply" >/dev/null
$L export "$job" "${A[@]}" -o "$TMP/final.ply" >/dev/null
job3=$($L submit --ingest "$ING" --dataset "$DATA" --voxel-mm 8)
sleep 3
kill -TERM "$agg"; wait "$agg" || { echo "tsan: aggregator exit status $?" >&2; }
if ls "$TMP"/tsan.* >/dev/null 2>&1; then
  echo "tsan: ThreadSanitizer reports in $TMP:" >&2
  grep -h "WARNING: ThreadSanitizer" "$TMP"/tsan.* | sort | uniq -c >&2
  trap - EXIT; cleanup; exit 1
fi
echo "tsan: no ThreadSanitizer report (jobs $job done, $job2 cancelled, $job3 stopped mid-run); logs in $TMP"
