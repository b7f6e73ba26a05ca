//! # The maneuvers found in the telemetry, as the calibration report gives them
//!
//! Filled by the calibration (`super::calibrate`: the maneuvers and their coarse attitudes)
//! and by the IRUCAL stage (`super::gyro_chain`: used or why not).

use serde::Serialize;

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
