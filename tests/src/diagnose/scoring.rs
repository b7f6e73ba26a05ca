//! # Scoring against the simulator's truth (only when `truth.json` exists; never used by the
//! analysis itself)
//!
//! Why here and not in the ground tool: the truth's field functions are the simulator's
//! sensor models (`sim_harness::scenario`), which the ground must not carry. [`TruthScorer`]
//! plugs into `ground_tool::diagnose::scoring::Scorer`; the `diagnose-scored` binary runs
//! `ground-tool diagnose` with it (report.json and report.md as the ground tool wrote them
//! before the move, `scoring` section included).
//!
//! * **Calibration error** per sensor: the rotation between estimated and true `M_AS`, with
//!   the common rotation of the FHST pair removed (absolute alignment is indistinguishable
//!   from attitude; the FHST pair defines the frame the OBC flies), arcsec.
//! * **Effect truth**: `truth.json` lists the present and undeclared effects by name; the
//!   parameter values come from the scenario file (`scenarios/undeclared/NAME.toml`, then
//!   `scenarios/NAME.toml`) when it can be found, mapped to the library's parameters.

use fsw_core::attitude::rotvec_from_rot;
use fsw_core::tables::types::matrix_from_rows;
use fsw_core::tables::AlignmentTable;
use fsw_core::units::ARCSEC_PER_RAD;
use gro_reference::run_folder::Truth as TruthFile;
use ground_tool::diagnose::report::{BeforeAfter, Scoring};
use ground_tool::diagnose::scoring::{ParameterCheck, Scorer, ScoringInputs, ScoringOutcome};
use ground_tool::diagnose::Detected;
use nalgebra::{Matrix3, Vector3};
use std::collections::BTreeMap;
use std::path::Path;

/// Truth read from `truth.json`.
#[derive(Clone, Debug)]
pub struct Truth {
    /// Scenario name.
    pub scenario: String,
    /// True alignments (sensor order).
    pub alignments: [Matrix3<f64>; 4],
    /// True alignments at the end of the run (truth.json `alignments_after_run`: an alignment
    /// step applied; `alignments` when absent): what the tables written after the run fly into.
    pub alignments_after_run: [Matrix3<f64>; 4],
    /// Undeclared effects.
    pub undeclared: Vec<String>,
    /// Present effects.
    pub present: Vec<String>,
    /// The scenario, if its file was found, with the FSS units as flown (a per-seed transfer
    /// function drawn with the run's seed).
    pub scenario_file: Option<sim_harness::scenario::Scenario>,
    /// Where `scenario_file` came from: `truth.json`'s `scenario_as_flown`, a scenario file
    /// of the run's name (older run folders), or nowhere (the field functions' truth is then
    /// unknown and scored as zero: [`Truth::field_truth_note`]).
    pub scenario_source: String,
    /// True gyro bias history: (s since the start, ACS bias in arcsec/s).
    pub bias_history: Vec<(f64, Vector3<f64>)>,
}

/// Read `truth.json` (None when absent).
///
/// # Errors
/// A present but malformed file.
pub fn read_truth(run_dir: &Path) -> anyhow::Result<Option<Truth>> {
    let Some(file) = TruthFile::read(run_dir)? else {
        return Ok(None);
    };
    let alignments = file.alignments.into_array().map(|m| matrix_from_rows(&m));
    let alignments_after_run = file
        .alignments_after_run
        .map_or(alignments, |a| a.into_array().map(|m| matrix_from_rows(&m)));
    let (scenario_file, scenario_source) = truth_scenario(&file);
    Ok(Some(Truth {
        scenario: file.scenario,
        alignments,
        alignments_after_run,
        undeclared: file.undeclared_effects,
        present: file.present_effects,
        scenario_file,
        scenario_source,
        bias_history: file
            .bias_history
            .map(|h| {
                h.samples
                    .iter()
                    .map(|x| (x.t_s, Vector3::from(x.bias_acs_rad_per_s) * ARCSEC_PER_RAD))
                    .collect()
            })
            .unwrap_or_default(),
    }))
}

