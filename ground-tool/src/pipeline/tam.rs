//! # TAM calibration against the FHST fine attitude, and the paper's FSS/TAM attitude check
//!
//! Why: the paper's FDF determined the primary magnetometer's bias ([0, 0, −4] mG) from
//! flight data and compared FSS/TAM attitudes with the FHST attitudes before deciding not to
//! uplink it (issue 20). The ground knows the attitude far better than a TAM needs (the FHST
//! fine attitude: arcseconds, against the 0.01° a 0.1-mG error makes of a 300-mG field), so
//! the calibration is the **batch least squares with the attitude known** of Lerner & Shuster
//! (*In-flight magnetometer calibration and attitude determination for near-Earth
//! spacecraft*, J. Guidance and Control 4(5), 1981, §II; the attitude-dependent form Alonso &
//! Shuster 2002, *TWOSTEP*, J. Astronaut. Sci. 50(4), start from): with the field model
//! `B_eci` at the definitive orbit position and time ([`gro_reference::field`]) and the FHST
//! fine attitude `A`, each TAM sample is
//!
//! `y_k = T · (A_k B_eci,k) + b + n_k`   (mG, TAM axes; `T = (I + D) M_ASᵀ`)
//!
//! linear in the bias `b` and the 3×3 `T` (scale, misalignment, non-orthogonality). Each TAM
//! axis is its own 4-parameter fit with the same design `[x_kᵀ 1]`, `x_k = A_k B_eci,k`.
//!
//! **What is estimated** is decided by the normal matrix: its condition number after scaling
//! to a unit diagonal ([`FULL_MODEL_MAX_CONDITION`]). Over an orbit the field turns through
//! large angles in the body, `T` is observable and the full model is fitted (bias, scale,
//! misalignment); when the field direction hardly changes (a short span) only the bias is
//! fitted with `T` at nominal (identity: the TAM axes are the ACS axes) and the bias σ carries
//! the consider error of an unknown `T` ([`T_PRIOR_SIGMA`]).
//!
//! **Noise.** The measurement noise is estimated from the residuals (`s² = RSS/(n − p)` per
//! axis) and reported beside the a-priori figure ([`TAM_PRIOR_NOISE_MILLIGAUSS`]: 0.2 mG
//! noise and the 0.3-mG count's quantisation); the bias σ uses the estimate. Each sample's
//! fine attitude comes from a ±[`FINE_HALF_WINDOW_S`] batch; its random error (a few arcsec,
//! ≤ 0.01 mG) is in the residuals and negligible against the TAM noise. σ is then inflated by a
//! **consider** term for an attitude error common to every fine attitude (the ACS the FHST
//! alignments realise, [`ATTITUDE_SYSTEMATIC_ARCSEC`]): propagated through the fit, it is
//! absorbed by `T`'s misalignment in the full model and leaks into the bias only in the
//! bias-only fit. **Model error:** none here (the simulator's truth field is this model); a
//! real mission adds the IGRF's omission (crustal and external fields, of order 100 nT = 1 mG
//! at 450 km, correlated along the orbit), which would dominate σ and is not modelled.
//!
//! **Consistency in time:** the bias each of [`CONSISTENCY_BLOCKS`] blocks in time would give
//! is compared with the noise (a Birge ratio, [`BlockConsistency`]); when it moves more, the
//! random σ is scaled up: a slow systematic (an orbit-periodic attitude error, a field-model
//! error) is then carried, not hidden.
//!
//! **Held-out check:** the samples are split in time at the median; each half's fit predicts
//! the other half, whose residual RMS and χ²/dof against the estimated noise are reported.
//!
//! **FSS/TAM attitude (the paper's comparison):** TRIAD with the FSS Sun as the first vector
//! and the TAM field as the second, against the FHST fine attitude at the same frame; per-axis
//! error statistics with the TAM read at nominal (no correction) and after the bias
//! correction.
//!
//! Without APID 0x013 data the report says so with the reason (never an error).

use crate::diagnose::stats::chi2_sf;
use crate::pipeline::observations::{fhst_attitude, triad, FrameObservations};
use crate::tp::Telemetry;
use fsw_core::attitude::rotvec_from_rot;
use fsw_core::raw::{TAMS, TAM_FLAG_TORQUERS_ON, TAM_FLAG_VALID};
use fsw_core::telemetry::MagneticsFrame;
use fsw_core::units::ARCSEC_PER_RAD;
use gro_reference::field::{FieldEvaluator, FieldModel};
use gro_reference::time::epoch_from_time_tag;
use nalgebra::{Matrix3, Matrix4, Vector3, Vector4};
use serde::Serialize;

/// TAM count size, mG per count (12 bits over ±600 mG: `docs/magnetics.md` §2). The TAM table
/// of the flight software will carry it; until the ground reads that table, this is the one
/// value both sides use.
pub const TAM_MILLIGAUSS_PER_COUNT: f64 = 0.3;

/// mG per nT (1 mG = 100 nT).
pub const MILLIGAUSS_PER_NANOTESLA: f64 = 0.01;

/// A-priori TAM noise per axis, mG: 0.2 mG white noise and the 0.3-mG count's quantisation
/// (`0.3/√12`), `docs/magnetics.md` §2. Reported beside the estimate; not used for σ.
pub const TAM_PRIOR_NOISE_MILLIGAUSS: f64 = 0.218;

