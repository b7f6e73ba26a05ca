//! # IRUCAL: Davenport/Keat gyro calibration, bias from inertial holds, plan covariance study
//!
//! Why: the paper (§5) calibrated the DRIRU-II misalignment/scale-factor matrix and the
//! high-rate biases from four maneuvers whose end attitudes came from FHST/FSS data, and
//! tracked the bias over six months from inertial holds. The method is Keat (1977) as used at
//! GSFC (Davenport & Welter 1988, Natanson 1998); `docs/algorithms.md` §7, §8, §10.
//!
//! ## Gyro model and unknowns
//! The calibrated increment over a step of `Δt` seconds is
//! `Δθᶜ = (I + ΔM) Δθ − b Δt` (rad, ACS), where `Δθ` is the raw increment already mapped to
//! ACS with the prelaunch `G`. The attitude propagates as `A_{k+1} = Rot(Δθᶜ_k) A_k`
//! (`Ȧ = −[ω×]A`, `fsw_core::attitude::rot`). The unknown correction to the current
//! calibration is `x = [vec(δM); δb]` (12; column-major `vec`, nalgebra's storage), so that
//! `ΔM ← ΔM + δM`, `b ← b + δb`.
//!
//! ## Measurement per interval `[t_a, t_b]`
//! Propagate from the sensor attitude `Aˢ_a` with the current calibration to `Â(t_b)`; the
//! residual `z` is defined by `Aˢ_b = Rot(z) Â(t_b)` (left ACS error, the workspace
//! convention). Linear model `z = S(t_b) x + n` with the recursion
//! `S_{k+1} = Rot(Δθᶜ_k) S_k + Rot(½Δθᶜ_k) [Δθ_kᵀ ⊗ I₃, −Δt_k I₃]`, `S(t_a) = 0` (§7), and
//! `R = P_b + Φ P_a Φᵀ + (σ_v² T + σ_u² T³/3) I`, `Φ = Â_b Â_aᵀ`.
//!
//! Normal equations are accumulated in scaled units (δM in ppm, δb in arcsec/s, z in
//! arcsec), iterated (Gauss–Newton) and checked for rank 12: with fewer than four independent
//! intervals or slews about fewer than three axes the problem is unobservable and an error
//! says which combination is missing.

use nalgebra::{DMatrix, DVector, Matrix3, SMatrix, Vector3};
use serde::Serialize;
use thiserror::Error;

use fsw_core::attitude::{rot, rotvec_from_rot};

use crate::linalg::{spd_inverse, sym_eigen_ascending};
use crate::{ARCSEC_PER_RAD, RAD_PER_ARCSEC};

/// Sensitivity of the end-attitude error to the 12 parameters (rad per unit parameter).
pub type Sensitivity = SMatrix<f64, 3, 12>;

/// Parts per million per unit (scale of the δM states).
pub const PPM: f64 = 1e-6;

/// Names of the 12 parameters, in state order (column-major `vec(δM)`, then `δb`).
pub const PARAMETER_NAMES: [&str; 12] = [
    "dM_xx", "dM_yx", "dM_zx", "dM_xy", "dM_yy", "dM_zy", "dM_xz", "dM_yz", "dM_zz", "db_x",
    "db_y", "db_z",
];

/// One gyro sample interval.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct GyroStep {
    /// Raw angle increment in ACS axes (after the prelaunch `G`), rad.
    pub dtheta_acs_rad: Vector3<f64>,
    /// Duration, s (from the time tags).
    pub dt_s: f64,
}

/// Ground gyro calibration: `Δθᶜ = (I + ΔM) Δθ − b Δt`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct GyroCalibration {
    /// ΔM (unitless; misalignment and scale-factor correction).
    pub delta_m: Matrix3<f64>,
    /// Bias (rad/s, ACS).
    pub bias_acs_rad_per_s: Vector3<f64>,
}

impl Default for GyroCalibration {
    fn default() -> Self {
        Self {
            delta_m: Matrix3::zeros(),
            bias_acs_rad_per_s: Vector3::zeros(),
        }
    }
}

impl GyroCalibration {
    /// Calibrated increment of one step.
    #[must_use]
    pub fn corrected(&self, step: &GyroStep) -> Vector3<f64> {
        (Matrix3::identity() + self.delta_m) * step.dtheta_acs_rad
            - self.bias_acs_rad_per_s * step.dt_s
    }
}

/// A sensor attitude with its covariance.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct AttitudeFix {
    /// Attitude `A = m_acs_from_eci`.
    pub m_acs_from_eci: Matrix3<f64>,
    /// Covariance of the left ACS error δθ (`A_true = Rot(δθ) A`), rad².
    pub cov_acs_rad2: Matrix3<f64>,
}

