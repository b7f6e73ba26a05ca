//! # FFCAL in stages: the alignment data and the staged fit (docs/algorithms.md §6, §10)
//!
//! What the full calibration (`super::calibrate`) and every held-out fold
//! (`super::alignment_heldout`) run alike: the FFCAL epochs from the frames, with the FSS
//! samples weighted per field cell ([`alignment_data_segments`]), and the fit itself
//! ([`AlignmentSetup::fit`]): the FHSTs first, from the gyro batches or the simultaneous star
//! pairs ([`FhstStageResult`]), then the FSSs relative to them ([`ffcal_staged`]).

use super::fss_consider::{consider_covariance, TransferSpreads};
use super::observations::FrameObservations;
use super::star_batches::star_batch_samples;
use crate::calibration::alignment::{
    cramer_rao_covariance, ffcal, AlignmentData, FfcalConfig, FfcalSolution, SensorObservation,
    SensorSpec,
};
use crate::calibration::fhst_relative::{
    estimate_relative_alignment, fuse_with_prior, FhstRelativeAlignment, RelativeAlignmentError,
};
use anyhow::{bail, Context};
use fsw_core::attitude::{rot, rotvec_from_rot};
use fsw_core::units::{ARCSEC_PER_RAD, RAD_PER_ARCSEC};
use nalgebra::{Matrix3, Vector3};
use serde::Serialize;

/// Sensor names in table order.
pub const SENSOR_NAMES: [&str; 4] = fsw_core::sensor::SensorId::NAMES;

/// Fewest gyro batches with both trackers for the gyro-batch FHST stage.
const MIN_GYRO_BATCHES: usize = 3;

/// Fewest simultaneous FHST1–FHST2 star epochs for the FHST stage of FFCAL.
const MIN_FHST_STAGE_EPOCHS: usize = 100;

/// χ²₃ at p = 0.001: above it the gyro batches and the simultaneous star pairs disagree on
/// FHST2 relative to FHST1 beyond their σ ([`FhstStageAgreement`]).
pub const STAGE_AGREEMENT_CHI2_MAX: f64 = 16.27;

/// Prior variance that holds the FHST alignments at their stage-1 values in stage 2 (arcsec²).
const HELD_PRIOR_ARCSEC2: f64 = 1e-6;

/// Size of the FSS field cells within which the systematic error counts as one (deg): its
/// correlation length. Why 8°: the transfer-function error is smooth over several degrees
/// (+25 to +31″ along a whole 24° sweep in `docs/investigations.md`), so 1° cells let a slew's
/// sweep of 30–60 cells outweigh the holds with one shared error. Measured (`calibration-mc`,
/// 20 seeds): 1° → FHST1–FSS2 within 36″ in 20/20 seeds of `gro-early-mission` but 0/20 with
/// one-orbit holds (mean 41″); 4° → 19/20 and 9/20; 8° → 20/20 and 19/20 (mean 28″ and 30″),
/// the FSS covariances then more conservative (mean NEES FSS1/FSS2 0.07/0.21 against
/// 0.12/1.27 at 1°).
pub(crate) const FSS_CELL_DEG: f64 = 8.0;

/// The gyro-batch FHST stage against the simultaneous star pairs: FHST2 relative to FHST1
/// (ACS, arcsec, with FHST1 held) from each, and the χ²₃ of their difference with the sum
/// of their covariances. Why: the held-out validation predicts dot products, which see the
/// relative alignment mainly about the axis normal to both boresights, and its χ² is
/// dominated by the FSS pairs; a gyro-batch model that is wrong on the other two axes (a
/// slew inside a hold batch, 7–14σ) passed it. The star pairs need no gyro, so they are a
/// check on the batch model that does not share its errors. Why the sum: the two estimates
/// share the simultaneous stars, so the difference's variance is at most the sum (a
/// conservative test: it does not fail a right model, measured χ² ≤ 6 on the writer's days
/// and the main job).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FhstStageAgreement {
    /// From the gyro batches (arcsec).
    pub theta_batches_arcsec: [f64; 3],
    /// From the simultaneous star pairs (arcsec).
    pub theta_pairs_arcsec: [f64; 3],
    /// 1σ of the difference per axis, from the sum of the covariances (arcsec).
    pub sigma_difference_arcsec: [f64; 3],
    /// χ² of the difference (3 degrees of freedom).
    pub chi2: f64,
    /// Whether `chi2` ≤ [`STAGE_AGREEMENT_CHI2_MAX`].
    pub passed: bool,
}

