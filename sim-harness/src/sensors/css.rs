//! # Coarse Sun sensors (CSSs): cosine-law eyes with Earth albedo
//!
//! Why: the CSSs find the Sun from any attitude (Sun acquisition, issue 20), where the FSSs'
//! 64° × 64° fields see nothing. The paper does not describe GRO's CSS layout; the default
//! is six eyes on the ±X, ±Y, ±Z body axes (a common full-sky arrangement), each a
//! documented scenario parameter.
//!
//! # Model (each eye, normal `n` in ACS)
//! `counts = round(k · (f_sun + f_albedo) + noise)`, clamped to `[0, 2·k]`, with
//! `k = counts_at_normal_incidence` and
//! - `f_sun = cos θ` for `θ = ∠(n, ŝ) ≤ fov_half_angle_deg`, else 0, and 0 in the umbra
//!   (ŝ: the apparent Sun in ACS; the photocell's cosine law, Wertz 1978 §6.1);
//! - `f_albedo = a · (R/r)² · max(0, n·(−r̂)) · max(0, ŝ·r̂)`: the Earth as a Lambertian
//!   disc of albedo `a` lit as its sub-spacecraft point, seen by a flat eye through the
//!   nadir cosine; a first-order model (exact for an eye facing nadir under a full disc,
//!   off by up to tens of per cent of the albedo term near the horizon and the terminator),
//!   `earth_albedo = 0` turns it off;
//! - `noise`: white Gaussian (counts, 1σ).
//!
//! Randomness: one `ChaCha8Rng`, stream [`super::stream::CSS`].

use nalgebra::Vector3;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use super::{model_rng, stream, TruthSnapshot};
use fsw_core::units::RAD_PER_DEG;
use gro_reference::sun::EARTH_RADIUS_KM;

/// Most eyes a CSS set may have.
pub const MAX_CSS_EYES: usize = 12;

/// The coarse Sun sensor set (scenario `[css]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CssParams {
    /// Eye normals in ACS (normalised on use); at most [`MAX_CSS_EYES`].
    pub normals_acs: Vec<[f64; 3]>,
    /// Half angle of each eye's field of view (deg), ≤ 90.
    pub fov_half_angle_deg: f64,
    /// Output at normal incidence, no albedo (counts).
    pub counts_at_normal_incidence: f64,
    /// White noise (counts, 1σ).
    pub noise_counts_1sigma: f64,
    /// Earth's Bond albedo for the reflected light (0 = off).
    pub earth_albedo: f64,
}

impl Default for CssParams {
    fn default() -> Self {
        Self {
            // The layout the OBC's boot magnetics table assumes (one definition).
            normals_acs: fsw_core::tables::magnetics::CSS_NORMALS_DEFAULT.to_vec(),
            fov_half_angle_deg: 85.0,
            counts_at_normal_incidence: 1_000.0,
            noise_counts_1sigma: 2.0,
            earth_albedo: 0.3,
        }
    }
}

impl CssParams {
    /// Check the parameters.
    ///
    /// # Errors
    /// No eye, too many, a zero normal, a field of view outside (0, 90]°, a non-positive
    /// scale, a negative noise or an albedo outside [0, 1].
    pub fn validate(&self) -> anyhow::Result<()> {
        if self.normals_acs.is_empty() || self.normals_acs.len() > MAX_CSS_EYES {
            anyhow::bail!(
                "css.normals_acs must have 1 to {MAX_CSS_EYES} eyes, got {}",
                self.normals_acs.len()
            );
        }
        if let Some(i) = self
            .normals_acs
            .iter()
            .position(|n| !(Vector3::from(*n).norm() > 1e-9))
        {
            anyhow::bail!("css.normals_acs[{i}] must not be zero");
        }
        if !(self.fov_half_angle_deg > 0.0 && self.fov_half_angle_deg <= 90.0) {
            anyhow::bail!(
                "css.fov_half_angle_deg must be in (0, 90], got {}",
                self.fov_half_angle_deg
            );
        }
        if !(self.counts_at_normal_incidence > 0.0 && self.counts_at_normal_incidence <= 30_000.0) {
            anyhow::bail!(
                "css.counts_at_normal_incidence must be in (0, 30000], got {}",
                self.counts_at_normal_incidence
            );
        }
        if !(self.noise_counts_1sigma >= 0.0) {
            anyhow::bail!(
                "css.noise_counts_1sigma must be ≥ 0, got {}",
                self.noise_counts_1sigma
            );
        }
        if !(0.0..=1.0).contains(&self.earth_albedo) {
            anyhow::bail!(
                "css.earth_albedo must be in [0, 1], got {}",
                self.earth_albedo
            );
        }
        Ok(())
    }
}

