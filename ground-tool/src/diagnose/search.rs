//! # The loop: add the best-supported effect, refit, test again
//!
//! Each iteration fits, for every candidate not yet in the model, the model + candidate
//! (alignments and batch attitudes always re-estimated with it: the recalibration) and keeps
//! the candidate only when **all** of these hold:
//!
//! 1. **likelihood ratio**: `F = (Δχ²/k) / s²` of the larger model, p-value Holm-corrected
//!    over the candidates of the iteration, below `alpha`;
//! 2. **BIC** improves: `n ln(χ²₀/χ²₁) − (k + extra) ln n > 10` (extra = grid-searched
//!    nonlinear parameters such as a cyclic pitch);
//! 3. **halves agree**: the candidate's parameters fitted on the two halves of the data
//!    (alternating 10-min blocks, [`super::fit::in_first_half`]) differ by less than 3σ (χ² of
//!    the difference, p > 0.0027);
//! 4. **indication and adequacy**: the structure the candidate is meant to explain (its
//!    signature regressors on its sensor, [`Effect::signature`]) must be there before
//!    (Bonferroni over the signature tests, p < `indication_alpha`) — a flexible candidate
//!    must not win on structure that shows up elsewhere — and gone afterwards (not
//!    significant at the Bonferroni level of the whole test family) or reduced by ≥ 80 %; a
//!    candidate that only soaks up part of a structure it cannot describe is not forced
//!    onto it.
//!
//! Among the passing candidates the one with the largest ΔBIC is added. The loop ends when
//! none passes; whatever structure the final residuals still show is reported as unexplained.
//!
//! With several effects present at once, checks 3–4 of one candidate are spoiled by the
//! structure of the others, and a flexible candidate (per-star catalog offsets) can take the
//! first place and absorb them all. So the loop above is phase 3 of three:
//!
//! 1. **forward on the likelihood**: add, by ΔBIC, every candidate that passes 1–2;
//! 2. **backward with every check**: test each added effect against the model without it
//!    (1 with its p Bonferroni-corrected over the library, 2–4, the veto by an effect already
//!    removed that explains the same sensors better, and a joint lack of fit: the generic
//!    extension must not still explain something on a sensor with an alignment-variation
//!    term); the weakest failing effect leaves and is not offered again (an FHST
//!    alignment-variation term takes its twin on the other tracker with it: only the relative
//!    alignment is observable); back to 1 until none fails;
//! 3. the forward loop with every check, from that model.

use super::effects::{Effect, EffectKind};
use super::fit::{accumulate_halves, indices, post_fit, solve, Layout, PostFit, SubFit, Systems};
use super::measurements::MeasurementSet;
pub use super::search_result::{Evidence, Iteration, SearchResult};
use super::stats::{chi2_sf, f_sf, holm_adjust};
use super::structure::{run_tests, Regressor, StructureTest};
use nalgebra::DMatrix;

/// Settings of the search.
#[derive(Clone, Copy, Debug)]
pub struct SearchConfig {
    /// Family-wise significance of the tests.
    pub alpha: f64,
    /// Halves must agree within this many σ (two-sided normal equivalent).
    pub halves_sigma: f64,
    /// Most effects added.
    pub max_iterations: usize,
    /// Required reduction of a signature structure that stays significant.
    pub adequacy_reduction: f64,
    /// Significance (Bonferroni over its signature tests) of the structure that indicates a
    /// candidate.
    pub indication_alpha: f64,
    /// Smallest BIC improvement accepted (10: "very strong" on the Kass–Raftery scale).
    pub min_delta_bic: f64,
    /// Offer the sparse catalog form ([`super::sparse_catalog`]); off only for ablation.
    pub sparse_catalog: bool,
}

impl Default for SearchConfig {
    fn default() -> Self {
        Self {
            alpha: 1.0e-3,
            halves_sigma: 3.0,
            max_iterations: 12,
            adequacy_reduction: 0.8,
            indication_alpha: 0.01,
            min_delta_bic: 10.0,
            sparse_catalog: true,
        }
    }
}

/// Estimate the cyclic pitch of an FSS from residuals: a grid of pitches (0.5°–8°, 1 % steps),
/// each fitted as sin/cos of both head angles on top of a low-order polynomial in α, β; the
/// pitch with the largest χ² reduction (None if the sensor has too little data).
#[must_use]
pub fn cyclic_pitch(set: &MeasurementSet, resid: &[[f64; 2]], sensor: usize) -> Option<f64> {
    let rows: Vec<(f64, f64, [f64; 2], f64)> = set
        .meas
        .iter()
        .zip(resid)
        .filter(|(m, _)| m.sensor == sensor && !m.outlier)
        .map(|(m, r)| (m.ang[0], m.ang[1], *r, 1.0 / (m.sigma * m.sigma)))
        .collect();
    if rows.len() < 200 {
        return None;
    }
    let e = super::effects::FSS_EDGE_RAD;
    let gain_at = |p_deg: f64| -> f64 {
        let w = std::f64::consts::TAU / (p_deg * fsw_core::units::RAD_PER_DEG);
        let mut gain = 0.0;
        for axis in 0..2 {
            let k = 8;
            let mut n = DMatrix::<f64>::zeros(k, k);
            let mut b = nalgebra::DVector::<f64>::zeros(k);
            for (a, bb, r, wt) in &rows {
                let (own, other) = if axis == 0 { (*a, *bb) } else { (*bb, *a) };
                let (x, y) = (own / e, other / e);
                let (s, c) = (w * own).sin_cos();
                let row = [1.0, x, y, x * x * x, x * y * y, x * x, s, c];
                for i in 0..k {
                    b[i] += wt * row[i] * r[axis];
                    for j in 0..k {
                        n[(i, j)] += wt * row[i] * row[j];
                    }
                }
            }
            for i in 0..k {
                n[(i, i)] += 1e-9 * n[(i, i)].max(1e-30);
            }
            let full = n.clone().cholesky().map(|c| c.solve(&b).dot(&b));
            let n6 = n.view((0, 0), (6, 6)).into_owned();
            let b6 = b.rows(0, 6).into_owned();
            let reduced = n6.cholesky().map(|c| c.solve(&b6).dot(&b6));
            if let (Some(f), Some(r)) = (full, reduced) {
                gain += f - r;
            }
        }
        gain
    };
    // Coarse grid (1 % steps over 0.5°–5°), then a fine one (0.05 %) around the best.
    let mut best: Option<(f64, f64)> = None;
    let mut gains = Vec::new();
    let mut p_deg = 0.5;
    while p_deg <= 5.0 {
        let gain = gain_at(p_deg);
        if best.is_none_or(|(_, g)| gain > g) {
            best = Some((p_deg, gain));
        }
        gains.push(gain);
        p_deg *= 1.01;
    }
    if let Some((p0, _)) = best {
        for k in -20..=20 {
            let p = p0 * (1.0 + 0.0005 * f64::from(k));
            let gain = gain_at(p);
            if best.is_none_or(|(_, g)| gain > g) {
                best = Some((p, gain));
            }
        }
    }
    // A real cyclic error stands out of the periodogram; otherwise no cyclic term.
    gains.sort_by(f64::total_cmp);
    let median = gains.get(gains.len() / 2).copied().unwrap_or(0.0);
    if std::env::var_os("DIAGNOSE_DEBUG").is_some() {
        crate::note!("pitch search sensor {sensor}: best {best:?} median {median}");
    }
    best.filter(|(_, g)| *g > 30.0_f64.max(3.0 * median))
        .map(|(p, _)| p * fsw_core::units::RAD_PER_DEG)
}

