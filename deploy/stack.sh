#!/usr/bin/env bash
# One-command local stack of the lfrecon streaming service:
#   deploy/stack.sh start [-n WORKERS] [--store DIR] [--bin DIR]   # ingest, aggregate, N depth + N propagate workers
#   deploy/stack.sh status                                         # which daemons run
#   deploy/stack.sh stop                                           # SIGTERM, then SIGKILL after 10 s
#   eval "$(deploy/stack.sh env)"                                  # the client's key variables
# Then: build/bin/lfrecon submit --dataset DIR   (prints a job id)
#       build/bin/lfrecon status JOB --wait ; build/bin/lfrecon export JOB -o mesh.ply
# Endpoints: $LFRECON_INGEST (default tcp://127.0.0.1:5550) and $LFRECON_AGGREGATE
# (default tcp://127.0.0.1:5551): loopback only unless you say otherwise.
# TCP is CURVE-authenticated and encrypted: the first start makes keys/ (lfrecon keygen:
# the daemons', a worker key, a client key) and each daemon's allow-list; ipc:// endpoints
# need no keys (their folder must be private, mode 0700).
# State lives in $LFRECON_RUN (default out/stack): pids/, logs/, store/ (the job store), keys/.
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
RUN="${LFRECON_RUN:-$ROOT/out/stack}"
BIN="${LFRECON_BIN:-$ROOT/build/bin}"
STORE="$RUN/store"
KEYS="$RUN/keys"
WORKERS=1
export LFRECON_INGEST="${LFRECON_INGEST:-tcp://127.0.0.1:5550}"
export LFRECON_AGGREGATE="${LFRECON_AGGREGATE:-tcp://127.0.0.1:5551}"

cmd="${1:-}"; shift || true
while [ $# -gt 0 ]; do
  case "$1" in
    -n|--workers) WORKERS="$2"; shift 2 ;;
    --store) STORE="$2"; shift 2 ;;
    --bin) BIN="$2"; shift 2 ;;
    *) echo "stack.sh: unknown argument $1" >&2; exit 2 ;;
  esac
done

running() { [ -f "$1" ] && kill -0 "$(cat "$1")" 2>/dev/null; }

launch() {  # name, args...
  local name="$1"; shift
  local pidf="$RUN/pids/$name.pid"
  if running "$pidf"; then echo "stack: $name already running (pid $(cat "$pidf"))"; return; fi
  "$@" >>"$RUN/logs/$name.log" 2>&1 &
  echo $! >"$pidf"
  echo "stack: $name pid $! (log $RUN/logs/$name.log)"
}

