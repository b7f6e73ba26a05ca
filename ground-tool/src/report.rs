//! # Reports for people: Markdown and PNG plots (plotters, bundled font)
//!
//! The plots follow the paper's figures: inter-sensor residuals before and after the
//! alignment calibration (its Figure 2) and the gyro bias history against the OBC's filter
//! bias (its Figures 3–4).

use crate::pipeline::calibrate::{CalibrationOutput, SENSOR_NAMES};
use crate::pipeline::observations::FrameObservations;
use anyhow::Context;
use fsw_core::tables::types::matrix_from_rows;
use fsw_core::tables::AlignmentTable;
use fsw_core::units::ARCSEC_PER_RAD;
use nalgebra::{Matrix3, Vector3};
use plotters::prelude::*;
use std::fmt::Write as _;
use std::path::Path;

static FONT: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");

fn register_font() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // A failure leaves plots without text rather than failing the report.
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
    });
}

/// One named series of (x, y) points.
pub struct Series {
    /// Legend label.
    pub label: String,
    /// Points.
    pub points: Vec<(f64, f64)>,
    /// Colour.
    pub color: RGBColor,
}

/// Scatter/line plot of several series to a PNG.
///
/// # Errors
/// Drawing or I/O failure.
pub fn plot_series(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
) -> anyhow::Result<()> {
    register_font();
    let all: Vec<(f64, f64)> = series
        .iter()
        .flat_map(|s| s.points.iter().copied())
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .collect();
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for (x, y) in &all {
        x0 = x0.min(*x);
        x1 = x1.max(*x);
        y0 = y0.min(*y);
        y1 = y1.max(*y);
    }
    if all.is_empty() {
        (x0, x1, y0, y1) = (0.0, 1.0, -1.0, 1.0);
    }
    if x1 <= x0 {
        x1 = x0 + 1.0;
    }
    if y1 <= y0 {
        y1 = y0 + 1.0;
    }
    let pad = 0.05 * (y1 - y0);
    let root = BitMapBackend::new(path, (1000, 560)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| anyhow::anyhow!("{e}"))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(x0..x1, (y0 - pad)..(y1 + pad))
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(y_label)
        .label_style(("sans-serif", 14))
        .draw()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    for s in series {
        let color = s.color;
        chart
            .draw_series(
                s.points
                    .iter()
                    .map(|&(x, y)| Circle::new((x, y), 2, color.filled())),
            )
            .map_err(|e| anyhow::anyhow!("{e}"))?
            .label(s.label.clone())
            .legend(move |(x, y)| Circle::new((x, y), 4, color.filled()));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font(("sans-serif", 14))
        .draw()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    root.present().map_err(|e| anyhow::anyhow!("{e}"))?;
    Ok(())
}

/// Dot-product residual (arcsec) of sensors `i`, `j` at one frame for a set of alignments:
/// `(r_i·r_j − b_i·b_j) / sin(angle)`, the angle error the pair sees.
fn pair_residual_arcsec(
    f: &FrameObservations,
    i: usize,
    j: usize,
    m_from_sensor: &[Matrix3<f64>; 4],
) -> Option<f64> {
    let vec_of = |k: usize| -> Option<(Vector3<f64>, Vector3<f64>)> {
        if k < 2 {
            let s = f.stars[k].as_ref()?;
            let (_, r) = s.identified?;
            Some((m_from_sensor[k] * s.meas.dir_sensor, r))
        } else {
            let s = f.suns[k - 2].as_ref()?;
            Some((m_from_sensor[k] * s.meas.dir_sensor, s.sun_eci))
        }
    };
    let (bi, ri) = vec_of(i)?;
    let (bj, rj) = vec_of(j)?;
    let sin = bi.cross(&bj).norm().max(1e-6);
    Some((ri.dot(&rj) - bi.dot(&bj)) / sin * ARCSEC_PER_RAD)
}

fn matrices(t: &AlignmentTable) -> [Matrix3<f64>; 4] {
    let m = t.matrices();
    [
        matrix_from_rows(m[0]),
        matrix_from_rows(m[1]),
        matrix_from_rows(m[2]),
        matrix_from_rows(m[3]),
    ]
}

/// Residual time series of a sensor pair before and after (s since the first frame, arcsec).
#[must_use]
pub fn pair_series(
    frames: &[FrameObservations],
    i: usize,
    j: usize,
    before: &AlignmentTable,
    after: &AlignmentTable,
) -> (Vec<(f64, f64)>, Vec<(f64, f64)>) {
    let (mb, ma) = (matrices(before), matrices(after));
    let t0 = frames.first().map_or(0.0, |f| f.time.seconds());
    let mut b = Vec::new();
    let mut a = Vec::new();
    for f in frames {
        let t = (f.time.seconds() - t0) / 3600.0;
        if let Some(r) = pair_residual_arcsec(f, i, j, &mb) {
            b.push((t, r));
        }
        if let Some(r) = pair_residual_arcsec(f, i, j, &ma) {
            a.push((t, r));
        }
    }
    (b, a)
}

/// Write `report.md`, `report.json` and the plots of a calibration into `out_dir`.
///
/// # Errors
/// I/O or plotting failure.
pub fn write_calibration_report(
    out_dir: &Path,
    out: &CalibrationOutput,
    flown: &AlignmentTable,
) -> anyhow::Result<()> {
    std::fs::create_dir_all(out_dir).with_context(|| format!("creating {}", out_dir.display()))?;
    let json = serde_json::to_string_pretty(&out.report)?;
    std::fs::write(out_dir.join("report.json"), json)?;

    let mut plots = Vec::new();
    for (i, j) in [(0usize, 1usize), (0, 2), (1, 3), (0, 3)] {
        let (b, a) = pair_series(&out.frames, i, j, flown, &out.alignment);
        if b.len() < 10 {
            continue;
        }
        let name = format!("residual_{}_{}.png", SENSOR_NAMES[i], SENSOR_NAMES[j]).to_lowercase();
        plot_series(
            &out_dir.join(&name),
            &format!(
                "{}–{} dot-product residual (paper Fig. 2)",
                SENSOR_NAMES[i], SENSOR_NAMES[j]
            ),
            "time (h)",
            "residual (arcsec)",
            &[
                Series {
                    label: "before (flown tables)".into(),
                    points: b,
                    color: RGBColor(200, 60, 40),
                },
                Series {
                    label: "after (calibrated)".into(),
                    points: a,
                    color: RGBColor(30, 90, 200),
                },
            ],
        )?;
        plots.push(name);
    }
    if !out.report.bias_history.is_empty() {
        let mut series = Vec::new();
        let colors = [
            RGBColor(200, 60, 40),
            RGBColor(30, 150, 60),
            RGBColor(30, 90, 200),
        ];
        let light = [
            RGBColor(240, 160, 150),
            RGBColor(150, 220, 160),
            RGBColor(150, 180, 240),
        ];
        for (axis, name) in ["x", "y", "z"].iter().enumerate() {
            series.push(Series {
                label: format!("ground {name}"),
                points: out
                    .report
                    .bias_history
                    .iter()
                    .map(|p| (p.t_s / 3600.0, p.bias_rad_per_s[axis] * ARCSEC_PER_RAD))
                    .collect(),
                color: colors[axis],
            });
            series.push(Series {
                label: format!("OBC filter {name}"),
                points: out
                    .report
                    .bias_history
                    .iter()
                    .filter_map(|p| {
                        p.obc_bias_rad_per_s
                            .map(|b| (p.t_s / 3600.0, b[axis] * ARCSEC_PER_RAD))
                    })
                    .collect(),
                color: light[axis],
            });
        }
        plot_series(
            &out_dir.join("bias_history.png"),
            "Gyro bias history (paper Figs. 3–4)",
            "time (h)",
            "bias (arcsec/s)",
            &series,
        )?;
        plots.push("bias_history.png".into());
        // The OBC's bias minus the ground's, with the ground's ±1σ band (what the onboard
        // filter still carries after its own convergence).
        let mut diff = Vec::new();
        for (axis, name) in ["x", "y", "z"].iter().enumerate() {
            let pts: Vec<(f64, f64, f64)> = out
                .report
                .bias_history
                .iter()
                .filter_map(|p| {
                    p.obc_bias_rad_per_s.map(|b| {
                        (
                            p.t_s / 3600.0,
                            (b[axis] - p.bias_rad_per_s[axis]) * ARCSEC_PER_RAD,
                            p.sigma_rad_per_s[axis] * ARCSEC_PER_RAD,
                        )
                    })
                })
                .collect();
            diff.push(Series {
                label: format!("OBC − ground {name}"),
                points: pts.iter().map(|(t, d, _)| (*t, *d)).collect(),
                color: colors[axis],
            });
            diff.push(Series {
                label: format!("ground ±1σ {name}"),
                points: pts
                    .iter()
                    .flat_map(|(t, _, s)| [(*t, *s), (*t, -*s)])
                    .collect(),
                color: light[axis],
            });
        }
        if diff.iter().any(|s| !s.points.is_empty()) {
            plot_series(
                &out_dir.join("bias_difference.png"),
                "OBC bias minus the ground's (smoothed, calibration filter)",
                "time (h)",
                "bias difference (arcsec/s)",
                &diff,
            )?;
            plots.push("bias_difference.png".into());
        }
    }

    let r = &out.report;
    let mut md = String::new();
    let _ = writeln!(md, "# Calibration report\n");
    let _ = writeln!(
        md,
        "Telemetry: {} raw frames, {} housekeeping, {} events, {} ephemeris records; {} regions skipped, {} duplicates, {} time reversals.\n",
        r.telemetry.packets_raw, r.telemetry.packets_housekeeping, r.telemetry.packets_event, r.telemetry.packets_ephemeris,
        r.telemetry.skipped.len(), r.telemetry.duplicates.len(), r.telemetry.time_reversals.len()
    );
    let _ = writeln!(
        md,
        "Data: stars identified against the full catalog FHST1 {} / FHST2 {} (unidentified {} / {}), Sun samples FSS1 {} / FSS2 {}, FFCAL epochs {}.\n",
        r.data.stars_identified[0], r.data.stars_identified[1], r.data.stars_unidentified[0], r.data.stars_unidentified[1],
        r.data.sun_samples[0], r.data.sun_samples[1], r.data.ffcal_epochs
    );
    let _ = writeln!(
        md,
        "## Alignments (FFCAL, {:?} weighting, {} passes)\n",
        r.ffcal.weighting, r.ffcal.iterations
    );
    let _ = writeln!(md, "| sensor | θ calibrated (ACS, ″) | σ (″) | θ adjusted (uplinked, ″) | residual RMS before (″) | after (″) |");
    let _ = writeln!(md, "|---|---|---|---|---|---|");
    for name in SENSOR_NAMES {
        if let (Some(c), Some(a)) = (r.alignments.get(name), r.alignments_adjusted.get(name)) {
            let _ = writeln!(
                md,
                "| {name} | [{:.1}, {:.1}, {:.1}] | [{:.1}, {:.1}, {:.1}] | [{:.1}, {:.1}, {:.1}] | {:.1} | {:.1} |",
                c.theta_acs_arcsec[0], c.theta_acs_arcsec[1], c.theta_acs_arcsec[2],
                c.sigma_arcsec[0], c.sigma_arcsec[1], c.sigma_arcsec[2],
                a.theta_acs_arcsec[0], a.theta_acs_arcsec[1], a.theta_acs_arcsec[2],
                r.residual_rms_arcsec.before.get(name).copied().unwrap_or(f64::NAN),
                r.residual_rms_arcsec.after.get(name).copied().unwrap_or(f64::NAN),
            );
        }
    }
    let f = |a: [f64; 3]| format!("[{:.1}, {:.1}, {:.1}]", a[0], a[1], a[2]);
    let _ = writeln!(
        md,
        "\nFHST2 relative to FHST1, 1σ per ACS axis: stated {}″; Cramér–Rao bound of the simultaneous star pairs {}″ (with the FSS epochs as well, as weighted here: {}″). FFCAL stages: {}.",
        f(r.ffcal.sigma_fhst2_rel_fhst1_arcsec),
        f(r.ffcal.crb_sigma_fhst2_rel_fhst1_fhst_only_arcsec),
        f(r.ffcal.crb_sigma_fhst2_rel_fhst1_all_sensors_arcsec),
        match r.ffcal.fhst_stage {
            Some(crate::pipeline::calibrate::FhstStage::GyroBatches) =>
                "FHSTs from every star in gyro-tied batches, then the FSSs relative to them",
            Some(crate::pipeline::calibrate::FhstStage::StarPairs) =>
                "FHSTs from simultaneous star pairs, then the FSSs relative to them",
            None => "one joint fit",
        }
    );
    if let Some(b) = &r.ffcal.gyro_batches {
        let _ = writeln!(
            md,
            "\nGyro-batch FHST stage: σ {}″ (Cramér–Rao bound {}″, χ²/dof {:.2}), {} batches, {} + {} star samples, {} rejected.",
            f(b.sigma_arcsec),
            f(b.crb_sigma_arcsec),
            b.variance_factor,
            b.batches,
            b.samples[0],
            b.samples[1],
            b.rejected
        );
    }
    if let Some(levels) = &r.ffcal.fss_systematic {
        let level = |e: &crate::pipeline::fss_systematic::FssSystematicEstimate| {
            e.estimated_arcsec.map_or_else(
                || format!("not measured ({} degrees of freedom)", e.dof),
                |x| format!("{x:.1}″ ({} cells, {} degrees of freedom)", e.cells, e.dof),
            )
        };
        let _ = writeln!(
            md,
            "\nFSS error left per field cell after calibration (the paper's \"inherent error\"): FSS1 {}, FSS2 {}; the weights use the declared {:.1}″; the FSS covariance: {}.",
            level(&levels[0]),
            level(&levels[1]),
            levels[0].declared_arcsec,
            if r.ffcal.fss_covariance == "consider" {
                "the declared transfer-function spreads as consider parameters plus the noise bound"
            } else {
                "the per-cell weights (each 8° cell one observation at the declared level)"
            }
        );
    }
    let _ = writeln!(
        md,
        "\nAdjustment (paper appendix): common rotation removed [{:.1}, {:.1}, {:.1}]″ so that the OBC's two-tracker attitude frame M_AN is unchanged.\n",
        r.adjustment_theta_acs_arcsec[0], r.adjustment_theta_acs_arcsec[1], r.adjustment_theta_acs_arcsec[2]
    );
    let v = &r.alignment_validation;
    let _ = writeln!(
        md,
        "**Alignment table:** {} — held-out validation: {}\n",
        if v.passed {
            "new alignments written"
        } else {
            "flown table kept (written again unchanged)"
        },
        v.reason
    );
    if v.passed && !v.not_validated.is_empty() {
        let _ = writeln!(
            md,
            "**Not validated, flown as before relative to the trackers:** {} (no held-out residual in any block of time: the sensor's data lie in one block, so its new alignment was never tested on data it was not fitted to).\n",
            v.not_validated.join(", ")
        );
    }
    if !v.rms_new_arcsec.is_empty() {
        let _ = writeln!(
            md,
            "| sensor | held-out RMS, new (″) | held-out RMS, flown (″) |"
        );
        let _ = writeln!(md, "|---|---|---|");
        for (name, new) in &v.rms_new_arcsec {
            let flown = v.rms_flown_arcsec.get(name).copied().unwrap_or(f64::NAN);
            let _ = writeln!(md, "| {name} | {new:.1} | {flown:.1} |");
        }
        let _ = writeln!(md);
    }
    let _ = writeln!(md, "## IRU\n");
    let used = r.maneuvers.iter().filter(|m| m.used).count();
    let _ = writeln!(
        md,
        "{} maneuvers found, {used} carried by the gyro chain between attitude fixes; rate-mode switches inside decimated frames: {} split at the switch, {} dropped.\n",
        r.maneuvers.len(),
        r.data.rate_switch_frames_split,
        r.data.rate_switch_frames_dropped
    );
    let listed = if r.maneuvers.len() > 20 {
        let _ = writeln!(
            md,
            "(only the maneuvers not used are listed; report.json has all)\n"
        );
        r.maneuvers
            .iter()
            .filter(|m| !m.used)
            .take(20)
            .collect::<Vec<_>>()
    } else {
        r.maneuvers.iter().collect()
    };
    for m in listed {
        let _ = writeln!(
            md,
            "- maneuver at {:.0}–{:.0} s, {:.2}° {}",
            m.start_s,
            m.end_s,
            m.angle_deg,
            m.why_not_used
                .as_ref()
                .map_or_else(|| "(used)".to_owned(), |w| format!("(not used: {w})"))
        );
        if let Some(c) = &m.coarse_attitude {
            let _ = writeln!(
                md,
                "  - coarse FSS + IRU attitude at its end: σ [{:.2}, {:.2}, {:.2}]°, {}",
                c.sigma_deg[0],
                c.sigma_deg[1],
                c.sigma_deg[2],
                c.difference_to_fine_deg
                    .map_or("no FHST attitude to compare".to_owned(), |d| {
                        format!("{d:.3}° from the FHST attitude")
                    })
            );
        }
    }
    match (&r.iru, &r.iru_skipped) {
        (Some(iru), _) => {
            let _ = writeln!(
                md,
                "\nδM (ppm) with 1σ, primary triad, from {} gyro links:\n",
                iru.links
            );
            write_delta_m(&mut md, &iru.delta_m, &iru.delta_m_sigma);
            let _ = writeln!(
                md,
                "\nBias at the last fix (ACS, arcsec/s): [{:.5}, {:.5}, {:.5}] ± [{:.5}, {:.5}, {:.5}].\n",
                iru.bias_rad_per_s[0] * ARCSEC_PER_RAD,
                iru.bias_rad_per_s[1] * ARCSEC_PER_RAD,
                iru.bias_rad_per_s[2] * ARCSEC_PER_RAD,
                iru.bias_sigma_rad_per_s[0] * ARCSEC_PER_RAD,
                iru.bias_sigma_rad_per_s[1] * ARCSEC_PER_RAD,
                iru.bias_sigma_rad_per_s[2] * ARCSEC_PER_RAD,
            );
            let _ = writeln!(
                md,
                "Estimator: {}; {} fixes, {} links ({} with maneuvers); rate random walk {:.2e} rad/s^1.5 used ({:.2e} declared); fixes' mean NIS per dof {:.2}, {} outside the gate.\n",
                iru.estimator,
                iru.fixes,
                iru.links,
                iru.maneuver_links,
                iru.rrw_used_rad_per_s_1p5,
                iru.rrw_declared_rad_per_s_1p5,
                iru.nis_mean_per_dof,
                iru.gated_fixes
            );
            for (t, chi2, dof) in &iru.misfit_fixes {
                let _ = writeln!(
                    md,
                    "Hold batch at t = {:.2} h refused as a fix: its attitude fit has χ² {chi2:.0} on {dof} dof (p below {:.0e}), so its vectors do not agree under their stated σ (seen when the bias the batch is propagated with, the OBC's, is wrong, as right after a bias reset or a triad switch; misidentified stars would do the same).\n",
                    t / 3600.0,
                    crate::pipeline::calibrate::FIX_MISFIT_P
                );
            }
            for b in &iru.bias_steps {
                let arcsec = |v: &[f64; 3]| v.map(|x| x * crate::ARCSEC_PER_RAD);
                let (st, sd) = (arcsec(&b.step_rad_per_s), arcsec(&b.sigma_rad_per_s));
                let _ = writeln!(
                    md,
                    "Bias change faster than the random walk, found by the change-point scan at t = {:.2} h and modelled as a step: [{:.4}, {:.4}, {:.4}] ± [{:.4}, {:.4}, {:.4}]″/s (Wald χ² {:.1}, p = {:.1e} corrected over {} positions); the bias walk restarts there.\n",
                    b.t_s / 3600.0, st[0], st[1], st[2], sd[0], sd[1], sd[2], b.delta_chi2, b.p_value, b.positions
                );
            }
            if iru.bias_steps_capped {
                let _ = writeln!(
                    md,
                    "The change-point scan stopped at its cap of {} steps: more bias changes faster than the walk may remain (see the bias history).\n",
                    iru.bias_steps.len()
                );
            }
            let _ = writeln!(md, "**Primary G:** {}\n", iru.decision);
            if let Some(b) = &iru.backup {
                let _ = writeln!(
                    md,
                    "Backup triad (X1, Y2, Z2; {:.0}° of rotation in the links), δM (ppm) with 1σ:\n",
                    b.rotation_deg
                );
                write_delta_m(&mut md, &b.delta_m, &b.delta_m_sigma);
                let _ = writeln!(md, "\n**Backup G:** {}\n", b.decision);
            }
        }
        (None, Some(why)) => {
            let _ = writeln!(md, "\nIRU calibration not done: {why}\n");
        }
        _ => {}
    }
    let _ = writeln!(md, "## Tables\n");
    for (k, v) in &r.tables {
        let _ = writeln!(md, "- {k}: `{v}`");
    }
    for c in &r.filter_changes {
        let _ = writeln!(md, "- filter table change: {c}");
    }
    let _ = writeln!(md, "\n## Plots\n");
    for p in &plots {
        let _ = writeln!(md, "![{p}]({p})");
    }
    std::fs::write(out_dir.join("report.md"), md)?;
    Ok(())
}

/// δM (ppm) with its 1σ, one row per line.
fn write_delta_m(md: &mut String, delta_m: &[[f64; 3]; 3], sigma: &[[f64; 3]; 3]) {
    for (row, sig) in delta_m.iter().zip(sigma) {
        let _ = writeln!(
            md,
            "    [{:8.0} ±{:5.0}] [{:8.0} ±{:5.0}] [{:8.0} ±{:5.0}]",
            row[0] * 1e6,
            sig[0] * 1e6,
            row[1] * 1e6,
            sig[1] * 1e6,
            row[2] * 1e6,
            sig[2] * 1e6
        );
    }
}
