//! # The wheel frames on the ground: wheel momentum, torquer-bar dipoles and a cross-check
//!
//! Why: the wheel frames (APID 0x014, `docs/icd.md` §3.6, format version 4) are the only
//! downlink of how close the reaction wheels came to their momentum limit and of what the
//! magnetic torquer bars actually carried. An analyst asks three things of them: did a wheel
//! approach its limit (the largest momentum per wheel, with Table 6's rotor inertia), did a
//! tachometer drop out (the valid fraction per wheel: the OBC then counted its commands,
//! event 0x0A03), and do the two independent reports of the bars agree: the bar current
//! monitors of the wheel frame and the "torquer bars on" bit of each TAM sample of the
//! magnetics frame (§3.5). They describe the same interval (the one that ended at the sample),
//! so a frame where a monitor reads current while every TAM bit says "off" — or the reverse —
//! is a telemetry fault (a stuck status bit, a dead monitor) that would otherwise pass
//! silently: the ground's TAM calibration keeps or drops samples by that bit.
//!
//! The summary goes into `calibrate`'s `report.json` (`wheels`); a file without wheel frames
//! gives `None` (nothing to say, and the report says why).

use crate::tp::Telemetry;
use fsw_core::raw::{
    TAM_FLAG_TORQUERS_ON, TAM_FLAG_VALID, TORQUER_AM2_PER_COUNT, TORQUER_MONITORS, WHEELS,
    WHEEL_RPM_PER_COUNT,
};
use fsw_core::tables::MagneticsTable;
use serde::Serialize;

/// A bar monitor at or above this dipole counts as "on" (A·m²): one count is the monitor's
/// resolution; a bar commanded off reads 0.
pub const BAR_ON_THRESHOLD_AM2: f64 = 1.0;

/// What the wheel frames of a run say (module doc).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct WheelSummary {
    /// Wheel frames read.
    pub frames: usize,
    /// Per wheel, the fraction of frames whose tachometer word was valid.
    pub tachometer_valid_fraction: [f64; WHEELS],
    /// Per wheel, the largest |speed| read, rpm (valid words only).
    pub largest_speed_rpm: [f64; WHEELS],
    /// Per wheel, the largest |momentum|, N·m·s: the speed times Table 6's rotor inertia.
    pub largest_momentum_nms: [f64; WHEELS],
    /// The rotor inertia used, kg·m² (Table 6 field 25).
    pub spin_inertia_kg_m2: f64,
    /// Which Table 6 the inertia came from (the flown one, or the boot one and why).
    pub spin_inertia_source: String,
    /// Per bar (ACS x, y, z), the RMS of the monitored dipole, A·m².
    pub bar_dipole_rms_am2: [f64; TORQUER_MONITORS],
    /// Per bar, the largest |monitored dipole|, A·m².
    pub bar_dipole_max_am2: [f64; TORQUER_MONITORS],
    /// Frames with a valid TAM sample and valid bar monitors at the same time code, compared.
    pub frames_compared_with_tam_flags: usize,
    /// Of those, frames where a monitor reads a dipole but no TAM sample has the bars-on bit.
    pub monitor_on_flag_off: usize,
    /// Of those, frames where a TAM sample has the bars-on bit but every monitor reads zero.
    pub flag_on_monitor_off: usize,
}

impl WheelSummary {
    /// Whether the bar monitors and the TAM bars-on bits disagree on any frame.
    #[must_use]
    pub const fn flags_disagree(&self) -> bool {
        self.monitor_on_flag_off > 0 || self.flag_on_monitor_off > 0
    }
}

/// Momentum of one rpm of a rotor of `inertia_kg_m2`, N·m·s.
fn nms_per_rpm(inertia_kg_m2: f64) -> f64 {
    inertia_kg_m2 * std::f64::consts::TAU / 60.0
}

/// The summary of `tm`'s wheel frames with the flown Table 6 `table` (its rotor inertia;
/// `table_source` says which table that is); `None` when the file has no wheel frames.
#[must_use]
pub fn summarize(
    tm: &Telemetry,
    table: &MagneticsTable,
    table_source: &str,
) -> Option<WheelSummary> {
    let frames = tm.wheels.len();
    if frames == 0 {
        return None;
    }
    let mut valid = [0usize; WHEELS];
    let mut largest_rpm = [0.0_f64; WHEELS];
    let mut sq = [0.0_f64; TORQUER_MONITORS];
    let mut max_dipole = [0.0_f64; TORQUER_MONITORS];
    let mut monitored = 0usize;
    for w in &tm.wheels {
        let s = &w.wheels;
        for (i, counts) in s.speed_counts.iter().enumerate() {
            if s.speed_valid & (1 << i) != 0 {
                valid[i] += 1;
                largest_rpm[i] =
                    largest_rpm[i].max((f64::from(*counts) * WHEEL_RPM_PER_COUNT).abs());
            }
        }
        if s.dipole_valid != 0 {
            monitored += 1;
        }
        for (k, counts) in s.dipole_counts.iter().enumerate() {
            if s.dipole_valid & (1 << k) != 0 {
                let m = f64::from(*counts) * TORQUER_AM2_PER_COUNT;
                sq[k] += m * m;
                max_dipole[k] = max_dipole[k].max(m.abs());
            }
        }
    }
    let (compared, monitor_on_flag_off, flag_on_monitor_off) = compare_with_tam_flags(tm);
    #[allow(clippy::cast_precision_loss)]
    let per_frame = |n: usize| n as f64 / frames as f64;
    #[allow(clippy::cast_precision_loss)]
    let rms = sq.map(|s| (s / monitored.max(1) as f64).sqrt());
    Some(WheelSummary {
        frames,
        tachometer_valid_fraction: valid.map(per_frame),
        largest_speed_rpm: largest_rpm,
        largest_momentum_nms: largest_rpm.map(|r| r * nms_per_rpm(table.wheel_spin_inertia_kg_m2)),
        spin_inertia_kg_m2: table.wheel_spin_inertia_kg_m2,
        spin_inertia_source: table_source.to_owned(),
        bar_dipole_rms_am2: rms,
        bar_dipole_max_am2: max_dipole,
        frames_compared_with_tam_flags: compared,
        monitor_on_flag_off,
        flag_on_monitor_off,
    })
}

