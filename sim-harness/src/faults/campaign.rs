//! # The fault campaign: fly each fault scenario with and without its faults, measure
//!
//! [`assess`] flies a scenario twice and reports what docs/reliability.md's fault table
//! shows ([`FaultReport`], [`markdown_table`]); [`shipped_fault_scenarios`] lists
//! `scenarios/faults/`. The faults themselves are [`super::model`].

use anyhow::bail;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::model::*;
use crate::closed_loop::{CycleRecord, Simulation};
use crate::scenario::Scenario;
use fsw_core::events::{Counters, EventId};
use fsw_core::tables::TableId;
use fsw_core::units::ARCSEC_PER_RAD;

/// The fine attitude requirement per axis (paper: 0.024° 3σ = 86.4″). [`assess`] counts the
/// OBC as recovered when every axis of every later cycle is inside it (stricter than 3σ).
pub const FINE_REQUIREMENT_ARCSEC: f64 = 86.4;

// ------------------------------------------------------------------------------------------
// Assessment: fly with and without the faults, measure.
// ------------------------------------------------------------------------------------------

/// What one fault scenario did (docs/reliability.md fault table).
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct FaultReport {
    /// Scenario name.
    pub scenario: String,
    /// Simulated seconds.
    pub duration_s: f64,
    /// First fault start (s).
    pub fault_start_s: f64,
    /// Last fault end (s; instantaneous faults end where they start).
    pub fault_end_s: f64,
    /// Largest per-axis `|δθ_i|` (arcsec) from the fault start to the recovery (or the end).
    pub worst_axis_error_arcsec: f64,
    /// Largest `|δθ|` (arcsec) over the same interval.
    pub worst_error_arcsec: f64,
    /// The same two figures over the same interval of the run without the faults.
    pub baseline_worst_axis_error_arcsec: f64,
    /// Largest per-axis `|δθ_i|` (arcsec) before the fault (from 600 s).
    pub pre_fault_worst_axis_error_arcsec: f64,
    /// How and when the attitude came back (report keys `recovered_at_s` …
    /// `fine_mode_regained_s`).
    #[serde(flatten)]
    pub recovery: Recovery,
    /// Largest `|δθ_i|` (arcsec) from the recovery to the end of the run.
    pub after_recovery_worst_axis_error_arcsec: f64,
    /// 3 × RMS per axis (arcsec) over the last 600 s of the run.
    pub final_three_rms_arcsec: [f64; 3],
    /// Events from the fault start to the end of the run: (name, count in the fault run,
    /// count in the run without faults).
    pub events: Vec<(String, u32, u32)>,
    /// Event names raised in the fault run more often than without the faults.
    pub fault_events: Vec<String>,
    /// OBC counters at the end of the fault run.
    pub counters: Counters,
    /// OBC counters at the end of the run without faults.
    pub baseline_counters: Counters,
    /// Whether the fault reached the active tables (report keys `table_crc_before` …
    /// `tables_activated`).
    #[serde(flatten)]
    pub tables: TableIntegrity,
    /// Largest `|δθ|` (arcsec) at the completion of each slew that ended after the fault start.
    pub post_slew_error_arcsec: Vec<f64>,
    /// Per-cycle trace (t, per-axis error arcsec, filter mode), for tests.
    #[serde(skip)]
    pub trace: Vec<(f64, [f64; 3], u8)>,
}

/// When the attitude came back within the requirement after a fault, against the same
/// flight without it.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct Recovery {
    /// First time ≥ the fault end from which every cycle to the end of the run has every axis
    /// within [`FINE_REQUIREMENT_ARCSEC`]; `None` = never.
    pub recovered_at_s: Option<f64>,
    /// `recovered_at_s − fault_end_s` (0 when the error never left the requirement).
    pub recovery_s: Option<f64>,
    /// The same for the run without the faults.
    pub baseline_recovery_s: Option<f64>,
    /// Time from the fault end to the first cycle in fine mode, if the filter left fine mode
    /// between the fault start and end (0 if it never left); `None` = never regained.
    pub fine_mode_regained_s: Option<f64>,
}

/// The active tables across a fault: a fault that only disturbs the sensors must leave them
/// as they were (docs/reliability.md fault table).
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct TableIntegrity {
    /// Active table CRCs just before the first fault, in [`TableId::ALL`]'s order.
    pub table_crc_before: [u32; TableId::ALL.len()],
    /// Active table CRCs at the end.
    pub table_crc_after: [u32; TableId::ALL.len()],
    /// Dumps of the active tables at the end equal to those just before the first fault.
    pub tables_unchanged: bool,
    /// `TableActivated` events at or after the fault start.
    pub tables_activated: u32,
}

struct Flight {
    trace: Vec<(f64, [f64; 3], u8)>,
    events: Vec<(f64, EventId)>,
    counters: Counters,
    crc_before: [u32; TableId::ALL.len()],
    crc_after: [u32; TableId::ALL.len()],
    dump_before: Vec<Vec<u8>>,
    dump_after: Vec<Vec<u8>>,
    slew_end_errors: Vec<(f64, f64)>,
}