/// Is an effect covered by the declared effects? (`x` covers `unit.x`, as in sim-harness.)
#[must_use]
pub fn is_declared(effect: &Effect, declared: &[String]) -> bool {
    let truth = effect.kind.truth_name();
    let unit = effect
        .sensor
        .map(|s| super::measurements::SENSOR_NAMES[s].to_ascii_lowercase());
    declared.iter().any(|d| {
        d == truth
            || d == effect.kind.name()
            || unit.as_ref().is_some_and(|u| *d == format!("{u}.{truth}"))
    }) && !matches!(
        effect.kind,
        EffectKind::AberrationAnnual | EffectKind::AberrationOrbital | EffectKind::Aberration
    )
}

/// For an aberration candidate, which aberration (0 annual, 1 orbital) each parameter scales.
fn aberration_parts(kind: EffectKind) -> Option<&'static [usize]> {
    match kind {
        EffectKind::AberrationAnnual => Some(&[0]),
        EffectKind::AberrationOrbital => Some(&[1]),
        EffectKind::Aberration => Some(&[0, 1]),
        _ => None,
    }
}

/// A candidate `c` fitted with `model`: the model's fit `current` and the fit with the
/// candidate `big`.
struct CandidateFit<'a> {
    model: &'a [usize],
    current: &'a SubFit,
    c: usize,
    big: &'a SubFit,
}

impl CandidateFit<'_> {
    /// The model with the candidate.
    fn with_candidate(&self) -> Vec<usize> {
        with_effect(self.model, self.c)
    }
}

/// `model` with effect `c` added.
pub(super) fn with_effect(model: &[usize], c: usize) -> Vec<usize> {
    let mut with = model.to_vec();
    with.push(c);
    with
}

/// Why a candidate's form does not fit: an extension of `kind` on its sensor still explains
/// Δχ² `d` (F `f`, p `p`).
fn lack_of_fit(kind: EffectKind, d: f64, f: f64, p: f64) -> String {
    format!(
        "lack of fit: a {} still explains Δχ² {d:.1} (F {f:.2}, p {p:.1e})",
        extension_terms(kind)
    )
}

/// What a lack-of-fit extension holds, for the rejection messages.
fn extension_terms(kind: EffectKind) -> &'static str {
    if kind == EffectKind::SecularAlignmentExtension {
        "secular alignment variation (time P1–P3)"
    } else {
        "generic extension (orbit harmonics 2–3, ΔT²)"
    }
}

fn max_excess(tests: &[StructureTest]) -> f64 {
    tests.iter().map(|t| t.f - 1.0).fold(0.0, f64::max)
}

fn sensors_of(effect: &Effect) -> Vec<usize> {
    match effect.sensor {
        Some(s) => vec![s],
        None if effect.kind == EffectKind::CatalogProperMotionError => vec![0, 1],
        None => vec![0, 1, 2, 3],
    }
}

/// Do two effects compete for the same structure? The same sensor, or both on FHSTs: only
/// the trackers' relative alignment is observable, so an FHST1 effect and an FHST2 effect can
/// explain the same data.
fn overlapping(a: &[usize], b: &[usize]) -> bool {
    a.iter().any(|s| b.contains(s)) || (a.iter().any(|&s| s < 2) && b.iter().any(|&s| s < 2))
}

/// Is `sub` a restriction of `full` (the same kind on the same sensor with fewer orbit
/// harmonics)? A restriction explains less by construction, and its failing a lack-of-fit
/// test is what the larger form is there for: it must not veto it.
fn restricts(sub: &Effect, full: &Effect) -> bool {
    sub.kind == full.kind && sub.sensor == full.sensor && sub.harmonics < full.harmonics
}

/// The full and the sparse catalog forms ([`super::sparse_catalog`]) describe the same
/// structure: a model holds one of them, so effect `i` is not offered when the other is in.
fn catalog_taken(layout: &Layout, model: &[usize], i: usize) -> bool {
    let catalog = |j: usize| layout.effects[j].kind == EffectKind::CatalogProperMotionError;
    catalog(i) && model.iter().any(|&m| m != i && catalog(m))
}

/// Run the loop.
///
/// # Errors
/// The baseline fit is singular (no usable data).
pub fn search(
    set: &mut MeasurementSet,
    declared: &[String],
    config: &SearchConfig,
) -> anyhow::Result<SearchResult> {
    let first = search_with_pitch(set, declared, config, &Nonlinear::default())?;
    // The cyclic pitch is a nonlinear parameter searched on the preliminary residuals; an
    // effect not yet modelled there (a time tag, a thermal term) can hide the reticle's
    // period. Search again on the final residuals; a period found only now restarts the loop
    // with it (once).
    let fss_pitch = |res: &SearchResult, s: usize| {
        res.layout
            .find(EffectKind::FssTransferFunction, Some(s))
            .and_then(|i| res.layout.effects[i].pitch_rad)
    };
    let mut again = [None, None];
    let mut any = false;
    for (k, s) in [2usize, 3].into_iter().enumerate() {
        again[k] = fss_pitch(&first, s);
        if again[k].is_none() {
            again[k] = cyclic_pitch(set, &first.after.resid, s);
            any |= again[k].is_some();
        }
    }
    // An accepted alignment step's time, scanned again on the final residuals with the step
    // added back: the preliminary fit's batch attitudes absorbed part of the step where the
    // sensor dominates them (an FSS1 step at 10,000 s was placed at 12,152 s).
    let steps = super::change_point::rescan_accepted_steps(set, &first);
    let moved = steps
        .iter()
        .zip(&first_step_times(&first))
        .any(|(new, old)| new.map(|s| s.0) != *old);
    if !any && !moved {
        return Ok(first);
    }
    if std::env::var_os("DIAGNOSE_DEBUG").is_some() {
        crate::note!(
            "cyclic pitch found on the final residuals (deg): {:?}, step times {:?}; loop again",
            again.map(|p| p.map(f64::to_degrees)),
            steps
        );
    }
    let forced = Nonlinear {
        pitch: Some(again),
        steps: moved.then_some(steps),
    };
    search_with_pitch(set, declared, config, &forced)
}

/// The accepted alignment steps' times per sensor.
fn first_step_times(res: &SearchResult) -> [Option<f64>; 4] {
    let mut out = [None; 4];
    for &i in &res.added {
        let e = &res.layout.effects[i];
        if let (EffectKind::AlignmentStep, Some(s)) = (e.kind, e.sensor) {
            out[s] = e.step_time_s;
        }
    }
    out
}

/// Nonlinear parameters fixed for a second search: the FSS cyclic pitches and the alignment
/// steps' times (time, positions of the first scan) per sensor.
#[derive(Clone, Copy, Debug, Default)]
struct Nonlinear {
    pitch: Option<[Option<f64>; 2]>,
    steps: Option<[Option<(f64, usize)>; 4]>,
}

