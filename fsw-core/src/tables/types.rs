//! # The four uplinkable tables and their validation
//!
//! Field lists and units are the contract with the ground tool (`docs/tables.md`). Every table
//! has a `validate()` that the OBC runs on load and the ground tool runs before writing an
//! image, so a table the core cannot use is never produced nor accepted.
//!
//! Matrices are stored row-major as `[[f64; 3]; 3]` (`m[row][col]`), as in the paper.

use super::error::TableError;
use crate::attitude::{is_proper_rotation, rot, rotvec_from_rot};
use crate::sensor::SensorId;
use crate::units::{ARCSEC_PER_RAD, RAD_PER_DEG};
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// Row-major 3×3 matrix as stored in tables.
/// The paper prints matrices row-major, `m[row][col]` (docs/tables.md).
pub type Mat3Rows = [[f64; 3]; 3];

/// Tolerance on orthonormality and determinant of alignment matrices (issue TBL-005).
/// docs/tables.md (Table 1: alignment, "orthonormal to 1e-6, det +1"); the paper's Table 1 rows
/// meet it.
pub const ROTATION_TOLERANCE: f64 = 1.0e-6;

/// Convert stored rows to a nalgebra matrix.
/// docs/tables.md (row-major storage, as the paper prints them).
#[must_use]
pub fn matrix_from_rows(m: &Mat3Rows) -> Matrix3<f64> {
    let [r0, r1, r2] = m;
    Matrix3::new(
        r0[0], r0[1], r0[2], r1[0], r1[1], r1[2], r2[0], r2[1], r2[2],
    )
}

/// Convert a nalgebra matrix to stored rows.
/// docs/tables.md (row-major storage, as the paper prints them).
#[must_use]
pub fn rows_from_matrix(m: &Matrix3<f64>) -> Mat3Rows {
    [
        [m.m11, m.m12, m.m13],
        [m.m21, m.m22, m.m23],
        [m.m31, m.m32, m.m33],
    ]
}

pub(crate) fn all_finite(m: &Mat3Rows) -> bool {
    m.iter().flatten().all(|x| x.is_finite())
}

pub(crate) fn check_finite(values: &[f64], field: u8) -> Result<(), TableError> {
    if values.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(TableError::NotFinite { field })
    }
}

pub(crate) fn check_range(value: f64, lo: f64, hi: f64, field: u8) -> Result<(), TableError> {
    if !value.is_finite() {
        return Err(TableError::NotFinite { field });
    }
    if (lo..=hi).contains(&value) {
        Ok(())
    } else {
        Err(TableError::OutOfRange { field })
    }
}

// ------------------------------------------------------------------------------------------
// Alignment table
// ------------------------------------------------------------------------------------------

/// Corrections for effects beyond a rigid alignment, applied by the OBC when non-zero
/// (issue 5: effects found on the ground become table data). All default to zero (off).
/// docs/tables.md (Table 1: alignment, fields 4–11); effects 1, 2, 4, 5, 15 of algorithms.md §9.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SensorCorrections {
    /// Time-tag offset per sensor (FHST1, FHST2, FSS1, FSS2), s: the measurement refers to
    /// `frame time − offset`. Range ±2 s.
    /// docs/tables.md (field 4); latency effect 1 of algorithms.md §9.
    pub time_offset_s: [f64; 4],
    /// FHST focal-plane distortion per tracker, rad: the true angles are
    /// `H = H_m − (d0 ρ² H_m + d1 H_m V_m)`, `V = V_m − (d0 ρ² V_m + d2 H_m V_m)` with
    /// `ρ² = H_m² + V_m²` (angles in rad; d0 in rad⁻², d1 and d2 in rad⁻¹). Range |d| ≤ 1.
    /// docs/tables.md (field 5); distortion effect 4 of algorithms.md §9.
    pub fhst_distortion: [[f64; 3]; 2],
    /// FSS transfer-function correction per sensor: the true head angles are
    /// `α = α_m − (c0 α_m + c1 α_m β_m² + c2)`, `β = β_m − (c3 β_m + c4 β_m α_m² + c5)`
    /// (rad; c0, c3 unitless scale errors, c1, c4 rad⁻², c2, c5 rad offsets). Range |c| ≤ 1.
    /// docs/tables.md (field 6); transfer-function errors of algorithms.md §4.
    pub fss_transfer: [[f64; 6]; 2],
    /// FHST magnitude-dependent bias per tracker `[b_H, b_V]`, rad per magnitude: after the
    /// distortion correction `H −= b_H (m − 4)`, `V −= b_V (m − 4)`, `m` the sample's
    /// instrument magnitude ([`FHST_MAGNITUDE_BIAS_REFERENCE_MAG`] = 4). Range |b| ≤ 1e-3.
    /// docs/tables.md (field 7); magnitude-dependent FHST error, effect 5 of algorithms.md §9.
    pub fhst_magnitude_bias_rad_per_mag: [[f64; 2]; 2],
    /// Thermal alignment drift per sensor (FHST1, FHST2, FSS1, FSS2): rotation vector per °C,
    /// ACS axes, rad/°C; the OBC uses `M_AS(T) = Rot(k (T − T_ref)) M_AS` with `T` the
    /// sensor's temperature of the raw frame (docs/icd.md §3.1), `T − T_ref` clamped to
    /// ±[`THERMAL_MAX_DEVIATION_C`]. Range |k| ≤ 1e-3.
    /// docs/tables.md (field 8); thermal alignment drift, effect 2 of algorithms.md §9.
    pub thermal_alignment_rad_per_c: [[f64; 3]; 4],
    /// Reference temperature `T_ref` of the thermal drift per sensor, °C, −100..=150.
    /// docs/tables.md (field 9); project choice: the mean temperature of the calibration data.
    pub thermal_reference_c: [f64; 4],
    /// FSS cubic transfer-function term per sensor `[k_α, k_β]`, rad⁻²: after the
    /// [`Self::fss_transfer`] correction `α −= k_α α_m³`, `β −= k_β β_m³`. Range |k| ≤ 1.
    /// docs/tables.md (field 10); edge growth of the transfer function, algorithms.md §4 and
    /// effect 15 of §9.
    pub fss_cubic: [[f64; 2]; 2],
    /// FSS cyclic (reticle-pitch) transfer-function term per sensor
    /// `[p, s_α, c_α, s_β, c_β]`: `α −= s_α sin(2π α_m/p) + c_α cos(2π α_m/p)`, the same for β
    /// with `s_β, c_β`; `p` the pitch in rad (0 = off, else 1e-3..=1.2), amplitudes in rad,
    /// |·| ≤ 1e-3.
    /// docs/tables.md (field 11); cyclic reticle error, effect 15 of algorithms.md §9.
    pub fss_cyclic: [[f64; 5]; 2],
}

