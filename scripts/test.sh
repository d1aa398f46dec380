#!/usr/bin/env bash
# Installs, checks the formatting, builds and runs every test (ctest).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
bash scripts/check-format.sh
bash scripts/build.sh
cd build
ctest --output-on-failure -j2 --timeout 900
