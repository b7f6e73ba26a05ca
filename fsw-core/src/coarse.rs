//! # Coarse attitude from the Sun, the magnetometers and the gyros
//!
//! Why: GRO's coarse-attitude requirement is 2° (3σ) per axis from FSS, TAM and IRU data; the
//! fine attitude needs star identification, which needs an attitude good to a fraction of a
//! degree first, and every slew, safe hold or lost track falls back on this solution. It runs
//! alongside the fine filter, whatever the mode, so that it can be compared with it.
//!
//! * **Vectors.** The Sun in ACS from an FSS (through the active alignment table) or, when no
//!   FSS sees it, from the six coarse Sun sensor eyes (`v = Σ cᵢ/k · nᵢ`, normalised: exact for
//!   cosine eyes in ± pairs, biased by Earth albedo, hence the CSS's larger σ). The field in ACS
//!   from TAM1 (TAM2 when TAM1 has no data): `B = M_AS (s ∘ counts − b)` with the magnetics
//!   table's alignment, count size and bias. References: the onboard Sun ephemeris and the
//!   onboard field model ([`crate::field_model`]) at the onboard orbit's position.
//! * **Fix.** TRIAD with the more accurate vector as anchor (algorithms.md §10a). Its
//!   covariance (Shuster & Oh, *J. Guidance* 4(1), 1981, in the form derived in
//!   docs/magnetics.md §5): with anchor `b₁` (σ₁), second vector `b₂` (σ₂), `c = b₁·b₂`,
//!   `s = |b₁ × b₂|`, `G = I + (c/s²) b₁ b₂ᵀ`:
//!   `P = σ₁² G (I − b₁b₁ᵀ) Gᵀ + (σ₂²/s²) b₁b₁ᵀ` — the rotation about the anchor is known only
//!   through the second vector, worse as the two close up; below the table's smallest angle
//!   no fix is made and the reason is reported.
//! * **Between fixes** (and in eclipse) the solution is carried on the gyro increments with the
//!   fine filter's bias estimate; its covariance grows by the angle random walk and by the
//!   filter's bias uncertainty times the time since the fix.

use nalgebra::{Matrix3, Vector3};

use crate::attitude::Quat;
use crate::field_model::{self, FieldModelError};
use crate::fss::{self, FssId};
use crate::raw::{
    CssSample, RawSensorFrame, TamSample, CSS_FLAG_VALID, TAMS, TAM_FLAG_TORQUERS_ON,
    TAM_FLAG_VALID,
};
use crate::tables::magnetics::{matrix, MagneticsTable};
use crate::tables::AlignmentTable;

/// nT per mG.
/// Project choice: the unit definition (1 G = 10⁵ nT).
pub const NT_PER_MILLIGAUSS: f64 = 100.0;

/// Smallest `|Σ cᵢ/k · nᵢ|` read as "the Sun is in view of the CSS eyes" (1 with the full Sun,
/// ≤ 0.3 from Earth albedo alone).
/// Project choice: docs/magnetics.md §5.
pub const CSS_MIN_SUN_NORM: f64 = 0.6;

/// Gate on a fix vector against the carried solution: `angle² / (σ_vec² + tr P) >` this
/// rejects it (χ² with 2 degrees of freedom at a false-alarm probability of 1e-6).
/// Project choice: docs/magnetics.md §5 (fault screening).
pub const GATE_CHI2: f64 = 27.6;
/// After this many consecutive gated attempts the gate is released for one fix (the carried
/// solution is then the suspect, not the vectors).
/// Project choice: docs/magnetics.md §5 (fault screening).
pub const GATE_RELEASE_ATTEMPTS: u16 = 30;
/// A TAM whose field magnitude differs from the model's by more than
/// `5 σ_field + this × |B_model|` is rejected (a stuck, dead or saturated magnetometer).
/// Project choice: docs/magnetics.md §5 (scale and model errors ≤ 1 %).
pub const TAM_MAGNITUDE_RELATIVE_TOLERANCE: f64 = 0.02;

/// Which vectors made the last fix.
/// Project choice (not in the paper): docs/magnetics.md §5.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum CoarseSource {
    /// No fix yet.
    /// docs/magnetics.md §5.
    #[default]
    None = 0,
    /// FSS Sun and TAM field.
    /// Paper: coarse attitude from FSS and TAM data.
    FssTam = 1,
    /// CSS Sun and TAM field.
    /// docs/magnetics.md §5.
    CssTam = 2,
}

