//! # The library of candidate effects (sensor side)
//!
//! Each effect is a parameterised addition to the measured angles with its own partial
//! derivatives (columns of the design matrix, arcsec per parameter unit), fitted jointly with
//! the per-sensor alignment rotations and the per-batch attitude (see [`super::fit`]).
//! Parameter units are chosen to be readable and well scaled:
//!
//! | effect | params | column on (measured − predicted) | signature (algorithms.md §9) |
//! |---|---|---|---|
//! | `aberration_annual` | k (scale of the annual β-term; 1 = full aberration) | `J Mᵀ A (β_E − u(u·β_E))` | differential between sensors, with the velocity direction |
//! | `aberration_orbital` | k (orbital β-term) | same with the orbital velocity | once per orbit |
//! | `aberration` | both k together (a model without aberration lacks both) | both columns | |
//! | `time_tag_offset` | τ (ms, + = sample older than its tag) | `J Mᵀ (ω × b)` | ∝ rate, flips with slew sign |
//! | `thermal_alignment_drift` | 3 (″/°C, ACS) | `−J Mᵀ [b×] ΔT` | follows the sensor temperature |
//! | `orbit_periodic_alignment` | 6 (″: cos u, sin u per ACS axis), or 12 with the second harmonic (`cos2u_x` …) | `−J Mᵀ [b×] (cos u, sin u[, cos 2u, sin 2u])` | orbit phase |
//! | `fhst_distortion` | radial Δρ at 4°, H·V terms at the (4°, 4°) corner (″) | `(ρ²H, ρ²V)/F³`, `(HV/F², 0)`, `(0, HV/F²)` | FOV position |
//! | `magnitude_bias` | (″/mag in H, V) | `(m − 4)` | magnitude |
//! | `fss_transfer_function` | scale (ppm), cross (″ at the 32° corner), cubic (″ at the edge), cyclic sin/cos (″) at a grid-searched pitch, per head | `α`, `α β²/E³`, `α³/E³`, `sin/cos(2π α / p)` | head angles |
//! | `catalog_proper_motion_error` | per star east/north offsets (″) | `J Mᵀ A e_{E,N}` | star id |
//!
//! Offsets degenerate with the alignment (FSS null offsets, the mean magnitude bias) are left
//! to the alignment parameters.

use super::measurements::{Measurement, MeasurementSet};
use fsw_core::units::{ARCSEC_PER_RAD, RAD_PER_DEG};
use serde::Serialize;

/// FHST reference field radius of the distortion parameters (4°).
pub const FHST_REF_RAD: f64 = 4.0 * RAD_PER_DEG;
/// FSS field edge of the transfer-function parameters (32°).
pub const FSS_EDGE_RAD: f64 = 32.0 * RAD_PER_DEG;
/// Reference magnitude of the magnitude bias.
pub const MAGNITUDE_REF: f64 = 4.0;
/// Stars need this many measurements to get catalog-offset parameters.
pub const CATALOG_MIN_SAMPLES: usize = 5;

/// Terms per axis of the generic alignment extension.
pub const GENERIC_TERMS: usize = 7;

/// Kinds of sensor-side effect.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum EffectKind {
    /// Annual velocity aberration (scale of the Earth-velocity term).
    AberrationAnnual,
    /// Orbital velocity aberration.
    AberrationOrbital,
    /// Both aberration terms together (a ground model without aberration lacks both; each
    /// alone is then an incomplete model whose split halves disagree).
    Aberration,
    /// Time-tag offset of one sensor.
    TimeTagOffset,
    /// Alignment rotation ∝ the sensor temperature.
    ThermalAlignmentDrift,
    /// Alignment rotation at the orbit period.
    OrbitPeriodicAlignment,
    /// FHST focal-plane distortion (table form).
    FhstDistortion,
    /// Magnitude-dependent FHST bias.
    MagnitudeBias,
    /// FSS transfer-function error (table form plus a cubic term).
    FssTransferFunction,
    /// FSS cyclic (fine-reticle interpolation) error.
    FssCyclicError,
    /// Per-star catalog position / proper-motion error.
    CatalogProperMotionError,
    /// Not a candidate: a generic extension of a sensor's alignment variation (orbit
    /// harmonics 2 and 3, the square of the temperature deviation) used only to test the
    /// lack of fit of the thermal and orbit-periodic candidates.
    GenericAlignmentExtension,
    /// Not a candidate: a secular alignment variation of a sensor (Legendre polynomials 1–3
    /// of time over its data), the second lack-of-fit test of the thermal and orbit-periodic
    /// candidates. A drift or a step (an alignment that moved once) is neither orbital nor
    /// thermal; forced onto those forms, a 14″ FHST2 step on the writer's calibration day
    /// took 40–60″ orbit-periodic amplitudes. A test of its own: inside the generic
    /// extension its 9 parameters diluted the test of the twice-per-orbit form.
    SecularAlignmentExtension,
    /// Not a candidate: the orbital aberration and Sun parallax of an orbit the telemetry
    /// does not give (no ephemeris records, `docs/icd.md` §3.4). The operator's model has
    /// them (declared), the ground cannot apply them, and left in the residuals (≤ 5.3″ on
    /// every sensor, ≤ 9″ on the FSSs) they were read as annual aberration, a thermal drift
    /// or a time tag on the wrong tracker. A circular orbit's `v/c = a cos nt + b sin nt`
    /// (ECI, 6 parameters in arcsec; position `(c/n)(a sin nt − b cos nt)` for the parallax),
    /// `n` from the residuals ([`unknown_orbit_rate`]); in the baseline, never reported.
    UnknownOrbit,
    /// The sensor's alignment rotated once, at a time found by the change-point scan
    /// ([`super::change_point`]): 3 parameters (ACS, arcsec) on its data from then on.
    AlignmentStep,
}

