//! # The run folder's `metadata.json` and `truth.json`, defined once (docs/icd.md §5)
//!
//! Why: the file was written by untyped `json!` in the simulator, read by a typed struct in
//! `calibrate` and by walking untyped JSON in the flown-table lookup and the ICD check: three
//! definitions that could drift apart without any error (a renamed key read as "absent" is
//! the GRO default, not a failure). Here is the one definition: `sim-harness run` writes
//! [`Metadata`], `ground-tool` reads it, and `docs/schema/metadata.schema.json` is generated
//! from it (`cargo run -p gro-reference --example write_schemas`; a test fails when the
//! shipped schema is stale), so an outside writer can validate its file before flying.
//!
//! Every field has a default, so an older run folder, the ICD writer's file
//! (`tests/icd/write_run.py`) or `{}` still reads: an absent key means the GRO value the field
//! names. Unknown keys are ignored; a key of the wrong type is refused (exit code 2, the
//! message names the file and the field).
//!
//! `truth.json` ([`Truth`], `docs/schema/truth.schema.json`) had the same history: written by
//! `json!` in `sim-harness run`, read by walking JSON in every scorer. It is scoring only:
//! the calibration and the diagnosis never read it.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::Context;
use fsw_core::units::{ARCSEC_PER_RAD, RAD_PER_ARCSEC};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::paper::Rows3;
use crate::InputError;

/// File name of the metadata inside a run folder.
pub const METADATA_FILE: &str = "metadata.json";

/// The effects every GRO analyst's model includes when `metadata.json` does not list
/// `declared_effects` (and the simulator's declaration when a scenario does not say): stellar
/// and solar aberration (annual and orbital), Sun parallax, the FSS transfer-function errors,
/// the early IRU bias drift. Part of the file's contract, so defined with it.
pub const DEFAULT_DECLARED_EFFECTS: [&str; 5] = [
    "aberration",
    "orbital_aberration",
    "sun_parallax",
    "fss_transfer_function",
    "iru_bias_transient",
];

/// A `declared_effects` list as the file means it: the list given, or
/// [`DEFAULT_DECLARED_EFFECTS`] when absent.
#[must_use]
pub fn declared_or_default(list: Option<&[String]>) -> Vec<String> {
    list.map_or_else(
        || DEFAULT_DECLARED_EFFECTS.map(str::to_owned).to_vec(),
        <[String]>::to_vec,
    )
}

/// The paper's inherent FSS error after calibration (§4.3: 0.022°), arcsec: the ground's
/// `fss_systematic_arcsec` when the metadata does not declare one.
pub const PAPER_FSS_SYSTEMATIC_ARCSEC: f64 = 0.022 * 3600.0;

/// What the operator declares about a run (`metadata.json`); every field has a default.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct Metadata {
    /// A name for reports (the simulator: the scenario's name).
    pub scenario: String,
    /// What the run is (informational).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
    /// Random seed of the run (informational).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// UTC of the first raw frame, ISO 8601 (`1991-04-09T00:00:00Z`); checked against the time
    /// codes (docs/icd.md §6).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub epoch_utc: Option<String>,
    /// OBC cycle, s (informational: the ground takes every interval from the time codes).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cycle_period_s: Option<f64>,
    /// Length of the run, s (informational).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub duration_s: Option<f64>,
    /// One raw frame downlinked every this many cycles (informational).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub telemetry_every_n_cycles: Option<u32>,
    /// Period of the definitive-orbit records, s (informational).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ephemeris_period_s: Option<f64>,
    /// Declared noise figures.
    pub sensors: DeclaredNoise,
    /// Effects the operator's model includes; absent = the GRO defaults
    /// ([`DEFAULT_DECLARED_EFFECTS`]), an empty list = none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub declared_effects: Option<Vec<String>>,
    /// 1σ spreads of the FSS transfer-function coefficients per unit (`FSS1`, `FSS2`); FFCAL
    /// carries them as consider parameters. Absent = the per-cell weights alone.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fss_transfer_function_sigma: Option<TransferSpreads>,
    /// What each table held at boot, by table name (informational).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub boot_tables: Option<BTreeMap<String, String>>,
    /// Table images loaded during the run, in load order; the last activated and accepted one
    /// of each table is the table flown (docs/icd.md §5, "Flown tables").
    pub uploads: Vec<Upload>,
    /// The simulated spacecraft's identity (its sensors and gyro): the ground copies it
    /// beside the tables it calibrates (`tables/provenance.json`,
    /// [`crate::provenance`]); absent in telemetry the simulator did not write.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spacecraft: Option<Spacecraft>,
    /// Keys of the file that are not part of the format (`sensors.fhst_sigma_arsec`), as
    /// [`Metadata::read`] found them: ignored, so a misspelt key leaves its figure at the
    /// default; the ground's run check warns with their names. Not a key of the file.
    #[serde(skip)]
    #[schemars(skip)]
    pub unknown_keys: Vec<String>,
}

