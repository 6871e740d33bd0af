#!/usr/bin/env bash
# `make test-stress`: the test suite while two busy loops load both cores, as on a laptop that is
# doing other things. The suite must pass here too: no test may depend on wall-clock margins. Its
# files run on one worker per core as in `make test` (TEST_WORKERS=0: in one process).
set -euo pipefail
cd "$(dirname "$0")/.."
LOADS=${CDPR_STRESS_LOADS:-2}
pids=()
stop() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done; }
trap stop EXIT INT TERM
for _ in $(seq "$LOADS"); do
  python3 -c 'while True: pass' &
  pids+=($!)
done
echo "[test-stress] $LOADS busy loops running (pids ${pids[*]}); the suite follows"
.venv/bin/python -m pytest -q -n "${TEST_WORKERS:-auto}" --dist loadfile tests "$@"
