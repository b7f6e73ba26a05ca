//! # DA and FADS: from decoded telemetry to identified, referenced observations
//!
//! **DA** (data adjustment, paper §3.3) applies a set of calibration tables to the raw counts
//! with the *flight* conversion code (`fsw_core::fhst::measure_tracker_at`,
//! `fsw_core::fss::measure_sensor_at`, `fsw_core::iru::IruIntegrator`): one definition of every
//! conversion, so the ground and the OBC can never disagree on a count. Every correction of the
//! tables goes in (FHST distortion and magnitude bias, the FSS transfer function with its
//! cubic and cyclic terms, the thermal alignment drift at the frame's temperatures, the gyro
//! scale asymmetry). Time-tag offsets are not applied here (they need the attitude motion:
//! the diagnose measurement model carries them).
//!
//! **FADS** (fine attitude determination) identifies every tracked star against the *full*
//! Hipparcos catalog (not the onboard subset) from the OBC's own attitude, and computes the
//! apparent reference directions seen from the spacecraft: proper motion and parallax to the
//! date, annual + orbital aberration from the definitive orbit (APID 0x020), and the apparent
//! Sun with parallax, light time and aberration. [`fine_attitude`] solves an attitude at the
//! centre of a batch with gyro propagation of every vector to the centre, as the paper does to
//! keep bias error out of the end attitudes of its IRU calibration.

use crate::attitude::quest::{solve_attitude, AttitudeError, AttitudeSolution, VectorPair};
use crate::calibration::iru::GyroStep;
use crate::tp::Telemetry;
use fsw_core::attitude::{rot, Quat};
use fsw_core::events::EventId;
use fsw_core::fhst::{self, FhstId, FhstMeasurement};
use fsw_core::fss::{self, FssId, FssMeasurement};
use fsw_core::iru::{delta_theta_from_pulses, pulse_weight_rad, IruConfiguration, IruIntegrator};
use fsw_core::raw::TimeTag;
use fsw_core::tables::{AlignmentTable, IruTable};
use fsw_core::telemetry::EphemerisRecord;
use fsw_core::units::{RAD_PER_ARCSEC, RAD_PER_DEG};
use gro_reference::sky::Sky;
use gro_reference::sun::SunEphemeris;
use nalgebra::{Matrix3, Vector3};

/// Declared sensor accuracies (`metadata.json` `sensors`; absent figures are the paper's):
/// defined once with the run folder (`gro_reference::run_folder`).
pub use gro_reference::run_folder::DeclaredNoise;

/// An FHST observation with its identification.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StarObservation {
    /// The measurement (through the DA tables).
    pub meas: FhstMeasurement,
    /// Identified catalog star (HIP) and its apparent direction from the spacecraft.
    pub identified: Option<(u32, Vector3<f64>)>,
    /// Catalog magnitude of the identified star.
    pub catalog_magnitude: f64,
    /// 1σ per axis, rad.
    pub sigma_rad: f64,
}

/// An FSS observation with its reference.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SunObservation {
    /// The measurement.
    pub meas: FssMeasurement,
    /// Apparent Sun direction from the spacecraft, J2000.
    pub sun_eci: Vector3<f64>,
    /// 1σ per axis, rad.
    pub sigma_rad: f64,
}

/// Everything known at one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameObservations {
    /// Frame time.
    pub time: TimeTag,
    /// Gyro increment over the interval that ended at this frame (ACS, no bias removed).
    pub gyro: Option<GyroStep>,
    /// IRU rate mode of that interval (of its last cycle, ICD §3.1 byte 13).
    pub high_rate: bool,
    /// The gyro step came from the backup triad (X1, Y2, Z2).
    pub iru_backup: bool,
    /// Whether the frame interval held a rate-mode switch, and what was done with it.
    pub rate_switch: RateSwitch,
    /// Per-axis variance added to the gyro step by splitting its pulses between the two rate
    /// modes (rad²; 0 without a switch).
    pub gyro_split_var_rad2: f64,
    /// How the split step moves (ACS, rad) per unit of the split fraction `c`: the angle
    /// before the switch at the top (`c = +½`) or bottom (`c = −½`) of its envelope
    /// (`split_step`); zero without a split. The calibration estimates `c` per kind of switch.
    pub gyro_split_dir_rad: Vector3<f64>,
    /// FHST1, FHST2.
    pub stars: [Option<StarObservation>; 2],
    /// FSS1, FSS2, boxed: most frames of most days hold no Sun (in eclipse, or out of the
    /// FSS field), and 2 × 96 bytes inline were a quarter of a frame (six months of 30-s
    /// frames: 0.1 GB of `None`s).
    pub suns: [Option<Box<SunObservation>>; 2],
    /// Temperatures, °C (FHST1, FHST2, FSS1, FSS2, IRU).
    pub temperatures_c: [f64; 5],
    /// OBC attitude estimate at this frame (housekeeping), if downlinked.
    pub obc_q_acs_from_eci: Option<Quat>,
    /// Spacecraft position and velocity, J2000, km and km/s (interpolated ephemeris).
    pub orbit: Option<(Vector3<f64>, Vector3<f64>)>,
}

