//! # Gyro batches: every identified star, on a gyro-carried attitude
//!
//! Input of [`crate::calibration::fhst_relative`]. Why: the FHST1–FHST2 relative alignment
//! is limited by each tracker's roll about its boresight, which only star offsets inside the
//! ±4° field reveal. Each tracker follows one star at a time, so most of its stars are not
//! seen at the same time as the other tracker's; the gyro ties them together.
//!
//! A batch is a run of frames with gyro data, no gap over [`MAX_GAP_S`], and one kind of
//! motion, which the telemetry measures, not only the rate-mode flag:
//! * a **hold**: every frame in low rate and turning slower than [`MOTION_RATE_ARCSEC_PER_S`]
//!   (the gyro increment through the flown `G`, the OBC's bias removed), at most
//!   [`HOLD_BATCH_MAX_S`] long. There the gyro's noise (≈ 0.1″) and bias drift are
//!   negligible, and so is its scale/misalignment error (δM × the angle turned) unless the
//!   body creeps (a slew slower than the motion rate, the control settling after a slew:
//!   100–300″ on `gro-early-mission`); a hold that turned more than
//!   [`STILL_ROTATION_ARCSEC`] carries δM as a slew does.
//! * a **slew**: frames in high rate or turning faster than that, at most [`SLEW_BATCH_MAX_S`]
//!   long. The stars cross the field and the flown gyro's scale and misalignment error
//!   δM carries the reference attitude off by `ε(t) = J(t) vec(δM)`, `J` accumulated from the
//!   batch centre ([`BatchStarSample::gyro_scale_partial`]). At a constant rate `ε` grows
//!   linearly, like a bias error, and the batch's drift term takes it; what the drift cannot
//!   take (the accelerations, the turn of the body within the batch) the fit takes with δM
//!   itself: nine global parameters estimated with θ, with the flown `G`'s prior σ
//!   ([`crate::calibration::iru_chain::PRIOR_DM_PPM`]), one δM for every batch.
//!
//! Why the motion and not the flag: a slew flown in LOW rate mode fell inside a 1200-s
//! "hold" batch, tied by the flown gyro through tens of degrees; δM × 40° is 100–300″ of
//! reference error the drift term cannot take, and the FHST1–FHST2 alignment came out
//! 7–14σ wrong (NEES 222; `docs/investigations.md`). Why a hold is cut at the turn rather
//! than given δM partials: it then keeps its stars at the gyro's noise, free of δM. Why it is
//! not cut at a small net rotation (tried: 100″): the settling after every slew then split the
//! main job's holds into 20–50-s pieces, 23 batches instead of 19 and σ of FHST2 4.97 → 5.82″,
//! to avoid a δM error of ≤ 0.3″ that the estimated δM takes anyway. Why a
//! slew's δM is estimated rather than a consider term: with the prior's 3000 ppm a consider
//! term is true but wide (σ of FHST2 up to 48″, 11″ on the standard day, where the stars give 6–8″; on the
//! writer's days), while estimated δM keeps σ true (NEES 1–5) and near the stars' bound,
//! and exactly the 3-parameter fit where no batch turned.
//!
//! The reference attitude of a batch is the FHST-only fine attitude at its centre (else the
//! OBC's) carried to every frame by the gyro with the OBC's bias.

use nalgebra::{Matrix3, SMatrix, Vector3};

use super::observations::{body_to_center, fhst_attitude, FrameObservations};
use crate::calibration::fhst_relative::{BatchStarSample, GyroScalePartial};
use fsw_core::sensor::SensorId;
use fsw_core::units::RAD_PER_ARCSEC;

/// Longest hold batch (s): a 16-min hold is one batch.
pub const HOLD_BATCH_MAX_S: f64 = 1200.0;
/// Longest slew batch (s): 9° at the OBC's 0.05°/s slews. Chosen by the Monte Carlo
/// (`calibration-mc`, 20 seeds, σ of the two roll axes and mean NEES): 20 s → 6.2″, 3.7;
/// 60 s → 5.3″, 3.5; 180 s → 5.0″, 3.2; 400 s → 4.7″, 3.7; 1200 s → 4.3″ but NEES 23 (the
/// gyro's scale and misalignment errors through the slews' accelerations).
pub const SLEW_BATCH_MAX_S: f64 = 180.0;
/// Body rate above which a frame is in motion (″/s), measured by the gyro. Why 15″/s
/// (0.004°/s): holds turn by ≤ 7″/s (control, pulse quantisation: ≤ 0.8″/s in low rate and
/// ≤ 7″/s in high rate on `gro-early-mission` and the ICD writer's days), slews by 0.05–0.4°/s;
/// a ramp's frames below it turn the body by a few tens of arcsec, ≤ 0.1″ of δM error.
pub const MOTION_RATE_ARCSEC_PER_S: f64 = 15.0;
/// Largest gyro rotation from a batch's centre (″) below which the batch's δM partials are
/// left out: δM's prior σ (3000 ppm) times 10″ is 0.03″. Saves their memory (216 bytes a
/// sample) in the still holds, most of the samples.
pub const STILL_ROTATION_ARCSEC: f64 = 10.0;
/// Shortest batch worth a 6-parameter nuisance (s).
const BATCH_MIN_S: f64 = 20.0;
/// A gap in the frames longer than this ends a batch (s).
const MAX_GAP_S: f64 = 5.0;

