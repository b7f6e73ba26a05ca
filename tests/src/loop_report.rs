//! # Before/after comparison of the calibration loop (scoring against truth)
//!
//! Truth (`truth.json`) is used only here, to score; the calibration never sees it.

use anyhow::Context;
use fsw_core::attitude::rotvec_from_rot;
use fsw_core::tables::types::matrix_from_rows;
use fsw_core::tables::AlignmentTable;
use fsw_core::units::ARCSEC_PER_RAD;
use gro_reference::run_folder::Truth;
use ground_tool::calibration::alignment::FfcalSolution;
use ground_tool::pipeline::calibrate::{CalibrationOutput, SENSOR_NAMES};
use nalgebra::{Matrix3, Vector3};
use serde::Serialize;
use sim_harness::run::Summary;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

/// A quantity before and after the uplink.
#[derive(Clone, Debug, Serialize, Default)]
pub struct Pair<T> {
    /// Flown with the prelaunch tables.
    pub before: T,
    /// Flown with the calibrated tables.
    pub after: T,
}

impl Pair<BTreeMap<String, f64>> {
    /// Each key of `before` with its value before and after (NaN where `after` lacks it).
    fn by_key(&self) -> impl Iterator<Item = (&String, f64, f64)> + '_ {
        self.before.iter().map(|(k, b)| {
            let a = self.after.get(k).copied().unwrap_or(f64::NAN);
            (k, *b, a)
        })
    }
}

/// The loop's result.
#[derive(Clone, Debug, Serialize, Default)]
pub struct LoopReport {
    /// Scenario.
    pub scenario: String,
    /// Seed of both flights.
    pub seed: u64,
    /// Relative alignment error against truth, arcsec, per sensor pair
    /// (angle of `R_iᵀ R_j`, `R_k = M_k,table M_k,trueᵀ`).
    pub relative_alignment_error_arcsec: Pair<BTreeMap<String, f64>>,
    /// The calibration's stated 1σ of each relative alignment (largest ACS axis, ″): from
    /// FFCAL's covariance relative to FHST1 (pairs without FHST1: the root sum of squares).
    pub relative_alignment_sigma_arcsec: BTreeMap<String, f64>,
    /// Absolute alignment error against truth per sensor, arcsec (includes the common
    /// rotation that the adjustment deliberately keeps).
    pub absolute_alignment_error_arcsec: Pair<BTreeMap<String, f64>>,
    /// FFCAL residual RMS per sensor, arcsec (before: flown tables; after: calibrated).
    pub residual_rms_arcsec: Pair<BTreeMap<String, f64>>,
    /// Post-maneuver attitude error at each slew completion, deg.
    pub post_maneuver_error_deg: Pair<Vec<f64>>,
    /// Fine-attitude error, 3 × RMS per ACS axis (bias included), arcsec, outside slews.
    pub fine_attitude_error_3rms_arcsec: Pair<[f64; 3]>,
    /// Largest |δM element| error against the true δM, ppm (before = the prelaunch G, δM = 0).
    pub iru_delta_m_max_error_ppm: Pair<Option<f64>>,
    /// Every δM element within 3σ of truth.
    pub iru_delta_m_within_3sigma: Option<bool>,
    /// Filter NEES mean (3 = consistent).
    pub filter_nees_mean: Pair<Option<f64>>,
    /// The OBC's coarse attitude, 3 × RMS per ACS axis against truth, deg (issue 20; `None`
    /// when a flight made no coarse fix).
    pub coarse_attitude_error_3sigma_deg: Pair<Option<[f64; 3]>>,
    /// Wall time of each flight, s.
    pub flight_wall_seconds: Pair<f64>,
    /// Whole loop wall time, s.
    pub wall_seconds: f64,
}

/// The run's truth (`RUN_DIR/truth.json`, the one definition [`Truth`]).
///
/// # Errors
/// No `truth.json` in the folder, or one that is not a truth.
pub fn read_truth(run_dir: &Path) -> anyhow::Result<Truth> {
    Truth::read(run_dir)?.with_context(|| format!("no truth.json in {}", run_dir.display()))
}

/// The primary triad's true δM, when the truth has the IRU.
#[must_use]
pub fn true_delta_m(truth: &Truth) -> Option<Matrix3<f64>> {
    truth
        .iru
        .as_ref()
        .map(|iru| matrix_from_rows(&iru.primary.delta_m))
}