/// A rate-mode switch split inside one frame interval (`split_rate_switches`), as every gyro
/// model that reads the step takes it (calibrate's chain, `iru_chain`; diagnose's slews,
/// `diagnose::gyro_slews`): the step was taken in the middle of its envelope (split fraction
/// `c = 0`); where the truth lies is nearly the same for every switch of one kind (slew
/// starts, slew ends), so the models estimate one `c` per kind, and what varies from one
/// switch to the next is the step's variance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GyroSplit {
    /// The interval ends in high rate: a slew start (else a slew end).
    pub into_high_rate: bool,
    /// Change of the step (ACS, rad) per unit split fraction.
    pub dir_rad: Vector3<f64>,
    /// Per-axis variance of the step (rad²).
    pub var_rad2: f64,
}

/// Split fractions estimated per kind of switch: [into high rate, into low rate].
pub const SPLIT_KINDS: usize = 2;

impl GyroSplit {
    /// Index of the split fraction this switch shares (0: into high rate, 1: into low rate).
    #[must_use]
    pub fn kind(&self) -> usize {
        usize::from(!self.into_high_rate)
    }
}

impl FrameObservations {
    /// The rate-mode switch split inside this frame's interval, if any.
    #[must_use]
    pub fn gyro_split(&self) -> Option<GyroSplit> {
        (self.rate_switch == RateSwitch::Split).then_some(GyroSplit {
            into_high_rate: self.high_rate,
            dir_rad: self.gyro_split_dir_rad,
            var_rad2: self.gyro_split_var_rad2,
        })
    }
}

/// A frame interval that contains an IRU rate-mode switch (decimated telemetry: the counter
/// difference mixes 0.05″ and 0.8″ pulses).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub enum RateSwitch {
    /// No switch inside the interval (or a 1-cycle interval).
    #[default]
    None,
    /// One switch at a known time (event 0x0203): the pulses were split between the modes.
    Split,
    /// A switch whose time or pulse split is unknown: the step was dropped (no gyro step).
    Dropped,
}

/// Interpolate the definitive orbit (cubic Hermite between records ≤ 600 s apart).
#[must_use]
pub fn interpolate_orbit(
    ephemeris: &[EphemerisRecord],
    t_s: f64,
) -> Option<(Vector3<f64>, Vector3<f64>)> {
    let idx = ephemeris.partition_point(|e| e.time.seconds() <= t_s);
    let (a, b) = match idx {
        0 => return None,
        i if i >= ephemeris.len() => {
            let last = ephemeris.last()?;
            // Extrapolate at most 60 s past the last record.
            let dt = t_s - last.time.seconds();
            if dt > 60.0 {
                return None;
            }
            let p = Vector3::from(last.pos_eci_km) + Vector3::from(last.vel_eci_km_per_s) * dt;
            return Some((p, Vector3::from(last.vel_eci_km_per_s)));
        }
        i => (&ephemeris[i - 1], &ephemeris[i]),
    };
    let (ta, tb) = (a.time.seconds(), b.time.seconds());
    let h = tb - ta;
    if !(h > 0.0 && h <= 600.0) {
        return None;
    }
    let s = (t_s - ta) / h;
    let (p0, p1) = (Vector3::from(a.pos_eci_km), Vector3::from(b.pos_eci_km));
    let (v0, v1) = (
        Vector3::from(a.vel_eci_km_per_s) * h,
        Vector3::from(b.vel_eci_km_per_s) * h,
    );
    let (s2, s3) = (s * s, s * s * s);
    let pos = p0 * (2.0 * s3 - 3.0 * s2 + 1.0)
        + v0 * (s3 - 2.0 * s2 + s)
        + p1 * (-2.0 * s3 + 3.0 * s2)
        + v1 * (s3 - s2);
    let vel = (p0 * (6.0 * s2 - 6.0 * s)
        + v0 * (3.0 * s2 - 4.0 * s + 1.0)
        + p1 * (-6.0 * s2 + 6.0 * s)
        + v1 * (3.0 * s2 - 2.0 * s))
        / h;
    Some((pos, vel))
}

/// Options of the FADS identification.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IdentifyOptions {
    /// Match window around the predicted direction, rad.
    pub window_rad: f64,
    /// Magnitude tolerance, mag.
    pub magnitude_tolerance: f64,
    /// Apply aberration (annual + orbital) to the references. Off only to study the effect.
    pub aberration: bool,
}

impl Default for IdentifyOptions {
    fn default() -> Self {
        Self {
            window_rad: 0.3 * RAD_PER_DEG,
            magnitude_tolerance: 0.8,
            aberration: true,
        }
    }
}

/// Longest frame spacing over which a gyro step is formed: 2.5 × the median spacing. Why:
/// the IRU counters are 16-bit (docs/icd.md §3.1); over a gap the difference of two counts
/// is known only modulo 65,536 pulses, so a step across it could be silently wrong (a 200-s
/// gap mid-slew gave a bias 100× off, docs/icd-conformance.md). Such frames get no step,
/// and the intervals that would need one are not used.
fn max_gyro_step_s(raw: &[fsw_core::raw::RawSensorFrame]) -> f64 {
    let mut dt: Vec<f64> = raw
        .windows(2)
        .map(|w| w[1].time.seconds() - w[0].time.seconds())
        .filter(|d| *d > 0.0)
        .collect();
    if dt.is_empty() {
        return f64::INFINITY;
    }
    let mid = dt.len() / 2;
    let (_, median, _) = dt.select_nth_unstable_by(mid, f64::total_cmp);
    2.5 * *median
}