impl EffectKind {
    /// Every kind of the library.
    pub const ALL: [Self; 15] = [
        Self::AberrationAnnual,
        Self::AberrationOrbital,
        Self::Aberration,
        Self::TimeTagOffset,
        Self::ThermalAlignmentDrift,
        Self::OrbitPeriodicAlignment,
        Self::FhstDistortion,
        Self::MagnitudeBias,
        Self::FssTransferFunction,
        Self::FssCyclicError,
        Self::CatalogProperMotionError,
        Self::GenericAlignmentExtension,
        Self::SecularAlignmentExtension,
        Self::UnknownOrbit,
        Self::AlignmentStep,
    ];

    /// Report name.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::AberrationAnnual => "aberration_annual",
            Self::AberrationOrbital => "aberration_orbital",
            Self::Aberration => "aberration",
            Self::TimeTagOffset => "time_tag_offset",
            Self::ThermalAlignmentDrift => "thermal_alignment_drift",
            Self::OrbitPeriodicAlignment => "orbit_periodic_alignment",
            Self::FhstDistortion => "fhst_distortion",
            Self::MagnitudeBias => "magnitude_bias",
            Self::FssTransferFunction => "fss_transfer_function",
            Self::FssCyclicError => "fss_cyclic_error",
            Self::CatalogProperMotionError => "catalog_proper_motion_error",
            Self::GenericAlignmentExtension => "generic_alignment_extension",
            Self::SecularAlignmentExtension => "secular_alignment_extension",
            Self::UnknownOrbit => "unknown_orbit",
            Self::AlignmentStep => "alignment_step",
        }
    }

    /// The name `sim-harness` uses in `truth.json` (`present_effects`, `undeclared_effects`)
    /// without the unit prefix.
    #[must_use]
    pub fn truth_name(self) -> &'static str {
        match self {
            Self::AberrationAnnual | Self::AberrationOrbital | Self::Aberration => "aberration",
            Self::ThermalAlignmentDrift | Self::OrbitPeriodicAlignment => "thermal_alignment_drift",
            Self::FssCyclicError | Self::FssTransferFunction => "fss_transfer_function",
            other => other.name(),
        }
    }
}

/// Names of `metadata.json` `declared_effects` that the ground's chain reads itself, beyond
/// the library's kinds: the orbital aberration and the Sun's parallax (star and Sun
/// directions) and the early gyro bias transient (the bias model).
pub const CHAIN_DECLARED_EFFECTS: [&str; 3] =
    ["orbital_aberration", "sun_parallax", "iru_bias_transient"];

/// Whether a `declared_effects` name can change anything in the ground's model: a library
/// kind (its report or truth name, alone or as `unit.name` for FHST1, FHST2, FSS1, FSS2) or
/// one of [`CHAIN_DECLARED_EFFECTS`]. A coarse screen for misspelt names: a unit prefix is
/// accepted for any kind, though [`super::search::is_declared`] only matches it on a
/// candidate of that unit. Any
/// other name is ignored, which the run check says (a misspelt name would leave the effect
/// out of the model unseen).
#[must_use]
pub fn declared_name_is_modelled(name: &str) -> bool {
    let bare = ["fhst1.", "fhst2.", "fss1.", "fss2."]
        .iter()
        .find_map(|u| name.strip_prefix(u))
        .unwrap_or(name);
    CHAIN_DECLARED_EFFECTS.contains(&name)
        || EffectKind::ALL
            .iter()
            .any(|k| k.name() == bare || k.truth_name() == bare)
}

/// One candidate effect (kind, sensor and its fixed settings).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Effect {
    /// Kind.
    pub kind: EffectKind,
    /// Sensor (None = all sensors).
    pub sensor: Option<usize>,
    /// Parameter names.
    pub params: Vec<String>,
    /// Parameter units.
    pub units: Vec<&'static str>,
    /// Prior 1σ per parameter: physically plausible sizes (FSS transfer terms ≤ 200″ and
    /// 0.2 % scale, FHST distortion ≤ 100″, thermal ≤ 30″/°C, time tags ≤ 1 s, ...). They
    /// keep combinations that the data leave unobserved (a transfer polynomial over a small
    /// part of the field) from taking absurd values, which would also make the split-half
    /// comparison meaningless.
    #[serde(skip)]
    pub prior_sigma: Vec<f64>,
    /// Pitch of the cyclic error (rad).
    pub pitch_rad: Option<f64>,
    /// Stars of the catalog effect (HIP).
    #[serde(skip)]
    pub stars: Vec<u32>,
    /// Their reference directions (J2000, unit), same order.
    #[serde(skip)]
    pub star_dirs: Vec<nalgebra::Vector3<f64>>,
    /// Soft linear constraints on the parameters: (param index, coefficient) rows = 0 with
    /// the given 1σ (the catalog offsets' net rotation per tracker).
    #[serde(skip)]
    pub constraints: Vec<(Vec<(usize, f64)>, f64)>,
    /// Extra (nonlinear) parameters searched on a grid (for the BIC): the cyclic pitch.
    pub extra_params: usize,
    /// Orbit harmonics of the orbit-periodic alignment (1, or 2: once and twice per orbit).
    pub harmonics: usize,
    /// Orbit rate of [`EffectKind::UnknownOrbit`] (rad/s).
    pub rate_rad_per_s: Option<f64>,
    /// First and last time of the sensor's data (s): the Legendre time terms of
    /// [`EffectKind::SecularAlignmentExtension`] run over it.
    #[serde(skip)]
    pub time_span_s: Option<[f64; 2]>,
    /// Not a candidate (only used for lack-of-fit tests).
    #[serde(skip)]
    pub hidden: bool,
    /// The sparse catalog form: only the stars whose own offset test passed
    /// ([`super::sparse_catalog`]), no net-rotation gauge.
    pub sparse: bool,
    /// Time of an [`EffectKind::AlignmentStep`] (s since the first frame).
    pub step_time_s: Option<f64>,
    /// Positions the nonlinear parameter was scanned over (the step time), or the subsets
    /// the sparse catalog form's stars were chosen from: the candidate's p-value is
    /// multiplied by it (1 for the others).
    pub scan_positions: usize,
}

