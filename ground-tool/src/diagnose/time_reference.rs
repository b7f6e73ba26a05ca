//! # Time tags against the gyro: whole slews tied to the holds around them
//!
//! **Why.** The gyro's pulse counts define the time reference. A sensor whose samples are
//! older than their time tags by τ sees the attitude `ω τ` behind the gyro's while the body
//! turns and nothing in a hold. The joint fit ([`super::fit`]) gives every batch (≤ 20 s in a
//! slew) its own attitude and rate, so a shift common to all sensors is absorbed wherever the
//! rate is constant over a batch: the search determines only the differences between the
//! sensors' time tags, and with two tagged sensors it can put a common constant on the wrong
//! one (`combo.toml`), or miss a tag every sensor shares. Here the time tags are absolute.
//!
//! **Model.** A slew arc is a run of contiguous batches in which the body turns (some frame
//! faster than [`TURNING_RATE_ARCSEC_PER_S`]) plus the contiguous batch before and after it
//! (the holds that tie the slew to the stars). One reference attitude is carried through
//! the whole arc with the calibrated gyro, `A(k) = Rot(φ_k) A(k−1)`, and every measurement's
//! residual is taken against it (`r − P ε_k`, `ε_k` the rotation from its batch's reference
//! to the arc's, `P = J Mᵀ [b×]`). Its error is, per arc, 15 nuisance parameters:
//! `δθ_k = T_k δθ₀ + B_k δb + D_k δM` with `T_k = Rot(φ_k) T_{k−1}` (an initial error rotates
//! with the body), `B_k = Rot(φ_k) B_{k−1} + I Δt_k` (bias error) and
//! `D_k = Rot(φ_k) D_{k−1} + [e_i φ_{k,j}]` (a scale/misalignment error δM of this slew on
//! top of IRUCAL's: it grows with the angle turned and persists after the slew). The
//! time-tag columns are those of the library (`J Mᵀ (ω × b)` per ms), one per sensor and one
//! common to the tested sensors (those with ≥ [`MIN_TURNING_SAMPLES`] measurements in
//! turning frames; an untested sensor's rows stay out of it); everything else the search
//! found (alignments, effects) is applied at its estimate (the batch system already
//! determines it; a common shift of the time tags does not move it). An untested sensor keeps
//! the search's time tag.
//!
//! **Why it is observable.** `ω(t) τ` is zero in the holds and follows the rate profile in
//! between; the nuisance spans a constant (rotated), a bias ramp and `δM ∫ω`, which keeps
//! growing through the slew and stays after it. No combination of those is zero before and
//! after the slew and `∝ ω` in between.
//!
//! **Evidence** (the search's rules, [`super::search`]): forward, the candidate (a sensor's
//! τ, or τ common to the tested sensors) with the largest ΔBIC among those passing the
//! F test (Holm over the candidates of the step, `alpha`), ΔBIC > `min_delta_bic` and the
//! halves (alternate arcs: each half has slews about every axis in both directions) within
//! `halves_sigma`; then backward, an effect that no longer passes against the model without
//! it (p Bonferroni-corrected over the candidates) leaves, the weakest first, and is not
//! offered again. The common τ is one parameter where per-sensor ones are several, so a
//! shared delay is described by it (the sparsest model), and a single sensor's tag by that
//! sensor's. The absolute τ of each sensor (common + own) replaces the search's relative time
//! tags in the model, in the report and in the flight tables
//! (`corrections.time_offset_s[i]`; [`super::fit::solve_fixed`] estimates the rest of the
//! model conditionally on them).

use super::effects::EffectKind;
use super::fit::{batch_ranges, indices, post_fit, solve_fixed, Fixed, Layout, SubFit};
use super::measurements::{MeasurementSet, SENSOR_NAMES};
use super::search::{with_effect, Evidence, Iteration, SearchConfig, SearchResult};
use super::stats::{chi2_sf, f_sf, holm_adjust};
use fsw_core::attitude::{rot, rotvec_from_rot};
use fsw_core::units::ARCSEC_PER_RAD;
use nalgebra::{DMatrix, DVector, Matrix3, SMatrix};

/// A frame turns when the body rate exceeds this (arcsec/s; 0.0056°/s, 7 % of GRO's slew
/// rate): below it a 1-s time tag moves the attitude by less than the FHST noise.
pub const TURNING_RATE_ARCSEC_PER_S: f64 = 20.0;
/// Longest turning run of one arc (s): beyond it (a continuous rotation) the run is cut.
pub const MAX_ARC_S: f64 = 1800.0;
/// Hold data tied to each end of a slew (s): one hold batch's worth.
const HOLD_TIE_S: f64 = super::measurements::BATCH_HOLD_S;
/// Longest gyro step inside an arc (s), as the batches' own cut.
const MAX_STEP_S: f64 = 5.0;
/// Arc nuisance: initial attitude (3), bias (3), δM (9).
const N_ARC: usize = 15;
/// Time unit of the bias nuisance (s): arcsec per 100 s, as the batches' rate term.
const BIAS_UNIT_S: f64 = 100.0;
/// Unit of the δM nuisance (100 ppm).
const DM_UNIT: f64 = 1e-4;
/// Prior 1σ of the arc nuisance: 600″, 10″/100 s, 3000 ppm.
const PRIOR_SIGMA: [f64; 3] = [600.0, 10.0, 30.0];
/// Prior 1σ of a time tag (ms), as the library's.
const TAU_PRIOR_MS: f64 = 1000.0;
/// A sensor is a candidate with at least this many measurements in turning frames.
const MIN_TURNING_SAMPLES: usize = 50;
/// Time-tag columns: 0 = common to all sensors (made common to the tested ones before the
/// selection, [`ArcSystem::common_to`]), 1 + sensor.
const N_TAU: usize = 5;

/// A slew arc: batches `first..=last` of the measurement set.
#[derive(Clone, Copy, Debug)]
pub struct Arc {
    /// First batch.
    pub first: usize,
    /// Last batch (inclusive).
    pub last: usize,
}

