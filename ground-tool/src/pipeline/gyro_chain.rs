//! # IRUCAL stage of the chain: the gyro chain from the telemetry, its solution, the table gate
//!
//! Why here: the estimator ([`crate::calibration::iru_chain`]) knows fixes and gyro links;
//! this module decides which fine attitudes become fixes, which gyro data join them, why a
//! maneuver is not used, and whether the IRU table may be written (held-out validation). It
//! replaces the interval form (one fix before and one after each maneuver, holds as separate
//! intervals, one constant bias), whose adjacent intervals shared end data while being
//! weighted as independent.
//!
//! **Fixes.** Every hold (the frames between maneuvers) is tiled with disjoint batch windows
//! (the paper's 10-min batches; two half-length windows in holds of 8–20 min, one in a hold of
//! 4–8 min), each giving a FHST-only fine attitude, or FHST + FSS where the trackers do not
//! suffice; in long holds one window per `HOLD_FIX_SPACING_S` is kept besides the first and
//! last. Disjoint data make the fixes independent, so the chain's correlations are exact.
//!
//! **Links.** Consecutive fixes are joined by the gyro steps between them when every frame has
//! a step and the triad does not change; a link may carry a maneuver whose own holds gave no
//! fix (the gyro carries the attitude to the next fix, with its noise). A break (gap, dropped
//! rate-switch step, configuration switch) releases the attitude but keeps the bias walk.

use nalgebra::{Matrix3, Vector3};
use serde::Serialize;

use fsw_core::tables::types::{matrix_from_rows, rows_from_matrix};
use fsw_core::tables::IruTable;

use super::iru_fixes::{
    batch_fix, gyro_complete, steps_between, FixFloors, FixRefusal, BATCH_HALF_S,
};
use super::maneuvers::ManeuverReport;
use super::observations::{FrameObservations, RateSwitch, SPLIT_KINDS};
use crate::calibration::iru::{GyroCalibration, IrucalSolution};
use crate::calibration::iru_chain::{
    significant_elements, solve_chain, validate_heldout, BiasStepTest, Chain, ChainConfig,
    ChainFix, ChainLink, ChainSolution, HeldOutValidation, RateScaleTest, Triad,
};
use crate::ARCSEC_PER_RAD;

/// Spacing of the fixes kept inside a long hold (s): the bias walk is slow, and fewer fixes
/// keep six months of telemetry within seconds.
const HOLD_FIX_SPACING_S: f64 = 1800.0;

/// Fewest links with a maneuver before IRUCAL is attempted at all.
const MIN_MANEUVER_LINKS: usize = 3;

/// Largest fraction of fixes the innovation gate may reject before the gyro model is said
/// not to fit (and no table is written).
const MAX_GATED_FRACTION: f64 = 0.05;

/// Largest mean normalised innovation (per dof) of the fixes with which the model's σ are
/// taken as right (a smaller one means conservative fix σ, which does not endanger a table).
const NIS_CONSISTENT: (f64, f64) = (0.0, 2.0);

/// The gyro chain of a run, with where each fix and link lies in the frames.
pub struct GyroChain {
    /// Fixes and links.
    pub chain: Chain,
    /// Frame index of each fix.
    pub fix_frames: Vec<usize>,
    /// Hold batches refused as fixes for a misfit (`calibrate::FixRefusal::Misfit`): time (s
    /// from `t0`), χ², dof.
    pub misfit_fixes: Vec<(f64, f64, usize)>,
    /// The time the misfit times count from (s, the time code's scale).
    pub t0_s: f64,
}

/// The frames of each hold: between maneuvers, before the first and after the last.
fn holds(frames: &[FrameObservations], maneuvers: &[(usize, usize)]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut start = 0usize;
    for &(s, e) in maneuvers {
        if s > start {
            out.push((start, s - 1));
        }
        start = e + 1;
    }
    if start + 1 < frames.len() {
        out.push((start, frames.len() - 1));
    }
    out
}

/// Batch windows (start, end) tiling a hold of `[ta, tb]` (s).
fn hold_windows(ta: f64, tb: f64) -> Vec<(f64, f64)> {
    let len = tb - ta;
    let full = 2.0 * BATCH_HALF_S;
    if len >= 2.0 * full {
        let mut out = Vec::new();
        let mut lo = ta;
        while lo + full <= tb + 1e-6 {
            out.push((lo, lo + full));
            lo += full;
        }
        out
    } else if len >= 0.8 * full {
        let mid = ta + 0.5 * len;
        vec![(ta, mid), (mid, tb)]
    } else if len >= 0.4 * full {
        vec![(ta, tb)]
    } else {
        Vec::new()
    }
}

