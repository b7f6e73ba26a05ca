//! # Held-out validation of the alignment table
//!
//! Why: FFCAL minimises its own residuals, so its in-sample residuals always fall; they cannot
//! tell whether the new table would serve the spacecraft better than the flown one. An
//! alignment that changed during the span, a handful of misidentified stars, or an FSS error
//! that the fit absorbed all pass an in-sample check and would be uplinked.
//!
//! So before the table is written the same estimator (`AlignmentSetup::fit`, both stages) is
//! re-run K times (K ≤ [`MAX_FOLDS`]), each time without one contiguous block of the span
//! (blocks of equal duration: contiguous so that the held-out data carry attitudes, stars
//! and Sun positions of their own, as the next flight will), and the held-out block's dot
//! products are evaluated with that fold's alignments and with the flown ones
//! (`calibration::alignment::alignment_residuals`, whitened with each epoch's full pair
//! covariance). The table is written only if
//! 1. the held-out χ² with the new alignments is lower than with the flown ones by more than
//!    [`MIN_IMPROVEMENT_Z`] standard errors of the paired difference (the same epochs under
//!    both tables; the standard error by batch means, [`paired_improvement`]): the table
//!    improves what it will be used on; and
//! 2. the held-out normalised residuals are consistent: χ²/dof ≤ [`HELDOUT_MS_MAX`] (the
//!    model and its σ describe data they were not fitted to);
//! 3. with the gyro-batch FHST stage, its FHST2-relative-to-FHST1 alignment agrees with the
//!    simultaneous star pairs' ([`FhstStageAgreement`]). Why: each fold re-runs the same
//!    batch model, so a model error (a slew inside a hold batch) is in every fold's fit and in
//!    the full one alike, and the held-out dot products see FHST2 mainly about the axis
//!    normal to both boresights while the FSS pairs dominate their χ²: such a table was
//!    7–14σ wrong on two axes and passed 1 and 2 (z 7.1, χ²/dof 0.36);
//!
//! otherwise the flown table is kept and the report says which test failed, with the numbers.
//! The common rotation of all sensors is not in dot products: it is set by the paper's
//! adjustment, a convention, not an estimate.

use std::collections::BTreeMap;

use nalgebra::{Matrix3, Vector3};
use serde::Serialize;

use super::ffcal_stages::{
    AlignmentSetup, FhstStageAgreement, SENSOR_NAMES, STAGE_AGREEMENT_CHI2_MAX,
};
use super::observations::FrameObservations;
use crate::calibration::alignment::{alignment_residuals, ffcal, FfcalConfig, Weighting};
use crate::diagnose::stats::chi2_per_dof;

/// Most folds (blocks of time held out in turn) and the largest held-out χ²/dof that counts
/// as consistent: the IRU table's (`calibration::iru_chain`), one rule for every table.
use crate::calibration::iru_chain::{HELDOUT_MS_MAX, MAX_FOLDS};

/// Fewest FFCAL epochs in a held-out block for it to count.
const MIN_HELDOUT_EPOCHS: usize = 10;

/// Fewest standard errors by which the new table must lower the held-out χ².
pub const MIN_IMPROVEMENT_Z: f64 = 3.0;

/// Most batches of the batch-means standard error.
const MAX_BATCHES: usize = 50;

/// A paired comparison of two tables on the same held-out epochs.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct PairedImprovement {
    /// Σ (χ²_flown − χ²_new) over the epochs: how much the new table lowers the χ².
    pub chi2_decrease: f64,
    /// Its standard error by batch means.
    pub standard_error: f64,
    /// `chi2_decrease / standard_error`.
    pub z: f64,
    /// Batches of consecutive epochs behind the standard error.
    pub batches: usize,
    /// Batches in which the new table lowers the χ².
    pub batches_improved: usize,
}

/// Groups of consecutive items for a standard error by batch means over `n` items: about
/// ten per group, at least 2 and at most [`MAX_BATCHES`] groups (fewer than 2 when `n` < 2).
#[must_use]
pub(crate) fn batch_groups(n: usize) -> usize {
    (n / 10).clamp(2, MAX_BATCHES).min(n)
}

