//! # Fault injection (scenario `[[faults]]`, issue 7)
//!
//! Why: a flight core is trusted for what it survives. Each `[[faults]]` entry of a scenario
//! is applied by the harness to the truth sensors, the spacecraft clock or the uplink at a
//! given time; the OBC (`fsw_core`) is never touched, it only sees what the hardware or the
//! ground would give it. The scenarios in `scenarios/faults/` use one fault kind each and
//! write down the expected OBC behaviour; [`assess`] flies a scenario with and without its
//! faults and measures what the docs/reliability.md table reports.
//!
//! ```toml
//! [[faults]]
//! kind = "fhst_dropout"     # both trackers give no data for one orbit
//! sensor = "both"
//! at_s = 600
//! duration_s = 5700
//! ```
//!
//! | kind | fields | what the harness does |
//! |---|---|---|
//! | `fhst_dropout` | `sensor` = "fhst1" / "fhst2" / "both", `at_s`, `duration_s` | the tracker words are all zero (no data, flags 0) in `[at_s, at_s + duration_s)`; the truth tracker keeps running underneath |
//! | `fhst_wrong_star` | `sensor` = "fhst1" / "fhst2", `at_s`, `duration_s`, optional `offset_deg = [H, V]`, optional `new_star_flag` (default false) | every valid sample of the window is displaced in the focal plane by `offset_deg`; without `offset_deg`, by the (H, V) offset, at `at_s`, from the tracked star to the nearest other catalogue star in the field (the tracker silently jumps to another star: the OBC's identification is then wrong). `new_star_flag` sets `FHST_FLAG_NEW_STAR` on the first faulty sample |
//! | `fss_glint` | `sensor` = "fss1" / "fss2", `at_s`, `duration_s`, `offset_deg = [α, β]` | the Sun angles are displaced by `offset_deg` while the Sun is seen (a reflection) |
//! | `iru_channel_failure` | `channel` = "X1" … "Z2", `at_s`, optional `bit` (default true) | the channel's counter stops from `at_s`; with `bit = true` its built-in-test bit is set (what `[iru] failure` does), with `bit = false` it sticks silently |
//! | `time_tag_jump` | `at_s`, `offset_s`, optional `duration_s` | the frame time tag is `t + offset_s` from `at_s` on (for `duration_s` only, if given: a glitch) |
//! | `table_upload` | `at_s`, `corruption` = "none" / "bit_flip" / "truncate" / "rotate" / "nan", optional `activate` (default true), `rotation_deg` + `rotation_sensor` (rotate), `bits` (bit_flip, default 1), `octets` (truncate, default 16) | an alignment image built from the start-up alignment (the true one with `fly_true_alignments`, else the boot table), damaged as said, is loaded at `at_s` and, if `activate`, activated in the same cycle |
//! | `filter_reset` | `at_s` | an unexpected `FilterReset` command (covariance reopened, estimate kept) |
//! | `iru_counter_wrap` | `at_s`, optional `margin_pulses` (default 40) | the six 16-bit counters start (t = 0) where, moved by their true bias at low rate until `at_s`, they stand `margin_pulses` short of the wrap in the direction the bias moves them: every counter wraps at about `at_s` (put a high-rate slew there). The OBC sees only count differences, so this is invisible except where the wraps fall |
//!
//! Damage of `table_upload`: `bit_flip` flips `bits` payload bits *after* the CRC was
//! computed (a transmission error); `truncate` drops the last `octets` octets; `rotate`
//! rotates the `rotation_sensor` alignment by `rotation_deg` about the ACS x axis and
//! reseals the image (valid CRC: a wrong table, not a damaged one); `nan` writes NaN into
//! FHST2's `M_AS[1][1]` and reseals.