/// [`FhstStageAgreement`] of the gyro-batch estimate `rel`; `None` without enough star pairs
/// for their own fit.
pub(crate) fn fhst_stage_agreement(
    sensors: &[SensorSpec],
    fhst_data: &AlignmentData,
    cfg: &FfcalConfig,
    rel: &FhstRelativeAlignment,
) -> Option<FhstStageAgreement> {
    if fhst_data.epoch_count() < MIN_FHST_STAGE_EPOCHS {
        return None;
    }
    let pairs = FhstStageResult::star_pairs(sensors, fhst_data, cfg).ok()?;
    let t = |k: usize| {
        rotvec_from_rot(&(pairs.m_acs_from_fhst[k] * sensors[k].m_acs_from_sensor.transpose()))
            * ARCSEC_PER_RAD
    };
    let theta_pairs = t(1) - t(0);
    let c = &pairs.covariance_arcsec2;
    let c_pairs = c.fixed_view::<3, 3>(0, 0) + c.fixed_view::<3, 3>(3, 3)
        - c.fixed_view::<3, 3>(0, 3)
        - c.fixed_view::<3, 3>(3, 0);
    let s = c_pairs + rel.covariance_arcsec2;
    let d = rel.theta_acs_arcsec - theta_pairs;
    let chi2 = d.dot(&(s.try_inverse()? * d));
    Some(FhstStageAgreement {
        theta_batches_arcsec: rel.theta_acs_arcsec.into(),
        theta_pairs_arcsec: theta_pairs.into(),
        sigma_difference_arcsec: [0, 1, 2].map(|i| s[(i, i)].max(0.0).sqrt()),
        chi2,
        passed: chi2 <= STAGE_AGREEMENT_CHI2_MAX,
    })
}

/// Data of the FHST stage of the staged FFCAL.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum FhstStage {
    /// Every identified star, tied by the gyro within batches of holds and slews
    /// (`calibration::fhst_relative`; default): the tracker rolls see every star offset.
    GyroBatches,
    /// Shuster's dot products of simultaneous star pairs only (the paper's FFCAL data).
    StarPairs,
}

/// The FSS field cell of a sensor-frame Sun direction ([`FSS_CELL_DEG`] on each head angle).
pub(crate) fn fss_cell(d: &Vector3<f64>) -> (i64, i64) {
    let a = d.x.atan2(d.z).to_degrees() / FSS_CELL_DEG;
    let b = d.y.atan2(d.z).to_degrees() / FSS_CELL_DEG;
    (a.floor() as i64, b.floor() as i64)
}

/// FFCAL epochs from the frames (`map`: sensor → FFCAL index, `None` = left out).
///
/// An FSS sample's σ grows with the number of samples that share its place in the field
/// (`FSS_CELL_DEG` cells): `σ² = σ_noise² + n σ_sys²`. Why: the FSS error that depends on the
/// Sun's position in the field (`fss_systematic_arcsec`) is the same for every sample at that
/// position, so a cell of `n` samples carries no more than one observation with `σ_sys` of
/// information about it; white-noise weights would claim arcsec accuracy from a sensor whose
/// error is tens of arcsec, and pull the alignments with it.
pub(crate) fn alignment_data(
    frames: &[FrameObservations],
    map: &[Option<usize>; 4],
    fss_systematic_arcsec: [f64; 2],
) -> AlignmentData {
    alignment_data_segments(&[frames], map, fss_systematic_arcsec)
}