impl Metadata {
    /// The effects the operator's model includes: the list given, or the GRO defaults
    /// ([`DEFAULT_DECLARED_EFFECTS`]) when `declared_effects` is absent.
    #[must_use]
    pub fn declared(&self) -> Vec<String> {
        declared_or_default(self.declared_effects.as_deref())
    }

    /// Whether the operator's model includes `effect` (absent list = the GRO defaults).
    #[must_use]
    pub fn declares(&self, effect: &str) -> bool {
        match &self.declared_effects {
            Some(list) => list.iter().any(|e| e == effect),
            None => DEFAULT_DECLARED_EFFECTS.contains(&effect),
        }
    }

    /// Read `RUN_DIR/metadata.json`; the defaults when the file is absent.
    ///
    /// # Errors
    /// [`InputError`] naming the file and the cause when it cannot be read, is not JSON, or
    /// has a key of the wrong type.
    pub fn read(run_dir: &Path) -> anyhow::Result<Self> {
        let path = run_dir.join(METADATA_FILE);
        if !path.exists() {
            return Ok(Self::default());
        }
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("reading {}", path.display()))?;
        // A UTF-8 byte-order mark (some editors write one) is not JSON but carries nothing.
        let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
        // The path of the offending key (`uploads[0].accepted`): serde_json alone gives only
        // a line and column.
        // The keys it ignores are kept (`unknown_keys`) so that a misspelt one is said.
        let mut unknown = Vec::new();
        let mut de = serde_json::Deserializer::from_str(text);
        let mut note = |p: serde_ignored::Path<'_>| unknown.push(p.to_string());
        let tracked = serde_ignored::Deserializer::new(&mut de, &mut note);
        let mut m: Self = serde_path_to_error::deserialize(tracked).map_err(|e| {
            let field = e.path().to_string();
            anyhow::Error::from(InputError::msg(format!(
                "{} is not valid metadata (docs/icd.md §5): field `{field}`: {}",
                path.display(),
                e.inner()
            )))
        })?;
        de.end().map_err(|e| {
            InputError::msg(format!(
                "{} is not valid metadata (docs/icd.md §5): {e} after the JSON object",
                path.display()
            ))
        })?;
        m.unknown_keys = unknown;
        Ok(m)
    }

    /// The file's JSON: keys in sorted order at every level (the order `json!` gave the
    /// simulator's files before this type existed, so their bytes did not change).
    ///
    /// # Errors
    /// Never for this type (every key is a string); the `serde_json` error otherwise.
    pub fn to_json_value(&self) -> serde_json::Result<serde_json::Value> {
        serde_json::to_value(self)
    }
}

/// Declared sensor accuracies (`metadata.json` `sensors`); absent figures are the paper's.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct DeclaredNoise {
    /// FHST 1σ per axis for a magnitude-2.0 and a magnitude-5.7 star, arcsec.
    pub fhst_sigma_arcsec: [f64; 2],
    /// FSS noise, counts 1σ (informational: the ground uses `fss_sigma_arcsec`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fss_noise_counts: Option<f64>,
    /// FSS 1σ per axis, arcsec (calibrated accuracy, transfer-function residual included).
    pub fss_sigma_arcsec: f64,
    /// FSS error that depends on where the Sun is in the field and so does not average down
    /// over samples at one position (transfer-function residual), 1σ per axis, arcsec.
    /// Absent = the paper's inherent 0.022° ([`PAPER_FSS_SYSTEMATIC_ARCSEC`],
    /// [`DeclaredNoise::fss_systematic_or_paper_arcsec`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fss_systematic_arcsec: Option<f64>,
    /// Gyro angle random walk, rad/√s.
    pub iru_arw_rad_per_sqrt_s: f64,
    /// Gyro rate random walk, rad/s^1.5.
    pub iru_rrw_rad_per_s_sqrt_s: f64,
}

