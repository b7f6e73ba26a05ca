//! # Residuals and regressors of every measurement
//!
//! **Reference attitude.** The frames are cut into batches (≤ 60 s in holds, ≤ 20 s while the
//! IRU is in high-rate mode, never across a gap). Each batch has a FHST-only fine attitude at
//! its centre frame ([`fine_attitude`]: every star vector carried to the centre with the
//! calibrated gyro), and that attitude is carried to every frame of the batch with the gyro.
//! The OBC's own attitude is the fallback when a batch has fewer than two stars.
//!
//! **Residual** of a measurement = measured − predicted, in the sensor's own axes (FHST H, V;
//! FSS α, β), arcsec, after the current tables (alignment, distortion, transfer function, time
//! offsets: a sensor with a table time offset τ₀ is predicted at `t − τ₀`).
//!
//! **Partials** (docs/algorithms.md §1, §3.1): with `J = ∂(angles)/∂s`, `s = Mᵀ b`:
//! attitude `∂r/∂δθ = J Mᵀ [b×]` (left body error), alignment `∂r/∂θ_M = −J Mᵀ [b×]`
//! (`M' = Rot(θ_M) M`), plus what [`super::effects`] needs (rate, aberration vectors, star
//! tangent basis, temperatures, FOV angles).
//!
//! **Regressors** (issue 5): time, orbit phase (argument of latitude from the definitive
//! orbit), Sun angle to the boresight, FOV position and radius, magnitude, body rate about the
//! sensor axes (sign included), rate mode, direction of the barycentric velocity in sensor
//! axes, the sensor's temperature, star id, time since the last slew.
//!
//! **Noise floor** per sensor from successive differences of residuals within a batch (same
//! star, low-rate mode): slowly varying effects cancel, so this is a model-free estimate of
//! the white noise. The declared σ (its magnitude shape) is rescaled to it.

use crate::calibration::iru::GyroCalibration;
use crate::pipeline::observations::{fine_attitude, AttitudeSensors, FrameObservations};
use fsw_core::attitude::{rot, skew};
use fsw_core::fhst::{hv_from_dir, hv_jacobian};
use fsw_core::tables::types::matrix_from_rows;
use fsw_core::tables::AlignmentTable;
use fsw_core::units::{ARCSEC_PER_RAD, DEG_PER_RAD};
use nalgebra::{Matrix2x3, Matrix3, Vector3};

/// Sensor names in table order.
pub const SENSOR_NAMES: [&str; 4] = fsw_core::sensor::SensorId::NAMES;
/// Speed of light (km/s).
pub const C_KM_PER_S: f64 = 299_792.458;
/// Longest batch in low-rate mode (s).
pub const BATCH_HOLD_S: f64 = 60.0;
/// Longest batch in high-rate mode (s).
pub const BATCH_SLEW_S: f64 = 20.0;
/// Residuals beyond this many robust σ are outliers (misidentifications, glitches).
const OUTLIER_SIGMA: f64 = 6.0;

/// Names of a sensor's two measurement axes.
#[must_use]
pub fn axis_names(sensor: usize) -> [&'static str; 2] {
    if sensor < 2 {
        ["H", "V"]
    } else {
        ["alpha", "beta"]
    }
}

/// Everything the analysis needs besides the frames.
#[derive(Clone, Debug)]
pub struct DiagnoseInput<'a> {
    /// The frames (DA/FADS output built with `alignment`).
    pub frames: &'a [FrameObservations],
    /// Earth barycentric velocity per frame (km/s, J2000).
    pub earth_vel_eci_km_per_s: Vec<Vector3<f64>>,
    /// Apparent Sun direction per frame (J2000, unit), for the Sun-angle regressor.
    pub sun_eci: Vec<Vector3<f64>>,
    /// Gyro calibration (δM on the DA increments; the bias is the fallback).
    pub gyro: GyroCalibration,
    /// Bias per frame (e.g. the OBC's estimate); `None` = `gyro.bias_acs_rad_per_s`.
    pub bias_per_frame: Option<Vec<Vector3<f64>>>,
    /// The tables the frames were built with (matrices and corrections).
    pub alignment: AlignmentTable,
    /// The frames' references carry aberration (annual and orbital together, FADS).
    pub frames_aberration: bool,
    /// The model's aberration (annual, orbital): the references are adjusted to it
    /// (k₀ = 1 or 0 per part).
    pub aberration_model: [bool; 2],
    /// Effects the operator declares (metadata.json `declared_effects`).
    pub declared_effects: Vec<String>,
}