/// The run's scenario as flown: `truth.json`'s `scenario_as_flown`, else (run folders written
/// before it was recorded) the scenario file of the run's name, with each FSS's transfer
/// function drawn as the simulator drew it. Returns the scenario and where it came from.
fn truth_scenario(file: &TruthFile) -> (Option<sim_harness::scenario::Scenario>, String) {
    let scenario = file.scenario.as_str();
    let mut unreadable = String::new();
    if let Some(as_flown) = file.scenario_as_flown.as_ref().filter(|v| !v.is_null()) {
        match serde_json::from_value::<sim_harness::scenario::Scenario>(as_flown.clone()) {
            Ok(s) => return (Some(s), "truth.json scenario_as_flown".into()),
            Err(e) => unreadable = format!("truth.json scenario_as_flown unreadable ({e}); "),
        }
    }
    let dir = sim_harness::scenario::scenarios_dir();
    let found = [
        dir.join("undeclared").join(format!("{scenario}.toml")),
        dir.join(format!("{scenario}.toml")),
    ]
    .into_iter()
    .find(|p| p.exists())
    .and_then(|p| {
        let s = sim_harness::scenario::Scenario::load(&p).ok()?;
        (s.name == scenario).then_some((s, p))
    });
    match found {
        Some((mut s, p)) => {
            let seed = file.seed;
            s.fss1 = s.fss1.as_flown(0, seed);
            s.fss2 = s.fss2.as_flown(1, seed);
            (
                Some(s),
                format!("{unreadable}{} (by the run's name)", p.display()),
            )
        }
        None => (None, unreadable),
    }
}

impl Truth {
    /// A note when the scoring cannot know the true field functions (FSS transfer function,
    /// FHST distortion): the table errors then count them as zero.
    #[must_use]
    pub fn field_truth_note(&self) -> Option<String> {
        self.scenario_file.is_none().then(|| {
            format!(
                "scoring: {}no scenario file named {:?} was found: the true FSS transfer \
                 function and FHST distortion are unknown and the table errors count them as zero",
                if self.scenario_source.is_empty() {
                    "truth.json has no scenario_as_flown and ".to_owned()
                } else {
                    self.scenario_source.clone()
                },
                self.scenario
            )
        })
    }

    /// The truth the tables written after the run are scored against: the alignments at the
    /// end of the run (`alignments_after_run`).
    #[must_use]
    pub fn after_run(&self) -> Self {
        Self {
            alignments: self.alignments_after_run,
            ..self.clone()
        }
    }
}

/// Alignment error vectors per sensor (ACS, arcsec), FHST-pair common rotation removed.
fn alignment_errors(est: &AlignmentTable, truth: &Truth) -> Vec<Vector3<f64>> {
    let m: Vec<Matrix3<f64>> = est.matrices().iter().map(|r| matrix_from_rows(r)).collect();
    let e: Vec<Vector3<f64>> = (0..4)
        .map(|i| rotvec_from_rot(&(m[i] * truth.alignments[i].transpose())) * ARCSEC_PER_RAD)
        .collect();
    let common = (e[0] + e[1]) * 0.5;
    e.iter().map(|x| x - common).collect()
}

/// Truth's field-dependent error of a measurement (arcsec, sensor axes): the FSS transfer
/// function or the FHST distortion of the scenario (zero when unknown).
fn truth_field_error(
    m: &ground_tool::diagnose::measurements::Measurement,
    truth: &Truth,
) -> [f64; 2] {
    let Some(s) = &truth.scenario_file else {
        return [0.0; 2];
    };
    let [a, b] = m.ang;
    match m.sensor {
        0 | 1 => {
            let fx = if m.sensor == 0 {
                &s.fhst1.effects
            } else {
                &s.fhst2.effects
            };
            let f = 4.0 * fsw_core::units::RAD_PER_DEG;
            let rho2 = a * a + b * b;
            let k3 = fx.radial_distortion_arcsec_at_4deg / f.powi(3);
            let hv = a * b / (f * f);
            [
                k3 * rho2 * a + fx.hv_distortion_arcsec_at_corner[0] * hv,
                k3 * rho2 * b + fx.hv_distortion_arcsec_at_corner[1] * hv,
            ]
        }
        _ => {
            let f = if m.sensor == 2 { &s.fss1 } else { &s.fss2 };
            [
                (f.alpha.apply(a, b) - a) * ARCSEC_PER_RAD,
                (f.beta.apply(b, a) - b) * ARCSEC_PER_RAD,
            ]
        }
    }
}