/// Why a fix was not made this time.
/// Project choice (not in the paper): the reason codes of event 0x0901 (docs/icd.md §3.3).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CoarseUnavailable {
    /// The magnetics table holds no field model (the boot table).
    /// docs/tables.md (Table 6, field 0).
    NoFieldModel,
    /// No valid onboard orbit (no orbit table, or the orbit is invalid).
    /// docs/tables.md (Table 5).
    NoOrbit,
    /// Neither TAM has data.
    /// docs/icd.md §3.5.
    NoField,
    /// Neither FSS nor the CSS eyes see the Sun (eclipse, or the Sun outside every FOV).
    /// docs/magnetics.md §5.
    NoSun,
    /// The Sun and the field are closer than the table's smallest angle.
    /// algorithms.md §10a ("near-parallel vectors").
    NearlyParallel,
    /// The field model refused the time or position.
    /// docs/magnetics.md §5 ([`FieldModelError`]).
    FieldModel(FieldModelError),
    /// The Sun ephemeris refused the time.
    /// docs/magnetics.md §5 (the onboard Sun ephemeris, Meeus ch. 25).
    Ephemeris,
    /// A non-finite value in the solution.
    /// Project choice (defensive check).
    NotFinite,
    /// Every TAM with data failed the magnitude check against the model.
    /// docs/magnetics.md §5 (fault screening).
    TamMagnitude,
    /// A vector disagreed with the carried solution beyond [`GATE_CHI2`].
    /// docs/magnetics.md §5 (fault screening).
    Gated,
    /// A Sun sensor reads a Sun while the onboard orbit puts the spacecraft in the Earth's
    /// shadow (a reflection or Earth light): no Sun vector is used.
    /// docs/magnetics.md §5 (fault screening).
    InShadow,
    /// Every TAM with data was sampled while a torquer bar was driven (its flag
    /// `TAM_FLAG_TORQUERS_ON`: the bars were to be off, so a bar is stuck on): no field used.
    /// docs/magnetics.md §7 (fault screening).
    TorquersOn,
}

impl CoarseUnavailable {
    /// Reason code (event 0x0901 p1).
    /// docs/icd.md §3.3.
    #[must_use]
    pub fn code(self) -> u32 {
        match self {
            Self::NoFieldModel => 1,
            Self::NoOrbit => 2,
            Self::NoField => 3,
            Self::NoSun => 4,
            Self::NearlyParallel => 5,
            Self::FieldModel(FieldModelError::NoModel) => 6,
            Self::FieldModel(FieldModelError::OutsideSpan) => 7,
            Self::FieldModel(FieldModelError::BadPosition) => 8,
            Self::FieldModel(FieldModelError::NotFinite) => 9,
            Self::Ephemeris => 10,
            Self::NotFinite => 11,
            Self::TamMagnitude => 12,
            Self::Gated => 13,
            Self::InShadow => 14,
            Self::TorquersOn => 15,
        }
    }
}

/// One measured direction with its reference and 1σ per axis.
/// algorithms.md §10a (TRIAD, QUEST weights).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VectorPair {
    /// Measured direction, ACS (unit).
    /// algorithms.md §1 (`b = A r`).
    pub body: Vector3<f64>,
    /// Reference direction, J2000 (unit).
    /// algorithms.md §1.
    pub reference: Vector3<f64>,
    /// 1σ per axis of the measured direction against the reference, rad.
    /// algorithms.md §10a.
    pub sigma_rad: f64,
}

/// The field a TAM measures, mG on ACS axes, or `None` without data.
/// `B = M_AS (s ∘ counts − b)` with the magnetics table's fields 9–11 (docs/tables.md Table 6).
#[must_use]
pub fn tam_field_acs_milligauss(
    sample: &TamSample,
    unit: usize,
    table: &MagneticsTable,
) -> Option<Vector3<f64>> {
    if sample.flags & TAM_FLAG_VALID == 0 {
        return None;
    }
    let scale = table.tam_milligauss_per_count.get(unit)?;
    let bias = table.tam_bias_milligauss.get(unit)?;
    let m = matrix(table.m_acs_from_tam.get(unit)?);
    let [cx, cy, cz] = sample.field_counts;
    let [sx, sy, sz] = *scale;
    let b_tam = Vector3::new(f64::from(cx) * sx, f64::from(cy) * sy, f64::from(cz) * sz)
        - Vector3::from(*bias);
    let b = m * b_tam;
    b.iter().all(|x| x.is_finite()).then_some(b)
}

/// The Sun direction in ACS from the CSS eyes, or `None` when they do not see the Sun.
/// `v = Σ cᵢ/k · nᵢ` (docs/magnetics.md §5); [`CSS_MIN_SUN_NORM`].
#[must_use]
pub fn css_sun_acs(sample: &CssSample, table: &MagneticsTable) -> Option<Vector3<f64>> {
    if sample.flags & CSS_FLAG_VALID == 0 {
        return None;
    }
    let k = table.css_counts_at_normal_incidence;
    let v = sample
        .counts
        .iter()
        .zip(table.css_normals_acs.iter())
        .fold(Vector3::zeros(), |acc, (c, n)| {
            acc + Vector3::from(*n) * (f64::from(*c) / k)
        });
    let norm = v.norm();
    (norm.is_finite() && norm >= CSS_MIN_SUN_NORM).then(|| v / norm)
}