use anyhow::bail;
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use crate::closed_loop::{CycleRecord, Simulation};
use crate::scenario::Scenario;
use fsw_core::attitude::rot;
use fsw_core::events::{Counters, EventId};
use fsw_core::raw::{
    FhstSample, FssSample, TimeTag, FHST_FLAG_NEW_STAR, FHST_FLAG_VALID, FSS_FLAG_SUN_ALPHA,
    IRU_CHANNEL_NAMES,
};
use fsw_core::tables::types::{matrix_from_rows, rows_from_matrix};
use fsw_core::tables::{AlignmentTable, TableId};
use fsw_core::units::{ARCSEC_PER_RAD, RAD_PER_DEG};

/// The fine attitude requirement per axis (paper: 0.024° 3σ = 86.4″). [`assess`] counts the
/// OBC as recovered when every axis of every later cycle is inside it (stricter than 3σ).
pub const FINE_REQUIREMENT_ARCSEC: f64 = 86.4;

/// Kinds of fault.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FaultKind {
    /// No FHST data.
    FhstDropout,
    /// A tracker reports a star where it is not (or another star as the tracked one).
    FhstWrongStar,
    /// An FSS reports a displaced Sun.
    FssGlint,
    /// A gyro channel fails.
    IruChannelFailure,
    /// The spacecraft clock jumps.
    TimeTagJump,
    /// An alignment table upload, possibly damaged.
    TableUpload,
    /// An unexpected filter reset.
    FilterReset,
    /// The gyro counters are preset to wrap at a given time.
    IruCounterWrap,
}

/// Damage of a `table_upload`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Corruption {
    /// A valid image.
    None,
    /// Bits flipped after the CRC was computed.
    BitFlip,
    /// The end of the image lost.
    Truncate,
    /// A valid image of a rotated alignment.
    Rotate,
    /// A valid image with a NaN matrix element.
    Nan,
}

/// One `[[faults]]` entry (module doc).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Fault {
    /// What.
    pub kind: FaultKind,
    /// Start (s from the epoch).
    pub at_s: f64,
    /// Length of the fault window (s); absent = instantaneous or permanent (per kind).
    #[serde(default)]
    pub duration_s: Option<f64>,
    /// "fhst1", "fhst2", "both" (dropout), "fss1", "fss2".
    #[serde(default)]
    pub sensor: Option<String>,
    /// Focal-plane or Sun-angle displacement (deg).
    #[serde(default)]
    pub offset_deg: Option<[f64; 2]>,
    /// `fhst_wrong_star`: flag the first faulty sample as a new acquisition.
    #[serde(default)]
    pub new_star_flag: bool,
    /// `iru_channel_failure`: channel name.
    #[serde(default)]
    pub channel: Option<String>,
    /// `iru_channel_failure`: the built-in-test bit reports the failure.
    #[serde(default)]
    pub bit: Option<bool>,
    /// `time_tag_jump`: the jump (s).
    #[serde(default)]
    pub offset_s: Option<f64>,
    /// `table_upload`: damage.
    #[serde(default)]
    pub corruption: Option<Corruption>,
    /// `table_upload`: activate after loading.
    #[serde(default)]
    pub activate: Option<bool>,
    /// `table_upload` rotate: angle (deg).
    #[serde(default)]
    pub rotation_deg: Option<f64>,
    /// `table_upload` rotate: "fhst1", "fhst2", "fss1", "fss2".
    #[serde(default)]
    pub rotation_sensor: Option<String>,
    /// `table_upload` bit_flip: number of bits.
    #[serde(default)]
    pub bits: Option<u32>,
    /// `table_upload` truncate: octets removed.
    #[serde(default)]
    pub octets: Option<usize>,
    /// `iru_counter_wrap`: pulses left before the wrap at `at_s` (default 40).
    #[serde(default)]
    pub margin_pulses: Option<u16>,
}

fn sensor_index(name: &str) -> Option<usize> {
    ["fhst1", "fhst2", "fss1", "fss2"]
        .iter()
        .position(|n| *n == name)
}

