//! # The true sky: Hipparcos stars, space motion, parallax, aberration, a cone index
//!
//! Why: the FHST truth must see every star where it really appears — catalogue position
//! (ICRS, epoch J1991.25 TT) moved by its proper motion to the date, displaced by annual
//! parallax and by velocity aberration (annual + orbital, [`crate::aberration`]). The onboard
//! software does not correct aberration by default; finding it is the ground's job.
//!
//! # Magnitude system (decision)
//! The FHST window 2.0–5.7 (gro_paper.toml `[sensors.fhst]`) is applied to an *instrument
//! magnitude* `m_inst = m + colour_term·(B−V)` with `m` the Hipparcos **Hp** by default
//! (`colour_term = 0`). Reason: the ICD (docs/icd.md §3.1) defines the FHST magnitude word as
//! "instrument magnitude ≈ Hipparcos Hp", and the image dissector's S-20 photocathode is a
//! broad band like Hp rather than Johnson V. `magnitude_system = "v"` selects V instead;
//! Hp − V is −0.05..+0.17 mag for normal stars (data/README.md), so the choice moves the
//! faint limit by ~0.1 mag and changes the eligible set by ~10 % (3231 stars in Hp, 3544 in
//! V). Very red variables and 5 double-star entries have Hp up to 3 mag brighter than V: they
//! are tracked as bright in Hp, a realistic catalogue hazard. Rows with an empty V use Hp.
//!
//! # Index
//! Declination bands of `cell_deg`, each split into right-ascension cells about `cell_deg`
//! wide; stars are stored sorted by cell (CSR offsets), built once from the catalogue
//! positions. A cone query visits the cells overlapping the cap (widened by
//! [`INDEX_MARGIN_RAD`] for proper motion and aberration) and tests the exact distance.
//! A 5.7° cone touches ~40 cells and ~30 stars, no allocation.

use nalgebra::Vector3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use super::aberration::aberrate;
use super::sun::{AU_KM, EARTH_RADIUS_KM};
use super::time::{JD_J2000, S_PER_JULIAN_YEAR};
use crate::data::CsvTable;
use fsw_core::units::{RAD_PER_ARCSEC, RAD_PER_DEG};

/// Hipparcos catalogue epoch J1991.25 (TT) as JD.
pub const HIPPARCOS_EPOCH_JD_TT: f64 = 2_448_349.062_5;
/// Radians per milliarcsecond.
const RAD_PER_MAS: f64 = RAD_PER_ARCSEC * 1.0e-3;
/// Extra radius for cone queries: covers aberration (26″), parallax (0.8″) and up to ~40 yr
/// of the largest proper motion (α Cen, 3.7″/yr) from the catalogue epoch.
pub const INDEX_MARGIN_RAD: f64 = 180.0 * RAD_PER_ARCSEC;

/// Which catalogue magnitude the instrument magnitude is built from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum MagnitudeSystem {
    /// Johnson V.
    V,
    /// Hipparcos Hp (default, as the ICD).
    #[default]
    Hp,
}

/// Truth-sky parameters (scenario `[sky]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SkyParams {
    /// Base magnitude of the instrument magnitude.
    pub magnitude_system: MagnitudeSystem,
    /// Colour term k in `m_inst = m + k (B−V)` (mag per mag).
    pub colour_term: f64,
    /// Apply annual parallax.
    pub apply_parallax: bool,
    /// Multiplier on the catalogue proper motions used by the truth (1 = right proper
    /// motion; 0 = stars frozen at J1991.25, i.e. a truth that "forgot" proper motion).
    /// Effect hook for catalogue-epoch studies; the onboard catalogue is separate.
    pub proper_motion_scale: f64,
    /// 1σ of an extra random proper motion per star and axis (mas/yr) added to the truth:
    /// the catalogue's proper motions are then wrong by this much. 0 = off.
    pub proper_motion_error_sigma_mas_per_yr: f64,
    /// Seed of the per-star proper-motion errors.
    pub proper_motion_error_seed: u64,
    /// Cell size of the cone index (deg).
    pub cell_deg: f64,
    /// Include the spacecraft's orbital velocity (≤ 5.2″) in the stars' aberration; `false`
    /// keeps only the annual part (attribution studies: the OBC can correct only that one).
    pub orbital_aberration: bool,
}