tcp() { case "$1" in ipc://*|inproc://*) return 1 ;; *) return 0 ;; esac; }

# Keys (once): the daemons' own, one for the workers, one for the client; allow-lists.
make_keys() {
  [ -f "$KEYS/aggregate.allow" ] && return
  mkdir -p "$KEYS"; chmod 700 "$KEYS"
  "$BIN/lfrecon" -q keygen aggregate --role server -o "$KEYS" >/dev/null
  "$BIN/lfrecon" -q keygen ingest --role ingest -o "$KEYS" >/dev/null
  "$BIN/lfrecon" -q keygen worker --role worker -o "$KEYS" >/dev/null
  "$BIN/lfrecon" -q keygen client --role client -o "$KEYS" >/dev/null
  cat "$KEYS/ingest.pub" "$KEYS/worker.pub" "$KEYS/client.pub" >"$KEYS/aggregate.allow"
  cat "$KEYS/client.pub" >"$KEYS/ingest.allow"
  echo "stack: keys and allow-lists in $KEYS"
}

case "$cmd" in
  start)
    for b in lfrecon lfrecon-aggregate lfrecon-ingest lfrecon-depth lfrecon-propagate; do
      [ -x "$BIN/$b" ] || { echo "stack: $BIN/$b missing; run deploy/build.sh first" >&2; exit 1; }
    done
    mkdir -p "$RUN/pids" "$RUN/logs" "$STORE"
    agg_sec=(); ing_sec=(); wrk_sec=()
    if tcp "$LFRECON_AGGREGATE" || tcp "$LFRECON_INGEST"; then
      make_keys
      tcp "$LFRECON_AGGREGATE" && agg_sec=(--key "$KEYS/aggregate.key" --allow "$KEYS/aggregate.allow") \
        && ing_sec=(--aggregate-key "$KEYS/aggregate.pub") \
        && wrk_sec=(--key "$KEYS/worker.key" --aggregate-key "$KEYS/aggregate.pub")
      tcp "$LFRECON_INGEST" && ing_sec+=(--allow "$KEYS/ingest.allow")
      [ ${#ing_sec[@]} -gt 0 ] && ing_sec+=(--key "$KEYS/ingest.key")
    fi
    for ep in "$LFRECON_AGGREGATE" "$LFRECON_INGEST"; do
      case "$ep" in ipc://*) d="$(dirname "${ep#ipc://}")"; mkdir -p "$d"; chmod 700 "$d" ;; esac
    done
    launch aggregate "$BIN/lfrecon-aggregate" --bind "$LFRECON_AGGREGATE" --store "$STORE" "${agg_sec[@]}"
    launch ingest "$BIN/lfrecon-ingest" --bind "$LFRECON_INGEST" --aggregate "$LFRECON_AGGREGATE" --store "$STORE" \
      "${ing_sec[@]}"
    for i in $(seq 1 "$WORKERS"); do
      launch "depth-$i" "$BIN/lfrecon-depth" --aggregate "$LFRECON_AGGREGATE" --store "$STORE" "${wrk_sec[@]}"
      launch "propagate-$i" "$BIN/lfrecon-propagate" --aggregate "$LFRECON_AGGREGATE" --store "$STORE" "${wrk_sec[@]}"
    done
    sleep 0.5
    for f in "$RUN"/pids/*.pid; do
      running "$f" || { echo "stack: $(basename "$f" .pid) exited at once; see its log" >&2; exit 1; }
    done
    echo "stack: up (ingest $LFRECON_INGEST, aggregate $LFRECON_AGGREGATE, $WORKERS worker(s) per stage, store $STORE)"
    if [ -f "$KEYS/client.key" ]; then echo "stack: client keys: eval \"\$($0 env)\""; fi
    ;;
  env)
    echo "export LFRECON_INGEST='$LFRECON_INGEST' LFRECON_AGGREGATE='$LFRECON_AGGREGATE'"
    if [ -f "$KEYS/client.key" ]; then echo "export LFRECON_KEY='$KEYS/client.key' LFRECON_INGEST_KEY='$KEYS/ingest.pub' LFRECON_AGGREGATE_KEY='$KEYS/aggregate.pub'"; fi
    ;;
  status)
    shopt -s nullglob
    for f in "$RUN"/pids/*.pid; do
      n=$(basename "$f" .pid)
      if running "$f"; then echo "$n: running (pid $(cat "$f"))"; else echo "$n: stopped"; fi
    done
    ;;
  stop)
    shopt -s nullglob
    pids=()
    for f in "$RUN"/pids/*.pid; do running "$f" && { kill -TERM "$(cat "$f")"; pids+=("$f"); }; done
    for _ in $(seq 1 100); do
      left=0
      for f in "${pids[@]}"; do running "$f" && left=1; done
      [ $left -eq 0 ] && break
      sleep 0.1
    done
    for f in "${pids[@]}"; do running "$f" && { echo "stack: $(basename "$f" .pid) did not stop; SIGKILL"; kill -KILL "$(cat "$f")"; }; done
    rm -f "$RUN"/pids/*.pid
    echo "stack: stopped"
    ;;
  *)
    sed -n '2,15p' "$0"; exit 2 ;;
esac
