//! The calibration report people read, and the tables' provenance, on a small run.
//!
//! Why (issue 21): the report showed 4 of the 6 sensor pairs and did not link every plot it
//! wrote; tables calibrated on one spacecraft were flown on another without a word. One
//! 100-minute flight of `gro-early-mission` (both trackers, FSS1 and the Sun, one slew) is
//! calibrated as `ground-tool calibrate` does it; the checks:
//! * every PNG in the report folder is linked from report.md, and every link is a file;
//! * a pair's residual plot exists exactly when the pair has common epochs, and a pair
//!   without is listed as not plotted;
//! * the OBC bias series read from the housekeeping alone equals the chain's decoding, on the
//!   clean file and on a damaged copy;
//! * `provenance.json` lets the simulator tell the same spacecraft (no warning, also on
//!   another plan) from another one (a warning naming the file, the field and the part).

use ground_tool::pipeline::calibrate::{calibrate_run, CalibrateOptions, SENSOR_NAMES};
use ground_tool::report::{
    pair_plot_name, pair_series, write_calibration_report, ObcBiasSeries, MIN_PAIR_SAMPLES,
    SENSOR_PAIRS,
};
use sim_harness::scenario::resolve;
use std::path::Path;

mod support;
use support::fly;

#[test]
fn report_links_every_plot_and_tables_know_their_spacecraft() {
    let root = Path::new(env!("CARGO_TARGET_TMPDIR")).join("report-plots");
    let _ = std::fs::remove_dir_all(&root);
    let mut scenario = resolve("gro-early-mission").unwrap();
    // Through the fourth slew's hold (slews at 1200, 3058, 5027, 6714 s): IRUCAL needs three
    // maneuvers joined to attitude fixes. Cut at 6000 s it had exactly three with the ideal
    // unloading torque; with the torquer bars (docs/magnetics.md §7) the hold after slew 2
    // has no ground batch with two referenced vectors, so only two were carried and no bias
    // history (nor bias_difference.png) was written.
    scenario.duration_s = 8400.0;
    let fly_a = root.join("a");
    fly(scenario.clone(), &fly_a, None);

    // The calibrate command's steps (ground-tool main.rs run_calibrate).
    let obc = ObcBiasSeries::read(&fly_a).unwrap();
    let cal = root.join("cal");
    let out = calibrate_run(&fly_a, &cal, &CalibrateOptions::default()).unwrap();
    let meta = ground_tool::pipeline::flown::metadata_or_default(&fly_a);
    gro_reference::provenance::write(&cal.join("tables"), &fly_a, &meta, "test").unwrap();
    let flown = fsw_core::tables::AlignmentTable::prelaunch();
    write_calibration_report(&cal, &out, &flown, Some(&obc)).unwrap();

    // Every PNG linked, every link a file.
    let md = std::fs::read_to_string(cal.join("report.md")).unwrap();
    let pngs: Vec<String> = std::fs::read_dir(&cal)
        .unwrap()
        .filter_map(Result::ok)
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".png"))
        .collect();
    for p in &pngs {
        assert!(
            md.contains(&format!("]({p})")),
            "{p} is not linked from report.md"
        );
    }
    let links: Vec<&str> = md
        .split("](")
        .skip(1)
        .filter_map(|s| s.split(')').next())
        .collect();
    for l in &links {
        assert!(
            cal.join(l).is_file(),
            "report.md links {l}, which is not in the folder"
        );
    }
    assert!(pngs.contains(&"bias_history.png".to_owned()), "{pngs:?}");
    assert!(pngs.contains(&"bias_difference.png".to_owned()), "{pngs:?}");

    // A pair's plot exists exactly when the pair has common epochs.
    let mut with_data = 0;
    for (i, j) in SENSOR_PAIRS {
        let (b, a) = pair_series(&out.frames, i, j, &flown, &out.alignment);
        let name = pair_plot_name(i, j);
        let has = b.len() >= MIN_PAIR_SAMPLES && a.len() >= MIN_PAIR_SAMPLES;
        let pair = format!("{}–{}", SENSOR_NAMES[i], SENSOR_NAMES[j]);
        assert_eq!(cal.join(&name).is_file(), has, "{name}: {} epochs", b.len());
        if has {
            with_data += 1;
            assert!(md.contains(&format!("Did calibration reduce the {pair} residual?")));
        } else {
            assert!(
                md.contains(&format!(
                    "Did calibration reduce the {pair} residual? — not plotted"
                )),
                "{pair} without data is not listed as not plotted"
            );
        }
    }
    // This flight gives FHST1–FHST2, FHST1–FSS1 and FHST2–FSS1 (FSS2 never sees the Sun in
    // its first 100 minutes): the pairs beyond the first four of the old report are there.
    assert!(with_data >= 3, "{with_data} pairs with data");
    assert!(cal.join("residual_fhst2_fss1.png").is_file());

    // The housekeeping read alone equals the chain's decoding, clean and damaged.
    let tm = ground_tool::tp::read_file(&fly_a.join("telemetry.bin")).unwrap();
    let full = ObcBiasSeries::from_telemetry(&tm);
    assert!(obc.t_s.len() > 1000);
    assert_eq!(obc.t_s, full.t_s);
    assert_eq!(obc.bias_rad_per_s, full.bias_rad_per_s);
    let mut bytes = std::fs::read(fly_a.join("telemetry.bin")).unwrap();
    let mid = bytes.len() / 2;
    bytes.splice(mid..mid, [0xA5u8; 37]);
    let damaged = root.join("damaged");
    std::fs::create_dir_all(&damaged).unwrap();
    std::fs::write(damaged.join("telemetry.bin"), &bytes).unwrap();
    let from_damaged = ObcBiasSeries::read(&damaged).unwrap();
    let decoded = ObcBiasSeries::from_telemetry(&ground_tool::tp::decode(&bytes));
    assert_eq!(from_damaged.t_s, decoded.t_s);
    assert!(from_damaged.t_s.len() + 2 >= obc.t_s.len());

    // Provenance: the same spacecraft on another plan raises nothing; another one is named.
    let tables = cal.join("tables");
    let mut other_plan = resolve("normal-ops").unwrap();
    other_plan.duration_s = 300.0;
    let same = fly(other_plan.clone(), &root.join("ops"), Some(&tables));
    assert_eq!(same.tables_provenance_warning, None);
    let mut other_craft = other_plan;
    other_craft.name = "other-craft".into();
    other_craft.fss1.misalignment_true_arcsec = Some([500.0, -300.0, 100.0]);
    let foreign = fly(other_craft, &root.join("other"), Some(&tables));
    let w = foreign
        .tables_provenance_warning
        .expect("tables of gro-early-mission flown on another spacecraft");
    assert!(w.starts_with("warning:"), "{w}");
    assert!(
        w.contains("provenance.json") && w.contains("spacecraft.id"),
        "{w}"
    );
    assert!(w.contains("true FSS1 parameters differ"), "{w}");
    // The same warning is in the run's summary.json.
    let summary: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(root.join("other").join("summary.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(summary["tables_provenance_warning"], serde_json::json!(w));
    let _ = std::fs::remove_dir_all(&root);
}