/// Calibration error per sensor (arcsec per axis): the RMS, over the run's own measurements
/// of that sensor, of the error of the calibrated measurement model — the alignment error
/// (FHST-pair common rotation removed: absolute alignment is indistinguishable from
/// attitude) plus the error of the modelled field function (FSS transfer function, FHST
/// distortion) against the truth's. `field_est` gives the model's field correction of a
/// measurement (arcsec). Rotations the data do not constrain (an FSS rolled about the Sun
/// line) and a transfer polynomial that trades with the alignment over the part of the field
/// the Sun visits do not count; sensors without measurements are not scored.
#[must_use]
pub fn calibration_error_arcsec(
    est: &AlignmentTable,
    truth: &Truth,
    set: &ground_tool::diagnose::measurements::MeasurementSet,
    field_est: &dyn Fn(usize) -> [f64; 2],
) -> BTreeMap<String, f64> {
    let d = alignment_errors(est, truth);
    let names = ground_tool::diagnose::measurements::SENSOR_NAMES;
    let mut sum = [0.0; 4];
    let mut n = [0usize; 4];
    for (i, m) in set.meas.iter().enumerate() {
        if m.outlier {
            continue;
        }
        // M_est = Rot(d) M_true ⇒ predicted angles change by −J Mᵀ (b × d).
        let align = -(m.jm
            * m.b_acs
                .cross(&(d[m.sensor] * fsw_core::units::RAD_PER_ARCSEC)))
            * ARCSEC_PER_RAD;
        let fe = field_est(i);
        let ft = truth_field_error(m, truth);
        let e0 = align.x + fe[0] - ft[0];
        let e1 = align.y + fe[1] - ft[1];
        sum[m.sensor] += 0.5 * (e0 * e0 + e1 * e1);
        n[m.sensor] += 1;
    }
    (0..4)
        .filter(|&i| n[i] > 0)
        .map(|i| (names[i].to_owned(), (sum[i] / n[i] as f64).sqrt()))
        .collect()
}

/// Full rotation angle of the alignment error per sensor (arcsec), FHST-pair common rotation
/// removed.
#[must_use]
pub fn rotation_error_arcsec(est: &AlignmentTable, truth: &Truth) -> BTreeMap<String, f64> {
    let d = alignment_errors(est, truth);
    let names = ground_tool::diagnose::measurements::SENSOR_NAMES;
    (0..4).map(|i| (names[i].to_owned(), d[i].norm())).collect()
}

/// Scores a diagnosis against `RUN_DIR/truth.json` when it exists (nothing otherwise).
#[derive(Clone, Copy, Debug, Default)]
pub struct TruthScorer;

