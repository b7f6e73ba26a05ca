//! # Scenario files (TOML)
//!
//! One file describes a run: epoch, duration, step, initial state, every truth and sensor
//! error parameter, and a timeline of ground commands. Every table uses
//! `deny_unknown_fields`, so a misspelt key is an error that names it (toml reports the key,
//! the line and the expected names); every parameter has a default (the GRO values or our
//! documented choices), so `name` and `duration_s` are all a minimal file needs.
//!
//! ```toml
//! name = "inertial hold"
//! duration_s = 3600
//! [initial]
//! q_acs_from_eci = [0.0, 0.0, 0.0, 1.0]
//! [orbit]
//! raan_deg = 120.0
//! [fhst1.effects]
//! radial_distortion_arcsec_at_4deg = 15.0
//! [[commands]]
//! at_s = 0
//! kind = "filter_initialize"
//! ```

use std::path::Path;

use anyhow::{bail, Context};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::sensors::fhst::FhstParams;
use crate::sensors::fss::FssParams;
use crate::sensors::iru::IruParams;
use crate::sensors::thermal::ThermalParams;
use crate::truth::dynamics::DynamicsParams;
use crate::truth::orbit::OrbitParams;
use crate::truth::sky::SkyParams;
use fsw_core::attitude::Quat;

fn default_seed() -> u64 {
    1
}
fn default_epoch() -> String {
    "1991-04-07T22:37:00Z".to_owned()
}
fn default_step() -> f64 {
    1.0
}
fn default_sun_refresh() -> f64 {
    600.0
}
fn default_ephemeris_period() -> f64 {
    60.0
}

/// Initial true state.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct InitialState {
    /// True attitude `q_acs_from_eci`, scalar last `[x, y, z, w]` (normalised on load).
    pub q_acs_from_eci: [f64; 4],
    /// True body rate (deg/s, ACS).
    pub rate_acs_deg_per_s: [f64; 3],
}

impl Default for InitialState {
    fn default() -> Self {
        Self {
            q_acs_from_eci: [0.0, 0.0, 0.0, 1.0],
            rate_acs_deg_per_s: [0.0; 3],
        }
    }
}

impl InitialState {
    /// The attitude as a quaternion.
    #[must_use]
    pub fn quat(&self) -> Quat {
        let [x, y, z, w] = self.q_acs_from_eci;
        Quat::new(x, y, z, w).normalized()
    }

    /// The rate in rad/s.
    #[must_use]
    pub fn rate_acs_rad_per_s(&self) -> Vector3<f64> {
        Vector3::from(self.rate_acs_deg_per_s) * fsw_core::units::RAD_PER_DEG
    }
}

/// Temperatures of the five raw-frame slots.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThermalSet {
    /// FHST1 node.
    #[serde(default = "thermal_0")]
    pub fhst1: ThermalParams,
    /// FHST2 node.
    #[serde(default = "thermal_1")]
    pub fhst2: ThermalParams,
    /// FSS1 node.
    #[serde(default = "thermal_2")]
    pub fss1: ThermalParams,
    /// FSS2 node.
    #[serde(default = "thermal_3")]
    pub fss2: ThermalParams,
    /// IRU baseplate node.
    #[serde(default = "thermal_4")]
    pub iru: ThermalParams,
}
fn thermal_0() -> ThermalParams {
    ThermalParams::default_for_slot(0)
}
fn thermal_1() -> ThermalParams {
    ThermalParams::default_for_slot(1)
}
fn thermal_2() -> ThermalParams {
    ThermalParams::default_for_slot(2)
}
fn thermal_3() -> ThermalParams {
    ThermalParams::default_for_slot(3)
}
fn thermal_4() -> ThermalParams {
    ThermalParams::default_for_slot(4)
}

impl Default for ThermalSet {
    fn default() -> Self {
        Self {
            fhst1: thermal_0(),
            fhst2: thermal_1(),
            fss1: thermal_2(),
            fss2: thermal_3(),
            iru: thermal_4(),
        }
    }
}

impl ThermalSet {
    /// In raw-frame slot order.
    #[must_use]
    pub fn slots(&self) -> [ThermalParams; 5] {
        [self.fhst1, self.fhst2, self.fss1, self.fss2, self.iru]
    }
}

/// Kinds of timeline command.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CommandKind {
    /// Slew to `q_acs_from_eci` and hold.
    SlewTo,
    /// Hold the current estimate.
    Hold,
    /// Select the IRU triad `config` ("primary" or "backup").
    SelectIruConfig,
    /// Initialise the filter at `q_acs_from_eci`, or at the true attitude if absent.
    FilterInitialize,
    /// Reopen the filter covariance.
    FilterReset,
}

/// One timeline entry.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimedCommand {
    /// When to send it (s from the epoch; sent with the first cycle at or after).
    pub at_s: f64,
    /// What.
    pub kind: CommandKind,
    /// Target or initial attitude (`slew_to`, `filter_initialize`), `[x, y, z, w]`.
    #[serde(default)]
    pub q_acs_from_eci: Option<[f64; 4]>,
    /// IRU configuration (`select_iru_config`): "primary" or "backup".
    #[serde(default)]
    pub config: Option<String>,
}

