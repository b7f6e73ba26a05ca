#!/usr/bin/env python3
"""Diagnose on telemetry from the independent ICD writer (tests/icd/write_run.py), with
undeclared effects injected by the writer; scored against the writer's truth_icd.json.

    cargo build --release -p ground-tool
    python3 tests/icd/diagnose_cases.py [--seeds "1 2 3"] [--work /tmp/icd-diagnose] [CASE ...]

Every case flies the writer's long plan (13 holds of 1200 s, 12 out-and-back slews about
every body axis, 5.7 h, ≈ 3.6 orbits), so the runs differ only in what is injected.

Columns of the per-run table:
  expected   the injected library effects as effect[sensor] (out-of-library ones in
             parentheses with the regressor their structure should be reported against)
  named      yes: every expected effect detected on its sensor and nothing else detected
  params     parameters within 3σ of the injected truth / parameters compared (max |z|)
  unexplained sensor:regressor (size ″, Holm p); "ok" when an out-of-library effect is
             reported on its sensor (or the other tracker: only the relative FHST alignment
             is observable) against one of its expected regressors as the leading one
  tables     FHST1–FHST2 relative alignment error (″) of the table `calibrate` writes for the
             same telemetry → of the table diagnose writes, against the writer's injected
             rotations (a step case: the rotation after the step, which the tables fly
             into); "worse" when diagnose's
             is more than 0.5″ worse
  verdict    PASS when named, all parameters within 3σ, every out-of-library effect
             reported as unexplained against a sensible regressor, and no other
             unexplained structure (structure on any sensor against an out-of-library
             effect's expected regressor, or on its sensor or the other tracker against
             any regressor, counts as that effect's)
"""

import json
import os
import shutil
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.normpath(os.path.join(HERE, "..", ".."))
sys.path.insert(0, os.path.join(ROOT, "scenarios", "undeclared"))
import ledger_check  # noqa: E402  (the evidence ledger's invariant on report.json)
from cases_cli import parser, selected_cases, write_json  # noqa: E402

BASE = ["--plan", "long", "--hold-s", "1200"]

