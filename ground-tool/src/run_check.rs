//! # Run-folder check against the ICD (`docs/icd.md`), before calibrate and diagnose
//!
//! The calibration chain takes decoded telemetry at its word: time codes are the time, a
//! counter that does not move is a stuck gyro, a frame without an orbit has no orbital
//! aberration. Telemetry written by another program can be well formed and still break one of
//! the ICD's rules in a way that would give a quietly wrong answer. This module looks for those
//! cases (`docs/icd-conformance.md` lists how each was found) and says what is wrong and what
//! would fix it:
//!
//! * **errors** (exit code 2): no raw frame at all (with what the reader found instead), time
//!   codes that are not TAI since 1958 (mission elapsed time), time codes that disagree with
//!   `metadata.json`'s `epoch_utc`, a block of packets whose time codes jump back while the
//!   packet sequence continues (`time_code_jump`);
//! * **warnings** for packets dropped for an isolated damaged time code (`time_code_outliers`,
//!   with their offsets);
//! * **warnings**: frames without an orbit, a sensor never usable (flags), an IRU channel
//!   unchanged long enough to be declared stuck, slews without high-rate frames, gaps, damage
//!   the reader repaired, housekeeping that matches no raw frame.

use crate::pipeline::observations::interpolate_orbit;
use crate::tp::Telemetry;
use fsw_core::raw::{FHST_FLAG_TRACKING, FHST_FLAG_VALID, FSS_FLAG_SUN_ALPHA, FSS_FLAG_SUN_BETA};
use fsw_core::tables::IruTable;
use gro_reference::run_folder::Metadata;
use serde::Serialize;

/// TAI seconds since 1958 of 1972-01-01: earlier time codes are taken for mission elapsed
/// time (no spacecraft of this ICD flew before UTC had leap seconds).
const EARLIEST_PLAUSIBLE_TAI1958_S: f64 = 5113.0 * 86_400.0;

/// Largest |first frame − epoch_utc| accepted, after TAI − UTC (0–37 s), s. The Sun moves
/// 0.041°/h: 600 s is 25″, the size of the FSS noise; beyond it the Sun reference is wrong.
const EPOCH_ERROR_S: f64 = 600.0;

/// |first frame − epoch_utc| beyond TAI − UTC that only earns a warning, s.
const EPOCH_WARNING_S: f64 = 60.0;

/// A gap is a step between raw frames longer than this many median cycle periods.
const GAP_CYCLES: f64 = 3.0;

/// Rotation (deg) in low-rate frames above which missing high-rate frames are reported.
const LOW_RATE_SLEW_DEG: f64 = 5.0;

/// How bad a finding is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum Severity {
    /// The run cannot give a meaningful result: exit code 2.
    Error,
    /// The result is usable but something is missing or was repaired.
    Warning,
}

/// One finding of the check.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Finding {
    /// Error or warning.
    pub severity: Severity,
    /// Short stable name (tests and scripts key on it).
    pub code: &'static str,
    /// What is wrong and what would fix it.
    pub message: String,
}

/// An input that breaks the ICD so that no meaningful result can be computed (exit code 2):
/// one type for every binary of the workspace ([`gro_reference::exit_code`]).
pub use gro_reference::InputError;

/// Check the declared figures of `metadata.json` against their physical ranges: the FHST and
/// FSS 1σ figures finite and > 0 (they are measurement weights); the gyro's random walks,
/// `fss_systematic_arcsec` and every transfer-function spread finite and ≥ 0 (zero is "no
/// such error": a noiseless gyro, as the ICD writer's `--quiet-iru` declares).
///
/// Why: a negative or zero σ turns the weights of FFCAL, the bias filter and IRUCAL into
/// garbage without any error (`iru_arw_rad_per_sqrt_s: -1` gave a garbage bias with exit 0).
///
/// # Errors
/// [`InputError`] naming the first offending field, its value and the range.
pub fn validate_metadata(path: &std::path::Path, m: &Metadata) -> Result<(), InputError> {
    let n = &m.sensors;
    let positive = [
        ("sensors.fhst_sigma_arcsec[0]", n.fhst_sigma_arcsec[0]),
        ("sensors.fhst_sigma_arcsec[1]", n.fhst_sigma_arcsec[1]),
        ("sensors.fss_sigma_arcsec", n.fss_sigma_arcsec),
    ];
    let non_negative = [
        ("sensors.iru_arw_rad_per_sqrt_s", n.iru_arw_rad_per_sqrt_s),
        (
            "sensors.fss_systematic_arcsec",
            n.fss_systematic_or_paper_arcsec(),
        ),
        (
            "sensors.iru_rrw_rad_per_s_sqrt_s",
            n.iru_rrw_rad_per_s_sqrt_s,
        ),
    ];
    let bad = |field: &str, v: f64, range: &str| {
        InputError::msg(format!(
            "{}: {field} = {v} is not a possible value ({range}; docs/icd.md §5): fix the declared noise figure",
            path.display()
        ))
    };
    for (field, v) in positive {
        if !(v.is_finite() && v > 0.0) {
            return Err(bad(field, v, "a 1σ figure must be finite and > 0"));
        }
    }
    for (field, v) in non_negative {
        if !(v.is_finite() && v >= 0.0) {
            return Err(bad(field, v, "must be finite and ≥ 0"));
        }
    }
    upload_table_names(path, m)?;
    if let Some(spreads) = &m.fss_transfer_function_sigma {
        // Every number of the spreads, by its JSON path.
        if let Ok(tree) = serde_json::to_value(spreads) {
            let mut stack = vec![("fss_transfer_function_sigma".to_owned(), &tree)];
            while let Some((p, v)) = stack.pop() {
                match v {
                    serde_json::Value::Object(o) => {
                        stack.extend(o.iter().map(|(k, x)| (format!("{p}.{k}"), x)));
                    }
                    serde_json::Value::Number(x) => {
                        let x = x.as_f64().unwrap_or(f64::NAN);
                        if !(x.is_finite() && x >= 0.0) {
                            return Err(bad(&p, x, "a 1σ spread must be finite and ≥ 0"));
                        }
                    }
                    _ => {}
                }
            }
        }
    }
    Ok(())
}

