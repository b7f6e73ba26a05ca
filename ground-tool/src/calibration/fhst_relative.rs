//! # FHST2 relative to FHST1 from every star, batches tied by the gyro
//!
//! Why: FFCAL's dot products use only the epochs at which both trackers hold a star at the
//! same instant, and one dot product per epoch sees a tracker's roll about its boresight only
//! through the star's offset along a single direction. The NASA Standard FHST follows one
//! star at a time and breaks track every few minutes, so each tracker sees many stars at
//! different places of its 8° field, most of them not at the same time as the other
//! tracker's. `docs/algorithms.md` §6 says the epoch's vectors may be "simultaneous, or
//! propagated to a common time with the gyro"; this module does that for batches of holds
//! and slews (`pipeline::star_batches`), in the equivalent form of §10: the batch attitude is
//! a nuisance parameter eliminated by its Schur complement, which equals using the complete
//! set of independent dot products of the batch with their exact covariance [SCN82; S90; §10].
//!
//! ## Model (first order, workspace conventions, `docs/conventions.md`)
//! Per sample of tracker `k` in batch `b` at time `t` (`τ = t − t_b`):
//! * `a = A_ref(t) u`: the catalog direction `u` (ECI) in ACS with the reference attitude,
//!   the batch centre's attitude carried to `t` by the gyro;
//! * `m = M_k s`: the measured direction in ACS with the flown alignment;
//! * true attitude `Rot(δ_b + δ̇_b τ) A_ref(t)`, true alignments `M_1` (the reference: its
//!   absolute alignment cannot be told from the attitude) and `Rot(θ) M_2`;
//! * so `m − a = a × (δ_b + δ̇_b τ − [k = 2] θ) + noise`, projected on two axes normal to `a`.
//!
//! The rate nuisance `δ̇_b` takes the batch's gyro bias error (a constant bias error makes
//! the reference drift linearly), so the result does not depend on the bias used.
//!
//! Where the gyro turned the body within a batch (a slew, or a hold that crept), the reference
//! also carries the flown gyro's scale and misalignment error: `m − a` gains `a × J(t) vec(δM)`
//! ([`GyroScalePartial`], `pipeline::star_batches`). δM is one for the whole span, so it is
//! estimated as nine more global parameters (ppm) with the IRU chain's prior σ
//! [`PRIOR_DM_PPM`]; θ's covariance is then the marginal one, with δM's uncertainty in it
//! ([`FhstRelativeAlignment::gyro_scale_arcsec2`]). Without such samples δM stays at its prior
//! and θ is exactly the 3-parameter fit's.
//!
//! ## Solution
//! Weighted least squares in arcsec, the 6 nuisance parameters of each batch eliminated
//! batch by batch (a 6×6 solve each: linear in the number of samples). Samples whose
//! normalised residual exceeds [`OUTLIER_CHI2`] (2 degrees of freedom) are dropped and the
//! fit repeated. The covariance is the inverse reduced normal matrix — the Cramér–Rao bound
//! of the model with the declared noise — scaled by the a-posteriori variance factor
//! `s² = χ²/dof`. Why scaled both ways: the declared FHST σ is a per-magnitude figure
//! (the paper's 8–24″) while the true noise also depends on the place in the field; with
//! 10⁴ samples `s²` is known to ≈ 1 %, and the Monte Carlo NEES is right only with it
//! (`tests/src/bin/calibration_mc.rs`).

use nalgebra::{Matrix3, Matrix6, SMatrix, SVector, Vector3, Vector6};
use serde::Serialize;
use thiserror::Error;

use crate::calibration::iru_chain::PRIOR_DM_PPM;
use crate::ARCSEC_PER_RAD;
use fsw_core::sensor::SensorId;

