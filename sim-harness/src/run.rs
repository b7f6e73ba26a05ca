//! # One run: the closed loop, the telemetry file, the truth and the scores
//!
//! [`run`] flies a scenario and, with an output folder, writes the run folder of
//! docs/icd.md §5:
//!
//! | file | content |
//! |---|---|
//! | `telemetry.bin` | CCSDS packets ([`crate::telemetry`]) |
//! | `metadata.json` | what the operator declares ([`gro_reference::run_folder::Metadata`], schema `docs/schema/metadata.schema.json`): `scenario`, `epoch_utc`, `cycle_period_s`, `sensors` (declared noise from the scenario's sensor parameters), `declared_effects`, `boot_tables`, `uploads`, and the simulated spacecraft's identity `spacecraft` ([`crate::provenance`]) |
//! | `uploads/*.tbl` | every table image uplinked (catalog, `--tables`, timeline loads) |
//! | `truth.json` | scoring only ([`gro_reference::run_folder::Truth`], schema `docs/schema/truth.schema.json`): true `alignments.{FHST1,FHST2,FSS1,FSS2}` (`M_AS`, row-major; at the start, without thermal drift), `alignments_after_run` (the same with any alignment step of the run applied: what tables written after the run fly into), IRU `delta_m` and `g` per configuration, `bias_history`, the flown `fss_transfer_function`, `scenario_as_flown` (the whole scenario, each FSS with the transfer function it flew), `present_effects`, `undeclared_effects`, `tam` (the magnetometers' true errors, [`crate::sensors::tam::truth_tams`]: `tam.bias_mG` is the primary TAM's bias) |
//! | `summary.json` | run statistics ([`Summary`]); with `--tables`, `tables_provenance_warning` when the tables may belong to another spacecraft ([`crate::provenance`]) |
//!
//! Every file is written under a `.partial` name and renamed when complete; `summary.json`
//! is renamed last, so a folder with a `summary.json` is a finished run.
//!
//! # Scores (`summary.json`)
//! * `attitude_error_arcsec`: per-axis rms, mean, std, 3σ and the max of `|δθ|` over the
//!   cycles with `t ≥ 600 s`, the filter initialised and the OBC not slewing (its control
//!   mode, from housekeeping); `attitude_error_arcsec_all`: every initialised cycle.
//! * `post_maneuver_error_deg`: `|δθ|` at the cycle of each `SlewCompleted` event. The OBC
//!   propagates on the gyros alone during slews, so this is the estimation error the slew
//!   left (what star identification after a maneuver must cope with; paper: < 0.5°).
//! * `filter_nees_mean`: mean of `δθᵀ P_θθ⁻¹ δθ` over the first window (3 if consistent).
//! * `rejected_measurements`: gated + input-rejected measurements (OBC counters).

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use crate::closed_loop::{CycleRecord, Simulation};
use crate::paper::PaperFacts;
use crate::scenario::Scenario;
use crate::sensors::fss::{FssHeadErrors, FssParams};
use crate::sensors::iru::{BACKUP_CHANNELS, PRIMARY_CHANNELS};
use crate::telemetry::PacketWriter;
use crate::truth::time::utc_string;
use fsw_core::events::EventId;
use fsw_core::raw::IRU_CHANNELS;
use fsw_core::tables::TableId;
use fsw_core::telemetry::{EphemerisRecord, MagneticsFrame, WheelFrame};
use fsw_core::units::{ARCSEC_PER_RAD, RAD_PER_ARCSEC, RAD_PER_DEG};
use gro_reference::run_folder::{
    DeclaredNoise, HeadSpread, Metadata, PerSensor, TransferSpreads, Truth, TruthBiasHistory,
    TruthBiasSample, TruthFssTransfer, TruthFssUnit, TruthIru, TruthTriad, UnitSpread, Upload,
    METADATA_FILE, TRUTH_FILE,
};

/// Start of the scored window (s): the filter has converged from its initial error.
pub const SCORE_START_S: f64 = 600.0;
/// Progress-bar update interval (cycles).
const PROGRESS_EVERY: u64 = 4096;

/// Options of one run.
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    /// Run folder; `None` = write nothing (bench).
    pub out_dir: Option<PathBuf>,
    /// `--tables DIR`.
    pub tables_dir: Option<PathBuf>,
    /// Draw a progress bar on stderr (only if it is a terminal).
    pub progress: bool,
}

/// Attitude-error statistics over a window (arcsec).
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct ErrorStats {
    /// Cycles in the window.
    pub cycles: u64,
    /// RMS per ACS axis.
    pub rms: [f64; 3],
    /// Mean per axis.
    pub mean: [f64; 3],
    /// Standard deviation per axis.
    pub std: [f64; 3],
    /// 3 × std per axis (compare with the paper's 0.024° = 86.4″ fine requirement).
    pub three_sigma: [f64; 3],
    /// Largest `|δθ|`.
    pub max: f64,
}

#[derive(Clone, Debug, Default)]
struct Accumulator {
    n: u64,
    sum: [f64; 3],
    sumsq: [f64; 3],
    max: f64,
}

impl Accumulator {
    fn add(&mut self, e_arcsec: &Vector3<f64>) {
        self.n += 1;
        for i in 0..3 {
            self.sum[i] += e_arcsec[i];
            self.sumsq[i] += e_arcsec[i] * e_arcsec[i];
        }
        self.max = self.max.max(e_arcsec.norm());
    }

    fn stats(&self) -> ErrorStats {
        if self.n == 0 {
            return ErrorStats::default();
        }
        let n = self.n as f64;
        let mut s = ErrorStats {
            cycles: self.n,
            max: self.max,
            ..ErrorStats::default()
        };
        for i in 0..3 {
            let mean = self.sum[i] / n;
            let ms = self.sumsq[i] / n;
            s.mean[i] = mean;
            s.rms[i] = ms.sqrt();
            s.std[i] = (ms - mean * mean).max(0.0).sqrt();
            s.three_sigma[i] = 3.0 * s.std[i];
        }
        s
    }
}

