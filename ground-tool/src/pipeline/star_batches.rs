//! # Gyro batches: every identified star, on a gyro-carried attitude
//!
//! Input of [`crate::calibration::fhst_relative`]. Why: the FHST1–FHST2 relative alignment
//! is limited by each tracker's roll about its boresight, which only star offsets inside the
//! ±4° field reveal. Each tracker follows one star at a time, so most of its stars are not
//! seen at the same time as the other tracker's; the gyro ties them together.
//!
//! A batch is a run of frames in one rate mode with gyro data and no gap over [`MAX_GAP_S`]:
//! at most [`HOLD_BATCH_MAX_S`] in a hold (low rate), where the gyro's noise (≈ 0.1″) and bias
//! drift are negligible, and at most [`SLEW_BATCH_MAX_S`] in a slew (high rate), where the
//! stars cross the field and the gyro's scale and misalignment errors (≈ 5e-4 × the angle
//! turned) grow with the rate — at a constant rate they grow linearly, like a bias error,
//! and the fit's drift term takes both. The reference attitude of a batch is the FHST-only
//! fine attitude at its centre (else the OBC's) carried to every frame by the gyro with the
//! OBC's bias.

use nalgebra::{Matrix3, Vector3};

use super::observations::{body_to_center, fhst_attitude, FrameObservations};
use crate::calibration::fhst_relative::BatchStarSample;
use fsw_core::sensor::SensorId;

/// Longest hold batch (s): a 16-min hold is one batch.
pub const HOLD_BATCH_MAX_S: f64 = 1200.0;
/// Longest slew batch (s): 9° at the OBC's 0.05°/s slews. Chosen by the Monte Carlo
/// (`calibration-mc`, 20 seeds, σ of the two roll axes and mean NEES): 20 s → 6.2″, 3.7;
/// 60 s → 5.3″, 3.5; 180 s → 5.0″, 3.2; 400 s → 4.7″, 3.7; 1200 s → 4.3″ but NEES 23 (the
/// gyro's scale and misalignment errors through the slews' accelerations).
pub const SLEW_BATCH_MAX_S: f64 = 180.0;
/// Shortest batch worth a 6-parameter nuisance (s).
const BATCH_MIN_S: f64 = 20.0;
/// A gap in the frames longer than this ends a batch (s).
const MAX_GAP_S: f64 = 5.0;

/// Batches as frame ranges `[lo, hi)`.
#[must_use]
pub fn star_batches(frames: &[FrameObservations]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut lo = 0;
    while lo < frames.len() {
        let t0 = frames[lo].time.seconds();
        let high_rate = frames[lo].high_rate;
        let max_s = if high_rate {
            SLEW_BATCH_MAX_S
        } else {
            HOLD_BATCH_MAX_S
        };
        let mut hi = lo + 1;
        while hi < frames.len() {
            let f = &frames[hi];
            let gap = f.time.seconds() - frames[hi - 1].time.seconds();
            if f.high_rate != high_rate
                || f.gyro.is_none()
                || !(gap <= MAX_GAP_S)
                || f.time.seconds() - t0 >= max_s
            {
                break;
            }
            hi += 1;
        }
        if frames[hi - 1].time.seconds() - t0 >= BATCH_MIN_S {
            out.push((lo, hi));
        }
        lo = hi;
    }
    out
}

/// The identified FHST samples of every batch (module doc), and the number of batches.
/// `bias_at(t)` is the gyro bias (ACS, rad/s) to carry the attitude with, e.g. the OBC's.
#[must_use]
pub fn star_batch_samples(
    frames: &[FrameObservations],
    bias_at: &dyn Fn(f64) -> Vector3<f64>,
) -> (Vec<BatchStarSample>, usize) {
    let mut out = Vec::new();
    let mut n = 0;
    for (lo, hi) in star_batches(frames) {
        let center = (lo + hi) / 2;
        let t_c = frames[center].time.seconds();
        let bias = bias_at(t_c);
        let a_center = match fhst_attitude(frames, lo..hi, center, &bias) {
            Ok(sol) => sol.m_acs_from_eci,
            Err(_) => match frames[center].obc_q_acs_from_eci {
                Some(q) => q.to_dcm(),
                None => continue,
            },
        };
        // A(k) = (A(c) A(k)ᵀ)ᵀ A(c): the centre attitude carried to frame k by the gyro.
        let att: Vec<Matrix3<f64>> =
            body_to_center(frames, lo..hi, center, &bias, &Matrix3::zeros())
                .iter()
                .map(|m| m.transpose() * a_center)
                .collect();
        let before = out.len();
        for k in lo..hi {
            let f = &frames[k];
            for (tracker, s) in SensorId::ALL.into_iter().zip(&f.stars) {
                if let Some((_, dir_eci)) = s.as_ref().and_then(|s| s.identified) {
                    if let Some(s) = s {
                        out.push(BatchStarSample {
                            tracker,
                            batch: n,
                            dt_s: f.time.seconds() - t_c,
                            ref_acs: att[k - lo] * dir_eci,
                            meas_acs: s.meas.dir_acs,
                            sigma_rad: s.sigma_rad,
                            aberration_uncorrected: f.orbit.is_none(),
                        });
                    }
                }
            }
        }
        if out.len() > before {
            n += 1;
        }
    }
    (out, n)
}