/// One two-axis measurement.
#[derive(Clone, Debug)]
pub struct Measurement {
    /// 0 FHST1, 1 FHST2, 2 FSS1, 3 FSS2.
    pub sensor: usize,
    /// Frame index.
    pub frame: usize,
    /// Batch index.
    pub batch: usize,
    /// Time since the first frame (s).
    pub t_s: f64,
    /// Time from the batch centre (s).
    pub dt_center_s: f64,
    /// Residual measured − predicted (arcsec), sensor axes.
    pub r: [f64; 2],
    /// 1σ per axis (arcsec): declared shape × the sensor's measured noise scale.
    pub sigma: f64,
    /// `J Mᵀ` (2×3): angle change (rad) per body-vector change.
    pub jm: Matrix2x3<f64>,
    /// Predicted body vector (unit, ACS).
    pub b_acs: Vector3<f64>,
    /// Predicted angles (rad): H, V or α, β. Regressors and effect columns use these, not
    /// the measured angles: binning on a measured angle selects on its noise and makes
    /// structure out of nothing (errors in variables).
    pub ang: [f64; 2],
    /// Body rate (rad/s, ACS, calibrated gyro).
    pub rate_acs: Vector3<f64>,
    /// Body rate about the sensor axes (rad/s).
    pub rate_sensor: Vector3<f64>,
    /// `A (β − u (u·β))` for the Earth's barycentric velocity (rad, ACS).
    pub ab_annual_acs: Vector3<f64>,
    /// The same for the spacecraft's orbital velocity.
    pub ab_orbital_acs: Vector3<f64>,
    /// Star tangent basis in ACS (east, north of the reference direction).
    pub tangent_acs: [Vector3<f64>; 2],
    /// Reference direction (J2000, unit) as used by the model.
    pub u_eci: Vector3<f64>,
    /// HIP number (0 for the Sun).
    pub star: u32,
    /// Catalog magnitude (NaN for the Sun).
    pub magnitude: f64,
    /// Temperature deviations from the run mean (°C), all five slots.
    pub dtemp: [f64; 5],
    /// Argument of latitude (rad), NaN without orbit.
    pub orbit_phase: f64,
    /// IRU in high-rate mode.
    pub high_rate: bool,
    /// Sun angle to the boresight (deg).
    pub sun_angle_deg: f64,
    /// Unit barycentric velocity in sensor axes.
    pub vel_sensor: Vector3<f64>,
    /// Time since the end of the last slew (s), NaN before the first.
    pub since_slew_s: f64,
    /// Excluded as an outlier.
    pub outlier: bool,
}

/// A batch of frames sharing one reference attitude.
#[derive(Clone, Debug)]
pub struct Batch {
    /// First frame.
    pub lo: usize,
    /// One past the last frame.
    pub hi: usize,
    /// Centre frame.
    pub center: usize,
    /// Time of the centre (s since the first frame).
    pub t_center_s: f64,
    /// Reference attitude at the centre.
    pub m_acs_from_eci: Matrix3<f64>,
    /// From the FHSTs (else the OBC fallback).
    pub fine: bool,
    /// High-rate batch.
    pub high_rate: bool,
    /// The FHSTs determine the batch attitude well enough (all three axes better than
    /// [`MAX_BATCH_SIGMA_ARCSEC`]), with the FSSs' help where the FHSTs alone cannot
    /// (one tracker); measurements of other batches are not used.
    pub usable: bool,
    /// The FHSTs alone determine the attitude (else the residuals of the batch are taken
    /// against the FHST + FSS attitude).
    pub fhst_only: bool,
}

/// A batch whose FHST attitude is worse than this (1σ, any axis, arcsec) is not used.
pub const MAX_BATCH_SIGMA_ARCSEC: f64 = 15.0;
/// Use batches whose attitude needs the FSS (one tracker + Sun): in LEO the Earth often
/// hides one tracker, and the Sun may be in an FSS mostly then. Their residuals are taken
/// against the FHST + FSS attitude, so FSS and FHST effects can trade through it; the fit is
/// still the exact joint likelihood.
pub const ALLOW_FSS_AIDED: bool = true;
/// Prior 1σ of the batch attitude correction (arcsec).
pub const NUISANCE_ANGLE_PRIOR_ARCSEC: f64 = 600.0;
/// Prior 1σ of the batch rate correction (arcsec per 100 s).
pub const NUISANCE_RATE_PRIOR: f64 = 10.0;

