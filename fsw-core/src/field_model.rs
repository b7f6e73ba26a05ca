//! # The onboard geomagnetic field model: spherical-harmonic synthesis and Earth orientation
//!
//! Why on board: the coarse attitude (`crate::coarse`) compares the field the TAMs measure with
//! the field the spacecraft should see at its onboard-orbit position; that reference has to be
//! computed where the measurement is. This is an implementation of its own, independent of the
//! ground's `gro_reference::field` (which the simulator's truth uses), so that a test comparing
//! the two checks both.
//!
//! * Coefficients: the magnetics table's Schmidt semi-normalised `g`, `h` (nT) at its epoch plus
//!   secular variation times the Julian years since it, refused beyond
//!   [`MAX_EXTRAPOLATION_YEARS`] (IGRF's own span for its secular variation).
//! * Synthesis: Gauss-normalised associated Legendre functions and their θ derivatives by the
//!   recursion of Wertz (ed.), *Spacecraft Attitude Determination and Control* (1978), app. H,
//!   with the Gauss → Schmidt factors formed row by row; reference radius 6371.2 km.
//! * Frames: GCRS/J2000 → true of date by the table's precession-nutation matrix, then about
//!   the pole by the apparent sidereal time (IAU 1982 GMST of UT1 plus the table's equation of
//!   the equinoxes; Meeus, *Astronomical Algorithms*, ch. 12) to Earth-fixed axes; polar
//!   motion (≤ 0.3″) is ignored.
//!
//! Cost: degree 10 is ≈ 60 multiply-adds per (n, m), a few thousand instructions, which is
//! why the coarse attitude fixes only every `coarse_fix_every_n_cycles`.

use nalgebra::{Matrix3, Vector3};

use crate::tables::magnetics::{matrix, MagneticsTable, FIELD_MAX_DEGREE, FIELD_N1};

/// IGRF reference radius, km.
/// Wertz (1978) app. H; IAGA IGRF (a = 6371.2 km).
pub const REFERENCE_RADIUS_KM: f64 = 6_371.2;
/// Julian year, s.
/// IAU (365.25 d of 86,400 s).
pub const JULIAN_YEAR_S: f64 = 365.25 * 86_400.0;
/// Largest time from the table's epoch at which the model is evaluated, Julian years.
/// Project choice after IAGA IGRF (secular variation predicts 5 years).
pub const MAX_EXTRAPOLATION_YEARS: f64 = 5.0;
/// TT − TAI, s.
/// IAU (TT = TAI + 32.184 s).
pub const TT_MINUS_TAI_S: f64 = 32.184;
/// Smallest radius at which the model is evaluated, km (below it the position is wrong).
/// Project choice: the onboard orbit's own floor, [`crate::orbit::MIN_RADIUS_KM`].
pub const MIN_RADIUS_KM: f64 = crate::orbit::MIN_RADIUS_KM;
/// Largest radius at which the model is evaluated, km.
/// Project choice: the onboard orbit's own ceiling, [`crate::orbit::MAX_RADIUS_KM`].
pub const MAX_RADIUS_KM: f64 = crate::orbit::MAX_RADIUS_KM;

/// Why no field was computed.
/// Project choice (not in the paper): typed reasons the coarse attitude reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FieldModelError {
    /// The active magnetics table holds no field model (degree 0, the boot table).
    /// docs/tables.md (Table 6, field 0).
    NoModel,
    /// The time is more than [`MAX_EXTRAPOLATION_YEARS`] from the coefficients' epoch.
    /// Project choice after the IAGA IGRF secular-variation span.
    OutsideSpan,
    /// The position's radius is outside [`MIN_RADIUS_KM`]..=[`MAX_RADIUS_KM`] or not finite.
    /// Project choice (the onboard orbit's range).
    BadPosition,
    /// The synthesis gave a non-finite value.
    /// Project choice (defensive check).
    NotFinite,
}

