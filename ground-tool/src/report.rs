//! # Reports for people: Markdown and PNG plots (plotters, bundled font)
//!
//! The plots follow the paper's figures: inter-sensor residuals before and after the
//! alignment calibration (its Figure 2) and the gyro bias history against the OBC's filter
//! bias (its Figures 3–4).

pub mod figure;

use crate::pipeline::calibrate::{
    BiasHistoryPoint, CalibrationOutput, CalibrationReport, SENSOR_NAMES,
};
use crate::pipeline::observations::FrameObservations;
use anyhow::Context;
use figure::{Figure, Kind, Layer, Panel};
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

/// Scatter plot of several series to a PNG, in one panel with the legend beside it (outside
/// the data area).
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
    figure::draw(
        path,
        &Figure {
            title: title.to_owned(),
            x_label: x_label.to_owned(),
            x_range: None,
            shared_y: false,
            panels: vec![Panel {
                title: String::new(),
                y_label: y_label.to_owned(),
                y_quantile: None,
                layers: series
                    .iter()
                    .map(|s| Layer {
                        label: Some(s.label.clone()),
                        color: s.color,
                        kind: Kind::Dots(s.points.clone()),
                    })
                    .collect(),
            }],
            notes: Vec::new(),
        },
    )
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
/// `obc_bias` is the OBC's bias from every housekeeping packet ([`ObcBiasSeries::read`]); the
/// bias plots then show it at full rate over the whole run, else only at the ground's epochs
/// (from `report.bias_history`).
///
/// # Errors
/// I/O or plotting failure.
pub fn write_calibration_report(
    out_dir: &Path,
    out: &CalibrationOutput,
    flown: &AlignmentTable,
    obc_bias: Option<&ObcBiasSeries>,
) -> anyhow::Result<()> {
    std::fs::create_dir_all(out_dir).with_context(|| format!("creating {}", out_dir.display()))?;
    let json = serde_json::to_string_pretty(&out.report)?;
    std::fs::write(out_dir.join("report.json"), json)?;

    let plots = write_plots(out_dir, out, flown, obc_bias)?;

    let r = &out.report;
    let mut md = String::new();
    md_header(&mut md, r);
    md_alignments(&mut md, r);
    md_alignment_validation(&mut md, r);
    md_maneuvers(&mut md, r);
    md_iru(&mut md, r);
    md_tam(&mut md, r);
    md_wheels(&mut md, r);
    md_tables(&mut md, r);
    write_plots_section(&mut md, &plots);
    std::fs::write(out_dir.join("report.md"), md)?;
    Ok(())
}

/// The header: what the telemetry and the data held.
fn md_header(md: &mut String, r: &CalibrationReport) {
    let _ = writeln!(md, "# Calibration report\n");
    let _ = writeln!(
        md,
        "Telemetry: {} raw frames, {} housekeeping, {} events, {} ephemeris records, {} magnetics frames (APID 0x013), {} wheel frames (APID 0x014); {} regions skipped, {} duplicates, {} time reversals.\n",
        r.telemetry.packets.raw, r.telemetry.packets.housekeeping, r.telemetry.packets.event, r.telemetry.packets.ephemeris, r.telemetry.packets.magnetics, r.telemetry.packets.wheels,
        r.telemetry.skipped.len(), r.telemetry.duplicates.len(), r.telemetry.time_reversals.len()
    );
    let _ = writeln!(
        md,
        "Data: stars identified against the full catalog FHST1 {} / FHST2 {} (unidentified {} / {}), Sun samples FSS1 {} / FSS2 {}, FFCAL epochs {}.\n",
        r.data.stars_identified[0], r.data.stars_identified[1], r.data.stars_unidentified[0], r.data.stars_unidentified[1],
        r.data.sun_samples[0], r.data.sun_samples[1], r.data.ffcal_epochs
    );
}

/// The alignments: FFCAL per sensor, its stages and σ, the FSS error left, the adjustment.
fn md_alignments(md: &mut String, r: &CalibrationReport) {
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
}

