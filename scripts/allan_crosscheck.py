#!/usr/bin/env python3
"""Recompute the allantools cross-check fixture of `ground-tool/src/calibration/allan.rs`.

Writes `ground-tool/tests/data/allan_crosscheck.json`: a deterministic gyro-like rate series
(white rate noise = angle random walk, plus a rate random walk, plus whole-pulse
quantization of the integrated angle, as the DRIRU II counts), the samples themselves (so the
Rust test needs no random generator of its own), and what `allantools` computes on them:

* `allantools.oadev(rate, rate=1/tau0, data_type="freq", taus=octaves)`: τ, σ, n;
* `allantools.edf_simple(N_phase, m, alpha)` for alpha in {2, 1, 0, -1, -2};
* `allantools.confidence_interval(sigma, edf, ci)` (scipy's χ² quantiles) at 68.3 % and 95 %.

The Rust test (`ground-tool/tests/allan_crosscheck.rs`) asserts agreement to 1e-9 relative
(σ), exactly (n), 1e-12 (edf) and 1e-7 (intervals: statrs against scipy quantiles).

Usage (any Python 3 with numpy; allantools and scipy from PyPI):

    python3 -m venv /tmp/allan-venv && /tmp/allan-venv/bin/pip install allantools
    /tmp/allan-venv/bin/python scripts/allan_crosscheck.py            # rewrite the fixture
    /tmp/allan-venv/bin/python scripts/allan_crosscheck.py --check    # compare, exit 1 if not
"""
import argparse
import json
import pathlib
import sys

import allantools
import numpy as np
import scipy

SEED = 19
N_SAMPLES = 4096
TAU0_S = 1.0
ARW_RAD_PER_SQRT_S = 1.5e-8       # white rate noise: sigma per sample = N / sqrt(tau0)
RRW_RAD_PER_S_SQRT_S = 4.0e-10    # rate random walk: step per sample = K sqrt(tau0)
PULSE_RAD = 0.05 / 206264.80624709636  # DRIRU II low-rate pulse (0.05 arcsec)
BIAS_RAD_PER_S = 1.7e-6           # a constant bias (drops out of the Allan variance)
FIXTURE = pathlib.Path(__file__).resolve().parent.parent / "ground-tool/tests/data/allan_crosscheck.json"


def series():
    """White + random-walk rate, integrated and counted in whole pulses (remainder kept)."""
    rng = np.random.default_rng(SEED)
    white = rng.standard_normal(N_SAMPLES) * ARW_RAD_PER_SQRT_S / np.sqrt(TAU0_S)
    walk = np.cumsum(rng.standard_normal(N_SAMPLES)) * RRW_RAD_PER_S_SQRT_S * np.sqrt(TAU0_S)
    rate_true = BIAS_RAD_PER_S + white + walk
    angle = np.cumsum(rate_true * TAU0_S)
    pulses = np.floor(angle / PULSE_RAD)
    delta_pulses = np.diff(np.concatenate([[0.0], pulses])).astype(np.int64)
    counted = delta_pulses * PULSE_RAD / TAU0_S
    return rate_true, delta_pulses, counted


def compute():
    rate_true, delta_pulses, counted = series()
    taus = TAU0_S * 2.0 ** np.arange(0, 12)
    out = {
        "provenance": {
            "generator": "scripts/allan_crosscheck.py (numpy default_rng(seed), white + random walk rate, whole-pulse counting)",
            "command": "python3 scripts/allan_crosscheck.py",
            "allantools_version": allantools.__version__,
            "numpy_version": np.__version__,
            "scipy_version": scipy.__version__,
            "python_version": sys.version.split()[0],
        },
        "parameters": {
            "seed": SEED,
            "n_samples": N_SAMPLES,
            "tau0_s": TAU0_S,
            "arw_rad_per_sqrt_s": ARW_RAD_PER_SQRT_S,
            "rrw_rad_per_s_sqrt_s": RRW_RAD_PER_S_SQRT_S,
            "pulse_rad": PULSE_RAD,
            "bias_rad_per_s": BIAS_RAD_PER_S,
        },
        "series": {},
    }
    for name, y in [("rate_true_rad_per_s", rate_true), ("rate_counted_rad_per_s", counted)]:
        t, dev, _, n = allantools.oadev(y, rate=1.0 / TAU0_S, data_type="freq", taus=taus)
        n_phase = len(y) + 1
        pts = []
        for tau, s, k in zip(t, dev, n):
            m = int(round(tau / TAU0_S))
            edf = {str(a): allantools.edf_simple(n_phase, m, a) for a in (2, 1, 0, -1, -2)}
            ci = {}
            for label, level in (("one_sigma", 0.682689492137086), ("p95", 0.95)):
                lo, hi = allantools.confidence_interval(s, edf["0"], ci=level)
                ci[label] = {"confidence": level, "edf_alpha0": edf["0"], "low": lo, "high": hi}
            pts.append({"tau_s": float(tau), "m": m, "sigma": float(s), "n": int(k), "edf_simple": edf, "interval": ci})
        entry = {"oadev": pts}
        if name == "rate_counted_rad_per_s":
            # Stored as whole pulses per sample: rate = pulses * pulse_rad / tau0_s.
            entry["delta_pulses"] = [int(v) for v in delta_pulses]
        else:
            entry["samples"] = [float(v) for v in y]
        out["series"][name] = entry
    return out


def compact_lists(obj):
    """JSON with the long sample lists on one line each."""
    def enc(o, ind):
        pad = " " * ind
        if isinstance(o, dict):
            items = [f'{pad} {json.dumps(k)}: {enc(v, ind + 1).lstrip()}' for k, v in o.items()]
            return pad + "{\n" + ",\n".join(items) + "\n" + pad + "}"
        if isinstance(o, list) and o and isinstance(o[0], dict):
            return pad + "[\n" + ",\n".join(pad + " " + json.dumps(v) for v in o) + "\n" + pad + "]"
        return pad + json.dumps(o)
    return enc(obj, 0)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--check", action="store_true", help="compare with the committed fixture instead of writing it")
    args = ap.parse_args()
    new = compute()
    if args.check:
        old = json.loads(FIXTURE.read_text())
        worst = 0.0
        for name, s in new["series"].items():
            for a, b in zip(s["oadev"], old["series"][name]["oadev"]):
                worst = max(worst, abs(a["sigma"] / b["sigma"] - 1.0))
            key = "samples" if "samples" in s else "delta_pulses"
            if s[key] != old["series"][name][key]:
                print(f"{name}: the samples differ from the fixture (another numpy generator?)")
                return 1
        print(f"largest relative difference of sigma vs the fixture: {worst:.2e}")
        return 0 if worst < 1e-9 else 1
    # One line per point and per sample list: small and still diffable.
    FIXTURE.write_text(compact_lists(new) + "\n")
    print(f"wrote {FIXTURE} ({FIXTURE.stat().st_size} bytes)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