/// A calibration interval: sensor attitudes at both ends, gyro data in between.
#[derive(Clone, Debug, PartialEq)]
pub struct CalibrationInterval {
    /// Sensor attitude at `t_a`.
    pub start: AttitudeFix,
    /// Sensor attitude at `t_b`.
    pub end: AttitudeFix,
    /// Gyro steps covering `[t_a, t_b]`.
    pub steps: Vec<GyroStep>,
}

/// Farrenkopf gyro noise parameters.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Default)]
pub struct GyroNoise {
    /// Angle random walk σ_v (rad/√s).
    pub sigma_v_rad_per_sqrt_s: f64,
    /// Rate random walk σ_u (rad/s^1.5).
    pub sigma_u_rad_per_s_1p5: f64,
}

impl GyroNoise {
    /// Per-axis variance (rad²) accumulated over `t_s` seconds.
    #[must_use]
    pub fn variance_rad2(&self, t_s: f64) -> f64 {
        let (v, u) = (self.sigma_v_rad_per_sqrt_s, self.sigma_u_rad_per_s_1p5);
        v * v * t_s + u * u * t_s * t_s * t_s / 3.0
    }
}

/// IRUCAL options.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IrucalConfig {
    /// Gyro noise over an interval.
    pub noise: GyroNoise,
    /// Optional prior σ on δM (ppm) and δb (arcsec/s); `None` = data only (rank 12 required).
    pub prior_sigma_ppm_and_arcsec_per_s: Option<(f64, f64)>,
    /// Maximum Gauss–Newton passes.
    pub max_iterations: usize,
    /// Converged when the largest scaled correction (ppm, arcsec/s) is below this.
    pub convergence: f64,
}

impl Default for IrucalConfig {
    fn default() -> Self {
        Self {
            noise: GyroNoise::default(),
            prior_sigma_ppm_and_arcsec_per_s: None,
            max_iterations: 10,
            convergence: 1e-3,
        }
    }
}

/// Why IRUCAL could not produce an answer.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum IruError {
    /// Fewer than four intervals (12 unknowns, 3 equations per interval).
    #[error("IRU calibration needs at least 4 intervals (12 unknowns, 3 equations each), got {got}: add slews about other axes and an inertial hold")]
    TooFewIntervals {
        /// Intervals given.
        got: usize,
    },
    /// An interval has no gyro data or a non-finite/negative value.
    #[error("interval {interval} is invalid ({reason}): fix or drop it")]
    InvalidInterval {
        /// Interval index.
        interval: usize,
        /// What is wrong.
        reason: &'static str,
    },
    /// The normal matrix has rank < 12.
    #[error("IRU calibration is unobservable: rank {rank} of 12 (eigenvalue/max < {threshold:.0e}); weakest combination: {mode}. Add slews about three non-coplanar axes, in both directions and with different durations, plus an inertial hold for the bias")]
    Unobservable {
        /// Numerical rank.
        rank: usize,
        /// Relative threshold.
        threshold: f64,
        /// Weakest parameter combination.
        mode: String,
    },
    /// An end-attitude covariance is not positive definite.
    #[error("interval {interval}: the residual covariance is not positive definite; give end-attitude covariances > 0")]
    BadCovariance {
        /// Interval index.
        interval: usize,
    },
    /// Gauss–Newton did not converge.
    #[error("IRU calibration did not converge in {iterations} passes (last step {last_step:.3e} ppm or arcsec/s): check the gyro data and end attitudes")]
    NotConverged {
        /// Passes made.
        iterations: usize,
        /// Largest scaled step of the last pass.
        last_step: f64,
    },
    /// An inertial hold cannot give a bias.
    #[error("inertial hold {hold}: {reason}")]
    BadHold {
        /// Hold index.
        hold: usize,
        /// What is missing.
        reason: String,
    },
}

/// Propagate an interval with the given calibration: end attitude `Â(t_b)`, sensitivity `S`
/// (rad per unit of the unscaled parameters) and duration.
#[must_use]
pub fn propagate_interval(
    start: &Matrix3<f64>,
    steps: &[GyroStep],
    cal: &GyroCalibration,
) -> (Matrix3<f64>, Sensitivity, f64) {
    let mut a = *start;
    let mut s = Sensitivity::zeros();
    let mut t = 0.0;
    for step in steps {
        let phi = cal.corrected(step);
        let r = rot(&phi);
        let mut b = Sensitivity::zeros();
        for j in 0..3 {
            for i in 0..3 {
                b[(i, 3 * j + i)] = step.dtheta_acs_rad[j];
            }
        }
        for i in 0..3 {
            b[(i, 9 + i)] = -step.dt_s;
        }
        s = r * s + rot(&(phi * 0.5)) * b;
        a = r * a;
        t += step.dt_s;
    }
    (a, s, t)
}

