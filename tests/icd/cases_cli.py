"""The command line the writer-case sweeps share (`diagnose_cases.py`, `gyro_cases.py`): case
names, seeds, the ground-tool binary, a work folder, and a JSON copy of the results."""

import argparse
import json
import os

ROOT = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))


def parser(doc, seeds, work, json_help, after_seeds=()):
    """The sweep's parser: `cases`, `--seeds` (default `seeds`), the options `after_seeds`
    ((flag, keywords) pairs), `--bin`, `--work` (default `work`), `--json`."""
    p = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("cases", nargs="*", help="case names (default: all)")
    p.add_argument("--seeds", default=seeds)
    for flag, keywords in after_seeds:
        p.add_argument(flag, **keywords)
    p.add_argument("--bin", default=os.path.join(ROOT, "target", "release", "ground-tool"))
    p.add_argument("--work", default=work)
    p.add_argument("--json", default=None, help=json_help)
    return p


def selected_cases(p, args, cases):
    """The cases named on the command line (all when none), an error for an unknown one."""
    selected = args.cases or list(cases)
    for c in selected:
        if c not in cases:
            p.error(f"unknown case {c}; cases: {', '.join(cases)}")
    return selected


def write_json(path, results):
    """`results` to `path` (indent 1) when `--json` was given."""
    if path:
        with open(path, "w") as f:
            json.dump(results, f, indent=1)
