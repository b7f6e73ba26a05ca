//! # `ground-tool diagnose RUN_DIR --out DIR`: the whole analysis of a run folder
//!
//! 1. TP, metadata (declared effects: a missing `declared_effects` means the GRO defaults,
//!    the same list `sim-harness` declares), the tables flown (`--tables DIR`, else the
//!    run's activated uploads, else the boot tables);
//! 2. the calibration chain with the current model (`calibrate_telemetry`: FADS with the
//!    declared aberration, FFCAL, adjustment, IRUCAL);
//! 3. residual analysis and the effect loop ([`super::analyse`]), then the gyro side;
//! 4. tables (`OUT/tables/alignment.tbl`, `iru.tbl`, and `filter.tbl` when a filter setting
//!    changes) for a closed-loop run with `sim-harness run ... --tables OUT/tables`;
//! 5. `report.json`, `report.md`, plots; scoring against `truth.json` only if it exists.

use super::gyro::{self, GyroConfig, GyroFrame, GyroInput};
use super::measurements::{DiagnoseInput, MeasurementSet, SENSOR_NAMES};
use super::report::{
    markdown, write_plots, BeforeAfter, DiagnoseReport, FlightSummary, GyroSummary,
};
use super::scoring::{Scorer, ScoringInputs, ScoringOutcome, TableFit};
use super::search::SearchConfig;
use super::{analyse_set, Analysis};
use crate::calibration::iru::GyroCalibration;
use crate::pipeline::calibrate::{
    calibrate_telemetry, read_run, write_table, CalibrateOptions, CalibrationOutput,
};
use crate::pipeline::flown::{flown_catalog, flown_tables};
use crate::tp;
use anyhow::Context;
use fsw_core::tables::{AlignmentTable, FilterTable, IruTable, TableId};
use nalgebra::{Matrix3, Vector3};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The GRO defaults of the declared effects (as `sim-harness` declares them).
pub use crate::pipeline::flown::DEFAULT_DECLARED_EFFECTS as DEFAULT_DECLARED;

/// Options of a diagnose run.
#[derive(Clone, Debug, Default)]
pub struct DiagnoseOptions {
    /// Folder with the tables flown (alignment.tbl, iru.tbl, filter.tbl).
    pub tables: Option<PathBuf>,
    /// Search settings.
    pub search: SearchConfig,
    /// Scores the result against a truth the ground does not have ([`super::scoring`]);
    /// `None` (the ground tool): no scoring.
    pub scorer: Option<std::sync::Arc<dyn Scorer>>,
}

/// Everything a diagnose run produced.
#[derive(Debug)]
pub struct DiagnoseOutput {
    /// The report (also written as JSON).
    pub report: DiagnoseReport,
    /// Sensor-side analysis.
    pub analysis: Analysis,
    /// The calibration chain's output (None when it failed and the flown tables were used),
    /// without its frames (let go before the search).
    pub calibration: Option<CalibrationOutput>,
    /// Time of the first frame (s since J2000, TT).
    pub first_frame_j2000_tt_s: f64,
    /// The alignment table written (the flown one when the held-out validation refused the
    /// new alignments).
    pub alignment: AlignmentTable,
    /// New filter table (if changed).
    pub filter: Option<FilterTable>,
    /// The gyro side (its candidates left over are in the ledger).
    pub gyro: gyro::GyroAnalysis,
}

/// What the analysis takes from the calibration chain. The frames are the chain output's
/// when there is one (not copied: six months of frames are ~0.5 GB).
struct Chain {
    /// The frames when the chain failed (empty otherwise: see [`Chain::frames`]).
    frames: Vec<crate::pipeline::observations::FrameObservations>,
    alignment: AlignmentTable,
    irucal: Option<crate::calibration::iru::IrucalSolution>,
    output: Option<CalibrationOutput>,
}

impl Chain {
    fn frames(&self) -> &[crate::pipeline::observations::FrameObservations] {
        self.output.as_ref().map_or(&self.frames, |o| &o.frames)
    }

    /// Let the frames go (the chain output's included: `DiagnoseOutput::calibration` then
    /// has none). Six months of 30-s frames are 0.37 GB; past the measurement set's build
    /// the analysis reads only their [`GyroFrame`]s.
    fn release_frames(&mut self) {
        self.frames = Vec::new();
        if let Some(o) = self.output.as_mut() {
            o.frames = Vec::new();
        }
    }
}

/// The chain's output without FFCAL/IRUCAL: DA/FADS with the flown tables.
fn chain_fallback(
    tm: &tp::Telemetry,
    metadata: &crate::pipeline::calibrate::Metadata,
    copt: &CalibrateOptions,
) -> anyhow::Result<Chain> {
    use crate::pipeline::calibrate::load_catalog;
    use crate::pipeline::observations::build_observations;
    let alignment = copt
        .flown_alignment
        .unwrap_or_else(AlignmentTable::prelaunch);
    let iru = copt.flown_iru.unwrap_or_else(IruTable::prelaunch);
    let sky = load_catalog()?;
    let frames = build_observations(
        tm,
        &alignment,
        &iru,
        &metadata.sensors,
        &sky,
        &copt.identify,
    );
    Ok(Chain {
        frames,
        alignment,
        irucal: None,
        output: None,
    })
}

