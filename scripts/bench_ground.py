#!/usr/bin/env python3
"""Cost of `ground-tool calibrate` and `ground-tool diagnose` on long telemetry (issue 22).

    nice -n 10 python3 scripts/bench_ground.py [--runs 3] [--cases bias,day] [--json FILE]

Builds `ground-tool` and `sim-harness` (`cargo build --release`), flies the telemetry once and
keeps it (`runs/bench-bias`: `gro-bias-history`, 182 days at 30-s frames, ≈ 2–3 min and 177 MB;
`runs/bench-day`: one 5.2-h `gro-early-mission` day), then runs each command N times under
`/usr/bin/time -v`, interleaved (calibrate, diagnose, calibrate, ...) so that a change in the
machine's load reaches every command alike. Prints the medians per command as JSON and as a
Markdown table, with the targets of issue 22:

    six-month calibrate ≤ 60 s wall, ≤ 1 GB peak RSS; six-month diagnose ≤ 60 s, ≤ 1 GB;
    diagnose ≤ 5 s on a 5.2-h day.

Medians, not means: the machine is shared, and one run slowed by another job must not move the
figure. CPU time is user + system. Peak RSS is the kernel's maximum resident set size of the
command's process (`/usr/bin/time`'s "Maximum resident set size", KiB), printed in MB of 10⁶
bytes; the 1-GB target is 10⁹ bytes. Without `/usr/bin/time` the same three figures come from
`wait4`. Outputs go to `runs/bench-out/<case>-<command>` (replaced each run).

A different binary (e.g. a saved copy of an earlier build, to compare before and after) can
be given with `--ground-tool PATH`; `--no-build` skips cargo.
"""

import argparse
import datetime
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
TARGET = os.environ.get("CARGO_TARGET_DIR") or os.path.join(ROOT, "target")
BIN = os.path.join(TARGET, "release")

# The run folders flown once and kept (scenario, folder under the repository).
CASES = {
    "bias": ("gro-bias-history", "runs/bench-bias", "six-month gro-bias-history"),
    "day": ("gro-early-mission", "runs/bench-day", "5.2-h gro-early-mission day"),
}
COMMANDS = ("calibrate", "diagnose")
# Targets of issue 22: (case, command) -> (wall s, peak RSS bytes); None = no target.
TARGETS = {
    ("bias", "calibrate"): (60.0, 1e9),
    ("bias", "diagnose"): (60.0, 1e9),
    ("day", "diagnose"): (5.0, None),
}
BYTES_PER_KIB = 1024


def log(msg):
    print(msg, file=sys.stderr, flush=True)


def build():
    cmd = ["cargo", "build", "--release", "-p", "ground-tool", "-p", "sim-harness"]
    log("$ " + " ".join(cmd))
    subprocess.run(cmd, cwd=ROOT, check=True)


def ensure_run(case, sim_harness):
    scenario, folder, _ = CASES[case]
    path = os.path.join(ROOT, folder)
    # sim-harness renames a finished run into place, so the telemetry's presence means a
    # whole run.
    if os.path.exists(os.path.join(path, "telemetry.bin")):
        return path
    cmd = [sim_harness, "run", scenario, "--out", path, "-q"]
    log("$ " + " ".join(cmd) + "   (once; kept for the next bench)")
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return path


def parse_time_v(text):
    """Wall s, user s, sys s, peak RSS KiB from `/usr/bin/time -v`'s report."""

    def field(name):
        m = re.search(r"^\s*" + re.escape(name) + r":\s*(\S+)\s*$", text, re.M)
        if not m:
            raise RuntimeError(f"/usr/bin/time -v output without '{name}':\n{text}")
        return m.group(1)

    wall = 0.0
    for part in field("Elapsed (wall clock) time (h:mm:ss or m:ss)").split(":"):
        wall = wall * 60.0 + float(part)
    return (
        wall,
        float(field("User time (seconds)")),
        float(field("System time (seconds)")),
        int(field("Maximum resident set size (kbytes)")),
    )


def measure(cmd):
    """Run `cmd`; (wall s, cpu s, peak RSS KiB). Raises on a non-zero exit."""
    if os.path.exists("/usr/bin/time"):
        with tempfile.NamedTemporaryFile("r", suffix=".time") as tf:
            p = subprocess.run(["/usr/bin/time", "-v", "-o", tf.name] + cmd,
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
            if p.returncode != 0:
                raise RuntimeError(f"{' '.join(cmd)}: exit {p.returncode}\n{p.stderr[-2000:]}")
            wall, user, sys_s, rss_kib = parse_time_v(tf.read())
        return wall, user + sys_s, rss_kib
    # wait4 gives the child's own rusage (ru_maxrss in KiB on Linux).
    t0 = time.monotonic()
    p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, ru = os.wait4(p.pid, 0)
    wall = time.monotonic() - t0
    p.returncode = os.waitstatus_to_exitcode(status)
    err = p.stderr.read().decode(errors="replace")
    p.stderr.close()
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)}: exit {p.returncode}\n{err[-2000:]}")
    return wall, ru.ru_utime + ru.ru_stime, ru.ru_maxrss


