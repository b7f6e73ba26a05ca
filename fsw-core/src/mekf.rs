//! # Multiplicative extended Kalman filter: attitude and gyro bias (algorithms.md §2)
//!
//! Reference state: `q̂` (ACS from ECI, [`Quat`]) and `b̂` (rad/s). Error state
//! `x = [δθ; δb]` with `A_true = Rot(δθ) Â` (left, body-frame; [`crate::attitude`]) and
//! `b_true = b̂ + δb`. Gyro model (Farrenkopf): `ω_meas = ω + b + η_v`, `ḃ = η_u`, spectral
//! densities `σ_v²`, `σ_u²` from the [`FilterTable`].
//!
//! ## Propagation ([`Mekf::propagate`])
//! * `φ = Δθ − b̂ Δt` (Δθ from [`crate::iru`]; the ground calibration `(I + ΔM)` is already in
//!   the table's `G`).
//! * `q̂ ← δq(φ) ⊗ q̂`, `δq(φ) = [sin(φ/2) φ/|φ|; cos(φ/2)]`: the exact rotation-vector update
//!   (algorithms.md §5 item 6). `b̂` is constant.
//! * With `K = [φ×]`: `Φ₁₁ = Rot(φ) = I − (sin φ/φ) K + ((1 − cos φ)/φ²) K²`,
//!   `Φ₁₂ = −Δt (I − ((1 − cos φ)/φ²) K + ((φ − sin φ)/φ³) K²)`, `Φ₂₁ = 0`, `Φ₂₂ = I`
//!   (algorithms.md §2, rewritten in `φ = ω̂Δt`).
//! * The three coefficients and `δq` come from one `sincos(φ/2)`; for `φ < 0.01 rad`
//!   (0.57°/cycle, every GRO rate) from their Taylor series to `φ⁶` (error < 1e-17): no trig.
//! * `P⁻ = Φ P Φᵀ + Q` using the block structure (four 3×3 products, no 6×6 product):
//!   `A = Φ₁₁P₁₁ + Φ₁₂P₂₁`, `B = Φ₁₁P₁₂ + Φ₁₂P₂₂`, `P₁₁⁻ = AΦ₁₁ᵀ + BΦ₁₂ᵀ`, `P₁₂⁻ = B`,
//!   `P₂₂⁻ = P₂₂`; `Q₁₁ = (σ_v²Δt + σ_u²Δt³/3) I`, `Q₁₂ = −σ_u²Δt²/2 I`, `Q₂₂ = σ_u²Δt I`.
//!   Pulse quantization is *not* added to Q (it telescopes; algorithms.md §2).
//!
//! ## Measurement updates (2 components, sequential, reset after each)
//! Every update has the form `ν ≈ [h 0] x + v`, `h` 2×3, `R = σ² I₂`:
//! * [`Mekf::update_vector`] (FSS, any unit vector): `ẑ = Â r`; with an orthonormal pair
//!   `e₁, e₂ ⟂ ẑ` (`e₁ × e₂ = ẑ`) the along-`ẑ` component, which carries no information, is
//!   dropped: `ν = [e₁·z, e₂·z]`, and from `z ≈ ẑ + [ẑ×]δθ`, `h = [−e₂ᵀ; e₁ᵀ]`.
//! * [`Mekf::update_focal_plane`] (FHST, algorithms.md §3.1): `ŝ = M_ASᵀ Â r`,
//!   `ν = (H − Ĥ, V − V̂)`, `h = ∂(H,V)/∂s · M_ASᵀ [b̂×]` ([`crate::fhst::hv_jacobian`]).
//! * `S = h P₁₁ hᵀ + R` (2×2, inverted in closed form only if `det S > 0` and finite);
//!   `R` is floored so that one update reduces the variance by at most
//!   [`MAX_VARIANCE_REDUCTION`] (keeps `P` positive definite in double precision),
//!   `d² = νᵀS⁻¹ν` (NIS), rejected when `d² > gate` (χ²₂: 11.83 = 99.73 %).
//! * `K = P Hᵀ S⁻¹` (6×2); Joseph form `P⁺ = (I − KH) P (I − KH)ᵀ + K R Kᵀ`, evaluated as
//!   `T = P − K (HP)`, `P⁺ = T − (T Hᵀ − σ²K) Kᵀ` (exactly the Joseph product, ~180
//!   multiplications), then symmetrised. An update whose `P⁺` is not finite with a positive
//!   diagonal is discarded (state unchanged).
//! * FHST updates ([`Mekf::update_focal_plane_consider`]) carry each tracker's systematic
//!   error (H, V; σ the table's `fhst_uncorrected_systematic_arcsec`) as consider states
//!   (Schmidt–Kalman: `P_xc`, 6×4, carried, the states never estimated), first-order
//!   Gauss–Markov with [`FHST_SYSTEMATIC_CORRELATION_S`]; every other update and the
//!   propagation keep `P_xc` consistent. Why not a floor on `P` (the
//!   [`Mekf::update_focal_plane_with_floor`] form, kept for comparison): a floor stops taking
//!   information once the variance reaches it, after a few samples of a new star, and keeps
//!   their white noise in the attitude (docs/obc_filter.md §9–10).
//! * Reset: `q̂ ← normalize(δq(δθ̂) ⊗ q̂)`, `b̂ ← b̂ + δb̂`. The covariance reset
//!   `T P Tᵀ, T = blkdiag(I − ½[δθ̂×], I)` (Mueller 2017, algorithms.md §12) is second order
//!   and omitted.
//! * Updates in one cycle are processed one after the other, each re-linearised at the reset
//!   state (SMEKF 2018, algorithms.md §12), which is more robust than batch processing when
//!   the prior error is large (1° at initialisation).
//!
//! ## Initialisation
//! [`Mekf::initialize`] from a known attitude, or [`Mekf::initialize_from_two_vectors`]
//! (TRIAD, the first pair exact) when no attitude is known; `P = diag(σ_θ² I, σ_b² I)` from the
//! table, `b̂ = 0` unless given.
//!
//! ## Robustness
//! No operation can panic; non-finite inputs are rejected with the state left unchanged; the
//! only inverses are closed-form 2×2.

use crate::attitude::{skew, Quat};
use crate::fhst::{hv_from_dir, hv_jacobian};
use crate::tables::types::FilterTable;
use nalgebra::{
    Matrix2, Matrix2x3, Matrix2x4, Matrix3, Matrix3x2, Matrix3x4, Matrix6, Matrix6x2, Matrix6x4,
    Vector2, Vector3,
};

/// Correlation time of the FHSTs' systematic errors (consider states), s: a quarter of GRO's
/// 96-min orbit, after which the uncorrected orbital aberration's direction has turned by 90°
/// (the part of the systematic error that changes; the residual alignment part is constant
/// and is kept by the first samples of each new geometry instead). docs/obc_filter.md §10.
/// Project choice (not in the paper).
pub const FHST_SYSTEMATIC_CORRELATION_S: f64 = 1440.0;

/// Below this rotation angle (rad) the propagation uses Taylor series (no trig).
const SERIES_LIMIT_RAD: f64 = 0.01;
/// Largest variance reduction one update may make: `R ≥ tr(h P₁₁ hᵀ)/2 / 1e10`. Any real
/// sensor is far inside this (a 1° prior and a 0.1″ star give 1.3e9), but a near-zero σ
/// would push an eigenvalue of `P` below the rounding level of its largest one (ε‖P‖) and
/// `P` would lose definiteness; `R` is raised to the floor instead.
/// Project choice (not in the paper): a numerical floor, not a sensor model.
pub const MAX_VARIANCE_REDUCTION: f64 = 1.0e10;
/// Longest accepted propagation step, s.
/// Project choice (not in the paper): bounds the first-order `Q` of algorithms.md §2.
pub const MAX_PROPAGATION_STEP_S: f64 = 10.0;
/// Largest accepted gyro increment in one step, rad (well above 2¹⁵ high-rate pulses).
/// Project choice (not in the paper): above any rate of the paper's 0.8″/pulse high-rate mode.
pub const MAX_DELTA_THETA_RAD: f64 = 0.5;
/// TRIAD: smallest accepted angle between the two vectors of a pair, rad (2°).
/// Project choice (not in the paper): TRIAD (Shuster & Oh 1981) degrades as sin of the angle.
pub const TRIAD_MIN_SEPARATION_RAD: f64 = 2.0 * crate::units::RAD_PER_DEG;
/// TRIAD: largest accepted difference between the body and reference separations, rad (0.5°).
/// Project choice (not in the paper): catches a misidentified pair before it seeds the filter.
pub const TRIAD_CONSISTENCY_RAD: f64 = 0.5 * crate::units::RAD_PER_DEG;

