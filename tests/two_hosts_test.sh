#!/usr/bin/env bash
# The station on two hosts: a "gantry" host (camera, projector, the operator's `vellum scan`)
# and a "processing" host (decoder, triangulator, flattener, restorer), each a network
# namespace, joined by a veth pair and nothing else. The bus is udpm with ttl=1, routed onto
# the link; a scan must complete and equal `vellum process` on the recorded scan.
#   tests/two_hosts_test.sh BUILD_DIR     (as root, inside scripts/netns-run.sh)
# Exit 77 (skipped) when network namespaces cannot be made here.
set -euo pipefail
build=$(cd "${1:?usage: two_hosts_test.sh BUILD_DIR}" && pwd)
src=$(cd "$(dirname "$0")/.." && pwd)
[ "$(id -u)" -eq 0 ] || { echo "skipped: needs root for ip netns"; exit 77; }
[ "${VELLUM_IN_NETNS:-}" = 1 ] || { echo "run inside scripts/netns-run.sh"; exit 2; }

work=$(mktemp -d /tmp/vellum-two-hosts.XXXXXX)
gantry=vellum-gantry-$$
proc=vellum-proc-$$
pids=()
cleanup() {
  local code=$?
  for p in "${pids[@]}"; do kill -TERM "$p" 2>/dev/null || true; done
  for p in "${pids[@]}"; do wait "$p" 2>/dev/null || true; done
  ip netns del "$gantry" 2>/dev/null || true
  ip netns del "$proc" 2>/dev/null || true
  if [ "$code" -eq 0 ]; then rm -rf "$work"; else echo "logs kept in $work"; fi
}
trap cleanup EXIT

# Two hosts and one cable. Each host: lo up, the link's end with an address, multicast on, and
# the multicast route on the link (so ttl=1 traffic leaves by it, and only by it).
ip netns add "$gantry" || { echo "skipped: cannot make network namespaces"; exit 77; }
ip netns add "$proc"
ip link add veth-gantry type veth peer name veth-proc
ip link set veth-gantry netns "$gantry"
ip link set veth-proc netns "$proc"
setup() {  # namespace, device, address
  ip -n "$1" link set lo up
  ip -n "$1" addr add "$3/30" dev "$2"
  ip -n "$1" link set "$2" multicast on
  ip -n "$1" link set "$2" up
  ip -n "$1" route add 224.0.0.0/4 dev "$2"
}
setup "$gantry" veth-gantry 10.77.0.1
setup "$proc" veth-proc 10.77.0.2

url="udpm://239.255.76.67:7841?ttl=1&recv_buf_size=4194304"
rig=$src/config/small_rig.yaml
on() {  # namespace, log name, command...
  local ns=$1 log=$2
  shift 2
  ip netns exec "$ns" "$@" >"$work/$log.log" 2>&1 &
  pids+=($!)
}
# The sanitizer build paces the processing daemons' chunked products (scripts/sanitize.sh).
pace=()
[ -n "${VELLUM_TEST_PACE:-}" ] && pace=(--pace "$VELLUM_TEST_PACE")
for d in decoder triangulator flattener restorer; do
  on "$proc" "$d" "$build/daemons/vellum-$d" --url "$url" --data "$work/scans" "${pace[@]}"
done
# The sim camera renders each capture: under the sanitizers a render of the curl page can take
# seconds, so the projector waits as long for a CAPTURE as the station test's does.
on "$gantry" camera "$build/daemons/vellum-camera" --url "$url" --backend sim --rig "$rig" \
  --page curl
on "$gantry" projector env SDL_VIDEODRIVER=offscreen "$build/daemons/vellum-projector" \
  --url "$url" --calibration "$rig" --fullscreen false --capture-timeout 30

# Every daemon logs "running" once it is subscribed (the sim camera after its first render).
for log in decoder triangulator flattener restorer camera projector; do
  for _ in $(seq 600); do
    grep -q "running (pid" "$work/$log.log" 2>/dev/null && break
    sleep 0.1
  done
  grep -q "running (pid" "$work/$log.log" || { echo "FAIL: vellum-$log did not start:"; \
    cat "$work/$log.log"; exit 1; }
done

# The operator scans from the gantry host; it returns once RESTORED comes back over the link.
if ! ip netns exec "$gantry" "$build/cli/vellum" scan --url "$url" --label "two hosts" \
  --timeout 120 >"$work/scan.log" 2>&1; then
  echo "FAIL: the scan did not complete across the link:"
  cat "$work/scan.log"
  exit 1
fi

scan=$(ls -d "$work"/scans/scan-* | head -1)
echo "scan restored on the processing host: $scan"
"$build/cli/vellum" process --scan "$scan/raw" --calibration "$scan/raw/calibration.yaml" \
  --out "$work/process" >"$work/process.log" 2>&1
for f in restored.tif flat.ply mesh.ply points.ply restored.json depth.png; do
  if ! cmp -s "$scan/results/$f" "$work/process/$f"; then
    echo "FAIL: $f differs between the two-host station and vellum process"
    exit 1
  fi
done

# Everything crossed by the cable: the captures one way (55 frames of 640x480), the status and
# RESTORED the other.
stat() { ip netns exec "$gantry" cat "/sys/class/net/veth-gantry/statistics/$1"; }
tx=$(stat tx_bytes)
rx=$(stat rx_bytes)
echo "link: gantry sent $tx bytes, received $rx bytes"
if [ "$tx" -lt 16000000 ]; then
  echo "FAIL: the captures did not cross the link (only $tx bytes sent)"
  exit 1
fi
echo "PASS: a scan across two hosts (udpm ttl=1 over a veth pair) equals vellum process"
