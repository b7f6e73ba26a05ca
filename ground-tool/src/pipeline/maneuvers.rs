//! # The maneuvers found in the telemetry, as the calibration report gives them
//!
//! Filled by the calibration (`super::calibrate`: the maneuvers and their coarse attitudes)
//! and by the IRUCAL stage (`super::gyro_chain`: used or why not).

use serde::Serialize;

/// The runs of high-rate frames (first index, last index), from each frame's high-rate flag
/// in order: the maneuvers, when the user gives none, and diagnose's slews. `with_open_end`:
/// also a run the frames end in (a maneuver whose end hold was not downlinked).
#[must_use]
pub fn high_rate_runs(
    high_rate: impl IntoIterator<Item = bool>,
    with_open_end: bool,
) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut start: Option<usize> = None;
    let mut frames = 0;
    for (i, high) in high_rate.into_iter().enumerate() {
        frames = i + 1;
        match (high, start) {
            (true, None) => start = Some(i),
            (false, Some(s)) => {
                out.push((s, i - 1));
                start = None;
            }
            _ => {}
        }
    }
    if let (Some(s), true) = (start, with_open_end) {
        out.push((s, frames - 1));
    }
    out
}

/// A maneuver found in the telemetry.
#[derive(Clone, Debug, Serialize)]
pub struct ManeuverReport {
    /// Start, s since the first frame.
    pub start_s: f64,
    /// End, s since the first frame.
    pub end_s: f64,
    /// Rotation angle from the gyro, deg.
    pub angle_deg: f64,
    /// Used for IRUCAL (a gyro link joins attitude fixes before and after it).
    pub used: bool,
    /// Why not, when not used.
    pub why_not_used: Option<String>,
    /// Coarse attitude at the maneuver end from the FSSs alone (the Sun moving in the body
    /// during the slew, tied by the gyro), when determined.
    pub coarse_attitude: Option<CoarseAttitude>,
}

/// A coarse (FSS + IRU) attitude, checked against the FHST fine attitude at the same time.
#[derive(Clone, Debug, Serialize)]
pub struct CoarseAttitude {
    /// Time, s since the first frame.
    pub t_s: f64,
    /// `A` as a scalar-last quaternion.
    pub q_acs_from_eci: [f64; 4],
    /// 1σ per ACS axis from the batch covariance, deg (FSS inherent error not included).
    pub sigma_deg: [f64; 3],
    /// Angle to the FHST-only fine attitude at the same time, deg (paper's coarse
    /// requirement: 2° 3σ per axis), when the trackers give one.
    pub difference_to_fine_deg: Option<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs of high-rate flags, with and without the run the frames end in.
    #[test]
    fn high_rate_runs_close_at_the_first_low_rate_frame() {
        let flags = [false, true, true, false, true, false, false, true, true];
        assert_eq!(high_rate_runs(flags, false), vec![(1, 2), (4, 4)]);
        assert_eq!(high_rate_runs(flags, true), vec![(1, 2), (4, 4), (7, 8)]);
        assert!(high_rate_runs([false; 3], true).is_empty());
    }
}
