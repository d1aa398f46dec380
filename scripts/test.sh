#!/usr/bin/env bash
# Installs, checks the formatting, builds and runs every test: the suite (ctest), the fuzzers
# for a fixed number of runs from a fixed seed, and the whole suite again under AddressSanitizer
# (with LeakSanitizer) and UndefinedBehaviorSanitizer.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
bash scripts/check-format.sh
bash scripts/build.sh
(cd build && ctest --output-on-failure -j2 --timeout 900 -LE family_full)
bash scripts/fuzz.sh --ci
bash scripts/sanitize.sh