impl Scorer for TruthScorer {
    fn score(&self, x: &ScoringInputs<'_>) -> anyhow::Result<ScoringOutcome> {
        let Some(t) = read_truth(x.run_dir)? else {
            return Ok(ScoringOutcome::default());
        };
        let set = &x.analysis.set;
        let res = &x.analysis.search;
        // The final model's field corrections (transfer function, distortion) per
        // measurement; the chain has none beyond the flown tables.
        let g = res.final_fit.expand(res.layout.total);
        let field_after = |k: usize| x.field_arcsec(&g, None, k);
        let none = |_: usize| [0.0; 2];
        let calibration_error = BeforeAfter {
            before: calibration_error_arcsec(x.chain_alignment, &t, set, &none),
            after: calibration_error_arcsec(x.ground_alignment, &t, set, &field_after),
        };
        // The tables written: diagnose's with the field terms that went up (none when the
        // validation refused them), calibrate's with none; and, for the record, the table
        // diagnose would have written without its held-out validation. They fly after the
        // run: scored against the alignments at its end (an alignment step applied).
        let written_field =
            |k: usize| x.field_arcsec(x.written.parameters, Some(x.written.held), k);
        let unvalidated_field =
            |k: usize| x.field_arcsec(x.unvalidated.parameters, Some(x.unvalidated.held), k);
        let t_after = t.after_run();
        let written_error = BeforeAfter {
            before: calibration_error_arcsec(x.calibrate_alignment, &t_after, set, &none),
            after: calibration_error_arcsec(x.written.alignment, &t_after, set, &written_field),
        };
        let unvalidated_error =
            calibration_error_arcsec(x.unvalidated.alignment, &t_after, set, &unvalidated_field);
        let rotation_error = BeforeAfter {
            before: rotation_error_arcsec(x.chain_alignment, &t),
            after: rotation_error_arcsec(x.ground_alignment, &t),
        };
        let scoring = Scoring {
            label: "scoring only: from truth.json, never used by the analysis".into(),
            truth_undeclared_effects: t.undeclared.clone(),
            field_truth: t
                .field_truth_note()
                .unwrap_or_else(|| t.scenario_source.clone()),
            detections_in_truth: x
                .detected
                .iter()
                .map(|d| (d.effect.clone(), d.sensor.clone(), matches_truth(d, &t)))
                .collect(),
            parameters: check_parameters(
                x.detected,
                &t,
                set.aberration_k0,
                x.first_frame_j2000_tt_s,
            ),
        };
        Ok(ScoringOutcome {
            calibration_error_arcsec: Some(calibration_error),
            calibration_rotation_error_arcsec: Some(rotation_error),
            written_table_error_arcsec: Some(written_error),
            unvalidated_table_error_arcsec: Some(unvalidated_error),
            scoring: Some(scoring),
        })
    }
}

/// Diagnose options that score against `truth.json` ([`TruthScorer`]): what
/// `ground-tool diagnose` did before the scoring left the ground tool.
#[must_use]
pub fn scored_options() -> ground_tool::diagnose::run::DiagnoseOptions {
    ground_tool::diagnose::run::DiagnoseOptions {
        scorer: Some(std::sync::Arc::new(TruthScorer)),
        ..ground_tool::diagnose::run::DiagnoseOptions::default()
    }
}

fn unit_of(sensor: &str) -> String {
    sensor.to_ascii_lowercase()
}

/// Does a detection name an effect that is in the truth for that unit?
#[must_use]
pub fn matches_truth(d: &Detected, truth: &Truth) -> bool {
    let name = match d.effect.as_str() {
        "aberration_annual" | "aberration" => "aberration".to_owned(),
        "aberration_orbital" => "orbital_aberration".to_owned(),
        "gyro_scale_asymmetry" => "iru.scale_asymmetry".to_owned(),
        "gyro_thermal_bias" => "iru.thermal_bias".to_owned(),
        "gyro_bias_transient" | "gyro_bias_ramp" => "iru_bias_transient".to_owned(),
        "orbit_periodic_alignment" | "thermal_alignment_drift" => {
            format!("{}.thermal_alignment_drift", unit_of(&d.sensor))
        }
        "catalog_proper_motion_error" => "catalog_proper_motion_error".to_owned(),
        "fss_transfer_function" => "fss_transfer_function".to_owned(),
        other => format!("{}.{other}", unit_of(&d.sensor)),
    };
    truth.present.contains(&name)
}