fn dumps(sim: &Simulation) -> Vec<Vec<u8>> {
    let mut buf = vec![0_u8; 128 * 1024];
    TableId::ALL
        .iter()
        .map(|id| {
            sim.fsw()
                .tables()
                .dump(*id, &mut buf)
                .map_or_else(|_| Vec::new(), |n| buf[..n].to_vec())
        })
        .collect()
}

fn crcs(sim: &Simulation) -> [u32; TableId::ALL.len()] {
    sim.fsw().tables().status().map(|s| s.active_crc)
}

fn fly(scenario: Scenario, snapshot_at_s: f64) -> anyhow::Result<Flight> {
    let mut sim = Simulation::new(scenario, None)?;
    let mut f = Flight {
        trace: Vec::new(),
        events: Vec::new(),
        counters: Counters::default(),
        crc_before: [0; TableId::ALL.len()],
        crc_after: [0; TableId::ALL.len()],
        dump_before: Vec::new(),
        dump_after: Vec::new(),
        slew_end_errors: Vec::new(),
    };
    let mut snap = false;
    loop {
        if !snap && sim.t_s() + 1e-9 >= snapshot_at_s {
            f.crc_before = crcs(&sim);
            f.dump_before = dumps(&sim);
            snap = true;
        }
        let Some(rec): Option<CycleRecord> = sim.step() else {
            break;
        };
        let t = rec.truth.t_s;
        let e = rec.attitude_error_acs_rad * ARCSEC_PER_RAD;
        let hk = &rec.output.housekeeping;
        f.trace.push((t, [e.x, e.y, e.z], hk.filter_mode));
        f.counters = hk.counters;
        for ev in &rec.output.events {
            f.events.push((t, ev.id));
            if ev.id == EventId::SlewCompleted {
                f.slew_end_errors.push((t, e.norm()));
            }
        }
    }
    if !snap {
        f.crc_before = crcs(&sim);
        f.dump_before = dumps(&sim);
    }
    f.crc_after = crcs(&sim);
    f.dump_after = dumps(&sim);
    Ok(f)
}

fn worst_axis(trace: &[(f64, [f64; 3], u8)], from: f64, to: f64) -> (f64, f64) {
    trace
        .iter()
        .filter(|(t, _, m)| *t >= from && *t <= to && *m != 0)
        .fold((0.0_f64, 0.0_f64), |(a, n), (_, e, _)| {
            let axis = e.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
            (a.max(axis), n.max(Vector3::from(*e).norm()))
        })
}

/// First time ≥ `from` after which every cycle has every axis inside the requirement.
fn recovered_at(trace: &[(f64, [f64; 3], u8)], from: f64) -> Option<f64> {
    let mut candidate = None;
    for (t, e, mode) in trace.iter().filter(|(t, _, _)| *t >= from) {
        let ok = *mode != 0 && e.iter().all(|x| x.abs() < FINE_REQUIREMENT_ARCSEC);
        match (ok, candidate) {
            (true, None) => candidate = Some(*t),
            (false, _) => candidate = None,
            _ => {}
        }
    }
    candidate
}

/// Time from `from` to the first cycle in fine mode at or after it, if the filter was out of
/// fine mode at some point in `[start, from]`; `Some(0)` if it never left fine mode.
fn fine_mode_regained(trace: &[(f64, [f64; 3], u8)], start: f64, from: f64) -> Option<f64> {
    let left = trace
        .iter()
        .any(|(t, _, m)| *t >= start && *t <= from && *m != 2);
    if !left {
        return Some(0.0);
    }
    trace
        .iter()
        .find(|(t, _, m)| *t >= from && *m == 2)
        .map(|(t, _, _)| t - from)
}

fn event_name(id: EventId) -> String {
    format!("{id:?}")
}

