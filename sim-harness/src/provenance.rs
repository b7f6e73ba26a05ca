//! # The simulator's side of `tables/provenance.json`: its spacecraft's identity and the check
//! of `--tables` against the scenario flown
//!
//! The file format, the identity and the writer are shared with the ground
//! ([`gro_reference::provenance`], module docs there: why, and why a warning and not a
//! refusal).

use std::path::Path;

pub use gro_reference::provenance::{
    write, Provenance, Spacecraft, FORMAT, PROVENANCE, STATE_KEYS,
};

use crate::scenario::Scenario;

/// The identity of the spacecraft `s` simulates: its sensors and gyro (what the tables
/// calibrate), not its plan, epoch, duration, seed or state at the start.
///
/// # Errors
/// A part that does not serialise (a defect).
pub fn spacecraft_of(s: &Scenario) -> anyhow::Result<Spacecraft> {
    Spacecraft::of_parts(vec![
        ("FHST1", serde_json::to_value(&s.fhst1)?),
        ("FHST2", serde_json::to_value(&s.fhst2)?),
        ("FSS1", serde_json::to_value(&s.fss1)?),
        ("FSS2", serde_json::to_value(&s.fss2)?),
        ("IRU", serde_json::to_value(&s.iru)?),
    ])
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
    let flown_sc = match spacecraft_of(flown) {
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
        assert_eq!(spacecraft_of(&a).unwrap(), spacecraft_of(&plan).unwrap());
        // normal-ops is the same spacecraft 55 days later: its tables are the operations flow.
        let ops = crate::scenario::resolve("normal-ops").unwrap();
        assert_eq!(spacecraft_of(&a).unwrap(), spacecraft_of(&ops).unwrap());
        let mut other = a.clone();
        other.fhst2.misalignment_true_arcsec = Some([30.0, -20.0, 10.0]);
        let (sa, so) = (spacecraft_of(&a).unwrap(), spacecraft_of(&other).unwrap());
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
        let meta = gro_reference::run_folder::Metadata {
            scenario: "gro-early-mission".into(),
            seed: Some(1),
            spacecraft: Some(spacecraft_of(&early).unwrap()),
            ..Default::default()
        };
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
            &gro_reference::run_folder::Metadata {
                scenario: "mine".into(),
                ..Default::default()
            },
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