/// All measurements of a run.
#[derive(Clone, Debug)]
pub struct MeasurementSet {
    /// Measurements (time order within a batch, FHSTs first).
    pub meas: Vec<Measurement>,
    /// Batches.
    pub batches: Vec<Batch>,
    /// Reference attitude per frame (None outside batches).
    pub frame_attitude: Vec<Option<Matrix3<f64>>>,
    /// Calibrated body rate per frame (rad/s).
    pub frame_rate: Vec<Vector3<f64>>,
    /// Time of each frame (s since the first frame).
    pub frame_time_s: Vec<f64>,
    /// Calibrated gyro increment of the step that ends at each frame (rad, ACS, bias removed)
    /// and its length (s); `None` without gyro data. The slew arcs of
    /// [`super::time_reference`] carry one attitude through many batches with it.
    pub frame_gyro: Vec<Option<(Vector3<f64>, f64)>>,
    /// Noise floor per sensor (arcsec, per axis), from successive differences.
    pub noise_floor_arcsec: [f64; 4],
    /// Scale applied to the declared σ per sensor.
    pub sigma_scale: [f64; 4],
    /// Alignment matrices the frames were built with.
    pub m_acs_from_sensor: [Matrix3<f64>; 4],
    /// k₀ of the references (annual, orbital; 1 with aberration applied).
    pub aberration_k0: [f64; 2],
    /// Time-tag offsets already applied (table), s.
    pub time_offset0_s: [f64; 4],
    /// Orbit period (s) estimated from the orbit, if any.
    pub orbit_period_s: Option<f64>,
    /// Run mean of each temperature slot (°C; FHST1, FHST2, FSS1, FSS2, IRU): the reference
    /// of [`Measurement::dtemp`] and so of the thermal effects' parameters.
    pub temperature_mean_c: [f64; 5],
}

fn orbit_phase(pos: &Vector3<f64>, vel: &Vector3<f64>) -> f64 {
    let h = pos.cross(vel);
    let n = Vector3::z().cross(&h);
    let n = if n.norm() < 1e-9 {
        Vector3::x()
    } else {
        n.normalize()
    };
    let hn = h.normalize();
    let y = hn.cross(&n);
    pos.dot(&y)
        .atan2(pos.dot(&n))
        .rem_euclid(std::f64::consts::TAU)
}

fn aberration_term(u: &Vector3<f64>, v_km_per_s: &Vector3<f64>) -> Vector3<f64> {
    let beta = v_km_per_s / C_KM_PER_S;
    beta - u * u.dot(&beta)
}

fn tangent_basis(u: &Vector3<f64>) -> [Vector3<f64>; 2] {
    let east = Vector3::z().cross(u);
    let east = if east.norm() < 1e-9 {
        Vector3::x()
    } else {
        east.normalize()
    };
    [east, u.cross(&east)]
}

/// Cut the frames into batches.
fn make_batches(frames: &[FrameObservations]) -> Vec<(usize, usize, bool)> {
    let mut out = Vec::new();
    let mut lo = 0usize;
    while lo < frames.len() {
        let t0 = frames[lo].time.seconds();
        let hr = frames[lo].high_rate;
        let limit = if hr { BATCH_SLEW_S } else { BATCH_HOLD_S };
        let mut hi = lo + 1;
        while hi < frames.len() {
            let f = &frames[hi];
            let gap = f.time.seconds() - frames[hi - 1].time.seconds();
            if f.high_rate != hr || f.time.seconds() - t0 >= limit || gap > 5.0 || f.gyro.is_none()
            {
                break;
            }
            hi += 1;
        }
        out.push((lo, hi, hr));
        lo = hi;
    }
    out
}

/// Calibrated gyro increments and their intervals per frame (step k ends at frame k): the
/// IRUCAL `δM` applied and the OBC bias at the frame removed.
fn calibrated_increments(input: &DiagnoseInput<'_>) -> (Vec<Vector3<f64>>, Vec<f64>) {
    let n = input.frames.len();
    let mut phi = vec![Vector3::zeros(); n];
    let mut dts = vec![0.0; n];
    for (k, f) in input.frames.iter().enumerate() {
        if let Some(g) = f.gyro {
            phi[k] = (Matrix3::identity() + input.gyro.delta_m) * g.dtheta_acs_rad
                - bias_at(input, k) * g.dt_s;
            dts[k] = g.dt_s;
        }
    }
    (phi, dts)
}

