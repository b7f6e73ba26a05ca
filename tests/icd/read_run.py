#!/usr/bin/env python3
"""A tiny telemetry.bin reader written from docs/icd.md §1–4 (Python 3, standard library
only), for checking what tests/icd/write_run.py wrote: packets by APID with their time
codes, raw frames' IRU counters and rate-mode byte, housekeeping IRU configuration and
rate-mode command, events, ephemeris.

    python3 tests/icd/read_run.py RUN            # a summary as JSON

As a module: `read(path)` returns a dict of lists (see `read`), `increments(raws)` the
per-frame counter differences (16-bit, read as signed) of the six channels.
"""

import json
import os
import struct
import sys

APID_RAW, APID_HK, APID_EVENT, APID_EPH, APID_MAG = 0x010, 0x011, 0x012, 0x020, 0x013
APID_WHEEL = 0x014
USER_LEN = {APID_RAW: 48, APID_HK: 230, APID_EVENT: 10, APID_EPH: 48, APID_MAG: 27,
            APID_WHEEL: 16}


def read(path):
    """Walk telemetry.bin packet by packet (ICD §1–2). Returns {"raw": [...], "hk": [...],
    "events": [...], "eph": [...], "mag": [...], "wheel": [...], "order": [(apid, t)], "bad": [offsets]} with t the time
    code in TAI seconds since 1958 (coarse + fine / 65536)."""
    if os.path.isdir(path):
        path = os.path.join(path, "telemetry.bin")
    data = open(path, "rb").read()
    out = {"raw": [], "hk": [], "events": [], "eph": [], "mag": [], "wheel": [], "order": [],
           "bad": []}
    off = 0
    while off + 6 <= len(data):
        w0, w1, dlen = struct.unpack_from(">HHH", data, off)
        apid = w0 & 0x7FF
        assert (w0 >> 13) == 0 and (w0 >> 12) & 1 == 0 and (w0 >> 11) & 1 == 1, f"header at {off}"
        assert (w1 >> 14) == 3, f"sequence flags at {off}"
        n = dlen + 1
        body = data[off + 6:off + 6 + n]
        if apid not in USER_LEN or n != 6 + USER_LEN[apid]:
            out["bad"].append(off)
            off += 6 + n
            continue
        coarse, fine = struct.unpack_from(">IH", body, 0)
        t = coarse + fine / 65536.0
        u = body[6:]
        out["order"].append((apid, t))
        if apid == APID_RAW:
            c = struct.unpack_from(">6H", u, 0)
            bit, mode = struct.unpack_from(">BB", u, 12)
            out["raw"].append({"t": t, "counters": list(c), "bit": bit, "rate_mode": mode,
                               "temps": list(struct.unpack_from(">5h", u, 38))})
        elif apid == APID_HK:
            q = struct.unpack_from(">4d", u, 0)
            b = struct.unpack_from(">3d", u, 32)
            fm, cm, cfg, rc = struct.unpack_from(">BBBB", u, 104)
            out["hk"].append({"t": t, "q": list(q), "bias": list(b), "filter_mode": fm,
                              "control_mode": cm, "iru_config": cfg, "rate_cmd": rc})
        elif apid == APID_EVENT:
            code, p1, p2 = struct.unpack_from(">HII", u, 0)
            out["events"].append({"t": t, "code": code, "p1": p1, "p2": p2})
        elif apid == APID_MAG:  # ICD §3.5 (format version 2)
            t1 = struct.unpack_from(">3hB", u, 0)
            t2 = struct.unpack_from(">3hB", u, 7)
            css = struct.unpack_from(">6HB", u, 14)
            out["mag"].append({"t": t, "tam1_counts": list(t1[:3]), "tam1_flags": t1[3],
                               "tam2_counts": list(t2[:3]), "tam2_flags": t2[3],
                               "css_counts": list(css[:6]), "css_flags": css[6]})
        elif apid == APID_WHEEL:  # ICD §3.6 (format version 4)
            w = struct.unpack_from(">4hB3hB", u, 0)
            out["wheel"].append({"t": t, "speed_counts": list(w[:4]), "speed_valid": w[4],
                                 "dipole_counts": list(w[5:8]), "dipole_valid": w[8]})
        else:
            out["eph"].append({"t": t, "pos": list(struct.unpack_from(">3d", u, 0)),
                               "vel": list(struct.unpack_from(">3d", u, 24))})
        off += 6 + n
    if off != len(data):
        out["bad"].append(off)
    return out


def increments(raws):
    """[(dt, [Δ per channel])] between consecutive raw frames: 16-bit differences as signed."""
    out = []
    for a, b in zip(raws, raws[1:]):
        d = [((y - x + 32768) % 65536) - 32768 for x, y in zip(a["counters"], b["counters"])]
        out.append((b["t"] - a["t"], d))
    return out


def main():
    r = read(sys.argv[1])
    t0 = r["raw"][0]["t"] if r["raw"] else 0.0
    steps = sorted({round(b["t"] - a["t"], 6) for a, b in zip(r["raw"], r["raw"][1:])})
    print(json.dumps({
        "raw_frames": len(r["raw"]), "housekeeping": len(r["hk"]), "events": len(r["events"]),
        "ephemeris": len(r["eph"]), "bad_offsets": r["bad"][:10],
        "raw_spacings_s": steps[:10],
        "high_rate_frames": sum(x["rate_mode"] == 1 for x in r["raw"]),
        "backup_hk": sum(h["iru_config"] == 1 for h in r["hk"]),
        "event_codes": {f"0x{c:04x}": sum(e["code"] == c for e in r["events"])
                        for c in sorted({e["code"] for e in r["events"]})},
        "first_backup_hk_s": next((h["t"] - t0 for h in r["hk"] if h["iru_config"] == 1), None),
    }, indent=1))


if __name__ == "__main__":
    main()
