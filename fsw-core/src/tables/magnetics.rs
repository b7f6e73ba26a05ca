//! # Table 6: magnetics — the onboard field model, the TAM calibration and the coarse-attitude settings
//!
//! Why one table: the coarse attitude (`crate::coarse`) needs all of it at once — the field the
//! magnetometers should see (an IGRF/DGRF spherical-harmonic model with its epoch and secular
//! variation, and the Earth orientation that carries it to inertial axes), what the TAMs
//! actually measure (alignment, count size, bias) and how far each vector can be trusted. The
//! ground recomputes the field model and the TAM bias together (issue 20: the paper's FDF
//! determined the primary TAM's bias [0, 0, −4] mG and compared FSS/TAM attitudes with FHST
//! ones), so they travel together and are validated together.
//!
//! The boot table holds no field model (`field_degree = 0`): the OBC computes no coarse
//! attitude until the ground uplinks one, as it propagates no orbit before an orbit table.
//! The coefficients are **Schmidt semi-normalised** as published by IAGA (nT, nT/yr); the OBC
//! applies the normalisation itself. Byte layout and ranges: `docs/tables.md` (Table 6).

use nalgebra::Matrix3;
use serde::{Deserialize, Serialize};

use super::error::TableError;
use super::image::decode_payload;
use super::types::{all_finite, check_finite, check_range, matrix_from_rows, Mat3Rows};
use crate::attitude::is_proper_rotation;
use crate::raw::{CSS_EYES, TAMS, WHEELS};

/// Highest spherical-harmonic degree the onboard field model holds (IGRF's main field before
/// 2000 is published to degree 10).
/// IAGA IGRF (DGRF 1990/1995 to degree 10); docs/tables.md (Table 6, field 0).
pub const FIELD_MAX_DEGREE: usize = 10;
/// Rows of the coefficient arrays (`n = 0..=FIELD_MAX_DEGREE`).
/// docs/tables.md (Table 6, fields 2–5).
pub const FIELD_N1: usize = FIELD_MAX_DEGREE + 1;

/// Spherical-harmonic coefficients `[n][m]` (row `n`, column `m ≤ n`; the rest zero).
/// docs/tables.md (Table 6, fields 2–5).
pub type HarmonicRows = [[f64; FIELD_N1]; FIELD_N1];

