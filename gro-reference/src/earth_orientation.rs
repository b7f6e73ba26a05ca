//! # Earth orientation: GCRS (J2000/ICRS axes) ↔ ITRS (Earth-fixed), for the geomagnetic field
//!
//! Why: the field model ([`crate::field`]) is Earth-fixed, the orbit and the attitude are in
//! the simulation's inertial frame (`eci` = J2000/ICRS axes). At GRO's 450 km the field's
//! gradient is about 3|B|/r ≈ 18 nT/km and its direction turns 1″ per ~30 m along track, so
//! the rotation must be good to a few arcseconds for the frame to cost under 1 nT.
//!
//! # Model (the classical IAU 1976/1980/1982 chain of the 1991 era)
//! `r_itrs = R3(GAST) · N · P · r_gcrs`, no polar motion (|x_p|, |y_p| ≤ 0.3″ in 1991;
//! the reference file `data/igrf_reference.csv` omits it too), no frame bias (23 mas):
//! - `P`: IAU 1976 precession (Lieske 1977), [`crate::sun::m_mod_from_j2000`].
//! - `N = R1(−ε − Δε) R3(−Δψ) R1(ε)`: IAU 1980 nutation, the 13 largest terms of Meeus,
//!   *Astronomical Algorithms* (2nd ed., 1998), table 22.A, with his fundamental arguments
//!   (his ch. 22 polynomials). The omitted terms are each ≤ 0.0063″ in Δψ (together 0.015″
//!   in Meeus's example 22.a).
//! - GAST = GMST (IAU 1982, Meeus eq. 12.4 in UT1) + Δψ cos ε + 0.00264″ sin Ω (the IAU 1994
//!   equation of the equinoxes' leading complementary term).
//! - UT1 = UTC + (UT1 − UTC) from the IERS daily values in `data/ut1_utc_1991.csv`
//!   (1991-01-01 .. 1992-06-30), interpolated linearly; outside that span the nearest end
//!   value is held (|UT1 − UTC| < 0.9 s always: at most 13.5″ of Earth rotation).
//!
//! Accuracy: against Skyfield's IAU 2006/2000A chain with the same UT1 (the ITRS positions in
//! `data/igrf_reference.csv`) the test `val_gcrs_to_itrs_against_skyfield` measures the
//! angle directly (0.006″ max, 0.13 m at 6833 km); the model differences (IAU 1980 vs 2000A
//! nutation, frame bias, the truncated series) are at most tens of milliarcseconds, i.e.
//! metres at GRO's radius.

use hifitime::Epoch;
use nalgebra::{Matrix3, Vector3};

use crate::data::CsvTable;
use crate::sun::{m_mod_from_j2000, mean_obliquity_rad, r1, r3};
use crate::time::{j2000_tt_s, S_PER_JULIAN_CENTURY};
use fsw_core::units::{RAD_PER_ARCSEC, RAD_PER_DEG};

/// IERS UT1 − UTC, daily, 1991-01-01 .. 1992-06-30 (`data/ut1_utc_1991.csv`, provenance in
/// its header and `data/README.md`).
pub const UT1_UTC_CSV: &str = include_str!("../../data/ut1_utc_1991.csv");

/// Rate of Greenwich sidereal time per second of UT1 (rad/s): 1.002 737 909 35 turns per
/// UT1 day (the IAU 1982 GMST rate, Meeus eq. 12.4's 360.985 647 366 29°/d). Used to carry
/// GAST over a few minutes in [`crate::field::FieldEvaluator`].
pub const SIDEREAL_RATE_RAD_PER_S: f64 = 360.985_647_366_29 / 86_400.0 * RAD_PER_DEG;

/// MJD (UTC) of 1991-01-01, the first row of [`UT1_UTC_CSV`].
const UT1_TABLE_FIRST_MJD: f64 = 48_257.0;

/// The daily UT1 − UTC table, parsed once.
fn ut1_table() -> &'static [f64] {
    static TABLE: std::sync::OnceLock<Vec<f64>> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| parse_ut1_table(UT1_UTC_CSV).unwrap_or_default())
}

