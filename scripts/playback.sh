#!/usr/bin/env bash
# Plays a recorded scan log through the real processing daemons on a udpm bus and waits for
# the restored page. Run it inside scripts/netns-run.sh (the demo does) so that the bus stays
# on a private loopback.
#   scripts/playback.sh LOG DATA_DIR
set -euo pipefail
log=$1
data=$2
bin=${VELLUM_BUILD:-build}
url=${VELLUM_URL:-"udpm://239.255.76.67:7667?ttl=0&recv_buf_size=4194304"}
mkdir -p "$data"
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill -TERM "$p" 2>/dev/null || true; done
  wait 2>/dev/null || true
}
trap cleanup EXIT
for stage in decoder triangulator flattener restorer; do
  "$bin/daemons/vellum-$stage" --url "$url" --data "$data" >"$data/vellum-$stage.log" 2>&1 &
  pids+=($!)
done
# Once every daemon's heartbeat is heard, play the log and follow the bus until the scan is
# restored (progress on stderr; the results line on stdout).
"$bin/cli/vellum" watch --url "$url" --count 1 --timeout 600 --play "$log"
