//! # Diagnose: residual analysis that finds effects the model lacks (issue 5)
//!
//! Calibration fixes the parameters of a model; it cannot fix a model that lacks an effect.
//! `ground-tool diagnose RUN_DIR --out DIR` runs the calibration chain with the current model,
//! then:
//!
//! 1. [`measurements`]: residuals of every FHST star and FSS Sun sample, in the sensor's own
//!    axes, against a ground fine attitude (FHST batches every ≤ 60 s with gyro propagation),
//!    with the regressors telemetry and ephemerides provide;
//! 2. [`structure`]: structure tests with stated significance (binned means against the noise,
//!    cubic fits, orbital harmonics, per-star grouping), Holm–Bonferroni corrected;
//! 3. [`effects`] + [`fit`]: a library of candidate effects, each a parameterised addition with
//!    its own partials, fitted jointly with the alignments and the batch attitudes;
//! 4. [`search`]: the loop — add the best-supported effect (likelihood ratio, BIC, agreement
//!    of the halves, adequacy), refit, test again; leftover structure is reported as
//!    unexplained with the regressor it follows;
//!    [`time_reference`]: the time tags against the gyro, from whole slews tied to the
//!    holds around them (the batches determine only their differences);
//! 5. [`gyro`]: the same for the gyro (bias drift and thermal bias from the hold-to-hold
//!    attitude differences, scale asymmetry from the slews);
//! 6. [`flight`]: effects the OBC should correct become table data (alignment corrections,
//!    filter aberration flag) that `fsw-core` applies, written only when [`heldout`] finds
//!    that they lower the held-out residuals against the table `calibrate` writes;
//! 7. [`ledger`]: every test significant after its multiplicity correction ends explained by
//!    an accepted effect or in `unexplained` with its size, regressor and the reason nothing
//!    was named (the candidates are tested once more against the final model for it);
//! 8. [`report`]: `report.md` with before/after plots against the guilty regressor and
//!    `report.json`; scoring against the simulator's truth is not the ground's: [`scoring`]
//!    is the seam the evaluation binary `diagnose-scored` (`tests` crate) plugs into.
//!
//! Frames with known effects for tests (`synthetic`), effects injected into real run folders
//! (`inject`) and the scorer live in the `tests` crate (`gro_tests::diagnose`).

pub mod change_point;
pub mod effects;
pub mod fit;
pub mod flight;
pub mod gyro;
mod gyro_data;
mod gyro_slews;
pub mod heldout;
pub mod ledger;
pub mod measurements;
pub mod regressor;
pub mod report;
pub mod run;
pub mod scoring;
pub mod search;
pub mod search_result;
pub mod sparse_catalog;
pub mod stats;
pub mod structure;
pub mod time_reference;

use measurements::{DiagnoseInput, MeasurementSet, SENSOR_NAMES};
use search::{search, SearchConfig, SearchResult};
use serde::Serialize;
use std::collections::BTreeMap;

/// A detected effect.
#[derive(Clone, Debug, Serialize)]
pub struct Detected {
    /// Effect name (library name, e.g. `time_tag_offset`).
    pub effect: String,
    /// Sensor (`FHST1` … `FSS2`, `IRU`, or `all`).
    pub sensor: String,
    /// Parameter estimates (name → value, units in `units`).
    pub parameters: BTreeMap<String, f64>,
    /// 1σ of each parameter.
    pub sigma: BTreeMap<String, f64>,
    /// Units of each parameter.
    pub units: BTreeMap<String, String>,
    /// The evidence that kept it.
    pub evidence: search::Evidence,
    /// Reference directions of the catalog effect's stars (HIP number → J2000 unit vector).
    #[serde(skip)]
    pub star_dirs: BTreeMap<String, nalgebra::Vector3<f64>>,
}

/// Structure no candidate explains.
#[derive(Clone, Debug, Serialize)]
pub struct Unexplained {
    /// Sensor.
    pub sensor: String,
    /// Regressor the structure follows.
    pub regressor: String,
    /// Axis (H, V, alpha, beta, or a gyro axis).
    pub axis: String,
    /// Test method.
    pub method: String,
    /// Size (arcsec; arcsec/s for gyro bias structure).
    pub size: f64,
    /// Holm-adjusted p-value.
    pub p_value: f64,
    /// Raw p-value.
    pub p_raw: f64,
    /// Other regressors with significant structure on this sensor (correlated with
    /// `regressor` or a second structure), strongest first.
    pub also_follows: Vec<String>,
    /// Unit of `size` (`arcsec`, `ms` for a slew-arc time tag, `arcsec/s`, `ppm`).
    pub unit: String,
    /// The test family ([`ledger::Family::name`]).
    pub source: String,
    /// Why nothing was named ([`ledger`]).
    pub reason: String,
}

/// Result of the sensor-side analysis.
#[derive(Clone, Debug)]
pub struct Analysis {
    /// The measurement set.
    pub set: MeasurementSet,
    /// The search.
    pub search: SearchResult,
    /// Detected effects (sensor side).
    pub detected: Vec<Detected>,
    /// Unexplained structure (sensor side).
    pub unexplained: Vec<Unexplained>,
    /// The time tags against the gyro (None: no slew arcs with data).
    pub time_reference: Option<time_reference::TimeReference>,
    /// The library candidates tested against the final model ([`ledger::sweep`]).
    pub swept: Vec<ledger::Swept>,
    /// Every significant test and its outcome (sensor side; the gyro's are added by
    /// [`run`]).
    pub ledger: Vec<ledger::LedgerEntry>,
    /// Residual RMS per sensor before (baseline model) and after (final model), arcsec.
    pub rms_before: [f64; 4],
    /// After.
    pub rms_after: [f64; 4],
}