/// Spacing of the TAM samples used, s: one sample with its own fine attitude per spacing
/// (widened on long runs so that at most [`MAX_SAMPLES`] are offered).
pub const SAMPLE_SPACING_S: f64 = 30.0;

/// Most sample times offered (a fine attitude each): six months at 30 s would be 524,000.
pub const MAX_SAMPLES: f64 = 20_000.0;

/// Half width of the FHST batch giving each sample's fine attitude, s. Wider than half the
/// spacing: a tracker holds one star for minutes, and a ±15-s batch had two non-parallel
/// stars at only a quarter of the samples (gro-early-mission). Neighbouring batches overlap,
/// so their attitude errors correlate, but those errors (median σ reported, a few arcsec:
/// ≤ 0.01 mG of a 400-mG field) are below 1 % of the TAM noise variance.
pub const FINE_HALF_WINDOW_S: f64 = 120.0;

/// Largest per-axis σ of a fine attitude used, arcsec (a worse one is a slew or one star).
pub const MAX_FINE_SIGMA_ARCSEC: f64 = 60.0;

/// A fine attitude whose χ² has a p-value below this is refused (as `batch_fix` does).
pub const FINE_MISFIT_P: f64 = 1e-6;

/// Fewest samples for a fit of one TAM.
pub const MIN_SAMPLES: usize = 30;

/// Largest condition number of the unit-diagonal normal matrix for the full model (bias,
/// scale, misalignment); above it only the bias is fitted.
pub const FULL_MODEL_MAX_CONDITION: f64 = 1e6;

/// Consider σ of each element of `T − I` in the bias-only fit (0.2 %: a prelaunch TAM scale
/// and a 0.1° alignment), dimensionless.
pub const T_PRIOR_SIGMA: f64 = 2e-3;

/// Consider σ per axis of an attitude error common to every fine attitude, arcsec: the body
/// frame the FHST alignments realise against the ACS the TAM was aligned to (the paper's
/// prelaunch FHST misalignments are 60–80″).
pub const ATTITUDE_SYSTEMATIC_ARCSEC: f64 = 60.0;

/// Blocks in time of the bias consistency check ([`BlockConsistency`]).
pub const CONSISTENCY_BLOCKS: usize = 8;

/// Field-model error assumed, mG: 0 because the simulator's truth is the same model (a real
/// mission: ≈ 1 mG, see the module doc).
pub const FIELD_MODEL_SIGMA_MILLIGAUSS: f64 = 0.0;

/// Why the TAM calibration could not be made (its text goes into `report.json` `tam.reason`).
#[derive(Debug, thiserror::Error)]
pub enum TamError {
    /// No APID 0x013 packets.
    #[error("no magnetics frames (APID 0x013) in the telemetry: the spacecraft carried no TAM data, or the file predates format version 2 (docs/icd.md §3.5)")]
    NoMagneticsFrames,
    /// The embedded field model did not load (a build defect).
    #[error("the field model did not load: {0}")]
    FieldModel(String),
    /// No offered sample had a fine attitude and a field.
    #[error("none of the {offered} sample times has a FHST fine attitude and a field (no fine attitude: {fine:?}; no orbit or outside the field model: {no_field})")]
    NoSamples {
        /// Sample times offered.
        offered: usize,
        /// Refused for the fine attitude.
        fine: FineRefusals,
        /// Refused for the field.
        no_field: usize,
    },
    /// Too few valid TAM1 readings among the samples.
    #[error("{samples} samples with a fine attitude and a field, but fewer than {MIN_SAMPLES} with a valid TAM1 reading")]
    TooFewPrimary {
        /// Samples with a fine attitude and a field.
        samples: usize,
    },
}

/// The TAM calibration of one run (`report.json` `tam`).
#[derive(Clone, Debug, Default, Serialize)]
pub struct TamReport {
    /// `determined` or `not_determined`.
    pub status: &'static str,
    /// Why not determined (or what limited it); `None` when determined without remark.
    pub reason: Option<String>,
    /// The method, with its citation.
    pub method: &'static str,
    /// Primary TAM (TAM1) bias, mG, TAM axes.
    #[serde(rename = "bias_mG")]
    pub bias_milligauss: Option<[f64; 3]>,
    /// Its 1σ, mG (random, attitude and model terms together).
    #[serde(rename = "bias_sigma_mG")]
    pub bias_sigma_milligauss: Option<[f64; 3]>,
    /// TAM1, TAM2 fits (`None` for a unit without enough valid samples).
    pub tam1: Option<TamUnitFit>,
    /// TAM2.
    pub tam2: Option<TamUnitFit>,
    /// Magnetics frames (APID 0x013) in the telemetry.
    pub magnetics_frames: usize,
    /// Sample times offered (one per [`SAMPLE_SPACING_S`]) and why some were not used.
    pub samples_offered: usize,
    /// Offered samples without a usable FHST fine attitude: no two non-parallel star
    /// vectors in the batch, a misfit (χ² p < [`FINE_MISFIT_P`]), an axis σ above
    /// [`MAX_FINE_SIGMA_ARCSEC`].
    pub refused_fine_attitude: FineRefusals,
    /// Median over the samples used of the fine attitude's largest axis σ, arcsec.
    pub fine_attitude_sigma_median_arcsec: Option<f64>,
    /// Offered samples without an orbit or outside the field model's span.
    pub refused_no_field: usize,
    /// The FSS/TAM TRIAD attitude against the FHST fine attitude (the paper's check).
    pub triad_comparison: Option<TriadComparison>,
    /// Whether the OBC's magnetics table (Table 6) is written from this calibration, and why
    /// (`super::magnetics_table`; `None` before `calibrate_run` decides).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub table: Option<MagneticsTableDecision>,
}

