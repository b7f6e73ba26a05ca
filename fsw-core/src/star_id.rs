//! # Direct-match star identification (algorithms.md §3.2; GLAS ATBD §4.2)
//!
//! Run once per **new acquisition** of a tracker (the executive keeps the identified star
//! while the tracker stays on it). With the gyro-propagated attitude `Â` (ACS from ECI):
//!
//! 1. Observed direction in inertial axes: `r_obs = Âᵀ b_meas`, `b_meas` the measured ACS
//!    direction ([`crate::fhst::FhstMeasurement::dir_acs`]). It is compared with the mean
//!    catalog directions: aberration (≤ 25″) is negligible against the 0.6° window. The
//!    *reference* vector given to the filter is the catalog direction aberrated by the caller
//!    ([`crate::sun_ephemeris::aberrate`]) when the table asks for it.
//! 2. Candidates: every catalog star with `∠(r_obs, r_c) ≤ ε` (ε from the attitude
//!    covariance, [`StarIdWindow::from_covariance`], at most the table's
//!    `star_id_window_arcsec`; compared as `r_obs·r_c ≥ cos ε`, one `cos` per call) and
//!    `|m_obs − m_c| ≤ Δm` (table `star_id_magnitude_tolerance`).
//! 3. Exactly one candidate → [`StarMatch`]; none → [`StarIdError::NoMatch`]; more →
//!    [`StarIdError::Ambiguous`] (rejected: a near neighbour inside the window could be the
//!    tracked star).
//!
//! The scan is one bounded linear pass over the table (≤ [`MAX_CATALOG_STARS`], ~10 flops a
//! star); it never stops early, so its time does not depend on the data.
//!
//! **Correctness argument.** If the attitude error plus the measurement error is below ε and
//! the magnitude error below Δm, the tracked star (if it is in the catalog) is always a
//! candidate; a unique candidate is then the right star. A wrong identification needs the
//! tracked star to be *missing* from the catalog (or its magnitude off by more than Δm) while
//! another star sits inside the window: the catalog must therefore reach Δm-ish beyond the
//! tracker's faint limit (integration test `est`, `star_id`).

use crate::attitude::Quat;
use crate::tables::types::{CatalogStar, FilterTable, StarCatalogTable, MAX_CATALOG_STARS};
use crate::units::RAD_PER_ARCSEC;
use nalgebra::Vector3;

/// An identified star.
/// algorithms.md §3.2 step 5.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StarMatch {
    /// The catalog entry (mean direction; the caller applies aberration for the reference).
    /// docs/tables.md (star catalog table); aberration per algorithms.md §3.3.
    pub star: CatalogStar,
    /// Index in the catalog table.
    /// docs/tables.md (star catalog table); telemetry docs/icd.md §3.2.
    pub catalog_index: u16,
    /// Angle between the observation (in inertial axes) and the catalog star, rad.
    /// algorithms.md §3.2 step 4 (`∠(r_obs, r_c)`).
    pub separation_rad: f64,
    /// Observed minus catalog magnitude, mag.
    /// algorithms.md §3.2 step 4 (`|m_obs − m_c|`).
    pub magnitude_difference: f64,
}

/// Why no star was identified.
/// algorithms.md §3.2.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StarIdError {
    /// The catalog table is empty.
    /// docs/icd.md §3.3 (event 0x0402, p2 = 3).
    NoCatalog,
    /// Observation, magnitude, attitude or window not finite / not usable.
    /// Project choice (not in the paper): NaN input is refused.
    InvalidInput,
    /// No catalog star in the window.
    /// algorithms.md §3.2 step 5; docs/icd.md §3.3 (event 0x0402, p2 = 1).
    NoMatch,
    /// More than one candidate.
    /// algorithms.md §3.2 step 5 ("exactly one"); docs/icd.md §3.3 (p2 = 2).
    Ambiguous {
        /// Number of candidates (saturating at 255).
        /// Project choice (not in the paper): evidence for the event log.
        candidates: u8,
    },
}

impl StarIdError {
    /// Event/telemetry code: 1 no match, 2 ambiguous, 3 no catalog, 4 invalid input.
    /// docs/icd.md §3.3 (event 0x0402).
    #[must_use]
    pub const fn code(self) -> u8 {
        match self {
            Self::NoMatch => 1,
            Self::Ambiguous { .. } => 2,
            Self::NoCatalog => 3,
            Self::InvalidInput => 4,
        }
    }
}

/// Window and magnitude tolerance of the identification.
/// algorithms.md §3.2 step 4.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StarIdWindow {
    /// Match window ε, rad (0 < ε < 0.5).
    /// algorithms.md §3.2 step 4 (`ε = k √(σ_st² + λ_max(P_θ))`, here a table constant).
    pub window_rad: f64,
    /// Magnitude tolerance Δm, mag.
    /// algorithms.md §3.2 step 4 (Δm, typically 0.5–1 mag).
    pub magnitude_tolerance: f64,
}

