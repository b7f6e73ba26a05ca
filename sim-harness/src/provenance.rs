//! # Whose spacecraft a tables folder was calibrated on: `tables/provenance.json`
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

use crate::scenario::Scenario;

/// File name of the provenance inside a tables folder.
pub const PROVENANCE: &str = "provenance.json";

/// Value of the file's `format` key.
pub const FORMAT: &str = "gro-tables-provenance-1";

/// The simulated spacecraft's identity (`metadata.json` `spacecraft`).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Spacecraft {
    /// CRC-32 of all the parts, `sim-%08x`.
    pub id: String,
    /// CRC-32 of each part's parameters (their JSON serialisation), `%08x`.
    pub parts: BTreeMap<String, String>,
}

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
    /// The identity of the spacecraft `s` simulates: its sensors and gyro (what the tables
    /// calibrate), not its plan, epoch, duration, seed or state at the start.
    ///
    /// # Errors
    /// A part that does not serialise (a defect).
    pub fn of(s: &Scenario) -> anyhow::Result<Self> {
        let parts: [(&str, serde_json::Value); 5] = [
            ("FHST1", serde_json::to_value(&s.fhst1)?),
            ("FHST2", serde_json::to_value(&s.fhst2)?),
            ("FSS1", serde_json::to_value(&s.fss1)?),
            ("FSS2", serde_json::to_value(&s.fss2)?),
            ("IRU", serde_json::to_value(&s.iru)?),
        ];
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

/// Write `tables_dir/provenance.json` from the source run's `metadata.json` (as a JSON value;
/// `Null` when the run has none).
///
/// # Errors
/// I/O (the message names the file).
pub fn write(
    tables_dir: &Path,
    source_run: &Path,
    metadata: &serde_json::Value,
    written_by: &str,
) -> anyhow::Result<Provenance> {
    let p = Provenance {
        format: FORMAT.to_owned(),
        written_by: written_by.to_owned(),
        source_run: source_run.display().to_string(),
        scenario: metadata
            .get("scenario")
            .and_then(|v| v.as_str())
            .map(str::to_owned),
        seed: metadata.get("seed").and_then(serde_json::Value::as_u64),
        spacecraft: metadata
            .get("spacecraft")
            .and_then(|v| serde_json::from_value(v.clone()).ok()),
    };
    let path = tables_dir.join(PROVENANCE);
    std::fs::write(&path, serde_json::to_string_pretty(&p)? + "\n")
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(p)
}

/// What [`check`] found.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Check {
    /// Calibrated on this spacecraft.
    Same,
    /// No `provenance.json` in the folder.
    Missing,
    /// A `provenance.json` that does not parse (the cause).
    Unreadable(String),
    /// Calibrated on telemetry without a simulator spacecraft identity (outside telemetry).
    Unknown {
        /// The source run's declared scenario.
        scenario: Option<String>,
    },
    /// Calibrated on another spacecraft.
    Different {
        /// The source run's scenario.
        scenario: Option<String>,
        /// The source spacecraft's id.
        source_id: String,
        /// The flown spacecraft's id.
        flown_id: String,
        /// Parts whose parameters differ.
        parts: Vec<String>,
    },
}

/// Compare the provenance of `tables_dir` with the spacecraft of `flown`.
#[must_use]
pub fn check(tables_dir: &Path, flown: &Scenario) -> Check {
    let path = tables_dir.join(PROVENANCE);
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Check::Missing,
        Err(e) => return Check::Unreadable(e.to_string()),
    };
    let p: Provenance = match serde_json::from_str(&text) {
        Ok(p) => p,
        Err(e) => return Check::Unreadable(e.to_string()),
    };
    let Some(source) = p.spacecraft else {
        return Check::Unknown {
            scenario: p.scenario,
        };
    };
    let flown_sc = match Spacecraft::of(flown) {
        Ok(s) => s,
        Err(e) => return Check::Unreadable(format!("{e:#}")),
    };
    if source.id == flown_sc.id {
        return Check::Same;
    }
    let parts = flown_sc
        .parts
        .iter()
        .filter(|(k, v)| source.parts.get(*k) != Some(*v))
        .map(|(k, _)| k.clone())
        .collect();
    Check::Different {
        scenario: p.scenario,
        source_id: source.id,
        flown_id: flown_sc.id,
        parts,
    }
}

