//! # FFCAL: attitude-independent sensor alignment calibration
//!
//! Why: the paper (§4) calibrated the FHST and FSS alignments in flight from six inertial
//! attitudes, because prelaunch alignments were off by up to 0.2° (FSS1). The method is
//! Shuster, Chitre & Niebur (1982) [SCN82], optionally with the optimal within-epoch weights
//! of Shuster et al. (1990) / Bierman & Shuster (1988) (`docs/algorithms.md` §6, §10).
//!
//! ## Model
//! At each epoch several sensors measure unit vectors `sᵢ` (sensor frame) of objects whose
//! inertial directions `rᵢ` are known. With the current alignments `Mᵢ = m_acs_from_sensorᵢ`,
//! `bᵢ = Mᵢ sᵢ`. Dot products do not depend on attitude:
//!
//! `yᵢⱼ = rᵢ·rⱼ − bᵢ·bⱼ = (bᵢ × bⱼ)·(θⱼ − θᵢ) + vᵢⱼ`,
//!
//! where the true alignments are `Rot(θᵢ) Mᵢ` (θ in ACS axes, paper eq. 4, the workspace
//! convention `fsw_core::attitude::rot`). States are the total corrections from prelaunch
//! `x = [θ₁; …; θ_N]` in **arcsec**, with the prelaunch alignments as prior (`x̄ = 0`,
//! covariance `P₀ = blkdiag(P₀ᵢ)`, arcsec²).
//!
//! ## Weighting
//! - [`Weighting::Shuster1982`]: every pair of distinct sensors at an epoch is one scalar
//!   measurement with variance `(σᵢ² + σⱼ²)(1 − (bᵢ·bⱼ)²)`, treated as independent. Pairs sharing
//!   a vector are in fact correlated, so the formal covariance `N⁻¹` is wrong; the reported
//!   covariance is the sandwich `N⁻¹ (Σ HᵀWRWH + P₀⁻¹) N⁻¹` with the true `R` (§6).
//! - [`Weighting::Optimal1990`]: per epoch the `2n − 3` independent dot products
//!   (anchor pair `(a, b)` = most orthogonal pair, then `(a, k)`, `(b, k)` for every other `k`)
//!   with their full covariance `R_t` (`cov(vᵢⱼ, vᵢₖ) = bⱼᵀRᵢbₖ`, `Rᵢ = σᵢ²(I − bᵢbᵢᵀ)`),
//!   `W_t = R_t⁻¹`. Under linearisation this attains the Cramér–Rao bound of the vector data
//!   with the epoch attitudes as nuisance parameters (§10); [`cramer_rao_information`]
//!   computes that bound independently and the tests check the equality.
//!
//! ## Solution
//! Gauss–Newton: accumulate the normal equations over the epochs (streaming: one `3N × 3N`
//! matrix, no stacked `H`), solve `(P₀⁻¹ + N) δ = g − P₀⁻¹ x`, update `Mᵢ ← Rot(δᵢ) Mᵢ`, repeat
//! until `max |δ| < tol`. The data normal matrix always has three (near-)zero eigenvalues:
//! a common rotation of all sensors is unobservable and only the prior fixes it
//! ([`ObservabilityReport`]).

use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use serde::Serialize;
use thiserror::Error;

use fsw_core::attitude::{rot, rotvec_from_rot};

use crate::attitude::quest::usable_pair;
use crate::linalg::{spd_inverse, sym_eigen_ascending, sym_pinv};
use crate::{ARCSEC_PER_RAD, RAD_PER_ARCSEC};

/// A sensor to calibrate: its identity, current (prelaunch) alignment and prior.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SensorSpec {
    /// Name, e.g. `FHST1`, `FSS2`.
    pub id: String,
    /// Prelaunch alignment `M_AS` (sensor → ACS; columns are the sensor axes in ACS).
    pub m_acs_from_sensor: Matrix3<f64>,
    /// Prior covariance of the correction θ (ACS axes, arcsec²).
    pub prior_cov_acs_arcsec2: Matrix3<f64>,
}

impl SensorSpec {
    /// Sensor with an isotropic prior of `prior_sigma_arcsec` per ACS axis.
    #[must_use]
    pub fn new(id: &str, m_acs_from_sensor: Matrix3<f64>, prior_sigma_arcsec: f64) -> Self {
        Self {
            id: id.to_owned(),
            m_acs_from_sensor,
            prior_cov_acs_arcsec2: Matrix3::identity() * prior_sigma_arcsec * prior_sigma_arcsec,
        }
    }
}

/// One sensor measurement at an epoch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorObservation {
    /// Index of the sensor in the `sensors` slice given to [`ffcal`].
    pub sensor: usize,
    /// Measured unit vector in the sensor frame.
    pub dir_sensor: Vector3<f64>,
    /// Reference unit vector in ECI (aberration and parallax already applied).
    pub dir_eci: Vector3<f64>,
    /// 1σ measurement error per tangent axis (rad), catalog error included.
    pub sigma_rad: f64,
}

/// Epochs of simultaneous observations, stored flat (one allocation for any data volume).
#[derive(Clone, Debug, Default)]
pub struct AlignmentData {
    observations: Vec<SensorObservation>,
    epoch_ends: Vec<usize>,
}

impl AlignmentData {
    /// Empty data set.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Empty data set with room for `epochs` epochs of `per_epoch` observations.
    #[must_use]
    pub fn with_capacity(epochs: usize, per_epoch: usize) -> Self {
        Self {
            observations: Vec::with_capacity(epochs.saturating_mul(per_epoch)),
            epoch_ends: Vec::with_capacity(epochs),
        }
    }

    /// Add one epoch (normalises the vectors).
    ///
    /// # Errors
    /// [`AlignmentError::TooFewObservations`] for fewer than two observations and
    /// [`AlignmentError::InvalidObservation`] for a zero or non-finite vector or σ ≤ 0.
    pub fn push_epoch(&mut self, observations: &[SensorObservation]) -> Result<(), AlignmentError> {
        let epoch = self.epoch_ends.len();
        if observations.len() < 2 {
            return Err(AlignmentError::TooFewObservations {
                epoch,
                got: observations.len(),
            });
        }
        for (index, o) in observations.iter().enumerate() {
            let usable = usable_pair(o.dir_sensor.norm(), o.dir_eci.norm(), o.sigma_rad);
            if !usable {
                return Err(AlignmentError::InvalidObservation { epoch, index });
            }
        }
        self.observations
            .extend(observations.iter().map(|o| SensorObservation {
                dir_sensor: o.dir_sensor.normalize(),
                dir_eci: o.dir_eci.normalize(),
                ..*o
            }));
        self.epoch_ends.push(self.observations.len());
        Ok(())
    }

    /// Number of epochs.
    #[must_use]
    pub fn epoch_count(&self) -> usize {
        self.epoch_ends.len()
    }

    /// Number of observations.
    #[must_use]
    pub fn observation_count(&self) -> usize {
        self.observations.len()
    }

    /// Observations of epoch `i` (empty if out of range).
    #[must_use]
    pub fn epoch(&self, i: usize) -> &[SensorObservation] {
        let start = if i == 0 {
            0
        } else {
            self.epoch_ends.get(i - 1).copied().unwrap_or(0)
        };
        let end = self.epoch_ends.get(i).copied().unwrap_or(start);
        self.observations.get(start..end).unwrap_or(&[])
    }

    /// The epochs as slices of observations.
    pub fn epochs(&self) -> impl Iterator<Item = &[SensorObservation]> + '_ {
        let mut start = 0;
        self.epoch_ends.iter().map(move |&end| {
            let s = self.observations.get(start..end).unwrap_or(&[]);
            start = end;
            s
        })
    }
}

