//! # Fixed-head star tracker measurement model (paper: FHST specifications; algorithms.md §3.1)
//!
//! The NASA Standard FHST tracks one star at a time in a 8°×8° field and reports two
//! focal-plane coordinates (7.78″/count), an instrument magnitude and status flags
//! ([`FhstSample`]).
//!
//! ## Equations
//!
//! * Counts → measured angles: `H_m = 7.78″ · N_H`, `V_m = 7.78″ · N_V`.
//! * Distortion correction ([`SensorCorrections::fhst_distortion`], `d = [d0, d1, d2]`, all
//!   zero = off): `H = H_m − (d0 ρ² H_m + d1 H_m V_m)`, `V = V_m − (d0 ρ² V_m + d2 H_m V_m)`,
//!   `ρ² = H_m² + V_m²`. [`apply_distortion`] is its inverse (for simulators and prediction of
//!   raw counts), by a bounded fixed-point iteration.
//! * Magnitude-dependent bias ([`SensorCorrections::fhst_magnitude_bias_rad_per_mag`],
//!   `b = [b_H, b_V]`, zero = off), after the distortion correction: `H −= b_H (m − 4)`,
//!   `V −= b_V (m − 4)`, `m` the sample's instrument magnitude.
//! * Thermal alignment drift ([`SensorCorrections::thermal_alignment_rad_per_c`]): the
//!   alignment of the tracker at its raw-frame temperature `T` is
//!   `Rot(k (T − T_ref)) M_AS` ([`AlignmentTable::m_acs_from_sensor_rows_at`],
//!   [`measure_tracker_at`]).
//! * Tangent-plane (gnomonic) form, boresight `+z_s`:
//!   `H = atan2(s_x, s_z)`, `V = atan2(s_y, s_z)`, `s = [tan H, tan V, 1]ᵀ / √(1+tan²H+tan²V)`.
//! * Sensor → ACS with the active alignment: `b = M_AS s` (columns of `M_AS` = sensor axes in
//!   ACS).
//! * Jacobian of the focal-plane angles ([`hv_jacobian`]):
//!   `∂H/∂s = [s_z, 0, −s_x]/(s_x²+s_z²)`, `∂V/∂s = [0, s_z, −s_y]/(s_y²+s_z²)`; with the error
//!   convention `A_true = Rot(δθ) Â`, `∂(H,V)/∂δθ = ∂(H,V)/∂s · M_ASᵀ [b̂×]` (used by
//!   [`crate::mekf::Mekf::update_focal_plane`]).
//!
//! ## Validity checks (in this order)
//! VALID flag, TRACKING flag, every value finite, measured `|H_m|, |V_m| ≤ 4°` (plus half a
//! count for quantization), magnitude within `2.0 − m, 5.7 + m` with the margin
//! [`FHST_MAGNITUDE_MARGIN`].
//!
//! ## Noise
//! [`measurement_sigma_rad`] adds the count quantization (`q/√12` = 2.2″) in quadrature to the
//! table's magnitude-dependent σ (paper: FHST random error 8–24″ 1σ).

use crate::raw::{FhstSample, FHST_FLAG_NEW_STAR, FHST_FLAG_TRACKING, FHST_FLAG_VALID};
use crate::tables::types::{
    matrix_from_rows, AlignmentTable, FilterTable, Mat3Rows, SensorCorrections,
    FHST_MAGNITUDE_BIAS_REFERENCE_MAG,
};
use crate::units::{RAD_PER_ARCSEC, RAD_PER_DEG};
use nalgebra::{Matrix2x3, Matrix3, Vector3};

/// FHST resolution, rad per count (7.78″).
/// Paper: FHST resolution 7.78″/count.
pub const FHST_RAD_PER_COUNT: f64 = 7.78 * RAD_PER_ARCSEC;
/// Half-width of the square field of view, rad (4°).
/// Paper: FHST FOV 8° square.
pub const FHST_HALF_FIELD_RAD: f64 = 4.0 * RAD_PER_DEG;
/// Brightest magnitude the tracker acquires.
/// Paper: FHST magnitude range 2.0–5.7.
pub const FHST_MAGNITUDE_MIN: f64 = 2.0;
/// Faintest magnitude the tracker acquires.
/// Paper: FHST magnitude range 2.0–5.7.
pub const FHST_MAGNITUDE_MAX: f64 = 5.7;
/// Margin accepted around the magnitude window, mag (instrument magnitude noise).
/// Project choice (not in the paper): tolerates instrument-magnitude noise at the window edges.
pub const FHST_MAGNITUDE_MARGIN: f64 = 0.3;
/// Fixed-point iterations of [`apply_distortion`] (each gains a factor ≈ 3·d0·ρ² + 2·|d1,2|·ρ).
const DISTORTION_ITERATIONS: usize = 8;