impl Check {
    /// The message for the user, naming the file, the field and the cause; `None` when the
    /// tables were calibrated on the spacecraft flown.
    #[must_use]
    pub fn message(&self, tables_dir: &Path, flown: &Scenario) -> Option<String> {
        let file = tables_dir.join(PROVENANCE);
        let file = file.display();
        let name = |s: &Option<String>| {
            s.as_deref()
                .map_or("an undeclared scenario".to_owned(), |n| format!("`{n}`"))
        };
        let consequence = "this run's attitude error says nothing about these tables (README, \"Feeding your own telemetry\"): judge them on the data they were calibrated on";
        match self {
            Self::Same => None,
            Self::Missing => Some(format!(
                "note: --tables {}: no {PROVENANCE}, so whether these tables were calibrated on the spacecraft of `{}` cannot be checked (`ground-tool calibrate` and `diagnose` write one)",
                tables_dir.display(),
                flown.name
            )),
            Self::Unreadable(why) => Some(format!(
                "warning: {file} cannot be read ({why}): whether these tables were calibrated on the spacecraft of `{}` cannot be checked",
                flown.name
            )),
            Self::Unknown { scenario } => Some(format!(
                "warning: {file}: `spacecraft` is absent: these tables were calibrated on telemetry of {} that carries no simulator spacecraft identity (telemetry this simulator did not write, or a run from before it wrote one), so they may belong to another spacecraft than that of `{}` flown now; if so, {consequence}",
                name(scenario),
                flown.name
            )),
            Self::Different {
                scenario,
                source_id,
                flown_id,
                parts,
            } => Some(format!(
                "warning: {file}: `spacecraft.id` {source_id} (scenario {}) is not the spacecraft of `{}` flown now ({flown_id}): the true {} parameters differ, so the tables are not this spacecraft's and {consequence}",
                name(scenario),
                flown.name,
                parts.join(", ")
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_identity_follows_the_spacecraft_not_the_plan() {
        let a = crate::scenario::resolve("gro-early-mission").unwrap();
        let mut plan = a.clone();
        plan.duration_s = 600.0;
        plan.seed = 99;
        plan.name = "another plan".into();
        plan.commands.clear();
        plan.iru.time_since_release_at_start_s += 86_400.0;
        assert_eq!(Spacecraft::of(&a).unwrap(), Spacecraft::of(&plan).unwrap());
        // normal-ops is the same spacecraft 55 days later: its tables are the operations flow.
        let ops = crate::scenario::resolve("normal-ops").unwrap();
        assert_eq!(Spacecraft::of(&a).unwrap(), Spacecraft::of(&ops).unwrap());
        let mut other = a.clone();
        other.fhst2.misalignment_true_arcsec = Some([30.0, -20.0, 10.0]);
        let (sa, so) = (Spacecraft::of(&a).unwrap(), Spacecraft::of(&other).unwrap());
        assert_ne!(sa.id, so.id);
        let differ: Vec<&String> = sa
            .parts
            .iter()
            .filter(|(k, v)| so.parts.get(*k) != Some(*v))
            .map(|(k, _)| k)
            .collect();
        assert_eq!(differ, vec!["FHST2"]);
    }

    #[test]
    fn check_names_the_file_the_field_and_the_parts() {
        let dir = std::env::temp_dir().join(format!("provenance-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let early = crate::scenario::resolve("gro-early-mission").unwrap();
        let mut ops = crate::scenario::resolve("normal-ops").unwrap();
        // Another spacecraft: its FHST1 sits elsewhere and its gyro has other scale errors.
        ops.fhst1.misalignment_true_arcsec = Some([40.0, 0.0, -25.0]);
        ops.iru.channel_scale_ppm[0] = 150.0;
        // No file: a note, not a warning.
        assert_eq!(check(&dir, &early), Check::Missing);
        assert!(check(&dir, &early)
            .message(&dir, &early)
            .unwrap()
            .starts_with("note:"));
        // Calibrated on gro-early-mission's spacecraft.
        let meta = serde_json::json!({
            "scenario": "gro-early-mission",
            "seed": 1,
            "spacecraft": Spacecraft::of(&early).unwrap(),
        });
        write(&dir, Path::new("runs/a"), &meta, "test").unwrap();
        assert_eq!(check(&dir, &early), Check::Same);
        assert_eq!(check(&dir, &early).message(&dir, &early), None);
        assert_eq!(
            check(&dir, &crate::scenario::resolve("normal-ops").unwrap()),
            Check::Same
        );
        // Flown on the other spacecraft: the parts that differ are named.
        let c = check(&dir, &ops);
        let Check::Different { parts, .. } = &c else {
            panic!("{c:?}");
        };
        assert_eq!(parts, &["FHST1".to_owned(), "IRU".to_owned()]);
        let m = c.message(&dir, &ops).unwrap();
        assert!(m.starts_with("warning:"), "{m}");
        assert!(m.contains(PROVENANCE) && m.contains("spacecraft.id"), "{m}");
        assert!(
            m.contains("`gro-early-mission`") && m.contains("`normal-ops`"),
            "{m}"
        );
        assert!(m.contains("FHST1, IRU"), "{m}");
        // Telemetry the simulator did not write (no spacecraft in its metadata).
        write(
            &dir,
            Path::new("mine"),
            &serde_json::json!({"scenario": "mine"}),
            "t",
        )
        .unwrap();
        let c = check(&dir, &early);
        assert_eq!(
            c,
            Check::Unknown {
                scenario: Some("mine".into())
            }
        );
        assert!(c
            .message(&dir, &early)
            .unwrap()
            .contains("no simulator spacecraft identity"));
        // A damaged file.
        std::fs::write(dir.join(PROVENANCE), "{").unwrap();
        assert!(matches!(check(&dir, &early), Check::Unreadable(_)));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