/// The frame's gyro step through the flown `G` with the bias removed (ACS, rad), if any.
fn step(f: &FrameObservations, bias: &dyn Fn(f64) -> Vector3<f64>) -> Option<Vector3<f64>> {
    f.gyro
        .map(|g| g.dtheta_acs_rad - bias(f.time.seconds()) * g.dt_s)
}

/// Whether the frame belongs to a slew (module doc): high rate, or turning faster than
/// [`MOTION_RATE_ARCSEC_PER_S`].
fn in_motion(f: &FrameObservations, bias: &dyn Fn(f64) -> Vector3<f64>) -> bool {
    f.high_rate
        || f.gyro.zip(step(f, bias)).is_some_and(|(g, s)| {
            g.dt_s > 0.0 && s.norm() > MOTION_RATE_ARCSEC_PER_S * RAD_PER_ARCSEC * g.dt_s
        })
}

/// Batches as frame ranges `[lo, hi)` with whether each is a slew (module doc). `bias_at(t)`
/// is the gyro bias (ACS, rad/s) to remove before the motion is measured, e.g. the OBC's.
#[must_use]
pub fn star_batches(
    frames: &[FrameObservations],
    bias_at: &dyn Fn(f64) -> Vector3<f64>,
) -> Vec<(usize, usize, bool)> {
    let moving: Vec<bool> = frames.iter().map(|f| in_motion(f, bias_at)).collect();
    let mut out = Vec::new();
    let mut lo = 0;
    while lo < frames.len() {
        let t0 = frames[lo].time.seconds();
        let slew = moving[lo];
        let max_s = if slew {
            SLEW_BATCH_MAX_S
        } else {
            HOLD_BATCH_MAX_S
        };
        let mut hi = lo + 1;
        while hi < frames.len() {
            let f = &frames[hi];
            let gap = f.time.seconds() - frames[hi - 1].time.seconds();
            if moving[hi] != slew
                || f.gyro.is_none()
                || !(gap <= MAX_GAP_S)
                || f.time.seconds() - t0 >= max_s
            {
                break;
            }
            hi += 1;
        }
        if frames[hi - 1].time.seconds() - t0 >= BATCH_MIN_S {
            out.push((lo, hi, slew));
        }
        lo = hi;
    }
    out
}