/// The decision on the magnetics table (`report.json` `tam.table`; made by `super::magnetics_table`).
#[derive(Clone, Debug, Default, Serialize)]
pub struct MagneticsTableDecision {
    /// Whether `tables/magnetics.tbl` is written.
    pub written: bool,
    /// Why, with the numbers.
    pub reason: String,
    /// The table's `field_sigma_milligauss`, TAM1 and TAM2 (when written).
    #[serde(rename = "field_sigma_mG")]
    pub field_sigma_milligauss: Option<[f64; 2]>,
    /// The table's `fss_sun_sigma_rad` in arcsec (when written).
    pub fss_sun_sigma_arcsec: Option<f64>,
    /// The bias per TAM the table subtracts, mG on its axes (when written).
    #[serde(rename = "tam_bias_mG")]
    pub tam_bias_milligauss: Option<[[f64; 3]; 2]>,
}

/// Why offered samples had no fine attitude.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct FineRefusals {
    /// Fewer than two non-parallel identified star vectors in the batch.
    pub no_solution: usize,
    /// χ² p-value below [`FINE_MISFIT_P`].
    pub misfit: usize,
    /// An axis σ above [`MAX_FINE_SIGMA_ARCSEC`].
    pub sigma: usize,
}

/// One TAM's fit.
#[derive(Clone, Debug, Default, Serialize)]
pub struct TamUnitFit {
    /// `bias, scale and misalignment (full 3x3 T)` or `bias only (T nominal)`.
    pub model: &'static str,
    /// Condition number of the unit-diagonal 4×4 normal matrix.
    pub normal_matrix_condition: f64,
    /// Bias, mG, TAM axes.
    #[serde(rename = "bias_mG")]
    pub bias_milligauss: [f64; 3],
    /// Total 1σ, mG.
    #[serde(rename = "bias_sigma_mG")]
    pub bias_sigma_milligauss: [f64; 3],
    /// Its random part (estimated noise through the fit), mG.
    #[serde(rename = "bias_sigma_random_mG")]
    pub bias_sigma_random_milligauss: [f64; 3],
    /// Its attitude consider part ([`ATTITUDE_SYSTEMATIC_ARCSEC`]), mG.
    #[serde(rename = "bias_sigma_attitude_mG")]
    pub bias_sigma_attitude_milligauss: [f64; 3],
    /// Its model part (`T` unknown in the bias-only fit; field model), mG.
    #[serde(rename = "bias_sigma_model_mG")]
    pub bias_sigma_model_milligauss: [f64; 3],
    /// `T = m_tam_from_acs` with scale (rows), identity in the bias-only fit.
    pub t_tam_from_acs: [[f64; 3]; 3],
    /// Scale factor errors `diag(T) − 1`, ppm (full model only).
    pub scale_ppm: Option<[f64; 3]>,
    /// Their 1σ, ppm.
    pub scale_sigma_ppm: Option<[f64; 3]>,
    /// Misalignment θ in ACS with `M_AS = Rot(θ)` (the antisymmetric part of `T`), arcsec.
    pub misalignment_acs_arcsec: Option<[f64; 3]>,
    /// Their 1σ, arcsec.
    pub misalignment_sigma_arcsec: Option<[f64; 3]>,
    /// Noise per axis estimated from the residuals, mG (used for σ).
    #[serde(rename = "noise_estimated_mG")]
    pub noise_estimated_milligauss: [f64; 3],
    /// The a-priori noise, mG ([`TAM_PRIOR_NOISE_MILLIGAUSS`]).
    #[serde(rename = "noise_prior_mG")]
    pub noise_prior_milligauss: f64,
    /// Residual RMS per axis, mG.
    #[serde(rename = "residual_rms_mG")]
    pub residual_rms_milligauss: [f64; 3],
    /// Residual RMS before the fit (`y − x`, nominal TAM), mG.
    #[serde(rename = "residual_rms_uncalibrated_mG")]
    pub residual_rms_uncalibrated_milligauss: [f64; 3],
    /// Samples fitted.
    pub samples: usize,
    /// Fit on one half in time, prediction of the other (both ways).
    pub heldout: Vec<TamHeldOut>,
    /// Whether the bias moves between blocks in time more than the noise explains; its
    /// `sigma_scale` (≥ 1) is applied to the random part of the bias σ.
    pub block_consistency: Option<BlockConsistency>,
}

/// The residuals' means over [`CONSISTENCY_BLOCKS`] blocks in time (the bias each block would
/// give with `T` at the full fit's) against the estimated noise: χ² over its exact
/// expectation `3 (K − Σ_k n_k h̄_kᵀ N⁻¹ h̄_k)` (`h̄_k` the block mean of `[x; 1]`: what the
/// fit itself removes). A ratio above 1 is a slow systematic the white-noise σ does not carry
/// (an orbit-periodic attitude error such as a thermal alignment drift, a field-model error);
/// σ's random part is then scaled by its square root (Birge ratio).
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct BlockConsistency {
    /// Blocks.
    pub blocks: usize,
    /// χ² / its expectation.
    pub chi2_ratio: f64,
    /// Degrees of freedom (the expectation of χ²).
    pub dof: f64,
    /// `√max(1, chi2_ratio)`.
    pub sigma_scale: f64,
}

