#!/usr/bin/env bash
# The paper's case (issue 5, must-show 4): gro-early-mission flown with the harness's FSS
# transfer-function errors in the truth (the default) and, with the same seed, without them
# (every FSS head coefficient zero); then IRUCAL (Davenport delta-M, through the calibration
# chain's API) with the effect not modelled, with the correction diagnose writes, with the
# truth's table terms, and on the run without the effect, against the paper's delta-M 1 sigma.
#
#   scenarios/undeclared/paper_case.sh [SEEDS="1 2 3 4 5"] [WORK=/tmp/diagnose-paper]
#
# Needs the release test build (cargo test --release compiles it the first time).
set -euo pipefail
SEEDS=${1:-"1 2 3 4 5"}
WORK=${2:-/tmp/diagnose-paper}
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
BIN=${BIN:-$ROOT/target/release}
mkdir -p "$WORK"
# The scenario without the transfer-function errors: gro-early-mission + zero head errors.
NOTF=$WORK/gro-early-mission-no-fss-tf.toml
{
  cat "$ROOT/scenarios/gro-early-mission.toml"
  for u in fss1 fss2; do
    for h in alpha beta; do
      printf '\n[%s.%s]\nscale_ppm = 0.0\ncyclic_arcsec = 0.0\ncross_arcsec_at_corner = 0.0\ncubic_arcsec_at_edge = 0.0\n' "$u" "$h"
    done
  done
} >"$NOTF"
pairs=()
for seed in $SEEDS; do
  "$BIN/sim-harness" run gro-early-mission --out "$WORK/tf-$seed" --seed "$seed" --force -q >/dev/null 2>&1
  "$BIN/sim-harness" run "$NOTF" --out "$WORK/notf-$seed" --seed "$seed" --force -q >/dev/null 2>&1
  pairs+=("$WORK/tf-$seed:$WORK/notf-$seed")
done
cd "$ROOT"
PAIRS=$(IFS=,; echo "${pairs[*]}") cargo test -q --release -p tests --test diagnose_paper -- --ignored --nocapture 2>&1 |
  grep -v '^running\|^test \|^$\|test result'
