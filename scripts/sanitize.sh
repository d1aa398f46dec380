#!/usr/bin/env bash
# The whole test suite under AddressSanitizer (with LeakSanitizer) and UndefinedBehaviorSanitizer:
# a RelWithDebInfo build in build-asan/ whose tests start the sanitized daemons too. Three labels
# are left out: `heavy` (long numeric runs, each named by the HEAVY filter in its CMakeLists
# beside the smaller test that runs its code sanitized), `scenes` (the full-size scene tests, outline_test, leaves_test and the family,
# half an hour sanitized) and `accuracy` (bars on whole-page accuracy: accuracy_test, the
# flattening bars, the calibration, albedo and studio-field bars: 340 s of test time more
# than a clean-clone CI spent here in 790 s). Their code runs sanitized in smaller tests, each named beside
# its ACCURACY filter in the CMakeLists; the plain build checks their bars.
# Any report aborts the process that made it, and so fails its test. The station's tests (label
# station: real daemons on a real bus) run here and only here in CI; the load test runs 10 scans
# here (50 by hand in the plain build: cd build && ctest -L station).
set -euo pipefail
cd "$(dirname "$0")/.."
cmake -S . -B build-asan -DCMAKE_BUILD_TYPE=RelWithDebInfo -DVELLUM_SANITIZE=address,undefined \
  -DVELLUM_BUILD_BENCH=OFF >/dev/null
cmake --build build-asan -j2
cd build-asan
# ctest starts the longest tests first once it knows their times: on a first run, borrow the
# plain build's (the same tests, in the same proportions).
if [ ! -f Testing/Temporary/CTestCostData.txt ] && [ -f ../build/Testing/Temporary/CTestCostData.txt ]; then
  mkdir -p Testing/Temporary
  cp ../build/Testing/Temporary/CTestCostData.txt Testing/Temporary/
fi
# The processing daemons publish their chunked products at 25 MB/s (100 in production): the
# sanitized receivers drain their sockets several times slower.
VELLUM_LOAD_SCANS=10 VELLUM_TEST_PACE=25 ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 \
  LSAN_OPTIONS=suppressions=$PWD/../tests/lsan.supp \
  UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
  ctest --output-on-failure -j2 --timeout 1800 --label-exclude 'scenes|accuracy|heavy'