# name -> writer flags. Sizes from docs/algorithms.md §9 (typical sizes) where it gives one.
CASES = {
    "clean": [],
    # --- single library effects
    "fhst1-time-tag": ["--time-tag", "FHST1:0.08"],  # 23″ at the 0.08°/s slew rate
    "fss1-time-tag": ["--time-tag", "FSS1:0.2"],  # 58″ at 0.08°/s
    "fss1-time-tag-large": ["--time-tag", "FSS1:0.4"],  # 115″ at 0.08°/s: beyond the outlier cut
    "fhst2-orbit-1+2": ["--temps", "flat", "--orbit-align",
                        "FHST2:4,-3,6,-2,5,3,2,-1,3,1,2,-2"],  # once ≈ 5–7″, twice ≈ 2–3″ per axis
    "fhst2-orbit-1": ["--temps", "flat", "--orbit-align", "FHST2:4,-3,6,-2,5,3"],
    "fhst1-distortion": ["--fhst-radial", "FHST1:15"],  # radial 15″ at 4° (21″ at the corners)
    "fss1-transfer": ["--fss-transfer", "FSS1:alpha_scale=300,beta_cubic=40"],
    "gyro-asymmetry": ["--gyro-asym", "100,-80,120"],  # ppm, §9 row 9: 10–100 ppm
    "gyro-ramp": ["--gyro-ramp", "0.003,-0.002,0.004"],  # ″/s per hour (0.017–0.023″/s over the run)
    "gyro-ramp-x3": ["--gyro-ramp", "0.009,-0.006,0.012"],  # detection-limit probe
    "gyro-bias-step": ["--gyro-bias-step", "10000:0.02,-0.015,0.02"],  # ″/s at an unknown time
    "gyro-bias-step-small": ["--gyro-bias-step", "6000:0.008,-0.006,0.008"],  # detection-limit probe
    # --- outside the library
    "gyro-mode-bias": ["--gyro-mode-bias", "0.02,-0.015,0.02"],  # ″/s in high rate only (15″ over a 60° slew)
    "gyro-mode-bias-small": ["--gyro-mode-bias", "0.006,-0.004,0.006"],  # detection-limit probe
    "gyro-rate2-3rates": ["--slew-rates", "0.04,0.08,0.16",
                          "--gyro-rate2", "10000,-8000,12000"],  # ppm at 1°/s: 13–307 ppm over the rates
    "gyro-scale-step": ["--gyro-scale-step", "10000:300,-250,300"],  # ppm from mid-run: 32″ on a 30° slew
    "clean-3rates": ["--slew-rates", "0.04,0.08,0.16"],  # control for the rate case
    # each axis out and back at 0.04 and at 0.16 °/s: a rate² scale is separable from an asymmetry
    "gyro-rate2-2rates": ["--slew-rates", "0.04,0.04,0.16,0.16",
                          "--gyro-rate2", "10000,-8000,12000"],
    "asym-2rates": ["--slew-rates", "0.04,0.04,0.16,0.16", "--gyro-asym", "100,-80,120"],
    "fhst2-ringing": ["--ringing", "FHST2:8,-6,10:40:120"],  # 14″ after each slew, 40 s, 120 s decay
    "fhst2-ringing-x2": ["--ringing", "FHST2:16,-12,20:40:120"],  # detection-limit probe
    "fhst1-step": ["--align-step", "FHST1:10000:0,12,-8"],  # 14″ once, mid-run
    # --- combinations
    "combo-tt+distortion": ["--time-tag", "FHST1:0.08", "--fhst-radial", "FHST1:15"],
    "combo-orbit+asym": ["--temps", "flat", "--orbit-align", "FHST2:4,-3,6,-2,5,3",
                         "--gyro-asym", "100,-80,120"],
    "combo-fss-tt+ramp+step": ["--time-tag", "FSS1:0.2", "--gyro-ramp", "0.003,-0.002,0.004",
                               "--align-step", "FHST1:10000:0,12,-8"],
    # --- from the outside reviews (docs/diagnose.md §9)
    "fhst2-time-tag": ["--time-tag", "FHST2:0.1"],
    "no-ephemeris": ["--no-eph"],  # clean, the orbit unknown to the ground
    "fss1-step": ["--align-step", "FSS1:10000:20,-15,10"],  # out of library, 27″ once
    "fhst2-step+orbit": ["--temps", "flat", "--orbit-align", "FHST2:4,-3,6,-2,5,3",
                         "--align-step", "FHST2:10000:0,12,-8"],
    "asym+ramp": ["--gyro-asym", "100,-80,120", "--gyro-ramp", "0.009,-0.006,0.012"],
    "hold600-dist+fss-tf": ["--hold-s", "600", "--fhst-radial", "FHST2:30",
                            "--fss-transfer", "FSS1:alpha_scale=300,beta_cubic=40"],
}

OTHER_TRACKER = {"FHST1": "FHST2", "FHST2": "FHST1"}


