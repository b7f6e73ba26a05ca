//! # `report.json` and `report.md` of `ground-tool diagnose`, with before/after plots
//!
//! `report.json` carries `detected` (list of `{effect, sensor, parameters, sigma, units,
//! evidence}`), `unexplained` (list of `{sensor, regressor, axis, method, size, unit, p_value,
//! also_follows, source, reason}`), `ledger` (every test significant after its multiplicity
//! correction and its outcome: explained by the accepted effects or unexplained with the
//! reason, [`super::ledger`]),
//! `residual_rms_arcsec.before/.after` per sensor, `iterations`, and — only when the run
//! folder has a `truth.json`, labelled as scoring — `calibration_error_arcsec.before/.after`
//! and a parameter check against the scenario.

use super::gyro::GyroAnalysis;
use super::measurements::{axis_names, SENSOR_NAMES};
pub use super::scoring::{BeforeAfter, Scoring};
use super::search::Iteration;
use super::structure::{binned_means, Regressor};
use super::{Analysis, Detected, Unexplained};
use crate::report::{plot_series, Series};
use plotters::style::RGBColor;
use serde::Serialize;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

/// The whole report.
#[derive(Clone, Debug, Serialize)]
pub struct DiagnoseReport {
    /// Run folder.
    pub run_dir: String,
    /// Scenario (metadata).
    pub scenario: String,
    /// Effects the operator declares (in the model from the start).
    pub declared_effects: Vec<String>,
    /// Library effects in the baseline model because they are declared.
    pub baseline_model: Vec<String>,
    /// Detected effects (sensor side and gyro).
    pub detected: Vec<Detected>,
    /// Structure no candidate explains.
    pub unexplained: Vec<Unexplained>,
    /// Every significant test and its outcome ([`super::ledger`]).
    pub ledger: Vec<super::ledger::LedgerEntry>,
    /// Residual RMS per sensor (arcsec): the calibration chain's model vs the final model.
    pub residual_rms_arcsec: BeforeAfter,
    /// White-noise floor per sensor (arcsec, successive differences).
    pub noise_floor_arcsec: BTreeMap<String, f64>,
    /// Measurements used per sensor.
    pub measurements: BTreeMap<String, usize>,
    /// Iterations of the loop (the last one adds nothing).
    pub iterations: usize,
    /// The loop, candidate by candidate.
    pub iteration_log: Vec<Iteration>,
    /// Gyro analysis: candidates, samples, notes.
    pub gyro: GyroSummary,
    /// Flight tables written and what went in.
    pub flight_tables: FlightSummary,
    /// Scoring only (truth.json): alignment error per sensor before (calibration chain) and
    /// after (diagnose), arcsec: RMS direction error over the sensor's measurements of this
    /// run, FHST-pair common rotation removed ([`super::scoring::calibration_error_arcsec`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub calibration_error_arcsec: Option<BeforeAfter>,
    /// Scoring only: the full rotation angle of the same alignment errors (includes
    /// rotations the data do not constrain), arcsec.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub calibration_rotation_error_arcsec: Option<BeforeAfter>,
    /// Scoring only: the error of the alignment tables *written* (what flies), before = the
    /// one `calibrate` writes for the same telemetry, after = diagnose's `tables/alignment.tbl`
    /// (with the field terms it carries), arcsec, as `calibration_error_arcsec` but against
    /// the alignments at the end of the run (truth.json `alignments_after_run`: a step applied).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub written_table_error_arcsec: Option<BeforeAfter>,
    /// Scoring only: the same for the table diagnose would have written without its held-out
    /// validation (every term of its flight model), for the record of what the gate changed.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unvalidated_table_error_arcsec: Option<BTreeMap<String, f64>>,
    /// Scoring only (truth.json).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scoring: Option<Scoring>,
    /// Plots written.
    pub plots: Vec<String>,
    /// Notes (e.g. the calibration chain could not run).
    pub notes: Vec<String>,
}

/// Gyro part of the report.
#[derive(Clone, Debug, Default, Serialize)]
pub struct GyroSummary {
    /// Hold-to-hold bias samples.
    pub bias_samples: usize,
    /// Slews used.
    pub slews: usize,
    /// Candidates and their evidence.
    pub candidates: Vec<super::search::Evidence>,
    /// Notes.
    pub notes: Vec<String>,
}

