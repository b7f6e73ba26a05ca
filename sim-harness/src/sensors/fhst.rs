//! # Fixed-head star tracker (NASA Standard FHST) truth model
//!
//! Why: the FHSTs are the fine attitude and alignment-calibration sensors; the model must
//! give the onboard software realistic one-star-at-a-time data and give the ground the
//! signatures it has to discover (aberration, distortion, thermal drift, ...).
//!
//! # Geometry
//! True alignment `M_AS,true = Rot(θ_true) M_AS,prelaunch` (θ_true in ACS, default the
//! Table 1 × Table 2 rotation, [`crate::paper::PaperFacts::rotation_vector_from_tables_rad`]),
//! optionally rotated further by `thermal_alignment_arcsec_per_c · ΔT`. A star's apparent
//! direction `u` (proper motion, parallax, annual + orbital aberration) gives
//! `s = M_AS,trueᵀ A u`, `H = atan2(s_x, s_z)`, `V = atan2(s_y, s_z)` (fsw_core::raw). In the
//! FOV when `s_z > 0` and `|H|, |V| ≤ fov_half_width_deg` (8° × 8°).
//!
//! # Noise (documented formula)
//! Per axis, 1σ in arcsec, with m the instrument magnitude and ρ = √(H² + V²):
//! `σ(m, ρ) = noise_floor + noise_faint · 10^{0.2 (m − magnitude_max)} + noise_edge · (ρ/ρ_corner)²`,
//! ρ_corner = 4√2°. The middle term is photon-limited centroiding (∝ flux^-½); the last is
//! the image dissector's off-axis blur. Defaults 6 + 12·… + 6 give 8.2″ for a 2.0 mag star on
//! the boresight and 24″ for a 5.7 mag star in a corner — the paper's 8–24″. The output is
//! quantized to 7.78″ counts (σ 2.2″). The measured magnitude has 0.05 mag noise.
//!
//! # Tracking (one star at a time)
//! ```text
//!   Searching ──(search_time_s elapsed, star in FOV)──> Tracking(star, since)
//!   Tracking ──(star leaves FOV | t − since ≥ max_track_s | Sun/Earth keep-out)──> Searching
//! ```
//! Acquisition picks the brightest eligible star (magnitude window 2.0–5.7, in FOV) that was
//! not tracked within `reacquire_holdoff_s`; if all were, the one tracked longest ago. This
//! emulates GRO's OBC commanding break-track to sample many stars (FOV coverage for the
//! calibration). The first sample of a new star carries `FHST_FLAG_NEW_STAR`.
//!
//! # Effect hooks (default off)
//! Time-tag offset (the sensor samples at `t − τ`), thermal alignment drift, focal-plane
//! distortion (radial ρ³ and H·V), magnitude-dependent bias, a one-time alignment step
//! (`M_AS' = Rot(θ) M_AS`, θ about the ACS axes, added to the thermal rotation from the step
//! time on). Catalogue proper-motion errors
//! live in [`crate::truth::sky::SkyParams`].

use nalgebra::{Matrix3, Vector3};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use super::{model_rng, quantize_i16, stream, TruthSnapshot};
use crate::paper::PaperFacts;
use crate::truth::sky::{ExclusionParams, Sky};
use fsw_core::attitude::rot;
use fsw_core::raw::{FhstSample, FHST_FLAG_NEW_STAR, FHST_FLAG_TRACKING, FHST_FLAG_VALID};
use fsw_core::units::{ARCSEC_PER_RAD, RAD_PER_ARCSEC, RAD_PER_DEG};

/// How many recently broken tracks the tracker remembers.
const RECENT_CAPACITY: usize = 32;
/// Reference magnitude of the magnitude-dependent bias.
const MAGNITUDE_BIAS_REFERENCE: f64 = 4.0;

