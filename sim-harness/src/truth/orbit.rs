//! # GRO orbit: J2-perturbed Keplerian motion, fixed-step RK4, J2000 axes
//!
//! Why: the sensors need the spacecraft position (Sun parallax, Earth exclusion, eclipse,
//! gravity gradient) and velocity (orbital aberration, ≤ 5.2″). GRO was released on
//! 1991-04-07T22:37:00 UTC into a = 6833 km, i = 28.48°, near-circular (gro_paper.toml
//! `[mission]`); RAAN and the argument of latitude at the epoch are scenario parameters.
//!
//! Model: point mass + J2 (EGM96 values), integrated in J2000/GCRS axes. The J2 axis is taken
//! as the J2000 pole; the true pole of 1991 differs by 0.04°, which changes the nodal rate by
//! ~1e-5 relative. No drag: at 450 km GRO's decay (~km per month) is irrelevant to attitude
//! sensing. The initial osculating elements are the scenario's; no mean-to-osculating
//! conversion is attempted.
//!
//! Integration: classical RK4 with steps of at most `max_step_s` (default 10 s; the energy
//! drift is ~1e-11 relative per day, see tests). Per cycle this is one to a few RK4 steps, no
//! allocation.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::sun::EARTH_RADIUS_KM;
use fsw_core::units::RAD_PER_DEG;

/// Earth gravitational parameter (km³/s²), EGM96/WGS84.
pub const MU_EARTH_KM3_PER_S2: f64 = 398_600.441_8;
/// Earth J2 (EGM96 unnormalised C20 with the sign flipped).
pub const J2_EARTH: f64 = 1.082_626_68e-3;

/// Orbit parameters (scenario `[orbit]`). Angles in degrees.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OrbitParams {
    /// Semimajor axis (km). Paper: 6833.
    pub semimajor_axis_km: f64,
    /// Eccentricity. Paper: "near-circular".
    pub eccentricity: f64,
    /// Inclination (deg). Paper: 28.48.
    pub inclination_deg: f64,
    /// Right ascension of the ascending node at the epoch (deg, J2000).
    pub raan_deg: f64,
    /// Argument of perigee (deg); irrelevant when `eccentricity` = 0.
    pub arg_perigee_deg: f64,
    /// Argument of latitude ω + ν at the epoch (deg).
    pub arg_latitude_deg: f64,
    /// Include the J2 perturbation.
    pub j2: bool,
    /// Largest RK4 step (s).
    pub max_step_s: f64,
}

impl Default for OrbitParams {
    fn default() -> Self {
        Self {
            semimajor_axis_km: 6833.0,
            eccentricity: 0.0,
            inclination_deg: 28.48,
            raan_deg: 0.0,
            arg_perigee_deg: 0.0,
            arg_latitude_deg: 0.0,
            j2: true,
            max_step_s: 10.0,
        }
    }
}

/// Position and velocity, J2000 axes.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct OrbitState {
    /// Position (km).
    pub pos_eci_km: Vector3<f64>,
    /// Velocity (km/s).
    pub vel_eci_km_per_s: Vector3<f64>,
}

impl OrbitState {
    /// Osculating state from Keplerian elements (two-body relations).
    #[must_use]
    pub fn from_elements(p: &OrbitParams) -> Self {
        let e = p.eccentricity.clamp(0.0, 0.99);
        let a = p.semimajor_axis_km;
        let (si, ci) = (p.inclination_deg * RAD_PER_DEG).sin_cos();
        let (so, co) = (p.raan_deg * RAD_PER_DEG).sin_cos();
        let argp = p.arg_perigee_deg * RAD_PER_DEG;
        let u = p.arg_latitude_deg * RAD_PER_DEG;
        let nu = u - argp;
        let semi_latus_km = a * (1.0 - e * e);
        let r = semi_latus_km / (1.0 + e * nu.cos());
        let sqrt_mu_over_p = (MU_EARTH_KM3_PER_S2 / semi_latus_km).sqrt();
        // Radial/transverse components, then the perifocal-to-ECI rotation via u.
        let v_r = sqrt_mu_over_p * e * nu.sin();
        let v_t = sqrt_mu_over_p * (1.0 + e * nu.cos());
        let (su, cu) = u.sin_cos();
        let radial = Vector3::new(co * cu - so * su * ci, so * cu + co * su * ci, su * si);
        let transverse = Vector3::new(-co * su - so * cu * ci, -so * su + co * cu * ci, cu * si);
        Self {
            pos_eci_km: radial * r,
            vel_eci_km_per_s: radial * v_r + transverse * v_t,
        }
    }