/// Why a filter operation did not change the state.
/// Project choice (not in the paper): errors instead of panics in the flight core.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MekfError {
    /// An input is not finite or out of its range.
    /// Project choice (not in the paper): NaN input is refused.
    InvalidInput,
    /// TRIAD: a pair of vectors is (nearly) collinear.
    /// TRIAD needs two non-parallel vectors (Shuster & Oh 1981).
    Collinear,
    /// TRIAD: the body and reference separations disagree by more than
    /// [`TRIAD_CONSISTENCY_RAD`].
    /// Project choice (not in the paper): the angle between two vectors is attitude-independent
    /// (algorithms.md §6).
    Inconsistent,
    /// The covariance became non-finite or lost a positive diagonal (state unchanged).
    /// Joseph-form checks of algorithms.md §2.
    NumericalFault,
}

/// Why a measurement update was not applied.
/// docs/icd.md §3.2 (residual status).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum UpdateRejection {
    /// A measurement, reference, σ or gate is not finite / out of range.
    /// docs/icd.md §3.2 (status 3).
    InvalidInput,
    /// The prediction is unusable: behind the sensor, or more than 90° from the measurement.
    /// Project choice (not in the paper): the linearisation of algorithms.md §2 is invalid there.
    Geometry,
    /// `νᵀS⁻¹ν` above the gate.
    /// docs/icd.md §3.2 (status 2); gate per algorithms.md §2.
    Gated,
    /// `S` not positive definite.
    /// algorithms.md §2 (`S = HPHᵀ + R`).
    Singular,
    /// The updated covariance failed its checks.
    /// Joseph-form checks of algorithms.md §2.
    NumericalFault,
}

/// Result of one measurement update.
/// algorithms.md §2 (vector measurement update).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct UpdateOutcome {
    /// The update was applied.
    /// docs/icd.md §3.2 (status 1).
    pub accepted: bool,
    /// Innovation, rad: the two components perpendicular to the predicted vector
    /// ([`Mekf::update_vector`]) or `(H − Ĥ, V − V̂)` ([`Mekf::update_focal_plane`]).
    /// Zero if the input was invalid.
    /// `ν` of algorithms.md §2; telemetry docs/icd.md §3.2.
    pub innovation_rad: [f64; 2],
    /// Normalised innovation squared `νᵀS⁻¹ν` (NaN if not computed).
    /// algorithms.md §2 (`S` and `ν`).
    pub nis: f64,
    /// Why it was not applied.
    /// docs/icd.md §3.2 (residual status).
    pub rejection: Option<UpdateRejection>,
}

impl UpdateOutcome {
    fn rejected(reason: UpdateRejection, nu: [f64; 2], nis: f64) -> Self {
        Self {
            accepted: false,
            innovation_rad: nu,
            nis,
            rejection: Some(reason),
        }
    }
}

/// Update statistics (saturating counters).
/// docs/icd.md §3.2 (counters).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct UpdateCounters {
    /// Updates applied.
    /// docs/icd.md §3.2 (accepted measurements).
    pub accepted: u32,
    /// Updates rejected by the χ² gate.
    /// docs/icd.md §3.2 (gated measurements).
    pub gated: u32,
    /// Updates rejected for any other reason.
    /// docs/icd.md §3.2 (rejected inputs).
    pub other_rejections: u32,
}

/// The filter state.
/// Lefferts, Markley & Shuster 1982 MEKF as in algorithms.md §2.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mekf {
    /// Attitude estimate, ACS from ECI.
    /// `q̂` of algorithms.md §2 (docs/conventions.md).
    pub q_acs_from_eci: Quat,
    /// Gyro bias estimate, ACS, rad/s.
    /// `b̂` of algorithms.md §2.
    pub bias_rad_per_s: Vector3<f64>,
    /// Error-state covariance, `[δθ (rad); δb (rad/s)]`.
    /// `P` of algorithms.md §2.
    pub covariance: Matrix6<f64>,
    /// Cross-covariance of the error state with the FHSTs' systematic errors, which are
    /// consider states (Schmidt–Kalman: carried, never estimated): rows `[δθ (rad); δb
    /// (rad/s)]`, columns FHST1 H, FHST1 V, FHST2 H, FHST2 V (rad). Their own variance is the
    /// systematic σ² the caller passes with each update (stationary first-order Gauss–Markov,
    /// [`FHST_SYSTEMATIC_CORRELATION_S`]).
    /// docs/obc_filter.md §10.
    pub cross_covariance_fhst_systematic: Matrix6x4<f64>,
    /// The systematic σ (rad) that [`Self::cross_covariance_fhst_systematic`] was built with:
    /// when an update brings another σ (a table load, the onboard orbit becoming valid), the
    /// cross-covariance is scaled by the ratio, which keeps the joint covariance of state and
    /// consider states positive semi-definite.
    /// docs/obc_filter.md §10.
    pub fhst_systematic_sigma_rad: f64,
    /// Update statistics.
    /// docs/icd.md §3.2 (counters).
    pub counters: UpdateCounters,
}

#[cfg(feature = "defmt")]
impl defmt::Format for Mekf {
    fn format(&self, f: defmt::Formatter) {
        let s = self.attitude_sigma_rad();
        defmt::write!(
            f,
            "Mekf {{ q: {}, b: {}, sigma_att: {}, counters: {} }}",
            self.q_acs_from_eci,
            [
                self.bias_rad_per_s.x,
                self.bias_rad_per_s.y,
                self.bias_rad_per_s.z
            ],
            [s.x, s.y, s.z],
            self.counters
        );
    }
}

/// `(sin φ/φ, (1−cos φ)/φ², (φ−sin φ)/φ³, sin(φ/2)/φ, cos(φ/2))` for `φ = |v|`.
fn rotation_coefficients(angle: f64) -> (f64, f64, f64, f64, f64) {
    let a2 = angle * angle;
    if angle < SERIES_LIMIT_RAD {
        let a4 = a2 * a2;
        let a6 = a4 * a2;
        let h2 = 0.25 * a2;
        let h4 = h2 * h2;
        let h6 = h4 * h2;
        (
            1.0 - a2 / 6.0 + a4 / 120.0 - a6 / 5040.0,
            0.5 - a2 / 24.0 + a4 / 720.0 - a6 / 40_320.0,
            1.0 / 6.0 - a2 / 120.0 + a4 / 5040.0 - a6 / 362_880.0,
            0.5 * (1.0 - h2 / 6.0 + h4 / 120.0 - h6 / 5040.0),
            1.0 - h2 / 2.0 + h4 / 24.0 - h6 / 720.0 + h4 * h4 / 40_320.0,
        )
    } else {
        let (s, c) = libm::sincos(0.5 * angle);
        let sin_a = 2.0 * s * c;
        (
            sin_a / angle,
            2.0 * s * s / a2,
            (angle - sin_a) / (a2 * angle),
            s / angle,
            c,
        )
    }
}

/// Quaternion of `Rot(v)` (series for small angles, no trig below 0.01 rad).
/// `δq(φ)` of algorithms.md §2 (series below 1e-8 rad there; this cut is a project choice).
#[must_use]
pub fn quat_from_small_rotation(v: &Vector3<f64>) -> Quat {
    let a2 = v.norm_squared();
    if a2 < SERIES_LIMIT_RAD * SERIES_LIMIT_RAD {
        let h2 = 0.25 * a2;
        let h4 = h2 * h2;
        let s = 0.5 * (1.0 - h2 / 6.0 + h4 / 120.0 - h4 * h2 / 5040.0);
        let c = 1.0 - h2 / 2.0 + h4 / 24.0 - h4 * h2 / 720.0 + h4 * h4 / 40_320.0;
        Quat::new(v.x * s, v.y * s, v.z * s, c)
    } else {
        Quat::from_rotation_vector(v)
    }
}

/// Normalised copy of a direction, `None` unless finite with norm in (0.5, 2).
fn unit(v: &Vector3<f64>) -> Option<Vector3<f64>> {
    let n = v.norm();
    (n > 0.5 && n < 2.0).then(|| v / n)
}

/// Closed-form inverse of a symmetric 2×2 matrix that must be positive definite.
fn inverse_spd2(s: &Matrix2<f64>) -> Option<Matrix2<f64>> {
    let (a, b, d) = (s.m11, 0.5 * (s.m12 + s.m21), s.m22);
    let det = a * d - b * b;
    if !(a > 0.0 && d > 0.0 && det > 0.0 && det.is_finite()) {
        return None;
    }
    let inv = Matrix2::new(d, -b, -b, a) / det;
    all_finite(inv.as_slice()).then_some(inv)
}

/// The matrix with columns `a`, `b`, `c`.
fn columns(a: &Vector3<f64>, b: &Vector3<f64>, c: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(a.x, b.x, c.x, a.y, b.y, c.y, a.z, b.z, c.z)
}