/// The IRU table diagnose writes: the flown table, its `G` updated only by the IRUCAL `δM`
/// elements determined at 3σ, and only when the chain itself would update `G` (a redundant,
/// self-consistent fit). The same rule as the effects' table terms ([`super::flight`]): an
/// element the maneuvers do not determine (no rotation about that axis, σ of thousands of
/// ppm) would make the OBC worse, not better. Returns the table and what was done.
#[must_use]
pub fn iru_table_out(flown: &IruTable, chain: Option<&CalibrationOutput>) -> (IruTable, String) {
    let mut out = *flown;
    let Some(c) = chain else {
        return (out, "IRU table as flown (no calibration chain)".to_owned());
    };
    let (Some(sol), Some(rep)) = (&c.irucal, &c.report.iru) else {
        return (out, "IRU table as flown (no IRUCAL solution)".to_owned());
    };
    if !rep.g_updated {
        return (
            out,
            "IRU table as flown (IRUCAL did not update G: δM not significant or not self-consistent)"
                .to_owned(),
        );
    }
    let dm = sol.calibration.delta_m;
    let sig = sol.sigma_delta_m;
    let mut kept = Matrix3::zeros();
    let mut dropped = Vec::new();
    for i in 0..3 {
        for j in 0..3 {
            if dm[(i, j)].abs() > 3.0 * sig[(i, j)] {
                kept[(i, j)] = dm[(i, j)];
            } else if dm[(i, j)] != 0.0 {
                dropped.push(format!(
                    "δM[{i}][{j}] = {:.0} ± {:.0} ppm",
                    dm[(i, j)] * 1e6,
                    sig[(i, j)] * 1e6
                ));
            }
        }
    }
    let g =
        (Matrix3::identity() + kept) * fsw_core::tables::types::matrix_from_rows(&flown.g_primary);
    out.g_primary = fsw_core::tables::types::rows_from_matrix(&g);
    let note = if dropped.is_empty() {
        "IRU table: G updated with the IRUCAL δM".to_owned()
    } else {
        format!(
            "IRU table: G updated with the IRUCAL δM elements determined at 3σ; left as flown: {}",
            dropped.join(", ")
        )
    };
    (out, note)
}

/// The alignment table `calibrate` writes for the same telemetry: its own when its held-out
/// validation passed, else the flown one (`pipeline::calibrate::run_calibrate`); the flown one
/// when the chain failed.
fn calibrate_written_alignment(cal: &Chain, copt: &CalibrateOptions) -> AlignmentTable {
    let flown = copt
        .flown_alignment
        .unwrap_or_else(AlignmentTable::prelaunch);
    match &cal.output {
        Some(o) => crate::pipeline::calibrate::alignment_to_fly(
            cal.alignment,
            flown,
            &o.report.alignment_validation,
        ),
        None => flown,
    }
}

/// Diagnose's flight model against `calibrate_alignment` on held-out data
/// ([`super::heldout`]); also the reference's alignment parameters.
fn validate_tables(
    analysis: &Analysis,
    flight: &super::flight::FlightUpdate,
    cal: &Chain,
    calibrate_alignment: &AlignmentTable,
) -> (
    super::heldout::FlightTableValidation,
    [f64; super::fit::N_ALIGN],
) {
    let m = |t: &AlignmentTable| -> [Matrix3<f64>; 4] {
        let ms = t.matrices();
        std::array::from_fn(|s| fsw_core::tables::types::matrix_from_rows(ms[s]))
    };
    let reference_arcsec =
        super::heldout::alignment_parameters_arcsec(&m(calibrate_alignment), &m(&cal.alignment));
    let reference = match &cal.output {
        Some(o) if o.report.alignment_validation.passed => "calibrate's alignment table",
        Some(_) => "the flown alignment table (calibrate's validation refused its own)",
        None => "the flown alignment table (no calibration chain)",
    };
    (
        super::heldout::validate_flight_tables(
            &analysis.set,
            &analysis.search.layout,
            &flight.flight_idx,
            &analysis.search.fixed,
            &reference_arcsec,
            reference,
        ),
        reference_arcsec,
    )
}

/// What the stages of one diagnosis share: the run's metadata and declared effects, the
/// tables flown, the calibration options, and the report's notes gathered on the way.
struct RunContext<'a> {
    run_dir: &'a Path,
    opts: &'a DiagnoseOptions,
    metadata: crate::pipeline::calibrate::Metadata,
    declared: Vec<String>,
    flown_catalog: Option<fsw_core::tables::StarCatalogTable>,
    flown_filter: Option<FilterTable>,
    copt: CalibrateOptions,
    /// The declared annual and orbital aberration.
    aberration: [bool; 2],
    notes: Vec<String>,
}

/// The three figures of the telemetry the analysis needs after letting it go: six months of
/// it decoded are ~0.2 GB, held otherwise through the analysis (issue 22).
struct TelemetryFigures {
    /// Time of the last raw frame (s): the tables' creation time.
    created: f64,
    /// Housekeeping cycles on the backup IRU configuration.
    backup_cycles: usize,
    /// Housekeeping cycles.
    hk_cycles: usize,
}

impl TelemetryFigures {
    fn of(tm: &tp::Telemetry) -> Self {
        Self {
            created: tm.raw.last().map_or(0.0, |r| r.time.seconds()),
            backup_cycles: tm.housekeeping.iter().filter(|h| h.iru_config == 1).count(),
            hk_cycles: tm.housekeeping.len(),
        }
    }
}

