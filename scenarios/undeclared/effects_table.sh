#!/usr/bin/env bash
# Per-effect bench of `ground-tool diagnose` (issue 5, must-show 1): every scenario of this
# folder (one undeclared effect each) flown with each seed, diagnosed, and flown again with
# the tables diagnose wrote. One line per (scenario, seed):
#
#   expected   the effect[sensor] the scenario switches on (from its first comment line)
#   named      diagnose detected it (and nothing outside the truth: "+extra" otherwise); for an
#              effect outside diagnose's library (EXPECT_UNEXPLAINED): reported as unexplained
#              structure on its sensor against its regressor, and the IRU table diagnose
#              wrote (report.json flight_tables.applied: "as flown" is right when the gyro
#              holds unexplained structure, "G updated" is not)
#   params     parameters within 3 sigma of the truth / parameters scored, and max |z|
#   rms/floor  the expected sensor's residual RMS after the loop over its noise floor (arcsec)
#   cal err    calibration error of that sensor before -> after (arcsec, scored against
#              truth.json: the measurement model over the measured field, report.json)
#   written    error of the alignment tables written (report.json written_table_error_arcsec:
#              calibrate's -> diagnose's, every sensor with data; "worse" = a sensor more than
#              0.5 arcsec worse in diagnose's), and the components diagnose's held-out
#              validation took (report.json flight_tables.validation)
#   att err    closed-loop attitude error (|rms| over the three axes, arcsec, t >= 600 s,
#              outside slews, sim-harness summary.json) flown with the tables flown before
#              -> flown with the diagnose tables (`sim-harness run SCEN --tables DIAG/tables`)
#
#   scenarios/undeclared/effects_table.sh [SEEDS="1 2 3"] [WORK=/tmp/diagnose-effects]
#   ONLY="fss-transfer fhst1-time-tag" scenarios/undeclared/effects_table.sh "1 2"
#
# Uses the release binaries if built (cargo build --release -p sim-harness -p ground-tool -p tests),
# else the dev ones (BIN=dir overrides). About 2 s per line with release binaries.
set -euo pipefail
SEEDS=${1:-"1 2 3"}
WORK=${2:-/tmp/diagnose-effects}
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
BIN=${BIN:-$ROOT/target/release}
# The scoring against truth.json is the tests crate's (`diagnose-scored`: ground-tool diagnose
# plus the scores; the ground tool never reads the truth): cargo build --release -p sim-harness -p tests.
if ! { [ -x "$BIN/sim-harness" ] && [ -x "$BIN/diagnose-scored" ]; }; then
  BIN=$ROOT/target/debug
