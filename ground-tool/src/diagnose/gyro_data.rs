//! # What the gyro analyses share: settings, input, result, and the batch attitudes
//!
//! The hold analysis ([`super::gyro`]: the bias history) and the slew analysis
//! ([`super::gyro_slews`]: asymmetry, scale against rate, bias against rate mode) read the
//! same input and write one [`GyroAnalysis`]; the holds hand the slews their bias history
//! ([`HoldBias`]) through [`SlewInput`]. Both judge a candidate with [`delta_bic`].

use super::measurements::MeasurementSet;
use super::search::Evidence;
use super::Detected;
use crate::calibration::iru::{GyroCalibration, GyroStep};
use crate::pipeline::observations::{FrameObservations, GyroSplit};
use fsw_core::raw::TimeTag;
use nalgebra::{Matrix3, Vector3};

/// BIC improvement of a candidate with `k` parameters over `n` rows, χ² from `c0` to `c1`,
/// with the same noise scale as the F test: the residual scale `s2 = c1/dof` when it is above
/// the declared noise (unknown σ: `n ln(c0/c1)`), the declared noise otherwise (known σ:
/// `c0 − c1`). With few rows and residuals quieter than declared, `n ln(c0/c1)` would
/// inflate a change the F test calls noise (ΔBIC 31 at LR p = 0.03 on clean data).
pub(super) fn delta_bic(c0: f64, c1: f64, s2: f64, n: usize, k: usize) -> f64 {
    let n = n as f64;
    let gain = if s2 >= 1.0 {
        n * (c0 / c1.max(1e-9)).ln()
    } else {
        c0 - c1
    };
    gain - k as f64 * n.ln()
}

/// Settings of the gyro analysis.
#[derive(Clone, Copy, Debug)]
pub struct GyroConfig {
    /// Family-wise significance.
    pub alpha: f64,
    /// Smallest ΔBIC accepted.
    pub min_delta_bic: f64,
    /// Declared bias random walk (rad/s^1.5).
    pub rrw_rad_per_s15: f64,
    /// Declared angle random walk (rad/√s).
    pub arw_rad_per_sqrt_s: f64,
    /// The operator declares the early bias transient (a ramp is in the baseline).
    pub transient_declared: bool,
}

/// What the gyro analysis reads of a frame: ≈ 120 bytes of its 704, so that the frames
/// (0.37 GB over six months of 30-s telemetry) can go once the measurement set is built.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GyroFrame {
    /// Frame time.
    pub time: TimeTag,
    /// Gyro increment over the interval that ended at this frame.
    pub gyro: Option<GyroStep>,
    /// IRU rate mode of that interval.
    pub high_rate: bool,
    /// The step came from the backup triad (its own bias and δM).
    pub iru_backup: bool,
    /// IRU temperature (°C).
    pub iru_temperature_c: f64,
    /// A rate-mode switch split inside the interval (decimated telemetry), as calibrate's
    /// chain takes it.
    pub split: Option<GyroSplit>,
}

impl From<&FrameObservations> for GyroFrame {
    fn from(f: &FrameObservations) -> Self {
        Self {
            time: f.time,
            gyro: f.gyro,
            high_rate: f.high_rate,
            iru_backup: f.iru_backup,
            iru_temperature_c: f.temperatures_c[4],
            split: f.gyro_split(),
        }
    }
}

/// The gyro analysis's input besides the sensor-side fit.
#[derive(Clone, Debug)]
pub struct GyroInput<'a> {
    /// Per frame.
    pub frames: &'a [GyroFrame],
    /// Gyro calibration (δM on the increments; the bias is the fallback).
    pub gyro: GyroCalibration,
    /// Bias per frame (e.g. the OBC's estimate); `None` = `gyro.bias_acs_rad_per_s`.
    pub bias_per_frame: Option<&'a [Vector3<f64>]>,
    /// δM of the backup triad (IRUCAL's), for the steps it produced; `None` = `gyro.delta_m`.
    pub delta_m_backup: Option<Matrix3<f64>>,
}