/// Parameters of effect `i` of a fit as (name → value, name → σ).
#[must_use]
pub fn effect_parameters(
    res: &SearchResult,
    i: usize,
) -> (
    BTreeMap<String, f64>,
    BTreeMap<String, f64>,
    BTreeMap<String, String>,
) {
    let e = &res.layout.effects[i];
    let mut v = BTreeMap::new();
    let mut s = BTreeMap::new();
    let mut u = BTreeMap::new();
    for (k, gi) in res.layout.range(i).enumerate() {
        if let Some((x, sig)) = res.final_fit.param(gi) {
            v.insert(e.params[k].clone(), x);
            s.insert(e.params[k].clone(), sig);
            u.insert(e.params[k].clone(), e.units[k].to_owned());
        }
    }
    if let Some(p) = e.pitch_rad {
        v.insert("pitch_deg".into(), p.to_degrees());
        u.insert("pitch_deg".into(), "deg".into());
    }
    if let Some(t) = e.step_time_s {
        v.insert("t_step_s".into(), t);
        u.insert("t_step_s".into(), "s since the first frame".into());
    }
    (v, s, u)
}

/// Unexplained structure from a family of tests: per sensor, the most significant test
/// (smallest p-value: F statistics of tests with different degrees of freedom do not
/// compare; ties broken by F), with the other regressors that also show significant
/// structure (Holm-adjusted p below `alpha`) in `also_follows`, strongest first. Structure
/// often follows several correlated regressors at once (in an inertial hold a twice-per-orbit
/// term is also a function of the velocity direction and of the orbit-driven temperature);
/// all are listed so the one that names the cause is not hidden behind a proxy.
#[must_use]
pub fn unexplained_from(tests: &[structure::StructureTest], alpha: f64) -> Vec<Unexplained> {
    let stronger = |a: &structure::StructureTest, b: &structure::StructureTest| {
        a.p_value
            .total_cmp(&b.p_value)
            .then_with(|| b.f.total_cmp(&a.f))
    };
    let mut out = Vec::new();
    for sensor in 0..4 {
        let mut best: BTreeMap<&str, &structure::StructureTest> = BTreeMap::new();
        for t in tests
            .iter()
            .filter(|t| t.sensor == sensor && t.p_holm < alpha)
        {
            let e = best.entry(t.regressor.name()).or_insert(t);
            if stronger(t, e).is_lt() {
                *e = t;
            }
        }
        let mut v: Vec<&structure::StructureTest> = best.into_values().collect();
        v.sort_by(|a, b| stronger(a, b));
        if let Some(t) = v.first() {
            out.push(Unexplained {
                sensor: SENSOR_NAMES[sensor].to_owned(),
                regressor: t.regressor.name().to_owned(),
                axis: t.axis_name.to_owned(),
                method: format!("{:?}", t.method).to_lowercase(),
                size: t.size_arcsec,
                p_value: t.p_holm,
                p_raw: t.p_value,
                also_follows: v[1..]
                    .iter()
                    .map(|t| t.regressor.name().to_owned())
                    .collect(),
                unit: "arcsec".to_owned(),
                source: ledger::Family::ResidualStructure.name().to_owned(),
                reason: String::new(),
            });
        }
    }
    out
}

/// Run the sensor-side analysis on prepared input.
///
/// # Errors
/// No usable data.
pub fn analyse(input: &DiagnoseInput<'_>, config: &SearchConfig) -> anyhow::Result<Analysis> {
    analyse_set(
        MeasurementSet::build(input),
        &input.declared_effects,
        config,
    )
}

/// [`analyse`] on a measurement set already built (the frames need not outlive the build:
/// `run::diagnose_run` lets them go before the search).
///
/// # Errors
/// No usable data.
pub fn analyse_set(
    mut set: MeasurementSet,
    declared_effects: &[String],
    config: &SearchConfig,
) -> anyhow::Result<Analysis> {
    if set.meas.len() < 100 {
        anyhow::bail!(
            "diagnose needs identified FHST stars and FSS Sun samples: only {} measurements with references",
            set.meas.len()
        );
    }
    let mut res = search(&mut set, declared_effects, config)?;
    let time_reference = time_reference::resolve(&set, &res, config);
    if let Some(tr) = &time_reference {
        time_reference::apply(&set, &mut res, tr)?;
    }
    let detected = res
        .added
        .iter()
        .zip(&res.evidence)
        .map(|(&i, ev)| {
            let e = &res.layout.effects[i];
            let (parameters, sigma, units) = effect_parameters(&res, i);
            Detected {
                effect: e.kind.name().to_owned(),
                sensor: e
                    .sensor
                    .map_or_else(|| "all".to_owned(), |s| SENSOR_NAMES[s].to_owned()),
                parameters,
                sigma,
                units,
                evidence: ev.clone(),
                star_dirs: e
                    .stars
                    .iter()
                    .zip(&e.star_dirs)
                    .map(|(h, u)| (h.to_string(), *u))
                    .collect(),
            }
        })
        .collect();
    let swept = ledger::sweep(&set, &res, config.alpha);
    let ledger = ledger::sensor_ledger(&res, &swept, time_reference.as_ref(), config.alpha);
    let mut unexplained = unexplained_from(&res.tests_after, config.alpha);
    ledger::attach_reasons(&mut unexplained, &ledger);
    unexplained.extend(ledger::unexplained_items(&ledger));
    let rms_before = set.rms_per_sensor(&res.before.resid);
    let rms_after = set.rms_per_sensor(&res.after.resid);
    Ok(Analysis {
        set,
        search: res,
        detected,
        unexplained,
        time_reference,
        swept,
        ledger,
        rms_before,
        rms_after,
    })
}