def score(truth, report):
    effects = truth.get("effects", [])
    lib = [e for e in effects if e.get("in_library")]
    out_lib = [e for e in effects if not e.get("in_library")]
    detected = report.get("detected", [])
    unexpl = report.get("unexplained", [])
    expected = {(e["effect"], e["sensor"]) for e in lib}
    got = [(d["effect"], d["sensor"]) for d in detected]
    named = all(x in got for x in expected)
    extra = [f"{a}[{b}]" for (a, b) in got if (a, b) not in expected]
    missing = [f"{a}[{b}]" for (a, b) in sorted(expected) if (a, b) not in got]
    n_par = n_ok = 0
    zmax = 0.0
    bad = []
    for e in lib:
        for d in detected:
            if (d["effect"], d["sensor"]) != (e["effect"], e["sensor"]):
                continue
            for k, t in e["parameters"].items():
                if k not in d["parameters"]:
                    n_par += 1  # a parameter of the truth the detected form lacks
                    bad.append(f"{e['sensor']}.{k} not estimated (truth {t:g})")
                    continue
                if d["sigma"].get(k):
                    z = (d["parameters"][k] - t) / d["sigma"][k]
                    n_par += 1
                    n_ok += abs(z) <= 3.0
                    zmax = max(zmax, abs(z))
                    if abs(z) > 3.0:
                        bad.append(f"{e['sensor']}.{k} {d['parameters'][k]:.3g}±{d['sigma'][k]:.2g} (truth {t:g})")
    # Unexplained structure: which entries are accounted for?
    accounted = set()
    out_ok = []
    for e in out_lib:
        sensors = {e["sensor"], OTHER_TRACKER.get(e["sensor"], e["sensor"])}
        follows = set(e.get("unexplained_should_follow", []))
        hit = [i for i, u in enumerate(unexpl)
               if u["sensor"] in sensors
               and follows & ({u["regressor"]} | set(u.get("also_follows", [])))]
        out_ok.append(bool(hit))
        # Structure of the same effect seen on the other tracker against another regressor
        # (relative alignment) is still this effect's, and so is the same structure on any
        # sensor against the expected regressor (through the attitude every sensor sees an
        # FHST's step): accounted for.
        accounted.update(i for i, u in enumerate(unexpl) if u["sensor"] in sensors
                         or u["regressor"] in e.get("unexplained_should_follow", []))
    extra_unexpl = [u for i, u in enumerate(unexpl) if i not in accounted]
    ok = (named and not extra and n_ok == n_par and all(out_ok) and not extra_unexpl)
    return {
        "expected": sorted(f"{a}[{b}]" for (a, b) in expected)
        + [f"({e['effect']}[{e['sensor']}] → {'/'.join(e['unexplained_should_follow'])})" for e in out_lib],
        "detected": [f"{a}[{b}]" for (a, b) in got],
        "named": named and not extra,
        "missing": missing,
        "extra": extra,
        "params_ok": n_ok,
        "params_n": n_par,
        "zmax": zmax,
        "params_bad": bad,
        "out_of_library_ok": out_ok,
        "unexplained": [f"{u['sensor']}:{u['regressor']} ({u['size']:.1f}″, p {u['p_value']:.0e})"
                        for u in unexpl],
        "extra_unexplained": len(extra_unexpl),
        "ledger_violations": ledger_check.violations(report),
        "pass": ok,
    }


def run_one(case, seed, args):
    run = os.path.join(args.work, f"{case}-s{seed}")
    out = run + "-diag"
    shutil.rmtree(run, ignore_errors=True)
    shutil.rmtree(out, ignore_errors=True)
    w = subprocess.run([sys.executable, os.path.join(HERE, "write_run.py"), "--out", run,
                        "--seed", str(seed)] + BASE + CASES[case], capture_output=True, text=True)
    if w.returncode != 0:
        return {"error": "writer: " + w.stderr.strip()[-300:]}
    d = subprocess.run([args.bin, "diagnose", run, "--out", out, "--force", "--json"],
                       capture_output=True, text=True)
    if d.returncode != 0:
        return {"error": f"diagnose exit {d.returncode}: " + d.stderr.strip()[-300:]}
    with open(os.path.join(run, "truth_icd.json")) as f:
        truth = json.load(f)
    with open(os.path.join(out, "report.json")) as f:
        report = json.load(f)
    r = score(truth, report)
    cal = run + "-cal"
    shutil.rmtree(cal, ignore_errors=True)
    c = subprocess.run([args.bin, "calibrate", run, "--out", cal, "--force"], capture_output=True, text=True)
    r["tables"] = None
    if c.returncode == 0:
        r["tables"] = (fhst_pair_error(args.bin, os.path.join(cal, "tables", "alignment.tbl"), truth),
                       fhst_pair_error(args.bin, os.path.join(out, "tables", "alignment.tbl"), truth))
    v = report.get("flight_tables", {}).get("validation") or {}
    r["taken"] = [t["component"] for t in v.get("taken", [])]
    return r


def fhst_pair_error(binary, table, truth):
    """FHST1–FHST2 relative alignment error (″) of an alignment table image against the
    writer's injected rotations (both as rotations from the prelaunch table, ACS)."""
    t = subprocess.run([binary, "table", "inspect", "--json", table], capture_output=True, text=True, check=True)
    rot = {name: v for name, v, _ in json.loads(t.stdout)["rotation_from_prelaunch_arcsec"]}
    inj = {k: list(v) for k, v in truth["injected_rotation_acs_arcsec"].items()}
    # An alignment step: the tables fly after the run, so the truth is the alignment after it.
    for e in truth.get("effects", []):
        if e["effect"] == "alignment_step" and e["sensor"] in inj:
            inj[e["sensor"]] = [a + b for a, b in zip(inj[e["sensor"]], e["rotation_acs_arcsec"])]
    e = [(rot["FHST2"][k] - rot["FHST1"][k]) - (inj["FHST2"][k] - inj["FHST1"][k]) for k in range(3)]
    return sum(x * x for x in e) ** 0.5