/// One reading of the CSS set: counts per eye (the first `eyes` entries).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct CssReading {
    /// Counts per eye.
    pub counts: [u16; MAX_CSS_EYES],
    /// Number of eyes in use.
    pub eyes: u8,
}

/// The CSS set.
#[derive(Clone, Debug)]
pub struct Css {
    params: CssParams,
    normals_acs: Vec<Vector3<f64>>,
    cos_fov: f64,
    rng: ChaCha8Rng,
}

impl Css {
    /// The CSS set of scenario seed `seed` (eyes beyond [`MAX_CSS_EYES`] are ignored;
    /// `validate` refuses them).
    #[must_use]
    pub fn new(params: CssParams, seed: u64) -> Self {
        Self::with_rng(params, model_rng(seed, stream::CSS))
    }

    /// A CSS set with a given generator.
    #[must_use]
    pub fn with_rng(params: CssParams, rng: ChaCha8Rng) -> Self {
        let normals_acs = params
            .normals_acs
            .iter()
            .take(MAX_CSS_EYES)
            .map(|n| Vector3::from(*n).normalize())
            .collect();
        let cos_fov = (params.fov_half_angle_deg * RAD_PER_DEG).cos();
        Self {
            params,
            normals_acs,
            cos_fov,
            rng,
        }
    }

    /// The model's parameters.
    #[must_use]
    pub fn params(&self) -> &CssParams {
        &self.params
    }

    /// The noise-free output of every eye (fraction of `counts_at_normal_incidence`): direct
    /// Sun plus albedo; entries past the eyes in use are 0. Allocates nothing.
    #[must_use]
    pub fn ideal_fractions(&self, truth: &TruthSnapshot) -> [f64; MAX_CSS_EYES] {
        let sun_acs = truth.m_acs_from_eci * truth.sun_dir_app_eci;
        let r = truth.pos_eci_km.norm();
        let r_hat_eci = truth.pos_eci_km / r.max(1e-9);
        let nadir_acs = -(truth.m_acs_from_eci * r_hat_eci);
        let lit = truth.sun_dir_app_eci.dot(&r_hat_eci).max(0.0);
        let albedo_scale =
            self.params.earth_albedo * (EARTH_RADIUS_KM / r.max(EARTH_RADIUS_KM)).powi(2) * lit;
        let mut out = [0.0; MAX_CSS_EYES];
        for (slot, n) in out.iter_mut().zip(&self.normals_acs) {
            let c = n.dot(&sun_acs);
            let direct = if !truth.in_umbra && c >= self.cos_fov && c > 0.0 {
                c
            } else {
                0.0
            };
            *slot = direct + albedo_scale * n.dot(&nadir_acs).max(0.0);
        }
        out
    }