/// The reason a candidate is vetoed by `v`, a stronger explanation that failed its checks.
fn vetoed_by(v: &Evidence) -> String {
    format!(
        "vetoed: {} explains the same structure better (ΔBIC {:.1}) but failed its checks",
        v.effect, v.delta_bic
    )
}

/// A candidate's evidence with its index in the layout and the fit of the model with it.
type Scored = (usize, Evidence, Option<SubFit>);

/// An F test of a hidden extension added to a model: (the fit with it, Δχ², F, p).
type ExtensionTest = (SubFit, f64, f64, f64);

/// The alignment-variation kinds, which a joint lack of fit implicates (aberration has a fixed
/// physical form and one parameter: a lack of fit elsewhere does not implicate it).
fn varies_alignment(kind: EffectKind) -> bool {
    matches!(
        kind,
        EffectKind::ThermalAlignmentDrift | EffectKind::OrbitPeriodicAlignment
    )
}

/// What every stage of one search shares: the measurements (outliers flagged), the library's
/// layout and normal equations, the settings, and the test levels derived from the baseline.
struct SearchContext<'a> {
    set: &'a MeasurementSet,
    layout: Layout,
    systems: Systems,
    config: &'a SearchConfig,
    /// Bonferroni level of the whole structure-test family of the baseline residuals.
    p_thr: f64,
    /// Rows of the full system (the `n` of BIC).
    n_rows: f64,
}

/// The model as the phases change it: its effects, those added and those excluded, its fit
/// and residuals, and the record of the iterations.
struct ModelState {
    model: Vec<usize>,
    added: Vec<usize>,
    excluded: Vec<usize>,
    current: SubFit,
    current_post: PostFit,
    iterations: Vec<Iteration>,
    evidence_added: Vec<Evidence>,
}

/// The library the search runs on and the declared baseline within it.
struct Library {
    layout: Layout,
    systems: Systems,
    baseline: Vec<usize>,
}

fn search_with_pitch(
    set: &mut MeasurementSet,
    declared: &[String],
    config: &SearchConfig,
    forced: &Nonlinear,
) -> anyhow::Result<SearchResult> {
    // 1. Preliminary fit: outlier flags and the FSS cyclic pitches.
    let (pf, pitch) = preliminary_fit(set, forced)?;
    let set: &MeasurementSet = set;
    // 2. The unknown-orbit terms when the telemetry has no orbit.
    let unknown_orbit = unknown_orbit(set, declared, &pf);
    // 3. The library: effects, alignment steps, the sparse catalog form; the baseline.
    let Library {
        layout,
        systems,
        baseline,
    } = full_library(set, declared, config, forced, &pf, pitch, unknown_orbit);
    // 4. The baseline's fit and structure tests, which set the test family's level.
    let baseline_fit = solve(&systems.full, &layout, &indices(&layout, &baseline))
        .ok_or_else(|| anyhow::anyhow!("diagnose: the baseline fit is singular"))?;
    let before = post_fit(set, &layout, &baseline_fit.expand(layout.total));
    let tests_before = run_tests(set, &before, None, None);
    let family = tests_before.len().max(1) as f64;
    let ctx = SearchContext {
        set,
        n_rows: systems.full.rows as f64,
        layout,
        systems,
        config,
        p_thr: config.alpha / family,
    };
    let mut st = ModelState {
        model: baseline.clone(),
        added: Vec::new(),
        excluded: Vec::new(),
        current: baseline_fit.clone(),
        current_post: before.clone(),
        iterations: Vec::new(),
        evidence_added: Vec::new(),
    };
    // 5. Phases 1 and 2 until no effect fails: forward on the likelihood, then the weakest
    //    failing effect leaves.
    let n_library = ctx.n_library(&st.model);
    loop {
        ctx.forward_on_likelihood(&mut st);
        let Some((k, e)) = ctx.weakest_failing(&st, n_library) else {
            break;
        };
        ctx.remove_effect(&mut st, k, e)?;
    }
    // 6. The evidence of the effects kept, each against the model without it.
    ctx.evidence_of_kept(&mut st);
    // 7. Phase 3: the forward loop with every check.
    ctx.forward_with_checks(&mut st);
    // 8. The final residuals' structure.
    let tests_after = run_tests(set, &st.current_post, None, None);
    Ok(SearchResult {
        layout: ctx.layout,
        baseline,
        added: st.added,
        baseline_fit,
        final_fit: st.current,
        before,
        after: st.current_post,
        iterations: st.iterations,
        tests_before,
        tests_after,
        evidence: st.evidence_added,
        systems: ctx.systems,
        fixed: Vec::new(),
    })
}

/// Fits the alignments with the FSS transfer polynomials and the time tags, flags the
/// outliers on its residuals and finds the FSS cyclic pitches (unless forced): (residuals,
/// pitches).
fn preliminary_fit(
    set: &mut MeasurementSet,
    forced: &Nonlinear,
) -> anyhow::Result<(PostFit, [Option<f64>; 2])> {
    // Preliminary fit (alignments only) to get clean residuals for the pitch search and the
    // outlier flags.
    // The FSS transfer polynomial is in the preliminary fit (only to clean the residuals of
    // the pitch search).
    let prelim_layout = Layout::new(super::effects::library(set, [None, None], None));
    let prelim_sys = accumulate_halves(set, &prelim_layout);
    // The per-sensor time tags are in it too: their signature grows with the rate, and a
    // large one (an FSS 0.4 s late: 115″ at 0.08°/s) otherwise puts its slew samples beyond
    // the outlier threshold, so that the search never sees them (censored: the estimate is
    // biased toward zero and its halves disagree). One parameter per sensor, and only these
    // flags and the pitch search use this fit.
    let prelim_tf: Vec<usize> = (0..prelim_layout.effects.len())
        .filter(|&i| {
            matches!(
                prelim_layout.effects[i].kind,
                EffectKind::FssTransferFunction | EffectKind::TimeTagOffset
            )
        })
        .collect();
    let prelim = solve(
        &prelim_sys.full,
        &prelim_layout,
        &indices(&prelim_layout, &prelim_tf),
    )
    .or_else(|| {
        solve(
            &prelim_sys.full,
            &prelim_layout,
            &indices(&prelim_layout, &[]),
        )
    })
    .ok_or_else(|| {
        anyhow::anyhow!("diagnose: the alignment fit is singular (no epochs with FHST stars?)")
    })?;
    let pf = post_fit(set, &prelim_layout, &prelim.expand(prelim_layout.total));
    set.flag_outliers(&pf.resid);
    let pitch = forced.pitch.unwrap_or_else(|| {
        [
            cyclic_pitch(set, &pf.resid, 2),
            cyclic_pitch(set, &pf.resid, 3),
        ]
    });

    if std::env::var_os("DIAGNOSE_DEBUG").is_some() {
        crate::note!(
            "cyclic pitch (deg): {:?}",
            pitch.map(|p| p.map(f64::to_degrees))
        );
    }
    Ok((pf, pitch))
}

