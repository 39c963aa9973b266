#!/usr/bin/env bash
# Stress the TUI tests: run tests/tui/test_tui_*.py RUNS times, one after the other, while
# BUSY busy-loop processes keep the cores loaded, to shake out races between the worker
# threads and the UI (issue 30). Not part of the default suite: it takes about an hour at
# 50 runs. See docs/development/tui-stress.md.
#
#   tests/tui/stress.sh [RUNS] [BUSY]      RUNS default 50, BUSY default: one per core
#
# Prints one line per run and "passed X/RUNS" at the end; the output of every failed run is
# kept in $STRESS_LOGS (default: a new temporary folder). Exit status 0 only if all passed.
set -u
runs=${1:-50}
busy=${2:-$(nproc)}
logs=${STRESS_LOGS:-$(mktemp -d -t tui-stress.XXXXXX)}
mkdir -p "$logs"
cd "$(dirname "$0")/../.." || exit 2
python=${PYTHON:-python}

pids=()
stop_busy() {
    for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null; done  # only the loops started here
    wait "${pids[@]}" 2>/dev/null
}
trap stop_busy EXIT
trap 'exit 130' INT TERM
for _ in $(seq "$busy"); do
    "$python" -c 'while True: pass' &
    pids+=($!)
done

echo "stress: $runs runs of tests/tui/test_tui_*.py, $busy busy-loop process(es), logs in $logs"
passed=0
for i in $(seq "$runs"); do
    start=$(date +%s)
    log="$logs/run-$i.log"
    if "$python" -m pytest -q -p no:cacheprovider tests/tui/test_tui_*.py >"$log" 2>&1; then
        passed=$((passed + 1))
        echo "run $i/$runs: pass ($(( $(date +%s) - start )) s)"
        rm -f "$log"
    else
        echo "run $i/$runs: FAIL ($(( $(date +%s) - start )) s), see $log"
        grep -E '^(FAILED|ERROR) ' "$log" | sed 's/^/    /'
    fi
done
echo "passed $passed/$runs"
[ "$passed" -eq "$runs" ]