/// A fit on one half of the samples predicting the other half.
#[derive(Clone, Debug, Default, Serialize)]
pub struct TamHeldOut {
    /// `first half` or `second half`: the half fitted.
    pub fitted: &'static str,
    /// Samples fitted / predicted.
    pub samples: [usize; 2],
    /// The half-fit's bias, mG.
    #[serde(rename = "bias_mG")]
    pub bias_milligauss: [f64; 3],
    /// RMS of the predicted half's residuals with the half-fit's parameters, mG.
    #[serde(rename = "predicted_rms_mG")]
    pub predicted_rms_milligauss: [f64; 3],
    /// χ²/dof of those residuals against the full fit's estimated noise (≈ 1 when the model
    /// carries over).
    pub chi2_per_dof: f64,
}

/// FSS/TAM TRIAD attitude against the FHST fine attitude.
#[derive(Clone, Debug, Default, Serialize)]
pub struct TriadComparison {
    /// Frames compared (a fine attitude, a valid TAM1 sample and an FSS Sun).
    pub samples: usize,
    /// With the TAM at nominal (no bias correction).
    pub uncorrected: AxisErrorStats,
    /// After the bias correction.
    pub bias_corrected: AxisErrorStats,
    /// After the full correction (bias and `T`), when the full model was fitted.
    pub fully_corrected: Option<AxisErrorStats>,
}

/// Per-axis statistics of `δθ` with `A_fhst = Rot(δθ) A_triad`, degrees.
#[derive(Clone, Debug, Default, Serialize)]
pub struct AxisErrorStats {
    /// Mean, deg.
    pub mean_deg: [f64; 3],
    /// RMS, deg.
    pub rms_deg: [f64; 3],
    /// Largest |δθ|, deg.
    pub max_abs_deg: [f64; 3],
    /// 3 × RMS, deg (the paper's coarse requirement is 2° at 3σ).
    pub three_rms_deg: [f64; 3],
}

/// One TAM sample with its fine attitude.
#[derive(Clone, Copy, Debug)]
struct Sample {
    /// Index into the frames.
    frame: usize,
    /// Model field, mG, ACS (`A B_eci`).
    field_acs_milligauss: Vector3<f64>,
    /// Model field, mG, ECI.
    field_eci_milligauss: Vector3<f64>,
    /// Fine attitude.
    m_acs_from_eci: Matrix3<f64>,
    /// Its largest axis σ, arcsec.
    fine_sigma_arcsec: f64,
    /// TAM readings, mG, TAM axes (`None` = not valid).
    tam_milligauss: [Option<Vector3<f64>>; TAMS],
}

/// A linear fit `y = T x + b` of one TAM.
#[derive(Clone, Copy, Debug)]
struct LinearFit {
    /// `T` (rows per TAM axis).
    t_tam_from_acs: Matrix3<f64>,
    /// `b`, mG.
    bias_milligauss: Vector3<f64>,
    /// Full model (true) or bias only.
    full: bool,
    /// `N⁻¹` (full: 4×4 over `[x; 1]`; bias only: `1/n` in the (3,3) element).
    n_inv: Matrix4<f64>,
}

impl LinearFit {
    fn predict(&self, x: &Vector3<f64>) -> Vector3<f64> {
        self.t_tam_from_acs * x + self.bias_milligauss
    }
}

/// The TAM stage of `calibrate`: fit TAM1 and TAM2 against the FHST fine attitude and compare
/// the FSS/TAM attitude with it (module doc). `obc_bias_at` gives the gyro bias (rad/s, ACS)
/// (at an absolute time, s since 1958 TAI) that carries the batch vectors to each sample.
#[must_use]
pub fn tam_stage(
    tm: &Telemetry,
    frames: &[FrameObservations],
    obc_bias_at: &dyn Fn(f64) -> Vector3<f64>,
) -> TamReport {
    let mut report = TamReport {
        status: "not_determined",
        method: "batch least squares with the attitude known (Lerner & Shuster 1981): y = T (A B_eci) + b per TAM axis, A the FHST fine attitude, B_eci the IGRF/DGRF field at the definitive orbit",
        magnetics_frames: tm.magnetics.len(),
        ..TamReport::default()
    };
    if tm.magnetics.is_empty() {
        report.reason = Some(TamError::NoMagneticsFrames.to_string());
        return report;
    }
    let samples = match collect_samples(tm, frames, obc_bias_at, &mut report) {
        Ok(s) => s,
        Err(why) => {
            report.reason = Some(why.to_string());
            return report;
        }
    };
    report.tam1 = fit_unit(&samples, 0);
    report.tam2 = fit_unit(&samples, 1);
    let Some(primary) = report.tam1.as_ref() else {
        let why = TamError::TooFewPrimary {
            samples: samples.len(),
        };
        report.reason = Some(why.to_string());
        return report;
    };
    report.status = "determined";
    report.bias_milligauss = Some(primary.bias_milligauss);
    report.bias_sigma_milligauss = Some(primary.bias_sigma_milligauss);
    report.triad_comparison = triad_comparison(&samples, frames, primary);
    report
}