/// Table 6: the onboard geomagnetic field model, the TAM calibration and the coarse-attitude
/// settings.
/// docs/tables.md (Table 6: magnetics); algorithms.md §10a (coarse attitude, TAM calibration).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MagneticsTable {
    /// Degree of the field model, 0 (none: no coarse attitude) to [`FIELD_MAX_DEGREE`].
    /// docs/tables.md (Table 6, field 0).
    pub field_degree: u8,
    /// Epoch of the coefficients, seconds since J2000.0 TT.
    /// docs/tables.md (Table 6, field 1).
    pub field_epoch_s_since_j2000_tt: f64,
    /// Schmidt semi-normalised `g[n][m]` at the epoch, nT.
    /// IAGA IGRF convention; docs/tables.md (Table 6, field 2).
    pub g_nt: HarmonicRows,
    /// Schmidt semi-normalised `h[n][m]` at the epoch, nT (`h[n][0]` unused, zero).
    /// IAGA IGRF convention; docs/tables.md (Table 6, field 3).
    pub h_nt: HarmonicRows,
    /// Secular variation of `g`, nT per Julian year (365.25 d).
    /// IAGA IGRF convention; docs/tables.md (Table 6, field 4).
    pub g_nt_per_year: HarmonicRows,
    /// Secular variation of `h`, nT per Julian year.
    /// IAGA IGRF convention; docs/tables.md (Table 6, field 5).
    pub h_nt_per_year: HarmonicRows,
    /// Precession and nutation at the field epoch: the rotation from J2000/GCRS axes to the
    /// true equator and equinox of date (rows). The OBC turns it about the pole by the
    /// apparent sidereal time to reach Earth-fixed axes; the ground re-uplinks it with the
    /// coefficients (precession moves it 50″ a year, far below the coarse requirement).
    /// IAU 1976/1980 (Meeus ch. 21–22); docs/tables.md (Table 6, field 6).
    pub m_tod_from_eci: Mat3Rows,
    /// UT1 − TAI, s (UT1 = TAI + this: −(TAI − UTC) + (UT1 − UTC), IERS), for sidereal time.
    /// IERS Bulletin A; docs/tables.md (Table 6, field 7).
    pub ut1_minus_tai_s: f64,
    /// Equation of the equinoxes at the epoch, rad (apparent minus mean sidereal time).
    /// IAU 1982 (Meeus ch. 12); docs/tables.md (Table 6, field 8).
    pub equation_of_equinoxes_rad: f64,
    /// TAM1, TAM2 alignment `M_AS` (sensor → ACS), rows; proper rotations.
    /// algorithms.md §10a (TAM calibration); docs/tables.md (Table 6, field 9).
    pub m_acs_from_tam: [Mat3Rows; TAMS],
    /// TAM1, TAM2 count size, mG per count (per sensor axis: scale-factor calibration).
    /// docs/magnetics.md §2; docs/tables.md (Table 6, field 10).
    pub tam_milligauss_per_count: [[f64; 3]; TAMS],
    /// TAM1, TAM2 bias subtracted from the reading, mG on the sensor's axes (the paper's
    /// primary-TAM bias [0, 0, −4] mG once the ground has determined it).
    /// Paper (`data/gro_paper.toml` `[sensors.tam]`); docs/tables.md (Table 6, field 11).
    pub tam_bias_milligauss: [[f64; 3]; TAMS],
    /// TAM1, TAM2: 1σ per axis of what is left in a corrected TAM field against the onboard
    /// model, mG: bias uncertainty, residual spacecraft field, field-model error, noise. Per
    /// TAM, because the ground may calibrate one and leave the other nominal.
    /// algorithms.md §10a; docs/tables.md (Table 6, field 12).
    pub field_sigma_milligauss: [f64; TAMS],
    /// 1σ per axis of an FSS Sun direction used by the coarse attitude, rad.
    /// docs/tables.md (Table 6, field 13).
    pub fss_sun_sigma_rad: f64,
    /// CSS eye normals (ACS, unit), order +X, −X, +Y, −Y, +Z, −Z by default.
    /// docs/magnetics.md §2; docs/tables.md (Table 6, field 14).
    pub css_normals_acs: [[f64; 3]; CSS_EYES],
    /// CSS output at normal incidence, counts.
    /// docs/magnetics.md §2; docs/tables.md (Table 6, field 15).
    pub css_counts_at_normal_incidence: f64,
    /// 1σ per axis of a CSS Sun direction (Earth albedo dominates), rad.
    /// docs/tables.md (Table 6, field 16).
    pub css_sun_sigma_rad: f64,
    /// A new coarse fix every this many cycles (the field synthesis is the costly part);
    /// between fixes the solution is carried on the gyros.
    /// Project choice; docs/tables.md (Table 6, field 17).
    pub coarse_fix_every_n_cycles: u16,
    /// Smallest Sun–field angle for a fix, rad: below it the rotation about the two nearly
    /// parallel vectors is unobservable and no fix is made.
    /// algorithms.md §10a ("near-parallel vectors"); docs/tables.md (Table 6, field 18).
    pub min_sun_field_angle_rad: f64,
    /// Momentum-unloading gain `k` of `m = k (h × B)/|B|²`, 1/s (the time constant of the
    /// unloading of the momentum perpendicular to the field is `1/k` while no bar saturates);
    /// 0 = no unloading (bars off).
    /// Markley & Crassidis (2014) ch. 7 (momentum management, the cross-product law);
    /// docs/tables.md (Table 6, field 19).
    pub unloading_gain_per_s: f64,
    /// Largest dipole the OBC commands per torquer bar, A·m² (the bars' rating).
    /// docs/magnetics.md §7; docs/tables.md (Table 6, field 20).
    pub torquer_dipole_limit_am2: f64,
    /// Unloading starts when the momentum to unload exceeds this, N·m·s (the dead band).
    /// docs/magnetics.md §7; docs/tables.md (Table 6, field 21).
    pub unloading_start_nms: f64,
    /// Unloading stops when the momentum to unload falls below this, N·m·s (≤ field 21: the
    /// hysteresis keeps the bars from chattering at the edge of the dead band).
    /// docs/magnetics.md §7; docs/tables.md (Table 6, field 22).
    pub unloading_stop_nms: f64,
    /// The bars-off check: a TAM sample taken with every bar commanded off that differs from
    /// the onboard model field (at the fine attitude) by more than this, mG, on 3 such samples
    /// in a row, is an unexpected field at the TAM (a bar stuck on, or a TAM fault: event
    /// 0x0A01), and the unloading uses the model field instead.
    /// docs/magnetics.md §7; docs/tables.md (Table 6, field 23).
    pub torquer_check_milligauss: f64,
    /// Reaction wheel spin axes in ACS (unit), wheel 1 to 4 in the tachometer words' order;
    /// a zero row is no wheel. The OBC turns the tachometers into the wheel momentum with
    /// them: `h = Σ a_i J ω_i`.
    /// docs/magnetics.md §7; docs/tables.md (Table 6, field 24).
    pub wheel_spin_axes_acs: [[f64; 3]; WHEELS],
    /// Wheel rotor inertia about its spin axis, kg·m² (every wheel).
    /// docs/magnetics.md §7; docs/tables.md (Table 6, field 25).
    pub wheel_spin_inertia_kg_m2: f64,
}

