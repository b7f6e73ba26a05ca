//! # The gyro in the slews: asymmetry, scale against rate, and bias against rate mode (issue 22)
//!
//! **Why.** The bias history ([`super::gyro`]) sees the gyro only in the holds, at low rate
//! and nearly zero rotation. Errors that act only while the spacecraft turns — a scale that
//! differs with the sign of the rate, a scale that grows with the rate, a bias that is not the
//! same in the high-rate mode the slews run in — leave the holds untouched and go into
//! IRUCAL's δM (and so into the IRU table) unless the slews are analysed for them.
//!
//! **Data.** For every slew, the last usable attitude batch before it and the first after
//! give `z = rotvec(A_after (Φ A_before)ᵀ)`, Φ the calibrated gyro's rotation between them
//! with the reference bias (the hold bias history when a candidate was accepted there, else
//! the OBC's estimate at the slew's start). Its sensitivity `S` to small gyro errors follows
//! the Davenport/Keat transition recursion (algorithms.md §7), one row block per slew, with the
//! batch attitude variances, the angle random walk and the bias random walk over the interval
//! as its weights.
//!
//! **Model.** Baseline: δM on top of IRUCAL's (9) and a bias correction over the high-rate
//! frames (3: the slews' own bias against the reference). Each test adds one form per ACS axis
//! and is counted in the family's Bonferroni factor ([`SLEW_TESTS`]):
//!
//! | test | columns per axis `j` (per frame) | regressor | library |
//! |---|---|---|---|
//! | scale asymmetry | `−|Δθ_j|` (a channel reading `1 ± a` with the sign of the rate) | `slew_angle_abs` | yes: named, fitted |
//! | scale against rate | `Δθ_j |ω_j/ω_ref|^p`, `p` on [`POWERS`] (× their number) | `slew_rate` | no: unexplained |
//! | bias against rate mode | the baseline's high-rate bias minus the holds' bias, Wald test | `rate_mode` | no: unexplained |
//! | scale step | the δM diagonal from slew `k` on, `k` scanned (× the positions) | `time_s` | no: unexplained |
//!
//! The asymmetry and the rate forms are F tests of their columns (the noise scale of the
//! residuals when above the declared noise), with ΔBIC and interleaved halves (slews alternate
//! axes and signs). A constant scale is δM itself: the rate forms see only what changes with the
//! rate, so slews that all run at one rate cannot separate them and the test says nothing. The
//! bias test compares two independent estimates (slews against holds) with both covariances,
//! the hold side's prediction variance at each slew's time (conservatively not divided by the
//! number of slews: the holds' bias errors are correlated). Every test that is significant and
//! not named goes to the evidence ledger as unexplained ([`super::ledger`]), and the IRU table
//! is then written as flown ([`super::run`]).

use super::gyro_data::{batch_attitude, delta_bic, GyroAnalysis, GyroLeftover, SlewInput};
use super::search::Evidence;
use super::stats::{chi2_sf, f_sf};
use super::Detected;
use crate::pipeline::observations::SPLIT_KINDS;
use fsw_core::attitude::{rot, rotvec_from_rot};
use fsw_core::units::{ARCSEC_PER_RAD, DEG_PER_RAD, RAD_PER_ARCSEC, RAD_PER_DEG};
use nalgebra::{DMatrix, DVector, Matrix3, SMatrix, Vector3};
use std::collections::BTreeMap;

/// First bias column (arcsec/s over the high-rate frames).
const BIAS: usize = 0;
/// First δM column (ppm, column-major: `3 + 3c + j` multiplies `Δθ_c` into axis `j`).
const DM: usize = 3;
/// First asymmetry column (ppm).
const ASYM: usize = 12;
/// First scale-against-rate column (ppm at the reference rate): 3 per power.
const POW: usize = 15;
/// Powers of the rate tried by the scale-against-rate test.
pub const POWERS: [f64; 4] = [0.5, 1.0, 2.0, 3.0];
/// First scale-step column (ppm from the step on; filled per scanned position).
const STEP: usize = POW + 3 * POWERS.len();
/// First split-fraction column: the rate-mode switches split inside decimated frames, one
/// fraction per kind of switch as in calibrate's chain
/// ([`crate::pipeline::observations::GyroSplit`]); in the baseline when a
/// slew has a split frame.
const SPLIT: usize = STEP + 3;
/// Columns of the slew model.
const NCOL: usize = SPLIT + SPLIT_KINDS;
/// Tests of the slew family (asymmetry, scale against rate, bias against rate mode, scale
/// step): their Bonferroni factor.
pub const SLEW_TESTS: f64 = 4.0;
/// Fewest slews on each side of a scanned scale step.
const STEP_SIDE: usize = 3;
/// Fewest slews analysed.
const MIN_SLEWS: usize = 6;