impl Fault {
    /// End of the fault window (s): `at_s + duration_s`, or `at_s` for instantaneous and
    /// permanent faults.
    #[must_use]
    pub fn end_s(&self) -> f64 {
        self.at_s + self.duration_s.unwrap_or(0.0)
    }

    /// Whether a windowed fault is active at `t_s` (`[at_s, at_s + duration_s)`; without a
    /// duration, from `at_s` on).
    #[must_use]
    pub fn active(&self, t_s: f64) -> bool {
        t_s + 1e-9 >= self.at_s && self.duration_s.is_none_or(|d| t_s + 1e-9 < self.at_s + d)
    }

    /// Which FHSTs (bit 0 = FHST1, bit 1 = FHST2) or FSSs (same bits) the fault addresses.
    fn unit_mask(&self) -> u8 {
        match self.sensor.as_deref() {
            Some("fhst1" | "fss1") => 1,
            Some("fhst2" | "fss2") => 2,
            Some("both") => 3,
            _ => 0,
        }
    }

    /// The IRU channel index of an `iru_channel_failure`.
    #[must_use]
    pub fn channel_index(&self) -> Option<usize> {
        let name = self.channel.as_deref()?;
        IRU_CHANNEL_NAMES.iter().position(|n| *n == name)
    }

    /// Check the fields of this kind; `here` names the entry.
    ///
    /// # Errors
    /// A missing, unknown or out-of-range field, named.
    pub fn validate(&self, here: &str) -> anyhow::Result<()> {
        if !(self.at_s.is_finite() && self.at_s >= 0.0) {
            bail!("{here}.at_s must be ≥ 0, got {}", self.at_s);
        }
        if let Some(d) = self.duration_s {
            if !(d.is_finite() && d > 0.0) {
                bail!("{here}.duration_s must be > 0, got {d}");
            }
        }
        let need_duration = || -> anyhow::Result<()> {
            if self.duration_s.is_none() {
                bail!("{here}: kind {:?} needs duration_s", self.kind);
            }
            Ok(())
        };
        let sensor = self.sensor.as_deref();
        match self.kind {
            FaultKind::FhstDropout => {
                need_duration()?;
                if !matches!(sensor, Some("fhst1" | "fhst2" | "both")) {
                    bail!("{here}.sensor must be \"fhst1\", \"fhst2\" or \"both\"");
                }
            }
            FaultKind::FhstWrongStar => {
                need_duration()?;
                if !matches!(sensor, Some("fhst1" | "fhst2")) {
                    bail!("{here}.sensor must be \"fhst1\" or \"fhst2\"");
                }
            }
            FaultKind::FssGlint => {
                need_duration()?;
                if !matches!(sensor, Some("fss1" | "fss2")) {
                    bail!("{here}.sensor must be \"fss1\" or \"fss2\"");
                }
                if self.offset_deg.is_none() {
                    bail!("{here}: kind fss_glint needs offset_deg = [alpha, beta]");
                }
            }
            FaultKind::IruChannelFailure => {
                if self.channel_index().is_none() {
                    bail!("{here}.channel must be one of X1, X2, Y1, Y2, Z1, Z2");
                }
            }
            FaultKind::TimeTagJump => match self.offset_s {
                Some(o) if o.is_finite() && o.abs() <= 1.0e6 => {}
                _ => bail!("{here}.offset_s must be a number of seconds within ±1e6"),
            },
            FaultKind::TableUpload => {
                let Some(c) = self.corruption else {
                    bail!("{here}: kind table_upload needs corruption = \"none\" | \"bit_flip\" | \"truncate\" | \"rotate\" | \"nan\"");
                };
                if c == Corruption::Rotate {
                    match self.rotation_deg {
                        Some(a) if a.is_finite() && a.abs() <= 180.0 => {}
                        _ => bail!("{here}.rotation_deg must be in [-180, 180]"),
                    }
                    if self
                        .rotation_sensor
                        .as_deref()
                        .and_then(sensor_index)
                        .is_none()
                    {
                        bail!("{here}.rotation_sensor must be fhst1, fhst2, fss1 or fss2");
                    }
                }
                if self.bits == Some(0) {
                    bail!("{here}.bits must be ≥ 1");
                }
            }
            FaultKind::FilterReset => {}
            FaultKind::IruCounterWrap => {
                if self.margin_pulses.is_some_and(|m| m > 30_000) {
                    bail!("{here}.margin_pulses must be ≤ 30000");
                }
            }
        }
        if let Some(o) = self.offset_deg {
            if !o.iter().all(|x| x.is_finite() && x.abs() <= 60.0) {
                bail!("{here}.offset_deg must be within ±60°");
            }
        }
        Ok(())
    }

