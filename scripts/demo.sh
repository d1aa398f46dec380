#!/usr/bin/env bash
# The main job on its embedded default: installs, builds, then plays the recorded scan in
# tests/data (a curled parchment leaf at 326 ppi, recorded from the virtual gantry through the
# real camera and projector daemons by scripts/record-demo.sh) through the real processing
# daemons on a private LCM bus, and writes the restored page.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
bash scripts/build.sh
out=$(realpath -m "${VELLUM_DEMO_OUT:-out/demo}")
rm -rf "$out"
scripts/netns-run.sh scripts/playback.sh build/tests/data/demo_leaf.lcmlog "$out"
results=$(ls -d "$out"/scan-*/results)
echo "demo: restored page $results/restored.tif; report $results/report.html (and restored.json, report.json, points.ply," \
  "depth.png, mesh.ply, flat.ply); raw captures in ${results%/results}/raw; daemon logs in $out"
