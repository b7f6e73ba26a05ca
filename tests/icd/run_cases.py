#!/usr/bin/env python3
"""Run every ICD-conformance case: write the run with write_run.py, then `ground-tool
calibrate` and `ground-tool diagnose` on it; print one markdown row per case.

    cargo build --release -p ground-tool
    python3 tests/icd/run_cases.py [--bin target/release/ground-tool] [--work /tmp/icd-cases] [CASE ...]
"""

import argparse
import json
import os
import shutil
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.normpath(os.path.join(HERE, "..", ".."))

# name -> (writer flags, post-processing of the run folder or None)
CASES = {
    "nominal": ([], None),
    "no-hk": (["--no-hk"], None),
    "hk-every-10": (["--hk-every", "10"], None),
    "no-eph": (["--no-eph"], None),
    "eph-300s": (["--eph-period", "300"], None),
    "eph-900s": (["--eph-period", "900"], None),
    "no-fss2": (["--missing", "FSS2"], None),
    "no-fhst1": (["--missing", "FHST1"], None),
    "no-fhst2": (["--missing", "FHST2"], None),
    "no-slews": (["--no-slews", "--duration", "2400"], None),
    "low-rate-slews": (["--low-rate-slews"], None),
    "short-120s": (["--no-slews", "--duration", "120"], None),
    "short-1-frame": (["--no-slews", "--duration", "0"], None),
    "epoch-2025": (["--epoch", "2025-06-01T00:00:00Z"], None),
    "gap-300s": (["--gap", "1500:300", "--gap", "3000:200"], None),
    "gap-in-slew": (["--gap", "1000:200"], None),
    "duplicates": (["--duplicate-every", "7"], None),
    "reordered": (["--reorder-every", "5"], None),
    "seq-wrap": (["--seq-start", "16000"], None),
    "fhst1-invalid-2000s": (["--invalid", "FHST1:0:2000"], None),
    "fss1-invalid-all": (["--invalid", "FSS1:0:100000"], None),
    "extreme": (["--extreme"], None),
    "quiet-iru": (["--quiet-iru"], None),
    "backup-channels-dead": (["--backup-channels-dead"], None),
    "hk-time-offset": (["--hk-offset-s", "0.5"], None),
    "metadata-empty": (["--metadata", "empty"], None),
    "metadata-none": (["--metadata", "none"], None),
    "met-time-codes": (["--time-code-offset-s", "-1049932826"], None),
    "time-codes-1-day-late": (["--time-code-offset-s", "86400"], None),
    "bad-empty-telemetry": (["--duration", "10"], "empty"),
    "bad-garbage-telemetry": (["--duration", "10"], "garbage"),
    "bad-no-telemetry": (["--duration", "10"], "remove"),
    "bad-metadata-json": (["--duration", "10"], "badmeta"),
    "bad-metadata-type": (["--duration", "10"], "badmetatype"),
}


def post(run, what):
    tm = os.path.join(run, "telemetry.bin")
    if what == "empty":
        open(tm, "wb").close()
    elif what == "garbage":
        with open(tm, "wb") as f:
            f.write(bytes((i * 37 + 11) % 256 for i in range(5000)))
    elif what == "remove":
        os.remove(tm)
    elif what == "badmeta":
        with open(os.path.join(run, "metadata.json"), "w") as f:
            f.write("{ not json")
    elif what == "badmetatype":
        with open(os.path.join(run, "metadata.json"), "w") as f:
            f.write('{"sensors": {"fhst_sigma_arcsec": 8.0}}')


def run_case(name, flags, what, args):
    run = os.path.join(args.work, name)
    shutil.rmtree(run, ignore_errors=True)
    w = subprocess.run([sys.executable, os.path.join(HERE, "write_run.py"), "--out", run] + flags,
                       capture_output=True, text=True)
    if w.returncode != 0:
        return {"case": name, "writer": w.stderr.strip().splitlines()[-1:]}
    if what:
        post(run, what)
    row = {"case": name}
    for cmd in ("calibrate", "diagnose"):
        out = os.path.join(run, cmd[:3])
        r = subprocess.run([args.bin, cmd, run, "--out", out, "--force", "--json"], capture_output=True, text=True)
        err = [l for l in r.stderr.splitlines() if l.strip()]
        row[cmd + "_rc"] = r.returncode
        row[cmd + "_msg"] = err[-1][:300] if err else ""
        if r.returncode == 0:
            try:
                rep = json.loads(r.stdout)
            except ValueError:
                rep = {}
            if cmd == "calibrate":
                row["calibrate_summary"] = summarize_calibration(rep, run)
            else:
                row["diagnose_summary"] = {
                    "detected": [d.get("effect", "?") + "[" + d.get("sensor", "?") + "]"
                                 for d in rep.get("detected", [])],
                    "unexplained": len(rep.get("unexplained", [])),
                }
    return row


def summarize_calibration(rep, run):
    s = {}
    data = rep.get("data", {})
    for k in ("stars_identified", "sun_samples", "ffcal_epochs"):
        if k in data:
            s[k] = data[k]
    try:
        truth = json.load(open(os.path.join(run, "truth_icd.json")))
        inj = truth["injected_rotation_acs_arcsec"]
        th = {k: v["theta_acs_arcsec"] for k, v in rep["alignments"].items()}
        rel = [th["FHST2"][i] - th["FHST1"][i] for i in range(3)]
        s["fhst2_rel_err_arcsec"] = [round(rel[i] - (inj["FHST2"][i] - inj["FHST1"][i]), 1) for i in range(3)]
    except (KeyError, OSError, ValueError, TypeError):
        pass
    iru = rep.get("iru") or {}
    if iru.get("bias_rad_per_s"):
        s["bias_arcsec_per_s"] = [round(x * 206264.806, 3) for x in iru["bias_rad_per_s"]]
    s["maneuvers"] = len(rep.get("maneuvers") or [])
    if rep.get("iru_skipped"):
        s["iru_skipped"] = str(rep["iru_skipped"])[:120]
    tel = rep.get("telemetry", {})
    s["tp"] = {k: (len(v) if isinstance(v, list) else v) for k, v in tel.items()
               if k in ("skipped", "duplicates", "time_reversals", "packets_housekeeping", "packets_ephemeris")}
    return s


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--bin", default=os.path.join(ROOT, "target", "release", "ground-tool"))
    p.add_argument("--work", default="/tmp/icd-cases")
    p.add_argument("cases", nargs="*")
    args = p.parse_args()
    os.makedirs(args.work, exist_ok=True)
    for name in args.cases or CASES:
        flags, what = CASES[name]
        print(json.dumps(run_case(name, flags, what, args), ensure_ascii=False), flush=True)


if __name__ == "__main__":
    main()