/// Build the chain (see the module doc). `bias_at` is the linearisation bias (the OBC's).
pub(crate) fn build_gyro_chain(
    frames: &[FrameObservations],
    maneuvers: &[(usize, usize)],
    bias_at: &dyn Fn(f64) -> Vector3<f64>,
    floors: &FixFloors,
    t0: f64,
) -> GyroChain {
    let zero_dm = Matrix3::zeros();
    let mut fix_frames: Vec<usize> = Vec::new();
    let mut fixes: Vec<ChainFix> = Vec::new();
    let mut misfit_fixes = Vec::new();
    for (a, b) in holds(frames, maneuvers) {
        let (ta, tb) = (frames[a].time.seconds(), frames[b].time.seconds());
        let mut found: Vec<(usize, ChainFix)> = Vec::new();
        for (lo, hi) in hold_windows(ta, tb) {
            let center = 0.5 * (lo + hi);
            let made = batch_fix(
                frames,
                center,
                lo,
                hi,
                &bias_at(center),
                &zero_dm,
                floors,
                true,
            );
            if let Err(FixRefusal::Misfit { chi2, dof }) = made {
                misfit_fixes.push((center - t0, chi2, dof));
            }
            if let Ok((idx, fix, systematic, sun)) = made {
                let t = frames[idx].time.seconds();
                found.push((
                    idx,
                    ChainFix {
                        t_s: t - t0,
                        fix,
                        systematic_cov_rad2: systematic,
                        sun,
                        bias_nominal_rad_per_s: bias_at(t),
                        triad: triad_of(&frames[idx]),
                    },
                ));
            }
        }
        // Keep the first and last of the hold and one per HOLD_FIX_SPACING_S between.
        let last = found.len().saturating_sub(1);
        let mut kept_t = f64::NEG_INFINITY;
        for (k, (idx, fix)) in found.into_iter().enumerate() {
            if k == 0 || k == last || fix.t_s - kept_t >= HOLD_FIX_SPACING_S {
                kept_t = fix.t_s;
                fix_frames.push(idx);
                fixes.push(fix);
            }
        }
    }
    let links = fix_frames
        .windows(2)
        .map(|w| link_between(frames, maneuvers, w[0], w[1]))
        .collect();
    GyroChain {
        chain: Chain { fixes, links },
        fix_frames,
        misfit_fixes,
        t0_s: t0,
    }
}

/// The gyro triad whose channels the frame's increment came from.
fn triad_of(frame: &FrameObservations) -> Triad {
    if frame.iru_backup {
        Triad::Backup
    } else {
        Triad::Primary
    }
}

/// The gyro link between the fixes at frames `a` and `b`, or `None` where the chain breaks.
fn link_between(
    frames: &[FrameObservations],
    maneuvers: &[(usize, usize)],
    a: usize,
    b: usize,
) -> Option<ChainLink> {
    if b <= a || !gyro_complete(frames, a, b) {
        return None;
    }
    let backup = frames[a + 1].iru_backup;
    if frames[a + 1..=b].iter().any(|f| f.iru_backup != backup) {
        return None;
    }
    let maneuver = maneuvers.iter().position(|&(s, e)| s > a && e <= b);
    let mut extra_var_rad2 = 0.0;
    let mut split_dirs_rad = [Vector3::zeros(); SPLIT_KINDS];
    for split in frames[a + 1..=b]
        .iter()
        .filter_map(FrameObservations::gyro_split)
    {
        extra_var_rad2 += split.var_rad2;
        split_dirs_rad[split.kind()] += split.dir_rad;
    }
    Some(ChainLink {
        steps: steps_between(frames, a, b),
        triad: triad_of(&frames[a + 1]),
        extra_var_rad2,
        maneuver,
        split_dirs_rad,
    })
}