/// Paired difference of per-epoch χ² (same epochs, same order) with its standard error by
/// batch means. Why batch means: the errors the tables leave are correlated over minutes (one
/// star tracked, one FSS cell), so epoch-to-epoch scatter would understate the standard error;
/// sums over batches of consecutive epochs are close to independent. Why paired: the two χ²
/// share their noise, and √(2 dof), the spread of one χ², would hide real improvements.
#[must_use]
pub fn paired_improvement(chi2_new: &[f64], chi2_flown: &[f64]) -> PairedImprovement {
    let n = chi2_new.len().min(chi2_flown.len());
    let batches = batch_groups(n);
    if batches < 2 {
        return PairedImprovement {
            chi2_decrease: f64::NAN,
            standard_error: f64::NAN,
            z: f64::NAN,
            batches,
            batches_improved: 0,
        };
    }
    let sums: Vec<f64> = (0..batches)
        .map(|b| {
            (b * n / batches..(b + 1) * n / batches)
                .map(|i| chi2_flown[i] - chi2_new[i])
                .sum()
        })
        .collect();
    let total: f64 = sums.iter().sum();
    let mean = total / batches as f64;
    let var = sums.iter().map(|s| (s - mean).powi(2)).sum::<f64>() / (batches - 1) as f64;
    let se = (batches as f64 * var).sqrt();
    PairedImprovement {
        chi2_decrease: total,
        standard_error: se,
        z: total / se,
        batches,
        batches_improved: sums.iter().filter(|&&s| s > 0.0).count(),
    }
}

/// The held-out validation of an alignment table (module doc).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AlignmentValidation {
    /// Blocks of time held out in turn.
    pub folds: usize,
    /// Folds whose training fit succeeded and whose block had data.
    pub folds_used: usize,
    /// Why a fold was not used (one line each).
    pub folds_skipped: Vec<String>,
    /// Held-out FFCAL epochs evaluated.
    pub epochs: usize,
    /// Held-out dot products (degrees of freedom of the χ²).
    pub dof: usize,
    /// Held-out χ² with each fold's new alignments.
    pub chi2_new: f64,
    /// Held-out χ² with the flown alignments.
    pub chi2_flown: f64,
    /// The paired decrease of the χ² and its standard error.
    pub improvement: PairedImprovement,
    /// χ²_new / dof: mean square of the held-out normalised residuals (1 = consistent).
    pub mean_square_normalised: f64,
    /// Probability of a χ²_new at least this large if the σ were exactly right (reported; the
    /// gate is on the mean square).
    pub p_value: f64,
    /// Held-out RMS angle residual per sensor with the new alignments (arcsec).
    pub rms_new_arcsec: BTreeMap<String, f64>,
    /// The same with the flown alignments (arcsec).
    pub rms_flown_arcsec: BTreeMap<String, f64>,
    /// Sensors of the fit with no held-out residual in any used block (a sensor seen in one
    /// block only: its fit without that block fails, so its new alignment is never tested on
    /// data it was not fitted to). The table keeps their flown alignments.
    pub not_validated: Vec<String>,
    /// The gyro-batch FHST stage against the simultaneous star pairs (the full fit; `None`
    /// with the star-pair stage or too few pairs): a table whose batches disagree with the
    /// pairs is not written (module doc, 3).
    pub fhst_stage_agreement: Option<FhstStageAgreement>,
    /// Whether the new table may be written.
    pub passed: bool,
    /// Why, with the numbers.
    pub reason: String,
}

impl AlignmentValidation {
    /// Record the FHST stage's agreement with the star pairs, and fail the table if they
    /// disagree (module doc, 3); say so in the reason when the gyro-batch stage was used but
    /// the check could not be made (`Some(None)`: too few simultaneous star pairs, or a
    /// singular covariance of the difference).
    pub(crate) fn check_fhst_stage(&mut self, checked: Option<Option<FhstStageAgreement>>) {
        let Some(agreement) = checked else {
            return;
        };
        if agreement.is_none() {
            self.reason.push_str("; the gyro-batch FHST stage was not checked against the simultaneous star pairs (too few pairs, or a singular covariance of their difference)");
        }
        if let Some(a) = agreement.as_ref().filter(|a| !a.passed) {
            let r = |v: [f64; 3]| format!("({:.1}, {:.1}, {:.1})", v[0], v[1], v[2]);
            self.reason = format!(
                "the gyro batches and the simultaneous star pairs disagree on FHST2 relative to FHST1: {}″ against {}″, χ² = {:.1} with σ of the difference {}″ (3 dof, at most {STAGE_AGREEMENT_CHI2_MAX}): the batch model is wrong (docs/algorithms.md §6a); {}",
                r(a.theta_batches_arcsec),
                r(a.theta_pairs_arcsec),
                a.chi2,
                r(a.sigma_difference_arcsec),
                self.reason
            );
            self.passed = false;
        }
        self.fhst_stage_agreement = agreement;
    }
}

