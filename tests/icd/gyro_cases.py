#!/usr/bin/env python3
"""The gyro cases of issue 16 ("Must show" 2, 4, 5) on telemetry from the independent ICD
writer: `ground-tool calibrate` on each, IRU δM scored against the writer's truth.

    cargo build --release -p ground-tool
    python3 tests/icd/gyro_cases.py [--seeds "1"] [--downlinks "1 30"] [--work /tmp/icd-gyro] [CASE ...]

Every case flies the same plan (BASE: the writer's calibration day, 5.9 h, 13 holds of 1200 s and
12 out-and-back slews about every body axis, at 0.04, 0.08 and 0.16 °/s in turn, so that a
rate-dependent scale error is not one constant scale; slews in high rate, holds in low
rate; the primary triad's true δM = the paper's published δM), once with 1-s frames and
once with `--downlink-every 30` (raw frames and housekeeping every 30 s; frames straddling
a rate switch mix 0.05″ and 0.8″ pulses). The cases differ only in the gyro:

  clean            nothing else
  bias-ramp        bias ramp (0.010, −0.008, 0.012) ″/s per hour (±0.024–0.035 ″/s about the mean)
  bias-step        bias step (0.04, −0.03, 0.05) ″/s at 11000 s (mid-run, of 21146 s)
  bias-transient   bias transient (0.10, −0.08, 0.12) ″/s e^(−t/7200 s) from the start
  rate2            scale error k ω² with k = (10000, −8000, 12000) ppm at 1 °/s
                   (13–19 ppm at 0.04 °/s, 51–77 at 0.08, 205–307 at 0.16)
  backup-halfway   the OBC selects the backup triad (X1, Y2, Z2) halfway (event 0x0202,
                   housekeeping byte 106 = 1); the backup's own δM (150–510 ppm) and bias
                   ((−0.30, 0.44, 0.29) ″/s against the primary's (0.30, −0.20, 0.25))
  backup-halfway-dm-only   the same with the backup bias = the primary's: only δM differs
  clean-switch-at-frames   control: clean, with every high-rate window widened to frame
                   times (--rate-switch-at-frames), so no frame straddles a switch

Per run: the exit code; IRU δM error against truth in units of the reported σ (report.json
`iru.delta_m`, `iru.delta_m_sigma`, rows of 3×3; truth `iru.primary.delta_m` of
truth_icd.json; and `iru.backup.*` against `iru.backup.delta_m` when the report has it):
the largest |z| (element), the number of |z| > 3 of 9, mean z² over the 9 elements (1 when
the σ are right); the largest |error| in ppm.

The frame. Like tests/icd/calibrate_seeds.py, which scores alignments relative to FHST1
because the ground chooses its own ACS frame, δM is scored in the ground's frame: the
ground's attitudes are A' = Rot(θ) A with θ = its adjusted FHST alignments minus the
injected ones (mean of FHST1 and FHST2, report.json `alignments_adjusted`), and in that
frame the true δM is δM − [θ×] (an antisymmetric part of ≈ θ, 100–150 ppm for the
≈ 30″ of the bisector adjustment on this plan). The column "raw" scores against the
writer's δM directly (what tests/src/bin/calibration_mc.rs does with the simulator's
truth). Then intervals used / rejected; whether a new G
was uplinked (`iru.g_updated`) and which tables calibrate wrote (OUT/tables/*.tbl; note
that iru.tbl is always written, with the flown G when `g_updated` is false).
Standard library only; 16 runs per seed, ≈ 2–3 min per seed (the writer dominates) on 2 shared cores.
"""

import json
import os
import shutil
import subprocess
import sys
import time

ARCSEC = 3.141592653589793 / 180 / 3600
HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.normpath(os.path.join(HERE, "..", ".."))
from cases_cli import parser, selected_cases, write_json  # noqa: E402

BASE = ["--plan", "long", "--hold-s", "1200", "--slew-rates", "0.04,0.08,0.16", "--iru-delta-m", "paper"]

CASES = {
    "clean": [],
    "bias-ramp": ["--gyro-ramp", "0.010,-0.008,0.012"],
    "bias-step": ["--gyro-bias-step", "11000:0.04,-0.03,0.05"],
    "bias-transient": ["--gyro-bias-transient", "0.10,-0.08,0.12:7200"],
    "rate2": ["--gyro-rate2", "10000,-8000,12000"],
    "backup-halfway": ["--backup-halfway"],
    # control: high-rate windows widened to frame times (at 1 s the same as clean)
    "clean-switch-at-frames": ["--rate-switch-at-frames"],
    # the backup triad with the primary's bias: only its δM differs
    "backup-halfway-dm-only": ["--backup-halfway", "--backup-bias", "0.30,-0.20,0.25"],
}