/// Truth values of a detection's parameters (from the scenario file).
#[must_use]
pub fn parameter_truth(
    d: &Detected,
    truth: &Truth,
    aberration_k0: [f64; 2],
) -> BTreeMap<String, f64> {
    let mut out = BTreeMap::new();
    let Some(s) = &truth.scenario_file else {
        return out;
    };
    let fhst = |n: &str| {
        if n == "FHST1" {
            Some(&s.fhst1)
        } else if n == "FHST2" {
            Some(&s.fhst2)
        } else {
            None
        }
    };
    let fss = |n: &str| {
        if n == "FSS1" {
            Some(&s.fss1)
        } else if n == "FSS2" {
            Some(&s.fss2)
        } else {
            None
        }
    };
    let sensor = d.sensor.as_str();
    match d.effect.as_str() {
        "aberration_annual" => {
            out.insert("k_annual_minus_applied".into(), 1.0 - aberration_k0[0]);
        }
        "aberration_orbital" => {
            let k = if s.sky.orbital_aberration { 1.0 } else { 0.0 };
            out.insert("k_orbital_minus_applied".into(), k - aberration_k0[1]);
        }
        "aberration" => {
            let k = if s.sky.orbital_aberration { 1.0 } else { 0.0 };
            out.insert("k_annual_minus_applied".into(), 1.0 - aberration_k0[0]);
            out.insert("k_orbital_minus_applied".into(), k - aberration_k0[1]);
        }
        "time_tag_offset" => {
            let tau = fhst(sensor)
                .map(|f| f.effects.time_tag_offset_s)
                .or_else(|| fss(sensor).map(|f| f.effects.time_tag_offset_s));
            if let Some(t) = tau {
                out.insert("tau".into(), t * 1e3);
            }
        }
        "thermal_alignment_drift" => {
            let k = fhst(sensor)
                .map(|f| f.effects.thermal_alignment_arcsec_per_c)
                .or_else(|| fss(sensor).map(|f| f.effects.thermal_alignment_arcsec_per_c));
            if let Some(k) = k {
                for (i, n) in ["x", "y", "z"].iter().enumerate() {
                    out.insert((*n).to_owned(), k[i]);
                }
            }
        }
        "fhst_distortion" => {
            if let Some(f) = fhst(sensor) {
                let [h, v] = f.effects.hv_distortion_arcsec_at_corner;
                let radial = f.effects.radial_distortion_arcsec_at_4deg;
                out.extend([
                    ("radial_at_4deg".to_owned(), radial),
                    ("hv_h_at_corner".to_owned(), h),
                    ("hv_v_at_corner".to_owned(), v),
                ]);
            }
        }
        "magnitude_bias" => {
            if let Some(f) = fhst(sensor) {
                let [h, v] = f.effects.magnitude_bias_arcsec_per_mag;
                out.extend([("h_per_mag".to_owned(), h), ("v_per_mag".to_owned(), v)]);
            }
        }
        "fss_transfer_function" => {
            if let Some(f) = fss(sensor) {
                for (head, h) in [("alpha", &f.alpha), ("beta", &f.beta)] {
                    out.insert(format!("{head}_scale"), h.scale_ppm);
                    out.insert(format!("{head}_cross_at_corner"), h.cross_arcsec_at_corner);
                    out.insert(format!("{head}_cubic_at_edge"), h.cubic_arcsec_at_edge);
                    out.insert(format!("{head}_cyclic_sin"), h.cyclic_arcsec);
                    out.insert(format!("{head}_cyclic_cos"), 0.0);
                }
                out.insert("pitch_deg".into(), f.alpha.cyclic_pitch_deg);
            }
        }
        "gyro_scale_asymmetry" => {
            let a = s.iru.effects.scale_asymmetry_ppm;
            for (n, ch) in [("x", 1), ("y", 2), ("z", 4)] {
                out.insert(n.into(), a[ch]);
            }
        }
        "gyro_bias_ramp" => {
            // Least-squares slope of the true bias over the run (arcsec/s per hour).
            let h = &truth.bias_history;
            if h.len() >= 3 {
                let n = h.len() as f64;
                let tm = h.iter().map(|(t, _)| t / 3600.0).sum::<f64>() / n;
                let bm = h.iter().map(|(_, b)| b).sum::<Vector3<f64>>() / n;
                let stt: f64 = h.iter().map(|(t, _)| (t / 3600.0 - tm).powi(2)).sum();
                let stb: Vector3<f64> = h.iter().map(|(t, b)| (b - bm) * (t / 3600.0 - tm)).sum();
                let slope = stb / stt;
                for (i, n) in ["x", "y", "z"].iter().enumerate() {
                    out.insert((*n).into(), slope[i]);
                }
            }
        }
        "alignment_step" => {
            let step = fhst(sensor)
                .map(|f| f.effects.alignment_step_arcsec)
                .or_else(|| fss(sensor).map(|f| f.effects.alignment_step_arcsec));
            if let Some(k) = step {
                for (i, n) in ["x", "y", "z"].iter().enumerate() {
                    out.insert((*n).to_owned(), k[i]);
                }
            }
        }
        "gyro_thermal_bias" => {
            let k = s.iru.effects.thermal_bias_deg_per_s_per_c;
            for (n, ch) in [("x", 1), ("y", 2), ("z", 4)] {
                out.insert(n.into(), k[ch] * 3600.0);
            }
        }
        _ => {}
    }
    out
}