/// One slew of the run.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct SlewReport {
    /// OBC slew number.
    pub number: u32,
    /// Start (s).
    pub start_s: f64,
    /// Completion (s).
    pub end_s: f64,
    /// `|δθ|` at completion (deg).
    pub post_maneuver_error_deg: f64,
    /// `δθ` at completion per ACS axis (arcsec).
    pub post_maneuver_error_acs_arcsec: [f64; 3],
}

/// One uplinked table.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct TableReport {
    /// Table name.
    pub table: String,
    /// File in the run folder (`uploads/...`).
    pub file: String,
    /// Where the image came from.
    pub source: String,
    /// Load command time (s).
    pub loaded_at_s: f64,
    /// The OBC accepted it.
    pub accepted: bool,
    /// Rejection reason code (docs/tables.md), 0 if accepted.
    pub reject_reason: u32,
    /// Activation time (s), if activated.
    pub activated_at_s: Option<f64>,
    /// CRC-32 of the image (as reported at activation).
    pub crc32: u32,
}

/// OBC measurement counters at the end of the run.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct MeasurementCounters {
    /// Accepted.
    pub accepted: u32,
    /// Refused by the χ² gate.
    pub gated: u32,
    /// Refused by input validation.
    pub rejected_inputs: u32,
    /// Stars identified.
    pub stars_identified: u32,
    /// Star identification without match.
    pub star_id_unmatched: u32,
    /// Ambiguous identifications.
    pub star_id_ambiguous: u32,
    /// Events dropped (more than 8 in a cycle).
    pub events_dropped: u32,
}

/// The length and speed of a closed-loop run (summary.json, `sim-harness bench`).
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct LoopTiming {
    /// Simulated time (s).
    pub sim_seconds: f64,
    /// Wall-clock time of the loop (s).
    pub wall_seconds: f64,
    /// `sim_seconds / wall_seconds`.
    pub real_time_factor: f64,
    /// Cycles run.
    pub cycles: u64,
    /// Wall time per cycle (ns).
    pub ns_per_cycle: f64,
}

impl LoopTiming {
    /// `cycles` cycles over `sim_s` simulated seconds in `wall_s` seconds of wall time.
    #[must_use]
    pub fn new(sim_s: f64, wall_s: f64, cycles: u64) -> Self {
        Self {
            sim_seconds: sim_s,
            wall_seconds: wall_s,
            real_time_factor: if wall_s > 0.0 { sim_s / wall_s } else { 0.0 },
            cycles,
            ns_per_cycle: if cycles > 0 {
                wall_s * 1e9 / cycles as f64
            } else {
                0.0
            },
        }
    }
}

/// summary.json.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct Summary {
    /// Scenario name.
    pub scenario: String,
    /// Seed.
    pub seed: u64,
    /// How long the loop flew and how fast (summary.json keys `sim_seconds` … `ns_per_cycle`).
    #[serde(flatten)]
    pub timing: LoopTiming,
    /// Errors over `t ≥ 600 s`, outside slews, filter initialised.
    pub attitude_error_arcsec: ErrorStats,
    /// Errors over every initialised cycle.
    pub attitude_error_arcsec_all: ErrorStats,
    /// `|δθ|` at each slew completion (deg).
    pub post_maneuver_error_deg: Vec<f64>,
    /// Slews.
    pub slews: Vec<SlewReport>,
    /// Mean NEES over the scored window (3 = consistent).
    pub filter_nees_mean: Option<f64>,
    /// Cycles in the NEES mean.
    pub filter_nees_cycles: u64,
    /// Fraction of the scored window in fine mode.
    pub fine_mode_fraction: f64,
    /// Gated + input-rejected measurements.
    pub rejected_measurements: u64,
    /// OBC counters.
    pub measurement_counters: MeasurementCounters,
    /// Tables uplinked.
    pub tables_loaded: Vec<TableReport>,
    /// Telemetry packets written.
    pub telemetry_packets: u64,
    /// Telemetry octets written.
    pub telemetry_bytes: u64,
    /// Downlinked raw frames whose IRU counters moved by ≥ 2¹⁵ since the previous one.
    pub iru_counter_aliasing_frames: u64,
    /// Largest true wheel momentum (N·m·s).
    pub max_wheel_momentum_nms: f64,
    /// 3 × RMS per ACS axis of the OBC's coarse attitude against the truth over every cycle
    /// after its first fix (deg); absent when it made none (issue 20's key).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coarse_attitude_error_3sigma_deg: Option<[f64; 3]>,
    /// The coarse attitude's consistency (absent when it made no fix).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coarse_attitude: Option<CoarseSummary>,
    /// With `--tables`: why the tables may not belong to the spacecraft flown
    /// ([`crate::provenance`]; absent when they were calibrated on it, or no tables).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tables_provenance_warning: Option<String>,
}

/// The OBC's coarse attitude against the truth over a run (`fsw_core::coarse`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CoarseSummary {
    /// Cycles with a coarse solution.
    pub cycles: u64,
    /// Mean `δθᵀ P⁻¹ δθ` (3 if the covariance is consistent).
    pub nees_mean: Option<f64>,
    /// Fraction of cycles with `|δθᵢ| ≤ 3σᵢ`, per ACS axis.
    pub within_3sigma_fraction: [f64; 3],
    /// Mean of the OBC's own 3σ per axis (deg).
    pub mean_3sigma_deg: [f64; 3],
    /// Largest `|δθ|` (deg).
    pub max_error_deg: f64,
    /// Mean error per axis (deg): a bias shows here.
    pub mean_error_deg: [f64; 3],
    /// The paper's requirement, 2° (3σ) per axis, met by `coarse_attitude_error_3sigma_deg`.
    pub meets_2deg_3sigma: bool,
    /// 3 × RMS per axis (deg) and cycles, by the last fix's vectors: FSS + TAM, CSS + TAM.
    pub by_source: Vec<CoarseSourceStats>,
    /// Cycles more than 60 s after the last fix (carried on the gyros: eclipse, no Sun in
    /// view, nearly parallel vectors).
    pub carried_over_60s_cycles: u64,
}

