#!/usr/bin/env bash
# Installs the station on this machine (as root): the packages, a Release build, then
# binaries in /usr/local/bin, systemd units in /usr/local/lib/systemd/system, the sysctl file
# that raises net.core.rmem_max, the lcm-spy jar, the configs in /etc/vellum (existing
# ones are kept) and the bus's firewall rules (/etc/vellum/vellum-bus.nft, loaded by
# vellum-bus-firewall.service with vellum.target). Then: edit /etc/vellum/*.yaml, put the calibration in
# /etc/vellum/calibration.yaml and run
#   systemctl enable --now vellum.target vellum-camera@video0 vellum-projector@0
# (and vellum-lights, for a station with extra lights: /etc/vellum/lights.yaml)
set -euo pipefail
cd "$(dirname "$0")/.."
prefix=${PREFIX:-/usr/local}
bash scripts/install-deps.sh
bash scripts/build.sh
cmake --install build --prefix "$prefix"
mkdir -p /etc/vellum /var/lib/vellum/scans
for f in "$prefix"/share/vellum/config/vellum-*.yaml "$prefix"/share/vellum/config/lights.yaml \
         "$prefix"/share/vellum/config/vellum-bus.nft; do
  [ -e "/etc/vellum/$(basename "$f")" ] || cp "$f" /etc/vellum/
done
if [ -d /run/systemd/system ]; then
  systemctl daemon-reload
  systemctl restart systemd-sysctl || true
else
  sysctl -p "$prefix/lib/sysctl.d/60-vellum.conf" || true
fi
echo "install-station: installed to $prefix; configs in /etc/vellum; scans go to /var/lib/vellum/scans"