fn warn(code: &'static str, message: String) -> Finding {
    Finding {
        severity: Severity::Warning,
        code,
        message,
    }
}

fn error(code: &'static str, message: String) -> Finding {
    Finding {
        severity: Severity::Error,
        code,
        message,
    }
}

/// UTC date and time of TAI seconds since 1958 (leap seconds ignored: for messages only).
fn date_of(tai1958_s: f64) -> String {
    let days = (tai1958_s / 86_400.0).floor();
    // Civil date from days since 1958-01-01 (= day 4383 before 1970-01-01).
    let z = days as i64 - 4383 + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    let sod = tai1958_s - days * 86_400.0;
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02.0}",
        (sod / 3600.0).floor(),
        ((sod % 3600.0) / 60.0).floor(),
        (sod % 60.0).floor()
    )
}

/// Seconds since 1958-01-01 of an ISO 8601 UTC date `YYYY-MM-DDTHH:MM:SS[.f][Z]`, without leap
/// seconds (so TAI − this = TAI − UTC, 0–37 s, for a consistent file).
fn utc_naive_1958_s(text: &str) -> Option<f64> {
    let t = text.trim().trim_end_matches('Z').trim_end_matches(" UTC");
    let (date, clock) = t.split_once(['T', ' '])?;
    let mut d = date.split('-').map(str::parse::<i64>);
    let (y, m, day) = (d.next()?.ok()?, d.next()?.ok()?, d.next()?.ok()?);
    let mut c = clock.split(':');
    let hh: f64 = c.next()?.parse().ok()?;
    let mi: f64 = c.next()?.parse().ok()?;
    let ss: f64 = c.next().unwrap_or("0").parse().ok()?;
    if !(1..=12).contains(&m) || !(1..=31).contains(&day) {
        return None;
    }
    let days_from_civil = |y: i64, m: i64, d: i64| -> i64 {
        let y = if m <= 2 { y - 1 } else { y };
        let era = y.div_euclid(400);
        let yoe = y - era * 400;
        let doy = (153 * (m + if m > 2 { -3 } else { 9 }) + 2) / 5 + d - 1;
        era * 146_097 + yoe * 365 + yoe / 4 - yoe / 100 + doy
    };
    let days = days_from_civil(y, m, day) - days_from_civil(1958, 1, 1);
    Some(days as f64 * 86_400.0 + hh * 3600.0 + mi * 60.0 + ss)
}

/// Every upload names a table of the OBC: an upload of an unknown table (`"aligment"`) would
/// be skipped when the flown tables are looked up, and the run calibrated against the boot
/// table with no word.
fn upload_table_names(path: &std::path::Path, m: &Metadata) -> Result<(), InputError> {
    use fsw_core::tables::TableId;
    for (i, u) in m.uploads.iter().enumerate() {
        if !TableId::ALL.iter().any(|id| id.name() == u.table) {
            let names: Vec<&str> = TableId::ALL.iter().map(|id| id.name()).collect();
            return Err(InputError::msg(format!(
                "{}: uploads[{i}].table = {:?} is not a table of the OBC ({}; docs/icd.md §5): the flown tables cannot be known; fix the name",
                path.display(),
                u.table,
                names.join(", ")
            )));
        }
    }
    Ok(())
}