impl Default for DeclaredNoise {
    fn default() -> Self {
        Self {
            fhst_sigma_arcsec: [8.0, 24.0],
            fss_noise_counts: None,
            fss_sigma_arcsec: 0.02 * 3600.0,
            fss_systematic_arcsec: None,
            iru_arw_rad_per_sqrt_s: 1.5e-7,
            iru_rrw_rad_per_s_sqrt_s: 1.0e-10,
        }
    }
}

impl DeclaredNoise {
    /// FHST σ (rad) for a magnitude, linear between the bright and faint figures.
    #[must_use]
    pub fn fhst_sigma_rad(&self, magnitude: f64) -> f64 {
        let t = ((magnitude - 2.0) / 3.7).clamp(0.0, 1.0);
        let [bright, faint] = self.fhst_sigma_arcsec;
        (bright + t * (faint - bright)) * RAD_PER_ARCSEC
    }

    /// The declared FSS systematic, or the paper's 0.022° when none is declared, arcsec.
    #[must_use]
    pub fn fss_systematic_or_paper_arcsec(&self) -> f64 {
        self.fss_systematic_arcsec
            .unwrap_or(PAPER_FSS_SYSTEMATIC_ARCSEC)
    }
}

/// One table image loaded during the run (`metadata.json` `uploads[]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct Upload {
    /// Table name: `alignment`, `iru`, `filter`, `star_catalog`, `orbit`.
    pub table: String,
    /// The image file, relative to the run folder (`uploads/...`); absent = not kept.
    pub file: Option<String>,
    /// Where the image came from (informational).
    pub source: String,
    /// Load command time, s from the start (informational).
    pub loaded_at_s: Option<f64>,
    /// The OBC accepted the image; absent = accepted.
    pub accepted: bool,
    /// Activation time, s from the start; absent or null = never activated (not flown).
    pub activated_at_s: Option<f64>,
    /// Activation time, UTC (informational).
    pub activated_utc: Option<String>,
    /// CRC-32 of the image as the OBC reported it at activation (informational).
    pub crc32: Option<u32>,
}

impl Default for Upload {
    fn default() -> Self {
        Self {
            table: String::new(),
            file: None,
            source: String::new(),
            loaded_at_s: None,
            accepted: true,
            activated_at_s: None,
            activated_utc: None,
            crc32: None,
        }
    }
}

impl Upload {
    /// The image the OBC flew from its activation on: activated and accepted.
    #[must_use]
    pub fn flown(&self) -> bool {
        self.activated_at_s.is_some() && self.accepted
    }
}

/// 1σ spreads of one head's transfer-function coefficients (arcsec unless named); the model
/// of docs/algorithms.md §4 (`E` = 32°).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct HeadSpread {
    /// Null offset (arcsec).
    pub offset_arcsec: f64,
    /// Scale factor (ppm of the head angle).
    pub scale_ppm: f64,
    /// Cyclic reticle error amplitude (arcsec); its phase is unknown.
    pub cyclic_arcsec: f64,
    /// Period of the cyclic error (deg); 0 = no cyclic term.
    pub cyclic_pitch_deg: f64,
    /// Cross-axis term `α β²/E³` at the 32° corner (arcsec).
    pub cross_arcsec_at_corner: f64,
    /// Edge term `α³/E³` at 32° (arcsec).
    pub cubic_arcsec_at_edge: f64,
}

/// The field edge the cross and cubic terms are scaled to (rad).
pub const HEAD_SPREAD_EDGE_RAD: f64 = 32.0 * std::f64::consts::PI / 180.0;