impl GyroChain {
    /// Why maneuver `k` (frames `s..=e`) is not in the estimator, or `None` when a link
    /// carries it.
    #[must_use]
    pub fn why_not_used(
        &self,
        frames: &[FrameObservations],
        k: usize,
        s: usize,
        e: usize,
    ) -> Option<String> {
        let carried = self
            .fix_frames
            .windows(2)
            .zip(&self.chain.links)
            .any(|(w, l)| w[0] < s && w[1] >= e && l.is_some());
        if carried {
            return None;
        }
        let before = self.fix_frames.iter().any(|&f| f < s);
        let after = self.fix_frames.iter().any(|&f| f >= e);
        let inside = &frames[s..=e];
        let dropped = inside
            .iter()
            .filter(|f| f.rate_switch == RateSwitch::Dropped)
            .count();
        let missing = inside.iter().filter(|f| f.gyro.is_none()).count();
        Some(if !before || !after {
            let side = if before { "after" } else { "before" };
            // Hold batches on the missing side that had the vectors but were refused for a
            // misfit: say so, with the size of the misfit, rather than "no vectors".
            let (ts, te) = (
                frames[s].time.seconds() - self.t0_s,
                frames[e].time.seconds() - self.t0_s,
            );
            let refused: Vec<&(f64, f64, usize)> = self
                .misfit_fixes
                .iter()
                .filter(|(t, _, _)| if before { *t > te } else { *t < ts })
                .collect();
            if refused.is_empty() {
                format!(
                    "maneuver {k}: no attitude fix {side} it in the telemetry (no batch with two referenced vectors)"
                )
            } else {
                let worst = refused
                    .iter()
                    .map(|(_, chi2, dof)| chi2 / (*dof).max(1) as f64)
                    .fold(0.0, f64::max);
                format!(
                    "maneuver {k}: no attitude fix {side} it: {} hold batch(es) there had the vectors but were refused as fixes for a misfit (χ²/dof up to {worst:.2}): star and Sun residuals larger than the declared noise allow — a sensor noisier than metadata.json's `sensors` declare, a wrong bias, or a wrong star identification",
                    refused.len()
                )
            }
        } else if dropped > 0 {
            format!("maneuver {k}: {dropped} frame(s) hold an IRU rate-mode switch that could not be split (no 0x0203 event inside, or no clean low-rate neighbour): the gyro chain breaks there")
        } else if missing > 0 {
            format!("maneuver {k}: {missing} frame(s) without a gyro step (telemetry gap or an unusable channel)")
        } else {
            format!("maneuver {k}: the gyro chain breaks between the fixes around it (a gap or an IRU configuration switch in the holds next to it)")
        })
    }
}

/// What the IRUCAL stage hands back to the chain.
pub struct IruStage {
    /// The IRU table to write (the flown one unless a validated δM changes `G`).
    pub table: IruTable,
    /// The report's IRU section.
    pub report: Option<IruReport>,
    /// The primary triad's solution in the interval form's type (for diagnose and the tests).
    pub solution: Option<IrucalSolution>,
    /// Why IRUCAL gave no answer.
    pub skipped: Option<String>,
    /// The chain solution (bias history).
    pub chain_solution: Option<ChainSolution>,
}

