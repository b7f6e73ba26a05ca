//! # Attitude control: inertial hold and rate-limited eigen-axis slews
//!
//! One law serves both modes; the mode only decides the IRU rate mode and when a slew ends.
//!
//! ## Equations
//!
//! * Attitude error to the target: `A_target = Rot(θ_e) Â`, i.e.
//!   `θ_e = rotvec(q_target ⊗ q̂⁻¹)` (ACS, rad). Rotating the body at `ω ∥ θ_e` for `|θ_e|/|ω|`
//!   seconds reaches the target (`Ȧ = −[ω×]A` ⇒ `A(t+τ) = Rot(ωτ) A(t)`): an eigen-axis slew.
//! * Commanded rate along `ê = θ_e/|θ_e|` (a saturated quaternion-feedback PD):
//!   `ω_c = ê · min(ω_max, √(2 α_d |θ_e|), k_θ |θ_e|)` with
//!   - `ω_max` = table `slew_rate_limit_rad_per_s`;
//!   - `α_d = DECELERATION_MARGIN · τ_max / J_max`: the square-root profile brakes at half
//!     the weakest axis's acceleration, so the wheels can always stop the slew without
//!     overshoot;
//!   - `k_θ = ω_n / (2ζ)` (table bandwidth and damping).
//! * Torque: `τ = J · k_ω (ω_c − ω̂) + ω̂ × J ω̂`, `k_ω = 2ζω_n`; for small errors
//!   `τ = J(ω_n² θ_e − 2ζω_n ω̂)`, the PD with natural frequency `ω_n` and damping `ζ`.
//! * Limit: if any axis exceeds `τ_max` (table `torque_limit_nm`), the whole vector is scaled
//!   down, so its direction (and the eigen axis) is kept.
//!
//! ## Modes and the IRU rate mode (as on GRO)
//! * [`ControlMode::Hold`]: inertial hold at the target; `high_rate_iru = false`.
//! * [`ControlMode::Slew`]: `high_rate_iru = true` until `|θ_e| < slew_complete_rad` and
//!   `|ω̂| < slew_complete_rad · ω_n`; then the controller switches itself to Hold at the
//!   same target and reports `slew_complete` once.
//!
//! Deterministic, allocation-free, constant work per call (two `sqrt`, one rotation vector).
//!
//! Sources: the paper gives the IRU rate modes (0.8″/pulse for maneuvers, 0.05″/pulse for
//! inertial pointing) and the calibration maneuvers; the control law is a project choice (not
//! in the paper): the quaternion-feedback eigen-axis slew of Wie, Weiss & Arapostathis
//! (JGCD 12(3), 1989) with a rate limit.

use crate::attitude::Quat;
use crate::tables::types::FilterTable;
use nalgebra::{Matrix3, Vector3};

/// Fraction of the weakest axis's torque-limited acceleration used to brake a slew.
/// Project choice (not in the paper): the wheels can always stop the slew without overshoot.
pub const DECELERATION_MARGIN: f64 = 0.5;
/// Slew completion rate threshold, as a multiple of `slew_complete_rad · ω_n` (rad/s).
/// Project choice (not in the paper): rate and angle thresholds of one time constant.
pub const SLEW_COMPLETE_RATE_FACTOR: f64 = 1.0;

/// Control mode.
/// Paper: GRO holds inertial attitudes and maneuvers between them; codes docs/icd.md §3.2.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ControlMode {
    /// Inertial hold at the target.
    /// Paper: low-rate IRU mode for inertial pointing.
    #[default]
    Hold,
    /// Rate-limited eigen-axis slew to the target.
    /// Paper: high-rate IRU mode for maneuvers; eigen-axis law per the module docs.
    Slew,
}

/// Why a command or a step was refused.
/// Project choice (not in the paper): errors instead of panics in the flight core.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ControlError {
    /// Target quaternion not finite or not near unit norm.
    /// Project choice (not in the paper): NaN input is refused.
    InvalidTarget,
    /// Attitude or rate estimate not finite; no torque computed.
    /// Project choice (not in the paper): NaN input is refused.
    InvalidEstimate,
    /// Table values unusable (non-positive inertia, limits, gains).
    /// docs/tables.md (filter table: inertia, limits, gains).
    InvalidTable,
}