/// Whether `pos_eci_km` is in the Earth's shadow for the Sun direction `sun_eci` (unit): a
/// cylinder of the Earth's equatorial radius behind the Earth (the penumbra, ≈ 8 s of a LEO
/// orbit, counts as sunlit).
/// Project choice: docs/magnetics.md §5 (cylindrical shadow, Wertz 1978 §3.5).
#[must_use]
pub fn in_earth_shadow(pos_eci_km: &Vector3<f64>, sun_eci: &Vector3<f64>) -> bool {
    let along = pos_eci_km.dot(sun_eci);
    along < 0.0 && (pos_eci_km - sun_eci * along).norm() < crate::orbit::EARTH_EQUATORIAL_RADIUS_KM
}

/// TRIAD with `anchor` first, and its attitude covariance (rad², ACS axes).
/// algorithms.md §10a; Shuster & Oh (1981); the covariance form of docs/magnetics.md §5.
///
/// # Errors
/// [`CoarseUnavailable::NearlyParallel`] when the vectors are closer than `min_angle_rad`;
/// [`CoarseUnavailable::NotFinite`].
pub fn triad(
    anchor: &VectorPair,
    other: &VectorPair,
    min_angle_rad: f64,
) -> Result<(Quat, Matrix3<f64>), CoarseUnavailable> {
    let b1 = anchor.body.normalize();
    let b2 = other.body.normalize();
    let r1 = anchor.reference.normalize();
    let r2 = other.reference.normalize();
    let nb = b1.cross(&b2);
    let nr = r1.cross(&r2);
    let s = nb.norm();
    if !(s >= libm::sin(min_angle_rad)) || !(nr.norm() >= libm::sin(min_angle_rad)) {
        return Err(CoarseUnavailable::NearlyParallel);
    }
    let t2b = nb / s;
    let t2r = nr / nr.norm();
    let t3b = b1.cross(&t2b);
    let t3r = r1.cross(&t2r);
    let body = Matrix3::from_columns(&[b1, t2b, t3b]);
    let reference = Matrix3::from_columns(&[r1, t2r, t3r]);
    let a = body * reference.transpose();
    let q = Quat::from_dcm(&a).normalized();
    let c = b1.dot(&b2);
    let s2 = s * s;
    let eye = Matrix3::identity();
    let g = eye + b1 * b2.transpose() * (c / s2);
    let perp = eye - b1 * b1.transpose();
    let (v1, v2) = (
        anchor.sigma_rad * anchor.sigma_rad,
        other.sigma_rad * other.sigma_rad,
    );
    let p = g * perp * g.transpose() * v1 + b1 * b1.transpose() * (v2 / s2);
    let p = (p + p.transpose()) * 0.5;
    if q.is_finite() && p.iter().all(|x| x.is_finite()) {
        Ok((q, p))
    } else {
        Err(CoarseUnavailable::NotFinite)
    }
}

/// The Sun directions in ACS this cycle, in order of preference: FSS1, FSS2 (through the
/// alignment table), the CSS eyes; each with its 1σ and source (`None` where a sensor has no
/// Sun).
/// Paper: FSS; docs/magnetics.md §5 (CSS fallback).
#[must_use]
pub fn sun_candidates_acs(
    frame: &RawSensorFrame,
    alignment: &AlignmentTable,
    table: &MagneticsTable,
) -> [Option<(Vector3<f64>, f64, CoarseSource)>; 3] {
    let fss = |id: FssId| {
        frame
            .fss
            .get(id.index())
            .and_then(|sample| fss::measure_sensor(sample, id, alignment).ok())
            .map(|m| (m.dir_acs, table.fss_sun_sigma_rad, CoarseSource::FssTam))
    };
    [
        fss(FssId::Fss1),
        fss(FssId::Fss2),
        css_sun_acs(&frame.css, table).map(|v| (v, table.css_sun_sigma_rad, CoarseSource::CssTam)),
    ]
}