/// One sample per [`SAMPLE_SPACING_S`] whose magnetics frame has a raw frame of the same time
/// code, an orbit, a field and a FHST-only fine attitude.
fn collect_samples(
    tm: &Telemetry,
    frames: &[FrameObservations],
    obc_bias_at: &dyn Fn(f64) -> Vector3<f64>,
    report: &mut TamReport,
) -> Result<Vec<Sample>, TamError> {
    let model = FieldModel::dgrf_1990_1995().map_err(|e| TamError::FieldModel(e.to_string()))?;
    let mut field = FieldEvaluator::new(model, FieldEvaluator::DEFAULT_REFRESH_S);
    let span_s = match (tm.magnetics.first(), tm.magnetics.last()) {
        (Some(a), Some(b)) => b.time.seconds() - a.time.seconds(),
        _ => 0.0,
    };
    let spacing_s = SAMPLE_SPACING_S.max(span_s / MAX_SAMPLES);
    let mut out = Vec::new();
    let mut next_s = f64::NEG_INFINITY;
    for m in &tm.magnetics {
        let t = m.time.seconds();
        if t < next_s || !m.tam.iter().any(|s| s.flags & TAM_FLAG_VALID != 0) {
            continue;
        }
        // A torquer bar was on (ICD format version 3, docs/icd.md §3.5): the words include
        // the bars' own field; the next bars-off frame is taken instead.
        if m.tam.iter().any(|s| s.flags & TAM_FLAG_TORQUERS_ON != 0) {
            continue;
        }
        let Ok(k) = frames.binary_search_by(|f| f.time.cmp(&m.time)) else {
            continue;
        };
        next_s = t + spacing_s;
        report.samples_offered += 1;
        let field_eci_nt = frames[k].orbit.and_then(|(pos_eci_km, _)| {
            field
                .field_gcrs_nt(epoch_from_time_tag(m.time), &pos_eci_km)
                .ok()
        });
        let Some(field_eci_nt) = field_eci_nt else {
            report.refused_no_field += 1;
            continue;
        };
        let (m_acs_from_eci, fine_sigma_arcsec) = match fine_attitude_at(frames, k, &obc_bias_at(t))
        {
            Ok(m) => m,
            Err(FineRefusal::NoSolution) => {
                report.refused_fine_attitude.no_solution += 1;
                continue;
            }
            Err(FineRefusal::Misfit) => {
                report.refused_fine_attitude.misfit += 1;
                continue;
            }
            Err(FineRefusal::Sigma) => {
                report.refused_fine_attitude.sigma += 1;
                continue;
            }
        };
        let field_eci_milligauss = field_eci_nt * MILLIGAUSS_PER_NANOTESLA;
        out.push(Sample {
            frame: k,
            field_acs_milligauss: m_acs_from_eci * field_eci_milligauss,
            field_eci_milligauss,
            m_acs_from_eci,
            fine_sigma_arcsec,
            tam_milligauss: tam_readings(m),
        });
    }
    if out.is_empty() {
        return Err(TamError::NoSamples {
            offered: report.samples_offered,
            fine: report.refused_fine_attitude,
            no_field: report.refused_no_field,
        });
    }
    let mut sigmas: Vec<f64> = out.iter().map(|s| s.fine_sigma_arcsec).collect();
    sigmas.sort_by(f64::total_cmp);
    report.fine_attitude_sigma_median_arcsec = sigmas.get(sigmas.len() / 2).copied();
    Ok(out)
}

/// The valid TAM readings of a frame, mG in TAM axes.
fn tam_readings(m: &MagneticsFrame) -> [Option<Vector3<f64>>; TAMS] {
    m.tam.map(|s| {
        (s.flags & TAM_FLAG_VALID != 0)
            .then(|| Vector3::from(s.field_counts.map(f64::from)) * TAM_MILLIGAUSS_PER_COUNT)
    })
}

/// Why a sample has no fine attitude ([`FineRefusals`]).
enum FineRefusal {
    NoSolution,
    Misfit,
    Sigma,
}

/// FHST-only fine attitude at frame `k` from the frames within ±[`FINE_HALF_WINDOW_S`].
fn fine_attitude_at(
    frames: &[FrameObservations],
    k: usize,
    bias_acs_rad_per_s: &Vector3<f64>,
) -> Result<(Matrix3<f64>, f64), FineRefusal> {
    let t = frames[k].time.seconds();
    let lo = frames.partition_point(|f| f.time.seconds() < t - FINE_HALF_WINDOW_S);
    let hi = frames.partition_point(|f| f.time.seconds() < t + FINE_HALF_WINDOW_S);
    let sol = fhst_attitude(frames, lo..hi.max(k + 1), k, bias_acs_rad_per_s)
        .map_err(|_| FineRefusal::NoSolution)?;
    #[allow(clippy::cast_precision_loss)]
    if chi2_sf(sol.chi2, sol.dof as f64) < FINE_MISFIT_P {
        return Err(FineRefusal::Misfit);
    }
    let worst_arcsec = (0..3)
        .map(|i| sol.cov_acs_rad2[(i, i)].max(0.0).sqrt() * ARCSEC_PER_RAD)
        .fold(0.0, f64::max);
    if worst_arcsec <= MAX_FINE_SIGMA_ARCSEC {
        Ok((sol.m_acs_from_eci, worst_arcsec))
    } else {
        Err(FineRefusal::Sigma)
    }
}