/// Reference magnitude of [`SensorCorrections::fhst_magnitude_bias_rad_per_mag`], mag.
/// docs/tables.md (field 7); project choice: mid-window of the paper's FHST range 2.0–5.7.
pub const FHST_MAGNITUDE_BIAS_REFERENCE_MAG: f64 = 4.0;

/// Largest temperature deviation `|T − T_ref|` the thermal drift correction uses, °C: a
/// reading further off is clamped (a failed thermistor must not rotate a sensor by more than
/// `k · 50 °C`).
/// docs/tables.md (field 8); project choice (not in the paper).
pub const THERMAL_MAX_DEVIATION_C: f64 = 50.0;

impl SensorCorrections {
    /// Thermal rotation vector `k (T − T_ref)` (rad, ACS) of `sensor` at temperature
    /// `temperature_c`; zero when the sensor has no thermal coefficient or the temperature is
    /// not finite.
    /// docs/tables.md (fields 8–9); effect 2 of algorithms.md §9.
    #[must_use]
    pub fn thermal_rotation_rad(&self, sensor: SensorId, temperature_c: f64) -> Vector3<f64> {
        let (Some(k), Some(t_ref)) = (
            self.thermal_alignment_rad_per_c.get(sensor.index()),
            self.thermal_reference_c.get(sensor.index()),
        ) else {
            return Vector3::zeros();
        };
        let [kx, ky, kz] = *k;
        if (kx == 0.0 && ky == 0.0 && kz == 0.0) || !temperature_c.is_finite() {
            return Vector3::zeros();
        }
        let dt = (temperature_c - t_ref).clamp(-THERMAL_MAX_DEVIATION_C, THERMAL_MAX_DEVIATION_C);
        Vector3::from(*k) * dt
    }
}

/// Sensor alignments `M_AS` (paper Table 1 / Table 3), sensor → ACS, columns = sensor axes.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AlignmentTable {
    /// `M_AS` of FHST1 (unitless, proper rotation).
    /// Paper Table 1 (prelaunch) at boot, Table 3 after calibration; docs/tables.md field 0.
    pub m_acs_from_fhst1: Mat3Rows,
    /// `M_AS` of FHST2.
    /// Paper Table 1 / Table 3; docs/tables.md field 1.
    pub m_acs_from_fhst2: Mat3Rows,
    /// `M_AS` of FSS1.
    /// Paper Table 1 (Table 3's FSS rows are illegible: Table 1 × Table 2); docs/tables.md field 2.
    pub m_acs_from_fss1: Mat3Rows,
    /// `M_AS` of FSS2.
    /// Paper Table 1 (Table 3's FSS rows are illegible: Table 1 × Table 2); docs/tables.md field 3.
    pub m_acs_from_fss2: Mat3Rows,
    /// Corrections for non-rigid effects (zero = off).
    /// docs/tables.md (fields 4–6); project choice (not in the paper): zero at boot.
    pub corrections: SensorCorrections,
}

/// `Rot(θ) M` as rows (the thermal drift's rotation, kept out of line: most sensors have none).
#[cold]
#[inline(never)]
fn drifted_rows(rows: &Mat3Rows, theta_rad: &Vector3<f64>) -> Mat3Rows {
    rows_from_matrix(&(rot(theta_rad) * matrix_from_rows(rows)))
}

impl AlignmentTable {
    /// The four alignment matrices in sensor order FHST1, FHST2, FSS1, FSS2.
    /// docs/tables.md (fields 0–3 in this order).
    #[must_use]
    pub fn matrices(&self) -> [&Mat3Rows; 4] {
        [
            &self.m_acs_from_fhst1,
            &self.m_acs_from_fhst2,
            &self.m_acs_from_fss1,
            &self.m_acs_from_fss2,
        ]
    }

    /// The stored alignment `M_AS` of `sensor` (table rows).
    /// docs/tables.md (fields 0–3).
    #[must_use]
    pub const fn rows(&self, sensor: SensorId) -> &Mat3Rows {
        match sensor {
            SensorId::Fhst1 => &self.m_acs_from_fhst1,
            SensorId::Fhst2 => &self.m_acs_from_fhst2,
            SensorId::Fss1 => &self.m_acs_from_fss1,
            SensorId::Fss2 => &self.m_acs_from_fss2,
        }
    }

    /// The four alignment matrices, mutable, in the order of [`Self::matrices`].
    /// docs/tables.md (fields 0–3 in this order).
    pub fn matrices_mut(&mut self) -> [&mut Mat3Rows; 4] {
        [
            &mut self.m_acs_from_fhst1,
            &mut self.m_acs_from_fhst2,
            &mut self.m_acs_from_fss1,
            &mut self.m_acs_from_fss2,
        ]
    }

    /// The paper's prelaunch alignments (Table 1), the boot table.
    #[must_use]
    pub fn prelaunch() -> Self {
        Self {
            m_acs_from_fhst1: [
                [-0.707293868, 0.000641730, -0.706919372],
                [-0.706919611, -0.000965840, 0.707293212],
                [-0.000228880, 0.999999344, 0.001136780],
            ],
            m_acs_from_fhst2: [
                [-0.706911922, -0.000668710, -0.707301319],
                [0.707300782, 0.000884930, -0.706912220],
                [0.001098630, -0.999999404, -0.000152590],
            ],
            m_acs_from_fss1: [
                [0.003753100, -0.865531862, 0.500839829],
                [0.999986291, 0.001422380, -0.005035412],
                [0.003645920, 0.500851870, 0.865525305],
            ],
            m_acs_from_fss2: [
                [0.000871080, 0.034161031, 0.999415934],
                [0.999991417, -0.004071418, -0.000732420],
                [0.004044019, 0.999408066, -0.034164291],
            ],
            corrections: SensorCorrections::default(),
        }
    }

    /// `M_AS` of `sensor` at the sensor temperature `temperature_c`: `Rot(k (T − T_ref))
    /// M_AS` with the table's thermal drift ([`SensorCorrections::thermal_rotation_rad`]), the
    /// stored rows unchanged when the sensor has no thermal coefficient.
    /// docs/tables.md (fields 0–3, 8–9); paper `M_AS`; effect 2 of algorithms.md §9.
    #[must_use]
    pub fn m_acs_from_sensor_rows_at(&self, sensor: SensorId, temperature_c: f64) -> Mat3Rows {
        self.drifted_rows_at(sensor, temperature_c)
            .unwrap_or_else(|| *self.rows(sensor))
    }