/// The coarse solution: attitude, covariance, where the last fix came from and how old it is.
/// Project choice (not in the paper): docs/magnetics.md §5.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoarseAttitude {
    /// Attitude, ACS from J2000.
    /// algorithms.md §1.
    pub q_acs_from_eci: Quat,
    /// Attitude error covariance, rad², ACS axes (`A_true = Rot(δθ) A_est`).
    /// algorithms.md §1 (error convention).
    pub covariance_rad2: Matrix3<f64>,
    /// A fix has been made (the solution means something).
    /// docs/magnetics.md §5.
    pub valid: bool,
    /// Vectors of the last fix.
    /// docs/magnetics.md §5.
    pub source: CoarseSource,
    /// Time since the last fix, s.
    /// docs/magnetics.md §5.
    pub age_s: f64,
    /// Why the last attempt made no fix (`None` after a fix).
    /// docs/icd.md §3.3 (event 0x0901).
    pub last_unavailable: Option<CoarseUnavailable>,
    /// Fixes made since boot.
    /// docs/magnetics.md §5.
    pub fixes: u32,
    /// Vectors rejected by the fault screening since boot (TAM magnitude, gate).
    /// docs/magnetics.md §5.
    pub rejections: u32,
    /// The last rejection: 1 TAM1 magnitude, 2 TAM2 magnitude, 3 field gated, 4 Sun gated
    /// (0 none since boot).
    /// docs/icd.md §3.3 (event 0x0903).
    pub last_rejection: u8,
    /// Cycles since the last attempt.
    cycles_since_attempt: u16,
    /// Consecutive attempts stopped by the gate.
    consecutive_gated: u16,
    /// The model field of the last attempt that computed one: (time, s since J2000 TT;
    /// field, nT, J2000 axes).
    reference_field: Option<(f64, Vector3<f64>)>,
}

impl Default for CoarseAttitude {
    fn default() -> Self {
        Self::new()
    }
}

impl CoarseAttitude {
    /// No solution yet.
    /// docs/magnetics.md §5.
    #[must_use]
    pub const fn new() -> Self {
        Self {
            q_acs_from_eci: Quat::IDENTITY,
            covariance_rad2: Matrix3::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
            valid: false,
            source: CoarseSource::None,
            age_s: 0.0,
            last_unavailable: None,
            fixes: 0,
            rejections: 0,
            last_rejection: 0,
            cycles_since_attempt: u16::MAX,
            consecutive_gated: 0,
            reference_field: None,
        }
    }

    /// Carry the solution over one cycle on the gyro increment `delta_theta_acs_rad` less the
    /// bias estimate; the covariance grows by `arw² dt` and by the bias covariance
    /// `P_bb (2 age + dt) dt` (an error `δb·age` since the fix).
    /// algorithms.md §2 (propagation); docs/magnetics.md §5.
    pub fn propagate(
        &mut self,
        delta_theta_acs_rad: &Vector3<f64>,
        bias_rad_per_s: &Vector3<f64>,
        bias_covariance_rad2_per_s2: &Matrix3<f64>,
        arw_rad_per_sqrt_s: f64,
        dt_s: f64,
    ) {
        if !self.valid || !(dt_s > 0.0) {
            return;
        }
        let phi = delta_theta_acs_rad - bias_rad_per_s * dt_s;
        if !phi.iter().all(|x| x.is_finite()) {
            return;
        }
        let dq = Quat::from_rotation_vector(&phi);
        let rot = dq.to_dcm();
        let q = dq.compose(&self.q_acs_from_eci).normalized();
        let grow = Matrix3::identity() * (arw_rad_per_sqrt_s * arw_rad_per_sqrt_s * dt_s)
            + bias_covariance_rad2_per_s2 * ((2.0 * self.age_s + dt_s) * dt_s);
        let p = rot * self.covariance_rad2 * rot.transpose() + grow;
        if q.is_finite() && p.iter().all(|x| x.is_finite()) {
            self.q_acs_from_eci = q;
            self.covariance_rad2 = (p + p.transpose()) * 0.5;
            self.age_s += dt_s;
        }
    }

    /// Add `grow` (rad², ACS) to the covariance of a carried solution: an error source outside
    /// the gyro noise model, such as the gyros' scale and misalignment error during a slew
    /// (the same term the fine filter adds, `FlightCore::step` phase 5).
    /// docs/magnetics.md §5.
    pub fn add_covariance(&mut self, grow: &Matrix3<f64>) {
        if !self.valid || !grow.iter().all(|x| x.is_finite()) {
            return;
        }
        let p = self.covariance_rad2 + grow;
        self.covariance_rad2 = (p + p.transpose()) * 0.5;
    }

    /// The model field (nT, J2000 axes) this cycle's fix attempt computed at `t_s`, if it
    /// computed one (the unloading's bars-off check then needs no second synthesis).
    /// docs/magnetics.md §5, §7.
    #[must_use]
    pub fn reference_field_eci_nt(&self, t_s: f64) -> Option<Vector3<f64>> {
        match self.reference_field {
            Some((t, b)) if t.to_bits() == t_s.to_bits() => Some(b),
            _ => None,
        }
    }

