//! No table without held-out validation (`pipeline::alignment_heldout`), on telemetry from
//! the independent ICD writer (`tests/icd/write_run.py`):
//! - prelaunch tables ≈ 100–700″ off: the new alignments lower the held-out χ² and are written;
//! - the same telemetry with those new alignments declared as the flown ones: a new fit cannot
//!   improve on them, so the flown table is written again, byte for byte;
//! - an alignment that steps by 60″ half-way through (outside the model): the held-out blocks
//!   are not predicted within σ, and the flown table is kept;
//! - the filter table's annual-aberration switch: written when the star pairs show the
//!   aberration, refused when the telemetry lacks it though the metadata declare it.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod support;

use fsw_core::tables::types::FilterTable;
use fsw_core::tables::AlignmentTable;
use ground_tool::pipeline::calibrate::read_table_image;
use serde_json::Value;
use std::path::{Path, PathBuf};

fn calibrate(run: &Path, out: &Path, extra: &[&str]) -> Value {
    support::calibrate_json(env!("CARGO_BIN_EXE_ground-tool"), run, out, extra)
}

fn validation(r: &Value) -> (bool, f64, f64, f64, String) {
    let v = &r["alignment_validation"];
    (
        v["passed"].as_bool().unwrap(),
        v["chi2_new"].as_f64().unwrap(),
        v["chi2_flown"].as_f64().unwrap(),
        v["mean_square_normalised"].as_f64().unwrap(),
        v["reason"].as_str().unwrap().to_owned(),
    )
}

fn table(out: &Path) -> AlignmentTable {
    read_table_image(&out.join("tables/alignment.tbl")).unwrap()
}

#[test]
fn alignment_table_is_written_only_when_held_out_data_say_it_is_better() {
    let run = support::write_run("heldout", "nominal", &[]);
    let out1: PathBuf = run.join("cal1");
    let r1 = calibrate(&run, &out1, &[]);
    let (passed, new, flown, ms, why) = validation(&r1);
    assert!(passed, "prelaunch tables: {why}");
    assert!(new < 0.5 * flown, "held-out χ² {new} vs flown {flown}");
    assert!(ms <= 2.0, "{why}");
    assert_ne!(
        table(&out1).matrices(),
        AlignmentTable::prelaunch().matrices(),
        "the new alignments were not written"
    );

    // The same telemetry, with the calibrated table declared flown. The OBC flew the boot
    // tables (its housekeeping says so): taken as flown all the same only as a what-if.
    let out2 = run.join("cal2");
    let tables1 = out1.join("tables");
    let refused = support::ground_tool(
        env!("CARGO_BIN_EXE_ground-tool"),
        "calibrate",
        &run,
        &out2,
        &["--force", "--tables", tables1.to_str().unwrap()],
    );
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert_eq!(refused.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("the OBC's active alignment table"),
        "{stderr}"
    );
    let r2 = calibrate(
        &run,
        &out2,
        &["--tables", tables1.to_str().unwrap(), "--trust-tables"],
    );
    let (passed, _, _, _, why) = validation(&r2);
    assert!(!passed, "a refit of the same data was written: {why}");
    assert!(why.contains("would not improve"), "{why}");
    assert_eq!(
        std::fs::read(out2.join("tables/alignment.tbl")).unwrap(),
        std::fs::read(tables1.join("alignment.tbl")).unwrap(),
        "the flown table must be written again unchanged"
    );
}

#[test]
fn an_alignment_that_changes_mid_run_is_not_uplinked() {
    let run = support::write_run(
        "heldout",
        "align-step",
        &["--align-step", "FHST2:2500:0,0,60"],
    );
    let out = run.join("cal");
    let r = calibrate(&run, &out, &[]);
    let (passed, _, _, ms, why) = validation(&r);
    assert!(!passed, "an alignment step was uplinked: {why}");
    assert!(ms > 2.0 && why.contains("within their σ"), "{why}");
    assert_eq!(
        table(&out).matrices(),
        AlignmentTable::prelaunch().matrices(),
        "the flown (prelaunch) table must be kept"
    );
}