/// Flight-table part of the report.
#[derive(Clone, Debug, Default, Serialize)]
pub struct FlightSummary {
    /// Files written.
    pub written: Vec<String>,
    /// What went in.
    pub applied: Vec<String>,
    /// Ground-only effects (and, when the held-out validation refused them, the terms that
    /// would have gone up).
    pub ground_only: Vec<String>,
    /// Held-out validation of diagnose's tables against the alignment table `calibrate`
    /// writes ([`super::heldout`]); `None` when there was nothing to validate.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub validation: Option<super::heldout::FlightTableValidation>,
}

const BLUE: RGBColor = RGBColor(31, 119, 180);
const ORANGE: RGBColor = RGBColor(255, 127, 14);
const GREEN: RGBColor = RGBColor(44, 160, 44);
const RED: RGBColor = RGBColor(214, 39, 40);

fn regressor_for(d: &Detected, a: &Analysis) -> Option<(usize, usize, Regressor)> {
    let sensor = SENSOR_NAMES.iter().position(|s| *s == d.sensor);
    let reg = match d.effect.as_str() {
        "aberration_annual" | "aberration" => Regressor::VelocityX,
        "aberration_orbital" => Regressor::OrbitPhase,
        "time_tag_offset" => Regressor::RateX,
        "thermal_alignment_drift" => Regressor::Temperature,
        "orbit_periodic_alignment" => Regressor::OrbitPhase,
        "fhst_distortion" => Regressor::FovH,
        "magnitude_bias" => Regressor::Magnitude,
        "fss_transfer_function" => Regressor::FovH,
        "catalog_proper_motion_error" => Regressor::StarId,
        _ => return None,
    };
    // The sensor/axis (and, for rates and FOV, the component) with the strongest structure
    // before.
    let regs: Vec<Regressor> = match reg {
        Regressor::RateX => vec![Regressor::RateX, Regressor::RateY, Regressor::RateZ],
        Regressor::FovH => vec![Regressor::FovH, Regressor::FovV, Regressor::FovRadius],
        Regressor::VelocityX => vec![Regressor::VelocityX, Regressor::VelocityY],
        r => vec![r],
    };
    a.search
        .tests_before
        .iter()
        .filter(|t| sensor.is_none_or(|s| s == t.sensor) && regs.contains(&t.regressor))
        .max_by(|x, y| x.f.total_cmp(&y.f))
        .map(|t| (t.sensor, t.axis, t.regressor))
        .or_else(|| sensor.map(|s| (s, 0, reg)))
}

fn plot_before_after(
    out: &Path,
    name: &str,
    a: &Analysis,
    sensor: usize,
    axis: usize,
    reg: Regressor,
    title: &str,
) -> anyhow::Result<String> {
    let bins = if reg == Regressor::StarId { 0 } else { 24 };
    let pts = |post: &super::fit::PostFit| -> Vec<(f64, f64)> {
        if bins == 0 {
            // Per-star means.
            let mut m: BTreeMap<u32, (f64, f64)> = BTreeMap::new();
            for (meas, r) in a.set.meas.iter().zip(&post.resid) {
                if meas.sensor == sensor && !meas.outlier {
                    let e = m.entry(meas.star).or_insert((0.0, 0.0));
                    e.0 += r[axis];
                    e.1 += 1.0;
                }
            }
            m.into_iter()
                .filter(|(_, (_, n))| *n >= 20.0)
                .map(|(h, (s, n))| (f64::from(h), s / n))
                .collect()
        } else {
            binned_means(&a.set, post, sensor, axis, reg, bins)
                .into_iter()
                .map(|(x, m, _)| (x, m))
                .collect()
        }
    };
    let file = format!("{name}.png");
    plot_series(
        &out.join(&file),
        title,
        reg.name(),
        &format!(
            "{} {} residual (arcsec, binned mean)",
            SENSOR_NAMES[sensor],
            axis_names(sensor)[axis]
        ),
        &[
            Series {
                label: "before (calibration chain + declared effects)".into(),
                points: pts(&a.search.before),
                color: ORANGE,
            },
            Series {
                label: "after (final model)".into(),
                points: pts(&a.search.after),
                color: BLUE,
            },
        ],
    )?;
    Ok(file)
}

