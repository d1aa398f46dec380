#!/usr/bin/env bash
# The whole test suite under AddressSanitizer (with LeakSanitizer) and UndefinedBehaviorSanitizer:
# a RelWithDebInfo build in build-asan/ whose tests start the sanitized daemons too. Any report
# aborts the process that made it, and so fails its test. The load test runs 10 scans here
# (50 in the plain build).
set -euo pipefail
cd "$(dirname "$0")/.."
cmake -S . -B build-asan -DCMAKE_BUILD_TYPE=RelWithDebInfo -DVELLUM_SANITIZE=address,undefined \
  -DVELLUM_BUILD_BENCH=OFF >/dev/null
cmake --build build-asan -j2
cd build-asan
VELLUM_LOAD_SCANS=10 ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 \
  UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
  ctest --output-on-failure -j2 --timeout 1800