/// Parse the UT1 − UTC table: consecutive days from [`UT1_TABLE_FIRST_MJD`].
fn parse_ut1_table(text: &str) -> anyhow::Result<Vec<f64>> {
    let t = CsvTable::parse(text, "data/ut1_utc_1991.csv")?;
    let (mjd_col, dut_col) = (t.column("mjd_utc")?, t.column("ut1_minus_utc_s")?);
    let mut out = Vec::with_capacity(t.len());
    for row in 0..t.len() {
        let mjd = t.f64(row, mjd_col)?;
        if mjd != UT1_TABLE_FIRST_MJD + row as f64 {
            anyhow::bail!("data/ut1_utc_1991.csv: row {row} has MJD {mjd}, not consecutive");
        }
        out.push(t.f64(row, dut_col)?);
    }
    Ok(out)
}

/// UT1 − UTC (s) at `epoch`: the IERS daily values interpolated linearly; the nearest end
/// value outside 1991-01-01 .. 1992-06-30.
#[must_use]
pub fn ut1_minus_utc_s(epoch: Epoch) -> f64 {
    let table = ut1_table();
    let Some(last) = table.len().checked_sub(1) else {
        return 0.0;
    };
    let x = (epoch.to_mjd_utc_days() - UT1_TABLE_FIRST_MJD).clamp(0.0, last as f64);
    let i = (x.floor() as usize).min(last.saturating_sub(1));
    let f = x - i as f64;
    let a = table.get(i).copied().unwrap_or(0.0);
    let b = table.get(i + 1).copied().unwrap_or(a);
    a + (b - a) * f
}

/// IAU 1980 nutation in longitude and obliquity (rad), 13 largest terms (Meeus table 22.A).
/// `t_cy`: Julian centuries TT since J2000.
#[must_use]
pub fn nutation_rad(t_cy: f64) -> (f64, f64) {
    let t = t_cy;
    let (t2, t3) = (t * t, t * t * t);
    // Fundamental arguments (deg), Meeus ch. 22.
    let d = 297.850_36 + 445_267.111_480 * t - 0.001_914_2 * t2 + t3 / 189_474.0;
    let m_sun = 357.527_72 + 35_999.050_340 * t - 0.000_160_3 * t2 - t3 / 300_000.0;
    let m_moon = 134.962_98 + 477_198.867_398 * t + 0.008_697_2 * t2 + t3 / 56_250.0;
    let f = 93.271_91 + 483_202.017_538 * t - 0.003_682_5 * t2 + t3 / 327_270.0;
    let om = 125.044_52 - 1_934.136_261 * t + 0.002_070_8 * t2 + t3 / 450_000.0;
    // (D, M, M', F, Ω multipliers; Δψ = (s0 + s1 T) sin, Δε = (c0 + c1 T) cos), 0.0001″.
    const TERMS: [([i8; 5], f64, f64, f64, f64); 13] = [
        ([0, 0, 0, 0, 1], -171_996.0, -174.2, 92_025.0, 8.9),
        ([-2, 0, 0, 2, 2], -13_187.0, -1.6, 5_736.0, -3.1),
        ([0, 0, 0, 2, 2], -2_274.0, -0.2, 977.0, -0.5),
        ([0, 0, 0, 0, 2], 2_062.0, 0.2, -895.0, 0.5),
        ([0, 1, 0, 0, 0], 1_426.0, -3.4, 54.0, -0.1),
        ([0, 0, 1, 0, 0], 712.0, 0.1, -7.0, 0.0),
        ([-2, 1, 0, 2, 2], -517.0, 1.2, 224.0, -0.6),
        ([0, 0, 0, 2, 1], -386.0, -0.4, 200.0, 0.0),
        ([0, 0, 1, 2, 2], -301.0, 0.0, 129.0, -0.1),
        ([-2, -1, 0, 2, 2], 217.0, -0.5, -95.0, 0.3),
        ([-2, 0, 1, 0, 0], -158.0, 0.0, 0.0, 0.0),
        ([-2, 0, 0, 2, 1], 129.0, 0.1, -70.0, 0.0),
        ([0, 0, -1, 2, 2], 123.0, 0.0, -53.0, 0.0),
    ];
    let args = [d, m_sun, m_moon, f, om];
    let (mut dpsi, mut deps) = (0.0, 0.0);
    for (mult, s0, s1, c0, c1) in TERMS {
        let arg_deg: f64 = mult.iter().zip(args).map(|(&k, a)| f64::from(k) * a).sum();
        let (s, c) = (arg_deg * RAD_PER_DEG).sin_cos();
        dpsi += (s0 + s1 * t) * s;
        deps += (c0 + c1 * t) * c;
    }
    let unit = 1e-4 * RAD_PER_ARCSEC;
    (dpsi * unit, deps * unit)
}