/// TRIAD attitude (ACS from ECI) from two body/reference pairs; the first pair is matched
/// exactly, the second only fixes the rotation about it.
/// TRIAD (Shuster & Oh 1981; Markley & Crassidis 2014).
///
/// # Errors
/// [`MekfError::InvalidInput`] (not finite / zero), [`MekfError::Collinear`] (pair closer than
/// [`TRIAD_MIN_SEPARATION_RAD`]), [`MekfError::Inconsistent`] (separations differ by more than
/// [`TRIAD_CONSISTENCY_RAD`]).
pub fn triad(
    b1: &Vector3<f64>,
    r1: &Vector3<f64>,
    b2: &Vector3<f64>,
    r2: &Vector3<f64>,
) -> Result<Quat, MekfError> {
    let (Some(b1), Some(r1), Some(b2), Some(r2)) = (unit(b1), unit(r1), unit(b2), unit(r2)) else {
        return Err(MekfError::InvalidInput);
    };
    let bc = b1.cross(&b2);
    let rc = r1.cross(&r2);
    let (bs, rs) = (bc.norm(), rc.norm());
    let min_sin = libm::sin(TRIAD_MIN_SEPARATION_RAD);
    if !(bs >= min_sin && rs >= min_sin) {
        return Err(MekfError::Collinear);
    }
    let sep_b = libm::atan2(bs, b1.dot(&b2));
    let sep_r = libm::atan2(rs, r1.dot(&r2));
    if !((sep_b - sep_r).abs() <= TRIAD_CONSISTENCY_RAD) {
        return Err(MekfError::Inconsistent);
    }
    let (b2n, r2n) = (bc / bs, rc / rs);
    let tb = columns(&b1, &b2n, &b1.cross(&b2n));
    let tr = columns(&r1, &r2n, &r1.cross(&r2n));
    let q = Quat::from_dcm(&(tb * tr.transpose()));
    if q.is_finite() {
        Ok(q)
    } else {
        Err(MekfError::InvalidInput)
    }
}

/// Direction measured `offset_s` seconds before the filter time, moved to the filter time
/// with the body rate: `b(t) = Rot(ω τ) b(t − τ)` (for [`crate::tables::SensorCorrections`]
/// `time_offset_s`).
/// Latency effect 1 of algorithms.md §9; `time_offset_s` of docs/tables.md (alignment table).
#[must_use]
pub fn compensate_time_offset(
    dir_acs: &Vector3<f64>,
    rate_rad_per_s: &Vector3<f64>,
    offset_s: f64,
) -> Vector3<f64> {
    crate::attitude::rot(&(rate_rad_per_s * offset_s)) * dir_acs
}

impl Default for Mekf {
    fn default() -> Self {
        Self::new()
    }
}

/// `diag(σ_θ² I, σ_b² I)`.
fn initial_covariance(attitude_sigma_rad: f64, bias_sigma_rad_per_s: f64) -> Matrix6<f64> {
    let (a, b) = (
        attitude_sigma_rad * attitude_sigma_rad,
        bias_sigma_rad_per_s * bias_sigma_rad_per_s,
    );
    Matrix6::from_diagonal(&nalgebra::Vector6::new(a, a, a, b, b, b))
}

impl Mekf {
    /// Identity attitude, zero bias, the boot table's initial covariance: a placeholder until
    /// one of the `initialize*` methods is called.
    /// Project choice (not in the paper): a defined state before initialisation.
    #[must_use]
    pub fn new() -> Self {
        let t = FilterTable::default_boot();
        Self {
            q_acs_from_eci: Quat::IDENTITY,
            bias_rad_per_s: Vector3::zeros(),
            covariance: initial_covariance(
                t.initial_attitude_sigma_rad,
                t.initial_bias_sigma_rad_per_s,
            ),
            cross_covariance_fhst_systematic: Matrix6x4::zeros(),
            fhst_systematic_sigma_rad: 0.0,
            counters: UpdateCounters::default(),
        }
    }

    /// Start from a known attitude with zero bias and the table's initial σ.
    /// algorithms.md §2 ("Reference state").
    ///
    /// # Errors
    /// [`MekfError::InvalidInput`] (state unchanged) for a non-finite or zero quaternion or
    /// invalid table σ.
    pub fn initialize(
        &mut self,
        q_acs_from_eci: &Quat,
        table: &FilterTable,
    ) -> Result<(), MekfError> {
        self.initialize_with_bias(q_acs_from_eci, &Vector3::zeros(), table)
    }

    /// Start from a known attitude and bias (e.g. the last good bias before a reset).
    /// algorithms.md §2 ("Reference state").
    ///
    /// # Errors
    /// [`MekfError::InvalidInput`] (state unchanged) for a non-finite or zero quaternion,
    /// non-finite bias or invalid table σ.
    pub fn initialize_with_bias(
        &mut self,
        q_acs_from_eci: &Quat,
        bias_rad_per_s: &Vector3<f64>,
        table: &FilterTable,
    ) -> Result<(), MekfError> {
        let n = q_acs_from_eci.norm();
        let sa = table.initial_attitude_sigma_rad;
        let sb = table.initial_bias_sigma_rad_per_s;
        let ok = (0.5..2.0).contains(&n)
            && q_acs_from_eci.is_finite()
            && bias_rad_per_s.iter().all(|x| x.is_finite())
            && positive_finite(sa)
            && positive_finite(sb);
        if !ok {
            return Err(MekfError::InvalidInput);
        }
        *self = Self {
            q_acs_from_eci: q_acs_from_eci.normalized(),
            bias_rad_per_s: *bias_rad_per_s,
            covariance: initial_covariance(sa, sb),
            cross_covariance_fhst_systematic: Matrix6x4::zeros(),
            fhst_systematic_sigma_rad: 0.0,
            counters: self.counters,
        };
        Ok(())
    }

    /// Start with no prior attitude from two simultaneous vector pairs (TRIAD, [`triad`]):
    /// body (ACS) measurements `b1`, `b2` of reference (ECI) directions `r1`, `r2`. Put the more
    /// accurate pair first (e.g. a star, then the Sun). The bias is reset to zero.
    /// TRIAD (Shuster & Oh 1981) when no attitude is known.
    ///
    /// # Errors
    /// As [`triad`] and [`Mekf::initialize`] (state unchanged).
    pub fn initialize_from_two_vectors(
        &mut self,
        b1: &Vector3<f64>,
        r1: &Vector3<f64>,
        b2: &Vector3<f64>,
        r2: &Vector3<f64>,
        table: &FilterTable,
    ) -> Result<(), MekfError> {
        let q = triad(b1, r1, b2, r2)?;
        self.initialize(&q, table)
    }

    /// Keep the estimate, reopen the covariance to the table's initial values.
    /// Project choice (not in the paper): the ground's "filter reset" command (docs/icd.md §3.3).
    ///
    /// # Errors
    /// [`MekfError::InvalidInput`] (state unchanged) for invalid table σ.
    pub fn reset_covariance(&mut self, table: &FilterTable) -> Result<(), MekfError> {
        let sa = table.initial_attitude_sigma_rad;
        let sb = table.initial_bias_sigma_rad_per_s;
        if !(positive_finite(sa) && positive_finite(sb)) {
            return Err(MekfError::InvalidInput);
        }
        self.covariance = initial_covariance(sa, sb);
        self.cross_covariance_fhst_systematic = Matrix6x4::zeros();
        Ok(())
    }

    /// Keep the estimate and the attitude covariance, reopen the bias covariance to the
    /// table's initial σ and decorrelate it from the attitude: for a change of the gyro
    /// channels that feed the filter (IRU configuration switch). The bias estimate belongs to
    /// the old channels; the new ones have their own biases (DRIRU II channel biases differ by
    /// up to ~1″/s), and a converged `P_bb` would make the filter trust the old estimate, let
    /// the attitude drift and then gate the stars that could correct it (issue 7,
    /// `scenarios/faults/iru-channel-failure-mid-slew.toml`). Reopened, `P_bb` grows `P_θθ`
    /// through propagation at the rate the bias error can move the attitude, so the next star
    /// updates are accepted and re-estimate the bias.
    /// Project choice (not in the paper): bias jumps after an IRU switch (algorithms.md §2 `P`).
    ///
    /// # Errors
    /// [`MekfError::InvalidInput`] (state unchanged) for an invalid table σ.
    pub fn reopen_bias_covariance(&mut self, table: &FilterTable) -> Result<(), MekfError> {
        let sb = table.initial_bias_sigma_rad_per_s;
        if !positive_finite(sb) {
            return Err(MekfError::InvalidInput);
        }
        let mut p = self.covariance;
        p.fixed_view_mut::<3, 3>(0, 3).fill(0.0);
        p.fixed_view_mut::<3, 3>(3, 0).fill(0.0);
        p.fixed_view_mut::<3, 3>(3, 3)
            .copy_from(&(Matrix3::identity() * (sb * sb)));
        if !covariance_ok(&p) {
            return Err(MekfError::NumericalFault);
        }
        self.covariance = p;
        self.cross_covariance_fhst_systematic
            .fixed_view_mut::<3, 4>(3, 0)
            .fill(0.0);
        Ok(())
    }

    /// Attitude 1σ per axis, rad.
    /// `√diag P₁₁` of algorithms.md §2.
    #[must_use]
    pub fn attitude_sigma_rad(&self) -> Vector3<f64> {
        let p = &self.covariance;
        sigmas(Vector3::new(p.m11, p.m22, p.m33))
    }

