#!/usr/bin/env bash
# The quality table of issue 13 / BRIEF §4: runs `lfrecon run` over a fixed
# list of sets and prints one markdown table (precision / observed recall /
# observed F at 2, 5 and 10 mm, observed thin recall at 5 mm, unmasked F at
# 5 mm, median distances, wall time, peak RSS). Not run by ctest: the
# figurines take minutes each.
#
#   tests/bench/quality_table.sh [--sets a,b,c] [--out DIR] [--cache DIR] [--lfrecon BIN]
#                                [--table-only] [--list] [-- extra lfrecon run args, e.g. --voxel-mm 2]
#
# Sets (default: all, in this order):
#   tabletop           lfrecon synth tabletop, 240 frames 320x180 (like deploy/demo.sh), clean
#   tabletop-degraded  the same as a hand-held capture: DEGRADED below
#   thin-degraded      thin_cylinder (a 1.8 mm textureless rod before a textured background), 240 frames
#                      320x180 (the rod ~1.3 px wide), DEGRADED
#   occlusion-degraded occlusion (objects occluding one another), 240 frames 320x180, DEGRADED
#   figurines          ../shared/data/figurines (480 frames 640x360, Blender)
#   figurines-noisy    ../shared/data/figurines-noisy (the same, noise + JPEG + exposure + pose error)
# DEGRADED = --noise 0.01 --format jpg --jpeg-quality 80 --exposure-drift 0.04 --pose-rot-deg 0.02
#            --pose-trans-mm 0.5 (the figurines-noisy recipe, BRIEF §3).
#
# --table-only makes the table from the sets' JSONs already in OUT without
# running anything (e.g. after running sets in several invocations).
# Writes OUT/table.md (also printed), OUT/<set>.json (the eval JSON with the
# run's wall time, peak RSS and command), OUT/runs/<set>/ (lfrecon run output
# and logs). Generated datasets are cached in CACHE (default OUT/datasets) and
# made again only when their synth command changes (delete CACHE after
# changing the generator). Recall, F and thin recall are on the observed
# ground truth (lfrecon eval's observation mask; marked "(all)" when a set has
# no ground-truth depth maps); F@5 all = unmasked. acc / comp = median
# distance reconstruction -> truth and observed truth -> reconstruction,
# capped at 10 mm. Wall time, CPU time (user + system: wall time depends on
# what else the machine runs) and peak RSS of `lfrecon run` from /usr/bin/time
# -v (wall and RSS from report.json when /usr/bin/time is missing). Needs jq.
set -euo pipefail

ROOT="$(cd "$(dirname "$0")/../.." && pwd)"
DATA="${LFRECON_DATA:-$ROOT/../shared/data}"
ALL_SETS="tabletop,tabletop-degraded,thin-degraded,occlusion-degraded,figurines,figurines-noisy"
SETS="$ALL_SETS"
OUT="$ROOT/out/quality"
CACHE=""
LFRECON="$ROOT/build/bin/lfrecon"
RUN_ARGS=()
TABLE_ONLY=0

usage() { sed -n '2,/^set -euo/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//'; }

while [[ $# -gt 0 ]]; do
  case "$1" in
    --sets) SETS="$2"; shift 2 ;;
    --out) OUT="$2"; shift 2 ;;
    --cache) CACHE="$2"; shift 2 ;;
    --lfrecon) LFRECON="$2"; shift 2 ;;
    --table-only) TABLE_ONLY=1; shift ;;
    --list) tr ',' '\n' <<<"$ALL_SETS"; exit 0 ;;
    -h|--help) usage; exit 0 ;;
    --) shift; RUN_ARGS=("$@"); break ;;
    *) echo "quality_table: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
CACHE="${CACHE:-$OUT/datasets}"

command -v jq >/dev/null || { echo "quality_table: needs jq (apt-get install jq)" >&2; exit 2; }
[[ -x "$LFRECON" ]] || { echo "quality_table: no lfrecon binary at $LFRECON (build the lfrecon target)" >&2; exit 2; }