/// The OBC's bias at frame `k` (the calibration's when the telemetry has none).
fn bias_at(input: &DiagnoseInput<'_>, k: usize) -> Vector3<f64> {
    input
        .bias_per_frame
        .as_ref()
        .and_then(|b| b.get(k).copied())
        .unwrap_or(input.gyro.bias_acs_rad_per_s)
}

/// The body rate at each frame: the mean of the increments ending at it and at the next.
fn frame_rates(phi: &[Vector3<f64>], dts: &[f64]) -> Vec<Vector3<f64>> {
    let n = phi.len();
    let mut frame_rate = vec![Vector3::zeros(); n];
    for k in 0..n {
        let (mut s, mut t) = (Vector3::zeros(), 0.0);
        for j in [k, k + 1] {
            if j < n && dts[j] > 0.0 {
                s += phi[j];
                t += dts[j];
            }
        }
        if t > 0.0 {
            frame_rate[k] = s / t;
        }
    }
    frame_rate
}

/// The run mean of each temperature slot (temperatures enter as deviations from it).
fn mean_temperatures(frames: &[FrameObservations]) -> [f64; 5] {
    let mut tmean = [0.0; 5];
    if !frames.is_empty() {
        for f in frames {
            for (m, t) in tmean.iter_mut().zip(f.temperatures_c) {
                *m += t;
            }
        }
        for m in &mut tmean {
            *m /= frames.len() as f64;
        }
    }
    tmean
}

/// Time since the end of the last slew at each frame (NaN before the first slew).
fn time_since_slew(frames: &[FrameObservations]) -> Vec<f64> {
    let mut since_slew = vec![f64::NAN; frames.len()];
    let mut last_end: Option<f64> = None;
    for (k, f) in frames.iter().enumerate() {
        if f.high_rate {
            last_end = Some(f.time.seconds());
        }
        since_slew[k] = last_end.map_or(f64::NAN, |e| f.time.seconds() - e);
    }
    since_slew
}

/// Orbit period from the first orbit state (two-body).
fn orbit_period(frames: &[FrameObservations]) -> Option<f64> {
    frames.iter().find_map(|f| f.orbit).map(|(p, v)| {
        let mu = 398_600.441_8;
        let r = p.norm();
        let energy = 0.5 * v.norm_squared() - mu / r;
        let a = -mu / (2.0 * energy);
        std::f64::consts::TAU * (a.powi(3) / mu).sqrt()
    })
}

/// The identified star and Sun sightings of the frames: at most one measurement each, so
/// the measurements are reserved at once and trimmed after, not doubled as they grow (six
/// months of 30-s frames: ~0.5 M of 424 B, issue 22).
fn count_sightings(frames: &[FrameObservations]) -> usize {
    frames
        .iter()
        .map(|f| {
            f.stars
                .iter()
                .filter(|s| s.as_ref().is_some_and(|s| s.identified.is_some()))
                .count()
                + f.suns.iter().filter(|s| s.is_some()).count()
        })
        .sum()
}

/// What the stages of [`MeasurementSet::build`] share: the input, the flown alignments and
/// time offsets, the aberration to add to the frames' references, and the per-frame series.
struct SetBuild<'a> {
    input: &'a DiagnoseInput<'a>,
    m_sensor: [Matrix3<f64>; 4],
    tau0: [f64; 4],
    /// The model's annual and orbital aberration factors less the frames'.
    dk: [f64; 2],
    t_first: f64,
    phi: Vec<Vector3<f64>>,
    dts: Vec<f64>,
    frame_rate: Vec<Vector3<f64>>,
    tmean: [f64; 5],
    since_slew: Vec<f64>,
}

/// One frame's context for its measurements: its attitude, batch and the velocities.
struct FrameContext {
    k: usize,
    a_k: Matrix3<f64>,
    batch: usize,
    t_s: f64,
    t_center: f64,
    phase: f64,
    v_e: Vector3<f64>,
    v_sc: Vector3<f64>,
    sun: Vector3<f64>,
    dtemp: [f64; 5],
}

/// One sighting before its residual: sensor, reference direction (ECI), measured angles
/// (rad), σ (rad), Hipparcos number (0 for the Sun) and catalog magnitude.
struct Sighting {
    sensor: usize,
    u: Vector3<f64>,
    ang: [f64; 2],
    sigma_rad: f64,
    star: u32,
    mag: f64,
}