/// What `metadata.json` holds that the ground does not use: keys outside the format (a
/// misspelt key leaves its figure at the default) and declared effects the ground's model
/// does not hold (a misspelt name leaves the effect out of the model). Warnings: the run is
/// still analysed, as the file says.
fn metadata_findings(m: &Metadata, out: &mut Vec<Finding>) {
    if !m.unknown_keys.is_empty() {
        out.push(warn(
            "metadata_unknown_keys",
            format!(
                "metadata.json: {} key(s) are not part of the format and were ignored (their figures keep the defaults; docs/icd.md §5): {}",
                m.unknown_keys.len(),
                m.unknown_keys.join(", ")
            ),
        ));
    }
    let unmodelled: Vec<String> = m
        .declared()
        .into_iter()
        .filter(|d| !crate::diagnose::effects::declared_name_is_modelled(d))
        .collect();
    if !unmodelled.is_empty() {
        out.push(warn(
            "metadata_unknown_effects",
            format!(
                "metadata.json: declared_effects {} change nothing in the ground's model (not an effect of docs/diagnose.md's library nor one of {}); a misspelt name leaves its effect out of the model",
                unmodelled.join(", "),
                crate::diagnose::effects::CHAIN_DECLARED_EFFECTS.join(", ")
            ),
        ));
    }
}

/// A table the ground takes as flown, for the cross-check against the CRCs the housekeeping
/// reports ([`flown_table_findings`]; built by `pipeline::flown::assumed_tables`).
#[derive(Clone, Debug, PartialEq)]
pub struct AssumedTable {
    /// Which table.
    pub id: fsw_core::tables::TableId,
    /// CRC-32 of its image (the image's trailer, as the OBC reports it once active); `None`
    /// = the boot table (the OBC reports 0).
    pub image_crc: Option<u32>,
    /// Its content is the boot table's (an image of the boot table is flown as the boot
    /// table: the OBC then reports 0).
    pub equals_boot: bool,
    /// Where the ground took it from (a file, or "the boot table").
    pub source: String,
}

impl AssumedTable {
    /// Whether the OBC reporting `crc` as its active table is consistent with this one.
    fn matches(&self, crc: u32) -> bool {
        self.image_crc == Some(crc) || (crc == 0 && self.equals_boot)
    }
}

/// The tables the ground takes as flown against the ones the OBC reported active in its
/// housekeeping (docs/icd.md §3.2, octet 213: CRC-32 of the active alignment, IRU, filter and
/// star-catalog images, 0 = boot). Why: the calibration's corrections are relative to the
/// flown tables; a `--tables` folder or an upload list that is not what the OBC flew gives a
/// wrong table with no error. An error when the last housekeeping packet's CRC differs from
/// the assumed table's (a warning when `trust`: the operator's what-if, `--trust-tables`); a warning when the OBC switched that table during the run (the
/// ground takes the last one for the whole run). Nothing to compare without housekeeping.
#[must_use]
pub fn flown_table_findings(tm: &Telemetry, assumed: &[AssumedTable], trust: bool) -> Vec<Finding> {
    let mut out = Vec::new();
    let Some(last) = tm.housekeeping.last() else {
        if !assumed.is_empty() {
            let list: Vec<String> = assumed
                .iter()
                .map(|a| format!("{} ({})", a.id.name(), a.source))
                .collect();
            out.push(warn(
                "flown_tables_unverified",
                format!(
                    "telemetry.bin has no housekeeping (APID 0x011): the tables the ground takes as flown cannot be checked against the ones the OBC reported active: {}",
                    list.join(", ")
                ),
            ));
        }
        return out;
    };
    let t0 = tm
        .raw
        .first()
        .map_or_else(|| last.time.seconds(), |r| r.time.seconds());
    let t_last = last.time.seconds() - t0;
    for a in assumed {
        let Some(k) = (a.id as usize).checked_sub(1).filter(|k| *k < 4) else {
            continue;
        };
        let reported = last.table_crc[k];
        if a.matches(reported) {
            out.extend(table_switched(tm, a, k, t0));
        } else {
            out.push(table_mismatch(a, reported, t_last, trust));
        }
    }
    out
}

/// The OBC reported another table active (at `t_last`, s after the first raw frame) than the
/// one the ground takes as flown: an error, or a warning when `trust` (a what-if).
fn table_mismatch(a: &AssumedTable, reported: u32, t_last: f64, trust: bool) -> Finding {
    let severity = if trust { warn } else { error };
    severity(
        "flown_table_mismatch",
        format!(
            "the OBC's active {} table had CRC-32 0x{reported:08x} in the last housekeeping packet ({t_last:.0} s after the first raw frame{}), but the ground takes as flown {} ({}): calibrating against it would give corrections relative to a table the OBC did not fly. Give the flown tables with --tables DIR, or correct metadata.json `uploads` (for a what-if against tables given with --tables, add --trust-tables)",
            a.id.name(),
            if reported == 0 { "; 0 = the boot table" } else { "" },
            a.source,
            a.image_crc
                .map_or_else(|| "the boot table, 0".to_owned(), |c| format!("CRC-32 0x{c:08x}")),
        ),
    )
}

/// The OBC switched table `a` (housekeeping slot `k`) during the run: the ground takes the
/// last one for the whole run, which the warning says with the packets that disagree.
fn table_switched(tm: &Telemetry, a: &AssumedTable, k: usize, t0: f64) -> Option<Finding> {
    let reported = tm.housekeeping.last()?.table_crc[k];
    let other = tm
        .housekeeping
        .iter()
        .filter(|h| h.table_crc[k] != reported)
        .count();
    let switched = tm
        .housekeeping
        .iter()
        .rev()
        .find(|h| h.table_crc[k] != reported)?
        .time
        .seconds()
        - t0;
    Some(warn(
        "flown_table_changed",
        format!(
            "the OBC's active {} table changed during the run: {other} of {} housekeeping packets (the last at {switched:.0} s after the first raw frame) report another table than the last; the ground takes the last one, {}, for the whole run",
            a.id.name(),
            tm.housekeeping.len(),
            a.source
        ),
    ))
}