/// The coarse attitude's error by the vectors of its last fix.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CoarseSourceStats {
    /// "fss+tam" or "css+tam".
    pub source: String,
    /// Cycles.
    pub cycles: u64,
    /// 3 × RMS per ACS axis (deg).
    pub error_3sigma_deg: [f64; 3],
    /// Mean `δθᵀ P⁻¹ δθ`.
    pub nees_mean: Option<f64>,
}

#[derive(Default)]
struct CoarseScorer {
    errors: Accumulator,
    by_source: [(Accumulator, f64, u64); 2],
    carried: u64,
    nees_sum: f64,
    nees_n: u64,
    within: [u64; 3],
    sigma3_sum: [f64; 3],
}

impl CoarseScorer {
    fn add(&mut self, c: &crate::closed_loop::CoarseCheck) {
        let e_deg = c.error_acs_rad / RAD_PER_DEG;
        self.errors.add(&e_deg);
        if c.age_s > 60.0 {
            self.carried += 1;
        }
        if let Some((acc, nees_sum, nees_n)) = self
            .by_source
            .get_mut(usize::from(c.source).wrapping_sub(1))
        {
            acc.add(&e_deg);
            if let Some(n) = c.nees {
                *nees_sum += n;
                *nees_n += 1;
            }
        }
        if let Some(n) = c.nees {
            self.nees_sum += n;
            self.nees_n += 1;
        }
        for i in 0..3 {
            let s3 = 3.0 * c.sigma_acs_rad[i];
            self.sigma3_sum[i] += s3 / RAD_PER_DEG;
            if c.error_acs_rad[i].abs() <= s3 {
                self.within[i] += 1;
            }
        }
    }

    fn summary(&self) -> (Option<[f64; 3]>, Option<CoarseSummary>) {
        let n = self.errors.n;
        if n == 0 {
            return (None, None);
        }
        let stats = self.errors.stats();
        let three = stats.rms.map(|r| 3.0 * r);
        let nf = n as f64;
        let summary = CoarseSummary {
            cycles: n,
            nees_mean: (self.nees_n > 0).then(|| self.nees_sum / self.nees_n as f64),
            within_3sigma_fraction: self.within.map(|w| w as f64 / nf),
            mean_3sigma_deg: self.sigma3_sum.map(|s| s / nf),
            max_error_deg: stats.max,
            mean_error_deg: stats.mean,
            meets_2deg_3sigma: three.iter().all(|x| *x <= 2.0),
            by_source: ["fss+tam", "css+tam"]
                .iter()
                .zip(&self.by_source)
                .filter(|(_, (acc, _, _))| acc.n > 0)
                .map(|(name, (acc, nees_sum, nees_n))| CoarseSourceStats {
                    source: (*name).to_owned(),
                    cycles: acc.n,
                    error_3sigma_deg: acc.stats().rms.map(|r| 3.0 * r),
                    nees_mean: (*nees_n > 0).then(|| nees_sum / *nees_n as f64),
                })
                .collect(),
            carried_over_60s_cycles: self.carried,
        };
        (Some(three), Some(summary))
    }
}

/// The scoring state of a run.
struct Scorer {
    coarse: CoarseScorer,
    steady: Accumulator,
    all: Accumulator,
    nees_sum: f64,
    nees_n: u64,
    fine: u64,
    slews: Vec<SlewReport>,
    open_slew: Option<(u32, f64)>,
    tables: Vec<TableReport>,
    load_cursor: usize,
    max_wheel: f64,
    counters: fsw_core::events::Counters,
}

impl Scorer {
    fn new(sim: &Simulation) -> Self {
        let tables = sim
            .uploads()
            .iter()
            .enumerate()
            .map(|(i, up)| TableReport {
                table: crate::uplink::image_table_id(&up.image)
                    .map_or("unknown", TableId::name)
                    .to_owned(),
                file: format!("uploads/{i:02}_{}", up.name),
                source: up.source.clone(),
                loaded_at_s: up.at_s,
                ..TableReport::default()
            })
            .collect();
        Self {
            coarse: CoarseScorer::default(),
            steady: Accumulator::default(),
            all: Accumulator::default(),
            nees_sum: 0.0,
            nees_n: 0,
            fine: 0,
            slews: Vec::new(),
            open_slew: None,
            tables,
            load_cursor: 0,
            max_wheel: 0.0,
            counters: fsw_core::events::Counters::default(),
        }
    }

    fn add(&mut self, rec: &CycleRecord, wheel_momentum: &[f64]) {
        let hk = &rec.output.housekeeping;
        let t = rec.truth.t_s;
        let err = rec.attitude_error_acs_rad * ARCSEC_PER_RAD;
        self.counters = hk.counters;
        for h in wheel_momentum {
            self.max_wheel = self.max_wheel.max(h.abs());
        }
        if let Some(c) = &rec.coarse {
            self.coarse.add(c);
        }
        for e in &rec.output.events {
            match e.id {
                EventId::SlewStarted => self.open_slew = Some((e.p1, t)),
                EventId::SlewCompleted => {
                    let start = match self.open_slew.take() {
                        Some((n, s)) if n == e.p1 => s,
                        _ => t,
                    };
                    self.slews.push(SlewReport {
                        number: e.p1,
                        start_s: start,
                        end_s: t,
                        post_maneuver_error_deg: rec.attitude_error_acs_rad.norm() / RAD_PER_DEG,
                        post_maneuver_error_acs_arcsec: [err.x, err.y, err.z],
                    });
                }
                EventId::TableLoaded | EventId::TableRejected => {
                    if let Some(tr) = self.tables.get_mut(self.load_cursor) {
                        tr.accepted = e.id == EventId::TableLoaded;
                        tr.reject_reason = if tr.accepted { 0 } else { e.p2 };
                    }
                    self.load_cursor += 1;
                }
                EventId::TableActivated => {
                    let name = TableId::from_u8(u8::try_from(e.p1).unwrap_or(0))
                        .map_or("unknown", TableId::name);
                    let upto = self.load_cursor.min(self.tables.len());
                    if let Some(tr) = self.tables[..upto]
                        .iter_mut()
                        .rev()
                        .find(|tr| tr.table == name && tr.accepted && tr.activated_at_s.is_none())
                    {
                        tr.activated_at_s = Some(t);
                        tr.crc32 = e.p2;
                    }
                }
                _ => {}
            }
        }
        if hk.filter_mode == 0 {
            return;
        }
        self.all.add(&err);
        // Scored outside slews (2) and Sun acquisition (3): the inertial attitude modes.
        if t >= SCORE_START_S && !matches!(hk.control_mode, 2 | 3) {
            self.steady.add(&err);
            if hk.filter_mode == 2 {
                self.fine += 1;
            }
            if let Some(n) = rec.nees {
                self.nees_sum += n;
                self.nees_n += 1;
            }
        }
    }
}