/// Longitude of the Moon's ascending node Ω (rad), Meeus ch. 22.
fn moon_node_rad(t_cy: f64) -> f64 {
    (125.044_52 - 1_934.136_261 * t_cy + 0.002_070_8 * t_cy * t_cy) * RAD_PER_DEG
}

/// Greenwich mean sidereal time (rad, in [0, 2π)), IAU 1982 (Meeus eq. 12.4), from the UT1
/// Julian date.
#[must_use]
pub fn gmst_rad(jd_ut1: f64) -> f64 {
    let d = jd_ut1 - 2_451_545.0;
    let t = d / 36_525.0;
    // Split 360.98564736629 d into whole turns and the remainder to keep precision.
    let deg = 280.460_618_37 + 0.985_647_366_29 * d + 360.0 * d.fract() + 0.000_387_933 * t * t
        - t * t * t / 38_710_000.0;
    deg.rem_euclid(360.0) * RAD_PER_DEG
}

/// Greenwich apparent sidereal time (rad) at `epoch`: GMST + equation of the equinoxes,
/// with UT1 − UTC from the IERS table ([`ut1_minus_utc_s`]).
#[must_use]
pub fn gast_rad(epoch: Epoch) -> f64 {
    gast_with_dut1_rad(epoch, ut1_minus_utc_s(epoch))
}

/// [`gast_rad`] with a given UT1 − UTC (s).
#[must_use]
pub fn gast_with_dut1_rad(epoch: Epoch, ut1_minus_utc_s: f64) -> f64 {
    let t_cy = j2000_tt_s(epoch) / S_PER_JULIAN_CENTURY;
    let (dpsi, _) = nutation_rad(t_cy);
    let jd_ut1 = epoch.to_jde_utc_days() + ut1_minus_utc_s / 86_400.0;
    let eq_eq = dpsi * mean_obliquity_rad(t_cy).cos()
        + 0.002_64 * RAD_PER_ARCSEC * moon_node_rad(t_cy).sin();
    (gmst_rad(jd_ut1) + eq_eq).rem_euclid(core::f64::consts::TAU)
}

/// The rotation `r_itrs = M r_gcrs` at `epoch` (passive; no polar motion, no frame bias).
#[must_use]
pub fn m_itrs_from_gcrs(epoch: Epoch) -> Matrix3<f64> {
    m_itrs_from_gcrs_with_dut1(epoch, ut1_minus_utc_s(epoch))
}

/// [`m_itrs_from_gcrs`] with a given UT1 − UTC (s), e.g. 0 to measure what the IERS table
/// buys.
#[must_use]
pub fn m_itrs_from_gcrs_with_dut1(epoch: Epoch, ut1_minus_utc_s: f64) -> Matrix3<f64> {
    r3(gast_with_dut1_rad(epoch, ut1_minus_utc_s)) * m_tod_from_gcrs(epoch)
}

/// Precession and nutation `N · P`: GCRS → true equator and equinox of date.
#[must_use]
pub fn m_tod_from_gcrs(epoch: Epoch) -> Matrix3<f64> {
    let t_cy = j2000_tt_s(epoch) / S_PER_JULIAN_CENTURY;
    let eps = mean_obliquity_rad(t_cy);
    let (dpsi, deps) = nutation_rad(t_cy);
    r1(-(eps + deps)) * r3(-dpsi) * r1(eps) * m_mod_from_j2000(t_cy)
}

/// Passive rotation about z by GAST: true equator of date → ITRS (no polar motion).
#[must_use]
pub fn m_itrs_from_tod(gast_rad: f64) -> Matrix3<f64> {
    r3(gast_rad)
}