/// What the measurement set's build leaves for the gyro side.
struct GyroSide {
    frames: Vec<GyroFrame>,
    calibration: GyroCalibration,
    /// IRUCAL's δM of the backup triad, when it flew slews.
    delta_m_backup: Option<Matrix3<f64>>,
    bias_per_frame: Option<Vec<Vector3<f64>>>,
    /// Time of the first frame (s since J2000, TT).
    frames_t0_j2000: f64,
}

/// The flight tables before writing, with what the report and the scorer need of their
/// making.
struct FlightTables {
    flight: super::flight::FlightUpdate,
    validation: super::heldout::FlightTableValidation,
    calibrate_alignment: AlignmentTable,
    ground_alignment: AlignmentTable,
    /// Diagnose's tables before the held-out validation: (alignment, parameters, held).
    unvalidated: (AlignmentTable, nalgebra::DVector<f64>, Vec<usize>),
}

/// The tables written and what the report says of the IRU table.
struct WrittenTables {
    paths: Vec<String>,
    alignment: AlignmentTable,
    iru_note: String,
    iru_applied: Vec<String>,
    iru_ground_only: Vec<String>,
    /// The filter terms calibrate tuned that diagnose wrote (`tuned_filter`).
    filter_applied: Vec<String>,
}

/// Per-frame Earth velocity (barycentric, km/s) and apparent Sun direction from the
/// spacecraft (ECI), for the aberration and the FSS models.
fn frame_ephemerides(
    frames: &[crate::pipeline::observations::FrameObservations],
) -> (Vec<Vector3<f64>>, Vec<Vector3<f64>>) {
    let mut earth = Vec::with_capacity(frames.len());
    let mut sun = Vec::with_capacity(frames.len());
    let mut eph: Option<gro_reference::sun::SunEphemeris> = None;
    for f in frames {
        let t = f.time.seconds_since_j2000_tt();
        let e = eph.get_or_insert_with(|| gro_reference::sun::SunEphemeris::new(t, 600.0));
        let st = e.state(t);
        earth.push(st.earth_vel_bary_eci_km_per_s);
        let (p, v) = f.orbit.unwrap_or((Vector3::zeros(), Vector3::zeros()));
        sun.push(st.apparent_dir_from_sc_eci(&p, &v));
    }
    (earth, sun)
}

/// The OBC's gyro bias estimate at each frame: the last housekeeping packet at or before it.
fn obc_bias_per_frame(
    frames: &[crate::pipeline::observations::FrameObservations],
    hk: &[fsw_core::telemetry::ObcHousekeeping],
) -> Vec<Vector3<f64>> {
    let mut bias = Vec::with_capacity(frames.len());
    let mut j = 0usize;
    for f in frames {
        while j + 1 < hk.len() && hk[j + 1].time <= f.time {
            j += 1;
        }
        bias.push(
            hk.get(j)
                .map_or(Vector3::zeros(), |h| Vector3::from(h.bias_acs_rad_per_s)),
        );
    }
    bias
}

/// The note on the unknown orbit modelled from the residuals, when the telemetry has none.
fn unknown_orbit_note(analysis: &Analysis) -> Option<String> {
    let i = analysis
        .search
        .layout
        .effects
        .iter()
        .position(|e| e.kind == super::effects::EffectKind::UnknownOrbit)?;
    let e = &analysis.search.layout.effects[i];
    let period_min = e
        .rate_rad_per_s
        .map_or(f64::NAN, |n| std::f64::consts::TAU / n / 60.0);
    let x = analysis
        .search
        .final_fit
        .expand(analysis.search.layout.total);
    let r: Vec<f64> = analysis.search.layout.range(i).map(|j| x[j]).collect();
    let amplitude = (r.iter().map(|v| v * v).sum::<f64>() / 2.0).sqrt();
    Some(format!(
        "no orbit in the telemetry (no ephemeris records, docs/icd.md §3.4): the declared orbital aberration and Sun parallax are modelled as an unknown circular orbit, period {period_min:.2} min found from the residuals, aberration amplitude {amplitude:.1}″ (≈ 5.3″ for a 7.7 km/s orbit)"
    ))
}

/// The IRU table with the gyro-side effects of the configuration that flew most of the run,
/// when it still validates: (table, terms applied, terms kept on the ground).
fn iru_with_gyro_effects(
    iru_out: IruTable,
    gyro_res: &gyro::GyroAnalysis,
    figures: &TelemetryFigures,
) -> (IruTable, Vec<String>, Vec<String>) {
    let (iru_corrected, iru_applied, mut iru_ground_only) = super::flight::iru_update(
        &iru_out,
        &gyro_res.detected,
        2 * figures.backup_cycles > figures.hk_cycles,
    );
    // A gyro effect too large for the table's range is reported and kept on the ground: the
    // other tables (and the report) are still worth having.
    match iru_corrected.validate() {
        Ok(()) => (iru_corrected, iru_applied, iru_ground_only),
        Err(e) => {
            let why = format!(
                "IRU table not corrected: with the gyro effects ({}) it does not validate ({e:?}); the chain's IRU table is written instead",
                iru_applied.join(", ")
            );
            crate::note!("warning: {why}");
            iru_ground_only.push(why);
            (iru_out, Vec::new(), iru_ground_only)
        }
    }
}