    /// `Some(Rot(k (T − T_ref)) M_AS)` for a sensor with a thermal drift coefficient (as
    /// [`Self::m_acs_from_sensor_rows_at`]), `None` for one without (the stored rows apply):
    /// the common case costs one look-up and three compares, and no copy.
    /// docs/tables.md (fields 8–9); effect 2 of algorithms.md §9.
    #[must_use]
    #[inline]
    pub fn drifted_rows_at(&self, sensor: SensorId, temperature_c: f64) -> Option<Mat3Rows> {
        match self
            .corrections
            .thermal_alignment_rad_per_c
            .get(sensor.index())
        {
            Some([kx, ky, kz]) if *kx != 0.0 || *ky != 0.0 || *kz != 0.0 => Some(drifted_rows(
                self.rows(sensor),
                &self.corrections.thermal_rotation_rad(sensor, temperature_c),
            )),
            _ => None,
        }
    }

    /// Content checks: finite, proper rotations, corrections in range.
    /// docs/tables.md (Table 1: alignment, ranges).
    ///
    /// Field numbers: 0–3 the matrices, 4 time offsets, 5 FHST distortion, 6 FSS transfer,
    /// 7 FHST magnitude bias, 8 thermal coefficients, 9 thermal reference temperatures,
    /// 10 FSS cubic terms, 11 FSS cyclic terms.
    ///
    /// # Errors
    /// The first failed check.
    pub fn validate(&self) -> Result<(), TableError> {
        for (sensor, m) in (0u8..).zip(self.matrices()) {
            if !all_finite(m) {
                return Err(TableError::NotFinite { field: sensor });
            }
            if !is_proper_rotation(&matrix_from_rows(m), ROTATION_TOLERANCE) {
                return Err(TableError::NotRotation { sensor });
            }
        }
        let c = &self.corrections;
        check_finite(&c.time_offset_s, 4)?;
        for t in c.time_offset_s {
            check_range(t, -2.0, 2.0, 4)?;
        }
        for d in c.fhst_distortion.iter().flatten() {
            check_range(*d, -1.0, 1.0, 5)?;
        }
        for k in c.fss_transfer.iter().flatten() {
            check_range(*k, -1.0, 1.0, 6)?;
        }
        for b in c.fhst_magnitude_bias_rad_per_mag.iter().flatten() {
            check_range(*b, -1.0e-3, 1.0e-3, 7)?;
        }
        for k in c.thermal_alignment_rad_per_c.iter().flatten() {
            check_range(*k, -1.0e-3, 1.0e-3, 8)?;
        }
        for t in c.thermal_reference_c {
            check_range(t, -100.0, 150.0, 9)?;
        }
        for k in c.fss_cubic.iter().flatten() {
            check_range(*k, -1.0, 1.0, 10)?;
        }
        for [pitch, amplitudes @ ..] in c.fss_cyclic {
            if pitch != 0.0 {
                check_range(pitch, 1.0e-3, 1.2, 11)?;
            }
            for a in amplitudes {
                check_range(a, -1.0e-3, 1.0e-3, 11)?;
            }
        }
        Ok(())
    }

    /// Largest rotation (arcsec) between this table's alignments and `other`'s, and the
    /// index of the sensor where it occurs.
    /// As the magnitudes of the paper's published rotation vectors; `rotvec` of algorithms.md §1.
    #[must_use]
    pub fn max_rotation_from_arcsec(&self, other: &AlignmentTable) -> (f64, u8) {
        let mut worst = (0.0, 0u8);
        for (i, (a, b)) in (0u8..).zip(self.matrices().into_iter().zip(other.matrices())) {
            let r = matrix_from_rows(a) * matrix_from_rows(b).transpose();
            let angle = rotvec_from_rot(&r).norm() * ARCSEC_PER_RAD;
            if !(angle <= worst.0) {
                worst = (angle, i);
            }
        }
        worst
    }
}

// ------------------------------------------------------------------------------------------
// IRU table
// ------------------------------------------------------------------------------------------

/// DRIRU II calibration (paper: `G`; algorithms.md §5):
/// `Δθ_acs = G · diag(k_i (1 − a_i sgn ΔN_i)) · w · ΔN` for the three selected channels in
/// X, Y, Z order, `w` the pulse weight of the rate mode, `a` the scale-factor asymmetry.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct IruTable {
    /// G of the primary configuration (X2, Y1, Z1), unitless, non-orthogonal.
    /// Paper: prelaunch `G` (used by OBC and ground); docs/tables.md (Table 2: IRU) field 0.
    pub g_primary: Mat3Rows,
    /// G of the backup configuration (X1, Y2, Z2).
    /// Paper: primary/backup configurations; the paper publishes one `G`; docs/tables.md field 1.
    pub g_backup: Mat3Rows,
    /// Scale factors k of the primary channels (X2, Y1, Z1), unitless, near 1.
    /// docs/tables.md field 2; project choice (not in the paper): 1 at boot.
    pub scale_factor_primary: [f64; 3],
    /// Scale factors k of the backup channels (X1, Y2, Z2).
    /// docs/tables.md field 3; project choice (not in the paper): 1 at boot.
    pub scale_factor_backup: [f64; 3],
    /// Low-rate pulse weight, arcsec per pulse (0.05 on GRO).
    /// Paper: DRIRU II low rate 0.05″/pulse; docs/tables.md field 4.
    pub low_rate_arcsec_per_pulse: f64,
    /// High-rate pulse weight, arcsec per pulse (0.8 on GRO).
    /// Paper: DRIRU II high rate 0.8″/pulse; docs/tables.md field 5.
    pub high_rate_arcsec_per_pulse: f64,
    /// A channel whose count changes by more than this in one cycle is flagged saturated.
    /// docs/tables.md field 6; project choice (not in the paper).
    pub saturation_pulses_per_cycle: u16,
    /// A channel whose count does not change for this many cycles is flagged stuck.
    /// docs/tables.md field 7; project choice (not in the paper).
    pub stuck_cycles: u16,
    /// Scale-factor asymmetry `a` of the primary channels (X2, Y1, Z1), unitless: a channel
    /// that reads `1 + a` times the true angle for positive rates and `1 − a` for negative
    /// ones over-reads by `a |Δθ|` both ways; the OBC scales each count difference by
    /// `1 − a sgn ΔN`. Range |a| ≤ 0.01; 0 at boot (off).
    /// docs/tables.md field 8; gyro scale asymmetry, effect 9 of algorithms.md §9.
    pub scale_asymmetry_primary: [f64; 3],
    /// Scale-factor asymmetry of the backup channels (X1, Y2, Z2), as
    /// [`Self::scale_asymmetry_primary`].
    /// docs/tables.md field 9; effect 9 of algorithms.md §9.
    pub scale_asymmetry_backup: [f64; 3],
}

impl IruTable {
    /// The prelaunch G of the paper (used for both configurations: the paper publishes one),
    /// unit scale factors, GRO pulse weights; the boot table.
    #[must_use]
    pub fn prelaunch() -> Self {
        let g = [
            [1.00000, 0.00108, 0.00079],
            [-0.00100, 1.00000, -0.00156],
            [-0.00056, 0.00128, 1.00000],
        ];
        Self {
            g_primary: g,
            g_backup: g,
            scale_factor_primary: [1.0; 3],
            scale_factor_backup: [1.0; 3],
            low_rate_arcsec_per_pulse: 0.05,
            high_rate_arcsec_per_pulse: 0.8,
            saturation_pulses_per_cycle: 30_000,
            stuck_cycles: 120,
            scale_asymmetry_primary: [0.0; 3],
            scale_asymmetry_backup: [0.0; 3],
        }
    }