fi
mkdir -p "$WORK"
: >"$WORK/lines.jsonl"
for f in "$ROOT"/scenarios/undeclared/*.toml; do
  name=$(basename "$f" .toml)
  case $name in clean | clean-*) continue ;; esac  # the clean plans: false_alarm.sh
  if [ -n "${ONLY:-}" ] && [[ " $ONLY " != *" $name "* ]]; then continue; fi
  for seed in $SEEDS; do
    run=$WORK/$name-$seed
    "$BIN/sim-harness" run "$f" --out "$run" --seed "$seed" --force -q >/dev/null 2>&1
    if ! "$BIN/diagnose-scored" "$run" --out "$run-diag" --force --json >"$run-diag.json" 2>"$run-diag.err"; then
      echo "{\"scenario\": \"$name\", \"seed\": $seed, \"error\": \"diagnose failed\"}" >>"$WORK/lines.jsonl"
      continue
    fi
    "$BIN/sim-harness" run "$f" --out "$run-after" --seed "$seed" --tables "$run-diag/tables" --force -q >/dev/null 2>&1
    python3 - "$f" "$name" "$seed" "$run" >>"$WORK/lines.jsonl" <<'PY'
import json, math, re, sys
scen, name, seed, run = sys.argv[1:5]
# The effects each scenario switches on: a list of effects, each a list of alternatives
# that name the same physics.
EXPECT = {
    "aberration": [[("aberration", "all"), ("aberration_annual", "all")]],
    "catalog": [[("catalog_proper_motion_error", "all")]],
    "fhst1-distortion": [[("fhst_distortion", "FHST1")]],
    "fhst1-magnitude": [[("magnitude_bias", "FHST1")]],
    "fhst1-time-tag": [[("time_tag_offset", "FHST1")]],
    "fhst2-thermal": [[("thermal_alignment_drift", "FHST2"), ("orbit_periodic_alignment", "FHST2")]],
    "fss-transfer": [[("fss_transfer_function", "FSS2")]],
    "fss2-time-tag": [[("time_tag_offset", "FSS2")]],
    "iru-asymmetry": [[("gyro_scale_asymmetry", "IRU")]],
    "iru-thermal-bias": [[("gyro_thermal_bias", "IRU")]],
    "iru-bias-drift": [[("gyro_bias_transient", "IRU"), ("gyro_bias_ramp", "IRU")]],
    "fhst1-step": [[("alignment_step", "FHST1")]],
    # The same time tag on every sensor: each sensor with data gets it, absolute against the
    # gyro (FSS1 never sees the Sun in this plan).
    "common-time-tag": [
        [("time_tag_offset", "FHST1")],
        [("time_tag_offset", "FHST2")],
        [("time_tag_offset", "FSS2")],
    ],
    "combo": [
        [("time_tag_offset", "FHST1")],
        [("fhst_distortion", "FHST1")],
        [("thermal_alignment_drift", "FHST2"), ("orbit_periodic_alignment", "FHST2")],
        [("time_tag_offset", "FSS2")],
    ],
}
# Effects outside diagnose's library: (sensor, regressor) of the unexplained structure
# they should be reported as (report.json unexplained).
EXPECT_UNEXPLAINED = {
    "iru-mode-bias": ("IRU", "rate_mode"),
    "iru-rate-power": ("IRU", "slew_rate"),
    "iru-scale-step": ("IRU", "time_s"),
}
groups = EXPECT.get(name, [])
exp = [a for g in groups for a in g]
r = json.load(open(run + "-diag.json"))
sc = r.get("scoring") or {}
det = [(d["effect"], d["sensor"]) for d in r["detected"]]
inside = {(e, s): ok for e, s, ok in sc.get("detections_in_truth", [])}
exp_names = {e for e, _ in exp}
found = sum(any((e, s) in g for e, s in det) for g in groups)
named = bool(groups) and found == len(groups)
exp_un = EXPECT_UNEXPLAINED.get(name)
if exp_un:
    named = any(u["sensor"] == exp_un[0] and u["regressor"] == exp_un[1] for u in r["unexplained"])
iru_note = next((a for a in r["flight_tables"].get("applied", []) if a.startswith("IRU table")), "")
iru_table = ("as flown (unexplained)" if iru_note.startswith("IRU table as flown: the gyro residuals hold unexplained")
             else "as flown" if iru_note.startswith("IRU table as flown") else "G updated" if iru_note else None)
extra = [f"{e}[{s}]" for e, s in det if not inside.get((e, s), False)]
params = [p for p in sc.get("parameters", []) if not p["parameter"].startswith("HIP")]
stars = [p for p in sc.get("parameters", []) if p["parameter"].startswith("HIP")]
def pz(ps):
    zs = [abs(p["z"]) for p in ps if math.isfinite(p["z"])]
    return (sum(z <= 3 for z in zs), len(zs), max(zs) if zs else float("nan"))
sensors = sorted({s for _, s in exp if s not in ("IRU", "all")}) or ["FHST1", "FHST2"]
rb, ra, fl = r["residual_rms_arcsec"]["before"], r["residual_rms_arcsec"]["after"], r["noise_floor_arcsec"]
ce = r.get("calibration_error_arcsec") or {"before": {}, "after": {}}
def att(d):
    s = json.load(open(d + "/summary.json"))["attitude_error_arcsec"]["rms"]
    return math.sqrt(sum(x * x for x in s))
out = {
    "scenario": name, "seed": int(seed),
    "expected": [" or ".join(f"{e}[{s}]" for e, s in g) for g in groups],
    "found": [found, len(groups)],
    "detected": [f"{e}[{s}]" for e, s in det],
    "named": named, "extra": extra,
    "params": pz(params), "stars": pz(stars),
    "param_detail": [(p["effect"], p["sensor"], p["parameter"], p["estimate"], p["sigma"], p["truth"], p["z"]) for p in params],
    "unexplained": [f"{u['sensor']}:{u['axis']}~{u['regressor']}" for u in r["unexplained"]],
    "rms": {s: (rb.get(s), ra.get(s), fl.get(s)) for s in sensors},
    "cal": {s: (ce["before"].get(s), ce["after"].get(s)) for s in sensors},
    "att": (att(run), att(run + "-after")),
    "written": {k: (v, (r.get("written_table_error_arcsec") or {}).get("after", {}).get(k),
                    (r.get("unvalidated_table_error_arcsec") or {}).get(k))
                for k, v in (r.get("written_table_error_arcsec") or {}).get("before", {}).items()},
    "taken": [t["component"] for t in (r["flight_tables"].get("validation") or {}).get("taken", [])],
    "expect_unexplained": list(exp_un) if exp_un else None,
    "iru_table": iru_table,
}
print(json.dumps(out))
PY
    tail -n 1 "$WORK/lines.jsonl" | python3 -c 'import json,sys; d=json.loads(sys.stdin.read()); print(d.get("scenario"), d.get("seed"), d.get("detected", d.get("error")))' >&2
  done
done
python3 - "$WORK/lines.jsonl" <<'PY'
import json, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
f = lambda x: "–" if x is None else f"{x:.1f}"
print("| scenario | seed | expected | detected | named | params ≤3σ (max abs z) | RMS after / floor (″) | cal err before → after (″) | att err before → after (″) |")
print("|---|---|---|---|---|---|---|---|---|")
ok = 0
for d in rows:
    if "error" in d:
        print(f"| {d['scenario']} | {d['seed']} | | diagnose failed | no | | | | |"); continue
    n, m, z = d["params"]
    ps = f"{n}/{m} ({z:.1f})" if m else "–"
    if d["stars"][1]:
        sn, sm, sz = d["stars"]
        ps += f"; stars {sn}/{sm}"
    rms = ", ".join(f"{s} {f(v[1])}/{f(v[2])}" for s, v in d["rms"].items())
    cal = ", ".join(f"{s} {f(v[0])} → {f(v[1])}" for s, v in d["cal"].items())
    named = ("yes" if d["named"] else "no") + (f" ({d['found'][0]}/{d['found'][1]})" if d["found"][1] > 1 else "") + (" +" + ",".join(d["extra"]) if d["extra"] else "")
    exp = ", ".join(d["expected"])
    if d.get("expect_unexplained"):
        exp = "(unexplained {}~{})".format(*d["expect_unexplained"])
        named += f"; IRU table {d.get('iru_table')}"
    det = ", ".join(d["detected"]) or "none"
    if d["unexplained"]:
        det += "; unexplained " + ", ".join(d["unexplained"])
    print(f"| {d['scenario']} | {d['seed']} | {exp} | {det} | {named} | {ps} | {rms} | {cal} | {d['att'][0]:.1f} → {d['att'][1]:.1f} |")
    ok += d["named"] and not d["extra"]
print(f"\nnamed right (and nothing else) in {ok} of {len(rows)} runs")
un_rows = [d for d in rows if "error" not in d and d.get("expect_unexplained")]
if un_rows:
    bad_iru = [d for d in un_rows if d.get("iru_table") == "G updated"]
    print(f"\noutside the library: unexplained on the right regressor in {sum(d['named'] for d in un_rows)} of {len(un_rows)} runs; "
          f"IRU table written (G updated) in {len(bad_iru)} of {len(un_rows)}"
          + (": " + ", ".join(f"{d['scenario']} {d['seed']}" for d in bad_iru) if bad_iru else ""))
def worst(d, col=1):
    return max((v[col] - v[0] for v in d.get("written", {}).values() if v[col] is not None and v[0] is not None), default=0.0)
print("\n| scenario | seed | tables written: calibrate's → diagnose's [without the validation] (″) | worst Δ [without] (″) | components taken |")
print("|---|---|---|---|---|")
for d in rows:
    if "error" in d:
        continue
    w = ", ".join(f"{s} {f(v[0])} → {f(v[1])} [{f(v[2] if len(v) > 2 else None)}]" for s, v in d.get("written", {}).items())
    print(f"| {d['scenario']} | {d['seed']} | {w} | {worst(d):+.1f} [{worst(d, 2):+.1f}] | {', '.join(d.get('taken', [])) or 'none'} |")
bad0 = [d for d in rows if "error" not in d and worst(d, 2) > 0.5]
print(f"\nwithout the held-out validation: worse than calibrate's by more than 0.5″ on a sensor in {len(bad0)} of {len(rows)} runs")
bad = [d for d in rows if "error" not in d and worst(d) > 0.5]
print(f"\ndiagnose's written alignment table worse than calibrate's by more than 0.5″ on a sensor in {len(bad)} of {len(rows)} runs" + (": " + ", ".join(f"{d['scenario']} {d['seed']}" for d in bad) if bad else ""))
# Per scenario over the seeds.
print("\n| scenario | runs | named (nothing else) | params within 3σ | RMS after / floor, worst | cal err before → after, mean (″) | att err before → after, mean (″) |")
print("|---|---|---|---|---|---|---|")
by = {}
for d in rows:
    by.setdefault(d["scenario"], []).append(d)
mean = lambda xs: sum(xs) / len(xs) if xs else float("nan")
for name, ds in by.items():
    good = [d for d in ds if "error" not in d]
    named = sum(d["named"] and not d["extra"] for d in good)
    pn = sum(d["params"][0] + d["stars"][0] for d in good)
    pm = sum(d["params"][1] + d["stars"][1] for d in good)
    ratios = [v[1] / v[2] for d in good for v in d["rms"].values() if v[1] and v[2]]
    cb = [v[0] for d in good for v in d["cal"].values() if v[0] is not None]
    ca = [v[1] for d in good for v in d["cal"].values() if v[1] is not None]
    ab = [d["att"][0] for d in good]
    aa = [d["att"][1] for d in good]
    print(f"| {name} | {len(ds)} | {named}/{len(ds)} | {pn}/{pm} | {max(ratios):.3f} | {mean(cb):.1f} → {mean(ca):.1f} | {mean(ab):.1f} → {mean(aa):.1f} |")
PY
# The evidence ledger's invariant on every diagnosed run (issue 22).
python3 "$ROOT/scenarios/undeclared/ledger_check.py" "$WORK"/*-diag.json | tail -n 1 || true
