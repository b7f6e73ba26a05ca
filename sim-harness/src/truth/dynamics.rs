//! # Rigid-body attitude dynamics with reaction wheels and gravity-gradient torque
//!
//! Why: the closed loop needs a true attitude and body rate that respond to the flight
//! software's wheel torque command, and the IRU truth needs the exact integral of the body
//! rate over each sample interval.
//!
//! # Model
//! * Spacecraft: rigid, 18 000 kg (gro_paper.toml `[mission]`). The paper gives no inertia;
//!   the default is **our estimate**: a 7.7 m × 4.6 m × 4.6 m body along ACS x
//!   (18 000·(4.6²+4.6²)/12 ≈ 6.3e4 and 18 000·(7.7²+4.6²)/12 ≈ 1.2e5 kg·m²) plus two solar
//!   arrays along ±y (≈ 600 kg at ~8.5 m adds ≈ 4.8e4 about x and z), i.e.
//!   diag(1.10e5, 1.25e5, 1.70e5) kg·m² with small products of inertia (−1.2e3, 8e2, −5e2).
//! * Reaction wheels: up to four, spin axes in ACS (default three orthogonal plus one skew
//!   along (1,1,1)/√3), each with a motor-torque limit and a momentum limit (chosen:
//!   0.4 N·m, 250 N·m·s; not from the paper). The flight software commands a body torque on
//!   the spacecraft; the wheels are driven with the minimum-norm allocation
//!   `τ_w = −W⁺ τ_cmd`, then each wheel is clamped to its torque limit and so that its
//!   momentum cannot pass its limit within the step (the body then gets less torque).
//! * External torque: gravity gradient `3 μ/r³ n × (I n)`, `n` the zenith unit vector in ACS,
//!   held constant over a step (evaluated at the step start).
//! * Momentum unloading (`momentum_unloading`): without it the orbit-averaged gravity
//!   gradient (≈ 0.05 N·m for this inertia in `normal-ops`) saturates the 250 N·m·s wheels
//!   within hours of inertial hold.
//!   - `"bars"`: GRO's way — the flight core commands the magnetic torquer bars
//!     ([`super::torquer`]) and the closed loop passes their torque `m × B` to
//!     [`RigidBody::step_with_external_torque`]; nothing is added here. Needs the truth field
//!     (`[magnetics] enabled = true`); used by `normal-ops` and `gro-early-mission`.
//!   - `"ideal"` (the default, for scenarios without the magnetics models: before issue 20
//!     the only model): an ideal external torque `τ_u = −h_w / T_u` (h_w the total wheel
//!     momentum in ACS, `T_u` = `momentum_unloading_time_constant_s`, default 600 s), held
//!     over a step; the attitude controller sees it as a slow disturbance and moves the
//!     momentum out of the wheels. The steady wheel momentum is then ≈ T_u × the secular
//!     torque (≈ 30–45 N·m·s in `normal-ops`).
//!   - `"off"`: no unloading (as `"ideal"` with `T_u = 0`).
//!
//! # Integration (per step `h`, torque held)
//! 1. RK4 on (ω, h_wheels) with `I ω̇ = τ_gg − W τ_w − ω × (I ω + W h_w)`, `ḣ_w = τ_w`.
//! 2. ω(t) inside the step is the cubic Hermite through (ω, ω̇) at both ends.
//! 3. Attitude: 4th-order Magnus update with the two Gauss points ω₁, ω₂:
//!    `φ = h/2 (ω₁ + ω₂) + √3 h²/12 (ω₁ × ω₂)`, `A⁺ = Rot(φ) A` (exact for a fixed axis;
//!    `dA/dt = −[ω×]A`, fsw_core convention).
//! 4. The IRU truth gets `∫ω dt = h/2 (ω₁ + ω₂)` (Gauss–Legendre, exact for cubic ω),
//!    what a rate-integrating gyro physically accumulates.

