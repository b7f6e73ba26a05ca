//! # Adjustment that preserves the OBC's two-tracker attitude (paper appendix)
//!
//! Why: FFCAL determines only *relative* alignments (a common rotation of all sensors is
//! unobservable, [`super::alignment`]). The OBC computes its fine attitude from the two FHSTs,
//! and the science instruments were aligned to that attitude before launch. So the paper
//! applies one common rotation to all calibrated alignments such that the frame the OBC builds
//! from the two FHST boresights is the same with the new alignments as with the prelaunch
//! ones: the relative alignments are corrected, the OBC attitude is not moved.
//!
//! ## Construction of `M_AN` (columns = the N-frame axes in ACS)
//! With `b₁ = M_AS(FHST1) e_z`, `b₂ = M_AS(FHST2) e_z` (boresights in ACS):
//! - [`BoresightFrame::Bisector`] (default): `n₁ = unit(b₁ + b₂)`, `n₃ = unit(b₁ × b₂)`,
//!   `n₂ = n₃ × n₁`. Symmetric in the two trackers: a change of the separation angle is
//!   split equally between them. The published rotation vectors are consistent with this
//!   choice (both boresights move by ≈13.7″ in opposite senses about `n₃`; see
//!   [`crate::paper`]).
//! - [`BoresightFrame::Fhst1Boresight`]: `n₁ = b₁`, `n₂ = unit(b₁ × b₂)`, `n₃ = n₁ × n₂`
//!   (FHST1 is the master: its boresight never moves, FHST2 absorbs the whole separation change).
//!
//! ## Adjustment
//! With `M_AN` from the prelaunch alignments and `M_AN'` from the calibrated ones,
//! `R = M_AN M_AN'ᵀ` maps the calibrated frame back onto the prelaunch one (`R M_AN' = M_AN`),
//! and every sensor gets `M_AS'' = R M_AS'`. In the paper's notation `R = Rot(θ_adj)` with
//! `θ_adj = rotvec(R)` in ACS; the adjusted FHST frame is then identical to the prelaunch one,
//! and all relative alignments `M_AS''ᵢᵀ M_AS''ⱼ = M_AS'ᵢᵀ M_AS'ⱼ` are kept.

use nalgebra::{Matrix3, Vector3};
use serde::Serialize;
use thiserror::Error;

use fsw_core::attitude::rotvec_from_rot;

use crate::ARCSEC_PER_RAD;

/// Which frame the OBC builds from the two FHST boresights (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Default)]
pub enum BoresightFrame {
    /// `n₁` along the bisector of the boresights, `n₃` normal to their plane (paper-consistent).
    #[default]
    Bisector,
    /// `n₁` along the FHST1 boresight, `n₂` normal to the boresight plane.
    Fhst1Boresight,
}

/// Why the adjustment could not be computed.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum AdjustError {
    /// The FHST boresights are (nearly) parallel, so they do not define a frame.
    #[error("FHST boresights are {angle_deg:.4}° apart: too close to parallel to define the OBC frame (need ≳ 0.1°); check the FHST alignments")]
    ParallelBoresights {
        /// Angle between them (deg).
        angle_deg: f64,
    },
    /// Prelaunch and calibrated lists have different lengths, or the FHST indices are bad.
    #[error("alignment lists do not match ({prelaunch} prelaunch, {calibrated} calibrated) or FHST index out of range: pass the same sensors in the same order")]
    Mismatch {
        /// Number of prelaunch alignments.
        prelaunch: usize,
        /// Number of calibrated alignments.
        calibrated: usize,
    },
}

/// `M_AN` (N-frame → ACS) from two FHST alignments.
///
/// # Errors
/// [`AdjustError::ParallelBoresights`] when the boresights are within ~0.1° of each other.
pub fn m_acs_from_n(
    m_acs_from_fhst1: &Matrix3<f64>,
    m_acs_from_fhst2: &Matrix3<f64>,
    construction: BoresightFrame,
) -> Result<Matrix3<f64>, AdjustError> {
    let b1 = m_acs_from_fhst1.column(2).into_owned().normalize();
    let b2 = m_acs_from_fhst2.column(2).into_owned().normalize();
    let cross = b1.cross(&b2);
    if cross.norm() < 2e-3 {
        return Err(AdjustError::ParallelBoresights {
            angle_deg: cross.norm().atan2(b1.dot(&b2)).to_degrees(),
        });
    }
    let (n1, n2, n3): (Vector3<f64>, Vector3<f64>, Vector3<f64>) = match construction {
        BoresightFrame::Bisector => {
            let n1 = (b1 + b2).normalize();
            let n3 = cross.normalize();
            (n1, n3.cross(&n1), n3)
        }
        BoresightFrame::Fhst1Boresight => {
            let n2 = cross.normalize();
            (b1, n2, b1.cross(&n2))
        }
    };
    Ok(Matrix3::from_columns(&[n1, n2, n3]))
}

/// Result of the adjustment.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Adjustment {
    /// Frame construction used.
    pub construction: BoresightFrame,
    /// `R = M_AN M_AN'ᵀ`, applied on the left of every calibrated alignment.
    pub m_adjust: Matrix3<f64>,
    /// `rotvec(R)` (ACS, arcsec): the common rotation removed from the calibration.
    pub theta_adjust_acs_arcsec: Vector3<f64>,
    /// Adjusted alignments `M_AS'' = R M_AS'`, in input order.
    pub m_acs_from_sensor_adjusted: Vec<Matrix3<f64>>,
}