/// Greenwich apparent sidereal time, rad in [0, 2π): IAU 1982 GMST of UT1 plus the table's
/// equation of the equinoxes. `t_s` is seconds since J2000.0 TT.
/// Meeus, *Astronomical Algorithms* (1998) eq. 12.4; IERS (UT1).
#[must_use]
pub fn gast_rad(table: &MagneticsTable, t_s: f64) -> f64 {
    // Days of UT1 since JD 2451545.0 UT1.
    let d = (t_s - TT_MINUS_TAI_S + table.ut1_minus_tai_s) / 86_400.0;
    let t = d / 36_525.0;
    // 360.98564736629 d split as 360 d + 0.98564736629 d keeps the precision of the fraction.
    let whole_turns_deg = 360.0 * (d - libm::floor(d));
    let deg = 280.460_618_37 + whole_turns_deg + 0.985_647_366_29 * d + 0.000_387_933 * t * t
        - t * t * t / 38_710_000.0;
    // `x − y⌊x/y⌋`, not `libm::fmod`: its integer reduction keeps panic paths
    // (scripts/no-panic-check.sh).
    let rad = wrap(deg, 360.0).to_radians() + table.equation_of_equinoxes_rad;
    wrap(rad, 2.0 * core::f64::consts::PI)
}

/// `x` reduced to `[0, period)`.
fn wrap(x: f64, period: f64) -> f64 {
    let r = x - period * libm::floor(x / period);
    if r >= period || r < 0.0 {
        0.0
    } else {
        r
    }
}

/// Rotation from J2000/GCRS axes to Earth-fixed axes at `t_s` (s since J2000.0 TT):
/// `R3(GAST) · M_tod_from_eci`.
/// Meeus ch. 12 (GAST), ch. 21–22 (precession, nutation: the table's matrix).
#[must_use]
pub fn m_itrs_from_eci(table: &MagneticsTable, t_s: f64) -> Matrix3<f64> {
    let theta = gast_rad(table, t_s);
    let (s, c) = (libm::sin(theta), libm::cos(theta));
    let r3 = Matrix3::new(c, s, 0.0, -s, c, 0.0, 0.0, 0.0, 1.0);
    r3 * matrix(&table.m_tod_from_eci)
}

fn coefficient(rows: &[[f64; FIELD_N1]; FIELD_N1], n: usize, m: usize) -> f64 {
    rows.get(n).and_then(|r| r.get(m)).copied().unwrap_or(0.0)
}

fn set(row: &mut [f64; FIELD_N1], m: usize, value: f64) {
    if let Some(x) = row.get_mut(m) {
        *x = value;
    }
}

fn get(row: &[f64; FIELD_N1], m: usize) -> f64 {
    row.get(m).copied().unwrap_or(0.0)
}

