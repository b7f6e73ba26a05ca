//! # Velocity aberration of light
//!
//! An observer moving with velocity `v` relative to the solar-system barycentre sees a source
//! of (astrometric) direction `u` at the apparent direction given by the special-relativistic
//! formula of the Explanatory Supplement (algorithms.md §3.3):
//!
//! `u_app = (γ⁻¹ u + (1 + f₁/(1 + γ⁻¹)) β) / (1 + f₁)`, `β = v/c`, `f₁ = u·β`, `γ⁻¹ = √(1−β²)`.
//!
//! For GRO, `v = v_earth_bary + v_sc_eci` (annual ≤ 20.5″, orbital ≤ 5.2″). The first-order
//! form differs by ~β² (2 mas) and is provided for tests and for the onboard-style model.

use nalgebra::Vector3;

/// Speed of light in vacuum (km/s).
pub const C_KM_PER_S: f64 = 299_792.458;

/// Relativistic aberration of unit direction `u_dir` for observer velocity `v_km_per_s`
/// (barycentric, same axes). Returns a unit vector.
#[must_use]
pub fn aberrate(u_dir: &Vector3<f64>, v_km_per_s: &Vector3<f64>) -> Vector3<f64> {
    let beta = v_km_per_s / C_KM_PER_S;
    let gamma_inv = (1.0 - beta.norm_squared()).sqrt();
    let f1 = u_dir.dot(&beta);
    let f2 = 1.0 + f1 / (1.0 + gamma_inv);
    let p = (u_dir * gamma_inv + beta * f2) / (1.0 + f1);
    p.normalize()
}

/// First-order (classical) aberration `normalize(u + β)`.
#[must_use]
pub fn aberrate_first_order(u_dir: &Vector3<f64>, v_km_per_s: &Vector3<f64>) -> Vector3<f64> {
    (u_dir + v_km_per_s / C_KM_PER_S).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;
    use fsw_core::units::ARCSEC_PER_RAD;

    #[test]
    fn shift_is_beta_sin_angle_toward_velocity() {
        let u = Vector3::new(1.0, 0.0, 0.0);
        let v = Vector3::new(0.0, 29.78, 0.0);
        let app = aberrate(&u, &v);
        let shift_arcsec = u.cross(&app).norm().asin() * ARCSEC_PER_RAD;
        let expect = (29.78 / C_KM_PER_S) * ARCSEC_PER_RAD;
        assert!(
            (shift_arcsec - expect).abs() < 0.01,
            "{shift_arcsec} vs {expect}"
        );
        assert!(app.y > 0.0, "displaced toward the apex");
        // Along the velocity: no shift.
        let along = aberrate(&v.normalize(), &v);
        assert!((along - v.normalize()).norm() < 1e-15);
        // First order agrees to ~β² (2 mas).
        let fo = aberrate_first_order(&u, &v);
        assert!((fo - app).norm() * ARCSEC_PER_RAD < 0.003);
    }
}
