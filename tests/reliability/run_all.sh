#!/usr/bin/env bash
# Bad inputs against every binary (issue 17): prints the docs/reliability.md table "Bad inputs
# and what each command does": the case, the command, the exit code (expected / measured), the
# first line of the message, and the check that nothing was lost and no wrong table written.
#
#   cargo build --release -p sim-harness -p ground-tool -p tests
#   tests/reliability/run_all.sh [WORK_DIR]        # ≈ 1 min; exits 1 if any row fails
#
# Needs python3 (the ICD writer tests/icd/write_run.py makes the damaged telemetry). The fast
# cases are also Rust tests run by `cargo test` (sim-harness/tests/reliability.rs,
# ground-tool/tests/reliability.rs, ground-tool/src/tp.rs, sim-harness/src/outdir.rs).
set -uo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
bin="${CARGO_TARGET_DIR:-$root/target}/release"
work="${1:-$(mktemp -d /tmp/gro-reliability.XXXXXX)}"
# The work folder is cleared first only if it is empty or an earlier work folder of this script.
if [ -d "$work" ] && [ -n "$(ls -A "$work")" ]; then
    [ -e "$work/.gro-reliability" ] || { echo "$work is not empty and not a work folder of run_all.sh" >&2; exit 2; }
    rm -rf "${work:?}"/* "$work"/.[!.]*
fi
mkdir -p "$work" && cd "$work" && touch .gro-reliability || exit 1
sh="$bin/sim-harness"; gt="$bin/ground-tool"; loop="$bin/calibration-loop"; mc="$bin/calibration-mc"
writer="python3 $root/tests/icd/write_run.py"
for b in "$sh" "$gt" "$loop" "$mc"; do
    [ -x "$b" ] || { echo "missing $b: cargo build --release -p sim-harness -p ground-tool -p tests" >&2; exit 1; }
done
failed=0

# row NAME EXPECTED_EXIT CHECK_RESULT -- COMMAND...   (runs COMMAND, logs to NAME.log)
last_rc=0
run() {
    local name="$1"; shift
    "$@" > "$name.log" 2>&1
    last_rc=$?
}
msg() { # first error line, else first warning line, of a log
    local m
    m="$(grep -m1 -E '^(error|sim-harness: error)' "$1.log" || grep -m1 '^warning' "$1.log" || true)"
    m="${m//|/\\|}"
    printf '%s' "${m:0:260}"
}
row() { # NAME CMD_TEXT EXPECTED CHECK_OK CHECK_TEXT
    local name="$1" cmd="$2" want="$3" ok="$4" check="$5" mark="ok"
    if [ "$last_rc" != "$want" ] || [ "$ok" != 1 ]; then mark="**FAIL**"; failed=1; fi
    printf '| %s | `%s` | %s / %s | %s | %s (%s) |\n' "$name" "$cmd" "$want" "$last_rc" "$(msg "$name")" "$check" "$mark"
}
same() { cmp -s "$1" "$2" && echo 1 || echo 0; }
absent() { [ ! -e "$1" ] && echo 1 || echo 0; }

echo "| bad input | command | exit expected / measured | message (first line) | nothing lost, no wrong table |"
echo "|---|---|---|---|---|"

# --- fixtures: a clean flight and its calibration
"$sh" run gro-early-mission --out run -q > /dev/null 2>&1 || { echo "fixture flight failed" >&2; exit 1; }
"$gt" calibrate run --out cal > /dev/null 2>&1 || { echo "fixture calibration failed" >&2; exit 1; }
scen="$root/scenarios/gro-early-mission.toml"

# --- 1. exit codes and messages
printf 'GROT garbage' > short.tbl
run table-short "$gt" table inspect short.tbl
row table-short "ground-tool table inspect short.tbl (12 octets)" 2 1 "nothing written"
cp cal/tables/alignment.tbl crc.tbl; printf '\x01' | dd of=crc.tbl bs=1 seek=100 conv=notrunc 2>/dev/null
run table-crc "$gt" table inspect crc.tbl
row table-crc "ground-tool table inspect crc.tbl (one octet changed)" 2 1 "nothing written"
run table-missing "$gt" table inspect no-such.tbl
row table-missing "ground-tool table inspect no-such.tbl" 2 "$(grep -c 'os error 2' table-missing.log)" "OS error printed once"
run mc-zero "$mc" -n 0 --work mcw
row mc-zero "calibration-mc -n 0" 2 "$(absent mcw)" "nothing created"
run shmc-zero "$sh" monte-carlo normal-ops -n 0 --out mc0 -q
row shmc-zero "sim-harness monte-carlo normal-ops -n 0" 2 "$(absent mc0)" "nothing created"

# --- 2. validation against physical ranges
for f in iru_arw_rad_per_sqrt_s:-1 fss_sigma_arcsec:-15 fhst_sigma_arcsec:[0,0]; do
    key="${f%%:*}"; val="${f#*:}"; d="run-$key"
    rm -rf "$d"; cp -r run "$d"
    python3 -c "import json,sys; p='$d/metadata.json'; m=json.load(open(p)); m['sensors']['$key']=json.loads('$val'); json.dump(m,open(p,'w'))"
    run "meta-$key" "$gt" calibrate "$d" --out "cal-$key"
    row "meta-$key" "ground-tool calibrate RUN (metadata $key: $val)" 2 "$(absent "cal-$key")" "no output folder, no table"
done
sed 's/^duration_s = .*/duration_s = 1e30/' "$scen" > dur.toml
run scen-duration "$sh" run dur.toml --out s-dur -q
row scen-duration "sim-harness run dur.toml (duration_s = 1e30)" 2 "$(absent s-dur)" "no run folder"
sed 's/^raan_deg = .*/raan_deg = inf/' "$scen" > raan.toml
run scen-raan "$sh" run raan.toml --out s-raan -q
row scen-raan "sim-harness run raan.toml (raan_deg = inf)" 2 "$(absent s-raan)" "no truth.json with nulls"
run opt-duration "$sh" run gro-early-mission --duration 1e30 --out s-dur2 -q
row opt-duration "sim-harness run gro-early-mission --duration 1e30" 2 "$(absent s-dur2)" "no run folder"
run tables-none "$gt" calibrate run --out cal-none --tables no-such-dir
row tables-none "ground-tool calibrate run --tables no-such-dir" 2 "$(absent cal-none)" "not read as the boot tables"
run sh-tables-none "$sh" run gro-early-mission --duration 60 --out s-none --tables no-such-dir -q
row sh-tables-none "sim-harness run … --tables no-such-dir" 2 "$(absent s-none)" "no run folder"
"$sh" run gro-early-mission --out run-up --tables cal/tables -q > /dev/null 2>&1
rm -rf run-gone; cp -r run-up run-gone; rm run-gone/uploads/01_alignment.tbl
run upload-gone "$gt" calibrate run-gone --out cal-gone
row upload-gone "ground-tool calibrate RUN (uploads/01_alignment.tbl deleted)" 2 "$(absent cal-gone)" "not read as \"boot tables flown\""
run tables-not-flown "$gt" calibrate run --out cal-nf --tables cal/tables
row tables-not-flown "ground-tool calibrate RUN --tables DIR (the run flew the boot tables)" 2 "$(absent cal-nf)" "no table relative to tables not flown"
rm -rf run-typo; cp -r run-up run-typo
python3 -c 'import json,sys; p=sys.argv[1]; m=json.load(open(p)); u=[x for x in m["uploads"] if x["table"]=="alignment"]; u[0]["table"]="aligment"; json.dump(m,open(p,"w"))' run-typo/metadata.json
run upload-typo "$gt" calibrate run-typo --out cal-typo
row upload-typo "ground-tool calibrate RUN (the alignment upload's table \"aligment\")" 2 "$(absent cal-typo)" "refused for the name, not read as \"boot table flown\""
"$sh" monte-carlo normal-ops -n 2 --seed 1 --duration 120 --out mcA -q > /dev/null 2>&1
"$sh" monte-carlo normal-ops -n 2 --seed 1 --duration 180 --out mcB -q > /dev/null 2>&1
run merge-duration "$sh" merge mcA mcB --out merged.json
row merge-duration "sim-harness merge (120 s and 180 s campaigns)" 2 "$(absent merged.json)" "no aggregate written"
"$sh" monte-carlo gro-early-mission -n 2 --seed 3 --duration 120 --out mcC -q > /dev/null 2>&1
run merge-scenario "$sh" merge mcA mcC --out merged.json
row merge-scenario "sim-harness merge (normal-ops and gro-early-mission)" 2 "$(absent merged.json)" "no aggregate written"
"$sh" monte-carlo normal-ops -n 4 --seed 1 --duration 120 --shard 0/2 --out mcS0 -q > /dev/null 2>&1
run merge-shard "$sh" merge mcS0 --out merged.json
row merge-shard "sim-harness merge (shard 0 of 2 only)" 2 "$(absent merged.json)" "no aggregate of half a campaign"
"$sh" monte-carlo normal-ops -n 4 --seed 1 --duration 120 --shard 1/2 --out mcS1 -q > /dev/null 2>&1
run merge-ok "$sh" merge mcS0 mcS1 --out merged.json
row merge-ok "sim-harness merge (both shards) — control" 0 "$([ -s merged.json ] && echo 1 || echo 0)" "aggregate of 4 runs"