/// Cut the batches into slew arcs (module doc).
#[must_use]
pub fn arcs(set: &MeasurementSet) -> Vec<Arc> {
    let turning_rad_per_s = TURNING_RATE_ARCSEC_PER_S / ARCSEC_PER_RAD;
    let nb = set.batches.len();
    let turns: Vec<bool> = set
        .batches
        .iter()
        .map(|b| (b.lo..b.hi).any(|k| set.frame_rate[k].norm() > turning_rad_per_s))
        .collect();
    // Batch i + 1 continues batch i: adjacent frames, gyro between them.
    let linked = |i: usize| {
        i + 1 < nb
            && set.batches[i].hi == set.batches[i + 1].lo
            && set.frame_gyro[set.batches[i + 1].lo].is_some_and(|(_, dt)| dt <= MAX_STEP_S)
    };
    let mut out = Vec::new();
    let mut i = 0;
    while i < nb {
        if !turns[i] {
            i += 1;
            continue;
        }
        let start = i;
        let t0 = set.batches[i].t_center_s;
        while linked(i) && turns[i + 1] && set.batches[i + 1].t_center_s - t0 < MAX_ARC_S {
            i += 1;
        }
        let last_turning = i;
        // The holds around it, at least HOLD_TIE_S of each (a batch cut at the mode change
        // can be a few frames long), none the previous arc took.
        let span = |a: usize, b: usize| {
            set.frame_time_s[set.batches[b].hi - 1] - set.frame_time_s[set.batches[a].lo]
        };
        let mut first = start;
        while first > 0
            && linked(first - 1)
            && !turns[first - 1]
            && out.last().is_none_or(|a: &Arc| a.last < first - 1)
            && (first == start || span(first, start - 1) < HOLD_TIE_S)
        {
            first -= 1;
        }
        let mut last = last_turning;
        while linked(last)
            && !turns[last + 1]
            && (last == last_turning || span(last_turning + 1, last) < HOLD_TIE_S)
        {
            last += 1;
        }
        out.push(Arc { first, last });
        i = last + 1;
    }
    out
}

/// The reduced normal equations of the time-tag columns over one arc (nuisance eliminated).
#[derive(Clone, Copy, Debug)]
struct ArcSystem {
    n: SMatrix<f64, N_TAU, N_TAU>,
    b: SMatrix<f64, N_TAU, 1>,
    chi2: f64,
    rows: usize,
    nuisance: usize,
    /// Measurements per sensor in turning frames (what tests a sensor's time tag).
    turning: [usize; 4],
}

impl ArcSystem {
    fn zeros() -> Self {
        Self {
            n: SMatrix::zeros(),
            b: SMatrix::zeros(),
            chi2: 0.0,
            rows: 0,
            nuisance: 0,
            turning: [0; 4],
        }
    }

    fn add(&mut self, o: &Self) {
        self.n += o.n;
        self.b += o.b;
        self.chi2 += o.chi2;
        self.rows += o.rows;
        self.nuisance += o.nuisance;
        for (t, n) in self.turning.iter_mut().zip(o.turning) {
            *t += n;
        }
    }

    /// Whether this system tests column `c` (0 = common to `tested`, 1 + sensor): at least
    /// [`MIN_TURNING_SAMPLES`] turning measurements of the sensor (of any tested sensor for
    /// the common column).
    fn tests(&self, c: usize, tested: &[usize]) -> bool {
        if c == 0 {
            tested
                .iter()
                .any(|&s| self.turning[s] >= MIN_TURNING_SAMPLES)
        } else {
            self.turning[c - 1] >= MIN_TURNING_SAMPLES
        }
    }

    /// The same system with the common column (0) made common to `tested` only: the sum of
    /// their own columns. Accumulated, it holds the rows of every sensor, so a sensor the arcs
    /// cannot test (too few samples in turning frames, no own column) would otherwise put its
    /// own time tag into the common τ, and the tested sensors' own columns would cancel it
    /// (false tags of ≈ 0 on them, the untested sensor's tag lost).
    fn common_to(&self, tested: &[usize]) -> Self {
        let mut w = SMatrix::<f64, N_TAU, N_TAU>::identity();
        w[(0, 0)] = 0.0;
        for &s in tested {
            w[(1 + s, 0)] = 1.0;
        }
        Self {
            n: w.transpose() * self.n * w,
            b: w.transpose() * self.b,
            ..*self
        }
    }
}

