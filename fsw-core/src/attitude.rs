//! # Attitude conventions for the whole workspace
//!
//! One convention, used by `fsw-core`, `sim-harness` and `ground-tool` alike
//! (written out for people in `docs/conventions.md`):
//!
//! * **Attitude matrix** `A = m_acs_from_eci` maps inertial (J2000/ICRS) components to ACS
//!   (body) components: `b = A r`. Kinematics `dA/dt = -[ω×] A`, ω the body rate in ACS.
//! * **Alignment matrix** `M_AS = m_acs_from_<sensor>` maps sensor components to ACS; its
//!   columns are the sensor axes in ACS and the sensor boresight is its z axis (paper
//!   appendix, `M_AS`; Table 1).
//! * **Rotation vector** θ (rad): the paper's `Rot(θ)` (algorithms.md §1),
//!   `Rot(θ) = cos θ I + (1 − cos θ) e eᵀ − sin θ [e×] = exp(−[θ×])`, i.e. the *passive*
//!   matrix of a frame rotated by +θ. Corrections are applied on the left in ACS, as the paper
//!   writes them:
//!   `M_AS' = Rot(θ) M_AS`.
//! * **Quaternion**: scalar-last Shuster/Markley `q = [q_v; q_4]`, `q_v = e sin(θ/2)`,
//!   `q_4 = cos(θ/2)`, with `A(q) = Rot(θ e)` and the natural-order product
//!   `A(p ⊗ q) = A(p) A(q)`. `q` and `−q` are the same attitude; we keep `q_4 ≥ 0` when
//!   normalising.
//! * **Error state**: a small attitude error is a left, body-frame rotation vector,
//!   `A_true = Rot(δθ) Â`.
//!
//! Everything here is `f64`, branch-bounded and panic-free.

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// Below this angle (rad) series expansions replace `sin θ / θ`-type ratios.
const SMALL_ANGLE_RAD: f64 = 1.0e-8;

/// Cross-product matrix `[v×]`, so that `[v×] w = v × w`.
/// algorithms.md §1 (`[v×]`, Markley & Crassidis 2014).
#[must_use]
pub fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// The paper's `Rot(θ)` (algorithms.md §1): `exp(−[θ×])`, the passive rotation of a frame by +θ
/// (rad).
#[must_use]
pub fn rot(theta_rad: &Vector3<f64>) -> Matrix3<f64> {
    let angle = theta_rad.norm();
    let k = skew(theta_rad);
    let (a, b) = if angle < SMALL_ANGLE_RAD {
        (1.0 - angle * angle / 6.0, 0.5 - angle * angle / 24.0)
    } else {
        (
            libm::sin(angle) / angle,
            (1.0 - libm::cos(angle)) / (angle * angle),
        )
    };
    // exp(-K) = I - a K + b K^2
    Matrix3::identity() - k * a + k * k * b
}

/// Inverse of [`rot`]: the rotation vector θ (rad, |θ| ≤ π) with `Rot(θ) = m`.
///
/// `m` should be a proper rotation; the result for anything else is the rotation vector of
/// the quaternion extracted from it (Shepperd's method), which is the nearest sensible answer.
#[must_use]
pub fn rotvec_from_rot(m: &Matrix3<f64>) -> Vector3<f64> {
    Quat::from_dcm(m).rotation_vector_rad()
}

/// Scalar-last attitude quaternion `[x, y, z, w]` with `A(q) = Rot(θ e)`.
///
/// The layout is fixed (`#[repr(C)]`, four `f64`), so it is also the telemetry layout.
/// Shuster/Markley convention: algorithms.md §1, docs/conventions.md; wire layout docs/icd.md §3.2.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(C)]
pub struct Quat {
    /// Vector part, x.
    /// `e_x sin(θ/2)` (algorithms.md §1).
    pub x: f64,
    /// Vector part, y.
    /// `e_y sin(θ/2)` (algorithms.md §1).
    pub y: f64,
    /// Vector part, z.
    /// `e_z sin(θ/2)` (algorithms.md §1).
    pub z: f64,
    /// Scalar part `cos(θ/2)`.
    /// algorithms.md §1.
    pub w: f64,
}

impl Default for Quat {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Quat {
    /// The identity attitude.
    /// `A = I` (algorithms.md §1).
    pub const IDENTITY: Quat = Quat {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 1.0,
    };

    /// Build from a vector part and a scalar part (no normalisation).
    /// Project choice (not in the paper): a `const` constructor for tables and tests.
    #[must_use]
    pub const fn new(x: f64, y: f64, z: f64, w: f64) -> Self {
        Self { x, y, z, w }
    }

    /// Vector part.
    /// `q_v` of algorithms.md §1.
    #[must_use]
    pub fn vector(&self) -> Vector3<f64> {
        Vector3::new(self.x, self.y, self.z)
    }