/// True per-star catalog offsets (HIP → (east, north) arcsec) at `j2000_tt_s`: the truth
/// sky (the scenario's proper-motion errors) against the catalog the ground uses.
#[must_use]
pub fn catalog_truth(truth: &Truth, j2000_tt_s: f64) -> BTreeMap<u32, [f64; 2]> {
    use sim_harness::truth::sky::{Sky, SkyParams};
    let mut out = BTreeMap::new();
    let Some(s) = &truth.scenario_file else {
        return out;
    };
    if s.sky.proper_motion_error_sigma_mas_per_yr <= 0.0 && s.sky.proper_motion_scale == 1.0 {
        return out;
    }
    let Ok(table) =
        sim_harness::data::CsvTable::parse(sim_harness::data::HIPPARCOS_CSV, "hipparcos")
    else {
        return out;
    };
    let (Ok(sky_true), Ok(sky_ground)) = (
        Sky::from_csv(&table, &s.sky),
        Sky::from_csv(&table, &SkyParams::default()),
    ) else {
        return out;
    };
    let origin = Vector3::zeros();
    for st in sky_ground.stars() {
        let Some(t) = sky_true.index_of_hip(st.hip).and_then(|i| sky_true.star(i)) else {
            continue;
        };
        let u = st.astrometric_dir_eci(j2000_tt_s, &origin);
        let v = t.astrometric_dir_eci(j2000_tt_s, &origin);
        let east = Vector3::z().cross(&u);
        if east.norm() < 1e-9 {
            continue;
        }
        let east = east.normalize();
        let north = u.cross(&east);
        let d = v - u;
        out.insert(
            st.hip,
            [
                d.dot(&east) * ARCSEC_PER_RAD,
                d.dot(&north) * ARCSEC_PER_RAD,
            ],
        );
    }
    out
}