/// Which tracker.
/// Paper: two FHSTs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FhstId {
    /// FHST1.
    /// Paper Table 1 (FHST1).
    Fhst1,
    /// FHST2.
    /// Paper Table 1 (FHST2).
    Fhst2,
}

impl FhstId {
    /// Both trackers, in order.
    /// Paper: two FHSTs.
    pub const ALL: [FhstId; 2] = [FhstId::Fhst1, FhstId::Fhst2];

    /// Index 0 or 1 (raw frame, correction arrays).
    /// Order of docs/icd.md §3.1 and docs/tables.md.
    #[must_use]
    pub const fn index(self) -> usize {
        match self {
            Self::Fhst1 => 0,
            Self::Fhst2 => 1,
        }
    }

    /// The tracker as one of the four aligned sensors.
    /// Paper Table 1.
    #[must_use]
    pub const fn sensor(self) -> crate::sensor::SensorId {
        match self {
            Self::Fhst1 => crate::sensor::SensorId::Fhst1,
            Self::Fhst2 => crate::sensor::SensorId::Fhst2,
        }
    }

    /// Active `M_AS` (sensor → ACS).
    /// Paper: `M_AS`, Table 1 at boot (docs/tables.md Table 1: alignment).
    #[must_use]
    pub fn m_acs_from_sensor(self, alignment: &AlignmentTable) -> Matrix3<f64> {
        match self {
            Self::Fhst1 => matrix_from_rows(&alignment.m_acs_from_fhst1),
            Self::Fhst2 => matrix_from_rows(&alignment.m_acs_from_fhst2),
        }
    }

    /// Distortion coefficients `[d0, d1, d2]` of this tracker.
    /// docs/tables.md (alignment table, `fhst_distortion`); effect 4 of algorithms.md §9.
    #[must_use]
    pub fn distortion(self, corrections: &SensorCorrections) -> [f64; 3] {
        let [d1, d2] = corrections.fhst_distortion;
        match self {
            Self::Fhst1 => d1,
            Self::Fhst2 => d2,
        }
    }

    /// Magnitude-bias coefficients `[b_H, b_V]` (rad/mag) of this tracker.
    /// docs/tables.md (alignment table, `fhst_magnitude_bias_rad_per_mag`); effect 5 of
    /// algorithms.md §9.
    #[must_use]
    pub fn magnitude_bias(self, corrections: &SensorCorrections) -> [f64; 2] {
        let [b1, b2] = corrections.fhst_magnitude_bias_rad_per_mag;
        match self {
            Self::Fhst1 => b1,
            Self::Fhst2 => b2,
        }
    }
}

/// A validated, corrected FHST measurement.
/// algorithms.md §3.1.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FhstMeasurement {
    /// Corrected horizontal focal-plane angle, rad.
    /// algorithms.md §3.1 (`H`).
    pub h_rad: f64,
    /// Corrected vertical focal-plane angle, rad.
    /// algorithms.md §3.1 (`V`).
    pub v_rad: f64,
    /// Star direction in sensor axes (unit).
    /// algorithms.md §3.1 (tangent-plane `s`).
    pub dir_sensor: Vector3<f64>,
    /// Star direction in ACS axes (unit), through the active alignment.
    /// `b = M_AS s` (paper `M_AS`; algorithms.md §1).
    pub dir_acs: Vector3<f64>,
    /// Instrument magnitude, mag.
    /// docs/icd.md §3.1; paper range 2.0–5.7.
    pub magnitude: f64,
    /// The tracker reports a new acquisition (star identification needed).
    /// docs/icd.md §3.1 (FHST new-star flag); star ID per algorithms.md §3.2.
    pub new_star: bool,
}

