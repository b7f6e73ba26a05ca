//! # The seam where a scorer against the simulator's truth plugs into `diagnose`
//!
//! Why a seam and not the scorer: scoring needs the truth's field functions (the simulated
//! FSS transfer function, FHST distortion) and the scenario, i.e. the simulator's own models.
//! A ground tool that carried them would let errors common to truth and ground cancel unseen,
//! and no real ground system has them. So the analysis never scores: `ground-tool diagnose`
//! writes no `scoring` section, and the evaluation binary `diagnose-scored` of the `tests`
//! crate (`gro_tests::diagnose::scoring`) runs the same diagnosis with a [`Scorer`] that
//! reads `truth.json`. What a scorer sees is [`ScoringInputs`]; what it returns is
//! [`ScoringOutcome`], written into `report.json` and `report.md` labelled as scoring.

use super::search::SearchResult;
use super::{Analysis, Detected};
use fsw_core::tables::AlignmentTable;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::Path;

/// One parameter compared with the truth.
#[derive(Clone, Debug, Serialize)]
pub struct ParameterCheck {
    /// Effect label.
    pub effect: String,
    /// Sensor.
    pub sensor: String,
    /// Parameter.
    pub parameter: String,
    /// Estimate.
    pub estimate: f64,
    /// 1σ.
    pub sigma: f64,
    /// True value.
    pub truth: f64,
    /// (estimate − truth)/σ.
    pub z: f64,
}

/// Before/after per sensor.
#[derive(Clone, Debug, Default, Serialize)]
pub struct BeforeAfter {
    /// Before.
    pub before: BTreeMap<String, f64>,
    /// After.
    pub after: BTreeMap<String, f64>,
}

/// Scoring block (truth.json present).
#[derive(Clone, Debug, Serialize)]
pub struct Scoring {
    /// Always "scoring only: from truth.json, never used by the analysis".
    pub label: String,
    /// Undeclared effects of the truth.
    pub truth_undeclared_effects: Vec<String>,
    /// Each detection and whether the truth has that effect on that unit.
    pub detections_in_truth: Vec<(String, String, bool)>,
    /// Parameter estimates against the scenario's values.
    pub parameters: Vec<ParameterCheck>,
    /// Where the true field functions (FSS transfer function, FHST distortion) of the table
    /// errors came from, or why they are unknown (then counted as zero).
    pub field_truth: String,
}

/// A table written (or that would have been written) with the parameters of the fit it holds.
#[derive(Clone, Copy, Debug)]
pub struct TableFit<'a> {
    /// The alignment table.
    pub alignment: &'a AlignmentTable,
    /// The fit's parameter vector (the layout's whole length).
    pub parameters: &'a nalgebra::DVector<f64>,
    /// The parameters the table holds ([`super::flight`]).
    pub held: &'a [usize],
}

/// What a finished diagnosis offers a scorer: the tables at each stage and the model.
#[derive(Clone, Copy, Debug)]
pub struct ScoringInputs<'a> {
    /// The run folder (its `truth.json`, if any, is the scorer's business).
    pub run_dir: &'a Path,
    /// The sensor-side analysis (measurements, search, final fit).
    pub analysis: &'a Analysis,
    /// Every detected effect, sensor and gyro side.
    pub detected: &'a [Detected],
    /// The calibration chain's alignments (before diagnose's model).
    pub chain_alignment: &'a AlignmentTable,
    /// The ground model's alignments (the final fit).
    pub ground_alignment: &'a AlignmentTable,
    /// The table `calibrate` writes for the same telemetry.
    pub calibrate_alignment: &'a AlignmentTable,
    /// The table diagnose wrote, with its fit.
    pub written: TableFit<'a>,
    /// The table diagnose would have written without its held-out validation.
    pub unvalidated: TableFit<'a>,
    /// Time of the first frame (s since J2000, TT).
    pub first_frame_j2000_tt_s: f64,
}

impl ScoringInputs<'_> {
    /// The field correction (arcsec, sensor axes) of measurement `k` by the model's field
    /// effects (transfer function, distortion) with the parameters of `g` a table holds
    /// (`held`; `None`: all of them, the ground model).
    #[must_use]
    pub fn field_arcsec(
        &self,
        g: &nalgebra::DVector<f64>,
        held: Option<&[usize]>,
        k: usize,
    ) -> [f64; 2] {
        field_arcsec(&self.analysis.search, &self.analysis.set, g, held, k)
    }
}

/// What a scorer returns: each field goes into `report.json` under its name.
#[derive(Clone, Debug, Default)]
pub struct ScoringOutcome {
    /// `calibration_error_arcsec`: the chain's and the ground model's alignments.
    pub calibration_error_arcsec: Option<BeforeAfter>,
    /// `calibration_rotation_error_arcsec`.
    pub calibration_rotation_error_arcsec: Option<BeforeAfter>,
    /// `written_table_error_arcsec`: calibrate's table and diagnose's.
    pub written_table_error_arcsec: Option<BeforeAfter>,
    /// `unvalidated_table_error_arcsec`.
    pub unvalidated_table_error_arcsec: Option<BTreeMap<String, f64>>,
    /// `scoring`.
    pub scoring: Option<Scoring>,
}

/// Scores a finished diagnosis against a truth the ground does not have.
pub trait Scorer: std::fmt::Debug + Send + Sync {
    /// The scores of this run (`ScoringOutcome::default()`: nothing to score, e.g. no
    /// `truth.json`).
    ///
    /// # Errors
    /// A truth file that exists but cannot be read.
    fn score(&self, inputs: &ScoringInputs<'_>) -> anyhow::Result<ScoringOutcome>;
}

/// The field correction (arcsec, sensor axes) of measurement `k` by the field effects of the
/// search's model (transfer function, distortion) with the parameters of `g` that a table
/// holds (`held`; `None`: all of them, the ground model).
#[must_use]
pub fn field_arcsec(
    res: &SearchResult,
    set: &super::measurements::MeasurementSet,
    g: &nalgebra::DVector<f64>,
    held: Option<&[usize]>,
    k: usize,
) -> [f64; 2] {
    let m = &set.meas[k];
    let mut out = [0.0; 2];
    let mut cols = Vec::new();
    for &i in res.baseline.iter().chain(&res.added) {
        if !matches!(
            res.layout.effects[i].kind,
            super::effects::EffectKind::FssTransferFunction
                | super::effects::EffectKind::FhstDistortion
        ) {
            continue;
        }
        cols.clear();
        res.layout.effects[i].columns(m, &|_| None, &mut cols);
        let o = res.layout.offsets[i];
        for (p, v) in &cols {
            if held.is_none_or(|h| h.contains(&(o + p))) {
                out[0] += v[0] * g[o + p];
                out[1] += v[1] * g[o + p];
            }
        }
    }
    out
}