/// [`alignment_data`] over the frames of several segments taken together (a held-out fold's
/// training data: the frames before and after the held-out block).
pub(crate) fn alignment_data_segments(
    segments: &[&[FrameObservations]],
    map: &[Option<usize>; 4],
    fss_systematic_arcsec: [f64; 2],
) -> AlignmentData {
    alignment_data_references(segments, map, fss_systematic_arcsec, &mut |_, d| *d)
}

/// [`alignment_data_segments`] with every reference direction (star or Sun, ECI) passed
/// through `reference(frame, direction)`: the references another model would use (e.g. the
/// OBC's without annual aberration, `super::alignment_heldout::validate_aberration_switch`).
pub(crate) fn alignment_data_references(
    segments: &[&[FrameObservations]],
    map: &[Option<usize>; 4],
    fss_systematic_arcsec: [f64; 2],
    reference: &mut dyn FnMut(&FrameObservations, &Vector3<f64>) -> Vector3<f64>,
) -> AlignmentData {
    let cell = fss_cell;
    let mut per_cell: std::collections::HashMap<(usize, (i64, i64)), usize> =
        std::collections::HashMap::new();
    let frames = || segments.iter().flat_map(|s| s.iter());
    for f in frames() {
        for (i, s) in f.suns.iter().enumerate() {
            if let Some(s) = s {
                *per_cell.entry((i, cell(&s.meas.dir_sensor))).or_default() += 1;
            }
        }
    }
    let sys_rad = fss_systematic_arcsec.map(|s| s / ARCSEC_PER_RAD);
    let mut data = AlignmentData::with_capacity(frames().count(), 4);
    let mut obs = Vec::with_capacity(4);
    for f in frames() {
        obs.clear();
        for (i, s) in f.stars.iter().enumerate() {
            if let Some(s) = s {
                if let (Some((_, dir_eci)), Some(sensor)) = (s.identified, map[i]) {
                    obs.push(SensorObservation {
                        sensor,
                        dir_sensor: s.meas.dir_sensor,
                        dir_eci: reference(f, &dir_eci),
                        sigma_rad: s.sigma_rad,
                    });
                }
            }
        }
        for (i, s) in f.suns.iter().enumerate() {
            if let (Some(s), Some(sensor)) = (s, map[i + 2]) {
                let n = per_cell
                    .get(&(i, cell(&s.meas.dir_sensor)))
                    .copied()
                    .unwrap_or(1) as f64;
                obs.push(SensorObservation {
                    sensor,
                    dir_sensor: s.meas.dir_sensor,
                    dir_eci: reference(f, &s.sun_eci),
                    sigma_rad: (s.sigma_rad.powi(2) + n * sys_rad[i] * sys_rad[i]).sqrt(),
                });
            }
        }
        if obs.len() >= 2 {
            // A malformed epoch (zero vector) is simply not used.
            let _ = data.push_epoch(&obs);
        }
    }
    data
}

/// The FHSTs after stage 1: alignments and their 6×6 covariance (arcsec², ACS).
pub(crate) struct FhstStageResult {
    m_acs_from_fhst: [Matrix3<f64>; 2],
    covariance_arcsec2: nalgebra::Matrix6<f64>,
    iterations: usize,
}

impl FhstStageResult {
    /// Stage 1 by Shuster's FFCAL on the simultaneous star pairs.
    fn star_pairs(
        sensors: &[SensorSpec],
        fhst_data: &AlignmentData,
        cfg: &FfcalConfig,
    ) -> anyhow::Result<Self> {
        let first = sensors
            .get(..2)
            .context("FFCAL stage 1 needs FHST1 and FHST2")?;
        let s1 =
            ffcal(first, fhst_data, cfg).context("FFCAL stage 1 (FHST1 + FHST2 star pairs)")?;
        Ok(Self {
            m_acs_from_fhst: [
                s1.sensors[0].m_acs_from_sensor_calibrated,
                s1.sensors[1].m_acs_from_sensor_calibrated,
            ],
            covariance_arcsec2: s1.covariance_arcsec2.fixed_view::<6, 6>(0, 0).into_owned(),
            iterations: s1.iterations,
        })
    }