#[test]
fn the_aberration_switch_is_written_only_when_the_telemetry_shows_aberration() {
    for (case, flags, expect) in [
        ("aberration", &[][..], true),
        ("no-aberration", &["--no-annual-aberration"][..], false),
    ] {
        let run = support::write_run("heldout", case, flags);
        let out = run.join("cal");
        let r = calibrate(&run, &out, &[]);
        let v = &r["filter_validation"];
        let z = v["improvement"]["z"].as_f64().unwrap();
        assert_eq!(v["passed"].as_bool(), Some(expect), "{case}: {v}");
        // The filter table is written when the switch passes or another term of it changed
        // (`pipeline::filter_tuning`); either way it carries the switch only if it passed.
        let tuned = r["filter_tuning"]
            .as_array()
            .unwrap()
            .iter()
            .any(|t| t["written"].as_bool() == Some(true));
        let path = out.join("tables/filter.tbl");
        assert_eq!(
            path.exists(),
            expect || tuned,
            "{case}: filter.tbl written = {}; {}",
            path.exists(),
            r["filter_changes"]
        );
        if path.exists() {
            let filter: FilterTable = read_table_image(&path).unwrap();
            assert_eq!(filter.aberration_correction, expect, "{case}");
        }
        let manifest = std::fs::read_to_string(out.join("tables/manifest.json")).unwrap();
        assert_eq!(
            manifest.contains("filter.tbl"),
            path.exists(),
            "{case}: {manifest}"
        );
        if expect {
            assert!(z > 3.0, "{case}: z = {z}");
        } else {
            assert!(z < 0.0, "{case}: the data contradict the switch, z = {z}");
        }
    }
}

/// A sensor whose data lie in one block of time is never tested on data it was not fitted to
/// (its fit without that block fails): it keeps its flown alignment relative to the trackers,
/// and the report names it. On the writer's nominal run FSS2 sees the Sun in the last block
/// only.
#[test]
fn a_sensor_the_held_out_blocks_never_test_flies_as_before_relative_to_the_trackers() {
    let run = support::write_run("heldout", "one-block-fss2", &[]);
    let out = run.join("cal");
    let r = calibrate(&run, &out, &[]);
    let (passed, _, _, _, why) = validation(&r);
    assert!(passed, "{why}");
    let not_validated = &r["alignment_validation"]["not_validated"];
    assert_eq!(not_validated, &serde_json::json!(["FSS2"]), "{r:#}");
    let m =
        |t: &AlignmentTable, k: usize| fsw_core::tables::types::matrix_from_rows(t.matrices()[k]);
    let (new, flown) = (table(&out), AlignmentTable::prelaunch());
    // FSS2 relative to FHST1: the flown one; FHST1 itself moved (the prelaunch table is
    // hundreds of arcsec off), so this is not the flown matrix in the ACS frame.
    let rel_new = m(&new, 0).transpose() * m(&new, 3);
    let rel_flown = m(&flown, 0).transpose() * m(&flown, 3);
    assert!(
        (rel_new - rel_flown).amax() < 1e-12,
        "{rel_new} vs {rel_flown}"
    );
    assert!(
        (m(&new, 0) - m(&flown, 0)).amax() > 1e-4,
        "FHST1 should have moved"
    );
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(
        md.contains("Not validated, flown as before relative to the trackers:** FSS2"),
        "{md}"
    );
}

/// One damaged time code (the 0.5-s fine bit of one raw frame flipped) is one frame's
/// problem, and a 2-s OBC cycle is a cycle: before, the first halved the cycle the ground
/// inferred from the time codes and the second was capped at 1 s; either way every rate-mode
/// switch frame became unsplittable and IRUCAL lost every maneuver (exit 0).
#[test]
fn the_cycle_is_read_from_the_time_codes_that_recur() {
    for (case, flags) in [
        ("flip", ["--flip-time-bit", "2000:15"]),
        ("cycle-2s", ["--cycle-s", "2"]),
    ] {
        let run = support::write_run("cycle", case, &flags);
        let r = calibrate(&run, &run.join("cal"), &[]);
        assert_eq!(
            r["data"]["rate_switch_frames_dropped"], 0,
            "{case}: {:#}",
            r["data"]
        );
        let maneuvers = r["maneuvers"].as_array().unwrap();
        assert_eq!(maneuvers.len(), 3, "{case}");
        assert!(
            maneuvers.iter().all(|m| m["used"] == true),
            "{case}: {:#}",
            r["iru_skipped"]
        );
    }
}