/// The alignment table's held-out validation.
fn md_alignment_validation(md: &mut String, r: &CalibrationReport) {
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
}

/// The IRU section: the maneuvers found and why any was not used.
fn md_maneuvers(md: &mut String, r: &CalibrationReport) {
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
}

/// IRUCAL: δM with 1σ, the bias, the estimator, refused fixes, bias steps, the G decisions.
fn md_iru(md: &mut String, r: &CalibrationReport) {
    match (&r.iru, &r.iru_skipped) {
        (Some(iru), _) => {
            let _ = writeln!(
                md,
                "\nδM (ppm) with 1σ, primary triad, from {} gyro links:\n",
                iru.links
            );
            write_delta_m(md, &iru.delta_m, &iru.delta_m_sigma);
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
                    crate::pipeline::iru_fixes::FIX_MISFIT_P
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
                write_delta_m(md, &b.delta_m, &b.delta_m_sigma);
                let _ = writeln!(md, "\n**Backup G:** {}\n", b.decision);
            }
        }
        (None, Some(why)) => {
            let _ = writeln!(md, "\nIRU calibration not done: {why}\n");
        }
        _ => {}
    }
}

/// The wheel frames (`pipeline::wheels`): nothing without them.
fn md_wheels(md: &mut String, r: &CalibrationReport) {
    let Some(w) = &r.wheels else {
        return;
    };
    // Per wheel or per bar, "a / b / c".
    let per_unit = |v: &[f64], p: usize| {
        v.iter()
            .map(|x| format!("{x:.p$}"))
            .collect::<Vec<_>>()
            .join(" / ")
    };
    let _ = writeln!(md, "## Reaction wheels and torquer bars (APID 0x014)\n");
    let _ = writeln!(
        md,
        "{} wheel frames. Largest wheel momentum per wheel {} N·m·s (speed {} rpm, rotor {} kg·m² from {}); tachometer valid fraction {}. Bar dipoles (current monitors) RMS {} A·m², largest {} A·m².\n",
        w.frames,
        per_unit(&w.largest_momentum_nms, 1),
        per_unit(&w.largest_speed_rpm, 0),
        w.spin_inertia_kg_m2,
        w.spin_inertia_source,
        per_unit(&w.tachometer_valid_fraction, 4),
        per_unit(&w.bar_dipole_rms_am2, 0),
        per_unit(&w.bar_dipole_max_am2, 0),
    );
    if w.flags_disagree() {
        let _ = writeln!(
            md,
            "**Warning:** the bar current monitors and the TAM \"torquer bars on\" bits disagree on {} of {} frames compared ({} with a monitor on and every bit off, {} with a bit on and every monitor at zero): a stuck status bit or a dead monitor; the TAM calibration chooses its samples by the bit.\n",
            w.monitor_on_flag_off + w.flag_on_monitor_off,
            w.frames_compared_with_tam_flags,
            w.monitor_on_flag_off,
            w.flag_on_monitor_off,
        );
    } else {
        let _ = writeln!(
            md,
            "The bar current monitors agree with the TAM \"torquer bars on\" bits on all {} frames compared.\n",
            w.frames_compared_with_tam_flags
        );
    }
}