/// Check a decoded run (`metadata`: the parsed `metadata.json`, if any).
#[must_use]
pub fn check(tm: &Telemetry, metadata: Option<&Metadata>) -> Vec<Finding> {
    let mut out = Vec::new();
    let r = &tm.report;
    // 1. What the reader repaired or dropped; a jump of the time codes stops the check.
    reader_findings(r, &mut out);
    if let Some(f) = time_code_jump(r) {
        out.push(f);
        return out;
    }
    // 2. Raw frames, with TAI-1958 time codes and the metadata's epoch.
    let Some(first) = tm.raw.first() else {
        out.push(no_raw_frames(r));
        return out;
    };
    let t0 = first.time.seconds();
    if let Some(f) = time_codes_not_tai1958(t0) {
        out.push(f);
        return out;
    }
    epoch_findings(t0, metadata, &mut out);
    if let Some(m) = metadata {
        metadata_findings(m, &mut out);
    }
    // 3. Orbit coverage, sensors, the IRU, gaps, housekeeping.
    orbit_coverage(tm, &mut out);
    unusable_sensors(tm, &mut out);
    let backup = tm.housekeeping.first().is_some_and(|h| h.iru_config == 1);
    let active: [usize; 3] = if backup { [0, 3, 5] } else { [1, 2, 4] };
    iru_findings(tm, t0, active, &mut out);
    gap_findings(tm, t0, active, &mut out);
    housekeeping_findings(tm, &mut out);
    out
}

/// What the reader repaired (skipped regions, duplicates, time reversals) and the packets it
/// dropped for a damaged time code.
fn reader_findings(r: &crate::tp::TpReport, out: &mut Vec<Finding>) {
    if !r.skipped.is_empty()
        || !r.duplicates.is_empty()
        || !r.time_reversals.is_empty()
        || !r.duplicate_conflicts.is_empty()
    {
        let first = r
            .skipped
            .first()
            .map(|s| format!(" (first at offset {}: {})", s.offset, s.reason))
            .unwrap_or_default();
        let retimed = r
            .retimed_copies
            .first()
            .map(|(at, t, t0)| {
                format!(
                    " ({} of them copies of an earlier packet under another time code, the first at offset {at}: {:+.3} s from its original)",
                    r.retimed_copies.len(),
                    t - t0
                )
            })
            .unwrap_or_default();
        out.push(warn(
            "telemetry_repaired",
            format!(
                "telemetry.bin: {} region(s) skipped, {} octets{first}; {} duplicated packet(s) dropped{retimed}; {} packet(s) sharing APID, sequence count and time with different content kept; {} time reversal(s), records re-sorted by time",
                r.skipped.len(),
                r.skipped_octets(),
                r.duplicates.len(),
                r.duplicate_conflicts.len(),
                r.time_reversals.len()
            ),
        ));
    }
    if !r.time_outliers.is_empty() {
        let list: Vec<String> = r
            .time_outliers
            .iter()
            .take(10)
            .map(|o| {
                format!(
                    "offset {} (APID 0x{:03x}, time code {:.0} s between {:.0} and {:.0} s)",
                    o.offset, o.apid, o.time_s, o.neighbours_s.0, o.neighbours_s.1
                )
            })
            .collect();
        out.push(warn(
            "time_code_outliers",
            format!(
                "telemetry.bin: {} packet(s) dropped for a damaged time code (in sequence with their neighbours but far from both in time): {}{} (docs/icd.md §4)",
                r.time_outliers.len(),
                list.join("; "),
                if r.time_outliers.len() > 10 { "; …" } else { "" }
            ),
        ));
    }
}

/// A block of packets whose time codes jump back while the sequence continues: an error.
fn time_code_jump(r: &crate::tp::TpReport) -> Option<Finding> {
    let j = r.time_jumps.first()?;
    Some(error(
        "time_code_jump",
        format!(
            "telemetry.bin: at offset {} the time codes of APID 0x{:03x} jump back by {:.0} s ({} → {} TAI) while the packet sequence continues ({} such jump(s) in all): a block of packets carries shifted time codes (a clock reset or a time-stamping error), not a few reordered packets; sorting by time would interleave two stretches of flight into one wrong timeline. Correct the time codes of the packets from offset {} on, or cut the file there and calibrate each part separately (docs/icd.md §4)",
            j.offset,
            j.apid,
            j.from_s - j.to_s,
            date_of(j.from_s),
            date_of(j.to_s),
            r.time_jumps.len(),
            j.offset
        ),
    ))
}