/// Width of the covariance window in standard deviations of the predicted position error:
/// the tracked star is outside a radius of `kσ` (isotropic 2-D Gaussian) with probability
/// `exp(−k²/2)` = 3.7e-6 for k = 5 (algorithms.md §3.2 step 4: k ≈ 3–5).
pub const WINDOW_NUM_SIGMAS: f64 = 5.0;

/// Narrowest window, arcsec: five times the faintest star's σ (24″, paper), so that a
/// covariance that claims too much cannot shut identification out. Project choice
/// (docs/obc_filter.md §4).
pub const WINDOW_FLOOR_ARCSEC: f64 = 120.0;

impl StarIdWindow {
    /// From the attitude covariance (issue 19): `ε = k √(σ_st² + f² + tr P_θθ)`, between
    /// [`WINDOW_FLOOR_ARCSEC`] and the table's `star_id_window_arcsec` (now the widest
    /// window). `tr P_θθ ≥ λ_max(P_θθ)` bounds the attitude error in any direction;
    /// `sigma_star_rad` is the measurement σ and `systematic_rad` the uncorrected systematic
    /// of the tracker. A non-finite input gives the table's window.
    /// algorithms.md §3.2 step 4; docs/obc_filter.md §4.
    #[must_use]
    pub fn from_covariance(
        filter: &FilterTable,
        attitude_covariance_trace_rad2: f64,
        sigma_star_rad: f64,
        systematic_rad: f64,
    ) -> Self {
        let table = Self::from_table(filter);
        let var = sigma_star_rad * sigma_star_rad
            + systematic_rad * systematic_rad
            + attitude_covariance_trace_rad2;
        if !(var.is_finite() && var >= 0.0) {
            return table;
        }
        let floor = WINDOW_FLOOR_ARCSEC * RAD_PER_ARCSEC;
        let window = (WINDOW_NUM_SIGMAS * libm::sqrt(var))
            .max(floor)
            .min(table.window_rad.max(floor));
        Self {
            window_rad: window,
            magnitude_tolerance: table.magnitude_tolerance,
        }
    }

    /// From the filter table.
    /// docs/tables.md (filter table: `star_id_window_arcsec`, `star_id_magnitude_tolerance`).
    #[must_use]
    pub fn from_table(filter: &FilterTable) -> Self {
        Self {
            window_rad: filter.star_id_window_arcsec * RAD_PER_ARCSEC,
            magnitude_tolerance: filter.star_id_magnitude_tolerance,
        }
    }
}

/// Identify an observed star with the table's window and magnitude tolerance.
/// algorithms.md §3.2 (direct match).
///
/// * `obs_dir_acs`: measured direction in ACS (unit or near-unit).
/// * `obs_magnitude`: instrument magnitude.
/// * `q_acs_from_eci`: predicted attitude.
///
/// # Errors
/// [`StarIdError`].
pub fn identify(
    obs_dir_acs: &Vector3<f64>,
    obs_magnitude: f64,
    q_acs_from_eci: &Quat,
    catalog: &StarCatalogTable,
    filter: &FilterTable,
) -> Result<StarMatch, StarIdError> {
    identify_in_window(
        obs_dir_acs,
        obs_magnitude,
        q_acs_from_eci,
        catalog,
        &StarIdWindow::from_table(filter),
    )
}

