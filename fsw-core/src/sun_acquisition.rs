//! # Sun acquisition: turn a body axis to the Sun from the Sun sensors and the gyros alone
//!
//! Why: after a loss of attitude (boot, a filter reset, a tumble) the spacecraft must bring
//! the Sun onto its arrays and into the fine Sun sensors' fields before any inertial
//! attitude exists. GRO carried coarse Sun sensors for this (the paper's spacecraft: CSSs,
//! FSSs, TAMs, reaction wheels). The mode needs no attitude estimate, no star and no field
//! model: the Sun direction in ACS from the best Sun sensor of the cycle (FSS1, FSS2, then the
//! CSS eyes: [`crate::coarse::sun_candidates_acs`]) and the bias-corrected gyro rate.
//!
//! ## Law
//! * Sun `ŝ` and the commanded axis `t̂` (both ACS). A body turning at `ω` sees a fixed
//!   inertial direction move as `ṡ = ŝ × ω`; with `ω ∥ t̂ × ŝ` the Sun moves toward `t̂`
//!   (`d(ŝ·t̂)/dt = |ω| sin θ > 0`). The error is therefore the rotation vector
//!   `θ_e = θ (t̂ × ŝ)/|t̂ × ŝ|`, `θ = atan2(|t̂ × ŝ|, t̂·ŝ)`; with the Sun behind (`θ` within
//!   [`ANTIPARALLEL_RAD`] of π) the axis is any one perpendicular to `t̂` (the ACS axis least
//!   aligned with it, crossed with `t̂`), so the turn starts.
//! * Torque: the eigen-axis law of [`crate::control`] on `θ_e` (the same rate limit,
//!   braking and gains as a slew), so the rate about the Sun line is damped to zero.
//! * No Sun this cycle (eclipse, no sensor lit): `θ_e = 0`, the law damps the rates.
//! * Within [`NEAR_BEHIND_RAD`] of the opposite point the turn keeps the axis it started
//!   about (there the Sun sensors' noise would swing `t̂ × ŝ`).
//! * Acquired: `θ` below [`ACQUIRED_RAD`] and `|ω̂|` below [`ACQUIRED_RATE_RAD_PER_S`]; the
//!   mode keeps pointing (a Sun hold) until the ground commands a hold or a slew. Acquired
//!   stays true within twice the threshold; beyond it the loss is reported (event 0x0606)
//!   and the turn resumes.
//!
//! Deterministic, allocation-free, constant work (one `atan2`, one `sqrt`).
//!
//! Sources: the law is the project's eigen-axis law (Wie, Weiss & Arapostathis, JGCD 12(3),
//! 1989) on a vector error, as in Sun-acquisition modes generally (Wertz, *Spacecraft
//! Attitude Determination and Control*, §19); thresholds are project choices (below).

use nalgebra::Vector3;

use crate::control::{eigen_axis_law, ControlError, LawOutput};
use crate::tables::types::FilterTable;

/// Sun within this angle of the commanded axis counts as acquired (rad): 2°, well inside an
/// FSS's field. With the CSS eyes alone (5° 1σ in the boot magnetics table) the pointing is
/// only as good as they are; once an FSS sees the Sun it takes over (it is preferred).
/// Project choice (not in the paper).
pub const ACQUIRED_RAD: f64 = 2.0 * crate::units::RAD_PER_DEG;

/// Body rate below which a pointed Sun counts as acquired (rad/s): 0.01°/s.
/// Project choice (not in the paper).
pub const ACQUIRED_RATE_RAD_PER_S: f64 = 0.01 * crate::units::RAD_PER_DEG;

/// Within this of π the turn keeps the axis it started about (rad): 10°, twice the CSS eyes'
/// 5° 1σ of the boot magnetics table, so that their noise cannot swing the turn.
/// Project choice (not in the paper).
pub const NEAR_BEHIND_RAD: f64 = 10.0 * crate::units::RAD_PER_DEG;

/// Within this of π the Sun is behind the axis and the turn axis is chosen (rad): 1e-6.
/// Project choice (not in the paper): below it `t̂ × ŝ` has no usable direction.
pub const ANTIPARALLEL_RAD: f64 = 1e-6;

/// Why a Sun-acquisition command was refused.
/// Project choice (not in the paper): errors instead of panics in the flight core.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SunAcquisitionError {
    /// The commanded axis is not finite or not within 1e-3 of unit length.
    /// docs/icd.md §3.3 (event 0x0701, p2 = 4).
    InvalidAxis,
}