/// The tables written, the filter changes and the derived FHST floor.
/// The TAM calibration and the FSS/TAM attitude check (`pipeline::tam`).
fn md_tam(md: &mut String, r: &CalibrationReport) {
    let t = &r.tam;
    let _ = writeln!(md, "## Magnetometers (TAM)\n");
    let (Some(b), Some(s)) = (t.bias_milligauss, t.bias_sigma_milligauss) else {
        let _ = writeln!(
            md,
            "Not determined: {}.\n",
            t.reason.as_deref().unwrap_or("no reason recorded")
        );
        return;
    };
    let f3 = |v: [f64; 3], p: usize| format!("[{:.p$}, {:.p$}, {:.p$}]", v[0], v[1], v[2]);
    let _ = writeln!(
        md,
        "Primary TAM bias {} ± {} mG (1σ), {}.\n",
        f3(b, 3),
        f3(s, 3),
        t.method
    );
    for (name, u) in [("TAM1", &t.tam1), ("TAM2", &t.tam2)] {
        if let Some(u) = u {
            let _ = writeln!(
                md,
                "- {name}: {} (normal-matrix condition {:.2e}); bias {} ± {} mG; {} samples, residual RMS {} mG (noise estimated {} mG, a priori {:.3}); bias over 8 blocks in time: χ² ratio {} (σ scaled by {}); held-out χ²/dof {}.",
                u.model,
                u.normal_matrix_condition,
                f3(u.bias_milligauss, 3),
                f3(u.bias_sigma_milligauss, 3),
                u.samples,
                f3(u.residual_rms_milligauss, 3),
                f3(u.noise_estimated_milligauss, 3),
                u.noise_prior_milligauss,
                u.block_consistency
                    .map_or("n/a".to_owned(), |c| format!("{:.2}", c.chi2_ratio)),
                u.block_consistency
                    .map_or("1".to_owned(), |c| format!("{:.2}", c.sigma_scale)),
                u.heldout
                    .iter()
                    .map(|h| format!("{:.2} (fit on the {})", h.chi2_per_dof, h.fitted))
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        }
    }
    if let Some(c) = &t.triad_comparison {
        let _ = writeln!(
            md,
            "\nFSS/TAM TRIAD attitude against the FHST fine attitude ({} frames), 3×RMS per axis: {} deg without the TAM correction, {} deg after the bias correction{}.",
            c.samples,
            f3(c.uncorrected.three_rms_deg, 3),
            f3(c.bias_corrected.three_rms_deg, 3),
            c.fully_corrected
                .as_ref()
                .map(|f| format!(", {} deg after the full correction", f3(f.three_rms_deg, 3)))
                .unwrap_or_default()
        );
    }
    let _ = writeln!(md);
}

fn md_tables(md: &mut String, r: &CalibrationReport) {
    let _ = writeln!(md, "## Tables\n");
    for (k, v) in &r.tables {
        let _ = writeln!(md, "- {k}: `{v}`");
    }
    for c in &r.filter_changes {
        let _ = writeln!(md, "- filter table change: {c}");
    }
    for g in r.filter_tuning.iter().filter(|g| !g.written) {
        let _ = writeln!(md, "- filter table `{}`: {}", g.field.field(), g.reason);
    }
    if let Some(f) = &r.fhst_floor {
        let _ = writeln!(
            md,
            "- FHST systematic per focal-plane axis: {:.2}″ derived (orbital aberration {:.2}″ ⊕ {}); the filter table flies {:.2}″{}",
            f.floor_arcsec,
            f.aberration_arcsec,
            f.source,
            f.flown_arcsec,
            f.note.as_ref().map_or(String::new(), |n| format!(": {n}"))
        );
    }
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

/// The OBC filter's gyro bias from every housekeeping packet (APID 0x011): what the onboard
/// computer believed at each downlinked cycle, to plot at full rate against the ground's.
#[derive(Clone, Debug, Default)]
pub struct ObcBiasSeries {
    /// Packet times, s (the telemetry's time scale, as `FrameObservations::time`).
    pub t_s: Vec<f64>,
    /// Bias in ACS, rad/s.
    pub bias_rad_per_s: Vec<[f64; 3]>,
    /// 1σ of the bias from the packet's covariance diagonal, rad/s (NaN where the variance
    /// is not a non-negative number).
    pub sigma_rad_per_s: Vec<[f64; 3]>,
}

impl ObcBiasSeries {
    /// The series of a decoded telemetry.
    #[must_use]
    pub fn from_telemetry(tm: &crate::tp::Telemetry) -> Self {
        Self::from_housekeeping(&tm.housekeeping)
    }

    /// The series of housekeeping records.
    #[must_use]
    pub fn from_housekeeping(housekeeping: &[fsw_core::telemetry::ObcHousekeeping]) -> Self {
        let mut s = Self::default();
        for h in housekeeping {
            s.t_s.push(h.time.seconds());
            s.bias_rad_per_s.push(h.bias_acs_rad_per_s);
            s.sigma_rad_per_s.push([3, 4, 5].map(|k| {
                let v = h.covariance_diag[k];
                if v.is_finite() && v >= 0.0 {
                    v.sqrt()
                } else {
                    f64::NAN
                }
            }));
        }
        s
    }

    /// The series of `run_dir/telemetry.bin` ([`crate::tp::read_housekeeping`]: the
    /// housekeeping alone, the same packets the chain keeps). A caller takes it before the
    /// chain decodes the file, so the chain's peak memory is not raised by it.
    ///
    /// # Errors
    /// The file cannot be read (the message names it).
    pub fn read(run_dir: &Path) -> anyhow::Result<Self> {
        let path = run_dir.join("telemetry.bin");
        let hk = crate::tp::read_housekeeping(&path)
            .with_context(|| format!("reading {} for the OBC bias plot", path.display()))?;
        Ok(Self::from_housekeeping(&hk))
    }
}

/// A plot written, with the question it answers and the numbers that answer it.
#[derive(Clone, Debug)]
pub struct PlotEntry {
    /// File name inside the report folder.
    pub file: String,
    /// The one question the plot answers at a glance.
    pub question: String,
    /// The answer in numbers (from the same data as the plot).
    pub answer: String,
}

/// The sensor pairs of the residual plots: every pair of the four sensors.
pub const SENSOR_PAIRS: [(usize, usize); 6] = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)];