/// DA + FADS over a whole telemetry set.
#[must_use]
pub fn build_observations(
    tm: &Telemetry,
    alignment: &AlignmentTable,
    iru: &IruTable,
    noise: &DeclaredNoise,
    sky: &Sky,
    options: &IdentifyOptions,
) -> Vec<FrameObservations> {
    let mut integrator = IruIntegrator::new();
    let mut hk_index = 0usize;
    let mut sun_ephemeris: Option<SunEphemeris> = None;
    let mut previous_time: Option<f64> = None;
    let mut frames = Vec::with_capacity(tm.raw.len());
    // The ground's own attitude, for identification where no OBC attitude was downlinked:
    // bootstrapped from the Sun and two trackers' stars, refreshed from every frame with two
    // identified stars, carried by the gyro in between (`OwnAttitude`).
    let mut own = OwnAttitude::default();
    let max_gyro_step_s = max_gyro_step_s(&tm.raw);
    // Per frame: the selected channels' pulse differences and the configuration, kept for
    // re-weighting a frame interval that holds a rate-mode switch (`split_rate_switches`).
    let mut pulses: Vec<Option<[f64; 3]>> = Vec::with_capacity(tm.raw.len());
    for raw in &tm.raw {
        let t_s = raw.time.seconds();
        let j2000_tt_s = raw.time.seconds_since_j2000_tt();
        // The OBC's configuration at this time decides which channels are integrated.
        while hk_index + 1 < tm.housekeeping.len() && tm.housekeeping[hk_index + 1].time <= raw.time
        {
            hk_index += 1;
        }
        let hk = tm
            .housekeeping
            .get(hk_index)
            .filter(|h| (h.time.seconds() - t_s).abs() < 1e-6);
        let config = match hk.map(|h| h.iru_config) {
            Some(1) => IruConfiguration::Backup,
            _ => IruConfiguration::Primary,
        };
        let out = integrator.process(&raw.iru, config, iru);
        let gyro = match (out.delta_theta_acs_rad, previous_time) {
            // Across a gap the 16-bit counters may have wrapped more than once: no step.
            (Some(d), Some(prev)) if t_s > prev && t_s - prev <= max_gyro_step_s => {
                Some(GyroStep {
                    dtheta_acs_rad: d,
                    dt_s: t_s - prev,
                })
            }
            _ => None,
        };
        previous_time = Some(t_s);
        pulses.push(gyro.map(|_| config.channels().map(|c| f64::from(out.delta_counts[c]))));
        let orbit = interpolate_orbit(&tm.ephemeris, t_s);
        let eph = sun_ephemeris.get_or_insert_with(|| SunEphemeris::new(j2000_tt_s, 600.0));
        let sun_state = eph.state(j2000_tt_s);
        let (pos, vel) = orbit.unwrap_or((Vector3::zeros(), Vector3::zeros()));
        let observer_bary_km = sun_state.earth_pos_bary_eci_km + pos;
        let observer_vel = if options.aberration {
            sun_state.earth_vel_bary_eci_km_per_s + vel
        } else {
            Vector3::zeros()
        };
        let obc_q = hk.map(|h| h.q_acs_from_eci);
        if let Some(g) = gyro {
            own.propagate(&g);
        }
        let sun_eci = if options.aberration {
            sun_state.apparent_dir_from_sc_eci(&pos, &vel)
        } else {
            sun_state.astrometric_from_km(&pos).normalize()
        };
        let mut temperatures_c = [0.0; 5];
        for (t, raw_t) in temperatures_c.iter_mut().zip(raw.temperatures_centi_c) {
            *t = f64::from(raw_t) * 0.01;
        }
        // DA: each sensor's measurement through the flown tables, once per frame, with every
        // correction the table carries as the OBC applies it (distortion, magnitude bias, the
        // full FSS transfer function, the thermal drift at the frame's sensor temperature).
        let fhst_meas: [Option<FhstMeasurement>; 2] = FhstId::ALL.map(|id| {
            raw.fhst.get(id.index()).and_then(|sample| {
                fhst::measure_tracker_at(sample, id, alignment, temperatures_c[id.index()]).ok()
            })
        });
        let fss_meas: [Option<FssMeasurement>; 2] = FssId::ALL.map(|id| {
            raw.fss.get(id.index()).and_then(|sample| {
                fss::measure_sensor_at(sample, id, alignment, temperatures_c[2 + id.index()]).ok()
            })
        });
        if obc_q.is_none() {
            own.note_stars(&fhst_meas, &fss_meas, t_s);
        }
        let id_q = obc_q.or_else(|| {
            if own.usable(t_s) {
                return own.q();
            }
            own.bootstrap(sky, &sun_eci, j2000_tt_s, &observer_bary_km, t_s, options)
        });
        let mut stars = [None, None];
        for (slot, meas) in stars.iter_mut().zip(fhst_meas) {
            let Some(meas) = meas else {
                continue;
            };
            let mut obs = StarObservation {
                meas,
                identified: None,
                catalog_magnitude: f64::NAN,
                sigma_rad: noise.fhst_sigma_rad(meas.magnitude),
            };
            if let Some(q) = id_q {
                let observer = (j2000_tt_s, &observer_bary_km, &observer_vel);
                if let Some((hip, dir, mag)) = identify_star(sky, &meas, &q, observer, options) {
                    obs.identified = Some((hip, dir));
                    obs.catalog_magnitude = mag;
                }
            }
            *slot = Some(obs);
        }
        let suns = fss_meas.map(|m| {
            m.map(|meas| {
                Box::new(SunObservation {
                    meas,
                    sun_eci,
                    sigma_rad: noise.fss_sigma_arcsec * RAD_PER_ARCSEC,
                })
            })
        });
        if obc_q.is_none() {
            own.refresh(&stars, &suns, t_s);
        }
        frames.push(FrameObservations {
            time: raw.time,
            gyro,
            high_rate: raw.iru.high_rate,
            iru_backup: config == IruConfiguration::Backup,
            rate_switch: RateSwitch::None,
            gyro_split_var_rad2: 0.0,
            gyro_split_dir_rad: Vector3::zeros(),
            stars,
            suns,
            temperatures_c,
            obc_q_acs_from_eci: obc_q,
            orbit,
        });
    }
    split_rate_switches(tm, &mut frames, &pulses, iru);
    frames
}