/// The (x, y) pairs of TAM `unit`: model field in ACS, reading in TAM axes (mG).
fn pairs(samples: &[Sample], unit: usize) -> Vec<(Vector3<f64>, Vector3<f64>)> {
    samples
        .iter()
        .filter_map(|s| s.tam_milligauss[unit].map(|y| (s.field_acs_milligauss, y)))
        .collect()
}

/// Normal matrix `Σ [x;1][x;1]ᵀ` and its condition number at unit diagonal.
fn normal_matrix(pairs: &[(Vector3<f64>, Vector3<f64>)]) -> (Matrix4<f64>, f64) {
    let mut n = Matrix4::zeros();
    for (x, _) in pairs {
        let h = Vector4::new(x.x, x.y, x.z, 1.0);
        n += h * h.transpose();
    }
    let d = Matrix4::from_diagonal(&n.diagonal().map(|v| 1.0 / v.max(1e-300).sqrt()));
    let eig = (d * n * d).symmetric_eigenvalues();
    let (lo, hi) = eig.iter().fold((f64::INFINITY, 0.0_f64), |(lo, hi), &e| {
        (lo.min(e), hi.max(e))
    });
    let cond = if lo > 0.0 { hi / lo } else { f64::INFINITY };
    (n, cond)
}

/// Fit `y = T x + b` (full) or `y = x + b` (bias only) to `pairs`.
fn fit(pairs: &[(Vector3<f64>, Vector3<f64>)], full: bool) -> Option<LinearFit> {
    if pairs.is_empty() {
        return None;
    }
    #[allow(clippy::cast_precision_loss)]
    let count = pairs.len() as f64;
    if !full {
        let mean = pairs.iter().map(|(x, y)| y - x).sum::<Vector3<f64>>() / count;
        let mut n_inv = Matrix4::zeros();
        n_inv[(3, 3)] = 1.0 / count;
        return Some(LinearFit {
            t_tam_from_acs: Matrix3::identity(),
            bias_milligauss: mean,
            full,
            n_inv,
        });
    }
    let (n, _) = normal_matrix(pairs);
    let n_inv = n.try_inverse()?;
    let mut t = Matrix3::zeros();
    let mut b = Vector3::zeros();
    for axis in 0..3 {
        let rhs = pairs
            .iter()
            .map(|(x, y)| Vector4::new(x.x, x.y, x.z, 1.0) * y[axis])
            .sum::<Vector4<f64>>();
        let p = n_inv * rhs;
        t.set_row(axis, &Vector3::new(p[0], p[1], p[2]).transpose());
        b[axis] = p[3];
    }
    Some(LinearFit {
        t_tam_from_acs: t,
        bias_milligauss: b,
        full,
        n_inv,
    })
}

/// RMS per axis of `y − prediction`.
fn residual_rms(
    pairs: &[(Vector3<f64>, Vector3<f64>)],
    predict: impl Fn(&Vector3<f64>) -> Vector3<f64>,
) -> Vector3<f64> {
    if pairs.is_empty() {
        return Vector3::zeros();
    }
    #[allow(clippy::cast_precision_loss)]
    let count = pairs.len() as f64;
    let ss = pairs
        .iter()
        .map(|(x, y)| (y - predict(x)).map(|r| r * r))
        .sum::<Vector3<f64>>();
    (ss / count).map(f64::sqrt)
}

/// The fit of TAM `unit` with its σ and held-out check; `None` below [`MIN_SAMPLES`].
fn fit_unit(samples: &[Sample], unit: usize) -> Option<TamUnitFit> {
    let data = pairs(samples, unit);
    if data.len() < MIN_SAMPLES {
        return None;
    }
    let (_, condition) = normal_matrix(&data);
    let full = condition <= FULL_MODEL_MAX_CONDITION;
    let f = fit(&data, full)?;
    let params = if full { 4.0 } else { 1.0 };
    #[allow(clippy::cast_precision_loss)]
    let dof = (data.len() as f64 - params).max(1.0);
    let rms = residual_rms(&data, |x| f.predict(x));
    #[allow(clippy::cast_precision_loss)]
    let noise = rms.map(|r| r * (data.len() as f64 / dof).sqrt());
    let consistency = block_consistency(&data, &f, &noise);
    let scale_random = consistency.map_or(1.0, |c| c.sigma_scale);
    let sigma_random = noise.map(|s| s * f.n_inv[(3, 3)].max(0.0).sqrt() * scale_random);
    let sigma_attitude = attitude_consider(&data, &f);
    let mean_x = data.iter().map(|(x, _)| *x).sum::<Vector3<f64>>() / count_f64(data.len());
    let sigma_t = if full {
        0.0
    } else {
        T_PRIOR_SIGMA * mean_x.norm()
    };
    let sigma_model =
        Vector3::repeat((sigma_t.powi(2) + FIELD_MODEL_SIGMA_MILLIGAUSS.powi(2)).sqrt());
    let sigma_total = Vector3::from_fn(|i, _| {
        (sigma_random[i].powi(2) + sigma_attitude[i].powi(2) + sigma_model[i].powi(2)).sqrt()
    });
    let (scale, misalignment) = if full {
        let (s, m) = scale_and_misalignment(&f, &noise);
        (Some(s), Some(m))
    } else {
        (None, None)
    };
    Some(TamUnitFit {
        model: if full {
            "bias, scale and misalignment (full 3x3 T)"
        } else {
            "bias only (T nominal: the field direction does not vary enough in the body)"
        },
        normal_matrix_condition: condition,
        bias_milligauss: f.bias_milligauss.into(),
        bias_sigma_milligauss: sigma_total.into(),
        bias_sigma_random_milligauss: sigma_random.into(),
        bias_sigma_attitude_milligauss: sigma_attitude.into(),
        bias_sigma_model_milligauss: sigma_model.into(),
        t_tam_from_acs: rows(&f.t_tam_from_acs),
        scale_ppm: scale.map(|s| s.0),
        scale_sigma_ppm: scale.map(|s| s.1),
        misalignment_acs_arcsec: misalignment.map(|m| m.0),
        misalignment_sigma_arcsec: misalignment.map(|m| m.1),
        noise_estimated_milligauss: noise.into(),
        noise_prior_milligauss: TAM_PRIOR_NOISE_MILLIGAUSS,
        residual_rms_milligauss: rms.into(),
        residual_rms_uncalibrated_milligauss: residual_rms(&data, |x| *x).into(),
        samples: data.len(),
        heldout: heldout(&data, full, &noise),
        block_consistency: consistency,
    })
}