/// Plots: each detected effect and each unexplained structure against its regressor, the
/// gyro bias history and the slew residuals.
///
/// # Errors
/// Drawing or I/O failure.
pub fn write_plots(
    out: &Path,
    a: &Analysis,
    detected: &[Detected],
    gyro: &GyroAnalysis,
) -> anyhow::Result<Vec<String>> {
    let mut files = Vec::new();
    for (i, d) in detected.iter().enumerate() {
        if d.sensor == "IRU" {
            continue;
        }
        if let Some((s, ax, reg)) = regressor_for(d, a) {
            let title = format!(
                "{} [{}]: residual vs {} before/after",
                d.effect,
                d.sensor,
                reg.name()
            );
            files.push(plot_before_after(
                out,
                &format!("detected_{i}_{}_{}", d.effect, d.sensor),
                a,
                s,
                ax,
                reg,
                &title,
            )?);
        }
    }
    for (i, u) in a.unexplained.iter().enumerate() {
        let Some(s) = SENSOR_NAMES.iter().position(|n| *n == u.sensor) else {
            continue;
        };
        let Some(reg) = Regressor::ALL
            .iter()
            .copied()
            .find(|r| r.name() == u.regressor)
        else {
            continue;
        };
        let ax = axis_names(s).iter().position(|n| *n == u.axis).unwrap_or(0);
        let title = format!(
            "UNEXPLAINED {} {}: residual vs {} ({:.1}″, p {:.1e})",
            u.sensor, u.axis, u.regressor, u.size, u.p_value
        );
        files.push(plot_before_after(
            out,
            &format!("unexplained_{i}_{}", u.sensor),
            a,
            s,
            ax,
            reg,
            &title,
        )?);
    }
    if !gyro.bias_series.is_empty() {
        let colors = [BLUE, ORANGE, GREEN];
        // Axis `ax` of a bias series against time in hours.
        let in_hours = |points: &[(f64, [f64; 3])], ax: usize| -> Vec<(f64, f64)> {
            points.iter().map(|(t, v)| (*t / 3600.0, v[ax])).collect()
        };
        let mut series = Vec::new();
        for ax in 0..3 {
            series.push(Series {
                label: format!("bias error {} (hold-to-hold)", ["x", "y", "z"][ax]),
                points: in_hours(&gyro.bias_series, ax),
                color: colors[ax],
            });
            if !gyro.bias_fit_after.is_empty() {
                series.push(Series {
                    label: format!("final model {}", ["x", "y", "z"][ax]),
                    points: in_hours(&gyro.bias_fit_after, ax),
                    color: RED,
                });
            }
        }
        plot_series(
            &out.join("gyro_bias.png"),
            "Gyro bias relative to the run mean of the OBC's estimate",
            "time (h)",
            "arcsec/s",
            &series,
        )?;
        files.push("gyro_bias.png".into());
    }
    if !gyro.slew_residuals.is_empty() {
        plot_series(
            &out.join("gyro_slews.png"),
            "Slew residual about the slew axis vs signed slew angle",
            "slew angle (deg)",
            "attitude residual (arcsec)",
            &[
                Series {
                    label: "before (bias + scale)".into(),
                    points: gyro
                        .slew_residuals
                        .iter()
                        .map(|(a, r0, _)| (*a, *r0))
                        .collect(),
                    color: ORANGE,
                },
                Series {
                    label: "after (with asymmetry)".into(),
                    points: gyro
                        .slew_residuals
                        .iter()
                        .map(|(a, _, r1)| (*a, *r1))
                        .collect(),
                    color: BLUE,
                },
            ],
        )?;
        files.push("gyro_slews.png".into());
    }
    Ok(files)
}

fn fmt_params(d: &Detected) -> String {
    if d.parameters.len() > 12 {
        return format!("{} parameters (see report.json)", d.parameters.len());
    }
    d.parameters
        .iter()
        .map(|(k, v)| match d.sigma.get(k) {
            Some(s) => format!(
                "{k} = {v:.4} ± {s:.4} {}",
                d.units.get(k).map_or("", String::as_str)
            ),
            None => format!("{k} = {v:.4} {}", d.units.get(k).map_or("", String::as_str)),
        })
        .collect::<Vec<_>>()
        .join("<br>")
}

/// The ledger section: every significant test and how it ended.
fn ledger_markdown(s: &mut String, ledger: &[super::ledger::LedgerEntry]) {
    use super::ledger::Outcome;
    let _ = writeln!(
        s,
        "## Evidence ledger\n\nEvery test significant after its multiplicity correction (family-wise α = 0.001) and how it ended.\n"
    );
    if ledger.is_empty() {
        let _ = writeln!(s, "No significant test.\n");
        return;
    }
    let _ = writeln!(
        s,
        "| family | sensor | axis | regressor | test | size | p (corrected) | outcome |\n|---|---|---|---|---|---|---|---|"
    );
    for e in ledger {
        let outcome = match &e.outcome {
            Outcome::Explained { by } => format!("explained by {}", by.join(", ")),
            Outcome::Unexplained { reason } => format!("UNEXPLAINED: {reason}"),
        };
        let size = if e.size.is_finite() {
            format!("{:.2} {}", e.size, e.unit)
        } else {
            "–".to_owned()
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {size} | {:.2e} | {} |",
            e.family.name(),
            e.sensor,
            e.axis,
            e.regressor,
            e.test.replace('|', "/"),
            e.p_holm,
            outcome.replace('|', "/")
        );
    }
    s.push('\n');
}