impl Effect {
    fn new(kind: EffectKind, sensor: Option<usize>, params: &[(&str, &'static str, f64)]) -> Self {
        Self {
            kind,
            sensor,
            params: params.iter().map(|p| p.0.to_owned()).collect(),
            units: params.iter().map(|p| p.1).collect(),
            prior_sigma: params.iter().map(|p| p.2).collect(),
            pitch_rad: None,
            harmonics: 1,
            rate_rad_per_s: None,
            time_span_s: None,
            stars: Vec::new(),
            star_dirs: Vec::new(),
            constraints: Vec::new(),
            extra_params: 0,
            hidden: false,
            sparse: false,
            step_time_s: None,
            scan_positions: 1,
        }
    }

    /// An alignment step of `sensor` at `t_step_s` (s since the first frame), found by a
    /// change-point scan over `positions` positions.
    #[must_use]
    pub fn alignment_step(sensor: usize, t_step_s: f64, positions: usize) -> Self {
        let mut e = Self::new(
            EffectKind::AlignmentStep,
            Some(sensor),
            &[
                ("x", "arcsec", 200.0),
                ("y", "arcsec", 200.0),
                ("z", "arcsec", 200.0),
            ],
        );
        e.step_time_s = Some(t_step_s);
        e.scan_positions = positions.max(1);
        e.extra_params = 1;
        e
    }

    /// The sparse catalog form: this (full) catalog effect restricted to the stars `keep`
    /// (indices into [`Effect::stars`]), without the per-tracker net-rotation constraints (a
    /// few stars' offsets do not move a tracker's alignment; their common rotation is data,
    /// not gauge).
    #[must_use]
    pub fn selected_stars(&self, keep: &[usize]) -> Self {
        let mut e = Self::new(self.kind, self.sensor, &[]);
        for &k in keep {
            for j in 0..2 {
                e.params.push(self.params[2 * k + j].clone());
                e.units.push(self.units[2 * k + j]);
                e.prior_sigma.push(self.prior_sigma[2 * k + j]);
            }
            e.stars.push(self.stars[k]);
            e.star_dirs.push(self.star_dirs[k]);
        }
        e.sparse = true;
        // The stars were chosen from every star seen by their own tests: the candidate's
        // p-value carries the choice of k among n (Bonferroni over the subsets), so one star
        // picked as the most deviant of a hundred is not tested as if named in advance.
        e.scan_positions = subsets(self.stars.len(), keep.len());
        e
    }

    /// Number of linear parameters.
    #[must_use]
    pub fn len(&self) -> usize {
        self.params.len()
    }

    /// No parameters.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.params.is_empty()
    }

    /// Short label, e.g. `time_tag_offset[FHST1]`.
    #[must_use]
    pub fn label(&self) -> String {
        if self.harmonics > 1 {
            if let Some(s) = self.sensor {
                return format!(
                    "{}[{}] (harmonics 1–{})",
                    self.kind.name(),
                    super::measurements::SENSOR_NAMES[s],
                    self.harmonics
                );
            }
        }
        match self.sensor {
            Some(s) => format!(
                "{}[{}]",
                self.kind.name(),
                super::measurements::SENSOR_NAMES[s]
            ),
            None if self.sparse => {
                format!("{} ({} selected stars)", self.kind.name(), self.stars.len())
            }
            None => self.kind.name().to_owned(),
        }
    }

    /// Does the effect act on this measurement at all?
    #[must_use]
    pub fn applies(&self, m: &Measurement) -> bool {
        self.sensor.is_none_or(|s| s == m.sensor)
    }

    /// Legendre polynomials P1–P3 of the time across the sensor's data span: the secular
    /// extension's terms.
    fn secular_extension_terms(&self, m: &Measurement) -> [f64; 3] {
        let x = self.time_span_s.map_or(0.0, |[t0, t1]| {
            if t1 > t0 {
                (2.0 * (m.t_s - t0) / (t1 - t0) - 1.0).clamp(-1.0, 1.0)
            } else {
                0.0
            }
        });
        [
            x,
            0.5 * (3.0 * x * x - 1.0),
            0.5 * (5.0 * x * x * x - 3.0 * x),
        ]
    }

    /// Columns (param index, [∂r_axis0, ∂r_axis1] in arcsec per parameter unit).
    pub fn columns(
        &self,
        m: &Measurement,
        star_index: &dyn Fn(u32) -> Option<usize>,
        out: &mut Vec<(usize, [f64; 2])>,
    ) {
        if !self.applies(m) {
            return;
        }
        let v2 = |v: nalgebra::Vector2<f64>| [v.x, v.y];
        let alignment_col = |axis: usize| {
            let mut e = nalgebra::Vector3::zeros();
            e[axis] = 1.0;
            -(m.jm * m.b_acs.cross(&e))
        };
        match self.kind {
            EffectKind::AberrationAnnual => {
                out.push((0, v2(m.jm * m.ab_annual_acs * ARCSEC_PER_RAD)))
            }
            EffectKind::AberrationOrbital => {
                out.push((0, v2(m.jm * m.ab_orbital_acs * ARCSEC_PER_RAD)))
            }
            EffectKind::Aberration => {
                out.push((0, v2(m.jm * m.ab_annual_acs * ARCSEC_PER_RAD)));
                out.push((1, v2(m.jm * m.ab_orbital_acs * ARCSEC_PER_RAD)));
            }
            EffectKind::UnknownOrbit => {
                let Some(n) = self.rate_rad_per_s else {
                    return;
                };
                let g = unknown_orbit_map(m);
                let (sin, cos) = (n * m.t_s).sin_cos();
                // The Sun also moves by the parallax of the spacecraft's position.
                let (ca, cb) = if m.sensor >= 2 {
                    let k = parallax_per_aberration(n);
                    (cos - k * sin, sin + k * cos)
                } else {
                    (cos, sin)
                };
                for j in 0..3 {
                    let col = g.column(j);
                    out.push((j, [col.x * ca, col.y * ca]));
                    out.push((3 + j, [col.x * cb, col.y * cb]));
                }
            }
            EffectKind::TimeTagOffset => {
                out.push((
                    0,
                    v2(m.jm * m.rate_acs.cross(&m.b_acs) * (ARCSEC_PER_RAD * 1e-3)),
                ));
            }
            EffectKind::AlignmentStep => {
                if self.step_time_s.is_some_and(|t| m.t_s >= t) {
                    for ax in 0..3 {
                        out.push((ax, v2(alignment_col(ax))));
                    }
                }
            }
            EffectKind::ThermalAlignmentDrift => {
                let dt = m.dtemp[m.sensor];
                for ax in 0..3 {
                    out.push((ax, v2(alignment_col(ax) * dt)));
                }
            }
            EffectKind::OrbitPeriodicAlignment => {
                if m.orbit_phase.is_finite() {
                    for h in 0..self.harmonics {
                        let (s, c) = ((h + 1) as f64 * m.orbit_phase).sin_cos();
                        for ax in 0..3 {
                            let col = alignment_col(ax);
                            out.push((6 * h + ax, v2(col * c)));
                            out.push((6 * h + 3 + ax, v2(col * s)));
                        }
                    }
                }
            }
            EffectKind::FhstDistortion => {
                let [h, v] = m.ang;
                let rho2 = h * h + v * v;
                let f3 = FHST_REF_RAD.powi(3);
                let f2 = FHST_REF_RAD.powi(2);
                out.push((0, [rho2 * h / f3, rho2 * v / f3]));
                out.push((1, [h * v / f2, 0.0]));
                out.push((2, [0.0, h * v / f2]));
            }
            EffectKind::MagnitudeBias => {
                if m.magnitude.is_finite() {
                    let dm = m.magnitude - MAGNITUDE_REF;
                    out.push((0, [dm, 0.0]));
                    out.push((1, [0.0, dm]));
                }
            }
            EffectKind::FssTransferFunction => {
                let (a, b) = (m.ang[0], m.ang[1]);
                let (x, y) = (a / FSS_EDGE_RAD, b / FSS_EDGE_RAD);
                out.push((0, [a * 1e-6 * ARCSEC_PER_RAD, 0.0]));
                out.push((1, [x * y * y, 0.0]));
                out.push((2, [x * x * x, 0.0]));
                out.push((3, [0.0, b * 1e-6 * ARCSEC_PER_RAD]));
                out.push((4, [0.0, y * x * x]));
                out.push((5, [0.0, y * y * y]));
                if let Some(p) = self.pitch_rad {
                    let w = std::f64::consts::TAU / p;
                    let (sa, ca) = (w * a).sin_cos();
                    let (sb, cb) = (w * b).sin_cos();
                    out.push((6, [sa, 0.0]));
                    out.push((7, [ca, 0.0]));
                    out.push((8, [0.0, sb]));
                    out.push((9, [0.0, cb]));
                }
            }
            EffectKind::FssCyclicError => {}
            EffectKind::GenericAlignmentExtension => {
                push_alignment_terms(out, m, GENERIC_TERMS, &generic_extension_terms(m));
            }
            EffectKind::SecularAlignmentExtension => {
                push_alignment_terms(out, m, 3, &self.secular_extension_terms(m));
            }
            EffectKind::CatalogProperMotionError => {
                if m.sensor < 2 {
                    if let Some(k) = star_index(m.star) {
                        out.push((2 * k, v2(m.jm * m.tangent_acs[0])));
                        out.push((2 * k + 1, v2(m.jm * m.tangent_acs[1])));
                    }
                }
            }
        }
    }

    /// Must the signature structure be significant before the candidate may be added?
    /// Not for aberration: its annual part is nearly a common rotation that the attitude
    /// absorbs, so the fit sees it before any single-regressor test does.
    #[must_use]
    pub fn needs_indication(&self) -> bool {
        // The sparse catalog form's indication is its own selection: each of its stars
        // passed a 2-dof test, Holm over the stars ([`super::sparse_catalog`]); the star-id
        // grouping test over every star seen dilutes three bad stars among a hundred
        // (min p 2.6e-3 for three 10–15″ offsets whose fit gives Δχ² 580).
        !matches!(
            self.kind,
            EffectKind::AberrationAnnual | EffectKind::AberrationOrbital | EffectKind::Aberration
        ) && !self.sparse
    }

    /// Regressors whose structure this effect should remove (adequacy check).
    #[must_use]
    pub fn signature(&self) -> &'static [super::regressor::Regressor] {
        use super::regressor::Regressor as R;
        match self.kind {
            EffectKind::AberrationAnnual => &[],
            // The combined candidate's orbital part is once per orbit: orbit-phase structure it
            // leaves (a twice-per-orbit term) is not its to explain.
            EffectKind::AberrationOrbital | EffectKind::Aberration => &[R::OrbitPhase],
            EffectKind::TimeTagOffset => &[R::RateX, R::RateY, R::RateZ],
            EffectKind::ThermalAlignmentDrift | EffectKind::OrbitPeriodicAlignment => {
                &[R::Temperature, R::OrbitPhase, R::Time]
            }
            EffectKind::FhstDistortion => &[R::FovH, R::FovV, R::FovRadius],
            EffectKind::MagnitudeBias => &[R::Magnitude],
            EffectKind::FssTransferFunction | EffectKind::FssCyclicError => &[R::FovH, R::FovV],
            EffectKind::CatalogProperMotionError => &[R::StarId],
            EffectKind::GenericAlignmentExtension | EffectKind::SecularAlignmentExtension => &[],
            EffectKind::UnknownOrbit | EffectKind::AlignmentStep => &[R::Time],
        }
    }
}