/// Accumulate one arc: residuals after the model `g` (time tags excluded) against the arc's
/// gyro-carried attitude. Also counts each sensor's measurements in turning frames.
fn accumulate_arc(
    set: &MeasurementSet,
    layout: &Layout,
    g: &DVector<f64>,
    arc: Arc,
    meas_of_batch: &[std::ops::Range<usize>],
) -> Option<ArcSystem> {
    let lo = set.batches[arc.first].lo;
    let hi = set.batches[arc.last].hi;
    let mut a = set.frame_attitude[lo]?;
    let mut t = Matrix3::<f64>::identity();
    let mut bm = Matrix3::<f64>::zeros();
    let mut d = SMatrix::<f64, 3, 9>::zeros();
    // Per frame: nuisance map L_k (3×15) and the offset ε_k (arcsec) of the batch reference.
    let mut frame_map = Vec::with_capacity(hi - lo);
    for k in lo..hi {
        if k > lo {
            let (phi, dt) = set.frame_gyro[k]?;
            let r = rot(&phi);
            a = r * a;
            t = r * t;
            bm = r * bm + Matrix3::identity() * (dt / BIAS_UNIT_S);
            d = r * d;
            for i in 0..3 {
                for j in 0..3 {
                    d[(i, 3 * i + j)] += phi[j] * DM_UNIT * ARCSEC_PER_RAD;
                }
            }
        }
        let eps = set.frame_attitude[k]
            .map(|ab| rotvec_from_rot(&(a * ab.transpose())) * ARCSEC_PER_RAD)?;
        let mut l = SMatrix::<f64, 3, N_ARC>::zeros();
        l.fixed_view_mut::<3, 3>(0, 0).copy_from(&t);
        l.fixed_view_mut::<3, 3>(0, 3).copy_from(&bm);
        l.fixed_view_mut::<3, 9>(0, 6).copy_from(&d);
        frame_map.push((l, eps));
    }
    let mut naa = SMatrix::<f64, N_ARC, N_ARC>::zeros();
    for j in 0..N_ARC {
        let s = PRIOR_SIGMA[usize::from(j >= 3) + usize::from(j >= 6)];
        naa[(j, j)] = 1.0 / (s * s);
    }
    let mut nag = SMatrix::<f64, N_ARC, N_TAU>::zeros();
    let mut na = SMatrix::<f64, N_ARC, 1>::zeros();
    let mut sys = ArcSystem::zeros();
    let (mut cols, mut scratch) = (Vec::new(), Vec::new());
    let turning_rad_per_s = TURNING_RATE_ARCSEC_PER_S / ARCSEC_PER_RAD;
    let mut turning = [0usize; 4];
    for bi in arc.first..=arc.last {
        for m in set.meas[meas_of_batch[bi].clone()]
            .iter()
            .filter(|m| !m.outlier)
        {
            let (l, eps) = &frame_map[m.frame - lo];
            let p = MeasurementSet::attitude_partial(m);
            let arow = p * l;
            let shift = p * eps;
            layout.row_columns(m, &mut cols, &mut scratch);
            let mut y = [m.r[0] - shift.x, m.r[1] - shift.y];
            for &(c, v) in &cols {
                y[0] -= v[0] * g[c];
                y[1] -= v[1] * g[c];
            }
            let tau = m.jm * m.rate_acs.cross(&m.b_acs) * (ARCSEC_PER_RAD * 1e-3);
            let w = 1.0 / (m.sigma * m.sigma);
            // A non-finite number anywhere would poison the arc's sums (and `max(0.0)` of a
            // NaN χ² is 0): such a measurement is left out.
            if !(w.is_finite()
                && y.iter().all(|v| v.is_finite())
                && arow.iter().all(|v| v.is_finite())
                && tau.iter().all(|v| v.is_finite()))
            {
                continue;
            }
            if m.rate_acs.norm() > turning_rad_per_s {
                turning[m.sensor] += 1;
            }
            for ax in 0..2 {
                let ar = arow.row(ax).transpose();
                let mut gr = SMatrix::<f64, N_TAU, 1>::zeros();
                gr[0] = tau[ax];
                gr[1 + m.sensor] = tau[ax];
                naa += ar * ar.transpose() * w;
                nag += ar * gr.transpose() * w;
                na += ar * (w * y[ax]);
                sys.n += gr * gr.transpose() * w;
                sys.b += gr * (w * y[ax]);
                sys.chi2 += w * y[ax] * y[ax];
                sys.rows += 1;
            }
        }
    }
    if sys.rows == 0 {
        return None;
    }
    let inv = naa.cholesky()?.inverse();
    let s = inv * nag;
    sys.n -= nag.transpose() * s;
    sys.b -= s.transpose() * na;
    sys.chi2 -= (na.transpose() * inv * na)[(0, 0)];
    sys.chi2 = sys.chi2.max(0.0);
    sys.nuisance = N_ARC;
    sys.turning = turning;
    Some(sys)
}

/// A sub-model: the time-tag columns `cols` fitted.
struct Sub {
    x: DVector<f64>,
    cov: DMatrix<f64>,
    chi2: f64,
    dof: f64,
}

impl Sub {
    fn s2(&self) -> f64 {
        if self.dof > 0.0 {
            (self.chi2 / self.dof).max(1e-6)
        } else {
            1.0
        }
    }
}

fn solve(sys: &ArcSystem, cols: &[usize]) -> Option<Sub> {
    let k = cols.len();
    let n = sys.n.select_rows(cols).select_columns(cols);
    let b = sys.b.select_rows(cols);
    let mut np = n.clone();
    for i in 0..k {
        np[(i, i)] += 1.0 / (TAU_PRIOR_MS * TAU_PRIOR_MS);
    }
    let chol = np.cholesky()?;
    let x = chol.solve(&b);
    let chi2 = (sys.chi2 - 2.0 * x.dot(&b) + x.dot(&(&n * &x))).max(0.0);
    Some(Sub {
        cov: chol.inverse(),
        x,
        chi2,
        dof: sys.rows as f64 - sys.nuisance as f64 - k as f64,
    })
}

/// The scatter of a column's estimate between the arcs that test it, against its stated σ:
/// `max(1, χ²/(K − 1))` of the K single-arc estimates of column `with[k]` about `x` (the
/// Birge ratio; 1 with fewer than two arcs). The arcs are the replications of the
/// experiment: an effect the model lacks (an alignment step, a gyro ramp) moves each slew's
/// time tag by more than its noise σ, and the halves and the reported σ must say so (FSS1
/// 200 ms with an FHST1 step and a gyro ramp: single-arc estimates 164–211 ms at σ 2–7 ms,
/// ratio ≈ 6; with σ from the noise alone the halves "differed" at 9 ms and the tag was lost).
fn scatter_ratio(
    arcs: &[ArcSystem],
    tested: &[usize],
    with: &[usize],
    k: usize,
    x: f64,
) -> (f64, usize) {
    let Some(&c) = with.get(k) else {
        return (1.0, 0);
    };
    let (mut chi2, mut n) = (0.0, 0usize);
    for a in arcs.iter().filter(|a| a.tests(c, tested)) {
        let Some(f) = solve(a, with) else { continue };
        let v = f.cov[(k, k)] * f.s2().max(1.0);
        if v > 0.0 && v.is_finite() && f.x[k].is_finite() {
            chi2 += (f.x[k] - x).powi(2) / v;
            n += 1;
        }
    }
    if n < 2 {
        (1.0, n)
    } else {
        ((chi2 / (n - 1) as f64).max(1.0), n)
    }
}

