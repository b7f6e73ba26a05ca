#!/usr/bin/env python3
"""Covariance realism of `ground-tool calibrate` on telemetry from the independent writer.

For seeds 1..N: write a run with tests/icd/write_run.py (its own sky, Sun, orbit, sensor
models and injected misalignments, from docs/icd.md alone), calibrate it, and score each
sensor's alignment relative to FHST1 against the writer's truth (truth_icd.json):
error = (θ_k − θ_FHST1)_calibrated − (θ_k − θ_FHST1)_injected, NEES = eᵀ P⁻¹ e with P =
report.json `ffcal.relative_covariance_to_fhst1_arcsec2[k]` (3 = covariance right).

    cargo build --release -p ground-tool
    python3 tests/icd/calibrate_seeds.py [--work /tmp/icd-seeds] [N=10] [-- writer flags ...]

Standard library only.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.normpath(os.path.join(HERE, "..", ".."))
SENSORS = ["FHST2", "FSS1", "FSS2"]


def det3(m):
    return (m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]))


def solve3(p, b):
    """p⁻¹ b by Cramer's rule (p is 3×3 and positive definite)."""
    d = det3(p)
    out = []
    for i in range(3):
        m = [row[:] for row in p]
        for r in range(3):
            m[r][i] = b[r]
        out.append(det3(m) / d)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("n", type=int, nargs="?", default=10)
    ap.add_argument("--work", default="/tmp/icd-seeds")
    ap.add_argument("--bin", default=os.path.join(ROOT, "target", "release", "ground-tool"))
    argv = sys.argv[1:]
    extra = argv[argv.index("--") + 1:] if "--" in argv else []
    a = ap.parse_args(argv[:argv.index("--")] if "--" in argv else argv)
    os.makedirs(a.work, exist_ok=True)
    scores = {k: [] for k in SENSORS}
    print("| seed | " + " | ".join(f"{k}: error (″) / NEES" for k in SENSORS) + " |")
    print("|---" * (len(SENSORS) + 1) + "|")
    for seed in range(1, a.n + 1):
        run = os.path.join(a.work, f"s{seed}")
        subprocess.run([sys.executable, os.path.join(HERE, "write_run.py"), "--out", run,
                        "--seed", str(seed)] + extra, check=True, stdout=subprocess.DEVNULL)
        subprocess.run([a.bin, "calibrate", run, "--out", run + "-cal", "--force"], check=True,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        truth = json.load(open(os.path.join(run, "truth_icd.json")))["injected_rotation_acs_arcsec"]
        rep = json.load(open(os.path.join(run + "-cal", "report.json")))
        err = {k: [c - t for c, t in zip(v["theta_acs_arcsec"], truth[k])]
               for k, v in rep["alignments"].items()}
        cov = rep["ffcal"]["relative_covariance_to_fhst1_arcsec2"]
        cells = []
        for k in SENSORS:
            if k not in err or k not in cov or "FHST1" not in err:
                cells.append("not observed")
                continue
            e = [x - y for x, y in zip(err[k], err["FHST1"])]
            nees = sum(x * y for x, y in zip(e, solve3(cov[k], e)))
            sig = [cov[k][i][i] ** 0.5 for i in range(3)]
            scores[k].append((nees, sum(x * x for x in e) ** 0.5))
            cells.append("[{:.1f}, {:.1f}, {:.1f}] (σ {:.1f}, {:.1f}, {:.1f}) / {:.2f}".format(*e, *sig, nees))
        print(f"| {seed} | " + " | ".join(cells) + " |", flush=True)
    print()
    for k in SENSORS:
        if scores[k]:
            n = [s[0] for s in scores[k]]
            m = [s[1] for s in scores[k]]
            print(f"{k}: mean NEES {statistics.mean(n):.2f} (3 = covariance right), "
                  f"median |error| {statistics.median(m):.1f}″, {len(n)} runs")


if __name__ == "__main__":
    main()