/// No raw sensor frame at all: an error naming what the reader found instead.
fn no_raw_frames(r: &crate::tp::TpReport) -> Finding {
    let mut reasons: Vec<&str> = r.skipped.iter().map(|s| s.reason.as_str()).collect();
    reasons.dedup();
    reasons.truncate(3);
    error(
        "no_raw_frames",
        format!(
            "telemetry.bin ({} octets) holds no raw sensor frame (APID 0x010: a 60-octet packet, 6 octets primary header with version 0, type TM, secondary header flag 1 + 6 octets CUC time + 48 octets user data, docs/icd.md §2–3.1); the reader decoded {} housekeeping, {} event and {} ephemeris packets and skipped {} octets{}",
            r.file_len,
            r.packets.housekeeping,
            r.packets.event,
            r.packets.ephemeris,
            r.skipped_octets(),
            if reasons.is_empty() {
                String::new()
            } else {
                format!(" ({})", reasons.join("; "))
            }
        ),
    )
}

/// Time codes that are not TAI seconds since 1958 (a run-relative clock): an error.
fn time_codes_not_tai1958(t0: f64) -> Option<Finding> {
    (t0 < EARLIEST_PLAUSIBLE_TAI1958_S).then(|| {
        error(
            "time_codes_not_tai1958",
            format!(
                "the first raw frame's time code is {t0:.0} s, i.e. {} TAI: time codes are TAI seconds since 1958-01-01T00:00:00 TAI (docs/icd.md §2), not seconds since the start of the run; the Sun and the stars are placed from them. Add the TAI seconds of the run start (e.g. 1991-04-09T00:00:00 UTC = 1049846426 s)",
                date_of(t0)
            ),
        )
    })
}

/// The metadata's `epoch_utc` against the first raw frame's time code.
fn epoch_findings(t0: f64, metadata: Option<&Metadata>, out: &mut Vec<Finding>) {
    if let Some(epoch) = metadata.and_then(|m| m.epoch_utc.as_deref()) {
        match utc_naive_1958_s(epoch) {
            None => out.push(warn(
                "epoch_utc_unreadable",
                format!("metadata.json epoch_utc `{epoch}` is not an ISO 8601 UTC time (YYYY-MM-DDTHH:MM:SSZ): not checked against the time codes"),
            )),
            Some(e) => {
                // TAI − UTC is 0..37 s: the difference beyond that range is the disagreement.
                let d = t0 - e;
                let beyond = if d < 0.0 {
                    -d
                } else if d > 37.0 {
                    d - 37.0
                } else {
                    0.0
                };
                let msg = format!(
                    "the first raw frame is at {} TAI but metadata.json epoch_utc is {epoch} ({d:+.0} s; TAI − UTC is 0–37 s): epoch_utc is the UTC of the first raw frame and the time codes are TAI seconds since 1958 (docs/icd.md §2, §5); a time error moves the Sun by 0.041°/h. Fix the time codes or epoch_utc",
                    date_of(t0)
                );
                if beyond > EPOCH_ERROR_S {
                    out.push(error("epoch_mismatch", msg));
                } else if beyond > EPOCH_WARNING_S {
                    out.push(warn("epoch_mismatch", msg));
                }
            }
        }
    }
}

/// Raw frames without an orbit (ephemeris records too far apart).
fn orbit_coverage(tm: &Telemetry, out: &mut Vec<Finding>) {
    let n = tm.raw.len();
    // Orbit coverage.
    if !tm.ephemeris.is_empty() {
        let without = tm
            .raw
            .iter()
            .filter(|f| interpolate_orbit(&tm.ephemeris, f.time.seconds()).is_none())
            .count();
        if without > 0 {
            let widest = tm
                .ephemeris
                .windows(2)
                .map(|w| w[1].time.seconds() - w[0].time.seconds())
                .fold(0.0_f64, f64::max);
            out.push(warn(
                "orbit_missing",
                format!(
                    "{without} of {n} raw frames have no orbit (ephemeris records up to {widest:.0} s apart; the ground interpolates between records ≤ 600 s apart and extrapolates ≤ 60 s past the last): orbital aberration (≤ 5″) and Sun parallax (≤ 9″) are not corrected there; write APID 0x020 at least every 60 s covering the whole run (docs/icd.md §3.4)"
                ),
            ));
        }
    }
}

