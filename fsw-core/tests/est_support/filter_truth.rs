//! The truth of the MEKF tests (`est_filter.rs`, `est_filter_mismatched.rs`): the primary
//! gyro's pulse counters and the trackers' star tracks.

use super::Rng;
use fsw_core::fhst;
use fsw_core::iru::{pulse_weight_rad, IruConfiguration};
use fsw_core::raw::IruSample;
use fsw_core::tables::IruTable;
use nalgebra::{Matrix3, Vector3};

/// Truth gyro: channel angles and pulse counters of the primary configuration.
pub struct TruthIru {
    pub ginv: Matrix3<f64>,
    pub angle_rad: Vector3<f64>,
    pub pulsed_rad: [f64; 3],
    pub counts: [u16; 6],
}

impl TruthIru {
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