/// How the dot products are weighted (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum Weighting {
    /// Shuster, Chitre & Niebur 1982: all pairs, scalar weights, sandwich covariance.
    Shuster1982,
    /// Shuster et al. 1990 / Bierman–Shuster 1988: `2n − 3` independent pairs, full `R_t`.
    Optimal1990,
}

/// FFCAL options.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FfcalConfig {
    /// Weighting scheme.
    pub weighting: Weighting,
    /// Maximum Gauss–Newton passes (each pass reads all the data once).
    pub max_iterations: usize,
    /// Converged when the largest correction of a pass is below this (arcsec).
    pub convergence_arcsec: f64,
    /// Fail (instead of returning prior-dominated numbers) when the data leave more than the
    /// three common-rotation directions unobservable.
    pub require_relative_observability: bool,
}

impl Default for FfcalConfig {
    fn default() -> Self {
        Self {
            weighting: Weighting::Optimal1990,
            max_iterations: 10,
            convergence_arcsec: 1e-3,
            require_relative_observability: true,
        }
    }
}

/// Why FFCAL could not produce an answer.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum AlignmentError {
    /// No sensors.
    #[error("no sensors given: FFCAL needs at least two sensors with alignments and priors")]
    NoSensors,
    /// An epoch with fewer than two observations.
    #[error("epoch {epoch} has {got} observation(s): an epoch needs at least 2 simultaneous sensor observations")]
    TooFewObservations {
        /// Epoch index.
        epoch: usize,
        /// Observations in it.
        got: usize,
    },
    /// A zero or non-finite vector or σ ≤ 0.
    #[error(
        "epoch {epoch}, observation {index}: zero/non-finite direction or σ ≤ 0; fix or drop it"
    )]
    InvalidObservation {
        /// Epoch index.
        epoch: usize,
        /// Observation index within the epoch.
        index: usize,
    },
    /// Observation refers to a sensor index outside the sensor list.
    #[error(
        "epoch {epoch} refers to sensor index {sensor} but only {sensors} sensors are defined"
    )]
    UnknownSensor {
        /// Epoch index.
        epoch: usize,
        /// Bad index.
        sensor: usize,
        /// Number of sensors.
        sensors: usize,
    },
    /// A prior covariance is not symmetric positive definite.
    #[error("prior covariance of sensor {sensor} is not positive definite: give a finite σ > 0 per axis")]
    InvalidPrior {
        /// Sensor id.
        sensor: String,
    },
    /// A sensor never appears in a pair with a different sensor.
    #[error("sensor {sensor} is never observed together with another sensor: add epochs in which it and another sensor observe simultaneously")]
    SensorWithoutData {
        /// Sensor id.
        sensor: String,
    },
    /// No data at all.
    #[error("no epochs: FFCAL needs epochs of simultaneous observations")]
    NoEpochs,
    /// The relative alignments are not all observable.
    #[error("{unobservable} direction(s) of the relative alignments are unobservable (eigenvalue/max < {threshold:.0e}); weakest mode beyond the common rotation: {mode}. Add epochs with more varied sensor-pair geometry (different star/Sun positions in the fields of view)")]
    Unobservable {
        /// Number of unobservable directions beyond the 3 common-rotation ones.
        unobservable: usize,
        /// Relative eigenvalue threshold used.
        threshold: f64,
        /// Description of the weakest mode.
        mode: String,
    },
    /// The total normal matrix is singular (should not happen with a valid prior).
    #[error("normal matrix is singular even with the prior: check the priors")]
    Singular,
    /// Gauss–Newton did not converge.
    #[error("Gauss–Newton did not converge in {iterations} passes (last step {last_step_arcsec:.3e} arcsec): the flown alignments may be too far off for the linearisation, or the data inconsistent (misidentified stars, a sensor with wrong flags): inspect the residual plots of the report, or fly with alignments closer to the truth")]
    NotConverged {
        /// Passes made.
        iterations: usize,
        /// Largest correction of the last pass (arcsec).
        last_step_arcsec: f64,
    },
}

/// Per-sensor result.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SensorAlignmentResult {
    /// Sensor id.
    pub id: String,
    /// Prelaunch (input) alignment.
    pub m_acs_from_sensor_prelaunch: Matrix3<f64>,
    /// Calibrated alignment `Rot(θ) M_AS`.
    pub m_acs_from_sensor_calibrated: Matrix3<f64>,
    /// Total correction θ from prelaunch (ACS axes, arcsec): `rotvec(M_cal M_preᵀ)`.
    pub theta_acs_arcsec: Vector3<f64>,
    /// 1σ of θ per ACS axis (arcsec), from the reported covariance.
    pub sigma_acs_arcsec: Vector3<f64>,
    /// RMS angle residual of the pairs involving this sensor with prelaunch alignments (arcsec).
    pub residual_rms_before_arcsec: f64,
    /// The same with the calibrated alignments (arcsec).
    pub residual_rms_after_arcsec: f64,
    /// Number of pairs (with another sensor) behind those RMS values.
    pub residual_pairs: usize,
}

/// Eigen-analysis of the data normal matrix (the "observability report").
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ObservabilityReport {
    /// Eigenvalues of the data-only normal matrix `Σ HᵀWH` (1/arcsec², ascending).
    pub eigenvalues_data_per_arcsec2: Vec<f64>,
    /// Eigenvalues with the prior added (1/arcsec², ascending).
    pub eigenvalues_with_prior_per_arcsec2: Vec<f64>,
    /// Eigenvalues below `threshold × max` (expected: 3, the common rotation).
    pub unobservable_count: usize,
    /// Relative threshold used.
    pub threshold: f64,
    /// Fraction (0..1) of the 3 weakest data eigenvectors that lies in the common-rotation
    /// subspace (`θ₁ = θ₂ = … = θ_N`); ≈ 1 when only the common rotation is unobservable.
    pub weakest_three_in_common_rotation: f64,
    /// The 4th weakest eigenvector (the weakest observable mode), one 3-vector per sensor,
    /// with its eigenvalue: this is the worst-determined relative alignment direction.
    pub weakest_relative_mode: Vec<[f64; 3]>,
    /// Eigenvalue of that mode (1/arcsec²).
    pub weakest_relative_eigenvalue_per_arcsec2: f64,
}

/// FFCAL result.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FfcalSolution {
    /// Weighting used.
    pub weighting: Weighting,
    /// Per-sensor results, in input order.
    pub sensors: Vec<SensorAlignmentResult>,
    /// Covariance of x (arcsec²): sandwich for 1982 weights, `(P₀⁻¹ + N)⁻¹` for optimal ones.
    pub covariance_arcsec2: DMatrix<f64>,
    /// Formal covariance `(P₀⁻¹ + N)⁻¹` (wrong for 1982 weights; kept to show by how much).
    pub formal_covariance_arcsec2: DMatrix<f64>,
    /// Data-only normal matrix `Σ HᵀWH` at the solution (1/arcsec²).
    pub normal_data_per_arcsec2: DMatrix<f64>,
    /// Gauss–Newton passes made.
    pub iterations: usize,
    /// Epochs read per pass.
    pub epochs: usize,
    /// Dot products used for estimation per pass.
    pub pairs_per_pass: usize,
    /// Weighted residual sum of squares at the solution.
    pub chi2: f64,
    /// Observability report.
    pub observability: ObservabilityReport,
}

