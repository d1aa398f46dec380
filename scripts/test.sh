#!/usr/bin/env bash
# Installs, checks the formatting and the docs' paths, builds and runs every test: the suite
# (ctest) but for the station's tests, the fuzzers for a fixed number of runs from a fixed
# seed, and the suite again under AddressSanitizer (with LeakSanitizer) and
# UndefinedBehaviorSanitizer, the station's tests (real daemons on a real bus, label station)
# there and only there: each test runs once where it tells the most (the full-size accuracy
# scenes in the plain build, the station sanitized).
# The daily tier: cd build && ctest -L unit (a few minutes).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
bash scripts/check-format.sh
bash scripts/check-docs.sh
bash scripts/check-options.sh
bash scripts/check-function-length.sh
bash scripts/build.sh
(cd build && ctest --output-on-failure -j2 --timeout 900 -LE 'family_full|station')
bash scripts/fuzz.sh --ci
bash scripts/sanitize.sh