/// The title, the run and its declared effects, the notes.
fn md_header(s: &mut String, r: &DiagnoseReport) {
    let _ = writeln!(s, "# ground-tool diagnose: {}\n", r.scenario);
    let _ = writeln!(
        s,
        "Run folder `{}`. Declared effects (in the model from the start): {}.",
        r.run_dir,
        r.declared_effects.join(", ")
    );
    let _ = writeln!(
        s,
        "Baseline model: calibration chain (FFCAL, adjustment, IRUCAL) + {}.\n",
        if r.baseline_model.is_empty() {
            "nothing else".to_owned()
        } else {
            r.baseline_model.join(", ")
        }
    );
    for n in &r.notes {
        let _ = writeln!(s, "> Note: {n}\n");
    }
}

/// The effects detected.
fn md_detected(s: &mut String, r: &DiagnoseReport) {
    let _ = writeln!(s, "## Detected effects\n");
    if r.detected.is_empty() {
        let _ = writeln!(
            s,
            "None: no candidate passed the likelihood-ratio, BIC, halves and adequacy tests.\n"
        );
    } else {
        let _ = writeln!(s, "| effect | sensor | parameters | ΔBIC | LR p (Holm) | halves p |\n|---|---|---|---|---|---|");
        for d in &r.detected {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {:.1} | {:.2e} | {:.3} |",
                d.effect,
                d.sensor,
                fmt_params(d),
                d.evidence.delta_bic,
                d.evidence.p_holm,
                d.evidence.halves_p
            );
        }
        s.push('\n');
    }
}

/// The structure left unexplained, then the ledger.
fn md_unexplained(s: &mut String, r: &DiagnoseReport) {
    let _ = writeln!(s, "## Unexplained structure\n");
    if r.unexplained.is_empty() {
        let _ = writeln!(s, "None at family-wise α = 0.001 (Holm).\n");
    } else {
        let _ = writeln!(
            s,
            "| sensor | axis | regressor | test | size | p (Holm) | also follows | why nothing was named |\n|---|---|---|---|---|---|---|---|"
        );
        for u in &r.unexplained {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {:.2} {} | {:.2e} | {} | {} |",
                u.sensor,
                u.axis,
                u.regressor,
                u.method,
                u.size,
                u.unit,
                u.p_value,
                u.also_follows.join(", "),
                u.reason.replace('|', "/")
            );
        }
        s.push('\n');
    }
    ledger_markdown(s, &r.ledger);
}

/// Residual RMS per sensor, before and after, with the noise floor.
fn md_residuals(s: &mut String, r: &DiagnoseReport) {
    let _ = writeln!(s, "## Residual RMS (arcsec, per axis)\n\n| sensor | measurements | before | after | noise floor |\n|---|---|---|---|---|");
    for n in SENSOR_NAMES {
        let g =
            |m: &BTreeMap<String, f64>| m.get(n).map_or("—".to_owned(), |v| format!("{v:.2}"));
        let _ = writeln!(
            s,
            "| {n} | {} | {} | {} | {} |",
            r.measurements.get(n).copied().unwrap_or(0),
            g(&r.residual_rms_arcsec.before),
            g(&r.residual_rms_arcsec.after),
            g(&r.noise_floor_arcsec)
        );
    }
}