impl FfcalSolution {
    /// Covariance (arcsec²) of the relative alignment `θ_i − θ_ref`.
    #[must_use]
    pub fn relative_covariance_arcsec2(&self, i: usize, reference: usize) -> Matrix3<f64> {
        let p = &self.covariance_arcsec2;
        let blk = |a: usize, b: usize| -> Matrix3<f64> {
            p.fixed_view::<3, 3>(3 * a, 3 * b).into_owned()
        };
        blk(i, i) + blk(reference, reference) - blk(i, reference) - blk(reference, i)
    }
}

/// Relative eigenvalue threshold under which a direction counts as unobservable.
pub const UNOBSERVABLE_REL_THRESHOLD: f64 = 1e-9;

/// One dot-product measurement inside an epoch (indices local to the epoch).
#[derive(Clone, Copy, Debug)]
struct Pair {
    k: usize,
    l: usize,
    /// Sensor blocks: `+c` in block `sl`, `−c` in block `sk`.
    sk: usize,
    sl: usize,
    /// `y` (arcsec) = (r_k·r_l − b_k·b_l) · ARCSEC_PER_RAD.
    y_arcsec: f64,
    /// `c = b_k × b_l`.
    c: Vector3<f64>,
}

/// Streaming normal-equation accumulator; all scratch reused between epochs.
struct Accumulator {
    n: usize,
    weighting: Weighting,
    normal: Vec<f64>,
    meat: Vec<f64>,
    rhs: Vec<f64>,
    chi2: f64,
    pairs_used: usize,
    resid_sum_sq_arcsec2: Vec<f64>,
    resid_count: Vec<usize>,
    // scratch
    b: Vec<Vector3<f64>>,
    sig2_arcsec2: Vec<f64>,
    pairs: Vec<Pair>,
    placed: Vec<usize>,
    r_cov: Vec<f64>,
    w: Vec<f64>,
    tmp: Vec<f64>,
    chol_l: Vec<f64>,
    chol_li: Vec<f64>,
    kh: Vec<f64>,
}

impl Accumulator {
    /// Add another accumulator's sums into this one.
    fn merge(&mut self, other: &Accumulator) {
        for (a, b) in self.normal.iter_mut().zip(&other.normal) {
            *a += b;
        }
        for (a, b) in self.meat.iter_mut().zip(&other.meat) {
            *a += b;
        }
        for (a, b) in self.rhs.iter_mut().zip(&other.rhs) {
            *a += b;
        }
        for (a, b) in self
            .resid_sum_sq_arcsec2
            .iter_mut()
            .zip(&other.resid_sum_sq_arcsec2)
        {
            *a += b;
        }
        for (a, b) in self.resid_count.iter_mut().zip(&other.resid_count) {
            *a += b;
        }
        self.chi2 += other.chi2;
        self.pairs_used += other.pairs_used;
    }

    fn new(sensors: usize, weighting: Weighting) -> Self {
        let n = 3 * sensors;
        Self {
            n,
            weighting,
            normal: vec![0.0; n * n],
            meat: vec![0.0; n * n],
            rhs: vec![0.0; n],
            chi2: 0.0,
            pairs_used: 0,
            resid_sum_sq_arcsec2: vec![0.0; sensors],
            resid_count: vec![0; sensors],
            b: Vec::new(),
            sig2_arcsec2: Vec::new(),
            pairs: Vec::new(),
            placed: Vec::new(),
            r_cov: Vec::new(),
            w: Vec::new(),
            tmp: Vec::new(),
            chol_l: Vec::new(),
            chol_li: Vec::new(),
            kh: Vec::new(),
        }
    }

    /// `cov(v_p, v_q)` (arcsec²) for the current epoch.
    fn pair_cov(&self, p: &Pair, q: &Pair) -> f64 {
        // v_kl = −(δb_k·b_l + b_k·δb_l); δb independent across observations with
        // covariance σ²(I − bbᵀ).
        let quad = |s: usize, u: &Vector3<f64>, v: &Vector3<f64>| -> f64 {
            let bs = &self.b[s];
            self.sig2_arcsec2[s] * (u.dot(v) - u.dot(bs) * v.dot(bs))
        };
        let mut c = 0.0;
        for (sp, op) in [(p.k, p.l), (p.l, p.k)] {
            for (sq, oq) in [(q.k, q.l), (q.l, q.k)] {
                if sp == sq {
                    c += quad(sp, &self.b[op], &self.b[oq]);
                }
            }
        }
        c
    }

    /// Add `Σ_pq K_pq h_pᵀ h_q` into `buf` (`n × n`, row-major), using `kh` (`m × n`) as
    /// scratch: first `kh = K H` exploiting that each row of `H` has two 3-blocks, then
    /// `buf += Hᵀ (K H)` the same way (≈ 8·m·n flops instead of 36·m²).
    fn add_quadratic(buf: &mut [f64], n: usize, pairs: &[Pair], k_mat: &[f64], kh: &mut Vec<f64>) {
        let m = pairs.len();
        kh.clear();
        kh.resize(m * n, 0.0);
        for (a, row) in kh.chunks_exact_mut(n).enumerate() {
            for (bq, q) in pairs.iter().enumerate() {
                let w = k_mat[a * m + bq];
                if w == 0.0 || q.sk == q.sl {
                    continue;
                }
                for r in 0..3 {
                    row[3 * q.sl + r] += w * q.c[r];
                    row[3 * q.sk + r] -= w * q.c[r];
                }
            }
        }
        for (p, row) in pairs.iter().zip(kh.chunks_exact(n)) {
            if p.sk == p.sl {
                continue;
            }
            for r in 0..3 {
                let cr = p.c[r];
                let dst_l = (3 * p.sl + r) * n;
                for (d, v) in buf[dst_l..dst_l + n].iter_mut().zip(row) {
                    *d += cr * v;
                }
                let dst_k = (3 * p.sk + r) * n;
                for (d, v) in buf[dst_k..dst_k + n].iter_mut().zip(row) {
                    *d -= cr * v;
                }
            }
        }
    }

    fn make_pair(&self, obs: &[SensorObservation], k: usize, l: usize) -> Pair {
        let (bk, bl) = (&self.b[k], &self.b[l]);
        Pair {
            k,
            l,
            sk: obs[k].sensor,
            sl: obs[l].sensor,
            y_arcsec: (obs[k].dir_eci.dot(&obs[l].dir_eci) - bk.dot(bl)) * ARCSEC_PER_RAD,
            c: bk.cross(bl),
        }
    }

    /// One epoch into the normal equations: the vectors in ACS, the residual statistics, the
    /// pairs the weighting uses, their weights, then the sums.
    fn add_epoch(&mut self, obs: &[SensorObservation], m_current: &[Matrix3<f64>]) {
        self.b.clear();
        self.sig2_arcsec2.clear();
        for o in obs {
            self.b.push(m_current[o.sensor] * o.dir_sensor);
            let s = o.sigma_rad * ARCSEC_PER_RAD;
            self.sig2_arcsec2.push(s * s);
        }
        self.residual_statistics(obs);
        self.pairs.clear();
        match self.weighting {
            Weighting::Shuster1982 => self.all_pairs(obs),
            Weighting::Optimal1990 => {
                if !self.independent_pairs(obs) {
                    return;
                }
            }
        }
        let m = self.pairs.len();
        if m == 0 {
            return;
        }
        let (r_cov, w) = self.pair_weights(m);
        self.accumulate(m, &w);
        self.r_cov = r_cov;
        self.w = w;
    }

