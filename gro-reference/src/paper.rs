//! # The GRO paper's published facts (`data/gro_paper.toml`), parsed once
//!
//! Why here: the simulator's truth models (`sim-harness::paper`) and the ground's
//! reproduction of the paper (`ground-tool paper`, the synthetic sensors, the paper's
//! alignment table) read the same transcription; one typed definition means a key renamed in
//! the file fails the same way on both sides, and neither walks the TOML by hand.
//!
//! The file is embedded at compile time so that no run depends on the working directory or
//! a different copy. Matrices are row-major (`m[row][col]`); an alignment `M_AS` maps sensor
//! to ACS (the file's header). Only the sections a crate uses are typed: serde ignores the
//! rest (mission, requirements, bias history).

use std::collections::BTreeMap;

use nalgebra::{Matrix3, Vector3};
use serde::Deserialize;

/// The transcription, embedded at build time.
pub const GRO_PAPER_TOML: &str = include_str!("../../data/gro_paper.toml");

/// Row-major 3×3 as stored in the TOML.
pub type Rows3 = [[f64; 3]; 3];

/// Convert row-major rows to a matrix.
#[must_use]
pub fn mat(rows: &Rows3) -> Matrix3<f64> {
    Matrix3::from_fn(|r, c| rows[r][c])
}

/// One IRU calibration maneuver of the paper (§5, Table "IRU calibration maneuvers").
#[derive(Clone, Debug, Deserialize, PartialEq)]
pub struct PaperManeuver {
    /// Rotation axis (`X`, `Y`, `Z`, body).
    pub axis: String,
    /// Rotation angle (deg, signed).
    pub angle_deg: f64,
    /// Sensors used for the initial attitude.
    pub initial_attitude_sensors: Vec<String>,
    /// Sensors used for the final attitude.
    pub final_attitude_sensors: Vec<String>,
    /// Interval duration (min).
    pub duration_min: f64,
}

/// Published IRU calibration (`[iru_calibration_published]`).
#[derive(Clone, Debug, Deserialize, PartialEq)]
pub struct PaperIruCalibration {
    /// ΔM of the primary triad (row-major).
    #[serde(rename = "delta_M")]
    pub delta_m: Rows3,
    /// 1σ of ΔM (row-major).
    #[serde(rename = "delta_M_1sigma")]
    pub delta_m_1sigma: Rows3,
}

/// The prelaunch IRU table (`[iru_prelaunch]`).
#[derive(Clone, Debug, Deserialize, PartialEq)]
pub struct PaperIruPrelaunch {
    /// Alignment/scale matrix `G` (primary triad X2, Y1, Z1 → ACS), row-major.
    #[serde(rename = "G")]
    pub g: Rows3,
}

/// Published alignment results (text of §4).
#[derive(Clone, Debug, Deserialize, PartialEq)]
pub struct PaperAlignmentResults {
    /// Reduction of the angle between the FHST boresights (arcsec).
    pub fhst_boresight_separation_reduction_arcsec: f64,
    /// FSS1 misalignment (deg).
    pub fss1_misalignment_deg: f64,
    /// FSS2 misalignment (deg).
    pub fss2_misalignment_deg: f64,
}

/// Published rotation vectors prelaunch → adjusted (`[rotation_vectors_published_arcsec]`).
#[derive(Clone, Debug, Deserialize, PartialEq)]
pub struct PaperRotationVectors {
    /// The printed vector per sensor (ACS, arcsec), keyed FHST1, FHST2, FSS1, FSS2.
    #[serde(flatten)]
    pub vectors: BTreeMap<String, [f64; 3]>,
    /// The printed magnitude per sensor (arcsec).
    pub magnitude: BTreeMap<String, f64>,
}

/// `[sensors.fss]`: the part used.
#[derive(Clone, Debug, Deserialize, PartialEq)]
pub struct PaperFss {
    /// FSS error left after the alignment calibration (deg), §4.3.
    pub inherent_error_after_calibration_deg: f64,
}

/// `[sensors.fhst]`: the part used.
#[derive(Clone, Debug, Deserialize, PartialEq)]
pub struct PaperFhst {
    /// Largest systematic error (arcsec, 1σ).
    pub systematic_error_1sigma_arcsec_max: f64,
}

/// `[sensors.tam]`.
#[derive(Clone, Debug, Deserialize, PartialEq)]
pub struct PaperTam {
    /// The primary TAM's bias FDF determined in flight (mG, sensor axes; not uplinked).
    #[serde(rename = "primary_bias_mG")]
    pub primary_bias_milligauss: [f64; 3],
}

/// `[sensors]`: the parts used.
#[derive(Clone, Debug, Deserialize, PartialEq)]
pub struct PaperSensors {
    /// Fine Sun sensors.
    pub fss: PaperFss,
    /// Fixed-head star trackers.
    pub fhst: PaperFhst,
    /// Magnetometers.
    pub tam: PaperTam,
}