// Wheel quantities are fixed-size parallel arrays indexed by wheel number; indexed loops
// over `0..wheel_count` read more clearly than zipped iterators here.
#![allow(clippy::needless_range_loop)]

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use super::orbit::MU_EARTH_KM3_PER_S2;
use fsw_core::attitude::Quat;

/// Maximum number of reaction wheels.
pub const MAX_WHEELS: usize = 4;

/// Rigid-body and wheel parameters (scenario `[dynamics]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DynamicsParams {
    /// Inertia tensor about the centre of mass in ACS (kg·m²), row-major, symmetric.
    pub inertia_acs_kg_m2: [[f64; 3]; 3],
    /// Wheel spin axes in ACS (normalised on load), 1 to 4 wheels.
    pub wheel_axes_acs: Vec<[f64; 3]>,
    /// Motor torque limit per wheel (N·m).
    pub wheel_torque_limit_nm: f64,
    /// Momentum limit per wheel (N·m·s).
    pub wheel_momentum_limit_nms: f64,
    /// Initial wheel momenta (N·m·s), one per wheel (missing = 0).
    pub initial_wheel_momentum_nms: Vec<f64>,
    /// Apply the gravity-gradient torque.
    pub gravity_gradient: bool,
    /// Time constant of the ideal magnetic momentum unloading (s); 0 = off. Used only with
    /// `momentum_unloading = "ideal"`.
    pub momentum_unloading_time_constant_s: f64,
    /// How wheel momentum is unloaded (module doc): `"ideal"` (default), `"bars"`, `"off"`.
    pub momentum_unloading: MomentumUnloading,
}

/// How wheel momentum is unloaded (scenario `[dynamics] momentum_unloading`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MomentumUnloading {
    /// An ideal external torque `−h_w / T_u` (module doc); the model before issue 20.
    #[default]
    Ideal,
    /// The flight core's magnetic torquer bars ([`super::torquer`]).
    Bars,
    /// None.
    Off,
}

impl Default for DynamicsParams {
    fn default() -> Self {
        let k = 1.0 / 3.0_f64.sqrt();
        Self {
            inertia_acs_kg_m2: [
                [1.10e5, -1.2e3, 8.0e2],
                [-1.2e3, 1.25e5, -5.0e2],
                [8.0e2, -5.0e2, 1.70e5],
            ],
            wheel_axes_acs: vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [k, k, k]],
            wheel_torque_limit_nm: 0.4,
            wheel_momentum_limit_nms: 250.0,
            initial_wheel_momentum_nms: Vec::new(),
            gravity_gradient: true,
            momentum_unloading_time_constant_s: 600.0,
            momentum_unloading: MomentumUnloading::Ideal,
        }
    }
}

/// True attitude state.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct AttitudeState {
    /// Attitude `A = m_acs_from_eci` as a scalar-last quaternion.
    pub q_acs_from_eci: Quat,
    /// Body rate in ACS (rad/s).
    pub rate_acs_rad_per_s: Vector3<f64>,
    /// Wheel momenta along their spin axes (N·m·s); entries past the wheel count are 0.
    pub wheel_momentum_nms: [f64; MAX_WHEELS],
}

/// What happened during one step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepReport {
    /// `∫ ω dt` over the step in ACS (rad) — what an ideal rate-integrating gyro sees.
    pub rate_integral_acs_rad: Vector3<f64>,
    /// Rotation vector φ of the step, `A(t+h) = Rot(φ) A(t)` (rad).
    pub rotation_vector_acs_rad: Vector3<f64>,
    /// Body torque the wheels actually applied (N·m), after saturation.
    pub wheel_torque_applied_acs_nm: Vector3<f64>,
    /// External torque (N·m): gravity gradient plus the ideal momentum unloading or the
    /// torquer bars' torque.
    pub gravity_gradient_acs_nm: Vector3<f64>,
    /// Some wheel hit its torque or momentum limit.
    pub saturated: bool,
}