/// Per-sensor sums of squared angle residuals and their counts.
#[derive(Default)]
struct RmsSums {
    sum_sq: Vec<f64>,
    count: Vec<usize>,
}

impl RmsSums {
    fn add(&mut self, rms_arcsec: &[f64], pairs: &[usize]) {
        self.sum_sq.resize(rms_arcsec.len(), 0.0);
        self.count.resize(rms_arcsec.len(), 0);
        for (k, (&r, &n)) in rms_arcsec.iter().zip(pairs).enumerate() {
            if n > 0 {
                self.sum_sq[k] += r * r * n as f64;
                self.count[k] += n;
            }
        }
    }

    fn by_name(&self, map: &[Option<usize>; 4]) -> BTreeMap<String, f64> {
        map.iter()
            .zip(SENSOR_NAMES)
            .filter_map(|(j, name)| {
                let j = (*j)?;
                let n = *self.count.get(j)?;
                (n > 0).then(|| (name.to_owned(), (self.sum_sq[j] / n as f64).sqrt()))
            })
            .collect()
    }
}

/// Frame index ranges of `folds` blocks of equal duration over `frames`.
fn time_blocks(frames: &[FrameObservations], folds: usize) -> Vec<(usize, usize)> {
    let (Some(first), Some(last)) = (frames.first(), frames.last()) else {
        return Vec::new();
    };
    let (t0, t1) = (first.time.seconds(), last.time.seconds());
    let edge = |k: usize| {
        if k >= folds {
            frames.len()
        } else {
            let t = t0 + (t1 - t0) * k as f64 / folds as f64;
            frames.partition_point(|f| f.time.seconds() < t)
        }
    };
    (0..folds).map(|k| (edge(k), edge(k + 1))).collect()
}

/// Validate the alignment estimator of `setup` on held-out blocks of `frames` (module doc).
#[must_use]
pub(crate) fn validate_alignment_heldout(
    frames: &[FrameObservations],
    setup: &AlignmentSetup<'_>,
) -> AlignmentValidation {
    let flown: Vec<Matrix3<f64>> = setup.sensors.iter().map(|s| s.m_acs_from_sensor).collect();
    let sys = [setup.fss_systematic_arcsec; 2];
    let blocks = time_blocks(frames, MAX_FOLDS);
    let (mut chi2_new, mut chi2_flown, mut dof, mut epochs) = (0.0, 0.0, 0usize, 0usize);
    let (mut rms_new, mut rms_flown) = (RmsSums::default(), RmsSums::default());
    let mut skipped = Vec::new();
    let mut used = 0;
    let (mut per_epoch_new, mut per_epoch_flown) = (Vec::new(), Vec::new());
    for (k, &(lo, hi)) in blocks.iter().enumerate() {
        let held =
            super::ffcal_stages::alignment_data_segments(&[&frames[lo..hi]], &setup.map, sys);
        if held.epoch_count() < MIN_HELDOUT_EPOCHS {
            skipped.push(format!(
                "block {}: {} FFCAL epochs (fewer than {MIN_HELDOUT_EPOCHS})",
                k + 1,
                held.epoch_count()
            ));
            continue;
        }
        let fit = match setup.fit(&[&frames[..lo], &frames[hi..]], None) {
            Ok(fit) => fit,
            Err(e) => {
                skipped.push(format!("block {}: the fit without it failed: {e:#}", k + 1));
                continue;
            }
        };
        let new: Vec<Matrix3<f64>> = fit
            .solution
            .sensors
            .iter()
            .map(|s| s.m_acs_from_sensor_calibrated)
            .collect();
        let (r_new, r_flown) = match (
            alignment_residuals(&held, &new, Weighting::Optimal1990),
            alignment_residuals(&held, &flown, Weighting::Optimal1990),
        ) {
            (Ok(a), Ok(b)) => (a, b),
            (Err(e), _) | (_, Err(e)) => {
                skipped.push(format!("block {}: residuals not formed: {e}", k + 1));
                continue;
            }
        };
        chi2_new += r_new.chi2;
        chi2_flown += r_flown.chi2;
        dof += r_new.pairs;
        epochs += held.epoch_count();
        rms_new.add(&r_new.rms_arcsec, &r_new.rms_pairs);
        rms_flown.add(&r_flown.rms_arcsec, &r_flown.rms_pairs);
        per_epoch_new.extend(r_new.chi2_per_epoch);
        per_epoch_flown.extend(r_flown.chi2_per_epoch);
        used += 1;
    }
    let improvement = paired_improvement(&per_epoch_new, &per_epoch_flown);
    let z = improvement.z;
    let (mean_square, p_value) = chi2_per_dof(chi2_new, dof);
    let folds = blocks.len();
    let rms_new_arcsec = rms_new.by_name(&setup.map);
    let not_validated: Vec<String> = setup
        .map
        .iter()
        .zip(SENSOR_NAMES)
        .filter(|(j, name)| j.is_some() && !rms_new_arcsec.contains_key(*name))
        .map(|(_, name)| name.to_owned())
        .collect();
    let no_tracker = ["FHST1", "FHST2"]
        .iter()
        .all(|t| not_validated.iter().any(|n| n == t));
    let (passed, reason) = if no_tracker {
        (
            false,
            format!(
                "neither tracker has a held-out residual ({}): the alignments cannot be validated on data they were not fitted to",
                skipped.join("; ")
            ),
        )
    } else if used < 2 {
        (
            false,
            format!(
                "only {used} of {folds} blocks of time could be held out ({}): the alignments cannot be validated on data they were not fitted to",
                skipped.join("; ")
            ),
        )
    } else if !(mean_square <= HELDOUT_MS_MAX) {
        (
            false,
            format!(
                "the new alignments do not predict held-out data within their σ: χ²/dof = {mean_square:.2} over {dof} dot products ({used}-fold by time, p = {p_value:.1e}; consistent: ≤ {HELDOUT_MS_MAX}): an alignment that changed during the span, or an error the model lacks"
            ),
        )
    } else if !(z > MIN_IMPROVEMENT_Z) {
        (
            false,
            format!(
                "held-out χ² with the new alignments {chi2_new:.1} is not lower than with the flown ones {chi2_flown:.1} by {MIN_IMPROVEMENT_Z} standard errors (decrease {:.1} ± {:.1}, z = {z:.1}; {used}-fold by time, {dof} dot products): the new table would not improve the attitude",
                improvement.chi2_decrease, improvement.standard_error
            ),
        )
    } else {
        (
            true,
            format!(
                "held-out χ² {chi2_new:.1} with the new alignments against {chi2_flown:.1} with the flown ones (decrease {:.1} ± {:.1}, z = {z:.1}; {used}-fold by time, {dof} dot products); χ²/dof = {mean_square:.2}",
                improvement.chi2_decrease, improvement.standard_error
            ),
        )
    };
    AlignmentValidation {
        folds,
        folds_used: used,
        folds_skipped: skipped,
        epochs,
        dof,
        chi2_new,
        chi2_flown,
        improvement,
        mean_square_normalised: mean_square,
        p_value,
        rms_new_arcsec,
        rms_flown_arcsec: rms_flown.by_name(&setup.map),
        not_validated,
        fhst_stage_agreement: None,
        passed,
        reason,
    }
}