impl Default for SkyParams {
    fn default() -> Self {
        Self {
            magnitude_system: MagnitudeSystem::Hp,
            colour_term: 0.0,
            apply_parallax: true,
            proper_motion_scale: 1.0,
            proper_motion_error_sigma_mas_per_yr: 0.0,
            proper_motion_error_seed: 0,
            cell_deg: 2.0,
            orbital_aberration: true,
        }
    }
}

/// One star of the truth sky.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SkyStar {
    /// Hipparcos number.
    pub hip: u32,
    /// Catalogue direction at J1991.25 (ICRS unit vector).
    pub dir_cat_eci: Vector3<f64>,
    /// Proper motion as a tangent vector (rad per Julian year), truth (scaled, perturbed).
    pub pm_eci_rad_per_yr: Vector3<f64>,
    /// Parallax (rad); 0 when the catalogue value is ≤ 0 or parallax is off.
    pub parallax_rad: f64,
    /// Instrument magnitude (see the module doc).
    pub magnitude: f64,
    /// Hipparcos Hp.
    pub hp_mag: f64,
    /// Johnson V (Hp where the catalogue has none).
    pub v_mag: f64,
}

impl SkyStar {
    /// Astrometric direction at `j2000_tt_s`, from an observer at `observer_bary_eci_km`
    /// (linear space motion from J1991.25 plus parallax; no aberration).
    #[must_use]
    pub fn astrometric_dir_eci(
        &self,
        j2000_tt_s: f64,
        observer_bary_eci_km: &Vector3<f64>,
    ) -> Vector3<f64> {
        let years = (j2000_tt_s - HIPPARCOS_EPOCH_J2000_TT_S) / S_PER_JULIAN_YEAR;
        let mut p = self.dir_cat_eci + self.pm_eci_rad_per_yr * years;
        if self.parallax_rad > 0.0 {
            p -= observer_bary_eci_km * (self.parallax_rad / AU_KM);
        }
        p.normalize()
    }

    /// Apparent direction: astrometric plus aberration for the observer's barycentric
    /// velocity (km/s).
    #[must_use]
    pub fn apparent_dir_eci(
        &self,
        j2000_tt_s: f64,
        observer_bary_eci_km: &Vector3<f64>,
        observer_vel_bary_eci_km_per_s: &Vector3<f64>,
    ) -> Vector3<f64> {
        aberrate(
            &self.astrometric_dir_eci(j2000_tt_s, observer_bary_eci_km),
            observer_vel_bary_eci_km_per_s,
        )
    }
}

/// J1991.25 in seconds since J2000 TT.
pub const HIPPARCOS_EPOCH_J2000_TT_S: f64 = (HIPPARCOS_EPOCH_JD_TT - JD_J2000) * 86_400.0;

/// The truth sky with its cone index.
#[derive(Clone, Debug)]
pub struct Sky {
    /// Stars sorted by index cell.
    stars: Vec<SkyStar>,
    /// Offsets into `stars` per cell (len = cells + 1).
    cell_start: Vec<u32>,
    /// First cell of each declination band (len = bands + 1).
    band_first_cell: Vec<u32>,
    band_rad: f64,
    orbital_aberration: bool,
}