/// FADS for one tracker measurement: the catalog star within the window of the direction
/// the attitude `q` gives it, within the magnitude tolerance, when there is exactly one:
/// (HIP, its reference direction at the observer `(TT s since J2000, barycentric position km,
/// velocity km/s)`, its catalog magnitude).
fn identify_star(
    sky: &Sky,
    meas: &FhstMeasurement,
    q: &Quat,
    (j2000_tt_s, observer_bary_km, observer_vel): (f64, &Vector3<f64>, &Vector3<f64>),
    options: &IdentifyOptions,
) -> Option<(u32, Vector3<f64>, f64)> {
    let r_obs = q.to_dcm().transpose() * meas.dir_acs;
    let mut found: Option<(u32, Vector3<f64>, f64)> = None;
    let mut count = 0usize;
    sky.for_each_in_cone(&r_obs, options.window_rad, |_, star| {
        if (star.magnitude - meas.magnitude).abs() > options.magnitude_tolerance {
            return;
        }
        let apparent = if options.aberration {
            star.apparent_dir_eci(j2000_tt_s, observer_bary_km, observer_vel)
        } else {
            star.astrometric_dir_eci(j2000_tt_s, observer_bary_km)
        };
        if apparent.dot(&r_obs).clamp(-1.0, 1.0).acos() <= options.window_rad {
            count += 1;
            found = Some((star.hip, apparent, star.magnitude));
        }
    });
    if count == 1 {
        found
    } else {
        None
    }
}

/// The IRU rate-mode switches announced by `0x0203` events: (time the new mode starts, high).
/// docs/icd.md §3.3: the command changed at the event's cycle applies from the next sample
/// interval, so the new mode starts one cycle after the event.
fn rate_mode_switches(tm: &Telemetry, cycle_s: f64) -> Vec<(f64, bool)> {
    tm.events
        .iter()
        .filter(|(_, e)| e.id == EventId::IruRateModeChanged)
        .map(|(t, e)| (t.seconds() + cycle_s, e.p1 == 1))
        .collect()
}

/// The flight software's cycle (s), from the time codes: the shortest spacing of consecutive
/// raw frames or events that *recurs* (at least [`CYCLE_MIN_COUNT`] times and in 1 ‰ of the
/// spacings), so that one damaged time code (a flipped fine bit makes one 0.5-s and one
/// 1.5-s spacing) cannot halve it and turn every frame interval into a "multi-cycle" one.
/// At most 1 s, unless at least [`CYCLE_MIN_EVENTS_ON_GRID`] events are downlinked and every
/// one lies on that longer grid (a 2-s OBC cycle): events come at cycle times, so they tell a
/// long cycle from decimated raw frames, whose spacing is several cycles. With fewer events,
/// or one off the grid, a longer spacing is read as decimation of a 1-s cycle and a switch
/// inside it is dropped. Left: a 1-s cycle decimated to 2 s whose events all fall on even
/// seconds reads as a 2-s cycle, and a 0.5-s cycle downlinked every second with sparse events
/// as 1 s; both would weight a switch frame with one mode (metadata.json's `cycle_period_s`
/// is not used: the ICD makes it informational).
fn cycle_period_s(tm: &Telemetry) -> f64 {
    let spacing = |a: f64, b: f64| ((b - a) * 1e3).round() as i64; // ms
    let raw = tm
        .raw
        .windows(2)
        .map(|w| spacing(w[0].time.seconds(), w[1].time.seconds()));
    let events = tm
        .events
        .windows(2)
        .map(|w| spacing(w[0].0.seconds(), w[1].0.seconds()));
    let mut counts: std::collections::BTreeMap<i64, usize> = std::collections::BTreeMap::new();
    for d in raw.chain(events).filter(|d| *d >= 1) {
        *counts.entry(d).or_default() += 1;
    }
    let total: usize = counts.values().sum();
    let needed = CYCLE_MIN_COUNT.max(total.div_ceil(1000));
    let Some(shortest_ms) = counts
        .iter()
        .find(|(_, &c)| c >= needed)
        .or_else(|| counts.iter().next())
        .map(|(&d, _)| d)
    else {
        return 1.0;
    };
    let shortest = shortest_ms as f64 * 1e-3;
    if shortest <= 1.0 {
        return shortest;
    }
    let t0 = tm.raw.first().map_or(0.0, |r| r.time.seconds());
    let on_grid = |t: f64| {
        let k = ((t - t0) / shortest).round();
        ((t - t0) - k * shortest).abs() < 1e-3
    };
    if tm.events.len() >= CYCLE_MIN_EVENTS_ON_GRID
        && tm.events.iter().all(|(t, _)| on_grid(t.seconds()))
    {
        shortest
    } else {
        1.0
    }
}