#[cfg(feature = "defmt")]
impl defmt::Format for FhstMeasurement {
    fn format(&self, f: defmt::Formatter) {
        defmt::write!(
            f,
            "FhstMeasurement {{ h: {}, v: {}, acs: {}, mag: {}, new: {} }}",
            self.h_rad,
            self.v_rad,
            [self.dir_acs.x, self.dir_acs.y, self.dir_acs.z],
            self.magnitude,
            self.new_star
        );
    }
}

/// Why a sample was not used.
/// Checks of algorithms.md §3.1 ("Validity checks").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FhstReject {
    /// VALID flag clear.
    /// docs/icd.md §3.1 (FHST flags bit0).
    NotValid,
    /// TRACKING flag clear (searching).
    /// docs/icd.md §3.1 (FHST flags bit1).
    NotTracking,
    /// A computed value is not finite (corrupt corrections).
    /// Project choice (not in the paper): a corrupt table must not reach the filter.
    NotFinite,
    /// Outside the ±4° field.
    /// Paper: FHST FOV 8° square; algorithms.md §3.1.
    OutOfField,
    /// Magnitude outside the acquisition window plus margin.
    /// Paper: FHST magnitude range 2.0–5.7; algorithms.md §3.1.
    MagnitudeOutOfRange,
}

impl FhstReject {
    /// The tracker simply has no star (not valid / not tracking): not an anomaly.
    /// Project choice (not in the paper): only anomalies raise an event.
    #[must_use]
    pub const fn is_no_data(self) -> bool {
        matches!(self, Self::NotValid | Self::NotTracking)
    }

    /// Event/telemetry code: 1 not valid, 2 not tracking, 3 not finite, 4 out of field,
    /// 5 magnitude.
    /// Reason code of event 0x0404, docs/icd.md §3.3.
    #[must_use]
    pub const fn code(self) -> u8 {
        match self {
            Self::NotValid => 1,
            Self::NotTracking => 2,
            Self::NotFinite => 3,
            Self::OutOfField => 4,
            Self::MagnitudeOutOfRange => 5,
        }
    }
}

/// Distortion correction: measured angles → true angles (rad), see the module docs.
/// docs/tables.md (alignment table, `fhst_distortion`); algorithms.md §9 effect 4.
#[must_use]
pub fn correct_distortion(h_m: f64, v_m: f64, d: &[f64; 3]) -> (f64, f64) {
    let [d0, d1, d2] = *d;
    let rho2 = h_m * h_m + v_m * v_m;
    let hv = h_m * v_m;
    (
        h_m - (d0 * rho2 * h_m + d1 * hv),
        v_m - (d0 * rho2 * v_m + d2 * hv),
    )
}

/// Inverse of [`correct_distortion`]: true angles → measured angles (rad), by fixed-point
/// iteration (converges geometrically inside the field for table-valid `|d| ≤ 1`).
/// docs/tables.md (alignment table, `fhst_distortion`).
#[must_use]
pub fn apply_distortion(h: f64, v: f64, d: &[f64; 3]) -> (f64, f64) {
    invert_correction(h, v, DISTORTION_ITERATIONS, |h_m, v_m| {
        correct_distortion(h_m, v_m, d)
    })
}

/// Measured angles whose correction `correct` gives the true angles `(h, v)` (rad): the
/// fixed-point iteration `m ← m + (true − correct(m))` from `m = true`, `iterations` times.
/// Shared by [`apply_distortion`] and the FSS's `apply_transfer_full`.
pub(crate) fn invert_correction(
    h: f64,
    v: f64,
    iterations: usize,
    correct: impl Fn(f64, f64) -> (f64, f64),
) -> (f64, f64) {
    let (mut h_m, mut v_m) = (h, v);
    for _ in 0..iterations {
        let (hc, vc) = correct(h_m, v_m);
        h_m += h - hc;
        v_m += v - vc;
    }
    (h_m, v_m)
}

/// Unit vector in sensor axes from tangent-plane angles (rad).
/// algorithms.md §3.1 (tangent-plane form; docs/conventions.md "Sensor geometry").
#[must_use]
pub fn dir_from_hv(h_rad: f64, v_rad: f64) -> Vector3<f64> {
    Vector3::new(libm::tan(h_rad), libm::tan(v_rad), 1.0).normalize()
}

/// Tangent-plane angles (rad) of a sensor-frame direction; `None` unless `s_z > 0` and finite.
/// algorithms.md §3.1 (tangent-plane form).
#[must_use]
pub fn hv_from_dir(s: &Vector3<f64>) -> Option<(f64, f64)> {
    if !(s.z > 0.0) || !s.iter().all(|x| x.is_finite()) {
        return None;
    }
    Some((libm::atan2(s.x, s.z), libm::atan2(s.y, s.z)))
}

