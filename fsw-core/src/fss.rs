//! # Fine Sun sensor measurement model (paper: FSS specifications; algorithms.md §4)
//!
//! Each Adcole FSS has two orthogonal single-axis heads sharing a boresight `+z_s`, 64°×64°
//! field, 0.004°/count ([`FssSample`]).
//!
//! ## Equations
//!
//! * Counts → measured head angles: `α_m = 0.004° · N_α`, `β_m = 0.004° · N_β`.
//! * Transfer-function correction ([`SensorCorrections::fss_transfer`], `c = [c0..c5]`, all
//!   zero = off): `α = α_m − (c0 α_m + c1 α_m β_m² + c2)`,
//!   `β = β_m − (c3 β_m + c4 β_m α_m² + c5)`. [`apply_transfer`] inverts it (fixed point).
//! * Cubic and cyclic terms ([`SensorCorrections::fss_cubic`] `[k_α, k_β]`,
//!   [`SensorCorrections::fss_cyclic`] `[p, s_α, c_α, s_β, c_β]`, zero = off), evaluated at
//!   the measured angles as the terms above ([`correct_transfer_full`]):
//!   `α −= k_α α_m³ + s_α sin(2π α_m/p) + c_α cos(2π α_m/p)`, the same for β. The cyclic term
//!   costs one `sincos` per head and cycle, only when `p ≠ 0`.
//! * Thermal alignment drift: `Rot(k (T − T_ref)) M_AS` at the sensor's raw-frame
//!   temperature ([`measure_sensor_at`]).
//! * Head angles are tangent-plane angles, `α = atan2(s_x, s_z)`, `β = atan2(s_y, s_z)`, so
//!   `s = [tan α, tan β, 1]ᵀ / |·|` (algorithms.md §4 "Unit vector").
//! * Sensor → ACS: `b = M_AS s`.
//!
//! ## Validity checks (in this order)
//! Sun presence on both heads, finite values, `|α_m|, |β_m| ≤ 32°` (the measured angles
//! bound the physical field).
//!
//! ## Noise
//! The filter uses the table's isotropic `fss_sigma_arcsec` for the 2 components
//! perpendicular to the Sun line. A tangent-plane angle error `dα` moves the direction by
//! `cos²α · dα` across the α head's plane, so near the field edge the isotropic σ is
//! conservative.

use crate::raw::{FssSample, FSS_FLAG_SUN_ALPHA, FSS_FLAG_SUN_BETA};
use crate::tables::types::{matrix_from_rows, AlignmentTable, Mat3Rows, SensorCorrections};
use crate::units::RAD_PER_DEG;
use nalgebra::{Matrix3, Vector3};

/// FSS resolution, rad per count (0.004°).
/// Paper: FSS resolution about 0.004°/count.
pub const FSS_RAD_PER_COUNT: f64 = 0.004 * RAD_PER_DEG;
/// Half-width of the field of view per head, rad (32°).
/// Paper: FSS FOV 64° × 64°; algorithms.md §4.
pub const FSS_HALF_FIELD_RAD: f64 = 32.0 * RAD_PER_DEG;
/// Fixed-point iterations of [`apply_transfer`].
const TRANSFER_ITERATIONS: usize = 6;

/// Which Sun sensor.
/// Paper: two FSSs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FssId {
    /// FSS1.
    /// Paper Table 1 (FSS1).
    Fss1,
    /// FSS2.
    /// Paper Table 1 (FSS2).
    Fss2,
}

impl FssId {
    /// Both sensors, in order.
    /// Paper: two FSSs.
    pub const ALL: [FssId; 2] = [FssId::Fss1, FssId::Fss2];

    /// Index 0 or 1 (raw frame, correction arrays).
    /// Order of docs/icd.md §3.1 and docs/tables.md.
    #[must_use]
    pub const fn index(self) -> usize {
        match self {
            Self::Fss1 => 0,
            Self::Fss2 => 1,
        }
    }

    /// The Sun sensor as one of the four aligned sensors.
    /// Paper Table 1.
    #[must_use]
    pub const fn sensor(self) -> crate::sensor::SensorId {
        match self {
            Self::Fss1 => crate::sensor::SensorId::Fss1,
            Self::Fss2 => crate::sensor::SensorId::Fss2,
        }
    }