/// Normalised squared residual (2 degrees of freedom) above which a sample is an outlier:
/// 25 ⇔ p ≈ 4e-6, so a clean run of 10⁴ samples loses none on average.
pub const OUTLIER_CHI2: f64 = 25.0;
/// Prior 1σ of a batch attitude correction (arcsec): only keeps a batch's nuisance block
/// invertible when a tracker saw no star in it.
const NUISANCE_ANGLE_PRIOR_ARCSEC: f64 = 3600.0;
/// Prior 1σ of a batch attitude drift (arcsec per [`RATE_UNIT_S`]).
const NUISANCE_RATE_PRIOR_ARCSEC: f64 = 3600.0;
/// Time unit of the drift nuisance (s), to keep the normal matrix well scaled.
const RATE_UNIT_S: f64 = 100.0;
/// Outlier passes.
const MAX_PASSES: usize = 4;
/// Global parameters: θ (3, arcsec) and the flown gyro's `vec(δM)` (9, ppm).
const NG: usize = 12;
/// A vector of the global parameters.
type Global = SVector<f64, NG>;
/// Nuisance × global block.
type NuisanceGlobal = SMatrix<f64, 6, NG>;

/// `∂ε/∂vec(δM)`: the reference attitude's error (rad, body axes at the sample time) per unit
/// of the flown gyro's scale and misalignment error δM (column-major vec), accumulated by the
/// gyro from the batch centre (`pipeline::star_batches`).
pub type GyroScalePartial = SMatrix<f64, 3, 9>;

/// One identified star sample of a batch.
#[derive(Clone, Debug, PartialEq)]
pub struct BatchStarSample {
    /// The tracker: FHST1 (the reference) or FHST2.
    pub tracker: SensorId,
    /// Batch index (`0..n_batches`).
    pub batch: usize,
    /// Time from the batch centre (s).
    pub dt_s: f64,
    /// Catalog direction in ACS with the batch's reference attitude at the sample time.
    pub ref_acs: Vector3<f64>,
    /// Measured direction in ACS with the flown alignment.
    pub meas_acs: Vector3<f64>,
    /// Declared 1σ per axis (rad).
    pub sigma_rad: f64,
    /// The reference lacks the orbital aberration (no definitive orbit at this time): the
    /// covariance then includes its effect as a consider term ([`UNCORRECTED_ORBIT_SPEED_KM_PER_S`]).
    pub aberration_uncorrected: bool,
    /// The reference's error per unit of the flown gyro's δM ([`GyroScalePartial`]) in a batch
    /// through a turn (a slew, or a hold that crept); `None` where the gyro did not turn the
    /// body. The fit estimates δM with its prior σ [`PRIOR_DM_PPM`] along with θ.
    pub gyro_scale_partial: Option<Box<GyroScalePartial>>,
}

/// Orbital speed assumed for references without orbital aberration (km/s): circular LEO at
/// the lowest altitudes. Why a consider term: without the orbit the ground cannot correct the
/// ≤ 5.4″ shift, and where each tracker holds one star for a whole batch the fit turns it
/// into tens of arcsec on a roll axis (`docs/investigations.md`: 38.6″ against a σ of 6″).
pub const UNCORRECTED_ORBIT_SPEED_KM_PER_S: f64 = 7.8;
/// Speed of light (km/s).
const C_KM_PER_S: f64 = 299_792.458;

/// Why the relative alignment could not be estimated.
#[derive(Debug, Error, PartialEq)]
pub enum RelativeAlignmentError {
    /// Fewer batches with stars in both trackers than needed.
    #[error("only {0} hold batches have identified stars in both FHSTs; at least {1} are needed (longer inertial holds with both trackers tracking)")]
    TooFewBatches(usize, usize),
    /// The reduced normal matrix is singular (e.g. every star at one place in the field).
    #[error("the FHST2-relative-to-FHST1 alignment is unobservable from the hold data (reduced normal matrix singular): the trackers need stars at different places of their fields")]
    Unobservable,
    /// A sample's batch index is out of range or a vector is not finite.
    #[error("malformed sample {0}: batch index out of range or non-finite vector")]
    MalformedSample(usize),
}