DEGRADED="--noise 0.01 --format jpg --jpeg-quality 80 --exposure-drift 0.04 --pose-rot-deg 0.02 --pose-trans-mm 0.5"
SMALL="--frames 240 --width 320 --height 180"

# synth arguments of a generated set; empty for a set on disk.
synth_args() {
  case "$1" in
    tabletop) echo "--scene tabletop $SMALL" ;;
    tabletop-degraded) echo "--scene tabletop $SMALL $DEGRADED" ;;
    thin-degraded) echo "--scene thin_cylinder $SMALL $DEGRADED" ;;
    occlusion-degraded) echo "--scene occlusion $SMALL $DEGRADED" ;;
    figurines|figurines-noisy) echo "" ;;
    *) return 1 ;;
  esac
}

IFS=',' read -r -a SET_LIST <<<"$SETS"
for s in "${SET_LIST[@]}"; do
  synth_args "$s" >/dev/null || { echo "quality_table: unknown set '$s' (sets: $ALL_SETS)" >&2; exit 2; }
done
mkdir -p "$OUT/runs" "$CACHE"

# The dataset folder of a set, generated into the cache when needed.
dataset_of() {
  local set="$1" args
  args="$(synth_args "$set")"
  if [[ -z "$args" ]]; then
    [[ -d "$DATA/$set" ]] || { echo "quality_table: $DATA/$set is missing" >&2; return 1; }
    echo "$DATA/$set"
    return
  fi
  local ds="$CACHE/$set" stamp="$CACHE/$set.synth"
  if [[ ! -f "$stamp" || "$(cat "$stamp")" != "$args" || ! -f "$ds/gt_mesh.ply" ]]; then
    rm -rf "$ds" "$stamp"
    echo "quality_table: generating $set: lfrecon synth $args" >&2
    # shellcheck disable=SC2086  # args is a word list
    "$LFRECON" synth --out "$ds" $args >"$CACHE/$set.synth.log" 2>&1 ||
      { echo "quality_table: lfrecon synth failed for $set (see $CACHE/$set.synth.log)" >&2; return 1; }
    echo "$args" >"$stamp"
  fi
  echo "$ds"
}

# Wall seconds from /usr/bin/time -v's "Elapsed (wall clock) time (h:mm:ss or m:ss): M:SS.ss".
wall_seconds() {
  sed -n 's/.*Elapsed (wall clock) time (h:mm:ss or m:ss): //p' "$1" | awk -F: '{ s = 0; for (i = 1; i <= NF; ++i) s = s * 60 + $i; print s }'
}

FAILED=()
for set in "${SET_LIST[@]}"; do
  [[ $TABLE_ONLY -eq 1 ]] && break
  ds="$(dataset_of "$set")" || { FAILED+=("$set"); continue; }
  run_dir="$OUT/runs/$set"
  rm -rf "$run_dir"
  mkdir -p "$run_dir"
  cmd=("$LFRECON" run --dataset "$ds" --out "$run_dir" "${RUN_ARGS[@]}")
  echo "quality_table: $set: ${cmd[*]}" >&2
  start=$SECONDS
  rc=0
  if [[ -x /usr/bin/time ]]; then
    /usr/bin/time -v -o "$run_dir/time.txt" "${cmd[@]}" >"$run_dir/run.log" 2>&1 || rc=$?
  else
    "${cmd[@]}" >"$run_dir/run.log" 2>&1 || rc=$?
  fi
  if [[ "$rc" -ne 0 || ! -f "$run_dir/mesh.ply" ]]; then
    echo "quality_table: $set: lfrecon run failed (exit $rc; see $run_dir/run.log)" >&2
    FAILED+=("$set")
    continue
  fi
  if [[ -f "$run_dir/time.txt" ]]; then
    wall="$(wall_seconds "$run_dir/time.txt")"
    rss_mib="$(awk -F': ' '/Maximum resident set size/ { printf "%.0f", $2 / 1024 }' "$run_dir/time.txt")"
    cpu="$(awk -F': ' '/User time|System time/ { s += $2 } END { printf "%.1f", s }' "$run_dir/time.txt")"
    source="time -v"
  else
    wall=$((SECONDS - start))
    rss_mib="$(jq '.peak_rss_bytes / 1048576 | round' "$run_dir/report.json")"
    cpu=null
    source="report.json"
  fi
  "$LFRECON" eval --dataset "$ds" --mesh "$run_dir/mesh.ply" --json >"$run_dir/eval.json" 2>"$run_dir/eval.log" ||
    { echo "quality_table: $set: lfrecon eval failed (see $run_dir/eval.log)" >&2; FAILED+=("$set"); continue; }
  jq --arg set "$set" --arg dataset "$ds" --arg synth "$(synth_args "$set")" --arg cmd "${cmd[*]}" \
     --argjson wall "$wall" --argjson cpu "$cpu" --argjson rss "$rss_mib" --arg source "$source" \
     --arg extra "${RUN_ARGS[*]}" --arg commit "$(git -C "$ROOT" rev-parse --short HEAD 2>/dev/null || echo '?')" \
     --slurpfile report "$run_dir/report.json" \
     '{set: $set, dataset: $dataset, synth_args: (if $synth == "" then null else $synth end), run_command: $cmd,
       run_extra_args: $extra, commit: $commit,
       wall_s: $wall, cpu_s: $cpu, peak_rss_mib: $rss, time_source: $source,
       run_seconds: $report[0].seconds, views: $report[0].views, eval: .}' \
     "$run_dir/eval.json" >"$OUT/$set.json"