/// Rigid body + wheels.
#[derive(Clone, Debug)]
pub struct RigidBody {
    inertia: Matrix3<f64>,
    inertia_inv: Matrix3<f64>,
    wheel_count: usize,
    wheel_axes: [Vector3<f64>; MAX_WHEELS],
    /// Rows of the allocation `W⁺` (τ_w,i = −alloc[i] · τ_cmd).
    alloc: [Vector3<f64>; MAX_WHEELS],
    torque_limit_nm: f64,
    momentum_limit_nms: f64,
    gravity_gradient: bool,
    unloading_rate_per_s: f64,
    state: AttitudeState,
}

impl RigidBody {
    /// Build from parameters and an initial attitude and rate.
    ///
    /// # Errors
    /// Inertia not symmetric positive definite, no wheels or more than four, zero axes, or
    /// wheel axes that do not span 3-D.
    pub fn new(
        p: &DynamicsParams,
        q_acs_from_eci: Quat,
        rate_acs_rad_per_s: Vector3<f64>,
    ) -> anyhow::Result<Self> {
        let i = Matrix3::from_fn(|r, c| p.inertia_acs_kg_m2[r][c]);
        if (i - i.transpose()).abs().max() > 1e-9 * i.abs().max() {
            anyhow::bail!("dynamics.inertia_acs_kg_m2 is not symmetric");
        }
        if i.cholesky().is_none() {
            anyhow::bail!("dynamics.inertia_acs_kg_m2 is not positive definite");
        }
        let inertia_inv = i
            .try_inverse()
            .ok_or_else(|| anyhow::anyhow!("dynamics.inertia_acs_kg_m2 is singular"))?;
        let n = p.wheel_axes_acs.len();
        if !(1..=MAX_WHEELS).contains(&n) {
            anyhow::bail!("dynamics.wheel_axes_acs must list 1 to {MAX_WHEELS} wheels, got {n}");
        }
        let mut wheel_axes = [Vector3::zeros(); MAX_WHEELS];
        for (k, a) in p.wheel_axes_acs.iter().enumerate() {
            let v = Vector3::new(a[0], a[1], a[2]);
            let norm = v.norm();
            if !(norm.is_finite() && norm > 1e-9) {
                anyhow::bail!("dynamics.wheel_axes_acs[{k}] is zero or not finite");
            }
            wheel_axes[k] = v / norm;
        }
        // W is 3×n with the axes as columns; W⁺ = Wᵀ (W Wᵀ)⁻¹.
        let wwt: Matrix3<f64> = wheel_axes[..n].iter().map(|a| a * a.transpose()).sum();
        let wwt_inv = wwt.try_inverse().filter(|_| wwt.determinant().abs() > 1e-9);
        let mut alloc = [Vector3::zeros(); MAX_WHEELS];
        match wwt_inv {
            Some(inv) => {
                for k in 0..n {
                    alloc[k] = inv * wheel_axes[k];
                }
            }
            None => {
                // Fewer than three independent axes: allocate by projection (partial control).
                alloc[..n].copy_from_slice(&wheel_axes[..n]);
            }
        }
        let mut wheel_momentum_nms = [0.0; MAX_WHEELS];
        for (k, h) in p.initial_wheel_momentum_nms.iter().take(n).enumerate() {
            wheel_momentum_nms[k] = *h;
        }
        Ok(Self {
            inertia: i,
            inertia_inv,
            wheel_count: n,
            wheel_axes,
            alloc,
            torque_limit_nm: p.wheel_torque_limit_nm.abs(),
            momentum_limit_nms: p.wheel_momentum_limit_nms.abs(),
            gravity_gradient: p.gravity_gradient,
            unloading_rate_per_s: if p.momentum_unloading == MomentumUnloading::Ideal
                && p.momentum_unloading_time_constant_s > 0.0
            {
                1.0 / p.momentum_unloading_time_constant_s
            } else {
                0.0
            },
            state: AttitudeState {
                q_acs_from_eci: q_acs_from_eci.normalized(),
                rate_acs_rad_per_s,
                wheel_momentum_nms,
            },
        })
    }