    /// This cycle's reading.
    pub fn sample(&mut self, truth: &TruthSnapshot) -> CssReading {
        let k = self.params.counts_at_normal_incidence;
        let sigma = self.params.noise_counts_1sigma;
        let mut out = CssReading {
            eyes: u8::try_from(self.normals_acs.len()).unwrap_or(0),
            ..CssReading::default()
        };
        let fractions = self.ideal_fractions(truth);
        let eyes = self.normals_acs.len();
        for (slot, f) in out.counts.iter_mut().zip(fractions).take(eyes) {
            let n: f64 = StandardNormal.sample(&mut self.rng);
            let v = (k * f + sigma * n).round().clamp(0.0, 2.0 * k);
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let c = v as u16;
            *slot = c;
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fsw_core::attitude::Quat;

    fn quiet() -> CssParams {
        CssParams {
            noise_counts_1sigma: 0.0,
            earth_albedo: 0.0,
            ..CssParams::default()
        }
    }

    /// Sun at angle θ from an eye's normal: counts = k cos θ inside the FOV, 0 outside.
    #[test]
    fn cosine_law_and_fov_cut() {
        let mut css = Css::new(quiet(), 1);
        for theta_deg in [0.0_f64, 30.0, 60.0, 84.0, 86.0, 120.0] {
            let th = theta_deg * RAD_PER_DEG;
            let mut truth = TruthSnapshot::at_rest(Quat::IDENTITY);
            // Sun in the x-y plane at θ from +X.
            truth.sun_dir_app_eci = Vector3::new(th.cos(), th.sin(), 0.0);
            let r = css.sample(&truth);
            let expect = if theta_deg <= 85.0 {
                (1_000.0 * th.cos()).round()
            } else {
                0.0
            };
            assert_eq!(f64::from(r.counts[0]), expect, "θ = {theta_deg}°");
            assert_eq!(r.eyes, 6);
            // The −X eye never sees a Sun in front of +X.
            if theta_deg < 90.0 {
                assert_eq!(r.counts[1], 0);
            }
        }
    }

    #[test]
    fn umbra_leaves_only_albedo_and_albedo_faces_nadir() {
        let params = CssParams {
            noise_counts_1sigma: 0.0,
            ..CssParams::default()
        };
        let css = Css::new(params, 1);
        let mut truth = TruthSnapshot::at_rest(Quat::IDENTITY);
        // Spacecraft on +x at 6833 km, Sun along +x: the sub-spacecraft point is at noon.
        truth.sun_dir_app_eci = Vector3::new(1.0, 0.0, 0.0);
        let f = css.ideal_fractions(&truth);
        let albedo = 0.3 * (EARTH_RADIUS_KM / 6_833.0).powi(2);
        assert!((f[0] - 1.0).abs() < 1e-12); // +X eye: direct Sun only (nadir is −X)
        assert!((f[1] - albedo).abs() < 1e-12); // −X eye faces nadir
        assert!(f[2].abs() < 1e-12);
        truth.in_umbra = true;
        let f = css.ideal_fractions(&truth);
        assert!(f[0].abs() < 1e-12);
        // Night side: the Sun behind the Earth lights nothing under the spacecraft.
        truth.sun_dir_app_eci = Vector3::new(-1.0, 0.0, 0.0);
        assert!(css.ideal_fractions(&truth)[1].abs() < 1e-12);
    }

    #[test]
    fn noise_has_the_stated_sigma() {
        let params = CssParams {
            earth_albedo: 0.0,
            noise_counts_1sigma: 5.0,
            ..CssParams::default()
        };
        let mut css = Css::new(params, 9);
        let truth = TruthSnapshot::at_rest(Quat::IDENTITY); // Sun along +Y: eye 2 at 1000
        let n = 4_000;
        let v: Vec<f64> = (0..n)
            .map(|_| f64::from(css.sample(&truth).counts[2]))
            .collect();
        let mean = v.iter().sum::<f64>() / f64::from(n);
        let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / f64::from(n - 1)).sqrt();
        // Rounding adds 1/12 count²: √(25 + 0.083) = 5.008; sampling spread of sd ≈ 5/√(2n).
        assert!(
            (mean - 1_000.0).abs() < 4.0 * 5.0 / f64::from(n).sqrt(),
            "{mean}"
        );
        assert!(
            (sd - 5.008).abs() < 4.0 * 5.0 / f64::from(2 * n).sqrt(),
            "{sd}"
        );
    }

    #[test]
    fn validate_refuses_bad_sets() {
        assert!(CssParams::default().validate().is_ok());
        let none = CssParams {
            normals_acs: vec![],
            ..CssParams::default()
        };
        assert!(none.validate().is_err());
        let wide = CssParams {
            fov_half_angle_deg: 95.0,
            ..CssParams::default()
        };
        assert!(wide.validate().is_err());
    }
}