    /// Content checks. Fields: 0 g_primary, 1 g_backup, 2/3 scale factors, 4/5 pulse weights,
    /// 6 saturation, 7 stuck cycles, 8/9 scale asymmetries.
    /// docs/tables.md (Table 2: IRU, ranges).
    ///
    /// # Errors
    /// The first failed check.
    pub fn validate(&self) -> Result<(), TableError> {
        for (field, g) in [(0u8, &self.g_primary), (1u8, &self.g_backup)] {
            if !all_finite(g) {
                return Err(TableError::NotFinite { field });
            }
            // Within 5 % of the identity element-wise: a gross error, not a calibration.
            let m = matrix_from_rows(g) - Matrix3::identity();
            if m.iter().any(|x| x.abs() > 0.05) {
                return Err(TableError::OutOfRange { field });
            }
        }
        for (field, k) in [
            (2u8, &self.scale_factor_primary),
            (3u8, &self.scale_factor_backup),
        ] {
            for v in k {
                check_range(*v, 0.95, 1.05, field)?;
            }
        }
        check_range(self.low_rate_arcsec_per_pulse, 1e-3, 10.0, 4)?;
        check_range(self.high_rate_arcsec_per_pulse, 1e-3, 10.0, 5)?;
        if self.saturation_pulses_per_cycle == 0 || self.saturation_pulses_per_cycle > 32_000 {
            return Err(TableError::OutOfRange { field: 6 });
        }
        if self.stuck_cycles < 2 {
            return Err(TableError::OutOfRange { field: 7 });
        }
        for (field, a) in [
            (8u8, &self.scale_asymmetry_primary),
            (9u8, &self.scale_asymmetry_backup),
        ] {
            for v in a {
                check_range(*v, -0.01, 0.01, field)?;
            }
        }
        Ok(())
    }

    /// Largest element change of G, k or the scale asymmetries (ppm) against another table,
    /// both configurations.
    /// docs/tables.md (`max_iru_change_ppm`).
    #[must_use]
    pub fn max_g_change_ppm(&self, other: &IruTable) -> f64 {
        let a = matrix_from_rows(&self.g_primary) - matrix_from_rows(&other.g_primary);
        let b = matrix_from_rows(&self.g_backup) - matrix_from_rows(&other.g_backup);
        let mut worst = 0.0_f64;
        for x in a.iter().chain(b.iter()) {
            worst = worst.max(x.abs() * 1.0e6);
        }
        for (x, y) in self
            .scale_factor_primary
            .iter()
            .chain(self.scale_factor_backup.iter())
            .zip(
                other
                    .scale_factor_primary
                    .iter()
                    .chain(other.scale_factor_backup.iter()),
            )
        {
            worst = worst.max((x - y).abs() * 1.0e6);
        }
        for (x, y) in self
            .scale_asymmetry_primary
            .iter()
            .chain(self.scale_asymmetry_backup.iter())
            .zip(
                other
                    .scale_asymmetry_primary
                    .iter()
                    .chain(other.scale_asymmetry_backup.iter()),
            )
        {
            worst = worst.max((x - y).abs() * 1.0e6);
        }
        worst
    }
}

// ------------------------------------------------------------------------------------------
// Filter table
// ------------------------------------------------------------------------------------------

/// RMS per focal-plane axis of the orbital velocity aberration, arcsec: `β = 7.5 km/s / c`
/// = 5.16″ turning once per orbit in the orbit plane gives `E[(β·e)²] ≤ β²/2` on any axis
/// `e`, i.e. at most `β/√2` = 3.65″ (derivation in docs/obc_filter.md §3). The boot
/// [`FilterTable::fhst_uncorrected_systematic_arcsec`], and what the OBC adds back while the
/// orbital correction is requested but the onboard orbit is not valid.
/// algorithms.md §3.3 ("LEO orbital ≤ 5.2″"); docs/obc_filter.md §3.
pub const ORBITAL_ABERRATION_RMS_PER_AXIS_ARCSEC: f64 = 3.65;

/// What the orbital aberration leaves per focal-plane axis with the onboard correction on,
/// arcsec: the onboard orbit's velocity error over a day ((12.4 + 15 + 1) m/s) over `c`
/// (docs/obc_filter.md §8). The recommended
/// [`FilterTable::fhst_uncorrected_systematic_arcsec`] with
/// [`FilterTable::orbital_aberration_correction`] on, before any alignment term.
pub const ORBITAL_ABERRATION_RESIDUAL_CORRECTED_ARCSEC: f64 = 0.02;