/// One cycle of the Sun acquisition.
/// Project choice (not in the paper); telemetry docs/icd.md §3.2 (control mode 3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SunAcquisitionOutput {
    /// The eigen-axis law's torque and rate command.
    /// Project choice (not in the paper): [`crate::control::eigen_axis_law`].
    pub law: LawOutput,
    /// Angle between the Sun and the commanded axis (rad); `None` without a Sun this cycle.
    /// Project choice (not in the paper): module docs.
    pub sun_angle_rad: Option<f64>,
    /// The Sun became acquired in this cycle.
    /// docs/icd.md §3.3 (event 0x0603).
    pub acquired_now: bool,
    /// No Sun sensor sees the Sun in this cycle, after it was seen or at the mode's first
    /// cycle (once per occurrence).
    /// docs/icd.md §3.3 (event 0x0604).
    pub sun_lost_now: bool,
    /// This is the mode's first cycle (0x0604 then says "no Sun at entry").
    /// docs/icd.md §3.3 (event 0x0604, p1).
    pub first_cycle: bool,
    /// The acquired Sun left twice the acquisition threshold in this cycle.
    /// docs/icd.md §3.3 (event 0x0606).
    pub acquisition_lost_now: bool,
}

/// The Sun-acquisition mode's state: the axis to bring to the Sun and what was seen.
/// Project choice (not in the paper).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SunAcquisition {
    target_axis_acs: [f64; 3],
    acquired: bool,
    sun_seen: bool,
    started: bool,
    /// The last turn axis while the Sun was behind the target (ACS, unit; zero before).
    behind_axis_acs: [f64; 3],
}

impl SunAcquisition {
    /// Start acquiring with `target_axis_acs` (unit, ACS).
    /// Project choice (not in the paper): docs/icd.md §3.3 (command 9).
    ///
    /// # Errors
    /// [`SunAcquisitionError::InvalidAxis`].
    pub fn new(target_axis_acs: [f64; 3]) -> Result<Self, SunAcquisitionError> {
        let v = Vector3::from(target_axis_acs);
        let n = v.norm();
        if !(v.iter().all(|x| x.is_finite()) && (n - 1.0).abs() < 1e-3) {
            return Err(SunAcquisitionError::InvalidAxis);
        }
        let unit = v / n;
        Ok(Self {
            target_axis_acs: [unit.x, unit.y, unit.z],
            acquired: false,
            sun_seen: true,
            started: false,
            behind_axis_acs: [0.0; 3],
        })
    }

    /// The commanded axis (ACS, unit).
    /// Project choice (not in the paper).
    #[must_use]
    pub const fn target_axis_acs(&self) -> [f64; 3] {
        self.target_axis_acs
    }

    /// Whether the Sun is on the axis and the rates are down.
    /// Project choice (not in the paper): [`ACQUIRED_RAD`], [`ACQUIRED_RATE_RAD_PER_S`].
    #[must_use]
    pub const fn acquired(&self) -> bool {
        self.acquired
    }

    /// One cycle from the Sun direction of the cycle (ACS, unit; `None`: no Sun) and the
    /// bias-corrected rate.
    /// Project choice (not in the paper): the law of the module docs.
    ///
    /// # Errors
    /// Those of [`eigen_axis_law`] (the caller commands zero torque).
    pub fn update(
        &mut self,
        sun_acs: Option<&Vector3<f64>>,
        rate_est_rad_per_s: &Vector3<f64>,
        table: &FilterTable,
    ) -> Result<SunAcquisitionOutput, ControlError> {
        let target = Vector3::from(self.target_axis_acs);
        let sun = sun_acs.and_then(|s| {
            let n = s.norm();
            (s.iter().all(|x| x.is_finite()) && n > 0.5).then(|| s / n)
        });
        let (err, angle) = match sun {
            Some(s) => {
                let (e, a) = self.error_keeping_the_turn(&target, &s);
                (e, Some(a))
            }
            None => (Vector3::zeros(), None),
        };
        let law = eigen_axis_law(&err, rate_est_rad_per_s, table)?;
        let first_cycle = !self.started;
        self.started = true;
        let sun_lost_now = angle.is_none() && (self.sun_seen || first_cycle);
        self.sun_seen = angle.is_some();
        let on_axis = angle.is_some_and(|a| a < ACQUIRED_RAD)
            && rate_est_rad_per_s.norm() < ACQUIRED_RATE_RAD_PER_S;
        let was_acquired = self.acquired;
        if let Some(a) = angle {
            // Hysteresis: once acquired, it stays so within twice the threshold.
            self.acquired = on_axis || (self.acquired && a < 2.0 * ACQUIRED_RAD);
        }
        Ok(SunAcquisitionOutput {
            law,
            sun_angle_rad: angle,
            acquired_now: self.acquired && !was_acquired,
            sun_lost_now,
            first_cycle,
            acquisition_lost_now: was_acquired && !self.acquired,
        })
    }