/// Compare every detection's parameters with the truth (catalog offsets per star).
#[must_use]
pub fn check_parameters(
    detected: &[Detected],
    truth: &Truth,
    aberration_k0: [f64; 2],
    j2000_tt_s: f64,
) -> Vec<ParameterCheck> {
    let mut out = Vec::new();
    let mut catalog: Option<BTreeMap<u32, [f64; 2]>> = None;
    for d in detected {
        let mut truths = parameter_truth(d, truth, aberration_k0);
        if d.effect == "catalog_proper_motion_error" {
            let cat = catalog.get_or_insert_with(|| catalog_truth(truth, j2000_tt_s));
            for k in d.parameters.keys() {
                let Some(rest) = k.strip_prefix("HIP") else {
                    continue;
                };
                let mut parts = rest.split('_');
                let (Some(h), Some(dir)) = (
                    parts.next().and_then(|h| h.parse::<u32>().ok()),
                    parts.next(),
                ) else {
                    continue;
                };
                if let Some(t) = cat.get(&h) {
                    truths.insert(k.clone(), if dir == "east" { t[0] } else { t[1] });
                }
            }
        }
        if d.effect == "catalog_proper_motion_error" {
            // Offsets are known up to a common rotation: compare after removing the net
            // rotation of (estimate − truth).
            let keys: Vec<String> = truths.keys().cloned().collect();
            let mut dirs = Vec::new();
            let mut x = Vec::new();
            let mut var = Vec::new();
            let mut used = Vec::new();
            let mut i = 0;
            while i + 1 < keys.len() {
                let (ke, kn) = (&keys[i], &keys[i + 1]);
                let hip = ke
                    .trim_start_matches("HIP")
                    .split('_')
                    .next()
                    .unwrap_or_default()
                    .to_owned();
                if ke.ends_with("_east")
                    && kn.ends_with("_north")
                    && kn.starts_with(&format!("HIP{hip}_"))
                {
                    if let (Some(u), Some(e), Some(n), Some(se), Some(sn)) = (
                        d.star_dirs.get(&hip),
                        d.parameters.get(ke),
                        d.parameters.get(kn),
                        d.sigma.get(ke),
                        d.sigma.get(kn),
                    ) {
                        dirs.push(*u);
                        x.extend([e - truths[ke], n - truths[kn]]);
                        var.extend([se * se, sn * sn]);
                        used.push((ke.clone(), kn.clone()));
                    }
                    i += 2;
                } else {
                    i += 1;
                }
            }
            let r = ground_tool::diagnose::effects::remove_net_rotation(&dirs, &x, &var);
            for (j, (ke, kn)) in used.iter().enumerate() {
                for (kk, idx) in [(ke, 2 * j), (kn, 2 * j + 1)] {
                    let s = var[idx].sqrt();
                    out.push(ParameterCheck {
                        effect: d.effect.clone(),
                        sensor: d.sensor.clone(),
                        parameter: format!("{kk} (net rotation removed)"),
                        estimate: truths[kk] + r[idx],
                        sigma: s,
                        truth: truths[kk],
                        z: r[idx] / s,
                    });
                }
            }
            continue;
        }
        for (k, t) in truths {
            if let (Some(&e), Some(&s)) = (d.parameters.get(&k), d.sigma.get(&k)) {
                out.push(ParameterCheck {
                    effect: d.effect.clone(),
                    sensor: d.sensor.clone(),
                    parameter: k,
                    estimate: e,
                    sigma: s,
                    truth: t,
                    z: (e - t) / s,
                });
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    /// A `truth.json` with identity alignments and the given extra fields, in a fresh folder.
    fn truth_dir(tag: &str, extra: &[(&str, serde_json::Value)]) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("scoring-{}-{tag}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let eye = serde_json::json!([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);
        let mut v = serde_json::json!({
            "seed": 3,
            "alignments": { "FHST1": eye, "FHST2": eye, "FSS1": eye, "FSS2": eye },
        });
        for (k, x) in extra {
            v[*k] = x.clone();
        }
        std::fs::write(dir.join("truth.json"), v.to_string()).unwrap();
        dir
    }

    #[test]
    fn the_field_truth_comes_from_truth_json_whatever_the_plan_is_called() {
        // A plan flown from a file outside scenarios/ (its name matches no shipped file):
        // truth.json's own copy of the scenario gives the transfer function it flew.
        let file = sim_harness::scenario::scenarios_dir().join("undeclared/clean.toml");
        let mut flown = sim_harness::scenario::Scenario::load(&file).unwrap();
        flown.name = "a-plan-of-elsewhere".into();
        flown.fss2 = flown.fss2.as_flown(1, 3);
        let dir = truth_dir(
            "as-flown",
            &[
                ("scenario", serde_json::json!("a-plan-of-elsewhere")),
                ("scenario_as_flown", serde_json::to_value(&flown).unwrap()),
            ],
        );
        let t = read_truth(&dir).unwrap().unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(t.scenario_source, "truth.json scenario_as_flown");
        assert_eq!(t.field_truth_note(), None);
        assert_eq!(t.scenario_file.unwrap().fss2, flown.fss2);
    }

    #[test]
    fn an_unknown_field_truth_is_said_not_scored_as_zero_in_silence() {
        let dir = truth_dir(
            "unknown",
            &[("scenario", serde_json::json!("a-plan-of-elsewhere"))],
        );
        let t = read_truth(&dir).unwrap().unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        assert!(t.scenario_file.is_none());
        let note = t.field_truth_note().unwrap();
        assert!(
            note.contains("a-plan-of-elsewhere") && note.contains("zero"),
            "{note}"
        );
    }
}