impl SetBuild<'_> {
    /// The batch's attitude at every frame: the fine attitude at the center (FHST-only; with
    /// one tracker, the FSSs help; else the OBC's), carried by the gyro increments
    /// (A(k) = Rot(φ_k) A(k−1)); `None` when there is none. (attitudes, center's, fine).
    fn batch_attitudes(
        &self,
        lo: usize,
        hi: usize,
        center: usize,
    ) -> Option<(Vec<Matrix3<f64>>, Matrix3<f64>, bool)> {
        let frames = self.input.frames;
        let bias = bias_at(self.input, center);
        let well_determined = |s: &crate::attitude::quest::AttitudeSolution| {
            (0..3).all(|i| s.cov_acs_rad2[(i, i)].max(0.0).sqrt() * ARCSEC_PER_RAD < 60.0)
        };
        let fine = [AttitudeSensors::FhstOnly, AttitudeSensors::FhstAndFss]
            .into_iter()
            .filter_map(|which| {
                fine_attitude(
                    frames,
                    lo..hi,
                    center,
                    &bias,
                    &self.input.gyro.delta_m,
                    which,
                )
                .ok()
            })
            .find(well_determined);
        let (a_center, is_fine) = match (fine, frames[center].obc_q_acs_from_eci) {
            (Some(s), _) => (s.m_acs_from_eci, true),
            (None, Some(q)) => (q.to_dcm(), false),
            (None, None) => return None,
        };
        let phi = &self.phi;
        let mut att = vec![Matrix3::identity(); hi - lo];
        att[center - lo] = a_center;
        for k in center + 1..hi {
            att[k - lo] = rot(&phi[k]) * att[k - 1 - lo];
        }
        for k in (lo..center).rev() {
            att[k - lo] = rot(&phi[k + 1]).transpose() * att[k + 1 - lo];
        }
        Some((att, a_center, is_fine))
    }

    /// Frame `k`'s context at attitude `a_k` in batch `batch` (center time `t_center`).
    fn frame_context(
        &self,
        k: usize,
        a_k: Matrix3<f64>,
        batch: usize,
        t_center: f64,
    ) -> FrameContext {
        let f = &self.input.frames[k];
        let (phase, v_sc) = match f.orbit {
            Some((p, v)) => (orbit_phase(&p, &v), v),
            None => (f64::NAN, Vector3::zeros()),
        };
        let at_frame = |v: &[Vector3<f64>]| v.get(k).copied().unwrap_or_else(Vector3::zeros);
        let v_e = at_frame(&self.input.earth_vel_eci_km_per_s);
        let sun = at_frame(&self.input.sun_eci);
        let mut dtemp = [0.0; 5];
        for (d, (t, m)) in dtemp
            .iter_mut()
            .zip(f.temperatures_c.iter().zip(self.tmean))
        {
            *d = t - m;
        }
        FrameContext {
            k,
            a_k,
            batch,
            t_s: f.time.seconds() - self.t_first,
            t_center,
            phase,
            v_e,
            v_sc,
            sun,
            dtemp,
        }
    }

    /// The star and Sun sightings of frame `k`, in the order FHST1, FHST2, FSS1, FSS2.
    fn sightings(&self, k: usize) -> Vec<Sighting> {
        let f = &self.input.frames[k];
        let mut out = Vec::new();
        for (i, s) in f.stars.iter().enumerate() {
            let Some(s) = s else { continue };
            let Some((hip, dir)) = s.identified else {
                continue;
            };
            out.push(Sighting {
                sensor: i,
                u: dir,
                ang: [s.meas.h_rad, s.meas.v_rad],
                sigma_rad: s.sigma_rad,
                star: hip,
                mag: s.catalog_magnitude,
            });
        }
        for (i, s) in f.suns.iter().enumerate() {
            let Some(s) = s else { continue };
            out.push(Sighting {
                sensor: i + 2,
                u: s.sun_eci,
                ang: [s.meas.alpha_rad, s.meas.beta_rad],
                sigma_rad: s.sigma_rad,
                star: 0,
                mag: f64::NAN,
            });
        }
        out
    }

    /// One sighting's residual, partials and regressors; `None` when the reference falls
    /// outside the sensor's field.
    fn measurement(&self, fc: &FrameContext, sg: &Sighting) -> Option<Measurement> {
        let (k, sensor) = (fc.k, sg.sensor);
        let f = &self.input.frames[k];
        let rate = self.frame_rate[k];
        let m = &self.m_sensor[sensor];
        let [dk_annual, dk_orbital] = self.dk;
        let (v_e, v_sc) = (fc.v_e, fc.v_sc);
        let v_tot = v_e + v_sc;
        // References to the model's aberration (first order).
        let u = if dk_annual == 0.0 && dk_orbital == 0.0 {
            sg.u
        } else {
            (sg.u
                + aberration_term(&sg.u, &v_e) * dk_annual
                + aberration_term(&sg.u, &v_sc) * dk_orbital)
                .normalize()
        };
        // Attitude at the sample time t − τ₀.
        let a_s = if self.tau0[sensor] == 0.0 {
            fc.a_k
        } else {
            rot(&(-rate * self.tau0[sensor])) * fc.a_k
        };
        let b = a_s * u;
        let s = m.transpose() * b;
        let (p0, p1) = hv_from_dir(&s)?;
        let jm = hv_jacobian(&s) * m.transpose();
        let boresight = m.column(2).into_owned();
        let tb = tangent_basis(&u);
        let vdir = if v_tot.norm() > 0.0 {
            v_tot.normalize()
        } else {
            v_tot
        };
        let sun = fc.sun;
        Some(Measurement {
            sensor,
            frame: k,
            batch: fc.batch,
            t_s: fc.t_s,
            dt_center_s: fc.t_s - fc.t_center,
            r: [
                (sg.ang[0] - p0) * ARCSEC_PER_RAD,
                (sg.ang[1] - p1) * ARCSEC_PER_RAD,
            ],
            sigma: sg.sigma_rad * ARCSEC_PER_RAD,
            jm,
            b_acs: b,
            ang: [p0, p1],
            rate_acs: rate,
            rate_sensor: m.transpose() * rate,
            ab_annual_acs: a_s * aberration_term(&u, &v_e),
            ab_orbital_acs: a_s * aberration_term(&u, &v_sc),
            tangent_acs: [a_s * tb[0], a_s * tb[1]],
            u_eci: u,
            star: sg.star,
            magnitude: sg.mag,
            dtemp: fc.dtemp,
            orbit_phase: fc.phase,
            high_rate: f.high_rate,
            sun_angle_deg: if sun.norm() > 0.0 {
                (a_s * sun).dot(&boresight).clamp(-1.0, 1.0).acos() * DEG_PER_RAD
            } else {
                f64::NAN
            },
            vel_sensor: m.transpose() * (a_s * vdir),
            since_slew_s: self.since_slew[k],
            outlier: false,
        })
    }
}

