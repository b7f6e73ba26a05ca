//! # Whose spacecraft a tables folder was calibrated on: `tables/provenance.json`
//!
//! The file format and the spacecraft identity (shared by the simulator, which writes the
//! identity into `metadata.json`, and the ground, which copies it beside its tables); the
//! check against a flown scenario is the simulator's (`sim_harness::provenance`).
//!
//! Why (issue 21): tables are calibrated on one spacecraft's telemetry — its true
//! alignments, gyro and sensors. Flown by the simulator on a *different* spacecraft they are
//! simply wrong for it, and the run's attitude error says nothing about them: the independent
//! ICD writer's tables flown on `normal-ops` took 3.6–4.4″ RMS to 18–46″ (NEES 467) with exit
//! code 0 and no word. The README warned; the tool did not.
//!
//! How:
//! * `sim-harness run` writes the simulated spacecraft's identity into `metadata.json`
//!   (`spacecraft`: a CRC-32 of each scenario part the tables calibrate — `FHST1`, `FHST2`,
//!   `FSS1`, `FSS2`, `IRU` — and `id`, one over all of them). The flight plan, epoch,
//!   duration, seed, thermal environment and the parts' state at the start or event times
//!   ([`STATE_KEYS`], keys ending in `_at_s`) are not part of it: the same spacecraft flown
//!   on another plan or later in its mission is the same spacecraft (`gro-early-mission`'s
//!   tables on `normal-ops`, 55 days later, are the operations flow and raise nothing).
//! * `ground-tool calibrate` and `diagnose` (and `calibration-loop`) copy the source run's
//!   `scenario`, `seed` and `spacecraft` from its `metadata.json` into
//!   `tables/provenance.json` beside the tables ([`write`]).
//! * `sim-harness run --tables DIR` compares them with the scenario it flies ([`check`]) and
//!   prints a warning naming the file, the field and the parts that differ; the warning is
//!   also kept in `summary.json` (`tables_provenance_warning`).
//!
//! Warn, not refuse: flying foreign tables on purpose is a legitimate experiment (the
//! measurement above is one; sensitivity studies and hand-made tables are others), and the
//! folder's tables are valid images either way — what is wrong is only the *reading* of the
//! result as a verdict on the tables. A refusal would force `--force` on every such use and
//! teach users to type it; a warning on stderr and in `summary.json` travels with the result.
//! A folder without `provenance.json` (made by hand, or by an older ground tool) gets a note
//! that it cannot be checked.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::Context;
use fsw_core::tables::image::IMAGE_CRC;
use serde::{Deserialize, Serialize};

use crate::run_folder::Metadata;
pub use crate::run_folder::Spacecraft;

/// File name of the provenance inside a tables folder.
pub const PROVENANCE: &str = "provenance.json";

/// Value of the file's `format` key.
pub const FORMAT: &str = "gro-tables-provenance-1";

/// Keys of a part that are its state when the run starts, not what it is: left out of the
/// identity (with every key ending in `_at_s`, the time of an event in the run).
pub const STATE_KEYS: [&str; 4] = [
    "time_since_release_at_start_s",
    "initial_high_rate",
    "initial_counts",
    "failure",
];

/// `v` without the state keys, at every depth.
fn without_state(v: serde_json::Value) -> serde_json::Value {
    match v {
        serde_json::Value::Object(o) => serde_json::Value::Object(
            o.into_iter()
                .filter(|(k, _)| !(STATE_KEYS.contains(&k.as_str()) || k.ends_with("_at_s")))
                .map(|(k, x)| (k, without_state(x)))
                .collect(),
        ),
        serde_json::Value::Array(a) => {
            serde_json::Value::Array(a.into_iter().map(without_state).collect())
        }
        x => x,
    }
}

impl Spacecraft {
    /// The identity of a spacecraft from its parts (name, parameters as JSON): what the
    /// tables calibrate, without the state keys. The simulator passes its scenario's
    /// FHST1, FHST2, FSS1, FSS2 and IRU (`sim_harness::provenance::spacecraft_of`).
    ///
    /// # Errors
    /// A part that does not serialise (a defect).
    pub fn of_parts(parts: Vec<(&str, serde_json::Value)>) -> anyhow::Result<Self> {
        let mut all = Vec::new();
        let mut map = BTreeMap::new();
        for (name, v) in parts {
            let text = serde_json::to_string(&without_state(v))?;
            all.extend_from_slice(name.as_bytes());
            all.extend_from_slice(text.as_bytes());
            map.insert(
                name.to_owned(),
                format!("{:08x}", IMAGE_CRC.checksum(text.as_bytes())),
            );
        }
        Ok(Self {
            id: format!("sim-{:08x}", IMAGE_CRC.checksum(&all)),
            parts: map,
        })
    }
}

/// `provenance.json`.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Provenance {
    /// [`FORMAT`].
    pub format: String,
    /// The command that wrote the tables.
    pub written_by: String,
    /// The run folder calibrated (as given on the command line).
    pub source_run: String,
    /// `metadata.json` `scenario` of that run (`None`: not declared).
    pub scenario: Option<String>,
    /// `metadata.json` `seed` of that run.
    pub seed: Option<u64>,
    /// `metadata.json` `spacecraft` of that run (`None`: the telemetry was not written by
    /// this simulator, or by an older one).
    pub spacecraft: Option<Spacecraft>,
}

/// Write `tables_dir/provenance.json` from the source run's `metadata.json` (the default
/// metadata when the run has none).
///
/// # Errors
/// I/O (the message names the file).
pub fn write(
    tables_dir: &Path,
    source_run: &Path,
    metadata: &Metadata,
    written_by: &str,
) -> anyhow::Result<Provenance> {
    let p = Provenance {
        format: FORMAT.to_owned(),
        written_by: written_by.to_owned(),
        source_run: source_run.display().to_string(),
        scenario: (!metadata.scenario.is_empty()).then(|| metadata.scenario.clone()),
        seed: metadata.seed,
        spacecraft: metadata.spacecraft.clone(),
    };
    let path = tables_dir.join(PROVENANCE);
    std::fs::write(&path, serde_json::to_string_pretty(&p)? + "\n")
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(p)
}