/// A whole scenario.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Short name (goes into metadata).
    pub name: String,
    /// Free text.
    #[serde(default)]
    pub description: String,
    /// Seed of every random stream.
    #[serde(default = "default_seed")]
    pub seed: u64,
    /// Start epoch, UTC (ISO 8601). Default: GRO release, 1991-04-07T22:37:00Z.
    #[serde(default = "default_epoch")]
    pub epoch_utc: String,
    /// Run length (s).
    pub duration_s: f64,
    /// Cycle period (s).
    #[serde(default = "default_step")]
    pub step_s: f64,
    /// Refresh interval of the cached Sun ephemeris (s).
    #[serde(default = "default_sun_refresh")]
    pub sun_refresh_s: f64,
    /// Period of the definitive-orbit telemetry records (s, ICD §3.4: ≤ 60).
    #[serde(default = "default_ephemeris_period")]
    pub ephemeris_period_s: f64,
    /// Star catalogue CSV (default: the workspace data/hipparcos_mag6p5.csv).
    #[serde(default)]
    pub catalog_path: Option<String>,
    /// Initial true state.
    #[serde(default)]
    pub initial: InitialState,
    /// Orbit.
    #[serde(default)]
    pub orbit: OrbitParams,
    /// Rigid body and wheels.
    #[serde(default)]
    pub dynamics: DynamicsParams,
    /// Truth sky.
    #[serde(default)]
    pub sky: SkyParams,
    /// FHST1.
    #[serde(default)]
    pub fhst1: FhstParams,
    /// FHST2.
    #[serde(default)]
    pub fhst2: FhstParams,
    /// FSS1.
    #[serde(default)]
    pub fss1: FssParams,
    /// FSS2.
    #[serde(default)]
    pub fss2: FssParams,
    /// IRU.
    #[serde(default)]
    pub iru: IruParams,
    /// Thermal nodes.
    #[serde(default)]
    pub thermal: ThermalSet,
    /// Command timeline.
    #[serde(default)]
    pub commands: Vec<TimedCommand>,
}

impl Scenario {
    /// Parse and validate TOML text; `source` names it in errors.
    ///
    /// # Errors
    /// TOML syntax, unknown or mistyped keys (named by toml), or a failed validation
    /// (named field and value).
    pub fn from_toml_str(text: &str, source: &str) -> anyhow::Result<Self> {
        let s: Self = toml::from_str(text).map_err(|e| anyhow::anyhow!("{source}: {e}"))?;
        s.validate()
            .with_context(|| format!("{source}: invalid scenario"))?;
        Ok(s)
    }