/// The unknown orbit's rate (rad/s) when the telemetry has no orbit while the operator's
/// model has orbital aberration or Sun parallax: the unknown-orbit terms then join the
/// baseline (`EffectKind::UnknownOrbit`).
fn unknown_orbit(set: &MeasurementSet, declared: &[String], pf: &PostFit) -> Option<f64> {
    let orbit_declared = declared
        .iter()
        .any(|d| d == "orbital_aberration" || d == "sun_parallax");
    let unknown_orbit = if set.orbit_period_s.is_none() && orbit_declared {
        super::effects::unknown_orbit_rate(set, &pf.resid)
    } else {
        None
    };
    if std::env::var_os("DIAGNOSE_DEBUG").is_some() {
        crate::note!(
            "unknown orbit: period {:?} min",
            unknown_orbit.map(|n| std::f64::consts::TAU / n / 60.0)
        );
    }
    unknown_orbit
}

/// The library of the search: the effects with the pitches and the unknown orbit, the
/// alignment steps at the change-point scan's best time per sensor on the preliminary
/// residuals (`change_point`), and the sparse catalog form when configured; the baseline is
/// the declared effects and the unknown-orbit terms.
fn full_library(
    set: &MeasurementSet,
    declared: &[String],
    config: &SearchConfig,
    forced: &Nonlinear,
    pf: &PostFit,
    pitch: [Option<f64>; 2],
    unknown_orbit: Option<f64>,
) -> Library {
    let mut library = super::effects::library(set, pitch, unknown_orbit);
    library.extend(super::change_point::step_effects(
        set,
        &pf.resid,
        forced.steps,
    ));
    let layout = Layout::new(library);
    let systems = accumulate_halves(set, &layout);
    let baseline: Vec<usize> = (0..layout.effects.len())
        .filter(|&i| {
            is_declared(&layout.effects[i], declared)
                || layout.effects[i].kind == EffectKind::UnknownOrbit
        })
        .collect();
    // The sparse catalog form (per-star offsets selected star by star): appended to the
    // library when a few stars pass their own tests against the baseline.
    let (layout, systems) = if config.sparse_catalog {
        let (l, s, _) = super::sparse_catalog::with_sparse_catalog(
            set,
            layout,
            systems,
            &baseline,
            config.alpha,
        );
        (l, s)
    } else {
        (layout, systems)
    };
    Library {
        layout,
        systems,
        baseline,
    }
}

/// The statistical criteria every candidate must meet (LR test after Holm, BIC): the
/// reasons it fails them.
fn statistical_reasons(e: &Evidence, config: &SearchConfig) -> Vec<String> {
    let mut why = Vec::new();
    if !(e.p_holm < config.alpha) {
        why.push(format!("LR p_holm {:.3e} ≥ {}", e.p_holm, config.alpha));
    }
    if !(e.delta_bic > config.min_delta_bic) {
        why.push(format!(
            "ΔBIC {:.1} ≤ {}",
            e.delta_bic, config.min_delta_bic
        ));
    }
    why
}

/// The gauge-free comparison of the halves' per-star catalog offsets: the stars both halves
/// determine (σ below half the prior), each half's net rotation removed; (χ², p, the
/// compared offsets of each half).
#[allow(clippy::too_many_arguments)]
fn catalog_halves(
    effect: &Effect,
    k: usize,
    (a, pa): (&SubFit, &[usize]),
    (b, pb): (&SubFit, &[usize]),
    xa: &nalgebra::DVector<f64>,
    xb: &nalgebra::DVector<f64>,
) -> (f64, f64, (Vec<f64>, Vec<f64>)) {
    let prior: Vec<f64> = effect.prior_sigma.clone();
    let va: Vec<f64> = pa
        .iter()
        .map(|&i| a.cov[(i, i)] * a.s2().max(1.0))
        .collect();
    let vb: Vec<f64> = pb
        .iter()
        .map(|&i| b.cov[(i, i)] * b.s2().max(1.0))
        .collect();
    let both: Vec<bool> = (0..k / 2)
        .map(|s| {
            (0..2).all(|j| {
                va[2 * s + j].sqrt() < 0.5 * prior[2 * s + j]
                    && vb[2 * s + j].sqrt() < 0.5 * prior[2 * s + j]
            })
        })
        .collect();
    let mask = |v: &[f64]| -> Vec<f64> {
        v.iter()
            .enumerate()
            .map(|(i, x)| if both[i / 2] { *x } else { f64::INFINITY })
            .collect()
    };
    let xa_v: Vec<f64> = xa.iter().copied().collect();
    let xb_v: Vec<f64> = xb.iter().copied().collect();
    let ra = super::effects::remove_net_rotation(&effect.star_dirs, &xa_v, &mask(&va));
    let rb = super::effects::remove_net_rotation(&effect.star_dirs, &xb_v, &mask(&vb));
    // χ² with the full covariance of the compared offsets: the offsets of
    // the stars of one hold share that hold's attitude error, and per-star
    // variances alone (the old test) hid a common shift between the halves
    // (an FSS1 alignment step read as 60 star offsets passed with p 0.997;
    // clean runs gave p ≈ 1). The net-rotation removal is linear: its
    // matrix on the compared offsets carries each half's covariance.
    let sel: Vec<usize> = (0..k).filter(|&i| both[i / 2]).collect();
    let n2 = sel.len();
    let rot_matrix = |v: &[f64]| -> DMatrix<f64> {
        let mv = mask(v);
        let mut r = DMatrix::zeros(n2, n2);
        for (q, &j) in sel.iter().enumerate() {
            let mut unit = vec![0.0; k];
            unit[j] = 1.0;
            let col = super::effects::remove_net_rotation(&effect.star_dirs, &unit, &mv);
            for (r_i, &i) in sel.iter().enumerate() {
                r[(r_i, q)] = col[i];
            }
        }
        r
    };
    let sub_cov = |fit: &SubFit, p: &[usize]| -> DMatrix<f64> {
        DMatrix::from_fn(n2, n2, |r_i, q| {
            fit.cov[(p[sel[r_i]], p[sel[q]])] * fit.s2().max(1.0)
        })
    };
    let (rma, rmb) = (rot_matrix(&va), rot_matrix(&vb));
    let c = &rma * sub_cov(a, pa) * rma.transpose() + &rmb * sub_cov(b, pb) * rmb.transpose();
    let d = nalgebra::DVector::from_iterator(n2, sel.iter().map(|&i| ra[i] - rb[i]));
    let (cinv, crank) = crate::linalg::sym_pinv(&c, 1e-9);
    let hchi2 = d.dot(&(&cinv * &d));
    let hp = if n2 > 3 && crank > 0 {
        chi2_sf(hchi2, crank as f64)
    } else {
        1.0
    };
    (hchi2, hp, (ra, rb))
}