impl Sky {
    /// Load `hipparcos_mag6p5.csv`-format text.
    ///
    /// # Errors
    /// Missing columns or unparsable numbers (named with the row).
    pub fn from_csv(table: &CsvTable, params: &SkyParams) -> anyhow::Result<Self> {
        let c = |n: &str| table.column(n);
        let (hip_c, ra_c, dec_c, pmra_c, pmdec_c, plx_c, hp_c, v_c, bv_c) = (
            c("hip")?,
            c("ra_deg")?,
            c("dec_deg")?,
            c("pmra_mas_yr")?,
            c("pmdec_mas_yr")?,
            c("parallax_mas")?,
            c("hp_mag")?,
            c("v_mag")?,
            c("b_v")?,
        );
        let mut rng = ChaCha8Rng::seed_from_u64(params.proper_motion_error_seed);
        let mut stars = Vec::with_capacity(table.len());
        for row in 0..table.len() {
            let hip: u32 = table
                .text(row, hip_c)
                .parse()
                .map_err(|e| anyhow::anyhow!("row {row}: bad hip: {e}"))?;
            let ra = table.f64(row, ra_c)? * RAD_PER_DEG;
            let dec = table.f64(row, dec_c)? * RAD_PER_DEG;
            let (sa, ca) = ra.sin_cos();
            let (sd, cd) = dec.sin_cos();
            let dir = Vector3::new(cd * ca, cd * sa, sd);
            let east = Vector3::new(-sa, ca, 0.0);
            let north = Vector3::new(-sd * ca, -sd * sa, cd);
            let mut pm_east = table.f64(row, pmra_c)? * params.proper_motion_scale;
            let mut pm_north = table.f64(row, pmdec_c)? * params.proper_motion_scale;
            if params.proper_motion_error_sigma_mas_per_yr > 0.0 {
                let (ge, gn): (f64, f64) = (
                    StandardNormal.sample(&mut rng),
                    StandardNormal.sample(&mut rng),
                );
                pm_east += ge * params.proper_motion_error_sigma_mas_per_yr;
                pm_north += gn * params.proper_motion_error_sigma_mas_per_yr;
            }
            let pm = (east * pm_east + north * pm_north) * RAD_PER_MAS;
            let plx_mas = table.f64(row, plx_c)?;
            let hp = table.f64(row, hp_c)?;
            let v = if table.text(row, v_c).is_empty() {
                hp
            } else {
                table.f64(row, v_c)?
            };
            let bv = if table.text(row, bv_c).is_empty() {
                0.0
            } else {
                table.f64(row, bv_c)?
            };
            let base = match params.magnitude_system {
                MagnitudeSystem::V => v,
                MagnitudeSystem::Hp => hp,
            };
            stars.push(SkyStar {
                hip,
                dir_cat_eci: dir,
                pm_eci_rad_per_yr: pm,
                parallax_rad: if params.apply_parallax && plx_mas > 0.0 {
                    plx_mas * RAD_PER_MAS
                } else {
                    0.0
                },
                magnitude: base + params.colour_term * bv,
                hp_mag: hp,
                v_mag: v,
            });
        }
        let mut sky = Self::build_index(stars, params.cell_deg);
        sky.orbital_aberration = params.orbital_aberration;
        Ok(sky)
    }

    /// Whether the FHST truth adds the orbital velocity to the aberration (see [`SkyParams`]).
    #[must_use]
    pub fn orbital_aberration(&self) -> bool {
        self.orbital_aberration
    }

    /// Load a catalogue file.
    ///
    /// # Errors
    /// I/O or format errors.
    pub fn load(path: &std::path::Path, params: &SkyParams) -> anyhow::Result<Self> {
        Self::from_csv(&CsvTable::read(path)?, params)
    }

    fn build_index(mut stars: Vec<SkyStar>, cell_deg: f64) -> Self {
        let band_rad = cell_deg.clamp(0.25, 30.0) * RAD_PER_DEG;
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let bands = (core::f64::consts::PI / band_rad).ceil() as usize;
        let band_rad = core::f64::consts::PI / bands as f64;
        let mut band_first_cell = Vec::with_capacity(bands + 1);
        let mut cells = 0_u32;
        for b in 0..bands {
            band_first_cell.push(cells);
            // Width at the band edge nearest the equator.
            let lo = -core::f64::consts::FRAC_PI_2 + b as f64 * band_rad;
            let hi = lo + band_rad;
            let widest = if lo <= 0.0 && hi >= 0.0 {
                1.0
            } else {
                lo.cos().max(hi.cos())
            };
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let n = ((2.0 * core::f64::consts::PI * widest / band_rad).floor() as u32).max(1);
            cells += n;
        }
        band_first_cell.push(cells);
        let mut sky = Self {
            stars: Vec::new(),
            cell_start: Vec::new(),
            band_first_cell,
            band_rad,
            orbital_aberration: true,
        };
        let mut keyed: Vec<(u32, SkyStar)> = stars
            .drain(..)
            .map(|s| (sky.cell_of(&s.dir_cat_eci), s))
            .collect();
        keyed.sort_by_key(|(c, s)| (*c, s.hip));
        let mut cell_start = vec![0_u32; cells as usize + 1];
        for (c, _) in &keyed {
            cell_start[*c as usize + 1] += 1;
        }
        for i in 0..cells as usize {
            cell_start[i + 1] += cell_start[i];
        }
        sky.stars = keyed.into_iter().map(|(_, s)| s).collect();
        sky.cell_start = cell_start;
        sky
    }