/// Adjust calibrated alignments so that the FHST boresight frame is the prelaunch one.
///
/// `fhst1`, `fhst2` index the two FHSTs in both lists.
///
/// # Errors
/// [`AdjustError`] for mismatched lists, bad indices or parallel boresights.
pub fn preserve_obc_attitude(
    m_acs_from_sensor_prelaunch: &[Matrix3<f64>],
    m_acs_from_sensor_calibrated: &[Matrix3<f64>],
    fhst1: usize,
    fhst2: usize,
    construction: BoresightFrame,
) -> Result<Adjustment, AdjustError> {
    let mismatch = AdjustError::Mismatch {
        prelaunch: m_acs_from_sensor_prelaunch.len(),
        calibrated: m_acs_from_sensor_calibrated.len(),
    };
    if m_acs_from_sensor_prelaunch.len() != m_acs_from_sensor_calibrated.len() || fhst1 == fhst2 {
        return Err(mismatch);
    }
    let (Some(p1), Some(p2), Some(c1), Some(c2)) = (
        m_acs_from_sensor_prelaunch.get(fhst1),
        m_acs_from_sensor_prelaunch.get(fhst2),
        m_acs_from_sensor_calibrated.get(fhst1),
        m_acs_from_sensor_calibrated.get(fhst2),
    ) else {
        return Err(mismatch);
    };
    let m_an_pre = m_acs_from_n(p1, p2, construction)?;
    let m_an_cal = m_acs_from_n(c1, c2, construction)?;
    let m_adjust = m_an_pre * m_an_cal.transpose();
    Ok(Adjustment {
        construction,
        m_adjust,
        theta_adjust_acs_arcsec: rotvec_from_rot(&m_adjust) * ARCSEC_PER_RAD,
        m_acs_from_sensor_adjusted: m_acs_from_sensor_calibrated
            .iter()
            .map(|m| m_adjust * m)
            .collect(),
    })
}

/// Angle (arcsec) of the rotation between the FHST frames of two alignment sets: 0 when the
/// OBC attitude is preserved.
///
/// # Errors
/// [`AdjustError::ParallelBoresights`].
pub fn m_an_rotation_arcsec(
    fhst_pair_a: (&Matrix3<f64>, &Matrix3<f64>),
    fhst_pair_b: (&Matrix3<f64>, &Matrix3<f64>),
    construction: BoresightFrame,
) -> Result<f64, AdjustError> {
    let a = m_acs_from_n(fhst_pair_a.0, fhst_pair_a.1, construction)?;
    let b = m_acs_from_n(fhst_pair_b.0, fhst_pair_b.1, construction)?;
    Ok(rotvec_from_rot(&(b * a.transpose())).norm() * ARCSEC_PER_RAD)
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;
    use crate::paper::PaperData;
    use crate::RAD_PER_ARCSEC;
    use fsw_core::attitude::rot;

    fn prelaunch() -> Vec<Matrix3<f64>> {
        let p = PaperData::embedded().unwrap();
        ["FHST1", "FHST2", "FSS1", "FSS2"]
            .iter()
            .map(|id| p.prelaunch(id).unwrap())
            .collect()
    }

    /// The adjusted FHST frame equals the prelaunch one to 1e-12 (rounding of 3×3 products),
    /// for both constructions, while every relative alignment of the calibration is kept.
    #[test]
    fn val_adjust_preserves_fhst_frame_and_relative_alignments() {
        let pre = prelaunch();
        let thetas = [
            Vector3::new(41.7, -41.7, -13.8),
            Vector3::new(56.4, 56.3, 13.7),
            Vector3::new(236.0, -407.0, -562.0),
            Vector3::new(-153.0, 2.0, 110.0),
        ];
        // calibrated = true relative alignments + an arbitrary common rotation (unobservable)
        let common = rot(&(Vector3::new(30.0, -70.0, 20.0) * RAD_PER_ARCSEC));
        let cal: Vec<Matrix3<f64>> = pre
            .iter()
            .zip(&thetas)
            .map(|(m, t)| common * rot(&(t * RAD_PER_ARCSEC)) * m)
            .collect();
        for construction in [BoresightFrame::Bisector, BoresightFrame::Fhst1Boresight] {
            let adj = preserve_obc_attitude(&pre, &cal, 0, 1, construction).unwrap();
            let before = m_acs_from_n(&pre[0], &pre[1], construction).unwrap();
            let after = m_acs_from_n(
                &adj.m_acs_from_sensor_adjusted[0],
                &adj.m_acs_from_sensor_adjusted[1],
                construction,
            )
            .unwrap();
            assert!(
                (after - before).amax() < 1e-12,
                "{construction:?}: {}",
                (after - before).amax()
            );
            for i in 0..4 {
                for j in 0..4 {
                    // m_i_from_j = M_iᵀ M_j is invariant under a common left rotation
                    let rel_cal = cal[i].transpose() * cal[j];
                    let rel_adj = adj.m_acs_from_sensor_adjusted[i].transpose()
                        * adj.m_acs_from_sensor_adjusted[j];
                    assert!((rel_cal - rel_adj).amax() < 1e-12);
                }
            }
        }
        // Fhst1Boresight keeps the FHST1 boresight exactly; Bisector keeps the bisector.
        let adj = preserve_obc_attitude(&pre, &cal, 0, 1, BoresightFrame::Fhst1Boresight).unwrap();
        assert!((adj.m_acs_from_sensor_adjusted[0].column(2) - pre[0].column(2)).amax() < 1e-12);
    }

    #[test]
    fn adjust_rejects_bad_input() {
        let pre = prelaunch();
        assert!(matches!(
            preserve_obc_attitude(&pre, &pre[..3], 0, 1, BoresightFrame::Bisector),
            Err(AdjustError::Mismatch { .. })
        ));
        let same = [pre[0], pre[0]];
        assert!(matches!(
            preserve_obc_attitude(&same, &same, 0, 1, BoresightFrame::Bisector),
            Err(AdjustError::ParallelBoresights { .. })
        ));
    }
}
