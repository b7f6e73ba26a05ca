//! # The attitude fixes of IRUCAL: fine attitudes over a batch, with what their covariance
//! leaves out (docs/algorithms.md §7)
//!
//! The gyro chain (`super::gyro_chain`) ties its links to these fixes; the calibration
//! (`super::calibrate`) sets the floors from FFCAL's result (`FixFloors::from_ffcal`).

use super::observations::{fine_attitude, AttitudeSensors, FrameObservations};
use crate::calibration::iru::{AttitudeFix, GyroStep};
use crate::diagnose::stats::chi2_sf;
use fsw_core::units::ARCSEC_PER_RAD;
use nalgebra::{Matrix3, Vector3};

/// Largest per-axis σ of a fine attitude accepted as an IRUCAL interval end, arcsec.
const MAX_FIX_SIGMA_ARCSEC: f64 = 120.0;

/// σ floor added to every fine attitude per axis (residual alignment error), arcsec.
const FIX_SIGMA_FLOOR_ARCSEC: f64 = 3.0;

/// What a fine attitude's formal covariance leaves out, added before it is used as an
/// IRUCAL interval end.
#[derive(Clone, Copy, Debug)]
pub(crate) struct FixFloors {
    /// For a FHST-only fix (rad²): a quarter of the FHST1–FHST2 relative alignment covariance.
    pub(crate) fhst_cov_rad2: Matrix3<f64>,
    /// For a fix that needed the Sun, per axis (arcsec): the FSS error that does not average
    /// down (`DeclaredNoise::fss_systematic_arcsec`, default the paper's inherent 0.022°).
    pub(crate) fss_arcsec: f64,
}

/// Half-length of the fine-attitude batches (s): the paper's 10-min batches.
pub(crate) const BATCH_HALF_S: f64 = 300.0;

/// The index of the first frame at or after `t_s` (the last frame when none is).
pub(crate) fn frame_index_at(frames: &[FrameObservations], t_s: f64) -> usize {
    frames
        .partition_point(|f| f.time.seconds() < t_s)
        .min(frames.len().saturating_sub(1))
}

/// Fixes whose attitude fit has a χ² p-value below this are refused ([`batch_fix`]): with
/// ≈ 10⁴ fixes in six months, ≈ 0.01 good fixes refused by chance.
pub(crate) const FIX_MISFIT_P: f64 = 1e-6;

/// Why [`batch_fix`] gives no fix.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum FixRefusal {
    /// Too few frames or vectors, or an axis worse than `MAX_FIX_SIGMA_ARCSEC`.
    NoSolution,
    /// The fit's residuals are impossible under the stated σ (χ² p < [`FIX_MISFIT_P`]).
    Misfit {
        /// χ² of the attitude fit.
        chi2: f64,
        /// Its degrees of freedom.
        dof: usize,
    },
}

