#!/usr/bin/env bash
# What each flight-table hook of `ground-tool diagnose` does to the closed loop by itself
# (issue 5, "Into the flight model"): for every run of an `effects_table.sh` work folder whose
# scenario has a hook, fly the scenario again with the diagnose tables but the hook's table
# fields set to zero (everything else, alignments included, as diagnose wrote it), and print
# the attitude error before (tables flown) -> after (diagnose tables) and with the hook off.
# The difference after - hook off is the hook's own effect; after - before also contains the
# re-estimated alignments.
#
#   scenarios/undeclared/effects_table.sh "1 2 3 4 5" /tmp/diagnose-effects   # first
#   scenarios/undeclared/hook_ablation.sh /tmp/diagnose-effects
#
# Hooks and the fields zeroed (byte layout: docs/tables.md, Tables 1 and 2):
#   fhst1-magnitude  alignment fhst_magnitude_bias_rad_per_mag (payload octets 464..496)
#   fhst2-thermal    alignment thermal_alignment_rad_per_c (496..592)
#   fss-transfer     alignment fss_cubic and fss_cyclic (624..736)
#   iru-asymmetry    iru scale_asymmetry_primary and _backup (the last 48 payload octets)
# att err: |rms| over the three axes (arcsec, t >= 600 s, outside slews, summary.json).
set -euo pipefail
WORK=${1:-/tmp/diagnose-effects}
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
BIN=${BIN:-$ROOT/target/release}
[ -x "$BIN/sim-harness" ] || BIN=$ROOT/target/debug
OUT=$WORK/ablation.jsonl
: >"$OUT"
for name in fhst1-magnitude fhst2-thermal fss-transfer iru-asymmetry; do
  for diag in "$WORK/$name"-*-diag; do
    [ -d "$diag/tables" ] || continue
    seed=${diag%-diag}
    seed=${seed##*-}
    off=$WORK/$name-$seed-hookoff-tables
    rm -rf "$off"
    cp -r "$diag/tables" "$off"
    python3 - "$name" "$off" <<'PY'
import struct, sys, zlib
name, d = sys.argv[1:3]
# (file, first payload octet, number of f64) of the hook's fields; negative = from the end.
FIELDS = {
    "fhst1-magnitude": ("alignment.tbl", 464, 4),
    "fhst2-thermal": ("alignment.tbl", 496, 12),
    "fss-transfer": ("alignment.tbl", 624, 14),
    "iru-asymmetry": ("iru.tbl", -48, 6),
}
f, at, n = FIELDS[name]
b = bytearray(open(f"{d}/{f}", "rb").read())
payload = len(b) - 24
start = 20 + (at if at >= 0 else payload + at)
b[start:start + 8 * n] = bytes(8 * n)
struct.pack_into(">I", b, len(b) - 4, zlib.crc32(bytes(b[:-4])) & 0xFFFFFFFF)
open(f"{d}/{f}", "wb").write(b)
PY
    # The images were changed on purpose: name them again (docs/tables.md, "Tables folders").
    "$BIN/ground-tool" table manifest "$off" >/dev/null
    "$BIN/sim-harness" run "$ROOT/scenarios/undeclared/$name.toml" --out "$WORK/$name-$seed-hookoff" \
      --seed "$seed" --tables "$off" --force -q >/dev/null 2>&1
    python3 - "$WORK" "$name" "$seed" >>"$OUT" <<'PY'
import json, math, sys
work, name, seed = sys.argv[1:4]
def att(d):
    s = json.load(open(f"{d}/summary.json"))["attitude_error_arcsec"]["rms"]
    return math.sqrt(sum(x * x for x in s))
r = json.load(open(f"{work}/{name}-{seed}-diag.json"))
run = f"{work}/{name}-{seed}"
print(json.dumps({"scenario": name, "seed": int(seed),
                  "detected": [f"{d['effect']}[{d['sensor']}]" for d in r["detected"]],
                  "before": att(run), "after": att(run + "-after"), "hook_off": att(run + "-hookoff")}))
PY
    tail -n 1 "$OUT" >&2
  done
done
python3 - "$OUT" <<'PY'
import json, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
print("| scenario | seed | detected | att err before → after (″) | hook off (″) | hook's own effect (″) |")
print("|---|---|---|---|---|---|")
for d in rows:
    print(f"| {d['scenario']} | {d['seed']} | {', '.join(d['detected']) or 'none'} | {d['before']:.1f} → {d['after']:.1f} | {d['hook_off']:.1f} | {d['after'] - d['hook_off']:+.1f} |")
print()
print("| scenario | runs | att err before → after, mean (″) | hook off, mean (″) | hook's own effect, mean (″) |")
print("|---|---|---|---|---|")
by = {}
for d in rows:
    by.setdefault(d["scenario"], []).append(d)
m = lambda xs: sum(xs) / len(xs)
for name, ds in by.items():
    b, a, o = m([d["before"] for d in ds]), m([d["after"] for d in ds]), m([d["hook_off"] for d in ds])
    print(f"| {name} | {len(ds)} | {b:.1f} → {a:.1f} | {o:.1f} | {a - o:+.1f} |")
PY
