#!/usr/bin/env bash
# Maintainer's tool: records the demo's scan (tests/data/demo_leaf.lcmlog.xz) through the real
# station: the camera daemon on the virtual gantry's demo rig (config/demo_rig.yaml, 343 ppi on the table)
# with a curled parchment leaf of 56 x 70 mm whose page is tests/data/demo_page.png (drawn by
# scripts/make-demo-page.py), the projector daemon (offscreen SDL) showing a columns-only
# sequence without inverses and with four phase steps (15 frames: small enough for the
# repository), and the processing daemons, all on a private loopback bus. Run it inside
# scripts/netns-run.sh after a build:
#   scripts/netns-run.sh scripts/record-demo.sh
set -euo pipefail
cd "$(dirname "$0")/.."
bin=${VELLUM_BUILD:-build}
url="udpm://239.255.76.67:7667?ttl=0&recv_buf_size=4194304"
work=$(mktemp -d)
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill -TERM "$p" 2>/dev/null || true; done
  wait 2>/dev/null || true
}
trap cleanup EXIT
rig=config/demo_rig.yaml
SDL_VIDEODRIVER=offscreen "$bin/daemons/vellum-projector" --url "$url" --calibration "$rig" \
  --fullscreen false --axes columns --gray-inverses false --phase-steps 4 \
  >"$work/projector.log" 2>&1 &
pids+=($!)
"$bin/daemons/vellum-camera" --url "$url" --backend sim --rig "$rig" --page curl \
  --page-size 56x70 --texture tests/data/demo_page.png >"$work/camera.log" 2>&1 &
pids+=($!)
for stage in decoder triangulator flattener restorer; do
  "$bin/daemons/vellum-$stage" --url "$url" --data "$work/scans" >"$work/$stage.log" 2>&1 &
  pids+=($!)
done
"$bin/cli/vellum" scan --url "$url" --shelfmark "Demo MS 1" --folio 7 --side recto \
  --operator "vellum demo" --timeout 120 ||
  { tail -n 5 "$work"/*.log; echo "record-demo: failed; the logs are in $work" >&2; exit 1; }
log=$(ls "$work"/scans/scan-*/raw/captures.lcmlog)
xz -9e -T1 -c "$log" >tests/data/demo_leaf.lcmlog.xz
rm -rf "$work"
echo "record-demo: $(du -h tests/data/demo_leaf.lcmlog.xz | cut -f1) tests/data/demo_leaf.lcmlog.xz from $log"