def main():
    p = parser(__doc__, "1 2 3", "/tmp/icd-diagnose", "also write the results here")
    args = p.parse_args()
    cases = selected_cases(p, args, CASES)
    seeds = [int(s) for s in args.seeds.split()]
    os.makedirs(args.work, exist_ok=True)
    results = {}
    print("| case | seed | expected | detected | named | params within 3σ (max \\|z\\|) | unexplained | tables: calibrate's → diagnose's FHST1–FHST2 (″), taken | verdict |")
    print("|---|---|---|---|---|---|---|---|---|")
    for c in cases:
        for s in seeds:
            r = run_one(c, s, args)
            results[f"{c}/{s}"] = r
            if "error" in r:
                print(f"| {c} | {s} | | | | | | ERROR {r['error']} |", flush=True)
                continue
            par = f"{r['params_ok']}/{r['params_n']} ({r['zmax']:.1f})" if r["params_n"] else "–"
            if r["params_bad"]:
                par += "; out: " + "; ".join(r["params_bad"])
            named = "yes" if r["named"] else "no" + (f" (missing {', '.join(r['missing'])})" if r["missing"] else "") \
                + (f" (+{', '.join(r['extra'])})" if r["extra"] else "")
            un = ", ".join(r["unexplained"]) or "none"
            if r["out_of_library_ok"]:
                un += " — out-of-library " + ("ok" if all(r["out_of_library_ok"]) else "NOT reported right")
            tb = "–" if not r.get("tables") else f"{r['tables'][0]:.1f} → {r['tables'][1]:.1f}" \
                + (" WORSE" if r["tables"][1] > r["tables"][0] + 0.5 else "") + "; " + (", ".join(r.get("taken", [])) or "none")
            print(f"| {c} | {s} | {', '.join(r['expected']) or 'nothing'} | {', '.join(r['detected']) or 'none'} "
                  f"| {named} | {par} | {un} | {tb} | {'PASS' if r['pass'] else 'fail'} |", flush=True)
    print()
    print("| case | runs | named (nothing else) | params within 3σ | out-of-library reported right | no other unexplained | pass |")
    print("|---|---|---|---|---|---|---|")
    tot = [0, 0]
    for c in cases:
        rs = [results[f"{c}/{s}"] for s in seeds if "error" not in results[f"{c}/{s}"]]
        n = len(rs)
        named = sum(r["named"] for r in rs)
        pk = sum(r["params_ok"] for r in rs)
        pn = sum(r["params_n"] for r in rs)
        ol = [all(r["out_of_library_ok"]) for r in rs if r["out_of_library_ok"]]
        ol_s = f"{sum(ol)}/{len(ol)}" if ol else "–"
        nu = sum(r["extra_unexplained"] == 0 for r in rs)
        ps = sum(r["pass"] for r in rs)
        tot[0] += ps
        tot[1] += len(seeds)
        print(f"| {c} | {len(seeds)} | {named}/{n} | {pk}/{pn} | {ol_s} | {nu}/{n} | {ps}/{len(seeds)} |")
    print(f"\npassed {tot[0]} of {tot[1]} runs")
    worse = [k for k, r in results.items() if r.get("tables") and r["tables"][1] > r["tables"][0] + 0.5]
    scored = [k for k, r in results.items() if r.get("tables")]
    print(f"diagnose's FHST1–FHST2 alignment more than 0.5″ worse than calibrate's in {len(worse)} of {len(scored)} runs {worse if worse else ''}")
    done = [r for r in results.values() if "error" not in r]
    broken = [k for k, r in results.items() if r.get("ledger_violations")]
    print(f"evidence ledger invariant (scenarios/undeclared/ledger_check.py): violated in {len(broken)} of "
          f"{len(done)} runs {broken if broken else ''}")
    write_json(args.json, results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