    /// Whether the next cycle's [`Self::fix_due`] will be true (the torquer bars are then
    /// commanded off for the coming interval, so that the fix's TAM sample sees no bar
    /// field: [`crate::unloading`]).
    /// docs/magnetics.md §7 (blanking).
    #[must_use]
    pub fn fix_due_next_cycle(&self, table: &MagneticsTable) -> bool {
        self.cycles_since_attempt.saturating_add(1) >= table.coarse_fix_every_n_cycles
    }

    /// Whether a fix is due this cycle (every `coarse_fix_every_n_cycles`).
    /// docs/tables.md (Table 6, field 17).
    pub fn fix_due(&mut self, table: &MagneticsTable) -> bool {
        self.cycles_since_attempt = self.cycles_since_attempt.saturating_add(1);
        if self.cycles_since_attempt >= table.coarse_fix_every_n_cycles {
            self.cycles_since_attempt = 0;
            true
        } else {
            false
        }
    }

    /// Try a fix from this frame at `t_s` (s since J2000.0 TT) with the onboard orbit's
    /// position `pos_eci_km` (`None`: no valid orbit). On success the solution is replaced;
    /// otherwise it is kept (carried on the gyros) and the reason recorded.
    /// docs/magnetics.md §5.
    ///
    /// # Errors
    /// Why no fix was made ([`CoarseUnavailable`]).
    pub fn try_fix(
        &mut self,
        frame: &RawSensorFrame,
        alignment: &AlignmentTable,
        table: &MagneticsTable,
        pos_eci_km: Option<&Vector3<f64>>,
        t_s: f64,
    ) -> Result<(), CoarseUnavailable> {
        let result = self.solve(frame, alignment, table, pos_eci_km, t_s);
        match result {
            Ok((q, p, source)) => {
                self.q_acs_from_eci = q;
                self.covariance_rad2 = p;
                self.valid = true;
                self.source = source;
                self.age_s = 0.0;
                self.last_unavailable = None;
                self.fixes = self.fixes.saturating_add(1);
                self.consecutive_gated = 0;
                Ok(())
            }
            Err(why) => {
                if why == CoarseUnavailable::Gated {
                    self.consecutive_gated = self.consecutive_gated.saturating_add(1);
                }
                self.last_unavailable = Some(why);
                Err(why)
            }
        }
    }

    /// References, screened vectors, TRIAD.
    fn solve(
        &mut self,
        frame: &RawSensorFrame,
        alignment: &AlignmentTable,
        table: &MagneticsTable,
        pos_eci_km: Option<&Vector3<f64>>,
        t_s: f64,
    ) -> Result<(Quat, Matrix3<f64>, CoarseSource), CoarseUnavailable> {
        if !table.has_field_model() {
            return Err(CoarseUnavailable::NoFieldModel);
        }
        let pos = pos_eci_km.ok_or(CoarseUnavailable::NoOrbit)?;
        let suns = sun_candidates_acs(frame, alignment, table);
        if suns.iter().all(Option::is_none) {
            return Err(CoarseUnavailable::NoSun);
        }
        let sun_eci =
            crate::sun_ephemeris::sun_dir_eci(t_s).map_err(|_| CoarseUnavailable::Ephemeris)?;
        if in_earth_shadow(pos, &sun_eci) {
            // A "Sun" read in the Earth's shadow is a reflection or Earth light.
            return Err(CoarseUnavailable::InShadow);
        }
        let b_eci_nt =
            field_model::field_eci_nt(table, pos, t_s).map_err(CoarseUnavailable::FieldModel)?;
        self.reference_field = Some((t_s, b_eci_nt));
        let field = self.screened_field(frame, table, &b_eci_nt)?;
        let mut sun = None;
        for (v, sigma, source) in suns.into_iter().flatten() {
            let pair = VectorPair {
                body: v,
                reference: sun_eci,
                sigma_rad: sigma,
            };
            if self.passes_gate(&pair) {
                sun = Some((pair, source));
                break;
            }
            self.reject(4);
        }
        let (sun, source) = sun.ok_or(CoarseUnavailable::Gated)?;
        let (anchor, other) = if sun.sigma_rad <= field.sigma_rad {
            (&sun, &field)
        } else {
            (&field, &sun)
        };
        let (q, p) = triad(anchor, other, table.min_sun_field_angle_rad)?;
        Ok((q, p, source))
    }