/// One slew: the rotation residual between its end attitudes and its sensitivities.
struct SlewRow {
    /// Residual rotation (arcsec, ACS).
    z: Vector3<f64>,
    /// Sensitivity to the model's columns (arcsec per column unit).
    s: SMatrix<f64, 3, NCOL>,
    /// Variance per axis (arcsec²).
    var: Vector3<f64>,
    /// Gyro-measured rotation (rad, ACS).
    angle: Vector3<f64>,
    /// Reference bias minus the holds' bias at the slew (arcsec/s), and the holds' variance.
    ref_minus_hold: Option<(Vector3<f64>, Vector3<f64>)>,
    /// Median over its high-rate frames of the largest axis rate (rad/s): the slew's rate.
    rate_rad_per_s: f64,
}

/// Smallest ratio of the fastest to the slowest slew rate for the scale-against-rate forms:
/// with one commanded rate they differ from δM only in the ramps, where decimated frames mix
/// the two pulse weights (on six months of 30-s frames a "scale against rate" of 14 % came out
/// at p 3e-4 from the slews' edges).
const MIN_RATE_SPREAD: f64 = 1.5;

/// A least-squares fit of some columns over the rows.
struct SlewFit {
    chi2: f64,
    x: DVector<f64>,
    cov: DMatrix<f64>,
    /// Equations.
    m: usize,
}

/// Run the slew tests and add their results to `out`.
pub(super) fn analyse(inp: &SlewInput<'_>, out: &mut GyroAnalysis) {
    let pairs = slew_intervals(inp, out);
    let omega_ref = reference_rate(inp);
    let rows = slew_rows(inp, &pairs, omega_ref);
    out.slews = rows.len();
    if rows.len() < MIN_SLEWS {
        out.notes.push(format!(
            "slews: only {} intervals with > 5° of rotation between attitude batches (need {MIN_SLEWS})",
            rows.len()
        ));
        return;
    }
    let all = |_: usize| true;
    // The split fractions of the switches the slews hold are nuisance parameters, as in
    // calibrate's chain: a decimated frame that spans a switch mixes both pulse weights, and
    // its step at the middle of its envelope is off by a fraction shared by every switch of
    // one kind (on 30-s frames, ± hundreds of arcseconds at each slew start).
    let split_cols = (SPLIT..NCOL).filter(|&c| rows.iter().any(|r| r.s.column(c).amax() > 0.0));
    let base: Vec<usize> = (BIAS..ASYM).chain(split_cols).collect();
    let Some(fit0) = solve(&rows, &base, &all) else {
        out.notes.push("slews: singular slew geometry".into());
        return;
    };
    let rates: Vec<f64> = rows
        .iter()
        .map(|r| r.rate_rad_per_s)
        .filter(|w| *w > 0.0)
        .collect();
    let spread = rates.iter().copied().fold(0.0, f64::max)
        / rates.iter().copied().fold(f64::INFINITY, f64::min);
    let rates_differ = spread >= MIN_RATE_SPREAD;
    if !rates_differ {
        out.notes.push(format!(
            "slews: all at one rate (fastest / slowest {spread:.2} < {MIN_RATE_SPREAD}): a scale that changes with the rate is δM itself here and is not tested"
        ));
    }
    // 1. The scale asymmetry (library).
    let asym_cols: Vec<usize> = (ASYM..ASYM + 3).collect();
    let mut model = base.clone();
    if let Some((mut ev, fit1, s2)) = column_test(
        &rows,
        &model,
        &asym_cols,
        "gyro_scale_asymmetry[IRU]",
        1.0,
        inp,
    ) {
        if ev.accepted && rates_differ {
            if let Some(why) = aliased_with_rate(&rows, &model, &asym_cols) {
                ev.accepted = false;
                ev.rejected_because = Some(why);
            }
        }
        if ev.accepted {
            out.detected
                .push(detected_asymmetry(&ev, &fit1, s2, model.len()));
            model.extend(&asym_cols);
        } else {
            out.leftover.push(GyroLeftover {
                evidence: ev.clone(),
                regressor: "slew_angle_abs",
                size: (0..3)
                    .map(|j| fit1.x[model.len() + j].abs())
                    .fold(0.0, f64::max),
                unit: "ppm",
            });
        }
        out.candidates.push(ev);
    }
    // 2. A scale that changes with the rate (outside the library): the best power on the grid.
    if rates_differ {
        rate_power_test(&rows, &model, omega_ref, inp, out);
    }
    // 3. A scale that changed once (outside the library): the step's slew scanned.
    let mut rows = rows;
    scale_step_test(&mut rows, &model, inp, out);
    // 4. The slews' bias against the holds' (outside the library).
    let Some(fit) = solve(&rows, &model, &all) else {
        return;
    };
    rate_mode_bias_test(&rows, &fit, &model, out, inp);
    for r in &rows {
        let j = r.angle.iamax();
        let resid = |f: &SlewFit, cols: &[usize]| {
            r.z[j]
                - cols
                    .iter()
                    .enumerate()
                    .map(|(a, &c)| r.s[(j, c)] * f.x[a])
                    .sum::<f64>()
        };
        out.slew_residuals.push((
            r.angle[j] * DEG_PER_RAD,
            resid(&fit0, &base),
            resid(&fit, &model),
        ));
    }
}

