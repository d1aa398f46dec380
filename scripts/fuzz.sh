#!/usr/bin/env bash
# Builds the libFuzzer targets with clang, AddressSanitizer and UndefinedBehaviorSanitizer in
# build-fuzz/, and runs each for a bounded time from its seed corpus (tests/fuzz_corpus/).
# A crash stops with its input saved in build-fuzz/crashes/; keep it in the corpus as a
# regression test once fixed.
#   scripts/fuzz.sh [SECONDS_PER_TARGET]   explore for that long per target (default 40)
#   scripts/fuzz.sh --ci                   what CI runs: a fixed seed and a fixed number of
#                                          runs per target (about 30 s each, at most 4
#                                          minutes); the corpus' regression inputs first.
#                                          Two runs still explore differently (from seed 1,
#                                          fuzz_files reached 1491-1523 edges in four runs,
#                                          with ASLR off too: OpenCV's and libvips' threads),
#                                          so a crash found once is kept as a seed.
# Every library is built with coverage counters (CMakeLists.txt, VELLUM_FUZZ), not only the
# targets: libFuzzer is guided by the readers' code, not just its harness's.
set -euo pipefail
cd "$(dirname "$0")/.."
mode=time
seconds=40
if [ "${1:-}" = "--ci" ]; then
  mode=ci
elif [ -n "${1:-}" ]; then
  seconds=$1
fi
CC=clang CXX=clang++ cmake -S . -B build-fuzz -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DVELLUM_FUZZ=ON -DVELLUM_SANITIZE=address,undefined -DVELLUM_BUILD_TESTS=OFF \
  -DVELLUM_BUILD_BENCH=OFF >/dev/null
cmake --build build-fuzz -j2 --target fuzz_messages fuzz_files fuzz_ply_roundtrip fuzz_scan_gate
rm -rf build-fuzz/crashes
mkdir -p build-fuzz/crashes
declare -A runs=([fuzz_messages]=200000 [fuzz_files]=60000 [fuzz_ply_roundtrip]=40000 [fuzz_scan_gate]=100000)
for target in fuzz_messages fuzz_files fuzz_ply_roundtrip fuzz_scan_gate; do
  corpus=build-fuzz/corpus/$target
  if [ "$mode" = ci ]; then
    rm -rf "$corpus"
    # At most 4 minutes a target as well: one CI run's fuzz_messages, same binary and seed,
    # wandered into inputs taking 5-8 ms each (30 minutes for its runs, which take a second
    # here); a crash still fails, the wall clock only bounds how far it explores.
    limit=(-seed=1 -runs="${runs[$target]}" -max_total_time=240)
    echo "fuzz: $target, ${runs[$target]} runs from seed 1"
  else
    limit=(-max_total_time="$seconds")
    echo "fuzz: $target for ${seconds} s"
  fi
  mkdir -p "$corpus"
  log=build-fuzz/$target.log
  # The fuzzer's own exit status decides (a crash, a leak, a timeout or an out-of-memory all
  # exit non-zero); its log is kept and its summary shown.
  status=0
  ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
    "build-fuzz/fuzz/$target" "${limit[@]}" -timeout=10 -rss_limit_mb=2048 \
    -artifact_prefix="build-fuzz/crashes/$target-" -print_final_stats=1 \
    "$corpus" "tests/fuzz_corpus/$target" >"$log" 2>&1 || status=$?
  grep -E "stat::number_of_executed_units|ERROR|SUMMARY|crash-|Done " "$log" || true
  if [ "$status" -ne 0 ] || ls build-fuzz/crashes/"$target"-* >/dev/null 2>&1; then
    echo "fuzz: $target failed (exit status $status; log $log):" \
      "$(ls build-fuzz/crashes/"$target"-* 2>/dev/null)" >&2
    exit 1
  fi
done
echo "fuzz: no crashes"