impl<'a> RunContext<'a> {
    /// The declared effects and the tables flown (`--tables`, else the run's activated
    /// uploads, else the boot tables).
    fn new(
        run_dir: &'a Path,
        metadata: crate::pipeline::calibrate::Metadata,
        opts: &'a DiagnoseOptions,
    ) -> anyhow::Result<Self> {
        let declared = metadata.declared();
        let flown_catalog = flown_catalog(run_dir, &metadata, opts.tables.as_deref())?;
        let annual = declared.iter().any(|d| d == "aberration");
        let orbital = declared.iter().any(|d| d == "orbital_aberration");
        let (flown_alignment, flown_iru, flown_filter) =
            flown_tables(run_dir, &metadata, opts.tables.as_deref())?;
        let mut copt = CalibrateOptions {
            flown_alignment,
            flown_iru,
            ..CalibrateOptions::default()
        };
        copt.identify.aberration = annual;
        Ok(Self {
            run_dir,
            opts,
            metadata,
            declared,
            flown_catalog,
            flown_filter,
            copt,
            aberration: [annual, orbital],
            notes: Vec::new(),
        })
    }

    /// The calibration chain with the current model; when it fails (it needs every sensor
    /// observed with another for FFCAL and maneuvers for IRUCAL), the frames with the flown
    /// tables: the joint fit still estimates the alignments from them.
    fn calibration_chain(&mut self, tm: &tp::Telemetry) -> anyhow::Result<Chain> {
        match calibrate_telemetry(tm, &self.metadata, &self.copt) {
            Ok(c) => Ok(Chain {
                frames: Vec::new(),
                alignment: c.alignment,
                irucal: c.irucal.clone(),
                output: Some(c),
            }),
            Err(e) => {
                let why = format!("{e:#}");
                if why.contains("only ") && why.contains("raw sensor frames") {
                    return Err(e);
                }
                self.notes.push(format!(
                    "calibration chain failed ({why}); analysis from the flown tables"
                ));
                chain_fallback(tm, &self.metadata, &self.copt)
            }
        }
    }

    /// The residuals of every FHST and FSS measurement, from the chain's frames with the
    /// per-frame ephemerides and OBC bias; and what the gyro side needs of the frames.
    fn measurement_set(
        &self,
        cal: &Chain,
        (earth, sun): (Vec<Vector3<f64>>, Vec<Vector3<f64>>),
        bias: Vec<Vector3<f64>>,
    ) -> (MeasurementSet, GyroSide) {
        let frames = cal.frames();
        let [annual, orbital] = self.aberration;
        let gyro_cal = cal.irucal.as_ref().map_or(
            GyroCalibration {
                delta_m: Matrix3::zeros(),
                bias_acs_rad_per_s: bias.first().copied().unwrap_or_else(Vector3::zeros),
            },
            |s| s.calibration,
        );
        let input = DiagnoseInput {
            frames,
            earth_vel_eci_km_per_s: earth,
            sun_eci: sun,
            gyro: gyro_cal,
            bias_per_frame: Some(bias),
            alignment: cal.alignment,
            frames_aberration: annual,
            aberration_model: [annual, orbital],
            declared_effects: self.declared.clone(),
        };
        crate::progress::step("residuals of every FHST and FSS measurement");
        let set = MeasurementSet::build(&input);
        let side = GyroSide {
            frames: frames.iter().map(GyroFrame::from).collect(),
            frames_t0_j2000: frames
                .first()
                .map_or(0.0, |f| f.time.seconds_since_j2000_tt()),
            calibration: input.gyro,
            delta_m_backup: cal
                .output
                .as_ref()
                .and_then(|o| o.report.iru.as_ref()?.backup.as_ref())
                .map(|b| fsw_core::tables::types::matrix_from_rows(&b.delta_m)),
            bias_per_frame: input.bias_per_frame,
        };
        (set, side)
    }

    /// The gyro residuals in the slews and their ledger.
    fn gyro_analysis(
        &self,
        side: &GyroSide,
        analysis: &Analysis,
    ) -> (gyro::GyroAnalysis, Vec<super::ledger::LedgerEntry>) {
        let opts = self.opts;
        let gcfg = GyroConfig {
            alpha: opts.search.alpha,
            min_delta_bic: opts.search.min_delta_bic,
            rrw_rad_per_s15: self.metadata.sensors.iru_rrw_rad_per_s_sqrt_s,
            arw_rad_per_sqrt_s: self.metadata.sensors.iru_arw_rad_per_sqrt_s,
            transient_declared: self.declared.iter().any(|d| d == "iru_bias_transient"),
        };
        let gyro_input = GyroInput {
            frames: &side.frames,
            gyro: side.calibration,
            bias_per_frame: side.bias_per_frame.as_deref(),
            delta_m_backup: side.delta_m_backup,
        };
        crate::progress::step("gyro residuals in the slews");
        let gyro_res = gyro::analyse(&gyro_input, &analysis.set, &analysis.search.after, &gcfg);
        let gyro_ledger = super::ledger::gyro_ledger(&gyro_res, opts.search.alpha);
        (gyro_res, gyro_ledger)
    }

