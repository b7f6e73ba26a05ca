//! The truth of the MEKF tests (`est_filter.rs`, `est_filter_mismatched.rs`): the primary
//! gyro's pulse counters and the trackers' star tracks.

use super::Rng;
use fsw_core::attitude::Quat;
use fsw_core::fhst::{self, FHST_RAD_PER_COUNT};
use fsw_core::iru::{pulse_weight_rad, IruConfiguration, IruIntegrator};
use fsw_core::mekf::Mekf;
use fsw_core::raw::{
    FhstSample, IruSample, FHST_FLAG_NEW_STAR, FHST_FLAG_TRACKING, FHST_FLAG_VALID,
};
use fsw_core::tables::types::{matrix_from_rows, Mat3Rows};
use fsw_core::tables::{AlignmentTable, FilterTable, IruTable};
use nalgebra::{Matrix3, Vector3};

/// Truth gyro: channel angles and pulse counters of the primary configuration.
pub struct TruthIru {
    pub ginv: Matrix3<f64>,
    pub angle_rad: Vector3<f64>,
    pub pulsed_rad: [f64; 3],
    pub counts: [u16; 6],
}

impl TruthIru {
    /// The primary configuration's gyro at channel angles `angle_rad`, nothing pulsed yet, the
    /// counters at arbitrary start values.
    pub fn primary(table: &IruTable, angle_rad: Vector3<f64>) -> Self {
        Self {
            ginv: IruConfiguration::Primary.g(table).try_inverse().unwrap(),
            angle_rad,
            pulsed_rad: [0.0; 3],
            counts: [100, 40_000, 65_000, 7, 123, 30_000],
        }
    }

    /// Counters at the end of an interval spent in the given mode: a pulse per `w` of angle
    /// not yet pulsed (the remainder carries over a mode switch).
    pub fn sample(&mut self, high_rate: bool, table: &IruTable) -> IruSample {
        let w = pulse_weight_rad(high_rate, table);
        let ch = IruConfiguration::Primary.channels();
        for (axis, &c) in ch.iter().enumerate() {
            let n = ((self.angle_rad[axis] - self.pulsed_rad[axis]) / w).floor();
            self.pulsed_rad[axis] += n * w;
            // The register is 16 bits: it wraps.
            self.counts[c] = self.counts[c].wrapping_add(n as i64 as u16);
        }
        // Unused backup channels count too (not stuck).
        for c in [0usize, 3, 5] {
            self.counts[c] = self.counts[c].wrapping_add(7);
        }
        IruSample {
            counts: self.counts,
            channel_failed: 0,
            high_rate,
        }
    }
}

pub struct Track {
    pub r_eci: Vector3<f64>,
    pub magnitude: f64,
    pub ends_at_s: u32,
    pub new: bool,
}

/// A star tracked for 1–5 min at a random place of the tracker's field.
pub fn new_track(rng: &mut Rng, a_true: &Matrix3<f64>, m: &Matrix3<f64>, now: u32) -> Track {
    let lim = 3.5_f64.to_radians();
    let s = fhst::dir_from_hv(rng.range(-lim, lim), rng.range(-lim, lim));
    Track {
        r_eci: a_true.transpose() * (m * s),
        magnitude: rng.range(2.0, 5.7),
        ends_at_s: now + 60 + (rng.next_u64() % 240) as u32,
        new: true,
    }
}

/// The prelaunch alignments of FHST1 and FHST2: the table's rows and their matrices.
pub fn prelaunch_trackers() -> ([Mat3Rows; 2], [Matrix3<f64>; 2]) {
    let al = AlignmentTable::prelaunch();
    let rows = [al.m_acs_from_fhst1, al.m_acs_from_fhst2];
    (rows, rows.map(|r| matrix_from_rows(&r)))
}

/// The truth's limit cycle at time `ts` (rad/s), added to its slow body rotation.
pub fn wobble(ts: f64) -> Vector3<f64> {
    Vector3::new(
        (ts / 97.0).sin(),
        (ts / 151.0 + 1.0).sin(),
        (ts / 263.0 + 2.0).cos(),
    ) * 1e-5
}

/// The filter initialised at the truth rotated by `−err0` (rad, about the axis of `err0`), and
/// the IRU integrator primed with the gyro's first counters (low rate).
pub fn start(
    q_true: &Quat,
    err0: &Vector3<f64>,
    gyro: &mut TruthIru,
    filter_table: &FilterTable,
    iru_table: &IruTable,
) -> (Mekf, IruIntegrator) {
    let mut filter = Mekf::new();
    filter
        .initialize(
            &Quat::from_rotation_vector(&(-err0)).compose(q_true),
            filter_table,
        )
        .unwrap();
    let mut iru = IruIntegrator::new();
    iru.process(
        &gyro.sample(false, iru_table),
        IruConfiguration::Primary,
        iru_table,
    );
    (filter, iru)
}

/// The OBC's propagation over one cycle: the IRU integrator on the gyro's counters (rate mode
/// `high_rate`), then the filter.
pub fn propagate(
    filter: &mut Mekf,
    iru: &mut IruIntegrator,
    gyro: &mut TruthIru,
    high_rate: bool,
    filter_table: &FilterTable,
    iru_table: &IruTable,
) {
    let out = iru.process(
        &gyro.sample(high_rate, iru_table),
        IruConfiguration::Primary,
        iru_table,
    );
    let d = out.delta_theta_acs_rad.expect("healthy IRU");
    filter.propagate(&d, 1.0, filter_table).unwrap();
}

/// Tangent-plane angles of the sensor-frame direction `s` when inside the tracker's ±3.8°
/// field; `None` = the star is lost.
pub fn in_field(s: &Vector3<f64>) -> Option<(f64, f64)> {
    let lim = 3.8_f64.to_radians();
    fhst::hv_from_dir(s).filter(|(h, v)| h.abs() < lim && v.abs() < lim)
}

/// The tracker's sample of the star at `(h, v)`: Gaussian noise σ (rad) per axis, rounded to
/// counts, flagged as a new star on the track's first sample.
pub fn fhst_sample(rng: &mut Rng, track: &mut Track, h: f64, v: f64, sigma: f64) -> FhstSample {
    let nh = ((h + sigma * rng.gauss()) / FHST_RAD_PER_COUNT).round();
    let nv = ((v + sigma * rng.gauss()) / FHST_RAD_PER_COUNT).round();
    let mut flags = FHST_FLAG_VALID | FHST_FLAG_TRACKING;
    if track.new {
        flags |= FHST_FLAG_NEW_STAR;
        track.new = false;
    }
    FhstSample {
        h_counts: nh as i16,
        v_counts: nv as i16,
        magnitude_centimag: (track.magnitude * 100.0).round() as i16,
        flags,
    }
}

/// NEES of the attitude error `e` (rad) against the filter's attitude covariance (3 dof).
pub fn attitude_nees(filter: &Mekf, e: &Vector3<f64>) -> f64 {
    let p11 = filter.covariance.fixed_view::<3, 3>(0, 0).into_owned();
    (e.transpose() * p11.try_inverse().unwrap() * e).x
}