    /// Current state.
    #[must_use]
    pub fn state(&self) -> &AttitudeState {
        &self.state
    }
    /// The wheels' total momentum in ACS (N·m·s).
    #[must_use]
    pub fn wheel_momentum_acs_nms(&self) -> Vector3<f64> {
        self.wheel_momentum_acs(&self.state.wheel_momentum_nms)
    }

    /// The wheels' momenta along their spin axes (N·m·s), one per wheel.
    #[must_use]
    pub fn wheel_momenta_nms(&self) -> &[f64] {
        self.state
            .wheel_momentum_nms
            .get(..self.wheel_count)
            .unwrap_or(&[])
    }

    /// Inertia tensor (kg·m², ACS).
    #[must_use]
    pub fn inertia(&self) -> &Matrix3<f64> {
        &self.inertia
    }

    /// Total angular momentum in ACS (body + wheels, N·m·s).
    #[must_use]
    pub fn momentum_acs_nms(&self) -> Vector3<f64> {
        self.inertia * self.state.rate_acs_rad_per_s
            + self.wheel_momentum_acs(&self.state.wheel_momentum_nms)
    }

    fn wheel_momentum_acs(&self, h: &[f64; MAX_WHEELS]) -> Vector3<f64> {
        let mut sum = Vector3::zeros();
        for k in 0..self.wheel_count {
            sum += self.wheel_axes[k] * h[k];
        }
        sum
    }

    /// Gravity-gradient torque (N·m) for the attitude `q` and position (km).
    #[must_use]
    pub fn gravity_gradient_acs_nm(
        &self,
        q_acs_from_eci: &Quat,
        pos_eci_km: &Vector3<f64>,
    ) -> Vector3<f64> {
        let r_m = pos_eci_km.norm() * 1.0e3;
        let zenith_acs = q_acs_from_eci.to_dcm() * pos_eci_km.normalize();
        let mu_m3 = MU_EARTH_KM3_PER_S2 * 1.0e9;
        zenith_acs.cross(&(self.inertia * zenith_acs)) * (3.0 * mu_m3 / (r_m * r_m * r_m))
    }

    /// Wheel motor torques for a commanded body torque, saturated for a step of `h_s`.
    fn wheel_torques(
        &self,
        torque_cmd_acs_nm: &Vector3<f64>,
        h_s: f64,
    ) -> ([f64; MAX_WHEELS], bool) {
        let mut out = [0.0; MAX_WHEELS];
        let mut saturated = false;
        for k in 0..self.wheel_count {
            let want = -self.alloc[k].dot(torque_cmd_acs_nm);
            let hk = self.state.wheel_momentum_nms[k];
            let lo = (-self.momentum_limit_nms - hk) / h_s;
            let hi = (self.momentum_limit_nms - hk) / h_s;
            let lo = lo.max(-self.torque_limit_nm).min(0.0);
            let hi = hi.min(self.torque_limit_nm).max(0.0);
            let got = want.clamp(lo, hi);
            saturated |= (got - want).abs() > 1e-12;
            out[k] = if got.is_finite() { got } else { 0.0 };
        }
        (out, saturated)
    }

    fn rate_derivative(
        &self,
        w: &Vector3<f64>,
        h: &[f64; MAX_WHEELS],
        ext: &Vector3<f64>,
        tau_w: &[f64; MAX_WHEELS],
    ) -> Vector3<f64> {
        let mut wheel_torque_on_wheels = Vector3::zeros();
        for k in 0..self.wheel_count {
            wheel_torque_on_wheels += self.wheel_axes[k] * tau_w[k];
        }
        let total_h = self.inertia * w + self.wheel_momentum_acs(h);
        self.inertia_inv * (ext - wheel_torque_on_wheels - w.cross(&total_h))
    }

    /// Advance by `h_s` with a commanded body torque (held) at orbit position `pos_eci_km`.
    pub fn step(
        &mut self,
        h_s: f64,
        torque_cmd_acs_nm: &Vector3<f64>,
        pos_eci_km: &Vector3<f64>,
    ) -> StepReport {
        self.step_with_external_torque(h_s, torque_cmd_acs_nm, pos_eci_km, &Vector3::zeros())
    }