/// Writes truth-bias samples every `period` seconds.
struct BiasRecorder {
    period_s: f64,
    next_s: f64,
    w_primary_inv: Matrix3<f64>,
    w_backup_inv: Matrix3<f64>,
    samples: Vec<TruthBiasSample>,
}

impl BiasRecorder {
    fn new(sim: &Simulation) -> Self {
        let rows = |chs: [usize; 3]| {
            let input = sim.iru().input_acs();
            Matrix3::from_rows(&[
                input[chs[0]].transpose(),
                input[chs[1]].transpose(),
                input[chs[2]].transpose(),
            ])
            .try_inverse()
            .unwrap_or_else(Matrix3::identity)
        };
        Self {
            period_s: sim.scenario().truth_bias_period_s,
            next_s: 0.0,
            w_primary_inv: rows(PRIMARY_CHANNELS),
            w_backup_inv: rows(BACKUP_CHANNELS),
            samples: Vec::new(),
        }
    }

    fn add(&mut self, sim: &Simulation, t_s: f64) {
        if t_s + 1e-9 < self.next_s {
            return;
        }
        self.next_s += self.period_s;
        let dev = sim.thermal(4).map_or(0.0, |n| n.deviation_c());
        let mut ch = [0.0; IRU_CHANNELS];
        for (i, b) in ch.iter_mut().enumerate() {
            *b = sim.iru().bias_rad_per_s(i, t_s, dev);
        }
        let triad = |chs: [usize; 3]| Vector3::new(ch[chs[0]], ch[chs[1]], ch[chs[2]]);
        let p = self.w_primary_inv * triad(PRIMARY_CHANNELS);
        let b = self.w_backup_inv * triad(BACKUP_CHANNELS);
        self.samples.push(TruthBiasSample {
            t_s,
            bias_acs_rad_per_s: [p.x, p.y, p.z],
            backup_bias_acs_rad_per_s: [b.x, b.y, b.z],
            channel_bias_rad_per_s: ch,
        });
    }
}

fn rows(m: &Matrix3<f64>) -> [[f64; 3]; 3] {
    fsw_core::tables::types::rows_from_matrix(m)
}

/// Effects active in a scenario's truth, by name (`sensor.effect` for per-unit hooks).
#[must_use]
pub fn present_effects(s: &Scenario) -> Vec<String> {
    let mut out: Vec<String> = vec!["aberration".into(), "sun_parallax".into()];
    if s.sky.orbital_aberration {
        out.push("orbital_aberration".into());
    }
    if s.sky.apply_parallax {
        out.push("stellar_parallax".into());
    }
    if s.sky.proper_motion_error_sigma_mas_per_yr > 0.0 {
        out.push("catalog_proper_motion_error".into());
    }
    if (s.sky.proper_motion_scale - 1.0).abs() > 0.0 {
        out.push("proper_motion_scale".into());
    }
    let nz = |v: &[f64]| v.iter().any(|x| *x != 0.0);
    for (name, f) in [("fhst1", &s.fhst1), ("fhst2", &s.fhst2)] {
        let e = &f.effects;
        if e.time_tag_offset_s != 0.0 {
            out.push(format!("{name}.time_tag_offset"));
        }
        if nz(&e.thermal_alignment_arcsec_per_c) {
            out.push(format!("{name}.thermal_alignment_drift"));
        }
        if e.radial_distortion_arcsec_at_4deg != 0.0 || nz(&e.hv_distortion_arcsec_at_corner) {
            out.push(format!("{name}.fhst_distortion"));
        }
        if nz(&e.magnitude_bias_arcsec_per_mag) {
            out.push(format!("{name}.magnitude_bias"));
        }
        if e.alignment_step_at_s.is_some() && nz(&e.alignment_step_arcsec) {
            out.push(format!("{name}.alignment_step"));
        }
    }
    let mut fss_tf = false;
    for (name, f) in [("fss1", &s.fss1), ("fss2", &s.fss2)] {
        for h in [&f.alpha, &f.beta] {
            fss_tf |= h.offset_arcsec != 0.0
                || h.scale_ppm != 0.0
                || h.cyclic_arcsec != 0.0
                || h.cross_arcsec_at_corner != 0.0
                || h.cubic_arcsec_at_edge != 0.0;
        }
        if f.effects.time_tag_offset_s != 0.0 {
            out.push(format!("{name}.time_tag_offset"));
        }
        if nz(&f.effects.thermal_alignment_arcsec_per_c) {
            out.push(format!("{name}.thermal_alignment_drift"));
        }
        if f.effects.alignment_step_at_s.is_some() && nz(&f.effects.alignment_step_arcsec) {
            out.push(format!("{name}.alignment_step"));
        }
    }
    if fss_tf {
        out.push("fss_transfer_function".into());
    }
    let i = &s.iru;
    if nz(&i.bias_transient_deg_per_s) {
        out.push("iru_bias_transient".into());
    }
    if nz(&i.high_rate_scale_ppm) {
        out.push("iru_mode_ratio_error".into());
    }
    if nz(&i.channel_scale_ppm) {
        out.push("iru_channel_scale_error".into());
    }
    if i.effects.time_tag_offset_s != 0.0 {
        out.push("iru.time_tag_offset".into());
    }
    if nz(&i.effects.scale_asymmetry_ppm) {
        out.push("iru.scale_asymmetry".into());
    }
    if nz(&i.effects.thermal_bias_deg_per_s_per_c) {
        out.push("iru.thermal_bias".into());
    }
    if nz(&i.effects.high_rate_bias_deg_per_s) {
        out.push("iru.high_rate_mode_bias".into());
    }
    if nz(&i.effects.rate_power_scale_ppm) {
        out.push("iru.rate_power_scale".into());
    }
    if i.effects.scale_step_at_s.is_some() && nz(&i.effects.scale_step_ppm) {
        out.push("iru.scale_step".into());
    }
    if i.failure.is_some() {
        out.push("iru_channel_failure".into());
    }
    out
}