    /// Active `M_AS` (sensor → ACS).
    /// Paper: `M_AS`, Table 1 at boot (docs/tables.md Table 1: alignment).
    #[must_use]
    pub fn m_acs_from_sensor(self, alignment: &AlignmentTable) -> Matrix3<f64> {
        match self {
            Self::Fss1 => matrix_from_rows(&alignment.m_acs_from_fss1),
            Self::Fss2 => matrix_from_rows(&alignment.m_acs_from_fss2),
        }
    }

    /// Transfer-function coefficients `[c0..c5]` of this sensor.
    /// docs/tables.md (alignment table, `fss_transfer`); algorithms.md §4.
    #[must_use]
    pub fn transfer(self, corrections: &SensorCorrections) -> [f64; 6] {
        let [c1, c2] = corrections.fss_transfer;
        match self {
            Self::Fss1 => c1,
            Self::Fss2 => c2,
        }
    }

    /// Every transfer-function term of this sensor (scale/cross/offset, cubic, cyclic).
    /// docs/tables.md (alignment table, fields 6, 10, 11); algorithms.md §4.
    #[must_use]
    pub fn transfer_terms(self, corrections: &SensorCorrections) -> TransferTerms {
        let i = self.index();
        TransferTerms {
            coefficients: self.transfer(corrections),
            cubic: corrections.fss_cubic.get(i).copied().unwrap_or([0.0; 2]),
            cyclic: corrections.fss_cyclic.get(i).copied().unwrap_or([0.0; 5]),
        }
    }
}

/// The transfer-function correction of one FSS (the alignment table's fields 6, 10, 11).
/// docs/tables.md (alignment table); algorithms.md §4 and effect 15 of §9.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TransferTerms {
    /// `[c0..c5]`: scale, cross-axis and offset terms.
    /// docs/tables.md (field 6).
    pub coefficients: [f64; 6],
    /// `[k_α, k_β]`, rad⁻²: cubic terms.
    /// docs/tables.md (field 10).
    pub cubic: [f64; 2],
    /// `[p, s_α, c_α, s_β, c_β]`: cyclic terms at pitch `p` (rad, 0 = off).
    /// docs/tables.md (field 11).
    pub cyclic: [f64; 5],
}

/// A validated, corrected Sun measurement.
/// algorithms.md §4.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FssMeasurement {
    /// Corrected α head angle, rad.
    /// algorithms.md §4 (α).
    pub alpha_rad: f64,
    /// Corrected β head angle, rad.
    /// algorithms.md §4 (β).
    pub beta_rad: f64,
    /// Sun direction in sensor axes (unit).
    /// algorithms.md §4 ("Unit vector").
    pub dir_sensor: Vector3<f64>,
    /// Sun direction in ACS axes (unit), through the active alignment.
    /// `b = M_AS s` (paper `M_AS`; algorithms.md §1).
    pub dir_acs: Vector3<f64>,
}

#[cfg(feature = "defmt")]
impl defmt::Format for FssMeasurement {
    fn format(&self, f: defmt::Formatter) {
        defmt::write!(
            f,
            "FssMeasurement {{ alpha: {}, beta: {}, acs: {} }}",
            self.alpha_rad,
            self.beta_rad,
            [self.dir_acs.x, self.dir_acs.y, self.dir_acs.z]
        );
    }
}

/// Why a sample was not used.
/// Checks of algorithms.md §4 ("When the data are valid").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FssReject {
    /// A head reports no Sun.
    /// docs/icd.md §3.1 (FSS flags); algorithms.md §4.
    NoSun {
        /// α head sees the Sun.
        /// docs/icd.md §3.1 (bit0).
        alpha: bool,
        /// β head sees the Sun.
        /// docs/icd.md §3.1 (bit1).
        beta: bool,
    },
    /// A computed value is not finite (corrupt corrections).
    /// Project choice (not in the paper): a corrupt table must not reach the filter.
    NotFinite,
    /// Outside the ±32° field.
    /// Paper: FSS FOV 64° × 64°; algorithms.md §4.
    OutOfField,
}