# --- 3. stale files, manifests, output folders
"$gt" calibrate run-up --out cal-stale > /dev/null 2>&1   # flew filter.tbl: no new one proposed
cp cal/tables/filter.tbl cal-stale/tables/filter.tbl       # an old calibration's filter table
run stale-reuse "$gt" calibrate run-up --out cal-stale
row stale-reuse "ground-tool calibrate RUN --out DIR (DIR/tables/filter.tbl from an older run)" 0 "$(absent cal-stale/tables/filter.tbl)" "old filter.tbl gone, folder = what the report lists"
mkdir -p handmade; cp cal/tables/alignment.tbl cal/tables/iru.tbl handmade/
run no-manifest "$sh" run gro-early-mission --duration 60 --out s-hand --tables handmade -q
row no-manifest "sim-harness run … --tables DIR (no manifest.json)" 2 "$(absent s-hand)" "nothing flown"
"$gt" table manifest handmade > /dev/null 2>&1
cp cal/tables/filter.tbl handmade/filter.tbl
run unlisted "$sh" run gro-early-mission --duration 60 --out s-hand --tables handmade -q
row unlisted "sim-harness run … --tables DIR (a filter.tbl not in the manifest)" 0 "$(python3 -c "import json; u=json.load(open('s-hand/metadata.json'))['uploads']; print(int(not any(x['table']=='filter' for x in u)))")" "filter.tbl not loaded, warning names it"
cp crc.tbl handmade/alignment.tbl
run changed "$sh" run gro-early-mission --duration 60 --out s-chg --tables handmade -q
row changed "sim-harness run … --tables DIR (alignment.tbl replaced after the manifest)" 2 "$(absent s-chg)" "nothing flown"
mkdir -p foreign; echo "my notes" > foreign/notes.txt
run foreign "$sh" run gro-early-mission --duration 60 --out foreign -q
row foreign "sim-harness run … --out DIR (DIR holds other files)" 2 "$(grep -c 'my notes' foreign/notes.txt)" "notes.txt kept"
run foreign-force "$sh" run gro-early-mission --duration 60 --out foreign --force -q
row foreign-force "… --out DIR --force" 0 "$(absent foreign/notes.txt)" "cleared, then one whole run"
"$sh" run gro-early-mission --duration 60 --out again -q > /dev/null 2>&1; cp cal/tables/filter.tbl again/uploads/99_old.tbl
run rerun "$sh" run gro-early-mission --duration 60 --out again -q
row rerun "sim-harness run … --out DIR (DIR = an older run with an extra uploads/99_old.tbl)" 0 "$(absent again/uploads/99_old.tbl)" "old upload gone"
"$sh" run normal-ops --duration 200000 --seed 1 --out solo -q > /dev/null 2>&1
rm -rf conc; ("$sh" run normal-ops --duration 200000 --seed 1 --out conc -q > conc-first.log 2>&1) & sleep 0.3
run concurrent "$sh" run normal-ops --duration 200000 --seed 2 --out conc -q
wait
row concurrent "two sim-harness run --out DIR at once (seeds 1 and 2)" 1 "$(same conc/telemetry.bin solo/telemetry.bin)" "DIR = seed 1's run, byte for byte"
mkdir -p mcw/seed-1; echo keep > mcw/seed-1/precious.txt
run mc-work "$mc" -n 1 --work mcw
row mc-work "calibration-mc -n 1 --work W (W/seed-1 holds a file)" 2 "$(grep -c keep mcw/seed-1/precious.txt)" "precious.txt kept"
run loop-1 "$loop" --out loop
run loop-2 "$loop" --out loop
row loop-2 "calibration-loop --out runs/loop, twice" 0 "$(diff <(grep '^|' loop-1.log) <(grep '^|' loop-2.log) > /dev/null && echo 1 || echo 0)" "same before/after table both times"

