//! # Synthetic frames with known effects (tests, studies)
//!
//! A small, fast stand-in for a `sim-harness` run that produces [`FrameObservations`]
//! directly: a random star sky (no catalog file), a circular orbit, a fixed Sun, holds and
//! slews at 0.08°/s about body axes, the paper's prelaunch alignments plus a true
//! misalignment, FHST and FSS noise and quantization like the harness, orbit-periodic
//! temperatures, and every effect of the library — plus effects that are *not* in it
//! (a temperature-squared alignment term, a decaying structural oscillation after slews) to
//! check that those end up as unexplained structure. The ground references are built as
//! the ground tool builds them (aberration applied or not), so an undeclared effect is one
//! that is in the truth and not in the references/tables.

use fsw_core::attitude::{rot, Quat};
use fsw_core::fhst::FhstMeasurement;
use fsw_core::fss::FssMeasurement;
use fsw_core::raw::TimeTag;
use fsw_core::tables::types::{matrix_from_rows, rows_from_matrix};
use fsw_core::tables::AlignmentTable;
use fsw_core::units::{ARCSEC_PER_RAD, RAD_PER_ARCSEC, RAD_PER_DEG};
use gro_reference::splitmix::SplitMix64;
use ground_tool::calibration::iru::{GyroCalibration, GyroStep};
use ground_tool::pipeline::observations::{
    DeclaredNoise, FrameObservations, RateSwitch, StarObservation, SunObservation,
};
use nalgebra::{Matrix3, Vector3};
use sim_harness::sensors::fss::FssHeadErrors;
use sim_harness::truth::aberration::aberrate;

use ground_tool::diagnose::measurements::{DiagnoseInput, MeasurementSet};

/// Effects switched on in the synthetic truth (zero = off).
#[derive(Clone, Debug, Default)]
pub struct SynthEffects {
    /// Time-tag offset per sensor (s): the sample is taken at `t − τ`.
    pub time_tag_s: [f64; 4],
    /// Thermal alignment per sensor (arcsec/°C, ACS).
    pub thermal_arcsec_per_c: [[f64; 3]; 4],
    /// FHST distortion: radial Δρ at 4°, H·V terms at the (4°, 4°) corner (arcsec).
    pub distortion_arcsec: [[f64; 3]; 2],
    /// FHST magnitude bias (arcsec/mag, H and V, about magnitude 4).
    pub magnitude_bias: [[f64; 2]; 2],
    /// FSS transfer errors per sensor (α head, β head); `None` = perfect.
    pub fss_tf: [Option<(FssHeadErrors, FssHeadErrors)>; 2],
    /// Catalog error: per-star offsets of this 1σ (arcsec) per axis.
    pub catalog_sigma_arcsec: f64,
    /// Catalog error of a few named stars: HIP → (east, north) arcsec (true − catalog), on
    /// top of `catalog_sigma_arcsec` (a handful of bad stars among the good ones).
    pub catalog_star_offsets: std::collections::BTreeMap<u32, [f64; 2]>,
    /// Not in the library: alignment ∝ ΔT² (arcsec/°C², ACS) per sensor.
    pub thermal_squared: [[f64; 3]; 4],
    /// Not in the library: (sensor, amplitude arcsec, period s, decay s, ACS axis) oscillation
    /// of the sensor's alignment after every slew.
    pub post_slew_oscillation: Option<(usize, f64, f64, f64, usize)>,
    /// (sensor, time s, rotation arcsec ACS): the sensor's alignment rotated once, from that
    /// time on (`M' = Rot(θ) M`).
    pub alignment_step: Option<(usize, f64, [f64; 3])>,
}

impl SynthEffects {
    /// Only a time tag: sensor `sensor` (FHST1, FHST2, FSS1, FSS2) sampled `tau_s` before its
    /// time code.
    #[must_use]
    pub fn time_tag(sensor: usize, tau_s: f64) -> Self {
        let mut fx = Self::default();
        fx.time_tag_s[sensor] = tau_s;
        fx
    }
}

/// Synthetic run settings.
#[derive(Clone, Debug)]
pub struct SynthConfig {
    /// Length (s).
    pub duration_s: f64,
    /// Seed.
    pub seed: u64,
    /// The ground references carry aberration (the operator declares it).
    pub aberration_applied: bool,
    /// Effects in the truth.
    pub effects: SynthEffects,
    /// Hold length between slews (s).
    pub hold_s: f64,
    /// Slew angle (deg).
    pub slew_deg: f64,
    /// Stars on the sky.
    pub stars: usize,
    /// Noise multiplier (0 = noise-free; quantization off too when 0).
    pub noise_scale: f64,
}