/// IRU results for the report.
#[derive(Clone, Debug, Serialize)]
pub struct IruReport {
    /// δM (row-major, unitless).
    pub delta_m: [[f64; 3]; 3],
    /// 1σ of δM.
    pub delta_m_sigma: [[f64; 3]; 3],
    /// Bias from the full calibration, ACS, rad/s.
    pub bias_rad_per_s: [f64; 3],
    /// 1σ, rad/s.
    pub bias_sigma_rad_per_s: [f64; 3],
    /// Number of intervals (maneuvers + holds).
    pub intervals: usize,
    /// Interval residuals before and after, arcsec.
    pub residual_before_arcsec: Vec<f64>,
    /// After.
    pub residual_after_arcsec: Vec<f64>,
    /// Whether the new G was written (δM significant at 3σ somewhere).
    pub g_updated: bool,
    /// The δM applied to G: the elements determined at 3σ, others 0 (all 0 without an update).
    pub delta_m_uplinked: [[f64; 3]; 3],
    /// Intervals dropped as outliers (index in the order they were built, after earlier drops).
    pub rejected_intervals: Vec<usize>,
    /// The estimator that produced δM.
    pub estimator: &'static str,
    /// Attitude fixes in the gyro chain.
    pub fixes: usize,
    /// Gyro links joining consecutive fixes.
    pub links: usize,
    /// Links that carry a maneuver.
    pub maneuver_links: usize,
    /// Rate random walk declared in the metadata (rad/s^1.5).
    pub rrw_declared_rad_per_s_1p5: f64,
    /// Rate random walk used (larger when the data's likelihood needed it).
    pub rrw_used_rad_per_s_1p5: f64,
    /// Scale of the attitude fixes' random covariance chosen by the likelihood (1 = as stated).
    pub fix_cov_scale: f64,
    /// Scale of the FHST-only fixes' systematic (per-attitude) covariance chosen by the
    /// likelihood.
    pub fix_systematic_scale: f64,
    /// Scale of the systematic covariance of the fixes that needed the Sun (FSS transfer
    /// function and alignment) chosen by the likelihood.
    pub fix_sun_systematic_scale: f64,
    /// Mean normalised innovation of the fixes per dof (1 = σ right).
    pub nis_mean_per_dof: f64,
    /// Fixes outside the innovation gate (not used).
    pub gated_fixes: usize,
    /// Hold batches refused as fixes because their own attitude fit does not fit (χ² p below
    /// `FIX_MISFIT_P`): time (s from the first frame), χ², dof.
    pub misfit_fixes: Vec<(f64, f64, usize)>,
    /// Why the gyro model does not fit, when it does not.
    pub model_fit: Option<String>,
    /// The lack-of-fit test of a scale error that changes with rate.
    pub rate_scale: RateScaleTest,
    /// Bias steps at unknown times found by the change-point scan and modelled: each with its
    /// time, size, σ and multiplicity-corrected p.
    pub bias_steps: Vec<BiasStepTest>,
    /// The scan's best candidate that was not accepted (when a scan ran and stopped).
    pub bias_step_rejected: Option<BiasStepTest>,
    /// The scan stopped at its cap of steps (`iru_chain::MAX_BIAS_STEPS`): more changes faster
    /// than the walk may remain.
    pub bias_steps_capped: bool,
    /// Where in their envelope the rate-mode switches inside decimated frames fell, as
    /// estimated (slew start, slew end; 0 = middle, ±0.5 = edges), with 1σ (0.5: no data).
    pub split_fraction: [f64; 2],
    /// See `split_fraction`.
    pub split_fraction_sigma: [f64; 2],
    /// Held-out validation of the primary triad's δM, when attempted.
    pub validation: Option<HeldOutValidation>,
    /// Why G was or was not updated (the real reason, with numbers).
    pub decision: String,
    /// The backup triad, when it flew slews.
    pub backup: Option<BackupIruReport>,
}

impl IruReport {
    /// What the slew uncertainty needs of this report (`super::filter_tuning`).
    #[must_use]
    pub fn tuning_evidence(&self) -> super::filter_tuning::IruEvidence {
        use super::filter_tuning::{HeldOut, IruEvidence, RateScale, TriadCalibration};
        let held_out = |v: &crate::calibration::iru_chain::HeldOutValidation| HeldOut {
            passed: v.passed,
            mean_square_normalised: v.mean_square_normalised,
            reason: v.reason.clone(),
        };
        let triad =
            |delta_m, delta_m_sigma, delta_m_uplinked, validation: Option<&_>| TriadCalibration {
                delta_m,
                delta_m_sigma,
                delta_m_uplinked,
                validation: validation.map(held_out),
            };
        IruEvidence {
            primary: triad(
                self.delta_m,
                self.delta_m_sigma,
                self.delta_m_uplinked,
                self.validation.as_ref(),
            ),
            g_updated: self.g_updated,
            decision: self.decision.clone(),
            rate_scale: RateScale {
                significant: self.rate_scale.significant,
                p_value: self.rate_scale.p_value,
            },
            backup: self.backup.as_ref().map(|b| {
                triad(
                    b.delta_m,
                    b.delta_m_sigma,
                    b.delta_m_uplinked,
                    b.validation.as_ref(),
                )
            }),
        }
    }
}

/// The backup triad's δM in the report.
#[derive(Clone, Debug, Serialize)]
pub struct BackupIruReport {
    /// δM (row-major, unitless).
    pub delta_m: [[f64; 3]; 3],
    /// 1σ.
    pub delta_m_sigma: [[f64; 3]; 3],
    /// Rotation the backup triad measured in the links (deg).
    pub rotation_deg: f64,
    /// Whether `G_backup` was updated.
    pub g_updated: bool,
    /// The δM applied to `G_backup` (0 without an update).
    pub delta_m_uplinked: [[f64; 3]; 3],
    /// Held-out validation, when attempted.
    pub validation: Option<HeldOutValidation>,
    /// Why `G_backup` was or was not updated.
    pub decision: String,
}