impl HeadSpread {
    /// The head-angle error (arcsec) of each coefficient at 1σ, for the head angle `own` and
    /// the other head's `other` (rad): what a declared spread means. The cyclic amplitude of
    /// unknown phase is a sine and a cosine of σ/√2 each (the same mean square).
    #[must_use]
    pub fn one_sigma_terms(&self, own_rad: f64, other_rad: f64) -> [f64; 6] {
        let x = own_rad / HEAD_SPREAD_EDGE_RAD;
        let y = other_rad / HEAD_SPREAD_EDGE_RAD;
        let phase = if self.cyclic_pitch_deg > 0.0 {
            2.0 * std::f64::consts::PI * own_rad.to_degrees() / self.cyclic_pitch_deg
        } else {
            0.0
        };
        let cyc = if self.cyclic_pitch_deg > 0.0 {
            self.cyclic_arcsec.abs() * std::f64::consts::FRAC_1_SQRT_2
        } else {
            0.0
        };
        [
            self.offset_arcsec.abs(),
            self.scale_ppm.abs() * 1e-6 * own_rad * ARCSEC_PER_RAD,
            cyc * phase.sin(),
            cyc * phase.cos(),
            self.cross_arcsec_at_corner.abs() * x * y * y,
            self.cubic_arcsec_at_edge.abs() * x * x * x,
        ]
    }

    /// Whether any spread is nonzero.
    #[must_use]
    pub fn any(&self) -> bool {
        [
            self.offset_arcsec,
            self.scale_ppm,
            self.cyclic_arcsec,
            self.cross_arcsec_at_corner,
            self.cubic_arcsec_at_edge,
        ]
        .iter()
        .any(|v| *v != 0.0)
    }
}

/// One FSS unit's spreads (`fss_transfer_function_sigma.FSS1`, `.FSS2`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct UnitSpread {
    /// α head.
    pub alpha: HeadSpread,
    /// β head.
    pub beta: HeadSpread,
}

/// The declared spreads by FSS name (`FSS1`, `FSS2`).
pub type TransferSpreads = BTreeMap<String, UnitSpread>;

/// The JSON Schemas of the run-folder files this crate defines, by file name under
/// `docs/schema/`: what `cargo run -p gro-reference --example write_schemas` writes and the
/// freshness test compares.
#[must_use]
pub fn schemas() -> Vec<(&'static str, String)> {
    let pretty = |s: schemars::Schema| {
        let mut text = serde_json::to_string_pretty(&s).unwrap_or_default();
        text.push('\n');
        text
    };
    vec![
        (
            "metadata.schema.json",
            pretty(schemars::schema_for!(Metadata)),
        ),
        (
            "tables-manifest.schema.json",
            pretty(schemars::schema_for!(crate::manifest::Manifest)),
        ),
        ("truth.schema.json", pretty(schemars::schema_for!(Truth))),
    ]
}