/// How far (frames) from a slew its bracketing attitude batches may be, and never past the
/// neighbouring slews: where the hold between two slews has no usable batch (a tracker
/// occulted), the nearest batch is beyond the other slew, and an interval over both would
/// count that slew twice. The report says how many slews were left out and why (on the
/// simulator's 24-h plans, 30 of 48: holds without a usable batch on one side).
const SLEW_WINDOW_FRAMES: usize = 1200;

/// The slews (runs of high-rate frames), each bracketed by the last usable attitude batch
/// before its end and the first after its start: holds on both sides when there are (within
/// [`SLEW_WINDOW_FRAMES`] and not past the neighbouring slews), else the outermost batches
/// inside the slew; kept when the gyro turned by
/// more than 5° between them and no gyro increment between them is missing or long.
fn slew_intervals(inp: &SlewInput<'_>, out: &mut GyroAnalysis) -> Vec<(usize, usize)> {
    let frames = inp.input.frames;
    let set = inp.set;
    let slews =
        crate::pipeline::maneuvers::high_rate_runs(frames.iter().map(|f| f.high_rate), false);
    let usable: Vec<usize> = (0..set.batches.len())
        .filter(|&i| inp.att[i].is_some())
        .collect();
    // A telemetry gap inside a slew: the gyro increment across it is one counter difference
    // that may have wrapped (run_check's `gyro_increment_ambiguous`), so no pair spans one.
    let mut dts: Vec<f64> = frames
        .iter()
        .filter_map(|f| f.gyro)
        .map(|g| g.dt_s)
        .collect();
    dts.sort_by(f64::total_cmp);
    let median_dt = dts.get(dts.len() / 2).copied().unwrap_or(1.0);
    let gap_free = |a: usize, b: usize| {
        frames.get(a + 1..=b).is_some_and(|r| {
            r.iter()
                .all(|f| f.gyro.is_some_and(|g| g.dt_s <= 3.0 * median_dt))
        })
    };
    let mut pairs = Vec::new();
    // Why slews were not used, counted for the report: (no usable attitude batch around it,
    // less than 5° turned between the batches found, a gap in the gyro data).
    let (mut no_batch, mut small, mut gaps, mut switched) = (0usize, 0usize, 0usize, 0usize);
    for (k, &(s, e)) in slews.iter().enumerate() {
        // The holds around the slew, up to the neighbouring slews: an interval that spans
        // another slew would count that one twice.
        let prev_end = k
            .checked_sub(1)
            .and_then(|j| slews.get(j))
            .map_or(0, |p| p.1 + 1);
        let next_start = slews
            .get(k + 1)
            .map_or(usize::MAX, |n| n.0.saturating_sub(1));
        let lo = s.saturating_sub(SLEW_WINDOW_FRAMES).max(prev_end);
        let hi = (e + SLEW_WINDOW_FRAMES).min(next_start);
        let inside: Vec<usize> = usable
            .iter()
            .copied()
            .filter(|&i| set.batches[i].center >= lo && set.batches[i].center <= hi)
            .collect();
        let before = inside
            .iter()
            .copied()
            .rfind(|&i| set.batches[i].center <= s)
            .or_else(|| inside.first().copied());
        let after = inside
            .iter()
            .copied()
            .find(|&i| set.batches[i].center >= e)
            .or_else(|| inside.last().copied());
        let (Some(ia), Some(ib)) = (before, after) else {
            no_batch += 1;
            continue;
        };
        let (ca, cb) = (set.batches[ia].center, set.batches[ib].center);
        if cb <= ca {
            no_batch += 1;
            continue;
        }
        if !gap_free(ca, cb) {
            gaps += 1;
            out.notes.push(format!(
                "slew at frames {s}..{e} not used for the slew tests: frames without a gyro increment (missing, or a channel the integrator declared stuck) or a step longer than 3 cycles between its end attitudes"
            ));
            continue;
        }
        // Across the OBC's gyro triad switch the interval mixes two biases and two δM.
        if frames[ca + 1..=cb]
            .iter()
            .any(|f| f.iru_backup != frames[cb].iru_backup)
        {
            switched += 1;
            continue;
        }
        let turned: Vector3<f64> = frames[ca + 1..=cb]
            .iter()
            .filter_map(|f| f.gyro)
            .map(|g| g.dtheta_acs_rad)
            .sum();
        if turned.norm() > 5.0 * RAD_PER_DEG {
            pairs.push((ia, ib));
        } else {
            small += 1;
        }
    }
    if pairs.len() < slews.len() {
        out.notes.push(format!(
            "slews: {} of {} used for the slew tests; not used: {no_batch} without a usable attitude batch on both sides (within {SLEW_WINDOW_FRAMES} frames, not past the neighbouring slews), {small} with less than 5° turned between the batches around them (the batches fell inside the slew), {gaps} with a gap in the gyro data, {switched} across the OBC's gyro triad switch",
            pairs.len(),
            slews.len()
        ));
    }
    pairs
}