/// Undeclared effects (all default off).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct FhstEffects {
    /// The sensor samples `time_tag_offset_s` before the frame time (s, + = late tag).
    pub time_tag_offset_s: f64,
    /// Alignment rotation per °C of sensor temperature deviation, ACS (arcsec/°C).
    pub thermal_alignment_arcsec_per_c: [f64; 3],
    /// Radial distortion `Δρ = k ρ³`, given as Δρ at ρ = 4° (arcsec).
    pub radial_distortion_arcsec_at_4deg: f64,
    /// Cross terms `ΔH = c_h H V`, `ΔV = c_v H V`, given at the (4°, 4°) corner (arcsec).
    pub hv_distortion_arcsec_at_corner: [f64; 2],
    /// Bias in (H, V) per magnitude fainter than 4.0 (arcsec/mag).
    pub magnitude_bias_arcsec_per_mag: [f64; 2],
    /// One-time alignment step: a rotation about the ACS axes (arcsec), `M_AS' = Rot(θ) M_AS`
    /// (the convention of diagnose's `alignment_step` and of the writer's `--align-step`),
    /// from `alignment_step_at_s` on.
    pub alignment_step_arcsec: [f64; 3],
    /// Time of the alignment step (s from the scenario start); `None` = no step.
    pub alignment_step_at_s: Option<f64>,
}

impl FhstEffects {
    /// The alignment rotation of the step at `t_s` (rad, ACS): zero before the step time.
    #[must_use]
    pub fn alignment_step_rad(&self, t_s: f64) -> Vector3<f64> {
        super::alignment_step_rad(self.alignment_step_arcsec, self.alignment_step_at_s, t_s)
    }
}

/// One FHST's parameters (scenario `[fhst1]`, `[fhst2]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FhstParams {
    /// True misalignment θ_true, ACS (arcsec): `M_true = Rot(θ_true) M_prelaunch`.
    /// `None` = the Table 1 × Table 2 rotation of this unit.
    pub misalignment_true_arcsec: Option<[f64; 3]>,
    /// Half width of the square FOV (deg). Paper: 8° square.
    pub fov_half_width_deg: f64,
    /// Brightest trackable instrument magnitude. Paper: 2.0.
    pub magnitude_min: f64,
    /// Faintest trackable instrument magnitude. Paper: 5.7.
    pub magnitude_max: f64,
    /// Noise floor (arcsec, 1σ per axis).
    pub noise_floor_arcsec: f64,
    /// Faint-star noise at `magnitude_max` (arcsec).
    pub noise_faint_arcsec: f64,
    /// Extra noise at the FOV corner (arcsec).
    pub noise_edge_arcsec: f64,
    /// Measured-magnitude noise (mag, 1σ).
    pub magnitude_noise_mag: f64,
    /// Count size (arcsec). Paper: 7.78.
    pub resolution_arcsec_per_count: f64,
    /// Break track after this long on one star (s).
    pub max_track_s: f64,
    /// Do not reacquire a star within this time of losing it, if another is available (s).
    pub reacquire_holdoff_s: f64,
    /// Search time after a break before a new star is reported (s).
    pub search_time_s: f64,
    /// Sun and Earth keep-out.
    pub exclusion: ExclusionParams,
    /// Undeclared effects.
    pub effects: FhstEffects,
}

impl Default for FhstParams {
    fn default() -> Self {
        Self {
            misalignment_true_arcsec: None,
            fov_half_width_deg: 4.0,
            magnitude_min: 2.0,
            magnitude_max: 5.7,
            noise_floor_arcsec: 6.0,
            noise_faint_arcsec: 12.0,
            noise_edge_arcsec: 6.0,
            magnitude_noise_mag: 0.05,
            resolution_arcsec_per_count: 7.78,
            max_track_s: 300.0,
            reacquire_holdoff_s: 1800.0,
            search_time_s: 2.0,
            exclusion: ExclusionParams::default(),
            effects: FhstEffects::default(),
        }
    }
}

impl FhstParams {
    /// 1σ noise per axis (arcsec) for magnitude `m` at focal-plane radius `rho_rad`.
    #[must_use]
    pub fn sigma_arcsec(&self, magnitude: f64, rho_rad: f64) -> f64 {
        let rho_corner = self.fov_half_width_deg * RAD_PER_DEG * std::f64::consts::SQRT_2;
        self.noise_floor_arcsec
            + self.noise_faint_arcsec * 10f64.powf(0.2 * (magnitude - self.magnitude_max))
            + self.noise_edge_arcsec * (rho_rad / rho_corner).powi(2)
    }
}

