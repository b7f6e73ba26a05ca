#!/usr/bin/env python3
"""Is diagnose's IRU table ever worse than calibrate's? (issue 22: "no run where diagnose's
written tables are worse than calibrate's ... δM error").

    python3 scenarios/undeclared/iru_table_check.py [WORK=/tmp/diagnose-effects] [BIN=target/release]

For every run folder of `WORK` with a `-diag` beside it (`effects_table.sh`'s `NAME-SEED`, or
`tests/icd/diagnose_cases.py`'s `CASE-sSEED`, whose `-cal` it reuses; or `false_alarm.sh`'s
`run-SEED` with `diag-SEED`), runs
`ground-tool calibrate` on the same telemetry (into `NAME-SEED-cal`, once), reads the primary
triad's G of both `iru.tbl` images (`ground-tool table inspect --json`) and prints each one's
RMS difference from the truth's `(I + δM) g` (`iru.primary` of truth.json or the writer's
truth_icd.json), in ppm. "WORSE" when
diagnose's is more than 10 ppm above calibrate's; "as flown" when diagnose kept the flown G
where calibrate updated it (the table not written: unexplained gyro structure).

With a simulator run (truth.json) it also prints the alignment table diagnose wrote against
calibrate's, from the report's `written_table_error_arcsec` (per sensor, RMS over the run's own
measurements of the alignment and field-function error against the truth): "ALIGN WORSE" when
a sensor is more than 0.5″ worse in diagnose's.
"""
import glob
import json
import os
import subprocess
import sys

ROOT = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
WORK = sys.argv[1] if len(sys.argv) > 1 else "/tmp/diagnose-effects"
BIN = sys.argv[2] if len(sys.argv) > 2 else os.path.join(ROOT, "target", "release")
GT = os.path.join(BIN, "ground-tool")


def matmul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def g_of(table):
    out = subprocess.run([GT, "table", "inspect", "--json", table], capture_output=True, text=True, check=True)
    return json.loads(out.stdout)["content"]["g_primary"]


def rms_ppm(g, ref):
    return (sum((g[i][j] - ref[i][j]) ** 2 for i in range(3) for j in range(3)) / 9.0) ** 0.5 * 1e6


worse = kept = same = better = 0
rows = align_rows = align_worse = align_better = 0
for run in sorted(glob.glob(os.path.join(WORK, "*"))):
    if run.endswith(("-diag", "-cal", "-after")) or not os.path.exists(os.path.join(run, "telemetry.bin")):
        continue
    name = os.path.basename(run)
    diag_dir = run + "-diag"
    if name.startswith("run-") and not os.path.exists(diag_dir):
        diag_dir = os.path.join(WORK, "diag-" + name[len("run-"):])
    diag = os.path.join(diag_dir, "tables", "iru.tbl")
    # The simulator's truth.json, or the independent writer's truth_icd.json (same `iru` keys).
    truth_file = next((os.path.join(run, f) for f in ("truth.json", "truth_icd.json")
                       if os.path.exists(os.path.join(run, f))), None)
    if truth_file is None or not os.path.exists(diag):
        continue
    cal = run + "-cal"
    if not os.path.exists(os.path.join(cal, "tables", "iru.tbl")):
        subprocess.run([GT, "calibrate", run, "--out", cal, "--force"], capture_output=True)
    cal_tbl = os.path.join(cal, "tables", "iru.tbl")
    if not os.path.exists(cal_tbl):
        print(f"{os.path.basename(run)}: calibrate wrote no IRU table")
        continue
    p = json.load(open(truth_file))["iru"]["primary"]
    eye_dm = [[(1.0 if i == j else 0.0) + p["delta_m"][i][j] for j in range(3)] for i in range(3)]
    truth = matmul(eye_dm, p["g"])
    e_cal, e_diag = rms_ppm(g_of(cal_tbl), truth), rms_ppm(g_of(diag), truth)
    e_flown = rms_ppm(p["g"], truth)
    rows += 1
    tag = ""
    if e_diag > e_cal + 10.0:
        if abs(e_diag - e_flown) < 1e-6:
            tag, kept = "as flown (calibrate updated)", kept + 1
        else:
            tag, worse = "WORSE", worse + 1
    elif abs(e_diag - e_cal) < 1e-6:
        same += 1
    elif e_diag < e_cal - 10.0:
        tag, better = "better", better + 1
    align = ""
    report = os.path.join(diag_dir, "report.json")
    w = json.load(open(report)).get("written_table_error_arcsec") if os.path.exists(report) else None
    if w:
        align_rows += 1
        bad = [k for k in w["after"] if k in w["before"] and w["after"][k] > w["before"][k] + 0.5]
        align_worse += bool(bad)
        align_better += any(w["after"][k] < w["before"][k] - 0.5 for k in w["after"] if k in w["before"])
        align = "  align " + ", ".join(f"{k} {w['before'][k]:.1f}->{w['after'][k]:.1f}" for k in w["after"])
        align += "  ALIGN WORSE: " + ", ".join(bad) if bad else ""
    print(f"{name:24s} calibrate {e_cal:7.1f}  diagnose {e_diag:7.1f} ppm  {tag}{align}")
print(f"\n{rows} runs: diagnose's G the same as calibrate's in {same}, better by > 10 ppm in {better}, "
      f"kept as flown where calibrate updated (worse) in {kept}, worse by a δM of its own in {worse}")
if align_rows:
    print(f"{align_rows} simulator runs: diagnose's alignment table worse than calibrate's by > 0.5″ "
          f"on a sensor in {align_worse}, better on a sensor in {align_better}")