/// Scaling from the scaled states (ppm, arcsec/s) to the unscaled ones (unitless, rad/s).
fn state_scale() -> SMatrix<f64, 12, 12> {
    let mut d = SMatrix::<f64, 12, 12>::zeros();
    for k in 0..9 {
        d[(k, k)] = PPM;
    }
    for k in 9..12 {
        d[(k, k)] = RAD_PER_ARCSEC;
    }
    d
}

/// Residual covariance of an interval (rad²).
fn interval_covariance(
    start: &AttitudeFix,
    end: &AttitudeFix,
    a_hat_start: &Matrix3<f64>,
    a_hat_end: &Matrix3<f64>,
    duration_s: f64,
    noise: &GyroNoise,
) -> Matrix3<f64> {
    let phi = a_hat_end * a_hat_start.transpose();
    end.cov_acs_rad2
        + phi * start.cov_acs_rad2 * phi.transpose()
        + Matrix3::identity() * noise.variance_rad2(duration_s)
}

fn describe_mode(v: &[f64]) -> String {
    let mut idx: Vec<usize> = (0..v.len()).collect();
    idx.sort_by(|&a, &b| v[b].abs().total_cmp(&v[a].abs()));
    idx.iter()
        .take(4)
        .filter(|&&k| v[k].abs() > 0.05)
        .map(|&k| format!("{:+.2}·{}", v[k], PARAMETER_NAMES[k]))
        .collect::<Vec<_>>()
        .join(" ")
}

/// Rank check of a scaled 12×12 normal matrix.
fn check_rank(normal: &DMatrix<f64>) -> Result<(Vec<f64>, usize), IruError> {
    let (values, vectors) = sym_eigen_ascending(normal);
    let max = values.iter().fold(0.0_f64, |a, &v| a.max(v));
    let threshold = 1e-10;
    let deficient = values.iter().filter(|&&v| v <= threshold * max).count();
    if deficient > 0 || max <= 0.0 {
        let weakest: Vec<f64> = vectors.column(0).iter().copied().collect();
        return Err(IruError::Unobservable {
            rank: 12 - deficient.max(usize::from(max <= 0.0) * 12),
            threshold,
            mode: describe_mode(&weakest),
        });
    }
    Ok((values.iter().copied().collect(), 12))
}

/// IRUCAL result.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct IrucalSolution {
    /// Calibration after the solve (input + corrections).
    pub calibration: GyroCalibration,
    /// Correction found: δM (unitless).
    pub delta_m_correction: Matrix3<f64>,
    /// Correction found: δb (rad/s).
    pub bias_correction_acs_rad_per_s: Vector3<f64>,
    /// 1σ of ΔM elements (unitless, row/col as ΔM).
    pub sigma_delta_m: Matrix3<f64>,
    /// 1σ of the bias (rad/s).
    pub sigma_bias_acs_rad_per_s: Vector3<f64>,
    /// Covariance of the scaled states (ppm², (arcsec/s)²), order [`PARAMETER_NAMES`].
    pub covariance_scaled: DMatrix<f64>,
    /// Eigenvalues of the scaled data normal matrix (ascending).
    pub normal_eigenvalues_scaled: Vec<f64>,
    /// Residual norm per interval before calibration (arcsec).
    pub residual_before_arcsec: Vec<f64>,
    /// Residual norm per interval after calibration (arcsec).
    pub residual_after_arcsec: Vec<f64>,
    /// χ² of the residuals at the solution (3 per interval, minus 12 without a prior).
    pub chi2: f64,
    /// Gauss–Newton passes.
    pub iterations: usize,
}

/// The covariance of the solution (the inverse of `normal`) and its 1σ of δM and of the
/// bias; `Unobservable` with `mode` when `normal` is singular.
fn covariance(
    normal: &DMatrix<f64>,
    mode: &str,
) -> Result<(DMatrix<f64>, Matrix3<f64>, Vector3<f64>), IruError> {
    let cov = spd_inverse(normal).ok_or_else(|| IruError::Unobservable {
        rank: 0,
        threshold: 0.0,
        mode: mode.into(),
    })?;
    let (sigma_delta_m, sigma_bias) = sigmas_from_cov(&cov);
    Ok((cov, sigma_delta_m, sigma_bias))
}

fn sigmas_from_cov(cov: &DMatrix<f64>) -> (Matrix3<f64>, Vector3<f64>) {
    let sd = |k: usize| cov[(k, k)].max(0.0).sqrt();
    let sigma_m = Matrix3::from_fn(|i, j| sd(3 * j + i) * PPM);
    let sigma_b = Vector3::from_fn(|i, _| sd(9 + i) * RAD_PER_ARCSEC);
    (sigma_m, sigma_b)
}

