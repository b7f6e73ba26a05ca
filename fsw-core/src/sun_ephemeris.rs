//! # Onboard low-precision Sun ephemeris and annual aberration (algorithms.md §3.3)
//!
//! Argument: seconds since J2000.0 TT ([`crate::raw::TimeTag::seconds_since_j2000_tt`]).
//! Output axes: J2000/ICRS equatorial (the 0.02″ frame bias is neglected). Valid 1950–2050.
//!
//! ## Model
//!
//! Keplerian mean elements of the Earth–Moon barycentre referred to the **fixed J2000
//! ecliptic and equinox** (Standish, "Keplerian Elements for Approximate Positions of the
//! Major Planets", JPL, table 1, 1800–2050), so no precession is needed; with
//! `T` = Julian centuries TT from J2000:
//!
//! | element | value at J2000 | rate per century |
//! |---|---|---|
//! | a (au) | 1.00000261 | +0.00000562 |
//! | e | 0.01671123 | −0.00004392 |
//! | I (°) | −0.00001531 | −0.01294668 |
//! | L (°) | 100.46457166 | 35999.37244981 |
//! | ϖ (°) | 102.93768193 | +0.32327364 |
//! | Ω (°) | 0 | 0 |
//!
//! * Mean anomaly `M = L − ϖ`; true anomaly by the equation of the centre to `e³`
//!   (`ν = M + (2e − e³/4) sin M + (5/4)e² sin 2M + (13/12)e³ sin 3M`, truncation ≈ 0.02″);
//!   `r = a(1 − e²)/(1 + e cos ν)`; argument of latitude `u = ν + ϖ` (Ω = 0).
//! * Heliocentric EMB position `r (cos u, sin u cos I, sin u sin I)` and velocity
//!   `n a/√(1−e²) · (−(sin u + e sin ϖ), (cos u + e cos ϖ) cos I, (cos u + e cos ϖ) sin I)`
//!   with `n` the rate of `L`.
//! * Geocentre = EMB − 4671 km · (cos λ_☾, sin λ_☾, 0), λ_☾ the Moon's mean longitude
//!   (`218.3164477° + 481267.88123421° T`, minus the general precession): this is the ±6.4″
//!   monthly wobble of the geocentre about the barycentre.
//! * Geometric Sun direction = −(geocentre), rotated from ecliptic to equator by
//!   ε₀ = 84381.406″ (IAU 2006).
//! * Earth velocity `β = v/c` (c = 173.1446 au/day); the Sun's own barycentric velocity
//!   (~13 m/s, 0.01″) is neglected.
//! * Apparent direction `u_app = (u + β)/|u + β|` ([`aberrate`]): classical aberration, which
//!   equals the first-order `u + β − u(u·β)` to O(β²) ≈ 2 mas and the relativistic form to
//!   the same order. Light time for the Sun (< 0.01″) is neglected.
//!
//! Against DE421 (Skyfield, `data/sun_reference.csv`, 1991) the apparent direction is good to
//! about 10″ (integration test `est`, `sun`), well inside the 0.01° requirement; the remaining
//! error is mostly the planetary perturbations (Venus, Jupiter) left out of the mean elements.
//! The Sun seen from the spacecraft additionally differs by the LEO parallax (≤ 9.5″) and the
//! orbital aberration (≤ 5.2″), which need the orbit: [`apparent_sun_from`] applies them with
//! the onboard orbit ([`crate::orbit`]).

use crate::units::{RAD_PER_ARCSEC, RAD_PER_DEG, S_PER_DAY};
use nalgebra::Vector3;

/// Seconds per Julian century.
const S_PER_CENTURY: f64 = 36_525.0 * S_PER_DAY;
/// Validity span of the mean elements, ± centuries from J2000.
const VALID_CENTURIES: f64 = 0.5;
/// Mean obliquity of the ecliptic at J2000 (IAU 2006), rad.
pub const OBLIQUITY_J2000_RAD: f64 = 84_381.406 * RAD_PER_ARCSEC;
/// Speed of light, au per day.
const C_AU_PER_DAY: f64 = 173.144_632_684_669_3;
/// Distance of the geocentre from the Earth–Moon barycentre, au (4671 km).
const GEOCENTRE_OFFSET_AU: f64 = 4671.0 / 149_597_870.7;
/// General precession in longitude, rad per century (5028.796″).
const PRECESSION_RAD_PER_CENTURY: f64 = 5_028.796_195 * RAD_PER_ARCSEC;