/// Fields 19–23 of a layout-2 Table 6 (momentum unloading), the part layout 2 added to
/// layout 1. A layout-2 payload is a [`MagneticsTableLayout1`] followed by these.
/// docs/tables.md (Table 6, "layouts").
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct MagneticsUnloadingFields {
    /// Field 19. docs/tables.md (Table 6).
    pub unloading_gain_per_s: f64,
    /// Field 20. docs/tables.md (Table 6).
    pub torquer_dipole_limit_am2: f64,
    /// Field 21. docs/tables.md (Table 6).
    pub unloading_start_nms: f64,
    /// Field 22. docs/tables.md (Table 6).
    pub unloading_stop_nms: f64,
    /// Field 23. docs/tables.md (Table 6).
    pub torquer_check_milligauss: f64,
}

impl MagneticsUnloadingFields {
    /// Fields 19–23 of `t`.
    /// docs/tables.md (Table 6, "layouts").
    #[must_use]
    pub const fn from_table(t: &MagneticsTable) -> Self {
        Self {
            unloading_gain_per_s: t.unloading_gain_per_s,
            torquer_dipole_limit_am2: t.torquer_dipole_limit_am2,
            unloading_start_nms: t.unloading_start_nms,
            unloading_stop_nms: t.unloading_stop_nms,
            torquer_check_milligauss: t.torquer_check_milligauss,
        }
    }
}

/// Table 6 as written before the momentum-unloading fields 19–23 (layout 1: 4,402 payload
/// octets). A payload of this layout is still accepted: the fields it lacks take their boot
/// values ([`MagneticsTable::from_layout1`]).
/// docs/tables.md (Table 6, "layouts").
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct MagneticsTableLayout1 {
    /// Field 0. docs/tables.md (Table 6).
    pub field_degree: u8,
    /// Field 1. docs/tables.md (Table 6).
    pub field_epoch_s_since_j2000_tt: f64,
    /// Field 2. docs/tables.md (Table 6).
    pub g_nt: HarmonicRows,
    /// Field 3. docs/tables.md (Table 6).
    pub h_nt: HarmonicRows,
    /// Field 4. docs/tables.md (Table 6).
    pub g_nt_per_year: HarmonicRows,
    /// Field 5. docs/tables.md (Table 6).
    pub h_nt_per_year: HarmonicRows,
    /// Field 6. docs/tables.md (Table 6).
    pub m_tod_from_eci: Mat3Rows,
    /// Field 7. docs/tables.md (Table 6).
    pub ut1_minus_tai_s: f64,
    /// Field 8. docs/tables.md (Table 6).
    pub equation_of_equinoxes_rad: f64,
    /// Field 9. docs/tables.md (Table 6).
    pub m_acs_from_tam: [Mat3Rows; TAMS],
    /// Field 10. docs/tables.md (Table 6).
    pub tam_milligauss_per_count: [[f64; 3]; TAMS],
    /// Field 11. docs/tables.md (Table 6).
    pub tam_bias_milligauss: [[f64; 3]; TAMS],
    /// Field 12. docs/tables.md (Table 6).
    pub field_sigma_milligauss: [f64; TAMS],
    /// Field 13. docs/tables.md (Table 6).
    pub fss_sun_sigma_rad: f64,
    /// Field 14. docs/tables.md (Table 6).
    pub css_normals_acs: [[f64; 3]; CSS_EYES],
    /// Field 15. docs/tables.md (Table 6).
    pub css_counts_at_normal_incidence: f64,
    /// Field 16. docs/tables.md (Table 6).
    pub css_sun_sigma_rad: f64,
    /// Field 17. docs/tables.md (Table 6).
    pub coarse_fix_every_n_cycles: u16,
    /// Field 18. docs/tables.md (Table 6).
    pub min_sun_field_angle_rad: f64,
}

