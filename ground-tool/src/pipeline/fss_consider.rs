//! # The FSS transfer function as a consider parameter of FFCAL
//!
//! Why: the FSS error that depends on the Sun's place in the field (the transfer function;
//! the paper's inherent 0.022° after calibration) is smooth over the field. A scale error or a
//! cubic term moves every 8° cell the same way, so the cells are not independent, and the
//! per-cell weights of `calibrate::alignment_data` (each cell one observation with the declared
//! systematic σ) understate the alignment error it leaves: over 20 seeds, each with its own
//! drawn transfer function, FSS1 / FSS2 NEES 3.9 / 4.6 with 3 expected, and tails to 25.
//!
//! When the operator declares the 1σ spreads of the transfer-function coefficients (metadata
//! `fss_transfer_function_sigma`, the Adcole model of algorithms.md §4: per head a null offset,
//! a scale factor, a cyclic reticle term of known pitch and unknown phase, the Snell cross-axis
//! term `α β²/E³` and the edge term `α³/E³`, `E` = 32°), FFCAL's stage 2 measures on the run's
//! own data how each coefficient moves the alignments: one Gauss–Newton pass from the converged
//! solution with every Sun direction of that FSS moved by the coefficient's 1σ term gives the
//! sensitivity column `s_k`, and `Σ s_k s_kᵀ` is added to the covariance (Schmidt's consider
//! covariance: the coefficients are not estimated, their uncertainty is carried). The weights
//! are left as they are; what the covariance then says is what the Sun's path through this
//! run's field leaves of an error of the declared kind.

use anyhow::Context;
use nalgebra::{DMatrix, DVector, Vector3};

use crate::calibration::alignment::{
    ffcal, AlignmentData, FfcalConfig, FfcalSolution, SensorObservation, SensorSpec,
};
use crate::RAD_PER_ARCSEC;

/// The declared spreads (`metadata.json` `fss_transfer_function_sigma`) and what each means as
/// a head-angle error at 1σ (`HeadSpread::one_sigma_terms`): defined with the run folder
/// (`gro_reference::run_folder`), the one definition the simulator writes.
pub use gro_reference::run_folder::{HeadSpread, TransferSpreads, UnitSpread};

/// A sensor-frame Sun direction with `d_alpha`, `d_beta` (rad) added to its head angles
/// (`α = atan2(x, z)`, `β = atan2(y, z)`, the FSS convention of fsw_core::raw).
fn moved(d: &Vector3<f64>, d_alpha: f64, d_beta: f64) -> Vector3<f64> {
    let a = d.x.atan2(d.z) + d_alpha;
    let b = d.y.atan2(d.z) + d_beta;
    Vector3::new(a.tan(), b.tan(), 1.0).normalize()
}

/// The solution's corrections stacked (arcsec, 3 per sensor).
fn stacked_theta(sol: &FfcalSolution) -> DVector<f64> {
    let mut v = DVector::zeros(3 * sol.sensors.len());
    for (j, s) in sol.sensors.iter().enumerate() {
        for i in 0..3 {
            v[3 * j + i] = s.theta_acs_arcsec[i];
        }
    }
    v
}

