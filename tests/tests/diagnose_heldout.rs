//! The held-out validation of diagnose's flight tables (`ground_tool::diagnose::heldout`) on
//! synthetic frames with known alignments and effects (`gro_tests::diagnose::synthetic`,
//! which uses the simulator's FSS model: moved here from the ground tool's unit tests).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use fsw_core::tables::types::matrix_from_rows;
use gro_tests::diagnose::synthetic::{generate, SynthConfig, SynthEffects};
use ground_tool::diagnose::effects::{library, EffectKind};
use ground_tool::diagnose::fit::{accumulate, batch_quadratic, Quadratic, Rows, N_ALIGN};
use ground_tool::diagnose::fit::{indices, Layout};
use ground_tool::diagnose::heldout::*;
use ground_tool::diagnose::measurements::MeasurementSet;
use nalgebra::DVector;

fn run(
    effects: SynthEffects,
    seed: u64,
) -> (gro_tests::diagnose::synthetic::SynthRun, MeasurementSet) {
    let synth = generate(&SynthConfig {
        duration_s: 3.0 * 3600.0,
        ..SynthConfig::seeded(effects, seed)
    });
    let set = synth.measurement_set();
    (synth, set)
}

fn truth_parameters(synth: &gro_tests::diagnose::synthetic::SynthRun) -> [f64; N_ALIGN] {
    let m_base = synth.alignment.matrices().map(matrix_from_rows);
    alignment_parameters_arcsec(&synth.m_true, &m_base)
}

/// A synthetic run with FHST1 distortion `distortion_arcsec` (radial, H·V terms), its
/// measurements, and the layout of the one effect that models it (the library's FHST1
/// distortion).
fn fhst1_distortion_run(
    distortion_arcsec: [f64; 3],
    seed: u64,
) -> (
    gro_tests::diagnose::synthetic::SynthRun,
    MeasurementSet,
    Layout,
) {
    let effects = SynthEffects {
        distortion_arcsec: [distortion_arcsec, [0.0; 3]],
        ..SynthEffects::default()
    };
    let (synth, set) = run(effects, seed);
    let dist = library(&set, [None, None], None)
        .into_iter()
        .find(|e| e.kind == EffectKind::FhstDistortion && e.sensor == Some(0))
        .expect("the library has FHST1 distortion");
    (synth, set, Layout::new(vec![dist]))
}

/// `batch_quadratic`'s χ² is the likelihood `accumulate` builds: at any global vector the batch sums
/// equal the quadratic form of the accumulated system.
#[test]
fn batch_chi2_is_the_accumulated_likelihood() {
    let (_, set, layout) = fhst1_distortion_run([6.0, 3.0, -2.0], 7);
    let normal = accumulate(&set, &layout, &|_| true);
    let g = DVector::from_fn(layout.total, |i, _| ((i as f64) * 0.37).sin() * 4.0);
    let quadratic = normal.chi2 - 2.0 * g.dot(&normal.b) + g.dot(&(&normal.n * &g));
    let per_batch: f64 = batch_quadratic(&set, &layout, &g, &|_| true, Quadratic::Chi2, Rows::All)
        .iter()
        .map(|b| b.1)
        .sum();
    assert!(
        (per_batch - quadratic).abs() < 1e-6 * quadratic.abs().max(1.0),
        "Σ batch χ² {per_batch} against the accumulated form {quadratic}"
    );
}

/// The gate takes a correction of the alignments the measurements were built with, and
/// nothing when the reference is the truth (the sign convention of
/// `alignment_parameters_arcsec` is checked on the way: the truth's parameters must give a
/// lower held-out χ² than the built-with table).
#[test]
fn gate_takes_a_real_correction_and_nothing_against_the_truth() {
    let (synth, set) = run(SynthEffects::default(), 11);
    let layout = Layout::new(Vec::new());
    let idx = indices(&layout, &[]);
    let truth = truth_parameters(&synth);
    let against_built = validate_flight_tables(
        &set,
        &layout,
        &idx,
        &[],
        &[0.0; N_ALIGN],
        "the table the measurements were built with",
    );
    let against_truth =
        validate_flight_tables(&set, &layout, &idx, &[], &truth, "the true alignments");
    let size = truth.iter().map(|x| x * x).sum::<f64>().sqrt();
    if std::env::var("SHOW").is_ok() {
        eprintln!(
            "size {size:.1}″\n{}\n{}",
            against_built.reason, against_truth.reason
        );
    }
    assert!(
        size > 5.0,
        "the synthetic built-with table is off by {size:.1}″"
    );
    assert!(against_built.passed, "{}", against_built.reason);
    assert!(
        against_truth.chi2.chi2_reference < against_built.chi2.chi2_reference,
        "truth {} against built-with {}",
        against_truth.chi2.chi2_reference,
        against_built.chi2.chi2_reference
    );
    assert!(!against_truth.passed, "{}", against_truth.reason);
    assert!(
        (0.8..1.25).contains(&against_truth.chi2.mean_square_reference),
        "held-out mean square with the true alignments {}",
        against_truth.chi2.mean_square_reference
    );
}

/// A real effect with exact alignments as the reference: the effect's terms are taken and
/// the alignments, which a refit can only move by noise, are not.
#[test]
fn gate_takes_the_effect_and_leaves_exact_alignments() {
    let (synth, set, layout) = fhst1_distortion_run([8.0, 4.0, -3.0], 12);
    let idx = indices(&layout, &[0]);
    let truth = truth_parameters(&synth);
    let v = validate_flight_tables(&set, &layout, &idx, &[], &truth, "the true alignments");
    if std::env::var("SHOW").is_ok() {
        eprintln!("{}", v.reason);
    }
    let taken: Vec<&str> = v.taken.iter().map(|t| t.component.as_str()).collect();
    assert!(
        taken.iter().any(|t| t.starts_with("fhst_distortion")),
        "{}",
        v.reason
    );
    assert!(
        !taken.iter().any(|t| t.ends_with("alignment")),
        "{}",
        v.reason
    );
}
