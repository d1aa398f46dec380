#!/usr/bin/env bash
# The install step puts everything in place: `cmake --install` into a scratch prefix, then
# every binary answers --help, the units point at installed binaries and pass
# `systemd-analyze verify` (when systemd is on the machine), the sysctl file raises rmem_max,
# and the bus's firewall rules are in place with the oneshot unit that loads them.
set -euo pipefail
build=$1
prefix=$(mktemp -d)
trap 'rm -rf "$prefix"' EXIT
cmake --install "$build" --prefix "$prefix" >/dev/null
for b in vellum vellum-camera vellum-projector vellum-lights vellum-decoder vellum-triangulator \
         vellum-flattener vellum-restorer vellum-viewer vellum-spy; do
  test -x "$prefix/bin/$b" || { echo "missing bin/$b"; exit 1; }
  "$prefix/bin/$b" --help >/dev/null || { echo "bin/$b --help failed"; exit 1; }
done
units="$prefix/lib/systemd/system"
for u in vellum.target vellum-camera@.service vellum-projector@.service vellum-lights.service \
         vellum-decoder.service vellum-triangulator.service vellum-flattener.service \
         vellum-restorer.service; do
  test -f "$units/$u" || { echo "missing unit $u"; exit 1; }
done
for u in "$units"/*.service; do
  case "$u" in
    */vellum-bus-firewall.service)  # A oneshot: loads the rules, no daemon to watch.
      grep -q '^Type=oneshot' "$u" && grep -q 'nft -f /etc/vellum/vellum-bus.nft' "$u" \
        && grep -q '^PartOf=vellum.target' "$u" || { echo "$u: not a oneshot loading the rules"; exit 1; }
      continue ;;
  esac
  grep -q '^Type=notify' "$u" && grep -q '^WatchdogSec=' "$u" && grep -q '^Restart=on-failure' "$u" \
    && grep -q '^PartOf=vellum.target' "$u" || { echo "$u: not notify/watchdog/restart/PartOf"; exit 1; }
done
grep -q 'net.core.rmem_max' "$prefix/lib/sysctl.d/60-vellum.conf"
test -f "$prefix/share/vellum/vellum_lcmtypes.jar"
test -f "$prefix/share/vellum/config/vellum-decoder.yaml"
test -f "$prefix/share/vellum/config/lights.yaml"
grep -q 'table inet vellum_bus' "$prefix/share/vellum/config/vellum-bus.nft"
if command -v nft >/dev/null && [ "$(id -u)" -eq 0 ]; then nft -c -f "$prefix/share/vellum/config/vellum-bus.nft"; fi
if command -v systemd-analyze >/dev/null; then
  sed -i "s|/usr/local/bin|$prefix/bin|" "$units"/*.service
  (cd "$units" && systemd-analyze verify --man=no ./vellum.target ./vellum-decoder.service \
    ./vellum-triangulator.service ./vellum-flattener.service ./vellum-restorer.service \
    ./vellum-camera@video0.service ./vellum-projector@0.service ./vellum-lights.service \
    ./vellum-bus-firewall.service)
fi
echo "install test: ok ($prefix)"