/// Run IRUCAL from `initial` (see the module doc).
///
/// # Errors
/// [`IruError`] when there are too few or invalid intervals, the problem has rank < 12, or
/// the iteration does not converge.
pub fn irucal(
    intervals: &[CalibrationInterval],
    initial: &GyroCalibration,
    cfg: &IrucalConfig,
) -> Result<IrucalSolution, IruError> {
    if intervals.len() < 4 && cfg.prior_sigma_ppm_and_arcsec_per_s.is_none() {
        return Err(IruError::TooFewIntervals {
            got: intervals.len(),
        });
    }
    for (interval, iv) in intervals.iter().enumerate() {
        if iv.steps.is_empty() {
            return Err(IruError::InvalidInterval {
                interval,
                reason: "no gyro steps",
            });
        }
        if iv.steps.iter().any(|s| {
            !(s.dt_s.is_finite() && s.dt_s >= 0.0)
                || s.dtheta_acs_rad.iter().any(|x| !x.is_finite())
        }) {
            return Err(IruError::InvalidInterval {
                interval,
                reason: "non-finite or negative gyro step",
            });
        }
    }
    let d = state_scale();
    let mut prior_info = DMatrix::zeros(12, 12);
    if let Some((sm, sb)) = cfg.prior_sigma_ppm_and_arcsec_per_s {
        for k in 0..12 {
            let s = if k < 9 { sm } else { sb };
            prior_info[(k, k)] = 1.0 / (s * s);
        }
    }
    let mut cal = *initial;
    let mut x_total = DVector::<f64>::zeros(12);
    let mut residual_before = Vec::new();
    let mut last_step = f64::INFINITY;
    let mut iterations = 0;
    loop {
        let mut normal = DMatrix::zeros(12, 12);
        let mut rhs = DVector::zeros(12);
        let mut chi2 = 0.0;
        let mut residuals = Vec::with_capacity(intervals.len());
        for (interval, iv) in intervals.iter().enumerate() {
            let (a_end, s, t) = propagate_interval(&iv.start.m_acs_from_eci, &iv.steps, &cal);
            let z_arcsec =
                rotvec_from_rot(&(iv.end.m_acs_from_eci * a_end.transpose())) * ARCSEC_PER_RAD;
            residuals.push(z_arcsec.norm());
            let r_rad2 = interval_covariance(
                &iv.start,
                &iv.end,
                &iv.start.m_acs_from_eci,
                &a_end,
                t,
                &cfg.noise,
            );
            let r_arcsec2 = r_rad2 * (ARCSEC_PER_RAD * ARCSEC_PER_RAD);
            let w = r_arcsec2
                .try_inverse()
                .filter(|w| w.iter().all(|x| x.is_finite()));
            let Some(w) = w else {
                return Err(IruError::BadCovariance { interval });
            };
            let f = s * d * ARCSEC_PER_RAD;
            let ft_w = f.transpose() * w;
            let nf = ft_w * f;
            let g = ft_w * z_arcsec;
            for r in 0..12 {
                rhs[r] += g[r];
                for c in 0..12 {
                    normal[(r, c)] += nf[(r, c)];
                }
            }
            chi2 += z_arcsec.dot(&(w * z_arcsec));
        }
        if residual_before.is_empty() {
            residual_before = residuals.clone();
        }
        let total = &normal + &prior_info;
        if cfg.prior_sigma_ppm_and_arcsec_per_s.is_none() {
            check_rank(&normal)?;
        }
        let converged = iterations > 0 && last_step < cfg.convergence;
        if converged || iterations >= cfg.max_iterations {
            if !converged {
                return Err(IruError::NotConverged {
                    iterations,
                    last_step,
                });
            }
            let (cov, sigma_delta_m, sigma_bias) = covariance(&total, "singular normal matrix")?;
            let (values, _) = sym_eigen_ascending(&normal);
            return Ok(IrucalSolution {
                calibration: cal,
                delta_m_correction: cal.delta_m - initial.delta_m,
                bias_correction_acs_rad_per_s: cal.bias_acs_rad_per_s - initial.bias_acs_rad_per_s,
                sigma_delta_m,
                sigma_bias_acs_rad_per_s: sigma_bias,
                covariance_scaled: cov,
                normal_eigenvalues_scaled: values.iter().copied().collect(),
                residual_before_arcsec: residual_before,
                residual_after_arcsec: residuals,
                chi2,
                iterations,
            });
        }
        let rhs_total = rhs - &prior_info * &x_total;
        let chol =
            ((&total + total.transpose()) * 0.5)
                .cholesky()
                .ok_or(IruError::Unobservable {
                    rank: 0,
                    threshold: 0.0,
                    mode: "singular normal matrix".into(),
                })?;
        let delta = chol.solve(&rhs_total);
        last_step = delta.amax();
        x_total += &delta;
        for j in 0..3 {
            for i in 0..3 {
                cal.delta_m[(i, j)] += delta[3 * j + i] * PPM;
            }
        }
        for i in 0..3 {
            cal.bias_acs_rad_per_s[i] += delta[9 + i] * RAD_PER_ARCSEC;
        }
        iterations += 1;
    }
}