    /// [`Self::step`] with a further external torque on the body (ACS, N·m, held over the
    /// step): the torquer bars' `m × B`.
    pub fn step_with_external_torque(
        &mut self,
        h_s: f64,
        torque_cmd_acs_nm: &Vector3<f64>,
        pos_eci_km: &Vector3<f64>,
        external_acs_nm: &Vector3<f64>,
    ) -> StepReport {
        let s0 = self.state;
        let mut gg = *external_acs_nm;
        gg += if self.gravity_gradient {
            self.gravity_gradient_acs_nm(&s0.q_acs_from_eci, pos_eci_km)
        } else {
            Vector3::zeros()
        };
        if self.unloading_rate_per_s > 0.0 {
            gg -= self.wheel_momentum_acs(&s0.wheel_momentum_nms) * self.unloading_rate_per_s;
        }
        let (tau_w, saturated) = self.wheel_torques(torque_cmd_acs_nm, h_s);
        let add_h = |h: &[f64; MAX_WHEELS], scale: f64| {
            let mut o = *h;
            for k in 0..MAX_WHEELS {
                o[k] += tau_w[k] * scale;
            }
            o
        };
        // RK4 on ω; the wheel momenta are linear in time (constant motor torque).
        let w0 = s0.rate_acs_rad_per_s;
        let h0 = s0.wheel_momentum_nms;
        let h_mid = add_h(&h0, 0.5 * h_s);
        let h_end = add_h(&h0, h_s);
        let k1 = self.rate_derivative(&w0, &h0, &gg, &tau_w);
        let k2 = self.rate_derivative(&(w0 + k1 * (0.5 * h_s)), &h_mid, &gg, &tau_w);
        let k3 = self.rate_derivative(&(w0 + k2 * (0.5 * h_s)), &h_mid, &gg, &tau_w);
        let k4 = self.rate_derivative(&(w0 + k3 * h_s), &h_end, &gg, &tau_w);
        let w1 = w0 + (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (h_s / 6.0);
        let wd1 = self.rate_derivative(&w1, &h_end, &gg, &tau_w);
        // Hermite ω at the Gauss points s = 1/2 ∓ √3/6.
        let hermite = |s: f64| {
            let s2 = s * s;
            let s3 = s2 * s;
            w0 * (2.0 * s3 - 3.0 * s2 + 1.0)
                + k1 * ((s3 - 2.0 * s2 + s) * h_s)
                + w1 * (-2.0 * s3 + 3.0 * s2)
                + wd1 * ((s3 - s2) * h_s)
        };
        let g = 3.0_f64.sqrt() / 6.0;
        let wa = hermite(0.5 - g);
        let wb = hermite(0.5 + g);
        let integral = (wa + wb) * (0.5 * h_s);
        let phi = integral + wa.cross(&wb) * (3.0_f64.sqrt() * h_s * h_s / 12.0);
        let dq = Quat::from_rotation_vector(&phi);
        self.state = AttitudeState {
            q_acs_from_eci: dq.compose(&s0.q_acs_from_eci).normalized(),
            rate_acs_rad_per_s: w1,
            wheel_momentum_nms: h_end,
        };
        let mut applied = Vector3::zeros();
        for k in 0..self.wheel_count {
            applied -= self.wheel_axes[k] * tau_w[k];
        }
        StepReport {
            rate_integral_acs_rad: integral,
            rotation_vector_acs_rad: phi,
            wheel_torque_applied_acs_nm: applied,
            gravity_gradient_acs_nm: gg,
            saturated,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fsw_core::attitude::rot;

    fn free_params() -> DynamicsParams {
        DynamicsParams {
            gravity_gradient: false,
            momentum_unloading_time_constant_s: 0.0,
            ..DynamicsParams::default()
        }
    }

    /// Torque-free tumbling: inertial angular momentum `Aᵀ H` and kinetic energy are
    /// conserved. Tolerance 1e-9 relative over 2000 s at 1 s steps (RK4 + Magnus-4 error is
    /// O(h⁵) per step).
    #[test]
    fn torque_free_conserves_inertial_momentum_and_energy() {
        let q0 = Quat::from_rotation_vector(&Vector3::new(0.3, -0.2, 0.5));
        let w0 = Vector3::new(0.4, -0.9, 0.6) * 0.01; // ~0.66 deg/s
        let mut body = RigidBody::new(&free_params(), q0, w0).unwrap();
        let h_inertial =
            |b: &RigidBody| b.state().q_acs_from_eci.to_dcm().transpose() * b.momentum_acs_nms();
        let energy = |b: &RigidBody| {
            0.5 * b
                .state()
                .rate_acs_rad_per_s
                .dot(&(b.inertia() * b.state().rate_acs_rad_per_s))
        };
        let (h0, e0) = (h_inertial(&body), energy(&body));
        for _ in 0..2000 {
            body.step(1.0, &Vector3::zeros(), &Vector3::new(6833.0, 0.0, 0.0));
        }
        let dh = (h_inertial(&body) - h0).norm() / h0.norm();
        let de = (energy(&body) - e0).abs() / e0;
        assert!(dh < 1e-9, "inertial momentum drift {dh}");
        assert!(de < 1e-9, "energy drift {de}");
    }

    /// A spin about a principal axis stays at constant rate and rotates exactly.
    #[test]
    fn principal_axis_spin_is_exact() {
        let p = DynamicsParams {
            inertia_acs_kg_m2: [[1.0e5, 0.0, 0.0], [0.0, 1.2e5, 0.0], [0.0, 0.0, 0.9e5]],
            gravity_gradient: false,
            momentum_unloading_time_constant_s: 0.0,
            ..DynamicsParams::default()
        };
        let w = Vector3::new(0.0, 0.0, 0.002);
        let mut body = RigidBody::new(&p, Quat::IDENTITY, w).unwrap();
        let mut total = Vector3::zeros();
        for _ in 0..500 {
            let r = body.step(1.0, &Vector3::zeros(), &Vector3::new(7000.0, 0.0, 0.0));
            total += r.rate_integral_acs_rad;
            assert!((r.rotation_vector_acs_rad - w).norm() < 1e-15);
        }
        let expect = rot(&(w * 500.0));
        assert!((body.state().q_acs_from_eci.to_dcm() - expect).abs().max() < 1e-12);
        assert!((total - w * 500.0).norm() < 1e-12);
    }

    /// From rest, a commanded torque accelerates the body at I⁻¹τ while total momentum
    /// stays zero; limits clamp.
    #[test]
    fn wheel_torque_and_saturation() {
        let mut body = RigidBody::new(&free_params(), Quat::IDENTITY, Vector3::zeros()).unwrap();
        let tau = Vector3::new(0.1, -0.05, 0.02);
        for _ in 0..10 {
            let r = body.step(1.0, &tau, &Vector3::new(7000.0, 0.0, 0.0));
            assert!(!r.saturated);
            assert!((r.wheel_torque_applied_acs_nm - tau).norm() < 1e-12);
        }
        assert!(
            body.momentum_acs_nms().norm() < 1e-9,
            "total momentum conserved"
        );
        let expect_rate = body.inertia().try_inverse().unwrap() * tau * 10.0;
        assert!(
            (body.state().rate_acs_rad_per_s - expect_rate).norm()
                < 1e-9 * expect_rate.norm().max(1e-6) + 1e-12
        );
        // Torque limit: a huge command is clamped per wheel.
        let r = body.step(
            1.0,
            &Vector3::new(50.0, 0.0, 0.0),
            &Vector3::new(7000.0, 0.0, 0.0),
        );
        assert!(r.saturated);
        assert!(r.wheel_torque_applied_acs_nm.x < 0.4 * 2.0);
        // Momentum limit: a single wheel near its limit cannot pass it.
        let p = DynamicsParams {
            wheel_axes_acs: vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            initial_wheel_momentum_nms: vec![249.9, 0.0, 0.0],
            ..free_params()
        };
        let mut b = RigidBody::new(&p, Quat::IDENTITY, Vector3::zeros()).unwrap();
        for _ in 0..5 {
            b.step(
                1.0,
                &Vector3::new(-0.3, 0.0, 0.0),
                &Vector3::new(7000.0, 0.0, 0.0),
            );
        }
        assert!((b.state().wheel_momentum_nms[0] - 250.0).abs() < 1e-9);
    }

    /// Gravity gradient about the x axis for a 45° tilt: 3n²(Izz − Iyy) sin θ cos θ.
    #[test]
    fn gravity_gradient_matches_formula() {
        let p = DynamicsParams {
            inertia_acs_kg_m2: [[1.1e5, 0.0, 0.0], [0.0, 1.25e5, 0.0], [0.0, 0.0, 1.7e5]],
            ..DynamicsParams::default()
        };
        let body = RigidBody::new(&p, Quat::IDENTITY, Vector3::zeros()).unwrap();
        let r_km = 6833.0;
        let s = std::f64::consts::FRAC_1_SQRT_2;
        let pos = Vector3::new(0.0, s, s) * r_km;
        let tau = body.gravity_gradient_acs_nm(&Quat::IDENTITY, &pos);
        let n2 = MU_EARTH_KM3_PER_S2 * 1e9 / (r_km * 1e3).powi(3);
        let expect = 3.0 * n2 * (1.7e5 - 1.25e5) * 0.5;
        assert!(
            (tau.x - expect).abs() < 1e-9 * expect,
            "{} vs {expect}",
            tau.x
        );
        assert!(tau.y.abs() < 1e-12 && tau.z.abs() < 1e-12);
        let aligned = body.gravity_gradient_acs_nm(&Quat::IDENTITY, &Vector3::new(0.0, 0.0, r_km));
        assert!(aligned.norm() < 1e-12);
    }

    /// The torquer bars' torque enters as an external torque: the total angular momentum
    /// (body + wheels, from rest) changes by `τ h` per step,
    /// τ = m × B, and `"bars"` adds no ideal unloading of its own.
    #[test]
    fn external_magnetic_torque_changes_the_total_momentum() {
        let p = DynamicsParams {
            gravity_gradient: false,
            momentum_unloading: MomentumUnloading::Bars,
            ..DynamicsParams::default()
        };
        let mut body = RigidBody::new(&p, Quat::IDENTITY, Vector3::zeros()).unwrap();
        let m = Vector3::new(2000.0, -1000.0, 500.0);
        let b_tesla = Vector3::new(10e-6, 25e-6, -15e-6);
        let tau = crate::truth::torquer::magnetic_torque_nm(&m, &b_tesla);
        let h0 = body.momentum_acs_nms();
        let pos = Vector3::new(7000.0, 0.0, 0.0);
        for _ in 0..10 {
            body.step_with_external_torque(1.0, &Vector3::zeros(), &pos, &tau);
        }
        // The body turns by ~1e-5 rad in 10 s: ACS and inertial axes agree to that order.
        let dh = body.momentum_acs_nms() - h0;
        assert!(
            (dh - tau * 10.0).norm() < 1e-4 * tau.norm() * 10.0,
            "{dh} vs {}",
            tau * 10.0
        );
        // The same with `step` and no torque: nothing changes (no ideal unloading).
        let mut still = RigidBody::new(&p, Quat::IDENTITY, Vector3::zeros()).unwrap();
        still.step(1.0, &Vector3::zeros(), &pos);
        assert!((still.momentum_acs_nms() - h0).norm() < 1e-12);
    }

    #[test]
    fn rejects_bad_parameters() {
        let bad = DynamicsParams {
            inertia_acs_kg_m2: [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]],
            ..DynamicsParams::default()
        };
        assert!(RigidBody::new(&bad, Quat::IDENTITY, Vector3::zeros()).is_err());
        let none = DynamicsParams {
            wheel_axes_acs: vec![],
            ..DynamicsParams::default()
        };
        assert!(RigidBody::new(&none, Quat::IDENTITY, Vector3::zeros()).is_err());
    }
}