/// Kalman filter, star identification and attitude control settings.
/// docs/tables.md (Table 3: filter); mostly project choices, sources per field.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FilterTable {
    /// Cycle period of the executive, s (0.125 ..= 2.0).
    /// docs/tables.md field 0; project choice (not in the paper).
    pub cycle_period_s: f64,
    /// Gyro angle random walk σ_v, rad/s^½ (Farrenkopf).
    pub arw_rad_per_sqrt_s: f64,
    /// Gyro rate random walk σ_u, rad/s^3/2 (Farrenkopf).
    pub rrw_rad_per_s_sqrt_s: f64,
    /// FHST measurement σ for a magnitude-2.0 star, arcsec per axis.
    /// Paper: FHST random error 8–24″ 1σ (boot 8); docs/tables.md field 3.
    pub fhst_sigma_bright_arcsec: f64,
    /// FHST measurement σ for a magnitude-5.7 star, arcsec per axis (linear in between).
    /// Paper: FHST random error 8–24″ 1σ (boot 24); docs/tables.md field 4.
    pub fhst_sigma_faint_arcsec: f64,
    /// FSS measurement σ per axis, arcsec (includes its transfer-function error).
    /// Paper: FSS calibrated accuracy 0.02°, inherent error 0.022° (boot 60″); docs/tables.md
    /// field 5.
    pub fss_sigma_arcsec: f64,
    /// χ² gate on the 2-component innovation (11.83 = 99.73 %).
    /// χ² with 2 degrees of freedom (algorithms.md §2 gating); docs/tables.md field 6.
    pub gate_chi2: f64,
    /// Initial attitude σ per axis after an initialisation, rad.
    /// docs/tables.md field 7; the paper's 0.5° post-maneuver requirement sits inside the 1° boot
    /// value.
    pub initial_attitude_sigma_rad: f64,
    /// Initial bias σ per axis, rad/s.
    /// docs/tables.md field 8; project choice (not in the paper).
    pub initial_bias_sigma_rad_per_s: f64,
    /// Star identification: the widest catalog match window, arcsec (≥ the 0.5° requirement);
    /// the window used is `5σ` of the predicted position error from the attitude covariance,
    /// between 120″ and this value (`star_id::StarIdWindow::from_covariance`, issue 19).
    /// Paper: post-maneuver error ≤ 0.5° so that the OBC can identify stars; docs/tables.md field
    /// 9.
    pub star_id_window_arcsec: f64,
    /// Star identification: magnitude tolerance, mag.
    /// algorithms.md §3.2 step 4 (Δm 0.5–1 mag); docs/tables.md field 10.
    pub star_id_magnitude_tolerance: f64,
    /// Apply annual velocity aberration to catalog stars (and the Sun) on board.
    /// algorithms.md §3.3; docs/tables.md field 11.
    pub aberration_correction: bool,
    /// Largest accepted change of any alignment per load, arcsec.
    /// docs/tables.md field 12; project choice: well above the paper's largest shift (FSS1, 733″).
    pub max_alignment_change_arcsec: f64,
    /// Largest accepted change of any G element or scale factor per load, ppm.
    /// docs/tables.md field 13; project choice (not in the paper).
    pub max_iru_change_ppm: f64,
    /// Slew rate limit, rad/s.
    /// docs/tables.md field 14; project choice (not in the paper).
    pub slew_rate_limit_rad_per_s: f64,
    /// Spacecraft inertia diagonal used by the control law, kg m².
    /// docs/tables.md field 15 (the harness spacecraft's values; the paper gives only 18 000 kg).
    pub inertia_kg_m2: [f64; 3],
    /// Control bandwidth (natural frequency), rad/s.
    /// docs/tables.md field 16; project choice (not in the paper).
    pub control_bandwidth_rad_per_s: f64,
    /// Control damping ratio.
    /// docs/tables.md field 17; project choice (not in the paper).
    pub control_damping: f64,
    /// Wheel torque command limit per axis, N m.
    /// docs/tables.md field 18; project choice (not in the paper).
    pub torque_limit_nm: f64,
    /// Attitude error below which a slew is complete and the IRU returns to low rate, rad.
    /// docs/tables.md field 19; paper: high rate only for maneuvers.
    pub slew_complete_rad: f64,
    /// Relative uncertainty of the gyro scale factors and misalignments (unitless, e.g. 1e-3
    /// before IRU calibration): during slews the attitude covariance grows coherently by this
    /// fraction of the angle turned, so that the filter accepts the post-maneuver star
    /// updates instead of gating them out.
    /// docs/tables.md field 20; effects 9–10 of algorithms.md §9 (gyro scale errors).
    pub gyro_scale_uncertainty: f64,
    /// Apply the orbital part of the velocity aberration to catalog stars and the Sun (the
    /// spacecraft's velocity from the onboard orbit, [`crate::orbit`]) and the Sun parallax
    /// (the Sun seen from the spacecraft, not from the geocentre). Independent of
    /// [`Self::aberration_correction`] (the annual part). When the onboard orbit is not valid
    /// the OBC applies the annual part only and says so (events 0x0801/0x0802). Boot false.
    /// algorithms.md §3.3 ("LEO orbital ≤ 5.2″", "Sun vector"); docs/tables.md field 21.
    pub orbital_aberration_correction: bool,
    /// Systematic FHST error per focal-plane axis that the OBC models but does not correct,
    /// arcsec (0..=60): the floor of the FHST updates and of the star-identification window
    /// (`Mekf::update_focal_plane_with_floor`). Boot 3.65 = `β_orbit/√2`, the uncorrected
    /// orbital aberration; with [`Self::orbital_aberration_correction`] on, what the onboard
    /// ephemerides leave (0.02, docs/obc_filter.md §3). While the orbital correction is
    /// requested but the orbit is not valid the OBC adds the 3.65″ back in quadrature.
    /// docs/tables.md field 22; docs/obc_filter.md §3 (derivation).
    pub fhst_uncorrected_systematic_arcsec: f64,
    /// 1σ of each element of the gyros' residual error `E` after calibration (unitless, each
    /// 0..=0.05; row = attitude-error axis, column = axis turned). When any element is
    /// non-zero a slew grows the attitude variance of axis `i` by `Σ_j E_ij² (a_j'² − a_j²)`,
    /// `a_j` the angle turned about ACS axis `j` since the slew began, instead of the
    /// isotropic [`Self::gyro_scale_uncertainty`] (which bounds every element and stays the
    /// prelaunch form). Boot: all zero.
    /// docs/tables.md field 23; docs/obc_filter.md §11 (the per-element slew term).
    pub gyro_calibration_sigma: [[f64; 3]; 3],
}

impl FilterTable {
    /// Boot settings (documented in `docs/tables.md`).
    #[must_use]
    pub fn default_boot() -> Self {
        Self {
            cycle_period_s: 1.0,
            // σ_v of the DRIRU II model, 0.003″/√s (docs/obc_filter.md §2).
            arw_rad_per_sqrt_s: 1.454e-8,
            // √(σ_u² + ṙ² T): the 0.0012″/s-in-6-h random walk (3.958e-11) and the early
            // bias transient at release (ṙ = 4.04e-12 rad/s², T = one orbit, 5,760 s),
            // docs/obc_filter.md §2.
            rrw_rad_per_s_sqrt_s: 3.1e-10,
            fhst_sigma_bright_arcsec: 8.0,
            fhst_sigma_faint_arcsec: 24.0,
            fss_sigma_arcsec: 60.0,
            gate_chi2: 11.83,
            initial_attitude_sigma_rad: 1.0 * RAD_PER_DEG,
            initial_bias_sigma_rad_per_s: 5.0e-6,
            star_id_window_arcsec: 0.6 * 3600.0,
            star_id_magnitude_tolerance: 0.6,
            aberration_correction: false,
            max_alignment_change_arcsec: 3600.0,
            max_iru_change_ppm: 20_000.0,
            slew_rate_limit_rad_per_s: 0.08 * RAD_PER_DEG,
            inertia_kg_m2: [1.10e5, 1.25e5, 1.70e5],
            control_bandwidth_rad_per_s: 0.05,
            control_damping: 0.9,
            torque_limit_nm: 0.5,
            slew_complete_rad: 0.05 * RAD_PER_DEG,
            gyro_scale_uncertainty: 1.0e-3,
            orbital_aberration_correction: false,
            fhst_uncorrected_systematic_arcsec: ORBITAL_ABERRATION_RMS_PER_AXIS_ARCSEC,
            gyro_calibration_sigma: [[0.0; 3]; 3],
        }
    }