/// Fly `scenario` with its faults and again without them, and measure (module doc,
/// [`FaultReport`]).
///
/// # Errors
/// A scenario without faults, or the simulator's errors.
pub fn assess(scenario: &Scenario) -> anyhow::Result<FaultReport> {
    if scenario.faults.is_empty() {
        bail!("{}: no [[faults]]", scenario.name);
    }
    let start = scenario
        .faults
        .iter()
        .map(|f| f.at_s)
        .fold(f64::INFINITY, f64::min);
    let end = scenario
        .faults
        .iter()
        .map(Fault::end_s)
        .fold(f64::NEG_INFINITY, f64::max);
    let faulty = fly(scenario.clone(), start)?;
    let mut clean_scenario = scenario.clone();
    clean_scenario.faults.clear();
    let clean = fly(clean_scenario, start)?;

    let recovered = recovered_at(&faulty.trace, end);
    let until = recovered.map_or(f64::INFINITY, |r| r.max(end));
    let (worst_axis_err, worst_err) = worst_axis(&faulty.trace, start, until);
    let (base_axis, _) = worst_axis(&clean.trace, start, until);
    let (pre, _) = worst_axis(&faulty.trace, crate::run::SCORE_START_S, start - 1e-9);
    let last = faulty.trace.last().map_or(0.0, |(t, _, _)| *t);
    let mut sumsq = [0.0; 3];
    let mut n = 0.0;
    for (_, e, _) in faulty.trace.iter().filter(|(t, _, _)| *t > last - 600.0) {
        for i in 0..3 {
            sumsq[i] += e[i] * e[i];
        }
        n += 1.0;
    }
    let final_three_rms = sumsq.map(|s| if n > 0.0 { 3.0 * (s / n).sqrt() } else { 0.0 });

    let count = |events: &[(f64, EventId)], id: EventId| -> u32 {
        let n = events
            .iter()
            .filter(|(t, e)| *t + 1e-9 >= start && *e == id)
            .count();
        u32::try_from(n).unwrap_or(u32::MAX)
    };
    let mut events = Vec::new();
    let mut fault_events = Vec::new();
    for id in EventId::ALL {
        let (a, b) = (count(&faulty.events, id), count(&clean.events, id));
        if a > 0 || b > 0 {
            events.push((event_name(id), a, b));
        }
        if a > b {
            fault_events.push(event_name(id));
        }
    }
    Ok(FaultReport {
        scenario: scenario.name.clone(),
        duration_s: scenario.duration_s,
        fault_start_s: start,
        fault_end_s: end,
        worst_axis_error_arcsec: worst_axis_err,
        worst_error_arcsec: worst_err,
        baseline_worst_axis_error_arcsec: base_axis,
        pre_fault_worst_axis_error_arcsec: pre,
        recovery: Recovery {
            recovered_at_s: recovered,
            recovery_s: recovered.map(|r| (r - end).max(0.0)),
            baseline_recovery_s: recovered_at(&clean.trace, end).map(|r| (r - end).max(0.0)),
            fine_mode_regained_s: fine_mode_regained(&faulty.trace, start, end),
        },
        after_recovery_worst_axis_error_arcsec: recovered
            .map_or(f64::NAN, |r| worst_axis(&faulty.trace, r, f64::INFINITY).0),
        final_three_rms_arcsec: final_three_rms,
        events,
        fault_events,
        counters: faulty.counters,
        baseline_counters: clean.counters,
        tables: TableIntegrity {
            table_crc_before: faulty.crc_before,
            table_crc_after: faulty.crc_after,
            tables_unchanged: faulty.dump_before == faulty.dump_after,
            tables_activated: count(&faulty.events, EventId::TableActivated),
        },
        post_slew_error_arcsec: faulty
            .slew_end_errors
            .iter()
            .filter(|(t, _)| *t >= start)
            .map(|(_, e)| *e)
            .collect(),
        trace: faulty.trace,
    })
}

/// Every `scenarios/faults/*.toml` of the workspace, sorted.
///
/// # Errors
/// The folder cannot be read.
pub fn shipped_fault_scenarios() -> anyhow::Result<Vec<std::path::PathBuf>> {
    let dir = crate::scenario::scenarios_dir().join("faults");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .map_err(|e| anyhow::anyhow!("{}: {e}", dir.display()))?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    Ok(files)
}

fn fmt_opt(v: Option<f64>) -> String {
    v.map_or_else(|| "never".to_owned(), |x| format!("{x:.0}"))
}

/// The docs/reliability.md fault table.
#[must_use]
pub fn markdown_table(reports: &[FaultReport]) -> String {
    let mut out = String::from(
        "| scenario | fault window (s) | worst axis error, fault start → recovery (″) | same interval, no fault (″) | back inside 86.4″/axis after the fault end (s) | fine mode regained after the fault end (s) | 3×RMS per axis, bias included, last 600 s (″) | events raised (fault run / no-fault run, from the fault start) | tables |\n|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in reports {
        let events = r
            .events
            .iter()
            .filter(|(n, _, _)| r.fault_events.contains(n))
            .map(|(n, a, b)| format!("{n} {a}/{b}"))
            .collect::<Vec<_>>()
            .join(", ");
        let tables = if r.tables.tables_unchanged {
            "unchanged".to_owned()
        } else {
            format!("changed ({} activated)", r.tables.tables_activated)
        };
        let [a, b, c] = r.final_three_rms_arcsec;
        let recovery = format!(
            "{} (no fault: {})",
            fmt_opt(r.recovery.recovery_s),
            fmt_opt(r.recovery.baseline_recovery_s)
        );
        out +=
            &format!(
            "| {} | {:.0}–{:.0} | {:.1} | {:.1} | {} | {} | {a:.1} / {b:.1} / {c:.1} | {} | {} |\n",
            r.scenario,
            r.fault_start_s,
            r.fault_end_s,
            r.worst_axis_error_arcsec,
            r.baseline_worst_axis_error_arcsec,
            recovery,
            fmt_opt(r.recovery.fine_mode_regained_s),
            if events.is_empty() { "none".to_owned() } else { events },
            tables
        );
    }
    out
}
