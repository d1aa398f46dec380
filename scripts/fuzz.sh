#!/usr/bin/env bash
# Builds the libFuzzer targets with clang, AddressSanitizer and UndefinedBehaviorSanitizer in
# build-fuzz/, and runs each for a bounded time from its seed corpus (tests/fuzz_corpus/).
# A crash stops with its input saved in build-fuzz/crashes/; keep it in the corpus as a
# regression test once fixed.
#   scripts/fuzz.sh [SECONDS_PER_TARGET]   (default 40)
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-40}
CC=clang CXX=clang++ cmake -S . -B build-fuzz -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DVELLUM_FUZZ=ON -DVELLUM_SANITIZE=address,undefined -DVELLUM_BUILD_TESTS=OFF \
  -DVELLUM_BUILD_BENCH=OFF >/dev/null
cmake --build build-fuzz -j2 --target fuzz_messages fuzz_files fuzz_ply_roundtrip
mkdir -p build-fuzz/crashes
for target in fuzz_messages fuzz_files fuzz_ply_roundtrip; do
  corpus=build-fuzz/corpus/$target
  mkdir -p "$corpus"
  echo "fuzz: $target for ${seconds} s"
  ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
    "build-fuzz/fuzz/$target" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 \
    -artifact_prefix="build-fuzz/crashes/$target-" -print_final_stats=1 \
    "$corpus" "tests/fuzz_corpus/$target" 2>&1 | grep -E "^#[0-9]+ +DONE|stat::number_of_executed_units|ERROR|SUMMARY|crash-|Done " || true
  if ls build-fuzz/crashes/"$target"-* >/dev/null 2>&1; then
    echo "fuzz: $target found a crash: $(ls build-fuzz/crashes/"$target"-*)" >&2
    exit 1
  fi
done
echo "fuzz: no crashes"