/// The estimate.
#[derive(Clone, Debug, Serialize)]
pub struct FhstRelativeAlignment {
    /// θ of FHST2 relative to FHST1, ACS (arcsec): `M_2,true ≈ Rot(θ) M_2` with FHST1 held.
    pub theta_acs_arcsec: Vector3<f64>,
    /// Covariance of θ (arcsec²): the bound scaled by `s²`, plus the consider term of the
    /// uncorrected orbital aberration.
    pub covariance_arcsec2: Matrix3<f64>,
    /// Consider covariance of the orbital aberration left in the references (arcsec²): each
    /// batch's unknown orbital velocity isotropic with speed
    /// [`UNCORRECTED_ORBIT_SPEED_KM_PER_S`], batches independent; zero when every sample had
    /// its orbit.
    pub aberration_consider_arcsec2: Matrix3<f64>,
    /// The part of the covariance from the flown gyro's δM, estimated with the alignment from
    /// the turning batches' stars (prior σ [`PRIOR_DM_PPM`] per element, one δM for the whole
    /// span): the covariance minus what it would be with δM known (arcsec², scaled by `s²`);
    /// zero without turning batches.
    pub gyro_scale_arcsec2: Matrix3<f64>,
    /// The bound of the model with the declared noise, unscaled (arcsec²).
    pub crb_covariance_arcsec2: Matrix3<f64>,
    /// A-posteriori variance factor χ²/dof.
    pub variance_factor: f64,
    /// Batches used (stars in both trackers).
    pub batches: usize,
    /// Samples used, per tracker.
    pub samples: [usize; 2],
    /// Samples dropped as outliers.
    pub rejected: usize,
    /// Residual RMS per tracker (arcsec per axis) after the fit.
    pub residual_rms_arcsec: [f64; 2],
}

/// Accumulated normal equations of one batch.
#[derive(Clone, Copy)]
struct BatchNormal {
    nbb: Matrix6<f64>,
    nbg: NuisanceGlobal,
    vb: Vector6<f64>,
    ngg: SMatrix<f64, NG, NG>,
    vg: Global,
    count: [usize; 2],
}

impl BatchNormal {
    fn new() -> Self {
        let mut nbb = Matrix6::zeros();
        for j in 0..3 {
            nbb[(j, j)] = NUISANCE_ANGLE_PRIOR_ARCSEC.powi(-2);
            nbb[(j + 3, j + 3)] = NUISANCE_RATE_PRIOR_ARCSEC.powi(-2);
        }
        Self {
            nbb,
            nbg: NuisanceGlobal::zeros(),
            vb: Vector6::zeros(),
            ngg: SMatrix::zeros(),
            vg: Global::zeros(),
            count: [0; 2],
        }
    }

    /// Add one sample's rows. Why the two forms: a hold's sample has no δM partials, and
    /// skipping their zeros keeps 10⁶ samples at the 3-parameter cost.
    fn add(&mut self, s: &BatchStarSample) {
        let w = (s.sigma_rad * ARCSEC_PER_RAD).powi(-2);
        self.count[s.tracker.index()] += 1;
        for (hb, hg, y) in sample_rows(s) {
            self.nbb += hb * hb.transpose() * w;
            self.vb += hb * (y * w);
            if s.gyro_scale_partial.is_some() {
                self.nbg += hb * hg.transpose() * w;
                self.ngg += hg * hg.transpose() * w;
                self.vg += hg * (y * w);
            } else {
                let h3 = hg.fixed_rows::<3>(0);
                let mut nbg = self.nbg.fixed_columns_mut::<3>(0);
                nbg += hb * h3.transpose() * w;
                let mut ngg = self.ngg.fixed_view_mut::<3, 3>(0, 0);
                ngg += h3 * h3.transpose() * w;
                let mut vg = self.vg.fixed_rows_mut::<3>(0);
                vg += h3 * (y * w);
            }
        }
    }
}

/// Two unit vectors normal to `a` (any pair: the fit is invariant to the choice).
fn tangent_basis(a: &Vector3<f64>) -> [Vector3<f64>; 2] {
    let helper = if a.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let e1 = a.cross(&helper).normalize();
    [e1, a.cross(&e1)]
}