/// The bar monitors against the TAM bars-on bits at the same time codes: (frames compared,
/// monitor on with every bit off, a bit on with every monitor zero). Both lists are sorted by
/// time (`tp::decode`), so one merge pass pairs them.
fn compare_with_tam_flags(tm: &Telemetry) -> (usize, usize, usize) {
    let (mut compared, mut monitor_only, mut flag_only) = (0, 0, 0);
    let mut mags = tm.magnetics.iter().peekable();
    for w in &tm.wheels {
        if w.wheels.dipole_valid == 0 {
            continue;
        }
        while mags.peek().is_some_and(|m| m.time < w.time) {
            mags.next();
        }
        let Some(m) = mags.peek().filter(|m| m.time == w.time) else {
            continue;
        };
        let mut valid_tams = m
            .tam
            .iter()
            .filter(|t| t.flags & TAM_FLAG_VALID != 0)
            .peekable();
        if valid_tams.peek().is_none() {
            continue;
        }
        compared += 1;
        let flag_on = valid_tams.any(|t| t.flags & TAM_FLAG_TORQUERS_ON != 0);
        let monitor_on = w.wheels.dipole_counts.iter().enumerate().any(|(k, c)| {
            w.wheels.dipole_valid & (1 << k) != 0
                && (f64::from(*c) * TORQUER_AM2_PER_COUNT).abs() >= BAR_ON_THRESHOLD_AM2
        });
        match (monitor_on, flag_on) {
            (true, false) => monitor_only += 1,
            (false, true) => flag_only += 1,
            _ => {}
        }
    }
    (compared, monitor_only, flag_only)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::float_cmp)]
    use super::*;
    use fsw_core::raw::{TamSample, TimeTag, WheelSample};
    use fsw_core::telemetry::{MagneticsFrame, WheelFrame};

    fn at(s: u32) -> TimeTag {
        TimeTag {
            coarse_s: 1_049_000_000 + s,
            fine: 0,
        }
    }

    fn wheel(s: u32, speed: i16, dipole: i16, valid: u8) -> WheelFrame {
        WheelFrame {
            time: at(s),
            wheels: WheelSample {
                speed_counts: [speed, -speed, 0, 7],
                speed_valid: valid,
                dipole_counts: [dipole, 0, 0],
                dipole_valid: 0x07,
            },
        }
    }

    fn mag(s: u32, bars_on: bool) -> MagneticsFrame {
        let flags = TAM_FLAG_VALID | if bars_on { TAM_FLAG_TORQUERS_ON } else { 0 };
        MagneticsFrame {
            time: at(s),
            tam: [TamSample {
                field_counts: [100, 200, 300],
                flags,
            }; 2],
            css: Default::default(),
        }
    }

    #[test]
    fn speeds_momenta_dipoles_and_the_flag_cross_check() {
        let table = MagneticsTable::boot();
        let mut tm = Telemetry::default();
        assert_eq!(
            summarize(&tm, &table, "the boot Table 6"),
            None,
            "no wheel frames, nothing to say"
        );
        tm.wheels = vec![
            wheel(0, 10_000, 0, 0x0F),
            wheel(1, -20_000, 3_000, 0x0F),
            wheel(2, 5, -4_000, 0x07),
            wheel(3, 0, 0, 0x0F),
        ];
        // Frame 1: bars on and flagged; frame 2: bars on, flag off (a fault); frame 3: bars
        // off, flag on (a fault); frame 0: off and off.
        tm.magnetics = vec![mag(0, false), mag(1, true), mag(2, false), mag(3, true)];
        let s = summarize(&tm, &table, "the boot Table 6").unwrap();
        assert_eq!(s.frames, 4);
        assert_eq!(s.tachometer_valid_fraction, [1.0, 1.0, 1.0, 0.75]);
        assert_eq!(s.largest_speed_rpm[0], 2_000.0);
        let h = 2_000.0 * table.wheel_spin_inertia_kg_m2 * std::f64::consts::TAU / 60.0;
        assert!((s.largest_momentum_nms[0] - h).abs() < 1e-9, "{s:?}");
        assert_eq!(s.bar_dipole_max_am2, [4_000.0, 0.0, 0.0]);
        assert!((s.bar_dipole_rms_am2[0] - (25.0e6_f64 / 4.0).sqrt()).abs() < 1e-6);
        assert_eq!(s.frames_compared_with_tam_flags, 4);
        assert_eq!((s.monitor_on_flag_off, s.flag_on_monitor_off), (1, 1));
        assert!(s.flags_disagree());
    }
}