/// Fewest occurrences of a spacing for it to count as the cycle ([`cycle_period_s`]).
const CYCLE_MIN_COUNT: usize = 3;

/// Fewest events, all on a grid longer than 1 s, for that grid to be read as the cycle
/// ([`cycle_period_s`]): a few events can fall on even seconds of a 1-s cycle by chance, and
/// reading decimation as a long cycle would mis-weight a switch frame instead of dropping it.
const CYCLE_MIN_EVENTS_ON_GRID: usize = 10;

/// Frame intervals that hold an IRU rate-mode switch (docs/icd.md §3.1: byte 13 is the mode
/// of the **last** cycle of the interval; with decimated telemetry the counter difference
/// mixes 0.05″ and 0.8″ pulses, `algorithms.md` §10a "Decimated gyro data").
///
/// Why: weighting every pulse of such an interval with the end mode's weight undercounts (or
/// overcounts) the slew by up to 15/16 of the high-rate pulses; over a 10° slew that is
/// thousands of ppm of false scale factor. The switch time comes from the `0x0203` events
/// (downlinked every cycle); the angle of the interval is split with the rate interpolated
/// between its one-mode neighbours (`split_step`), and the split's uncertainty (including one
/// cycle of switch timing, since writers differ on the event's cycle) is carried as a
/// variance of the step. Without events, or with more than one switch inside, or without
/// one-mode neighbours on both sides, the step is dropped (the gyro chain breaks there and the report says how many
/// frames were dropped).
fn split_rate_switches(
    tm: &Telemetry,
    frames: &mut [FrameObservations],
    pulses: &[Option<[f64; 3]>],
    iru: &IruTable,
) {
    let cycle_s = cycle_period_s(tm);
    let switches = rate_mode_switches(tm, cycle_s);
    let have_events = !tm.events.is_empty();
    // Mode of the interval that starts at `t`.
    let mode_from = |t: f64, fallback: bool| -> bool {
        let k = switches.partition_point(|c| c.0 <= t + 1e-6);
        if k == 0 {
            fallback
        } else {
            switches[k - 1].1
        }
    };
    // First: which intervals hold a switch, and the switch time when exactly one is known.
    let n = frames.len();
    let mut straddles: Vec<Option<Option<f64>>> = vec![None; n];
    for k in 1..n {
        let (t_prev, t_now) = (frames[k - 1].time.seconds(), frames[k].time.seconds());
        // A one-cycle interval has one mode, the one byte 13 gives.
        if frames[k].gyro.is_none() || t_now - t_prev < 1.5 * cycle_s {
            continue;
        }
        let end_mode = frames[k].high_rate;
        let start_mode = if have_events {
            mode_from(t_prev, frames[k - 1].high_rate)
        } else {
            frames[k - 1].high_rate
        };
        let inside: Vec<(f64, bool)> = switches
            .iter()
            .copied()
            .filter(|c| c.0 > t_prev + 1e-6 && c.0 < t_now - 1e-6)
            .collect();
        if inside.is_empty() && start_mode == end_mode {
            continue;
        }
        straddles[k] = Some(match inside.as_slice() {
            [(t_switch, new_mode)] if *new_mode == end_mode && start_mode != end_mode => {
                Some(*t_switch)
            }
            _ => None,
        });
    }
    // Then the split of each, from a clean low-rate neighbour.
    for k in 1..n {
        let Some(switch) = straddles[k] else {
            continue;
        };
        let split = switch.and_then(|t_switch| {
            let high_before = !frames[k].high_rate;
            // Both neighbours must be one-mode intervals.
            let clean = |j: usize| straddles.get(j).is_some_and(Option::is_none);
            (clean(k - 1) && clean(k + 1))
                .then(|| split_step(frames, pulses, iru, k, t_switch, high_before))
                .flatten()
        });
        let f = &mut frames[k];
        match split {
            Some((dtheta, dir, var)) => {
                if let Some(g) = f.gyro.as_mut() {
                    g.dtheta_acs_rad = dtheta;
                }
                f.gyro_split_var_rad2 = var;
                f.gyro_split_dir_rad = dir;
                f.rate_switch = RateSwitch::Split;
            }
            None => {
                f.gyro = None;
                f.rate_switch = RateSwitch::Dropped;
            }
        }
    }
}

/// The rate (pulses × weight / s, per selected channel) and centre time of the wholly
/// one-mode frame interval `k`.
fn interval_rate(
    frames: &[FrameObservations],
    pulses: &[Option<[f64; 3]>],
    iru: &IruTable,
    k: usize,
) -> Option<([f64; 3], f64)> {
    let f = frames.get(k)?;
    let prev = frames.get(k.checked_sub(1)?)?;
    let p = pulses.get(k).copied().flatten()?;
    let dt = f.time.seconds() - prev.time.seconds();
    if !(dt > 0.0) || f.gyro.is_none() {
        return None;
    }
    let w = pulse_weight_rad(f.high_rate, iru);
    Some((
        p.map(|x| x * w / dt),
        0.5 * (f.time.seconds() + prev.time.seconds()),
    ))
}