/// Present effects the scenario does not declare (a declared `x` covers `unit.x`).
#[must_use]
pub fn undeclared_effects(s: &Scenario) -> Vec<String> {
    let declared = s.declared_effects();
    present_effects(s)
        .into_iter()
        .filter(|e| {
            let short = e.split('.').next_back().unwrap_or(e);
            !declared.iter().any(|d| d == e || d == short)
        })
        .collect()
}

/// Declared noise figures (metadata.json `sensors`) from the scenario's sensor parameters:
/// FHST σ for a bright on-axis and a faint corner star with the count quantization added in
/// quadrature; FSS noise in counts, and as an angle (noise ⊕ quantization ⊕ rms of the
/// transfer-function error over ±25°); IRU random walks in SI units.
#[must_use]
pub fn declared_noise(s: &Scenario) -> DeclaredNoise {
    let f = &s.fhst1;
    let q2 = f.resolution_arcsec_per_count.powi(2) / 12.0;
    let corner = f.fov_half_width_deg * RAD_PER_DEG * std::f64::consts::SQRT_2;
    let bright = (f.sigma_arcsec(f.magnitude_min, 0.0).powi(2) + q2).sqrt();
    let faint = (f.sigma_arcsec(f.magnitude_max, corner).powi(2) + q2).sqrt();
    let fss = &s.fss1;
    let count_arcsec = fss.resolution_deg_per_count * 3600.0;
    let tf_rms = [&s.fss1, &s.fss2].map(FssParams::transfer_function_rms_arcsec);
    let fss_sigma = ((fss.noise_counts_1sigma * count_arcsec).powi(2)
        + count_arcsec.powi(2) / 12.0
        + tf_rms[0].powi(2))
    .sqrt();
    DeclaredNoise {
        fhst_sigma_arcsec: [bright, faint],
        fss_noise_counts: Some(fss.noise_counts_1sigma),
        fss_sigma_arcsec: fss_sigma,
        // The level of a declared transfer function is part of the declaration (an
        // undeclared one leaves the ground at its default, the paper's 0.022°).
        fss_systematic_arcsec: fss_transfer_declared(s)
            .then(|| (0.5 * (tf_rms[0].powi(2) + tf_rms[1].powi(2))).sqrt()),
        iru_arw_rad_per_sqrt_s: s.iru.angle_random_walk_arcsec_per_sqrt_s * RAD_PER_ARCSEC,
        iru_rrw_rad_per_s_sqrt_s: s.iru.bias_random_walk_arcsec_per_s15 * RAD_PER_ARCSEC,
    }
}

/// `metadata.json`: what the operator declares (the one definition,
/// [`gro_reference::run_folder::Metadata`]).
fn metadata(sim: &Simulation, scorer: &Scorer) -> Metadata {
    let s = sim.scenario();
    let uploads = scorer
        .tables
        .iter()
        .map(|t| Upload {
            table: t.table.clone(),
            file: Some(t.file.clone()),
            source: t.source.clone(),
            loaded_at_s: Some(t.loaded_at_s),
            accepted: t.accepted,
            activated_at_s: t.activated_at_s,
            activated_utc: t.activated_at_s.map(|a| utc_string(sim.clock().epoch(a))),
            crc32: Some(t.crc32),
        })
        .collect();
    let boot_tables = [
        (
            "alignment",
            "fsw-core boot table: paper Table 1 prelaunch alignments",
        ),
        ("iru", "fsw-core boot table: paper prelaunch G, k = 1"),
        (
            "filter",
            "fsw-core boot table: FilterTable::default_boot (docs/tables.md)",
        ),
        ("star_catalog", "empty (the catalog is uplinked at t = 0)"),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_owned(), v.to_owned()))
    .collect();
    Metadata {
        scenario: s.name.clone(),
        description: Some(s.description.clone()),
        seed: Some(s.seed),
        epoch_utc: Some(s.epoch_utc.clone()),
        cycle_period_s: Some(s.step_s),
        duration_s: Some(s.duration_s),
        telemetry_every_n_cycles: Some(s.telemetry_every_n_cycles),
        ephemeris_period_s: Some(s.ephemeris_period_s),
        sensors: declared_noise(s),
        declared_effects: Some(s.declared_effects()),
        fss_transfer_function_sigma: declared_fss_spreads(s),
        boot_tables: Some(boot_tables),
        uploads,
        // The spacecraft's identity, which the ground copies beside the tables it calibrates
        // (crate::provenance): `--tables` then says when tables meet another spacecraft.
        spacecraft: crate::provenance::spacecraft_of(s).ok(),
        unknown_keys: Vec::new(),
    }
}

/// Whether the scenario declares the FSS transfer function (its level and spreads are then
/// part of the metadata).
fn fss_transfer_declared(s: &Scenario) -> bool {
    s.declared_effects()
        .iter()
        .any(|e| e == "fss_transfer_function")
}