    /// The damaged alignment image of a `table_upload` built from `base`.
    ///
    /// # Errors
    /// Encoding failures (none for an alignment table).
    pub fn upload_image(&self, base: &AlignmentTable, created: TimeTag) -> anyhow::Result<Vec<u8>> {
        let mut table = *base;
        let corruption = self.corruption.unwrap_or(Corruption::None);
        match corruption {
            Corruption::Rotate => {
                let angle = self.rotation_deg.unwrap_or(0.0) * RAD_PER_DEG;
                let r = rot(&Vector3::new(angle, 0.0, 0.0));
                let m = match self.rotation_sensor.as_deref().and_then(sensor_index) {
                    Some(0) => &mut table.m_acs_from_fhst1,
                    Some(1) => &mut table.m_acs_from_fhst2,
                    Some(2) => &mut table.m_acs_from_fss1,
                    _ => &mut table.m_acs_from_fss2,
                };
                *m = rows_from_matrix(&(r * matrix_from_rows(m)));
            }
            Corruption::Nan => table.m_acs_from_fhst2[1][1] = f64::NAN,
            Corruption::None | Corruption::BitFlip | Corruption::Truncate => {}
        }
        let mut image = crate::onboard::image(TableId::Alignment, created, &table)?;
        match corruption {
            Corruption::BitFlip => {
                // Payload octets only (after the 20-octet header), spread over the image.
                let bits = self.bits.unwrap_or(1) as usize;
                let payload = image.len().saturating_sub(24);
                for k in 0..bits {
                    let octet = 20 + (k * 37 + 11) % payload.max(1);
                    if let Some(b) = image.get_mut(octet) {
                        *b ^= 1 << (k % 8);
                    }
                }
            }
            Corruption::Truncate => {
                let n = self.octets.unwrap_or(16).min(image.len());
                image.truncate(image.len() - n);
            }
            _ => {}
        }
        Ok(image)
    }
}

/// Validate every `[[faults]]` entry.
///
/// # Errors
/// The first bad entry, named `faults[i]`.
pub fn validate_all(faults: &[Fault]) -> anyhow::Result<()> {
    for (i, f) in faults.iter().enumerate() {
        f.validate(&format!("faults[{i}]"))?;
    }
    Ok(())
}

/// Per-run state of the sensor faults (what the harness needs between cycles).
#[derive(Clone, Debug, Default)]
pub struct FaultState {
    /// Offset (rad, H and V) of each `fhst_wrong_star` fault, fixed at its first cycle.
    wrong_star_offset_rad: Vec<Option<[f64; 2]>>,
}

impl FaultState {
    /// State for `faults`.
    #[must_use]
    pub fn new(faults: &[Fault]) -> Self {
        Self {
            wrong_star_offset_rad: vec![None; faults.len()],
        }
    }