/// Per-star offsets are known only up to a common rotation of the sky (the batch attitudes
/// absorb it): remove the weighted least-squares net rotation `ω` (`east = e_N·ω`,
/// `north = −e_E·ω`) from a vector of per-star (east, north) offsets with variances `var`.
#[must_use]
pub fn remove_net_rotation(dirs: &[nalgebra::Vector3<f64>], x: &[f64], var: &[f64]) -> Vec<f64> {
    let mut n = nalgebra::Matrix3::<f64>::zeros();
    let mut b = nalgebra::Vector3::<f64>::zeros();
    let rows = |k: usize| {
        let [e, nn] = tangent_basis_eci(&dirs[k]);
        [nn, -e]
    };
    for k in 0..dirs.len() {
        let r = rows(k);
        for j in 0..2 {
            let i = 2 * k + j;
            if !(var[i].is_finite() && var[i] > 0.0) {
                continue;
            }
            let w = 1.0 / var[i];
            n += r[j] * r[j].transpose() * w;
            b += r[j] * (w * x[i]);
        }
    }
    let omega = n
        .try_inverse()
        .map_or_else(nalgebra::Vector3::zeros, |inv| inv * b);
    (0..x.len())
        .map(|i| x[i] - rows(i / 2)[i % 2].dot(&omega))
        .collect()
}