    /// Residual statistics over all pairs of distinct sensors (independent of weighting).
    fn residual_statistics(&mut self, obs: &[SensorObservation]) {
        let nobs = obs.len();
        for k in 0..nobs {
            for l in (k + 1)..nobs {
                if obs[k].sensor == obs[l].sensor {
                    continue;
                }
                let sin_angle = self.b[k].cross(&self.b[l]).norm();
                if sin_angle < 1e-3 {
                    continue;
                }
                let y = (obs[k].dir_eci.dot(&obs[l].dir_eci) - self.b[k].dot(&self.b[l]))
                    * ARCSEC_PER_RAD;
                let angle_resid = y / sin_angle;
                for s in [obs[k].sensor, obs[l].sensor] {
                    self.resid_sum_sq_arcsec2[s] += angle_resid * angle_resid;
                    self.resid_count[s] += 1;
                }
            }
        }
    }

    /// Shuster 1982: every pair of distinct sensors that do not see one object.
    fn all_pairs(&mut self, obs: &[SensorObservation]) {
        let nobs = obs.len();
        for k in 0..nobs {
            for l in (k + 1)..nobs {
                if obs[k].sensor != obs[l].sensor && !same_object(obs, k, l) {
                    let p = self.make_pair(obs, k, l);
                    if p.c.norm() > 1e-9 {
                        self.pairs.push(p);
                    }
                }
            }
        }
    }

    /// The 1990 variant: the most orthogonal pair as the anchor, then every other vector tied
    /// to two placed ones. `false` when every vector of the epoch sees one object (the Sun in
    /// both FSSs): the epoch is not used.
    fn independent_pairs(&mut self, obs: &[SensorObservation]) -> bool {
        let nobs = obs.len();
        // anchor = most orthogonal pair
        let (mut a, mut bb, mut best) = (0, 1, -1.0);
        for k in 0..nobs {
            for l in (k + 1)..nobs {
                let s = self.b[k].cross(&self.b[l]).norm_squared();
                if s > best {
                    best = s;
                    a = k;
                    bb = l;
                }
            }
        }
        if same_object(obs, a, bb) {
            return false;
        }
        let p = self.make_pair(obs, a, bb);
        self.pairs.push(p);
        // Every other vector k is tied to the two already-placed vectors (i, j) it is
        // farthest from the plane of: the dot products with i and j fix b_k only up to
        // a reflection through that plane, and lose first-order sensitivity to the
        // out-of-plane direction when b_k is near it.
        let mut placed = std::mem::take(&mut self.placed);
        placed.clear();
        placed.push(a);
        placed.push(bb);
        for k in 0..nobs {
            if k == a || k == bb {
                continue;
            }
            let (mut pi, mut pj, mut best_det) = (a, bb, -1.0);
            for (x, &i) in placed.iter().enumerate() {
                for &j in placed.iter().skip(x + 1) {
                    let det = self.b[k].dot(&self.b[i].cross(&self.b[j])).abs();
                    if det > best_det {
                        best_det = det;
                        pi = i;
                        pj = j;
                    }
                }
            }
            for i in [pi, pj] {
                if !same_object(obs, i, k) {
                    let p = self.make_pair(obs, i, k);
                    self.pairs.push(p);
                }
            }
            placed.push(k);
        }
        self.placed = placed;
        true
    }

    /// The full covariance `R` of the `m` chosen pairs and their weight matrix `W`: its
    /// diagonal inverse (Shuster 1982, whose sandwich `W R W` goes into the meat) or its
    /// inverse (1990).
    fn pair_weights(&mut self, m: usize) -> (Vec<f64>, Vec<f64>) {
        let mut r_cov = std::mem::take(&mut self.r_cov);
        r_cov.clear();
        r_cov.resize(m * m, 0.0);
        for a in 0..m {
            for bq in a..m {
                let c = self.pair_cov(&self.pairs[a], &self.pairs[bq]);
                r_cov[a * m + bq] = c;
                r_cov[bq * m + a] = c;
            }
        }
        let mut w = std::mem::take(&mut self.w);
        w.clear();
        w.resize(m * m, 0.0);
        match self.weighting {
            Weighting::Shuster1982 => {
                for a in 0..m {
                    let v = r_cov[a * m + a];
                    w[a * m + a] = if v > 0.0 { 1.0 / v } else { 0.0 };
                }
                // meat: W R W
                let mut tmp = std::mem::take(&mut self.tmp);
                tmp.clear();
                tmp.resize(m * m, 0.0);
                for a in 0..m {
                    for bq in 0..m {
                        tmp[a * m + bq] = w[a * m + a] * r_cov[a * m + bq] * w[bq * m + bq];
                    }
                }
                Self::add_quadratic(&mut self.meat, self.n, &self.pairs, &tmp, &mut self.kh);
                self.tmp = tmp;
            }
            Weighting::Optimal1990 => {
                if !small_spd_inverse(&r_cov, m, &mut w, &mut self.chol_l, &mut self.chol_li) {
                    let r_mat = DMatrix::from_row_slice(m, m, &r_cov);
                    let (pinv, _) = sym_pinv(&r_mat, 1e-10);
                    for a in 0..m {
                        for bq in 0..m {
                            w[a * m + bq] = pinv[(a, bq)];
                        }
                    }
                }
            }
        }
        (r_cov, w)
    }

    /// `Hᵀ W H` into the normal matrix, `Hᵀ W y` into the right-hand side, `yᵀ W y` into χ².
    fn accumulate(&mut self, m: usize, w: &[f64]) {
        Self::add_quadratic(&mut self.normal, self.n, &self.pairs, w, &mut self.kh);
        for (a, p) in self.pairs.iter().enumerate() {
            let mut wy = 0.0;
            for (bq, q) in self.pairs.iter().enumerate() {
                wy += w[a * m + bq] * q.y_arcsec;
            }
            self.chi2 += p.y_arcsec * wy;
            if p.sk != p.sl {
                for r in 0..3 {
                    self.rhs[3 * p.sl + r] += p.c[r] * wy;
                    self.rhs[3 * p.sk + r] -= p.c[r] * wy;
                }
            }
        }
        self.pairs_used += m;
    }
}

/// Two vectors of one epoch whose reference directions are closer than this (sine) see the
/// same object (the Sun in both FSSs, in their 2° overlap).
const SAME_OBJECT_SIN: f64 = 0.0175;

/// Whether observations `k` and `l` see the same object. Why: their dot product is
/// `cos(small angle)`, quadratic in the alignment error — its first-order partial
/// `b_k × b_l` and its variance both vanish, so a weighted pair adds a near-zero/near-zero
/// row that stalls Gauss–Newton (an oscillating step was seen when the Sun stayed in the
/// FSS overlap for an hour). Such pairs are left out; each vector is still tied to the others.
fn same_object(obs: &[SensorObservation], k: usize, l: usize) -> bool {
    obs[k].dir_eci.cross(&obs[l].dir_eci).norm() < SAME_OBJECT_SIN
}

/// Number of chunks the epochs are split into for the parallel pass. Fixed (not the thread
/// count) and summed in order, so results are bit-identical on any machine.
const ACCUMULATION_CHUNKS: usize = 64;

/// One pass over the data: per-chunk accumulators in parallel (rayon), summed in chunk order.
fn accumulate(
    data: &AlignmentData,
    m_current: &[Matrix3<f64>],
    sensors: usize,
    weighting: Weighting,
) -> Accumulator {
    use rayon::prelude::*;
    let epochs = data.epoch_count();
    let chunk = epochs.div_ceil(ACCUMULATION_CHUNKS).max(1);
    let starts: Vec<usize> = (0..epochs).step_by(chunk).collect();
    let parts: Vec<Accumulator> = starts
        .par_iter()
        .map(|&start| {
            let mut acc = Accumulator::new(sensors, weighting);
            for e in start..(start + chunk).min(epochs) {
                acc.add_epoch(data.epoch(e), m_current);
            }
            acc
        })
        .collect();
    let mut total = Accumulator::new(sensors, weighting);
    for p in &parts {
        total.merge(p);
    }
    total
}

