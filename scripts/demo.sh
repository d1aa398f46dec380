#!/usr/bin/env bash
# The main job on its embedded default: installs, builds, renders a scan of a curled
# checkerboard page with the virtual gantry, and processes it into the restored flat page.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
bash scripts/build.sh
out=${VELLUM_DEMO_OUT:-out/demo}
./build/cli/vellum render --page curl --texture checkerboard --out "$out/scan"
./build/cli/vellum process --scan "$out/scan" --calibration "$out/scan/calibration.yaml" \
  --out "$out/result"
echo "demo: scan in $out/scan; restored page $out/result/restored.tif (and points.ply, depth.png, mesh.ply, flat.ply, restored.json, report.json)"