    /// The first TAM (TAM1, TAM2) whose field passes the magnitude check against the model
    /// (`5 σ_field + 2 % |B|`) and the gate against the carried solution.
    fn screened_field(
        &mut self,
        frame: &RawSensorFrame,
        table: &MagneticsTable,
        b_eci_nt: &Vector3<f64>,
    ) -> Result<VectorPair, CoarseUnavailable> {
        let b_model_mg = b_eci_nt.norm() / NT_PER_MILLIGAUSS;
        let mut outcome = CoarseUnavailable::NoField;
        for (unit, sample) in frame.tam.iter().enumerate().take(TAMS) {
            // The bars are commanded off before every fix (phase 7c): a sample taken with a
            // bar driven holds the bar's own field (up to hundreds of mG), whatever its
            // magnitude says.
            if sample.flags & TAM_FLAG_VALID != 0 && sample.flags & TAM_FLAG_TORQUERS_ON != 0 {
                self.reject(if unit == 0 { 5 } else { 6 });
                if matches!(outcome, CoarseUnavailable::NoField) {
                    outcome = CoarseUnavailable::TorquersOn;
                }
                continue;
            }
            let Some(b) = tam_field_acs_milligauss(sample, unit, table) else {
                continue;
            };
            let sigma_mg = table
                .field_sigma_milligauss
                .get(unit)
                .copied()
                .unwrap_or(f64::NAN);
            let tolerance_mg = 5.0 * sigma_mg + TAM_MAGNITUDE_RELATIVE_TOLERANCE * b_model_mg;
            let code = if unit == 0 { 1 } else { 2 };
            if !((b.norm() - b_model_mg).abs() <= tolerance_mg) {
                self.reject(code);
                if outcome == CoarseUnavailable::NoField {
                    outcome = CoarseUnavailable::TamMagnitude;
                }
                continue;
            }
            let pair = VectorPair {
                body: b,
                reference: *b_eci_nt,
                sigma_rad: sigma_mg / b.norm(),
            };
            if self.passes_gate(&pair) {
                return Ok(pair);
            }
            self.reject(3);
            outcome = CoarseUnavailable::Gated;
        }
        Err(outcome)
    }

    /// The gate against the carried solution (passes when there is none, or after
    /// [`GATE_RELEASE_ATTEMPTS`] consecutive gated attempts): the angle between the vector and
    /// its prediction `Â r` against `σ_vec² + tr P`.
    fn passes_gate(&self, v: &VectorPair) -> bool {
        if !self.valid || self.consecutive_gated >= GATE_RELEASE_ATTEMPTS {
            return true;
        }
        let predicted = self.q_acs_from_eci.to_dcm() * v.reference.normalize();
        let body = v.body.normalize();
        // The angle itself, not its sine: a reversed vector (a TAM of inverted polarity) is
        // 180° off, not 0°.
        let angle = libm::atan2(predicted.cross(&body).norm(), predicted.dot(&body));
        let variance = v.sigma_rad * v.sigma_rad + self.covariance_rad2.trace().max(0.0);
        angle * angle <= GATE_CHI2 * variance
    }