/// Solve the chain, validate on held-out maneuvers, decide the table (see the module doc).
pub fn irucal_stage(
    chain: &Chain,
    cfg: &ChainConfig,
    flown: &IruTable,
    maneuvers: &mut [ManeuverReport],
) -> IruStage {
    let mut stage = IruStage {
        table: *flown,
        report: None,
        solution: None,
        skipped: None,
        chain_solution: None,
    };
    let maneuver_links = chain
        .links
        .iter()
        .flatten()
        .filter(|l| l.maneuver.is_some())
        .count();
    if maneuver_links < MIN_MANEUVER_LINKS {
        stage.skipped = Some(format!(
            "IRUCAL needs at least {MIN_MANEUVER_LINKS} maneuvers joined by gyro data to attitude fixes; found {} maneuvers, {maneuver_links} carried ({})",
            maneuvers.len(),
            maneuvers
                .iter()
                .filter_map(|m| m.why_not_used.clone())
                .take(3)
                .collect::<Vec<_>>()
                .join("; ")
        ));
        return stage;
    }
    crate::progress::step("IRUCAL: calibration filter and smoother, change-point scan");
    let sol = match solve_chain(chain, cfg) {
        Ok(s) => s,
        Err(e) => {
            stage.skipped = Some(format!("IRUCAL failed: {e}"));
            return stage;
        }
    };
    if let Ok(path) = std::env::var("GROUND_TOOL_CHAIN_CSV") {
        write_chain_csv(&path, chain, &sol);
    }
    let fit = model_fit(&sol, cfg);
    let mut table = *flown;
    let (g_updated, dm_up, validation, decision) =
        decide_triad(chain, cfg, &sol, &fit, Triad::Primary, &mut table.g_primary);
    let backup = (sol.rotation_deg[1] > 1.0).then(|| {
        let (upd, dmb, v, why) =
            decide_triad(chain, cfg, &sol, &fit, Triad::Backup, &mut table.g_backup);
        BackupIruReport {
            delta_m: rows_from_matrix(&sol.delta_m[1]),
            delta_m_sigma: rows_from_matrix(&sol.sigma_delta_m[1]),
            rotation_deg: sol.rotation_deg[1],
            g_updated: upd,
            delta_m_uplinked: rows_from_matrix(&dmb),
            validation: v,
            decision: why,
        }
    });
    let last_bias = sol.bias.last().copied();
    let bias = last_bias.map_or([0.0; 3], |b| b.bias_rad_per_s);
    let bias_sigma = last_bias.map_or([0.0; 3], |b| b.sigma_rad_per_s);
    let residual_before: Vec<f64> = sol
        .link_residual_before_arcsec
        .iter()
        .flatten()
        .copied()
        .collect();
    let residual_after: Vec<f64> = sol
        .link_residual_after_arcsec
        .iter()
        .flatten()
        .copied()
        .collect();
    stage.report = Some(IruReport {
        delta_m: rows_from_matrix(&sol.delta_m[0]),
        delta_m_sigma: rows_from_matrix(&sol.sigma_delta_m[0]),
        bias_rad_per_s: bias,
        bias_sigma_rad_per_s: bias_sigma,
        intervals: residual_after.len(),
        residual_before_arcsec: residual_before.clone(),
        residual_after_arcsec: residual_after.clone(),
        g_updated,
        delta_m_uplinked: rows_from_matrix(&dm_up),
        rejected_intervals: sol.gated.clone(),
        estimator: "calibration Kalman filter + RTS smoother over the whole timeline (bias random walk, fixes shared by adjacent links)",
        fixes: chain.fixes.len(),
        links: chain.links.iter().flatten().count(),
        maneuver_links,
        rrw_declared_rad_per_s_1p5: sol.rrw_declared,
        rrw_used_rad_per_s_1p5: sol.rrw_used,
        fix_cov_scale: sol.fix_cov_scale,
        fix_systematic_scale: sol.fix_systematic_scale,
        fix_sun_systematic_scale: sol.fix_sun_systematic_scale,
        nis_mean_per_dof: sol.nis_mean_per_dof,
        gated_fixes: sol.gated.len(),
        misfit_fixes: Vec::new(),
        model_fit: fit.clone().err(),
        rate_scale: sol.rate_scale,
        bias_steps: sol.bias_steps.clone(),
        bias_step_rejected: sol
            .bias_step_scan
            .filter(|s| !sol.bias_steps.contains(s)),
        bias_steps_capped: sol.bias_steps.len() >= crate::calibration::iru_chain::MAX_BIAS_STEPS,
        split_fraction: sol.split_fraction,
        split_fraction_sigma: sol.split_fraction_sigma,
        validation,
        decision,
        backup,
    });
    stage.solution = Some(irucal_solution(
        &sol,
        (bias, bias_sigma),
        residual_before,
        residual_after,
    ));
    stage.table = table;
    stage.chain_solution = Some(sol);
    stage
}