/// Evidence of column `c` against `model` (F test, ΔBIC, halves); `None` when a fit is
/// singular or no degrees of freedom are left.
fn evaluate(
    full: &ArcSystem,
    halves: Option<[&ArcSystem; 2]>,
    scatter: &dyn Fn(&[usize], usize, f64) -> (f64, usize),
    alpha: f64,
    model: &[usize],
    c: usize,
) -> Option<Evidence> {
    let small = solve(full, model)?;
    let with = with_effect(model, c);
    let big = solve(full, &with)?;
    // No degrees of freedom left (arcs with fewer equations than their nuisance): no
    // test (the F tail of d2 ≤ 0 is 0, a "detection" of anything).
    if !(big.dof >= 1.0) {
        return None;
    }
    let dchi2 = small.chi2 - big.chi2;
    let f = dchi2 / big.s2();
    let p = f_sf(f, 1.0, big.dof);
    let n_rows = full.rows as f64;
    let dbic = n_rows * (small.chi2 / big.chi2.max(1e-9)).ln() - n_rows.ln();
    let k = with.len() - 1;
    // The column must stand out against the scatter between the arcs (a random-effects
    // test: its σ inflated by the scatter ratio): a tag that one arc shows and the others do
    // not is not a delay of the sensor, however strong its likelihood ratio. (A Student t
    // with K − 1 dof would reject a 100 ms tag seen in two arcs at 80 and 86 ± 4 ms.)
    let (ratio, _) = scatter(&with, k, big.x[k]);
    let z2 = big.x[k].powi(2) / (big.cov[(k, k)] * big.s2().max(1.0) * ratio);
    let p_re = chi2_sf(z2, 1.0);
    let (mut hchi2, mut hp, mut est) = (f64::NAN, 0.0, (Vec::new(), Vec::new()));
    if let Some((a, b)) =
        halves.and_then(|[first, second]| Some((solve(first, &with)?, solve(second, &with)?)))
    {
        let va = a.cov[(k, k)] * a.s2().max(1.0) * ratio;
        let vb = b.cov[(k, k)] * b.s2().max(1.0) * ratio;
        hchi2 = (a.x[k] - b.x[k]).powi(2) / (va + vb);
        hp = chi2_sf(hchi2, 1.0);
        est = (vec![a.x[k]], vec![b.x[k]]);
    }
    Some(Evidence {
        adequate: p_re < alpha,
        ..Evidence::likelihood_test(column_label(c), 1, (dchi2, f, p), dbic, (hchi2, hp, est))
    })
}

fn column_label(c: usize) -> String {
    if c == 0 {
        "time_tag_offset[all] (slew arcs, against the gyro)".to_owned()
    } else {
        format!(
            "time_tag_offset[{}] (slew arcs, against the gyro)",
            SENSOR_NAMES[c - 1]
        )
    }
}

/// The time tags the slew arcs determine.
#[derive(Clone, Debug)]
pub struct TimeReference {
    /// Arcs used.
    pub arcs: usize,
    /// Passes of the arcs against the re-estimated model ([`resolve`]).
    pub passes: usize,
    /// Scalar equations in them.
    pub rows: usize,
    /// Columns kept (0 = common to the tested sensors, 1 + sensor).
    pub model: Vec<usize>,
    /// The sensors the arcs test (at least [`MIN_TURNING_SAMPLES`] measurements in turning
    /// frames); the others keep the search's time tags ([`apply`]).
    pub tested: [bool; 4],
    /// Absolute time tag per sensor (ms, 1σ): common + own; `None` = not in the model.
    pub tau_ms: [Option<(f64, f64)>; 4],
    /// Evidence of what each sensor's time tag rests on (the common column's for a shared
    /// delay).
    pub evidence: [Option<Evidence>; 4],
    /// The selection, step by step.
    pub iterations: Vec<Iteration>,
    /// Every offered column left out of the final model, tested against it (p Holm-adjusted
    /// over them): the evidence ledger ([`super::ledger`]) reports a significant one as
    /// unexplained with the reason it was not kept (one arc only, halves, scatter, BIC).
    pub leftover: Vec<ArcLeftover>,
}

/// A time-tag column the arcs did not keep, tested against the final arc model.
#[derive(Clone, Debug)]
pub struct ArcLeftover {
    /// Column (0 = common to the tested sensors, 1 + sensor).
    pub column: usize,
    /// Its evidence (`p_holm`: the larger of the LR p and the p of the estimate against the
    /// scatter between the arcs, each Holm-adjusted over the left-over columns;
    /// `rejected_because` from the selection's rules).
    pub evidence: Evidence,
    /// Its estimate and 1σ (ms) against the final model.
    pub tau_ms: (f64, f64),
    /// Arcs that test it.
    pub arcs: usize,
}

impl ArcLeftover {
    /// The column's sensor name (`all` for the common column).
    #[must_use]
    pub fn sensor(&self) -> &'static str {
        match self.column {
            0 => "all",
            c => SENSOR_NAMES[c - 1],
        }
    }
}

/// Passes of the arcs against a model re-estimated with their time tags (see [`resolve`]).
const MAX_PASSES: usize = 4;

/// Determine the absolute time tags from the slew arcs. `None` when the run has fewer than
/// two arcs with data.
///
/// The arcs apply the rest of the model at its estimate, and the search estimated it without
/// the absolute time tags: an FHST's alignment fitted while its slew samples carried an
/// unmodelled 29″ shift is off, and the arcs then read part of that as time tag (a 50-min
/// run with one FHST1 slew: 86 ± 4 ms for 100). So the arcs are run again against the model
/// re-estimated with their time tags fixed ([`apply`]'s conditional fit), until the time
/// tags and the selection stop changing (≤ [`MAX_PASSES`] passes; the selection of the
/// last pass is reported).
#[must_use]
pub fn resolve(
    set: &MeasurementSet,
    res: &SearchResult,
    config: &SearchConfig,
) -> Option<TimeReference> {
    let layout = &res.layout;
    let meas_of_batch = batch_ranges(set);
    let arcs = arcs(set);
    let debug = std::env::var_os("DIAGNOSE_DEBUG").is_some();
    if debug {
        for a in &arcs {
            let (b0, b1) = (&set.batches[a.first], &set.batches[a.last]);
            crate::note!(
                "arc: batches {}..={} t {:.0}..{:.0} s, usable {}",
                a.first,
                a.last,
                b0.t_center_s,
                b1.t_center_s,
                (a.first..=a.last)
                    .filter(|&b| set.batches[b].usable)
                    .count()
            );
        }
    }
    let mut fit = res.final_fit.clone();
    let mut last: Option<TimeReference> = None;
    for pass in 1..=MAX_PASSES {
        let mut g = fit.expand(layout.total);
        for (i, e) in layout.effects.iter().enumerate() {
            if e.kind == EffectKind::TimeTagOffset {
                for j in layout.range(i) {
                    g[j] = 0.0;
                }
            }
        }
        let systems: Vec<ArcSystem> = arcs
            .iter()
            .filter_map(|&a| accumulate_arc(set, layout, &g, a, &meas_of_batch))
            .collect();
        let mut tr = select(&systems, config, debug)?;
        tr.passes = pass;
        let converged = last.as_ref().is_some_and(|l| {
            l.model == tr.model
                && l.tau_ms.iter().zip(&tr.tau_ms).all(|(a, b)| match (a, b) {
                    (Some((xa, _)), Some((xb, sb))) => (xa - xb).abs() <= 0.05 * sb,
                    (None, None) => true,
                    _ => false,
                })
        });
        if debug {
            crate::note!("arcs pass {pass}: model {:?}, τ {:?}", tr.model, tr.tau_ms);
        }
        if converged || pass == MAX_PASSES {
            return Some(tr);
        }
        let Some(next) = conditional_fit(res, &tr).map(|m| m.fit) else {
            return Some(tr);
        };
        fit = next;
        last = Some(tr);
    }
    last
}

