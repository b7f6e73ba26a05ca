//! # Scoring against the simulator's truth (only when `truth.json` exists; never used by the
//! analysis itself)
//!
//! * **Calibration error** per sensor: the rotation between estimated and true `M_AS`, with
//!   the common rotation of the FHST pair removed (absolute alignment is indistinguishable
//!   from attitude; the FHST pair defines the frame the OBC flies), arcsec.
//! * **Effect truth**: `truth.json` lists the present and undeclared effects by name; the
//!   parameter values come from the scenario file (`scenarios/undeclared/NAME.toml`, then
//!   `scenarios/NAME.toml`) when it can be found, mapped to the library's parameters.

use super::Detected;
use fsw_core::attitude::rotvec_from_rot;
use fsw_core::tables::types::matrix_from_rows;
use fsw_core::tables::AlignmentTable;
use fsw_core::units::ARCSEC_PER_RAD;
use nalgebra::{Matrix3, Vector3};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::Path;

/// Truth read from `truth.json`.
#[derive(Clone, Debug)]
pub struct Truth {
    /// Scenario name.
    pub scenario: String,
    /// True alignments (sensor order).
    pub alignments: [Matrix3<f64>; 4],
    /// Undeclared effects.
    pub undeclared: Vec<String>,
    /// Present effects.
    pub present: Vec<String>,
    /// The scenario, if its file was found.
    pub scenario_file: Option<sim_harness::scenario::Scenario>,
}

/// Read `truth.json` (None when absent).
///
/// # Errors
/// A present but malformed file.
pub fn read_truth(run_dir: &Path) -> anyhow::Result<Option<Truth>> {
    let path = run_dir.join("truth.json");
    if !path.exists() {
        return Ok(None);
    }
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path)?)
        .map_err(|e| anyhow::anyhow!("{} is not valid JSON: {e}", path.display()))?;
    let names = ["FHST1", "FHST2", "FSS1", "FSS2"];
    let mut alignments = [Matrix3::identity(); 4];
    for (i, n) in names.iter().enumerate() {
        let rows: [[f64; 3]; 3] = serde_json::from_value(v["alignments"][n].clone())
            .map_err(|e| anyhow::anyhow!("truth.json alignments.{n}: {e}"))?;
        alignments[i] = matrix_from_rows(&rows);
    }
    let list = |k: &str| -> Vec<String> {
        v[k].as_array()
            .map(|a| {
                a.iter()
                    .filter_map(|x| x.as_str().map(str::to_owned))
                    .collect()
            })
            .unwrap_or_default()
    };
    let scenario = v["scenario"].as_str().unwrap_or_default().to_owned();
    let dir = sim_harness::scenario::scenarios_dir();
    let scenario_file = [
        dir.join("undeclared").join(format!("{scenario}.toml")),
        dir.join(format!("{scenario}.toml")),
    ]
    .iter()
    .find(|p| p.exists())
    .and_then(|p| sim_harness::scenario::Scenario::load(p).ok())
    .filter(|s| s.name == scenario);
    Ok(Some(Truth {
        scenario,
        alignments,
        undeclared: list("undeclared_effects"),
        present: list("present_effects"),
        scenario_file,
    }))
}

/// Calibration error per sensor (arcsec), FHST-pair common rotation removed.
#[must_use]
pub fn calibration_error_arcsec(est: &AlignmentTable, truth: &Truth) -> BTreeMap<String, f64> {
    let m: Vec<Matrix3<f64>> = est.matrices().iter().map(|r| matrix_from_rows(r)).collect();
    let e: Vec<Vector3<f64>> = (0..4)
        .map(|i| rotvec_from_rot(&(m[i] * truth.alignments[i].transpose())) * ARCSEC_PER_RAD)
        .collect();
    let common = (e[0] + e[1]) * 0.5;
    let names = super::measurements::SENSOR_NAMES;
    (0..4)
        .map(|i| (names[i].to_owned(), (e[i] - common).norm()))
        .collect()
}

/// One parameter compared with the truth.
#[derive(Clone, Debug, Serialize)]
pub struct ParameterCheck {
    /// Effect label.
    pub effect: String,
    /// Sensor.
    pub sensor: String,
    /// Parameter.
    pub parameter: String,
    /// Estimate.
    pub estimate: f64,
    /// 1σ.
    pub sigma: f64,
    /// True value.
    pub truth: f64,
    /// (estimate − truth)/σ.
    pub z: f64,
}

fn unit_of(sensor: &str) -> String {
    sensor.to_ascii_lowercase()
}

/// Does a detection name an effect that is in the truth for that unit?
#[must_use]
pub fn matches_truth(d: &Detected, truth: &Truth) -> bool {
    let name = match d.effect.as_str() {
        "aberration_annual" => "aberration".to_owned(),
        "aberration_orbital" => "orbital_aberration".to_owned(),
        "gyro_scale_asymmetry" => "iru.scale_asymmetry".to_owned(),
        "gyro_thermal_bias" => "iru.thermal_bias".to_owned(),
        "gyro_bias_transient" | "gyro_bias_ramp" => "iru_bias_transient".to_owned(),
        "orbit_periodic_alignment" | "thermal_alignment_drift" => {
            format!("{}.thermal_alignment_drift", unit_of(&d.sensor))
        }
        "catalog_proper_motion_error" => "catalog_proper_motion_error".to_owned(),
        "fss_transfer_function" => "fss_transfer_function".to_owned(),
        other => format!("{}.{other}", unit_of(&d.sensor)),
    };
    truth.present.iter().any(|p| *p == name)
}