/// Residuals of `data` at given alignments, without estimating anything: what a table would
/// leave on data it was not fitted to (held-out validation, `pipeline::alignment_heldout`).
#[derive(Clone, Debug, PartialEq)]
pub struct AlignmentResiduals {
    /// Weighted residual sum of squares of the dot products (whitened with the epoch's full
    /// pair covariance under [`Weighting::Optimal1990`]).
    pub chi2: f64,
    /// Dot products behind `chi2` (its degrees of freedom).
    pub pairs: usize,
    /// RMS angle residual of the pairs involving each sensor (arcsec; NaN without pairs).
    pub rms_arcsec: Vec<f64>,
    /// Pairs behind each sensor's RMS.
    pub rms_pairs: Vec<usize>,
    /// Each epoch's share of `chi2`, in epoch order (for paired comparisons of two tables on
    /// the same epochs).
    pub chi2_per_epoch: Vec<f64>,
}

/// The residuals of `data` with the alignments `m_acs_from_sensor` (one per sensor index of
/// `data`), weighted as `weighting` says.
///
/// # Errors
/// [`AlignmentError::UnknownSensor`]: an observation's sensor index outside
/// `m_acs_from_sensor`.
pub fn alignment_residuals(
    data: &AlignmentData,
    m_acs_from_sensor: &[Matrix3<f64>],
    weighting: Weighting,
) -> Result<AlignmentResiduals, AlignmentError> {
    let ns = m_acs_from_sensor.len();
    for (epoch, obs) in data.epochs().enumerate() {
        if let Some(bad) = obs.iter().find(|o| o.sensor >= ns) {
            return Err(AlignmentError::UnknownSensor {
                epoch,
                sensor: bad.sensor,
                sensors: ns,
            });
        }
    }
    let acc = accumulate(data, m_acs_from_sensor, ns, weighting);
    let chi2_per_epoch = {
        use rayon::prelude::*;
        (0..data.epoch_count())
            .into_par_iter()
            .map_init(
                || Accumulator::new(ns, weighting),
                |a, e| {
                    // From zero per epoch: the same on any thread, whatever it did before.
                    a.chi2 = 0.0;
                    a.add_epoch(data.epoch(e), m_acs_from_sensor);
                    a.chi2
                },
            )
            .collect()
    };
    let rms_arcsec = acc
        .resid_sum_sq_arcsec2
        .iter()
        .zip(&acc.resid_count)
        .map(|(&sq, &n)| {
            if n > 0 {
                (sq / n as f64).sqrt()
            } else {
                f64::NAN
            }
        })
        .collect();
    Ok(AlignmentResiduals {
        chi2: acc.chi2,
        pairs: acc.pairs_used,
        rms_arcsec,
        rms_pairs: acc.resid_count,
        chi2_per_epoch,
    })
}

/// In-place inverse of a small SPD matrix (row-major `m × m`) by Cholesky; false if not SPD.
fn small_spd_inverse(
    a: &[f64],
    m: usize,
    out: &mut [f64],
    l: &mut Vec<f64>,
    li: &mut Vec<f64>,
) -> bool {
    l.clear();
    l.resize(m * m, 0.0);
    li.clear();
    li.resize(m * m, 0.0);
    for i in 0..m {
        for j in 0..=i {
            let mut s = a[i * m + j];
            for k in 0..j {
                s -= l[i * m + k] * l[j * m + k];
            }
            if i == j {
                if s <= 1e-14 * a[i * m + i].abs().max(f64::MIN_POSITIVE) || !s.is_finite() {
                    return false;
                }
                l[i * m + i] = s.sqrt();
            } else {
                l[i * m + j] = s / l[j * m + j];
            }
        }
    }
    // inverse of L (lower triangular)
    for i in 0..m {
        li[i * m + i] = 1.0 / l[i * m + i];
        for j in 0..i {
            let mut s = 0.0;
            for k in j..i {
                s -= l[i * m + k] * li[k * m + j];
            }
            li[i * m + j] = s / l[i * m + i];
        }
    }
    // A⁻¹ = L⁻ᵀ L⁻¹
    for i in 0..m {
        for j in 0..m {
            let mut s = 0.0;
            for k in i.max(j)..m {
                s += li[k * m + i] * li[k * m + j];
            }
            out[i * m + j] = s;
        }
    }
    true
}

fn validate(
    sensors: &[SensorSpec],
    data: &AlignmentData,
) -> Result<Vec<Matrix3<f64>>, AlignmentError> {
    if sensors.is_empty() {
        return Err(AlignmentError::NoSensors);
    }
    if data.epoch_count() == 0 {
        return Err(AlignmentError::NoEpochs);
    }
    let mut prior_info = Vec::with_capacity(sensors.len());
    for s in sensors {
        let p = s.prior_cov_acs_arcsec2;
        let inv = if p.iter().all(|x| x.is_finite()) {
            ((p + p.transpose()) * 0.5).cholesky().map(|c| c.inverse())
        } else {
            None
        };
        let Some(inv) = inv else {
            return Err(AlignmentError::InvalidPrior {
                sensor: s.id.clone(),
            });
        };
        prior_info.push(inv);
    }
    let mut paired = vec![false; sensors.len()];
    for (epoch, obs) in data.epochs().enumerate() {
        for o in obs {
            if o.sensor >= sensors.len() {
                return Err(AlignmentError::UnknownSensor {
                    epoch,
                    sensor: o.sensor,
                    sensors: sensors.len(),
                });
            }
        }
        for o in obs {
            if obs.iter().any(|p| p.sensor != o.sensor) {
                paired[o.sensor] = true;
            }
        }
    }
    if let Some(i) = paired.iter().position(|&p| !p) {
        return Err(AlignmentError::SensorWithoutData {
            sensor: sensors[i].id.clone(),
        });
    }
    Ok(prior_info)
}

fn to_dmatrix(buf: &[f64], n: usize) -> DMatrix<f64> {
    let m = DMatrix::from_row_slice(n, n, buf);
    (&m + m.transpose()) * 0.5
}

/// Describe a mode vector (one 3-vector per sensor) for error messages.
fn describe_mode(sensors: &[SensorSpec], v: &[[f64; 3]]) -> String {
    sensors
        .iter()
        .zip(v)
        .map(|(s, x)| format!("{}=[{:.2},{:.2},{:.2}]", s.id, x[0], x[1], x[2]))
        .collect::<Vec<_>>()
        .join(" ")
}