/// Earth-fixed position of a GCRS position at `epoch` (km in, km out).
#[must_use]
pub fn itrs_from_gcrs_km(epoch: Epoch, pos_gcrs_km: &Vector3<f64>) -> Vector3<f64> {
    m_itrs_from_gcrs(epoch) * pos_gcrs_km
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::{data_dir, CsvTable};
    use crate::time::epoch_from_iso;
    use fsw_core::units::ARCSEC_PER_RAD;

    #[test]
    fn ut1_table_reads_and_interpolates() {
        let table = parse_ut1_table(UT1_UTC_CSV).unwrap();
        assert_eq!(table.len(), 547);
        // finals2000A.all: MJD 48356 (1991-04-10) 0.3940858 s, MJD 48357 0.3916317 s.
        let noon = epoch_from_iso("1991-04-10T12:00:00Z").unwrap();
        let expect = 0.5 * (0.394_085_8 + 0.391_631_7);
        assert!((ut1_minus_utc_s(noon) - expect).abs() < 1e-9);
        // Held at the ends.
        let early = epoch_from_iso("1990-06-01T00:00:00Z").unwrap();
        assert!((ut1_minus_utc_s(early) - 0.618_687_3).abs() < 1e-9);
    }

    /// Meeus example 12.a: 1987-04-10 0h UT, GMST = 13h10m46.3668s.
    #[test]
    fn gmst_matches_meeus_example() {
        let gmst_s = gmst_rad(2_446_895.5) / core::f64::consts::TAU * 86_400.0;
        let expect = 13.0 * 3600.0 + 10.0 * 60.0 + 46.3668;
        assert!((gmst_s - expect).abs() < 1e-3, "{gmst_s}");
    }

    /// Meeus example 22.a: 1987-04-10 0h TD, Δψ = −3.788″, Δε = +9.443″ with the full
    /// series; the 13 terms give −3.773″ (the ~50 omitted terms, each ≤ 0.0063″, add up to
    /// 0.015″ here; Δψ moves the pole by only Δψ sin ε, since GAST absorbs Δψ cos ε): guard
    /// 0.02″.
    #[test]
    fn nutation_matches_meeus_example() {
        let t = (2_446_895.5 - 2_451_545.0) / 36_525.0;
        let (dpsi, deps) = nutation_rad(t);
        assert!(
            (dpsi * ARCSEC_PER_RAD + 3.788).abs() < 0.02,
            "{}",
            dpsi * ARCSEC_PER_RAD
        );
        assert!(
            (deps * ARCSEC_PER_RAD - 9.443).abs() < 0.02,
            "{}",
            deps * ARCSEC_PER_RAD
        );
    }

    /// Source: `data/igrf_reference.csv` (Skyfield 1.55: IAU 2006/2000A, UT1 from
    /// finals2000A.all, no polar motion), 100 points on 1991-04-10. Budget: frame bias 0.023″,
    /// IAU 1980 vs 2000A nutation and the truncated series a few 0.01″, UT1 interpolation
    /// < 1 ms (0.015″): 0.1″ in all (3 m at 6833 km). Positions are printed to 1 m (0.03″).
    #[test]
    fn val_gcrs_to_itrs_against_skyfield() {
        let t = CsvTable::read(&data_dir().join("igrf_reference.csv")).unwrap();
        assert_eq!(t.len(), 100);
        let epoch0 = epoch_from_iso("1991-04-10T00:00:00Z").unwrap();
        let ts = t.column("t_s").unwrap();
        let mut max_arcsec = 0.0_f64;
        let mut max_km = 0.0_f64;
        for row in 0..t.len() {
            let epoch = epoch0 + hifitime::Unit::Second * t.f64(row, ts).unwrap();
            let gcrs = t.xyz(row, "{}_gcrs_km").unwrap();
            let itrs = t.xyz(row, "{}_itrs_km").unwrap();
            let mine = itrs_from_gcrs_km(epoch, &gcrs);
            max_km = max_km.max((mine - itrs).norm());
            max_arcsec = max_arcsec.max(mine.angle(&itrs) * ARCSEC_PER_RAD);
        }
        eprintln!(
            "GCRS→ITRS vs Skyfield: max {max_arcsec:.4}″, {:.2} m",
            max_km * 1e3
        );
        assert!(max_arcsec < 0.1, "GCRS→ITRS max {max_arcsec}″");
    }
}