/// `J(k)` of every frame of a slew batch (module doc): the reference attitude's error (rad,
/// body axes at frame k) per unit of `vec(δM)` (column-major), `ε(k) = m_kᵀ Σ_{j∈(c,k]} m_j δM φ_j`
/// forward of the centre `c` and `−m_kᵀ Σ_{j∈(k,c]} m_j δM φ_j` before it, with
/// `m_k = A(c) A(k)ᵀ` (`to_center`) and `φ_j` the gyro step into frame `j`.
fn gyro_scale_partials(
    frames: &[FrameObservations],
    lo: usize,
    center: usize,
    to_center: &[Matrix3<f64>],
    bias: &Vector3<f64>,
) -> Vec<GyroScalePartial> {
    // m (φᵀ ⊗ I₃): δM φ = (φᵀ ⊗ I₃) vec(δM).
    let term = |j: usize| {
        let phi = frames[j]
            .gyro
            .map_or_else(Vector3::zeros, |g| g.dtheta_acs_rad - bias * g.dt_s);
        let m = &to_center[j - lo];
        let mut t = SMatrix::<f64, 3, 9>::zeros();
        for c in 0..3 {
            t.fixed_view_mut::<3, 3>(0, 3 * c).copy_from(&(m * phi[c]));
        }
        t
    };
    let n = to_center.len();
    let mut sums = vec![SMatrix::<f64, 3, 9>::zeros(); n];
    for k in center + 1..lo + n {
        sums[k - lo] = sums[k - 1 - lo] + term(k);
    }
    for k in (lo..center).rev() {
        sums[k - lo] = sums[k + 1 - lo] - term(k + 1);
    }
    sums.iter()
        .zip(to_center)
        .map(|(s, m)| m.transpose() * s)
        .collect()
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
    for (lo, hi, slew) in star_batches(frames, bias_at) {
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
        let to_center = body_to_center(frames, lo..hi, center, &bias, &Matrix3::zeros());
        let mut partials = gyro_scale_partials(frames, lo, center, &to_center, &bias);
        // ‖J‖ is the angle turned from the centre (rad, up to a factor ≤ √3).
        let still = STILL_ROTATION_ARCSEC * RAD_PER_ARCSEC;
        if !slew && partials.iter().all(|j| j.norm() < still) {
            partials.clear();
        }
        // A(k) = (A(c) A(k)ᵀ)ᵀ A(c): the centre attitude carried to frame k by the gyro.
        let att: Vec<Matrix3<f64>> = to_center.iter().map(|m| m.transpose() * a_center).collect();
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
                            gyro_scale_partial: partials.get(k - lo).map(|j| Box::new(*j)),
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

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;
    use crate::calibration::iru::GyroStep;
    use crate::pipeline::observations::RateSwitch;
    use fsw_core::attitude::rotvec_from_rot;
    use fsw_core::raw::TimeTag;

    /// 1-s frames in low rate with the gyro steps `rates` (rad/s, ACS, one per frame).
    fn frames(rates: &[Vector3<f64>]) -> Vec<FrameObservations> {
        rates
            .iter()
            .enumerate()
            .map(|(k, w)| FrameObservations {
                time: TimeTag::from_seconds(1.0e9 + k as f64).unwrap(),
                gyro: Some(GyroStep {
                    dtheta_acs_rad: *w,
                    dt_s: 1.0,
                }),
                high_rate: false,
                iru_backup: false,
                rate_switch: RateSwitch::None,
                gyro_split_var_rad2: 0.0,
                gyro_split_dir_rad: Vector3::zeros(),
                stars: [None, None],
                suns: [None, None],
                temperatures_c: [20.0; 5],
                obc_q_acs_from_eci: None,
                orbit: None,
            })
            .collect()
    }

    /// A hold, a 0.4°/s turn with its ramps flown in LOW rate, a hold: the turn ends the
    /// first hold and is batched as a slew, whatever the rate-mode flag says.
    #[test]
    fn a_low_rate_turn_ends_the_hold() {
        let w = 0.4_f64.to_radians();
        let rates: Vec<Vector3<f64>> = (0..1400)
            .map(|k| {
                let r = match k {
                    600..=609 => w * f64::from(k - 599) / 10.0,
                    610..=689 => w,
                    690..=699 => w * f64::from(700 - k) / 10.0,
                    _ => 0.0,
                };
                Vector3::new(0.0, r, 0.0)
            })
            .collect();
        let f = frames(&rates);
        let zero = |_: f64| Vector3::zeros();
        let b = star_batches(&f, &zero);
        assert_eq!(b, [(0, 600, false), (600, 700, true), (700, 1400, false)]);
        // A slow drift (5″/s, below the motion rate) is a hold, with the δM partials of its
        // turn (`gyro_scale_partials`).
        let slow = frames(&vec![Vector3::new(5.0 * RAD_PER_ARCSEC, 0.0, 0.0); 300]);
        assert_eq!(star_batches(&slow, &zero), [(0, 300, false)]);
    }

    /// `J(k) vec(δM)` is the reference's error when the true gyro is `(I + δM)` times the
    /// flown one, on a turn about two axes with accelerations, both sides of the centre.
    #[test]
    fn gyro_scale_partials_are_the_attitude_error_of_delta_m() {
        let rates: Vec<Vector3<f64>> = (0..180)
            .map(|k| {
                let t = f64::from(k) / 180.0;
                Vector3::new(0.3 * (3.0 * t).sin(), 0.4 * t * t, 0.05).map(f64::to_radians)
            })
            .collect();
        let f = frames(&rates);
        let dm = Matrix3::new(
            1500.0, -800.0, 600.0, -700.0, 1200.0, -900.0, 500.0, -600.0, 1800.0,
        ) * 1e-6;
        let (lo, hi, center) = (0, f.len(), 90);
        let zero = Vector3::zeros();
        let flown = body_to_center(&f, lo..hi, center, &zero, &Matrix3::zeros());
        let truth = body_to_center(&f, lo..hi, center, &zero, &dm);
        let j = gyro_scale_partials(&f, lo, center, &flown, &zero);
        let vec_dm = nalgebra::SVector::<f64, 9>::from_column_slice(dm.as_slice());
        let mut worst: f64 = 0.0;
        for k in [0, 30, 89, 91, 150, 179] {
            // A_true(k) = Rot(ε) A_ref(k) ⇒ Rot(ε) = m_true(k)ᵀ m_flown(k).
            let eps = rotvec_from_rot(&(truth[k].transpose() * flown[k]));
            let lin = j[k] * vec_dm;
            assert!(eps.norm() > 1e-6, "frame {k}: ε {eps:?}");
            worst = worst.max((eps - lin).norm() / eps.norm());
        }
        assert!(worst < 0.02, "relative error of J vec(δM): {worst}");
    }
}