/// What the stages of [`select`] share: the arcs' systems reduced to the sensors with enough
/// turning samples, their sum, each column's halves, the columns offered and the settings.
struct Selection<'a> {
    reduced: Vec<ArcSystem>,
    sensors: Vec<usize>,
    full: ArcSystem,
    halves: Vec<Option<[ArcSystem; 2]>>,
    offered: Vec<usize>,
    config: &'a SearchConfig,
    halves_p_min: f64,
}

/// The columns as the selection changes them, and the record of its iterations.
#[derive(Default)]
struct ColumnState {
    model: Vec<usize>,
    excluded: Vec<usize>,
    kept: Vec<Evidence>,
    iterations: Vec<Iteration>,
}

/// Prints each arc's own estimate of the time tags (`DIAGNOSE_DEBUG`).
fn debug_arcs(reduced: &[ArcSystem], sensors: &[usize]) {
    for (k, s) in reduced.iter().enumerate() {
        let cols: Vec<usize> = sensors.iter().map(|c| c + 1).collect();
        let per: Vec<String> = match solve(s, &cols) {
            Some(f) => sensors
                .iter()
                .enumerate()
                .map(|(i, &c)| {
                    format!(
                        "{} {:.1} ± {:.1}",
                        SENSOR_NAMES[c],
                        f.x[i],
                        (f.cov[(i, i)] * f.s2().max(1.0)).sqrt()
                    )
                })
                .collect(),
            None => vec!["singular".to_owned()],
        };
        crate::note!(
            "arc {k}: rows {}, turning {:?}: {}",
            s.rows,
            s.turning,
            per.join(", ")
        );
    }
}

impl<'a> Selection<'a> {
    /// The sensors with enough turning samples, the arcs reduced to them and summed, the
    /// halves per column and the columns offered; `None` with fewer than two arcs or no
    /// column to offer.
    fn new(systems: &[ArcSystem], config: &'a SearchConfig, debug: bool) -> Option<Self> {
        let mut turning = [0usize; 4];
        for s in systems {
            for (t, n) in turning.iter_mut().zip(s.turning) {
                *t += n;
            }
        }
        if debug {
            crate::note!(
                "arcs with data {}; turning samples {turning:?}",
                systems.len()
            );
        }
        if systems.len() < 2 {
            return None;
        }
        let sensors: Vec<usize> = (0..4)
            .filter(|&s| turning[s] >= MIN_TURNING_SAMPLES)
            .collect();
        let reduced: Vec<ArcSystem> = systems.iter().map(|s| s.common_to(&sensors)).collect();
        let mut full = ArcSystem::zeros();
        for s in &reduced {
            full.add(s);
        }
        if debug {
            debug_arcs(&reduced, &sensors);
        }
        // Halves per column: alternate arcs among those that test it. Alternate arcs of the
        // whole run would leave a sensor seen only in every other slew (an FHST that sees
        // stars in the x and z slews but not in the y slew between them) with one empty
        // half, whose estimate is the prior's 0 ± 1 s: a test that always passes. A column
        // tested in one arc only has no halves and is not kept: one slew cannot show that a
        // delay repeats.
        let halves: Vec<Option<[ArcSystem; 2]>> = (0..N_TAU)
            .map(|c| {
                let with: Vec<&ArcSystem> =
                    reduced.iter().filter(|s| s.tests(c, &sensors)).collect();
                (with.len() >= 2).then(|| {
                    let mut h = [ArcSystem::zeros(), ArcSystem::zeros()];
                    for (k, s) in with.iter().enumerate() {
                        h[k % 2].add(s);
                    }
                    h
                })
            })
            .collect();
        let mut offered: Vec<usize> = sensors.iter().map(|s| s + 1).collect();
        if sensors.len() >= 2 {
            offered.insert(0, 0);
        }
        if offered.is_empty() {
            return None;
        }
        Some(Self {
            reduced,
            sensors,
            full,
            halves,
            offered,
            config,
            halves_p_min: chi2_sf(config.halves_sigma * config.halves_sigma, 1.0),
        })
    }

    /// The scatter ratio of column `k` of the model `with` at estimate `x` between the arcs.
    fn scatter(&self, with: &[usize], k: usize, x: f64) -> (f64, usize) {
        scatter_ratio(&self.reduced, &self.sensors, with, k, x)
    }

    /// Evidence of column `c` against `model`.
    fn evaluate(&self, model: &[usize], c: usize) -> Option<Evidence> {
        let h = self
            .halves
            .get(c)
            .and_then(Option::as_ref)
            .map(|[a, b]| [a, b]);
        evaluate(
            &self.full,
            h,
            &|with: &[usize], k: usize, x: f64| self.scatter(with, k, x),
            self.config.alpha,
            model,
            c,
        )
    }

    /// Why column evidence `e` (LR p adjusted `p_adjusted`) is not kept, if it is not.
    fn why_not(&self, e: &Evidence, p_adjusted: f64) -> Option<String> {
        let config = self.config;
        let mut why = Vec::new();
        if !(p_adjusted < config.alpha) {
            why.push(format!(
                "LR p (adjusted) {p_adjusted:.2e} ≥ {}",
                config.alpha
            ));
        }
        if !(e.delta_bic > config.min_delta_bic) {
            why.push(format!(
                "ΔBIC {:.1} ≤ {}",
                e.delta_bic, config.min_delta_bic
            ));
        }
        if !e.adequate {
            why.push("not above the scatter between the arcs".to_owned());
        }
        if e.halves_estimates.0.is_empty() {
            why.push("no halves: fewer than two arcs test it".to_owned());
        } else if !(e.halves_p > self.halves_p_min) {
            why.push(format!(
                "halves differ (χ² {:.1}, p {:.2e})",
                e.halves_chi2, e.halves_p
            ));
        }
        (!why.is_empty()).then(|| why.join("; "))
    }