/// Rows of one sample: (nuisance partials, global partials (θ, then δM per ppm), residual
/// arcsec).
fn sample_rows(s: &BatchStarSample) -> [(Vector6<f64>, Global, f64); 2] {
    let a = s.ref_acs;
    let r = (s.meas_acs - a) * ARCSEC_PER_RAD;
    let tau = s.dt_s / RATE_UNIT_S;
    tangent_basis(&a).map(|e| {
        // e·(a × x) = (e × a)·x
        let g = e.cross(&a);
        let mut hb = Vector6::zeros();
        for j in 0..3 {
            hb[j] = g[j];
            hb[j + 3] = g[j] * tau;
        }
        let mut hg = Global::zeros();
        if s.tracker == SensorId::Fhst2 {
            hg.fixed_rows_mut::<3>(0).copy_from(&-g);
        }
        // The reference's δM error enters as the batch's attitude error does: `g·(J vec δM)`.
        if let Some(j) = s.gyro_scale_partial.as_deref() {
            hg.fixed_rows_mut::<9>(3)
                .copy_from(&(j.transpose() * g * (ARCSEC_PER_RAD * 1e-6)));
        }
        (hb, hg, e.dot(&r))
    })
}

/// Estimate FHST2's alignment relative to FHST1 from hold batches (module doc).
///
/// # Errors
/// [`RelativeAlignmentError`]: malformed samples, too few batches with both trackers
/// (`min_batches`), or an unobservable geometry.
pub fn estimate_relative_alignment(
    samples: &[BatchStarSample],
    n_batches: usize,
    min_batches: usize,
) -> Result<FhstRelativeAlignment, RelativeAlignmentError> {
    for (i, s) in samples.iter().enumerate() {
        let finite = s
            .ref_acs
            .iter()
            .chain(s.meas_acs.iter())
            .all(|x| x.is_finite())
            && s.dt_s.is_finite()
            && s.sigma_rad.is_finite()
            && s.sigma_rad > 0.0;
        if s.batch >= n_batches || !s.tracker.is_fhst() || !finite {
            return Err(RelativeAlignmentError::MalformedSample(i));
        }
    }
    let mut used = vec![true; samples.len()];
    let mut nuisance = vec![Vector6::zeros(); n_batches];
    for pass in 0..MAX_PASSES {
        let mut batches = vec![BatchNormal::new(); n_batches];
        for (s, _) in samples.iter().zip(&used).filter(|(_, u)| **u) {
            batches[s.batch].add(s);
        }
        // Reduced system of θ. A batch without both trackers informs θ only through the
        // weak nuisance prior: left out.
        // δM's prior (ppm): the flown `G`'s uncertainty; without turned samples it keeps the
        // δM block at its prior and θ exactly the 3-parameter fit's.
        let mut ngg = SMatrix::<f64, NG, NG>::zeros();
        for j in 3..NG {
            ngg[(j, j)] = PRIOR_DM_PPM.powi(-2);
        }
        let mut vg = Global::zeros();
        let mut inverses = vec![None; n_batches];
        let mut good_batches = 0;
        for (k, bn) in batches.iter().enumerate() {
            if bn.count[0] == 0 || bn.count[1] == 0 {
                continue;
            }
            let Some(inv) = bn.nbb.try_inverse() else {
                continue;
            };
            good_batches += 1;
            // θ rows of this batch with the nuisance eliminated:
            // N_gg − N_gb N_bb⁻¹ N_bg, v_g − N_gb N_bb⁻¹ v_b.
            ngg += bn.ngg - bn.nbg.transpose() * inv * bn.nbg;
            vg += bn.vg - bn.nbg.transpose() * inv * bn.vb;
            inverses[k] = Some(inv);
        }
        if good_batches < min_batches {
            return Err(RelativeAlignmentError::TooFewBatches(
                good_batches,
                min_batches,
            ));
        }
        let full = ngg
            .cholesky()
            .map(|c| c.inverse())
            .ok_or(RelativeAlignmentError::Unobservable)?;
        let global = full * vg;
        let theta: Vector3<f64> = global.fixed_rows::<3>(0).into();
        let crb: Matrix3<f64> = full.fixed_view::<3, 3>(0, 0).into();
        for (k, bn) in batches.iter().enumerate() {
            nuisance[k] =
                inverses[k].map_or(Vector6::zeros(), |inv| inv * (bn.vb - bn.nbg * global));
        }
        // Residuals, variance factor, outliers.
        let mut chi2 = 0.0;
        let mut rows = 0usize;
        let mut z2 = vec![0.0; samples.len()];
        for (i, s) in samples.iter().enumerate() {
            if inverses[s.batch].is_none() {
                continue;
            }
            let w = (s.sigma_rad * ARCSEC_PER_RAD).powi(-2);
            let mut zz = 0.0;
            for (hb, hg, y) in sample_rows(s) {
                let e = y - hb.dot(&nuisance[s.batch]) - hg.dot(&global);
                zz += e * e * w;
            }
            z2[i] = zz;
            if used[i] {
                chi2 += zz;
                rows += 2;
            }
        }
        let turned = samples.iter().any(|s| s.gyro_scale_partial.is_some());
        let dof = rows
            .saturating_sub(6 * good_batches + if turned { NG } else { 3 })
            .max(1);
        let variance_factor = chi2 / dof as f64;
        let cov = crb * variance_factor;
        let keep: Vec<bool> = samples
            .iter()
            .zip(&z2)
            .zip(&used)
            .map(|((s, z), u)| {
                if inverses[s.batch].is_none() {
                    *u
                } else {
                    z / variance_factor <= OUTLIER_CHI2
                }
            })
            .collect();
        let changed = keep != used;
        // The outlier set settles in one or two passes; the last pass is kept as it is.
        if !changed || pass + 1 == MAX_PASSES {
            let mut samples_used = [0usize; 2];
            let mut sum2 = [0.0; 2];
            for (i, s) in samples.iter().enumerate() {
                if used[i] && inverses[s.batch].is_some() {
                    samples_used[s.tracker.index()] += 1;
                    for (hb, hg, y) in sample_rows(s) {
                        let e = y - hb.dot(&nuisance[s.batch]) - hg.dot(&global);
                        sum2[s.tracker.index()] += e * e;
                    }
                }
            }
            let rms = |t: usize| (sum2[t] / (2 * samples_used[t].max(1)) as f64).sqrt();
            let consider = aberration_consider(samples, &used, &batches, &inverses, &full);
            // θ's covariance with δM known: the inverse of the θ block of the reduced matrix.
            let known = ngg
                .fixed_view::<3, 3>(0, 0)
                .into_owned()
                .try_inverse()
                .unwrap_or(crb);
            return Ok(FhstRelativeAlignment {
                theta_acs_arcsec: theta,
                covariance_arcsec2: cov + consider,
                aberration_consider_arcsec2: consider,
                gyro_scale_arcsec2: (crb - known) * variance_factor,
                crb_covariance_arcsec2: crb,
                variance_factor,
                batches: good_batches,
                samples: samples_used,
                rejected: used.iter().filter(|u| !**u).count(),
                residual_rms_arcsec: [rms(0), rms(1)],
            });
        }
        used = keep;
    }
    Err(RelativeAlignmentError::Unobservable)
}