/// Sun ephemeris result, J2000/ICRS axes.
/// Standish JPL mean elements (module docs); algorithms.md §3.3 ("Sun vector").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SunState {
    /// Apparent geocentric Sun direction (unit; annual aberration applied).
    /// Aberration per algorithms.md §3.3 (annual ≤ 20.5″).
    pub dir_eci: Vector3<f64>,
    /// Geometric geocentric Sun direction (unit).
    /// Standish JPL mean elements (module docs).
    pub geometric_dir_eci: Vector3<f64>,
    /// Earth–Sun distance, au.
    /// Standish JPL mean elements (module docs).
    pub distance_au: f64,
    /// Earth's heliocentric velocity over c (≈ barycentric to 0.01″), unitless.
    /// `β` of algorithms.md §3.3.
    pub earth_velocity_over_c: Vector3<f64>,
}

#[cfg(feature = "defmt")]
impl defmt::Format for SunState {
    fn format(&self, f: defmt::Formatter) {
        defmt::write!(
            f,
            "SunState {{ dir: {}, r_au: {}, beta: {} }}",
            [self.dir_eci.x, self.dir_eci.y, self.dir_eci.z],
            self.distance_au,
            [
                self.earth_velocity_over_c.x,
                self.earth_velocity_over_c.y,
                self.earth_velocity_over_c.z
            ]
        );
    }
}

/// Why no ephemeris was produced.
/// Project choice (not in the paper): errors instead of panics in the flight core.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EphemerisError {
    /// Time not finite.
    /// Project choice (not in the paper): NaN input is refused.
    NotFinite,
    /// Time outside 1950–2050, where the mean elements are not valid.
    /// Validity span of the Standish JPL table 1 elements (module docs).
    OutOfRange,
}

/// Rotate ecliptic-J2000 components to equatorial J2000.
fn ecliptic_to_equatorial(v: &Vector3<f64>) -> Vector3<f64> {
    // Constants: cos/sin of ε₀ evaluated once by the compiler would need const fn trig;
    // the values are cos(84381.406″) and sin(84381.406″).
    const COS_EPS: f64 = 0.917_482_143_065_241_9;
    const SIN_EPS: f64 = 0.397_776_969_112_605_96;
    Vector3::new(
        v.x,
        COS_EPS * v.y - SIN_EPS * v.z,
        SIN_EPS * v.y + COS_EPS * v.z,
    )
}