/// Eigen-analysis of the data normal matrix and the total one.
fn observability(
    normal: &DMatrix<f64>,
    total: &DMatrix<f64>,
    sensors: usize,
) -> ObservabilityReport {
    let (values, vectors) = sym_eigen_ascending(normal);
    let (values_total, _) = sym_eigen_ascending(total);
    let max = values.iter().fold(0.0_f64, |a, &v| a.max(v));
    let threshold = UNOBSERVABLE_REL_THRESHOLD;
    let unobservable_count = values.iter().filter(|&&v| v <= threshold * max).count();
    // Orthonormal basis of the common rotation: u_k = [e_k; e_k; …]/√N.
    let n = 3 * sensors;
    let mut common = DMatrix::zeros(n, 3);
    for s in 0..sensors {
        for k in 0..3 {
            common[(3 * s + k, k)] = 1.0 / (sensors as f64).sqrt();
        }
    }
    let weakest = vectors.columns(0, 3.min(n));
    let proj = common.transpose() * weakest;
    let weakest_three_in_common_rotation = proj.norm_squared() / 3.0;
    let (weakest_relative_mode, weakest_relative_eigenvalue_per_arcsec2) = if n > 3 {
        let col = vectors.column(3);
        (
            (0..sensors)
                .map(|s| [col[3 * s], col[3 * s + 1], col[3 * s + 2]])
                .collect(),
            values[3],
        )
    } else {
        (Vec::new(), f64::NAN)
    };
    ObservabilityReport {
        eigenvalues_data_per_arcsec2: values.iter().copied().collect(),
        eigenvalues_with_prior_per_arcsec2: values_total.iter().copied().collect(),
        unobservable_count,
        threshold,
        weakest_three_in_common_rotation,
        weakest_relative_mode,
        weakest_relative_eigenvalue_per_arcsec2,
    }
}

/// Run FFCAL (see the module doc).
///
/// # Errors
/// [`AlignmentError`] for invalid input, missing data, unobservable relative alignments
/// (when `cfg.require_relative_observability`), or non-convergence.
pub fn ffcal(
    sensors: &[SensorSpec],
    data: &AlignmentData,
    cfg: &FfcalConfig,
) -> Result<FfcalSolution, AlignmentError> {
    let prior_info = validate(sensors, data)?;
    let ns = sensors.len();
    let n = 3 * ns;
    let m_prelaunch: Vec<Matrix3<f64>> = sensors.iter().map(|s| s.m_acs_from_sensor).collect();
    let mut m_current = m_prelaunch.clone();
    let mut prior_info_full = DMatrix::zeros(n, n);
    for (s, pi) in prior_info.iter().enumerate() {
        prior_info_full
            .fixed_view_mut::<3, 3>(3 * s, 3 * s)
            .copy_from(pi);
    }
    let mut residual_before: Option<(Vec<f64>, Vec<usize>)> = None;
    let mut last_step = f64::INFINITY;
    let mut iterations = 0;
    loop {
        let acc = accumulate(data, &m_current, ns, cfg.weighting);
        if residual_before.is_none() {
            residual_before = Some((acc.resid_sum_sq_arcsec2.clone(), acc.resid_count.clone()));
        }
        let normal = to_dmatrix(&acc.normal, n);
        let total = &normal + &prior_info_full;
        let converged = iterations > 0 && last_step < cfg.convergence_arcsec;
        if converged || iterations >= cfg.max_iterations {
            if !converged {
                return Err(AlignmentError::NotConverged {
                    iterations,
                    last_step_arcsec: last_step,
                });
            }
            let obs_report = observability(&normal, &total, ns);
            if cfg.require_relative_observability && obs_report.unobservable_count > 3 {
                let (_, vectors) = sym_eigen_ascending(&normal);
                let col = vectors.column(obs_report.unobservable_count - 1);
                let mode: Vec<[f64; 3]> = (0..ns)
                    .map(|s| [col[3 * s], col[3 * s + 1], col[3 * s + 2]])
                    .collect();
                return Err(AlignmentError::Unobservable {
                    unobservable: obs_report.unobservable_count - 3,
                    threshold: obs_report.threshold,
                    mode: describe_mode(sensors, &mode),
                });
            }
            let formal = spd_inverse(&total).ok_or(AlignmentError::Singular)?;
            let covariance = match cfg.weighting {
                Weighting::Optimal1990 => formal.clone(),
                Weighting::Shuster1982 => {
                    let meat = to_dmatrix(&acc.meat, n) + &prior_info_full;
                    let c = &formal * meat * &formal;
                    (&c + c.transpose()) * 0.5
                }
            };
            let (before_sq, before_n) = residual_before.unwrap_or_default();
            let rms = |sq: f64, k: usize| {
                if k > 0 {
                    (sq / k as f64).sqrt()
                } else {
                    f64::NAN
                }
            };
            let results = sensors
                .iter()
                .enumerate()
                .map(|(s, spec)| SensorAlignmentResult {
                    id: spec.id.clone(),
                    m_acs_from_sensor_prelaunch: m_prelaunch[s],
                    m_acs_from_sensor_calibrated: m_current[s],
                    theta_acs_arcsec: rotvec_from_rot(&(m_current[s] * m_prelaunch[s].transpose()))
                        * ARCSEC_PER_RAD,
                    sigma_acs_arcsec: Vector3::from_fn(|k, _| {
                        covariance[(3 * s + k, 3 * s + k)].max(0.0).sqrt()
                    }),
                    residual_rms_before_arcsec: rms(before_sq[s], before_n[s]),
                    residual_rms_after_arcsec: rms(acc.resid_sum_sq_arcsec2[s], acc.resid_count[s]),
                    residual_pairs: acc.resid_count[s],
                })
                .collect();
            return Ok(FfcalSolution {
                weighting: cfg.weighting,
                sensors: results,
                covariance_arcsec2: covariance,
                formal_covariance_arcsec2: formal,
                normal_data_per_arcsec2: normal,
                iterations,
                epochs: data.epoch_count(),
                pairs_per_pass: acc.pairs_used,
                chi2: acc.chi2,
                observability: obs_report,
            });
        }
        // Gauss–Newton step on the total corrections.
        let mut x_arcsec = DVector::zeros(n);
        for s in 0..ns {
            let th = rotvec_from_rot(&(m_current[s] * m_prelaunch[s].transpose())) * ARCSEC_PER_RAD;
            x_arcsec.fixed_rows_mut::<3>(3 * s).copy_from(&th);
        }
        let rhs = DVector::from_column_slice(&acc.rhs) - &prior_info_full * &x_arcsec;
        let chol = ((&total + total.transpose()) * 0.5)
            .cholesky()
            .ok_or(AlignmentError::Singular)?;
        let delta = chol.solve(&rhs);
        last_step = delta.amax();
        for (s, m) in m_current.iter_mut().enumerate() {
            let d: Vector3<f64> = delta.fixed_rows::<3>(3 * s).into_owned() * RAD_PER_ARCSEC;
            *m = rot(&d) * *m;
        }
        iterations += 1;
    }
}

/// Fisher information (1/arcsec²) of the alignment corrections carried by the vector data,
/// with each epoch's attitude eliminated as a nuisance parameter (`docs/algorithms.md` §10):
/// per epoch `J = blkdiag(Qₖ) − [Qₖ]ᵀ (Σ Qₖ)⁻¹ [Qₗ]` with `Qₖ = (I − bₖbₖᵀ)/σₖ²` placed in the
/// block of the sensor of observation `k`. No prior included.
///
/// Computed from the vector measurement model directly (not from dot products), so it is an
/// independent check of the optimal weighting: `N_optimal = J` under linearisation.
///
/// # Errors
/// As [`ffcal`]'s input validation; an epoch whose vectors are all parallel is skipped (it has
/// no attitude-free information).
pub fn cramer_rao_information(
    sensors: &[SensorSpec],
    data: &AlignmentData,
    m_acs_from_sensor: &[Matrix3<f64>],
) -> Result<DMatrix<f64>, AlignmentError> {
    validate(sensors, data)?;
    let n = 3 * sensors.len();
    let mut info = DMatrix::zeros(n, n);
    let mut q: Vec<Matrix3<f64>> = Vec::new();
    for obs in data.epochs() {
        q.clear();
        let mut g = Matrix3::zeros();
        for o in obs {
            let b = m_acs_from_sensor[o.sensor] * o.dir_sensor;
            let s = o.sigma_rad * ARCSEC_PER_RAD;
            let qk = (Matrix3::identity() - b * b.transpose()) / (s * s);
            g += qk;
            q.push(qk);
        }
        let Some(g_inv) = g.try_inverse() else {
            continue;
        };
        for (k, ok) in obs.iter().enumerate() {
            let mut blk = info.fixed_view_mut::<3, 3>(3 * ok.sensor, 3 * ok.sensor);
            blk += q[k];
            for (l, ol) in obs.iter().enumerate() {
                let t = q[k] * g_inv * q[l];
                let mut blk = info.fixed_view_mut::<3, 3>(3 * ok.sensor, 3 * ol.sensor);
                blk -= t;
            }
        }
    }
    Ok((&info + info.transpose()) * 0.5)
}