    /// Stage 1 from the gyro-batch relative alignment fused with the flown alignments'
    /// priors (`fhst_relative::fuse_with_prior`).
    fn gyro_batches(sensors: &[SensorSpec], rel: &FhstRelativeAlignment) -> anyhow::Result<Self> {
        let (p1, p2) = match sensors {
            [a, b, ..] => (a, b),
            _ => bail!("FFCAL stage 1 needs FHST1 and FHST2"),
        };
        let (t1, t2, cov) =
            fuse_with_prior(rel, &p1.prior_cov_acs_arcsec2, &p2.prior_cov_acs_arcsec2).context(
                "gyro-batch FHST stage: prior + relative covariance not positive definite",
            )?;
        Ok(Self {
            m_acs_from_fhst: [
                rot(&(t1 * RAD_PER_ARCSEC)) * p1.m_acs_from_sensor,
                rot(&(t2 * RAD_PER_ARCSEC)) * p2.m_acs_from_sensor,
            ],
            covariance_arcsec2: cov,
            iterations: 1,
        })
    }
}

/// The operator's choice of stages (`CalibrateOptions::ffcal_staging`).
#[derive(Clone, Copy, Debug)]
pub(crate) struct FfcalStaging {
    /// FFCAL in two stages, the FHSTs first.
    pub(crate) staged_ffcal: bool,
    /// The data of the FHST stage asked for.
    pub(crate) fhst_stage: FhstStage,
}

/// What an FFCAL fit needs besides the frames: the same for the full fit and for every
/// held-out fold (`super::alignment_heldout`), so a fold re-runs exactly the estimator whose
/// table would be written.
pub(crate) struct AlignmentSetup<'a> {
    /// The observed sensors (indices of `map`), with the flown alignments and their priors.
    pub(crate) sensors: &'a [SensorSpec],
    /// Table index (FHST1, FHST2, FSS1, FSS2) → sensor index in `sensors`, `None` = unobserved.
    pub(crate) map: [Option<usize>; 4],
    /// Declared FSS systematic error (arcsec) behind the per-cell weights.
    pub(crate) fss_systematic_arcsec: f64,
    /// How the FHST stage is chosen.
    pub(crate) staging: FfcalStaging,
    /// FFCAL options.
    pub(crate) cfg: FfcalConfig,
    /// The OBC's bias at a time (ACS, rad/s), to carry the gyro batches.
    pub(crate) obc_bias_at: &'a dyn Fn(f64) -> Vector3<f64>,
    /// Counts of the data, for the error messages.
    pub(crate) data_note: String,
}

/// One FFCAL fit: its inputs and its solution.
pub(crate) struct AlignmentFit {
    /// The epochs of ≥ 2 referenced vectors (every sensor).
    pub(crate) data: AlignmentData,
    /// The simultaneous FHST1–FHST2 star epochs.
    pub(crate) fhst_data: AlignmentData,
    /// The FHST stage used, if staged.
    pub(crate) fhst_stage: Option<(FhstStage, FhstStageResult)>,
    /// The gyro-batch relative alignment, or why there is none.
    pub(crate) batch_rel: Result<FhstRelativeAlignment, RelativeAlignmentError>,
    /// The alignments and their covariance.
    pub(crate) solution: FfcalSolution,
}

