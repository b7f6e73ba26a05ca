#!/usr/bin/env python3
"""The evidence ledger's invariant, checked on report.json files (issue 22; the complete check
from the raw test results is `ledger::violations`, run by tests/tests/diagnose_ledger.rs).

    python3 scenarios/undeclared/ledger_check.py DIAG/report.json ...   # or the --json outputs

From the report alone: every ledger entry has an outcome; an explained entry names effects
that are detected or in the baseline model; an unexplained one has a size, a regressor and a
reason, and is in `unexplained` (residual structure: its sensor's summary lists its regressor,
as the main one or in `also_follows`; the other families: its test is among the item's
`method`, joined by "; "); every `unexplained` item has a reason and an unexplained ledger
entry.
Prints one line per file and the violations; exit status 1 when any file violates it.
"""

import json
import math
import sys


def violations(r):
    out = []
    ledger = r.get("ledger")
    if ledger is None:
        return ["no ledger in the report"]
    unexpl = r.get("unexplained", [])
    named = {f"{d['effect']}[{d['sensor']}]" for d in r.get("detected", [])}
    baseline = {b if "[" in b else f"{b}[all]" for b in r.get("baseline_model", [])}
    for e in ledger:
        o = e.get("outcome", {})
        if o.get("outcome") == "explained":
            by = o.get("by", [])
            if not by:
                out.append(f"{e['id']}: explained by nothing")
            out += [f"{e['id']}: explained by {b}, not detected" for b in by
                    if b not in named and b not in baseline]
        elif o.get("outcome") == "unexplained":
            size = e.get("size")
            if not o.get("reason") or not e.get("regressor") or size is None or not math.isfinite(size):
                out.append(f"{e['id']}: unexplained without size, regressor or reason")
            if e["family"] == "residual_structure":
                listed = any(u["sensor"] == e["sensor"] and u.get("source") == e["family"]
                             and (u["regressor"] == e["regressor"] or e["regressor"] in u["also_follows"])
                             for u in unexpl)
            else:
                listed = any(u["sensor"] == e.get("report_sensor", e["sensor"])
                             and u.get("source") == e["family"]
                             and e["test"] in u["method"].split("; ")
                             for u in unexpl)
            if not listed:
                out.append(f"{e['id']}: unexplained, not in the report's list")
        else:
            out.append(f"{e.get('id')}: no outcome")
    for u in unexpl:
        if not u.get("reason"):
            out.append(f"unexplained {u['sensor']}:{u['regressor']} without a reason")
        if not any(e.get("report_sensor", e["sensor"]) == u["sensor"] and e["family"] == u.get("source")
                   and e["outcome"]["outcome"] == "unexplained" for e in ledger):
            out.append(f"unexplained {u['sensor']}:{u['regressor']} has no ledger entry")
    return out


def main():
    bad = 0
    for path in sys.argv[1:]:
        with open(path) as f:
            r = json.load(f)
        v = violations(r)
        n_unexpl = sum(e["outcome"]["outcome"] == "unexplained" for e in r.get("ledger", []))
        print(f"{path}: {len(r.get('ledger', []))} significant tests, {n_unexpl} unexplained, "
              f"{len(v)} violations")
        for x in v:
            print(f"  {x}")
        bad += bool(v)
    print(f"files violating the invariant: {bad} / {len(sys.argv) - 1}")
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