/// The reference rate of the scale-against-rate forms: the median over the high-rate frames
/// of the largest axis rate (rad/s), so that the parameters read as ppm at a typical slew rate.
fn reference_rate(inp: &SlewInput<'_>) -> f64 {
    let mut rates: Vec<f64> = inp
        .input
        .frames
        .iter()
        .filter(|f| f.high_rate)
        .filter_map(|f| f.gyro)
        .filter(|g| g.dt_s > 0.0)
        .map(|g| g.dtheta_acs_rad.amax() / g.dt_s)
        .filter(|w| *w > 0.0)
        .collect();
    rates.sort_by(f64::total_cmp);
    rates
        .get(rates.len() / 2)
        .copied()
        .unwrap_or(0.1 * RAD_PER_DEG)
}

/// The rows of the slew model, one per interval of `pairs`.
fn slew_rows(inp: &SlewInput<'_>, pairs: &[(usize, usize)], omega_ref: f64) -> Vec<SlewRow> {
    let frames = inp.input.frames;
    let mut rows = Vec::new();
    for &(ia, ib) in pairs {
        let (Some((ma, va)), Some((mb, vb))) =
            (batch_attitude(inp.att, ia), batch_attitude(inp.att, ib))
        else {
            continue;
        };
        let (ca, cb) = (inp.set.batches[ia].center, inp.set.batches[ib].center);
        let mid = (ca + cb) / 2;
        let hold = inp.hold_bias.and_then(|h| {
            Some((
                *h.bias_rad_per_s.get(mid)? + inp.b_ref,
                *h.var_arcsec2_per_s2.get(mid)?,
                h.modelled,
            ))
        });
        // With a bias history accepted, its value at the middle of the interval (exact for a
        // ramp); else the OBC's bias at the start.
        let bias = match hold {
            Some((b, _, true)) => b,
            _ => inp
                .input
                .bias_per_frame
                .as_ref()
                .and_then(|b| b.get(ca).copied())
                .unwrap_or(*inp.b_ref),
        };
        let ref_minus_hold = hold.map(|(b, v, _)| ((bias - b) * ARCSEC_PER_RAD, v));
        let mut phi_total = Matrix3::identity();
        let mut sm = SMatrix::<f64, 3, NCOL>::zeros();
        let mut angle = Vector3::zeros();
        let mut split_var_rad2 = 0.0;
        let mut rates: Vec<f64> = frames[ca + 1..=cb]
            .iter()
            .filter(|f| f.high_rate)
            .filter_map(|f| f.gyro)
            .filter(|g| g.dt_s > 0.0)
            .map(|g| g.dtheta_acs_rad.amax() / g.dt_s)
            .collect();
        rates.sort_by(f64::total_cmp);
        let rate_rad_per_s = rates.get(rates.len() / 2).copied().unwrap_or(0.0);
        for f in &frames[ca + 1..=cb] {
            let Some(g) = f.gyro else { continue };
            let dth = g.dtheta_acs_rad;
            let phi = (Matrix3::identity() + inp.input.delta_m(f)) * dth - bias * g.dt_s;
            let mut u = SMatrix::<f64, 3, NCOL>::zeros();
            for j in 0..3 {
                if f.high_rate {
                    u[(j, BIAS + j)] = -g.dt_s * RAD_PER_ARCSEC;
                }
                for c in 0..3 {
                    u[(j, DM + 3 * c + j)] = dth[c] * 1e-6;
                }
                u[(j, ASYM + j)] = -dth[j].abs() * 1e-6;
                let w = if g.dt_s > 0.0 {
                    (dth[j] / g.dt_s / omega_ref).abs()
                } else {
                    0.0
                };
                for (q, p) in POWERS.iter().enumerate() {
                    u[(j, POW + 3 * q + j)] = dth[j] * w.powf(*p) * 1e-6;
                }
            }
            if let Some(split) = f.split {
                u.set_column(SPLIT + split.kind(), &split.dir_rad);
                split_var_rad2 += split.var_rad2;
            }
            let r = rot(&phi);
            sm = r * sm + rot(&(phi * 0.5)) * u;
            phi_total = r * phi_total;
            angle += dth;
        }
        let z = rotvec_from_rot(&(mb * (phi_total * ma).transpose())) * ARCSEC_PER_RAD;
        let t = (cb - ca) as f64;
        let proc = (inp.cfg.arw_rad_per_sqrt_s * ARCSEC_PER_RAD).powi(2) * t
            + (inp.cfg.rrw_rad_per_s15 * ARCSEC_PER_RAD).powi(2) * t.powi(3) / 3.0
            + split_var_rad2 * ARCSEC_PER_RAD * ARCSEC_PER_RAD;
        rows.push(SlewRow {
            z,
            s: sm * ARCSEC_PER_RAD,
            var: va + vb + Vector3::repeat(proc),
            angle,
            ref_minus_hold,
            rate_rad_per_s,
        });
    }
    rows
}

