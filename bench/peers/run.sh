#!/usr/bin/env bash
# Peer speed benchmark: Basilisk (bsk 2.12.x from PyPI) vs our sim-harness, same closed loop.
#
#   bench/peers/run.sh [--duration S] [--repeats N] [--skip-ours] [--skip-basilisk]
#
# 1. creates bench/peers/.venv (git-ignored) and pip-installs bsk 2.12.x + numba if missing,
# 2. runs basilisk_gro.py (median of N runs, sim loop only),
# 3. runs ours: cargo run --release -p sim-harness -- bench --duration S --json
#    (skipped, with a message, while sim-harness has no `bench` subcommand),
# 4. prints a Markdown table with both real-time factors and the ratio ours/basilisk.
# Defaults: --duration 3600 --repeats 5. The machine has 2 shared cores: timings are noisy.
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
ROOT="$(cd "$HERE/../.." && pwd)"
VENV="$HERE/.venv"
DURATION=3600
REPEATS=5
RUN_OURS=1
RUN_BSK=1
BSK_SPEC='bsk>=2.12,<2.13'

while [ $# -gt 0 ]; do
  case "$1" in
    --duration) DURATION="$2"; shift 2 ;;
    --repeats) REPEATS="$2"; shift 2 ;;
    --skip-ours) RUN_OURS=0; shift ;;
    --skip-basilisk) RUN_BSK=0; shift ;;
    -h|--help) sed -n '2,13p' "$0"; exit 0 ;;
    *) echo "run.sh: unknown argument $1" >&2; exit 2 ;;
  esac
done

OUT="$(mktemp -d)"
trap 'rm -rf "$OUT"' EXIT

# ---- Basilisk -------------------------------------------------------------------------------
pick_python() {
  for py in python3.11 python3.12 python3.10 python3; do
    if command -v "$py" >/dev/null 2>&1 &&
       "$py" -c 'import sys; sys.exit(0 if (3, 9) <= sys.version_info[:2] < (3, 14) else 1)'; then
      echo "$py"; return 0
    fi
  done
  return 1
}

if [ "$RUN_BSK" = 1 ]; then
  if [ ! -x "$VENV/bin/python" ]; then
    PY="$(pick_python)" || { echo "run.sh: need Python 3.9-3.13 for the bsk wheel" >&2; exit 1; }
    echo ">> creating $VENV with $PY" >&2
    "$PY" -m venv "$VENV"
  fi
  if ! "$VENV/bin/python" -c 'import Basilisk, numba' >/dev/null 2>&1; then
    echo ">> pip install '$BSK_SPEC' numba into $VENV" >&2
    "$VENV/bin/python" -m pip install --quiet --upgrade pip >&2
    "$VENV/bin/python" -m pip install --quiet "$BSK_SPEC" numba >&2
  fi
  echo ">> Basilisk: $DURATION s simulated, $REPEATS repeats" >&2
  "$VENV/bin/python" "$HERE/basilisk_gro.py" --duration "$DURATION" --repeats "$REPEATS" --verbose \
    2> "$OUT/basilisk.err" | tail -n 1 > "$OUT/basilisk.json" || {
      echo "run.sh: the Basilisk run failed:" >&2; cat "$OUT/basilisk.err" >&2; exit 1; }
  grep -v 'unwritten message\|^\[FILE' "$OUT/basilisk.err" >&2 || true
  cat "$OUT/basilisk.json"
fi

# ---- ours -----------------------------------------------------------------------------------
OURS_NOTE=""
if [ "$RUN_OURS" = 1 ]; then
  echo ">> ours: cargo run --release -p sim-harness -- bench --duration $DURATION --json" >&2
  if (cd "$ROOT" && cargo run --release -q -p sim-harness -- bench --duration "$DURATION" --json) \
       > "$OUT/ours.out" 2> "$OUT/ours.err" &&
     grep '^{' "$OUT/ours.out" | tail -n 1 > "$OUT/ours.json" &&
     grep -q '"real_time_factor"' "$OUT/ours.json"; then
    cat "$OUT/ours.json"
  else
    rm -f "$OUT/ours.json"
    OURS_NOTE="skipped: sim-harness has no working \`bench --json\` subcommand yet (no JSON with real_time_factor on stdout)"
    echo ">> ours $OURS_NOTE" >&2
    tail -n 5 "$OUT/ours.err" >&2 || true
  fi
else
  OURS_NOTE="skipped (--skip-ours)"
fi

# ---- table ----------------------------------------------------------------------------------
PYFMT="$VENV/bin/python"; [ -x "$PYFMT" ] || PYFMT="$(pick_python)"
OURS_NOTE="$OURS_NOTE" "$PYFMT" - "$OUT" <<'EOF'
import json, os, sys
out = sys.argv[1]
def load(name):
    p = os.path.join(out, name)
    if os.path.exists(p) and os.path.getsize(p) > 0:
        with open(p) as f:
            return json.load(f)
    return None
b, o = load("basilisk.json"), load("ours.json")
def cell(x, fmt):
    return fmt.format(x) if isinstance(x, (int, float)) else "n/a"
print()
print("| simulator | step (s) | simulated (s) | wall, median (s) | real-time factor |")
print("|---|---|---|---|---|")
if b:
    print(f"| Basilisk {b['bsk_version']} ({b['repeats']} runs) | {b['step_s']} | {b['sim_seconds']:g} "
          f"| {b['wall_seconds']:.3f} | {b['real_time_factor']:.0f} |")
if o:
    print(f"| ours (sim-harness) | {cell(o.get('step_s'), '{}')} | {cell(o.get('sim_seconds'), '{:g}')} "
          f"| {cell(o.get('wall_seconds'), '{:.3f}')} | {o['real_time_factor']:.0f} |")
else:
    print(f"| ours (sim-harness) | | | | {os.environ.get('OURS_NOTE') or 'n/a'} |")
print()
if b and o:
    print(f"ratio ours/basilisk (real-time factor): **{o['real_time_factor'] / b['real_time_factor']:.2f}**")
else:
    print("ratio ours/basilisk: n/a")
EOF