    /// [`pointing_error_rad`], except that with the Sun within [`NEAR_BEHIND_RAD`] of the
    /// point opposite the axis the turn keeps the axis it started about: there `t̂ × ŝ` is
    /// short and the Sun sensors' noise would swing it from cycle to cycle.
    fn error_keeping_the_turn(
        &mut self,
        target: &Vector3<f64>,
        sun: &Vector3<f64>,
    ) -> (Vector3<f64>, f64) {
        let (err, angle) = pointing_error_rad(target, sun);
        if core::f64::consts::PI - angle >= NEAR_BEHIND_RAD {
            self.behind_axis_acs = [0.0; 3];
            return (err, angle);
        }
        let prev = Vector3::from(self.behind_axis_acs);
        // The previous axis, kept perpendicular to the target (the turn must move the Sun).
        let kept = prev - target * prev.dot(target);
        let axis = if kept.norm() > 0.5 {
            kept.normalize()
        } else {
            err.try_normalize(0.0).unwrap_or_else(Vector3::zeros)
        };
        self.behind_axis_acs = [axis.x, axis.y, axis.z];
        (axis * angle, angle)
    }
}

/// The rotation vector that turns the body so that the Sun `sun` (ACS, unit) moves onto
/// `target` (ACS, unit), and the angle between them (rad).
/// Project choice (not in the paper): module docs ("Law"), algorithms.md §1 convention.
#[must_use]
pub fn pointing_error_rad(target: &Vector3<f64>, sun: &Vector3<f64>) -> (Vector3<f64>, f64) {
    let axis = target.cross(sun);
    let sin = axis.norm();
    let angle = libm::atan2(sin, target.dot(sun));
    if angle <= 0.0 {
        return (Vector3::zeros(), 0.0);
    }
    if core::f64::consts::PI - angle < ANTIPARALLEL_RAD || sin <= 0.0 {
        // The Sun behind the axis: any perpendicular turns it; the ACS axis least aligned
        // with the target, crossed with it, is never parallel to it.
        let (ax, ay, az) = (target.x.abs(), target.y.abs(), target.z.abs());
        let least = if ax <= ay && ax <= az {
            Vector3::x()
        } else if ay <= az {
            Vector3::y()
        } else {
            Vector3::z()
        };
        let perp = target.cross(&least);
        let n = perp.norm();
        return if n > 0.0 {
            (perp * (angle / n), angle)
        } else {
            (Vector3::zeros(), angle)
        };
    }
    (axis * (angle / sin), angle)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::attitude::rot;

    fn table() -> FilterTable {
        FilterTable::default_boot()
    }

    /// Turning the body about the error vector brings the Sun onto the axis: the sign the
    /// module docs derive, checked with the project's one rotation convention.
    #[test]
    fn turning_about_the_error_brings_the_sun_to_the_axis() {
        let target = Vector3::new(1.0, 0.0, 0.0);
        for sun in [
            Vector3::new(0.0, 1.0, 0.0),
            Vector3::new(-0.3, -0.2, 0.9).normalize(),
            Vector3::new(0.8, 0.1, -0.59).normalize(),
        ] {
            let (err, angle) = pointing_error_rad(&target, &sun);
            assert!((err.norm() - angle).abs() < 1e-12);
            // A rotation of the body by err: body vectors of inertial directions move by
            // Rot(err) (algorithms.md §1, A' = Rot(θ) A).
            let moved = rot(&err) * sun;
            assert!((moved - target).norm() < 1e-9, "{sun:?} -> {moved:?}");
        }
    }

    /// The Sun exactly behind the axis still gives a turn of π about a perpendicular axis.
    #[test]
    fn sun_behind_the_axis_turns_about_a_perpendicular() {
        let target = Vector3::new(0.0, 0.0, 1.0);
        let (err, angle) = pointing_error_rad(&target, &-target);
        assert!((angle - core::f64::consts::PI).abs() < 1e-12);
        assert!(err.dot(&target).abs() < 1e-12);
        assert!((err.norm() - angle).abs() < 1e-12);
        let (err0, a0) = pointing_error_rad(&target, &target);
        assert_eq!((err0, a0), (Vector3::zeros(), 0.0));
    }

    /// Without a Sun the law only damps: the torque opposes the rate; the loss is reported
    /// once, and a pointed, quiet Sun is reported acquired once.
    #[test]
    fn no_sun_damps_and_acquisition_is_reported_once() {
        let mut acq = SunAcquisition::new([1.0, 0.0, 0.0]).unwrap();
        let w = Vector3::new(1e-3, -2e-3, 5e-4);
        let out = acq.update(None, &w, &table()).unwrap();
        assert!(out.sun_lost_now && out.first_cycle && out.sun_angle_rad.is_none());
        assert!(out.law.torque_acs_nm.dot(&w) < 0.0);
        let again = acq.update(None, &w, &table()).unwrap();
        assert!(!again.sun_lost_now && !again.first_cycle);
        let sun = Vector3::new(1.0, 0.01, 0.0).normalize();
        let quiet = Vector3::zeros();
        let first = acq.update(Some(&sun), &quiet, &table()).unwrap();
        assert!(first.acquired_now && acq.acquired());
        let second = acq.update(Some(&sun), &quiet, &table()).unwrap();
        assert!(!second.acquired_now && acq.acquired());
        // Far off the axis it is no longer acquired, and that is reported once.
        let off = Vector3::new(0.0, 1.0, 0.0);
        let lost = acq.update(Some(&off), &quiet, &table()).unwrap();
        assert!(lost.acquisition_lost_now && !acq.acquired());
        let still = acq.update(Some(&off), &quiet, &table()).unwrap();
        assert!(!still.acquisition_lost_now);
        // The Sun lost after being seen is reported once, not as an entry.
        let gone = acq.update(None, &quiet, &table()).unwrap();
        assert!(gone.sun_lost_now && !gone.first_cycle);
    }

    /// With the Sun near the point opposite the axis, noise that swings `t̂ × ŝ` around does
    /// not swing the turn: the axis it started about is kept while the Sun stays within
    /// [`NEAR_BEHIND_RAD`] of the opposite point.
    #[test]
    fn the_turn_keeps_its_axis_near_the_opposite_point() {
        let mut acq = SunAcquisition::new([0.0, 0.0, 1.0]).unwrap();
        let quiet = Vector3::zeros();
        let d = 3.0 * crate::units::RAD_PER_DEG;
        let first = Vector3::new(libm::sin(d), 0.0, -libm::cos(d));
        let out = acq.update(Some(&first), &quiet, &table()).unwrap();
        let axis0 = out.law.rate_cmd_rad_per_s.normalize();
        // The noise puts the Sun on the other side of the opposite point: the bare error
        // would turn the other way.
        let other = Vector3::new(-libm::sin(d), 0.01, -libm::cos(d)).normalize();
        let (bare, _) = pointing_error_rad(&Vector3::z(), &other);
        assert!(bare.normalize().dot(&axis0) < -0.9);
        let out = acq.update(Some(&other), &quiet, &table()).unwrap();
        assert!(out.law.rate_cmd_rad_per_s.normalize().dot(&axis0) > 0.99);
        // Out of the near-behind cone the bare error rules again.
        let side = Vector3::new(-1.0, 0.0, 0.0);
        let out = acq.update(Some(&side), &quiet, &table()).unwrap();
        let (e, _) = pointing_error_rad(&Vector3::z(), &side);
        assert!(out.law.rate_cmd_rad_per_s.normalize().dot(&e.normalize()) > 0.999);
    }

    /// An axis that is not a unit vector, or not finite, is refused.
    #[test]
    fn bad_axes_are_refused() {
        for axis in [[0.0, 0.0, 0.0], [f64::NAN, 0.0, 1.0], [2.0, 0.0, 0.0]] {
            assert_eq!(
                SunAcquisition::new(axis),
                Err(SunAcquisitionError::InvalidAxis)
            );
        }
        assert!(SunAcquisition::new([0.0, 0.6, 0.8]).is_ok());
    }
}