impl Default for SynthConfig {
    fn default() -> Self {
        Self {
            duration_s: 4.0 * 3600.0,
            seed: 1,
            aberration_applied: true,
            effects: SynthEffects::default(),
            hold_s: 900.0,
            slew_deg: 20.0,
            stars: 3000,
            noise_scale: 1.0,
        }
    }
}

/// Whether the body turns faster than 20″/s in frame `f` (by its gyro increment): a frame of
/// a slew arc.
#[must_use]
pub fn turning(f: &FrameObservations) -> bool {
    f.gyro
        .is_some_and(|g| g.dtheta_acs_rad.norm() / g.dt_s * ARCSEC_PER_RAD > 20.0)
}

/// A synthetic run.
#[derive(Clone, Debug)]
pub struct SynthRun {
    /// Frames as the ground tool would build them.
    pub frames: Vec<FrameObservations>,
    /// Earth velocity per frame.
    pub earth_vel: Vec<Vector3<f64>>,
    /// Sun per frame.
    pub sun: Vec<Vector3<f64>>,
    /// The alignment table the frames were built with (the "current calibration").
    pub alignment: AlignmentTable,
    /// True static alignments.
    pub m_true: [Matrix3<f64>; 4],
    /// True per-star catalog offsets (HIP → east, north arcsec).
    pub catalog_offsets: std::collections::BTreeMap<u32, [f64; 2]>,
    /// Settings.
    pub config: SynthConfig,
}

impl SynthConfig {
    /// The default settings with `effects` and `seed`.
    #[must_use]
    pub fn seeded(effects: SynthEffects, seed: u64) -> Self {
        Self {
            seed,
            effects,
            ..Self::default()
        }
    }
}

impl SynthRun {
    /// The measurement set diagnose builds from this run (no declared effect).
    #[must_use]
    pub fn measurement_set(&self) -> MeasurementSet {
        MeasurementSet::build(&self.input(&[]))
    }

    /// Input of the analysis.
    #[must_use]
    pub fn input(&self, declared: &[&str]) -> DiagnoseInput<'_> {
        DiagnoseInput {
            frames: &self.frames,
            earth_vel_eci_km_per_s: self.earth_vel.clone(),
            sun_eci: self.sun.clone(),
            gyro: GyroCalibration {
                delta_m: Matrix3::zeros(),
                bias_acs_rad_per_s: Vector3::zeros(),
            },
            bias_per_frame: None,
            alignment: self.alignment,
            frames_aberration: self.config.aberration_applied,
            aberration_model: [self.config.aberration_applied; 2],
            declared_effects: declared.iter().map(|s| (*s).to_owned()).collect(),
        }
    }
}

struct Star {
    hip: u32,
    dir: Vector3<f64>,
    mag: f64,
    offset: Vector3<f64>,
}

fn unit(rng: &mut SplitMix64) -> Vector3<f64> {
    loop {
        let v = Vector3::new(
            2.0 * rng.unit() - 1.0,
            2.0 * rng.unit() - 1.0,
            2.0 * rng.unit() - 1.0,
        );
        let n = v.norm();
        if n > 0.1 && n <= 1.0 {
            return v / n;
        }
    }
}