    /// Forward: adds, by ΔBIC, the passing column (p Holm-adjusted over the candidates)
    /// until none passes.
    fn forward(&self, st: &mut ColumnState) {
        loop {
            let cands: Vec<usize> = self
                .offered
                .iter()
                .copied()
                .filter(|c| !st.model.contains(c) && !st.excluded.contains(c))
                .collect();
            let mut evs: Vec<(usize, Evidence)> = cands
                .iter()
                .filter_map(|&c| self.evaluate(&st.model, c).map(|e| (c, e)))
                .collect();
            if evs.is_empty() {
                break;
            }
            let adj = holm_adjust(&evs.iter().map(|e| e.1.p_value).collect::<Vec<_>>());
            let mut best: Option<(usize, f64)> = None;
            for (i, ((_, e), a)) in evs.iter_mut().zip(adj).enumerate() {
                e.p_holm = a;
                e.rejected_because = self.why_not(e, a);
                if e.rejected_because.is_none() && best.is_none_or(|(_, b)| e.delta_bic > b) {
                    best = Some((i, e.delta_bic));
                }
            }
            let Some((bi, _)) = best else {
                st.iterations.push(Iteration {
                    number: 0,
                    added: None,
                    candidates: evs.into_iter().map(|e| e.1).collect(),
                });
                break;
            };
            evs[bi].1.accepted = true;
            let c = evs[bi].0;
            st.model.push(c);
            st.kept.push(evs[bi].1.clone());
            st.iterations.push(Iteration {
                number: 0,
                added: Some(column_label(c)),
                candidates: evs.into_iter().map(|e| e.1).collect(),
            });
        }
    }

    /// Backward: the weakest column that fails against the model without it (p Bonferroni
    /// over the columns offered) leaves and is excluded; the evidence of those that pass is
    /// renewed. False when none fails.
    fn backward(&self, st: &mut ColumnState) -> bool {
        let n_offered = self.offered.len() as f64;
        let mut worst: Option<(usize, Evidence)> = None;
        for (k, &c) in st.model.iter().enumerate() {
            let without: Vec<usize> = st.model.iter().copied().filter(|&x| x != c).collect();
            let Some(mut e) = self.evaluate(&without, c) else {
                continue;
            };
            let p_adj = (e.p_value * n_offered).min(1.0);
            e.p_holm = p_adj;
            e.rejected_because = self.why_not(&e, p_adj);
            if e.rejected_because.is_some()
                && worst
                    .as_ref()
                    .is_none_or(|(_, w)| e.delta_bic < w.delta_bic)
            {
                worst = Some((k, e));
            } else if e.rejected_because.is_none() {
                e.accepted = true;
                st.kept[k] = e;
            }
        }
        let Some((k, e)) = worst else { return false };
        let c = st.model.remove(k);
        st.kept.remove(k);
        st.excluded.push(c);
        st.iterations.push(Iteration {
            number: 0,
            added: Some(format!(
                "removed {} (backward: {})",
                column_label(c),
                e.rejected_because.clone().unwrap_or_default()
            )),
            candidates: vec![e],
        });
        true
    }

    /// The offered columns left out of `model`, each tested against it ([`leftover_columns`]).
    fn leftover(&self, model: &[usize]) -> Vec<ArcLeftover> {
        leftover_columns(
            &self.offered,
            model,
            &self.reduced,
            &self.sensors,
            &|c| {
                self.evaluate(model, c).map(|mut e| {
                    e.rejected_because = self.why_not(&e, 0.0);
                    e
                })
            },
            &|c| {
                let with = with_effect(model, c);
                let k = model.len();
                let f = solve(&self.full, &with)?;
                let ratio = self.scatter(&with, k, f.x[k]).0;
                Some((f.x[k], (f.cov[(k, k)] * f.s2().max(1.0) * ratio).sqrt()))
            },
        )
    }

    /// Each tested sensor's time tag (ms, σ scaled by the scatter between the arcs) from the
    /// common and its own column of `fit`, and its evidence (its own column's when it has
    /// one).
    fn per_sensor(&self, fit: &Sub, model: &[usize], kept: &[Evidence]) -> TimeTags {
        let scale = fit.s2().max(1.0);
        let ratio: Vec<f64> = (0..model.len())
            .map(|k| self.scatter(model, k, fit.x[k]).0)
            .collect();
        let mut tau_ms = [None; 4];
        let mut evidence: [Option<Evidence>; 4] = Default::default();
        let common = model.iter().position(|&c| c == 0);
        for &s in &self.sensors {
            let own = model.iter().position(|&c| c == s + 1);
            if common.is_none() && own.is_none() {
                continue;
            }
            let (mut x, mut v) = (0.0, 0.0);
            for a in [common, own].into_iter().flatten() {
                x += fit.x[a];
                for b in [common, own].into_iter().flatten() {
                    v += fit.cov[(a, b)] * (ratio[a] * ratio[b]).sqrt();
                }
            }
            tau_ms[s] = Some((x, (v * scale).sqrt()));
            // A sensor's own deviation is the more specific evidence when it has one.
            evidence[s] = own.or(common).map(|a| kept[a].clone());
        }
        (tau_ms, evidence)
    }
}

/// Per sensor: the time tag (ms, σ) and the evidence for it.
type TimeTags = ([Option<(f64, f64)>; 4], [Option<Evidence>; 4]);

/// The selection of time-tag columns over the arcs' systems (module doc, **Evidence**).
fn select(systems: &[ArcSystem], config: &SearchConfig, debug: bool) -> Option<TimeReference> {
    // 1. The columns offered and what their tests share.
    let sel = Selection::new(systems, config, debug)?;
    // 2. Forward, then backward, until no column fails (at most 2 N_TAU rounds).
    let mut st = ColumnState::default();
    for _ in 0..2 * N_TAU {
        sel.forward(&mut st);
        if !sel.backward(&mut st) {
            break;
        }
    }
    // 3. The fit of the model kept, finite, and the columns left out.
    let fit = solve(&sel.full, &st.model)?;
    if !(fit.x.iter().chain(fit.cov.iter()).all(|v| v.is_finite()) && fit.chi2.is_finite()) {
        return None;
    }
    let leftover = sel.leftover(&st.model);
    // 4. Each sensor's time tag and evidence.
    let (tau_ms, evidence) = sel.per_sensor(&fit, &st.model, &st.kept);
    Some(TimeReference {
        arcs: systems.len(),
        passes: 1,
        rows: sel.full.rows,
        tested: std::array::from_fn(|s| sel.sensors.contains(&s)),
        model: st.model,
        tau_ms,
        evidence,
        iterations: st.iterations,
        leftover,
    })
}