    /// The quaternion of `Rot(θ)` for a rotation vector θ (rad). Exact for any angle.
    /// `q = [e sin(θ/2); cos(θ/2)]` (algorithms.md §1); a series below 1e-8 rad (algorithms.md §2).
    #[must_use]
    pub fn from_rotation_vector(theta_rad: &Vector3<f64>) -> Self {
        let angle = theta_rad.norm();
        let half = 0.5 * angle;
        let s = if angle < SMALL_ANGLE_RAD {
            0.5 - angle * angle / 48.0
        } else {
            libm::sin(half) / angle
        };
        Self::new(
            theta_rad.x * s,
            theta_rad.y * s,
            theta_rad.z * s,
            libm::cos(half),
        )
    }

    /// Rotation vector θ (rad) of this quaternion, `|θ| ≤ π` (the `q_4 ≥ 0` representative).
    /// The "rotvec" inverse of algorithms.md §1: `2 atan2(|q_v|, q_4) q_v/|q_v|`.
    #[must_use]
    pub fn rotation_vector_rad(&self) -> Vector3<f64> {
        let q = self.canonical();
        let v = q.vector();
        let vn = v.norm();
        if vn < SMALL_ANGLE_RAD {
            // 2 atan2(|v|, w)/|v| -> 2/w for small |v|
            let w = if q.w > 0.0 { q.w } else { 1.0 };
            return v * (2.0 / w);
        }
        v * (2.0 * libm::atan2(vn, q.w) / vn)
    }

    /// Norm `|q|`.
    /// Project choice (not in the paper): used to renormalise after composition.
    #[must_use]
    pub fn norm(&self) -> f64 {
        libm::sqrt(self.x * self.x + self.y * self.y + self.z * self.z + self.w * self.w)
    }

    /// Unit-norm copy with `w ≥ 0`; the identity if the norm is zero or not finite.
    /// Forcing `q_4 ≥ 0` follows algorithms.md §1 ("Treat q and −q as equal").
    #[must_use]
    pub fn normalized(&self) -> Self {
        let n = self.norm();
        if !(n.is_finite() && n > 0.0) {
            return Self::IDENTITY;
        }
        Self::new(self.x / n, self.y / n, self.z / n, self.w / n).canonical()
    }

    /// The same attitude with `w ≥ 0`.
    /// algorithms.md §1: `q` and `−q` are the same attitude.
    #[must_use]
    pub fn canonical(&self) -> Self {
        if self.w < 0.0 {
            Self::new(-self.x, -self.y, -self.z, -self.w)
        } else {
            *self
        }
    }

    /// Inverse (conjugate) of a unit quaternion: `A(q⁻¹) = A(q)ᵀ`.
    /// algorithms.md §1 (Shuster/Markley quaternion algebra).
    #[must_use]
    pub fn conjugate(&self) -> Self {
        Self::new(-self.x, -self.y, -self.z, self.w)
    }

    /// Natural-order product `self ⊗ rhs`, with `A(p ⊗ q) = A(p) A(q)`.
    /// algorithms.md §1 ("natural-order" product; Markley & Crassidis 2014, Lefferts, Markley &
    /// Shuster 1982).
    #[must_use]
    pub fn compose(&self, rhs: &Quat) -> Self {
        let pv = self.vector();
        let qv = rhs.vector();
        let v = qv * self.w + pv * rhs.w - pv.cross(&qv);
        Self::new(v.x, v.y, v.z, self.w * rhs.w - pv.dot(&qv))
    }

    /// Attitude matrix `A(q) = (q₄² − |q_v|²) I + 2 q_v q_vᵀ − 2 q₄ [q_v×]`.
    /// algorithms.md §1 (equals the paper's `Rot(θ e)`).
    #[must_use]
    pub fn to_dcm(&self) -> Matrix3<f64> {
        let v = self.vector();
        Matrix3::identity() * (self.w * self.w - v.dot(&v)) + v * v.transpose() * 2.0
            - skew(&v) * (2.0 * self.w)
    }

    /// Quaternion of an attitude matrix (Shepperd's method; robust for every angle).
    #[must_use]
    pub fn from_dcm(m: &Matrix3<f64>) -> Self {
        // A(q) = Rot: A[0][1] = 2(xy + wz), A[1][0] = 2(xy − wz), etc.
        let m00 = m.m11;
        let m11 = m.m22;
        let m22 = m.m33;
        let tr = m00 + m11 + m22;
        let q = if tr >= m00 && tr >= m11 && tr >= m22 {
            let w4 = 2.0 * libm::sqrt(1.0 + tr);
            Self::new(
                (m.m23 - m.m32) / w4,
                (m.m31 - m.m13) / w4,
                (m.m12 - m.m21) / w4,
                0.25 * w4,
            )
        } else if m00 >= m11 && m00 >= m22 {
            let x4 = 2.0 * libm::sqrt(1.0 + 2.0 * m00 - tr);
            Self::new(
                0.25 * x4,
                (m.m12 + m.m21) / x4,
                (m.m13 + m.m31) / x4,
                (m.m23 - m.m32) / x4,
            )
        } else if m11 >= m22 {
            let y4 = 2.0 * libm::sqrt(1.0 + 2.0 * m11 - tr);
            Self::new(
                (m.m12 + m.m21) / y4,
                0.25 * y4,
                (m.m23 + m.m32) / y4,
                (m.m31 - m.m13) / y4,
            )
        } else {
            let z4 = 2.0 * libm::sqrt(1.0 + 2.0 * m22 - tr);
            Self::new(
                (m.m13 + m.m31) / z4,
                (m.m23 + m.m32) / z4,
                0.25 * z4,
                (m.m12 - m.m21) / z4,
            )
        };
        q.normalized()
    }