# --- more of our own
echo "not a folder" > afile
run out-file "$sh" run gro-early-mission --duration 60 --out afile -q
row out-file "sim-harness run … --out FILE" 2 "$(grep -c 'not a folder' afile)" "the file kept"
mkdir -p wrap; cp -r run wrap/run
run out-input "$gt" calibrate wrap/run --out wrap --force
row out-input "ground-tool calibrate wrap/run --out wrap --force" 2 "$([ -s wrap/run/telemetry.bin ] && echo 1 || echo 0)" "the input run kept"
mkdir -p empty-run
run no-telemetry "$gt" calibrate empty-run --out cal-empty
row no-telemetry "ground-tool calibrate DIR (no telemetry.bin)" 2 "$(absent cal-empty)" "no output folder"
mkdir -p trav; cp cal/tables/alignment.tbl trav/
printf '{"format":"gro-tables-manifest-1","written_by":"x","tables":[{"file":"../crc.tbl","table":"alignment","table_id":1,"octets":760,"crc32":"0x0"}]}' > trav/manifest.json
run manifest-path "$sh" run gro-early-mission --duration 60 --out s-trav --tables trav -q
row manifest-path "sim-harness run … --tables DIR (manifest names ../crc.tbl)" 2 "$(absent s-trav)" "nothing outside DIR read"
"$sh" run gro-early-mission --duration 60 --out stale-lock -q > /dev/null 2>&1; echo 4000000000 > .stale-lock.lock
run stale-lock "$sh" run gro-early-mission --duration 60 --out stale-lock -q
row stale-lock "sim-harness run … --out DIR (lock file of a process that no longer exists)" 0 "$(absent .stale-lock.lock)" "lock taken over and removed"

# --- 4. time codes (the ICD writer's run: 4 909 frames)
$writer --out w-clean > /dev/null 2>&1
$writer --out w-flip --flip-time-bit 2000:36 > /dev/null 2>&1
$writer --out w-shift --time-shift-after 2500:-3600 > /dev/null 2>&1
"$gt" calibrate w-clean --out c-clean > /dev/null 2>&1
run time-flip "$gt" calibrate w-flip --out c-flip
frames() { python3 -c "import json; print(json.load(open('$1/report.json'))['data']['frames'])" 2>/dev/null; }
row time-flip "ground-tool calibrate RUN (raw frame 2000: time-code bit 36 flipped, +2^20 s)" 0 "$([ "$(frames c-flip)" = "$(( $(frames c-clean) - 1 ))" ] && grep -q time_code_outliers c-flip/input_check.json && echo 1 || echo 0)" "1 frame dropped and listed in input_check.json, the other 4 908 used"
run time-shift "$gt" calibrate w-shift --out c-shift
row time-shift "ground-tool calibrate RUN (time codes from t = 2500 s shifted by −3600 s)" 2 "$(absent c-shift/tables)" "no table"

echo
echo "work folder: $work"
exit $failed