    /// Content checks; field numbers are the declaration order 0..=23.
    /// docs/tables.md (Table 3: filter, ranges).
    ///
    /// # Errors
    /// The first failed check.
    pub fn validate(&self) -> Result<(), TableError> {
        check_range(self.cycle_period_s, 0.125, 2.0, 0)?;
        check_range(self.arw_rad_per_sqrt_s, 0.0, 1e-3, 1)?;
        check_range(self.rrw_rad_per_s_sqrt_s, 0.0, 1e-5, 2)?;
        check_range(self.fhst_sigma_bright_arcsec, 0.1, 3600.0, 3)?;
        check_range(self.fhst_sigma_faint_arcsec, 0.1, 3600.0, 4)?;
        check_range(self.fss_sigma_arcsec, 0.1, 36_000.0, 5)?;
        check_range(self.gate_chi2, 1.0, 1.0e6, 6)?;
        check_range(self.initial_attitude_sigma_rad, 1e-9, 4.0, 7)?;
        check_range(self.initial_bias_sigma_rad_per_s, 1e-12, 1e-2, 8)?;
        check_range(self.star_id_window_arcsec, 1.0, 7200.0, 9)?;
        check_range(self.star_id_magnitude_tolerance, 0.0, 5.0, 10)?;
        check_range(self.max_alignment_change_arcsec, 0.0, 36_000.0, 12)?;
        check_range(self.max_iru_change_ppm, 0.0, 100_000.0, 13)?;
        check_range(self.slew_rate_limit_rad_per_s, 1e-5, 0.1, 14)?;
        for i in self.inertia_kg_m2 {
            check_range(i, 1.0, 1.0e8, 15)?;
        }
        check_range(self.control_bandwidth_rad_per_s, 1e-4, 1.0, 16)?;
        check_range(self.control_damping, 0.1, 5.0, 17)?;
        check_range(self.torque_limit_nm, 1e-3, 100.0, 18)?;
        check_range(self.slew_complete_rad, 1e-6, 0.5, 19)?;
        check_range(self.gyro_scale_uncertainty, 0.0, 0.05, 20)?;
        check_range(self.fhst_uncorrected_systematic_arcsec, 0.0, 60.0, 22)?;
        for e in self.gyro_calibration_sigma.iter().flatten() {
            check_range(*e, 0.0, 0.05, 23)?;
        }
        Ok(())
    }

    /// FHST σ (rad) for a star of the given magnitude, clamped to the 2.0–5.7 window.
    /// Paper: FHST random error 8–24″ 1σ, magnitudes 2.0–5.7.
    ///
    /// Between the table's two end points the σ follows the photon-noise law of a centroid,
    /// `σ(m) = a + b · 10^{0.2 (m − 5.7)}` (σ ∝ flux^{−½} plus a floor), with `a`, `b` such that
    /// `σ(2.0)` = `fhst_sigma_bright_arcsec` and `σ(5.7)` = `fhst_sigma_faint_arcsec`: the law
    /// of the FHST model (`sim-harness` sensors/fhst.rs). The former linear interpolation
    /// overstated mid-range stars by up to 25 % (m = 4: 16.6″ against 13.4″).
    /// docs/obc_filter.md §3.
    #[must_use]
    pub fn fhst_sigma_rad(&self, magnitude: f64) -> f64 {
        /// `10^{0.2 (2.0 − 5.7)}`: the bright end's flux term relative to the faint end's.
        const BRIGHT_FLUX_TERM: f64 = 0.181_970_085_860_998_4;
        let m = magnitude.clamp(2.0, 5.7);
        let b = (self.fhst_sigma_faint_arcsec - self.fhst_sigma_bright_arcsec)
            / (1.0 - BRIGHT_FLUX_TERM);
        let a = self.fhst_sigma_faint_arcsec - b;
        let arcsec = a + b * libm::exp10(0.2 * (m - 5.7));
        arcsec / ARCSEC_PER_RAD
    }
}

// ------------------------------------------------------------------------------------------
// Star catalog table
// ------------------------------------------------------------------------------------------

/// Capacity of the onboard catalog (all Hipparcos stars of the FHST window fit: 3231 with
/// 2.0 ≤ Hp ≤ 5.7).
pub const MAX_CATALOG_STARS: usize = 4096;

/// One onboard catalog star.
/// docs/tables.md (Table 4: star catalog).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CatalogStar {
    /// Catalog number (HIP).
    /// docs/tables.md (Table 4); Hipparcos HIP number.
    pub id: u32,
    /// Unit direction in J2000/ICRS at the catalog epoch of the table (proper motion applied
    /// on the ground), `f32` (7e-8 rad resolution, 0.015 arcsec).
    /// docs/tables.md (Table 4).
    pub dir_eci: [f32; 3],
    /// Magnitude in the FHST's instrument system, 0.01 mag.
    /// docs/tables.md (Table 4); Hp-like instrument magnitude (docs/conventions.md).
    pub magnitude_centimag: i16,
}

impl CatalogStar {
    /// Direction as an `f64` vector.
    /// docs/tables.md (Table 4: `f32` storage, `f64` use).
    #[must_use]
    pub fn dir(&self) -> Vector3<f64> {
        let [x, y, z] = self.dir_eci;
        Vector3::new(f64::from(x), f64::from(y), f64::from(z))
    }
}

/// The onboard star catalog.
/// docs/tables.md (Table 4: star catalog); Hipparcos subset built on the ground.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StarCatalogTable {
    /// Catalog epoch (proper motion applied to it), years since J2000.0.
    /// docs/tables.md (Table 4); catalog error effect 6 of algorithms.md §9.
    pub epoch_years_since_j2000: f64,
    /// Stars, any order.
    /// docs/tables.md (Table 4, at most `MAX_CATALOG_STARS`).
    pub stars: heapless::Vec<CatalogStar, MAX_CATALOG_STARS>,
}

impl StarCatalogTable {
    /// Content checks: finite epoch within ±100 years, unit directions (±1e-6), magnitudes
    /// −2..=9. Fields: 0 epoch, 1 direction, 2 magnitude.
    /// docs/tables.md (Table 4: ranges).
    ///
    /// # Errors
    /// The first failed check.
    pub fn validate(&self) -> Result<(), TableError> {
        check_range(self.epoch_years_since_j2000, -100.0, 100.0, 0)?;
        for s in &self.stars {
            let n = s.dir().norm();
            if !n.is_finite() {
                return Err(TableError::NotFinite { field: 1 });
            }
            if (n - 1.0).abs() > 1.0e-6 {
                return Err(TableError::OutOfRange { field: 1 });
            }
            if !(-200..=900).contains(&s.magnitude_centimag) {
                return Err(TableError::OutOfRange { field: 2 });
            }
        }
        Ok(())
    }
}

// ------------------------------------------------------------------------------------------
// Orbit table
// ------------------------------------------------------------------------------------------