/// Sun state at `t_s` seconds since J2000.0 TT.
/// Standish JPL mean elements; algorithms.md §3.3.
///
/// # Errors
/// [`EphemerisError`] for a non-finite time or one outside 1950–2050.
pub fn sun_state(t_s_since_j2000_tt: f64) -> Result<SunState, EphemerisError> {
    if !t_s_since_j2000_tt.is_finite() {
        return Err(EphemerisError::NotFinite);
    }
    let t = t_s_since_j2000_tt / S_PER_CENTURY;
    if !(t.abs() <= VALID_CENTURIES) {
        return Err(EphemerisError::OutOfRange);
    }
    let a = 1.000_002_61 + 0.000_005_62 * t;
    let e = 0.016_711_23 - 0.000_043_92 * t;
    let inc = (-0.000_015_31 - 0.012_946_68 * t) * RAD_PER_DEG;
    let mean_lon = (100.464_571_66 + 35_999.372_449_81 * t) * RAD_PER_DEG;
    let peri = (102.937_681_93 + 0.323_273_64 * t) * RAD_PER_DEG;
    let m = libm::remainder(mean_lon - peri, core::f64::consts::TAU);

    // Equation of the centre to e³, multiple angles by recursion (one sin/cos pair).
    let (sm, cm) = libm::sincos(m);
    let s2m = 2.0 * sm * cm;
    let c2m = cm * cm - sm * sm;
    let s3m = s2m * cm + c2m * sm;
    let e2 = e * e;
    let e3 = e2 * e;
    let nu = m + (2.0 * e - 0.25 * e3) * sm + 1.25 * e2 * s2m + (13.0 / 12.0) * e3 * s3m;
    let (snu, cnu) = libm::sincos(nu);
    let r = a * (1.0 - e2) / (1.0 + e * cnu);
    let (sp, cp) = libm::sincos(peri);
    // u = ν + ϖ
    let su = snu * cp + cnu * sp;
    let cu = cnu * cp - snu * sp;
    let (si, ci) = libm::sincos(inc);
    let emb = Vector3::new(r * cu, r * su * ci, r * su * si);

    // Geocentre offset from the EMB, opposite the Moon (mean longitude, J2000 ecliptic).
    let moon_lon =
        (218.316_447_7 + 481_267.881_234_21 * t) * RAD_PER_DEG - PRECESSION_RAD_PER_CENTURY * t;
    let (sl, cl) = libm::sincos(libm::remainder(moon_lon, core::f64::consts::TAU));
    let earth = emb - Vector3::new(cl, sl, 0.0) * GEOCENTRE_OFFSET_AU;

    // Velocity (au/day): n a / sqrt(1 - e²) with n the rate of L in rad/day.
    let n = 35_999.372_449_81 * RAD_PER_DEG / 36_525.0;
    let vf = n * a / libm::sqrt(1.0 - e2);
    let vy = vf * (cu + e * cp);
    let v = Vector3::new(-vf * (su + e * sp), vy * ci, vy * si);

    let distance_au = earth.norm();
    let geometric_dir_eci = ecliptic_to_equatorial(&(-earth / distance_au));
    let earth_velocity_over_c = ecliptic_to_equatorial(&(v / C_AU_PER_DAY));
    let dir_eci = aberrate(&geometric_dir_eci, &earth_velocity_over_c);
    Ok(SunState {
        dir_eci,
        geometric_dir_eci,
        distance_au,
        earth_velocity_over_c,
    })
}

/// Apparent geocentric Sun direction (unit, J2000/ICRS) at `t_s` seconds since J2000 TT.
/// algorithms.md §3.3 ("Sun vector": apparent direction).
///
/// # Errors
/// As [`sun_state`].
pub fn sun_dir_eci(t_s_since_j2000_tt: f64) -> Result<Vector3<f64>, EphemerisError> {
    sun_state(t_s_since_j2000_tt).map(|s| s.dir_eci)
}

/// Earth velocity over c (J2000/ICRS) at `t_s` seconds since J2000 TT, for annual aberration.
/// algorithms.md §3.3 (`β = v/c`).
///
/// # Errors
/// As [`sun_state`].
pub fn earth_velocity_over_c(t_s_since_j2000_tt: f64) -> Result<Vector3<f64>, EphemerisError> {
    sun_state(t_s_since_j2000_tt).map(|s| s.earth_velocity_over_c)
}

/// Aberrate a unit direction by the observer velocity `β = v/c`:
/// `u_app = (u + β)/|u + β|` (classical; first order `u + β − u(u·β)`, error O(β²) ≈ 2 mas).
/// Returns `u` unchanged if the result is not finite.
/// algorithms.md §3.3 ("First order" and relativistic forms).
#[must_use]
pub fn aberrate(u: &Vector3<f64>, beta: &Vector3<f64>) -> Vector3<f64> {
    let w = u + beta;
    let n = w.norm();
    if n.is_finite() && n > 0.0 {
        w / n
    } else {
        *u
    }
}

/// The OBC's reference direction of a catalog star (unit, J2000/ICRS) at `t_s` seconds since
/// J2000 TT: `dir` aberrated by the Earth's velocity (the annual part, when `annual`) plus
/// `observer_vel_over_c` (the spacecraft's velocity relative to the geocentre over c, the
/// orbital part, when given); `dir` itself when neither applies (or the ephemeris fails).
/// algorithms.md §3.3 (`β` = Earth's ~29.8 km/s plus the orbital ~7.5 km/s).
#[must_use]
pub fn star_reference_dir(
    dir: &Vector3<f64>,
    t_s_since_j2000_tt: f64,
    annual: bool,
    observer_vel_over_c: Option<&Vector3<f64>>,
) -> Vector3<f64> {
    let earth = if annual {
        earth_velocity_over_c(t_s_since_j2000_tt).ok()
    } else {
        None
    };
    match (earth, observer_vel_over_c) {
        (None, None) => *dir,
        (Some(beta), None) => aberrate(dir, &beta),
        (None, Some(beta)) => aberrate(dir, beta),
        (Some(earth), Some(observer)) => aberrate(dir, &(earth + observer)),
    }
}

