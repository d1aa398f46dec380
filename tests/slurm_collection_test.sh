#!/usr/bin/env bash
# `vellum collection run --slurm` on a real one-node Slurm cluster (tests/slurm/cluster.sh: munged,
# slurmctld and slurmd from Debian, inside this test's private network namespace), over a
# collection of 20 scans: 18 leaves of the virtual gantry (seeds 1 to 18, at the station's size)
# and the two recorded scans of tests/data (the demo leaf and the station tests' checkerboard
# leaf). The same collection is processed by the local pool beside it. Checks:
#   - a task cancelled mid-way (scancel) leaves its scans wholly old; with no resubmission and no
#     task taking another's scans the run reports them, and a second run finishes exactly the rest;
#   - every product equals the local run's byte for byte (but report.json and report.html, which
#     carry the stages' times), each scan's manifest checks, and no scan was processed twice;
#   - a new calibration for half the scans makes exactly those stale, with the reason, and a
#     Slurm run processes exactly those.
# usage: slurm_collection_test.sh VELLUM DEMO_LOG CURL_LOG (inside scripts/netns-run.sh)
set -euo pipefail
vellum=${1:?usage: slurm_collection_test.sh VELLUM DEMO_LOG CURL_LOG}
demo_log=${2:?usage: slurm_collection_test.sh VELLUM DEMO_LOG CURL_LOG}
curl_log=${3:?usage: slurm_collection_test.sh VELLUM DEMO_LOG CURL_LOG}
src=$(cd "$(dirname "$0")/.." && pwd)
work=$(mktemp -d /tmp/vellum_slurm_test.XXXXXX)
cleanup() {
  "$src/tests/slurm/cluster.sh" stop "$work/cluster" || true
  [ -n "${KEEP:-}" ] || rm -rf "$work"
}
trap cleanup EXIT
fail() {
  echo "slurm_collection_test: FAIL: $*" >&2
  exit 1
}
wait_for() {  # wait_for SECONDS WHAT COMMAND...: until COMMAND succeeds
  local seconds=$1 what=$2
  shift 2
  local deadline=$((SECONDS + seconds))
  until "$@"; do
    [ "$SECONDS" -lt "$deadline" ] || fail "$what (not within $seconds s)"
    sleep 0.05
  done
}

export SLURM_CONF
SLURM_CONF=$("$src/tests/slurm/cluster.sh" start "$work/cluster")
echo "slurm_collection_test: cluster up ($SLURM_CONF)"

# The leaves at the station's own size (the default rig: 1600 x 1200, 108 MB of frames a scan), as
# a library's collection holds them; two rendered at a time.
rig=$src/config/default_calibration.yaml
seq 1 18 | xargs -P 2 -I{} sh -c '"$1" render --out "$2/local/scan-$((1000 + {}))/raw" \
  --calibration "$3" --seed {} --truth false >/dev/null 2>&1 || { echo "render seed {}" >&2; exit 255; }' \
  sh "$vellum" "$work" "$rig" || fail "rendering the leaves"
"$vellum" export "$demo_log" "$work/local/scan-2000-demo/raw" >/dev/null || fail "export $demo_log"
"$vellum" export "$curl_log" "$work/local/scan-2001-curl/raw" >/dev/null || fail "export $curl_log"
cp -a "$work/local" "$work/slurm"
scans=$(cd "$work/local" && ls -d scan-*)
[ "$(echo "$scans" | wc -w)" -eq 20 ] || fail "expected 20 scans"

"$vellum" collection run --root "$work/local" >"$work/local.log" 2>&1 ||
  fail "the local run: $(cat "$work/local.log")"

# The Slurm run, in 5 tasks of 4; one task cancelled while it works. No task takes another's
# scans (--steal no) and none is submitted again (--resubmit 0): the cancelled task's are left.
root=$work/slurm
"$vellum" collection run --slurm --chunk 4 --cpus-per-task 1 --resubmit 0 --steal no --root "$root" \
  >"$work/slurm1.log" 2>&1 &