/// The 1σ spreads of the FSS transfer-function coefficients (metadata
/// `fss_transfer_function_sigma`, for the ground's consider covariance): the magnitudes of the
/// scenario's coefficients, the population a per-seed unit is drawn from
/// ([`crate::sensors::fss::FssHeadErrors::drawn`]) and of which a fixed unit is one member.
/// Only with a declared transfer function.
#[must_use]
pub fn declared_fss_spreads(s: &Scenario) -> Option<TransferSpreads> {
    if !fss_transfer_declared(s) {
        return None;
    }
    let head = |h: &crate::sensors::fss::FssHeadErrors| HeadSpread {
        offset_arcsec: h.offset_arcsec.abs(),
        scale_ppm: h.scale_ppm.abs(),
        cyclic_arcsec: h.cyclic_arcsec.abs(),
        cyclic_pitch_deg: h.cyclic_pitch_deg,
        cross_arcsec_at_corner: h.cross_arcsec_at_corner.abs(),
        cubic_arcsec_at_edge: h.cubic_arcsec_at_edge.abs(),
    };
    let unit = |f: &FssParams| UnitSpread {
        alpha: head(&f.alpha),
        beta: head(&f.beta),
    };
    Some(
        [("FSS1", unit(&s.fss1)), ("FSS2", unit(&s.fss2))]
            .into_iter()
            .map(|(k, v)| (k.to_owned(), v))
            .collect(),
    )
}

/// `truth.json` ([`Truth`], the one definition in `gro_reference::run_folder`).
fn truth(sim: &Simulation, bias: &BiasRecorder) -> anyhow::Result<Truth<Scenario, FssHeadErrors>> {
    let s = sim.scenario();
    let paper = PaperFacts::load()?;
    let m = sim.true_alignments();
    // The alignments at the end of the run (an alignment step applied if it happened within
    // the run): the truth the tables written after the run fly into.
    let end = s.duration_s;
    let steps = [
        s.fhst1.effects.alignment_step_rad(end),
        s.fhst2.effects.alignment_step_rad(end),
        s.fss1.effects.alignment_step_rad(end),
        s.fss2.effects.alignment_step_rad(end),
    ];
    let theta = |k: usize| {
        let t = fsw_core::attitude::rotvec_from_rot(&(m[k] * paper.prelaunch(k).transpose()))
            * ARCSEC_PER_RAD;
        [t.x, t.y, t.z]
    };
    let dm_p = s
        .iru
        .delta_m_true_primary
        .unwrap_or_else(|| rows(&paper.iru_delta_m));
    // The whole scenario as flown (each FSS with the transfer function it flew), so that a
    // scorer needs no scenario file of the same name to know the field functions.
    let mut as_flown = s.clone();
    as_flown.fss1 = s.fss1.as_flown(0, s.seed);
    as_flown.fss2 = s.fss2.as_flown(1, s.seed);
    let triad = |channels: [usize; 3], names: [&str; 3], delta_m| TruthTriad {
        channels: names.map(str::to_owned).to_vec(),
        g: rows(&paper.iru_g),
        delta_m,
        channel_scale_ppm: channels.map(|c| s.iru.channel_scale_ppm[c]),
        high_rate_scale_ppm: channels.map(|c| s.iru.high_rate_scale_ppm[c]),
    };
    let unit = |k: usize| TruthFssUnit {
        alpha: sim.fss()[k].params().alpha,
        beta: sim.fss()[k].params().beta,
    };
    Ok(Truth {
        scenario: s.name.clone(),
        seed: s.seed,
        scenario_as_flown: Some(as_flown),
        alignments: PerSensor::from_array([0, 1, 2, 3].map(|k| rows(&m[k]))),
        alignments_after_run: Some(PerSensor::from_array(
            [0, 1, 2, 3].map(|k| rows(&(fsw_core::attitude::rot(&steps[k]) * m[k]))),
        )),
        misalignment_from_prelaunch_acs_arcsec: Some(PerSensor::from_array([0, 1, 2, 3].map(theta))),
        iru: Some(TruthIru {
            primary: triad(PRIMARY_CHANNELS, ["X2", "Y1", "Z1"], dm_p),
            backup: triad(BACKUP_CHANNELS, ["X1", "Y2", "Z2"], s.iru.delta_m_true_backup),
            convention: "Δθ_acs = (I + delta_m) g Δφ (channel angles X, Y, Z of the triad)".into(),
        }),
        bias_history: Some(TruthBiasHistory {
            period_s: bias.period_s,
            note: "true gyro bias mapped to ACS through the true triad geometry; channel biases in raw channel order X1, X2, Y1, Y2, Z1, Z2".into(),
            samples: bias.samples.clone(),
        }),
        fss_transfer_function: Some(TruthFssTransfer {
            fss1: unit(0),
            fss2: unit(1),
            note: "the transfer function each FSS flew (drawn from the scenario's spreads when transfer_function_per_seed)".into(),
        }),
        present_effects: present_effects(s),
        undeclared_effects: undeclared_effects(s),
        tam: Some(crate::sensors::tam::truth_tams(&s.tam1, &s.tam2)),
        injected_effect: None,
    })
}

/// The run folder's files are written as `NAME.partial` and renamed by [`RunFolder::commit`].
struct RunFolder {
    dir: PathBuf,
    renames: Vec<(PathBuf, PathBuf)>,
}