/// Truth values of a detection's parameters (from the scenario file).
#[must_use]
pub fn parameter_truth(
    d: &Detected,
    truth: &Truth,
    aberration_k0: [f64; 2],
) -> BTreeMap<String, f64> {
    let mut out = BTreeMap::new();
    let Some(s) = &truth.scenario_file else {
        return out;
    };
    let fhst = |n: &str| {
        if n == "FHST1" {
            Some(&s.fhst1)
        } else if n == "FHST2" {
            Some(&s.fhst2)
        } else {
            None
        }
    };
    let fss = |n: &str| {
        if n == "FSS1" {
            Some(&s.fss1)
        } else if n == "FSS2" {
            Some(&s.fss2)
        } else {
            None
        }
    };
    let sensor = d.sensor.as_str();
    match d.effect.as_str() {
        "aberration_annual" => {
            out.insert("k_annual_minus_applied".into(), 1.0 - aberration_k0[0]);
        }
        "aberration_orbital" => {
            let k = if s.sky.orbital_aberration { 1.0 } else { 0.0 };
            out.insert("k_orbital_minus_applied".into(), k - aberration_k0[1]);
        }
        "time_tag_offset" => {
            let tau = fhst(sensor)
                .map(|f| f.effects.time_tag_offset_s)
                .or_else(|| fss(sensor).map(|f| f.effects.time_tag_offset_s));
            if let Some(t) = tau {
                out.insert("tau".into(), t * 1e3);
            }
        }
        "thermal_alignment_drift" => {
            let k = fhst(sensor)
                .map(|f| f.effects.thermal_alignment_arcsec_per_c)
                .or_else(|| fss(sensor).map(|f| f.effects.thermal_alignment_arcsec_per_c));
            if let Some(k) = k {
                for (i, n) in ["x", "y", "z"].iter().enumerate() {
                    out.insert((*n).to_owned(), k[i]);
                }
            }
        }
        "fhst_distortion" => {
            if let Some(f) = fhst(sensor) {
                out.insert(
                    "radial_at_4deg".into(),
                    f.effects.radial_distortion_arcsec_at_4deg,
                );
                out.insert(
                    "hv_h_at_corner".into(),
                    f.effects.hv_distortion_arcsec_at_corner[0],
                );
                out.insert(
                    "hv_v_at_corner".into(),
                    f.effects.hv_distortion_arcsec_at_corner[1],
                );
            }
        }
        "magnitude_bias" => {
            if let Some(f) = fhst(sensor) {
                out.insert(
                    "h_per_mag".into(),
                    f.effects.magnitude_bias_arcsec_per_mag[0],
                );
                out.insert(
                    "v_per_mag".into(),
                    f.effects.magnitude_bias_arcsec_per_mag[1],
                );
            }
        }
        "fss_transfer_function" => {
            if let Some(f) = fss(sensor) {
                for (head, h) in [("alpha", &f.alpha), ("beta", &f.beta)] {
                    out.insert(format!("{head}_scale"), h.scale_ppm);
                    out.insert(format!("{head}_cross_at_corner"), h.cross_arcsec_at_corner);
                    out.insert(format!("{head}_cubic_at_edge"), h.cubic_arcsec_at_edge);
                    out.insert(format!("{head}_cyclic_sin"), h.cyclic_arcsec);
                    out.insert(format!("{head}_cyclic_cos"), 0.0);
                }
                out.insert("pitch_deg".into(), f.alpha.cyclic_pitch_deg);
            }
        }
        "gyro_scale_asymmetry" => {
            let a = s.iru.effects.scale_asymmetry_ppm;
            for (n, ch) in [("x", 1), ("y", 2), ("z", 4)] {
                out.insert(n.into(), a[ch]);
            }
        }
        "gyro_thermal_bias" => {
            let k = s.iru.effects.thermal_bias_deg_per_s_per_c;
            for (n, ch) in [("x", 1), ("y", 2), ("z", 4)] {
                out.insert(n.into(), k[ch] * 3600.0);
            }
        }
        _ => {}
    }
    out
}

/// Compare every detection's parameters with the truth.
#[must_use]
pub fn check_parameters(
    detected: &[Detected],
    truth: &Truth,
    aberration_k0: [f64; 2],
) -> Vec<ParameterCheck> {
    let mut out = Vec::new();
    for d in detected {
        for (k, t) in parameter_truth(d, truth, aberration_k0) {
            if let (Some(&e), Some(&s)) = (d.parameters.get(&k), d.sigma.get(&k)) {
                out.push(ParameterCheck {
                    effect: d.effect.clone(),
                    sensor: d.sensor.clone(),
                    parameter: k,
                    estimate: e,
                    sigma: s,
                    truth: t,
                    z: (e - t) / s,
                });
            }
        }
    }
    out
}
