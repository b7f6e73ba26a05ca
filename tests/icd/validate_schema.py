#!/usr/bin/env python3
"""Validate run folders' JSON files against the published schemas (docs/schema/, issue 18).

    python3 tests/icd/validate_schema.py RUN_OR_OUTPUT_DIR ...

For each folder: metadata.json (when present) against docs/schema/metadata.schema.json,
truth.json (when present: a simulator run) against docs/schema/truth.schema.json and
tables/manifest.json (when present) against docs/schema/tables-manifest.schema.json. A folder
with none of them is an error (nothing was checked). Before that, the schema must refuse a
metadata file with a key of the wrong type (so a schema that accepts everything fails here).
Needs the `jsonschema` package (PyPI); .ci/run installs it in a venv. Prints
'N passed, N failed' and exits 1 on any failure.
"""
import json
import os
import sys

import jsonschema

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCHEMA_DIR = os.path.join(ROOT, "docs", "schema")


def load(path):
    with open(path) as f:
        return json.load(f)


def validator(name):
    schema = load(os.path.join(SCHEMA_DIR, name))
    cls = jsonschema.validators.validator_for(schema)
    cls.check_schema(schema)
    return cls(schema)


def main(dirs):
    meta = validator("metadata.schema.json")
    manifest = validator("tables-manifest.schema.json")
    truth = validator("truth.schema.json")
    passed, failed = 0, 0
    # The schema must be able to fail.
    for bad in ({"epoch_utc": 5}, {"sensors": {"fhst_sigma_arcsec": 8.0}},
                {"uploads": [{"table": "iru", "accepted": "yes"}]}):
        if meta.is_valid(bad):
            print(f"FAIL metadata schema accepts {json.dumps(bad)}")
            failed += 1
        else:
            passed += 1
    for bad in ({"seed": "one"}, {"tam": {"bias_mG": "x"}}):
        if truth.is_valid(bad):
            print(f"FAIL truth schema accepts {json.dumps(bad)}")
            failed += 1
        else:
            passed += 1
    for d in dirs:
        checked = 0
        for rel, v in (("metadata.json", meta), ("truth.json", truth),
                       (os.path.join("tables", "manifest.json"), manifest)):
            p = os.path.join(d, rel)
            if not os.path.exists(p):
                continue
            checked += 1
            errors = sorted(v.iter_errors(load(p)), key=lambda e: list(e.path))
            if errors:
                failed += 1
                for e in errors:
                    print(f"FAIL {p}: {'/'.join(map(str, e.path)) or '(root)'}: {e.message}")
            else:
                passed += 1
                print(f"ok   {p}")
        if checked == 0:
            failed += 1
            print(f"FAIL {d}: none of metadata.json, truth.json, tables/manifest.json")
    print(f"{passed} passed, {failed} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    if len(sys.argv) < 2:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    sys.exit(main(sys.argv[1:]))