    /// Bias 1σ per axis, rad/s.
    /// `√diag P₂₂` of algorithms.md §2.
    #[must_use]
    pub fn bias_sigma_rad_per_s(&self) -> Vector3<f64> {
        let p = &self.covariance;
        sigmas(Vector3::new(p.m44, p.m55, p.m66))
    }

    /// Bias-corrected body rate over a step, `Δθ/Δt − b̂` (rad/s), for the controller;
    /// `None` for a non-positive or non-finite step.
    /// `ω̂ = φ/Δt` of algorithms.md §2.
    #[must_use]
    pub fn corrected_rate_rad_per_s(
        &self,
        delta_theta_acs_rad: &Vector3<f64>,
        dt_s: f64,
    ) -> Option<Vector3<f64>> {
        if !(dt_s > 0.0 && dt_s.is_finite()) {
            return None;
        }
        let w = delta_theta_acs_rad / dt_s - self.bias_rad_per_s;
        w.iter().all(|x| x.is_finite()).then_some(w)
    }

    /// Propagate over one step with the gyro increment `Δθ` (ACS, rad) measured over `dt_s`.
    /// algorithms.md §2 ("Propagation with gyro increments"; Farrenkopf `Q`).
    ///
    /// # Errors
    /// [`MekfError::InvalidInput`] (state unchanged) for non-finite input, `dt_s` outside
    /// `(0, MAX_PROPAGATION_STEP_S]` or `|Δθ| > MAX_DELTA_THETA_RAD`;
    /// [`MekfError::NumericalFault`] if the covariance would become non-finite.
    pub fn propagate(
        &mut self,
        delta_theta_acs_rad: &Vector3<f64>,
        dt_s: f64,
        table: &FilterTable,
    ) -> Result<(), MekfError> {
        let sv2 = table.arw_rad_per_sqrt_s * table.arw_rad_per_sqrt_s;
        let su2 = table.rrw_rad_per_s_sqrt_s * table.rrw_rad_per_s_sqrt_s;
        let ok = dt_s > 0.0
            && dt_s <= MAX_PROPAGATION_STEP_S
            && all_finite(delta_theta_acs_rad.as_slice())
            && delta_theta_acs_rad.norm() <= MAX_DELTA_THETA_RAD
            && sv2.is_finite()
            && su2.is_finite()
            && sv2 >= 0.0
            && su2 >= 0.0;
        if !ok {
            return Err(MekfError::InvalidInput);
        }
        let phi = delta_theta_acs_rad - self.bias_rad_per_s * dt_s;
        let angle = phi.norm();
        if !(angle <= MAX_DELTA_THETA_RAD) {
            return Err(MekfError::InvalidInput);
        }
        let (sa, oc, ps, hs, hc) = rotation_coefficients(angle);
        let k = skew(&phi);
        let k2 = k * k;
        let eye = Matrix3::identity();
        let phi11 = eye - k * sa + k2 * oc;
        let phi12 = (eye - k * oc + k2 * ps) * (-dt_s);

        let p = &self.covariance;
        let p11 = p.fixed_view::<3, 3>(0, 0).into_owned();
        let p12 = p.fixed_view::<3, 3>(0, 3).into_owned();
        let p22 = p.fixed_view::<3, 3>(3, 3).into_owned();
        let a = phi11 * p11 + phi12 * p12.transpose();
        let b = phi11 * p12 + phi12 * p22;
        let q11 = sv2 * dt_s + su2 * dt_s * dt_s * dt_s / 3.0;
        let q12 = -0.5 * su2 * dt_s * dt_s;
        let q22 = su2 * dt_s;
        let n11 = a * phi11.transpose() + b * phi12.transpose();
        let n11 = (n11 + n11.transpose()) * 0.5 + eye * q11;
        let n12 = b + eye * q12;
        let n22 = p22 + eye * q22;

        let mut np = Matrix6::zeros();
        np.fixed_view_mut::<3, 3>(0, 0).copy_from(&n11);
        np.fixed_view_mut::<3, 3>(0, 3).copy_from(&n12);
        np.fixed_view_mut::<3, 3>(3, 0).copy_from(&n12.transpose());
        np.fixed_view_mut::<3, 3>(3, 3).copy_from(&n22);
        if !covariance_ok(&np) {
            return Err(MekfError::NumericalFault);
        }
        // Consider states: `P_xc⁻ = Φ P_xc a`, `a = exp(−Δt/τ)` (their own Gauss–Markov
        // decay; their noise is independent of the gyro's).
        let c = &self.cross_covariance_fhst_systematic;
        let decay = libm::exp(-dt_s / FHST_SYSTEMATIC_CORRELATION_S);
        let (c_top, c_bot) = cross_halves(c);
        let mut nc = Matrix6x4::zeros();
        nc.fixed_view_mut::<3, 4>(0, 0)
            .copy_from(&((phi11 * c_top + phi12 * c_bot) * decay));
        nc.fixed_view_mut::<3, 4>(3, 0).copy_from(&(c_bot * decay));
        if !all_finite(nc.as_slice()) {
            return Err(MekfError::NumericalFault);
        }
        let dq = Quat::new(phi.x * hs, phi.y * hs, phi.z * hs, hc);
        self.q_acs_from_eci = dq.compose(&self.q_acs_from_eci).normalized();
        self.covariance = np;
        self.cross_covariance_fhst_systematic = nc;
        Ok(())
    }

    /// Add `variance_rad2` to each diagonal element of the attitude block `P_θθ` (an
    /// attitude error source outside the gyro model, e.g. a coast without gyro data).
    /// Project choice (not in the paper): docs/obc_filter.md §4.
    ///
    /// # Errors
    /// [`MekfError::InvalidInput`] (state unchanged) for a negative or non-finite variance.
    pub fn add_attitude_variance(&mut self, variance_rad2: f64) -> Result<(), MekfError> {
        if !(variance_rad2.is_finite() && variance_rad2 >= 0.0) {
            return Err(MekfError::InvalidInput);
        }
        let mut p = self.covariance;
        p.m11 += variance_rad2;
        p.m22 += variance_rad2;
        p.m33 += variance_rad2;
        if !covariance_ok(&p) {
            return Err(MekfError::NumericalFault);
        }
        self.covariance = p;
        Ok(())
    }

    /// Unit-vector update (drops the along-vector component): measured direction in ACS,
    /// reference direction in ECI, σ per perpendicular axis (rad), χ² gate.
    /// algorithms.md §2 ("Vector measurement update"; Joseph form).
    pub fn update_vector(
        &mut self,
        meas_dir_acs: &Vector3<f64>,
        ref_dir_eci: &Vector3<f64>,
        sigma_rad: f64,
        gate_chi2: f64,
    ) -> UpdateOutcome {
        self.update_vector_with_floor(meas_dir_acs, ref_dir_eci, sigma_rad, 0.0, gate_chi2)
    }

    /// [`Mekf::update_vector`] for a sensor whose error has a systematic part of σ
    /// `systematic_floor_rad` per axis that does not average down over samples (an alignment
    /// residual, a transfer-function error at a fixed Sun position): the update is weighted
    /// so that the posterior variance along each measured direction stays at or above
    /// `systematic_floor_rad²` (the weighting is in the private `Mekf::apply_update`). `0` = white noise only.
    /// docs/obc_filter.md §3 (systematic floor).
    pub fn update_vector_with_floor(
        &mut self,
        meas_dir_acs: &Vector3<f64>,
        ref_dir_eci: &Vector3<f64>,
        sigma_rad: f64,
        systematic_floor_rad: f64,
        gate_chi2: f64,
    ) -> UpdateOutcome {
        let (Some(z), Some(r)) = (unit(meas_dir_acs), unit(ref_dir_eci)) else {
            return self.reject(UpdateRejection::InvalidInput, [0.0; 2], f64::NAN);
        };
        let zhat = self.q_acs_from_eci.to_dcm() * r;
        if !(z.dot(&zhat) > 0.0) {
            return self.reject(UpdateRejection::Geometry, [0.0; 2], f64::NAN);
        }
        // e1 ⟂ ẑ from the axis least aligned with ẑ; e2 = ẑ × e1 (e1 × e2 = ẑ).
        let (ax, ay, az) = (zhat.x.abs(), zhat.y.abs(), zhat.z.abs());
        let axis = if ax <= ay && ax <= az {
            Vector3::x()
        } else if ay <= az {
            Vector3::y()
        } else {
            Vector3::z()
        };
        let e1 = zhat.cross(&axis).normalize();
        let e2 = zhat.cross(&e1);
        let nu = Vector2::new(e1.dot(&z), e2.dot(&z));
        let h = Matrix2x3::new(-e2.x, -e2.y, -e2.z, e1.x, e1.y, e1.z);
        self.apply_update(&nu, &h, sigma_rad, systematic_floor_rad, gate_chi2)
    }