    fn reject(&mut self, code: u8) {
        self.rejections = self.rejections.saturating_add(1);
        self.last_rejection = code;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::attitude::attitude_error_rad;

    fn pair(a: &Matrix3<f64>, r: Vector3<f64>, sigma: f64) -> VectorPair {
        let r = r.normalize();
        VectorPair {
            body: a * r,
            reference: r,
            sigma_rad: sigma,
        }
    }

    #[test]
    fn triad_recovers_an_exact_attitude() {
        let q = Quat::from_rotation_vector(&Vector3::new(0.3, -1.2, 0.7));
        let a = q.to_dcm();
        let s = pair(&a, Vector3::new(0.2, 0.9, 0.1), 1e-3);
        let b = pair(&a, Vector3::new(-0.5, 0.1, 0.8), 1e-2);
        let (qe, _) = triad(&s, &b, 0.1).unwrap();
        assert!(attitude_error_rad(&q, &qe).norm() < 1e-12);
    }

    /// The covariance form against a Monte Carlo of TRIAD with perturbed vectors: the sample
    /// covariance agrees element by element within 5 % of its scale.
    #[test]
    fn triad_covariance_matches_monte_carlo() {
        let q = Quat::from_rotation_vector(&Vector3::new(0.1, 0.4, -0.2));
        let a = q.to_dcm();
        let (s1, s2) = (2e-3, 1e-2);
        let anchor = pair(&a, Vector3::new(0.3, 0.8, 0.2), s1);
        let other = pair(&a, Vector3::new(0.7, 0.1, 0.6), s2);
        let (_, p) = triad(&anchor, &other, 0.1).unwrap();
        // A small deterministic normal generator (Box–Muller over an LCG).
        let mut state = 12_345_u64;
        let mut uniform = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let mut normal = || {
            let (u1, u2) = (uniform(), uniform());
            libm::sqrt(-2.0 * libm::log(u1)) * libm::cos(2.0 * core::f64::consts::PI * u2)
        };
        let n = 20_000;
        let mut sum = Matrix3::zeros();
        for _ in 0..n {
            let mut perturb = |v: &Vector3<f64>, sigma: f64| {
                let d = Vector3::new(normal(), normal(), normal()) * sigma;
                (v + (d - v * v.dot(&d))).normalize()
            };
            let a1 = VectorPair {
                body: perturb(&anchor.body, s1),
                ..anchor
            };
            let o1 = VectorPair {
                body: perturb(&other.body, s2),
                ..other
            };
            let (qe, _) = triad(&a1, &o1, 0.1).unwrap();
            let e = attitude_error_rad(&q, &qe);
            sum += e * e.transpose();
        }
        let sample = sum / f64::from(n);
        let scale = p.norm();
        assert!((sample - p).norm() < 0.05 * scale, "{sample} vs {p}");
    }

    #[test]
    fn nearly_parallel_vectors_are_refused() {
        let a = Matrix3::identity();
        let s = pair(&a, Vector3::new(1.0, 0.0, 0.0), 1e-3);
        let b = pair(&a, Vector3::new(1.0, 0.05, 0.0), 1e-2);
        assert_eq!(triad(&s, &b, 0.1), Err(CoarseUnavailable::NearlyParallel));
    }

    #[test]
    fn css_reads_the_sun_and_not_the_albedo_alone() {
        let t = MagneticsTable::boot();
        let sun = Vector3::new(0.6, -0.48, 0.64);
        let mut sample = CssSample {
            counts: [0; 6],
            flags: CSS_FLAG_VALID,
        };
        for (c, n) in sample.counts.iter_mut().zip(t.css_normals_acs.iter()) {
            let cos = Vector3::from(*n).dot(&sun);
            *c = (1000.0 * cos.max(0.0)).round() as u16;
        }
        let v = css_sun_acs(&sample, &t).unwrap();
        assert!((v - sun).norm() < 2e-3);
        let albedo_only = CssSample {
            counts: [0, 0, 0, 0, 0, 280],
            flags: CSS_FLAG_VALID,
        };
        assert_eq!(css_sun_acs(&albedo_only, &t), None);
        assert_eq!(css_sun_acs(&CssSample::default(), &t), None);
    }

    #[test]
    fn tam_field_applies_scale_bias_and_alignment() {
        let mut t = MagneticsTable::boot();
        t.tam_bias_milligauss[0] = [0.0, 0.0, -4.0];
        t.m_acs_from_tam[0] = [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
        let s = TamSample {
            field_counts: [100, -200, 300],
            flags: TAM_FLAG_VALID,
        };
        let b = tam_field_acs_milligauss(&s, 0, &t).unwrap();
        assert!((b - Vector3::new(-60.0, -30.0, 94.0)).norm() < 1e-9, "{b}");
        assert_eq!(tam_field_acs_milligauss(&TamSample::default(), 0, &t), None);
    }

    /// A frame whose TAMs and CSS eyes see attitude `q` at `pos`, `t_s` (dipole field model).
    fn scene() -> (MagneticsTable, Quat, Vector3<f64>, f64, RawSensorFrame) {
        let mut t = MagneticsTable::boot();
        t.field_degree = 1;
        t.g_nt[1][0] = -29_775.0;
        t.g_nt[1][1] = -1_848.0;
        t.h_nt[1][1] = 5_406.0;
        let q = Quat::from_rotation_vector(&Vector3::new(0.4, -0.9, 0.3));
        let a = q.to_dcm();
        let pos = Vector3::new(4_000.0, 5_000.0, 2_000.0);
        let t_s = -2.74e8;
        t.field_epoch_s_since_j2000_tt = t_s;
        let b_eci = crate::field_model::field_eci_nt(&t, &pos, t_s).unwrap();
        let sun_eci = crate::sun_ephemeris::sun_dir_eci(t_s).unwrap();
        let b_counts = (a * b_eci) / NT_PER_MILLIGAUSS / 0.3;
        let tam = TamSample {
            field_counts: [b_counts.x, b_counts.y, b_counts.z].map(|c| c.round() as i16),
            flags: TAM_FLAG_VALID,
        };
        let sun_acs = a * sun_eci;
        let mut css = CssSample {
            counts: [0; 6],
            flags: CSS_FLAG_VALID,
        };
        for (c, n) in css.counts.iter_mut().zip(t.css_normals_acs.iter()) {
            *c = (1000.0 * Vector3::from(*n).dot(&sun_acs).max(0.0)).round() as u16;
        }
        let frame = RawSensorFrame {
            tam: [tam, tam],
            css,
            ..RawSensorFrame::default()
        };
        (t, q, pos, t_s, frame)
    }

    /// The fault screening: a dead TAM1 is refused on its magnitude and TAM2 used; a TAM1
    /// bias jump of 40 mG is refused by the gate and TAM2 used; a glint on a CSS eye is
    /// refused by the gate (no other Sun: no fix) until the gate is released after
    /// `GATE_RELEASE_ATTEMPTS` attempts.
    #[test]
    fn screening_refuses_failed_sensors_and_falls_back() {
        let (mut t, q, pos, t_s, frame) = scene();
        // A Sun good to 0.1° (the scene's CSS is exact), so that the carried solution is
        // sharp enough for the gate to see a 9° field error.
        t.css_sun_sigma_rad = 0.1_f64.to_radians();
        let align = AlignmentTable::prelaunch();
        let mut c = CoarseAttitude::new();
        c.try_fix(&frame, &align, &t, Some(&pos), t_s).unwrap();
        assert!(attitude_error_rad(&q, &c.q_acs_from_eci).norm() < 0.01);
        assert_eq!(c.source, CoarseSource::CssTam);

        let mut dead = frame;
        dead.tam[0].field_counts = [0; 3];
        c.try_fix(&dead, &align, &t, Some(&pos), t_s).unwrap();
        assert_eq!(c.last_rejection, 1);
        assert!(attitude_error_rad(&q, &c.q_acs_from_eci).norm() < 0.01);

        let mut jump = frame;
        let b = Vector3::from(jump.tam[0].field_counts.map(f64::from));
        let perp = b.cross(&Vector3::new(0.0, 0.0, 1.0)).normalize() * (40.0 / 0.3);
        for (c, d) in jump.tam[0].field_counts.iter_mut().zip(perp.iter()) {
            *c = (f64::from(*c) + d).round() as i16;
        }
        c.try_fix(&jump, &align, &t, Some(&pos), t_s).unwrap();
        assert_eq!(c.last_rejection, 3);
        assert!(attitude_error_rad(&q, &c.q_acs_from_eci).norm() < 0.01);

        let mut glint = frame;
        let darkest = glint.css.counts.iter().position(|x| *x == 0).unwrap();
        glint.css.counts[darkest] = 800;
        for _ in 0..GATE_RELEASE_ATTEMPTS {
            assert_eq!(
                c.try_fix(&glint, &align, &t, Some(&pos), t_s),
                Err(CoarseUnavailable::Gated)
            );
            assert_eq!(c.last_rejection, 4);
        }
        // Released: the glinted Sun is taken (the carried solution is then the suspect).
        c.try_fix(&glint, &align, &t, Some(&pos), t_s).unwrap();
        assert!(attitude_error_rad(&q, &c.q_acs_from_eci).norm() > 0.05);
    }

    /// A Sun read in the Earth's shadow (a glint in eclipse) is refused, whatever the gate.
    #[test]
    fn a_sun_in_the_earth_shadow_is_refused() {
        let (t, _, pos, t_s, frame) = scene();
        let align = AlignmentTable::prelaunch();
        let sun = crate::sun_ephemeris::sun_dir_eci(t_s).unwrap();
        let behind = -sun * pos.norm();
        assert!(in_earth_shadow(&behind, &sun) && !in_earth_shadow(&(sun * 7_000.0), &sun));
        let mut c = CoarseAttitude::new();
        assert_eq!(
            c.try_fix(&frame, &align, &t, Some(&behind), t_s),
            Err(CoarseUnavailable::InShadow)
        );
    }

    #[test]
    fn missing_inputs_are_named() {
        let (t, _, pos, t_s, frame) = scene();
        let align = AlignmentTable::prelaunch();
        let mut c = CoarseAttitude::new();
        let boot = MagneticsTable::boot();
        assert_eq!(
            c.try_fix(&frame, &align, &boot, Some(&pos), t_s),
            Err(CoarseUnavailable::NoFieldModel)
        );
        assert_eq!(
            c.try_fix(&frame, &align, &t, None, t_s),
            Err(CoarseUnavailable::NoOrbit)
        );
        let mut dark = frame;
        dark.css = CssSample::default();
        assert_eq!(
            c.try_fix(&dark, &align, &t, Some(&pos), t_s),
            Err(CoarseUnavailable::NoSun)
        );
        let mut no_tam = frame;
        no_tam.tam = [TamSample::default(); 2];
        assert_eq!(
            c.try_fix(&no_tam, &align, &t, Some(&pos), t_s),
            Err(CoarseUnavailable::NoField)
        );
        let mut both_dead = frame;
        both_dead.tam[0].field_counts = [0; 3];
        both_dead.tam[1].field_counts = [0; 3];
        assert_eq!(
            c.try_fix(&both_dead, &align, &t, Some(&pos), t_s),
            Err(CoarseUnavailable::TamMagnitude)
        );
        assert!(!c.valid);
    }
}