impl MagneticsTableLayout1 {
    /// Fields 0–18 of `t`: its layout-1 image, for an OBC of the old layout and for tests.
    /// docs/tables.md (Table 6, "layouts").
    #[must_use]
    pub fn from_table(t: &MagneticsTable) -> Self {
        Self {
            field_degree: t.field_degree,
            field_epoch_s_since_j2000_tt: t.field_epoch_s_since_j2000_tt,
            g_nt: t.g_nt,
            h_nt: t.h_nt,
            g_nt_per_year: t.g_nt_per_year,
            h_nt_per_year: t.h_nt_per_year,
            m_tod_from_eci: t.m_tod_from_eci,
            ut1_minus_tai_s: t.ut1_minus_tai_s,
            equation_of_equinoxes_rad: t.equation_of_equinoxes_rad,
            m_acs_from_tam: t.m_acs_from_tam,
            tam_milligauss_per_count: t.tam_milligauss_per_count,
            tam_bias_milligauss: t.tam_bias_milligauss,
            field_sigma_milligauss: t.field_sigma_milligauss,
            fss_sun_sigma_rad: t.fss_sun_sigma_rad,
            css_normals_acs: t.css_normals_acs,
            css_counts_at_normal_incidence: t.css_counts_at_normal_incidence,
            css_sun_sigma_rad: t.css_sun_sigma_rad,
            coarse_fix_every_n_cycles: t.coarse_fix_every_n_cycles,
            min_sun_field_angle_rad: t.min_sun_field_angle_rad,
        }
    }
}

/// The default CSS layout: six eyes on ±X, ±Y, ±Z of ACS.
/// docs/magnetics.md §2 (project choice; the paper gives no layout).
pub const CSS_NORMALS_DEFAULT: [[f64; 3]; CSS_EYES] = [
    [1.0, 0.0, 0.0],
    [-1.0, 0.0, 0.0],
    [0.0, 1.0, 0.0],
    [0.0, -1.0, 0.0],
    [0.0, 0.0, 1.0],
    [0.0, 0.0, -1.0],
];

/// The default wheel layout: three wheels on the ACS axes and a fourth along
/// `(1, 1, 1)/√3`, the truth's default.
/// Project choice (the paper gives no wheel layout); docs/magnetics.md §7.
pub const WHEEL_SPIN_AXES_DEFAULT: [[f64; 3]; WHEELS] = [
    [1.0, 0.0, 0.0],
    [0.0, 1.0, 0.0],
    [0.0, 0.0, 1.0],
    [FRAC_1_SQRT_3, FRAC_1_SQRT_3, FRAC_1_SQRT_3],
];

/// `1/√3` (the nearest `f64`), the skewed wheel's direction cosines.
const FRAC_1_SQRT_3: f64 = 0.577_350_269_189_625_8;

const IDENTITY_ROWS: Mat3Rows = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