/// Cramér–Rao covariance bound (arcsec²) of the corrections: `(P₀⁻¹ + J)⁻¹`.
///
/// # Errors
/// As [`cramer_rao_information`], plus [`AlignmentError::Singular`].
pub fn cramer_rao_covariance(
    sensors: &[SensorSpec],
    data: &AlignmentData,
    m_acs_from_sensor: &[Matrix3<f64>],
) -> Result<DMatrix<f64>, AlignmentError> {
    let prior_info = validate(sensors, data)?;
    let mut j = cramer_rao_information(sensors, data, m_acs_from_sensor)?;
    for (s, pi) in prior_info.iter().enumerate() {
        let mut blk = j.fixed_view_mut::<3, 3>(3 * s, 3 * s);
        blk += pi;
    }
    spd_inverse(&j).ok_or(AlignmentError::Singular)
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;
    use crate::synth::{alignment_data, gro_sensors, Rng, SyntheticSensor};

    fn truth_arcsec() -> [Vector3<f64>; 4] {
        [
            Vector3::new(10.0, -20.0, 30.0),
            Vector3::new(-40.0, 20.0, 60.0),
            Vector3::new(236.0, -407.0, -562.0),
            Vector3::new(-153.0, 2.0, 110.0),
        ]
    }

    fn specs(syn: &[SyntheticSensor], prior_sigma_arcsec: f64) -> Vec<SensorSpec> {
        syn.iter()
            .map(|s| SensorSpec::new(&s.id, s.m_acs_from_sensor_prelaunch, prior_sigma_arcsec))
            .collect()
    }

    /// Error of the estimated alignments relative to the truth, as a left ACS rotation vector
    /// (arcsec): `rotvec(M̂ M_trueᵀ)`.
    fn errors_arcsec(sol: &FfcalSolution, syn: &[SyntheticSensor]) -> Vec<Vector3<f64>> {
        sol.sensors
            .iter()
            .zip(syn)
            .map(|(r, s)| {
                rotvec_from_rot(
                    &(r.m_acs_from_sensor_calibrated * s.m_acs_from_sensor_true().transpose()),
                ) * ARCSEC_PER_RAD
            })
            .collect()
    }

    /// The Sun in both FSSs at once (their overlap): the dot product of the two views of one
    /// object has no first-order information and must not enter. With it, Gauss–Newton
    /// oscillated without converging on real data (its whitened row claims half the angle
    /// between the two views); here, with 5 FSS-only epochs per full one, FFCAL converges and
    /// FSS2 is still recovered through the FHST stars.
    #[test]
    fn two_views_of_one_object_do_not_stall_gauss_newton() {
        let mut rng = Rng::new(7);
        let syn = gro_sensors(&truth_arcsec());
        let mut data = AlignmentData::with_capacity(400, 4);
        for _ in 0..400 {
            let mut obs = crate::synth::alignment_epoch(&mut rng, &syn);
            // FSS2 sees FSS1's object (the Sun): the same reference direction, and FSS1's
            // (noisy) view carried through both true alignments plus FSS2's own noise.
            let sun_eci = obs[2].dir_eci;
            let b_acs = syn[2].m_acs_from_sensor_true() * obs[2].dir_sensor;
            let s2 = syn[3].m_acs_from_sensor_true().transpose() * b_acs;
            obs[3].dir_sensor = crate::synth::perturb_unit_vector(&mut rng, &s2, syn[3].sigma_rad);
            obs[3].dir_eci = sun_eci;
            data.push_epoch(&obs).unwrap();
            // Epochs where only the two FSSs see the Sun (the trackers occulted): the
            // degenerate pair alone.
            for _ in 0..5 {
                data.push_epoch(&obs[2..4]).unwrap();
            }
        }
        let sol = ffcal(&specs(&syn, 3600.0), &data, &FfcalConfig::default())
            .expect("FFCAL converges with two views of one object per epoch");
        let err = errors_arcsec(&sol, &syn);
        let rel = err[3] - err[0];
        let cov = sol.relative_covariance_arcsec2(3, 0);
        for k in 0..3 {
            assert!(
                rel[k].abs() < 4.0 * cov[(k, k)].sqrt() + 1.0,
                "FSS2 axis {k}: {rel:?}"
            );
        }
    }

    /// 2 FHSTs 90° apart + 2 FSSs, 300 random epochs: the alignments relative to FHST1 are
    /// recovered within 4σ per axis (4σ: 9 components × 2 weightings, a false alarm rate of
    /// ~1e-3 overall), and the residuals drop to the noise level.
    #[test]
    fn val_ffcal_recovers_relative_alignments() {
        for weighting in [Weighting::Optimal1990, Weighting::Shuster1982] {
            let mut rng = Rng::new(42);
            let syn = gro_sensors(&truth_arcsec());
            let data = alignment_data(&mut rng, &syn, 300);
            let cfg = FfcalConfig {
                weighting,
                ..FfcalConfig::default()
            };
            let sol = ffcal(&specs(&syn, 3600.0), &data, &cfg).unwrap();
            let err = errors_arcsec(&sol, &syn);
            for i in 1..4 {
                let rel = err[i] - err[0];
                let cov = sol.relative_covariance_arcsec2(i, 0);
                for k in 0..3 {
                    let sigma = cov[(k, k)].sqrt();
                    assert!(
                        rel[k].abs() < 4.0 * sigma,
                        "{weighting:?} sensor {i} axis {k}: {} vs σ {sigma}",
                        rel[k]
                    );
                    assert!(sigma < 20.0, "σ {sigma} too large for 300 epochs");
                }
            }
            // FSS1 was 0.2° off: residual before ≫ after ≈ noise.
            assert!(sol.sensors[2].residual_rms_before_arcsec > 300.0);
            assert!(sol.sensors[2].residual_rms_after_arcsec < 80.0);
            assert!(sol.iterations <= 5, "iterations {}", sol.iterations);
            if weighting == Weighting::Optimal1990 {
                let dof = sol.pairs_per_pass as f64;
                assert!(
                    (sol.chi2 / dof - 1.0).abs() < 0.15,
                    "χ²/dof = {}",
                    sol.chi2 / dof
                );
                assert_eq!(sol.pairs_per_pass, 300 * 5);
            } else {
                assert_eq!(sol.pairs_per_pass, 300 * 6);
            }
        }
    }

    /// Monte Carlo: with the truth drawn from the prior, the full-state normalised error
    /// `eᵀP⁻¹e / 12` must average 1 (60 trials × 12 dof: σ of the mean ≈ 0.053; tolerance 0.2
    /// ≈ 4σ). Checked for the optimal weights and for the 1982 weights with the sandwich
    /// covariance.
    #[test]
    fn val_ffcal_monte_carlo_normalised_errors() {
        let prior_sigma_arcsec = 200.0;
        for weighting in [Weighting::Optimal1990, Weighting::Shuster1982] {
            let mut rng = Rng::new(7);
            let trials = 60;
            let mut sum = 0.0;
            for _ in 0..trials {
                let truth: [Vector3<f64>; 4] =
                    std::array::from_fn(|_| rng.normal3() * prior_sigma_arcsec);
                let syn = gro_sensors(&truth);
                let data = alignment_data(&mut rng, &syn, 40);
                let cfg = FfcalConfig {
                    weighting,
                    ..FfcalConfig::default()
                };
                let sol = ffcal(&specs(&syn, prior_sigma_arcsec), &data, &cfg).unwrap();
                let est: Vec<Vector3<f64>> =
                    sol.sensors.iter().map(|s| s.theta_acs_arcsec).collect();
                let e = DVector::from_iterator(
                    12,
                    (0..4)
                        .flat_map(|s| (0..3).map(move |k| (s, k)))
                        .map(|(s, k)| est[s][k] - truth[s][k]),
                );
                let p_inv = spd_inverse(&sol.covariance_arcsec2).unwrap();
                sum += e.dot(&(p_inv * &e)) / 12.0;
            }
            let mean = sum / f64::from(trials);
            assert!(
                (mean - 1.0).abs() < 0.2,
                "{weighting:?}: mean normalised error variance {mean}"
            );
        }
    }

    /// A common rotation of all sensors is invisible to the data: the data normal matrix has
    /// exactly 3 null directions spanning it, the estimate of the common part stays at the
    /// prior mean (0), and its posterior σ is the prior's σ/√N.
    #[test]
    fn val_ffcal_common_rotation_is_unobservable() {
        let common = Vector3::new(100.0, -50.0, 80.0);
        let truth = truth_arcsec().map(|t| t + common);
        let mut rng = Rng::new(3);
        let syn = gro_sensors(&truth);
        let data = alignment_data(&mut rng, &syn, 200);
        let prior = 600.0;
        let sol = ffcal(&specs(&syn, prior), &data, &FfcalConfig::default()).unwrap();
        let obs = &sol.observability;
        assert_eq!(obs.unobservable_count, 3);
        assert!(
            obs.weakest_three_in_common_rotation > 0.999,
            "{}",
            obs.weakest_three_in_common_rotation
        );
        let mean_est: Vector3<f64> = sol
            .sensors
            .iter()
            .map(|s| s.theta_acs_arcsec)
            .sum::<Vector3<f64>>()
            / 4.0;
        let mean_true: Vector3<f64> = truth.iter().sum::<Vector3<f64>>() / 4.0;
        // the estimated common part is ≈ 0 (prior mean), not the true 100/−50/80 offset
        assert!(mean_est.norm() < 5.0, "estimated common part {mean_est:?}");
        assert!((mean_true - mean_est).norm() > 100.0);
        // posterior σ of the common mode = prior σ / √4
        let mut u = DVector::zeros(12);
        for s in 0..4 {
            u[3 * s] = 0.25;
        }
        let var = u.dot(&(&sol.covariance_arcsec2 * &u));
        assert!(
            (var.sqrt() / (prior / 2.0) - 1.0).abs() < 0.01,
            "σ_common {}",
            var.sqrt()
        );
    }

    /// The optimal weighting reaches the Cramér–Rao bound computed independently from the
    /// vector model (relative difference < 1e-6; the same linearisation point is used, and the
    /// residual ~1e-7 comes from epochs whose extra vectors lie close to the plane of their two
    /// partners, where `R_t` is ill-conditioned),
    /// and the 1982 sandwich covariance is never better than the bound.
    #[test]
    fn val_ffcal_optimal_weights_attain_cramer_rao() {
        let mut rng = Rng::new(9);
        let syn = gro_sensors(&truth_arcsec());
        let data = alignment_data(&mut rng, &syn, 100);
        let sp = specs(&syn, 1000.0);
        let sol = ffcal(&sp, &data, &FfcalConfig::default()).unwrap();
        let m_cal: Vec<Matrix3<f64>> = sol
            .sensors
            .iter()
            .map(|s| s.m_acs_from_sensor_calibrated)
            .collect();
        let j = cramer_rao_information(&sp, &data, &m_cal).unwrap();
        let rel = (&j - &sol.normal_data_per_arcsec2).norm() / j.norm();
        assert!(rel < 1e-6, "relative difference {rel}");

        let cfg = FfcalConfig {
            weighting: Weighting::Shuster1982,
            ..FfcalConfig::default()
        };
        let sol82 = ffcal(&sp, &data, &cfg).unwrap();
        let crb = cramer_rao_covariance(&sp, &data, &m_cal).unwrap();
        let diff = &sol82.covariance_arcsec2 - &crb;
        let (values, _) = sym_eigen_ascending(&diff);
        assert!(
            values[0] > -1e-6 * crb.norm(),
            "sandwich below the CRB: {}",
            values[0]
        );
        // and the 1982 formal covariance is not the true one: some relative-alignment σ
        // differs by more than 1 % (ignoring correlations between pairs that share a vector)
        let rel_sigma = |p: &DMatrix<f64>, i: usize, k: usize| {
            (p[(3 * i + k, 3 * i + k)] + p[(k, k)] - 2.0 * p[(3 * i + k, k)]).sqrt()
        };
        let worst = (1..4)
            .flat_map(|i| (0..3).map(move |k| (i, k)))
            .map(|(i, k)| {
                (rel_sigma(&sol82.formal_covariance_arcsec2, i, k)
                    / rel_sigma(&sol82.covariance_arcsec2, i, k)
                    - 1.0)
                    .abs()
            })
            .fold(0.0_f64, f64::max);
        assert!(worst > 0.01, "formal and sandwich σ agree to {worst}");
    }

    #[test]
    fn ffcal_input_errors_are_explicit() {
        let mut rng = Rng::new(1);
        let syn = gro_sensors(&truth_arcsec());
        let sp = specs(&syn, 100.0);
        // Two epochs cannot determine 9 relative angles.
        let data = alignment_data(&mut rng, &syn, 1);
        assert!(matches!(
            ffcal(&sp, &data, &FfcalConfig::default()),
            Err(AlignmentError::Unobservable { .. })
        ));
        // FSS2 never observed together with another sensor.
        let mut d2 = AlignmentData::new();
        for _ in 0..20 {
            let obs = crate::synth::alignment_epoch(&mut rng, &syn);
            d2.push_epoch(&obs[..3]).unwrap();
        }
        assert!(matches!(
            ffcal(&sp, &d2, &FfcalConfig::default()),
            Err(AlignmentError::SensorWithoutData { ref sensor }) if sensor == "FSS2"
        ));
        assert!(matches!(
            ffcal(&sp, &AlignmentData::new(), &FfcalConfig::default()),
            Err(AlignmentError::NoEpochs)
        ));
        let obs = crate::synth::alignment_epoch(&mut rng, &syn);
        assert!(matches!(
            d2.push_epoch(&obs[..1]),
            Err(AlignmentError::TooFewObservations { got: 1, .. })
        ));
        let bad = [
            SensorSpec::new("X", Matrix3::identity(), 0.0),
            sp[1].clone(),
        ];
        let mut d3 = AlignmentData::new();
        d3.push_epoch(&obs[..2]).unwrap();
        assert!(matches!(
            ffcal(&bad, &d3, &FfcalConfig::default()),
            Err(AlignmentError::InvalidPrior { .. })
        ));
    }
}
