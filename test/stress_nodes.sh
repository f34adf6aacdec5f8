#!/usr/bin/env bash
# Run the node tests N times in a row while two CPU-bound processes load both cores;
# report how many runs failed (issue 13: "no test depends on wall-clock luck").
#
#   test/stress_nodes.sh [N] [extra pytest args…]     (default N = 30)
#   make stress N=30
#
# Each run's pytest output goes to $STRESS_LOG_DIR/run_<i>.log (default a temp dir,
# printed at the start); the last line is the figure, e.g. "stress: 30 runs, 0 failed".
# Exit status: 0 if every run passed, 1 otherwise.  The load processes are always
# stopped (trap), and only they: they are killed by their own pids.
set -u
N=${1:-30}
shift || true
case "$N" in ''|*[!0-9]*) echo "stress_nodes.sh: error: N must be a whole number, got '$N'" >&2; exit 2;; esac
if [ "$N" -lt 1 ]; then echo "stress_nodes.sh: error: N must be >= 1, got $N" >&2; exit 2; fi
ROOT=$(cd "$(dirname "$0")/.." && pwd)
PY=${PY:-$ROOT/.venv/bin/python}
LOGS=${STRESS_LOG_DIR:-$(mktemp -d /tmp/motor_comp_stress.XXXXXX)}
mkdir -p "$LOGS"
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST

LOAD_PIDS=()
stop_load() {
    for pid in "${LOAD_PIDS[@]}"; do kill "$pid" 2>/dev/null; done
    wait "${LOAD_PIDS[@]}" 2>/dev/null
}
trap stop_load EXIT
trap 'exit 130' INT TERM
for _ in 1 2; do   # two CPU-bound processes: both cores busy
    "$PY" -c 'while True: pass' &
    LOAD_PIDS+=($!)
done
echo "stress: $N runs of test/nodes under load (pids ${LOAD_PIDS[*]}); logs in $LOGS"

failed=0
for i in $(seq 1 "$N"); do
    start=$(date +%s)
    if (cd "$ROOT" && "$PY" -m pytest -q -rs -p no:cacheprovider --basetemp="$LOGS/tmp_$i" \
            test/nodes "$@") > "$LOGS/run_$i.log" 2>&1; then
        result=passed
        rm -rf "$LOGS/tmp_$i"
    else
        result=FAILED
        failed=$((failed + 1))
    fi
    summary=$(tail -n 1 "$LOGS/run_$i.log")
    echo "stress: run $i/$N $result in $(( $(date +%s) - start )) s: $summary"
    grep -E '^(FAILED|ERROR|SKIPPED) ' "$LOGS/run_$i.log" | sed 's/^/stress:     /'
done
echo "stress: $N runs, $failed failed"
[ "$failed" -eq 0 ]