run=$!
list=$root/vellum-collection/slurm/array-1/scans.txt
done_in_chunk() {  # done_in_chunk K: how many of task K's scans the ledger has done
  local n=0 folder
  for folder in $(sed -n "$(($1 * 4 + 1)),$(($1 * 4 + 4))p" "$list"); do
    grep -qs '"state": "done"' "$root/vellum-collection/scans/$folder.json" && n=$((n + 1))
  done
  echo "$n"
}
cancelled=""
cancel_mid_way() {  # A running task with one to three of its four scans done: cancelled.
  local task state k
  [ -f "$list" ] || return 1
  while read -r task state; do
    [ "$state" = RUNNING ] || continue
    k=${task#*_}
    if [ "$(done_in_chunk "$k")" -ge 1 ] && [ "$(done_in_chunk "$k")" -le 3 ]; then
      scancel "$task" && cancelled=$k && return 0
    fi
  done < <(squeue -h -r -o "%i %T" 2>/dev/null)
  return 1
}
wait_for 300 "a task to cancel mid-way" cancel_mid_way
echo "slurm_collection_test: cancelled task $cancelled with $(done_in_chunk "$cancelled") of its 4 scans done"
status=0
wait "$run" || status=$?
[ "$status" -eq 1 ] || fail "the run with a cancelled task exited $status: $(cat "$work/slurm1.log")"
grep -q "scan(s) not processed: their task failed or was cancelled" "$work/slurm1.log" ||
  fail "the cancelled task's scans not reported: $(cat "$work/slurm1.log")"
left=$("$vellum" collection plan --root "$root" | grep -c ": stale:" || true)
[ "$left" -ge 1 ] && [ "$left" -le 3 ] || fail "$left scans left after the cancel, expected 1 to 3"

"$vellum" collection run --slurm --chunk 4 --cpus-per-task 1 --root "$root" \
  >"$work/slurm2.log" 2>&1 || fail "the second run: $(cat "$work/slurm2.log")"
grep -q "^$left scan(s) to process on Slurm" "$work/slurm2.log" ||
  fail "the second run did not take exactly the $left left: $(cat "$work/slurm2.log")"

# Every scan done once, its products those of the local run, its manifest checking.
"$vellum" collection status --all --root "$root" >"$work/status.txt" ||
  fail "status: $(cat "$work/status.txt")"
grep -q "^20 scan(s): 20 done" "$work/status.txt" || fail "not all done: $(cat "$work/status.txt")"
grep -q "processed by collection runs: 20 scan(s) 1 time(s);$" "$work/status.txt" ||
  fail "a scan processed twice or never: $(cat "$work/status.txt")"
compared=0
for scan in $scans; do
  "$vellum" manifest check "$root/$scan" >/dev/null || fail "$scan: its manifest does not check"
  while IFS= read -r -d '' file; do
    rel=${file#"$work/local/$scan/"}
    case $rel in results/report.json | results/report.html) continue ;; esac
    cmp -s "$file" "$root/$scan/$rel" || fail "$scan/$rel differs from the local run's"
    compared=$((compared + 1))
  done < <(find "$work/local/$scan/results" -type f -print0)
done
echo "slurm_collection_test: $compared files equal to the local run's, byte for byte"

# A refined calibration for half the scans: exactly those stale, for that reason, and processed.
changed=""
for scan in $(echo "$scans" | awk 'NR % 2 == 1'); do
  # The camera's focal length (the first number of camera_matrix), refined by 0.1%.
  python3 - "$root/$scan/raw/calibration.yaml" <<'PY'
import re, sys
text = open(sys.argv[1]).read()
at = text.index('data: [', text.index('camera_matrix:')) + len('data: [')
number = re.match(r'\s*([-+0-9.eE]+)', text[at:])
text = text[:at] + ' %r' % (float(number.group(1)) * 1.001) + text[at + number.end():]
open(sys.argv[1], 'w').write(text)
PY
  changed="$changed $scan"
done
"$vellum" collection plan --root "$root" >"$work/plan.txt" || true
planned=$(grep ": stale: calibration changed: [0-9a-f]* -> [0-9a-f]*$" "$work/plan.txt" |
  cut -d: -f1 | sort | xargs)
[ "$planned" = "$(echo "$changed" | xargs -n1 | sort | xargs)" ] ||
  fail "planned stale: '$planned', expected '$changed': $(cat "$work/plan.txt")"
[ "$(grep -c ": stale:" "$work/plan.txt")" -eq 10 ] || fail "$(cat "$work/plan.txt")"
"$vellum" collection run --slurm --chunk 3 --cpus-per-task 1 --root "$root" \
  >"$work/slurm3.log" 2>&1 || fail "the run after the calibration: $(cat "$work/slurm3.log")"
grep -q "^10 scan(s) to process on Slurm" "$work/slurm3.log" || fail "$(cat "$work/slurm3.log")"
# In 4 tasks of 3, two at a time on the node's two cores: the two that begin first take the scans
# of those not begun (which are cancelled once every scan is done), each scan once.
total=0
most=0
for task_log in "$root"/vellum-collection/slurm/array-3/task-*.log; do
  n=$(grep -c "done (" "$task_log" || true)
  total=$((total + n))
  [ "$n" -gt "$most" ] && most=$n
done
[ "$total" -eq 10 ] || fail "the array's tasks processed $total scans, expected 10"
[ "$most" -gt 3 ] || fail "no task took another's scans (at most $most each)"
"$vellum" collection status --root "$root" >"$work/status.txt" || fail "$(cat "$work/status.txt")"
grep -q "processed by collection runs: 10 scan(s) 1 time(s); 10 scan(s) 2 time(s);$" \
  "$work/status.txt" || fail "$(cat "$work/status.txt")"
echo "slurm_collection_test: passed"