/// Tracker state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TrackState {
    /// Looking for a star; may acquire from `ready_at_s` on.
    Searching {
        /// Earliest acquisition time (s).
        ready_at_s: f64,
    },
    /// Tracking one star.
    Tracking {
        /// Index into [`Sky::stars`].
        star: usize,
        /// Acquisition time (s).
        since_s: f64,
        /// No sample has been reported for it yet.
        fresh: bool,
    },
}

/// Truth about the last sample, for logging (`true_` columns) and tests.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct FhstTruth {
    /// HIP number of the tracked star (0 if none).
    pub hip: u32,
    /// True (H, V) before noise, distortion and quantization (rad).
    pub hv_rad: [f64; 2],
    /// Instrument magnitude of the star.
    pub magnitude: f64,
    /// 1σ noise applied (arcsec).
    pub sigma_arcsec: f64,
}

/// One FHST.
#[derive(Clone, Debug)]
pub struct Fhst {
    params: FhstParams,
    m_acs_from_fhst_true: Matrix3<f64>,
    rng: ChaCha8Rng,
    state: TrackState,
    /// (HIP, time the track ended) of recent tracks; ring buffer.
    recent: [(u32, f64); RECENT_CAPACITY],
    recent_next: usize,
    last_truth: FhstTruth,
}

impl Fhst {
    /// FHST `unit` (0 or 1) with its paper prelaunch alignment.
    #[must_use]
    pub fn new(unit: usize, params: FhstParams, paper: &PaperFacts, seed: u64) -> Self {
        let unit = unit.min(1);
        let theta = params.misalignment_true_arcsec.map_or_else(
            || paper.rotation_vector_from_tables_rad(unit),
            |a| Vector3::new(a[0], a[1], a[2]) * RAD_PER_ARCSEC,
        );
        let m_true = rot(&theta) * paper.m_acs_from_fhst_prelaunch[unit];
        Self::with_alignment(m_true, params, model_rng(seed, stream::FHST1 + unit as u64))
    }

    /// An FHST with an explicit true alignment (tests, special scenarios).
    #[must_use]
    pub fn with_alignment(
        m_acs_from_fhst_true: Matrix3<f64>,
        params: FhstParams,
        rng: ChaCha8Rng,
    ) -> Self {
        Self {
            params,
            m_acs_from_fhst_true,
            rng,
            state: TrackState::Searching {
                ready_at_s: f64::NEG_INFINITY,
            },
            recent: [(0, f64::NEG_INFINITY); RECENT_CAPACITY],
            recent_next: 0,
            last_truth: FhstTruth::default(),
        }
    }

    /// True alignment without thermal drift.
    #[must_use]
    pub fn m_acs_from_fhst_true(&self) -> &Matrix3<f64> {
        &self.m_acs_from_fhst_true
    }

    /// Tracker state.
    #[must_use]
    pub fn state(&self) -> TrackState {
        self.state
    }

    /// The model's parameters.
    #[must_use]
    pub fn params(&self) -> &FhstParams {
        &self.params
    }

    /// Truth of the last sample.
    #[must_use]
    pub fn last_truth(&self) -> FhstTruth {
        self.last_truth
    }

    fn break_track(&mut self, sky: &Sky, t_s: f64) {
        if let TrackState::Tracking { star, .. } = self.state {
            if let Some(s) = sky.star(star) {
                self.recent[self.recent_next] = (s.hip, t_s);
                self.recent_next = (self.recent_next + 1) % RECENT_CAPACITY;
            }
        }
        self.state = TrackState::Searching {
            ready_at_s: t_s + self.params.search_time_s,
        };
    }

    fn last_tracked_s(&self, hip: u32) -> f64 {
        self.recent
            .iter()
            .filter(|(h, _)| *h == hip)
            .map(|(_, t)| *t)
            .fold(f64::NEG_INFINITY, f64::max)
    }

    /// (H, V) in rad of direction `s` in sensor axes, if inside the FOV.
    fn in_fov(&self, s: &Vector3<f64>) -> Option<[f64; 2]> {
        if s.z <= 0.0 {
            return None;
        }
        let h = s.x.atan2(s.z);
        let v = s.y.atan2(s.z);
        let half = self.params.fov_half_width_deg * RAD_PER_DEG;
        (h.abs() <= half && v.abs() <= half).then_some([h, v])
    }

