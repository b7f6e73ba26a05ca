#!/usr/bin/env python3
"""IRUCAL over seeds on a long scenario (issue 16, "Must show" 2 and 4): flies SCENARIO for each
seed with the prelaunch tables, runs `ground-tool calibrate` on the telemetry, and scores the
IRU δM of the primary triad (and the backup triad when the report has it) against truth.json.

    cargo build --release -p sim-harness -p ground-tool
    python3 scripts/iru_seeds.py scenarios/gro-two-weeks.toml --seeds "1 2 3 4 5" [--work DIR]

Per seed: mean (error/σ)² over the 9 elements (1 = σ right), the largest |error/σ|, whether G
was written, the noise model the filter chose. Summary: the mean over seeds of the per-seed
mean (error/σ)², and the fraction of elements within 3σ. The telemetry of each seed is deleted
after its calibration (two weeks at 1-s frames are 370 MB); the reports stay in WORK.
"""

import argparse
import json
import os
import shutil
import subprocess
import sys

ROOT = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
BIN = os.path.join(ROOT, "target", "release")


def score(report, truth, triad):
    rep = report["iru"] if triad == "primary" else report["iru"].get("backup")
    if rep is None:
        return None
    dm, sg = rep["delta_m"], rep["delta_m_sigma"]
    tr = truth["iru"][triad]["delta_m"]
    z = [(dm[i][j] - tr[i][j]) / sg[i][j] for i in range(3) for j in range(3)]
    return z


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scenario")
    p.add_argument("--seeds", default="1 2 3 4 5")
    p.add_argument("--work", default="/tmp/iru-seeds")
    a = p.parse_args()
    name = os.path.splitext(os.path.basename(a.scenario))[0]
    allz = {"primary": [], "backup": []}
    per_seed = {"primary": [], "backup": []}
    for seed in a.seeds.split():
        run = os.path.join(a.work, f"{name}-s{seed}")
        cal = run + "-cal"
        for d in (run, cal):
            shutil.rmtree(d, ignore_errors=True)
        subprocess.run([os.path.join(BIN, "sim-harness"), "run", a.scenario, "--seed", seed,
                        "--out", run, "-q"], check=True, stdout=subprocess.DEVNULL)
        c = subprocess.run([os.path.join(BIN, "ground-tool"), "calibrate", run, "--out", cal],
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        os.remove(os.path.join(run, "telemetry.bin"))
        if c.returncode != 0:
            print(f"seed {seed}: calibrate exit {c.returncode}: {c.stderr.strip()[-300:]}")
            continue
        report = json.load(open(os.path.join(cal, "report.json")))
        truth = json.load(open(os.path.join(run, "truth.json")))
        iru = report.get("iru")
        if iru is None:
            print(f"seed {seed}: no IRU solution: {report.get('iru_skipped')}")
            continue
        for triad in ("primary", "backup"):
            z = score(report, truth, triad)
            if z is None:
                continue
            m = sum(v * v for v in z) / 9
            allz[triad] += z
            per_seed[triad].append(m)
            g = iru["g_updated"] if triad == "primary" else iru["backup"]["g_updated"]
            print(f"seed {seed} {triad}: mean (err/σ)² {m:.2}, max |err/σ| {max(abs(v) for v in z):.2}, "
                  f"σ {min(s for r in (iru if triad == 'primary' else iru['backup'])['delta_m_sigma'] for s in r) * 1e6:.0f}–"
                  f"{max(s for r in (iru if triad == 'primary' else iru['backup'])['delta_m_sigma'] for s in r) * 1e6:.0f} ppm, "
                  f"G written {g}")
        print(f"seed {seed}: σ_u {iru['rrw_used_rad_per_s_1p5']:.2e} (declared {iru['rrw_declared_rad_per_s_1p5']:.2e}), "
              f"fix scales {iru['fix_cov_scale']} / {iru['fix_systematic_scale']} / {iru.get('fix_sun_systematic_scale')} (random / FHST / Sun), NIS/dof {iru['nis_mean_per_dof']:.2}, "
              f"gated {iru['gated_fixes']}; {iru['decision'][:160]}")
        sys.stdout.flush()
    for triad in ("primary", "backup"):
        if per_seed[triad]:
            z = allz[triad]
            print(f"{triad}: seeds {len(per_seed[triad])}, mean (error/σ)² {sum(per_seed[triad]) / len(per_seed[triad]):.2f}, "
                  f"within 3σ {sum(1 for v in z if abs(v) < 3) / len(z) * 100:.0f} %")


if __name__ == "__main__":
    main()