/// Fewest common epochs of a pair that get a residual plot.
pub const MIN_PAIR_SAMPLES: usize = 10;

/// File name of the residual plot of sensors `i`, `j`.
#[must_use]
pub fn pair_plot_name(i: usize, j: usize) -> String {
    format!("residual_{}_{}.png", SENSOR_NAMES[i], SENSOR_NAMES[j]).to_lowercase()
}

/// Time axis of the plots: hours, or days beyond three days.
struct TimeAxis {
    div: f64,
    label: &'static str,
}

impl TimeAxis {
    fn for_span(span_s: f64) -> Self {
        if span_s > 3.0 * 86_400.0 {
            Self {
                div: 86_400.0,
                label: "time since the first frame (days)",
            }
        } else {
            Self {
                div: 3600.0,
                label: "time since the first frame (h)",
            }
        }
    }
}

fn rms(v: &[(f64, f64)]) -> f64 {
    (v.iter().map(|p| p.1 * p.1).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

fn mean(v: &[(f64, f64)]) -> f64 {
    v.iter().map(|p| p.1).sum::<f64>() / v.len().max(1) as f64
}

/// The zero line of a residual panel (not in the legend).
fn zero_line() -> Layer {
    Layer {
        label: None,
        color: GREY,
        kind: Kind::HLine(0.0),
    }
}

/// A panel of residuals (arcsec): the zero line and the residuals as dots.
fn residual_panel(title: &str, label: String, color: RGBColor, dots: Vec<(f64, f64)>) -> Panel {
    Panel {
        title: title.into(),
        y_label: "residual (arcsec)".into(),
        y_quantile: None,
        layers: vec![
            zero_line(),
            Layer {
                label: Some(label),
                color,
                kind: Kind::Dots(dots),
            },
        ],
    }
}

const BEFORE: RGBColor = RGBColor(200, 60, 40);
const AFTER: RGBColor = RGBColor(30, 90, 200);
const GREY: RGBColor = RGBColor(120, 120, 120);
/// Quantile of the bias history panels' y range: 0.1 % of the samples may lie beyond it
/// (the OBC's first hours from its initial bias on a six-month run; 19 samples of a 5-h run).
const HISTORY_QUANTILE: f64 = 0.001;
/// Quantile of the difference panels' y range ([`figure::Panel::y_quantile`]).
const DIFF_QUANTILE: f64 = 0.05;
/// The OBC's series in the bias plots (the same in every axis panel, so one legend serves).
const OBC: RGBColor = RGBColor(90, 140, 230);
/// The OBC's full-rate series in the history (lighter: the ground's fixes go over it).
const OBC_BAND: RGBColor = RGBColor(125, 165, 235);
/// The OBC's own ±1σ (drawn over the difference).
const OBC_SIGMA: RGBColor = RGBColor(230, 140, 20);
/// The ground's estimates.
const GROUND: RGBColor = RGBColor(180, 30, 30);

/// Every plot of the calibration report: the six pairs' residuals (where they have common
/// epochs), the bias history and the OBC − ground bias difference.
fn write_plots(
    out_dir: &Path,
    out: &CalibrationOutput,
    flown: &AlignmentTable,
    obc: Option<&ObcBiasSeries>,
) -> anyhow::Result<Vec<PlotEntry>> {
    let t0 = out.frames.first().map_or(0.0, |f| f.time.seconds());
    let t_end = out.frames.last().map_or(0.0, |f| f.time.seconds()) - t0;
    let obc_end = obc.and_then(|o| o.t_s.last()).map_or(0.0, |t| t - t0);
    let span_s = t_end.max(obc_end).max(1.0);
    let axis = TimeAxis::for_span(span_s);
    let x_range = Some((0.0, span_s / axis.div));
    let mut plots = Vec::new();
    for (i, j) in SENSOR_PAIRS {
        let (b, a) = pair_series(&out.frames, i, j, flown, &out.alignment);
        let pair = format!("{}–{}", SENSOR_NAMES[i], SENSOR_NAMES[j]);
        let file = pair_plot_name(i, j);
        if b.len() < MIN_PAIR_SAMPLES || a.len() < MIN_PAIR_SAMPLES {
            plots.push(PlotEntry {
                file: String::new(),
                question: format!("Did calibration reduce the {pair} residual?"),
                answer: format!(
                    "not plotted: {} frames hold both sensors' referenced vectors (a plot needs {MIN_PAIR_SAMPLES})",
                    b.len().min(a.len())
                ),
            });
            continue;
        }
        let scale = |v: Vec<(f64, f64)>| -> Vec<(f64, f64)> {
            v.into_iter()
                .map(|(t, r)| (t * 3600.0 / axis.div, r))
                .collect()
        };
        let (b, a) = (scale(b), scale(a));
        let (rb, ra, mb, ma) = (rms(&b), rms(&a), mean(&b), mean(&a));
        let n_epochs = b.len();
        let answer = format!(
            "RMS {rb:.1}″ → {ra:.1}″ (mean {mb:+.1}″ → {ma:+.1}″) over {} common epochs",
            a.len()
        );
        figure::draw(
            &out_dir.join(&file),
            &Figure {
                title: format!("{pair} dot-product residual before and after calibration (paper Fig. 2)"),
                x_label: axis.label.to_owned(),
                x_range,
                shared_y: true,
                panels: vec![
                    residual_panel(
                        "before: the flown (prelaunch) alignments",
                        format!("before (flown tables): RMS {rb:.1}″, mean {mb:+.1}″"),
                        BEFORE,
                        b,
                    ),
                    residual_panel(
                        "after: the calibrated alignments (same scale)",
                        format!("after (calibrated): RMS {ra:.1}″, mean {ma:+.1}″"),
                        AFTER,
                        a,
                    ),
                ],
                notes: vec![
                    format!("{n_epochs} epochs with both sensors' referenced vectors."),
                    "Residual: (r_i·r_j − b_i·b_j) / sin(angle), the angle error the pair sees; 0 = the two sensors agree with the references.".into(),
                ],
            },
        )?;
        plots.push(PlotEntry {
            file,
            question: format!("Did calibration reduce the {pair} residual?"),
            answer,
        });
    }
    plots.extend(bias_plots(out_dir, out, obc, t0, &axis, x_range)?);
    Ok(plots)
}

/// The ground's bias at its epochs, linearly interpolated at `t` (relative s) within their
/// span: between two fixes with no measurement in between, the smoothed random-walk bias is
/// the straight line between them. Not between fixes of different gyro triads (each has its
/// own bias, and the switch lies somewhere between them).
fn interpolate_ground(points: &[BiasHistoryPoint], t: f64, axis: usize) -> Option<f64> {
    let k = points.partition_point(|p| p.t_s <= t);
    let (a, b) = (points.get(k.checked_sub(1)?)?, points.get(k));
    match b {
        Some(b) if b.t_s > a.t_s && b.triad != a.triad => None,
        Some(b) if b.t_s > a.t_s => {
            let w = (t - a.t_s) / (b.t_s - a.t_s);
            Some(a.bias_rad_per_s[axis] * (1.0 - w) + b.bias_rad_per_s[axis] * w)
        }
        _ => (t == a.t_s).then_some(a.bias_rad_per_s[axis]),
    }
}

/// `bias_history.png` (OBC at every housekeeping packet, ground at its epochs with ±1σ, one
/// panel per axis over the whole run) and `bias_difference.png` (OBC − ground).
fn bias_plots(
    out_dir: &Path,
    out: &CalibrationOutput,
    obc: Option<&ObcBiasSeries>,
    t0: f64,
    axis: &TimeAxis,
    x_range: Option<(f64, f64)>,
) -> anyhow::Result<Vec<PlotEntry>> {
    let ground = &out.report.bias_history;
    let mut plots = Vec::new();
    if ground.is_empty() && obc.is_none_or(|o| o.t_s.is_empty()) {
        plots.push(PlotEntry {
            file: String::new(),
            question: "Does the OBC's gyro bias follow the ground's over the whole run?".into(),
            answer: "not plotted: no ground bias history (no IRU chain) and no housekeeping".into(),
        });
        return Ok(plots);
    }
    let as_x = |t_rel_s: f64| t_rel_s / axis.div;
    // The OBC at full rate (relative s), or at the ground's epochs without a series.
    let obc_points: Vec<(f64, [f64; 3], [f64; 3])> = match obc {
        Some(o) => o
            .t_s
            .iter()
            .zip(&o.bias_rad_per_s)
            .zip(&o.sigma_rad_per_s)
            .map(|((t, b), s)| (t - t0, *b, *s))
            .collect(),
        None => ground
            .iter()
            .filter_map(|p| p.obc_bias_rad_per_s.map(|b| (p.t_s, b, [f64::NAN; 3])))
            .collect(),
    };
    let full_rate = obc.is_some();
    // Connect housekeeping samples closer than 10 typical spacings (a gap in the downlink
    // breaks the line).
    let gap = {
        let mut d: Vec<f64> = obc_points.windows(2).map(|w| w[1].0 - w[0].0).collect();
        d.sort_by(f64::total_cmp);
        as_x(10.0 * d.get(d.len() / 2).copied().unwrap_or(1.0).max(1.0))
    };
    let names = ["x", "y", "z"];
    let mut panels = Vec::new();
    let mut diff_panels = Vec::new();
    let mut diff_rms = [f64::NAN; 3];
    let mut within = [0usize; 3];
    let mut compared = [0usize; 3];
    for (k, name) in names.iter().enumerate() {
        let (panel, diff_panel, rms_k, within_k, compared_k) =
            bias_axis_panels(k, name, &obc_points, ground, full_rate, gap, axis);
        panels.push(panel);
        diff_panels.push(diff_panel);
        diff_rms[k] = rms_k;
        within[k] = within_k;
        compared[k] = compared_k;
    }
    let source = if full_rate {
        format!(
            "OBC: {} housekeeping packets; ground: {} fixes of the calibration filter (RTS-smoothed).",
            obc_points.len(),
            ground.len()
        )
    } else {
        format!(
            "OBC: only at the ground's {} fixes (no housekeeping series given).",
            ground.len()
        )
    };
    figure::draw(
        &out_dir.join("bias_history.png"),
        &Figure {
            title: "Gyro bias: the OBC's estimate and the ground's over the whole run (paper Figs. 3–4)".into(),
            x_label: axis.label.to_owned(),
            x_range,
            shared_y: false,
            panels,
            notes: vec![source.clone()],
        },
    )?;
    let span = |pts: &[BiasHistoryPoint]| {
        pts.first()
            .zip(pts.last())
            .map_or("no ground fixes".to_owned(), |(a, b)| {
                format!(
                    "{} ground fixes from {:.2} to {:.2} {}",
                    pts.len(),
                    as_x(a.t_s),
                    as_x(b.t_s),
                    if axis.div > 3600.0 { "days" } else { "h" }
                )
            })
    };
    plots.push(PlotEntry {
        file: "bias_history.png".into(),
        question: "Does the OBC's gyro bias follow the ground's over the whole run?".into(),
        answer: format!(
            "{}; OBC at {} ({})",
            span(ground),
            if full_rate {
                "every housekeeping packet"
            } else {
                "the ground's epochs only"
            },
            obc_points.len()
        ),
    });
    if ground.is_empty() {
        return Ok(plots);
    }
    let f = |v: f64| format!("{v:.4}");
    let fraction = |k: usize| {
        if compared[k] == 0 {
            "n/a".to_owned()
        } else {
            format!("{:.0} %", 100.0 * within[k] as f64 / compared[k] as f64)
        }
    };
    let answer = format!(
        "RMS of OBC − ground x / y / z: {} / {} / {}″/s; within the OBC's own 1σ: {} / {} / {} of the samples",
        f(diff_rms[0]),
        f(diff_rms[1]),
        f(diff_rms[2]),
        fraction(0),
        fraction(1),
        fraction(2)
    );
    figure::draw(
        &out_dir.join("bias_difference.png"),
        &Figure {
            title: "OBC bias minus the ground's, with both uncertainties".into(),
            x_label: axis.label.to_owned(),
            x_range,
            shared_y: false,
            panels: diff_panels,
            notes: vec![source, answer.clone()],
        },
    )?;
    plots.push(PlotEntry {
        file: "bias_difference.png".into(),
        question: "How far is the OBC's bias from the ground's, and does the OBC's own 1σ cover the difference?".into(),
        answer,
    });
    Ok(plots)
}

/// Axis `k`'s two panels of the bias plots: the OBC's bias and the ground's, and OBC −
/// ground with both 1σ; also the RMS of the difference and how many OBC samples were
/// compared and within their own 1σ.
#[allow(clippy::too_many_arguments)]
fn bias_axis_panels(
    k: usize,
    name: &str,
    obc_points: &[(f64, [f64; 3], [f64; 3])],
    ground: &[BiasHistoryPoint],
    full_rate: bool,
    gap: f64,
    axis: &TimeAxis,
) -> (Panel, Panel, f64, usize, usize) {
    let as_x = |t_rel_s: f64| t_rel_s / axis.div;
    let arcsec = ARCSEC_PER_RAD;
    let (mut within, mut compared) = (0usize, 0usize);
    let obc_line: Vec<(f64, f64)> = obc_points
        .iter()
        .map(|(t, b, _)| (as_x(*t), b[k] * arcsec))
        .collect();
    let ground_bars: Vec<(f64, f64, f64)> = ground
        .iter()
        .map(|p| {
            (
                as_x(p.t_s),
                p.bias_rad_per_s[k] * arcsec,
                p.sigma_rad_per_s[k] * arcsec,
            )
        })
        .collect();
    let obc_kind = if full_rate {
        Kind::Line {
            points: obc_line,
            gap,
        }
    } else {
        Kind::Rings(obc_line)
    };
    let panel = Panel {
        title: format!("axis {name} (ACS)"),
        y_label: "bias (arcsec/s)".into(),
        // The OBC's first minutes from its initial bias are clipped only on long runs.
        y_quantile: Some(HISTORY_QUANTILE),
        // The OBC's full-rate band underneath, the ground's smoothed fixes on top (over
        // months a thin dark trail through the OBC's noise; small dots beyond 200 fixes).
        layers: vec![
            Layer {
                label: Some(if full_rate {
                    "OBC filter, every housekeeping packet".into()
                } else {
                    "OBC filter at the ground's epochs".into()
                }),
                color: OBC_BAND,
                kind: obc_kind,
            },
            Layer {
                label: Some("ground (calibration filter, smoothed) ±1σ at its fixes".into()),
                color: GROUND,
                kind: Kind::Bars(ground_bars.clone()),
            },
        ],
    };
    // OBC − ground wherever both exist (ground interpolated between its fixes), with the
    // OBC's own ±1σ, and the ground's ±1σ around zero at its fixes.
    let diff: Vec<(f64, f64)> = obc_points
        .iter()
        .filter_map(|(t, b, _)| {
            interpolate_ground(ground, *t, k).map(|g| (as_x(*t), (b[k] - g) * arcsec))
        })
        .collect();
    let obc_sigma: Vec<(f64, f64)> = obc_points
        .iter()
        .filter(|(t, _, s)| s[k].is_finite() && interpolate_ground(ground, *t, k).is_some())
        .map(|(t, _, s)| (as_x(*t), s[k] * arcsec))
        .collect();
    for (t, b, s) in obc_points {
        if let (Some(g), true) = (interpolate_ground(ground, *t, k), s[k].is_finite()) {
            compared += 1;
            if (b[k] - g).abs() <= s[k] {
                within += 1;
            }
        }
    }
    let diff_rms = rms(&diff);
    let mut layers = vec![zero_line()];
    layers.push(Layer {
        label: Some("0 ± the ground's 1σ at its fixes".into()),
        color: GREY,
        kind: Kind::Bars(ground_bars.iter().map(|&(t, _, s)| (t, 0.0, s)).collect()),
    });
    layers.push(Layer {
        label: Some(if full_rate {
            "OBC − ground (ground interpolated between its fixes)".into()
        } else {
            "OBC − ground at the ground's fixes".into()
        }),
        color: OBC,
        kind: if full_rate {
            Kind::Line { points: diff, gap }
        } else {
            Kind::Dots(diff)
        },
    });
    // The OBC's ±1σ over the difference: where the difference fills the band (months
    // of it), the band's edges must still show.
    if !obc_sigma.is_empty() {
        layers.push(Layer {
            label: Some("± the OBC's own 1σ (housekeeping covariance)".into()),
            color: OBC_SIGMA,
            kind: Kind::Line {
                points: obc_sigma.clone(),
                gap,
            },
        });
        layers.push(Layer {
            label: Some("± the OBC's own 1σ (housekeeping covariance)".into()),
            color: OBC_SIGMA,
            kind: Kind::Line {
                points: obc_sigma.iter().map(|&(t, s)| (t, -s)).collect(),
                gap,
            },
        });
    }
    let diff_panel = Panel {
        title: format!("axis {name} (ACS)"),
        y_label: "OBC − ground (arcsec/s)".into(),
        // The OBC's first convergence (minutes) would flatten the hours after it; the
        // whole of it is in bias_history.png.
        y_quantile: Some(DIFF_QUANTILE),
        layers,
    };
    (panel, diff_panel, diff_rms, within, compared)
}

/// The `## Plots` section: every plot written, under its question, with the answer in
/// numbers; then the plots not written and why.
fn write_plots_section(md: &mut String, plots: &[PlotEntry]) {
    let _ = writeln!(md, "\n## Plots\n");
    let _ = writeln!(
        md,
        "Each plot answers one question; the numbers under it are the answer from the same data.\n"
    );
    for p in plots.iter().filter(|p| !p.file.is_empty()) {
        let _ = writeln!(md, "### {}\n", p.question);
        let _ = writeln!(md, "{}\n", p.answer);
        let _ = writeln!(md, "![{}]({})\n", p.question, p.file);
    }
    let missing: Vec<&PlotEntry> = plots.iter().filter(|p| p.file.is_empty()).collect();
    if !missing.is_empty() {
        let _ = writeln!(md, "Not plotted:\n");
        for p in missing {
            let _ = writeln!(md, "- {} — {}", p.question, p.answer);
        }
    }
}