/// Whether a triad's G is updated: only with δM elements determined at 3σ, a gyro model
/// that fits, and the held-out validation passed; then `table_g` takes them. Returns
/// (updated, the δM uplinked, the validation, why).
fn decide_triad(
    chain: &Chain,
    cfg: &ChainConfig,
    sol: &ChainSolution,
    fit: &Result<(), String>,
    triad: Triad,
    table_g: &mut [[f64; 3]; 3],
) -> (bool, Matrix3<f64>, Option<HeldOutValidation>, String) {
    let k = match triad {
        Triad::Primary => 0,
        Triad::Backup => 1,
    };
    let dm_up = significant_elements(&sol.delta_m[k], &sol.sigma_delta_m[k]);
    if dm_up.iter().all(|x| *x == 0.0) {
        return (
            false,
            Matrix3::zeros(),
            None,
            "G left at its flown value: no δM element is determined at 3σ".to_owned(),
        );
    }
    if let Err(why) = fit {
        return (
            false,
            Matrix3::zeros(),
            None,
            format!("G left at its flown value: {why}"),
        );
    }
    let mask = dm_up.map(|x| x != 0.0);
    let cfg_solved = ChainConfig {
        fix_cov_scale: sol.fix_cov_scale,
        fix_systematic_scale: sol.fix_systematic_scale,
        fix_sun_systematic_scale: sol.fix_sun_systematic_scale,
        bias_restarts: sol.bias_restarts,
        ..*cfg
    };
    crate::progress::step(&format!(
        "IRUCAL: held-out validation of the {triad:?} triad's G"
    ));
    let validation = validate_heldout(chain, &cfg_solved, triad, sol.rrw_used, &mask);
    match validation {
        Ok(v) if v.passed => {
            let g = (Matrix3::identity() + dm_up) * matrix_from_rows(table_g);
            *table_g = rows_from_matrix(&g);
            let why = format!(
                "G updated with the δM elements determined at 3σ; held-out validation: {}",
                v.reason
            );
            (true, dm_up, Some(v), why)
        }
        Ok(v) => {
            let why = format!("G left at its flown value: {}", v.reason);
            (false, Matrix3::zeros(), Some(v), why)
        }
        Err(e) => (
            false,
            Matrix3::zeros(),
            None,
            format!("G left at its flown value: the held-out fit failed ({e})"),
        ),
    }
}

/// The chain's solution as IRUCAL's (primary triad, the last bias), for the reports and the
/// diagnose chain.
fn irucal_solution(
    sol: &ChainSolution,
    (bias, bias_sigma): ([f64; 3], [f64; 3]),
    residual_before: Vec<f64>,
    residual_after: Vec<f64>,
) -> IrucalSolution {
    let cov = &sol.covariance_ppm2[0];
    let mut covariance_scaled = nalgebra::DMatrix::zeros(12, 12);
    for r in 0..9 {
        for c in 0..9 {
            covariance_scaled[(r, c)] = cov[(r, c)];
        }
    }
    for i in 0..3 {
        covariance_scaled[(9 + i, 9 + i)] = (bias_sigma[i] * ARCSEC_PER_RAD).powi(2);
    }
    IrucalSolution {
        calibration: GyroCalibration {
            delta_m: sol.delta_m[0],
            bias_acs_rad_per_s: Vector3::from(bias),
        },
        delta_m_correction: sol.delta_m[0],
        bias_correction_acs_rad_per_s: Vector3::zeros(),
        sigma_delta_m: sol.sigma_delta_m[0],
        sigma_bias_acs_rad_per_s: Vector3::from(bias_sigma),
        covariance_scaled,
        normal_eigenvalues_scaled: Vec::new(),
        residual_before_arcsec: residual_before,
        residual_after_arcsec: residual_after,
        chi2: sol.nis.iter().flatten().sum(),
        iterations: sol.iterations,
    }
}