impl MeasurementSet {
    /// Build residuals, partials and regressors.
    #[must_use]
    pub fn build(input: &DiagnoseInput<'_>) -> Self {
        let frames = input.frames;
        let n = frames.len();
        // 1. The flown alignments and time offsets, the aberration to add, the per-frame
        //    series (calibrated increments, rates, temperatures, time since the last slew).
        let m_sensor: [Matrix3<f64>; 4] = {
            let t = input.alignment.matrices();
            [
                matrix_from_rows(t[0]),
                matrix_from_rows(t[1]),
                matrix_from_rows(t[2]),
                matrix_from_rows(t[3]),
            ]
        };
        let k_frames = if input.frames_aberration { 1.0 } else { 0.0 };
        let k0 = input.aberration_model.map(|b| if b { 1.0 } else { 0.0 });
        let (phi, dts) = calibrated_increments(input);
        let b = SetBuild {
            input,
            m_sensor,
            tau0: input.alignment.corrections.time_offset_s,
            dk: [k0[0] - k_frames, k0[1] - k_frames],
            t_first: frames.first().map_or(0.0, |f| f.time.seconds()),
            frame_rate: frame_rates(&phi, &dts),
            phi,
            dts,
            tmean: mean_temperatures(frames),
            since_slew: time_since_slew(frames),
        };
        // 2. Per batch: the attitude at every frame, then every sighting's measurement.
        let mut batches = Vec::new();
        let mut frame_attitude = vec![None; n];
        let mut meas = Vec::with_capacity(count_sightings(frames));
        for (lo, hi, hr) in make_batches(frames) {
            let center = (lo + hi) / 2;
            let Some((att, a_center, is_fine)) = b.batch_attitudes(lo, hi, center) else {
                continue;
            };
            let batch_index = batches.len();
            let t_center = frames[center].time.seconds() - b.t_first;
            batches.push(Batch {
                lo,
                hi,
                center,
                t_center_s: t_center,
                m_acs_from_eci: a_center,
                fine: is_fine,
                high_rate: hr,
                usable: true,
                fhst_only: true,
            });
            for k in lo..hi {
                let a_k = att[k - lo];
                frame_attitude[k] = Some(a_k);
                let fc = b.frame_context(k, a_k, batch_index, t_center);
                meas.extend(
                    b.sightings(k)
                        .iter()
                        .filter_map(|sg| b.measurement(&fc, sg)),
                );
            }
        }
        meas.shrink_to_fit();
        // 3. The set, its noise floor and its batches checked.
        let mut set = Self {
            meas,
            batches,
            frame_attitude,
            frame_time_s: frames
                .iter()
                .map(|f| f.time.seconds() - b.t_first)
                .collect(),
            frame_gyro: (0..n)
                .map(|k| (b.dts[k] > 0.0).then_some((b.phi[k], b.dts[k])))
                .collect(),
            noise_floor_arcsec: [f64::NAN; 4],
            sigma_scale: [1.0; 4],
            m_acs_from_sensor: m_sensor,
            aberration_k0: k0,
            time_offset0_s: b.tau0,
            orbit_period_s: orbit_period(frames),
            temperature_mean_c: b.tmean,
            frame_rate: b.frame_rate,
        };
        set.estimate_noise();
        set.check_batches();
        set
    }