    /// FHST focal-plane update: corrected measured angles `(H, V)` (rad), reference star
    /// direction (ECI), the tracker's `M_AS`, σ per axis (rad), χ² gate.
    /// algorithms.md §2 with the focal-plane form of algorithms.md §3.1.
    pub fn update_focal_plane(
        &mut self,
        h_rad: f64,
        v_rad: f64,
        ref_dir_eci: &Vector3<f64>,
        m_acs_from_sensor: &Matrix3<f64>,
        sigma_rad: f64,
        gate_chi2: f64,
    ) -> UpdateOutcome {
        self.update_focal_plane_with_floor(
            h_rad,
            v_rad,
            ref_dir_eci,
            m_acs_from_sensor,
            sigma_rad,
            0.0,
            gate_chi2,
        )
    }

    /// [`Mekf::update_focal_plane`] with a systematic floor per axis, rad (as
    /// [`Mekf::update_vector_with_floor`]).
    /// docs/obc_filter.md §3 (systematic floor).
    #[allow(clippy::too_many_arguments)]
    pub fn update_focal_plane_with_floor(
        &mut self,
        h_rad: f64,
        v_rad: f64,
        ref_dir_eci: &Vector3<f64>,
        m_acs_from_sensor: &Matrix3<f64>,
        sigma_rad: f64,
        systematic_floor_rad: f64,
        gate_chi2: f64,
    ) -> UpdateOutcome {
        match self.focal_plane_innovation(h_rad, v_rad, ref_dir_eci, m_acs_from_sensor) {
            Ok((nu, h)) => self.apply_update(&nu, &h, sigma_rad, systematic_floor_rad, gate_chi2),
            Err(reason) => self.reject(reason, [0.0; 2], f64::NAN),
        }
    }

    /// The focal-plane innovation `ν = (H − Ĥ, V − V̂)` and its Jacobian `h` (module docs) of
    /// a star at the current estimate; the rejection when an input is not finite or the star
    /// is behind the tracker.
    fn focal_plane_innovation(
        &self,
        h_rad: f64,
        v_rad: f64,
        ref_dir_eci: &Vector3<f64>,
        m_acs_from_sensor: &Matrix3<f64>,
    ) -> Result<(Vector2<f64>, Matrix2x3<f64>), UpdateRejection> {
        let r = unit(ref_dir_eci).ok_or(UpdateRejection::InvalidInput)?;
        let ok = h_rad.is_finite() && v_rad.is_finite() && all_finite(m_acs_from_sensor.as_slice());
        if !ok {
            return Err(UpdateRejection::InvalidInput);
        }
        let b_hat = self.q_acs_from_eci.to_dcm() * r;
        let mt = m_acs_from_sensor.transpose();
        let s_hat = mt * b_hat;
        let (h_pred, v_pred) = hv_from_dir(&s_hat).ok_or(UpdateRejection::Geometry)?;
        let nu = Vector2::new(h_rad - h_pred, v_rad - v_pred);
        let h = hv_jacobian(&s_hat) * mt * skew(&b_hat);
        Ok((nu, h))
    }

    /// Commit an accepted update: the state correction `dx = K ν` reset into `q̂` and `b̂`,
    /// the new covariance and cross-covariance; rejected (state unchanged) if any of them is
    /// not finite.
    fn commit_update(
        &mut self,
        dx: &nalgebra::Vector6<f64>,
        np: Matrix6<f64>,
        nc: Matrix6x4<f64>,
        nu_arr: [f64; 2],
        nis: f64,
    ) -> UpdateOutcome {
        let dtheta = Vector3::new(dx.x, dx.y, dx.z);
        let dbias = Vector3::new(dx.w, dx.a, dx.b);
        let q = quat_from_small_rotation(&dtheta).compose(&self.q_acs_from_eci);
        if !(q.is_finite() && all_finite(dbias.as_slice()) && all_finite(nc.as_slice())) {
            return self.reject(UpdateRejection::NumericalFault, nu_arr, nis);
        }
        self.q_acs_from_eci = q.normalized();
        self.bias_rad_per_s += dbias;
        self.covariance = np;
        self.cross_covariance_fhst_systematic = nc;
        self.counters.accepted = self.counters.accepted.saturating_add(1);
        UpdateOutcome {
            accepted: true,
            innovation_rad: nu_arr,
            nis,
            rejection: None,
        }
    }

    fn reject(&mut self, reason: UpdateRejection, nu: [f64; 2], nis: f64) -> UpdateOutcome {
        if reason == UpdateRejection::Gated {
            self.counters.gated = self.counters.gated.saturating_add(1);
        } else {
            self.counters.other_rejections = self.counters.other_rejections.saturating_add(1);
        }
        UpdateOutcome::rejected(reason, nu, nis)
    }

    /// Generic 2-component update with `H = [h 0]`, `R = σ² I₂`, and the systematic floor
    /// `f` (rad, 0 = none).
    ///
    /// With a floor, the measurement is first rotated into the eigenvectors `u₁, u₂` of the
    /// predicted measurement covariance `h P₁₁ hᵀ` (eigenvalues `λ₁, λ₂`; a rotation leaves
    /// `σ² I₂` unchanged), and component `i` gets `Rᵢ = max(σ², λᵢ f²/(λᵢ − f²))`: the
    /// posterior variance along `uᵢ`, `λᵢRᵢ/(λᵢ + Rᵢ)`, is then `≥ f²`. Where `λᵢ ≤ f²` the
    /// sensor has nothing left to tell (`Rᵢ = λᵢ / ε`, [`FLOORED_INFORMATION_FRACTION`]).
    /// This is the posterior of a sensor whose error is `white(σ) + constant(f)`, in the
    /// limit of many samples at one geometry (docs/obc_filter.md §3). The χ² gate and the
    /// reported NIS use `h P hᵀ + (σ² + f²) I`, not the floored `R`.
    fn apply_update(
        &mut self,
        nu: &Vector2<f64>,
        h: &Matrix2x3<f64>,
        sigma_rad: f64,
        floor_rad: f64,
        gate_chi2: f64,
    ) -> UpdateOutcome {
        let nu_arr = [nu.x, nu.y];
        let ok = positive_finite(sigma_rad)
            && positive_finite(gate_chi2)
            && floor_rad.is_finite()
            && floor_rad >= 0.0
            && all_finite(nu.as_slice())
            && all_finite(h.as_slice());
        if !ok {
            return self.reject(UpdateRejection::InvalidInput, [0.0; 2], f64::NAN);
        }
        let p = &self.covariance;
        let p11 = p.fixed_view::<3, 3>(0, 0).into_owned();
        // Rotate into the eigenvectors of h P₁₁ hᵀ when a floor is asked for.
        let (nu, h) = if floor_rad > 0.0 {
            let hph0 = h * p11 * h.transpose();
            let u = eigenvectors_sym2(&hph0);
            (u.transpose() * nu, u.transpose() * h)
        } else {
            (*nu, *h)
        };
        let nu = &nu;
        let h = &h;
        let p12 = p.fixed_view::<3, 3>(0, 3).into_owned();
        let ht = h.transpose();
        // P Hᵀ = [P₁₁ hᵀ; P₂₁ hᵀ]
        let pht_top: Matrix3x2<f64> = p11 * ht;
        let pht_bot: Matrix3x2<f64> = p12.transpose() * ht;
        let hph = h * pht_top;
        let numeric = 0.5 * (hph.m11 + hph.m22) / MAX_VARIANCE_REDUCTION;
        let white = (sigma_rad * sigma_rad).max(numeric);
        let r_diag = Vector2::new(
            floored_variance(white, hph.m11, floor_rad),
            floored_variance(white, hph.m22, floor_rad),
        );
        let r_mat = Matrix2::from_diagonal(&r_diag);
        let s = hph + r_mat;
        let Some(s_inv) = inverse_spd2(&s) else {
            return self.reject(UpdateRejection::Singular, nu_arr, f64::NAN);
        };
        // The gate tests the innovation against what it can be: the prediction's spread, the
        // white noise and the systematic, `S_gate = h P hᵀ + (σ² + f²) I` (the floored `R` of
        // the update would let any outlier through once `P` reaches the floor).
        let s_gate = hph + Matrix2::identity() * (white + floor_rad * floor_rad);
        let Some(s_gate_inv) = inverse_spd2(&s_gate) else {
            return self.reject(UpdateRejection::Singular, nu_arr, f64::NAN);
        };
        let nis = (nu.transpose() * s_gate_inv * nu).x;
        if !(nis <= gate_chi2) {
            return self.reject(UpdateRejection::Gated, nu_arr, nis);
        }
        let mut pht = Matrix6x2::zeros();
        pht.fixed_view_mut::<3, 2>(0, 0).copy_from(&pht_top);
        pht.fixed_view_mut::<3, 2>(3, 0).copy_from(&pht_bot);
        let k = pht * s_inv;
        // Joseph form: T = (I − KH) P = P − K (HP), HP = (PHᵀ)ᵀ for symmetric P;
        // P⁺ = T (I − KH)ᵀ + K R Kᵀ = T − (T Hᵀ − R K) Kᵀ, T Hᵀ = T[:, 0..3] hᵀ.
        let t = p - k * pht.transpose();
        let tht = t.fixed_view::<6, 3>(0, 0) * ht;
        let np = t - (tht - k * r_mat) * k.transpose();
        let np = (np + np.transpose()) * 0.5;
        if !covariance_ok(&np) {
            return self.reject(UpdateRejection::NumericalFault, nu_arr, nis);
        }
        // A measurement free of the FHST systematic errors: `P_xc⁺ = (I − K H) P_xc`.
        let c = &self.cross_covariance_fhst_systematic;
        let nc = c - k * (h * cross_top(c));
        self.commit_update(&(k * nu), np, nc, nu_arr, nis)
    }

