#!/usr/bin/env bash
# A one-node Slurm cluster on this machine for the collection tests: munged, slurmctld and slurmd
# from Debian's packages, with a key, configuration (slurm.conf.in), state and logs of their own
# under DIR. Run it inside a private network namespace (scripts/netns-run.sh): its daemons then
# talk over loopback only, nothing they send can leave the machine, and their ports cannot meet
# another cluster's.
#   cluster.sh start DIR   starts the three daemons and waits until the node takes jobs; prints
#                          the SLURM_CONF to export for sbatch, squeue, scancel
#   cluster.sh stop DIR    stops them (each by its pid file) and waits until they are gone
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
what=${1:?usage: cluster.sh start|stop DIR}
dir=$(mkdir -p "${2:?usage: cluster.sh start|stop DIR}" && cd "$2" && pwd)
conf=$dir/slurm.conf

wait_for() {  # wait_for SECONDS WHAT COMMAND...: until COMMAND succeeds
  local seconds=$1 what=$2
  shift 2
  local deadline=$((SECONDS + seconds))
  until "$@" >/dev/null 2>&1; do
    if [ "$SECONDS" -ge "$deadline" ]; then
      echo "cluster.sh: $what within ${seconds} s; logs in $dir" >&2
      tail -n 20 "$dir"/*.log "$dir"/munge/*.log >&2 2>/dev/null || true
      return 1
    fi
    sleep 0.2
  done
}

stop_pid() {  # stop_pid FILE: SIGTERM to the pid in FILE, then wait for it to go
  [ -f "$1" ] || return 0
  local pid
  pid=$(cat "$1")
  kill "$pid" 2>/dev/null || return 0
  local deadline=$((SECONDS + 30))
  while kill -0 "$pid" 2>/dev/null && [ "$SECONDS" -lt "$deadline" ]; do sleep 0.1; done
  kill -9 "$pid" 2>/dev/null || true
}

case $what in
start)
  for program in munged slurmctld slurmd sinfo; do
    command -v "$program" >/dev/null || [ -x "/usr/sbin/$program" ] || {
      echo "cluster.sh: $program missing (apt install slurm-wlm munge)" >&2
      exit 1
    }
  done
  if [ "${VELLUM_IN_NETNS:-}" != 1 ]; then
    echo "cluster.sh: run it inside scripts/netns-run.sh (a private network namespace)" >&2
    exit 1
  fi
  export PATH=$PATH:/usr/sbin
  # Slurm resolves 127.0.0.1 with getaddrinfo's AI_ADDRCONFIG, which answers nothing on a host
  # whose only addresses are loopback's: one more address on lo, in this namespace only.
  ip addr add 10.254.0.1/32 dev lo 2>/dev/null || true
  mkdir -p "$dir/munge" "$dir/state" "$dir/spool"
  chmod 700 "$dir/munge"
  head -c 1024 /dev/urandom >"$dir/munge/munge.key"
  chmod 400 "$dir/munge/munge.key"
  munged --force --key-file="$dir/munge/munge.key" --socket="$dir/munge/munge.socket" \
    --pid-file="$dir/munge/munged.pid" --log-file="$dir/munge/munged.log" \
    --seed-file="$dir/munge/munged.seed"
  wait_for 20 "munged did not answer" munge -n -S "$dir/munge/munge.socket"
  host=$(hostname -s)
  cpus=$(nproc)
  memory=$(awk '/MemTotal/ { print int($2 / 1024 * 0.9) }' /proc/meminfo)
  sed -e "s|@DIR@|$dir|g" -e "s|@HOST@|$host|g" -e "s|@CPUS@|$cpus|g" \
    -e "s|@MEMORY@|$memory|g" -e "s|@USER@|$(id -un)|g" -e "s|@CTLPORT@|6817|g" \
    -e "s|@DPORT@|6818|g" "$here/slurm.conf.in" >"$conf"
  slurmctld -f "$conf" -i
  slurmd -f "$conf" -N "$host"
  export SLURM_CONF=$conf
  wait_for 60 "the node did not come up idle" sh -c "sinfo -h -o %T | grep -qx idle"
  echo "$conf"
  ;;
stop)
  stop_pid "$dir/slurmd.pid"
  stop_pid "$dir/slurmctld.pid"
  stop_pid "$dir/munge/munged.pid"
  ;;
*)
  echo "usage: cluster.sh start|stop DIR" >&2
  exit 2
  ;;
esac