/// East/north basis of a direction (as the measurement set builds it).
#[must_use]
pub fn tangent_basis_eci(u: &nalgebra::Vector3<f64>) -> [nalgebra::Vector3<f64>; 2] {
    let east = nalgebra::Vector3::z().cross(u);
    let east = if east.norm() < 1e-9 {
        nalgebra::Vector3::x()
    } else {
        east.normalize()
    };
    [east, u.cross(&east)]
}

/// `J Mᵀ A (I − u uᵀ)` (2×3, arcsec per arcsec of `v/c` along each ECI axis): how a
/// velocity aberration moves a measurement. From the tangent basis, which the measurement
/// carries in both frames.
fn unknown_orbit_map(m: &Measurement) -> nalgebra::Matrix2x3<f64> {
    let [e, n] = tangent_basis_eci(&m.u_eci);
    let t = m.tangent_acs[0] * e.transpose() + m.tangent_acs[1] * n.transpose();
    m.jm * t
}

/// Sun parallax per unit of orbital aberration for a circular orbit of rate `n`:
/// `|r| / AU = (c / n) (v / c) / AU`.
fn parallax_per_aberration(n_rad_per_s: f64) -> f64 {
    const C_KM_PER_S: f64 = 299_792.458;
    const AU_KM: f64 = 149_597_870.7;
    C_KM_PER_S / (n_rad_per_s * AU_KM)
}

/// Shortest run for [`unknown_orbit_rate`] (s): a third of an orbit, over which the
/// aberration still turns by 2 rad.
pub const UNKNOWN_ORBIT_MIN_SPAN_S: f64 = 1800.0;

/// Orbit periods searched for [`EffectKind::UnknownOrbit`] (min): low Earth orbits.
pub const UNKNOWN_ORBIT_PERIOD_MIN: [f64; 2] = [85.0, 130.0];

/// The orbit rate (rad/s) that the residuals `resid` of `set` follow best with the
/// unknown-orbit columns: the largest χ² reduction of their six-parameter least-squares fit
/// over periods in [`UNKNOWN_ORBIT_PERIOD_MIN`] (0.5 min steps, then 0.02 min around the
/// best). `None` with fewer than 200 measurements or a run shorter than
/// [`UNKNOWN_ORBIT_MIN_SPAN_S`].
#[must_use]
pub fn unknown_orbit_rate(set: &MeasurementSet, resid: &[[f64; 2]]) -> Option<f64> {
    let rows: Vec<(&Measurement, [f64; 2])> = set
        .meas
        .iter()
        .zip(resid)
        .filter(|(m, r)| !m.outlier && r.iter().all(|v| v.is_finite()))
        .map(|(m, r)| (m, *r))
        .collect();
    let span = rows.iter().map(|(m, _)| m.t_s).fold(0.0, f64::max)
        - rows
            .iter()
            .map(|(m, _)| m.t_s)
            .fold(f64::INFINITY, f64::min);
    if rows.len() < 200 || !(span >= UNKNOWN_ORBIT_MIN_SPAN_S) {
        return None;
    }
    let maps: Vec<nalgebra::Matrix2x3<f64>> =
        rows.iter().map(|(m, _)| unknown_orbit_map(m)).collect();
    // χ² reduction at one period, with each batch's attitude and rate eliminated as in the
    // joint fit (they absorb the slow part of the signature; without them the best period
    // of a 5.7-h writer run was 1.6 % short).
    let gain = |period_min: f64| -> f64 {
        let n = std::f64::consts::TAU / (period_min * 60.0);
        let k = parallax_per_aberration(n);
        let mut nn = nalgebra::SMatrix::<f64, 6, 6>::zeros();
        let mut b = nalgebra::SVector::<f64, 6>::zeros();
        let mut nbb = nalgebra::SMatrix::<f64, 6, 6>::zeros();
        let mut nbo = nalgebra::SMatrix::<f64, 6, 6>::zeros();
        let mut bb = nalgebra::SVector::<f64, 6>::zeros();
        let mut batch = usize::MAX;
        let close = |nn: &mut nalgebra::SMatrix<f64, 6, 6>,
                     b: &mut nalgebra::SVector<f64, 6>,
                     nbb: &mut nalgebra::SMatrix<f64, 6, 6>,
                     nbo: &mut nalgebra::SMatrix<f64, 6, 6>,
                     bb: &mut nalgebra::SVector<f64, 6>| {
            for j in 0..6 {
                nbb[(j, j)] += 1e-6;
            }
            if let Some(c) = nbb.cholesky() {
                *nn -= nbo.transpose() * c.solve(nbo);
                *b -= nbo.transpose() * c.solve(bb);
            }
            *nbb = nalgebra::SMatrix::zeros();
            *nbo = nalgebra::SMatrix::zeros();
            *bb = nalgebra::SVector::zeros();
        };
        for ((m, r), g) in rows.iter().zip(&maps) {
            if m.batch != batch {
                close(&mut nn, &mut b, &mut nbb, &mut nbo, &mut bb);
                batch = m.batch;
            }
            let (sin, cos) = (n * m.t_s).sin_cos();
            let (ca, cb) = if m.sensor >= 2 {
                (cos - k * sin, sin + k * cos)
            } else {
                (cos, sin)
            };
            let w = 1.0 / (m.sigma * m.sigma);
            for ax in 0..2 {
                let row = g.row(ax);
                let mut a = nalgebra::SVector::<f64, 6>::zeros();
                let mut z = nalgebra::SVector::<f64, 6>::zeros();
                for j in 0..3 {
                    a[j] = row[j] * ca;
                    a[3 + j] = row[j] * cb;
                    let mut e = nalgebra::Vector3::zeros();
                    e[j] = 1.0;
                    let att = -(m.jm * m.b_acs.cross(&e));
                    z[j] = att[ax];
                    z[3 + j] = att[ax] * m.dt_center_s / 100.0;
                }
                nn += a * a.transpose() * w;
                b += a * (w * r[ax]);
                nbb += z * z.transpose() * w;
                nbo += z * a.transpose() * w;
                bb += z * (w * r[ax]);
            }
        }
        close(&mut nn, &mut b, &mut nbb, &mut nbo, &mut bb);
        for j in 0..6 {
            nn[(j, j)] += 1.0 / (20.0 * 20.0);
        }
        nn.cholesky().map_or(0.0, |c| b.dot(&c.solve(&b)))
    };
    let mut best = (f64::NEG_INFINITY, UNKNOWN_ORBIT_PERIOD_MIN[0]);
    let steps =
        ((UNKNOWN_ORBIT_PERIOD_MIN[1] - UNKNOWN_ORBIT_PERIOD_MIN[0]) / 0.5).round() as usize;
    for i in 0..=steps {
        let p = UNKNOWN_ORBIT_PERIOD_MIN[0] + 0.5 * i as f64;
        let g = gain(p);
        if g > best.0 {
            best = (g, p);
        }
    }
    let centre = best.1;
    for i in 0..=50 {
        let p = centre - 0.5 + 0.02 * f64::from(i);
        let g = gain(p);
        if g > best.0 {
            best = (g, p);
        }
    }
    Some(std::f64::consts::TAU / (best.1 * 60.0))
}