/// `∂(H, V)/∂s` (2×3, rad per unit) at a sensor-frame direction (any length; `s_z ≠ 0`).
/// algorithms.md §3.1 ("Jacobians").
#[must_use]
pub fn hv_jacobian(s: &Vector3<f64>) -> Matrix2x3<f64> {
    let dh = s.x * s.x + s.z * s.z;
    let dv = s.y * s.y + s.z * s.z;
    Matrix2x3::new(s.z / dh, 0.0, -s.x / dh, 0.0, s.z / dv, -s.y / dv)
}

/// Predicted (corrected) focal-plane angles of an ACS direction seen through `M_AS`; `None`
/// if behind the sensor.
/// algorithms.md §3.1 with the paper's `M_AS`.
#[must_use]
pub fn predict_hv(dir_acs: &Vector3<f64>, m_acs_from_sensor: &Matrix3<f64>) -> Option<(f64, f64)> {
    hv_from_dir(&(m_acs_from_sensor.transpose() * dir_acs))
}

/// Measurement σ per axis (rad) for a star of `magnitude`: the table's σ(m) and the count
/// quantization `q/√12` in quadrature.
/// Paper: FHST random error 8–24″ 1σ; quantization per algorithms.md §3.1.
#[must_use]
pub fn measurement_sigma_rad(magnitude: f64, filter: &FilterTable) -> f64 {
    let s = filter.fhst_sigma_rad(magnitude);
    let q2 = FHST_RAD_PER_COUNT * FHST_RAD_PER_COUNT / 12.0;
    libm::sqrt(s * s + q2)
}

/// [`measure_corrected`] with the tracker's alignment, distortion and magnitude bias from the
/// alignment table, without the thermal drift (the alignment at `T = T_ref`; see
/// [`measure_tracker_at`]).
/// docs/tables.md (alignment table).
///
/// # Errors
/// As [`measure`].
pub fn measure_tracker(
    sample: &FhstSample,
    tracker: FhstId,
    alignment: &AlignmentTable,
) -> Result<FhstMeasurement, FhstReject> {
    let m = match tracker {
        FhstId::Fhst1 => &alignment.m_acs_from_fhst1,
        FhstId::Fhst2 => &alignment.m_acs_from_fhst2,
    };
    let c = &alignment.corrections;
    measure_corrected(
        sample,
        m,
        &tracker.distortion(c),
        &tracker.magnitude_bias(c),
    )
}

/// [`measure_tracker`] with the tracker's alignment at its temperature `temperature_c` (°C,
/// the raw frame's, docs/icd.md §3.1): every correction of the alignment table, as the OBC
/// applies them.
/// docs/tables.md (alignment table, fields 0–1, 5, 7–9).
///
/// # Errors
/// As [`measure`].
pub fn measure_tracker_at(
    sample: &FhstSample,
    tracker: FhstId,
    alignment: &AlignmentTable,
    temperature_c: f64,
) -> Result<FhstMeasurement, FhstReject> {
    let m = alignment.m_acs_from_sensor_rows_at(tracker.sensor(), temperature_c);
    let c = &alignment.corrections;
    measure_corrected(
        sample,
        &m,
        &tracker.distortion(c),
        &tracker.magnitude_bias(c),
    )
}

/// Convert and validate one tracker sample with the tracker's `M_AS` (table rows) and
/// distortion coefficients `[d0, d1, d2]` (no magnitude bias).
/// algorithms.md §3.1.
///
/// # Errors
/// The first failed check, see [`FhstReject`].
pub fn measure(
    sample: &FhstSample,
    m_acs_from_sensor: &Mat3Rows,
    distortion: &[f64; 3],
) -> Result<FhstMeasurement, FhstReject> {
    measure_corrected(sample, m_acs_from_sensor, distortion, &[0.0; 2])
}