/// `Σ s_k s_kᵀ` (arcsec², the sensors' order) over every declared coefficient of every FSS in
/// `sensors` (matched by id), each `s_k` the change of one Gauss–Newton pass of FFCAL from
/// `sensors` (which must hold the converged alignments) when that FSS's Sun directions move
/// by the coefficient's 1σ term. Zero when nothing is declared.
///
/// # Errors
/// An FFCAL pass that fails (the unperturbed one does not, so this means a degenerate
/// perturbation, which is reported rather than ignored).
pub fn consider_covariance(
    sensors: &[SensorSpec],
    data: &AlignmentData,
    cfg: &FfcalConfig,
    spreads: &TransferSpreads,
) -> anyhow::Result<DMatrix<f64>> {
    let n = 3 * sensors.len();
    let mut cov = DMatrix::zeros(n, n);
    // One pass is the linear sensitivity (the start is the solution): accept it as final.
    let one_pass = FfcalConfig {
        max_iterations: 1,
        convergence_arcsec: f64::MAX,
        ..*cfg
    };
    let mut base: Option<DVector<f64>> = None;
    let mut obs: Vec<SensorObservation> = Vec::new();
    for (j, spec) in sensors.iter().enumerate() {
        let Some(spread) = spreads.get(&spec.id) else {
            continue;
        };
        for (head, h) in [(0usize, &spread.alpha), (1, &spread.beta)] {
            if !h.any() {
                continue;
            }
            for k in 0..6 {
                let mut pert = AlignmentData::with_capacity(data.epoch_count(), 4);
                let mut any = false;
                for epoch in data.epochs() {
                    obs.clear();
                    for o in epoch {
                        let mut o = *o;
                        if o.sensor == j {
                            let d = &o.dir_sensor;
                            let (a, b) = (d.x.atan2(d.z), d.y.atan2(d.z));
                            let (own, other) = if head == 0 { (a, b) } else { (b, a) };
                            let delta = h.one_sigma_terms(own, other)[k] * RAD_PER_ARCSEC;
                            any |= delta != 0.0;
                            o.dir_sensor = if head == 0 {
                                moved(d, delta, 0.0)
                            } else {
                                moved(d, 0.0, delta)
                            };
                        }
                        obs.push(o);
                    }
                    pert.push_epoch(&obs)
                        .context("FSS consider: a moved Sun direction is not usable")?;
                }
                if !any {
                    continue;
                }
                let b = match &base {
                    Some(b) => b.clone(),
                    None => {
                        let b = stacked_theta(&ffcal(sensors, data, &one_pass)?);
                        base = Some(b.clone());
                        b
                    }
                };
                let s = stacked_theta(&ffcal(sensors, &pert, &one_pass)?) - b;
                cov += &s * s.transpose();
            }
        }
    }
    Ok(cov)
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;

    /// A moved direction has exactly the head angles asked for.
    #[test]
    fn moved_changes_one_head_angle() {
        let d = Vector3::new(0.2_f64.tan(), (-0.1_f64).tan(), 1.0).normalize();
        let m = moved(&d, 1e-4, 0.0);
        assert!((m.x.atan2(m.z) - 0.2001).abs() < 1e-12);
        assert!((m.y.atan2(m.z) + 0.1).abs() < 1e-12);
    }

    /// A Sun held at the FSS boresight with a 10″ α-offset spread: the consider covariance is
    /// 100 arcsec² about the sensor's y axis (an α shift is a rotation about y), nothing on x,
    /// nothing about the Sun line, and nothing for the tracker.
    #[test]
    fn offset_spread_at_one_sun_position_is_a_rotation_about_y() {
        use fsw_core::attitude::rot;
        use nalgebra::Matrix3;
        let mut data = AlignmentData::new();
        let stars = [
            Vector3::new(0.03, 0.01, 1.0).normalize(),
            Vector3::new(-0.02, 0.04, 1.0).normalize(),
        ];
        let m_fhst = rot(&Vector3::new(0.0, std::f64::consts::FRAC_PI_2, 0.0));
        let sun = Vector3::z();
        for k in 0..20 {
            let a = rot(&Vector3::new(
                0.1 * f64::from(k),
                -0.05 * f64::from(k),
                0.02,
            ));
            let obs = [
                SensorObservation {
                    sensor: 0,
                    dir_sensor: stars[0],
                    dir_eci: a.transpose() * m_fhst * stars[0],
                    sigma_rad: 5.0 * RAD_PER_ARCSEC,
                },
                SensorObservation {
                    sensor: 0,
                    dir_sensor: stars[1],
                    dir_eci: a.transpose() * m_fhst * stars[1],
                    sigma_rad: 5.0 * RAD_PER_ARCSEC,
                },
                SensorObservation {
                    sensor: 1,
                    dir_sensor: sun,
                    dir_eci: a.transpose() * sun,
                    sigma_rad: 10.0 * RAD_PER_ARCSEC,
                },
            ];
            data.push_epoch(&obs).unwrap();
        }
        let mut fhst = SensorSpec::new("FHST1", m_fhst, 0.01);
        fhst.prior_cov_acs_arcsec2 = Matrix3::identity() * 1e-4;
        let sensors = [fhst, SensorSpec::new("FSS1", Matrix3::identity(), 1800.0)];
        let mut spreads = TransferSpreads::new();
        spreads.insert(
            "FSS1".into(),
            UnitSpread {
                alpha: HeadSpread {
                    offset_arcsec: 10.0,
                    ..HeadSpread::default()
                },
                ..UnitSpread::default()
            },
        );
        let cfg = FfcalConfig {
            require_relative_observability: false,
            ..FfcalConfig::default()
        };
        let c = consider_covariance(&sensors, &data, &cfg, &spreads).unwrap();
        assert!((c[(4, 4)] - 100.0).abs() < 1.0, "about y: {}", c[(4, 4)]);
        assert!(c[(3, 3)] < 0.01 && c[(5, 5)] < 0.01, "{c}");
        assert!(c.view((0, 0), (3, 3)).abs().max() < 0.01, "{c}");
        // Nothing declared for this unit: nothing added.
        let none = consider_covariance(&sensors, &data, &cfg, &TransferSpreads::new()).unwrap();
        assert_eq!(none.abs().max(), 0.0);
    }
}
