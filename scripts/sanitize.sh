#!/usr/bin/env bash
# The whole test suite under AddressSanitizer (with LeakSanitizer) and UndefinedBehaviorSanitizer:
# a RelWithDebInfo build in build-asan/ whose tests start the sanitized daemons too. The
# full-size scene tests (label `scenes`: outline_test, leaves_test) are left out, as they take
# half an hour sanitized; their code (finding the leaf, pages, flying points) runs here through
# the chain, CLI and station tests on the small rig. So are five accuracy tests on the
# full-size rig (about 750 s sanitized, the slowest of the suite): their code runs sanitized in
# smaller tests (the calibration solve in CliTest.CalibrateSolve... and Calibrate.BadPoses...,
# decoding without inverses or finest bits in patterns_test, the flying-point filter and the
# whole pipeline in the chain and CLI tests); what they add is the accuracy bars, which the
# plain build checks. Likewise five more (about 420 s sanitized, measured in a clean-clone CI
# run): the 300x300 sheet of FlattenFine (225 s; the same solve runs sanitized on its 200x150
# sheet and in FlattenAccuracy), the two albedo accuracy tests and the studio field's (their code
# runs sanitized in CliTest.AFlatFieldGivesEachPageItsAlbedo and
# CliTest.AStudioFieldTakesTheLampsShadingOutOfTheTexture) and FullBleedBoard (the whole chain,
# run sanitized by the chain and CLI tests). Any report
# aborts the process that made it, and so fails its test. The station's tests (label station:
# real daemons on a real bus) run here and only here in CI; the load test runs 10 scans here (50
# by hand in the plain build: cd build && ctest -L station).
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
  ctest --output-on-failure -j2 --timeout 1800 --label-exclude scenes \
  --exclude-regex '^(Calibrate\.(RecoversTheVirtualGantrysCalibration|APageScannedWithTheSolvedCalibrationMeetsTheBar)|OtherRigs\.GrayCodeWithoutInverses.*|FlyingPoints\.AreRejected.*|ExperimentOne\.RestoredCornersMatchTheControl|Sheets/FlattenFine\.MeetsTheSameBar/A300x300 .*|Albedo\.(APlainCurledLeafIsEvenWhereItsTextureIsShaded|CheckerboardSquaresHaveTheirTrueAlbedo)|StudioField\.TheLampsShadingIsTakenOutOfTheTexture|FullBleedBoard\.HalfThePageInkStillMeetsTheBar)$'