/// The field on Earth-fixed axes (nT) at the Earth-fixed position `pos_itrs_km`, at `t_s`
/// (s since J2000.0 TT, for the secular variation).
/// Wertz (1978) app. H (Gauss-normalised recursion, Schmidt factors); IAGA IGRF.
///
/// # Errors
/// [`FieldModelError`]: no model, outside the span, a bad position, a non-finite result.
pub fn field_itrs_nt(
    table: &MagneticsTable,
    pos_itrs_km: &Vector3<f64>,
    t_s: f64,
) -> Result<Vector3<f64>, FieldModelError> {
    let degree = usize::from(table.field_degree).min(FIELD_MAX_DEGREE);
    if degree == 0 {
        return Err(FieldModelError::NoModel);
    }
    let years = (t_s - table.field_epoch_s_since_j2000_tt) / JULIAN_YEAR_S;
    if !(years.abs() <= MAX_EXTRAPOLATION_YEARS) {
        return Err(FieldModelError::OutsideSpan);
    }
    let r = pos_itrs_km.norm();
    if !(MIN_RADIUS_KM..=MAX_RADIUS_KM).contains(&r) {
        return Err(FieldModelError::BadPosition);
    }
    let rho = libm::hypot(pos_itrs_km.x, pos_itrs_km.y);
    let (st_true, ct) = (rho / r, pos_itrs_km.z / r);
    let (sl, cl) = if rho > 0.0 {
        (pos_itrs_km.y / rho, pos_itrs_km.x / rho)
    } else {
        (0.0, 1.0)
    };
    let st = st_true.max(1e-9);

    let mut cos_m = [0.0; FIELD_N1];
    let mut sin_m = [0.0; FIELD_N1];
    set(&mut cos_m, 0, 1.0);
    for m in 1..FIELD_N1 {
        let (c, s) = (
            get(&cos_m, m.saturating_sub(1)),
            get(&sin_m, m.saturating_sub(1)),
        );
        set(&mut cos_m, m, c * cl - s * sl);
        set(&mut sin_m, m, s * cl + c * sl);
    }
    // Rows n − 2 and n − 1 of the Gauss-normalised P and dP/dθ, and row n − 1 of the Schmidt
    // factors' first column.
    let (mut p2, mut dp2) = ([0.0; FIELD_N1], [0.0; FIELD_N1]);
    let (mut p1, mut dp1) = ([0.0; FIELD_N1], [0.0; FIELD_N1]);
    set(&mut p1, 0, 1.0);
    let mut schmidt_n0 = 1.0;
    let ratio = REFERENCE_RADIUS_KM / r;
    let mut ratio_pow = ratio * ratio;
    let (mut b_r, mut b_theta, mut b_phi) = (0.0, 0.0, 0.0);
    for n in 1..FIELD_N1 {
        if n > degree {
            break;
        }
        let nf = n as f64;
        let mut p = [0.0; FIELD_N1];
        let mut dp = [0.0; FIELD_N1];
        for m in 0..n {
            let mf = m as f64;
            let k = if n > 1 {
                ((nf - 1.0) * (nf - 1.0) - mf * mf) / ((2.0 * nf - 1.0) * (2.0 * nf - 3.0))
            } else {
                0.0
            };
            set(&mut p, m, ct * get(&p1, m) - k * get(&p2, m));
            set(
                &mut dp,
                m,
                ct * get(&dp1, m) - st * get(&p1, m) - k * get(&dp2, m),
            );
        }
        set(&mut p, n, st * get(&p1, n.saturating_sub(1)));
        set(
            &mut dp,
            n,
            st * get(&dp1, n.saturating_sub(1)) + ct * get(&p1, n.saturating_sub(1)),
        );
        ratio_pow *= ratio;
        schmidt_n0 *= (2.0 * nf - 1.0) / nf;
        let mut schmidt = schmidt_n0;
        let (mut sr, mut s_theta, mut s_phi) = (0.0, 0.0, 0.0);
        for m in 0..=n {
            let mf = m as f64;
            if m > 0 {
                let double = if m == 1 { 2.0 } else { 1.0 };
                schmidt *= libm::sqrt((nf - mf + 1.0) * double / (nf + mf));
            }
            let g = schmidt
                * (coefficient(&table.g_nt, n, m)
                    + years * coefficient(&table.g_nt_per_year, n, m));
            let h = schmidt
                * (coefficient(&table.h_nt, n, m)
                    + years * coefficient(&table.h_nt_per_year, n, m));
            let (cm, sm) = (get(&cos_m, m), get(&sin_m, m));
            let gh = g * cm + h * sm;
            sr += gh * get(&p, m);
            s_theta += gh * get(&dp, m);
            s_phi += mf * (-g * sm + h * cm) * get(&p, m);
        }
        b_r += ratio_pow * (nf + 1.0) * sr;
        b_theta -= ratio_pow * s_theta;
        b_phi -= ratio_pow * s_phi;
        p2 = p1;
        dp2 = dp1;
        p1 = p;
        dp1 = dp;
    }
    let b_phi = b_phi / st;
    let r_hat = Vector3::new(st_true * cl, st_true * sl, ct);
    let theta_hat = Vector3::new(ct * cl, ct * sl, -st_true);
    let phi_hat = Vector3::new(-sl, cl, 0.0);
    let b = r_hat * b_r + theta_hat * b_theta + phi_hat * b_phi;
    if b.iter().all(|x| x.is_finite()) {
        Ok(b)
    } else {
        Err(FieldModelError::NotFinite)
    }
}