/// The offered columns not in `model`, each tested against it, p Holm-adjusted over them;
/// `rejected_because` holds the selection's other reasons (`why_not` at p = 0), or the
/// multiplicity alone.
fn leftover_columns(
    offered: &[usize],
    model: &[usize],
    reduced: &[ArcSystem],
    sensors: &[usize],
    evaluate: &dyn Fn(usize) -> Option<Evidence>,
    estimate: &dyn Fn(usize) -> Option<(f64, f64)>,
) -> Vec<ArcLeftover> {
    let mut out: Vec<ArcLeftover> = offered
        .iter()
        .copied()
        .filter(|c| !model.contains(c))
        .filter_map(|c| {
            Some(ArcLeftover {
                column: c,
                evidence: evaluate(c)?,
                tau_ms: estimate(c)?,
                arcs: reduced.iter().filter(|s| s.tests(c, sensors)).count(),
            })
        })
        .collect();
    // The column's significance is that of both of the selection's tests: the likelihood
    // ratio, and the estimate against the scatter between the arcs that test it (its σ
    // inflated by the Birge ratio: the arcs are the replications, and an LR beyond the noise
    // that the arcs do not repeat is not a delay; 43 ± 28 ms at LR p 7e-4 on a catalog
    // run). One arc has no scatter: its σ is the noise's.
    let lr = holm_adjust(&out.iter().map(|l| l.evidence.p_value).collect::<Vec<_>>());
    let re = holm_adjust(
        &out.iter()
            .map(|l| chi2_sf((l.tau_ms.0 / l.tau_ms.1).powi(2), 1.0))
            .collect::<Vec<_>>(),
    );
    for ((l, a), b) in out.iter_mut().zip(lr).zip(re) {
        l.evidence.p_holm = a.max(b);
    }
    out
}

/// The search's model with the arcs' time tags in place of its own: what [`apply`] reports
/// and what [`resolve`]'s next pass applies.
struct ArcModel {
    /// Effects added to the baseline (the arcs' time tags included).
    added: Vec<usize>,
    /// Their evidence.
    evidence: Vec<Evidence>,
    /// The arcs' time tags, fixed.
    fixed: Vec<Fixed>,
    /// One line per time tag.
    summary: Vec<String>,
    /// The rest of the model estimated conditionally on them.
    fit: SubFit,
}

fn conditional_fit(res: &SearchResult, tr: &TimeReference) -> Option<ArcModel> {
    // The arcs decide the time tags of the sensors they test.
    let decided = |i: usize| {
        let e = &res.layout.effects[i];
        e.kind == EffectKind::TimeTagOffset && e.sensor.is_some_and(|s| tr.tested[s])
    };
    let mut added = Vec::new();
    let mut evidence = Vec::new();
    let mut summary = Vec::new();
    for (&i, e) in res.added.iter().zip(&res.evidence) {
        if !decided(i) {
            added.push(i);
            evidence.push(e.clone());
            if res.layout.effects[i].kind == EffectKind::TimeTagOffset {
                summary.push(format!(
                    "{} from the batches (too few samples in the arcs' slews)",
                    res.layout.effects[i].label()
                ));
            }
        }
    }
    let mut fixed = Vec::new();
    for s in 0..4 {
        let (Some((x, sigma)), Some(i)) = (
            tr.tau_ms[s],
            res.layout.find(EffectKind::TimeTagOffset, Some(s)),
        ) else {
            continue;
        };
        if !res.baseline.contains(&i) {
            added.push(i);
            let mut e = tr.evidence[s]
                .clone()
                .unwrap_or_else(|| Evidence::placeholder(res.layout.effects[i].label()));
            e.accepted = true;
            evidence.push(e);
        }
        fixed.push(Fixed {
            index: res.layout.range(i).start,
            value: x,
            sigma,
        });
        summary.push(format!("{} {x:.1} ± {sigma:.1} ms", SENSOR_NAMES[s]));
    }
    let mut model = res.baseline.clone();
    model.extend(&added);
    let fit = solve_fixed(
        &res.systems.full,
        &res.layout,
        &indices(&res.layout, &model),
        &fixed,
    )?;
    Some(ArcModel {
        added,
        evidence,
        fixed,
        summary,
        fit,
    })
}

