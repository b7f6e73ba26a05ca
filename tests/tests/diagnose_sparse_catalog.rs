//! The sparse catalog form's star screen (`ground_tool::diagnose::sparse_catalog`) under the
//! null, on synthetic frames with the simulator's FSS transfer function
//! (`gro_tests::diagnose::synthetic`): moved here from the ground tool's unit tests.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use gro_tests::diagnose::synthetic::{generate, SynthConfig, SynthEffects};
use ground_tool::diagnose::effects::library;
use ground_tool::diagnose::effects::EffectKind;
use ground_tool::diagnose::fit::{accumulate_fhst_only, accumulate_halves, Layout};
use ground_tool::diagnose::sparse_catalog::screen;
use sim_harness::sensors::fss::FssHeadErrors;

/// One-sided Kolmogorov–Smirnov distance of `p` from U(0, 1): how far the empirical CDF
/// rises above the diagonal (too many small p-values). A star whose offset the batch
/// attitudes absorb in one direction has one effective degree of freedom against the
/// test's two, which makes its p-value conservative (the other side of the diagonal).
fn ks_above(mut p: Vec<f64>) -> f64 {
    p.sort_by(f64::total_cmp);
    let n = p.len() as f64;
    p.iter()
        .enumerate()
        .map(|(i, &v)| (i + 1) as f64 / n - v)
        .fold(0.0, f64::max)
}

/// Under the null (nothing undeclared but the two FSS transfer functions, the Sun's
/// position-dependent error that the screen must not lean on), the screen's per-star
/// p-values against the baseline are uniform or conservative, the tail included:
/// one-sided KS at 1 % over every star of 24 runs, and the counts below 1e-2 and 1e-3
/// within their Poisson bounds (P ≈ 1e-3). The same stars tested with the FSS rows in
/// the system (the screen before) fail both by far: the transfer function moves the
/// attitude of every batch the Sun helps determine, and the stars of those batches show it.
#[test]
fn star_screen_p_values_are_uniform_under_the_null() {
    let show = std::env::var("SHOW").is_ok();
    let (mut p_all, mut p_with_fss) = (Vec::new(), Vec::new());
    for seed in 40..64 {
        let effects = SynthEffects {
            fss_tf: [
                Some((FssHeadErrors::default(), FssHeadErrors::default())),
                Some((FssHeadErrors::default(), FssHeadErrors::default())),
            ],
            ..SynthEffects::default()
        };
        let synth = generate(&SynthConfig {
            duration_s: 3.0 * 3600.0,
            ..SynthConfig::seeded(effects, seed)
        });
        let set = synth.measurement_set();
        let catalog = library(&set, [None, None], None)
            .into_iter()
            .find(|e| e.kind == EffectKind::CatalogProperMotionError && !e.sparse)
            .expect("the library has the catalog form");
        let layout = Layout::new(vec![catalog]);
        let tests = screen(&layout, &accumulate_fhst_only(&set, &layout), &[], 1e-300);
        p_all.extend(tests.iter().map(|t| t.p_value));
        let full = accumulate_halves(&set, &layout).full;
        p_with_fss.extend(
            screen(&layout, &full, &[], 1e-300)
                .iter()
                .map(|t| t.p_value),
        );
    }
    let summary = |p: &[f64]| {
        let below = |x: f64| p.iter().filter(|&&v| v < x).count();
        (p.len(), ks_above(p.to_vec()), below(0.01), below(0.001))
    };
    let (n, ks, b2, b3) = summary(&p_all);
    let (m, ks_old, b2_old, b3_old) = summary(&p_with_fss);
    if show {
        eprintln!("trackers only: {n} star tests, KS+ {ks:.3}, below 0.01 {b2}, below 0.001 {b3}");
        eprintln!("with the FSS rows: {m} tests, KS+ {ks_old:.3}, below 0.01 {b2_old}, below 0.001 {b3_old}");
    }
    let crit = 1.52 / (n as f64).sqrt();
    let bound = |x: f64| x * n as f64 + 3.1 * (x * n as f64).sqrt() + 1.0;
    assert!(n > 1500, "{n} star tests");
    assert!(ks < crit, "KS+ {ks} over {n} tests");
    assert!((b2 as f64) <= bound(0.01), "{b2} below 1e-2 of {n}");
    assert!((b3 as f64) <= bound(0.001), "{b3} below 1e-3 of {n}");
    assert!(ks_old > crit && b3_old as f64 > bound(0.001));
}