/// The onboard orbit: the spacecraft state at an epoch, as the ground's orbit determination
/// gives it from tracking; the OBC propagates it ([`crate::orbit`]).
/// docs/tables.md (Table 5: orbit); algorithms.md §3.3 (orbital aberration, Sun parallax).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OrbitTable {
    /// Epoch of the state, seconds since J2000.0 TT (the time of
    /// [`crate::raw::TimeTag::seconds_since_j2000_tt`]); within ±50 years of J2000 (the onboard
    /// Sun ephemeris's span).
    /// docs/tables.md (Table 5, field 0).
    pub epoch_s_since_j2000_tt: f64,
    /// Position at the epoch, J2000/GCRS axes, km; radius
    /// [`crate::orbit::MIN_RADIUS_KM`]..=[`crate::orbit::MAX_RADIUS_KM`].
    /// docs/tables.md (Table 5, field 1).
    pub pos_eci_km: [f64; 3],
    /// Velocity at the epoch, J2000/GCRS axes, km/s: a bound orbit (below the escape speed)
    /// whose perigee radius is at least [`crate::orbit::MIN_RADIUS_KM`].
    /// docs/tables.md (Table 5, field 2).
    pub vel_eci_km_per_s: [f64; 3],
}

impl OrbitTable {
    /// The boot table: no orbit (all zero). It does not validate and is never propagated:
    /// the OBC has no orbit until one is uplinked.
    /// docs/tables.md (Table 5: "boot: none").
    #[must_use]
    pub fn none() -> Self {
        Self {
            epoch_s_since_j2000_tt: 0.0,
            pos_eci_km: [0.0; 3],
            vel_eci_km_per_s: [0.0; 3],
        }
    }

    /// Content checks. Fields: 0 epoch, 1 position, 2 velocity.
    /// docs/tables.md (Table 5: ranges).
    ///
    /// # Errors
    /// The first failed check: [`TableError::NotFinite`] or [`TableError::OutOfRange`] with
    /// the field number.
    pub fn validate(&self) -> Result<(), TableError> {
        /// ±50 Julian years of J2000, s: the onboard Sun ephemeris's span.
        const MAX_EPOCH_S: f64 = 50.0 * 365.25 * 86_400.0;
        check_range(self.epoch_s_since_j2000_tt, -MAX_EPOCH_S, MAX_EPOCH_S, 0)?;
        check_finite(&self.pos_eci_km, 1)?;
        check_finite(&self.vel_eci_km_per_s, 2)?;
        let r = Vector3::from(self.pos_eci_km);
        let v = Vector3::from(self.vel_eci_km_per_s);
        let r_km = r.norm();
        check_range(
            r_km,
            crate::orbit::MIN_RADIUS_KM,
            crate::orbit::MAX_RADIUS_KM,
            1,
        )?;
        match crate::orbit::perigee_radius_km(&r, &v) {
            Some(rp) if rp >= crate::orbit::MIN_RADIUS_KM => Ok(()),
            _ => Err(TableError::OutOfRange { field: 2 }),
        }
    }
}

/// Largest rotation bound check used at load and at activation.
/// docs/tables.md (`max_alignment_change_arcsec`, "Lifecycle").
///
/// # Errors
/// [`TableError::ChangeTooLarge`] when an alignment moves by more than the bound.
pub fn check_alignment_change(
    new: &AlignmentTable,
    active: &AlignmentTable,
    filter: &FilterTable,
) -> Result<(), TableError> {
    let (change, sensor) = new.max_rotation_from_arcsec(active);
    if !(change <= filter.max_alignment_change_arcsec) {
        #[allow(clippy::cast_possible_truncation)]
        return Err(TableError::ChangeTooLarge {
            field: sensor,
            change: change as f32,
            limit: filter.max_alignment_change_arcsec as f32,
        });
    }
    Ok(())
}