// Computed and compared in `crate::provenance`; defined here, with the file it is part of, so
// that the run-folder contract does not import the provenance module that reads it.
/// The simulated spacecraft's identity (`metadata.json` `spacecraft`).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Spacecraft {
    /// CRC-32 of all the parts, `sim-%08x`.
    pub id: String,
    /// CRC-32 of each part's parameters (their JSON serialisation), `%08x`.
    pub parts: BTreeMap<String, String>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn absent_declared_effects_are_the_gro_defaults_an_empty_list_is_none() {
        let meta = |v: serde_json::Value| -> Metadata {
            serde_json::from_value(v).unwrap_or_else(|e| panic!("{e}"))
        };
        let absent = meta(serde_json::json!({})).declared();
        assert_eq!(absent, DEFAULT_DECLARED_EFFECTS.map(str::to_owned).to_vec());
        assert!(meta(serde_json::json!({ "declared_effects": [] }))
            .declared()
            .is_empty());
        assert!(meta(serde_json::json!({})).declares("aberration"));
        let m = meta(serde_json::json!({ "declared_effects": ["sun_parallax"] }));
        assert!(!m.declares("aberration") && m.declares("sun_parallax"));
    }

    /// An upload without `accepted` is accepted (older folders); one without
    /// `activated_at_s` or with null was never flown.
    #[test]
    fn upload_defaults_follow_the_icd() {
        let u: Upload = serde_json::from_value(serde_json::json!({
            "table": "alignment", "file": "uploads/01_alignment.tbl", "activated_at_s": 2.0
        }))
        .unwrap_or_else(|e| panic!("{e}"));
        assert!(u.accepted && u.flown());
        let never: Upload = serde_json::from_value(serde_json::json!({
            "table": "alignment", "activated_at_s": null
        }))
        .unwrap_or_else(|e| panic!("{e}"));
        assert!(!never.flown());
        let rejected: Upload = serde_json::from_value(serde_json::json!({
            "table": "iru", "activated_at_s": 1.0, "accepted": false
        }))
        .unwrap_or_else(|e| panic!("{e}"));
        assert!(!rejected.flown());
    }

    /// A key of the wrong type is refused with the file and the field named (the untyped
    /// readers took it as absent, i.e. the GRO default).
    #[test]
    fn a_key_of_the_wrong_type_is_refused_naming_the_field() {
        let dir = std::env::temp_dir().join(format!("gro-ref-meta-{}", std::process::id()));
        let _ = std::fs::create_dir_all(&dir);
        let write = |text: &str| std::fs::write(dir.join(METADATA_FILE), text);
        assert!(write(r#"{"epoch_utc": 5}"#).is_ok());
        let e = Metadata::read(&dir).map(|_| ()).unwrap_err();
        let text = format!("{e:#}");
        assert!(crate::is_input_error(&e), "{text}");
        assert!(
            text.contains("metadata.json") && text.contains("epoch_utc"),
            "{text}"
        );
        assert!(write(r#"{"uploads": [{"table": "iru", "accepted": "yes"}]}"#).is_ok());
        let text = format!("{:#}", Metadata::read(&dir).map(|_| ()).unwrap_err());
        assert!(text.contains("accepted"), "{text}");
        assert!(write("{}").is_ok());
        assert_eq!(Metadata::read(&dir).ok(), Some(Metadata::default()));
        // Keys outside the format are kept by path (a misspelt one would otherwise leave its
        // figure at the default unseen); a byte-order mark is read past.
        assert!(
            write("\u{feff}{\"sensors\": {\"fhst_sigma_arsec\": [1, 2]}, \"colour\": 1}").is_ok()
        );
        let m = Metadata::read(&dir).unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!(m.unknown_keys, ["sensors.fhst_sigma_arsec", "colour"]);
        assert_eq!(m.sensors, DeclaredNoise::default());
        // Anything after the object is refused, naming the file.
        assert!(write("{} {}").is_ok());
        let text = format!("{:#}", Metadata::read(&dir).map(|_| ()).unwrap_err());
        assert!(
            text.contains("metadata.json") && text.contains("after the JSON object"),
            "{text}"
        );
        let _ = std::fs::remove_dir_all(&dir);
        assert_eq!(Metadata::read(&dir).ok(), Some(Metadata::default()));
    }

    /// The absent systematic is the paper's, a declared one is taken as is (zero included).
    #[test]
    fn fss_systematic_defaults_to_the_paper() {
        let n = DeclaredNoise::default();
        assert_eq!(
            n.fss_systematic_or_paper_arcsec(),
            PAPER_FSS_SYSTEMATIC_ARCSEC
        );
        assert!((PAPER_FSS_SYSTEMATIC_ARCSEC - 79.2).abs() < 1e-9);
        let zero = DeclaredNoise {
            fss_systematic_arcsec: Some(0.0),
            ..n
        };
        assert_eq!(zero.fss_systematic_or_paper_arcsec(), 0.0);
    }

    /// The terms at known points: the scale at 10°, the edge and corner terms at (32°, 32°),
    /// the cyclic pair's mean square equal to the amplitude's.
    #[test]
    fn one_sigma_terms_at_known_points() {
        let h = HeadSpread {
            offset_arcsec: -3.0,
            scale_ppm: 150.0,
            cyclic_arcsec: 6.0,
            cyclic_pitch_deg: 2.0,
            cross_arcsec_at_corner: -30.0,
            cubic_arcsec_at_edge: 20.0,
        };
        let t = h.one_sigma_terms(10f64.to_radians(), 0.0);
        assert!((t[0] - 3.0).abs() < 1e-12);
        assert!((t[1] - 150e-6 * 36_000.0).abs() < 1e-9);
        assert!((t[2] * t[2] + t[3] * t[3] - 18.0).abs() < 1e-9);
        let c = h.one_sigma_terms(HEAD_SPREAD_EDGE_RAD, HEAD_SPREAD_EDGE_RAD);
        assert!((c[4] - 30.0).abs() < 1e-9 && (c[5] - 20.0).abs() < 1e-9);
        assert!(!HeadSpread::default().any() && h.any());
    }
}

/// File name of the simulator's truth inside a run folder: scoring only, never read by the
/// calibration or the diagnosis.
pub const TRUTH_FILE: &str = "truth.json";

/// One value per attitude sensor, keyed FHST1, FHST2, FSS1, FSS2 in the file.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct PerSensor<T> {
    /// FHST1.
    #[serde(rename = "FHST1")]
    pub fhst1: T,
    /// FHST2.
    #[serde(rename = "FHST2")]
    pub fhst2: T,
    /// FSS1.
    #[serde(rename = "FSS1")]
    pub fss1: T,
    /// FSS2.
    #[serde(rename = "FSS2")]
    pub fss2: T,
}

impl<T> PerSensor<T> {
    /// From the four values in sensor order (FHST1, FHST2, FSS1, FSS2).
    #[must_use]
    pub fn from_array([fhst1, fhst2, fss1, fss2]: [T; 4]) -> Self {
        Self {
            fhst1,
            fhst2,
            fss1,
            fss2,
        }
    }

    /// The four values in sensor order (FHST1, FHST2, FSS1, FSS2).
    #[must_use]
    pub fn into_array(self) -> [T; 4] {
        [self.fhst1, self.fhst2, self.fss1, self.fss2]
    }

    /// The value of the sensor named `id` (`FHST1` … `FSS2`).
    #[must_use]
    pub fn get(&self, id: &str) -> Option<&T> {
        match id {
            "FHST1" => Some(&self.fhst1),
            "FHST2" => Some(&self.fhst2),
            "FSS1" => Some(&self.fss1),
            "FSS2" => Some(&self.fss2),
            _ => None,
        }
    }
}

/// `truth.json`: what the simulator flew, for scoring (`sim-harness run` writes it; the
/// scorers of the `tests` crate read it). `S` is the scenario as flown and `H` one FSS head's
/// transfer-function coefficients: the simulator's own types when it writes, JSON values for
/// a reader that does not carry the simulator (the default). Fields a run folder written
/// before them lacks are optional or default to empty.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Truth<S = serde_json::Value, H = serde_json::Value> {
    /// Scenario name.
    #[serde(default)]
    pub scenario: String,
    /// Seed of the run.
    #[serde(default)]
    pub seed: u64,
    /// The whole scenario as flown (each FSS with the transfer function it flew), so that a
    /// scorer needs no scenario file of the same name.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scenario_as_flown: Option<S>,
    /// True `M_AS` per sensor at the start (row-major, without thermal drift).
    pub alignments: PerSensor<Rows3>,
    /// The same with any alignment step of the run applied: what tables written after the
    /// run fly into.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alignments_after_run: Option<PerSensor<Rows3>>,
    /// True misalignment from the paper's prelaunch alignment per sensor (ACS rotation
    /// vector, arcsec).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub misalignment_from_prelaunch_acs_arcsec: Option<PerSensor<[f64; 3]>>,
    /// The IRU's true geometry per triad.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub iru: Option<TruthIru>,
    /// The true gyro bias over the run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bias_history: Option<TruthBiasHistory>,
    /// The transfer function each FSS flew.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fss_transfer_function: Option<TruthFssTransfer<H>>,
    /// Effects active in the truth, by name (`sensor.effect` for per-unit hooks).
    #[serde(default)]
    pub present_effects: Vec<String>,
    /// Present effects the run's metadata does not declare.
    #[serde(default)]
    pub undeclared_effects: Vec<String>,
    /// The magnetometers' true errors.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tam: Option<TruthTams>,
    /// The effect `tests`' injection added to a copied run folder (absent in a flown one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub injected_effect: Option<String>,
}

impl<S: Serialize, H: Serialize> Truth<S, H> {
    /// The file's JSON: keys in sorted order at every level (the order `json!` gave the
    /// simulator's file before this type existed, so its bytes did not change).
    ///
    /// # Errors
    /// A scenario or coefficient type that does not serialize to JSON.
    pub fn to_json_value(&self) -> serde_json::Result<serde_json::Value> {
        serde_json::to_value(self)
    }
}

impl Truth {
    /// Read `RUN_DIR/truth.json`; `None` when the run folder has none.
    ///
    /// # Errors
    /// A present file that cannot be read or is not a truth (the message names the field).
    pub fn read(run_dir: &Path) -> anyhow::Result<Option<Self>> {
        let path = run_dir.join(TRUTH_FILE);
        if !path.exists() {
            return Ok(None);
        }
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("reading {}", path.display()))?;
        let mut de = serde_json::Deserializer::from_str(&text);
        serde_path_to_error::deserialize(&mut de)
            .map(Some)
            .map_err(|e| {
                anyhow::anyhow!(
                    "{} is not a valid truth: field `{}`: {}",
                    path.display(),
                    e.path(),
                    e.inner()
                )
            })
    }
}

