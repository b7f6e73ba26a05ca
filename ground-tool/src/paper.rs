//! # Reproduction of the CGRO in-flight calibration paper (`ground-tool paper`)
//!
//! Davis, Eudell, Kulp, Lindrose & Harman, "The Results of the In-Flight Attitude Sensor
//! Calibration for the Arthur Holly Compton Gamma Ray Observatory" (CSC/GSFC, ~1992). The
//! published numbers are transcribed in `data/gro_paper.toml` (embedded at build time); this
//! module recomputes what can be recomputed from them and says where the paper is not
//! self-consistent.

use std::collections::BTreeMap;

use nalgebra::Matrix3;
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

/// Published IRU calibration.
#[derive(Clone, Debug, Deserialize, PartialEq)]
pub struct PaperIruCalibration {
    /// ΔM (row-major).
    #[serde(rename = "delta_M")]
    pub delta_m: Rows3,
    /// 1σ of ΔM (row-major).
    #[serde(rename = "delta_M_1sigma")]
    pub delta_m_1sigma: Rows3,
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

#[derive(Clone, Debug, Deserialize, PartialEq)]
struct SensorsFss {
    inherent_error_after_calibration_deg: f64,
}

#[derive(Clone, Debug, Deserialize, PartialEq)]
struct SensorsFhst {
    systematic_error_1sigma_arcsec_max: f64,
}

#[derive(Clone, Debug, Deserialize, PartialEq)]
struct Sensors {
    fss: SensorsFss,
    fhst: SensorsFhst,
}

/// The parts of `gro_paper.toml` this crate uses.
#[derive(Clone, Debug, Deserialize, PartialEq)]
pub struct PaperData {
    sensors: Sensors,
    /// Table 1: prelaunch `M_AS` per sensor.
    pub table1_prelaunch: BTreeMap<String, Rows3>,
    /// Table 2: `M_SS''` per sensor.
    pub table2_misalignment: BTreeMap<String, Rows3>,
    /// Table 3 (FHST rows only are legible): `M_AS''`.
    pub table3_adjusted: BTreeMap<String, Rows3>,
    /// Published rotation vectors and magnitudes (arcsec, ACS).
    pub rotation_vectors_published_arcsec: toml::Table,
    /// Published alignment statements.
    pub alignment_results_published: PaperAlignmentResults,
    /// The four IRU calibration maneuvers.
    pub iru_calibration_intervals: Vec<PaperManeuver>,
    /// Published ΔM and σ.
    pub iru_calibration_published: PaperIruCalibration,
    /// Published high-rate biases (deg/s) with σ per channel.
    pub iru_high_rate_bias_deg_per_s: BTreeMap<String, BTreeMap<String, [f64; 2]>>,
}

impl PaperData {
    /// Parse the embedded transcription.
    ///
    /// # Errors
    /// A TOML error if the embedded file no longer matches this schema.
    pub fn embedded() -> Result<Self, toml::de::Error> {
        toml::from_str(GRO_PAPER_TOML)
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
    pub fn rotation_vector_published_arcsec(&self, id: &str) -> Option<nalgebra::Vector3<f64>> {
        let arr = self.rotation_vectors_published_arcsec.get(id)?.as_array()?;
        let v: Vec<f64> = arr.iter().filter_map(toml::Value::as_float).collect();
        (v.len() == 3).then(|| nalgebra::Vector3::new(v[0], v[1], v[2]))
    }

    /// Published rotation magnitude of a sensor (arcsec).
    #[must_use]
    pub fn rotation_magnitude_published_arcsec(&self, id: &str) -> Option<f64> {
        self.rotation_vectors_published_arcsec
            .get("magnitude")?
            .as_table()?
            .get(id)?
            .as_float()
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
