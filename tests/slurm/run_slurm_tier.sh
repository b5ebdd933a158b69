#!/usr/bin/env bash
# The Slurm test tier (docs/experiments.md "Testing against a real Slurm"): starts a one-node
# Slurm cluster on this machine (tests/slurm/slurm_cluster.sh; root, Debian's slurm-wlm and
# munge), runs the smoke experiment through `artex experiment --backend slurm`, scancels one
# array task while it runs, checks that the first invocation reports it and `experiment status`
# names its log, reruns (only the cancelled run is resubmitted), and compares results.csv with
# the local backend's (timing metrics aside). The daemons are stopped at the end in every case.
# Skips (exit 0, with the reason) when the daemons cannot start.
#   tests/slurm/run_slurm_tier.sh [BUILD_DIR] [EXPERIMENT_FILE]
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
BUILD="${1:-${ARTEX_BUILD_DIR:-$ROOT/build}}"
EXPERIMENT="${2:-$ROOT/configs/experiments/smoke.yaml}"
ARTEX="$BUILD/experiments/artex"
say() { echo "slurm tier: $*"; }
fail() {
  say "FAILED: $*"
  exit 1
}

[[ -x $ARTEX ]] || fail "$ARTEX not built"
# shellcheck source=tests/slurm/slurm_cluster.sh
source "$ROOT/tests/slurm/slurm_cluster.sh"
WORK="$(mktemp -d /tmp/artex-slurm-tier.XXXXXX)"
cleanup() {
  local rc=$?
  slurm_cluster_stop
  if [[ $rc -eq 0 ]]; then
    rm -rf "$WORK"
  else
    say "kept $WORK (cluster logs in $WORK/cluster/log)"
  fi
}
trap cleanup EXIT
trap 'exit 130' INT TERM  # so that the EXIT trap stops the daemons on an interrupt too
START=$(date +%s.%N)
elapsed() { python3 -c "import sys; print('%.1f' % (float(sys.argv[2]) - float(sys.argv[1])))" "$START" "$(date +%s.%N)"; }

if ! slurm_cluster_start "$WORK/cluster"; then
  say "SKIPPED: cannot start a one-node Slurm cluster: $SLURM_CLUSTER_WHY"
  exit 0
fi
say "one-node cluster up in $(elapsed) s ($(sinfo -h -N -o '%N %c CPUs %m MB'))"

# 1. The local backend (the reference table).
"$ARTEX" experiment "$EXPERIMENT" -o "$WORK/local" -j 2 --threads-per-run 1 --no-plots \
  >"$WORK/local.log" 2>&1 || { cat "$WORK/local.log"; fail "local backend"; }
say "local backend done at $(elapsed) s"

# 2. The Slurm backend, one task at a time; task 1 is cancelled while its run computes.
OUT="$WORK/slurm"
SLURM_ARGS=(--backend slurm --cpus-per-task 1 --max-parallel 1 --poll-seconds 0.5 --no-plots)
"$ARTEX" experiment "$EXPERIMENT" -o "$OUT" "${SLURM_ARGS[@]}" >"$WORK/first.log" 2>&1 &
FIRST=$!
JOB=""
for ((i = 0; i < 1200; ++i)); do
  [[ -s $OUT/slurm/submit-001/job_id ]] && JOB=$(cat "$OUT/slurm/submit-001/job_id")
  # Task 1 has started its run (its start marker is written once artex runs in the task).
  if [[ -n $JOB && -e $OUT/slurm/submit-001/state/1.started ]]; then
    scancel "${JOB}_1"
    break
  fi
  kill -0 "$FIRST" 2>/dev/null || break
  sleep 0.1
done
[[ -n $JOB ]] || { cat "$WORK/first.log"; fail "no job array was submitted"; }
FIRST_RC=0
wait "$FIRST" || FIRST_RC=$?
cat "$WORK/first.log"
[[ $FIRST_RC -ne 0 ]] || fail "the first invocation should report the cancelled run (exit 0)"
grep -q "FAILED .*CANCELLED" "$WORK/first.log" || fail "the first invocation did not report CANCELLED"
say "first invocation: exit $FIRST_RC, task ${JOB}_1 cancelled, at $(elapsed) s"

"$ARTEX" experiment status "$OUT" >"$WORK/status.log" 2>&1 || { cat "$WORK/status.log"; fail "status"; }
cat "$WORK/status.log"
grep -q "CANCELLED" "$WORK/status.log" || fail "status does not show the cancelled task"
grep -q "slurm-logs/.*/slurm-${JOB}_1.log" "$WORK/status.log" || fail "status does not name the task's log"
grep -q "1 failed" "$WORK/status.log" || fail "status should count 1 failed run"

# 3. Rerun: only the cancelled run is submitted again.
"$ARTEX" experiment "$EXPERIMENT" -o "$OUT" "${SLURM_ARGS[@]}" >"$WORK/second.log" 2>&1 ||
  { cat "$WORK/second.log"; fail "the rerun failed"; }
cat "$WORK/second.log"
grep -q "submitted 1 run(s) as job array" "$WORK/second.log" || fail "the rerun should submit exactly 1 run"
grep -q "resubmitted 1 whose task had ended without completing:.*(CANCELLED)" "$WORK/second.log" ||
  fail "the rerun should name the cancelled run as resubmitted"
"$ARTEX" experiment status "$OUT" >"$WORK/status2.log" 2>&1
grep -q " 0 failed, 0 not submitted" "$WORK/status2.log" || { cat "$WORK/status2.log"; fail "runs missing after the rerun"; }

# 4. Nothing lost or duplicated; the same table as the local backend (timing metrics aside).
if find "$OUT/runs" -maxdepth 2 -name '.slurm-*' | grep -q .; then fail "task folders left behind"; fi
python3 "$ROOT/tests/slurm/compare_results.py" "$WORK/local/results.csv" "$OUT/results.csv" ||
  fail "results.csv differs between the local and the Slurm backend"
RUNS=$(find "$OUT/runs" -mindepth 2 -maxdepth 2 -type d ! -name 'slurm-logs' ! -name '.*' | wc -l)
say "PASSED in $(elapsed) s: $RUNS runs, 2 submissions, 1 task cancelled and resubmitted, tables identical"