    /// Diagnose's flight tables, validated against the table calibrate writes on held-out
    /// blocks of time (`super::heldout`): the tables are rebuilt from the reference with only
    /// the components the validation took; nothing taken, calibrate's alignment table is
    /// written. Every term left out is listed as not written.
    fn flight_tables(&mut self, analysis: &Analysis, cal: &Chain) -> anyhow::Result<FlightTables> {
        let filter_flown = self.flown_filter.unwrap_or_else(FilterTable::default_boot);
        let flight_all = super::flight::flight_update(
            &analysis.search,
            &cal.alignment,
            &filter_flown,
            self.flown_catalog.as_ref(),
            analysis.set.count_per_sensor(),
            analysis.set.temperature_mean_c,
            None,
        )?;
        crate::progress::step("held-out validation of the tables");
        let calibrate_alignment = calibrate_written_alignment(cal, &self.copt);
        let (validation, reference_arcsec) =
            validate_tables(analysis, &flight_all, cal, &calibrate_alignment);
        let validated = validation.passed;
        let ground_alignment = flight_all.ground_alignment;
        let unvalidated = (
            flight_all.alignment,
            flight_all.flight_fit.expand(analysis.search.layout.total),
            flight_all.flight_idx.clone(),
        );
        let mut flight = if validated {
            super::flight::flight_update(
                &analysis.search,
                &calibrate_alignment,
                &filter_flown,
                self.flown_catalog.as_ref(),
                analysis.set.count_per_sensor(),
                analysis.set.temperature_mean_c,
                Some(super::flight::Restriction {
                    free: &validation.taken_params,
                    reference_arcsec,
                }),
            )?
        } else {
            let mut f = flight_all;
            let terms: Vec<String> = f.applied.drain(..).collect();
            f.ground_only.extend(
                terms
                    .into_iter()
                    .map(|a| format!("not written (held-out validation): {a}")),
            );
            f.alignment = calibrate_alignment;
            f.catalog = None;
            f.filter = None;
            f.flight_idx.clear();
            self.notes.push(format!(
                "diagnose's tables not written; the alignment table calibrate writes is written instead: {}",
                validation.reason
            ));
            f
        };
        if validated {
            flight
                .ground_only
                .extend(validation.not_taken.iter().map(|c| {
                    let trackers = c
                        .trackers
                        .map_or_else(String::new, |t| format!(", trackers' rows {}", t.z_text()));
                    format!(
                        "not written (held-out validation, {}{trackers}): {}",
                        c.improvement.z_text(),
                        c.component
                    )
                }));
        }
        self.chain_filter(cal, &mut flight, &filter_flown)?;
        Ok(FlightTables {
            flight,
            validation,
            calibrate_alignment,
            ground_alignment,
            unvalidated,
        })
    }

    /// What `calibrate` uplinks as well (`calibrate::filter_update`): the onboard annual-
    /// aberration correction when the model declares aberration and the flown table has it
    /// off. Only when the chain's held-out check of that change passed
    /// (`pipeline::alignment_heldout::validate_aberration_switch`).
    fn chain_filter(
        &self,
        cal: &Chain,
        flight: &mut super::flight::FlightUpdate,
        filter_flown: &FilterTable,
    ) -> anyhow::Result<()> {
        let chain_filter_validated = cal.output.as_ref().is_some_and(|o| o.filter.is_some());
        let (chain_filter, chain_changes) = if chain_filter_validated {
            crate::pipeline::calibrate::filter_update(
                flight.filter.as_ref().unwrap_or(filter_flown),
                &self.metadata,
            )?
        } else {
            (None, Vec::new())
        };
        if let Some(f) = chain_filter {
            flight.filter = Some(f);
            flight.applied.extend(
                chain_changes
                    .iter()
                    .map(|c| format!("calibration chain: filter.{c}")),
            );
        }
        Ok(())
    }

    /// Writes `OUT/tables/`: the alignment table, the IRU table (IRUCAL's δM unless the gyro
    /// residuals hold unexplained structure, then the gyro-side effects), the star catalog
    /// and the filter table when diagnose changed them.
    fn write_tables(
        &mut self,
        out_dir: &Path,
        cal: &Chain,
        flight: &super::flight::FlightUpdate,
        (gyro_res, gyro_ledger): (&gyro::GyroAnalysis, &[super::ledger::LedgerEntry]),
        figures: &TelemetryFigures,
    ) -> anyhow::Result<WrittenTables> {
        let created = figures.created;
        std::fs::create_dir_all(out_dir.join("tables"))
            .with_context(|| format!("creating {}", out_dir.display()))?;
        let mut written = Vec::new();
        let p = out_dir.join("tables").join("alignment.tbl");
        // The chain's held-out validation judges the chain's model; diagnose's tables carry
        // the effects it found on top (a time tag, say), which that model lacks: a refusal
        // there makes the flown table the reference of diagnose's own validation above.
        if let Some(v) = cal
            .output
            .as_ref()
            .map(|o| &o.report.alignment_validation)
            .filter(|v| !v.passed)
        {
            self.notes.push(format!(
                "calibrate's held-out validation refused its own alignments ({}); diagnose's tables were validated against the flown ones",
                v.reason
            ));
        }
        let alignment_out = flight.alignment;
        write_table(&p, TableId::Alignment, &alignment_out, created)?;
        written.push(p.display().to_string());
        // An IRUCAL whose gyro residuals hold structure nothing explains (a bias step or ramp,
        // a scale error against rate outside the library) is not trusted: its δM absorbed
        // that structure (issue 22), so G stays as flown and the report says why.
        let flown_iru_table = self.copt.flown_iru.unwrap_or_else(IruTable::prelaunch);
        let gyro_unexplained = super::ledger::unexplained_items(gyro_ledger);
        let (iru_out, iru_note) = if gyro_unexplained.is_empty() {
            iru_table_out(&flown_iru_table, cal.output.as_ref())
        } else {
            (
                flown_iru_table,
                format!(
                    "IRU table as flown: the gyro residuals hold unexplained structure ({}), so the IRUCAL δM is not written",
                    gyro_unexplained
                        .iter()
                        .map(|u| format!(
                            "{} against {}, {:.3} {}, Holm p {:.1e}",
                            u.sensor, u.regressor, u.size, u.unit, u.p_value
                        ))
                        .collect::<Vec<_>>()
                        .join("; ")
                ),
            )
        };
        let (iru_out, iru_applied, iru_ground_only) =
            iru_with_gyro_effects(iru_out, gyro_res, figures);
        iru_out
            .validate()
            .map_err(|e| anyhow::anyhow!("diagnose: the IRU table does not validate ({e:?})"))?;
        let p = out_dir.join("tables").join("iru.tbl");
        write_table(&p, TableId::Iru, &iru_out, created)?;
        written.push(p.display().to_string());
        if let Some(c) = &flight.catalog {
            let p = out_dir.join("tables").join("star_catalog.tbl");
            write_table(&p, TableId::StarCatalog, c, created)?;
            written.push(p.display().to_string());
        }
        let filter_flown = self.flown_filter.unwrap_or_else(FilterTable::default_boot);
        let (filter_out, filter_applied) = self.tuned_filter(
            cal,
            flight.filter.unwrap_or(filter_flown),
            gyro_unexplained.is_empty(),
        );
        if flight.filter.is_some() || !filter_applied.is_empty() {
            let p = out_dir.join("tables").join("filter.tbl");
            write_table(&p, TableId::Filter, &filter_out, created)?;
            written.push(p.display().to_string());
        }
        Ok(WrittenTables {
            paths: written,
            alignment: alignment_out,
            iru_note,
            iru_applied,
            iru_ground_only,
            filter_applied,
        })
    }