impl MagneticsTable {
    /// The boot table: no field model (no coarse attitude until one is uplinked), TAMs on
    /// their nominal axes (ACS), 0.3 mG/count, no bias correction, conservative σ's.
    /// docs/tables.md (Table 6: "boot").
    #[must_use]
    pub fn boot() -> Self {
        Self {
            field_degree: 0,
            field_epoch_s_since_j2000_tt: 0.0,
            g_nt: [[0.0; FIELD_N1]; FIELD_N1],
            h_nt: [[0.0; FIELD_N1]; FIELD_N1],
            g_nt_per_year: [[0.0; FIELD_N1]; FIELD_N1],
            h_nt_per_year: [[0.0; FIELD_N1]; FIELD_N1],
            m_tod_from_eci: IDENTITY_ROWS,
            ut1_minus_tai_s: 0.0,
            equation_of_equinoxes_rad: 0.0,
            m_acs_from_tam: [IDENTITY_ROWS; TAMS],
            tam_milligauss_per_count: [[0.3; 3]; TAMS],
            tam_bias_milligauss: [[0.0; 3]; TAMS],
            // Before calibration: a bias of the paper's size (4 mG) in an unknown direction,
            // 4/√3 = 2.3 mG per axis, with an uncalibrated TAM alignment (≤ 0.2°: 1.4 mG of
            // 400 mG) and scale (0.1 %: 0.4 mG): 2.5 mG per axis (docs/magnetics.md §5).
            field_sigma_milligauss: [2.5; TAMS],
            // FSS: the prelaunch alignments were off by up to 0.20° (paper: FSS1 0.20°, FSS2
            // 0.05°, found by the in-flight calibration); 0.004° counts are negligible.
            fss_sun_sigma_rad: 0.1 * core::f64::consts::PI / 180.0,
            css_normals_acs: CSS_NORMALS_DEFAULT,
            css_counts_at_normal_incidence: 1000.0,
            // Earth albedo through a cosine eye moves the Sun direction by degrees.
            css_sun_sigma_rad: 5.0 * core::f64::consts::PI / 180.0,
            coarse_fix_every_n_cycles: 10,
            min_sun_field_angle_rad: 10.0 * core::f64::consts::PI / 180.0,
            // Momentum unloading (docs/magnetics.md §7): a 333-s time constant (1,000 s let
            // the stored momentum plus a 60° slew's reach 213 of the 250 N·m·s on
            // gro-early-mission, 333 s 181), the bars'
            // assumed 4,000 A·m² rating, a 20/10 N·m·s dead band (a tenth of the 250 N·m·s
            // wheel limit: the orbit's cyclic gravity-gradient momentum is stored, not dumped)
            // and a 20-mG bars-off check (8σ of the boot field σ: a prelaunch TAM bias and
            // misalignment stay below it).
            unloading_gain_per_s: 3.0e-3,
            torquer_dipole_limit_am2: 4_000.0,
            unloading_start_nms: 20.0,
            unloading_stop_nms: 10.0,
            torquer_check_milligauss: 20.0,
            // The truth's default wheels (docs/magnetics.md §7): 0.8 kg·m² holds the
            // 250-N·m·s limit at 2,984 rpm, inside the tachometer word's ±3,276.7 rpm.
            wheel_spin_axes_acs: WHEEL_SPIN_AXES_DEFAULT,
            wheel_spin_inertia_kg_m2: 0.8,
        }
    }

    /// Decode a Table 6 payload of any layout: layout 3 (fields 0–25), else layout 2
    /// (fields 0–23: the wheel fields 24–25 take their boot values), else layout 1 (fields
    /// 0–18: the unloading fields take their boot values too, [`Self::from_layout1`]). The
    /// layouts differ in length, so at most one decodes exactly. Returns the table and its
    /// layout (1, 2 or 3). The OBC's table services and the ground's tools both read through
    /// it.
    /// docs/tables.md (Table 6, "layouts").
    ///
    /// # Errors
    /// The layout-3 decode error when no layout decodes.
    pub fn decode_any_layout(payload: &[u8]) -> Result<(Self, u8), TableError> {
        match decode_payload::<Self>(payload) {
            Ok(t) => Ok((t, 3)),
            Err(e) => {
                if let Ok((old, u)) =
                    decode_payload::<(MagneticsTableLayout1, MagneticsUnloadingFields)>(payload)
                {
                    return Ok((Self::from_layout2(&old, &u), 2));
                }
                match decode_payload::<MagneticsTableLayout1>(payload) {
                    Ok(old) => Ok((Self::from_layout1(&old), 1)),
                    Err(_) => Err(e),
                }
            }
        }
    }