    /// Produce this cycle's sample. `temperature_dev_c` is the sensor's temperature minus
    /// its mean (drives the thermal alignment hook).
    pub fn sample(
        &mut self,
        truth: &TruthSnapshot,
        sky: &Sky,
        temperature_dev_c: f64,
    ) -> FhstSample {
        let fx = self.params.effects;
        let t = truth.t_s;
        let m_acs_from_eci = truth.m_acs_from_eci_earlier(fx.time_tag_offset_s);
        let thermal = Vector3::from(fx.thermal_alignment_arcsec_per_c)
            * (RAD_PER_ARCSEC * temperature_dev_c)
            + fx.alignment_step_rad(t);
        let m_acs_from_fhst = if thermal == Vector3::zeros() {
            self.m_acs_from_fhst_true
        } else {
            rot(&thermal) * self.m_acs_from_fhst_true
        };
        let m_fhst_from_eci = m_acs_from_fhst.transpose() * m_acs_from_eci;
        let boresight_eci = m_fhst_from_eci.row(2).transpose();
        self.last_truth = FhstTruth::default();
        if !self.params.exclusion.is_clear(
            &boresight_eci,
            &truth.sun_dir_app_eci,
            &truth.pos_eci_km,
        ) {
            self.break_track(sky, t);
            return FhstSample::default();
        }
        let obs_pos = truth.observer_pos_bary_eci_km();
        let obs_vel = if sky.orbital_aberration() {
            truth.observer_vel_bary_eci_km_per_s()
        } else {
            truth.earth_vel_bary_eci_km_per_s
        };
        let apparent_in_sensor = |idx: usize| {
            sky.star(idx)
                .map(|s| m_fhst_from_eci * s.apparent_dir_eci(truth.j2000_tt_s, &obs_pos, &obs_vel))
        };
        // Keep or break the current track.
        if let TrackState::Tracking { star, since_s, .. } = self.state {
            let visible = apparent_in_sensor(star).and_then(|s| self.in_fov(&s));
            if visible.is_none() || t - since_s >= self.params.max_track_s {
                self.break_track(sky, t);
            }
        }
        // Acquire.
        if let TrackState::Searching { ready_at_s } = self.state {
            if t < ready_at_s {
                return FhstSample::default();
            }
            let half = self.params.fov_half_width_deg * RAD_PER_DEG;
            let radius = (2.0 * half * half).sqrt() * 1.01;
            let holdoff = self.params.reacquire_holdoff_s;
            // Best = (not recently tracked, brightest) else (oldest track).
            let mut best: Option<(usize, bool, f64, f64)> = None;
            sky.for_each_in_cone(&boresight_eci, radius, |idx, star| {
                if !(self.params.magnitude_min..=self.params.magnitude_max)
                    .contains(&star.magnitude)
                {
                    return;
                }
                let s =
                    m_fhst_from_eci * star.apparent_dir_eci(truth.j2000_tt_s, &obs_pos, &obs_vel);
                if self.in_fov(&s).is_none() {
                    return;
                }
                let last = self.last_tracked_s(star.hip);
                let fresh = t - last >= holdoff;
                let better = match best {
                    None => true,
                    Some((_, bfresh, bmag, blast)) => {
                        if fresh != bfresh {
                            fresh
                        } else if fresh {
                            star.magnitude < bmag
                        } else {
                            last < blast
                        }
                    }
                };
                if better {
                    best = Some((idx, fresh, star.magnitude, last));
                }
            });
            match best {
                Some((idx, ..)) => {
                    self.state = TrackState::Tracking {
                        star: idx,
                        since_s: t,
                        fresh: true,
                    }
                }
                None => {
                    return FhstSample {
                        flags: 0,
                        ..FhstSample::default()
                    }
                }
            }
        }
        let TrackState::Tracking {
            star,
            since_s,
            fresh,
        } = self.state
        else {
            return FhstSample::default();
        };
        self.state = TrackState::Tracking {
            star,
            since_s,
            fresh: false,
        };
        let Some(sky_star) = sky.star(star) else {
            return FhstSample::default();
        };
        let Some(hv) = apparent_in_sensor(star).and_then(|s| self.in_fov(&s)) else {
            return FhstSample::default();
        };
        self.measure(hv, sky_star.hip, sky_star.magnitude, fresh)
    }