    /// Apply the FHST faults active at `t_s` to tracker `unit`'s sample. `other_star` gives,
    /// on demand, the (H, V) offset (rad) from the tracked star to the nearest other star.
    pub fn apply_fhst(
        &mut self,
        faults: &[Fault],
        unit: usize,
        t_s: f64,
        sample: FhstSample,
        resolution_arcsec_per_count: f64,
        other_star: impl Fn() -> Option<[f64; 2]>,
    ) -> FhstSample {
        let mut out = sample;
        let bit = 1u8 << unit.min(1);
        for (i, f) in faults.iter().enumerate() {
            if f.unit_mask() & bit == 0 || !f.active(t_s) {
                continue;
            }
            match f.kind {
                FaultKind::FhstDropout => out = FhstSample::default(),
                FaultKind::FhstWrongStar => {
                    if out.flags & FHST_FLAG_VALID == 0 {
                        continue;
                    }
                    let first = self
                        .wrong_star_offset_rad
                        .get(i)
                        .is_some_and(Option::is_none);
                    if first {
                        let off = match f.offset_deg {
                            Some([h, v]) => Some([h * RAD_PER_DEG, v * RAD_PER_DEG]),
                            None => other_star(),
                        };
                        if let Some(slot) = self.wrong_star_offset_rad.get_mut(i) {
                            *slot = Some(off.unwrap_or([0.0; 2]));
                        }
                        if f.new_star_flag {
                            out.flags |= FHST_FLAG_NEW_STAR;
                        }
                    }
                    let [dh, dv] = self
                        .wrong_star_offset_rad
                        .get(i)
                        .copied()
                        .flatten()
                        .unwrap_or([0.0; 2]);
                    let q = resolution_arcsec_per_count;
                    out.h_counts = shift_counts(out.h_counts, dh * ARCSEC_PER_RAD / q);
                    out.v_counts = shift_counts(out.v_counts, dv * ARCSEC_PER_RAD / q);
                }
                _ => {}
            }
        }
        out
    }

    /// Apply the FSS faults active at `t_s` to sensor `unit`'s sample.
    #[must_use]
    pub fn apply_fss(
        faults: &[Fault],
        unit: usize,
        t_s: f64,
        sample: FssSample,
        resolution_deg_per_count: f64,
    ) -> FssSample {
        let mut out = sample;
        let bit = 1u8 << unit.min(1);
        for f in faults {
            if f.kind != FaultKind::FssGlint || f.unit_mask() & bit == 0 || !f.active(t_s) {
                continue;
            }
            if out.flags & FSS_FLAG_SUN_ALPHA == 0 {
                continue;
            }
            let [da, db] = f.offset_deg.unwrap_or([0.0; 2]);
            out.alpha_counts = shift_counts(out.alpha_counts, da / resolution_deg_per_count);
            out.beta_counts = shift_counts(out.beta_counts, db / resolution_deg_per_count);
        }
        out
    }

    /// The clock offset (s) of the `time_tag_jump` faults active at `t_s`.
    #[must_use]
    pub fn time_offset_s(faults: &[Fault], t_s: f64) -> f64 {
        faults
            .iter()
            .filter(|f| f.kind == FaultKind::TimeTagJump && f.active(t_s))
            .map(|f| f.offset_s.unwrap_or(0.0))
            .sum()
    }
}

fn shift_counts(c: i16, delta_counts: f64) -> i16 {
    let v = (f64::from(c) + delta_counts).round();
    #[allow(clippy::cast_possible_truncation)]
    let out = v.clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16;
    out
}

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
    /// Active table CRCs just before the first fault (alignment, IRU, filter, catalog, orbit).
    pub table_crc_before: [u32; 5],
    /// Active table CRCs at the end.
    pub table_crc_after: [u32; 5],
    /// Dumps of the active tables at the end equal to those just before the first fault.
    pub tables_unchanged: bool,
    /// `TableActivated` events at or after the fault start.
    pub tables_activated: u32,
    /// Largest `|δθ|` (arcsec) at the completion of each slew that ended after the fault start.
    pub post_slew_error_arcsec: Vec<f64>,
    /// Per-cycle trace (t, per-axis error arcsec, filter mode), for tests.
    #[serde(skip)]
    pub trace: Vec<(f64, [f64; 3], u8)>,
}