    /// The filter-table terms calibrate tuned from the flight (`pipeline::filter_tuning`) on
    /// top of `filter`, as calibrate wrote them; the slew uncertainty only when G is
    /// calibrate's (`g_is_calibrates`: it was derived from that G's residual error). Returns
    /// the table and the terms applied.
    fn tuned_filter(
        &mut self,
        cal: &Chain,
        mut filter: FilterTable,
        g_is_calibrates: bool,
    ) -> (FilterTable, Vec<String>) {
        use crate::pipeline::filter_tuning::FilterTerm;
        let mut applied = Vec::new();
        for t in cal
            .output
            .iter()
            .flat_map(|o| o.report.filter_tuning.iter())
            .filter(|t| t.written)
        {
            if t.field == FilterTerm::SlewUncertainty && !g_is_calibrates {
                self.notes.push(format!(
                    "filter.{} not written: G stays as flown, and calibrate's value was derived for its own G",
                    t.field.field()
                ));
                continue;
            }
            let mut f = filter;
            if t.apply(&mut f) && f.validate().is_ok() {
                filter = f;
                applied.push(format!(
                    "calibration chain: filter.{}: {}",
                    t.field.field(),
                    t.reason
                ));
            }
        }
        (filter, applied)
    }

    /// The report: detections, ledger, residuals, iterations, the gyro side, the tables, and
    /// the scorer's figures when one is plugged in.
    #[allow(clippy::too_many_arguments)]
    fn report(
        self,
        analysis: &Analysis,
        cal: &Chain,
        tables: FlightTables,
        written: WrittenTables,
        (gyro_res, gyro_ledger): (&gyro::GyroAnalysis, Vec<super::ledger::LedgerEntry>),
        frames_t0_j2000: f64,
    ) -> anyhow::Result<DiagnoseReport> {
        let FlightTables {
            flight,
            validation,
            calibrate_alignment,
            ground_alignment,
            unvalidated,
        } = tables;
        let mut detected = analysis.detected.clone();
        detected.extend(gyro_res.detected.iter().cloned());
        let names = SENSOR_NAMES;
        let to_map = |v: [f64; 4]| -> BTreeMap<String, f64> {
            (0..4)
                .filter(|&i| v[i].is_finite())
                .map(|i| (names[i].to_owned(), v[i]))
                .collect()
        };
        let counts = analysis.set.count_per_sensor();
        let (g_flight, g_unvalidated) = (
            flight.flight_fit.expand(analysis.search.layout.total),
            &unvalidated.1,
        );
        let outcome = match &self.opts.scorer {
            Some(scorer) => scorer.score(&ScoringInputs {
                run_dir: self.run_dir,
                analysis,
                detected: &detected,
                chain_alignment: &cal.alignment,
                ground_alignment: &ground_alignment,
                calibrate_alignment: &calibrate_alignment,
                written: TableFit {
                    alignment: &written.alignment,
                    parameters: &g_flight,
                    held: &flight.flight_idx,
                },
                unvalidated: TableFit {
                    alignment: &unvalidated.0,
                    parameters: g_unvalidated,
                    held: &unvalidated.2,
                },
                first_frame_j2000_tt_s: frames_t0_j2000,
            })?,
            None => ScoringOutcome::default(),
        };
        Ok(DiagnoseReport {
            run_dir: self.run_dir.display().to_string(),
            scenario: self.metadata.scenario.clone(),
            declared_effects: self.declared,
            baseline_model: analysis
                .search
                .baseline
                .iter()
                .map(|&i| analysis.search.layout.effects[i].label())
                .collect(),
            detected: detected.clone(),
            unexplained: analysis
                .unexplained
                .iter()
                .cloned()
                .chain(super::ledger::unexplained_items(&gyro_ledger))
                .collect(),
            ledger: analysis.ledger.iter().cloned().chain(gyro_ledger).collect(),
            residual_rms_arcsec: BeforeAfter {
                before: to_map(analysis.rms_before),
                after: to_map(analysis.rms_after),
            },
            noise_floor_arcsec: to_map(analysis.set.noise_floor_arcsec),
            measurements: (0..4).map(|i| (names[i].to_owned(), counts[i])).collect(),
            iterations: analysis.search.iterations.len(),
            iteration_log: analysis.search.iterations.clone(),
            gyro: GyroSummary {
                bias_samples: gyro_res.bias_samples,
                slews: gyro_res.slews,
                candidates: gyro_res.candidates.clone(),
                notes: gyro_res.notes.clone(),
            },
            flight_tables: FlightSummary {
                written: written.paths,
                applied: {
                    let mut a = flight.applied.clone();
                    a.push(written.iru_note.clone());
                    a.extend(written.iru_applied);
                    a.extend(written.filter_applied);
                    a
                },
                ground_only: {
                    let mut g = flight.ground_only.clone();
                    g.extend(written.iru_ground_only);
                    g
                },
                validation: Some(validation),
            },
            calibration_error_arcsec: outcome.calibration_error_arcsec,
            calibration_rotation_error_arcsec: outcome.calibration_rotation_error_arcsec,
            written_table_error_arcsec: outcome.written_table_error_arcsec,
            unvalidated_table_error_arcsec: outcome.unvalidated_table_error_arcsec,
            scoring: outcome.scoring,
            plots: Vec::new(),
            notes: self.notes,
        })
    }
}