impl GyroInput<'_> {
    /// The δM of the triad that produced the frame's step.
    #[must_use]
    pub fn delta_m(&self, frame: &GyroFrame) -> Matrix3<f64> {
        match (frame.iru_backup, self.delta_m_backup) {
            (true, Some(dm)) => dm,
            _ => self.gyro.delta_m,
        }
    }
}

/// The gyro analysis result.
#[derive(Clone, Debug, Default)]
pub struct GyroAnalysis {
    /// Detected gyro effects.
    pub detected: Vec<Detected>,
    /// Evidence of every candidate (for the report).
    pub candidates: Vec<Evidence>,
    /// Number of bias samples and slews used.
    pub bias_samples: usize,
    /// Slews used for the asymmetry.
    pub slews: usize,
    /// Bias history (t s, bias error arcsec/s per axis) for plots.
    pub bias_series: Vec<(f64, [f64; 3])>,
    /// Baseline fit of the bias (t, fitted arcsec/s per axis) and the final one.
    pub bias_fit_before: Vec<(f64, [f64; 3])>,
    /// Final fit.
    pub bias_fit_after: Vec<(f64, [f64; 3])>,
    /// Slew residuals before/after the asymmetry (angle deg signed about the dominant axis,
    /// residual arcsec along it).
    pub slew_residuals: Vec<(f64, f64, f64)>,
    /// Notes (why something was not analysed).
    pub notes: Vec<String>,
    /// The candidates not kept, tested against the final model (the last round of the bias
    /// history, the asymmetry when rejected): the evidence ledger ([`super::ledger`]) reports
    /// a significant one as unexplained with its size and the reason it was not kept.
    pub leftover: Vec<GyroLeftover>,
}

/// A gyro candidate not kept, with its size against the final model.
#[derive(Clone, Debug)]
pub struct GyroLeftover {
    /// Its evidence (`p_holm`: Bonferroni over the candidates of its family).
    pub evidence: Evidence,
    /// The regressor its structure follows (`time_s`, `iru_temperature_c`, `slew_angle_abs`).
    pub regressor: &'static str,
    /// Size: RMS of the fitted term over the samples (arcsec/s), or the largest asymmetry
    /// (ppm).
    pub size: f64,
    /// Unit of `size`.
    pub unit: &'static str,
}

/// A batch's corrected attitude and its per-axis variance (rad²), boxed: few batches are
/// usable (on six months of 30-s frames a few thousand of 0.5 million), so the list costs 8
/// bytes per batch instead of 104 (issue 22).
pub(super) type BatchAttitude = Option<Box<(Matrix3<f64>, Vector3<f64>)>>;

/// The attitude of batch `i`, if usable.
pub(super) fn batch_attitude(
    att: &[BatchAttitude],
    i: usize,
) -> Option<(Matrix3<f64>, Vector3<f64>)> {
    att[i].as_deref().copied()
}

/// The bias the holds measure, per frame: the bias history's fit (its constant and the
/// accepted candidates) relative to the reference `b_ref`, with its prediction variance.
#[derive(Clone, Debug)]
pub(super) struct HoldBias {
    /// Fitted bias relative to `b_ref` (rad/s, ACS), per frame.
    pub(super) bias_rad_per_s: Vec<Vector3<f64>>,
    /// Variance of that fit (arcsec²/s², per ACS axis), per frame: the fit's covariance
    /// scaled by the residual χ²/dof when it is above one.
    pub(super) var_arcsec2_per_s2: Vec<Vector3<f64>>,
    /// A candidate beyond the constant was accepted (the slews then take this history as
    /// their bias; otherwise the OBC's estimate at each slew's start).
    pub(super) modelled: bool,
}

/// What the slew analysis reads ([`super::gyro_slews`]).
pub(super) struct SlewInput<'a> {
    pub(super) input: &'a GyroInput<'a>,
    pub(super) set: &'a MeasurementSet,
    pub(super) att: &'a [BatchAttitude],
    pub(super) b_ref: &'a Vector3<f64>,
    pub(super) hold_bias: Option<&'a HoldBias>,
    pub(super) cfg: &'a GyroConfig,
}