/// The field on J2000/GCRS axes (nT) at the J2000 position `pos_eci_km` and time `t_s`
/// (s since J2000.0 TT).
/// Wertz (1978) app. H ([`field_itrs_nt`]) through Meeus ch. 12 ([`m_itrs_from_eci`]).
///
/// # Errors
/// As [`field_itrs_nt`].
pub fn field_eci_nt(
    table: &MagneticsTable,
    pos_eci_km: &Vector3<f64>,
    t_s: f64,
) -> Result<Vector3<f64>, FieldModelError> {
    if !pos_eci_km.iter().all(|x| x.is_finite()) || !t_s.is_finite() {
        return Err(FieldModelError::BadPosition);
    }
    let m = m_itrs_from_eci(table, t_s);
    let b_itrs = field_itrs_nt(table, &(m * pos_eci_km), t_s)?;
    Ok(m.transpose() * b_itrs)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A centred dipole (g10 only) gives the textbook field: at the magnetic equator
    /// B = −g10 (a/r)³ along −θ̂ (northward), at the pole 2 g10 (a/r)³ radially.
    #[test]
    fn dipole_matches_closed_form() {
        let mut t = MagneticsTable::boot();
        t.field_degree = 1;
        t.g_nt[1][0] = -29_775.0;
        let r = 7_000.0;
        let k = (REFERENCE_RADIUS_KM / r).powi(3);
        let eq = field_itrs_nt(&t, &Vector3::new(r, 0.0, 0.0), 0.0).unwrap();
        assert!(
            (eq - Vector3::new(0.0, 0.0, 29_775.0 * k)).norm() < 1e-6,
            "{eq}"
        );
        let pole = field_itrs_nt(&t, &Vector3::new(0.0, 0.0, r), 0.0).unwrap();
        assert!(
            (pole - Vector3::new(0.0, 0.0, -2.0 * 29_775.0 * k)).norm() < 1e-3,
            "{pole}"
        );
    }

    #[test]
    fn refusals_are_typed() {
        let mut t = MagneticsTable::boot();
        let p = Vector3::new(7_000.0, 0.0, 0.0);
        assert_eq!(field_itrs_nt(&t, &p, 0.0), Err(FieldModelError::NoModel));
        t.field_degree = 1;
        t.g_nt[1][0] = -29_775.0;
        assert_eq!(
            field_itrs_nt(&t, &p, 6.0 * JULIAN_YEAR_S),
            Err(FieldModelError::OutsideSpan)
        );
        assert_eq!(
            field_itrs_nt(&t, &Vector3::new(100.0, 0.0, 0.0), 0.0),
            Err(FieldModelError::BadPosition)
        );
        assert_eq!(
            field_eci_nt(&t, &Vector3::new(f64::NAN, 0.0, 0.0), 0.0),
            Err(FieldModelError::BadPosition)
        );
    }

    /// GMST at 1987-04-10 0h UT1 is 13h10m46.3668s (Meeus example 12.a).
    #[test]
    fn gmst_matches_meeus_example() {
        // JD 2446895.5 UT1; with UT1 − TAI = 0 the instant is that many days plus TT − TAI.
        let tab = MagneticsTable::boot();
        let d = 2_446_895.5 - 2_451_545.0;
        let t_s = d * 86_400.0 + TT_MINUS_TAI_S;
        let want = (13.0 + 10.0 / 60.0 + 46.3668 / 3600.0) * 15.0_f64.to_radians();
        let got = gast_rad(&tab, t_s);
        assert!((got - want).abs() < 1e-7, "{got} {want}");
    }
}