/// Scatter of the split fraction from one switch to the next, as a fraction of its envelope
/// (what the estimated common fraction leaves): measured on `gro-bias-history` at 1-s and
/// 30-s downlink, the slews' main axis had λ = 0.009–0.012 at slew starts and 0.50–0.60 at
/// slew ends (`docs/investigations.md`, "Rate-mode switches in decimated telemetry").
const SPLIT_SCATTER: f64 = 0.04;

/// The angle per selected channel of frame interval `k` whose pulses switch weight at
/// `t_switch` (high rate before it when `high_before`): the step (ACS, rad), its direction per
/// unit split fraction, and its per-axis variance.
///
/// The counts give `N = I₁/w₁ + I₂/w₂` (angles `I₁` before and `I₂` after the switch, pulse
/// weights `w₁`, `w₂`) but not the split, so the angle `A = I₁ + I₂ = w₂ N + I₁ (1 − w₂/w₁)`
/// depends on `I₁`. With the rate monotone through the switch (a slew accelerating out of a
/// hold or braking into one) the rate before the switch lies between the mean rates of the
/// one-mode neighbour intervals before (`r_a`) and after (`r_b`): `I₁ = τ₁ (r_a + λ (r_b −
/// r_a))`, `λ ∈ [0, 1]`. The step is taken at `λ = ½`; where the truth lies depends on the
/// control profile and is nearly the same for every slew start (or end): the calibration
/// estimates `c = λ − ½` per kind (`gyro_split_dir_rad` is the step's change per unit `c`), and
/// what varies from slew to slew (`SPLIT_SCATTER` of the envelope and one pulse) is the
/// step's variance.
#[allow(clippy::too_many_arguments)]
fn split_step(
    frames: &[FrameObservations],
    pulses: &[Option<[f64; 3]>],
    iru: &IruTable,
    k: usize,
    t_switch: f64,
    high_before: bool,
) -> Option<(Vector3<f64>, Vector3<f64>, f64)> {
    let total = pulses.get(k).copied().flatten()?;
    let t_prev = frames.get(k.checked_sub(1)?)?.time.seconds();
    let (ra, _) = interval_rate(frames, pulses, iru, k - 1)?;
    let (rb, _) = interval_rate(frames, pulses, iru, k + 1)?;
    let (w1, w2) = (
        pulse_weight_rad(high_before, iru),
        pulse_weight_rad(!high_before, iru),
    );
    let tau1 = t_switch - t_prev;
    let gain = 1.0 - w2 / w1;
    let mut angle = [0.0; 3];
    let mut per_c = [0.0; 3];
    let mut var: f64 = 0.0;
    for c in 0..3 {
        // I₁ = τ₁ (r_a + λ (r_b − r_a)), λ = ½ + c.
        angle[c] = w2 * total[c] + 0.5 * (ra[c] + rb[c]) * tau1 * gain;
        per_c[c] = (rb[c] - ra[c]) * tau1 * gain;
        let spread = SPLIT_SCATTER * per_c[c].abs() + w1.max(w2);
        var = var.max(spread * spread);
    }
    let config = if frames[k].iru_backup {
        IruConfiguration::Backup
    } else {
        IruConfiguration::Primary
    };
    // Angles as equivalent counts of high-rate pulses (the table's scale factors and
    // asymmetry act per channel the same way).
    let w_high = pulse_weight_rad(true, iru);
    let step = delta_theta_from_pulses(&angle.map(|x| x / w_high), true, config, iru);
    let dir = delta_theta_from_pulses(&per_c.map(|x| x / w_high), true, config, iru);
    Some((step, dir, var))
}

/// Largest age of the ground's own attitude used for identification, s: the gyro bias
/// (≈ 0.6″/s uncorrected) keeps it inside the 0.3° window for about this long.
const OWN_ATTITUDE_MAX_AGE_S: f64 = 900.0;

/// Tolerance of the bootstrap's angle and direction matches, rad: FSS alignment errors of the
/// paper's size (0.2°) plus the FHST's.
const BOOTSTRAP_TOLERANCE_RAD: f64 = 0.4 * RAD_PER_DEG;

/// Oldest tracker star used by the bootstrap, s (gyro drift ≤ 0.1° over it).
const BOOTSTRAP_STAR_AGE_S: f64 = 600.0;

/// A star seen by a tracker: body direction and magnitude.
#[derive(Clone, Copy, Debug)]
struct StarSighting {
    dir_acs: Vector3<f64>,
    magnitude: f64,
}

/// The ground's own attitude estimate `A` where the telemetry has no OBC attitude.
#[derive(Clone, Copy, Debug, Default)]
struct OwnAttitude {
    m_acs_from_eci: Option<Matrix3<f64>>,
    refreshed_s: f64,
    /// Each tracker's last star: body direction carried to the current frame by the gyro,
    /// magnitude, time seen (the trackers rarely see stars together with the Sun in view).
    last_star: [Option<(Vector3<f64>, f64, f64)>; 2],
    /// The Sun's last body direction from an FSS, carried the same way, and its time.
    last_sun: Option<(Vector3<f64>, f64)>,
}

impl OwnAttitude {
    fn propagate(&mut self, g: &GyroStep) {
        let r = rot(&g.dtheta_acs_rad);
        if let Some(a) = self.m_acs_from_eci.as_mut() {
            *a = r * *a;
        }
        for (b, _, _) in self.last_star.iter_mut().flatten() {
            *b = r * *b;
        }
        if let Some((b, _)) = self.last_sun.as_mut() {
            *b = r * *b;
        }
    }