struct Flight {
    trace: Vec<(f64, [f64; 3], u8)>,
    events: Vec<(f64, EventId)>,
    counters: Counters,
    crc_before: [u32; 5],
    crc_after: [u32; 5],
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

fn crcs(sim: &Simulation) -> [u32; 5] {
    sim.fsw().tables().status().map(|s| s.active_crc)
}

fn fly(scenario: Scenario, snapshot_at_s: f64) -> anyhow::Result<Flight> {
    let mut sim = Simulation::new(scenario, None)?;
    let mut f = Flight {
        trace: Vec::new(),
        events: Vec::new(),
        counters: Counters::default(),
        crc_before: [0; 5],
        crc_after: [0; 5],
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
        recovered_at_s: recovered,
        recovery_s: recovered.map(|r| (r - end).max(0.0)),
        baseline_recovery_s: recovered_at(&clean.trace, end).map(|r| (r - end).max(0.0)),
        fine_mode_regained_s: fine_mode_regained(&faulty.trace, start, end),
        after_recovery_worst_axis_error_arcsec: recovered
            .map_or(f64::NAN, |r| worst_axis(&faulty.trace, r, f64::INFINITY).0),
        final_three_rms_arcsec: final_three_rms,
        events,
        fault_events,
        counters: faulty.counters,
        baseline_counters: clean.counters,
        table_crc_before: faulty.crc_before,
        table_crc_after: faulty.crc_after,
        tables_unchanged: faulty.dump_before == faulty.dump_after,
        tables_activated: count(&faulty.events, EventId::TableActivated),
        post_slew_error_arcsec: faulty
            .slew_end_errors
            .iter()
            .filter(|(t, _)| *t >= start)
            .map(|(_, e)| *e)
            .collect(),
        trace: faulty.trace,
    })
}