def git_commit():
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, check=True,
                             capture_output=True, text=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"],
                               cwd=ROOT, capture_output=True, text=True).stdout.strip()
        return out + ("-dirty" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def verdict(case, command, wall, rss_bytes):
    target = TARGETS.get((case, command))
    if target is None:
        return None, None
    wall_max, rss_max = target
    parts = [f"wall ≤ {wall_max:g} s"]
    ok = wall <= wall_max
    if rss_max is not None:
        parts.append(f"peak RSS ≤ {rss_max / 1e9:g} GB")
        ok = ok and rss_bytes <= rss_max
    return ", ".join(parts), ok


def main():
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--runs", type=int, default=3, help="runs per command (default 3)")
    p.add_argument("--cases", default="bias,day",
                   help="comma-separated: bias (six months), day (5.2 h); default both")
    p.add_argument("--commands", default=",".join(COMMANDS),
                   help="comma-separated: calibrate, diagnose; default both")
    p.add_argument("--ground-tool", help="ground-tool binary to time (default: the release build)")
    p.add_argument("--no-build", action="store_true", help="do not run cargo build")
    p.add_argument("--out", default=os.path.join(ROOT, "runs", "bench-out"),
                   help="folder for the commands' outputs (default runs/bench-out)")
    p.add_argument("--json", help="also write the JSON result to this file")
    a = p.parse_args()
    cases = [c for c in a.cases.split(",") if c]
    commands = [c for c in a.commands.split(",") if c]
    for c in cases:
        if c not in CASES:
            p.error(f"unknown case {c!r} (known: {', '.join(CASES)})")
    for c in commands:
        if c not in COMMANDS:
            p.error(f"unknown command {c!r} (known: {', '.join(COMMANDS)})")
    if a.runs < 1:
        p.error("--runs must be at least 1")

    if not a.no_build:
        build()
    ground_tool = a.ground_tool or os.path.join(BIN, "ground-tool")
    runs = {c: ensure_run(c, os.path.join(BIN, "sim-harness")) for c in cases}
    os.makedirs(a.out, exist_ok=True)

    samples = {(c, k): [] for c in cases for k in commands}
    load_before = os.getloadavg()
    for i in range(a.runs):
        for c in cases:
            for k in commands:
                out = os.path.join(a.out, f"{c}-{k}")
                cmd = [ground_tool, k, runs[c], "--out", out, "--force"]
                wall, cpu, rss_kib = measure(cmd)
                samples[(c, k)].append({"wall_s": wall, "cpu_s": cpu, "peak_rss_kib": rss_kib})
                log(f"run {i + 1}/{a.runs} {c} {k}: wall {wall:.2f} s, cpu {cpu:.2f} s, "
                    f"peak RSS {rss_kib * BYTES_PER_KIB / 1e6:.0f} MB")
    load_after = os.getloadavg()

    results = []
    for c in cases:
        for k in commands:
            s = samples[(c, k)]
            wall = statistics.median(x["wall_s"] for x in s)
            cpu = statistics.median(x["cpu_s"] for x in s)
            rss_bytes = statistics.median(x["peak_rss_kib"] for x in s) * BYTES_PER_KIB
            target, ok = verdict(c, k, wall, rss_bytes)
            results.append({
                "case": c,
                "run": CASES[c][2],
                "run_dir": os.path.relpath(runs[c], ROOT),
                "command": k,
                "argv": f"ground-tool {k} {os.path.relpath(runs[c], ROOT)} --out OUT --force",
                "median_wall_s": round(wall, 3),
                "median_cpu_s": round(cpu, 3),
                "median_peak_rss_mb": round(rss_bytes / 1e6, 1),
                "target": target,
                "meets_target": ok,
                "samples": s,
            })
    doc = {
        "date_utc": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "commit": git_commit(),
        "ground_tool": os.path.relpath(ground_tool, ROOT)
        if ground_tool.startswith(ROOT) else ground_tool,
        "runs_per_command": a.runs,
        "load_average_1min_before_after": [round(load_before[0], 2), round(load_after[0], 2)],
        "results": results,
    }
    text = json.dumps(doc, indent=2, ensure_ascii=False)
    print(text)
    if a.json:
        with open(a.json, "w", encoding="utf-8") as f:
            f.write(text + "\n")

    print()
    print(f"Medians of {a.runs} runs, {doc['date_utc']}, commit {doc['commit']}, "
          f"load average {load_before[0]:.1f} → {load_after[0]:.1f}:")
    print()
    print("| run | command | wall (s) | CPU (s) | peak RSS (MB) | target | met |")
    print("|---|---|---|---|---|---|---|")
    for r in results:
        met = "—" if r["meets_target"] is None else ("yes" if r["meets_target"] else "**no**")
        print(f"| {r['run']} | `{r['command']}` | {r['median_wall_s']:.2f} | "
              f"{r['median_cpu_s']:.2f} | {r['median_peak_rss_mb']:.0f} | "
              f"{r['target'] or '—'} | {met} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
