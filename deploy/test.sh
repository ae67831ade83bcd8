#!/usr/bin/env bash
# README command 2: install what is missing, build, and run the whole test suite;
# then every libFuzzer target for a short bounded time (deploy/fuzz.sh: a clang
# build of the fuzz targets only, 10 s each; LFRECON_FUZZ=0 skips it) and the
# readers', CLI, integration and fuzz-corpus tests under ASan+UBSan
# (deploy/sanitize.sh, a second build of only what those tests need, -O1 -g1;
# LFRECON_SANITIZE=0 skips it). CI aim: under ~40 min on 2 cores (the last
# clean-clone runs took 47-51 min, the sanitizer phase 28 of them; the builds
# are unity builds since to cut that); each phase prints its wall time.
set -euo pipefail
cd "$(dirname "$0")/.."
start=$SECONDS
phase() {  # phase NAME COMMAND...: runs it, then prints its wall time
  local t0=$SECONDS name=$1
  shift
  "$@"
  echo "test.sh: $name: $((SECONDS - t0)) s (total $((SECONDS - start)) s)"
}
phase install ./deploy/install_deps.sh
phase build ./deploy/build.sh
phase ctest bash -c 'cd build && ctest --output-on-failure -j2 --timeout 600'
if [ "${LFRECON_FUZZ:-1}" != 0 ]; then phase fuzz ./deploy/fuzz.sh; fi
if [ "${LFRECON_SANITIZE:-1}" != 0 ]; then phase sanitize ./deploy/sanitize.sh; fi