/// Whether the gyro model fits the fixes: few gated fixes and a consistent mean NIS.
fn model_fit(sol: &ChainSolution, cfg: &ChainConfig) -> Result<(), String> {
    let r = &sol.rate_scale;
    if r.significant {
        let steps = match (sol.bias_steps.len(), &sol.bias_step_scan) {
            (0, Some(b)) if !b.significant => format!(
                "; no bias step explains it (the change-point scan's best, at t = {:.1} h, has corrected p = {:.1e} over {} positions)",
                b.t_s / 3600.0,
                b.p_value,
                b.positions
            ),
            (0, _) => String::new(),
            (n, _) => format!(
                "; {n} bias step(s) found by the change-point scan are modelled and it still does not fit"
            ),
        };
        return Err(format!(
            "the gyro model does not fit: the maneuvers' residuals follow the body rate, k = [{:.0}, {:.0}, {:.0}] ± [{:.0}, {:.0}, {:.0}] ppm at 1°/s as a rate-proportional scale (Wald χ² {:.1} on 3 dof, p = {:.1e}): a scale error that changes with rate, or a bias change the random walk (σ_u {:.2e} rad/s^1.5) cannot follow, which the maneuvers see first{steps}; δM from this fit would be wrong",
            r.k_ppm_at_1deg_per_s[0], r.k_ppm_at_1deg_per_s[1], r.k_ppm_at_1deg_per_s[2],
            r.sigma_ppm[0], r.sigma_ppm[1], r.sigma_ppm[2], r.delta_chi2, r.p_value, sol.rrw_used
        ));
    }
    let gated = sol.gated.len();
    let tested = sol.nis_count.max(1);
    if gated as f64 > MAX_GATED_FRACTION * tested as f64 {
        return Err(format!(
            "the gyro model does not fit: {gated} of {tested} attitude fixes fall outside the filter's χ²₃ gate ({:.1}); a gyro error the model lacks (a nonlinear scale, a bias change faster than the random walk) or bad fixes",
            cfg.gate_nis
        ));
    }
    let m = sol.nis_mean_per_dof;
    if !(m <= NIS_CONSISTENT.1) {
        return Err(format!(
            "the fixes' normalised innovations have mean square {m:.2} per dof over {tested} fixes (consistent: ≤ {:.1}): the gyro model's σ do not describe the data",
            NIS_CONSISTENT.1
        ));
    }
    Ok(())
}

/// Developer aid: the chain's fixes and links as CSV (`GROUND_TOOL_CHAIN_CSV=path`).
fn write_chain_csv(path: &str, chain: &Chain, sol: &ChainSolution) {
    use std::fmt::Write as _;
    let mut out = String::from(
        "j,t_s,sig_x,sig_y,sig_z,nis,gated,link_T_s,maneuver,rot_deg,z_before,z_after\n",
    );
    for (j, f) in chain.fixes.iter().enumerate() {
        let sd = |i: usize| f.fix.cov_acs_rad2[(i, i)].sqrt() * ARCSEC_PER_RAD;
        let link = chain.links.get(j).and_then(Option::as_ref);
        let _ = writeln!(
            out,
            "{j},{:.1},{:.1},{:.1},{:.1},{},{},{},{},{},{},{}",
            f.t_s,
            sd(0),
            sd(1),
            sd(2),
            sol.nis
                .get(j)
                .copied()
                .flatten()
                .map_or(String::new(), |v| format!("{v:.2}")),
            u8::from(sol.gated.contains(&j)),
            link.map_or(String::new(), |l| format!(
                "{:.0}",
                l.steps.iter().map(|s| s.dt_s).sum::<f64>()
            )),
            link.and_then(|l| l.maneuver)
                .map_or(String::new(), |m| m.to_string()),
            link.map_or(String::new(), |l| format!(
                "{:.2}",
                l.steps
                    .iter()
                    .map(|s| s.dtheta_acs_rad.norm())
                    .sum::<f64>()
                    .to_degrees()
            )),
            sol.link_residual_before_arcsec
                .get(j)
                .copied()
                .flatten()
                .map_or(String::new(), |v| format!("{v:.1}")),
            sol.link_residual_after_arcsec
                .get(j)
                .copied()
                .flatten()
                .map_or(String::new(), |v| format!("{v:.1}")),
        );
    }
    let _ = std::fs::write(path, out);
}