impl FssReject {
    /// No Sun on a head (eclipse, Sun outside the field): not an anomaly.
    /// Project choice (not in the paper): only anomalies raise an event.
    #[must_use]
    pub const fn is_no_data(self) -> bool {
        matches!(self, Self::NoSun { .. })
    }

    /// Event/telemetry code: 1 no Sun, 2 not finite, 3 out of field.
    /// Reason code of event 0x0404, docs/icd.md §3.3.
    #[must_use]
    pub const fn code(self) -> u8 {
        match self {
            Self::NoSun { .. } => 1,
            Self::NotFinite => 2,
            Self::OutOfField => 3,
        }
    }
}

/// Transfer-function correction: measured head angles → true head angles (rad).
/// docs/tables.md (alignment table, `fss_transfer`); form per algorithms.md §4 (cross-axis term).
#[must_use]
pub fn correct_transfer(alpha_m: f64, beta_m: f64, c: &[f64; 6]) -> (f64, f64) {
    let [c0, c1, c2, c3, c4, c5] = *c;
    (
        alpha_m - (c0 * alpha_m + c1 * alpha_m * beta_m * beta_m + c2),
        beta_m - (c3 * beta_m + c4 * beta_m * alpha_m * alpha_m + c5),
    )
}

/// Inverse of [`correct_transfer`]: true angles → measured angles (rad), fixed-point
/// iteration (for simulators and ground checks; converges for calibration-sized `c`).
/// docs/tables.md (alignment table, `fss_transfer`).
#[must_use]
pub fn apply_transfer(alpha: f64, beta: f64, c: &[f64; 6]) -> (f64, f64) {
    apply_transfer_full(
        alpha,
        beta,
        &TransferTerms {
            coefficients: *c,
            ..TransferTerms::default()
        },
    )
}

/// The cyclic term `s sin(2π x/p) + c cos(2π x/p)` of one head (rad); 0 when `p = 0`.
fn cyclic_term(x: f64, pitch_rad: f64, sin_rad: f64, cos_rad: f64) -> f64 {
    if pitch_rad == 0.0 {
        return 0.0;
    }
    let (s, c) = libm::sincos(core::f64::consts::TAU * x / pitch_rad);
    sin_rad * s + cos_rad * c
}

/// The full transfer-function correction: measured head angles → true head angles (rad),
/// [`correct_transfer`] then the cubic and cyclic terms, all at the measured angles (module
/// docs). Zero cubic and cyclic terms give exactly [`correct_transfer`].
/// docs/tables.md (alignment table, fields 6, 10, 11); algorithms.md §4, effect 15 of §9.
#[must_use]
#[inline]
pub fn correct_transfer_full(alpha_m: f64, beta_m: f64, t: &TransferTerms) -> (f64, f64) {
    let (mut alpha, mut beta) = correct_transfer(alpha_m, beta_m, &t.coefficients);
    let [k_a, k_b] = t.cubic;
    if k_a != 0.0 || k_b != 0.0 {
        alpha -= k_a * alpha_m * alpha_m * alpha_m;
        beta -= k_b * beta_m * beta_m * beta_m;
    }
    let [pitch, s_a, c_a, s_b, c_b] = t.cyclic;
    if pitch != 0.0 {
        alpha -= cyclic_term(alpha_m, pitch, s_a, c_a);
        beta -= cyclic_term(beta_m, pitch, s_b, c_b);
    }
    (alpha, beta)
}

/// Inverse of [`correct_transfer_full`]: true angles → measured angles (rad), fixed-point
/// iteration (for simulators and ground checks; converges while the correction's slope is
/// well below 1, i.e. for calibration-sized terms: a 6″ cyclic term at a 2° pitch has slope
/// 5e-3).
/// docs/tables.md (alignment table, fields 6, 10, 11).
#[must_use]
pub fn apply_transfer_full(alpha: f64, beta: f64, t: &TransferTerms) -> (f64, f64) {
    crate::fhst::invert_correction(alpha, beta, TRANSFER_ITERATIONS, |a_m, b_m| {
        correct_transfer_full(a_m, b_m, t)
    })
}