impl AlignmentSetup<'_> {
    /// FFCAL over the frames of `segments` (module doc, step 3): the FHSTs first, from the
    /// gyro batches or the simultaneous star pairs, then the FSSs relative to that frame
    /// (`ffcal_staged`); without a FHST stage, one joint fit. `consider`: the declared FSS
    /// transfer-function spreads for the stage-2 covariance (changes σ, not the estimate).
    ///
    /// # Errors
    /// A stage that cannot be solved, with the data counts in the message.
    pub(crate) fn fit(
        &self,
        segments: &[&[FrameObservations]],
        consider: Option<&TransferSpreads>,
    ) -> anyhow::Result<AlignmentFit> {
        let sys = [self.fss_systematic_arcsec; 2];
        let data = alignment_data_segments(segments, &self.map, sys);
        let context = || {
            format!(
                "FFCAL: {} epochs with ≥ 2 referenced vectors ({})",
                data.epoch_count(),
                self.data_note
            )
        };
        let fhst_data = alignment_data_segments(segments, &[Some(0), Some(1), None, None], sys);
        let (mut batch_samples, mut batch_count) = (Vec::new(), 0);
        for seg in segments {
            let (samples, n) = star_batch_samples(seg, self.obc_bias_at);
            batch_samples.extend(samples.into_iter().map(|mut s| {
                s.batch += batch_count;
                s
            }));
            batch_count += n;
        }
        let batch_rel = estimate_relative_alignment(&batch_samples, batch_count, MIN_GYRO_BATCHES);
        let (sensors, cfg) = (self.sensors, &self.cfg);
        let fhst_stage = match (
            self.staging.staged_ffcal,
            self.staging.fhst_stage,
            &batch_rel,
        ) {
            (false, _, _) => None,
            (true, FhstStage::GyroBatches, Ok(rel)) => Some((
                FhstStage::GyroBatches,
                FhstStageResult::gyro_batches(sensors, rel)?,
            )),
            // Without usable batches the star pairs still give the stage.
            (true, _, _) if fhst_data.epoch_count() >= MIN_FHST_STAGE_EPOCHS => Some((
                FhstStage::StarPairs,
                FhstStageResult::star_pairs(sensors, &fhst_data, cfg).with_context(context)?,
            )),
            (true, _, _) => None,
        };
        let solution = match &fhst_stage {
            Some((_, stage1)) => {
                let white = consider.map(|spreads| {
                    (
                        spreads,
                        alignment_data_segments(segments, &self.map, [0.0; 2]),
                    )
                });
                ffcal_staged(
                    sensors,
                    stage1,
                    &data,
                    cfg,
                    white.as_ref().map(|(s, w)| (*s, w)),
                )
                .with_context(context)?
            }
            None => ffcal(sensors, &data, cfg).with_context(context)?,
        };
        Ok(AlignmentFit {
            data,
            fhst_data,
            fhst_stage,
            batch_rel,
            solution,
        })
    }
}