/// IRU change bound check used at load and at activation.
/// docs/tables.md (`max_iru_change_ppm`, "Lifecycle").
///
/// # Errors
/// [`TableError::ChangeTooLarge`] when G or k move by more than the bound.
pub fn check_iru_change(
    new: &IruTable,
    active: &IruTable,
    filter: &FilterTable,
) -> Result<(), TableError> {
    let change = new.max_g_change_ppm(active);
    if !(change <= filter.max_iru_change_ppm) {
        #[allow(clippy::cast_possible_truncation)]
        return Err(TableError::ChangeTooLarge {
            field: 0,
            change: change as f32,
            limit: filter.max_iru_change_ppm as f32,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::units::RAD_PER_ARCSEC;

    #[test]
    fn new_alignment_corrections_default_off_and_validate() {
        let a = AlignmentTable::prelaunch();
        assert_eq!(a.validate(), Ok(()));
        assert_eq!(a.corrections, SensorCorrections::default());
        for s in SensorId::ALL {
            // No thermal coefficient: the stored rows whatever the temperature.
            assert_eq!(
                a.m_acs_from_sensor_rows_at(s, 80.0),
                *a.matrices()[s.index()]
            );
            assert_eq!(a.rows(s), a.matrices()[s.index()]);
            assert_eq!(
                a.corrections.thermal_rotation_rad(s, -40.0),
                Vector3::zeros()
            );
        }
    }

    #[test]
    fn new_alignment_corrections_rejected_out_of_range_or_not_finite() {
        let base = AlignmentTable::prelaunch();
        type Case = (fn(&mut SensorCorrections), TableError);
        let cases: [Case; 12] = [
            (
                |c| c.fhst_magnitude_bias_rad_per_mag[1][0] = 1.1e-3,
                TableError::OutOfRange { field: 7 },
            ),
            (
                |c| c.fhst_magnitude_bias_rad_per_mag[0][1] = f64::NAN,
                TableError::NotFinite { field: 7 },
            ),
            (
                |c| c.thermal_alignment_rad_per_c[3][2] = -2.0e-3,
                TableError::OutOfRange { field: 8 },
            ),
            (
                |c| c.thermal_alignment_rad_per_c[0][0] = f64::INFINITY,
                TableError::NotFinite { field: 8 },
            ),
            (
                |c| c.thermal_reference_c[2] = 151.0,
                TableError::OutOfRange { field: 9 },
            ),
            (
                |c| c.thermal_reference_c[1] = f64::NAN,
                TableError::NotFinite { field: 9 },
            ),
            (
                |c| c.fss_cubic[1][1] = -1.5,
                TableError::OutOfRange { field: 10 },
            ),
            (
                |c| c.fss_cubic[0][0] = f64::NAN,
                TableError::NotFinite { field: 10 },
            ),
            (
                |c| c.fss_cyclic[0][0] = 1.0e-4,
                TableError::OutOfRange { field: 11 },
            ),
            (
                |c| c.fss_cyclic[1] = [2.0, 0.0, 0.0, 0.0, 0.0],
                TableError::OutOfRange { field: 11 },
            ),
            (
                |c| c.fss_cyclic[1][3] = 2.0e-3,
                TableError::OutOfRange { field: 11 },
            ),
            (
                |c| c.fss_cyclic[0][0] = f64::NAN,
                TableError::NotFinite { field: 11 },
            ),
        ];
        for (i, (set, err)) in cases.iter().enumerate() {
            let mut t = base;
            set(&mut t.corrections);
            assert_eq!(t.validate(), Err(*err), "case {i}");
        }
        // Amplitudes with the cyclic term off (pitch 0) are still range-checked; in range,
        // every new field at its limit validates.
        let mut t = base;
        t.corrections.fhst_magnitude_bias_rad_per_mag = [[1.0e-3, -1.0e-3]; 2];
        t.corrections.thermal_alignment_rad_per_c = [[-1.0e-3, 0.0, 1.0e-3]; 4];
        t.corrections.thermal_reference_c = [-100.0, 150.0, 20.0, 0.0];
        t.corrections.fss_cubic = [[1.0, -1.0]; 2];
        t.corrections.fss_cyclic = [[1.2, 1.0e-3, -1.0e-3, 0.0, 1.0e-3], [0.0; 5]];
        assert_eq!(t.validate(), Ok(()));
    }

    #[test]
    fn thermal_rotation_follows_the_temperature_and_is_clamped() {
        let mut a = AlignmentTable::prelaunch();
        let k = [4.0 * RAD_PER_ARCSEC, 0.0, -2.0 * RAD_PER_ARCSEC];
        a.corrections.thermal_alignment_rad_per_c[1] = k;
        a.corrections.thermal_reference_c[1] = 17.0;
        let c = &a.corrections;
        let at = |t: f64| c.thermal_rotation_rad(SensorId::Fhst2, t);
        assert!((at(20.0) - Vector3::from(k) * 3.0).norm() < 1e-18);
        assert_eq!(at(17.0), Vector3::zeros());
        // Clamped at ±50 °C from the reference; NaN and other sensors: none.
        assert!((at(300.0) - Vector3::from(k) * THERMAL_MAX_DEVIATION_C).norm() < 1e-18);
        assert!((at(-300.0) + Vector3::from(k) * THERMAL_MAX_DEVIATION_C).norm() < 1e-18);
        assert_eq!(at(f64::NAN), Vector3::zeros());
        assert_eq!(
            c.thermal_rotation_rad(SensorId::Fhst1, 30.0),
            Vector3::zeros()
        );
        // M_AS(T) = Rot(k ΔT) M_AS, as the truth model rotates the sensor (M' = Rot(θ) M).
        let m = a.m_acs_from_sensor_rows_at(SensorId::Fhst2, 22.0);
        let expect = rot(&(Vector3::from(k) * 5.0)) * matrix_from_rows(&a.m_acs_from_fhst2);
        assert!((matrix_from_rows(&m) - expect).norm() < 1e-15);
        assert_eq!(
            a.m_acs_from_sensor_rows_at(SensorId::Fhst1, 22.0),
            a.m_acs_from_fhst1
        );
    }

    #[test]
    fn orbit_table_validation_names_the_field() {
        let v = libm::sqrt(crate::orbit::MU_EARTH_KM3_PER_S2 / 6833.0);
        let good = OrbitTable {
            epoch_s_since_j2000_tt: -2.7e8,
            pos_eci_km: [6833.0, 0.0, 0.0],
            vel_eci_km_per_s: [0.0, v * 0.88, v * 0.475],
        };
        assert_eq!(good.validate(), Ok(()));
        assert_eq!(
            OrbitTable::none().validate(),
            Err(TableError::OutOfRange { field: 1 })
        );
        type Case = (fn(&mut OrbitTable), TableError);
        let cases: [Case; 8] = [
            (
                |t| t.epoch_s_since_j2000_tt = f64::NAN,
                TableError::NotFinite { field: 0 },
            ),
            (
                |t| t.epoch_s_since_j2000_tt = 2.0e9,
                TableError::OutOfRange { field: 0 },
            ),
            (
                |t| t.pos_eci_km[2] = f64::INFINITY,
                TableError::NotFinite { field: 1 },
            ),
            // 6400 km: below 100 km altitude.
            (
                |t| t.pos_eci_km = [6400.0, 0.0, 0.0],
                TableError::OutOfRange { field: 1 },
            ),
            (
                |t| t.pos_eci_km = [60_000.0, 0.0, 0.0],
                TableError::OutOfRange { field: 1 },
            ),
            (
                |t| t.vel_eci_km_per_s[0] = f64::NAN,
                TableError::NotFinite { field: 2 },
            ),
            // Above the escape speed (10.8 km/s at 6833 km): not bound.
            (
                |t| t.vel_eci_km_per_s = [0.0, 11.0, 0.0],
                TableError::OutOfRange { field: 2 },
            ),
            // Radial fall: perigee inside the Earth.
            (
                |t| t.vel_eci_km_per_s = [-1.0, 0.5, 0.0],
                TableError::OutOfRange { field: 2 },
            ),
        ];
        for (i, (set, err)) in cases.iter().enumerate() {
            let mut t = good;
            set(&mut t);
            assert_eq!(t.validate(), Err(*err), "case {i}");
        }
    }

    #[test]
    fn filter_floor_field_validated() {
        let mut f = FilterTable::default_boot();
        assert!(!f.orbital_aberration_correction);
        assert!((f.fhst_uncorrected_systematic_arcsec - 3.65).abs() < 1e-12);
        f.fhst_uncorrected_systematic_arcsec = 0.0;
        assert_eq!(f.validate(), Ok(()));
        f.fhst_uncorrected_systematic_arcsec = -0.1;
        assert_eq!(f.validate(), Err(TableError::OutOfRange { field: 22 }));
        f.fhst_uncorrected_systematic_arcsec = f64::NAN;
        assert_eq!(f.validate(), Err(TableError::NotFinite { field: 22 }));
    }

    #[test]
    fn iru_asymmetry_validated_and_bounded_by_the_change_check() {
        let base = IruTable::prelaunch();
        assert_eq!(base.validate(), Ok(()));
        let mut t = base;
        t.scale_asymmetry_primary = [4.0e-4, -3.0e-4, 0.01];
        t.scale_asymmetry_backup = [-0.01, 0.0, 1.0e-4];
        assert_eq!(t.validate(), Ok(()));
        // 0.01 = 10,000 ppm is the largest change: the load bound sees it.
        assert!((t.max_g_change_ppm(&base) - 10_000.0).abs() < 1e-6);
        t.scale_asymmetry_primary[1] = 0.011;
        assert_eq!(t.validate(), Err(TableError::OutOfRange { field: 8 }));
        let mut t = base;
        t.scale_asymmetry_backup[2] = f64::NAN;
        assert_eq!(t.validate(), Err(TableError::NotFinite { field: 9 }));
    }
}