/// One control cycle's output.
/// Project choice (not in the paper); telemetry docs/icd.md §3.2.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ControlOutput {
    /// Wheel torque command, ACS, N·m, each axis within ±`torque_limit_nm`.
    /// docs/icd.md §3.2 (offset 108); limit from docs/tables.md (filter table).
    pub torque_acs_nm: Vector3<f64>,
    /// Command the IRU high-rate mode for the next interval.
    /// Paper: high rate (0.8″/pulse) in maneuvers, low rate (0.05″/pulse) inertial.
    pub high_rate_iru: bool,
    /// Mode after this step.
    /// docs/icd.md §3.2 (offset 105).
    pub mode: ControlMode,
    /// Attitude error to the target `θ_e` (ACS, rad).
    /// Error convention of algorithms.md §1 (`Rot(θ_e)` on the left).
    pub attitude_error_rad: Vector3<f64>,
    /// Commanded body rate (ACS, rad/s).
    /// Project choice (not in the paper): see the module docs.
    pub rate_cmd_rad_per_s: Vector3<f64>,
    /// The torque was scaled down to the limit.
    /// Project choice (not in the paper): direction-preserving limit.
    pub torque_limited: bool,
    /// A slew completed in this step (mode is now Hold).
    /// docs/icd.md §3.3 (event 0x0602).
    pub slew_complete: bool,
    /// The step could not compute a torque (zero commanded, mode unchanged).
    /// Project choice (not in the paper): a fault commands zero torque.
    pub fault: Option<ControlError>,
}

#[cfg(feature = "defmt")]
impl defmt::Format for ControlOutput {
    fn format(&self, f: defmt::Formatter) {
        defmt::write!(
            f,
            "ControlOutput {{ torque: {}, high_rate: {}, mode: {}, err: {}, limited: {}, done: {}, fault: {} }}",
            [self.torque_acs_nm.x, self.torque_acs_nm.y, self.torque_acs_nm.z],
            self.high_rate_iru,
            self.mode,
            [
                self.attitude_error_rad.x,
                self.attitude_error_rad.y,
                self.attitude_error_rad.z
            ],
            self.torque_limited,
            self.slew_complete,
            self.fault
        );
    }
}

/// The attitude controller.
/// Project choice (not in the paper): the paper does not describe the OBC control law.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Controller {
    mode: ControlMode,
    target: Quat,
}

impl Default for Controller {
    fn default() -> Self {
        Self::new()
    }
}

fn valid_target(q: &Quat) -> Option<Quat> {
    let n = q.norm();
    (q.is_finite() && (n - 1.0).abs() < 1e-3).then(|| q.normalized())
}

impl Controller {
    /// Hold at the identity attitude until told otherwise.
    /// Project choice (not in the paper): a defined state before the first command.
    #[must_use]
    pub const fn new() -> Self {
        Self {
            mode: ControlMode::Hold,
            target: Quat::IDENTITY,
        }
    }

    /// Current mode.
    /// docs/icd.md §3.2 (control mode).
    #[must_use]
    pub const fn mode(&self) -> ControlMode {
        self.mode
    }

    /// Current target (ACS from ECI).
    /// Convention of algorithms.md §1.
    #[must_use]
    pub const fn target(&self) -> Quat {
        self.target
    }

    /// Inertial hold at `target`.
    /// Paper: inertial pointing between maneuvers.
    ///
    /// # Errors
    /// [`ControlError::InvalidTarget`] (mode and target unchanged).
    pub fn hold(&mut self, target: &Quat) -> Result<(), ControlError> {
        self.target = valid_target(target).ok_or(ControlError::InvalidTarget)?;
        self.mode = ControlMode::Hold;
        Ok(())
    }

    /// Slew to `target`, then hold there.
    /// Paper: calibration maneuvers (X 60°, Z −28°, Y 31°, Y −60°).
    ///
    /// # Errors
    /// [`ControlError::InvalidTarget`] (mode and target unchanged).
    pub fn slew_to(&mut self, target: &Quat) -> Result<(), ControlError> {
        self.target = valid_target(target).ok_or(ControlError::InvalidTarget)?;
        self.mode = ControlMode::Slew;
        Ok(())
    }

    /// One control cycle from the attitude estimate and the bias-corrected rate.
    /// Project choice (not in the paper): PD law of the module docs.
    ///
    /// On invalid input ([`ControlError::InvalidEstimate`], [`ControlError::InvalidTable`])
    /// the output has zero torque, `fault` set, and the mode is unchanged.
    pub fn update(
        &mut self,
        q_est: &Quat,
        rate_est_rad_per_s: &Vector3<f64>,
        table: &FilterTable,
    ) -> ControlOutput {
        match self.compute(q_est, rate_est_rad_per_s, table) {
            Ok(out) => out,
            Err(e) => ControlOutput {
                high_rate_iru: self.mode == ControlMode::Slew,
                mode: self.mode,
                fault: Some(e),
                ..ControlOutput::default()
            },
        }
    }