    /// Specific angular momentum (km²/s).
    #[must_use]
    pub fn angular_momentum(&self) -> Vector3<f64> {
        self.pos_eci_km.cross(&self.vel_eci_km_per_s)
    }

    /// Right ascension of the ascending node (rad, −π..π) of the osculating orbit.
    #[must_use]
    pub fn raan_rad(&self) -> f64 {
        let h = self.angular_momentum();
        h.x.atan2(-h.y)
    }

    /// Specific mechanical energy including the J2 potential (km²/s²), conserved by the
    /// dynamics when `j2` is true.
    #[must_use]
    pub fn energy(&self, j2: bool) -> f64 {
        let r = self.pos_eci_km.norm();
        let mut potential = MU_EARTH_KM3_PER_S2 / r;
        if j2 {
            let sin_lat = self.pos_eci_km.z / r;
            let p2 = 0.5 * (3.0 * sin_lat * sin_lat - 1.0);
            potential *= 1.0 - J2_EARTH * (EARTH_RADIUS_KM / r).powi(2) * p2;
        }
        0.5 * self.vel_eci_km_per_s.norm_squared() - potential
    }
}

/// Gravitational acceleration (km/s²): point mass plus optional J2.
#[must_use]
pub fn gravity_accel_km_per_s2(pos_eci_km: &Vector3<f64>, j2: bool) -> Vector3<f64> {
    let r2 = pos_eci_km.norm_squared();
    let r = r2.sqrt();
    let mut a = -pos_eci_km * (MU_EARTH_KM3_PER_S2 / (r2 * r));
    if j2 {
        let z2_over_r2 = pos_eci_km.z * pos_eci_km.z / r2;
        let k = -1.5 * J2_EARTH * MU_EARTH_KM3_PER_S2 * EARTH_RADIUS_KM * EARTH_RADIUS_KM
            / (r2 * r2 * r);
        a += Vector3::new(
            pos_eci_km.x * (1.0 - 5.0 * z2_over_r2),
            pos_eci_km.y * (1.0 - 5.0 * z2_over_r2),
            pos_eci_km.z * (3.0 - 5.0 * z2_over_r2),
        ) * k;
    }
    a
}

/// The orbit propagator: current time (s from the scenario epoch) and state.
#[derive(Clone, Debug)]
pub struct Orbit {
    t_s: f64,
    state: OrbitState,
    j2: bool,
    max_step_s: f64,
    period_s: f64,
}

impl Orbit {
    /// Start at `t_s = 0` from the scenario elements.
    #[must_use]
    pub fn new(p: &OrbitParams) -> Self {
        let a = p.semimajor_axis_km;
        Self {
            t_s: 0.0,
            state: OrbitState::from_elements(p),
            j2: p.j2,
            max_step_s: p.max_step_s.clamp(0.01, 60.0),
            period_s: 2.0 * core::f64::consts::PI * (a * a * a / MU_EARTH_KM3_PER_S2).sqrt(),
        }
    }

    /// Current time (s since the scenario epoch).
    #[must_use]
    pub fn t_s(&self) -> f64 {
        self.t_s
    }

    /// Current state.
    #[must_use]
    pub fn state(&self) -> &OrbitState {
        &self.state
    }

    /// Keplerian period of the initial semimajor axis (s).
    #[must_use]
    pub fn period_s(&self) -> f64 {
        self.period_s
    }

    /// Propagate to `t_s` (forward or backward) with RK4 steps of at most `max_step_s`.
    pub fn advance_to(&mut self, t_s: f64) {
        let span = t_s - self.t_s;
        if span == 0.0 {
            return;
        }
        // At least one step; never more than needed for max_step_s.
        let steps = (span.abs() / self.max_step_s).ceil().max(1.0);
        let h = span / steps;
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        for _ in 0..steps as u64 {
            self.state = rk4_step(&self.state, h, self.j2);
        }
        self.t_s = t_s;
    }
}