    fn usable(&self, t_s: f64) -> bool {
        self.m_acs_from_eci.is_some() && t_s - self.refreshed_s <= OWN_ATTITUDE_MAX_AGE_S
    }

    fn q(&self) -> Option<Quat> {
        self.m_acs_from_eci.map(|a| Quat::from_dcm(&a))
    }

    /// Remember each tracker's star and the Sun of this frame (for the bootstrap).
    fn note_stars(
        &mut self,
        fhst: &[Option<FhstMeasurement>; 2],
        fss: &[Option<FssMeasurement>; 2],
        t_s: f64,
    ) {
        if let Some(sun) = fss.iter().flatten().next() {
            self.last_sun = Some((sun.dir_acs, t_s));
        }
        for (slot, m) in self.last_star.iter_mut().zip(fhst) {
            if let Some(m) = m {
                *slot = Some((m.dir_acs, m.magnitude, t_s));
            }
        }
    }

    /// From this frame's identified stars: TRIAD from two stars (both trackers), or from one
    /// star and the Sun (the FSS's ≤ 0.2° alignment error only reaches the roll about the
    /// star); one star alone re-points the estimate onto it (two axes) without renewing it.
    fn refresh(
        &mut self,
        stars: &[Option<StarObservation>; 2],
        suns: &[Option<Box<SunObservation>>; 2],
        t_s: f64,
    ) {
        let ids: Vec<(Vector3<f64>, Vector3<f64>)> = stars
            .iter()
            .flatten()
            .filter_map(|s| s.identified.map(|(_, r)| (s.meas.dir_acs, r)))
            .collect();
        let sun = suns
            .iter()
            .flatten()
            .next()
            .map(|s| (s.meas.dir_acs, s.sun_eci));
        let second = ids.get(1).copied().or(sun);
        match (ids.first(), second) {
            (Some(&(b1, r1)), Some((b2, r2))) => {
                if let Some(m) = triad(&b1, &r1, &b2, &r2) {
                    self.m_acs_from_eci = Some(m);
                    self.refreshed_s = t_s;
                }
            }
            (Some(&(b1, r1)), None) => {
                if let Some(a) = self.m_acs_from_eci.as_mut() {
                    // Smallest rotation taking the predicted body vector onto the measured one.
                    let predicted = *a * r1;
                    let axis = predicted.cross(&b1);
                    let angle = axis.norm().atan2(predicted.dot(&b1));
                    if let Some(u) = axis.try_normalize(1e-15) {
                        *a = rot(&(-u * angle)) * *a;
                    }
                }
            }
            _ => {}
        }
    }

    /// Lost-in-space start: the Sun (in an FSS) and one star per tracker. Every catalog star
    /// at the measured Sun–star angle with the measured magnitude gives an attitude (TRIAD
    /// with the Sun); it is kept only if exactly one of them also puts a catalog star of the
    /// right magnitude where the other tracker sees one.
    #[allow(clippy::too_many_arguments)]
    fn bootstrap(
        &mut self,
        sky: &Sky,
        sun_eci: &Vector3<f64>,
        j2000_tt_s: f64,
        observer_bary_km: &Vector3<f64>,
        t_s: f64,
        options: &IdentifyOptions,
    ) -> Option<Quat> {
        let sun_acs = self
            .last_sun
            .filter(|(_, t)| t_s - t <= BOOTSTRAP_STAR_AGE_S)
            .map(|(b, _)| b)?;
        let fresh = |s: Option<(Vector3<f64>, f64, f64)>| {
            s.filter(|(_, _, t)| t_s - t <= BOOTSTRAP_STAR_AGE_S)
        };
        let (Some(m1), Some(m2)) = (fresh(self.last_star[0]), fresh(self.last_star[1])) else {
            return None;
        };
        let (m1, m2) = (
            StarSighting {
                dir_acs: m1.0,
                magnitude: m1.1,
            },
            StarSighting {
                dir_acs: m2.0,
                magnitude: m2.1,
            },
        );
        let angle1 = sun_acs.angle(&m1.dir_acs);
        let mut found: Option<Matrix3<f64>> = None;
        let mut count = 0usize;
        for star in sky.stars() {
            if (star.magnitude - m1.magnitude).abs() > options.magnitude_tolerance {
                continue;
            }
            let r1 = star.astrometric_dir_eci(j2000_tt_s, observer_bary_km);
            if (sun_eci.angle(&r1) - angle1).abs() > BOOTSTRAP_TOLERANCE_RAD {
                continue;
            }
            let Some(a) = triad(&sun_acs, sun_eci, &m1.dir_acs, &r1) else {
                continue;
            };
            let predicted = a.transpose() * m2.dir_acs;
            sky.for_each_in_cone(&predicted, BOOTSTRAP_TOLERANCE_RAD, |_, s2| {
                if (s2.magnitude - m2.magnitude).abs() <= options.magnitude_tolerance
                    && s2
                        .astrometric_dir_eci(j2000_tt_s, observer_bary_km)
                        .angle(&predicted)
                        <= BOOTSTRAP_TOLERANCE_RAD
                {
                    count += 1;
                    found = Some(a);
                }
            });
            if count > 1 {
                return None;
            }
        }
        if count != 1 {
            return None;
        }
        self.m_acs_from_eci = found;
        self.refreshed_s = t_s;
        self.q()
    }
}