    fn compute(
        &mut self,
        q_est: &Quat,
        rate_est_rad_per_s: &Vector3<f64>,
        table: &FilterTable,
    ) -> Result<ControlOutput, ControlError> {
        let qn = q_est.norm();
        let inputs_ok = q_est.is_finite()
            && (0.5..2.0).contains(&qn)
            && rate_est_rad_per_s.iter().all(|x| x.is_finite());
        if !inputs_ok {
            return Err(ControlError::InvalidEstimate);
        }
        let err = self
            .target
            .compose(&q_est.normalized().conjugate())
            .rotation_vector_rad();
        let angle = err.norm();
        let law = eigen_axis_law(&err, rate_est_rad_per_s, table)?;
        let (torque, rate_cmd, torque_limited) = (
            law.torque_acs_nm,
            law.rate_cmd_rad_per_s,
            law.torque_limited,
        );
        let w = *rate_est_rad_per_s;
        let wn = table.control_bandwidth_rad_per_s;

        let mut slew_complete = false;
        if self.mode == ControlMode::Slew
            && angle < table.slew_complete_rad
            && w.norm() < SLEW_COMPLETE_RATE_FACTOR * table.slew_complete_rad * wn
        {
            self.mode = ControlMode::Hold;
            slew_complete = true;
        }
        Ok(ControlOutput {
            torque_acs_nm: torque,
            high_rate_iru: self.mode == ControlMode::Slew,
            mode: self.mode,
            attitude_error_rad: err,
            rate_cmd_rad_per_s: rate_cmd,
            torque_limited,
            slew_complete,
            fault: None,
        })
    }
}

/// The torque of one cycle of the eigen-axis law (module docs): rate command along `err_rad`
/// (a rotation vector that, turned at a rate along it, reaches the target), torque-limited
/// with its direction kept.
/// Project choice (not in the paper): shared by the inertial modes and the Sun acquisition
/// (`crate::sun_acquisition`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LawOutput {
    /// Wheel torque, ACS, N·m, each axis within ±`torque_limit_nm`.
    /// Limit from docs/tables.md (filter table).
    pub torque_acs_nm: Vector3<f64>,
    /// Commanded body rate, ACS, rad/s.
    /// Project choice (not in the paper): see the module docs.
    pub rate_cmd_rad_per_s: Vector3<f64>,
    /// The torque was scaled down to the limit.
    /// Project choice (not in the paper): direction-preserving limit.
    pub torque_limited: bool,
}