/// `truth.json` `iru`: the true geometry of both triads.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TruthIru {
    /// The primary triad (X2, Y1, Z1).
    pub primary: TruthTriad,
    /// The backup triad (X1, Y2, Z2).
    pub backup: TruthTriad,
    /// How `g` and `delta_m` map channel angles to ACS.
    pub convention: String,
}

/// One IRU triad's true geometry.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TruthTriad {
    /// The channels, in the order of the triad's X, Y, Z.
    pub channels: Vec<String>,
    /// The prelaunch `G` (row-major).
    pub g: Rows3,
    /// The true `δM` (row-major): `Δθ_acs = (I + δM) g Δφ`.
    pub delta_m: Rows3,
    /// Per channel scale-factor error (ppm).
    pub channel_scale_ppm: [f64; 3],
    /// Per channel extra scale-factor error in high-rate mode (ppm).
    pub high_rate_scale_ppm: [f64; 3],
}

/// `truth.json` `bias_history`: the true gyro bias, sampled.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TruthBiasHistory {
    /// Spacing of the samples (s).
    pub period_s: f64,
    /// What the samples are.
    pub note: String,
    /// The samples.
    pub samples: Vec<TruthBiasSample>,
}

/// One true-bias sample.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TruthBiasSample {
    /// Time since the start (s).
    pub t_s: f64,
    /// The primary triad's bias mapped to ACS through the true triad geometry (rad/s).
    pub bias_acs_rad_per_s: [f64; 3],
    /// The backup triad's, likewise (rad/s).
    pub backup_bias_acs_rad_per_s: [f64; 3],
    /// Every channel's bias in raw channel order X1, X2, Y1, Y2, Z1, Z2 (rad/s).
    pub channel_bias_rad_per_s: [f64; fsw_core::raw::IRU_CHANNELS],
}