fn rk4_step(s: &OrbitState, h: f64, j2: bool) -> OrbitState {
    let (r0, v0) = (s.pos_eci_km, s.vel_eci_km_per_s);
    let a1 = gravity_accel_km_per_s2(&r0, j2);
    let r1 = r0 + v0 * (0.5 * h);
    let v1 = v0 + a1 * (0.5 * h);
    let a2 = gravity_accel_km_per_s2(&r1, j2);
    let r2 = r0 + v1 * (0.5 * h);
    let v2 = v0 + a2 * (0.5 * h);
    let a3 = gravity_accel_km_per_s2(&r2, j2);
    let r3 = r0 + v2 * h;
    let v3 = v0 + a3 * h;
    let a4 = gravity_accel_km_per_s2(&r3, j2);
    OrbitState {
        pos_eci_km: r0 + (v0 + v1 * 2.0 + v2 * 2.0 + v3) * (h / 6.0),
        vel_eci_km_per_s: v0 + (a1 + a2 * 2.0 + a3 * 2.0 + a4) * (h / 6.0),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_body_returns_after_one_period() {
        let p = OrbitParams {
            j2: false,
            raan_deg: 120.0,
            arg_latitude_deg: 33.0,
            ..OrbitParams::default()
        };
        let mut orbit = Orbit::new(&p);
        let start = *orbit.state();
        // data/igrf_reference.csv quotes 5621.188 s for a = 6833 km and this μ.
        assert!(
            (orbit.period_s() - 5621.188).abs() < 0.01,
            "{}",
            orbit.period_s()
        );
        assert!((start.pos_eci_km.norm() - 6833.0).abs() < 1e-9);
        assert!(
            (start.vel_eci_km_per_s.norm() - (MU_EARTH_KM3_PER_S2 / 6833.0).sqrt()).abs() < 1e-12
        );
        assert!((start.raan_rad() - 120.0 * RAD_PER_DEG).abs() < 1e-12);
        orbit.advance_to(orbit.period_s());
        let err_km = (orbit.state().pos_eci_km - start.pos_eci_km).norm();
        assert!(err_km < 1e-3, "closure error {err_km} km");
    }

    #[test]
    fn j2_energy_is_conserved_over_a_day() {
        let p = OrbitParams {
            eccentricity: 0.001,
            arg_perigee_deg: 40.0,
            ..OrbitParams::default()
        };
        let mut orbit = Orbit::new(&p);
        let e0 = orbit.state().energy(true);
        orbit.advance_to(86_400.0);
        let e1 = orbit.state().energy(true);
        assert!(
            ((e1 - e0) / e0).abs() < 1e-9,
            "relative drift {}",
            (e1 - e0) / e0
        );
        // The polar component of angular momentum is conserved under J2 (axisymmetric).
        let mut o2 = Orbit::new(&p);
        let hz0 = o2.state().angular_momentum().z;
        o2.advance_to(20_000.0);
        assert!((o2.state().angular_momentum().z - hz0).abs() / hz0 < 1e-9);
    }

    /// Verifies the J2 secular nodal rate dΩ/dt = −(3/2) n J2 (R/p)² cos i (about −6.9°/day
    /// for GRO). Tolerance 1 %: the fitted slope uses osculating elements, whose mean
    /// semimajor axis differs from 6833 km by O(J2).
    #[test]
    fn val_j2_nodal_regression_rate() {
        let p = OrbitParams::default();
        let mut orbit = Orbit::new(&p);
        let n = (MU_EARTH_KM3_PER_S2 / p.semimajor_axis_km.powi(3)).sqrt();
        let analytic = -1.5
            * n
            * J2_EARTH
            * (EARTH_RADIUS_KM / p.semimajor_axis_km).powi(2)
            * (p.inclination_deg * RAD_PER_DEG).cos();
        // Least-squares slope of the unwrapped node over one day.
        let (mut st, mut sy, mut stt, mut sty, mut count) = (0.0, 0.0, 0.0, 0.0, 0.0);
        let mut prev = orbit.state().raan_rad();
        let mut unwrapped = prev;
        for k in 0..=1440 {
            let t = f64::from(k) * 60.0;
            orbit.advance_to(t);
            let node = orbit.state().raan_rad();
            let mut d = node - prev;
            d -= (d / (2.0 * core::f64::consts::PI)).round() * 2.0 * core::f64::consts::PI;
            unwrapped += d;
            prev = node;
            st += t;
            sy += unwrapped;
            stt += t * t;
            sty += t * unwrapped;
            count += 1.0;
        }
        let slope = (count * sty - st * sy) / (count * stt - st * st);
        let deg_per_day = slope / RAD_PER_DEG * 86_400.0;
        eprintln!(
            "nodal rate: fitted {deg_per_day:.4} deg/day, analytic {:.4} deg/day",
            analytic / RAD_PER_DEG * 86_400.0
        );
        assert!(((slope - analytic) / analytic).abs() < 0.01);
    }
}