/// FFCAL in two stages. Why: the FSSs carry systematic errors of tens of arcsec (the paper's
/// inherent 0.022° after calibration: transfer-function error) that their noise figure does
/// not describe; in one joint fit these errors leak into the FHST1–FHST2 relative alignment,
/// which the star pairs alone determine to a few arcsec. So:
/// 1. the FHSTs (`sensors[0..2]`) from their stars only (`stage1`: the gyro batches, or
///    Shuster's simultaneous star pairs);
/// 2. every sensor from all epochs with the FHSTs held at their stage-1 values, which gives
///    the FSSs relative to the FHST frame.
///
/// Covariance: the FHST block is stage 1's. An FSS's error is its stage-2 (conditional) error
/// plus the error of the FHST frame it was tied to, taken as the mean rotation of the two
/// trackers: `C(fss_i, fss_j) = C₂(i, j) + C_f`, `C(fss_i, fhst_k) = ½ (C₁(1,k) + C₁(2,k))`,
/// `C_f = ¼ Σ C₁`. With the transfer function's spreads declared (`fss_consider`: the spreads
/// and the FSS samples at white-noise σ), `C₂` is the consider covariance plus the noise bound.
/// Residuals before are those of the flown alignments over all epochs.
fn ffcal_staged(
    sensors: &[SensorSpec],
    stage1: &FhstStageResult,
    data: &AlignmentData,
    cfg: &FfcalConfig,
    fss_consider: Option<(&TransferSpreads, &AlignmentData)>,
) -> anyhow::Result<FfcalSolution> {
    let mut held = sensors.to_vec();
    for (spec, m) in held.iter_mut().zip(&stage1.m_acs_from_fhst) {
        spec.m_acs_from_sensor = *m;
        spec.prior_cov_acs_arcsec2 = Matrix3::identity() * HELD_PRIOR_ARCSEC2;
    }
    // An FSS that saw the Sun at one place only cannot have its rotation about the Sun line
    // determined: the prior keeps it there (and its σ says so) rather than failing the run.
    let stage2_cfg = FfcalConfig {
        require_relative_observability: false,
        ..*cfg
    };
    let mut sol =
        ffcal(&held, data, &stage2_cfg).context("FFCAL stage 2 (FSSs relative to the FHSTs)")?;
    // With declared transfer-function spreads the stage-2 covariance is what the data say
    // about the two error sources the FSS samples carry: the transfer function as consider
    // parameters (`fss_consider`), and the noise by the Cramér–Rao bound of the samples at
    // their white-noise σ (`white`; sub-arcsec over thousands of samples). The per-cell
    // weights' own formal covariance stands for the same transfer function and would count it
    // twice (20 seeds, each its own unit: FSS NEES 1.5 / 1.3 with both, 2.9 / 3.1 without).
    if let Some((spreads, white)) = fss_consider {
        let converged: Vec<SensorSpec> = held
            .iter()
            .zip(&sol.sensors)
            .map(|(spec, r)| SensorSpec {
                m_acs_from_sensor: r.m_acs_from_sensor_calibrated,
                ..spec.clone()
            })
            .collect();
        let m: Vec<Matrix3<f64>> = converged.iter().map(|c| c.m_acs_from_sensor).collect();
        let noise = cramer_rao_covariance(&converged, white, &m)
            .context("FFCAL stage 2: the noise bound of the FSS samples")?;
        sol.covariance_arcsec2 =
            noise + consider_covariance(&converged, data, &stage2_cfg, spreads)?;
    }
    // Before-residuals and corrections relative to the flown alignments.
    let before = ffcal(
        sensors,
        data,
        &FfcalConfig {
            max_iterations: 1,
            ..*cfg
        },
    )
    .ok();
    let n = sol.covariance_arcsec2.nrows();
    let c1 = &stage1.covariance_arcsec2;
    let blk1 =
        |a: usize, b: usize| -> Matrix3<f64> { c1.fixed_view::<3, 3>(3 * a, 3 * b).into_owned() };
    let frame_cov = (blk1(0, 0) + blk1(0, 1) + blk1(1, 0) + blk1(1, 1)) * 0.25;
    let mut cov = sol.covariance_arcsec2.clone();
    for a in 0..n / 3 {
        for b in 0..n / 3 {
            let block = match (a < 2, b < 2) {
                (true, true) => blk1(a, b),
                (true, false) => (blk1(a, 0) + blk1(a, 1)) * 0.5,
                (false, true) => (blk1(0, b) + blk1(1, b)) * 0.5,
                (false, false) => {
                    sol.covariance_arcsec2
                        .fixed_view::<3, 3>(3 * a, 3 * b)
                        .into_owned()
                        + frame_cov
                }
            };
            cov.fixed_view_mut::<3, 3>(3 * a, 3 * b).copy_from(&block);
        }
    }
    sol.covariance_arcsec2 = cov;
    for (k, (r, spec)) in sol.sensors.iter_mut().zip(sensors).enumerate() {
        r.m_acs_from_sensor_prelaunch = spec.m_acs_from_sensor;
        r.theta_acs_arcsec =
            rotvec_from_rot(&(r.m_acs_from_sensor_calibrated * spec.m_acs_from_sensor.transpose()))
                * ARCSEC_PER_RAD;
        r.sigma_acs_arcsec = Vector3::from_fn(|i, _| {
            sol.covariance_arcsec2[(3 * k + i, 3 * k + i)]
                .max(0.0)
                .sqrt()
        });
        if let Some(b) = before.as_ref().and_then(|b| b.sensors.get(k)) {
            r.residual_rms_before_arcsec = b.residual_rms_before_arcsec;
        }
    }
    sol.iterations += stage1.iterations;
    Ok(sol)
}