/// The consider covariance of the orbital aberration missing from flagged samples: the
/// estimate is linear in the residuals, so an unknown velocity `v_b` per batch moves it by
/// `K_b v_b` with `K_b = C Σ (h_g − N_gbᵀ N_bb⁻¹ h_b) w ∂y/∂v`, `∂y/∂v = e·(I − a aᵀ)/c`;
/// `Σ_b K_b (V²/3) K_bᵀ`.
fn aberration_consider(
    samples: &[BatchStarSample],
    used: &[bool],
    batches: &[BatchNormal],
    inverses: &[Option<Matrix6<f64>>],
    full: &SMatrix<f64, NG, NG>,
) -> Matrix3<f64> {
    let mut d = vec![SMatrix::<f64, NG, 3>::zeros(); batches.len()];
    let mut any = false;
    for (s, _) in samples
        .iter()
        .zip(used)
        .filter(|(s, u)| **u && s.aberration_uncorrected)
    {
        let (Some(inv), Some(bn)) = (inverses[s.batch], batches.get(s.batch)) else {
            continue;
        };
        any = true;
        let w = (s.sigma_rad * ARCSEC_PER_RAD).powi(-2);
        let a = s.ref_acs;
        let basis = tangent_basis(&a);
        for ((hb, hg, _), e) in sample_rows(s).into_iter().zip(basis) {
            let g = hg - bn.nbg.transpose() * (inv * hb);
            // ∂y/∂v_j (arcsec per unit of V): e·(u_j − (u_j·a) a) V/c.
            let dy_dv = (e - a * e.dot(&a))
                * (UNCORRECTED_ORBIT_SPEED_KM_PER_S / C_KM_PER_S)
                * ARCSEC_PER_RAD;
            d[s.batch] += g * dy_dv.transpose() * w;
        }
    }
    if !any {
        return Matrix3::zeros();
    }
    d.iter().fold(Matrix3::zeros(), |acc, db| {
        let k = (full * db).fixed_rows::<3>(0).into_owned();
        acc + k * k.transpose() / 3.0
    })
}