    /// FHST focal-plane update with the tracker's systematic error as a consider state
    /// (Schmidt–Kalman): `ν = h δθ + c_k + v`, `c_k` (2, rad) the systematic error of tracker
    /// `tracker` (0 = FHST1, 1 = FHST2) in its H, V axes with variance `systematic_rad²`,
    /// `v` white with `sigma_rad²`. Inputs as [`Mekf::update_focal_plane`].
    ///
    /// `M = P Hᵀ + P_xc Eᵀ`, `S = H P Hᵀ + H P_xc Eᵀ + E P_cx Hᵀ + (f² + σ²) I`, `K = M S⁻¹`,
    /// `P⁺ = P − K S Kᵀ`, `P_xc⁺ = P_xc − K (H P_xc + f² E)` (`E` selects the tracker's two
    /// columns); the NIS and the gate use this `S`. Unlike the floor of
    /// [`Mekf::update_focal_plane_with_floor`], every sample of a star is weighted as the
    /// white + systematic model says: the white noise of the first samples keeps averaging
    /// down, and a state error from elsewhere (a slew, the other tracker) is corrected at the
    /// rate the samples allow (docs/obc_filter.md §9–10).
    #[allow(clippy::too_many_arguments)]
    pub fn update_focal_plane_consider(
        &mut self,
        h_rad: f64,
        v_rad: f64,
        ref_dir_eci: &Vector3<f64>,
        m_acs_from_sensor: &Matrix3<f64>,
        sigma_rad: f64,
        systematic_rad: f64,
        tracker: usize,
        gate_chi2: f64,
    ) -> UpdateOutcome {
        let ok = tracker < 2
            && systematic_rad.is_finite()
            && systematic_rad >= 0.0
            && positive_finite(sigma_rad)
            && positive_finite(gate_chi2);
        if !ok {
            return self.reject(UpdateRejection::InvalidInput, [0.0; 2], f64::NAN);
        }
        let (nu, h) =
            match self.focal_plane_innovation(h_rad, v_rad, ref_dir_eci, m_acs_from_sensor) {
                Ok(x) => x,
                Err(reason) => return self.reject(reason, [0.0; 2], f64::NAN),
            };
        let nu_arr = [nu.x, nu.y];
        if !all_finite(nu.as_slice()) || !all_finite(h.as_slice()) {
            return self.reject(UpdateRejection::InvalidInput, [0.0; 2], f64::NAN);
        }
        // Consider states of another σ: `P_xc` scales with it.
        // (The same σ scales by exactly 1.)
        let c_scaled = if self.fhst_systematic_sigma_rad > 0.0 {
            self.cross_covariance_fhst_systematic
                * (systematic_rad / self.fhst_systematic_sigma_rad)
        } else {
            Matrix6x4::zeros()
        };
        let p = &self.covariance;
        let c = &c_scaled;
        let ht = h.transpose();
        let pht_top: Matrix3x2<f64> = p.fixed_view::<3, 3>(0, 0) * ht;
        let pht_bot: Matrix3x2<f64> = p.fixed_view::<3, 3>(3, 0) * ht;
        let mut m = Matrix6x2::zeros();
        m.fixed_view_mut::<3, 2>(0, 0).copy_from(&pht_top);
        m.fixed_view_mut::<3, 2>(3, 0).copy_from(&pht_bot);
        // The tracker's two columns, and `f² E` (constant offsets: no runtime index).
        // (`copy_from` into owned matrices: `into_owned` of these views keeps a panic path
        // that the no-panic link check finds.)
        let mut ck = Matrix6x2::zeros();
        let f2e = if tracker == 0 {
            ck.copy_from(&c.fixed_view::<6, 2>(0, 0));
            Matrix2x4::new(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0)
        } else {
            ck.copy_from(&c.fixed_view::<6, 2>(0, 2));
            Matrix2x4::new(0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0)
        };
        let hph = h * pht_top;
        let hck = h * ck.fixed_view::<3, 2>(0, 0);
        let numeric = 0.5 * (hph.m11 + hph.m22) / MAX_VARIANCE_REDUCTION;
        let white = (sigma_rad * sigma_rad).max(numeric);
        let f2 = systematic_rad * systematic_rad;
        let s = hph + hck + hck.transpose() + Matrix2::identity() * (white + f2);
        let s = (s + s.transpose()) * 0.5;
        let Some(s_inv) = inverse_spd2(&s) else {
            return self.reject(UpdateRejection::Singular, nu_arr, f64::NAN);
        };
        let nis = (nu.transpose() * s_inv * nu).x;
        if !(nis <= gate_chi2) {
            return self.reject(UpdateRejection::Gated, nu_arr, nis);
        }
        let m = m + ck;
        let k = m * s_inv;
        let np = p - k * s * k.transpose();
        let np = (np + np.transpose()) * 0.5;
        if !covariance_ok(&np) {
            return self.reject(UpdateRejection::NumericalFault, nu_arr, nis);
        }
        let hc: Matrix2x4<f64> = h * cross_top(c) + f2e * f2;
        let nc = c - k * hc;
        let outcome = self.commit_update(&(k * nu), np, nc, nu_arr, nis);
        if outcome.accepted {
            self.fhst_systematic_sigma_rad = systematic_rad;
        }
        outcome
    }
}

/// Fraction of a component's prior information a floored measurement may still carry when
/// its predicted variance is already at the floor (`R = λ / ε`): small enough to be
/// negligible, large enough to keep `S` well conditioned.
/// Project choice (not in the paper): numerical, docs/obc_filter.md §3.
pub const FLOORED_INFORMATION_FRACTION: f64 = 1.0e-6;

/// Measurement variance for one component with predicted variance `lambda` (`h P hᵀ`), white
/// variance `white` and systematic floor `floor_rad`: `max(white, λ f²/(λ − f²))`, or
/// `λ/ε` when `λ ≤ f²` (docs/obc_filter.md §3).
fn floored_variance(white: f64, lambda: f64, floor_rad: f64) -> f64 {
    let f2 = floor_rad * floor_rad;
    if f2 <= 0.0 {
        return white;
    }
    // λ ≤ f²·(1 + ε): nothing left to learn (also covers λ ≤ 0 from rounding).
    if !(lambda > f2 * (1.0 + FLOORED_INFORMATION_FRACTION)) {
        return (lambda.max(white) / FLOORED_INFORMATION_FRACTION).max(white);
    }
    white.max(lambda * f2 / (lambda - f2))
}

/// Orthonormal eigenvectors (columns) of a symmetric 2×2 matrix, closed form
/// (`φ = ½ atan2(2b, a − d)`); the identity for a multiple of the identity.
fn eigenvectors_sym2(m: &Matrix2<f64>) -> Matrix2<f64> {
    let (a, b, d) = (m.m11, 0.5 * (m.m12 + m.m21), m.m22);
    let phi = 0.5 * libm::atan2(2.0 * b, a - d);
    let (sn, cs) = libm::sincos(phi);
    if !(sn.is_finite() && cs.is_finite()) {
        return Matrix2::identity();
    }
    Matrix2::new(cs, -sn, sn, cs)
}

/// The δθ and δb rows of the consider cross-covariance, as owned 3×4 matrices (`copy_from`:
/// `into_owned` of these views keeps a panic path that the no-panic link check finds).
fn cross_halves(c: &Matrix6x4<f64>) -> (Matrix3x4<f64>, Matrix3x4<f64>) {
    let mut top = Matrix3x4::zeros();
    let mut bot = Matrix3x4::zeros();
    top.copy_from(&c.fixed_view::<3, 4>(0, 0));
    bot.copy_from(&c.fixed_view::<3, 4>(3, 0));
    (top, bot)
}

/// The δθ rows of the consider cross-covariance (what a measurement's `h` multiplies).
fn cross_top(c: &Matrix6x4<f64>) -> Matrix3x4<f64> {
    let mut top = Matrix3x4::zeros();
    top.copy_from(&c.fixed_view::<3, 4>(0, 0));
    top
}

/// `x > 0` and finite (false for NaN).
/// `√max(0, v)` per element: 1σ from three variances (a negative rounding residue reads 0).
fn sigmas(variances: Vector3<f64>) -> Vector3<f64> {
    variances.map(|v| libm::sqrt(v.max(0.0)))
}

fn positive_finite(x: f64) -> bool {
    x > 0.0 && x.is_finite()
}

/// Every element finite: the sum of finite numbers of covariance size is finite, and any NaN
/// or infinity makes it non-finite (a plain loop, cheaper than per-element tests).
fn all_finite(values: &[f64]) -> bool {
    values.iter().fold(0.0, |acc, x| acc + x).is_finite()
}