fn gauss(rng: &mut SplitMix64) -> f64 {
    // Box–Muller.
    let u1 = rng.unit().max(1e-300);
    let u2 = rng.unit();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// The slew plan: (start time, body axis, signed angle deg), alternating axes and signs.
fn plan(cfg: &SynthConfig) -> Vec<(f64, Vector3<f64>, f64)> {
    let axes = [
        (Vector3::x(), 1.0),
        (Vector3::y(), -1.0),
        (Vector3::z(), 1.0),
        (Vector3::x(), -1.0),
        (Vector3::y(), 1.0),
        (Vector3::z(), -1.0),
    ];
    let rate = 0.08;
    let mut out = Vec::new();
    let mut t = cfg.hold_s;
    let mut k = 0;
    while t < cfg.duration_s {
        let (axis, sign) = axes[k % axes.len()];
        let angle = sign * cfg.slew_deg * if axis.z > 0.5 { 1.25 } else { 1.0 };
        out.push((t, axis, angle));
        t += angle.abs() / rate + cfg.hold_s;
        k += 1;
    }
    out
}

/// Generate a run: the sky ([`sky`]), the geometry ([`Geometry::new`]), then one frame a
/// second ([`Scene::frame`]) with the attitude stepped along the slew plan.
#[must_use]
pub fn generate(cfg: &SynthConfig) -> SynthRun {
    let mut rng =
        SplitMix64::new(cfg.seed.wrapping_mul(0x2545_F491_4F6C_DD1D) ^ 0x5851_F42D_4C95_7F2D);
    // 1. Sky.
    let (stars, catalog_offsets) = sky(cfg, &mut rng);
    // 2. Geometry.
    let geometry = Geometry::new();
    let mut a = geometry.initial_attitude();
    let scene = Scene::new(cfg, stars, geometry);
    // 3. Frames.
    let n = cfg.duration_s as usize;
    let mut frames = Vec::with_capacity(n);
    let mut earth = Vec::with_capacity(n);
    let mut suns = Vec::with_capacity(n);
    let mut trackers = Trackers::default();
    let mut prev_rate = Vector3::zeros();
    for k in 0..n {
        let t = k as f64;
        let (_, _, since) = scene.rate_at(t);
        if k > 0 {
            // Exact rotation over the step with the rate of the interval that ended now.
            let (r_prev, _, _) = scene.rate_at(t - 0.5);
            a = rot(&(r_prev)) * a;
            prev_rate = r_prev;
        }
        let epoch = scene.epoch(t, since, a, prev_rate);
        let (frame, sun_app) = scene.frame(k, &epoch, &mut trackers, &mut rng);
        frames.push(frame);
        earth.push(scene.geometry.earth_vel);
        suns.push(sun_app);
    }
    SynthRun {
        frames,
        earth_vel: earth,
        sun: suns,
        alignment: scene.geometry.alignment,
        m_true: scene.geometry.m_true,
        catalog_offsets,
        config: cfg.clone(),
    }
}

/// Stage 1: the random sky, with the catalog errors of the effects (east, north; arcsec per
/// star).
fn sky(
    cfg: &SynthConfig,
    rng: &mut SplitMix64,
) -> (Vec<Star>, std::collections::BTreeMap<u32, [f64; 2]>) {
    let fx = &cfg.effects;
    let mut stars = Vec::with_capacity(cfg.stars);
    let mut catalog_offsets = std::collections::BTreeMap::new();
    for k in 0..cfg.stars {
        let dir = unit(rng);
        let mag = 2.0 + 3.7 * rng.unit().powf(0.6);
        let hip = 1000 + k as u32;
        let mut offset = Vector3::zeros();
        if fx.catalog_sigma_arcsec > 0.0 {
            let east = Vector3::z().cross(&dir).normalize();
            let north = dir.cross(&east);
            let (de, dn) = (
                gauss(rng) * fx.catalog_sigma_arcsec,
                gauss(rng) * fx.catalog_sigma_arcsec,
            );
            offset = (east * de + north * dn) * RAD_PER_ARCSEC;
            catalog_offsets.insert(hip, [de, dn]);
        }
        if let Some(&[de, dn]) = fx.catalog_star_offsets.get(&hip) {
            let east = Vector3::z().cross(&dir).normalize();
            let north = dir.cross(&east);
            offset += (east * de + north * dn) * RAD_PER_ARCSEC;
            let e = catalog_offsets.entry(hip).or_insert([0.0; 2]);
            e[0] += de;
            e[1] += dn;
        }
        stars.push(Star {
            hip,
            dir,
            mag,
            offset,
        });
    }
    (stars, catalog_offsets)
}

/// Stage 2: the true and flown alignments, the Sun and the Earth's velocity.
struct Geometry {
    /// The alignment table flown (the truth plus small errors relative to FHST1).
    alignment: AlignmentTable,
    /// True alignments (FHST1, FHST2, FSS1, FSS2).
    m_true: [Matrix3<f64>; 4],
    /// Flown alignments.
    flown: [Matrix3<f64>; 4],
    sun_eci: Vector3<f64>,
    /// km/s.
    earth_vel: Vector3<f64>,
}

impl Geometry {
    fn new() -> Self {
        let pre = AlignmentTable::prelaunch();
        let m_pre: Vec<Matrix3<f64>> = pre.matrices().iter().map(|m| matrix_from_rows(m)).collect();
        let mis = [
            Vector3::new(20.0, -30.0, 15.0),
            Vector3::new(-40.0, 25.0, 60.0),
            Vector3::new(300.0, -500.0, 200.0),
            Vector3::new(-200.0, 150.0, 100.0),
        ];
        let m_true: [Matrix3<f64>; 4] =
            std::array::from_fn(|i| rot(&(mis[i] * RAD_PER_ARCSEC)) * m_pre[i]);
        // The "current calibration": truth plus small errors relative to FHST1.
        let cal_err = [
            Vector3::zeros(),
            Vector3::new(3.0, -2.0, 4.0),
            Vector3::new(20.0, -15.0, 10.0),
            Vector3::new(-10.0, 12.0, 8.0),
        ];
        let mut alignment = pre;
        let flown: [Matrix3<f64>; 4] =
            std::array::from_fn(|i| rot(&(cal_err[i] * RAD_PER_ARCSEC)) * m_true[i]);
        alignment.m_acs_from_fhst1 = rows_from_matrix(&flown[0]);
        alignment.m_acs_from_fhst2 = rows_from_matrix(&flown[1]);
        alignment.m_acs_from_fss1 = rows_from_matrix(&flown[2]);
        alignment.m_acs_from_fss2 = rows_from_matrix(&flown[3]);
        let sun_eci = Vector3::new(0.3, 0.9, 0.3).normalize();
        let earth_vel = sun_eci.cross(&Vector3::z()).normalize() * 29.78;
        Self {
            alignment,
            m_true,
            flown,
            sun_eci,
            earth_vel,
        }
    }

    /// Initial attitude: the Sun at (10°, −5°) in FSS1.
    fn initial_attitude(&self) -> Matrix3<f64> {
        let sun_eci = self.sun_eci;
        let b_sun =
            self.m_true[2] * fsw_core::fss::dir_from_angles(10.0 * RAD_PER_DEG, -5.0 * RAD_PER_DEG);
        let axis = sun_eci.cross(&b_sun);
        let ang = sun_eci.dot(&b_sun).clamp(-1.0, 1.0).acos();
        // A maps sun_eci to b_sun: A = exp(+[θ×]) = Rot(−θ) with θ along sun × b.
        let a = rot(&(-axis.normalize() * ang));
        rot(&(-b_sun * 0.7)) * a
    }
}

/// What every frame reads: the configuration, the sky, the geometry, the slew plan, the
/// orbit and the sensors' noise and quantization.
struct Scene<'a> {
    cfg: &'a SynthConfig,
    stars: Vec<Star>,
    geometry: Geometry,
    /// (start time, body axis, signed angle deg).
    slews: Vec<(f64, Vector3<f64>, f64)>,
    /// Orbit radius (km), mean motion (rad/s), inclination (rad), period (s).
    r_km: f64,
    n_orb: f64,
    inc: f64,
    period: f64,
    noise: DeclaredNoise,
    /// Epoch of the first frame (s).
    t_base: f64,
}