/// Sensors with no usable sample in the whole run.
fn unusable_sensors(tm: &Telemetry, out: &mut Vec<Finding>) {
    let n = tm.raw.len();
    // Sensors never usable.
    let names = ["FHST1", "FHST2", "FSS1", "FSS2"];
    for (i, name) in names.iter().enumerate() {
        let (usable, partial) = tm.raw.iter().fold((0usize, 0usize), |(u, p), f| {
            let flags = if i < 2 {
                f.fhst.get(i).map_or(0, |s| s.flags)
            } else {
                f.fss.get(i - 2).map_or(0, |s| s.flags)
            };
            let both = if i < 2 {
                FHST_FLAG_VALID | FHST_FLAG_TRACKING
            } else {
                FSS_FLAG_SUN_ALPHA | FSS_FLAG_SUN_BETA
            };
            let bits = flags & both;
            (
                u + usize::from(bits == both),
                p + usize::from(bits != 0 && bits != both),
            )
        });
        if usable == 0 {
            let need = if i < 2 {
                "flags bit0 (valid) and bit1 (tracking)"
            } else {
                "flags bit0 and bit1 (Sun present on both heads)"
            };
            let extra = if partial > 0 {
                format!(" ({partial} frames have only one of the two bits)")
            } else {
                String::new()
            };
            out.push(warn(
                "sensor_never_usable",
                format!(
                    "{name} has no usable sample in {n} raw frames: the ground uses a sample only with {need} set{extra} (docs/icd.md §3.1); {name} is not calibrated"
                ),
            ));
        }
    }
}

/// IRU: stuck channels of the `active` configuration, and slews without high-rate frames.
fn iru_findings(tm: &Telemetry, t0: f64, active: [usize; 3], out: &mut Vec<Finding>) {
    let channel = ["X1", "X2", "Y1", "Y2", "Z1", "Z2"];
    let stuck_cycles = usize::from(IruTable::prelaunch().stuck_cycles);
    for &c in &active {
        let mut run = 0usize;
        let mut longest = (0usize, 0.0_f64);
        for w in tm.raw.windows(2) {
            let same = w[0].iru.counts.get(c) == w[1].iru.counts.get(c);
            run = if same { run + 1 } else { 0 };
            if run > longest.0 {
                longest = (run, w[1].time.seconds() - t0);
            }
        }
        if longest.0 >= stuck_cycles {
            out.push(warn(
                "iru_channel_unchanged",
                format!(
                    "IRU channel {} counter unchanged for {} consecutive frames (to t = {:.0} s): the integrator declares a channel stuck after {stuck_cycles} unchanged cycles and leaves its axis out, so gyro propagation and the bias estimate lose that axis; a real gyro's counter moves with bias and noise every few cycles (docs/icd.md §3.1, IRU)",
                    channel[c], longest.0, longest.1
                ),
            ));
        }
    }
    let iru = IruTable::prelaunch();
    let high = tm.raw.iter().filter(|f| f.iru.high_rate).count();
    if high == 0 {
        let turned_deg: f64 = tm
            .raw
            .windows(2)
            .map(|w| {
                let d: Vec<f64> = active
                    .iter()
                    .map(|&c| {
                        let a = w[0].iru.counts.get(c).copied().unwrap_or(0);
                        let b = w[1].iru.counts.get(c).copied().unwrap_or(0);
                        #[allow(clippy::cast_possible_wrap)]
                        let dn = b.wrapping_sub(a) as i16;
                        f64::from(dn) * iru.low_rate_arcsec_per_pulse
                    })
                    .collect();
                d.iter().map(|x| x * x).sum::<f64>().sqrt() / 3600.0
            })
            .sum();
        if turned_deg > LOW_RATE_SLEW_DEG {
            out.push(warn(
                "no_high_rate_frames",
                format!(
                    "the gyro turned {turned_deg:.0}° but no raw frame has IRU rate mode 1 (high): calibrate finds IRU calibration maneuvers as runs of high-rate frames, so IRUCAL has none; give them with `calibrate --maneuver START:END` (s since the first frame) or write the rate mode of the slews as 1 (docs/icd.md §3.1)"
                ),
            ));
        }
    }
}

/// Gaps in the raw frames, and gaps across which the gyro counter difference has wrapped.
fn gap_findings(tm: &Telemetry, t0: f64, active: [usize; 3], out: &mut Vec<Finding>) {
    // Gaps: longer than GAP_CYCLES median frame spacings.
    if let Some(median) = crate::calibration::allan::median_spacing_s(tm) {
        let gaps: Vec<(f64, f64)> = tm
            .raw
            .windows(2)
            .filter_map(|w| {
                let d = w[1].time.seconds() - w[0].time.seconds();
                (d > GAP_CYCLES * median).then_some((w[0].time.seconds() - t0, d))
            })
            .collect();
        // A gap whose neighbouring frames count fast enough to pass 32767 pulses over it.
        let pulses_per_s = |i: usize| -> f64 {
            let (Some(a), Some(b)) = (tm.raw.get(i), tm.raw.get(i + 1)) else {
                return 0.0;
            };
            let dt = b.time.seconds() - a.time.seconds();
            active
                .iter()
                .map(|&c| {
                    let (x, y) = (a.iru.counts[c], b.iru.counts[c]);
                    #[allow(clippy::cast_possible_wrap)]
                    let dn = y.wrapping_sub(x) as i16;
                    f64::from(dn).abs() / dt.max(1e-9)
                })
                .fold(0.0, f64::max)
        };
        for (k, w) in tm.raw.windows(2).enumerate() {
            let d = w[1].time.seconds() - w[0].time.seconds();
            if d > GAP_CYCLES * median {
                let rate = pulses_per_s(k.saturating_sub(1)).max(pulses_per_s(k + 1));
                if rate * d > 32_767.0 {
                    out.push(warn(
                        "gyro_increment_ambiguous",
                        format!(
                            "gap of {d:.0} s after t = {:.0} s while the gyro counted {rate:.0} pulses/s: the counter difference across it has wrapped, so that gyro increment is wrong (attitude propagation, the bias estimate and any IRU maneuver across it are affected; report.json lists the maneuvers): send the frames, or give the maneuvers with --maneuver avoiding it",
                            w[0].time.seconds() - t0
                        ),
                    ));
                }
            }
        }
        if let Some(&(at, len)) = gaps.iter().max_by(|a, b| a.1.total_cmp(&b.1)) {
            out.push(warn(
                "time_gaps",
                format!(
                    "{} gap(s) in the raw frames (cycle {median:.3} s; largest {len:.0} s after t = {at:.0} s): no measurements there, and the gyro increment across a gap is one 16-bit counter difference, wrong if more than 32767 pulses passed (41 s at 0.5°/s in low rate)",
                    gaps.len()
                ),
            ));
        }
    }
}