/// A planned calibration maneuver for the covariance study.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct PlannedManeuver {
    /// Rotation axis (ACS, unit).
    pub axis_acs: Vector3<f64>,
    /// Signed rotation angle (rad).
    pub angle_rad: f64,
    /// Interval duration (s); the slew is at constant rate over the whole interval.
    pub duration_s: f64,
    /// Covariance of the start attitude error (ACS at the start, rad²).
    pub cov_start_acs_rad2: Matrix3<f64>,
    /// Covariance of the end attitude error (ACS at the end, rad²).
    pub cov_end_acs_rad2: Matrix3<f64>,
}

impl PlannedManeuver {
    /// Maneuver with isotropic end-attitude errors of `sigma_start_rad`, `sigma_end_rad` per axis.
    #[must_use]
    pub fn isotropic(
        axis_acs: Vector3<f64>,
        angle_rad: f64,
        duration_s: f64,
        sigma_start_rad: f64,
        sigma_end_rad: f64,
    ) -> Self {
        Self {
            axis_acs,
            angle_rad,
            duration_s,
            cov_start_acs_rad2: Matrix3::identity() * sigma_start_rad * sigma_start_rad,
            cov_end_acs_rad2: Matrix3::identity() * sigma_end_rad * sigma_end_rad,
        }
    }
}

/// Predicted accuracy of a maneuver plan.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PlanStudy {
    /// Predicted 1σ of ΔM (unitless).
    pub sigma_delta_m: Matrix3<f64>,
    /// Predicted 1σ of the bias (rad/s).
    pub sigma_bias_acs_rad_per_s: Vector3<f64>,
    /// Scaled covariance (ppm², (arcsec/s)²).
    pub covariance_scaled: DMatrix<f64>,
}

/// Gyro steps of a constant-rate slew (`step_s` seconds each).
#[must_use]
pub fn slew_steps(
    axis_acs: &Vector3<f64>,
    angle_rad: f64,
    duration_s: f64,
    step_s: f64,
) -> Vec<GyroStep> {
    let n = (duration_s / step_s).ceil().max(1.0) as usize;
    let dt = duration_s / n as f64;
    let d = axis_acs.normalize() * (angle_rad / n as f64);
    vec![
        GyroStep {
            dtheta_acs_rad: d,
            dt_s: dt
        };
        n
    ]
}

/// Covariance study of a maneuver plan (no data): the Fisher information of the 12
/// parameters from the S-recursion along the planned (nominal) motion, `R` from the end
/// attitude covariances and the gyro noise (§7, §10). The result does not depend on the
/// absolute attitude: each maneuver starts at the identity and its covariances are in ACS.
///
/// # Errors
/// [`IruError::Unobservable`] when the plan cannot determine all 12 parameters.
pub fn study_plan(
    plan: &[PlannedManeuver],
    noise: &GyroNoise,
    step_s: f64,
) -> Result<PlanStudy, IruError> {
    if plan.len() < 4 {
        return Err(IruError::TooFewIntervals { got: plan.len() });
    }
    let d = state_scale();
    let mut normal = DMatrix::zeros(12, 12);
    for (interval, m) in plan.iter().enumerate() {
        let steps = slew_steps(&m.axis_acs, m.angle_rad, m.duration_s, step_s);
        let (a_end, s, t) =
            propagate_interval(&Matrix3::identity(), &steps, &GyroCalibration::default());
        let fix = |cov: &Matrix3<f64>| AttitudeFix {
            m_acs_from_eci: Matrix3::identity(),
            cov_acs_rad2: *cov,
        };
        let r = interval_covariance(
            &fix(&m.cov_start_acs_rad2),
            &fix(&m.cov_end_acs_rad2),
            &Matrix3::identity(),
            &a_end,
            t,
            noise,
        ) * (ARCSEC_PER_RAD * ARCSEC_PER_RAD);
        let Some(w) = r.try_inverse() else {
            return Err(IruError::BadCovariance { interval });
        };
        let f = s * d * ARCSEC_PER_RAD;
        let nf = f.transpose() * w * f;
        for rr in 0..12 {
            for c in 0..12 {
                normal[(rr, c)] += nf[(rr, c)];
            }
        }
    }
    check_rank(&normal)?;
    let (cov, sigma_delta_m, sigma_bias) = covariance(&normal, "singular")?;
    Ok(PlanStudy {
        sigma_delta_m,
        sigma_bias_acs_rad_per_s: sigma_bias,
        covariance_scaled: cov,
    })
}

