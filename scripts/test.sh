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
# Each phase's start and the seconds since the run began, so that a slow run says where.
phase() { echo "test.sh: $1 at $(date +%T), ${SECONDS} s in"; }
phase "installing"
bash scripts/install-deps.sh
phase "checking"
bash scripts/check-format.sh
bash scripts/check-docs.sh
bash scripts/check-options.sh
bash scripts/check-function-length.sh
phase "building"
bash scripts/build.sh
phase "testing"
(cd build && ctest --output-on-failure -j2 --timeout 900 -LE 'family_full|station')
phase "fuzzing"
bash scripts/fuzz.sh --ci
phase "the sanitized build and tests"
bash scripts/sanitize.sh
phase "done"