/// Weighted least squares of `cols` over the rows `use_row` keeps.
fn solve(rows: &[SlewRow], cols: &[usize], use_row: &dyn Fn(usize) -> bool) -> Option<SlewFit> {
    let k = cols.len();
    let mut n = DMatrix::<f64>::zeros(k, k);
    let mut b = DVector::<f64>::zeros(k);
    let mut rr = 0.0;
    let mut m = 0;
    for (_, r) in rows.iter().enumerate().filter(|(ri, _)| use_row(*ri)) {
        for i in 0..3 {
            let w = 1.0 / r.var[i];
            m += 1;
            rr += w * r.z[i] * r.z[i];
            for (a, &ca) in cols.iter().enumerate() {
                b[a] += w * r.s[(i, ca)] * r.z[i];
                for (c, &cc) in cols.iter().enumerate() {
                    n[(a, c)] += w * r.s[(i, ca)] * r.s[(i, cc)];
                }
            }
        }
    }
    for a in 0..k {
        n[(a, a)] += 1e-12;
    }
    let ch = n.cholesky()?;
    let x = ch.solve(&b);
    let chi2 = (rr - x.dot(&b)).max(0.0);
    Some(SlewFit {
        chi2,
        x,
        cov: ch.inverse(),
        m,
    })
}