/// The bias consistency over blocks in time ([`BlockConsistency`]); `None` with fewer than 10
/// samples per block.
fn block_consistency(
    data: &[(Vector3<f64>, Vector3<f64>)],
    f: &LinearFit,
    noise: &Vector3<f64>,
) -> Option<BlockConsistency> {
    let k = CONSISTENCY_BLOCKS;
    if data.len() < 10 * k {
        return None;
    }
    let (mut chi2, mut removed) = (0.0, 0.0);
    for b in 0..k {
        let block = data.get(b * data.len() / k..(b + 1) * data.len() / k)?;
        let n = count_f64(block.len());
        let mean_r = block
            .iter()
            .map(|(x, y)| y - f.predict(x))
            .sum::<Vector3<f64>>()
            / n;
        let mean_h = block
            .iter()
            .map(|(x, _)| Vector4::new(x.x, x.y, x.z, 1.0))
            .sum::<Vector4<f64>>()
            / n;
        chi2 += (0..3)
            .map(|i| n * (mean_r[i] / noise[i].max(1e-12)).powi(2))
            .sum::<f64>();
        removed += n * (mean_h.transpose() * f.n_inv * mean_h)[(0, 0)];
    }
    let dof = 3.0 * (count_f64(k) - removed);
    (dof > 0.5).then(|| {
        let chi2_ratio = chi2 / dof;
        BlockConsistency {
            blocks: k,
            chi2_ratio,
            dof,
            sigma_scale: chi2_ratio.max(1.0).sqrt(),
        }
    })
}

#[allow(clippy::cast_precision_loss)]
fn count_f64(n: usize) -> f64 {
    n as f64
}

fn rows(m: &Matrix3<f64>) -> [[f64; 3]; 3] {
    [0, 1, 2].map(|i| [m[(i, 0)], m[(i, 1)], m[(i, 2)]])
}

/// σ of the bias per axis from an attitude error common to every sample
/// ([`ATTITUDE_SYSTEMATIC_ARCSEC`] per axis): `δy_k = T [x_k×] δθ` through the fit.
fn attitude_consider(data: &[(Vector3<f64>, Vector3<f64>)], f: &LinearFit) -> Vector3<f64> {
    let sigma_rad = ATTITUDE_SYSTEMATIC_ARCSEC / ARCSEC_PER_RAD;
    let mut out = Vector3::zeros();
    for axis in 0..3 {
        // Sensitivity of the bias of this axis to δθ (1×3).
        let mut g = Vector3::zeros();
        for (x, _) in data {
            let row = (f.t_tam_from_acs * x.cross_matrix()).row(axis).transpose();
            let h = Vector4::new(x.x, x.y, x.z, 1.0);
            let weight = if f.full {
                (f.n_inv * h)[3]
            } else {
                f.n_inv[(3, 3)]
            };
            g += row * weight;
        }
        out[axis] = sigma_rad * g.norm();
    }
    out
}

/// Scale `diag(T) − 1` (ppm) and misalignment θ (arcsec, `M_AS = Rot(θ)`, `T ≈ (I + D)(I +
/// [θ×])`) with their σ from the estimated noise.
fn scale_and_misalignment(
    f: &LinearFit,
    noise: &Vector3<f64>,
) -> (([f64; 3], [f64; 3]), ([f64; 3], [f64; 3])) {
    let t = &f.t_tam_from_acs;
    let var = |axis: usize, col: usize| (noise[axis].powi(2) * f.n_inv[(col, col)]).max(0.0);
    let scale = [0, 1, 2].map(|i| (t[(i, i)] - 1.0) * 1e6);
    let scale_sigma = [0, 1, 2].map(|i| var(i, i).sqrt() * 1e6);
    // [θ×] = (T − Tᵀ)/2: θx = A(2,1), θy = A(0,2), θz = A(1,0).
    let idx = [(2, 1), (0, 2), (1, 0)];
    let theta = idx.map(|(r, c)| 0.5 * (t[(r, c)] - t[(c, r)]) * ARCSEC_PER_RAD);
    let theta_sigma = idx.map(|(r, c)| 0.5 * (var(r, c) + var(c, r)).sqrt() * ARCSEC_PER_RAD);
    ((scale, scale_sigma), (theta, theta_sigma))
}