/// Housekeeping that never lines up with a raw frame.
fn housekeeping_findings(tm: &Telemetry, out: &mut Vec<Finding>) {
    // Housekeeping that never lines up with a raw frame.
    if !tm.housekeeping.is_empty() {
        let matched = tm
            .housekeeping
            .iter()
            .filter(|h| {
                let i = tm.raw.partition_point(|f| f.time < h.time);
                tm.raw.get(i).is_some_and(|f| f.time == h.time)
            })
            .count();
        if matched == 0 {
            out.push(warn(
                "housekeeping_unmatched",
                format!(
                    "none of the {} housekeeping packets has the time code of a raw frame: the OBC attitude and IRU configuration are used only at a raw frame with the same time code (docs/icd.md §4), so the ground identifies stars from its own attitude",
                    tm.housekeeping.len()
                ),
            ));
        }
    }
}

/// What `calibrate`, `diagnose` and `allan` are asked besides their own options: the run
/// folder, the output folder (replaced whole with `force` when it is not the command's own
/// previous output), the tables folder flown, and how to report (`json`, `quiet`).
#[derive(Clone, Copy, Debug)]
pub struct CommandArgs<'a> {
    /// Run folder with telemetry.bin.
    pub run_dir: &'a std::path::Path,
    /// Output folder.
    pub out: &'a std::path::Path,
    /// Replace a non-empty output folder another tool wrote.
    pub force: bool,
    /// Tables folder of the images flown.
    pub tables: Option<&'a std::path::Path>,
    /// Print report.json to stdout.
    pub json: bool,
    /// No progress on stderr.
    pub quiet: bool,
    /// Take `tables` as flown even where the housekeeping says otherwise (a what-if):
    /// [`flown_table_findings`]' mismatch is then a warning.
    pub trust_tables: bool,
}

impl CommandArgs<'_> {
    /// [`begin_output`] of `command` with these folders.
    ///
    /// # Errors
    /// As [`begin_output`].
    pub fn begin_output(&self, command: &str) -> anyhow::Result<gro_reference::outdir::OutputDir> {
        begin_output(self.out, command, self.force, self.run_dir, self.tables)
    }
}

/// The output folder of a command over `run_dir` (and a `tables` folder), begun as a
/// temporary sibling of `out_target` ([`gro_reference::outdir::OutputDir`]), with the run
/// folder and the tables folder given as its inputs (which the output may not replace).
///
/// # Errors
/// As [`gro_reference::outdir::OutputDir::begin`].
pub fn begin_output(
    out_target: &std::path::Path,
    command: &str,
    force: bool,
    run_dir: &std::path::Path,
    tables: Option<&std::path::Path>,
) -> anyhow::Result<gro_reference::outdir::OutputDir> {
    gro_reference::outdir::OutputDir::begin(
        out_target,
        command,
        force,
        &[Some(run_dir), tables]
            .into_iter()
            .flatten()
            .collect::<Vec<_>>(),
    )
}