/// [`identify`] with an explicit window.
/// algorithms.md §3.2 (direct match).
///
/// # Errors
/// [`StarIdError`].
pub fn identify_in_window(
    obs_dir_acs: &Vector3<f64>,
    obs_magnitude: f64,
    q_acs_from_eci: &Quat,
    catalog: &StarCatalogTable,
    window: &StarIdWindow,
) -> Result<StarMatch, StarIdError> {
    if catalog.stars.is_empty() {
        return Err(StarIdError::NoCatalog);
    }
    let n = obs_dir_acs.norm();
    let qn = q_acs_from_eci.norm();
    let ok = (0.5..2.0).contains(&n)
        && obs_magnitude.is_finite()
        && q_acs_from_eci.is_finite()
        && (0.5..2.0).contains(&qn)
        && window.window_rad > 0.0
        && window.window_rad < 0.5
        && window.magnitude_tolerance >= 0.0
        && window.magnitude_tolerance.is_finite();
    if !ok {
        return Err(StarIdError::InvalidInput);
    }
    let a = q_acs_from_eci.normalized().to_dcm();
    let r_obs = a.transpose() * (obs_dir_acs / n);
    let cos_window = libm::cos(window.window_rad);

    let mut count: u32 = 0;
    let mut found: Option<(usize, CatalogStar, f64, f64)> = None;
    for (index, star) in catalog.stars.iter().take(MAX_CATALOG_STARS).enumerate() {
        let dot = r_obs.dot(&star.dir());
        let dm = obs_magnitude - f64::from(star.magnitude_centimag) * 0.01;
        if dot >= cos_window && dm.abs() <= window.magnitude_tolerance {
            count = count.saturating_add(1);
            found = Some((index, *star, dm, dot));
        }
    }
    match (count, found) {
        (1, Some((index, star, dm, _))) => {
            let c = star.dir();
            let separation_rad = libm::atan2(r_obs.cross(&c).norm(), r_obs.dot(&c));
            Ok(StarMatch {
                star,
                catalog_index: u16::try_from(index).unwrap_or(u16::MAX),
                separation_rad,
                magnitude_difference: dm,
            })
        }
        (0, _) => Err(StarIdError::NoMatch),
        (c, _) => Err(StarIdError::Ambiguous {
            candidates: u8::try_from(c).unwrap_or(u8::MAX),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn star(id: u32, v: Vector3<f64>, mag: f64) -> CatalogStar {
        let v = v.normalize();
        CatalogStar {
            id,
            dir_eci: [v.x as f32, v.y as f32, v.z as f32],
            magnitude_centimag: (mag * 100.0).round() as i16,
        }
    }

    fn window() -> StarIdWindow {
        StarIdWindow::from_table(&FilterTable::default_boot())
    }

    #[test]
    fn unique_ambiguous_and_none() {
        let mut cat = StarCatalogTable::default();
        let d = 0.3_f64.to_radians();
        cat.stars
            .push(star(1, Vector3::new(1.0, 0.0, 0.0), 4.0))
            .unwrap();
        cat.stars
            .push(star(2, Vector3::new(1.0, d.tan(), 0.0), 4.2))
            .unwrap();
        cat.stars
            .push(star(3, Vector3::new(0.0, 1.0, 0.0), 3.0))
            .unwrap();
        let q = Quat::IDENTITY;
        let w = window();
        // Star 3 alone.
        let m = identify_in_window(&Vector3::new(0.0, 1.0, 0.001), 3.1, &q, &cat, &w).unwrap();
        assert_eq!((m.star.id, m.catalog_index), (3, 2));
        assert!((m.separation_rad - 0.001).abs() < 1e-6);
        // Stars 1 and 2 both within 0.6 deg and 0.6 mag: ambiguous.
        assert_eq!(
            identify_in_window(&Vector3::new(1.0, 0.0, 0.0), 4.1, &q, &cat, &w),
            Err(StarIdError::Ambiguous { candidates: 2 })
        );
        // Magnitude separates them.
        let m = identify_in_window(&Vector3::new(1.0, 0.0, 0.0), 3.5, &q, &cat, &w).unwrap();
        assert_eq!(m.star.id, 1);
        // Nothing there.
        assert_eq!(
            identify_in_window(&Vector3::new(0.0, 0.0, 1.0), 4.0, &q, &cat, &w),
            Err(StarIdError::NoMatch)
        );
        assert_eq!(
            identify_in_window(&Vector3::new(f64::NAN, 0.0, 1.0), 4.0, &q, &cat, &w),
            Err(StarIdError::InvalidInput)
        );
    }

    #[test]
    fn covariance_window_is_k_sigma_between_the_floor_and_the_table() {
        let t = FilterTable::default_boot();
        let as2 = RAD_PER_ARCSEC * RAD_PER_ARCSEC;
        // σ_st 10″, systematic 0, tr P = 3 × 100²: 5 √(100 + 30000) = 867.2″.
        let w = StarIdWindow::from_covariance(&t, 3.0e4 * as2, 10.0 * RAD_PER_ARCSEC, 0.0);
        assert!((w.window_rad / RAD_PER_ARCSEC - 5.0 * 30_100.0_f64.sqrt()).abs() < 1e-6);
        assert!((w.magnitude_tolerance - t.star_id_magnitude_tolerance).abs() < 1e-15);
        // A tight covariance: the floor.
        let w = StarIdWindow::from_covariance(&t, 3.0 * as2, 8.0 * RAD_PER_ARCSEC, 0.0);
        assert!((w.window_rad / RAD_PER_ARCSEC - WINDOW_FLOOR_ARCSEC).abs() < 1e-9);
        // A 1° prior: the table's window.
        let w = StarIdWindow::from_covariance(&t, 3.0 * 3600.0 * 3600.0 * as2, 0.0, 0.0);
        assert_eq!(w, StarIdWindow::from_table(&t));
        // Not finite: the table's window.
        let w = StarIdWindow::from_covariance(&t, f64::NAN, 0.0, 0.0);
        assert_eq!(w, StarIdWindow::from_table(&t));
    }

    #[test]
    fn uses_the_attitude() {
        let mut cat = StarCatalogTable::default();
        let r = Vector3::new(0.2, -0.5, 0.8).normalize();
        cat.stars.push(star(7, r, 5.0)).unwrap();
        cat.stars.push(star(8, -r, 5.0)).unwrap();
        let q = Quat::from_rotation_vector(&Vector3::new(0.4, 1.0, -2.0));
        let b = q.to_dcm() * r;
        let m = identify(&b, 5.1, &q, &cat, &FilterTable::default_boot()).unwrap();
        assert_eq!(m.star.id, 7);
        assert!(m.separation_rad < 1e-7, "{}", m.separation_rad);
        assert!((m.magnitude_difference - 0.1).abs() < 1e-9);
        assert_eq!(
            identify(
                &b,
                5.1,
                &q,
                &StarCatalogTable::default(),
                &FilterTable::default_boot()
            ),
            Err(StarIdError::NoCatalog)
        );
    }
}