/// Finite with a positive diagonal.
fn covariance_ok(p: &Matrix6<f64>) -> bool {
    all_finite(p.as_slice())
        && p.m11 > 0.0
        && p.m22 > 0.0
        && p.m33 > 0.0
        && p.m44 > 0.0
        && p.m55 > 0.0
        && p.m66 > 0.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::attitude::{attitude_error_rad, rot};

    /// One static star on one tracker, white σ 12″, the systematic σ 3.65″ declared and none
    /// present, 600 samples after a 60″ prior error, over 20 noise sequences: the consider
    /// update averages every sample (error ≈ 12/√600 = 0.5″), the floored update keeps the
    /// first `σ²/f²` ≈ 11 samples' noise (≈ 3.6″) (docs/obc_filter.md §9–10). The consider
    /// σ stays near the declared systematic (the samples cannot tell it is absent).
    #[test]
    fn consider_update_keeps_averaging_where_the_floored_update_freezes() {
        let t = table();
        let arcsec = crate::units::RAD_PER_ARCSEC;
        let (sigma, f) = (12.0 * arcsec, 3.65 * arcsec);
        let r = Vector3::new(0.01, 0.02, 1.0).normalize();
        let m = Matrix3::identity();
        let (h_true, v_true) = hv_from_dir(&r).unwrap();
        let mut state: u64 = 0x1234_5678;
        let mut gauss = || {
            // 12 uniforms (Irwin–Hall): enough for a test of averages.
            let mut acc = -6.0;
            for _ in 0..12 {
                state = state
                    .wrapping_mul(6_364_136_223_846_793_005)
                    .wrapping_add(1_442_695_040_888_963_407);
                acc += (state >> 11) as f64 / (1u64 << 53) as f64;
            }
            acc
        };
        let (mut sq_consider, mut sq_floor, mut sigma_consider) = (0.0, 0.0, f64::INFINITY);
        let trials = 20;
        for _ in 0..trials {
            let q0 = quat_from_small_rotation(&(Vector3::new(40.0, -45.0, 0.0) * arcsec));
            let mut a = Mekf::new();
            a.initialize(&q0, &t).unwrap();
            a.covariance
                .fixed_view_mut::<3, 3>(0, 0)
                .fill_diagonal((60.0 * arcsec).powi(2));
            // A converged bias (0.001″/s): the test is about the attitude's averaging.
            a.covariance
                .fixed_view_mut::<3, 3>(3, 3)
                .fill_diagonal((1e-3 * arcsec).powi(2));
            let mut b = a;
            for _ in 0..600 {
                let (h, v) = (h_true + sigma * gauss(), v_true + sigma * gauss());
                a.propagate(&Vector3::zeros(), 1.0, &t).unwrap();
                b.propagate(&Vector3::zeros(), 1.0, &t).unwrap();
                a.update_focal_plane_consider(h, v, &r, &m, sigma, f, 0, 1e6);
                b.update_focal_plane_with_floor(h, v, &r, &m, sigma, f, 1e6);
            }
            let ea = attitude_error_rad(&Quat::IDENTITY, &a.q_acs_from_eci);
            let eb = attitude_error_rad(&Quat::IDENTITY, &b.q_acs_from_eci);
            sq_consider += ea.x * ea.x + ea.y * ea.y;
            sq_floor += eb.x * eb.x + eb.y * eb.y;
            let s = a.attitude_sigma_rad();
            sigma_consider = sigma_consider.min(s.x.min(s.y));
        }
        let rms = |sq: f64| (sq / (2.0 * f64::from(trials))).sqrt() / arcsec;
        let (rc, rf) = (rms(sq_consider), rms(sq_floor));
        assert!(
            rc < 1.2,
            "consider: RMS error {rc:.2}″ (white-noise average 0.5″)"
        );
        assert!(
            rf > 2.0,
            "floor: RMS error {rf:.2}″ (the freeze this test shows)"
        );
        assert!(
            sigma_consider > 0.7 * f,
            "consider σ {:.2}″ below the declared systematic",
            sigma_consider / arcsec
        );
    }

    /// A new systematic σ (the onboard orbit becoming valid: 3.65″ → 0.02″) scales the
    /// cross-covariance: the next updates keep `P` positive definite and the filter keeps
    /// taking stars (without the scaling it lost definiteness and gated every star).
    #[test]
    fn consider_update_survives_a_change_of_the_systematic_sigma() {
        let t = table();
        let arcsec = crate::units::RAD_PER_ARCSEC;
        let r = Vector3::new(0.01, 0.02, 1.0).normalize();
        let m = Matrix3::identity();
        let (h, v) = hv_from_dir(&r).unwrap();
        let mut f = Mekf::new();
        f.initialize(&Quat::IDENTITY, &t).unwrap();
        for k in 0..400 {
            let sys = if k < 200 { 3.65 } else { 0.02 };
            f.propagate(&Vector3::zeros(), 1.0, &t).unwrap();
            let o =
                f.update_focal_plane_consider(h, v, &r, &m, 8.0 * arcsec, sys * arcsec, 0, 11.83);
            assert!(o.accepted, "sample {k}: {o:?}");
        }
        let p = f.covariance;
        assert!(p.symmetric_eigen().eigenvalues.iter().all(|&e| e > 0.0));
        assert!((f.fhst_systematic_sigma_rad - 0.02 * arcsec).abs() < 1e-15);
    }

    fn table() -> FilterTable {
        FilterTable::default_boot()
    }

    #[test]
    fn coefficients_series_and_trig_agree_at_the_switch() {
        let below = rotation_coefficients(SERIES_LIMIT_RAD * (1.0 - 1e-12));
        let x = SERIES_LIMIT_RAD;
        let exact = (
            x.sin() / x,
            2.0 * (x / 2.0).sin().powi(2) / (x * x),
            (x - x.sin()) / (x * x * x),
            (x / 2.0).sin() / x,
            (x / 2.0).cos(),
        );
        assert!((below.0 - exact.0).abs() < 1e-15);
        assert!((below.1 - exact.1).abs() < 1e-15);
        assert!((below.2 - exact.2).abs() < 1e-9); // exact form itself loses ~1e-10 here
        assert!((below.3 - exact.3).abs() < 1e-15);
        assert!((below.4 - exact.4).abs() < 1e-15);
        let above = rotation_coefficients(x * (1.0 + 1e-12));
        assert!((above.2 - below.2).abs() < 1e-9);
    }

    #[test]
    fn small_rotation_quaternion_matches_the_exact_one() {
        for v in [
            Vector3::new(1e-9, 0.0, -2e-9),
            Vector3::new(3e-3, -4e-3, 5e-3),
            Vector3::new(0.2, 0.1, -0.3),
        ] {
            let a = quat_from_small_rotation(&v);
            let b = Quat::from_rotation_vector(&v);
            assert!((a.vector() - b.vector()).norm() < 1e-17 && (a.w - b.w).abs() < 2e-16);
        }
    }

    #[test]
    fn propagation_is_the_exact_rotation_and_phi_matches_finite_differences() {
        let mut f = Mekf::new();
        f.initialize(&Quat::IDENTITY, &table()).unwrap();
        f.bias_rad_per_s = Vector3::new(1e-4, -2e-4, 5e-5);
        let dt = 1.0;
        for dth in [
            Vector3::new(0.003, -0.001, 0.002),
            Vector3::new(0.05, 0.02, -0.04),
        ] {
            let mut g = f;
            g.propagate(&dth, dt, &table()).unwrap();
            let phi = dth - f.bias_rad_per_s * dt;
            let expect = rot(&phi) * f.q_acs_from_eci.to_dcm();
            assert!((g.q_acs_from_eci.to_dcm() - expect).norm() < 1e-14);

            // Φ by finite differences of the nonlinear error propagation:
            // δθ⁺ for an initial δθ and δb, with the true increment Δθ − (b̂+δb)Δt.
            let (sa, oc, ps, _, _) = rotation_coefficients(phi.norm());
            let k = skew(&phi);
            let phi11 = Matrix3::identity() - k * sa + k * k * oc;
            let phi12 = (Matrix3::identity() - k * oc + k * k * ps) * (-dt);
            let eps = 1e-7;
            for j in 0..3 {
                let mut d = Vector3::zeros();
                d[j] = eps;
                // attitude column
                let a_true0 = rot(&d) * f.q_acs_from_eci.to_dcm();
                let a_true1 = rot(&phi) * a_true0;
                let e = attitude_error_rad(&Quat::from_dcm(&a_true1), &g.q_acs_from_eci);
                assert!((e / eps - phi11.column(j)).norm() < 1e-6);
                // bias column
                let a_true1 = rot(&(phi - d)) * f.q_acs_from_eci.to_dcm();
                let e = attitude_error_rad(&Quat::from_dcm(&a_true1), &g.q_acs_from_eci);
                assert!((e / eps - phi12.column(j)).norm() < 1e-6, "{e:?} {phi12:?}");
            }
        }
    }

    #[test]
    fn vector_update_moves_toward_the_measurement_and_shrinks_p() {
        let t = table();
        let truth = Quat::from_rotation_vector(&Vector3::new(0.3, -0.2, 1.0));
        let err = Vector3::new(0.004, -0.006, 0.002);
        let est = Quat::from_rotation_vector(&(-err)).compose(&truth);
        let mut f = Mekf::new();
        f.initialize(&est, &t).unwrap();
        let e0 = attitude_error_rad(&truth, &f.q_acs_from_eci);
        let r = Vector3::new(0.1, 0.7, -0.3).normalize();
        let z = truth.to_dcm() * r;
        let out = f.update_vector(&z, &r, 1e-5, 11.83);
        assert!(out.accepted, "{out:?}");
        let e1 = attitude_error_rad(&truth, &f.q_acs_from_eci);
        // The components perpendicular to z are corrected, the one along z is not.
        let along = z * z.dot(&e0);
        assert!((e1 - along).norm() < 0.02 * e0.norm(), "{e0:?} -> {e1:?}");
        assert!(f.covariance.trace() < Mekf::new().covariance.trace());
        let p = f.covariance;
        assert!((p - p.transpose()).norm() == 0.0);
        assert!(p.cholesky().is_some());
    }

    #[test]
    fn focal_plane_update_matches_vector_update_direction() {
        let t = table();
        let al = crate::tables::AlignmentTable::prelaunch();
        let m = crate::fhst::FhstId::Fhst1.m_acs_from_sensor(&al);
        let truth = Quat::from_rotation_vector(&Vector3::new(-0.5, 0.1, 0.4));
        let err = Vector3::new(-0.003, 0.002, 0.004);
        let est = Quat::from_rotation_vector(&(-err)).compose(&truth);
        // A star 1 deg off the boresight.
        let s = crate::fhst::dir_from_hv(0.017, -0.01);
        let r = truth.to_dcm().transpose() * (m * s);
        let mut f = Mekf::new();
        f.initialize(&est, &t).unwrap();
        let out = f.update_focal_plane(0.017, -0.01, &r, &m, 1e-5, 11.83);
        assert!(out.accepted);
        let e1 = attitude_error_rad(&truth, &f.q_acs_from_eci);
        let b = m * s;
        let e0 = attitude_error_rad(&truth, &est);
        assert!((e1 - b * b.dot(&e0)).norm() < 0.02 * e0.norm(), "{e1:?}");
    }

    #[test]
    fn gating_and_invalid_inputs_are_rejected_without_change() {
        let t = table();
        let mut f = Mekf::new();
        f.initialize(&Quat::IDENTITY, &t).unwrap();
        f.covariance = Matrix6::identity() * 1e-12;
        let before = f;
        let r = Vector3::new(0.0, 0.0, 1.0);
        // 0.01 rad off with σ = 1e-5: NIS huge.
        let z = Vector3::new(0.01, 0.0, 1.0);
        let out = f.update_vector(&z, &r, 1e-5, 11.83);
        assert_eq!(out.rejection, Some(UpdateRejection::Gated));
        assert!(out.nis > 1e5);
        for (z, s, g) in [
            (Vector3::new(f64::NAN, 0.0, 1.0), 1e-5, 11.83),
            (Vector3::new(0.0, 0.0, 1.0), f64::NAN, 11.83),
            (Vector3::new(0.0, 0.0, 1.0), 1e-5, f64::INFINITY),
            (Vector3::new(0.0, 0.0, 0.0), 1e-5, 11.83),
            (Vector3::new(0.0, 0.0, 1.0), -1.0, 11.83),
        ] {
            let out = f.update_vector(&z, &r, s, g);
            assert_eq!(out.rejection, Some(UpdateRejection::InvalidInput));
        }
        assert_eq!(
            f.update_vector(&Vector3::new(0.0, 0.0, -1.0), &r, 1e-5, 11.83)
                .rejection,
            Some(UpdateRejection::Geometry)
        );
        let m = Matrix3::identity();
        assert_eq!(
            f.update_focal_plane(0.0, 0.0, &-r, &m, 1e-5, 11.83)
                .rejection,
            Some(UpdateRejection::Geometry)
        );
        assert_eq!(
            f.update_focal_plane(f64::NAN, 0.0, &r, &m, 1e-5, 11.83)
                .rejection,
            Some(UpdateRejection::InvalidInput)
        );
        assert_eq!(f.q_acs_from_eci, before.q_acs_from_eci);
        assert_eq!(f.covariance, before.covariance);
        assert_eq!(f.counters.gated, 1);
        assert_eq!(f.counters.other_rejections, 8);
        assert!(f
            .propagate(&Vector3::new(f64::NAN, 0.0, 0.0), 1.0, &t)
            .is_err());
        assert!(f.propagate(&Vector3::zeros(), 0.0, &t).is_err());
        assert!(f.propagate(&Vector3::zeros(), f64::NAN, &t).is_err());
        assert!(f.propagate(&Vector3::new(1.0, 0.0, 0.0), 1.0, &t).is_err());
        assert_eq!(f.covariance, before.covariance);
    }

    #[test]
    fn reopening_the_bias_keeps_the_attitude_block_and_decorrelates() {
        let t = table();
        let mut f = Mekf::new();
        f.initialize(&Quat::IDENTITY, &t).unwrap();
        // Converge a little and correlate attitude and bias by propagation.
        f.covariance = Matrix6::identity() * 1e-14;
        for _ in 0..100 {
            f.propagate(&Vector3::new(1e-4, 0.0, 0.0), 1.0, &t).unwrap();
        }
        let before = f;
        assert!(before.covariance.fixed_view::<3, 3>(0, 3).norm() > 0.0);
        f.reopen_bias_covariance(&t).unwrap();
        assert_eq!(
            f.covariance.fixed_view::<3, 3>(0, 0),
            before.covariance.fixed_view::<3, 3>(0, 0)
        );
        assert!(f
            .covariance
            .fixed_view::<3, 3>(0, 3)
            .iter()
            .all(|x| *x == 0.0));
        let sb = t.initial_bias_sigma_rad_per_s;
        assert_eq!(f.bias_sigma_rad_per_s(), Vector3::repeat(sb));
        assert_eq!(f.q_acs_from_eci, before.q_acs_from_eci);
        assert_eq!(f.bias_rad_per_s, before.bias_rad_per_s);
        let mut bad = t;
        bad.initial_bias_sigma_rad_per_s = f64::NAN;
        assert_eq!(f.reopen_bias_covariance(&bad), Err(MekfError::InvalidInput));
    }

    #[test]
    fn near_zero_sigma_does_not_break_positive_definiteness() {
        // Found by the est (mekf_robust) property test: σ = 5.7e-12 rad against a 1° prior.
        let mut f = Mekf::new();
        f.initialize(
            &Quat::from_rotation_vector(&Vector3::new(0.1, 0.2, 0.3)),
            &table(),
        )
        .unwrap();
        let m = Matrix3::new(0.0, 0.0, 1.0, 0.0, 1.0, 0.0, -1.0, 0.0, 0.0);
        let out = f.update_focal_plane(
            0.0,
            0.0,
            &Vector3::new(0.672_719_502_888_829_6, 0.0, 0.0),
            &m,
            5.730_599_888_929_648_6e-12,
            1e164,
        );
        assert!(out.accepted);
        assert!(f.covariance.cholesky().is_some());
    }

    #[test]
    fn triad_recovers_the_attitude_and_checks_geometry() {
        let q = Quat::from_rotation_vector(&Vector3::new(1.0, -2.0, 0.5));
        let a = q.to_dcm();
        let r1 = Vector3::new(0.3, 0.4, 0.5).normalize();
        let r2 = Vector3::new(-0.7, 0.1, 0.2).normalize();
        let est = triad(&(a * r1), &r1, &(a * r2), &r2).unwrap();
        assert!(est.angle_to_rad(&q) < 1e-12);
        let mut f = Mekf::new();
        f.initialize_from_two_vectors(&(a * r1), &r1, &(a * r2), &r2, &table())
            .unwrap();
        assert!(f.q_acs_from_eci.angle_to_rad(&q) < 1e-12);
        assert_eq!(triad(&r1, &r1, &r1, &r1), Err(MekfError::Collinear));
        assert_eq!(
            triad(
                &(a * r1),
                &r1,
                &(a * r2),
                &(rot(&Vector3::new(0.0, 0.0, 0.05)) * r2)
            ),
            Err(MekfError::Inconsistent)
        );
        assert_eq!(
            triad(&Vector3::zeros(), &r1, &r2, &r2),
            Err(MekfError::InvalidInput)
        );
    }

    #[test]
    fn time_offset_compensation() {
        let b = Vector3::new(0.0, 0.0, 1.0);
        let w = Vector3::new(0.01, 0.0, 0.0);
        // A(t) = Rot(ωτ) A(t−τ): the body turned +0.5 mrad about x.
        let c = compensate_time_offset(&b, &w, 0.05);
        assert!((c - rot(&Vector3::new(5e-4, 0.0, 0.0)) * b).norm() < 1e-15);
        assert!((c.y - 5e-4).abs() < 1e-9);
    }
}