    /// Mark batches whose FHST attitude is poorly determined (one star, short slew batches)
    /// and exclude their measurements.
    fn check_batches(&mut self) {
        // One batch at a time (the measurements are in batch order): two 6×6 information
        // matrices per batch for the whole run at once were 0.3 GB on six months of 30-s
        // frames (issue 22). The sums are the same, in the same order.
        let good = |inf: &mut nalgebra::Matrix6<f64>| {
            for j in 0..3 {
                inf[(j, j)] += 1.0 / NUISANCE_ANGLE_PRIOR_ARCSEC.powi(2);
                inf[(j + 3, j + 3)] += 1.0 / NUISANCE_RATE_PRIOR.powi(2);
            }
            match inf.try_inverse() {
                Some(cov) => (0..3).all(|j| cov[(j, j)].sqrt() < MAX_BATCH_SIGMA_ARCSEC),
                None => false,
            }
        };
        let mut next = 0usize;
        for (i, b) in self.batches.iter_mut().enumerate() {
            let mut info_fhst = nalgebra::Matrix6::<f64>::zeros();
            let mut info_all = nalgebra::Matrix6::<f64>::zeros();
            let mut has_fhst = false;
            let start = next;
            while next < self.meas.len() && self.meas[next].batch == i {
                next += 1;
            }
            for m in self.meas[start..next].iter().filter(|m| !m.outlier) {
                let a = Self::attitude_partial(m);
                let t = m.dt_center_s / 100.0;
                let w = 1.0 / (m.sigma * m.sigma);
                for ax in 0..2 {
                    let mut row = nalgebra::Vector6::zeros();
                    for j in 0..3 {
                        row[j] = a[(ax, j)];
                        row[j + 3] = a[(ax, j)] * t;
                    }
                    let add = row * row.transpose() * w;
                    info_all += add;
                    if m.sensor < 2 {
                        info_fhst += add;
                        has_fhst = true;
                    }
                }
            }
            b.fhst_only = good(&mut info_fhst);
            // A batch needs a star: the Sun alone gives two axes.
            b.usable = has_fhst && (b.fhst_only || (ALLOW_FSS_AIDED && good(&mut info_all)));
        }
        debug_assert_eq!(next, self.meas.len(), "measurements in batch order");
        let usable: Vec<bool> = self.batches.iter().map(|b| b.usable).collect();
        for m in &mut self.meas {
            if !usable[m.batch] {
                m.outlier = true;
            }
        }
    }