/// Unit vector in sensor axes from head angles (rad): the head angles are tangent-plane
/// angles, as the FHST's ([`crate::fhst::dir_from_hv`]).
/// algorithms.md §4 ("Unit vector").
#[must_use]
pub fn dir_from_angles(alpha_rad: f64, beta_rad: f64) -> Vector3<f64> {
    crate::fhst::dir_from_hv(alpha_rad, beta_rad)
}

/// Head angles (rad) of a sensor-frame direction; `None` unless `s_z > 0` and finite
/// ([`crate::fhst::hv_from_dir`]).
/// algorithms.md §4 ("Measured angles").
#[must_use]
pub fn angles_from_dir(s: &Vector3<f64>) -> Option<(f64, f64)> {
    crate::fhst::hv_from_dir(s)
}

/// [`measure_corrected`] with the sensor's alignment and every transfer-function term from
/// the table, without the thermal drift (the alignment at `T = T_ref`; see
/// [`measure_sensor_at`]).
/// docs/tables.md (alignment table).
///
/// # Errors
/// As [`measure`].
pub fn measure_sensor(
    sample: &FssSample,
    sensor: FssId,
    alignment: &AlignmentTable,
) -> Result<FssMeasurement, FssReject> {
    let m = match sensor {
        FssId::Fss1 => &alignment.m_acs_from_fss1,
        FssId::Fss2 => &alignment.m_acs_from_fss2,
    };
    measure_corrected(sample, m, &sensor.transfer_terms(&alignment.corrections))
}

/// [`measure_sensor`] with the sensor's alignment at its temperature `temperature_c` (°C, the
/// raw frame's, docs/icd.md §3.1): every correction of the alignment table, as the OBC
/// applies them.
/// docs/tables.md (alignment table, fields 2–3, 6, 8–11).
///
/// # Errors
/// As [`measure`].
pub fn measure_sensor_at(
    sample: &FssSample,
    sensor: FssId,
    alignment: &AlignmentTable,
    temperature_c: f64,
) -> Result<FssMeasurement, FssReject> {
    let m = alignment.m_acs_from_sensor_rows_at(sensor.sensor(), temperature_c);
    measure_corrected(sample, &m, &sensor.transfer_terms(&alignment.corrections))
}

/// Convert and validate one Sun sensor sample with the sensor's `M_AS` (table rows) and
/// transfer coefficients `[c0..c5]` (no cubic or cyclic terms).
/// algorithms.md §4.
///
/// # Errors
/// The first failed check, see [`FssReject`].
pub fn measure(
    sample: &FssSample,
    m_acs_from_sensor: &Mat3Rows,
    transfer: &[f64; 6],
) -> Result<FssMeasurement, FssReject> {
    measure_corrected(
        sample,
        m_acs_from_sensor,
        &TransferTerms {
            coefficients: *transfer,
            ..TransferTerms::default()
        },
    )
}