    /// A table of layout 2 (fields 0–23): the wheel fields 24–25 take their boot values.
    /// docs/tables.md (Table 6, "layouts").
    #[must_use]
    pub fn from_layout2(old: &MagneticsTableLayout1, u: &MagneticsUnloadingFields) -> Self {
        Self {
            unloading_gain_per_s: u.unloading_gain_per_s,
            torquer_dipole_limit_am2: u.torquer_dipole_limit_am2,
            unloading_start_nms: u.unloading_start_nms,
            unloading_stop_nms: u.unloading_stop_nms,
            torquer_check_milligauss: u.torquer_check_milligauss,
            ..Self::from_layout1(old)
        }
    }

    /// A table of layout 1 (fields 0–18): the unloading fields 19–23 take their boot values.
    /// docs/tables.md (Table 6, "layouts").
    #[must_use]
    pub fn from_layout1(old: &MagneticsTableLayout1) -> Self {
        Self {
            field_degree: old.field_degree,
            field_epoch_s_since_j2000_tt: old.field_epoch_s_since_j2000_tt,
            g_nt: old.g_nt,
            h_nt: old.h_nt,
            g_nt_per_year: old.g_nt_per_year,
            h_nt_per_year: old.h_nt_per_year,
            m_tod_from_eci: old.m_tod_from_eci,
            ut1_minus_tai_s: old.ut1_minus_tai_s,
            equation_of_equinoxes_rad: old.equation_of_equinoxes_rad,
            m_acs_from_tam: old.m_acs_from_tam,
            tam_milligauss_per_count: old.tam_milligauss_per_count,
            tam_bias_milligauss: old.tam_bias_milligauss,
            field_sigma_milligauss: old.field_sigma_milligauss,
            fss_sun_sigma_rad: old.fss_sun_sigma_rad,
            css_normals_acs: old.css_normals_acs,
            css_counts_at_normal_incidence: old.css_counts_at_normal_incidence,
            css_sun_sigma_rad: old.css_sun_sigma_rad,
            coarse_fix_every_n_cycles: old.coarse_fix_every_n_cycles,
            min_sun_field_angle_rad: old.min_sun_field_angle_rad,
            ..Self::boot()
        }
    }

    /// Whether the table asks for momentum unloading (a positive gain and dipole limit).
    /// docs/tables.md (Table 6, fields 19–20).
    #[must_use]
    pub fn unloading_enabled(&self) -> bool {
        self.unloading_gain_per_s > 0.0 && self.torquer_dipole_limit_am2 > 0.0
    }

    /// Whether the table gives a wheel geometry (any spin axis not zero): the OBC then takes
    /// the wheel momentum from the tachometers.
    /// docs/tables.md (Table 6, field 24).
    #[must_use]
    pub fn has_wheel_geometry(&self) -> bool {
        self.wheel_spin_axes_acs
            .iter()
            .any(|a| a.iter().any(|x| *x != 0.0))
    }

    /// Whether the table holds a field model (coarse attitude possible).
    /// docs/tables.md (Table 6, field 0).
    #[must_use]
    pub fn has_field_model(&self) -> bool {
        self.field_degree > 0
    }