/// Validation of a filter-table change that switches the OBC's annual-aberration correction on
/// (`calibrate::filter_update`). Two models of the references are compared on held-out
/// data, each with its own alignments: the apparent references (annual aberration applied,
/// as the ground's and the new table's) and the references without it (the flown table's).
///
/// The observable is the simultaneous FHST1–FHST2 star pairs only. Why: over one tracker's
/// 8° field annual aberration (≤ 20.5″) is nearly a common shift, an attitude error that
/// attitude-independent dot products do not see; between the two trackers, far apart on the
/// sky, the shifts differ by up to ≈ 20″, and the star pairs measure that at a few arcsec.
/// The FSS pairs carry tens of arcsec of systematic error and, measured on the main job, drown
/// the signal (z 2.5 with them, 5.9 without). For each block of time of
/// [`validate_alignment_heldout`], the FHST1–FHST2 relative alignment is fitted (FFCAL) on the
/// other blocks under each model, and the held-out pairs' χ² is summed. The change is written
/// only if the apparent references lower the held-out χ² by more than [`MIN_IMPROVEMENT_Z`]
/// standard errors of the paired difference: the telemetry itself says the correction is
/// needed.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AberrationSwitchValidation {
    /// Folds used.
    pub folds_used: usize,
    /// Held-out dot products.
    pub dof: usize,
    /// Held-out χ² with the references corrected for annual aberration (the new table).
    pub chi2_new: f64,
    /// Held-out χ² with the references without it (the flown table).
    pub chi2_flown: f64,
    /// The paired decrease of the χ² and its standard error.
    pub improvement: PairedImprovement,
    /// Whether the change may be written.
    pub passed: bool,
    /// Why, with the numbers.
    pub reason: String,
}

/// Map of the FHSTs alone (their star pairs).
const FHST_ONLY: [Option<usize>; 4] = [Some(0), Some(1), None, None];

