#!/usr/bin/env bash
# README command 2: install what is missing, build, and run the whole test suite;
# then every libFuzzer target for a short bounded time (deploy/fuzz.sh: a clang
# build of the fuzz targets only, 20 s each; LFRECON_FUZZ=0 skips it) and, with
# LFRECON_SANITIZE=1, the tests under ASan+UBSan (deploy/sanitize.sh, a second
# build; off by default until its CI time is measured on 2 cores).
set -euo pipefail
cd "$(dirname "$0")/.."
./deploy/install_deps.sh
./deploy/build.sh
(cd build && ctest --output-on-failure -j2 --timeout 600)
if [ "${LFRECON_FUZZ:-1}" != 0 ]; then ./deploy/fuzz.sh; fi
if [ "${LFRECON_SANITIZE:-0}" != 0 ]; then ./deploy/sanitize.sh; fi