/// One cycle of the saturated quaternion-feedback law of the module docs for the error
/// `err_rad` and the bias-corrected rate `rate_est_rad_per_s`.
/// Project choice (not in the paper): Wie, Weiss & Arapostathis (JGCD 12(3), 1989).
///
/// # Errors
/// [`ControlError::InvalidTable`] for unusable inertia, gains or limits;
/// [`ControlError::InvalidEstimate`] for a non-finite error, rate or torque.
pub fn eigen_axis_law(
    err_rad: &Vector3<f64>,
    rate_est_rad_per_s: &Vector3<f64>,
    table: &FilterTable,
) -> Result<LawOutput, ControlError> {
    if !(err_rad.iter().all(|x| x.is_finite()) && rate_est_rad_per_s.iter().all(|x| x.is_finite()))
    {
        return Err(ControlError::InvalidEstimate);
    }
    let [jx, jy, jz] = table.inertia_kg_m2;
    let wn = table.control_bandwidth_rad_per_s;
    let zeta = table.control_damping;
    let tau_max = table.torque_limit_nm;
    let w_max = table.slew_rate_limit_rad_per_s;
    let j_max = jx.max(jy).max(jz);
    let params_ok = [
        jx,
        jy,
        jz,
        wn,
        zeta,
        tau_max,
        w_max,
        table.slew_complete_rad,
    ]
    .iter()
    .all(|x| x.is_finite() && *x > 0.0);
    if !params_ok {
        return Err(ControlError::InvalidTable);
    }
    let j = Matrix3::from_diagonal(&Vector3::new(jx, jy, jz));
    let w = *rate_est_rad_per_s;
    let angle = err_rad.norm();
    let k_theta = wn / (2.0 * zeta);
    let k_omega = 2.0 * zeta * wn;
    let alpha_d = DECELERATION_MARGIN * tau_max / j_max;
    let rate_mag = w_max
        .min(libm::sqrt(2.0 * alpha_d * angle))
        .min(k_theta * angle);
    let rate_cmd = if angle > 0.0 {
        err_rad * (rate_mag / angle)
    } else {
        Vector3::zeros()
    };
    let mut torque = j * ((rate_cmd - w) * k_omega) + w.cross(&(j * w));
    let peak = torque.amax();
    let torque_limited = peak > tau_max;
    if torque_limited {
        torque *= tau_max / peak;
    }
    if !torque.iter().all(|x| x.is_finite()) {
        return Err(ControlError::InvalidEstimate);
    }
    Ok(LawOutput {
        torque_acs_nm: torque,
        rate_cmd_rad_per_s: rate_cmd,
        torque_limited,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hold_at_target_gives_zero_torque_and_low_rate() {
        let t = FilterTable::default_boot();
        let q = Quat::from_rotation_vector(&Vector3::new(0.1, 0.2, 0.3));
        let mut c = Controller::new();
        c.hold(&q).unwrap();
        let out = c.update(&q, &Vector3::zeros(), &t);
        assert!(out.torque_acs_nm.norm() < 1e-12);
        assert!(!out.high_rate_iru);
        assert_eq!(out.mode, ControlMode::Hold);
    }

    #[test]
    fn small_error_is_a_pd_and_points_the_right_way() {
        let t = FilterTable::default_boot();
        let target = Quat::IDENTITY;
        // Estimate: Â = Rot(-e) A_target, so θ_e = +e.
        let e = Vector3::new(1e-4, -2e-4, 0.5e-4);
        let est = Quat::from_rotation_vector(&(-e));
        let mut c = Controller::new();
        c.hold(&target).unwrap();
        let out = c.update(&est, &Vector3::zeros(), &t);
        assert!((out.attitude_error_rad - e).norm() < 1e-12);
        let wn = t.control_bandwidth_rad_per_s;
        let j = t.inertia_kg_m2;
        let expect = Vector3::new(j[0] * e.x, j[1] * e.y, j[2] * e.z) * (wn * wn);
        assert!(
            (out.torque_acs_nm - expect).norm() < 1e-9 * expect.norm().max(1.0),
            "{out:?}"
        );
    }

    #[test]
    fn large_error_is_rate_and_torque_limited_along_the_axis() {
        let t = FilterTable::default_boot();
        let mut c = Controller::new();
        let target = Quat::from_rotation_vector(&Vector3::new(0.0, 1.0, 0.0));
        c.slew_to(&target).unwrap();
        let out = c.update(&Quat::IDENTITY, &Vector3::zeros(), &t);
        assert!(out.high_rate_iru && out.torque_limited);
        assert!((out.rate_cmd_rad_per_s.norm() - t.slew_rate_limit_rad_per_s).abs() < 1e-15);
        assert!(out.torque_acs_nm.amax() <= t.torque_limit_nm * (1.0 + 1e-12));
        assert!(out.torque_acs_nm.y > 0.0 && out.torque_acs_nm.x.abs() < 1e-12);
    }

    #[test]
    fn invalid_inputs() {
        let t = FilterTable::default_boot();
        let mut c = Controller::new();
        assert_eq!(
            c.slew_to(&Quat::new(f64::NAN, 0.0, 0.0, 1.0)),
            Err(ControlError::InvalidTarget)
        );
        assert_eq!(
            c.slew_to(&Quat::new(0.0, 0.0, 0.0, 2.0)),
            Err(ControlError::InvalidTarget)
        );
        assert_eq!(c.mode(), ControlMode::Hold);
        let out = c.update(&Quat::IDENTITY, &Vector3::new(f64::NAN, 0.0, 0.0), &t);
        assert_eq!(out.fault, Some(ControlError::InvalidEstimate));
        assert_eq!(out.torque_acs_nm, Vector3::zeros());
        let mut bad = t;
        bad.inertia_kg_m2[1] = 0.0;
        let out = c.update(&Quat::IDENTITY, &Vector3::zeros(), &bad);
        assert_eq!(out.fault, Some(ControlError::InvalidTable));
    }
}