/// F test of `cand` added to `model`, with ΔBIC and interleaved halves; `scanned` multiplies
/// the p-value (a grid searched for the best form). Returns the evidence (accepted when every
/// check passes), the fit with the candidate (its columns last) and the noise scale.
fn column_test(
    rows: &[SlewRow],
    model: &[usize],
    cand: &[usize],
    name: &str,
    scanned: f64,
    inp: &SlewInput<'_>,
) -> Option<(Evidence, SlewFit, f64)> {
    let all = |_: usize| true;
    let c0 = solve(rows, model, &all)?.chi2;
    let cols: Vec<usize> = model.iter().chain(cand).copied().collect();
    let fit1 = solve(rows, &cols, &all)?;
    let k = cand.len();
    let dof = fit1.m as f64 - cols.len() as f64;
    let s2 = if dof > 0.0 {
        (fit1.chi2 / dof).max(1e-9)
    } else {
        1.0
    };
    let f = ((c0 - fit1.chi2) / k as f64) / s2.max(1.0);
    let p = if dof > 0.0 {
        (f_sf(f, k as f64, dof) * scanned).min(1.0)
    } else {
        1.0
    };
    let p_holm = (p * SLEW_TESTS).min(1.0);
    let dbic = delta_bic(c0, fit1.chi2, s2, fit1.m, k);
    // Halves: interleaved (slews alternate axes and signs, so consecutive halves would lose
    // observability).
    let (ha, hb) = (
        solve(rows, &cols, &|i| i % 2 == 0),
        solve(rows, &cols, &|i| i % 2 == 1),
    );
    let (mut hchi2, mut hp, mut hest) = (f64::NAN, 1.0, (Vec::new(), Vec::new()));
    let first = model.len();
    if let (Some(a), Some(b)) = (ha, hb) {
        hchi2 = (first..cols.len())
            .map(|j| (a.x[j] - b.x[j]).powi(2) / (a.cov[(j, j)] + b.cov[(j, j)]))
            .sum::<f64>();
        hp = chi2_sf(hchi2, k as f64);
        hest = (
            (first..cols.len()).map(|j| a.x[j]).collect(),
            (first..cols.len()).map(|j| b.x[j]).collect(),
        );
    }
    let alpha = inp.cfg.alpha;
    let mut why = Vec::new();
    if !(p_holm < alpha) {
        why.push(format!("LR p {p:.2e} (×{SLEW_TESTS} slew tests) ≥ {alpha}"));
    }
    if !(dbic > inp.cfg.min_delta_bic) {
        why.push(format!("ΔBIC {dbic:.1} ≤ {}", inp.cfg.min_delta_bic));
    }
    if !(hp > 0.0027) {
        why.push(format!("halves differ (χ² {hchi2:.1}, p {hp:.2e})"));
    }
    let ev = Evidence {
        p_holm,
        adequate: true,
        accepted: why.is_empty(),
        rejected_because: (!why.is_empty()).then(|| why.join("; ")),
        ..Evidence::likelihood_test(
            name.to_owned(),
            k,
            (c0 - fit1.chi2, f, p),
            dbic,
            (hchi2, hp, hest),
        )
    };
    Some((ev, fit1, s2))
}

/// Can the data tell the asymmetry from a scale that changes with the rate? When each axis is
/// slewed out at one rate and back at another (the writer's three-rate plan), `a |Δθ|` and
/// `k Δθ |ω|^p` are the same two numbers per axis and the asymmetry would be named for either.
/// The two forms have as many parameters, so they are compared by their χ² (a likelihood
/// ratio between non-nested models, in units of the asymmetry fit's noise scale): the
/// asymmetry is named only when it fits better than the best power by more than
/// [`SEPARATION_CHI2`]; otherwise the reason is returned and the name is withheld.
fn aliased_with_rate(rows: &[SlewRow], model: &[usize], asym_cols: &[usize]) -> Option<String> {
    let all = |_: usize| true;
    let (q, fit_pow) = (0..POWERS.len())
        .filter_map(|q| {
            let cols: Vec<usize> = model.iter().copied().chain(power_cols(q)).collect();
            Some((q, solve(rows, &cols, &all)?))
        })
        .min_by(|a, b| a.1.chi2.total_cmp(&b.1.chi2))?;
    let cols: Vec<usize> = model.iter().chain(asym_cols).copied().collect();
    let fit_asym = solve(rows, &cols, &all)?;
    let dof = fit_asym.m as f64 - cols.len() as f64;
    let s2 = if dof > 0.0 { fit_asym.chi2 / dof } else { 1.0 };
    let margin = (fit_pow.chi2 - fit_asym.chi2) / s2.max(1.0);
    (margin <= SEPARATION_CHI2).then(|| {
        format!(
            "not separable from a scale that changes with the rate (|ω|^{}): χ² {:.1} against the asymmetry's {:.1} (a margin of {margin:.1} ≤ {SEPARATION_CHI2} at noise scale {:.2}); the slews' rates and signs cannot tell them apart",
            POWERS[q],
            fit_pow.chi2,
            fit_asym.chi2,
            s2.max(1.0)
        )
    })
}