/// Sensors with enough data (≥ 50 measurements).
fn active_sensors(set: &MeasurementSet) -> [bool; 4] {
    let c = set.count_per_sensor();
    [c[0] >= 50, c[1] >= 50, c[2] >= 50, c[3] >= 50]
}

/// Orbits a sensor's data must span before an orbit-periodic term is offered for it.
///
/// Why: a periodicity is established only by repetition. Over less than an orbit, `cos u`
/// and `sin u` are two smooth functions of time that absorb any slow structure (a drift, a
/// slew's unmodelled signature: a 50-min run with an FHST time tag gave a 60″
/// `orbit_periodic_alignment[FSS1]`), and the halves of the data (first and second half in
/// time) must each hold a whole orbit for their agreement to say the variation repeats.
pub const MIN_ORBITS_FOR_PERIODIC: f64 = 2.0;

/// Whether each sensor's data span at least [`MIN_ORBITS_FOR_PERIODIC`] orbits.
#[must_use]
pub fn spans_orbits(set: &MeasurementSet) -> [bool; 4] {
    let Some(period_s) = set.orbit_period_s.filter(|p| p.is_finite() && *p > 0.0) else {
        return [false; 4];
    };
    let spans = data_spans(set, |m| m.orbit_phase.is_finite());
    core::array::from_fn(|s| {
        spans[s].is_some_and(|[t0, t1]| t1 - t0 >= MIN_ORBITS_FOR_PERIODIC * period_s)
    })
}

/// First and last time of each sensor's non-outlier data that `keep` accepts, if any.
fn data_spans(
    set: &MeasurementSet,
    keep: impl Fn(&super::measurements::Measurement) -> bool,
) -> [Option<[f64; 2]>; 4] {
    let mut first = [f64::INFINITY; 4];
    let mut last = [f64::NEG_INFINITY; 4];
    for m in set.meas.iter().filter(|m| !m.outlier && keep(m)) {
        first[m.sensor] = first[m.sensor].min(m.t_s);
        last[m.sensor] = last[m.sensor].max(m.t_s);
    }
    core::array::from_fn(|s| (last[s] > first[s]).then_some([first[s], last[s]]))
}

/// The candidate library for a measurement set. `fss_pitch_rad[i]` is the cyclic pitch found
/// for FSS i (none: no cyclic candidate).
#[must_use]
pub fn library(
    set: &MeasurementSet,
    fss_pitch_rad: [Option<f64>; 2],
    unknown_orbit_rad_per_s: Option<f64>,
) -> Vec<Effect> {
    let active = active_sensors(set);
    let periodic = spans_orbits(set);
    let spans = data_spans(set, |_| true);
    let mut out = vec![
        Effect::new(
            EffectKind::AberrationAnnual,
            None,
            &[("k_annual_minus_applied", "1", 10.0)],
        ),
        Effect::new(
            EffectKind::AberrationOrbital,
            None,
            &[("k_orbital_minus_applied", "1", 10.0)],
        ),
        Effect::new(
            EffectKind::Aberration,
            None,
            &[
                ("k_annual_minus_applied", "1", 10.0),
                ("k_orbital_minus_applied", "1", 10.0),
            ],
        ),
    ];
    if let Some(n) = unknown_orbit_rad_per_s {
        let mut e = Effect::new(
            EffectKind::UnknownOrbit,
            None,
            &[
                ("v_over_c_cos_x", "arcsec", 20.0),
                ("v_over_c_cos_y", "arcsec", 20.0),
                ("v_over_c_cos_z", "arcsec", 20.0),
                ("v_over_c_sin_x", "arcsec", 20.0),
                ("v_over_c_sin_y", "arcsec", 20.0),
                ("v_over_c_sin_z", "arcsec", 20.0),
            ],
        );
        e.rate_rad_per_s = Some(n);
        e.hidden = true;
        out.push(e);
    }
    for s in 0..4 {
        if active[s] {
            sensor_effects(&mut out, s, periodic[s], spans[s], fss_pitch_rad);
        }
    }
    out.extend(catalog_effect(set));
    out
}