/// The scoring against the truth, when a scorer was plugged in.
fn md_scoring(s: &mut String, r: &DiagnoseReport) {
    if let Some(c) = &r.calibration_error_arcsec {
        let _ = writeln!(s, "\n## Calibration error (SCORING ONLY: from truth.json)\n\nAlignment error per sensor (arcsec): RMS direction error over this run's measurements of the sensor, common FHST-pair rotation removed (the full rotation angles are in report.json).\n\n| sensor | before (chain) | after (diagnose) |\n|---|---|---|");
        for n in SENSOR_NAMES {
            let _ = writeln!(
                s,
                "| {n} | {:.2} | {:.2} |",
                c.before.get(n).copied().unwrap_or(f64::NAN),
                c.after.get(n).copied().unwrap_or(f64::NAN)
            );
        }
    }
    if let Some(sc) = &r.scoring {
        let _ = writeln!(
            s,
            "\nTruth's undeclared effects: {}.\n",
            sc.truth_undeclared_effects.join(", ")
        );
        let _ = writeln!(s, "True field functions: {}.\n", sc.field_truth);
        for (e, u, ok) in &sc.detections_in_truth {
            let _ = writeln!(
                s,
                "* detection {e} [{u}]: {}",
                if *ok {
                    "in the truth"
                } else {
                    "NOT in the truth (false alarm)"
                }
            );
        }
        if !sc.parameters.is_empty() {
            let _ = writeln!(s, "\n| effect | sensor | parameter | estimate | σ | truth | z |\n|---|---|---|---|---|---|---|");
            for p in &sc.parameters {
                let _ = writeln!(
                    s,
                    "| {} | {} | {} | {:.4} | {:.4} | {:.4} | {:.2} |",
                    p.effect, p.sensor, p.parameter, p.estimate, p.sigma, p.truth, p.z
                );
            }
        }
    }
}

/// The flight tables: written, applied, kept on the ground, validation; the gyro side.
fn md_flight_tables(s: &mut String, r: &DiagnoseReport) {
    let _ = writeln!(s, "\n## Flight tables\n");
    for w in &r.flight_tables.written {
        let _ = writeln!(s, "* written: `{w}`");
    }
    for a in &r.flight_tables.applied {
        let _ = writeln!(s, "* {a}");
    }
    for g in &r.flight_tables.ground_only {
        let _ = writeln!(s, "* ground only: {g}");
    }
    if let Some(v) = &r.flight_tables.validation {
        let _ = writeln!(
            s,
            "\n**Held-out validation against {}: {}.** {}",
            v.reference,
            if v.passed {
                "diagnose's tables written"
            } else {
                "refused, calibrate's table written"
            },
            v.reason
        );
    }
    let _ = writeln!(
        s,
        "\n## Gyro\n\n{} hold-to-hold bias samples, {} slews.",
        r.gyro.bias_samples, r.gyro.slews
    );
    for n in &r.gyro.notes {
        let _ = writeln!(s, "* {n}");
    }
    for c in &r.gyro.candidates {
        let _ = writeln!(
            s,
            "* {}: Δχ² {:.1}, ΔBIC {:.1}, halves p {:.3}: {}",
            c.effect,
            c.delta_chi2,
            c.delta_bic,
            c.halves_p,
            verdict(c.accepted, c.rejected_because.as_deref(), "kept")
        );
    }
}

/// A candidate's verdict: `taken` when accepted, else why not.
fn verdict(accepted: bool, rejected_because: Option<&str>, taken: &str) -> String {
    if accepted {
        taken.to_owned()
    } else {
        rejected_because.unwrap_or_default().to_owned()
    }
}

/// The loop: every iteration with its candidates, then the plots.
fn md_loop(s: &mut String, r: &DiagnoseReport) {
    let _ = writeln!(s, "\n## The loop ({} iterations)\n", r.iterations);
    for it in &r.iteration_log {
        let _ = writeln!(
            s,
            "**Iteration {}**: {}\n",
            it.number,
            it.added
                .as_deref()
                .map_or("nothing added; stop".to_owned(), |a| format!("added {a}"))
        );
        let mut c: Vec<_> = it.candidates.iter().collect();
        c.sort_by(|a, b| b.delta_bic.total_cmp(&a.delta_bic));
        let _ = writeln!(s, "| candidate | k | Δχ² | F | p (Holm) | ΔBIC | halves p | verdict |\n|---|---|---|---|---|---|---|---|");
        for e in c.iter().take(8) {
            let _ = writeln!(
                s,
                "| {} | {} | {:.1} | {:.2} | {:.2e} | {:.1} | {:.3} | {} |",
                e.effect,
                e.k,
                e.delta_chi2,
                e.f,
                e.p_holm,
                e.delta_bic,
                e.halves_p,
                verdict(e.accepted, e.rejected_because.as_deref(), "added")
            );
        }
        s.push('\n');
    }
    if !r.plots.is_empty() {
        let _ = writeln!(s, "## Plots\n");
        for p in &r.plots {
            let _ = writeln!(s, "![{p}]({p})\n");
        }
    }
}

/// Markdown report.
#[must_use]
pub fn markdown(r: &DiagnoseReport) -> String {
    let mut s = String::new();
    md_header(&mut s, r);
    md_detected(&mut s, r);
    md_unexplained(&mut s, r);
    md_residuals(&mut s, r);
    md_scoring(&mut s, r);
    md_flight_tables(&mut s, r);
    md_loop(&mut s, r);
    s
}