impl SearchContext<'_> {
    /// The fit of the model with `effects` on the normal equations `sys`.
    fn fit_model(&self, sys: &super::fit::Normal, effects: &[usize]) -> Option<SubFit> {
        solve(sys, &self.layout, &indices(&self.layout, effects))
    }

    /// F test of a hidden extension `ext` (lack-of-fit terms) added to `model`, whose fit has
    /// χ² `chi2`: (the fit with it, Δχ², F, p).
    fn extension_test(&self, model: &[usize], chi2: f64, ext: usize) -> Option<ExtensionTest> {
        let with = with_effect(model, ext);
        let fe = self.fit_model(&self.systems.full, &with)?;
        let k = self.layout.effects[ext].len() as f64;
        let d = chi2 - fe.chi2;
        let f = (d / k) / fe.s2();
        let p = f_sf(f, k, fe.dof);
        Some((fe, d, f, p))
    }

    /// Does effect `x` add nothing to `model` once effect `y` is in it (F test at `alpha`)?
    /// Then the structure `x` explains is `y`'s, whatever sensors each acts on: through the
    /// batch attitudes an FSS transfer function that pulls the attitude where one tracker is
    /// blind shows on that tracker's stars, and per-star catalog offsets (60 parameters)
    /// explained 98 % of its Δχ² on the writer's FSS1 transfer function.
    fn adds_nothing_beyond(&self, model: &[usize], x: usize, y: usize) -> bool {
        let with_y = with_effect(model, y);
        let mut with_both = with_y.clone();
        with_both.push(x);
        match (
            self.fit_model(&self.systems.full, &with_y),
            self.fit_model(&self.systems.full, &with_both),
        ) {
            (Some(a), Some(b)) => {
                let k = self.layout.effects[x].len() as f64;
                let f = ((a.chi2 - b.chi2) / k) / b.s2();
                f_sf(f, k, b.dof) >= self.config.alpha
            }
            _ => false,
        }
    }

    /// The library's size for the backward step's Bonferroni correction: the visible effects
    /// outside the baseline `model`.
    fn n_library(&self, model: &[usize]) -> f64 {
        (0..self.layout.effects.len())
            .filter(|&i| !model.contains(&i) && !self.layout.effects[i].hidden)
            .count()
            .max(1) as f64
    }

    /// The candidates offered: visible effects neither in the model nor excluded, and not a
    /// second catalog form.
    fn candidates(&self, st: &ModelState) -> Vec<usize> {
        (0..self.layout.effects.len())
            .filter(|&i| {
                !st.model.contains(&i)
                    && !st.excluded.contains(&i)
                    && !self.layout.effects[i].hidden
                    && !catalog_taken(&self.layout, &st.model, i)
            })
            .collect()
    }

    /// Evidence of every candidate against `model` (fit `current`, residuals `current_post`);
    /// `full`: the halves, indication, adequacy and lack-of-fit checks too, else only the
    /// likelihood ratio and BIC. Returns the evidence and the best passing candidate.
    fn evaluate(
        &self,
        model: &[usize],
        current: &SubFit,
        current_post: &PostFit,
        candidates: &[usize],
        full: bool,
    ) -> (Vec<Scored>, Option<(usize, f64)>) {
        let config = self.config;
        let mut evs: Vec<Scored> = candidates
            .iter()
            .filter_map(|&c| self.likelihood_evidence(model, current, c))
            .collect();
        let adj = holm_adjust(&evs.iter().map(|e| e.1.p_value).collect::<Vec<_>>());
        let halves_p_min = chi2_sf(config.halves_sigma * config.halves_sigma, 1.0);
        for ((_, e, _), a) in evs.iter_mut().zip(adj) {
            e.p_holm = a;
        }
        // Adequacy only for the candidates that pass the statistical criteria (cost).
        let mut best: Option<(usize, f64)> = None;
        for (i, (c, e, big)) in evs.iter_mut().enumerate() {
            let mut why = statistical_reasons(e, config);
            // A step happens once: the half without it cannot fit it.
            let once = self.layout.effects[*c].kind == EffectKind::AlignmentStep;
            if full && !once && !(e.halves_p > halves_p_min) {
                why.push(format!(
                    "halves differ (χ² {:.1}, p {:.2e})",
                    e.halves_chi2, e.halves_p
                ));
            }
            if full && why.is_empty() {
                why.extend(self.unphysical_aberration(*c, big.as_ref()));
            }
            if full && why.is_empty() {
                if let Some(big) = big.as_ref() {
                    let fit = CandidateFit {
                        model,
                        current,
                        c: *c,
                        big,
                    };
                    self.adequacy(&fit, current_post, e, &mut why);
                } else if self.layout.effects[*c].signature().is_empty() {
                    e.adequate = true;
                }
            }
            if why.is_empty() {
                if best.is_none_or(|(_, b)| e.delta_bic > b) {
                    best = Some((i, e.delta_bic));
                }
            } else {
                e.rejected_because = Some(why.join("; "));
            }
        }
        (evs, best)
    }

    /// The likelihood-ratio evidence of candidate `c` added to `model` (fit `current`): Δχ²,
    /// F, p (Bonferroni over a scanned parameter), ΔBIC and the halves' agreement; `None`
    /// when the model with it is singular.
    fn likelihood_evidence(&self, model: &[usize], current: &SubFit, c: usize) -> Option<Scored> {
        let n_rows = self.n_rows;
        let effect = &self.layout.effects[c];
        let with = with_effect(model, c);
        let big = self.fit_model(&self.systems.full, &with)?;
        let k = effect.len();
        let dchi2 = current.chi2 - big.chi2;
        let s2 = big.s2();
        let f = (dchi2 / k as f64) / s2;
        // A scanned nonlinear parameter (a step's time): Bonferroni over the scan.
        let p = (f_sf(f, k as f64, big.dof) * effect.scan_positions as f64).min(1.0);
        let dbic = n_rows * (current.chi2 / big.chi2).ln()
            - (k + effect.extra_params) as f64 * n_rows.ln();
        let (hchi2, hp, est) = self.halves(c, &with);
        Some((
            c,
            Evidence::likelihood_test(effect.label(), k, (dchi2, f, p), dbic, (hchi2, hp, est)),
            Some(big),
        ))
    }

    /// Candidate `c`'s parameters fitted on the two halves of the data by the model `with`
    /// (which holds it), compared: (χ² of the difference, its p, the two estimates); (NaN, 0,
    /// empty) when a half's fit is singular.
    fn halves(&self, c: usize, with: &[usize]) -> (f64, f64, (Vec<f64>, Vec<f64>)) {
        let layout = &self.layout;
        let effect = &layout.effects[c];
        let k = effect.len();
        let range: Vec<usize> = layout.range(c).collect();
        let fit_half = |sys: &super::fit::Normal| {
            super::fit::solve_opt(sys, layout, &indices(layout, with), false)
        };
        let (Some(a), Some(b)) = (
            fit_half(&self.systems.first),
            fit_half(&self.systems.second),
        ) else {
            return (f64::NAN, 0.0, (Vec::new(), Vec::new()));
        };
        let pos = |fit: &SubFit| -> Vec<usize> {
            range
                .iter()
                .filter_map(|i| fit.idx.iter().position(|j| j == i))
                .collect()
        };
        let (pa, pb) = (pos(&a), pos(&b));
        let xa = nalgebra::DVector::from_iterator(k, pa.iter().map(|&i| a.x[i]));
        let xb = nalgebra::DVector::from_iterator(k, pb.iter().map(|&i| b.x[i]));
        if effect.kind == EffectKind::CatalogProperMotionError && !effect.sparse {
            return catalog_halves(effect, k, (&a, &pa), (&b, &pb), &xa, &xb);
        }
        let mut cab = DMatrix::zeros(k, k);
        for (r, (&ia, &ib)) in pa.iter().zip(&pb).enumerate() {
            for (q, (&ja, &jb)) in pa.iter().zip(&pb).enumerate() {
                cab[(r, q)] = a.cov[(ia, ja)] * a.s2().max(1.0) + b.cov[(ib, jb)] * b.s2().max(1.0);
            }
        }
        let (inv, rank) = crate::linalg::sym_pinv(&cab, 1e-12);
        if std::env::var_os("DIAGNOSE_DEBUG").is_some()
            && effect.kind == EffectKind::FssTransferFunction
        {
            let z: Vec<String> = (0..k)
                .map(|i| {
                    format!(
                        "{:.1}±{:.1}/{:.1}±{:.1}",
                        xa[i],
                        (a.cov[(pa[i], pa[i])] * a.s2().max(1.0)).sqrt(),
                        xb[i],
                        (b.cov[(pb[i], pb[i])] * b.s2().max(1.0)).sqrt()
                    )
                })
                .collect();
            crate::note!("halves {}: {}", effect.label(), z.join(" "));
        }
        let d = &xa - &xb;
        let hchi2 = d.dot(&(&inv * &d));
        let hp = chi2_sf(hchi2, rank.max(1) as f64);
        (
            hchi2,
            hp,
            (xa.iter().copied().collect(), xb.iter().copied().collect()),
        )
    }

    /// A velocity aberration is there (k = 1) or not (k = 0): an aberration candidate whose k
    /// is neither (within 3σ, at least ±0.15) describes another structure (an FHST2 alignment
    /// step on the writer's calibration day gave k_orbital − k₀ = 1.99 ± 0.07 and was
    /// accepted). The reasons candidate `c` (fit `big`) is unphysical.
    fn unphysical_aberration(&self, c: usize, big: Option<&SubFit>) -> Vec<String> {
        let mut why = Vec::new();
        let layout = &self.layout;
        if let (Some(part_of), Some(big)) = (aberration_parts(layout.effects[c].kind), big) {
            for (pi, gi) in layout.range(c).enumerate() {
                let (Some(pos), Some(&part)) =
                    (big.idx.iter().position(|&j| j == gi), part_of.get(pi))
                else {
                    continue;
                };
                let x = big.x[pos];
                let sd = (big.cov[(pos, pos)] * big.s2().max(1.0)).sqrt();
                let k0 = self.set.aberration_k0[part];
                let physical = [-k0, 1.0 - k0]
                    .iter()
                    .any(|v| (x - v).abs() <= (3.0 * sd).max(0.15));
                if !physical {
                    why.push(format!(
                        "unphysical: {} = {x:.2} ± {sd:.2} (k is 1 or 0; applied k₀ = {k0})",
                        layout.effects[c].params[pi]
                    ));
                }
            }
        }
        why
    }

    /// Indication and adequacy of a candidate (`fit`; residuals of its model
    /// `current_post`): its signature structure must be there before and gone (or reduced)
    /// after, and no extension may still explain what it is meant to; sets `e.adequate` and
    /// `e.signature_excess` and adds the reasons it fails to `why`.
    fn adequacy(
        &self,
        fit: &CandidateFit<'_>,
        current_post: &PostFit,
        e: &mut Evidence,
        why: &mut Vec<String>,
    ) {
        let (set, layout, config) = (self.set, &self.layout, self.config);
        let (c, big) = (fit.c, fit.big);
        let effect = &layout.effects[c];
        let sig: &[Regressor] = effect.signature();
        if sig.is_empty() {
            e.adequate = true;
            return;
        }
        let sensors = sensors_of(effect);
        let pre = run_tests(set, current_post, Some(&sensors), Some(sig));
        let post = post_fit(set, layout, &big.expand(layout.total));
        let after = run_tests(set, &post, Some(&sensors), Some(sig));
        let (x0, x1) = (max_excess(&pre), max_excess(&after));
        e.signature_excess = (x0, x1);
        let p_min = pre.iter().map(|t| t.p_value).fold(1.0, f64::min);
        let indicated = !effect.needs_indication()
            || p_min * (pre.len().max(1) as f64) < config.indication_alpha;
        let still = after.iter().any(|t| t.p_value < self.p_thr);
        e.adequate = indicated && (!still || x1 <= (1.0 - config.adequacy_reduction) * x0);
        if !indicated {
            why.push(format!(
                "not indicated: no signature structure before (min p {p_min:.2e} over {} tests)",
                pre.len()
            ));
        } else if !e.adequate {
            why.push(format!(
                "inadequate: signature structure remains (max F−1 {x0:.1} → {x1:.1})"
            ));
        }
        if e.adequate && varies_alignment(effect.kind) {
            self.variation_lack_of_fit(fit, e, why);
        }
        if e.adequate && effect.kind == EffectKind::AlignmentStep {
            self.step_lack_of_fit(fit, e, why);
        }
    }

    /// Lack of fit of an alignment-variation candidate `c` (fit `big`): does a generic
    /// extension on the same sensor (orbit harmonics 2–3, ΔT²; then, as a test of its own,
    /// time P1–P3) still explain something? Then the structure has another form than the
    /// candidate's.
    fn variation_lack_of_fit(
        &self,
        fit: &CandidateFit<'_>,
        e: &mut Evidence,
        why: &mut Vec<String>,
    ) {
        let (layout, config) = (&self.layout, self.config);
        let (model, big, with_c) = (fit.model, fit.big, fit.with_candidate());
        let effect = &layout.effects[fit.c];
        if let Some((ext, (fe, d, f_ext, p_ext))) = layout
            .find(EffectKind::GenericAlignmentExtension, effect.sensor)
            .and_then(|ext| {
                self.extension_test(&with_c, big.chi2, ext)
                    .map(|t| (ext, t))
            })
        {
            // A test of the candidate's form, not a model choice: the
            // F test at the family level decides (BIC would charge the
            // extension's 21 parameters and let a twice-per-orbit or a
            // quadratic structure be forced onto the linear candidate).
            if p_ext < config.alpha {
                e.adequate = false;
                why.push(lack_of_fit(
                    EffectKind::GenericAlignmentExtension,
                    d,
                    f_ext,
                    p_ext,
                ));
            }
            // The form with the second harmonic describes a thermal orbit
            // cycle, which has its once-per-orbit part: given the generic
            // extension (which holds the 2u terms), the candidate must
            // still add something. A twice-per-orbit structure alone (a
            // geomagnetic sensitivity, algorithms.md §9 row 18, or a
            // ΔT² term of a sinusoidal temperature) is left unexplained.
            if e.adequate && effect.harmonics > 1 {
                let only_ext = with_effect(model, ext);
                if let Some(f0) = self.fit_model(&self.systems.full, &only_ext) {
                    let d1 = f0.chi2 - fe.chi2;
                    let f1 = (d1 / 6.0) / fe.s2();
                    let p1 = f_sf(f1, 6.0, fe.dof);
                    if !(p1 < config.alpha) {
                        e.adequate = false;
                        why.push(format!(
                            "no once-per-orbit part: given the 2u terms the candidate adds Δχ² {d1:.1} (F {f1:.2}, p {p1:.1e})"
                        ));
                    }
                }
            }
        }
        if let Some((_, d, f_ext, p_ext)) = layout
            .find(EffectKind::SecularAlignmentExtension, effect.sensor)
            .and_then(|ext| self.extension_test(&with_c, big.chi2, ext))
        {
            if e.adequate && p_ext < config.alpha {
                e.adequate = false;
                why.push(lack_of_fit(
                    EffectKind::SecularAlignmentExtension,
                    d,
                    f_ext,
                    p_ext,
                ));
            }
        }
    }

    /// An alignment step's lack of fit, against the same extensions on its sensor. A step at
    /// a scanned time is a flexible form: a ΔT² alignment term of FHST2 (outside the library,
    /// on the simulator's temperatures) was taken as a step at 3,512 s (Δχ² 465), the generic
    /// extension (orbit harmonics 2–3, ΔT²) still explaining Δχ² 65 (p 8e-6) beside it and
    /// 528 alone: a smooth form that fits better alone and still adds beside the step is the
    /// description, not the step. The secular extension (time P1–P3) is judged by its share
    /// of the step's Δχ² only: over a sensor's data with gaps (an FSS sees the Sun in some
    /// holds) three polynomials mimic a step (Δχ² 2,460 alone against the step's 2,445 on the
    /// writer's FSS1 step), and a real step whose time the data place a hold late leaves a
    /// small secular remainder (Δχ² 67), which is reported, not a reason to drop the step.
    fn step_lack_of_fit(&self, fit: &CandidateFit<'_>, e: &mut Evidence, why: &mut Vec<String>) {
        let (layout, config) = (&self.layout, self.config);
        let (model, current, big) = (fit.model, fit.current, fit.big);
        let with_c = fit.with_candidate();
        let effect = &layout.effects[fit.c];
        for kind in [
            EffectKind::GenericAlignmentExtension,
            EffectKind::SecularAlignmentExtension,
        ] {
            let Some(ext) = layout.find(kind, effect.sensor) else {
                continue;
            };
            let Some((_, d, f_ext, p_ext)) = self.extension_test(&with_c, big.chi2, ext) else {
                continue;
            };
            if !(p_ext < config.alpha) {
                continue;
            }
            let share = (1.0 - config.adequacy_reduction) * e.delta_chi2;
            let alone = self
                .extension_test(model, current.chi2, ext)
                .map_or(0.0, |t| t.1);
            let smooth_better =
                kind == EffectKind::GenericAlignmentExtension && alone >= e.delta_chi2;
            if e.adequate && (d > share || smooth_better) {
                e.adequate = false;
                why.push(format!(
                    "{} beside the step's {:.1}, and {alone:.1} alone",
                    lack_of_fit(kind, d, f_ext, p_ext),
                    e.delta_chi2
                ));
            }
        }
    }

    /// Phase 1, forward on the likelihood alone: with several effects present, each one's
    /// halves and adequacy checks are spoiled by the others' structure, and a flexible
    /// candidate (per-star catalog offsets) can take the first place and absorb them. So the
    /// model first takes, by ΔBIC, every candidate the LR test and BIC support.
    fn forward_on_likelihood(&self, st: &mut ModelState) {
        let layout = &self.layout;
        for _ in 0..self.config.max_iterations {
            let candidates = self.candidates(st);
            let (mut evs, best) =
                self.evaluate(&st.model, &st.current, &st.current_post, &candidates, false);
            let Some((bi, _)) = best else { break };
            let c = evs[bi].0;
            let Some(big) = evs[bi].2.take() else { break };
            st.model.push(c);
            st.added.push(c);
            st.current_post = post_fit(self.set, layout, &big.expand(layout.total));
            st.current = big;
            st.iterations.push(Iteration {
                number: st.iterations.len() + 1,
                added: Some(format!(
                    "{} (forward, on the likelihood)",
                    layout.effects[c].label()
                )),
                candidates: evs.into_iter().map(|e| e.1).collect(),
            });
        }
    }

    /// Phase 2, backward with every check: each added effect is tested against the model
    /// without it (its LR p Bonferroni-corrected over the `n_library` effects, and the veto
    /// of an excluded effect that explains the same structure better); the weakest failing
    /// one, else the joint lack of fit's suspect: (its position in `added`, its evidence).
    fn weakest_failing(&self, st: &ModelState, n_library: f64) -> Option<(usize, Evidence)> {
        let (layout, config) = (&self.layout, self.config);
        let mut worst: Option<(usize, Evidence)> = None;
        for (k, &c) in st.added.iter().enumerate() {
            let without: Vec<usize> = st.model.iter().copied().filter(|&i| i != c).collect();
            let Some(fit) = self.fit_model(&self.systems.full, &without) else {
                continue;
            };
            let post = post_fit(self.set, layout, &fit.expand(layout.total));
            let (mut evs, _) = self.evaluate(&without, &fit, &post, &[c], true);
            let Some((_, mut e, _)) = evs.pop() else {
                continue;
            };
            if e.p_value * n_library >= config.alpha {
                let why = format!(
                    "LR p {:.2e} × {n_library} candidates ≥ {}",
                    e.p_value, config.alpha
                );
                e.rejected_because = Some(match e.rejected_because.take() {
                    Some(w) => format!("{why}; {w}"),
                    None => why,
                });
            }
            if e.rejected_because.is_none() && !st.excluded.is_empty() {
                e.rejected_because = self.backward_veto(st, &without, &fit, &post, c, &e);
            }
            if e.rejected_because.is_some()
                && worst
                    .as_ref()
                    .is_none_or(|(_, w)| e.delta_bic < w.delta_bic)
            {
                worst = Some((k, e));
            }
        }
        // Joint lack of fit: when no effect fails on its own, a generic extension (orbit
        // harmonics 2–3, ΔT²) must not still explain something on a sensor whose
        // alignment-variation terms are in the model; otherwise effects are sharing a
        // structure none of them describes, and the weakest alignment-variation term leaves.
        worst.or_else(|| self.joint_lack_of_fit(&st.model, &st.added, &st.current))
    }

    /// The veto of the forward loop, in the backward step: an effect already removed for
    /// failing its checks that explains the same sensors much better (against the same model
    /// `without` effect `c`, fit `fit`, residuals `post`) means the structure is not `c`'s
    /// either. The reason, when vetoed.
    fn backward_veto(
        &self,
        st: &ModelState,
        without: &[usize],
        fit: &SubFit,
        post: &PostFit,
        c: usize,
        e: &Evidence,
    ) -> Option<String> {
        let (layout, config) = (&self.layout, self.config);
        let (others, _) = self.evaluate(without, fit, post, &st.excluded, false);
        let mine = sensors_of(&layout.effects[c]);
        others
            .iter()
            .find(|(o, v, _)| {
                v.p_holm < config.alpha
                    && v.delta_bic > e.delta_bic + config.min_delta_bic
                    && (overlapping(&sensors_of(&layout.effects[*o]), &mine)
                        || self.adds_nothing_beyond(without, c, *o))
                    && !restricts(&layout.effects[*o], &layout.effects[c])
            })
            .map(|(_, v, _)| vetoed_by(v))
    }

    /// The joint lack of fit: on each sensor, a generic or secular extension that still
    /// explains something while alignment-variation terms of that sensor are in the model
    /// names the weakest of them (the smallest χ² increase when it alone is taken out):
    /// (its position in `added`, its evidence).
    fn joint_lack_of_fit(
        &self,
        model: &[usize],
        added: &[usize],
        current: &SubFit,
    ) -> Option<(usize, Evidence)> {
        let (layout, config) = (&self.layout, self.config);
        for (s, ext_kind) in (0..4).flat_map(|s| {
            [
                EffectKind::GenericAlignmentExtension,
                EffectKind::SecularAlignmentExtension,
            ]
            .map(|k| (s, k))
        }) {
            let Some(ext) = layout.find(ext_kind, Some(s)) else {
                continue;
            };
            let test = self.extension_test(model, current.chi2, ext);
            if std::env::var_os("DIAGNOSE_DEBUG").is_some() {
                if let Some((_, d, _, p)) = &test {
                    crate::note!("joint lack of fit sensor {s}: Δχ² {d:.1}, p {p:.2e}");
                }
            }
            let suspects: Vec<usize> = (0..added.len())
                .filter(|&k| {
                    let e = &layout.effects[added[k]];
                    varies_alignment(e.kind) && overlapping(&sensors_of(e), &[s])
                })
                .collect();
            if suspects.is_empty() {
                continue;
            }
            let Some((_, d, _, p_ext)) = test else {
                continue;
            };
            if p_ext >= config.alpha {
                continue;
            }
            // The weakest suspect: the smallest χ² increase when it alone is taken out.
            let weakest = suspects
                .iter()
                .filter_map(|&k| {
                    let without: Vec<usize> =
                        model.iter().copied().filter(|&i| i != added[k]).collect();
                    self.fit_model(&self.systems.full, &without)
                        .map(|f| (k, f.chi2 - current.chi2))
                })
                .min_by(|a, b| a.1.total_cmp(&b.1));
            if let Some((k, dchi2)) = weakest {
                let mut e = Evidence::placeholder(layout.effects[added[k]].label());
                e.delta_chi2 = dchi2;
                e.accepted = false;
                e.rejected_because = Some(format!(
                    "joint lack of fit on {}: a {} still explains Δχ² {d:.1} (p {p_ext:.1e}) with it in the model",
                    super::measurements::SENSOR_NAMES[s],
                    extension_terms(ext_kind)
                ));
                return Some((k, e));
            }
        }
        None
    }

    /// Removes the effect at position `k` of `added` (evidence `e`) from the model, excludes
    /// it (and its twin on the other tracker) from the next phases, and refits.
    fn remove_effect(&self, st: &mut ModelState, k: usize, e: Evidence) -> anyhow::Result<()> {
        let layout = &self.layout;
        let c = st.added.remove(k);
        st.model.retain(|&i| i != c);
        st.excluded.push(c);
        // Only the trackers' relative alignment is observable: an alignment variation of one
        // FHST is the opposite variation of the other plus an attitude change, so the form
        // rejected on one tracker is rejected on both.
        let removed = &layout.effects[c];
        if varies_alignment(removed.kind) {
            if let Some(s @ 0..=1) = removed.sensor {
                if let Some(mirror) = layout.effects.iter().position(|e| {
                    e.kind == removed.kind
                        && e.sensor == Some(1 - s)
                        && e.harmonics == removed.harmonics
                }) {
                    if !st.model.contains(&mirror) && !st.excluded.contains(&mirror) {
                        st.excluded.push(mirror);
                    }
                }
            }
        }
        st.current = self
            .fit_model(&self.systems.full, &st.model)
            .ok_or_else(|| anyhow::anyhow!("diagnose: a sub-model fit is singular"))?;
        st.current_post = post_fit(self.set, layout, &st.current.expand(layout.total));
        st.iterations.push(Iteration {
            number: st.iterations.len() + 1,
            added: Some(format!(
                "removed {} (backward: {})",
                layout.effects[c].label(),
                e.rejected_because.clone().unwrap_or_default()
            )),
            candidates: vec![e],
        });
        Ok(())
    }

    /// The evidence of the effects kept, each against the model without it.
    fn evidence_of_kept(&self, st: &mut ModelState) {
        let layout = &self.layout;
        for &c in &st.added {
            let without: Vec<usize> = st.model.iter().copied().filter(|&i| i != c).collect();
            if let Some(fit) = self.fit_model(&self.systems.full, &without) {
                let post = post_fit(self.set, layout, &fit.expand(layout.total));
                let (mut evs, _) = self.evaluate(&without, &fit, &post, &[c], true);
                if let Some((_, mut e, _)) = evs.pop() {
                    e.accepted = true;
                    st.evidence_added.push(e);
                    continue;
                }
            }
            st.evidence_added
                .push(Evidence::placeholder(layout.effects[c].label()));
        }
    }

    /// Phase 3, the forward loop with every check, from there (whatever is still missing;
    /// an effect the backward step removed is not offered again).
    fn forward_with_checks(&self, st: &mut ModelState) {
        let layout = &self.layout;
        for _ in 1..=self.config.max_iterations {
            let number = st.iterations.len() + 1;
            let candidates = self.candidates(st);
            let (mut evs, mut best) =
                self.evaluate(&st.model, &st.current, &st.current_post, &candidates, true);
            if let Some((bi, b_bic)) = best {
                if let Some(why) = self.forward_veto(&st.model, &evs, bi, b_bic) {
                    evs[bi].1.rejected_because = Some(why);
                    best = None;
                }
            }
            let Some((bi, _)) = best else {
                st.iterations.push(Iteration {
                    number,
                    added: None,
                    candidates: evs.into_iter().map(|e| e.1).collect(),
                });
                break;
            };
            let (c, _, big) = &mut evs[bi];
            let c = *c;
            let Some(big) = big.take() else { break };
            evs[bi].1.accepted = true;
            st.model.push(c);
            st.added.push(c);
            st.current_post = post_fit(self.set, layout, &big.expand(layout.total));
            st.current = big;
            st.evidence_added.push(evs[bi].1.clone());
            st.iterations.push(Iteration {
                number,
                added: Some(layout.effects[c].label()),
                candidates: evs.into_iter().map(|e| e.1).collect(),
            });
        }
    }

    /// A stronger explanation that failed only on halves or adequacy vetoes a weaker one on
    /// the same sensors: the structure is then not forced onto the weaker candidate. The
    /// reason the best candidate `evs[bi]` (ΔBIC `b_bic`) is vetoed, if it is.
    fn forward_veto(
        &self,
        model: &[usize],
        evs: &[Scored],
        bi: usize,
        b_bic: f64,
    ) -> Option<String> {
        let (layout, config) = (&self.layout, self.config);
        let chosen = &layout.effects[evs[bi].0];
        let chosen_sensors = sensors_of(chosen);
        let chosen_index = evs[bi].0;
        let veto = evs.iter().find(|(c, e, _)| {
            let other = &layout.effects[*c];
            let statistically_ok = e.p_holm < config.alpha && e.delta_bic > config.min_delta_bic;
            statistically_ok
                && e.rejected_because.is_some()
                && e.delta_bic > b_bic + config.min_delta_bic
                && !restricts(other, chosen)
                && (overlapping(&sensors_of(other), &chosen_sensors)
                    || self.adds_nothing_beyond(model, chosen_index, *c))
        });
        veto.map(|(_, v, _)| vetoed_by(v))
    }
}
