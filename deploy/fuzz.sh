#!/usr/bin/env bash
# libFuzzer run of every fuzz target (tests/fuzz): builds them with clang-14
# (-fsanitize=fuzzer,address,undefined, -O1 -gline-tables-only as OSS-Fuzz
# does) in ${FUZZ_BUILD_DIR:-build-fuzz}, only the libraries they need (target
# fuzz_all), then runs each for ${FUZZ_SECONDS:-10} s from its seed corpus
# tests/fuzz/corpus/<target> (the tree's corpus is only read; new inputs go to
# build-fuzz/corpus/<target>). CI's 10 s per target is a smoke run (20 s ran
# 90-660 k inputs per target); longer: FUZZ_SECONDS=600 ./deploy/fuzz.sh.
# A crash, leak, timeout (10 s) or RSS above 2 GiB fails the run; the input
# that did it is in build-fuzz/artifacts/ (add it to the seed corpus with the fix).
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD="${FUZZ_BUILD_DIR:-build-fuzz}"
SECS="${FUZZ_SECONDS:-10}"
cmake -S . -B "$BUILD" -DCMAKE_CXX_COMPILER=clang++-14 -DCMAKE_BUILD_TYPE=RelWithDebInfo -DLFRECON_FUZZ=ON \
  "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -gline-tables-only -DNDEBUG" -DLFRECON_BUILD_BENCHMARKS=OFF \
  "-DCMAKE_CXX_FLAGS=-fsanitize=fuzzer-no-link,address,undefined -fno-sanitize-recover=undefined -fno-omit-frame-pointer" \
  >"$BUILD.configure.log" 2>&1 || { cat "$BUILD.configure.log"; exit 1; }
cmake --build "$BUILD" -j"${JOBS:-2}" --target fuzz_all
echo "fuzz: configure + build $SECONDS s"
mkdir -p "$BUILD/artifacts"
# One target per core (${JOBS:-2} at a time): libFuzzer runs one thread.
fuzz_one() {
  local exe=$1 t="${1##*/fuzz_}"
  local log="$BUILD/fuzz_$t.log"
  mkdir -p "$BUILD/corpus/$t"
  if "$exe" -max_total_time="$SECS" -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 \
      -artifact_prefix="$BUILD/artifacts/$t-" "$BUILD/corpus/$t" "tests/fuzz/corpus/$t" >"$log" 2>&1; then
    echo "fuzz: $t: $(grep -o 'number_of_executed_units: [0-9]*' "$log" | grep -o '[0-9]*' || echo '?') inputs in ${SECS} s, no crash"
  else
    { echo "fuzz: $t: FAILED (log $log, input in $BUILD/artifacts/):"
      grep -E "ERROR|SUMMARY|Test unit written" "$log" | head -5; } >&2
    touch "$BUILD/fuzz_$t.failed"
  fi
}
rm -f "$BUILD"/fuzz_*.failed
for exe in "$BUILD"/fuzz/fuzz_*; do
  fuzz_one "$exe" &
  while [ "$(jobs -rp | wc -l)" -ge "${JOBS:-2}" ]; do wait -n || true; done
done
wait
failed=()
for f in "$BUILD"/fuzz_*.failed; do [ -e "$f" ] && { t="${f##*/fuzz_}"; failed+=("${t%.failed}"); }; done
[ ${#failed[@]} -eq 0 ] || { echo "fuzz: failed: ${failed[*]}" >&2; exit 1; }