/// Error of FFCAL sensor `j`'s alignment relative to sensor 0 (FHST1) against the truth, ACS,
/// arcsec (`rotvec(R_j R_0ᵀ)`, `R_k = M_k,calibrated M_k,trueᵀ`), and its NEES with the stated
/// relative covariance (3 degrees of freedom).
///
/// # Errors
/// A sensor the truth does not name, a sensor index out of range, or a singular covariance.
pub fn relative_error_and_nees(
    solution: &FfcalSolution,
    truth: &Truth,
    j: usize,
) -> anyhow::Result<(Vector3<f64>, f64)> {
    let r = |k: usize| -> anyhow::Result<Matrix3<f64>> {
        let s = solution.sensors.get(k).context("sensor index")?;
        let t = truth
            .alignments
            .get(&s.id)
            .map(matrix_from_rows)
            .with_context(|| format!("truth.json alignments.{}", s.id))?;
        Ok(s.m_acs_from_sensor_calibrated * t.transpose())
    };
    let e = rotvec_from_rot(&(r(j)? * r(0)?.transpose())) * ARCSEC_PER_RAD;
    let p_inv = solution
        .relative_covariance_arcsec2(j, 0)
        .try_inverse()
        .context("singular relative covariance")?;
    Ok((e, (e.transpose() * p_inv * e)[(0, 0)]))
}

fn alignment_errors(
    table: &AlignmentTable,
    truth: &[Matrix3<f64>; 4],
) -> (BTreeMap<String, f64>, BTreeMap<String, f64>) {
    let est = table.matrices().map(matrix_from_rows);
    let r: Vec<Matrix3<f64>> = (0..4).map(|k| est[k] * truth[k].transpose()).collect();
    let mut relative = BTreeMap::new();
    for (i, j) in [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)] {
        let angle = rotvec_from_rot(&(r[i].transpose() * r[j])).norm() * ARCSEC_PER_RAD;
        relative.insert(format!("{}-{}", SENSOR_NAMES[i], SENSOR_NAMES[j]), angle);
    }
    let mut absolute = BTreeMap::new();
    for k in 0..4 {
        absolute.insert(
            SENSOR_NAMES[k].to_string(),
            rotvec_from_rot(&r[k]).norm() * ARCSEC_PER_RAD,
        );
    }
    (relative, absolute)
}

fn three_rms(s: &Summary) -> [f64; 3] {
    s.attitude_error_arcsec.rms.map(|x| 3.0 * x)
}

/// The stated 1σ of every sensor pair's relative alignment (largest ACS axis, ″).
fn stated_relative_sigma(calibration: &CalibrationOutput) -> BTreeMap<String, f64> {
    let rel = &calibration
        .report
        .ffcal
        .relative_covariance_to_fhst1_arcsec2;
    let var = |name: &str| -> f64 {
        if name == SENSOR_NAMES[0] {
            return 0.0;
        }
        rel.get(name)
            .map_or(f64::INFINITY, |c| c[0][0].max(c[1][1]).max(c[2][2]))
    };
    let mut out = BTreeMap::new();
    for i in 0..4 {
        for j in i + 1..4 {
            let (a, b) = (SENSOR_NAMES[i], SENSOR_NAMES[j]);
            out.insert(format!("{a}-{b}"), (var(a) + var(b)).sqrt());
        }
    }
    out
}