/// A timed sensor attitude during an inertial hold.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct TimedFix {
    /// Time since the start of the hold (s).
    pub t_s: f64,
    /// Attitude `A = m_acs_from_eci`.
    pub m_acs_from_eci: Matrix3<f64>,
    /// 1σ per ACS axis (rad).
    pub sigma_acs_rad: Vector3<f64>,
}

/// An inertial hold: sensor fixes and the gyro steps from `t = 0` (first fix) onward.
#[derive(Clone, Debug, PartialEq)]
pub struct InertialHold {
    /// Sensor attitudes, in time order; the first is at `t = 0`.
    pub fixes: Vec<TimedFix>,
    /// Gyro steps from `t = 0` covering the last fix.
    pub steps: Vec<GyroStep>,
}

/// Bias estimate from one hold.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct BiasEstimate {
    /// Mid-time of the fixes (s, same origin as the caller's hold time).
    pub t_mid_s: f64,
    /// Bias correction δb found (rad/s): `b ← b + δb`.
    pub delta_bias_acs_rad_per_s: Vector3<f64>,
    /// Total bias after the correction (rad/s).
    pub bias_acs_rad_per_s: Vector3<f64>,
    /// 1σ (rad/s).
    pub sigma_acs_rad_per_s: Vector3<f64>,
    /// Number of fixes used.
    pub fixes: usize,
}

/// Bias from an inertial hold (§8): `z_j = rotvec(Aˢ_j Â(t_j)ᵀ) = z₀ − δb t_j + n_j`, a
/// weighted straight-line fit per axis; `var(δb) = 1/Σ wⱼ(tⱼ − t̄)² + σ_v²/T`.
///
/// Valid only for a truly inertial hold: a rate `ω̄` leaks `ΔM ω̄` into the bias.
///
/// # Errors
/// [`IruError::BadHold`] with fewer than two fixes, zero duration, unsorted fixes or gyro data
/// that do not reach the last fix.
pub fn bias_from_hold(
    hold: &InertialHold,
    cal: &GyroCalibration,
    noise: &GyroNoise,
    index: usize,
) -> Result<BiasEstimate, IruError> {
    let bad = |reason: &str| IruError::BadHold {
        hold: index,
        reason: reason.to_owned(),
    };
    let (Some(first), Some(last)) = (hold.fixes.first(), hold.fixes.last()) else {
        return Err(bad(
            "no fixes: need ≥ 2 sensor attitudes spread over the hold",
        ));
    };
    if hold.fixes.len() < 2 || last.t_s - first.t_s <= 0.0 {
        return Err(bad("need ≥ 2 sensor attitudes at different times"));
    }
    if hold.fixes.windows(2).any(|w| w[1].t_s < w[0].t_s) {
        return Err(bad("fixes are not in time order"));
    }
    let mut a = first.m_acs_from_eci;
    let mut t = first.t_s;
    let mut steps = hold.steps.iter();
    let mut samples: Vec<(f64, Vector3<f64>, Vector3<f64>)> = Vec::with_capacity(hold.fixes.len());
    for fix in &hold.fixes {
        while t < fix.t_s - 1e-9 {
            let Some(step) = steps.next() else {
                return Err(bad(
                    "gyro data end before the last fix: supply steps covering the hold",
                ));
            };
            a = rot(&cal.corrected(step)) * a;
            t += step.dt_s;
        }
        let z = rotvec_from_rot(&(fix.m_acs_from_eci * a.transpose()));
        samples.push((fix.t_s, z, fix.sigma_acs_rad));
    }
    let duration = last.t_s - first.t_s;
    let mut delta = Vector3::zeros();
    let mut sigma = Vector3::zeros();
    for k in 0..3 {
        let w: Vec<f64> = samples.iter().map(|s| 1.0 / (s.2[k] * s.2[k])).collect();
        let sw: f64 = w.iter().sum();
        let t_bar = samples.iter().zip(&w).map(|(s, w)| w * s.0).sum::<f64>() / sw;
        let z_bar = samples.iter().zip(&w).map(|(s, w)| w * s.1[k]).sum::<f64>() / sw;
        let stt: f64 = samples
            .iter()
            .zip(&w)
            .map(|(s, w)| w * (s.0 - t_bar).powi(2))
            .sum();
        let stz: f64 = samples
            .iter()
            .zip(&w)
            .map(|(s, w)| w * (s.0 - t_bar) * (s.1[k] - z_bar))
            .sum();
        if !(stt > 0.0 && stt.is_finite()) {
            return Err(bad("fix σ must be finite and > 0"));
        }
        delta[k] = -stz / stt;
        let sv = noise.sigma_v_rad_per_sqrt_s;
        sigma[k] = (1.0 / stt + sv * sv / duration).sqrt();
    }
    Ok(BiasEstimate {
        t_mid_s: 0.5 * (first.t_s + last.t_s),
        delta_bias_acs_rad_per_s: delta,
        bias_acs_rad_per_s: cal.bias_acs_rad_per_s + delta,
        sigma_acs_rad_per_s: sigma,
        fixes: samples.len(),
    })
}