/// The parts of `gro_paper.toml` the workspace uses.
#[derive(Clone, Debug, Deserialize, PartialEq)]
pub struct PaperData {
    /// Sensor facts.
    pub sensors: PaperSensors,
    /// Table 1: prelaunch `M_AS` per sensor.
    pub table1_prelaunch: BTreeMap<String, Rows3>,
    /// Table 2: `M_SS''` per sensor.
    pub table2_misalignment: BTreeMap<String, Rows3>,
    /// Table 3 (FHST rows only are legible): `M_AS''`.
    pub table3_adjusted: BTreeMap<String, Rows3>,
    /// Published rotation vectors and magnitudes (arcsec, ACS).
    pub rotation_vectors_published_arcsec: PaperRotationVectors,
    /// Published alignment statements.
    pub alignment_results_published: PaperAlignmentResults,
    /// The prelaunch IRU table.
    pub iru_prelaunch: PaperIruPrelaunch,
    /// The four IRU calibration maneuvers.
    pub iru_calibration_intervals: Vec<PaperManeuver>,
    /// Published ΔM and σ.
    pub iru_calibration_published: PaperIruCalibration,
    /// Published high-rate biases (deg/s) with σ per channel, under `primary` and `backup`.
    pub iru_high_rate_bias_deg_per_s: BTreeMap<String, BTreeMap<String, [f64; 2]>>,
}

impl PaperData {
    /// Parse the embedded transcription.
    ///
    /// # Errors
    /// A TOML error if the embedded file no longer matches this schema.
    pub fn embedded() -> Result<Self, toml::de::Error> {
        Self::parse(GRO_PAPER_TOML)
    }

    /// Parse gro_paper.toml text.
    ///
    /// # Errors
    /// A TOML error naming the missing or malformed key.
    pub fn parse(text: &str) -> Result<Self, toml::de::Error> {
        toml::from_str(text)
    }

    /// Table 1 alignment of a sensor.
    #[must_use]
    pub fn prelaunch(&self, id: &str) -> Option<Matrix3<f64>> {
        self.table1_prelaunch.get(id).map(mat)
    }

    /// Table 2 matrix of a sensor.
    #[must_use]
    pub fn misalignment(&self, id: &str) -> Option<Matrix3<f64>> {
        self.table2_misalignment.get(id).map(mat)
    }

    /// Published Table 3 (FHSTs only).
    #[must_use]
    pub fn adjusted_published(&self, id: &str) -> Option<Matrix3<f64>> {
        self.table3_adjusted.get(id).map(mat)
    }

    /// Published rotation vector of a sensor (arcsec, ACS).
    #[must_use]
    pub fn rotation_vector_published_arcsec(&self, id: &str) -> Option<Vector3<f64>> {
        self.rotation_vectors_published_arcsec
            .vectors
            .get(id)
            .map(|v| Vector3::from(*v))
    }

    /// Published rotation magnitude of a sensor (arcsec).
    #[must_use]
    pub fn rotation_magnitude_published_arcsec(&self, id: &str) -> Option<f64> {
        self.rotation_vectors_published_arcsec
            .magnitude
            .get(id)
            .copied()
    }

    /// Published high-rate bias of an IRU channel and its 1σ (deg/s); `triad` is `primary`
    /// or `backup`.
    #[must_use]
    pub fn high_rate_bias_deg_per_s(&self, triad: &str, channel: &str) -> Option<[f64; 2]> {
        self.iru_high_rate_bias_deg_per_s
            .get(triad)
            .and_then(|m| m.get(channel))
            .copied()
    }

    /// FSS inherent error after calibration (deg), paper §4.3.
    #[must_use]
    pub fn fss_inherent_error_deg(&self) -> f64 {
        self.sensors.fss.inherent_error_after_calibration_deg
    }

    /// FHST maximum systematic error (arcsec, 1σ).
    #[must_use]
    pub fn fhst_systematic_error_arcsec(&self) -> f64 {
        self.sensors.fhst.systematic_error_1sigma_arcsec_max
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// The embedded file parses, with every table of the four sensors and the published
    /// figures the two sides test against.
    #[test]
    fn embedded_parses_with_every_sensor() {
        let p = PaperData::embedded().unwrap();
        for id in ["FHST1", "FHST2", "FSS1", "FSS2"] {
            assert!(p.prelaunch(id).is_some(), "{id}");
            assert!(p.misalignment(id).is_some(), "{id}");
            assert!(p.rotation_vector_published_arcsec(id).is_some(), "{id}");
            assert!(p.rotation_magnitude_published_arcsec(id).is_some(), "{id}");
        }
        assert!(p.adjusted_published("FSS1").is_none());
        assert_eq!(p.sensors.tam.primary_bias_milligauss, [0.0, 0.0, -4.0]);
        assert_eq!(
            p.high_rate_bias_deg_per_s("primary", "X2"),
            Some([1.66e-4, 0.10e-4])
        );
        assert_eq!(p.iru_calibration_intervals.len(), 4);
        assert!((mat(&p.iru_prelaunch.g)[(0, 1)] - 0.00108).abs() < 1e-12);
    }
}