/// Fuse the relative estimate with the flown alignments' priors: `x = (θ₁, θ₂)` (ACS,
/// arcsec, from the flown alignments) with prior `blkdiag(P₁, P₂)` and the measurement
/// `θ₂ − θ₁ = z` (covariance `R`). Why: the prior fixes the common rotation the data cannot
/// see, as FFCAL's does (§6), so both trackers move and the adjustment can keep the OBC's
/// frame. Returns `(θ₁, θ₂, covariance 6×6)`.
#[must_use]
pub fn fuse_with_prior(
    relative: &FhstRelativeAlignment,
    prior1_arcsec2: &Matrix3<f64>,
    prior2_arcsec2: &Matrix3<f64>,
) -> Option<(Vector3<f64>, Vector3<f64>, nalgebra::Matrix6<f64>)> {
    // S = P₁ + P₂ + R; K₁ = −P₁ S⁻¹, K₂ = P₂ S⁻¹.
    let s = prior1_arcsec2 + prior2_arcsec2 + relative.covariance_arcsec2;
    let s_inv = s.cholesky()?.inverse();
    let k1 = -prior1_arcsec2 * s_inv;
    let k2 = prior2_arcsec2 * s_inv;
    let z = relative.theta_acs_arcsec;
    let mut p0 = Matrix6::zeros();
    p0.fixed_view_mut::<3, 3>(0, 0).copy_from(prior1_arcsec2);
    p0.fixed_view_mut::<3, 3>(3, 3).copy_from(prior2_arcsec2);
    let mut k = nalgebra::Matrix6x3::zeros();
    k.fixed_view_mut::<3, 3>(0, 0).copy_from(&k1);
    k.fixed_view_mut::<3, 3>(3, 0).copy_from(&k2);
    let mut h = nalgebra::Matrix3x6::zeros();
    h.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(-Matrix3::identity()));
    h.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&Matrix3::identity());
    let p = (Matrix6::identity() - k * h) * p0;
    let p = (p + p.transpose()) * 0.5;
    Some((k1 * z, k2 * z, p))
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;
    use fsw_core::attitude::rot;

    fn synth(theta_true_arcsec: Vector3<f64>, seed: u64) -> (Vec<BatchStarSample>, usize) {
        let n = 12;
        (
            crate::synth::fhst_batch_samples(theta_true_arcsec, n, 6, 100, seed),
            n,
        )
    }

    #[test]
    fn recovers_relative_alignment_with_consistent_covariance() {
        let truth = Vector3::new(40.0, -25.0, 70.0);
        let mut nees = 0.0;
        let runs = 20;
        for seed in 0..runs {
            let (s, n) = synth(truth, seed);
            let est = estimate_relative_alignment(&s, n, 3).expect("estimate");
            let e = est.theta_acs_arcsec - truth;
            let c = est.covariance_arcsec2;
            nees += (e.transpose() * c.try_inverse().expect("cov") * e)[(0, 0)];
            assert!(est.variance_factor > 0.8 && est.variance_factor < 1.2);
            assert!(est.rejected <= 2, "rejected {}", est.rejected);
        }
        let mean = nees / runs as f64;
        // χ²₃ mean 3; over 20 runs the mean has σ ≈ 0.55.
        assert!(mean > 1.5 && mean < 4.8, "mean NEES {mean}");
    }

    #[test]
    fn outlier_is_dropped_and_errors_are_reported() {
        let (mut s, n) = synth(Vector3::new(10.0, 10.0, 10.0), 7);
        s[5].meas_acs = rot(&Vector3::new(0.0, 0.01, 0.0)) * s[5].meas_acs;
        let est = estimate_relative_alignment(&s, n, 3).expect("estimate");
        assert_eq!(est.rejected, 1);
        assert_eq!(
            estimate_relative_alignment(&s, n, 50).unwrap_err(),
            RelativeAlignmentError::TooFewBatches(12, 50)
        );
        s[0].batch = n;
        assert_eq!(
            estimate_relative_alignment(&s, n, 3).unwrap_err(),
            RelativeAlignmentError::MalformedSample(0)
        );
    }

    /// Without the orbit the covariance grows by the consider term, and the term bounds what
    /// a real uncorrected aberration does to the estimate.
    #[test]
    fn uncorrected_aberration_enters_as_consider_covariance() {
        let truth = Vector3::new(40.0, -25.0, 70.0);
        let (clean, n) = synth(truth, 3);
        let base = estimate_relative_alignment(&clean, n, 3).expect("estimate");
        assert_eq!(base.aberration_consider_arcsec2, Matrix3::zeros());
        // The same data with an uncorrected orbital velocity of 7.5 km/s per batch (its
        // direction changing from batch to batch), flagged.
        let mut flagged = clean.clone();
        for s in &mut flagged {
            let phi = s.batch as f64 * 0.9;
            let v = Vector3::new(phi.cos(), phi.sin(), 0.3).normalize() * (7.5 / C_KM_PER_S);
            s.meas_acs = (s.meas_acs + (v - s.meas_acs * v.dot(&s.meas_acs))).normalize();
            s.aberration_uncorrected = true;
        }
        let est = estimate_relative_alignment(&flagged, n, 3).expect("estimate");
        let c = est.aberration_consider_arcsec2;
        assert!(c.trace() > 0.0);
        assert!(
            (est.covariance_arcsec2 - est.crb_covariance_arcsec2 * est.variance_factor - c).norm()
                < 1e-9 * c.norm()
        );
        // The shift the aberration caused is within 3σ of the consider term on every axis.
        let shift = est.theta_acs_arcsec - base.theta_acs_arcsec;
        for i in 0..3 {
            assert!(
                shift[i].abs() < 3.0 * c[(i, i)].sqrt() + 1e-6,
                "axis {i}: shift {shift:?}, consider σ {:?}",
                c.diagonal().map(f64::sqrt)
            );
        }
    }

    #[test]
    fn fusion_moves_both_trackers_by_the_measured_difference() {
        let rel = FhstRelativeAlignment {
            theta_acs_arcsec: Vector3::new(30.0, -12.0, 6.0),
            covariance_arcsec2: Matrix3::identity() * 1e-4,
            aberration_consider_arcsec2: Matrix3::zeros(),
            gyro_scale_arcsec2: Matrix3::zeros(),
            crb_covariance_arcsec2: Matrix3::identity() * 1e-4,
            variance_factor: 1.0,
            batches: 10,
            samples: [1, 1],
            rejected: 0,
            residual_rms_arcsec: [0.0; 2],
        };
        let p = Matrix3::identity() * 3600.0;
        let (t1, t2, cov) = fuse_with_prior(&rel, &p, &p).expect("fuse");
        assert!((t2 - t1 - rel.theta_acs_arcsec).norm() < 1e-3);
        // Equal priors: each tracker takes half.
        assert!((t1 + t2).norm() < 1e-6);
        // The common rotation keeps half the prior variance.
        let c = |a: usize, b: usize| cov[(a, b)];
        assert!(((c(0, 0) + c(3, 3) + 2.0 * c(0, 3)) / 4.0 - 1800.0).abs() < 1.0);
    }
}