impl RunFolder {
    fn new(dir: &Path) -> anyhow::Result<Self> {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        // A previous run's summary would make a half-written folder look complete.
        let old = dir.join("summary.json");
        if old.exists() {
            std::fs::remove_file(&old).with_context(|| format!("removing {}", old.display()))?;
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            renames: Vec::new(),
        })
    }

    fn create(&mut self, name: &str) -> anyhow::Result<std::fs::File> {
        let final_path = self.dir.join(name);
        if let Some(parent) = final_path.parent() {
            std::fs::create_dir_all(parent)?;
        }
        let partial = PathBuf::from(format!("{}.partial", final_path.display()));
        let f = std::fs::File::create(&partial)
            .with_context(|| format!("creating {}", partial.display()))?;
        self.renames.push((partial, final_path));
        Ok(f)
    }

    fn write_json(&mut self, name: &str, v: &impl Serialize) -> anyhow::Result<()> {
        let mut f = BufWriter::new(self.create(name)?);
        serde_json::to_writer_pretty(&mut f, v)?;
        f.write_all(b"\n")?;
        f.flush()?;
        Ok(())
    }

    fn commit(self) -> anyhow::Result<()> {
        // summary.json last.
        let (mut last, mut rest): (Vec<_>, Vec<_>) = self
            .renames
            .into_iter()
            .partition(|(_, f)| f.file_name().is_some_and(|n| n == "summary.json"));
        rest.append(&mut last);
        for (from, to) in rest {
            std::fs::rename(&from, &to)
                .with_context(|| format!("renaming {} to {}", from.display(), to.display()))?;
        }
        Ok(())
    }
}

fn progress_bar(enabled: bool, cycles: u64) -> Option<ProgressBar> {
    use std::io::IsTerminal;
    if !enabled || !std::io::stderr().is_terminal() {
        return None;
    }
    let pb = ProgressBar::with_draw_target(Some(cycles), ProgressDrawTarget::stderr());
    pb.set_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {wide_bar} {pos}/{len} cycles ({per_sec}, eta {eta})",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    Some(pb)
}

/// The loop shared by [`run`] and [`bench`].
fn drive<W: Write>(
    sim: &mut Simulation,
    tm: &mut PacketWriter<W>,
    scorer: &mut Scorer,
    mut bias: Option<&mut BiasRecorder>,
    pb: Option<&ProgressBar>,
) -> anyhow::Result<u64> {
    let n_tm = u64::from(sim.scenario().telemetry_every_n_cycles.max(1));
    let eph_period = sim.scenario().ephemeris_period_s;
    let mut next_eph = 0.0;
    let mut aliasing = 0_u64;
    let mut since_downlink = [0_i64; IRU_CHANNELS];
    let mut prev_counts: Option<[u16; IRU_CHANNELS]> = None;
    // APID 0x013 after each downlinked raw frame while the spacecraft carries magnetics.
    let magnetics = sim.magnetics().is_some();
    // APID 0x014 after it while the spacecraft carries the wheel tachometers.
    let wheels = sim.scenario().wheel_tachometers.enabled;
    while let Some(rec) = sim.step() {
        let t = rec.truth.t_s;
        let counts = rec.frame.iru.counts;
        if let Some(prev) = prev_counts {
            for ch in 0..IRU_CHANNELS {
                #[allow(clippy::cast_possible_wrap)]
                let d = counts[ch].wrapping_sub(prev[ch]) as i16;
                since_downlink[ch] += i64::from(d);
            }
        }
        prev_counts = Some(counts);
        let time = rec.frame.time;
        if rec.cycle % n_tm == 0 {
            if since_downlink.iter().any(|d| d.abs() >= 32_768) {
                aliasing += 1;
            }
            since_downlink = [0; IRU_CHANNELS];
            tm.raw(&rec.frame)?;
            if magnetics {
                tm.magnetics(&MagneticsFrame::of_raw_frame(&rec.frame))?;
            }
            if wheels {
                tm.wheels(&WheelFrame::of_raw_frame(&rec.frame))?;
            }
            if t + 1e-9 >= next_eph {
                tm.ephemeris(&EphemerisRecord {
                    time,
                    pos_eci_km: rec.truth.pos_eci_km.into(),
                    vel_eci_km_per_s: rec.truth.vel_eci_km_per_s.into(),
                })?;
                while next_eph <= t + 1e-9 {
                    next_eph += eph_period;
                }
            }
            tm.housekeeping(&rec.output.housekeeping)?;
        }
        for e in &rec.output.events {
            tm.event(time, e)?;
        }
        scorer.add(&rec, &sim.true_attitude().wheel_momentum_nms);
        if let Some(b) = bias.as_deref_mut() {
            b.add(sim, t);
        }
        if let Some(pb) = pb {
            if rec.cycle % PROGRESS_EVERY == 0 {
                pb.set_position(rec.cycle);
            }
        }
    }
    Ok(aliasing)
}

fn summary(
    sim: &Simulation,
    scorer: Scorer,
    wall_s: f64,
    cycles: u64,
    aliasing: u64,
    packets: u64,
    bytes: u64,
) -> Summary {
    let s = sim.scenario();
    let sim_s = (cycles.saturating_sub(1)) as f64 * s.step_s;
    let k = scorer.counters;
    let counters = MeasurementCounters {
        accepted: k.accepted_measurements,
        gated: k.gated_measurements,
        rejected_inputs: k.rejected_inputs,
        stars_identified: k.stars_identified,
        star_id_unmatched: k.star_id_unmatched,
        star_id_ambiguous: k.star_id_ambiguous,
        events_dropped: k.events_dropped,
    };
    let steady = scorer.steady.stats();
    let (coarse_3sigma, coarse_summary) = scorer.coarse.summary();
    Summary {
        scenario: s.name.clone(),
        seed: s.seed,
        timing: LoopTiming::new(sim_s, wall_s, cycles),
        fine_mode_fraction: if steady.cycles > 0 {
            scorer.fine as f64 / steady.cycles as f64
        } else {
            0.0
        },
        attitude_error_arcsec: steady,
        attitude_error_arcsec_all: scorer.all.stats(),
        post_maneuver_error_deg: scorer
            .slews
            .iter()
            .map(|s| s.post_maneuver_error_deg)
            .collect(),
        slews: scorer.slews,
        filter_nees_mean: (scorer.nees_n > 0).then(|| scorer.nees_sum / scorer.nees_n as f64),
        filter_nees_cycles: scorer.nees_n,
        rejected_measurements: u64::from(counters.gated) + u64::from(counters.rejected_inputs),
        measurement_counters: counters,
        tables_loaded: scorer.tables,
        telemetry_packets: packets,
        telemetry_bytes: bytes,
        iru_counter_aliasing_frames: aliasing,
        max_wheel_momentum_nms: scorer.max_wheel,
        coarse_attitude_error_3sigma_deg: coarse_3sigma,
        coarse_attitude: coarse_summary,
        tables_provenance_warning: None,
    }
}