/// Orbit harmonics 2–3, the square of the own temperature, and for an FHST the other
/// tracker's temperature and its square (only relative FHST alignment is observable: the
/// other tracker's thermal motion looks like this one's): the generic extension's terms.
fn generic_extension_terms(m: &Measurement) -> [f64; GENERIC_TERMS] {
    let dt = m.dtemp[m.sensor];
    let dto = if m.sensor < 2 {
        m.dtemp[1 - m.sensor]
    } else {
        0.0
    };
    let u = m.orbit_phase;
    let (c2, s2, c3, s3) = if u.is_finite() {
        (
            (2.0 * u).cos(),
            (2.0 * u).sin(),
            (3.0 * u).cos(),
            (3.0 * u).sin(),
        )
    } else {
        (0.0, 0.0, 0.0, 0.0)
    };
    [c2, s2, c3, s3, dt * dt, dto, dto * dto]
}

/// Columns of an alignment term per ACS axis times each of `terms` (`stride` columns per
/// axis), as the alignment-extension candidates have them.
fn push_alignment_terms(
    out: &mut Vec<(usize, [f64; 2])>,
    m: &Measurement,
    stride: usize,
    terms: &[f64],
) {
    for ax in 0..3 {
        let mut e = nalgebra::Vector3::zeros();
        e[ax] = 1.0;
        let col = -(m.jm * m.b_acs.cross(&e));
        for (k, t) in terms.iter().enumerate() {
            let v = col * *t;
            out.push((stride * ax + k, [v.x, v.y]));
        }
    }
}