/// Writes the plots, `report.json` and `report.md` of `report` into `out_dir`.
fn write_report(
    out_dir: &Path,
    report: &mut DiagnoseReport,
    analysis: &Analysis,
    gyro_res: &gyro::GyroAnalysis,
) -> anyhow::Result<()> {
    crate::progress::step("report and plots");
    report.plots = write_plots(out_dir, analysis, &report.detected, gyro_res)?;
    std::fs::write(
        out_dir.join("report.json"),
        serde_json::to_string_pretty(&report)?,
    )
    .with_context(|| format!("writing {}", out_dir.join("report.json").display()))?;
    std::fs::write(out_dir.join("report.md"), markdown(report))
        .with_context(|| format!("writing {}", out_dir.join("report.md").display()))?;
    Ok(())
}

/// Run the diagnosis of a run folder and write the report and tables into `out_dir`.
///
/// # Errors
/// Missing or malformed inputs (the message says what), too little data, I/O.
pub fn diagnose_run(
    run_dir: &Path,
    out_dir: &Path,
    opts: &DiagnoseOptions,
) -> anyhow::Result<DiagnoseOutput> {
    // 1. The telemetry, the metadata, the tables flown, the calibration chain.
    crate::progress::step("reading the telemetry");
    let (tm, metadata) = read_run(run_dir)?;
    let mut ctx = RunContext::new(run_dir, metadata, opts)?;
    let mut cal = ctx.calibration_chain(&tm)?;
    // 2. Per-frame ephemerides and OBC bias; the telemetry is let go but for three figures.
    let ephemerides = frame_ephemerides(cal.frames());
    let bias = obc_bias_per_frame(cal.frames(), &tm.housekeeping);
    let figures = TelemetryFigures::of(&tm);
    drop(tm);
    // 3. The measurement set; then the frames are let go.
    let (set, gyro_side) = ctx.measurement_set(&cal, ephemerides, bias);
    cal.release_frames();
    // 4. Residual structure and the effect library (joint fit), and its notes.
    crate::progress::step("residual structure and the effect library (joint fit)");
    let analysis = analyse_set(set, &ctx.declared, &opts.search)?;
    ctx.notes.extend(unknown_orbit_note(&analysis));
    ctx.notes
        .extend(coverage_notes(&analysis.set, gyro_side.frames.len(), |k| {
            gyro_side.frames.get(k).is_some_and(|f| f.high_rate)
        }));
    ctx.notes.extend(super::change_point::attribution_notes(
        &analysis.set,
        &analysis.search,
    ));
    // 5. The gyro side.
    let (gyro_res, gyro_ledger) = ctx.gyro_analysis(&gyro_side, &analysis);
    // 6. The flight tables, validated on held-out data, and written.
    let tables = ctx.flight_tables(&analysis, &cal)?;
    let written = ctx.write_tables(
        out_dir,
        &cal,
        &tables.flight,
        (&gyro_res, &gyro_ledger),
        &figures,
    )?;
    // 7. The report.
    let alignment = written.alignment;
    let filter = tables.flight.filter;
    let mut report = ctx.report(
        &analysis,
        &cal,
        tables,
        written,
        (&gyro_res, gyro_ledger),
        gyro_side.frames_t0_j2000,
    )?;
    write_report(out_dir, &mut report, &analysis, &gyro_res)?;
    Ok(DiagnoseOutput {
        report,
        analysis,
        alignment,
        filter,
        calibration: cal.output,
        first_frame_j2000_tt_s: gyro_side.frames_t0_j2000,
        gyro: gyro_res,
    })
}