/// Quantum of an FHST measurement (arcsec).
const FHST_Q_ARCSEC: f64 = 7.78;
/// Quantum of an FSS measurement (arcsec).
const FSS_Q_ARCSEC: f64 = 0.004 * 3600.0;
/// Slew rate (deg/s).
const SLEW_RATE_DEG_PER_S: f64 = 0.08;

/// One frame's truth: time, attitude and the rate of the interval that ended at it.
struct Epoch {
    t: f64,
    /// Time since the last slew ended (NaN before the first, and in a slew).
    since: f64,
    /// `A`, ACS from ECI.
    a: Matrix3<f64>,
    prev_rate: Vector3<f64>,
    /// Observer velocity (km/s).
    v_obs: Vector3<f64>,
    pos: Vector3<f64>,
    vel: Vector3<f64>,
    /// Temperature deviations (°C): FHST1, FHST2, FSS1, FSS2, IRU.
    dtemp: [f64; 5],
}

impl Epoch {
    /// Attitude at a sensor's sample time `τ` s earlier.
    fn a_at(&self, tau: f64) -> Matrix3<f64> {
        if tau == 0.0 {
            self.a
        } else {
            rot(&(-self.prev_rate * tau)) * self.a
        }
    }
}

/// The trackers' state: the star each follows (index, since), and the stars each left
/// recently (hip, when).
#[derive(Default)]
struct Trackers {
    track: [Option<(usize, f64)>; 2],
    recent: [Vec<(u32, f64)>; 2],
}