    /// Every component finite.
    /// Project choice (not in the paper): the input validation of every sensor rejects NaN.
    #[must_use]
    pub fn is_finite(&self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.z.is_finite() && self.w.is_finite()
    }

    /// Angle (rad) of the rotation taking `other` to `self` (0..π).
    /// Project choice (not in the paper): the slew-completion and test metric.
    #[must_use]
    pub fn angle_to_rad(&self, other: &Quat) -> f64 {
        self.compose(&other.conjugate())
            .rotation_vector_rad()
            .norm()
    }
}

/// Small-angle error vector δθ (rad) with `A_true = Rot(δθ) A_est` (the filter's error state).
/// The error-state convention of algorithms.md §1 and docs/conventions.md ("Attitude errors").
#[must_use]
pub fn attitude_error_rad(q_true: &Quat, q_est: &Quat) -> Vector3<f64> {
    q_true.compose(&q_est.conjugate()).rotation_vector_rad()
}

/// Matrix is orthonormal within `tol` (max-abs of `MᵀM − I`) with determinant within `tol` of +1.
/// The table check of docs/tables.md (Table 1 alignment: orthonormal to 1e-6, det +1).
#[must_use]
pub fn is_proper_rotation(m: &Matrix3<f64>, tol: f64) -> bool {
    let e = m.transpose() * m - Matrix3::identity();
    let max = e.iter().fold(0.0_f64, |acc, x| acc.max(x.abs()));
    m.iter().all(|x| x.is_finite()) && max <= tol && (m.determinant() - 1.0).abs() <= tol
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: &Matrix3<f64>, b: &Matrix3<f64>, tol: f64) -> bool {
        (a - b).iter().all(|x| x.abs() <= tol)
    }

    #[test]
    fn rot_is_exp_of_minus_skew() {
        let th = Vector3::new(0.3, -0.2, 0.9);
        let m = rot(&th);
        // Passive: the rotation axis is unchanged, and Rot(θ) = R_active(θ)^T.
        assert!((m * th - th).norm() < 1e-14);
        let active = nalgebra::Rotation3::from_scaled_axis(th);
        assert!(close(&m, &active.matrix().transpose(), 1e-14));
    }

    #[test]
    fn rot_about_z_matches_paper_form() {
        // Paper eq. 3 for θ = φ e_z: the first row is [cos φ, sin φ, 0].
        let phi: f64 = 0.25;
        let m = rot(&Vector3::new(0.0, 0.0, phi));
        assert!((m.m11 - phi.cos()).abs() < 1e-15);
        assert!((m.m12 - phi.sin()).abs() < 1e-15);
        assert!((m.m21 + phi.sin()).abs() < 1e-15);
    }

    #[test]
    fn quaternion_matches_rot_and_composes() {
        let a = Vector3::new(0.1, 0.7, -0.4);
        let b = Vector3::new(-1.2, 0.3, 0.5);
        let qa = Quat::from_rotation_vector(&a);
        let qb = Quat::from_rotation_vector(&b);
        assert!(close(&qa.to_dcm(), &rot(&a), 1e-14));
        assert!(close(
            &qa.compose(&qb).to_dcm(),
            &(rot(&a) * rot(&b)),
            1e-14
        ));
        let back = Quat::from_dcm(&rot(&a)).rotation_vector_rad();
        assert!((back - a).norm() < 1e-13);
    }

    #[test]
    fn inverse_near_pi_and_zero() {
        for th in [
            Vector3::new(0.0, 0.0, 3.1),
            Vector3::new(1e-12, -2e-12, 0.0),
            Vector3::new(2.0, -2.0, 0.5),
        ] {
            let back = rotvec_from_rot(&rot(&th));
            assert!((back - th).norm() < 1e-9, "{th:?} -> {back:?}");
        }
    }

    #[test]
    fn small_angle_identity() {
        let th = Vector3::new(2e-5, -1e-5, 3e-5);
        let approx = Matrix3::identity() - skew(&th) + skew(&th) * skew(&th) * 0.5;
        assert!(close(&rot(&th), &approx, 1e-14));
    }
}