/// `ground-tool diagnose RUN_DIR --out OUT`: check the run, diagnose it into a temporary
/// sibling of `OUT` and rename it into place, write the tables' manifest, print the findings
/// (or `report.json` with `json`). One definition for the ground tool (no scorer) and the
/// evaluation binary `diagnose-scored` of the `tests` crate (a scorer against `truth.json`).
///
/// # Errors
/// As [`diagnose_run`]; a refusal about the data is an [`crate::run_check::InputError`]
/// (exit code 2), an I/O error a runtime failure.
pub fn diagnose_command(
    args: &crate::run_check::CommandArgs<'_>,
    scorer: Option<std::sync::Arc<dyn Scorer>>,
) -> anyhow::Result<()> {
    let (run_dir, out_target) = (args.run_dir, args.out);
    let progress = crate::progress::Session::start("ground-tool diagnose", !args.quiet);
    let options = DiagnoseOptions {
        tables: args.tables.map(std::path::Path::to_path_buf),
        scorer,
        ..DiagnoseOptions::default()
    };
    let dir = args.begin_output("ground-tool diagnose")?;
    let out = dir.path();
    let assumed = crate::pipeline::flown::assumed_tables(
        run_dir,
        &crate::pipeline::flown::metadata_checked(run_dir)?,
        args.tables,
    )?;
    crate::run_check::check_run_dir(run_dir, out, &assumed, args.trust_tables)?;
    // Diagnose's refusals (too few frames, a singular fit) are about the data: exit code 2;
    // an I/O error (writing the report) stays a runtime failure.
    let result = diagnose_run(run_dir, out, &options).map_err(|e| {
        if e.chain().any(|c| c.is::<std::io::Error>()) || gro_reference::is_input_error(&e) {
            e
        } else {
            crate::run_check::InputError(e.context(format!(
                "{}: the telemetry does not support a diagnosis",
                run_dir.display()
            )))
            .into()
        }
    })?;
    // The folder is new: its images are exactly the ones this diagnose wrote.
    gro_reference::manifest::write_for_all(&out.join("tables"), "ground-tool diagnose")?;
    gro_reference::provenance::write(
        &out.join("tables"),
        run_dir,
        &crate::pipeline::flown::metadata_or_default(run_dir),
        "ground-tool diagnose",
    )?;
    // Diagnose names the files it wrote by the temporary folder's path: name them by OUT.
    let (tmp, target) = (out.display().to_string(), out_target.display().to_string());
    for f in ["report.json", "report.md"] {
        let p = out.join(f);
        if let Ok(text) = std::fs::read_to_string(&p) {
            std::fs::write(&p, text.replace(&tmp, &target))
                .with_context(|| format!("cannot write {}", p.display()))?;
        }
    }
    dir.commit()?;
    drop(progress);
    for note in &result.report.notes {
        eprintln!("note: {note}");
    }
    if args.json {
        let text = serde_json::to_string_pretty(&result.report)?;
        println!("{}", text.replace(&tmp, &target));
    } else {
        let r = &result.report;
        for d in &r.detected {
            eprintln!(
                "detected: {} [{}] (ΔBIC {:.1})",
                d.effect, d.sensor, d.evidence.delta_bic
            );
        }
        for u in &r.unexplained {
            eprintln!(
                "unexplained: {} {} follows {} ({:.2}\", p {:.1e})",
                u.sensor, u.axis, u.regressor, u.size, u.p_value
            );
        }
        eprintln!(
            "wrote {}/report.md, report.json and tables/",
            out_target.display()
        );
    }
    Ok(())
}

/// What a sensor's data leave untestable: no usable sample at all, data in one hold only
/// (a field-dependent error or an alignment variation is then its alignment), or no sample
/// in a slew (its time tag needs the body to turn). Without these notes an untested
/// sensor's candidates read as "checked, nothing found" (helper-20's review: FSS2 sees the
/// Sun in one hold of the writer's long plan).
fn coverage_notes(
    set: &super::measurements::MeasurementSet,
    n_frames: usize,
    high_rate: impl Fn(usize) -> bool,
) -> Vec<String> {
    use super::measurements::SENSOR_NAMES;
    // Hold index of every frame: a hold ends where high-rate (slew) frames begin.
    let mut hold = Vec::with_capacity(n_frames);
    let mut h = 0usize;
    let mut in_slew = false;
    for k in 0..n_frames {
        let hr = high_rate(k);
        if hr && !in_slew {
            h += 1;
        }
        in_slew = hr;
        hold.push(h);
    }
    let mut notes = Vec::new();
    for (s, name) in SENSOR_NAMES.iter().enumerate() {
        let mine: Vec<_> = set
            .meas
            .iter()
            .filter(|m| m.sensor == s && !m.outlier)
            .collect();
        if mine.is_empty() {
            notes.push(format!(
                "{name}: no usable measurement: none of its effects was tested"
            ));
            continue;
        }
        let mut holds: Vec<usize> = mine
            .iter()
            .filter(|m| !m.high_rate)
            .filter_map(|m| hold.get(m.frame).copied())
            .collect();
        holds.sort_unstable();
        holds.dedup();
        let in_slews = mine.iter().filter(|m| m.high_rate).count();
        if holds.len() < 2 {
            notes.push(format!(
                "{name}: data in {} hold(s) ({} samples): its field-dependent errors and alignment variations cannot be told from its alignment and were not testable",
                holds.len(),
                mine.len()
            ));
        }
        if in_slews == 0 {
            notes.push(format!(
                "{name}: no sample during slews: its time tag was not testable"
            ));
        }
    }
    notes
}