impl<'a> Scene<'a> {
    fn new(cfg: &'a SynthConfig, stars: Vec<Star>, geometry: Geometry) -> Self {
        let r_km: f64 = 6833.0;
        let mu = 398_600.441_8;
        let n_orb = (mu / r_km.powi(3)).sqrt();
        Self {
            cfg,
            stars,
            geometry,
            slews: plan(cfg),
            r_km,
            n_orb,
            inc: 28.5 * RAD_PER_DEG,
            period: std::f64::consts::TAU / n_orb,
            noise: DeclaredNoise::default(),
            t_base: 33.0 * 365.25 * 86_400.0 + 0.25 * 86_400.0,
        }
    }

    /// Position and velocity (km, km/s) on the circular orbit.
    fn orbit(&self, t: f64) -> (Vector3<f64>, Vector3<f64>) {
        let (r_km, n_orb, inc) = (self.r_km, self.n_orb, self.inc);
        let u = n_orb * t + 0.3;
        let p = Vector3::new(u.cos(), u.sin() * inc.cos(), u.sin() * inc.sin()) * r_km;
        let v = Vector3::new(-u.sin(), u.cos() * inc.cos(), u.cos() * inc.sin()) * (r_km * n_orb);
        (p, v)
    }

    /// Orbit-periodic temperature deviation of a slot (°C).
    fn temp(&self, t: f64, slot: usize) -> f64 {
        let amp = [1.5, 2.0, 4.0, 4.0, 0.3][slot];
        let ph = [0.0, 0.6, 1.3, 2.0, 2.7][slot];
        amp * (std::f64::consts::TAU * t / self.period + ph).cos()
    }

    /// Body rate at `t` (rad/s), whether in a slew, and the time since the last slew ended.
    fn rate_at(&self, t: f64) -> (Vector3<f64>, bool, f64) {
        let rate_mag = SLEW_RATE_DEG_PER_S * RAD_PER_DEG;
        let mut since = f64::NAN;
        for (t0, axis, angle) in &self.slews {
            let dur = angle.abs() / SLEW_RATE_DEG_PER_S;
            if t >= *t0 && t < t0 + dur {
                return (axis * rate_mag * angle.signum(), true, f64::NAN);
            }
            if t >= t0 + dur {
                since = t - (t0 + dur);
            }
        }
        (Vector3::zeros(), false, since)
    }

    /// Quantized to `q` (none without noise).
    fn quant(&self, x: f64, q: f64) -> f64 {
        if self.cfg.noise_scale > 0.0 {
            (x / q).round() * q
        } else {
            x
        }
    }

    fn epoch(&self, t: f64, since: f64, a: Matrix3<f64>, prev_rate: Vector3<f64>) -> Epoch {
        let (pos, vel) = self.orbit(t);
        Epoch {
            t,
            since,
            a,
            prev_rate,
            v_obs: self.geometry.earth_vel + vel,
            pos,
            vel,
            dtemp: std::array::from_fn(|s| self.temp(t, s)),
        }
    }

    /// Sensor alignment at this time (thermal and non-library terms).
    fn m_sensor(&self, ep: &Epoch, s: usize) -> Matrix3<f64> {
        let fx = &self.cfg.effects;
        let dt = ep.dtemp[s];
        let mut th = Vector3::from(fx.thermal_arcsec_per_c[s]) * dt
            + Vector3::from(fx.thermal_squared[s]) * (dt * dt);
        if let Some((ss, t_step, theta)) = fx.alignment_step {
            if ss == s && ep.t >= t_step {
                th += Vector3::from(theta);
            }
        }
        if let Some((os, amp, per, decay, axis)) = fx.post_slew_oscillation {
            if os == s && ep.since.is_finite() {
                th[axis.min(2)] += amp
                    * (-ep.since / decay).exp()
                    * (std::f64::consts::TAU * ep.since / per).sin();
            }
        }
        if th == Vector3::zeros() {
            self.geometry.m_true[s]
        } else {
            rot(&(th * RAD_PER_ARCSEC)) * self.geometry.m_true[s]
        }
    }