/// Score the loop against the truth of the first flight.
///
/// # Errors
/// None today (the truth is typed); kept for the callers' `?`.
pub fn compare(
    a: &Summary,
    b: &Summary,
    calibration: &CalibrationOutput,
    truth: &Truth,
) -> anyhow::Result<LoopReport> {
    let true_m = truth.alignments.into_array().map(|m| matrix_from_rows(&m));
    let (rel_before, abs_before) = alignment_errors(&AlignmentTable::prelaunch(), &true_m);
    let (rel_after, abs_after) = alignment_errors(&calibration.alignment, &true_m);
    let true_dm = true_delta_m(truth);
    let (dm_before, dm_after, within) = match (true_dm, &calibration.irucal) {
        (Some(t), Some(sol)) => {
            let err = sol.calibration.delta_m - t;
            let within = (0..9).all(|k| err[k].abs() <= 3.0 * sol.sigma_delta_m[k]);
            (
                Some(t.abs().max() * 1e6),
                Some(err.abs().max() * 1e6),
                Some(within),
            )
        }
        (Some(t), None) => (Some(t.abs().max() * 1e6), None, None),
        _ => (None, None, None),
    };
    Ok(LoopReport {
        scenario: a.scenario.clone(),
        seed: a.seed,
        relative_alignment_error_arcsec: Pair {
            before: rel_before,
            after: rel_after,
        },
        relative_alignment_sigma_arcsec: stated_relative_sigma(calibration),
        absolute_alignment_error_arcsec: Pair {
            before: abs_before,
            after: abs_after,
        },
        residual_rms_arcsec: Pair {
            before: calibration.report.residual_rms_arcsec.before.clone(),
            after: calibration.report.residual_rms_arcsec.after.clone(),
        },
        post_maneuver_error_deg: Pair {
            before: a.post_maneuver_error_deg.clone(),
            after: b.post_maneuver_error_deg.clone(),
        },
        fine_attitude_error_3rms_arcsec: Pair {
            before: three_rms(a),
            after: three_rms(b),
        },
        iru_delta_m_max_error_ppm: Pair {
            before: dm_before,
            after: dm_after,
        },
        iru_delta_m_within_3sigma: within,
        filter_nees_mean: Pair {
            before: a.filter_nees_mean,
            after: b.filter_nees_mean,
        },
        coarse_attitude_error_3sigma_deg: Pair {
            before: a.coarse_attitude_error_3sigma_deg,
            after: b.coarse_attitude_error_3sigma_deg,
        },
        flight_wall_seconds: Pair {
            before: a.timing.wall_seconds,
            after: b.timing.wall_seconds,
        },
        wall_seconds: 0.0,
    })
}

/// The before/after table for people.
#[must_use]
pub fn render_markdown(r: &LoopReport) -> String {
    let mut md = String::new();
    let _ = writeln!(md, "# Calibration loop: {} (seed {})\n", r.scenario, r.seed);
    let _ = writeln!(
        md,
        "| quantity | before (prelaunch tables) | after (calibrated, uplinked) |"
    );
    let _ = writeln!(md, "|---|---|---|");
    for (k, before, after) in r.relative_alignment_error_arcsec.by_key() {
        let _ = writeln!(
            md,
            "| relative alignment error {k} (″, vs truth) | {before:.1} | {after:.1} |"
        );
    }
    for (k, before, after) in r.residual_rms_arcsec.by_key() {
        let _ = writeln!(md, "| residual RMS {k} (″) | {before:.1} | {after:.1} |");
    }
    let fmt_list = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{x:.4}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let _ = writeln!(
        md,
        "| post-maneuver error per slew (°) | {} | {} |",
        fmt_list(&r.post_maneuver_error_deg.before),
        fmt_list(&r.post_maneuver_error_deg.after)
    );
    let f = |a: [f64; 3]| format!("[{:.1}, {:.1}, {:.1}]", a[0], a[1], a[2]);
    let _ = writeln!(
        md,
        "| fine-attitude error 3×RMS per axis (″; requirement 86.4″) | {} | {} |",
        f(r.fine_attitude_error_3rms_arcsec.before),
        f(r.fine_attitude_error_3rms_arcsec.after)
    );
    let o = |x: Option<f64>| x.map_or("n/a".to_string(), |v| format!("{v:.0}"));
    let _ = writeln!(
        md,
        "| IRU δM max element error (ppm, vs truth) | {} | {}{} |",
        o(r.iru_delta_m_max_error_ppm.before),
        o(r.iru_delta_m_max_error_ppm.after),
        match r.iru_delta_m_within_3sigma {
            Some(true) => " (all within 3σ)",
            Some(false) => " (NOT all within 3σ)",
            None => "",
        }
    );
    let n = |x: Option<f64>| x.map_or("n/a".to_string(), |v| format!("{v:.2}"));
    let _ = writeln!(
        md,
        "| filter NEES mean (3 = consistent) | {} | {} |",
        n(r.filter_nees_mean.before),
        n(r.filter_nees_mean.after)
    );
    let c = |x: Option<[f64; 3]>| {
        x.map_or("n/a".to_string(), |v| {
            format!("[{:.2}, {:.2}, {:.2}]", v[0], v[1], v[2])
        })
    };
    let _ = writeln!(
        md,
        "| coarse attitude error 3×RMS per axis (°; requirement 2°, FSS + TAM + IRU) | {} | {} |",
        c(r.coarse_attitude_error_3sigma_deg.before),
        c(r.coarse_attitude_error_3sigma_deg.after)
    );
    let _ = writeln!(
        md,
        "\nWall time: {:.1} s (flights {:.1} s and {:.1} s).",
        r.wall_seconds, r.flight_wall_seconds.before, r.flight_wall_seconds.after
    );
    md
}