/// Put the absolute time tags into the search's result in place of its relative ones: the
/// time-tag effects added become those of [`TimeReference::tau_ms`], fixed at the arcs'
/// estimates; the rest of the final model is re-estimated conditionally on them
/// ([`solve_fixed`]), with its residuals and structure tests. A sensor the arcs do not test
/// ([`TimeReference::tested`]) keeps the search's time tag (free, against the others'), and a
/// declared time tag (in the baseline) is fixed there, not added a second time.
///
/// # Errors
/// The conditional fit is singular.
pub fn apply(
    set: &MeasurementSet,
    res: &mut SearchResult,
    tr: &TimeReference,
) -> anyhow::Result<()> {
    let ArcModel {
        added,
        evidence,
        fixed,
        summary,
        fit,
    } = conditional_fit(res, tr)
        .ok_or_else(|| anyhow::anyhow!("diagnose: the fit with the arcs' time tags is singular"))?;
    res.after = post_fit(set, &res.layout, &fit.expand(res.layout.total));
    res.tests_after = super::structure::run_tests(set, &res.after, None, None);
    res.final_fit = fit;
    res.added = added;
    res.evidence = evidence;
    res.fixed = fixed;
    let n0 = res.iterations.len();
    for (k, mut it) in tr.iterations.iter().cloned().enumerate() {
        it.number = n0 + k + 1;
        res.iterations.push(it);
    }
    res.iterations.push(Iteration {
        number: res.iterations.len() + 1,
        added: Some(format!(
            "time tags against the gyro from {} slew arcs ({} equations, {} pass{}): {}",
            tr.arcs,
            tr.rows,
            tr.passes,
            if tr.passes == 1 { "" } else { "es" },
            if summary.is_empty() {
                "none".to_owned()
            } else {
                summary.join(", ")
            }
        )),
        candidates: Vec::new(),
    });
    Ok(())
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    /// An arc system from rows `(sensor, time-tag partial, residual)`, unit weights, no
    /// nuisance (as `accumulate_arc` builds the time-tag part).
    fn system(rows: &[(usize, f64, f64)], nuisance: usize) -> ArcSystem {
        let mut sys = ArcSystem::zeros();
        for &(s, t, y) in rows {
            let mut gr = SMatrix::<f64, N_TAU, 1>::zeros();
            gr[0] = t;
            gr[1 + s] = t;
            sys.n += gr * gr.transpose();
            sys.b += gr * y;
            sys.chi2 += y * y;
            sys.rows += 1;
        }
        sys.nuisance = nuisance;
        sys
    }

    /// The common column is common to the tested sensors only: an untested sensor's time tag
    /// (FSS1, 400 ms) does not enter it (it did: the common τ took it and the tested sensors'
    /// own columns cancelled it).
    #[test]
    fn common_column_leaves_out_untested_sensors() {
        let mut rows = Vec::new();
        for k in 0..200 {
            let t = 1.0 + f64::from(k % 7);
            rows.push((0, t, 0.0));
            rows.push((1, -t, 0.0));
            rows.push((2, t, 0.4 * t * 1000.0));
        }
        let sys = system(&rows, 0).common_to(&[0, 1]);
        let common = solve(&sys, &[0]).unwrap();
        assert!(common.x[0].abs() < 1e-6, "common τ {}", common.x[0]);
        let own = solve(&sys, &[3]).unwrap();
        assert!((own.x[0] - 400.0).abs() < 1e-3, "FSS1 τ {}", own.x[0]);
        // Untouched: the tested sensors' own columns and the χ².
        let all = system(&rows, 0);
        assert_eq!(sys.n[(1, 1)], all.n[(1, 1)]);
        assert_eq!(sys.chi2, all.chi2);
    }

    /// No evidence without degrees of freedom (fewer equations than the arcs' nuisance): the
    /// F tail of d2 ≤ 0 is 0, which read as a detection of anything.
    #[test]
    fn no_evidence_without_degrees_of_freedom() {
        let rows: Vec<_> = (0..10).map(|k| (0, 1.0 + f64::from(k), 30.0)).collect();
        let sys = system(&rows, N_ARC);
        assert!(evaluate(&sys, Some([&sys, &sys]), &|_, _, _| (1.0, 0), 0.001, &[], 1).is_none());
        // With enough equations the same column is evidence.
        let sys = system(&rows.repeat(3), N_ARC);
        assert!(evaluate(&sys, Some([&sys, &sys]), &|_, _, _| (1.0, 0), 0.001, &[], 1).is_some());
    }

    /// Halves per column: a sensor with a 100 ms tag tested in one arc of three (FHST1 in the
    /// only slew where it sees stars) has no halves and is not kept, however strong its
    /// likelihood ratio (alternate arcs gave it an empty half, the prior's 0 ± 1 s, which
    /// always agreed); seen in two arcs it is kept with its value.
    #[test]
    fn a_time_tag_seen_in_one_arc_only_is_not_kept() {
        let arc = |tagged: bool| {
            let mut rows = Vec::new();
            for k in 0..300 {
                let t = 1.0 + f64::from(k % 5);
                rows.push((1, t, 0.0));
                if tagged {
                    rows.push((0, t, 0.1 * t * 1000.0 + if k % 2 == 0 { 1.0 } else { -1.0 }));
                }
            }
            let mut sys = system(&rows, N_ARC);
            sys.turning = [if tagged { 300 } else { 0 }, 300, 0, 0];
            sys
        };
        let config = SearchConfig::default();
        let one = select(&[arc(true), arc(false), arc(false)], &config, false).unwrap();
        assert!(one.tau_ms[0].is_none(), "{:?}", one.tau_ms);
        assert!(one
            .iterations
            .iter()
            .any(|it| it.candidates.iter().any(|c| c
                .rejected_because
                .as_deref()
                .is_some_and(|w| w.contains("no halves")))));
        // Not dropped without a word (issue 22): the column is left over, significant
        // against the final arc model, with its size and the reason, and the evidence ledger
        // reports it as unexplained ("one arc only").
        let left = one
            .leftover
            .iter()
            .find(|l| l.column == 1)
            .expect("FHST1's own column is left over");
        assert!(left.evidence.p_holm < config.alpha, "{left:?}");
        assert!(
            (left.tau_ms.0 - 100.0).abs() < 3.0 * left.tau_ms.1,
            "{left:?}"
        );
        assert_eq!(left.arcs, 1);
        let entries = super::super::ledger::arc_entries(&one, config.alpha);
        assert!(
            entries.iter().any(|e| e.sensor == "FHST1"
                && matches!(&e.outcome, super::super::ledger::Outcome::Unexplained { reason }
                if reason.starts_with("one arc only"))),
            "{entries:#?}"
        );
        let two = select(&[arc(true), arc(false), arc(true)], &config, false).unwrap();
        let (tau, sigma) = two.tau_ms[0].unwrap();
        assert!((tau - 100.0).abs() < 3.0 * sigma, "{tau} ± {sigma}");
        assert!(two.tau_ms[1].is_none(), "{:?}", two.tau_ms);
    }

    /// The arc's reference offset: `A_a = Rot(ε) A_b` is what `rotvec_from_rot(A_a A_bᵀ)`
    /// returns, and the residual shift `P ε` has the sign of an attitude error
    /// (`A_true = Rot(δθ) Â`: the batch's error is the arc's plus ε).
    #[test]
    fn reference_offset_convention() {
        let ab = rot(&Vector3::new(0.3, -0.2, 0.5));
        let eps = Vector3::new(2e-5, -1e-5, 3e-5);
        let aa = rot(&eps) * ab;
        let back = rotvec_from_rot(&(aa * ab.transpose()));
        assert!((back - eps).norm() < 1e-12, "{back:?}");
        // Carried error: Rot(φ) Rot(δ) Rot(φ)ᵀ = Rot(Rot(φ) δ).
        let phi = Vector3::new(0.01, 0.2, -0.1);
        let delta = Vector3::new(1e-5, 2e-5, -1e-5);
        let lhs = rot(&phi) * rot(&delta) * rot(&phi).transpose();
        let rhs = rot(&(rot(&phi) * delta));
        assert!((lhs - rhs).norm() < 1e-12);
    }
}