/// Bias history from a sequence of inertial holds (paper §5: bias over 1991-04-09..10-27).
///
/// # Errors
/// The first [`IruError::BadHold`] met.
pub fn bias_history(
    holds: &[InertialHold],
    cal: &GyroCalibration,
    noise: &GyroNoise,
) -> Result<Vec<BiasEstimate>, IruError> {
    holds
        .iter()
        .enumerate()
        .map(|(i, h)| bias_from_hold(h, cal, noise, i))
        .collect()
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;
    use crate::synth::Rng;
    use crate::RAD_PER_DEG;

    struct Truth {
        delta_m: Matrix3<f64>,
        bias_rad_per_s: Vector3<f64>,
    }

    fn truth() -> Truth {
        Truth {
            delta_m: Matrix3::new(
                300e-6, 400e-6, -200e-6, -500e-6, -250e-6, 100e-6, -550e-6, 350e-6, 150e-6,
            ),
            // paper's primary high-rate biases, deg/s → rad/s
            bias_rad_per_s: Vector3::new(1.66e-4, 0.99e-4, 1.41e-4) * RAD_PER_DEG,
        }
    }

    /// Simulate one interval: constant-rate slew, 1-s steps, raw increments that the true
    /// calibration maps to the true motion, angle noise σ_v, end fixes with σ per axis.
    fn simulate(
        rng: &mut Rng,
        truth: &Truth,
        axis: Vector3<f64>,
        angle_deg: f64,
        duration_s: f64,
        fix_sigma_rad: f64,
        sigma_v: f64,
    ) -> CalibrationInterval {
        let true_steps = slew_steps(&axis, angle_deg * RAD_PER_DEG, duration_s, 1.0);
        let mut a = rng.rotation();
        let a0 = a;
        let inv = (Matrix3::identity() + truth.delta_m).try_inverse().unwrap();
        let mut steps = Vec::with_capacity(true_steps.len());
        for s in &true_steps {
            a = rot(&s.dtheta_acs_rad) * a;
            let raw = inv * (s.dtheta_acs_rad + truth.bias_rad_per_s * s.dt_s)
                + rng.normal3() * (sigma_v * s.dt_s.sqrt());
            steps.push(GyroStep {
                dtheta_acs_rad: raw,
                dt_s: s.dt_s,
            });
        }
        let cov = Matrix3::identity() * fix_sigma_rad * fix_sigma_rad;
        let mut fix = |m: Matrix3<f64>| AttitudeFix {
            m_acs_from_eci: rot(&(rng.normal3() * fix_sigma_rad)) * m,
            cov_acs_rad2: cov,
        };
        let start = fix(a0);
        let end = fix(a);
        CalibrationInterval { start, end, steps }
    }

    fn plan() -> Vec<(Vector3<f64>, f64, f64)> {
        vec![
            (Vector3::x(), 60.0, 1140.0),
            (Vector3::z(), -28.0, 900.0),
            (Vector3::y(), 31.0, 900.0),
            (Vector3::y(), -60.0, 1200.0),
            (Vector3::x(), -45.0, 600.0),
            (Vector3::z(), 40.0, 600.0),
            (Vector3::x(), 0.0, 1800.0),
        ]
    }

    /// Synthetic gyro data with a known ΔM (≈500 ppm) and the paper's biases: all 12
    /// parameters are recovered within 3σ (the brief's criterion), and the residuals drop to
    /// the end-attitude noise.
    #[test]
    fn val_irucal_recovers_misalignment_and_bias() {
        let tr = truth();
        let mut rng = Rng::new(2024);
        let sigma_fix = 10.0 * RAD_PER_ARCSEC;
        let noise = GyroNoise {
            sigma_v_rad_per_sqrt_s: 1e-7,
            sigma_u_rad_per_s_1p5: 0.0,
        };
        let intervals: Vec<_> = plan()
            .iter()
            .map(|&(ax, ang, dur)| {
                simulate(
                    &mut rng,
                    &tr,
                    ax,
                    ang,
                    dur,
                    sigma_fix,
                    noise.sigma_v_rad_per_sqrt_s,
                )
            })
            .collect();
        let cfg = IrucalConfig {
            noise,
            ..IrucalConfig::default()
        };
        let sol = irucal(&intervals, &GyroCalibration::default(), &cfg).unwrap();
        for j in 0..3 {
            for i in 0..3 {
                let err = sol.calibration.delta_m[(i, j)] - tr.delta_m[(i, j)];
                assert!(
                    err.abs() < 3.0 * sol.sigma_delta_m[(i, j)],
                    "ΔM[{i}][{j}] error {err:e} σ {:e}",
                    sol.sigma_delta_m[(i, j)]
                );
            }
            let err = sol.calibration.bias_acs_rad_per_s[j] - tr.bias_rad_per_s[j];
            assert!(
                err.abs() < 3.0 * sol.sigma_bias_acs_rad_per_s[j],
                "bias[{j}] error {err:e}"
            );
        }
        assert!(sol.residual_before_arcsec.iter().any(|&r| r > 300.0));
        assert!(
            sol.residual_after_arcsec.iter().all(|&r| r < 80.0),
            "{:?}",
            sol.residual_after_arcsec
        );
        assert!(sol.iterations <= 5);

        // The covariance study of the same plan predicts the same σ (nominal vs actual motion,
        // 2 % tolerance for the ΔM-induced difference of the propagated path).
        let planned: Vec<PlannedManeuver> = plan()
            .iter()
            .map(|&(ax, ang, dur)| {
                PlannedManeuver::isotropic(ax, ang * RAD_PER_DEG, dur, sigma_fix, sigma_fix)
            })
            .collect();
        let study = study_plan(&planned, &noise, 1.0).unwrap();
        for j in 0..3 {
            for i in 0..3 {
                let r = study.sigma_delta_m[(i, j)] / sol.sigma_delta_m[(i, j)];
                assert!((r - 1.0).abs() < 0.02, "σ ratio {r}");
            }
        }
    }

    #[test]
    fn irucal_reports_unobservable_plans() {
        let tr = truth();
        let mut rng = Rng::new(1);
        let s = 10.0 * RAD_PER_ARCSEC;
        let only_x: Vec<_> = [60.0, -30.0, 45.0, 0.0]
            .iter()
            .map(|&ang| simulate(&mut rng, &tr, Vector3::x(), ang, 600.0, s, 0.0))
            .collect();
        let err = irucal(
            &only_x,
            &GyroCalibration::default(),
            &IrucalConfig::default(),
        )
        .unwrap_err();
        assert!(matches!(err, IruError::Unobservable { .. }), "{err}");
        assert!(err.to_string().contains("three non-coplanar axes"));
        assert!(matches!(
            irucal(
                &only_x[..3],
                &GyroCalibration::default(),
                &IrucalConfig::default()
            ),
            Err(IruError::TooFewIntervals { got: 3 })
        ));
    }

    /// One-hour hold, a fix every 10 s at 10″: the bias error is found within 3σ and σ matches
    /// the textbook two-parameter fit `√(12σ²/(N T²))` (5e-4 ″/s) to 2 %.
    #[test]
    fn val_bias_from_inertial_holds() {
        let mut rng = Rng::new(77);
        let sigma_fix = 10.0 * RAD_PER_ARCSEC;
        let cal = GyroCalibration::default();
        let mut holds = Vec::new();
        let biases: Vec<Vector3<f64>> = (0..3)
            .map(|k| Vector3::new(0.6, 0.36, 0.5 + 0.1 * f64::from(k)) * RAD_PER_ARCSEC)
            .collect();
        for b in &biases {
            let a0 = rng.rotation();
            let steps: Vec<GyroStep> = (0..3600)
                .map(|_| GyroStep {
                    dtheta_acs_rad: *b,
                    dt_s: 1.0,
                })
                .collect();
            // true body is inertial; raw gyro reads the bias
            let fixes = (0..=360)
                .map(|j| TimedFix {
                    t_s: f64::from(j) * 10.0,
                    m_acs_from_eci: rot(&(rng.normal3() * sigma_fix)) * a0,
                    sigma_acs_rad: Vector3::repeat(sigma_fix),
                })
                .collect();
            holds.push(InertialHold { fixes, steps });
        }
        let history = bias_history(&holds, &cal, &GyroNoise::default()).unwrap();
        let expected_sigma = (12.0 * sigma_fix * sigma_fix / (361.0 * 3600.0 * 3600.0)).sqrt();
        for (est, b) in history.iter().zip(&biases) {
            for k in 0..3 {
                let err = est.bias_acs_rad_per_s[k] - b[k];
                assert!(
                    err.abs() < 3.0 * est.sigma_acs_rad_per_s[k],
                    "axis {k}: {err:e}"
                );
                assert!((est.sigma_acs_rad_per_s[k] / expected_sigma - 1.0).abs() < 0.02);
            }
        }
        let short = InertialHold {
            fixes: holds[0].fixes.clone(),
            steps: holds[0].steps[..100].to_vec(),
        };
        assert!(matches!(
            bias_from_hold(&short, &cal, &GyroNoise::default(), 0),
            Err(IruError::BadHold { .. })
        ));
    }
}
