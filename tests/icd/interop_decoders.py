#!/usr/bin/env python3
"""Do outside decoders read our telemetry as we do? (issue 21, "machine-readable formats")

    python3 tests/icd/interop_decoders.py TELEMETRY_OR_RUN_DIR... [--ground-tool BIN] [--descriptions DIR]

For each telemetry.bin (or run folder holding one), decodes every packet three ways and
compares every field of every packet:

* `ground-tool icd decode` (this project's reader: `ground-tool/src/tp.rs` and the flight
  decoders of `fsw-core/src/telemetry.rs`), one CSV per APID;
* NASA's `ccsdspy` (PyPI) with the generated layouts `DIR/ccsdspy/apid_0x0NN_NAME.csv`
  (`ccsdspy.FixedLength.from_file`, packets split by `ccsdspy.utils.split_by_apid`);
* LASP's `space_packet_parser` (PyPI), an XTCE-driven decoder, with the generated mission
  database `DIR/gro-telemetry.xtce.xml`.

Integers must be equal; floats bit-equal (binary32 fields compared after widening, as all
three do). Also: the packet counts per APID agree, and every container the XTCE decoder
chose matches the packet's APID. DIR defaults to docs/icd (the shipped files; a test in
ground-tool checks they are current). Exit 0 when everything agrees, 1 on any difference
(the first few are printed), 2 on bad arguments or a missing decoder.

    python3 -m pip install ccsdspy==2.0.1 space_packet_parser==6.2.0
"""
import argparse
import csv
import math
import os
import subprocess
import sys
import tempfile

ROOT = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))

try:
    import numpy as np
    from ccsdspy import FixedLength
    from ccsdspy.utils import split_by_apid
    import space_packet_parser as spp
    from space_packet_parser.generators.ccsds import ccsds_generator
except ImportError as e:  # pragma: no cover
    print(f"error: {e}: python3 -m pip install ccsdspy==2.0.1 space_packet_parser==6.2.0", file=sys.stderr)
    sys.exit(2)


def same(a, b):
    """Equal integers, or bit-equal floats (NaN equal to NaN)."""
    if isinstance(a, float) or isinstance(b, float):
        a, b = float(a), float(b)
        return (math.isnan(a) and math.isnan(b)) or a == b
    return int(a) == int(b)


def parse_ours(text):
    """A CSV value of `ground-tool icd decode`: an integer, else a float."""
    try:
        return int(text)
    except ValueError:
        return float(text)


def layouts(desc_dir):
    """APID -> (name, csv path) from the generated ccsdspy files."""
    out = {}
    for f in sorted(os.listdir(os.path.join(desc_dir, "ccsdspy"))):
        # apid_0x010_raw_sensor_frame.csv
        apid = int(f[len("apid_"):len("apid_0x000")], 16)
        out[apid] = (f[len("apid_0x000_"):-len(".csv")], os.path.join(desc_dir, "ccsdspy", f))
    return out


def check_file(tm, gt, desc_dir, max_print=8):
    problems = []
    with tempfile.TemporaryDirectory() as tmp:
        r = subprocess.run([gt, "icd", "decode", tm, "--out", tmp], capture_output=True, text=True)
        if r.returncode != 0:
            return [f"ground-tool icd decode failed (exit {r.returncode}): {r.stderr.strip()}"]
        ours = {}
        for apid, (name, _) in layouts(desc_dir).items():
            with open(os.path.join(tmp, f"apid_0x{apid:03x}_{name}.csv")) as fp:
                rows = list(csv.reader(fp))
            ours[apid] = (rows[0], [[parse_ours(x) for x in row] for row in rows[1:]])

    # ccsdspy
    with open(tm, "rb") as fp:
        streams = split_by_apid(fp)
    for apid, (name, path) in layouts(desc_dir).items():
        cols, rows = ours[apid]
        if apid not in streams:
            if rows:
                problems.append(f"ccsdspy: no APID 0x{apid:03x} packets, ground-tool has {len(rows)}")
            continue
        data = FixedLength.from_file(path).load(streams[apid], include_primary_header=False)
        n = len(next(iter(data.values())))
        if n != len(rows):
            problems.append(f"ccsdspy: APID 0x{apid:03x} {n} packets, ground-tool {len(rows)}")
            continue
        for j, c in enumerate(cols):
            col = data[c]
            for i in range(n):
                v = col[i].item() if isinstance(col[i], np.generic) else col[i]
                if not same(v, rows[i][j]):
                    problems.append(f"ccsdspy: APID 0x{apid:03x} packet {i} {c}: {v!r} != ground-tool {rows[i][j]!r}")
                    break

    # space_packet_parser with the XTCE database
    defn = spp.load_xtce(os.path.join(desc_dir, "gro-telemetry.xtce.xml"))
    names = {apid: name for apid, (name, _) in layouts(desc_dir).items()}
    seen = {apid: 0 for apid in names}
    with open(tm, "rb") as fp:
        for raw in ccsds_generator(fp):
            pkt = defn.parse_bytes(raw)
            apid = raw.apid
            if apid not in names:
                problems.append(f"XTCE: packet of unknown APID 0x{apid:03x}")
                continue
            i = seen[apid]
            seen[apid] += 1
            cols, rows = ours[apid]
            if i >= len(rows):
                continue
            for j, c in enumerate(cols):
                if c not in pkt:
                    problems.append(f"XTCE: APID 0x{apid:03x} packet {i}: no {c} (container chosen wrongly?)")
                    break
                v = pkt[c]
                v = v.raw_value if hasattr(v, "raw_value") else v
                if not same(v, rows[i][j]):
                    problems.append(f"XTCE: APID 0x{apid:03x} packet {i} {c}: {v!r} != ground-tool {rows[i][j]!r}")
                    break
    for apid, n in seen.items():
        if n != len(ours[apid][1]):
            problems.append(f"XTCE: APID 0x{apid:03x} {n} packets, ground-tool {len(ours[apid][1])}")
    counts = ", ".join(f"0x{a:03x}: {len(ours[a][1])}" for a in sorted(ours))
    fields = sum(len(ours[a][0]) * len(ours[a][1]) for a in ours)
    print(f"{tm}: packets {counts}; {fields} field values compared with ccsdspy and with the XTCE decoder: "
          + ("all equal" if not problems else f"{len(problems)} differences"))
    for p in problems[:max_print]:
        print("  " + p)
    return problems


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("inputs", nargs="+", help="telemetry.bin files or run folders")
    ap.add_argument("--ground-tool", default=os.path.join(ROOT, "target", "release", "ground-tool"))
    ap.add_argument("--descriptions", default=os.path.join(ROOT, "docs", "icd"))
    a = ap.parse_args()
    if not os.access(a.ground_tool, os.X_OK):
        print(f"error: {a.ground_tool}: no ground-tool binary (cargo build --release -p ground-tool)", file=sys.stderr)
        sys.exit(2)
    bad = 0
    for x in a.inputs:
        tm = os.path.join(x, "telemetry.bin") if os.path.isdir(x) else x
        if not os.path.exists(tm):
            print(f"error: {tm}: no such file", file=sys.stderr)
            sys.exit(2)
        bad += bool(check_file(tm, a.ground_tool, a.descriptions))
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