    /// Distortion, bias, noise and quantization of a true (H, V) (rad).
    fn measure(&mut self, hv: [f64; 2], hip: u32, magnitude: f64, fresh: bool) -> FhstSample {
        let p = &self.params;
        let fx = p.effects;
        let [h, v] = hv;
        let rho = (h * h + v * v).sqrt();
        let four_deg = 4.0 * RAD_PER_DEG;
        // Distortion in rad.
        let k3 = fx.radial_distortion_arcsec_at_4deg * RAD_PER_ARCSEC / four_deg.powi(3);
        let mut dh = k3 * rho * rho * h;
        let mut dv = k3 * rho * rho * v;
        let hv_scale = h * v / (four_deg * four_deg);
        dh += fx.hv_distortion_arcsec_at_corner[0] * RAD_PER_ARCSEC * hv_scale;
        dv += fx.hv_distortion_arcsec_at_corner[1] * RAD_PER_ARCSEC * hv_scale;
        let dm = magnitude - MAGNITUDE_BIAS_REFERENCE;
        dh += fx.magnitude_bias_arcsec_per_mag[0] * RAD_PER_ARCSEC * dm;
        dv += fx.magnitude_bias_arcsec_per_mag[1] * RAD_PER_ARCSEC * dm;
        let sigma = p.sigma_arcsec(magnitude, rho);
        let nh: f64 = StandardNormal.sample(&mut self.rng);
        let nv: f64 = StandardNormal.sample(&mut self.rng);
        let nm: f64 = StandardNormal.sample(&mut self.rng);
        let h_arcsec = (h + dh) * ARCSEC_PER_RAD + sigma * nh;
        let v_arcsec = (v + dv) * ARCSEC_PER_RAD + sigma * nv;
        self.last_truth = FhstTruth {
            hip,
            hv_rad: hv,
            magnitude,
            sigma_arcsec: sigma,
        };
        let mut flags = FHST_FLAG_VALID | FHST_FLAG_TRACKING;
        if fresh {
            flags |= FHST_FLAG_NEW_STAR;
        }
        FhstSample {
            h_counts: quantize_i16(h_arcsec, p.resolution_arcsec_per_count),
            v_counts: quantize_i16(v_arcsec, p.resolution_arcsec_per_count),
            magnitude_centimag: quantize_i16(magnitude + p.magnitude_noise_mag * nm, 0.01),
            flags,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::CsvTable;
    use crate::truth::sky::SkyParams;
    use fsw_core::attitude::Quat;

    /// A one-star sky at `dir` (V = `mag`), no proper motion or parallax.
    fn sky_with(stars: &[([f64; 3], f64, u32)]) -> Sky {
        let mut text = String::from(
            "hip,ra_deg,dec_deg,pmra_mas_yr,pmdec_mas_yr,parallax_mas,hp_mag,v_mag,b_v,v_i,sn,nc\n",
        );
        for (d, mag, hip) in stars {
            let v = Vector3::from(*d).normalize();
            let ra = v.y.atan2(v.x).to_degrees();
            let dec = v.z.asin().to_degrees();
            text += &format!("{hip},{ra:.12},{dec:.12},0,0,0,{mag},{mag},0.5,0.5,5,1\n");
        }
        Sky::from_csv(
            &CsvTable::parse(&text, "test").unwrap(),
            &SkyParams::default(),
        )
        .unwrap()
    }

    /// Sensor = ACS = ECI, noise off, boresight +z (zenith at +x is 90° away: Earth clear).
    fn quiet_tracker(params: FhstParams) -> Fhst {
        Fhst::with_alignment(Matrix3::identity(), params, model_rng(1, 1))
    }

    fn noiseless() -> FhstParams {
        FhstParams {
            noise_floor_arcsec: 0.0,
            noise_faint_arcsec: 0.0,
            noise_edge_arcsec: 0.0,
            magnitude_noise_mag: 0.0,
            search_time_s: 0.0,
            exclusion: ExclusionParams {
                sun_deg: 30.0,
                earth_limb_deg: -90.0,
            },
            ..FhstParams::default()
        }
    }

    #[test]
    fn star_on_boresight_gives_zero_counts_and_new_star_flag() {
        let sky = sky_with(&[([0.0, 0.0, 1.0], 3.0, 11)]);
        let mut fhst = quiet_tracker(noiseless());
        let truth = TruthSnapshot::at_rest(Quat::IDENTITY);
        let s = fhst.sample(&truth, &sky, 0.0);
        assert_eq!((s.h_counts, s.v_counts), (0, 0));
        assert_eq!(
            s.flags,
            FHST_FLAG_VALID | FHST_FLAG_TRACKING | FHST_FLAG_NEW_STAR
        );
        assert_eq!(s.magnitude_centimag, 300);
        let again = fhst.sample(&truth, &sky, 0.0);
        assert_eq!(again.flags, FHST_FLAG_VALID | FHST_FLAG_TRACKING);
    }

    /// A star at tangent-plane (H, V) = (1000″, −2000″) gives round(H/7.78) counts, through a
    /// non-trivial true alignment and attitude.
    #[test]
    fn known_offset_through_alignment_and_attitude() {
        let (h, v) = (1000.0 * RAD_PER_ARCSEC, -2000.0 * RAD_PER_ARCSEC);
        let s_sensor = Vector3::new(h.tan(), v.tan(), 1.0).normalize();
        let m_acs_from_fhst = rot(&Vector3::new(0.4, -1.1, 0.3));
        let q = Quat::from_rotation_vector(&Vector3::new(-0.2, 0.5, 0.9));
        let a = q.to_dcm();
        let star_eci = a.transpose() * m_acs_from_fhst * s_sensor;
        let sky = sky_with(&[(star_eci.into(), 4.0, 7)]);
        let mut fhst = Fhst::with_alignment(m_acs_from_fhst, noiseless(), model_rng(1, 1));
        let mut truth = TruthSnapshot::at_rest(q);
        // Put the Sun and the Earth far from this boresight.
        let bore = a.transpose() * m_acs_from_fhst * Vector3::z();
        truth.sun_dir_app_eci = -bore;
        truth.pos_eci_km = bore * 6833.0;
        let out = fhst.sample(&truth, &sky, 0.0);
        assert_eq!(out.h_counts, (1000.0_f64 / 7.78).round() as i16);
        assert_eq!(out.v_counts, (-2000.0_f64 / 7.78).round() as i16);
        assert!((fhst.last_truth().hv_rad[0] - h).abs() < 1e-9);
    }

    /// Quantization statistics: with only the 7.78″ rounding, the error is uniform
    /// (σ = q/√12 = 2.25″, |e| ≤ q/2).
    #[test]
    fn quantization_error_is_uniform() {
        let mut fhst = quiet_tracker(noiseless());
        let (mut sum, mut sum2, n) = (0.0, 0.0, 20_000);
        for k in 0..n {
            let h = (f64::from(k) * 0.731_3 - 7000.0) * RAD_PER_ARCSEC;
            let out = fhst.measure([h, 0.0], 1, 4.0, false);
            let e = f64::from(out.h_counts) * 7.78 - h * ARCSEC_PER_RAD;
            assert!(e.abs() <= 3.89 + 1e-9);
            sum += e;
            sum2 += e * e;
        }
        let mean = sum / f64::from(n);
        let sd = (sum2 / f64::from(n) - mean * mean).sqrt();
        assert!(mean.abs() < 0.05, "{mean}");
        assert!((sd - 7.78 / 12f64.sqrt()).abs() < 0.05, "{sd}");
    }

    /// The noise formula spans the paper's 8–24″ and the realised scatter matches σ.
    #[test]
    fn noise_formula_and_scatter() {
        let p = FhstParams::default();
        let corner = 4.0 * RAD_PER_DEG * std::f64::consts::SQRT_2;
        assert!((p.sigma_arcsec(2.0, 0.0) - 8.2).abs() < 0.1);
        assert!((p.sigma_arcsec(5.7, corner) - 24.0).abs() < 1e-9);
        let mut fhst = Fhst::with_alignment(Matrix3::identity(), p.clone(), model_rng(9, 1));
        let n = 20_000;
        let mut sum2 = 0.0;
        for _ in 0..n {
            let out = fhst.measure([0.0, 0.0], 1, 5.7, false);
            sum2 += (f64::from(out.h_counts) * 7.78).powi(2);
        }
        let sd = (sum2 / f64::from(n)).sqrt();
        let expect = (p.sigma_arcsec(5.7, 0.0).powi(2) + 7.78 * 7.78 / 12.0).sqrt();
        assert!((sd - expect).abs() < 0.03 * expect, "{sd} vs {expect}");
    }

    /// Brightest first; break after max_track_s; the next acquisition prefers a star not
    /// tracked recently; leaving the FOV breaks track; Sun keep-out gives no data.
    #[test]
    fn acquisition_break_track_and_exclusion() {
        let d = |h_deg: f64, v_deg: f64| {
            let (h, v) = (h_deg.to_radians(), v_deg.to_radians());
            [h.tan(), v.tan(), 1.0]
        };
        let sky = sky_with(&[
            (d(1.0, 1.0), 4.5, 1),
            (d(-2.0, 0.5), 3.1, 2),
            (d(0.0, -3.0), 5.0, 3),
            (d(0.0, 3.0), 6.2, 4),
        ]);
        let mut fhst = quiet_tracker(FhstParams {
            max_track_s: 10.0,
            ..noiseless()
        });
        let mut truth = TruthSnapshot::at_rest(Quat::IDENTITY);
        let mut sequence = Vec::new();
        for k in 0..40 {
            truth.t_s = f64::from(k);
            let s = fhst.sample(&truth, &sky, 0.0);
            assert!(s.flags & FHST_FLAG_VALID != 0);
            if s.flags & FHST_FLAG_NEW_STAR != 0 {
                sequence.push(fhst.last_truth().hip);
            }
        }
        // 3.1 mag first, then 4.5, then 5.0 (6.2 is outside the window), then the oldest.
        assert_eq!(sequence, vec![2, 1, 3, 2]);
        // Slew the star out of the FOV: track breaks and star 2 is not reacquired at once.
        truth.t_s = 100.0;
        truth.q_acs_from_eci =
            Quat::from_rotation_vector(&Vector3::new(0.0, 3.5f64.to_radians(), 0.0));
        truth.m_acs_from_eci = truth.q_acs_from_eci.to_dcm();
        fhst.sample(&truth, &sky, 0.0);
        // Sun in the FOV direction: no data and searching.
        truth.sun_dir_app_eci = truth.m_acs_from_eci.transpose() * Vector3::z();
        let s = fhst.sample(&truth, &sky, 0.0);
        assert_eq!(s.flags, 0);
        assert!(matches!(fhst.state(), TrackState::Searching { .. }));
    }

    /// Annual aberration reaches the counts: a 30 km/s velocity across the boresight moves a
    /// boresight star by 20.6″ ≈ 2.65 counts.
    #[test]
    fn aberration_moves_the_star() {
        let sky = sky_with(&[([0.0, 0.0, 1.0], 3.0, 11)]);
        let mut fhst = quiet_tracker(noiseless());
        let mut truth = TruthSnapshot::at_rest(Quat::IDENTITY);
        truth.earth_vel_bary_eci_km_per_s = Vector3::new(30.0, 0.0, 0.0);
        let s = fhst.sample(&truth, &sky, 0.0);
        let expect = 30.0 / crate::truth::aberration::C_KM_PER_S * ARCSEC_PER_RAD / 7.78;
        assert_eq!(s.h_counts, expect.round() as i16);
        assert_eq!(s.v_counts, 0);
    }

    /// Effect hooks: distortion at the corner, time-tag offset and thermal alignment.
    #[test]
    fn effect_hooks() {
        let mut p = noiseless();
        p.resolution_arcsec_per_count = 1.0; // 4° = 14 400 counts fits i16
        p.effects.radial_distortion_arcsec_at_4deg = 20.0;
        let mut f = quiet_tracker(p.clone());
        let four = 4.0 * RAD_PER_DEG;
        let out = f.measure([four, 0.0], 1, 4.0, false);
        assert!((f64::from(out.h_counts) - (four * ARCSEC_PER_RAD + 20.0)).abs() <= 0.5);
        p.effects = FhstEffects {
            hv_distortion_arcsec_at_corner: [5.0, -3.0],
            ..FhstEffects::default()
        };
        let mut f = quiet_tracker(p.clone());
        let out = f.measure([four, four], 1, 4.0, false);
        assert!((f64::from(out.v_counts) - (four * ARCSEC_PER_RAD - 3.0)).abs() <= 0.5);
        // Time-tag offset: rotating at 0.1°/s about ACS y with τ = 0.05 s shifts H by 18″.
        let sky = sky_with(&[([0.0, 0.0, 1.0], 3.0, 11)]);
        p.effects = FhstEffects {
            time_tag_offset_s: 0.05,
            ..FhstEffects::default()
        };
        let mut f = quiet_tracker(p.clone());
        let mut truth = TruthSnapshot::at_rest(Quat::IDENTITY);
        truth.rate_acs_rad_per_s = Vector3::new(0.0, 0.1 * RAD_PER_DEG, 0.0);
        f.sample(&truth, &sky, 0.0);
        assert!((f.last_truth().hv_rad[0].abs() * ARCSEC_PER_RAD - 18.0).abs() < 0.01);
        // Thermal: 2″/°C about ACS x at +3 °C moves V by 6″.
        p.effects = FhstEffects {
            thermal_alignment_arcsec_per_c: [2.0, 0.0, 0.0],
            ..FhstEffects::default()
        };
        let mut f = quiet_tracker(p);
        f.sample(&TruthSnapshot::at_rest(Quat::IDENTITY), &sky, 3.0);
        assert!((f.last_truth().hv_rad[1].abs() * ARCSEC_PER_RAD - 6.0).abs() < 0.01);
    }

    /// Alignment step: nothing before its time; after it the star moves as under the thermal
    /// hook's rotation of the same vector (both `M_AS' = Rot(θ) M_AS`, ACS): 20″ about ACS x
    /// moves V by 20″.
    #[test]
    fn alignment_step_rotates_after_its_time() {
        let sky = sky_with(&[([0.0, 0.0, 1.0], 3.0, 11)]);
        let mut p = noiseless();
        p.effects = FhstEffects {
            alignment_step_arcsec: [20.0, 0.0, 0.0],
            alignment_step_at_s: Some(100.0),
            ..FhstEffects::default()
        };
        let mut truth = TruthSnapshot::at_rest(Quat::IDENTITY);
        let mut f = quiet_tracker(p.clone());
        truth.t_s = 99.0;
        f.sample(&truth, &sky, 0.0);
        let before = f.last_truth().hv_rad;
        assert!(
            before[0].abs() < 1e-12 && before[1].abs() < 1e-12,
            "{before:?}"
        );
        truth.t_s = 100.0;
        f.sample(&truth, &sky, 0.0);
        let after = f.last_truth().hv_rad;
        assert!(
            (after[1].abs() * ARCSEC_PER_RAD - 20.0).abs() < 0.01,
            "{after:?}"
        );
        assert!(after[0].abs() < 1e-12);
        let mut thermal = noiseless();
        thermal.effects.thermal_alignment_arcsec_per_c = [2.0, 0.0, 0.0];
        let mut g = quiet_tracker(thermal);
        g.sample(&truth, &sky, 10.0);
        assert!((g.last_truth().hv_rad[1] - after[1]).abs() < 1e-15);
    }

    /// Paper alignment: FHST boresights ~90° apart; determinism per seed.
    #[test]
    fn paper_units_and_determinism() {
        let paper = PaperFacts::load().unwrap();
        let f1 = Fhst::new(0, FhstParams::default(), &paper, 5);
        let f2 = Fhst::new(1, FhstParams::default(), &paper, 5);
        let sep = f1
            .m_acs_from_fhst_true()
            .column(2)
            .dot(&f2.m_acs_from_fhst_true().column(2))
            .acos()
            .to_degrees();
        assert!((sep - 90.0).abs() < 0.2, "{sep}");
        let mut a = Fhst::new(0, FhstParams::default(), &paper, 5);
        let mut b = Fhst::new(0, FhstParams::default(), &paper, 5);
        for _ in 0..10 {
            assert_eq!(
                a.measure([0.001, 0.002], 1, 4.0, false),
                b.measure([0.001, 0.002], 1, 4.0, false)
            );
        }
    }
}