/// Smallest χ² margin by which a named slew form must fit better than its best unnamed
/// alternative with as many parameters (a likelihood ratio of e^4.5 ≈ 90).
const SEPARATION_CHI2: f64 = 9.0;

/// The columns of the scale-against-rate form with power `POWERS[q]`.
fn power_cols(q: usize) -> impl Iterator<Item = usize> {
    (0..3).map(move |j| POW + 3 * q + j)
}

/// The accepted asymmetry as a detected effect (its columns start at `first` in `fit`).
fn detected_asymmetry(ev: &Evidence, fit: &SlewFit, s2: f64, first: usize) -> Detected {
    let mut parameters = BTreeMap::new();
    let mut sigma = BTreeMap::new();
    let mut units = BTreeMap::new();
    for (ax, name) in ["x", "y", "z"].iter().enumerate() {
        let j = first + ax;
        parameters.insert((*name).to_owned(), fit.x[j]);
        sigma.insert((*name).to_owned(), (fit.cov[(j, j)] * s2.max(1.0)).sqrt());
        units.insert(
            (*name).to_owned(),
            "ppm (+: over-reads both ways)".to_owned(),
        );
    }
    Detected {
        effect: "gyro_scale_asymmetry".into(),
        sensor: "IRU".into(),
        parameters,
        sigma,
        units,
        evidence: ev.clone(),
        star_dirs: BTreeMap::new(),
    }
}

/// A scale error that grows with a power of the rate (outside the library): each power of
/// [`POWERS`] tried against `model`, the best by χ², its p-value × the grid size. Significant:
/// unexplained against `slew_rate`, its size the largest coefficient (ppm at `omega_ref`).
fn rate_power_test(
    rows: &[SlewRow],
    model: &[usize],
    omega_ref: f64,
    inp: &SlewInput<'_>,
    out: &mut GyroAnalysis,
) {
    let mut best: Option<(Evidence, SlewFit, f64)> = None;
    for q in 0..POWERS.len() {
        let cols: Vec<usize> = power_cols(q).collect();
        let Some((mut ev, fit, p)) = column_test(
            rows,
            model,
            &cols,
            "gyro_scale_vs_rate[IRU]",
            POWERS.len() as f64,
            inp,
        ) else {
            continue;
        };
        if best.as_ref().is_none_or(|b| ev.delta_chi2 > b.0.delta_chi2) {
            ev.effect = format!(
                "gyro_scale_vs_rate[IRU] (|ω/{:.3}°/s|^{p})",
                omega_ref * DEG_PER_RAD,
                p = POWERS[q]
            );
            best = Some((ev, fit, p));
        }
    }
    let Some((ev, fit, _)) = best else {
        return;
    };
    let size = largest_added(&fit, model);
    unexplained(
        out,
        ev,
        inp.cfg.alpha,
        "a scale that changes with the rate",
        ("slew_rate", size, "ppm at the reference rate"),
    );
}

/// A scale factor that changed once (outside the library): the δM diagonal from slew `k` on,
/// `k` scanned over the slews (at least [`STEP_SIDE`] on each side), the best by χ², its
/// p-value × the positions. The slews are in time order. Significant: unexplained against
/// `time_s`, its size the largest change (ppm).
fn scale_step_test(
    rows: &mut [SlewRow],
    model: &[usize],
    inp: &SlewInput<'_>,
    out: &mut GyroAnalysis,
) {
    let n = rows.len();
    if n < 2 * STEP_SIDE {
        return;
    }
    let positions = n + 1 - 2 * STEP_SIDE;
    let cols: Vec<usize> = (STEP..STEP + 3).collect();
    let fill = |rows: &mut [SlewRow], k: usize| {
        for (i, r) in rows.iter_mut().enumerate() {
            for j in 0..3 {
                for a in 0..3 {
                    r.s[(a, STEP + j)] = if i >= k { r.s[(a, DM + 4 * j)] } else { 0.0 };
                }
            }
        }
    };
    let mut best: Option<(usize, Evidence, SlewFit)> = None;
    for k in STEP_SIDE..=n - STEP_SIDE {
        fill(rows, k);
        let Some((ev, fit, _)) = column_test(
            rows,
            model,
            &cols,
            "gyro_scale_step[IRU]",
            positions as f64,
            inp,
        ) else {
            continue;
        };
        if best.as_ref().is_none_or(|b| ev.delta_chi2 > b.1.delta_chi2) {
            best = Some((k, ev, fit));
        }
    }
    let Some((k, mut ev, fit)) = best else {
        return;
    };
    fill(rows, k);
    ev.effect = format!("gyro_scale_step[IRU] (from slew {} of {n})", k + 1);
    // A step happens once: the interleaved halves do test it (both hold slews on each side),
    // but a failed halves check is not a reason to call it something else.
    let size = largest_added(&fit, model);
    unexplained(
        out,
        ev,
        inp.cfg.alpha,
        "a scale factor that changed once",
        ("time_s", size, "ppm"),
    );
}