    /// Content checks. Fields numbered as in docs/tables.md (Table 6).
    /// docs/tables.md (Table 6: ranges).
    ///
    /// # Errors
    /// The first failed check: [`TableError::NotFinite`] or [`TableError::OutOfRange`] with
    /// the field number.
    pub fn validate(&self) -> Result<(), TableError> {
        /// ±50 Julian years of J2000, s.
        const MAX_EPOCH_S: f64 = 50.0 * 365.25 * 86_400.0;
        /// Largest Gauss coefficient magnitude, nT (g10 is about −30,000 nT).
        const MAX_COEFFICIENT_NT: f64 = 100_000.0;
        /// Largest secular variation, nT/yr.
        const MAX_SV_NT_PER_YEAR: f64 = 1_000.0;
        if usize::from(self.field_degree) > FIELD_MAX_DEGREE {
            return Err(TableError::OutOfRange { field: 0 });
        }
        check_range(
            self.field_epoch_s_since_j2000_tt,
            -MAX_EPOCH_S,
            MAX_EPOCH_S,
            1,
        )?;
        let rows = [
            (&self.g_nt, MAX_COEFFICIENT_NT, 2u8),
            (&self.h_nt, MAX_COEFFICIENT_NT, 3),
            (&self.g_nt_per_year, MAX_SV_NT_PER_YEAR, 4),
            (&self.h_nt_per_year, MAX_SV_NT_PER_YEAR, 5),
        ];
        for (c, limit, field) in rows {
            for row in c {
                check_finite(row, field)?;
                if row.iter().any(|x| x.abs() > limit) {
                    return Err(TableError::OutOfRange { field });
                }
            }
        }
        check_rotation(&self.m_tod_from_eci, 6)?;
        check_range(self.ut1_minus_tai_s, -100.0, 100.0, 7)?;
        check_range(self.equation_of_equinoxes_rad, -1e-4, 1e-4, 8)?;
        for m in &self.m_acs_from_tam {
            check_rotation(m, 9)?;
        }
        for s in self.tam_milligauss_per_count.iter().flatten() {
            check_range(*s, 1e-3, 10.0, 10)?;
        }
        for b in self.tam_bias_milligauss.iter().flatten() {
            check_range(*b, -100.0, 100.0, 11)?;
        }
        for s in self.field_sigma_milligauss {
            check_range(s, 1e-3, 100.0, 12)?;
        }
        check_range(self.fss_sun_sigma_rad, 1e-6, 0.2, 13)?;
        for n in &self.css_normals_acs {
            check_finite(n, 14)?;
            let norm2 = n.iter().map(|x| x * x).sum::<f64>();
            if !((0.999..=1.001).contains(&norm2)) {
                return Err(TableError::OutOfRange { field: 14 });
            }
        }
        check_range(self.css_counts_at_normal_incidence, 1.0, 65_535.0, 15)?;
        check_range(self.css_sun_sigma_rad, 1e-4, 0.5, 16)?;
        if self.coarse_fix_every_n_cycles == 0 {
            return Err(TableError::OutOfRange { field: 17 });
        }
        check_range(self.min_sun_field_angle_rad, 0.01, 1.5, 18)?;
        check_range(self.unloading_gain_per_s, 0.0, 0.1, 19)?;
        check_range(self.torquer_dipole_limit_am2, 0.0, 100_000.0, 20)?;
        check_range(self.unloading_start_nms, 0.0, 1_000.0, 21)?;
        check_range(self.unloading_stop_nms, 0.0, self.unloading_start_nms, 22)?;
        check_range(self.torquer_check_milligauss, 1.0, 500.0, 23)?;
        // The bars are off in the cycle before each TAM sample the OBC uses (the cycle before
        // a coarse fix): with a fix every cycle they could never be on.
        if self.unloading_enabled() && self.coarse_fix_every_n_cycles < 2 {
            return Err(TableError::OutOfRange { field: 17 });
        }
        self.validate_wheels()
    }

    /// Fields 24–25: each spin axis unit or zero (no wheel); the wheels present span 3-D
    /// (else part of the momentum is invisible to the tachometers); a plausible inertia.
    fn validate_wheels(&self) -> Result<(), TableError> {
        let mut gram = Matrix3::zeros();
        for a in &self.wheel_spin_axes_acs {
            check_finite(a, 24)?;
            let norm2 = a.iter().map(|x| x * x).sum::<f64>();
            if norm2 == 0.0 {
                continue;
            }
            if !((0.999..=1.001).contains(&norm2)) {
                return Err(TableError::OutOfRange { field: 24 });
            }
            let v = nalgebra::Vector3::new(a[0], a[1], a[2]);
            gram += v * v.transpose();
        }
        // det(Σ a aᵀ) > 0.01: well clear of wheels in one plane (0 there); three
        // orthogonal wheels give 1.
        if self.has_wheel_geometry() && gram.determinant() < 0.01 {
            return Err(TableError::OutOfRange { field: 24 });
        }
        check_range(self.wheel_spin_inertia_kg_m2, 1e-3, 100.0, 25)
    }
}

