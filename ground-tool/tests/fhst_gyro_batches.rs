//! FFCAL's FHST stage from the gyro batches (`pipeline::star_batches`,
//! `calibration::fhst_relative`) on telemetry from the independent ICD writer
//! (`tests/icd/write_run.py`): slews the rate-mode flag does not mark, and slews fast enough
//! for the flown gyro's δM to matter. The FHST2-relative-to-FHST1 alignment must be
//! consistent with its stated covariance: NEES below χ²₃'s 0.999 quantile (16.3). Before the
//! batches followed the gyro's motion, the low-rate case gave NEES 222 (a 0.4°/s slew inside a
//! 1200-s "hold" batch) and the δM case 38 (the flown `G` through a 72° slew batch).
//! python3 is required (CI has it).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod support;

use nalgebra::{Matrix3, Vector3};
use serde_json::Value;

/// χ²₃ at p = 0.999.
const NEES_MAX: f64 = 16.27;

fn vec3(v: &Value) -> Vector3<f64> {
    Vector3::from_iterator(v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()))
}

/// Write the writer's `--plan long` day with `flags`, calibrate it, and return the NEES of
/// FHST2 relative to FHST1 against the writer's truth, with the error and the σ (arcsec).
fn fhst2_relative_nees(case: &str, flags: &[&str]) -> (f64, Vector3<f64>, Vector3<f64>) {
    let mut all = vec!["--seed", "1", "--plan", "long", "--hold-s", "600"];
    all.extend_from_slice(flags);
    let run = support::write_run("gyro-batches", case, &all);
    let out = run.join("cal");
    let report = support::calibrate_json(env!("CARGO_BIN_EXE_ground-tool"), &run, &out, &[]);
    let truth: Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("truth_icd.json")).unwrap())
            .unwrap();
    let _ = std::fs::remove_dir_all(&run);
    assert_eq!(report["ffcal"]["fhst_stage"], "gyro_batches", "{report:#}");
    let est = |k: &str| vec3(&report["alignments"][k]["theta_acs_arcsec"]);
    let inj = |k: &str| vec3(&truth["injected_rotation_acs_arcsec"][k]);
    let err = (est("FHST2") - inj("FHST2")) - (est("FHST1") - inj("FHST1"));
    let rows = report["ffcal"]["relative_covariance_to_fhst1_arcsec2"]["FHST2"]
        .as_array()
        .unwrap();
    let cov = Matrix3::from_fn(|i, j| rows[i][j].as_f64().unwrap());
    let nees = (err.transpose() * cov.try_inverse().unwrap() * err)[(0, 0)];
    (nees, err, cov.diagonal().map(f64::sqrt))
}

/// Slews at 0.4°/s flown in LOW rate mode: the holds must end where the gyro turns.
#[test]
fn low_rate_slews_end_the_hold_batches() {
    let (nees, err, sigma) = fhst2_relative_nees(
        "low-rate-slews",
        &["--slew-rate-deg-s", "0.4", "--low-rate-slews"],
    );
    assert!(
        nees < NEES_MAX,
        "NEES {nees:.1}: error {err:.1?}″ against σ {sigma:.1?}″"
    );
}

/// High-rate slews at 0.4°/s with a true δM of up to 1800 ppm: the slew batches must carry
/// the flown gyro's δM uncertainty.
#[test]
fn fast_slews_carry_the_flown_gyro_scale_uncertainty() {
    let (nees, err, sigma) = fhst2_relative_nees(
        "fast-slews-delta-m",
        &[
            "--slew-rate-deg-s",
            "0.4",
            "--iru-delta-m",
            "1500,-800,600,-700,1200,-900,500,-600,1800",
        ],
    );
    assert!(
        nees < NEES_MAX,
        "NEES {nees:.1}: error {err:.1?}″ against σ {sigma:.1?}″"
    );
    // The σ stays useful: the stars still pin the relative alignment to ≲ 10″.
    assert!(sigma.x < 10.0 && sigma.y < 10.0, "σ {sigma:.1?}″");
}
