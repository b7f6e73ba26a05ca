//! # Optimal single-frame attitude from weighted vector pairs (Wahba's problem)
//!
//! Why: the ground needs sensor-only attitudes for the IRU calibration end points (paper §5,
//! "attitudes from FHST/FSS data at both ends of each maneuver") and for checking FFCAL.
//!
//! Method: minimise `L(A) = ½ Σ wᵢ |bᵢ − A rᵢ|²` with `wᵢ = 1/σᵢ²`. With the attitude
//! profile matrix `B = Σ wᵢ bᵢ rᵢᵀ = U S Vᵀ` (SVD), the optimum is
//! `A = U diag(1, 1, det U det V) Vᵀ` (Markley's SVD method; equivalent to Davenport's
//! q-method and QUEST but without the characteristic-polynomial root search).
//!
//! Covariance: with the error state of the workspace, `A_true = Rot(δθ) Â` (δθ in body/ACS
//! axes, `docs/algorithms.md` §1), and the QUEST measurement model (`bᵢ` errors isotropic
//! about `bᵢ` with covariance `σᵢ² (I − bᵢbᵢᵀ)`), the Fisher information of δθ is
//! `F = Σ (I − b̂ᵢ b̂ᵢᵀ)/σᵢ²` with `b̂ᵢ = Â rᵢ`, and `P_θθ = F⁻¹` (Shuster's QUEST covariance,
//! exact to first order). [`AttitudeSolution::cov_acs_rad2`] holds it.

use nalgebra::{Matrix3, Vector3};
use thiserror::Error;

use fsw_core::attitude::Quat;

/// One measured direction and its reference direction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VectorPair {
    /// Measured unit vector in body (ACS) axes, `b = M_AS s` (normalised on use).
    pub dir_acs: Vector3<f64>,
    /// Reference unit vector in inertial (ECI) axes (normalised on use).
    pub dir_eci: Vector3<f64>,
    /// 1σ angular error of the measured direction per tangent axis (rad).
    pub sigma_rad: f64,
}

/// Why an attitude could not be computed.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum AttitudeError {
    /// Fewer than two vectors.
    #[error("attitude needs at least 2 vector pairs, got {got}: add a second sensor observation")]
    TooFewVectors {
        /// Number given.
        got: usize,
    },
    /// A σ is not strictly positive and finite, or a vector is zero/non-finite.
    #[error("vector pair {index} is invalid (zero/non-finite direction or σ ≤ 0): fix the input")]
    InvalidPair {
        /// Index of the bad pair.
        index: usize,
    },
    /// All vectors (nearly) parallel: rotation about them is unobservable.
    #[error("vectors are (nearly) parallel: information condition {condition:.3e}; rotation about the common direction is unobservable, add a non-parallel vector")]
    Unobservable {
        /// Smallest/largest eigenvalue of the attitude information matrix.
        condition: f64,
    },
}

/// Optimal attitude, its quaternion and its covariance.
#[derive(Clone, Debug, PartialEq)]
pub struct AttitudeSolution {
    /// `A = m_acs_from_eci`, the attitude matrix.
    pub m_acs_from_eci: Matrix3<f64>,
    /// The same attitude as a scalar-last quaternion (`A(q) = A`).
    pub q_acs_from_eci: Quat,
    /// Covariance of δθ (rad², ACS axes) with `A_true = Rot(δθ) Â`.
    pub cov_acs_rad2: Matrix3<f64>,
    /// `Σ |bᵢ − Â rᵢ|²/σᵢ²`; χ² with `2n − 3` degrees of freedom under the model.
    pub chi2: f64,
    /// Degrees of freedom of `chi2`.
    pub dof: usize,
}

/// Whether a measured and a reference direction of norms `norm_a`, `norm_b` with the
/// measurement σ `sigma_rad` can enter a fit: both norms and σ finite and positive.
#[must_use]
pub fn usable_pair(norm_a: f64, norm_b: f64, sigma_rad: f64) -> bool {
    [norm_a, norm_b, sigma_rad]
        .iter()
        .all(|x| x.is_finite() && *x > 0.0)
}