    /// Stage 3: one frame (and the apparent Sun): the trackers, the Sun sensors, the gyro.
    fn frame(
        &self,
        k: usize,
        ep: &Epoch,
        trackers: &mut Trackers,
        rng: &mut SplitMix64,
    ) -> (FrameObservations, Vector3<f64>) {
        let star0 = self.tracker(ep, 0, trackers, rng);
        let star1 = self.tracker(ep, 1, trackers, rng);
        let (suns_obs, sun_app) = self.sun_sensors(ep, rng);
        let prev_rate = ep.prev_rate;
        let gyro = (k > 0).then_some(GyroStep {
            dtheta_acs_rad: prev_rate,
            dt_s: 1.0,
        });
        let time = TimeTag::from_seconds(self.t_base + ep.t).unwrap_or_default();
        let frame = FrameObservations {
            time,
            gyro,
            high_rate: prev_rate.norm() > 0.0,
            iru_backup: false,
            rate_switch: RateSwitch::None,
            gyro_split_var_rad2: 0.0,
            gyro_split_dir_rad: nalgebra::Vector3::zeros(),
            stars: [star0, star1],
            suns: suns_obs,
            temperatures_c: std::array::from_fn(|s| 20.0 + ep.dtemp[s]),
            obc_q_acs_from_eci: Some(Quat::from_dcm(&ep.a)),
            orbit: Some((ep.pos, ep.vel)),
        };
        (frame, sun_app)
    }

    /// Tracker `tr`: keep its star for up to 300 s while visible, else take the brightest
    /// visible star near the boresight, preferring one not followed in the last 30 min
    /// ([`Self::star_measurement`]).
    fn tracker(
        &self,
        ep: &Epoch,
        tr: usize,
        trackers: &mut Trackers,
        rng: &mut SplitMix64,
    ) -> Option<StarObservation> {
        let (t, half) = (ep.t, HALF_FOV_DEG * RAD_PER_DEG);
        let stars = &self.stars;
        let m = self.m_sensor(ep, tr);
        let a_s = ep.a_at(self.cfg.effects.time_tag_s[tr]);
        let to_sensor = m.transpose() * a_s;
        let visible = |i: usize| -> Option<(f64, f64)> {
            let st = &stars[i];
            let u = aberrate(&(st.dir + st.offset).normalize(), &ep.v_obs);
            let s = to_sensor * u;
            if s.z <= 0.0 {
                return None;
            }
            let (h, v) = (s.x.atan2(s.z), s.y.atan2(s.z));
            (h.abs() <= half && v.abs() <= half).then_some((h, v))
        };
        let (track, recent) = (&mut trackers.track[tr], &mut trackers.recent[tr]);
        let mut new_star = false;
        let keep = track.is_some_and(|(i, since_t)| t - since_t < 300.0 && visible(i).is_some());
        if !keep {
            if let Some((i, _)) = track.take() {
                recent.push((stars[i].hip, t));
            }
            let bore = (m.transpose() * a_s).row(2).transpose();
            let mut best: Option<(usize, bool, f64)> = None;
            for (i, st) in stars.iter().enumerate() {
                if st.dir.dot(&bore) < (6.0 * RAD_PER_DEG).cos() || visible(i).is_none() {
                    continue;
                }
                let last = recent
                    .iter()
                    .filter(|(h, _)| *h == st.hip)
                    .map(|(_, tt)| *tt)
                    .fold(f64::NEG_INFINITY, f64::max);
                let fresh = t - last >= 1800.0;
                let better = match best {
                    None => true,
                    Some((_, bf, bm)) => (fresh && !bf) || (fresh == bf && st.mag < bm),
                };
                if better {
                    best = Some((i, fresh, st.mag));
                }
            }
            if let Some((i, _, _)) = best {
                *track = Some((i, t));
                new_star = true;
            }
        }
        let (i, _) = (*track)?;
        let (h, v) = visible(i)?;
        Some(self.star_measurement(ep, tr, &stars[i], (h, v), new_star, rng))
    }