/// The largest of the three columns a test added to `model` (ppm).
fn largest_added(fit: &SlewFit, model: &[usize]) -> f64 {
    (0..3)
        .map(|j| fit.x[model.len() + j].abs())
        .fold(0.0, f64::max)
}

/// A test outside the library reported as unexplained: never accepted; when it passed its
/// rules or is significant after the family's correction (`alpha`), the reason is that no
/// library effect has its signature (`what`); into the leftovers with its regressor, size
/// and unit, and into the candidates.
fn unexplained(
    out: &mut GyroAnalysis,
    mut ev: Evidence,
    alpha: f64,
    what: &str,
    (regressor, size, unit): (&'static str, f64, &'static str),
) {
    ev.accepted = false;
    if ev.rejected_because.is_none() || ev.p_holm < alpha {
        ev.rejected_because = Some(format!("no library effect has this signature: {what}"));
    }
    out.leftover.push(GyroLeftover {
        evidence: ev.clone(),
        regressor,
        size,
        unit,
    });
    out.candidates.push(ev);
}

/// The slews' bias (the baseline's high-rate bias correction on top of the reference)
/// against the holds' bias at the same times (outside the library): a Wald test with both
/// covariances, 3 dof. Significant: unexplained against `rate_mode`.
fn rate_mode_bias_test(
    rows: &[SlewRow],
    fit: &SlewFit,
    model: &[usize],
    out: &mut GyroAnalysis,
    inp: &SlewInput<'_>,
) {
    let diffs: Vec<(Vector3<f64>, Vector3<f64>)> =
        rows.iter().filter_map(|r| r.ref_minus_hold).collect();
    if diffs.len() != rows.len() || model[..3] != [BIAS, BIAS + 1, BIAS + 2] {
        return;
    }
    let n = diffs.len() as f64;
    let ref_minus_hold = diffs.iter().map(|d| d.0).sum::<Vector3<f64>>() / n;
    let hold_var = diffs.iter().map(|d| d.1).sum::<Vector3<f64>>() / n;
    let dof = fit.m as f64 - model.len() as f64;
    let s2 = if dof > 0.0 {
        (fit.chi2 / dof).max(1.0)
    } else {
        1.0
    };
    let d = Vector3::new(fit.x[0], fit.x[1], fit.x[2]) + ref_minus_hold;
    let c = Matrix3::from_fn(|i, j| fit.cov[(i, j)] * s2) + Matrix3::from_diagonal(&hold_var);
    let Some(ci) = c.try_inverse() else {
        return;
    };
    let chi2 = (d.transpose() * ci * d)[(0, 0)];
    let p = chi2_sf(chi2, 3.0);
    let p_holm = (p * SLEW_TESTS).min(1.0);
    let alpha = inp.cfg.alpha;
    let no_halves = (f64::NAN, f64::NAN, (Vec::new(), Vec::new()));
    let ev = Evidence {
        p_holm,
        adequate: true,
        rejected_because: Some(if p_holm < alpha {
            format!(
                "no library effect has this signature: the slews' bias differs from the holds' by [{:.4}, {:.4}, {:.4}] ± [{:.4}, {:.4}, {:.4}]″/s (Wald χ² {chi2:.1}, 3 dof)",
                d.x,
                d.y,
                d.z,
                c[(0, 0)].sqrt(),
                c[(1, 1)].sqrt(),
                c[(2, 2)].sqrt()
            )
        } else {
            format!("Wald p {p:.2e} (×{SLEW_TESTS} slew tests) ≥ {alpha}")
        }),
        ..Evidence::likelihood_test(
            "gyro_rate_mode_bias[IRU]".into(),
            3,
            (chi2, chi2 / 3.0, p),
            f64::NAN,
            no_halves,
        )
    };
    out.leftover.push(GyroLeftover {
        evidence: ev.clone(),
        regressor: "rate_mode",
        size: d.norm(),
        unit: "arcsec/s",
    });
    out.candidates.push(ev);
}