/// Fit each half in time and predict the other.
fn heldout(
    data: &[(Vector3<f64>, Vector3<f64>)],
    full: bool,
    noise: &Vector3<f64>,
) -> Vec<TamHeldOut> {
    let half = data.len() / 2;
    let (first, second) = data.split_at(half);
    [
        ("first half", first, second),
        ("second half", second, first),
    ]
    .into_iter()
    .filter_map(|(name, fitted, predicted)| {
        let f = fit(fitted, full)?;
        let rms = residual_rms(predicted, |x| f.predict(x));
        let chi2 = (0..3)
            .map(|i| (rms[i] / noise[i].max(1e-12)).powi(2))
            .sum::<f64>()
            / 3.0;
        Some(TamHeldOut {
            fitted: name,
            samples: [fitted.len(), predicted.len()],
            bias_milligauss: f.bias_milligauss.into(),
            predicted_rms_milligauss: rms.into(),
            chi2_per_dof: chi2,
        })
    })
    .collect()
}

/// TRIAD (FSS Sun first, TAM1 field second) against the fine attitude, before and after the
/// bias correction (and the full correction when fitted).
fn triad_comparison(
    samples: &[Sample],
    frames: &[FrameObservations],
    tam1: &TamUnitFit,
) -> Option<TriadComparison> {
    let bias = Vector3::from(tam1.bias_milligauss);
    let t = Matrix3::from_fn(|r, c| tam1.t_tam_from_acs[r][c]);
    let t_inv = t.try_inverse();
    let full = tam1.scale_ppm.is_some();
    let mut errors: [Vec<Vector3<f64>>; 3] = Default::default();
    for s in samples {
        let Some(y) = s.tam_milligauss[0] else {
            continue;
        };
        let Some(sun) = frames[s.frame].suns.iter().flatten().next() else {
            continue;
        };
        let corrected = [
            Some(y),
            Some(y - bias),
            t_inv.filter(|_| full).map(|ti| ti * (y - bias)),
        ];
        for (slot, b_acs) in corrected.iter().enumerate() {
            let Some(b_acs) = b_acs else {
                continue;
            };
            let Some(a) = triad(
                &sun.meas.dir_acs,
                &sun.sun_eci,
                b_acs,
                &s.field_eci_milligauss,
            ) else {
                continue;
            };
            errors[slot].push(rotvec_from_rot(&(s.m_acs_from_eci * a.transpose())));
        }
    }
    if errors[0].is_empty() {
        return None;
    }
    Some(TriadComparison {
        samples: errors[0].len(),
        uncorrected: axis_stats(&errors[0]),
        bias_corrected: axis_stats(&errors[1]),
        fully_corrected: (!errors[2].is_empty()).then(|| axis_stats(&errors[2])),
    })
}

fn axis_stats(errors_rad: &[Vector3<f64>]) -> AxisErrorStats {
    let n = count_f64(errors_rad.len().max(1));
    let deg = |v: &Vector3<f64>| v.map(f64::to_degrees);
    let mean = deg(&(errors_rad.iter().sum::<Vector3<f64>>() / n));
    let rms = deg(&(errors_rad
        .iter()
        .map(|e| e.map(|x| x * x))
        .sum::<Vector3<f64>>()
        / n)
        .map(f64::sqrt));
    let max_abs = deg(&errors_rad
        .iter()
        .fold(Vector3::zeros(), |m: Vector3<f64>, e| {
            m.zip_map(e, |a, b| a.max(b.abs()))
        }));
    AxisErrorStats {
        mean_deg: mean.into(),
        rms_deg: rms.into(),
        max_abs_deg: max_abs.into(),
        three_rms_deg: (rms * 3.0).into(),
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    /// A field turning through the body over an orbit: the full fit recovers `T` and `b`
    /// exactly without noise, and the bias-only fit recovers `b` when `T = I`.
    #[test]
    fn linear_fit_recovers_t_and_bias() {
        let t_true = Matrix3::new(
            1.001, 0.0024, -0.0015, -0.0024, 0.9992, 0.0034, 0.0015, -0.0034, 1.0006,
        );
        let b_true = Vector3::new(0.0, 0.0, -4.0);
        let data: Vec<_> = (0..200)
            .map(|k| {
                let u = f64::from(k) * 0.05;
                let x = Vector3::new(300.0 * u.cos(), 200.0 * u.sin(), 150.0 * (2.0 * u).cos());
                (x, t_true * x + b_true)
            })
            .collect();
        let (_, cond) = normal_matrix(&data);
        assert!(cond < FULL_MODEL_MAX_CONDITION, "{cond}");
        let f = fit(&data, true).unwrap();
        assert!((f.bias_milligauss - b_true).norm() < 1e-9);
        assert!((f.t_tam_from_acs - t_true).norm() < 1e-12);
        let ident: Vec<_> = data.iter().map(|(x, _)| (*x, x + b_true)).collect();
        let f = fit(&ident, false).unwrap();
        assert!((f.bias_milligauss - b_true).norm() < 1e-12);
        // A field fixed in the body: T is not observable.
        let fixed: Vec<_> = (0..50)
            .map(|_| (Vector3::new(300.0, 1.0, 2.0), Vector3::zeros()))
            .collect();
        assert!(normal_matrix(&fixed).1 > FULL_MODEL_MAX_CONDITION);
    }
}