    /// The tracker's measurement of star `st` at true (H, V): distortion, magnitude bias,
    /// noise by magnitude and field position, quantization.
    fn star_measurement(
        &self,
        ep: &Epoch,
        tr: usize,
        st: &Star,
        (h, v): (f64, f64),
        new_star: bool,
        rng: &mut SplitMix64,
    ) -> StarObservation {
        let fx = &self.cfg.effects;
        let (ns, half) = (self.cfg.noise_scale, HALF_FOV_DEG * RAD_PER_DEG);
        let f = 4.0 * RAD_PER_DEG;
        let d = fx.distortion_arcsec[tr];
        let rho2 = h * h + v * v;
        let mut dh = d[0] * rho2 * h / f.powi(3) + d[1] * h * v / (f * f);
        let mut dv = d[0] * rho2 * v / f.powi(3) + d[2] * h * v / (f * f);
        dh += fx.magnitude_bias[tr][0] * (st.mag - 4.0);
        dv += fx.magnitude_bias[tr][1] * (st.mag - 4.0);
        let rho = rho2.sqrt();
        let sigma = 6.0
            + 12.0 * 10f64.powf(0.2 * (st.mag - 5.7))
            + 6.0 * (rho / (half * std::f64::consts::SQRT_2)).powi(2);
        let hm = self.quant(
            h * ARCSEC_PER_RAD + dh + ns * sigma * gauss(rng),
            FHST_Q_ARCSEC,
        ) * RAD_PER_ARCSEC;
        let vm = self.quant(
            v * ARCSEC_PER_RAD + dv + ns * sigma * gauss(rng),
            FHST_Q_ARCSEC,
        ) * RAD_PER_ARCSEC;
        let mag_m = st.mag + 0.05 * gauss(rng);
        let dir_sensor = fsw_core::fhst::dir_from_hv(hm, vm);
        let reference = if self.cfg.aberration_applied {
            aberrate(&st.dir, &ep.v_obs)
        } else {
            st.dir
        };
        StarObservation {
            meas: FhstMeasurement {
                h_rad: hm,
                v_rad: vm,
                dir_sensor,
                dir_acs: self.geometry.flown[tr] * dir_sensor,
                magnitude: mag_m,
                new_star,
            },
            identified: Some((st.hip, reference)),
            catalog_magnitude: st.mag,
            sigma_rad: self.noise.fhst_sigma_rad(st.mag),
        }
    }

    /// The Sun sensors outside the umbra, each within its ±32° field (transfer function,
    /// noise, quantization), and the apparent Sun.
    fn sun_sensors(
        &self,
        ep: &Epoch,
        rng: &mut SplitMix64,
    ) -> ([Option<Box<SunObservation>>; 2], Vector3<f64>) {
        let fx = &self.cfg.effects;
        let (pos, sun_eci, ns) = (ep.pos, self.geometry.sun_eci, self.cfg.noise_scale);
        let in_umbra =
            pos.dot(&sun_eci) < 0.0 && (pos - sun_eci * pos.dot(&sun_eci)).norm() < 6378.0;
        let sun_app = aberrate(&sun_eci, &ep.v_obs);
        let sun_ref = if self.cfg.aberration_applied {
            sun_app
        } else {
            sun_eci
        };
        let mut suns_obs = [None, None];
        if in_umbra {
            return (suns_obs, sun_app);
        }
        for u in 0..2 {
            let s_idx = u + 2;
            let m = self.m_sensor(ep, s_idx);
            let s = m.transpose() * (ep.a_at(fx.time_tag_s[s_idx]) * sun_app);
            if s.z <= 0.0 {
                continue;
            }
            let (al, be) = (s.x.atan2(s.z), s.y.atan2(s.z));
            if al.abs() > 32.0 * RAD_PER_DEG || be.abs() > 32.0 * RAD_PER_DEG {
                continue;
            }
            let (am, bm) = match &fx.fss_tf[u] {
                Some((ea, eb)) => (ea.apply(al, be), eb.apply(be, al)),
                None => (al, be),
            };
            let mut q = |x: f64| {
                self.quant(
                    x * ARCSEC_PER_RAD + ns * 0.5 * FSS_Q_ARCSEC * gauss(rng),
                    FSS_Q_ARCSEC,
                ) * RAD_PER_ARCSEC
            };
            let (aq, bq) = (q(am), q(bm));
            let dir_sensor = fsw_core::fss::dir_from_angles(aq, bq);
            suns_obs[u] = Some(Box::new(SunObservation {
                meas: FssMeasurement {
                    alpha_rad: aq,
                    beta_rad: bq,
                    dir_sensor,
                    dir_acs: self.geometry.flown[s_idx] * dir_sensor,
                },
                sun_eci: sun_ref,
                sigma_rad: self.noise.fss_sigma_arcsec * RAD_PER_ARCSEC,
            }));
        }
        (suns_obs, sun_app)
    }
}

/// Half-width of the FHST field (deg).
const HALF_FOV_DEG: f64 = 4.0;