/// The provenance check of a `--tables` folder against the spacecraft flown
/// ([`crate::provenance`]): its message, printed on stderr once per folder and process (a
/// Monte Carlo campaign flies the same folder in every run), or `None` when the tables were
/// calibrated on this spacecraft.
fn tables_provenance(dir: &Path, flown: &Scenario) -> Option<String> {
    static PRINTED: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());
    let msg = crate::provenance::check(dir, flown).message(dir, flown)?;
    if let Ok(mut printed) = PRINTED.lock() {
        if !printed.iter().any(|p| p == dir) {
            printed.push(dir.to_path_buf());
            eprintln!("{msg}");
        }
    }
    Some(msg)
}

/// Fly a scenario; with `opts.out_dir`, write the run folder (module doc).
///
/// # Errors
/// [`crate::InputError`] for bad inputs (tables, parameters); I/O and internal errors.
pub fn run(scenario: Scenario, opts: &RunOptions) -> anyhow::Result<Summary> {
    let mut sim = Simulation::new(scenario, opts.tables_dir.as_deref())?;
    let provenance_warning = opts
        .tables_dir
        .as_deref()
        .and_then(|dir| tables_provenance(dir, sim.scenario()));
    let mut scorer = Scorer::new(&sim);
    let pb = progress_bar(opts.progress, sim.cycle_count());
    let Some(dir) = opts.out_dir.as_deref() else {
        let mut tm = PacketWriter::new(std::io::sink());
        let start = Instant::now();
        let aliasing = drive(&mut sim, &mut tm, &mut scorer, None, pb.as_ref())?;
        let wall = start.elapsed().as_secs_f64();
        if let Some(pb) = pb {
            pb.finish_and_clear();
        }
        let cycles = sim.cycle_count();
        let (packets, bytes) = (tm.packets(), tm.bytes());
        let mut s = summary(&sim, scorer, wall, cycles, aliasing, packets, bytes);
        s.tables_provenance_warning = provenance_warning;
        return Ok(s);
    };
    let mut folder = RunFolder::new(dir)?;
    for (i, up) in sim.uploads().iter().enumerate() {
        let mut f = folder.create(&format!("uploads/{i:02}_{}", up.name))?;
        f.write_all(&up.image)?;
    }
    let file = folder.create("telemetry.bin")?;
    let mut tm = PacketWriter::new(BufWriter::with_capacity(1 << 20, file));
    let mut bias = BiasRecorder::new(&sim);
    let start = Instant::now();
    let aliasing = drive(&mut sim, &mut tm, &mut scorer, Some(&mut bias), pb.as_ref())?;
    let wall = start.elapsed().as_secs_f64();
    if let Some(pb) = pb {
        pb.finish_and_clear();
    }
    let (packets, bytes) = (tm.packets(), tm.bytes());
    tm.finish().context("writing telemetry.bin")?;
    // As a JSON value: its keys sorted, as the `json!` writer had them (the same bytes).
    folder.write_json(METADATA_FILE, &metadata(&sim, &scorer).to_json_value()?)?;
    folder.write_json(TRUTH_FILE, &truth(&sim, &bias)?.to_json_value()?)?;
    let cycles = sim.cycle_count();
    let mut summary = summary(&sim, scorer, wall, cycles, aliasing, packets, bytes);
    summary.tables_provenance_warning = provenance_warning;
    folder.write_json("summary.json", &summary)?;
    folder.commit()?;
    Ok(summary)
}

/// The bench scenario: the embedded gro-early-mission.
///
/// # Errors
/// A defect in the embedded scenario.
pub fn bench_scenario() -> anyhow::Result<Scenario> {
    let (_, text) = crate::scenario::EMBEDDED_SCENARIOS[0];
    let mut s = Scenario::from_toml_str(text, "gro-early-mission (embedded)")?;
    s.base_dir = Some(crate::scenario::scenarios_dir());
    Ok(s)
}

/// `sim-harness bench`: fly the embedded gro-early-mission for `duration_s` with the
/// telemetry encoded into a sink (no files) and report the speed.
///
/// # Errors
/// As [`run`].
pub fn bench(duration_s: f64) -> anyhow::Result<serde_json::Value> {
    let mut s = bench_scenario()?;
    s.duration_s = duration_s;
    let sum = run(s, &RunOptions::default())?;
    Ok(serde_json::to_value(sum.timing)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The FSS systematic level and the coefficients' spreads are declared with a declared
    /// transfer function (the level of the unit, or of the population when drawn per seed)
    /// and left out when the transfer function is undeclared (the ground then uses its
    /// default).
    #[test]
    fn fss_systematic_declared_with_the_transfer_function() {
        let mut s = crate::scenario::resolve("gro-early-mission").unwrap();
        let unit = declared_noise(&s).fss_systematic_arcsec.unwrap();
        let expect = (0.5
            * (s.fss1.transfer_function_rms_arcsec().powi(2)
                + s.fss2.transfer_function_rms_arcsec().powi(2)))
        .sqrt();
        assert!(
            (unit - expect).abs() < 1e-9 && unit > 1.0,
            "{unit} vs {expect}"
        );
        s.fss1.transfer_function_per_seed = true;
        s.fss2.transfer_function_per_seed = true;
        let population = declared_noise(&s).fss_systematic_arcsec.unwrap();
        assert!(population != unit && population > 1.0);
        let spreads = declared_fss_spreads(&s).unwrap();
        assert_eq!(
            spreads.get("FSS1").map(|u| u.beta.scale_ppm),
            Some(s.fss1.beta.scale_ppm.abs())
        );
        s.declared_effects = Some(vec!["aberration".into()]);
        assert!(declared_noise(&s).fss_systematic_arcsec.is_none());
        assert!(declared_fss_spreads(&s).is_none());
    }
}