/// Magnitude-bias correction: angles (rad) with the bias `b (m − 4)` of a star of instrument
/// magnitude `magnitude` removed, `b = [b_H, b_V]` in rad/mag.
/// docs/tables.md (alignment table, `fhst_magnitude_bias_rad_per_mag`); effect 5 of
/// algorithms.md §9.
#[must_use]
pub fn correct_magnitude_bias(h: f64, v: f64, magnitude: f64, bias: &[f64; 2]) -> (f64, f64) {
    let [b_h, b_v] = *bias;
    let dm = magnitude - FHST_MAGNITUDE_BIAS_REFERENCE_MAG;
    (h - b_h * dm, v - b_v * dm)
}

/// Convert and validate one tracker sample with the tracker's `M_AS` (table rows),
/// distortion coefficients `[d0, d1, d2]` and magnitude bias `[b_H, b_V]` (rad/mag).
/// algorithms.md §3.1; docs/tables.md (alignment table, fields 5 and 7).
///
/// # Errors
/// The first failed check, see [`FhstReject`].
pub fn measure_corrected(
    sample: &FhstSample,
    m_acs_from_sensor: &Mat3Rows,
    distortion: &[f64; 3],
    magnitude_bias: &[f64; 2],
) -> Result<FhstMeasurement, FhstReject> {
    if sample.flags & FHST_FLAG_VALID == 0 {
        return Err(FhstReject::NotValid);
    }
    if sample.flags & FHST_FLAG_TRACKING == 0 {
        return Err(FhstReject::NotTracking);
    }
    let h_m = f64::from(sample.h_counts) * FHST_RAD_PER_COUNT;
    let v_m = f64::from(sample.v_counts) * FHST_RAD_PER_COUNT;
    let magnitude = f64::from(sample.magnitude_centimag) * 0.01;
    let (h, v) = correct_distortion(h_m, v_m, distortion);
    let (h, v) = match *magnitude_bias {
        [b_h, b_v] if b_h != 0.0 || b_v != 0.0 => {
            correct_magnitude_bias(h, v, magnitude, magnitude_bias)
        }
        _ => (h, v),
    };
    let dir_sensor = dir_from_hv(h, v);
    let dir_acs = matrix_from_rows(m_acs_from_sensor) * dir_sensor;
    if !(h.is_finite() && v.is_finite() && dir_acs.iter().all(|x| x.is_finite())) {
        return Err(FhstReject::NotFinite);
    }
    let limit = FHST_HALF_FIELD_RAD + 0.5 * FHST_RAD_PER_COUNT;
    if !(h_m.abs() <= limit && v_m.abs() <= limit) {
        return Err(FhstReject::OutOfField);
    }
    let magnitudes =
        FHST_MAGNITUDE_MIN - FHST_MAGNITUDE_MARGIN..=FHST_MAGNITUDE_MAX + FHST_MAGNITUDE_MARGIN;
    if !magnitudes.contains(&magnitude) {
        return Err(FhstReject::MagnitudeOutOfRange);
    }
    Ok(FhstMeasurement {
        h_rad: h,
        v_rad: v,
        dir_sensor,
        dir_acs,
        magnitude,
        new_star: sample.flags & FHST_FLAG_NEW_STAR != 0,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::attitude::skew;

    fn sample(h: i16, v: i16, mag: i16) -> FhstSample {
        FhstSample {
            h_counts: h,
            v_counts: v,
            magnitude_centimag: mag,
            flags: FHST_FLAG_VALID | FHST_FLAG_TRACKING,
        }
    }

    #[test]
    fn boresight_maps_to_sensor_z_column() {
        let al = AlignmentTable::prelaunch();
        for id in FhstId::ALL {
            let m = measure_tracker(&sample(0, 0, 400), id, &al).unwrap();
            let z = id.m_acs_from_sensor(&al).column(2).into_owned();
            assert!((m.dir_acs - z).norm() < 1e-15);
            assert!(!m.new_star);
        }
    }

    #[test]
    fn tangent_plane_round_trip_and_sign() {
        let s = dir_from_hv(0.05, -0.03);
        assert!(s.x > 0.0 && s.y < 0.0);
        let (h, v) = hv_from_dir(&s).unwrap();
        assert!((h - 0.05).abs() < 1e-15 && (v + 0.03).abs() < 1e-15);
        assert!(hv_from_dir(&Vector3::new(0.0, 0.0, -1.0)).is_none());
        // Counts: 100 counts = 778 arcsec.
        let al = AlignmentTable::prelaunch();
        let m = measure(&sample(100, -50, 300), &al.m_acs_from_fhst1, &[0.0; 3]).unwrap();
        assert!((m.h_rad - 778.0 * RAD_PER_ARCSEC).abs() < 1e-15);
        assert!((m.v_rad + 389.0 * RAD_PER_ARCSEC).abs() < 1e-15);
    }

    #[test]
    fn distortion_inverse_round_trip() {
        let d = [0.8, -0.02, 0.03];
        for (h, v) in [(0.06, 0.06), (-0.069, 0.01), (0.0, -0.05)] {
            let (hm, vm) = apply_distortion(h, v, &d);
            let (hc, vc) = correct_distortion(hm, vm, &d);
            assert!(
                (hc - h).abs() < 1e-15 && (vc - v).abs() < 1e-15,
                "{} {}",
                hc - h,
                vc - v
            );
        }
        // Zero coefficients: identity.
        assert_eq!(correct_distortion(0.01, 0.02, &[0.0; 3]), (0.01, 0.02));
    }

    #[test]
    fn jacobian_matches_finite_differences_and_attitude_form() {
        let s = dir_from_hv(0.04, -0.06);
        let j = hv_jacobian(&s);
        for k in 0..3 {
            let mut e = Vector3::zeros();
            e[k] = 1e-7;
            let (hp, vp) = hv_from_dir(&(s + e)).unwrap();
            let (hm, vm) = hv_from_dir(&(s - e)).unwrap();
            assert!(((hp - hm) / 2e-7 - j[(0, k)]).abs() < 1e-6);
            assert!(((vp - vm) / 2e-7 - j[(1, k)]).abs() < 1e-6);
        }
        // ∂(H,V)/∂δθ = J Mᵀ [b̂×] against the exact Rot(δθ).
        let al = AlignmentTable::prelaunch();
        let m = FhstId::Fhst2.m_acs_from_sensor(&al);
        let b = m * s;
        let jt = j * m.transpose() * skew(&b);
        let dth = Vector3::new(2e-6, -1e-6, 3e-6);
        let b2 = crate::attitude::rot(&dth) * b;
        let (h2, v2) = hv_from_dir(&(m.transpose() * b2)).unwrap();
        let (h1, v1) = hv_from_dir(&(m.transpose() * b)).unwrap();
        let lin = jt * dth;
        // Second-order terms are ~|δθ|² = 1.4e-11.
        assert!(
            (h2 - h1 - lin.x).abs() < 5e-11 && (v2 - v1 - lin.y).abs() < 5e-11,
            "{} {}",
            h2 - h1 - lin.x,
            v2 - v1 - lin.y
        );
    }

    #[test]
    fn checks_reject_in_order() {
        let al = AlignmentTable::prelaunch();
        let mut s = sample(0, 0, 400);
        s.flags = FHST_FLAG_TRACKING;
        assert_eq!(
            measure_tracker(&s, FhstId::Fhst1, &al),
            Err(FhstReject::NotValid)
        );
        s.flags = FHST_FLAG_VALID;
        assert_eq!(
            measure_tracker(&s, FhstId::Fhst1, &al),
            Err(FhstReject::NotTracking)
        );
        // 4 deg = 1850.9 counts: 1851 accepted (half-count margin), 1852 rejected.
        assert!(measure_tracker(&sample(1851, 0, 400), FhstId::Fhst1, &al).is_ok());
        assert_eq!(
            measure_tracker(&sample(0, -1852, 400), FhstId::Fhst1, &al),
            Err(FhstReject::OutOfField)
        );
        assert_eq!(
            measure_tracker(&sample(0, 0, 600 + 1), FhstId::Fhst1, &al),
            Err(FhstReject::MagnitudeOutOfRange)
        );
        assert_eq!(
            measure_tracker(&sample(0, 0, 169), FhstId::Fhst1, &al),
            Err(FhstReject::MagnitudeOutOfRange)
        );
        assert!(measure_tracker(&sample(0, 0, 170), FhstId::Fhst1, &al).is_ok());
        let mut bad = al;
        bad.corrections.fhst_distortion[1] = [f64::NAN, 0.0, 0.0];
        assert_eq!(
            measure_tracker(&sample(10, 10, 400), FhstId::Fhst2, &bad),
            Err(FhstReject::NotFinite)
        );
        assert!(FhstReject::NotTracking.is_no_data() && !FhstReject::OutOfField.is_no_data());
        let mut s = sample(0, 0, 400);
        s.flags |= FHST_FLAG_NEW_STAR;
        assert!(measure_tracker(&s, FhstId::Fhst2, &al).unwrap().new_star);
    }

    /// The truth model's bias (sim-harness `magnitude_bias_arcsec_per_mag`: the measured angle
    /// is the true one plus `b (m − 4)`) is removed by the table term of the same sign.
    #[test]
    fn magnitude_bias_removed_with_the_truth_models_sign() {
        let mut al = AlignmentTable::prelaunch();
        let b = [2.5 * RAD_PER_ARCSEC, -1.5 * RAD_PER_ARCSEC];
        al.corrections.fhst_magnitude_bias_rad_per_mag[0] = b;
        let s = sample(200, -100, 550);
        let plain = measure_tracker(&s, FhstId::Fhst1, &AlignmentTable::prelaunch()).unwrap();
        let m = measure_tracker(&s, FhstId::Fhst1, &al).unwrap();
        // m − 4 = 1.5 mag: H by −3.75″, V by +2.25″.
        assert!((m.h_rad - (plain.h_rad - 3.75 * RAD_PER_ARCSEC)).abs() < 1e-15);
        assert!((m.v_rad - (plain.v_rad + 2.25 * RAD_PER_ARCSEC)).abs() < 1e-15);
        // The other tracker and the reference magnitude are unaffected.
        assert_eq!(
            measure_tracker(&s, FhstId::Fhst2, &al),
            measure_tracker(&s, FhstId::Fhst2, &AlignmentTable::prelaunch())
        );
        let at_ref = sample(200, -100, 400);
        assert_eq!(
            measure_tracker(&at_ref, FhstId::Fhst1, &al),
            measure_tracker(&at_ref, FhstId::Fhst1, &AlignmentTable::prelaunch())
        );
        // Truth angle + bias, read back through the correction: the truth (no quantization).
        let (h, v) = (0.031, -0.012);
        let (hm, vm) = (h + b[0] * (5.2 - 4.0), v + b[1] * (5.2 - 4.0));
        let (hc, vc) = correct_magnitude_bias(hm, vm, 5.2, &b);
        assert!((hc - h).abs() < 1e-17 && (vc - v).abs() < 1e-17);
    }

    /// The thermal drift rotates the tracker's alignment as the truth model does
    /// (`M(T) = Rot(k ΔT) M`): a star on the boresight is seen along the rotated boresight.
    #[test]
    fn thermal_drift_rotates_the_tracker_alignment() {
        let mut al = AlignmentTable::prelaunch();
        let k = [0.0, 0.0, 4.0 * RAD_PER_ARCSEC];
        al.corrections.thermal_alignment_rad_per_c[1] = k;
        al.corrections.thermal_reference_c[1] = 17.0;
        let s = sample(0, 0, 400);
        let m = measure_tracker_at(&s, FhstId::Fhst2, &al, 19.5).unwrap();
        let z = crate::attitude::rot(&(Vector3::from(k) * 2.5))
            * FhstId::Fhst2.m_acs_from_sensor(&al).column(2);
        assert!((m.dir_acs - z).norm() < 1e-15);
        // At the reference temperature, or without a coefficient: the stored alignment.
        assert_eq!(
            measure_tracker_at(&s, FhstId::Fhst2, &al, 17.0),
            measure_tracker(&s, FhstId::Fhst2, &al)
        );
        assert_eq!(
            measure_tracker_at(&s, FhstId::Fhst1, &al, 40.0),
            measure_tracker(&s, FhstId::Fhst1, &al)
        );
    }

    #[test]
    fn predict_inverts_measure() {
        let al = AlignmentTable::prelaunch();
        let m = measure_tracker(&sample(-1200, 900, 450), FhstId::Fhst2, &al).unwrap();
        let (h, v) = predict_hv(&m.dir_acs, &FhstId::Fhst2.m_acs_from_sensor(&al)).unwrap();
        // The published M_AS is orthonormal only to ~1e-9, so Mᵀ is not exactly M⁻¹.
        assert!((h - m.h_rad).abs() < 1e-8 && (v - m.v_rad).abs() < 1e-8);
        let sig = measurement_sigma_rad(2.0, &FilterTable::default_boot());
        assert!((sig / RAD_PER_ARCSEC - (64.0_f64 + 7.78 * 7.78 / 12.0).sqrt()).abs() < 1e-9);
    }
}
