#!/usr/bin/env python3
"""Checks that tests/icd/write_run.py's gyro, downlink, backup and long-plan options write
what they claim, by decoding the bytes back with tests/icd/read_run.py (written from
docs/icd.md) and comparing with the truth the writer records in truth_icd.json.
Python 3, standard library only; ≈ 1 min on one core.

    python3 tests/icd/check_writer.py [--work /tmp/icd-check-writer]

What is checked (each prints PASS/FAIL; the exit code is the number of failures):
  * frame spacing N cycles, housekeeping only with raw frames, ephemeris at its own period,
    events at cycles without a raw frame, --no-events drops only the events;
  * byte 13 = the rate mode of the last cycle's interval, housekeeping byte 107 = the mode
    commanded for the next one, both from the 0x0203 events; the frames whose interval
    straddles a switch are those truth_icd.json counts;
  * the IRU counters: for every frame interval in one rate mode, (I + δM) G w ΔN − b Δt of
    the active triad (truth δM and bias, the backup's after the switch) equals the turn
    between the housekeeping attitudes within 2″ + 30 ppm; a straddling interval lies
    between its low-rate and high-rate readings;
  * the bias: over the holds, the counters' rate against truth_icd.json's bias model
    (constant + ramp + steps + transient, recomputed here) within 0.003″/s per 300 s;
  * --backup-halfway: event 0x0202 (p1 = 1) once, housekeeping byte 106 = 0 before and 1
    from the switch on, the switch in a low-rate hold;
  * --gyro-rate2 / --gyro-rate3: the gyro's excess angle over every slew = Σ Δθ (k2 ω² +
    k3 |ω|³) within 5 % + 3″;
  * aliasing: --downlink-every 200 at 0.08°/s is refused (exit 2); with --allow-alias
    the run is written and truth_icd.json counts the aliased intervals;
  * --days with --downlink-every: the span, repeated slews, both rate modes.
"""

import argparse
import json
import math
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from read_run import read  # noqa: E402

ARCSEC = math.pi / 180 / 3600
FAILS = []


def check(name, ok, detail=""):
    print(f"{'PASS' if ok else 'FAIL'}  {name}" + (f"  ({detail})" if detail else ""), flush=True)
    if not ok:
        FAILS.append(name)


def write(work, name, flags):
    out = os.path.join(work, name)
    r = subprocess.run([sys.executable, os.path.join(HERE, "write_run.py"), "--out", out] + flags,
                       capture_output=True, text=True)
    return out, r