/// Apparent Sun direction (unit, J2000/ICRS) seen from an observer at `pos_eci_km` from the
/// geocentre moving at `vel_over_c` relative to it: the geocentric Sun position
/// (`geometric_dir_eci · distance`) minus the observer's (the LEO parallax, ≤ 9.5″),
/// aberrated by the Earth's plus the observer's velocity (annual and orbital). The geocentric
/// apparent direction if the difference is degenerate.
/// algorithms.md §3.3 ("Sun vector": apparent direction from the spacecraft).
#[must_use]
pub fn apparent_sun_from(
    sun: &SunState,
    pos_eci_km: &Vector3<f64>,
    vel_over_c: &Vector3<f64>,
) -> Vector3<f64> {
    let sun_km = sun.geometric_dir_eci * (sun.distance_au * crate::orbit::AU_KM);
    let from_observer_km = sun_km - pos_eci_km;
    let n = from_observer_km.norm();
    if !(n.is_finite() && n > 0.0) {
        return sun.dir_eci;
    }
    aberrate(
        &(from_observer_km / n),
        &(sun.earth_velocity_over_c + vel_over_c),
    )
}

/// Inverse of [`aberrate`] to first order: the mean direction whose apparent direction is
/// `u_app`, `(u_app − β)/|u_app − β|` (error O(β²)).
/// algorithms.md §3.3 (first-order form).
#[must_use]
pub fn unaberrate(u_app: &Vector3<f64>, beta: &Vector3<f64>) -> Vector3<f64> {
    aberrate(u_app, &(-beta))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::units::ARCSEC_PER_RAD;

    #[test]
    fn obliquity_constants_match() {
        let (s, c) = libm::sincos(OBLIQUITY_J2000_RAD);
        let v = ecliptic_to_equatorial(&Vector3::new(0.0, 1.0, 0.0));
        assert!((v.y - c).abs() < 3e-16 && (v.z - s).abs() < 3e-16);
    }

    #[test]
    fn march_equinox_1991() {
        // 1991-03-21 03:02 UTC March equinox: apparent longitude of date 0. In J2000 axes the
        // equinox of date sits at +5029″ × 8.78 yr ≈ +442″ of J2000 ecliptic longitude.
        let t = (2_448_336.627 - 2_451_545.0) * S_PER_DAY;
        let s = sun_state(t).unwrap();
        let (se, ce) = libm::sincos(OBLIQUITY_J2000_RAD);
        let d = s.dir_eci;
        let ecl = Vector3::new(d.x, ce * d.y + se * d.z, -se * d.y + ce * d.z);
        let lon = libm::atan2(ecl.y, ecl.x) * ARCSEC_PER_RAD;
        // Nutation in longitude (≤ 17″) and the ephemeris error are in the tolerance.
        assert!((lon - 442.0).abs() < 40.0, "{lon}");
        assert!(ecl.z.abs() * ARCSEC_PER_RAD < 5.0);
        // Distance near 1 au, aberration about 20.5 arcsec.
        assert!((s.distance_au - 0.996).abs() < 0.002);
        let ab = s.dir_eci.cross(&s.geometric_dir_eci).norm() * ARCSEC_PER_RAD;
        assert!((ab - 20.5).abs() < 0.5, "{ab}");
    }

    #[test]
    fn rejects_bad_time() {
        assert_eq!(sun_state(f64::NAN), Err(EphemerisError::NotFinite));
        assert_eq!(sun_state(1.0e12), Err(EphemerisError::OutOfRange));
    }

    #[test]
    fn aberration_shift_is_beta_sin_angle() {
        let u = Vector3::new(1.0, 0.0, 0.0);
        let beta = Vector3::new(0.0, 1e-4, 0.0);
        let a = aberrate(&u, &beta);
        assert!((a.y - 1e-4).abs() < 1e-11);
        let back = unaberrate(&a, &beta);
        assert!((back - u).norm() < 1e-11);
    }
}