    fn band_of_dec(&self, dec: f64) -> usize {
        let bands = self.band_first_cell.len() - 1;
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let b = ((dec + core::f64::consts::FRAC_PI_2) / self.band_rad)
            .floor()
            .max(0.0) as usize;
        b.min(bands - 1)
    }

    fn cells_in_band(&self, band: usize) -> u32 {
        self.band_first_cell[band + 1] - self.band_first_cell[band]
    }

    fn ra_cell(&self, band: usize, ra: f64) -> u32 {
        let n = self.cells_in_band(band);
        let frac = ra.rem_euclid(2.0 * core::f64::consts::PI) / (2.0 * core::f64::consts::PI);
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let c = (frac * f64::from(n)).floor() as u32;
        c.min(n - 1)
    }

    fn cell_of(&self, dir: &Vector3<f64>) -> u32 {
        let dec = dir.z.clamp(-1.0, 1.0).asin();
        let ra = dir.y.atan2(dir.x);
        let band = self.band_of_dec(dec);
        self.band_first_cell[band] + self.ra_cell(band, ra)
    }

    /// All stars (sorted by index cell, not by HIP).
    #[must_use]
    pub fn stars(&self) -> &[SkyStar] {
        &self.stars
    }

    /// Star by internal index.
    #[must_use]
    pub fn star(&self, idx: usize) -> Option<&SkyStar> {
        self.stars.get(idx)
    }

    /// Internal index of a HIP number (linear search; not for the per-cycle path).
    #[must_use]
    pub fn index_of_hip(&self, hip: u32) -> Option<usize> {
        self.stars.iter().position(|s| s.hip == hip)
    }

    /// Call `f(index, star)` for every star whose *catalogue* direction lies within
    /// `radius_rad + INDEX_MARGIN_RAD` of `center_eci` (unit). The caller applies its exact
    /// test to the apparent direction. No allocation.
    pub fn for_each_in_cone<F: FnMut(usize, &SkyStar)>(
        &self,
        center_eci: &Vector3<f64>,
        radius_rad: f64,
        mut f: F,
    ) {
        let r = (radius_rad + INDEX_MARGIN_RAD).min(core::f64::consts::PI);
        let cos_r = r.cos();
        let dec_c = center_eci.z.clamp(-1.0, 1.0).asin();
        let ra_c = center_eci.y.atan2(center_eci.x);
        let lo_band = self.band_of_dec(dec_c - r);
        let hi_band = self.band_of_dec(dec_c + r);
        let pole_inside = dec_c.abs() + r >= core::f64::consts::FRAC_PI_2;
        let half_width = if pole_inside {
            core::f64::consts::PI
        } else {
            (r.sin() / dec_c.cos()).clamp(-1.0, 1.0).asin()
        };
        for band in lo_band..=hi_band {
            let n = self.cells_in_band(band);
            let first = self.band_first_cell[band];
            let mut visit = |cell: u32| {
                let c = (first + cell) as usize;
                let (a, b) = (self.cell_start[c] as usize, self.cell_start[c + 1] as usize);
                for (k, s) in self.stars[a..b].iter().enumerate() {
                    if s.dir_cat_eci.dot(center_eci) >= cos_r {
                        f(a + k, s);
                    }
                }
            };
            if pole_inside
                || 2.0 * half_width >= 2.0 * core::f64::consts::PI * (1.0 - 1.0 / f64::from(n))
            {
                for cell in 0..n {
                    visit(cell);
                }
            } else {
                let c0 = self.ra_cell(band, ra_c - half_width);
                let c1 = self.ra_cell(band, ra_c + half_width);
                let mut cell = c0;
                loop {
                    visit(cell);
                    if cell == c1 {
                        break;
                    }
                    cell = (cell + 1) % n;
                }
            }
        }
    }
}

/// Bright-object keep-out angles (scenario parameters of each tracker).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ExclusionParams {
    /// Minimum angle between the boresight and the Sun (deg).
    pub sun_deg: f64,
    /// Minimum angle between the boresight and the Earth's limb (deg); negative allows
    /// pointing inside the limb (for tests).
    pub earth_limb_deg: f64,
}