# --- small math (independent of the writer's)
def mm(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def mv(m, v):
    return [sum(m[i][k] * v[k] for k in range(3)) for i in range(3)]


def dcm(q):
    x, y, z, w = q
    return [[w * w + x * x - y * y - z * z, 2 * (x * y + w * z), 2 * (x * z - w * y)],
            [2 * (x * y - w * z), w * w - x * x + y * y - z * z, 2 * (y * z + w * x)],
            [2 * (x * z + w * y), 2 * (y * z - w * x), w * w - x * x - y * y + z * z]]


def turn(qa, qb):
    """Rotation vector Δθ with A_b = Rot(Δθ) A_a (docs/conventions.md: Rot(θ) = exp(−[θ×]))."""
    a, b = dcm(qa), dcm(qb)
    r = mm(b, [list(x) for x in zip(*a)])
    v = [0.5 * (r[1][2] - r[2][1]), 0.5 * (r[2][0] - r[0][2]), 0.5 * (r[0][1] - r[1][0])]
    s = math.sqrt(sum(x * x for x in v))
    c = 0.5 * (r[0][0] + r[1][1] + r[2][2] - 1)
    ang = math.atan2(s, c)
    return [x * ang / s for x in v] if s > 1e-15 else v


def truth_bias(truth, cfg, t):
    """The bias model of truth_icd.json, recomputed here (rad/s, ACS)."""
    iru = truth["iru"]
    b = list(iru["primary" if cfg == 0 else "backup"]["bias_acs_rad_per_s"])
    for i in range(3):
        b[i] += iru["bias_ramp_arcsec_per_s_per_h"][i] * ARCSEC * t / 3600
    for st in iru["bias_steps"]:
        if t >= st["t_s"]:
            b = [b[i] + st["step_acs_arcsec_per_s"][i] * ARCSEC for i in range(3)]
    tr = iru["bias_transient"]
    if tr:
        f = math.exp(-t / tr["tau_s"])
        b = [b[i] + tr["amplitude_acs_arcsec_per_s"][i] * f * ARCSEC for i in range(3)]
    return b


CH = {0: (1, 2, 4), 1: (0, 3, 5)}  # primary X2 Y1 Z1, backup X1 Y2 Z2


def gyro_turn(truth, cfg, dn6, w_arcsec):
    """(I + δM) G w ΔN of one triad, rad (bias not removed)."""
    tri = truth["iru"]["primary" if cfg == 0 else "backup"]
    m = mm([[(i == j) + tri["delta_m"][i][j] for j in range(3)] for i in range(3)], tri["g"])
    return mv(m, [dn6[c] * w_arcsec * ARCSEC for c in CH[cfg]])


def mode_timeline(events, t0):
    """Cycle times (s from t0) at which the commanded rate mode changed, and the new mode."""
    return [(round(e["t"] - t0, 6), e["p1"]) for e in events if e["code"] == 0x0203]


def mode_of_interval_ending(tl, t):
    """Mode of the cycle interval ending at t: the last command issued at a cycle c whose
    next sample (c + 1 s, ICD §3.3 event 0x0203) is before t."""
    m = 0
    for (c, v) in tl:
        if c + 1.0 < t - 1e-6:
            m = v
    return m


def check_stream(run, n, label, with_events=True, ref=None):
    truth = json.load(open(os.path.join(run, "truth_icd.json")))
    r = read(run)
    raw, hk = r["raw"], r["hk"]
    t0 = raw[0]["t"]
    sp = {round(b["t"] - a["t"], 6) for a, b in zip(raw, raw[1:])}
    check(f"{label}: raw frames every {n} s", sp == {float(n)}, f"spacings {sorted(sp)[:5]}")
    check(f"{label}: housekeeping only at raw frames, one each",
          [h["t"] for h in hk] == [x["t"] for x in raw])
    eph_sp = [b["t"] - a["t"] for a, b in zip(r["eph"], r["eph"][1:])]
    check(f"{label}: ephemeris at its own period (60 s), covering the run",
          max(eph_sp) <= 60.0 + 1e-6 and r["eph"][0]["t"] <= t0 + 1e-6 and r["eph"][-1]["t"] >= raw[-1]["t"] - 1e-6,
          f"spacing {min(eph_sp):g}..{max(eph_sp):g} s")
    if not with_events:
        check(f"{label}: no events", not r["events"])
        return truth, r
    raw_t = {x["t"] for x in raw}
    ev_off = [e for e in r["events"] if e["t"] not in raw_t]
    check(f"{label}: events every cycle (some at cycles without a raw frame)",
          (n == 1 and not ev_off) or (n > 1 and ev_off), f"{len(ev_off)} of {len(r['events'])} off-frame")
    tl = mode_timeline(r["events"], t0)
    bad13 = [x["t"] - t0 for x in raw[1:] if x["rate_mode"] != mode_of_interval_ending(tl, x["t"] - t0)]
    check(f"{label}: byte 13 = mode of the last cycle's interval (from 0x0203)", not bad13, f"bad at {bad13[:3]}")
    bad107 = [h["t"] - t0 for h in hk if h["rate_cmd"] != mode_of_interval_ending(tl, h["t"] - t0 + 2.0)]
    check(f"{label}: housekeeping byte 107 = mode commanded for the next interval", not bad107, f"bad at {bad107[:3]}")
    # Straddling frames: a switch (one cycle after the command at c) with t_prev < c + 1 < t.
    strad = [b["t"] - t0 for a, b in zip(raw, raw[1:])
             if any(a["t"] - t0 + 1e-6 < c + 1.0 < b["t"] - t0 - 1e-6 for (c, _v) in tl)]
    check(f"{label}: frames straddling a rate switch = truth_icd.json's count",
          len(strad) == truth["downlink"]["frames_straddling_rate_switch"],
          f"{len(strad)} vs {truth['downlink']['frames_straddling_rate_switch']}")
    # Counters against the housekeeping attitudes (true attitude × a constant 7″ error).
    cfg_at = {h["t"]: h["iru_config"] for h in hk}
    worst, n_one = 0.0, 0
    steps = [s["t_s"] for s in truth["iru"]["bias_steps"]]
    for (a, b), h0, h1 in zip(zip(raw, raw[1:]), hk, hk[1:]):
        ta, tb = a["t"] - t0, b["t"] - t0
        if tb in strad or any(ta < s <= tb for s in steps):
            continue
        dn = [((y - x + 32768) % 65536) - 32768 for x, y in zip(a["counters"], b["counters"])]
        q = turn(h0["q"], h1["q"])
        tol = 2.0 + 30e-6 * math.sqrt(sum(x * x for x in q)) / ARCSEC
        w = 0.8 if b["rate_mode"] == 1 else 0.05
        for cfg in (0, 1):
            bb = truth_bias(truth, cfg, 0.5 * (ta + tb))
            g = [x - bi * (tb - ta) for x, bi in zip(gyro_turn(truth, cfg, dn, w), bb)]
            worst = max(worst, max(abs(x - y) for x, y in zip(g, q)) / ARCSEC / tol)
            n_one += 1
    check(f"{label}: counters of both triads ((I + δM) G w ΔN − b Δt) = the attitude's turn",
          worst <= 1.0, f"{n_one} triad-intervals in one rate mode, worst {worst:.2f} of the tolerance")
    if ref is not None:
        # The same run with 1-s frames: the counters must be those of the same cycles, and a
        # straddling interval is the sum of its 1-s intervals, each in its own rate mode.
        by_t = {x["t"]: x for x in ref["raw"]}
        same = all(by_t.get(x["t"], {}).get("counters") == x["counters"] for x in raw)
        check(f"{label}: counters = the 1-s run's at the same cycles (all six)", same)
        ref_raw = ref["raw"]
        idx = {x["t"]: i for i, x in enumerate(ref_raw)}
        worst_mix, off_13, n_mix = 0.0, 0.0, 0
        idx_hk = {h["t"]: i for i, h in enumerate(hk)}
        for a, b in zip(raw, raw[1:]):
            tb = b["t"] - t0
            if tb not in strad:
                continue
            n_mix += 1
            cfg = cfg_at[b["t"]]
            exact = [0.0, 0.0, 0.0]
            for i in range(idx[a["t"]], idx[b["t"]]):
                x, y = ref_raw[i], ref_raw[i + 1]
                d1 = [((v - u + 32768) % 65536) - 32768 for u, v in zip(x["counters"], y["counters"])]
                exact = [e + g for e, g in zip(exact, gyro_turn(truth, cfg, d1, 0.8 if y["rate_mode"] else 0.05))]
            dn = [((y - x + 32768) % 65536) - 32768 for x, y in zip(a["counters"], b["counters"])]
            read13 = gyro_turn(truth, cfg, dn, 0.8 if b["rate_mode"] else 0.05)
            q = turn(hk[idx_hk[a["t"]]]["q"], hk[idx_hk[b["t"]]]["q"])
            tol = 2.0 + 30e-6 * math.sqrt(sum(x * x for x in q)) / ARCSEC
            bb = truth_bias(truth, cfg, 0.5 * (a["t"] + b["t"]) - t0)
            dt = b["t"] - a["t"]
            worst_mix = max(worst_mix, max(abs(e - bi * dt - qq) for e, bi, qq in zip(exact, bb, q)) / ARCSEC / tol)
            off_13 = max(off_13, max(abs(e - r13) for e, r13 in zip(exact, read13)) / ARCSEC)
        check(f"{label}: a straddling interval, summed over its 1-s intervals in their own modes, = the turn",
              n_mix > 0 and worst_mix <= 1.0,
              f"{n_mix} intervals, worst {worst_mix:.2f} of the tolerance; read with byte 13's weight alone "
              f"one is off by up to {off_13:.0f}″")
    # Bias over the holds: mean counter rate per ≤ 300 s window of low-rate frames.
    win, bad, nwin = [], [], 0
    for a, b in zip(raw, raw[1:]):
        ta, tb = a["t"] - t0, b["t"] - t0
        if b["rate_mode"] == 1 or tb in strad or any(ta < s <= tb for s in steps):
            win = []
            continue
        win.append((ta, tb, [((y - x + 32768) % 65536) - 32768 for x, y in zip(a["counters"], b["counters"])]))
        if win[-1][1] - win[0][0] >= 300.0:
            tt0, tt1 = win[0][0], win[-1][1]
            for cfg in (0, 1):
                tot = [sum(x[2][c] for x in win) for c in range(6)]
                g = gyro_turn(truth, cfg, tot, 0.05)
                # the truth's bias averaged over the window (transient: exact mean)
                bm = [sum(truth_bias(truth, cfg, tt0 + (j + 0.5) * (tt1 - tt0) / 50)[i] for j in range(50)) / 50
                      for i in range(3)]
                e = max(abs(g[i] / (tt1 - tt0) - bm[i]) for i in range(3)) / ARCSEC
                nwin += 1
                if e > 0.003:
                    bad.append((round(tt0), cfg, round(e, 4)))
            win = []
    check(f"{label}: bias over the holds = truth model (ramp, steps, transient), both triads",
          nwin > 0 and not bad, f"{nwin} windows, off: {bad[:3]}")
    return truth, r


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--work", default="/tmp/icd-check-writer")
    a = ap.parse_args()
    os.makedirs(a.work, exist_ok=True)
    base = ["--hold-s", "600", "--iru-delta-m", "paper", "--gyro-bias-step", "1500:0.05,-0.04,0.06",
            "--gyro-bias-transient", "0.08,-0.06,0.1:1500", "--gyro-ramp", "0.01,-0.008,0.012",
            "--backup-halfway", "--slew-rates", "0.04,0.16"]
    for n in (1, 30):
        run, w = write(a.work, f"dl{n}", base + ["--downlink-every", str(n)])
        check(f"dl{n}: written", w.returncode == 0, w.stderr.strip()[-200:])
        if w.returncode:
            continue
        truth, r = check_stream(run, n, f"dl{n}", ref=read(os.path.join(a.work, "dl1")) if n > 1 else None)
        t0 = r["raw"][0]["t"]
        ev = [e for e in r["events"] if e["code"] == 0x0202]
        tsw = truth["iru"]["backup_selected_at_s"]
        check(f"dl{n}: one event 0x0202 (p1 = 1) at the switch", len(ev) == 1 and ev[0]["p1"] == 1
              and abs(ev[0]["t"] - t0 - tsw) < 1e-6, f"switch at {tsw} s of {truth['duration_s']} s")
        cfg = [(h["t"] - t0, h["iru_config"]) for h in r["hk"]]
        check(f"dl{n}: housekeeping byte 106 = 0 before the switch, 1 from it on",
              all(c == (1 if t >= tsw - 1e-6 else 0) for (t, c) in cfg) and any(c for _t, c in cfg))
        hold_ok = not any(x["rate_mode"] for x in r["raw"] if abs(x["t"] - t0 - tsw) <= max(n, 60))
        check(f"dl{n}: the switch is in a low-rate hold, after half the run",
              hold_ok and tsw >= 0.5 * truth["duration_s"])
    # --no-events: same bytes otherwise
    run_ne, w = write(a.work, "dl30-noev", base + ["--downlink-every", "30", "--no-events"])
    if w.returncode == 0:
        check_stream(run_ne, 30, "dl30 --no-events", with_events=False)
        r1, r2 = read(os.path.join(a.work, "dl30")), read(run_ne)
        check("dl30 --no-events: raw frames and housekeeping identical to dl30",
              r1["raw"] == r2["raw"] and r1["hk"] == r2["hk"] and r1["eph"] == r2["eph"])
    run, w = write(a.work, "dl30-aligned", base + ["--downlink-every", "30", "--rate-switch-at-frames"])
    if w.returncode == 0:
        truth, r = check_stream(run, 30, "dl30 --rate-switch-at-frames")
        check("--rate-switch-at-frames: no frame straddles a switch",
              truth["downlink"]["frames_straddling_rate_switch"] == 0 and
              all((round(e["t"] - r["raw"][0]["t"] + 1.0) % 30) == 0 for e in r["events"] if e["code"] == 0x0203))
    # Rate nonlinearities, 1-s frames: excess angle per slew.
    k2, k3 = [20000.0, -15000.0, 25000.0], [100000.0, 80000.0, -120000.0]
    run, w = write(a.work, "rate23", ["--hold-s", "300", "--slew-rates", "0.04,0.16,0.1",
                                      "--gyro-rate2", ",".join(map(str, k2)), "--gyro-rate3", ",".join(map(str, k3))])
    if w.returncode == 0:
        truth = json.load(open(os.path.join(run, "truth_icd.json")))
        r = read(run)
        bad, nsl = [], 0
        acc = None
        for (a_, b_), h0, h1 in zip(zip(r["raw"], r["raw"][1:]), r["hk"], r["hk"][1:]):
            dt = b_["t"] - a_["t"]
            if b_["rate_mode"] == 1:
                if acc is None:
                    acc = [[0.0] * 3, [0.0] * 3, [0.0] * 3]  # gyro, attitude, predicted excess
                dn = [((y - x + 32768) % 65536) - 32768 for x, y in zip(a_["counters"], b_["counters"])]
                bb = truth_bias(truth, 0, 0.5 * (a_["t"] + b_["t"]) - r["raw"][0]["t"])
                g = [x - y * dt for x, y in zip(gyro_turn(truth, 0, dn, 0.8), bb)]
                q = turn(h0["q"], h1["q"])
                for i in range(3):
                    om = q[i] / dt / (math.pi / 180)
                    acc[0][i] += g[i]
                    acc[1][i] += q[i]
                    acc[2][i] += q[i] * (k2[i] * om * om + k3[i] * abs(om) ** 3) * 1e-6
            elif acc is not None:
                nsl += 1
                ax = max(range(3), key=lambda i: abs(acc[1][i]))
                got = (acc[0][ax] - acc[1][ax]) / ARCSEC
                want = acc[2][ax] / ARCSEC
                if abs(got - want) > 0.05 * abs(want) + 3.0:
                    bad.append((ax, round(got, 1), round(want, 1)))
                acc = None
        check("rate2+rate3: excess gyro angle per slew = Σ Δθ (k2 ω² + k3 |ω|³)", nsl >= 3 and not bad,
              f"{nsl} slews, off: {bad[:3]}")
    # Aliasing
    _run, w = write(a.work, "alias", ["--hold-s", "300", "--downlink-every", "200"])
    check("--downlink-every 200 at 0.08°/s refused (exit 2, says the limit)",
          w.returncode == 2 and "alias" in w.stderr and "--downlink-every <=" in w.stderr, w.stderr.strip()[:160])
    run, w = write(a.work, "alias-allowed", ["--hold-s", "300", "--downlink-every", "200", "--allow-alias"])
    if w.returncode == 0:
        d = json.load(open(os.path.join(run, "truth_icd.json")))["downlink"]
        check("--allow-alias: written, aliased intervals counted", d["aliased_frame_intervals"] > 0
              and d["max_pulses_between_frames"] > 32767, json.dumps({k: d[k] for k in ("aliased_frame_intervals",
                                                                                         "max_pulses_between_frames")}))
    # --days with --downlink-every
    run, w = write(a.work, "days", ["--days", "0.35", "--downlink-every", "30"])
    check("--days 0.35 --downlink-every 30 written", w.returncode == 0, w.stderr.strip()[-200:])
    if w.returncode == 0:
        r = read(run)
        span = r["raw"][-1]["t"] - r["raw"][0]["t"]
        n_slew = sum(e["code"] == 0x0601 for e in r["events"])
        modes = {x["rate_mode"] for x in r["raw"]}
        check("--days: span 0.35 d, more slews than one calibration day (12), both rate modes",
              abs(span - 0.35 * 86400) <= 30 and n_slew > 12 and modes == {0, 1},
              f"span {span:.0f} s, {n_slew} slews, modes {sorted(modes)}")
        check_stream(run, 30, "days")
    print(f"\n{len(FAILS)} failed" + (": " + "; ".join(FAILS) if FAILS else ""))
    return len(FAILS)


if __name__ == "__main__":
    sys.exit(main())