/// `truth.json` `fss_transfer_function`: each FSS's two heads as flown.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TruthFssTransfer<H = serde_json::Value> {
    /// FSS1.
    #[serde(rename = "FSS1")]
    pub fss1: TruthFssUnit<H>,
    /// FSS2.
    #[serde(rename = "FSS2")]
    pub fss2: TruthFssUnit<H>,
    /// Where the coefficients come from.
    pub note: String,
}

/// One FSS's heads as flown.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TruthFssUnit<H = serde_json::Value> {
    /// α head.
    pub alpha: H,
    /// β head.
    pub beta: H,
}

/// `truth.json` `tam`: the primary TAM at the top level, TAM2 under `tam2`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TruthTams {
    /// The primary TAM (TAM1).
    #[serde(flatten)]
    pub tam1: TruthTam,
    /// TAM2.
    pub tam2: TruthTam,
    /// Axes and units.
    pub note: String,
}

/// One TAM's true errors (sensor axes, mG; 1 mG = 100 nT).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TruthTam {
    /// Bias (mG).
    #[serde(rename = "bias_mG")]
    pub bias_milligauss: [f64; 3],
    /// What a bias fit with the torquer bars off recovers: the bias plus the residual field
    /// as the TAM sees it (mG).
    #[serde(rename = "effective_bias_mG")]
    pub effective_bias_milligauss: [f64; 3],
    /// Scale-factor error per axis (ppm).
    pub scale_ppm: [f64; 3],
    /// Misalignment (ACS rotation vector, arcsec).
    pub misalignment_acs_arcsec: [f64; 3],
    /// The spacecraft's residual field (ACS, mG).
    #[serde(rename = "residual_field_acs_mG")]
    pub residual_field_acs_milligauss: [f64; 3],
    /// White noise 1σ (mG).
    #[serde(rename = "noise_mG_1sigma")]
    pub noise_milligauss_1sigma: f64,
    /// Quantisation step (mG per count).
    #[serde(rename = "resolution_mG_per_count")]
    pub resolution_milligauss_per_count: f64,
}