    /// Read, parse and validate a scenario file.
    ///
    /// # Errors
    /// I/O, parse or validation errors, with the path.
    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        Self::from_toml_str(&text, &path.display().to_string())
    }

    /// Check values serde cannot.
    ///
    /// # Errors
    /// The first offending field, by its TOML path.
    pub fn validate(&self) -> anyhow::Result<()> {
        let pos = |name: &str, v: f64| -> anyhow::Result<()> {
            if !(v.is_finite() && v > 0.0) {
                bail!("{name} must be a positive number, got {v}");
            }
            Ok(())
        };
        pos("step_s", self.step_s)?;
        if !(self.duration_s.is_finite() && self.duration_s >= 0.0) {
            bail!("duration_s must be ≥ 0, got {}", self.duration_s);
        }
        pos("sun_refresh_s", self.sun_refresh_s)?;
        pos("ephemeris_period_s", self.ephemeris_period_s)?;
        crate::truth::time::epoch_from_iso(&self.epoch_utc).context("epoch_utc")?;
        let q = self.initial.q_acs_from_eci;
        let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
        if !(n.is_finite() && (n - 1.0).abs() < 1e-3) {
            bail!("initial.q_acs_from_eci must be a unit quaternion [x, y, z, w], norm is {n}");
        }
        pos(
            "orbit.semimajor_axis_km",
            self.orbit.semimajor_axis_km - 6378.137,
        )
        .context("orbit.semimajor_axis_km must exceed the Earth radius")?;
        if !(0.0..1.0).contains(&self.orbit.eccentricity) {
            bail!(
                "orbit.eccentricity must be in [0, 1), got {}",
                self.orbit.eccentricity
            );
        }
        for (name, f) in [("fhst1", &self.fhst1), ("fhst2", &self.fhst2)] {
            pos(&format!("{name}.fov_half_width_deg"), f.fov_half_width_deg)?;
            pos(
                &format!("{name}.resolution_arcsec_per_count"),
                f.resolution_arcsec_per_count,
            )?;
            pos(&format!("{name}.max_track_s"), f.max_track_s)?;
            if f.magnitude_min > f.magnitude_max {
                bail!(
                    "{name}.magnitude_min ({}) exceeds magnitude_max ({})",
                    f.magnitude_min,
                    f.magnitude_max
                );
            }
        }
        for (name, f) in [("fss1", &self.fss1), ("fss2", &self.fss2)] {
            pos(&format!("{name}.fov_half_width_deg"), f.fov_half_width_deg)?;
            pos(
                &format!("{name}.resolution_deg_per_count"),
                f.resolution_deg_per_count,
            )?;
        }
        pos(
            "iru.low_rate_arcsec_per_pulse",
            self.iru.low_rate_arcsec_per_pulse,
        )?;
        pos(
            "iru.high_rate_arcsec_per_pulse",
            self.iru.high_rate_arcsec_per_pulse,
        )?;
        for (i, c) in self.commands.iter().enumerate() {
            let here = format!("commands[{i}]");
            if !(c.at_s.is_finite() && c.at_s >= 0.0) {
                bail!("{here}.at_s must be ≥ 0, got {}", c.at_s);
            }
            match c.kind {
                CommandKind::SlewTo if c.q_acs_from_eci.is_none() => {
                    bail!("{here}: kind = \"slew_to\" needs q_acs_from_eci")
                }
                CommandKind::SelectIruConfig
                    if !matches!(c.config.as_deref(), Some("primary" | "backup")) =>
                {
                    bail!("{here}: kind = \"select_iru_config\" needs config = \"primary\" or \"backup\"")
                }
                _ => {}
            }
            if let Some(q) = c.q_acs_from_eci {
                let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
                if !(n.is_finite() && (n - 1.0).abs() < 1e-3) {
                    bail!("{here}.q_acs_from_eci must be a unit quaternion, norm is {n}");
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn minimal_scenario_takes_gro_defaults() {
        let s = Scenario::from_toml_str("name = \"x\"\nduration_s = 10\n", "t").unwrap();
        assert_eq!(s.epoch_utc, "1991-04-07T22:37:00Z");
        assert_eq!(s.step_s, 1.0);
        assert_eq!(s.orbit.semimajor_axis_km, 6833.0);
        assert_eq!(s.fhst1.resolution_arcsec_per_count, 7.78);
        assert_eq!(s.thermal.fss1, ThermalParams::default_for_slot(2));
    }

    #[test]
    fn unknown_field_error_names_the_key() {
        let err = Scenario::from_toml_str(
            "name = \"x\"\nduration_s = 10\n[fhst1]\nmax_trak_s = 5\n",
            "t",
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("max_trak_s"), "{err}");
        let err = Scenario::from_toml_str(
            "name = \"x\"\nduration_s = 10\n[fhst1.effects]\nfoo = 1\n",
            "t",
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("foo"), "{err}");
        let err = Scenario::from_toml_str("name = \"x\"\nduration_s = 10\nstep_s = -1\n", "t")
            .unwrap_err();
        assert!(format!("{err:#}").contains("step_s"), "{err:#}");
        let err = Scenario::from_toml_str(
            "name = \"x\"\nduration_s = 10\n[[commands]]\nat_s = 5\nkind = \"slew_to\"\n",
            "t",
        )
        .unwrap_err();
        assert!(format!("{err:#}").contains("commands[0]"), "{err:#}");
    }

    #[test]
    fn full_featured_scenario_parses() {
        let text = r#"
name = "cal"
seed = 42
duration_s = 100
[initial]
q_acs_from_eci = [0.0, 0.0, 0.7071067811865476, 0.7071067811865476]
rate_acs_deg_per_s = [0.0, 0.01, 0.0]
[orbit]
raan_deg = 120
arg_latitude_deg = 30
[sky]
magnitude_system = "v"
[fhst2]
misalignment_true_arcsec = [10.0, -5.0, 3.0]
[fhst2.effects]
time_tag_offset_s = 0.05
[fss1.alpha]
cyclic_arcsec = 4.0
[iru]
failure = { channel = "Z1", at_s = 50.0 }
[thermal.iru]
mean_c = 30.0
[[commands]]
at_s = 0
kind = "filter_initialize"
[[commands]]
at_s = 10
kind = "select_iru_config"
config = "backup"
"#;
        let s = Scenario::from_toml_str(text, "t").unwrap();
        assert_eq!(s.seed, 42);
        assert_eq!(s.fhst2.effects.time_tag_offset_s, 0.05);
        assert_eq!(s.iru.failure.as_ref().unwrap().channel, "Z1");
        assert_eq!(s.thermal.iru.mean_c, 30.0);
        assert_eq!(s.thermal.fhst1, ThermalParams::default_for_slot(0));
        assert_eq!(s.commands.len(), 2);
        assert!((s.initial.quat().z - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-12);
    }
}

#[cfg(test)]
mod shipped_scenarios {
    use super::*;

    /// Every file in the workspace `scenarios/` folder parses and validates.
    #[test]
    fn all_shipped_scenarios_load() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios");
        let mut count = 0;
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "toml") {
                Scenario::load(&path).unwrap_or_else(|e| panic!("{}: {e:#}", path.display()));
                count += 1;
            }
        }
        assert!(count >= 2, "found {count} scenarios in {}", dir.display());
    }
}
