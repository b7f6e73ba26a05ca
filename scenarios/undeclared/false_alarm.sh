#!/usr/bin/env bash
# False-alarm bench of `ground-tool diagnose` (issue 5): the clean scenario (nothing
# undeclared) flown with N seeds; a run "alarms" when diagnose reports any detected effect or
# any unexplained structure. Requirement: at most 1 alarm in 20 runs.
#
#   scenarios/undeclared/false_alarm.sh [N=20] [FIRST_SEED=100] [WORK=/tmp/diagnose-fa]
#   SCENARIO=gro-early-mission scenarios/undeclared/false_alarm.sh 10   # another clean geometry
#
# The shipped clean plans and their seeds in docs/diagnose.md §3 (issue 22: every plan):
#   scenarios/undeclared/false_alarm.sh 20 100
#   SCENARIO=scenarios/gro-early-mission.toml scenarios/undeclared/false_alarm.sh 20 200
#   SCENARIO=scenarios/gro-early-mission-orbit-holds.toml scenarios/undeclared/false_alarm.sh 20 300
#   SCENARIO=scenarios/gro-early-mission-reordered.toml scenarios/undeclared/false_alarm.sh 20 400
#   SCENARIO=scenarios/undeclared/clean-three-rates.toml scenarios/undeclared/false_alarm.sh 20 500
#
# Uses the release binaries if built and current (cargo build --release -p sim-harness -p
# ground-tool), else the dev ones (BIN=dir overrides). About 5 s per seed in the dev profile.
set -euo pipefail
N=${1:-20}
FIRST=${2:-100}
WORK=${3:-/tmp/diagnose-fa}
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
BIN=${BIN:-$ROOT/target/release}
# Fall back to the dev build when the release one is missing or predates `diagnose`.
if ! { [ -x "$BIN/sim-harness" ] && "$BIN/ground-tool" diagnose --help >/dev/null 2>&1; }; then
  BIN=$ROOT/target/debug
fi
mkdir -p "$WORK"
alarms=0
for ((k = 0; k < N; k++)); do
  seed=$((FIRST + k))
  run=$WORK/run-$seed
  "$BIN/sim-harness" run "${SCENARIO:-$ROOT/scenarios/undeclared/clean.toml}" --out "$run" --seed "$seed" --force -q >/dev/null 2>&1
  "$BIN/ground-tool" diagnose "$run" --out "$WORK/diag-$seed" --force --json >"$WORK/diag-$seed.json" 2>/dev/null || {
    echo "seed $seed: diagnose failed (exit $?)"; alarms=$((alarms + 1)); continue; }
  line=$(python3 - "$WORK/diag-$seed.json" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
d = [f"{x['effect']}[{x['sensor']}]" for x in r["detected"]]
u = [f"{x['sensor']}:{x['axis']}~{x['regressor']} ({x['size']:.2f}\", p {x['p_value']:.1e})" for x in r["unexplained"]]
print(("ALARM" if d or u else "ok"), "detected:", d, "unexplained:", u)
PY
)
  echo "seed $seed: $line"
  case $line in ALARM*) alarms=$((alarms + 1)) ;; esac
done
echo "false alarms: $alarms / $N"