fn check_rotation(m: &Mat3Rows, field: u8) -> Result<(), TableError> {
    if !all_finite(m) {
        return Err(TableError::NotFinite { field });
    }
    if is_proper_rotation(&matrix_from_rows(m), super::types::ROTATION_TOLERANCE) {
        Ok(())
    } else {
        Err(TableError::OutOfRange { field })
    }
}

/// `M` of a table's rows (for callers outside the tables module).
/// docs/tables.md (Table 6, fields 6 and 9).
#[must_use]
pub fn matrix(m: &Mat3Rows) -> Matrix3<f64> {
    matrix_from_rows(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn boot_validates_and_holds_no_field() {
        let t = MagneticsTable::boot();
        assert_eq!(t.validate(), Ok(()));
        assert!(!t.has_field_model());
    }

    #[test]
    fn each_bad_field_is_named() {
        let mut t = MagneticsTable::boot();
        t.field_degree = 11;
        assert_eq!(t.validate(), Err(TableError::OutOfRange { field: 0 }));
        let mut t = MagneticsTable::boot();
        t.g_nt[1][0] = f64::NAN;
        assert_eq!(t.validate(), Err(TableError::NotFinite { field: 2 }));
        let mut t = MagneticsTable::boot();
        t.m_acs_from_tam[1][0][0] = -1.0;
        assert_eq!(t.validate(), Err(TableError::OutOfRange { field: 9 }));
        let mut t = MagneticsTable::boot();
        t.css_normals_acs[2] = [0.0, 2.0, 0.0];
        assert_eq!(t.validate(), Err(TableError::OutOfRange { field: 14 }));
        let mut t = MagneticsTable::boot();
        t.coarse_fix_every_n_cycles = 0;
        assert_eq!(t.validate(), Err(TableError::OutOfRange { field: 17 }));
        let mut t = MagneticsTable::boot();
        t.coarse_fix_every_n_cycles = 1;
        assert_eq!(t.validate(), Err(TableError::OutOfRange { field: 17 }));
        t.unloading_gain_per_s = 0.0;
        assert_eq!(
            t.validate(),
            Ok(()),
            "a fix every cycle is fine without unloading"
        );
        let mut t = MagneticsTable::boot();
        t.unloading_gain_per_s = f64::NAN;
        assert_eq!(t.validate(), Err(TableError::NotFinite { field: 19 }));
        let mut t = MagneticsTable::boot();
        t.torquer_dipole_limit_am2 = -1.0;
        assert_eq!(t.validate(), Err(TableError::OutOfRange { field: 20 }));
        let mut t = MagneticsTable::boot();
        t.unloading_stop_nms = t.unloading_start_nms + 1.0;
        assert_eq!(t.validate(), Err(TableError::OutOfRange { field: 22 }));
        let mut t = MagneticsTable::boot();
        t.torquer_check_milligauss = 0.5;
        assert_eq!(t.validate(), Err(TableError::OutOfRange { field: 23 }));
        let mut t = MagneticsTable::boot();
        t.wheel_spin_axes_acs[3] = [0.5, 0.5, 0.5];
        assert_eq!(t.validate(), Err(TableError::OutOfRange { field: 24 }));
        let mut t = MagneticsTable::boot();
        t.wheel_spin_axes_acs = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0; 3], [0.0; 3]];
        assert_eq!(
            t.validate(),
            Err(TableError::OutOfRange { field: 24 }),
            "two wheels cannot see the momentum along z"
        );
        t.wheel_spin_axes_acs = [[0.0; 3]; WHEELS];
        assert_eq!(t.validate(), Ok(()), "no geometry: the command count");
        assert!(!t.has_wheel_geometry());
        let mut t = MagneticsTable::boot();
        t.wheel_spin_inertia_kg_m2 = 0.0;
        assert_eq!(t.validate(), Err(TableError::OutOfRange { field: 25 }));
        assert!(MagneticsTable::boot().has_wheel_geometry());
    }
}