def score_dm(est, sig, truth):
    """Per-element z = (estimate − truth) / σ of a 3×3 δM."""
    z, err = [], []
    for i in range(3):
        for j in range(3):
            e = est[i][j] - truth[i][j]
            err.append(e)
            z.append(e / sig[i][j] if sig[i][j] > 0 else float("inf"))
    worst = max(range(9), key=lambda k: abs(z[k]))
    return {
        "z": [round(x, 2) for x in z],
        "max_abs_z": abs(z[worst]),
        "max_z_element": "xyz"[worst // 3] + "xyz"[worst % 3],
        "n_over_3": sum(abs(x) > 3 for x in z),
        "mean_z2": sum(x * x for x in z) / 9,
        "max_abs_err_ppm": max(abs(x) for x in err) * 1e6,
        "sigma_ppm_range": [min(min(r) for r in sig) * 1e6, max(max(r) for r in sig) * 1e6],
    }


def run_one(case, seed, n, args):
    name = f"{case}-dl{n}-s{seed}"
    run = os.path.join(args.work, name)
    out = run + "-cal"
    shutil.rmtree(run, ignore_errors=True)
    shutil.rmtree(out, ignore_errors=True)
    t_start = time.time()
    w = subprocess.run([sys.executable, os.path.join(HERE, "write_run.py"), "--out", run, "--seed", str(seed),
                        "--downlink-every", str(n)] + BASE + CASES[case], capture_output=True, text=True)
    if w.returncode != 0:
        return {"case": case, "seed": seed, "downlink": n, "error": "writer: " + w.stderr.strip()[-300:]}
    t_write = time.time() - t_start
    c = subprocess.run([args.bin, "calibrate", run, "--out", out], capture_output=True, text=True)
    res = {"case": case, "seed": seed, "downlink": n, "exit": c.returncode,
           "write_s": round(t_write, 1), "calibrate_s": round(time.time() - t_start - t_write, 1)}
    if c.returncode != 0:
        res["stderr"] = c.stderr.strip()[-300:]
    truth = json.load(open(os.path.join(run, "truth_icd.json")))
    res["straddling_frames"] = truth["downlink"]["frames_straddling_rate_switch"]
    tables = os.path.join(out, "tables")
    res["tables"] = sorted(f for f in os.listdir(tables) if f.endswith(".tbl")) if os.path.isdir(tables) else []
    rp = os.path.join(out, "report.json")
    if not os.path.exists(rp):
        return res
    rep = json.load(open(rp))
    iru = rep.get("iru")
    if not iru:
        res["iru"] = None
        res["iru_skipped"] = rep.get("iru_skipped")
        return res
    res["g_updated"] = iru.get("g_updated")
    res["intervals"] = iru.get("intervals")
    res["rejected"] = len(iru.get("rejected_intervals", []))
    mans = rep.get("maneuvers", [])
    res["maneuvers_used"] = f"{sum(1 for m in mans if m.get('used'))}/{len(mans)}"
    theta = ground_frame_arcsec(rep, truth)
    res["ground_frame_arcsec"] = [round(x, 1) for x in theta] if theta else None
    for tri in ("primary", "backup"):
        src = iru if tri == "primary" else iru.get("backup")
        if not src:
            continue
        t = truth["iru"][tri]["delta_m"]
        res[tri + "_raw"] = score_dm(src["delta_m"], src["delta_m_sigma"], t)
        res[tri] = score_dm(src["delta_m"], src["delta_m_sigma"], in_ground_frame(t, theta)) if theta else None
    return res


def ground_frame_arcsec(rep, truth):
    """The rotation of the ground's ACS frame from the writer's: the mean over FHST1 and
    FHST2 of (adjusted calibrated − injected) alignment rotation (report.json
    `alignments_adjusted`, truth_icd.json `injected_rotation_acs_arcsec`), arcsec."""
    adj = rep.get("alignments_adjusted") or {}
    inj = truth["injected_rotation_acs_arcsec"]
    d = [[a - b for a, b in zip(adj[k]["theta_acs_arcsec"], inj[k])] for k in ("FHST1", "FHST2") if k in adj]
    return [sum(x[i] for x in d) / len(d) for i in range(3)] if d else None


def in_ground_frame(dm, theta_arcsec):
    """δM the ground should find when its attitudes are A' = Rot(θ) A (docs/conventions.md,
    Rot(θ) ≈ I − [θ×]): Δθ' = (I − [θ×]) Δθ, so δM' = δM − [θ×] (first order)."""
    x, y, z = (v * ARCSEC for v in theta_arcsec)
    skew = [[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]]
    return [[dm[i][j] - skew[i][j] for j in range(3)] for i in range(3)]


def row(r):
    if "error" in r:
        return f"| {r['case']} | {r['downlink']} s | {r['seed']} | ERROR {r['error']} |||||||||"
    p = r.get("primary")
    if p is None:
        dm = f"no IRU result ({r.get('iru_skipped') or r.get('stderr', '')})"
        return (f"| {r['case']} | {r['downlink']} s | {r['seed']} | {r['exit']} | {dm} | | | | | | "
                f"| {', '.join(r['tables']) or 'none'} | |")
    raw = r["primary_raw"]
    z = p["z"]
    zs = "; ".join(" ".join(f"{z[3 * i + j]:+.1f}" for j in range(3)) for i in range(3))
    dm = (f"{zs} | {p['max_abs_z']:.1f} ({p['max_z_element']}) | {p['n_over_3']}/9 | {p['mean_z2']:.2f} | "
          f"{p['max_abs_err_ppm']:.0f} (σ {p['sigma_ppm_range'][0]:.0f}–{p['sigma_ppm_range'][1]:.0f}) | "
          f"{raw['max_abs_z']:.1f} / {raw['mean_z2']:.1f}")
    b = r.get("backup")
    bk = f"max\\|z\\| {b['max_abs_z']:.1f}, mean z² {b['mean_z2']:.2f}" if b else "not reported"
    return (f"| {r['case']} | {r['downlink']} s | {r['seed']} | {r['exit']} | {dm} | "
            f"{r['maneuvers_used']}, {r['intervals']} int., {r['rejected']} rej. | "
            f"{'**yes**' if r['g_updated'] else 'no'} | {', '.join(r['tables'])} | {bk} |")


def summary(results):
    """Per case and frame spacing, over the seeds: markdown lines."""
    out = ["| case | frames | runs | exit codes | δM max \\|err/σ\\| (min–max over seeds) | mean z² (mean over seeds) "
           "| elements \\|z\\| > 3 | max \\|err\\| ppm | raw mean z² | intervals rejected | G uplinked |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
    keys = []
    for r in results:
        if (r["case"], r["downlink"]) not in keys:
            keys.append((r["case"], r["downlink"]))
    for (c, n) in keys:
        rs = [r for r in results if r["case"] == c and r["downlink"] == n]
        ok = [r for r in rs if r.get("primary")]
        ex = sorted({r.get("exit", "err") for r in rs})
        if not ok:
            out.append(f"| {c} | {n} s | {len(rs)} | {ex} | no IRU result | | | | | | |")
            continue
        mz = [r["primary"]["max_abs_z"] for r in ok]
        z2 = [r["primary"]["mean_z2"] for r in ok]
        raw = [r["primary_raw"]["mean_z2"] for r in ok]
        out.append(f"| {c} | {n} s | {len(rs)} | {', '.join(map(str, ex))} | {min(mz):.1f}–{max(mz):.1f} "
                   f"| {sum(z2) / len(z2):.2f} | {sum(r['primary']['n_over_3'] for r in ok)}/{9 * len(ok)} "
                   f"| {max(r['primary']['max_abs_err_ppm'] for r in ok):.0f} | {sum(raw) / len(raw):.1f} "
                   f"| {'/'.join(str(r['rejected']) for r in ok)} | {sum(bool(r['g_updated']) for r in ok)}/{len(ok)} |")
    return "\n".join(out)


def main():
    ap = parser(__doc__, "1", "/tmp/icd-gyro", "also write every result here",
                after_seeds=[("--downlinks", {"default": "1 30", "help": "--downlink-every values to run each case at"})])
    ap.add_argument("--from-json", default=None, help="print only the summary of an earlier --json file")
    args = ap.parse_args()
    if args.from_json:
        print(summary(json.load(open(args.from_json))))
        return 0
    cases = selected_cases(ap, args, CASES)
    if not os.path.exists(args.bin):
        ap.error(f"{args.bin} not found: cargo build --release -p ground-tool")
    os.makedirs(args.work, exist_ok=True)
    print("| case | frames | seed | exit | δM err/σ per element (rows x; y; z) | δM max \\|err/σ\\| (element) | \\|z\\|>3 | mean z² | max \\|err\\| ppm (σ range) "
          "| raw: max \\|z\\| / mean z² | maneuvers used, intervals, rejected | G uplinked (`g_updated`) "
          "| tables written | backup δM |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    results = []
    for c in cases:
        for s in (int(x) for x in args.seeds.split()):
            for n in (int(x) for x in args.downlinks.split()):
                r = run_one(c, s, n, args)
                results.append(r)
                print(row(r), flush=True)
    print()
    print(summary(results))
    write_json(args.json, results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