/// The (H, V) offset (rad) from the star tracker `fhst` tracks now to the nearest other
/// catalogue star inside its field at the truth attitude, if any.
#[must_use]
pub fn other_star_offset(
    m_acs_from_fhst: &Matrix3<f64>,
    tracked_hv_rad: [f64; 2],
    truth: &crate::sensors::TruthSnapshot,
    sky: &crate::truth::sky::Sky,
    fov_half_width_rad: f64,
    magnitude_window: (f64, f64),
) -> Option<[f64; 2]> {
    let m_fhst_from_eci = m_acs_from_fhst.transpose() * truth.m_acs_from_eci;
    let boresight = m_fhst_from_eci.row(2).transpose();
    let obs_pos = truth.observer_pos_bary_eci_km();
    let obs_vel = truth.observer_vel_bary_eci_km_per_s();
    let mut best: Option<(f64, [f64; 2])> = None;
    sky.for_each_in_cone(&boresight, fov_half_width_rad * 1.5, |_, star| {
        if !(magnitude_window.0..=magnitude_window.1).contains(&star.magnitude) {
            return;
        }
        let s = m_fhst_from_eci * star.apparent_dir_eci(truth.j2000_tt_s, &obs_pos, &obs_vel);
        if s.z <= 0.0 {
            return;
        }
        let (h, v) = (s.x.atan2(s.z), s.y.atan2(s.z));
        if h.abs() > fov_half_width_rad || v.abs() > fov_half_width_rad {
            return;
        }
        let d = [h - tracked_hv_rad[0], v - tracked_hv_rad[1]];
        let dist = d[0].hypot(d[1]);
        // Not the tracked star itself (closer than 30″).
        if dist < 30.0 / ARCSEC_PER_RAD {
            return;
        }
        if best.is_none_or(|(b, _)| dist < b) {
            best = Some((dist, d));
        }
    });
    best.map(|(_, d)| d)
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
        let tables = if r.tables_unchanged {
            "unchanged".to_owned()
        } else {
            format!("changed ({} activated)", r.tables_activated)
        };
        let [a, b, c] = r.final_three_rms_arcsec;
        let recovery = format!(
            "{} (no fault: {})",
            fmt_opt(r.recovery_s),
            fmt_opt(r.baseline_recovery_s)
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
            fmt_opt(r.fine_mode_regained_s),
            if events.is_empty() { "none".to_owned() } else { events },
            tables
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every `scenarios/faults/*.toml` parses, validates and has at least one fault.
    #[test]
    fn shipped_fault_scenarios_load() {
        let files = shipped_fault_scenarios().unwrap();
        assert!(files.len() >= 9, "{files:?}");
        for f in files {
            let s = Scenario::load(&f).unwrap_or_else(|e| panic!("{}: {e:#}", f.display()));
            assert!(!s.faults.is_empty(), "{}", f.display());
        }
    }

    #[test]
    fn windows_and_validation() {
        let text = "name = \"x\"\nduration_s = 10\n[[faults]]\nkind = \"fhst_dropout\"\nsensor = \"both\"\nat_s = 5\nduration_s = 2\n";
        let s = Scenario::from_toml_str(text, "t").unwrap();
        let f = &s.faults[0];
        assert!(!f.active(4.0) && f.active(5.0) && f.active(6.0) && !f.active(7.0));
        assert_eq!(f.unit_mask(), 3);
        // A dropout without a duration, an unknown key, a glint without offset: refused, named.
        for (bad, what) in [
            (
                "kind = \"fhst_dropout\"\nsensor = \"both\"\nat_s = 5\n",
                "duration_s",
            ),
            (
                "kind = \"fss_glint\"\nsensor = \"fss1\"\nat_s = 5\nduration_s = 1\n",
                "offset_deg",
            ),
            (
                "kind = \"iru_channel_failure\"\nchannel = \"Q1\"\nat_s = 5\n",
                "channel",
            ),
            (
                "kind = \"time_tag_jump\"\nat_s = 5\nofset_s = 1\n",
                "ofset_s",
            ),
        ] {
            let err = Scenario::from_toml_str(
                &format!("name = \"x\"\nduration_s = 10\n[[faults]]\n{bad}"),
                "t",
            )
            .unwrap_err();
            assert!(format!("{err:#}").contains(what), "{err:#}");
        }
    }

    /// The damaged images are refused by the OBC's table services for the intended reason.
    #[test]
    fn damaged_images_are_refused_for_their_reason() {
        use fsw_core::tables::TableSet;
        let base = AlignmentTable::prelaunch();
        let upload = |c: Corruption| Fault {
            kind: FaultKind::TableUpload,
            at_s: 0.0,
            duration_s: None,
            sensor: None,
            offset_deg: None,
            new_star_flag: false,
            channel: None,
            bit: None,
            offset_s: None,
            corruption: Some(c),
            activate: None,
            rotation_deg: Some(10.0),
            rotation_sensor: Some("fhst1".into()),
            bits: Some(3),
            octets: None,
            margin_pulses: None,
        };
        for (c, code) in [
            (Corruption::BitFlip, 9),
            (Corruption::Truncate, 8),
            (Corruption::Rotate, 15),
            (Corruption::Nan, 12),
        ] {
            let img = upload(c).upload_image(&base, TimeTag::default()).unwrap();
            let mut set = TableSet::boot();
            let e = set.load(&img).unwrap_err();
            assert_eq!(e.0, Some(TableId::Alignment), "{c:?}");
            assert_eq!(e.1.code(), code, "{c:?}: {e:?}");
        }
        let img = upload(Corruption::None)
            .upload_image(&base, TimeTag::default())
            .unwrap();
        assert_eq!(TableSet::boot().load(&img), Ok(TableId::Alignment));
    }
}