/// A fine attitude centred at `t_center_s` from frames within ±`BATCH_HALF_S` restricted to
/// `[lo_s, hi_s]`: FHST-only when the trackers give it, else FHST + FSS (the last value: the fix
/// needed the Sun); with the part of its covariance that is systematic (the floors: the same for fixes of one kind in one attitude).
///
/// The covariance adds what the formal one ignores: `FixFloors::fhst_cov_rad2` for a FHST-only fix
/// (the FHST1–FHST2 relative alignment uncertainty: a fix may follow either tracker's frame),
/// and the FSS's inherent error (`FixFloors::fss_arcsec` per axis) for a fix that needed the
/// Sun, which otherwise would claim arcsec accuracy from hundreds of samples of a sensor
/// whose error is systematic.
#[allow(clippy::too_many_arguments)]
pub(crate) fn batch_fix(
    frames: &[FrameObservations],
    t_center_s: f64,
    lo_s: f64,
    hi_s: f64,
    bias: &Vector3<f64>,
    delta_m: &Matrix3<f64>,
    floors: &FixFloors,
    allow_fss: bool,
) -> Result<(usize, AttitudeFix, Matrix3<f64>, bool), FixRefusal> {
    let lo = frame_index_at(frames, (t_center_s - BATCH_HALF_S).max(lo_s));
    let hi = frame_index_at(frames, (t_center_s + BATCH_HALF_S).min(hi_s)) + 1;
    let center = frame_index_at(frames, t_center_s);
    if hi <= lo + 10 || center < lo || center >= hi {
        return Err(FixRefusal::NoSolution);
    }
    // FHST-only ends are best (the paper's recommendation); when the trackers do not give two
    // non-parallel vectors in the batch (Earth occultation, a single star), fall back to
    // FHST + FSS ends as the paper itself did for some of its intervals.
    let fhst_only = fine_attitude(
        frames,
        lo..hi,
        center,
        bias,
        delta_m,
        AttitudeSensors::FhstOnly,
    );
    let (sol, floor, sun) = match fhst_only {
        Ok(sol) => (sol, floors.fhst_cov_rad2, false),
        Err(_) if !allow_fss => return Err(FixRefusal::NoSolution),
        Err(_) => (
            fine_attitude(
                frames,
                lo..hi,
                center,
                bias,
                delta_m,
                AttitudeSensors::FhstAndFss,
            )
            .map_err(|_| FixRefusal::NoSolution)?,
            Matrix3::identity() * (floors.fss_arcsec / ARCSEC_PER_RAD).powi(2),
            true,
        ),
    };
    // A fix whose own residuals are impossible under its stated σ is not a fix: its stars were
    // carried to the batch centre with a bias the gyro did not have (the OBC's estimate just
    // after a triad switch or a reset, 1.3″/s off for half an hour: 490″ off while claiming
    // 8.6″, `docs/investigations.md`). Its χ² p-value below FIX_MISFIT_P refuses it, and the
    // chain reports it.
    if chi2_sf(sol.chi2, sol.dof as f64) < FIX_MISFIT_P {
        return Err(FixRefusal::Misfit {
            chi2: sol.chi2,
            dof: sol.dof,
        });
    }
    // Floor for systematic errors the formal covariance ignores (residual alignment error).
    let systematic =
        floor + Matrix3::identity() * (FIX_SIGMA_FLOOR_ARCSEC / ARCSEC_PER_RAD).powi(2);
    let cov = sol.cov_acs_rad2 + systematic;
    // A fix is an interval end only if every axis is known to FSS quality or better (the
    // paper's FSS-based ends were 0.022°); a batch with one star and the Sun nearly parallel
    // gives a formally valid but useless attitude.
    let sigma_max_rad = (0..3)
        .map(|i| cov[(i, i)].max(0.0).sqrt())
        .fold(0.0, f64::max);
    if !(sigma_max_rad * ARCSEC_PER_RAD <= MAX_FIX_SIGMA_ARCSEC) {
        return Err(FixRefusal::NoSolution);
    }
    Ok((
        center,
        AttitudeFix {
            m_acs_from_eci: sol.m_acs_from_eci,
            cov_acs_rad2: cov,
        },
        systematic,
        sun,
    ))
}

/// Every frame after `a` up to `b` has a gyro step (none lost to a gap or a bad count).
pub(crate) fn gyro_complete(frames: &[FrameObservations], a: usize, b: usize) -> bool {
    frames
        .get(a + 1..=b)
        .is_some_and(|f| f.iter().all(|f| f.gyro.is_some()))
}

pub(crate) fn steps_between(frames: &[FrameObservations], a: usize, b: usize) -> Vec<GyroStep> {
    frames[a + 1..=b]
        .iter()
        .map(|f| {
            f.gyro.unwrap_or(GyroStep {
                dtheta_acs_rad: Vector3::zeros(),
                dt_s: 0.0,
            })
        })
        .collect()
}