/// Read and check a run folder; print the findings to stderr and write them to
/// `out/input_check.json`.
///
/// # Errors
/// [`InputError`] when a finding is an error; I/O errors writing the findings. A missing or
/// unreadable `telemetry.bin` or `metadata.json` is left to the chain, which reports it.
pub fn check_run_dir(
    run_dir: &std::path::Path,
    out: &std::path::Path,
    assumed: &[AssumedTable],
    trust_tables: bool,
) -> anyhow::Result<Vec<Finding>> {
    let Ok(tm) = crate::tp::read_file(&run_dir.join("telemetry.bin")) else {
        return Ok(Vec::new());
    };
    let metadata = Metadata::read(run_dir).ok();
    let mut findings = check(&tm, metadata.as_ref());
    if !findings.iter().any(|f| f.severity == Severity::Error) {
        findings.extend(flown_table_findings(&tm, assumed, trust_tables));
    }
    for f in &findings {
        if f.severity == Severity::Warning {
            crate::note!("warning: {}", f.message);
        }
    }
    std::fs::create_dir_all(out)?;
    std::fs::write(
        out.join("input_check.json"),
        serde_json::to_string_pretty(&findings)?,
    )?;
    if let Some(e) = findings.iter().find(|f| f.severity == Severity::Error) {
        return Err(InputError::msg(&e.message).into());
    }
    Ok(findings)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An upload of a table the OBC does not have is refused, naming it; keys outside the
    /// format and declared effects the ground does not model are warned, by name.
    #[test]
    fn metadata_names_the_ground_cannot_use_are_said() {
        let path = std::path::Path::new("run/metadata.json");
        let mut m = Metadata::default();
        assert!(validate_metadata(path, &m).is_ok());
        m.uploads.push(gro_reference::run_folder::Upload {
            table: "aligment".into(),
            ..Default::default()
        });
        let e = validate_metadata(path, &m)
            .map(|()| String::new())
            .unwrap_or_else(|e| e.to_string());
        assert!(
            e.contains("uploads[0].table") && e.contains("aligment"),
            "{e}"
        );
        m.uploads[0].table = "alignment".into();
        assert!(validate_metadata(path, &m).is_ok());

        let mut out = Vec::new();
        metadata_findings(&m, &mut out);
        assert!(out.is_empty(), "{out:?}");
        m.unknown_keys = vec!["sensors.fhst_sigma_arsec".into()];
        m.declared_effects = Some(vec![
            "aberation".into(),
            "fhst2.time_tag_offset".into(),
            "orbital_aberration".into(),
            "fss_transfer_function".into(),
        ]);
        metadata_findings(&m, &mut out);
        let codes: Vec<&str> = out.iter().map(|f| f.code).collect();
        assert_eq!(codes, ["metadata_unknown_keys", "metadata_unknown_effects"]);
        assert!(out[0].message.contains("sensors.fhst_sigma_arsec"));
        assert!(out[1].message.contains("aberation"));
        assert!(
            !out[1].message.contains("time_tag_offset"),
            "{}",
            out[1].message
        );
    }

    /// The tables the ground assumes are checked against the CRCs the OBC reported: another
    /// table is an error, a boot-content image flown as boot is not, a switch during the run
    /// is a warning.
    #[test]
    fn assumed_tables_are_checked_against_the_housekeeping_crcs() {
        use fsw_core::tables::TableId;
        let hk = |t: f64, crc: u32| fsw_core::telemetry::ObcHousekeeping {
            time: fsw_core::raw::TimeTag::from_seconds(1.0e9 + t).unwrap_or_default(),
            table_crc: [crc, 0, 0, 0],
            ..Default::default()
        };
        let assumed = |image_crc: Option<u32>, equals_boot: bool| AssumedTable {
            id: TableId::Alignment,
            image_crc,
            equals_boot,
            source: "tables/alignment.tbl".into(),
        };
        let tm = |crcs: &[u32]| Telemetry {
            housekeeping: crcs
                .iter()
                .enumerate()
                .map(|(i, c)| hk(i as f64, *c))
                .collect(),
            ..Default::default()
        };
        let codes = |tm: &Telemetry, a: AssumedTable| -> Vec<&'static str> {
            flown_table_findings(tm, &[a], false)
                .iter()
                .map(|f| f.code)
                .collect()
        };
        let flown = tm(&[0xabcd; 3]);
        assert!(codes(&flown, assumed(Some(0xabcd), false)).is_empty());
        assert_eq!(codes(&flown, assumed(None, true)), ["flown_table_mismatch"]);
        assert_eq!(
            codes(&flown, assumed(Some(0x1234), false)),
            ["flown_table_mismatch"]
        );
        let boot = tm(&[0; 3]);
        assert!(codes(&boot, assumed(None, true)).is_empty());
        assert!(codes(&boot, assumed(Some(0x1234), true)).is_empty());
        assert_eq!(
            codes(&boot, assumed(Some(0x1234), false)),
            ["flown_table_mismatch"]
        );
        let switched = tm(&[0, 0, 0xabcd]);
        assert_eq!(
            codes(&switched, assumed(Some(0xabcd), false)),
            ["flown_table_changed"]
        );
        assert_eq!(
            codes(&Telemetry::default(), assumed(None, true)),
            ["flown_tables_unverified"]
        );
        assert!(flown_table_findings(&Telemetry::default(), &[], false).is_empty());
        // The operator's what-if: the mismatch is said, not refused.
        let what_if = flown_table_findings(&flown, &[assumed(None, true)], true);
        assert_eq!(what_if.len(), 1);
        assert_eq!(what_if[0].severity, Severity::Warning);
    }

    #[test]
    fn dates_round_trip() {
        let s = utc_naive_1958_s("1991-04-09T00:00:00Z").unwrap_or(f64::NAN);
        assert_eq!(s, 1_049_846_400.0);
        assert_eq!(date_of(s), "1991-04-09T00:00:00");
        assert_eq!(date_of(0.0), "1958-01-01T00:00:00");
        assert!(utc_naive_1958_s("yesterday").is_none());
    }
}
