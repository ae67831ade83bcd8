#!/usr/bin/env bash
# Tests under AddressSanitizer + UndefinedBehaviorSanitizer: a second build in
# ${ASAN_BUILD_DIR:-build-asan} (g++, -fsanitize=address,undefined, no UB
# recovery, ${ASAN_OPT:--O1 -g1}: ASan's documentation asks for -O1 or more, line
# tables give the reports' stacks; RelWithDebInfo's -O2 -g took 2.1x the compile
# CPU time on the heaviest file, probabilistic_fusion.cc: 303 s against 142 s,
# and 1.5x on auth_test.cc), then ctest there. Any ASan report (out of
# bounds, use after free, leaks at exit) or UB fails the test it happens in.
# CI runs a subset (2 cores): ASAN_TESTS, a ctest regex, by default the unit
# tests of the input readers and of the service (util, geometry, io, cli) and
# every integration and fuzz-corpus test (the depth tests, algorithm code on
# generated data, take 140-205 s each under ASan and are left out); the integration tests run
# the whole pipeline inside the sanitized daemons (ingest, depth, propagation,
# fusion, export, refine). Only the libraries, daemons and test executables
# of the subset are built, as one target (test_subset: both cores busy; the
# benchmarks and the other tests are not built). ASAN_TESTS=. builds and runs everything.
# A unity build like deploy/build.sh's (LFRECON_UNITY=OFF: one file per unit).
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD="${ASAN_BUILD_DIR:-build-asan}"
TESTS="${ASAN_TESTS:-^(util|geometry|io|cli|integration|fuzz)_}"
OPT="${ASAN_OPT:--O1 -g1}"
cmake -S . -B "$BUILD" -DCMAKE_BUILD_TYPE=RelWithDebInfo "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=$OPT -DNDEBUG" \
  -DLFRECON_BUILD_BENCHMARKS=OFF "-DLFRECON_TEST_SUBSET=$TESTS" "-DCMAKE_UNITY_BUILD=${LFRECON_UNITY:-ON}" \
  "-DCMAKE_CXX_FLAGS=-fsanitize=address,undefined -fno-sanitize-recover=undefined -fno-omit-frame-pointer" \
  >"$BUILD.configure.log" 2>&1 || { cat "$BUILD.configure.log"; exit 1; }
# test_subset (tests/CMakeLists.txt): the executables of the tests matching
# $TESTS and what they run (lfrecon, the daemons).
cmake --build "$BUILD" -j"${JOBS:-2}" --target test_subset
echo "sanitize: configure + build $SECONDS s"
# Leak checking is off by default: OpenCV's videoio (GStreamer, libusb) leaks at
# exit (io_frame_source_test: 22 KB in libusb_get_device_list and an unloaded
# plugin); ASAN_OPTIONS=detect_leaks=1 turns it on.
export ASAN_OPTIONS="${ASAN_OPTIONS:-detect_leaks=0:abort_on_error=1:strict_string_checks=1}"
export UBSAN_OPTIONS="${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}"
cd "$BUILD"
ctest --output-on-failure -j2 --timeout 1200 -R "$TESTS"
