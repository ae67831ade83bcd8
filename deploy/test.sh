#!/usr/bin/env bash
# README command 2: install what is missing, build, and run the whole test suite;
# then every libFuzzer target for a short bounded time (deploy/fuzz.sh: a clang
# build of the fuzz targets only, 20 s each; LFRECON_FUZZ=0 skips it) and the
# readers', CLI, integration and fuzz-corpus tests under ASan+UBSan
# (deploy/sanitize.sh, a second build; LFRECON_SANITIZE=0 skips it). Measured
# on a clean clone here (2 cores, load ~4): build + tests + fuzz 22 min; the
# ASan build ~15 min more and its 21 tests 5 min.
set -euo pipefail
cd "$(dirname "$0")/.."
./deploy/install_deps.sh
./deploy/build.sh
(cd build && ctest --output-on-failure -j2 --timeout 600)
if [ "${LFRECON_FUZZ:-1}" != 0 ]; then ./deploy/fuzz.sh; fi
if [ "${LFRECON_SANITIZE:-1}" != 0 ]; then ./deploy/sanitize.sh; fi