/// Speed of light (km/s).
const C_KM_PER_S: f64 = 299_792.458;

/// Held-out χ² per epoch (in time order), dot products and folds used of the FHST1–FHST2
/// star pairs, FFCAL fitted on the other blocks, with the references passed through
/// `reference` (blocks of time as [`validate_alignment_heldout`]).
fn heldout_fhst_pairs_chi2(
    frames: &[FrameObservations],
    setup: &AlignmentSetup<'_>,
    reference: &mut dyn FnMut(&FrameObservations, &Vector3<f64>) -> Vector3<f64>,
) -> (Vec<f64>, usize, usize) {
    use super::ffcal_stages::alignment_data_references;
    let sys = [setup.fss_systematic_arcsec; 2];
    let cfg = FfcalConfig {
        require_relative_observability: false,
        ..setup.cfg
    };
    let (mut chi2, mut dof, mut used) = (Vec::new(), 0usize, 0usize);
    let Some(fhsts) = setup.sensors.get(..2) else {
        return (chi2, dof, used);
    };
    for (lo, hi) in time_blocks(frames, MAX_FOLDS) {
        let held = alignment_data_references(&[&frames[lo..hi]], &FHST_ONLY, sys, reference);
        if held.epoch_count() < MIN_HELDOUT_EPOCHS {
            continue;
        }
        let train =
            alignment_data_references(&[&frames[..lo], &frames[hi..]], &FHST_ONLY, sys, reference);
        let Ok(sol) = ffcal(fhsts, &train, &cfg) else {
            continue;
        };
        let m: Vec<Matrix3<f64>> = sol
            .sensors
            .iter()
            .map(|s| s.m_acs_from_sensor_calibrated)
            .collect();
        if let Ok(r) = alignment_residuals(&held, &m, Weighting::Optimal1990) {
            chi2.extend(r.chi2_per_epoch);
            dof += r.pairs;
            used += 1;
        }
    }
    (chi2, dof, used)
}

/// Validate switching the OBC's annual-aberration correction on (see
/// [`AberrationSwitchValidation`]).
#[must_use]
pub(crate) fn validate_aberration_switch(
    frames: &[FrameObservations],
    setup: &AlignmentSetup<'_>,
) -> AberrationSwitchValidation {
    use gro_reference::sun::SunEphemeris;
    let (per_epoch_new, dof, used) = heldout_fhst_pairs_chi2(frames, setup, &mut |_, u| *u);
    let mut eph: Option<SunEphemeris> = None;
    // First order: u_app = u + β − (u·β) u, so u = u_app − β + (u_app·β) u_app (2 mas).
    let (per_epoch_flown, _, _) = heldout_fhst_pairs_chi2(frames, setup, &mut |f, u_app| {
        let t = f.time.seconds_since_j2000_tt();
        let e = eph.get_or_insert_with(|| SunEphemeris::new(t, 600.0));
        let beta = e.state(t).earth_vel_bary_eci_km_per_s / C_KM_PER_S;
        (u_app - beta + u_app * u_app.dot(&beta)).normalize()
    });
    let (chi2_new, chi2_flown) = (
        per_epoch_new.iter().sum::<f64>(),
        per_epoch_flown.iter().sum::<f64>(),
    );
    let improvement = paired_improvement(&per_epoch_new, &per_epoch_flown);
    let z = improvement.z;
    let paired = per_epoch_new.len() == per_epoch_flown.len();
    let passed = used >= 2 && paired && z > MIN_IMPROVEMENT_Z;
    let reason = if used < 2 || !paired {
        format!("only {used} block(s) of time with FHST1–FHST2 star pairs could be held out under both models: the change cannot be validated")
    } else if passed {
        format!(
            "held-out χ² {chi2_new:.1} with the references corrected for annual aberration against {chi2_flown:.1} without (decrease {:.1} ± {:.1}, z = {z:.1}; {used}-fold by time, {dof} dot products)",
            improvement.chi2_decrease, improvement.standard_error
        )
    } else {
        format!(
            "held-out χ² with the references corrected for annual aberration {chi2_new:.1} is not lower than without {chi2_flown:.1} by {MIN_IMPROVEMENT_Z} standard errors (decrease {:.1} ± {:.1}, z = {z:.1}; {used}-fold by time, {dof} dot products): the telemetry does not show the correction is needed",
            improvement.chi2_decrease, improvement.standard_error
        )
    };
    AberrationSwitchValidation {
        folds_used: used,
        dof,
        chi2_new,
        chi2_flown,
        improvement,
        passed,
        reason,
    }
}