/// Solve Wahba's problem for the given pairs (see the module doc).
///
/// # Errors
/// [`AttitudeError`] when there are fewer than two pairs, a pair is invalid, or the vectors
/// are (nearly) parallel.
pub fn solve_attitude(pairs: &[VectorPair]) -> Result<AttitudeSolution, AttitudeError> {
    if pairs.len() < 2 {
        return Err(AttitudeError::TooFewVectors { got: pairs.len() });
    }
    let mut profile = Matrix3::zeros();
    let mut normalized = Vec::with_capacity(pairs.len());
    for (index, p) in pairs.iter().enumerate() {
        let (nb, nr) = (p.dir_acs.norm(), p.dir_eci.norm());
        if !usable_pair(nb, nr, p.sigma_rad) {
            return Err(AttitudeError::InvalidPair { index });
        }
        let b = p.dir_acs / nb;
        let r = p.dir_eci / nr;
        let w = 1.0 / (p.sigma_rad * p.sigma_rad);
        profile += b * r.transpose() * w;
        normalized.push((b, r, w));
    }
    let svd = profile.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err(AttitudeError::Unobservable { condition: 0.0 });
    };
    let d = u.determinant() * v_t.determinant();
    let m_acs_from_eci = u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d.signum())) * v_t;

    let mut information = Matrix3::zeros();
    let mut chi2 = 0.0;
    for (b, r, w) in &normalized {
        let b_hat = m_acs_from_eci * r;
        information += (Matrix3::identity() - b_hat * b_hat.transpose()) * *w;
        chi2 += (b - b_hat).norm_squared() * w;
    }
    let eig = information.symmetric_eigen();
    let max = eig.eigenvalues.max();
    let min = eig.eigenvalues.min();
    let condition = if max > 0.0 { min / max } else { 0.0 };
    if condition < 1e-10 {
        return Err(AttitudeError::Unobservable { condition });
    }
    let Some(cov_acs_rad2) = information.try_inverse() else {
        return Err(AttitudeError::Unobservable { condition });
    };
    Ok(AttitudeSolution {
        m_acs_from_eci,
        q_acs_from_eci: Quat::from_dcm(&m_acs_from_eci),
        cov_acs_rad2: (cov_acs_rad2 + cov_acs_rad2.transpose()) * 0.5,
        chi2,
        dof: 2 * pairs.len() - 3,
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;
    use crate::synth::{perturb_unit_vector, Rng};
    use fsw_core::attitude::{rot, rotvec_from_rot};

    fn pairs_for(
        rng: &mut Rng,
        m_acs_from_eci: &Matrix3<f64>,
        sigmas_rad: &[f64],
    ) -> Vec<VectorPair> {
        sigmas_rad
            .iter()
            .map(|&sigma_rad| {
                let dir_eci = rng.unit_vector();
                let dir_acs = perturb_unit_vector(rng, &(m_acs_from_eci * dir_eci), sigma_rad);
                VectorPair {
                    dir_acs,
                    dir_eci,
                    sigma_rad,
                }
            })
            .collect()
    }

    #[test]
    fn noise_free_recovers_attitude_exactly() {
        let mut rng = Rng::new(11);
        for _ in 0..20 {
            let a = rng.rotation();
            let pairs = pairs_for(&mut rng, &a, &[0.0, 0.0, 0.0])
                .into_iter()
                .map(|p| VectorPair {
                    sigma_rad: 1e-5,
                    ..p
                })
                .collect::<Vec<_>>();
            let sol = solve_attitude(&pairs).unwrap();
            assert!((sol.m_acs_from_eci - a).norm() < 1e-12);
            assert!((sol.q_acs_from_eci.to_dcm() - a).norm() < 1e-12);
        }
    }

    /// The covariance is the one of the left body-frame error `A_true = Rot(δθ) Â`: the
    /// normalised errors over a Monte Carlo must have unit variance (tolerance: 3000 draws of a
    /// χ²₃ has a relative σ of 1.5 % on its mean; 8 % allows > 5σ).
    #[test]
    fn covariance_is_consistent_monte_carlo() {
        let mut rng = Rng::new(5);
        let sig = [10e-6, 30e-6, 200e-6];
        let mut sum = 0.0;
        let n = 3000;
        for _ in 0..n {
            let a = rng.rotation();
            let pairs = pairs_for(&mut rng, &a, &sig);
            let sol = solve_attitude(&pairs).unwrap();
            let dtheta = rotvec_from_rot(&(a * sol.m_acs_from_eci.transpose()));
            // convention check: A_true = Rot(δθ) Â
            assert!((rot(&dtheta) * sol.m_acs_from_eci - a).norm() < 1e-12);
            sum += dtheta.dot(&(sol.cov_acs_rad2.try_inverse().unwrap() * dtheta));
        }
        let mean = sum / f64::from(n) / 3.0;
        assert!(
            (mean - 1.0).abs() < 0.08,
            "normalised error variance {mean}"
        );
    }

    #[test]
    fn parallel_vectors_are_unobservable() {
        let v = Vector3::new(0.0, 0.0, 1.0);
        let pairs = [
            VectorPair {
                dir_acs: v,
                dir_eci: v,
                sigma_rad: 1e-5,
            },
            VectorPair {
                dir_acs: v,
                dir_eci: v,
                sigma_rad: 1e-5,
            },
        ];
        assert!(matches!(
            solve_attitude(&pairs),
            Err(AttitudeError::Unobservable { .. })
        ));
        assert!(matches!(
            solve_attitude(&pairs[..1]),
            Err(AttitudeError::TooFewVectors { got: 1 })
        ));
    }

    /// Two orthogonal vectors of equal σ: the QUEST covariance is σ² diag(1, 1, ½) in the frame
    /// (b1, b2, b1×b2) (textbook closed form).
    #[test]
    fn two_vector_closed_form() {
        let sigma = 1e-4;
        let pairs = [
            VectorPair {
                dir_acs: Vector3::x(),
                dir_eci: Vector3::x(),
                sigma_rad: sigma,
            },
            VectorPair {
                dir_acs: Vector3::y(),
                dir_eci: Vector3::y(),
                sigma_rad: sigma,
            },
        ];
        let sol = solve_attitude(&pairs).unwrap();
        let expect = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, 0.5)) * sigma * sigma;
        assert!((sol.cov_acs_rad2 - expect).norm() < 1e-20);
    }
}