done

# One row per set that has a JSON (this run's, in the order asked).
{
  echo "| set | P@2 | R@2 | F@2 | P@5 | R@5 | F@5 | P@10 | R@10 | F@10 | thin R@5 | F@5 all | acc (mm) | comp (mm) | wall (s) | CPU (s) | peak RSS (MiB) |"
  echo "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
  for set in "${SET_LIST[@]}"; do
    [[ -f "$OUT/$set.json" ]] || continue
    # Tab-separated figures (null: "-"), formatted by awk.
    jq -r '
      .eval as $e
      | ($e.observed_share != null) as $obs
      | def at(t): ($e.scores[] | select(.threshold_mm == t));
        def rec(t): (if $obs then at(t).recall_observed else at(t).recall end);
        def fs(t): (if $obs then at(t).fscore_observed else at(t).fscore end);
        [.set + (if $obs then "" else " (all)" end),
         at(2).precision, rec(2), fs(2), at(5).precision, rec(5), fs(5), at(10).precision, rec(10), fs(10),
         (if $obs then at(5).thin_recall_observed else at(5).thin_recall end), at(5).fscore,
         $e.median_accuracy_mm, (if $obs then $e.median_completeness_observed_mm else $e.median_completeness_mm end),
         .wall_s, .cpu_s, .peak_rss_mib]
      | map(if . == null then "-" else tostring end) | @tsv' "$OUT/$set.json" |
      awk -F'\t' '{
        printf "| %s |", $1
        for (i = 2; i <= 12; ++i) printf " %s |", ($i == "-" ? "-" : sprintf("%.3f", $i))
        for (i = 13; i <= 14; ++i) printf " %s |", ($i == "-" ? "-" : sprintf("%.2f", $i))
        printf " %.0f | %s | %.0f |\n", $15, ($16 == "-" ? "-" : sprintf("%.0f", $16)), $17
      }'
  done
  echo
  echo "R, F and thin R on the observed ground truth (\"(all)\": no ground-truth depth maps, all of it); F@5 all: unmasked;"
  echo "acc / comp: median distance reconstruction -> truth / observed truth -> reconstruction, capped at 10 mm."
  for set in "${SET_LIST[@]}"; do
    [[ -f "$OUT/$set.json" ]] || continue
    jq -r '"- \(.set): \(if .synth_args then "lfrecon synth " + .synth_args else .dataset end); lfrecon run \(if (.run_extra_args // "") == "" then "(defaults)" else .run_extra_args end), tree at \(.commit // "?")"' "$OUT/$set.json"
  done
} >"$OUT/table.md"
cat "$OUT/table.md"
if [[ ${#FAILED[@]} -gt 0 ]]; then
  echo "quality_table: failed: ${FAILED[*]}" >&2
  exit 1
fi