/// The candidates of sensor `s`: time tag, thermal drift, orbit-periodic alignment (when the
/// data span orbits), the hidden lack-of-fit extensions, and its field terms (FHST
/// distortion and magnitude bias; FSS transfer function with the cyclic term at the pitch
/// found).
fn sensor_effects(
    out: &mut Vec<Effect>,
    s: usize,
    periodic: bool,
    span: Option<[f64; 2]>,
    fss_pitch_rad: [Option<f64>; 2],
) {
    out.push(Effect::new(
        EffectKind::TimeTagOffset,
        Some(s),
        &[("tau", "ms", 1000.0)],
    ));
    out.push(Effect::new(
        EffectKind::ThermalAlignmentDrift,
        Some(s),
        &[
            ("x", "arcsec/degC", 30.0),
            ("y", "arcsec/degC", 30.0),
            ("z", "arcsec/degC", 30.0),
        ],
    ));
    let once = [
        ("cos_x", "arcsec", 100.0),
        ("cos_y", "arcsec", 100.0),
        ("cos_z", "arcsec", 100.0),
        ("sin_x", "arcsec", 100.0),
        ("sin_y", "arcsec", 100.0),
        ("sin_z", "arcsec", 100.0),
    ];
    // The same with the second harmonic: a thermal orbit cycle is not a sinusoid
    // (eclipse entry and exit, algorithms.md §9 row 2: "periodic at orbit period and
    // harmonics"). A separate candidate, so a once-per-orbit variation is not charged six
    // more parameters; the evidence decides between them.
    let mut both = once.to_vec();
    both.extend([
        ("cos2u_x", "arcsec", 100.0),
        ("cos2u_y", "arcsec", 100.0),
        ("cos2u_z", "arcsec", 100.0),
        ("sin2u_x", "arcsec", 100.0),
        ("sin2u_y", "arcsec", 100.0),
        ("sin2u_z", "arcsec", 100.0),
    ]);
    if periodic {
        out.push(Effect::new(
            EffectKind::OrbitPeriodicAlignment,
            Some(s),
            &once,
        ));
        let mut e = Effect::new(EffectKind::OrbitPeriodicAlignment, Some(s), &both);
        e.harmonics = 2;
        out.push(e);
    }
    {
        let mut names = Vec::new();
        for ax in ["x", "y", "z"] {
            for t in [
                "cos2u",
                "sin2u",
                "cos3u",
                "sin3u",
                "dT2",
                "dT_other",
                "dT_other2",
            ] {
                names.push((format!("{ax}_{t}"), "arcsec", 100.0));
            }
        }
        let refs: Vec<(&str, &'static str, f64)> =
            names.iter().map(|(n, u, s)| (n.as_str(), *u, *s)).collect();
        let mut e = Effect::new(EffectKind::GenericAlignmentExtension, Some(s), &refs);
        e.hidden = true;
        out.push(e);
        let names: Vec<String> = ["x", "y", "z"]
            .iter()
            .flat_map(|ax| (1..=3).map(move |k| format!("{ax}_time_p{k}")))
            .collect();
        let refs: Vec<(&str, &'static str, f64)> = names
            .iter()
            .map(|n| (n.as_str(), "arcsec", 100.0))
            .collect();
        let mut e = Effect::new(EffectKind::SecularAlignmentExtension, Some(s), &refs);
        e.hidden = true;
        e.time_span_s = span;
        out.push(e);
    }
    if s < 2 {
        out.push(Effect::new(
            EffectKind::FhstDistortion,
            Some(s),
            &[
                ("radial_at_4deg", "arcsec", 100.0),
                ("hv_h_at_corner", "arcsec", 100.0),
                ("hv_v_at_corner", "arcsec", 100.0),
            ],
        ));
        out.push(Effect::new(
            EffectKind::MagnitudeBias,
            Some(s),
            &[
                ("h_per_mag", "arcsec/mag", 20.0),
                ("v_per_mag", "arcsec/mag", 20.0),
            ],
        ));
    } else {
        let mut params = vec![
            ("alpha_scale", "ppm", 2000.0),
            ("alpha_cross_at_corner", "arcsec", 200.0),
            ("alpha_cubic_at_edge", "arcsec", 200.0),
            ("beta_scale", "ppm", 2000.0),
            ("beta_cross_at_corner", "arcsec", 200.0),
            ("beta_cubic_at_edge", "arcsec", 200.0),
        ];
        let pitch = fss_pitch_rad[s - 2];
        if pitch.is_some() {
            params.extend([
                ("alpha_cyclic_sin", "arcsec", 60.0),
                ("alpha_cyclic_cos", "arcsec", 60.0),
                ("beta_cyclic_sin", "arcsec", 60.0),
                ("beta_cyclic_cos", "arcsec", 60.0),
            ]);
        }
        let mut e = Effect::new(EffectKind::FssTransferFunction, Some(s), &params);
        e.pitch_rad = pitch;
        e.extra_params = usize::from(pitch.is_some());
        out.push(e);
    }
}

/// The catalog candidate: per-star offsets of the stars seen often enough (at least three),
/// constrained to no net rotation per tracker.
fn catalog_effect(set: &MeasurementSet) -> Option<Effect> {
    // Catalog: stars seen often enough, in at least two batches.
    let mut seen: std::collections::BTreeMap<u32, (usize, usize, usize)> =
        std::collections::BTreeMap::new();
    let mut dirs: std::collections::BTreeMap<u32, nalgebra::Vector3<f64>> =
        std::collections::BTreeMap::new();
    let mut trackers: std::collections::BTreeMap<u32, [bool; 2]> =
        std::collections::BTreeMap::new();
    for m in set
        .meas
        .iter()
        .filter(|m| m.sensor < 2 && !m.outlier && m.star != 0)
    {
        dirs.entry(m.star).or_insert(m.u_eci);
        trackers.entry(m.star).or_insert([false; 2])[m.sensor] = true;
        let e = seen.entry(m.star).or_insert((0, usize::MAX, 0));
        e.0 += 1;
        if e.1 != m.batch {
            e.2 += 1;
            e.1 = m.batch;
        }
    }
    let stars: Vec<u32> = seen
        .iter()
        .filter(|(_, (n, _, _))| *n >= CATALOG_MIN_SAMPLES)
        .map(|(h, _)| *h)
        .collect();
    if stars.len() < 3 {
        return None;
    }
    let mut names = Vec::with_capacity(2 * stars.len());
    for h in &stars {
        names.push((format!("HIP{h}_east"), "arcsec", 60.0));
        names.push((format!("HIP{h}_north"), "arcsec", 60.0));
    }
    let refs: Vec<(&str, &'static str, f64)> =
        names.iter().map(|(n, u, s)| (n.as_str(), *u, *s)).collect();
    let mut e = Effect::new(EffectKind::CatalogProperMotionError, None, &refs);
    e.star_dirs = stars
        .iter()
        .map(|h| dirs.get(h).copied().unwrap_or_else(nalgebra::Vector3::z))
        .collect();
    // Gauge: a common rotation of the stars one tracker sees is the same as a rotation of
    // that tracker (or of the attitude), so per-star offsets can move the alignments
    // (the roll about a boresight above all). The offsets are therefore constrained to
    // have no least-squares net rotation per tracker (0 ± 0.5″ in every axis): the
    // catalog effect cannot move a tracker's alignment, which stays what the data give
    // without it.
    for tr in 0..2 {
        let members: Vec<usize> = (0..stars.len())
            .filter(|&k| trackers.get(&stars[k]).is_some_and(|t| t[tr]))
            .collect();
        if members.len() < 3 {
            continue;
        }
        let n = members.len() as f64;
        let mut pm = nalgebra::Matrix3::<f64>::zeros();
        for &k in &members {
            let [east, north] = tangent_basis_eci(&e.star_dirs[k]);
            pm += (north * north.transpose() + east * east.transpose()) / n;
        }
        let Some(pinv) = pm.try_inverse() else {
            continue;
        };
        for axis in 0..3 {
            let coef = pinv.row(axis).transpose();
            let mut row = Vec::with_capacity(2 * members.len());
            for &k in &members {
                let [east, north] = tangent_basis_eci(&e.star_dirs[k]);
                row.push((2 * k, coef.dot(&north) / n));
                row.push((2 * k + 1, -coef.dot(&east) / n));
            }
            e.constraints.push((row, 0.5));
        }
    }
    e.stars = stars;
    Some(e)
}

/// `C(n, k)` (statrs), saturating at `usize::MAX` (a look-elsewhere factor: only its size
/// matters).
#[must_use]
pub fn subsets(n: usize, k: usize) -> usize {
    let c = statrs::function::factorial::binomial(n as u64, k as u64);
    if c >= usize::MAX as f64 {
        usize::MAX
    } else {
        (c as usize).max(1)
    }
}

#[cfg(test)]
mod tests {
    use super::{subsets, EffectKind};

    /// `EffectKind::ALL` lists every kind once: the match below stops compiling when a kind is
    /// added, and a kind missing from `ALL` would be warned as unmodelled when declared.
    #[test]
    fn effect_kind_all_lists_every_kind() {
        let position = |k: EffectKind| match k {
            EffectKind::AberrationAnnual => 0,
            EffectKind::AberrationOrbital => 1,
            EffectKind::Aberration => 2,
            EffectKind::TimeTagOffset => 3,
            EffectKind::ThermalAlignmentDrift => 4,
            EffectKind::OrbitPeriodicAlignment => 5,
            EffectKind::FhstDistortion => 6,
            EffectKind::MagnitudeBias => 7,
            EffectKind::FssTransferFunction => 8,
            EffectKind::FssCyclicError => 9,
            EffectKind::CatalogProperMotionError => 10,
            EffectKind::GenericAlignmentExtension => 11,
            EffectKind::SecularAlignmentExtension => 12,
            EffectKind::UnknownOrbit => 13,
            EffectKind::AlignmentStep => 14,
        };
        for (i, k) in EffectKind::ALL.iter().enumerate() {
            assert_eq!(position(*k), i, "{k:?}");
        }
    }

    #[test]
    fn subsets_counts_the_choices_and_saturates() {
        assert_eq!(subsets(5, 2), 10);
        assert_eq!(subsets(102, 1), 102);
        assert_eq!(subsets(102, 0), 1);
        assert_eq!(subsets(4, 4), 1);
        assert_eq!(subsets(3000, 1500), usize::MAX);
    }
}