impl Default for ExclusionParams {
    /// 45° Sun and 25° Earth-limb keep-out: chosen as plausible for a shaded image-dissector
    /// tracker; the paper gives no values.
    fn default() -> Self {
        Self {
            sun_deg: 45.0,
            earth_limb_deg: 25.0,
        }
    }
}

impl ExclusionParams {
    /// The boresight is clear of the Sun and of the Earth's limb.
    #[must_use]
    pub fn is_clear(
        &self,
        boresight_eci: &Vector3<f64>,
        sun_dir_eci: &Vector3<f64>,
        pos_eci_km: &Vector3<f64>,
    ) -> bool {
        let sun_angle = boresight_eci.dot(sun_dir_eci).clamp(-1.0, 1.0).acos();
        if sun_angle < self.sun_deg * RAD_PER_DEG {
            return false;
        }
        let r = pos_eci_km.norm();
        let earth_radius_angle = (EARTH_RADIUS_KM / r).clamp(-1.0, 1.0).asin();
        let nadir_angle = boresight_eci
            .dot(&(-pos_eci_km / r))
            .clamp(-1.0, 1.0)
            .acos();
        nadir_angle - earth_radius_angle >= self.earth_limb_deg * RAD_PER_DEG
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::data_dir;
    use crate::sun::sun_state;
    use fsw_core::units::ARCSEC_PER_RAD;

    fn sky() -> Sky {
        sky_with(SkyParams::default())
    }

    /// The shipped catalog loaded with `params`.
    fn sky_with(params: SkyParams) -> Sky {
        Sky::load(&data_dir().join("hipparcos_mag6p5.csv"), &params).unwrap()
    }

    fn angle_mas(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
        a.normalize().cross(&b.normalize()).norm().asin() * ARCSEC_PER_RAD * 1e3
    }

    /// Source: data/aberration_reference.csv (Skyfield 1.55 + DE421). Tolerances: space
    /// motion + parallax 1 mas; aberration formula 0.1 mas (same relativistic formula); full
    /// chain with our own Earth ephemeris 2 mas.
    #[test]
    fn val_space_motion_parallax_and_aberration() {
        let sky = sky();
        let t = CsvTable::read(&data_dir().join("aberration_reference.csv")).unwrap();
        assert_eq!(t.len(), 1000);
        let (hip_c, jd_c) = (t.column("hip").unwrap(), t.column("jd_tt").unwrap());
        let (mut max_astr, mut max_ab, mut max_chain, mut max_cat) =
            (0.0_f64, 0.0_f64, 0.0_f64, 0.0_f64);
        for row in 0..t.len() {
            let hip: u32 = t.text(row, hip_c).parse().unwrap();
            let star = sky.star(sky.index_of_hip(hip).unwrap()).unwrap();
            let s = (t.f64(row, jd_c).unwrap() - JD_J2000) * 86_400.0;
            let cat = t.xyz(row, "cat_{}").unwrap();
            let astr = t.xyz(row, "astr_{}").unwrap();
            let app = t.xyz(row, "app_{}").unwrap();
            let v = t.xyz(row, "earth_v{}_kms").unwrap();
            let sun = sun_state(s);
            max_cat = max_cat.max(angle_mas(&star.dir_cat_eci, &cat));
            let mine_astr = star.astrometric_dir_eci(s, &sun.earth_pos_bary_eci_km);
            max_astr = max_astr.max(angle_mas(&mine_astr, &astr));
            max_ab = max_ab.max(angle_mas(&aberrate(&astr, &v), &app));
            let mine_app = star.apparent_dir_eci(
                s,
                &sun.earth_pos_bary_eci_km,
                &sun.earth_vel_bary_eci_km_per_s,
            );
            max_chain = max_chain.max(angle_mas(&mine_app, &app));
        }
        eprintln!(
            "stars vs Skyfield: catalogue {max_cat:.4} mas, astrometric {max_astr:.4} mas, \
             aberration formula {max_ab:.4} mas, full chain {max_chain:.4} mas"
        );
        assert!(max_cat < 0.01);
        assert!(max_astr < 1.0);
        assert!(max_ab < 0.1);
        assert!(max_chain < 2.0);
    }

    /// The index returns exactly the brute-force set, including near the poles and RA wrap.
    #[test]
    fn cone_index_matches_brute_force() {
        let sky = sky();
        assert_eq!(sky.stars().len(), 7982);
        let radius = 5.66 * RAD_PER_DEG;
        let centers = [
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(1.0, -0.01, 0.05),
            Vector3::new(0.0, 0.05, 1.0),
            Vector3::new(0.1, 0.0, -1.0),
            Vector3::new(-0.3, 0.4, 0.86),
            Vector3::new(-1.0, -1.0, 0.0),
            Vector3::new(0.2, -0.3, -0.93),
        ];
        for c in centers {
            let c = c.normalize();
            let cos_r = (radius + INDEX_MARGIN_RAD).cos();
            let mut found: Vec<u32> = Vec::new();
            sky.for_each_in_cone(&c, radius, |_, s| found.push(s.hip));
            let mut brute: Vec<u32> = sky
                .stars()
                .iter()
                .filter(|s| s.dir_cat_eci.dot(&c) >= cos_r)
                .map(|s| s.hip)
                .collect();
            found.sort_unstable();
            brute.sort_unstable();
            assert_eq!(found, brute, "center {c:?}");
            assert!(!brute.is_empty());
        }
    }

    /// Eligible FHST stars (2.0 ≤ m ≤ 5.7) and their density, for the record.
    #[test]
    fn fhst_window_star_count() {
        let count = |magnitude_system| {
            let sky = sky_with(SkyParams {
                magnitude_system,
                ..SkyParams::default()
            });
            sky.stars()
                .iter()
                .filter(|s| (2.0..=5.7).contains(&s.magnitude))
                .count()
        };
        let (n, n_hp) = (count(MagnitudeSystem::V), count(MagnitudeSystem::Hp));
        eprintln!(
            "FHST-eligible stars: {n} in V, {n_hp} in Hp; {:.2} per 8x8 deg FOV (Hp)",
            n_hp as f64 * 64.0 / 41_253.0
        );
        assert!((3000..4200).contains(&n), "{n}");
        assert!((3000..4200).contains(&n_hp), "{n_hp}");
    }

    #[test]
    fn proper_motion_hooks() {
        let frozen = sky_with(SkyParams {
            proper_motion_scale: 0.0,
            ..SkyParams::default()
        });
        let normal = sky();
        let i = normal.index_of_hip(71683).unwrap();
        let j = frozen.index_of_hip(71683).unwrap();
        let s = HIPPARCOS_EPOCH_J2000_TT_S + S_PER_JULIAN_YEAR;
        let zero = Vector3::zeros();
        let d = angle_mas(
            &normal.star(i).unwrap().astrometric_dir_eci(s, &zero),
            &frozen.star(j).unwrap().astrometric_dir_eci(s, &zero),
        );
        assert!((d - 3700.0).abs() < 200.0, "α Cen A moves ~3.7″/yr: {d}");
        let noisy = sky_with(SkyParams {
            proper_motion_error_sigma_mas_per_yr: 10.0,
            ..SkyParams::default()
        });
        let k = noisy.index_of_hip(71683).unwrap();
        let e = angle_mas(
            &normal.star(i).unwrap().astrometric_dir_eci(s, &zero),
            &noisy.star(k).unwrap().astrometric_dir_eci(s, &zero),
        );
        assert!(e > 0.0 && e < 60.0, "{e}");
    }

    #[test]
    fn exclusion_geometry() {
        let ex = ExclusionParams::default();
        let pos = Vector3::new(6833.0, 0.0, 0.0);
        let sun = Vector3::new(0.0, 1.0, 0.0);
        // Zenith: clear of both.
        assert!(ex.is_clear(&Vector3::new(1.0, 0.0, 0.0), &sun, &pos));
        // 10° from the Sun.
        let near_sun = Vector3::new(
            10.0_f64.to_radians().sin(),
            10.0_f64.to_radians().cos(),
            0.0,
        );
        assert!(!ex.is_clear(&near_sun, &sun, &pos));
        // The Earth's radius subtends asin(6378.137/6833) = 69.0° from 6833 km, so the limb is
        // 111.0° from zenith; 25° keep-out -> clear only within 86.0° of zenith.
        let at = |deg_from_zenith: f64| {
            let a = deg_from_zenith.to_radians();
            Vector3::new(a.cos(), 0.0, a.sin())
        };
        assert!(ex.is_clear(&at(85.5), &sun, &pos));
        assert!(!ex.is_clear(&at(86.5), &sun, &pos));
    }
}
