#!/usr/bin/env bash
# Runs a command inside a private network namespace whose only interface is loopback, set up
# for LCM's udpm multicast (lo up, multicast on, a 224.0.0.0/4 route on lo): bus traffic can
# never leave this machine. It also gets a private mount namespace (tests mount a small tmpfs
# to fill a disk). As root it uses `unshare -n -m`; otherwise a user namespace as well.
set -euo pipefail
if [ "${VELLUM_IN_NETNS:-}" != 1 ]; then
  flags=(-n -m)
  [ "$(id -u)" -eq 0 ] || flags=(-r -n -m)
  exec env VELLUM_IN_NETNS=1 unshare "${flags[@]}" "$0" "$@"
fi
ip link set lo up
ip link set lo multicast on
ip route add 224.0.0.0/4 dev lo
exec "$@"