/// Convert and validate one Sun sensor sample with the sensor's `M_AS` (table rows) and its
/// full transfer-function correction.
/// algorithms.md §4; docs/tables.md (alignment table, fields 6, 10, 11).
///
/// # Errors
/// The first failed check, see [`FssReject`].
pub fn measure_corrected(
    sample: &FssSample,
    m_acs_from_sensor: &Mat3Rows,
    transfer: &TransferTerms,
) -> Result<FssMeasurement, FssReject> {
    let alpha_sun = sample.flags & FSS_FLAG_SUN_ALPHA != 0;
    let beta_sun = sample.flags & FSS_FLAG_SUN_BETA != 0;
    if !(alpha_sun && beta_sun) {
        return Err(FssReject::NoSun {
            alpha: alpha_sun,
            beta: beta_sun,
        });
    }
    let alpha_m = f64::from(sample.alpha_counts) * FSS_RAD_PER_COUNT;
    let beta_m = f64::from(sample.beta_counts) * FSS_RAD_PER_COUNT;
    let (alpha, beta) = correct_transfer_full(alpha_m, beta_m, transfer);
    let dir_sensor = dir_from_angles(alpha, beta);
    let dir_acs = matrix_from_rows(m_acs_from_sensor) * dir_sensor;
    if !(alpha.is_finite() && beta.is_finite() && dir_acs.iter().all(|x| x.is_finite())) {
        return Err(FssReject::NotFinite);
    }
    if !(alpha_m.abs() <= FSS_HALF_FIELD_RAD && beta_m.abs() <= FSS_HALF_FIELD_RAD) {
        return Err(FssReject::OutOfField);
    }
    Ok(FssMeasurement {
        alpha_rad: alpha,
        beta_rad: beta,
        dir_sensor,
        dir_acs,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(a: i16, b: i16) -> FssSample {
        FssSample {
            alpha_counts: a,
            beta_counts: b,
            flags: FSS_FLAG_SUN_ALPHA | FSS_FLAG_SUN_BETA,
        }
    }

    #[test]
    fn counts_to_vector() {
        let al = AlignmentTable::prelaunch();
        let m = measure_sensor(&sample(2500, -1250), FssId::Fss1, &al).unwrap();
        assert!((m.alpha_rad - 10.0 * RAD_PER_DEG).abs() < 1e-15);
        assert!((m.beta_rad + 5.0 * RAD_PER_DEG).abs() < 1e-15);
        let (a, b) = angles_from_dir(&m.dir_sensor).unwrap();
        assert!((a - m.alpha_rad).abs() < 1e-15 && (b - m.beta_rad).abs() < 1e-15);
        let back = FssId::Fss1.m_acs_from_sensor(&al).transpose() * m.dir_acs;
        // The published M_AS is orthonormal only to ~1e-8.
        assert!((back - m.dir_sensor).norm() < 1e-7);
        let z = measure_sensor(&sample(0, 0), FssId::Fss2, &al).unwrap();
        let col = FssId::Fss2.m_acs_from_sensor(&al).column(2).into_owned();
        assert!(
            (z.dir_acs - col).norm() < 1e-15,
            "{}",
            (z.dir_acs - col).norm()
        );
    }

    #[test]
    fn transfer_round_trip_and_identity() {
        let c = [1e-3, 0.02, 2e-4, -5e-4, -0.01, -1e-4];
        for (a, b) in [(0.5, -0.5), (-0.3, 0.1), (0.0, 0.0)] {
            let (am, bm) = apply_transfer(a, b, &c);
            let (ac, bc) = correct_transfer(am, bm, &c);
            assert!((ac - a).abs() < 1e-12 && (bc - b).abs() < 1e-12);
        }
        assert_eq!(correct_transfer(0.2, -0.1, &[0.0; 6]), (0.2, -0.1));
    }

    /// The harness's head error (sim-harness `FssHeadErrors::apply`: `α_m = α + cubic (α/E)³ +
    /// cyclic sin(2π α/p)`, E = 32°) is removed by the table terms with the same signs,
    /// `k = cubic/E³` and `s = cyclic`, to far below a count.
    #[test]
    fn cubic_and_cyclic_terms_remove_the_truth_models_error() {
        use crate::units::RAD_PER_ARCSEC;
        let e = 32.0 * RAD_PER_DEG;
        let pitch = 2.0 * RAD_PER_DEG;
        let (cubic_a, cubic_b, cyc_a, cyc_b) = (20.0, -15.0, 6.0, -4.0);
        let truth = |x: f64, cubic: f64, cyc: f64| {
            x + (cubic * (x / e).powi(3) + cyc * libm::sin(core::f64::consts::TAU * x / pitch))
                * RAD_PER_ARCSEC
        };
        let t = TransferTerms {
            coefficients: [0.0; 6],
            cubic: [
                cubic_a * RAD_PER_ARCSEC / (e * e * e),
                cubic_b * RAD_PER_ARCSEC / (e * e * e),
            ],
            cyclic: [
                pitch,
                cyc_a * RAD_PER_ARCSEC,
                0.0,
                cyc_b * RAD_PER_ARCSEC,
                0.0,
            ],
        };
        let mut worst: f64 = 0.0;
        for k in -30..=30 {
            let a = f64::from(k) * 0.5 * RAD_PER_DEG + 0.0013;
            let b = -0.7 * a + 0.002;
            let (am, bm) = (truth(a, cubic_a, cyc_a), truth(b, cubic_b, cyc_b));
            let (ac, bc) = correct_transfer_full(am, bm, &t);
            worst = worst.max((ac - a).abs()).max((bc - b).abs());
            // The inverse reproduces the measured angles.
            let (am2, bm2) = apply_transfer_full(ac, bc, &t);
            assert!((am2 - am).abs() < 1e-13 && (bm2 - bm).abs() < 1e-13);
        }
        // Evaluating the terms at the measured angle costs ≤ slope × error ≈ 0.1″ at most.
        assert!(worst < 0.1 * RAD_PER_ARCSEC, "{}", worst / RAD_PER_ARCSEC);
        // Without the terms the error is up to ≈ 26″.
        let (a, b) = (30.0 * RAD_PER_DEG, 0.0);
        let (ac, _) = correct_transfer(truth(a, cubic_a, cyc_a), b, &[0.0; 6]);
        assert!((ac - a).abs() > 15.0 * RAD_PER_ARCSEC);
        // Zero terms: exactly the scale/cross correction.
        let c = [1e-3, 0.02, 2e-4, -5e-4, -0.01, -1e-4];
        let only = TransferTerms {
            coefficients: c,
            ..TransferTerms::default()
        };
        assert_eq!(
            correct_transfer_full(0.3, -0.2, &only),
            correct_transfer(0.3, -0.2, &c)
        );
        // Through the table: FSS2's terms, FSS1 unaffected.
        let mut al = AlignmentTable::prelaunch();
        al.corrections.fss_cubic[1] = t.cubic;
        al.corrections.fss_cyclic[1] = t.cyclic;
        assert_eq!(al.validate(), Ok(()));
        let s = sample(6000, -2000);
        let m = measure_sensor(&s, FssId::Fss2, &al).unwrap();
        let (a_m, b_m) = (6000.0 * FSS_RAD_PER_COUNT, -2000.0 * FSS_RAD_PER_COUNT);
        assert_eq!(
            (m.alpha_rad, m.beta_rad),
            correct_transfer_full(a_m, b_m, &t)
        );
        assert_eq!(
            measure_sensor(&s, FssId::Fss1, &al),
            measure_sensor(&s, FssId::Fss1, &AlignmentTable::prelaunch())
        );
    }

    #[test]
    fn thermal_drift_rotates_the_sun_sensor_alignment() {
        use crate::units::RAD_PER_ARCSEC;
        let mut al = AlignmentTable::prelaunch();
        let k = [3.0 * RAD_PER_ARCSEC, -RAD_PER_ARCSEC, 0.0];
        al.corrections.thermal_alignment_rad_per_c[2] = k;
        al.corrections.thermal_reference_c[2] = 22.0;
        let m = measure_sensor_at(&sample(0, 0), FssId::Fss1, &al, 18.0).unwrap();
        let z = crate::attitude::rot(&(Vector3::from(k) * -4.0))
            * FssId::Fss1.m_acs_from_sensor(&al).column(2);
        assert!((m.dir_acs - z).norm() < 1e-15);
        assert_eq!(
            measure_sensor_at(&sample(0, 0), FssId::Fss2, &al, 18.0),
            measure_sensor(&sample(0, 0), FssId::Fss2, &al)
        );
    }

    #[test]
    fn checks() {
        let al = AlignmentTable::prelaunch();
        let mut s = sample(0, 0);
        s.flags = FSS_FLAG_SUN_ALPHA;
        assert_eq!(
            measure_sensor(&s, FssId::Fss1, &al),
            Err(FssReject::NoSun {
                alpha: true,
                beta: false
            })
        );
        assert!(measure_sensor(&sample(8000, -8000), FssId::Fss1, &al).is_ok());
        assert_eq!(
            measure_sensor(&sample(8001, 0), FssId::Fss1, &al),
            Err(FssReject::OutOfField)
        );
        assert_eq!(
            measure_sensor(&sample(0, -8001), FssId::Fss2, &al),
            Err(FssReject::OutOfField)
        );
        let mut bad = al;
        bad.corrections.fss_transfer[0][2] = f64::INFINITY;
        assert_eq!(
            measure_sensor(&sample(1, 1), FssId::Fss1, &bad),
            Err(FssReject::NotFinite)
        );
    }
}