    /// Successive-difference noise floor and σ rescaling; flags outliers.
    fn estimate_noise(&mut self) {
        for sensor in 0..4 {
            // Successive pairs within a batch, same star, low rate.
            let idx: Vec<usize> = (0..self.meas.len())
                .filter(|&i| self.meas[i].sensor == sensor)
                .collect();
            let mut z = Vec::new();
            let mut d_abs = Vec::new();
            for w in idx.windows(2) {
                let (a, b) = (&self.meas[w[0]], &self.meas[w[1]]);
                if a.batch != b.batch
                    || a.star != b.star
                    || a.high_rate
                    || b.high_rate
                    || b.frame != a.frame + 1
                {
                    continue;
                }
                let s = (a.sigma * a.sigma + b.sigma * b.sigma).sqrt();
                for ax in 0..2 {
                    let d = b.r[ax] - a.r[ax];
                    if !(d.is_finite() && s.is_finite() && s > 0.0) {
                        continue;
                    }
                    z.push((d / s).abs());
                    d_abs.push(d.abs() / std::f64::consts::SQRT_2);
                }
            }
            if z.len() < 20 {
                continue;
            }
            // RMS of the differences without the largest 0.5 % (outliers, new stars). Not a
            // median: quantized data (the FSS's 14.4″ counts with 7″ noise) make most
            // successive differences exactly zero or one count.
            let mut sorted = z.clone();
            sorted.sort_by(f64::total_cmp);
            let lim = sorted[((sorted.len() as f64) * 0.995) as usize - 1];
            let keep: Vec<usize> = (0..z.len()).filter(|&i| z[i] <= lim).collect();
            // Gaussian correction of the 0.5 % trim: E[z²; |z| < 2.807]/0.995 = 0.961.
            let trim = 0.961_f64.sqrt();
            let scale = (keep.iter().map(|&i| z[i] * z[i]).sum::<f64>() / keep.len().max(1) as f64)
                .sqrt()
                / trim;
            let floor = (keep.iter().map(|&i| d_abs[i] * d_abs[i]).sum::<f64>()
                / keep.len().max(1) as f64)
                .sqrt()
                / trim;
            let mad = lim;
            if std::env::var_os("DIAGNOSE_DEBUG").is_some() {
                crate::note!(
                    "noise sensor {sensor}: pairs {} mad {mad} keep {} scale {scale} floor {floor}",
                    z.len(),
                    keep.len()
                );
            }
            if scale.is_finite() && scale > 1e-3 {
                self.sigma_scale[sensor] = scale;
                self.noise_floor_arcsec[sensor] = floor;
                for m in self.meas.iter_mut().filter(|m| m.sensor == sensor) {
                    m.sigma *= scale;
                }
            }
        }
        // Outliers against a per-batch median (robust to the reference attitude's error).
        for m in &mut self.meas {
            let z = (m.r[0].powi(2) + m.r[1].powi(2)).sqrt() / m.sigma;
            // Generous: the baseline residuals still hold every unmodelled effect.
            m.outlier = !z.is_finite() || z > OUTLIER_SIGMA * 4.0;
        }
    }

    /// Flag outliers from post-fit residuals (`OUTLIER_SIGMA` × σ per axis).
    pub fn flag_outliers(&mut self, post: &[[f64; 2]]) {
        let usable: Vec<bool> = self.batches.iter().map(|b| b.usable).collect();
        for (m, r) in self.meas.iter_mut().zip(post) {
            let z = r[0].abs().max(r[1].abs()) / m.sigma;
            m.outlier = !usable[m.batch] || !z.is_finite() || z > OUTLIER_SIGMA;
        }
    }

    /// Attitude partial `∂r/∂δθ` (arcsec per arcsec).
    #[must_use]
    pub fn attitude_partial(m: &Measurement) -> Matrix2x3<f64> {
        m.jm * skew(&m.b_acs)
    }

    /// Residual RMS per sensor (arcsec, both axes pooled) of the given residuals.
    #[must_use]
    pub fn rms_per_sensor(&self, r: &[[f64; 2]]) -> [f64; 4] {
        let mut s = [0.0; 4];
        let mut c = [0usize; 4];
        for (m, r) in self.meas.iter().zip(r) {
            if m.outlier {
                continue;
            }
            s[m.sensor] += r[0] * r[0] + r[1] * r[1];
            c[m.sensor] += 2;
        }
        let mut out = [f64::NAN; 4];
        for k in 0..4 {
            if c[k] > 0 {
                out[k] = (s[k] / c[k] as f64).sqrt();
            }
        }
        out
    }

    /// Number of (non-outlier) measurements per sensor.
    #[must_use]
    pub fn count_per_sensor(&self) -> [usize; 4] {
        let mut c = [0usize; 4];
        for m in self.meas.iter().filter(|m| !m.outlier) {
            c[m.sensor] += 1;
        }
        c
    }
}