/// TRIAD `A` (ACS from ECI) from two body/reference pairs; `None` when nearly parallel.
pub(crate) fn triad(
    b1: &Vector3<f64>,
    r1: &Vector3<f64>,
    b2: &Vector3<f64>,
    r2: &Vector3<f64>,
) -> Option<Matrix3<f64>> {
    let frame = |v1: &Vector3<f64>, v2: &Vector3<f64>| -> Option<Matrix3<f64>> {
        let e1 = v1.try_normalize(1e-12)?;
        let e2 = e1.cross(v2).try_normalize(1e-3)?;
        Some(Matrix3::from_columns(&[e1, e2, e1.cross(&e2)]))
    };
    Some(frame(b1, b2)? * frame(r1, r2)?.transpose())
}

/// Which sensors a fine attitude may use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AttitudeSensors {
    /// FHSTs only (the paper's recommendation for IRU calibration ends).
    FhstOnly,
    /// FHSTs and FSSs.
    FhstAndFss,
    /// FSSs only: a coarse attitude, determined when the Sun moves in the body during the
    /// batch (a slew) or both FSSs see it; the paper's coarse attitude used FSS + TAM + IRU.
    FssOnly,
}

/// Rotations carrying body vectors of each frame of `range` to the frame `center`
/// (`range` must contain `center`): `m[k − range.start] = A(center) A(k)ᵀ`, from the gyro steps
/// corrected by `(I + δM)` and the bias, `A(k) = Rot(φ_k) A(k−1)`; a frame without a step
/// counts as no motion. Shared by the fine attitudes and the FHST gyro batches.
#[must_use]
pub fn body_to_center(
    frames: &[FrameObservations],
    range: core::ops::Range<usize>,
    center: usize,
    bias_acs_rad_per_s: &Vector3<f64>,
    delta_m: &Matrix3<f64>,
) -> Vec<Matrix3<f64>> {
    let (lo, hi) = (range.start, range.end);
    let step = |k: usize| {
        frames[k]
            .gyro
            .map(|g| {
                (Matrix3::identity() + delta_m) * g.dtheta_acs_rad - bias_acs_rad_per_s * g.dt_s
            })
            .unwrap_or_else(Vector3::zeros)
    };
    let mut to_center = vec![Matrix3::identity(); hi - lo];
    // Forward from the centre: A(k) = Rot(φ_k) A(k−1) → b_center = A(c) A(k)ᵀ b_k.
    for k in center + 1..hi {
        to_center[k - lo] = to_center[k - 1 - lo] * rot(&step(k)).transpose();
    }
    for k in (lo..center).rev() {
        to_center[k - lo] = to_center[k + 1 - lo] * rot(&step(k + 1));
    }
    to_center
}

/// [`fine_attitude`] from the FHSTs alone, the gyro increments taken as the flown `G` gives
/// them (no δM): the tracker-only attitudes of the coarse-attitude check, the FHST gyro
/// batches and the TAM samples.
///
/// # Errors
/// As [`fine_attitude`].
pub fn fhst_attitude(
    frames: &[FrameObservations],
    range: core::ops::Range<usize>,
    center: usize,
    bias_acs_rad_per_s: &Vector3<f64>,
) -> Result<AttitudeSolution, AttitudeError> {
    fine_attitude(
        frames,
        range,
        center,
        bias_acs_rad_per_s,
        &Matrix3::zeros(),
        AttitudeSensors::FhstOnly,
    )
}

/// Fine attitude at the centre frame `center` from the frames `range` (indices into
/// `frames`): every vector is carried to the centre time with the gyro increments corrected by
/// `bias_acs_rad_per_s` and `delta_m`, then the batch is solved with QUEST/SVD.
///
/// # Errors
/// [`AttitudeError`] when the batch has fewer than two non-parallel vectors.
pub fn fine_attitude(
    frames: &[FrameObservations],
    range: core::ops::Range<usize>,
    center: usize,
    bias_acs_rad_per_s: &Vector3<f64>,
    delta_m: &Matrix3<f64>,
    sensors: AttitudeSensors,
) -> Result<AttitudeSolution, AttitudeError> {
    let lo = range.start.min(center);
    let hi = range.end.max(center + 1).min(frames.len());
    let to_center = body_to_center(frames, lo..hi, center, bias_acs_rad_per_s, delta_m);
    let mut pairs = Vec::new();
    for k in range.start.max(lo)..range.end.min(hi) {
        let f = &frames[k];
        let m = to_center[k - lo];
        for s in f
            .stars
            .iter()
            .flatten()
            .filter(|_| sensors != AttitudeSensors::FssOnly)
        {
            if let Some((_, dir_eci)) = s.identified {
                pairs.push(VectorPair {
                    dir_acs: m * s.meas.dir_acs,
                    dir_eci,
                    sigma_rad: s.sigma_rad,
                });
            }
        }
        if sensors != AttitudeSensors::FhstOnly {
            for s in f.suns.iter().flatten() {
                pairs.push(VectorPair {
                    dir_acs: m * s.meas.dir_acs,
                    dir_eci: s.sun_eci,
                    sigma_rad: s.sigma_rad,
                });
            }
        }
    }
    solve_attitude(&pairs)
}
