//! # Joint least squares: batch attitudes + alignments + effects
//!
//! Model of every measurement residual (arcsec):
//! `r = A (δθ_b + δθ̇_b (t − t_b)) + G g + noise`, with the per-batch attitude correction
//! (6 nuisance parameters: angle and rate), `g` the global parameters (alignment rotations of
//! FHST2, FSS1, FSS2 in ACS — FHST1 is the reference, its absolute alignment being
//! indistinguishable from attitude, algorithms.md §3.1 — and every candidate effect).
//!
//! **The attitude comes from the FHSTs only.** FSS measurements do not inform the batch
//! attitude (their errors would leak into it); their rows use the FHST estimate
//! `â_b = â0_b − S_b g` and enter as `r − F â0_b = (K − F S_b) g + noise`.
//!
//! **One pass, every sub-model.** The nuisance is eliminated batch by batch (Schur
//! complement); both the FHST reduction and the FSS rows act column by column, so the reduced
//! normal equations of any subset of the global parameters are the corresponding sub-blocks
//! of the full system. The candidate search therefore accumulates once and then solves small
//! systems. Halves of the data (first/second half of the batches in time) are accumulated
//! separately; the full system is their sum.

use super::effects::{Effect, EffectKind};
use super::measurements::{
    Measurement, MeasurementSet, NUISANCE_ANGLE_PRIOR_ARCSEC, NUISANCE_RATE_PRIOR,
};
use nalgebra::{DMatrix, DVector, Matrix6, Vector6};
use std::collections::HashMap;

/// Global alignment parameters: FHST2, FSS1, FSS2 × 3 (arcsec, ACS).
pub const N_ALIGN: usize = 9;
/// Nuisance parameters per batch.
pub const NUISANCE: usize = 6;
/// Prior 1σ of an alignment correction (arcsec).
const ALIGN_PRIOR_ARCSEC: f64 = 3600.0;
/// Time unit of the batch rate nuisance (s).
pub const RATE_UNIT_S: f64 = 100.0;

/// Offset of a sensor's alignment parameters (None for the reference FHST1).
#[must_use]
pub fn align_offset(sensor: usize) -> Option<usize> {
    match sensor {
        1 => Some(0),
        2 => Some(3),
        3 => Some(6),
        _ => None,
    }
}

/// Where every effect's parameters sit in the global vector.
#[derive(Clone, Debug)]
pub struct Layout {
    /// The effects.
    pub effects: Vec<Effect>,
    /// Offset of each effect's first parameter.
    pub offsets: Vec<usize>,
    /// Total number of global parameters.
    pub total: usize,
    /// Per effect: HIP → the star's index among the effect's stars (the full catalog form
    /// and the sparse one hold different subsets).
    star_index: Vec<HashMap<u32, usize>>,
}

impl Layout {
    /// Layout of alignments + the given effects.
    #[must_use]
    pub fn new(effects: Vec<Effect>) -> Self {
        let mut offsets = Vec::with_capacity(effects.len());
        let mut total = N_ALIGN;
        let mut star_index = Vec::with_capacity(effects.len());
        for e in &effects {
            offsets.push(total);
            total += e.len();
            star_index.push(if e.kind == EffectKind::CatalogProperMotionError {
                e.stars.iter().enumerate().map(|(k, h)| (*h, k)).collect()
            } else {
                HashMap::new()
            });
        }
        Self {
            effects,
            offsets,
            total,
            star_index,
        }
    }

    /// Parameter indices of effect `i`.
    #[must_use]
    pub fn range(&self, i: usize) -> std::ops::Range<usize> {
        self.offsets[i]..self.offsets[i] + self.effects[i].len()
    }

    /// Index of an effect by kind and sensor.
    #[must_use]
    pub fn find(&self, kind: EffectKind, sensor: Option<usize>) -> Option<usize> {
        self.effects
            .iter()
            .position(|e| e.kind == kind && e.sensor == sensor)
    }

    /// All global columns of a measurement: (global index, [axis 0, axis 1]).
    pub fn row_columns(
        &self,
        m: &Measurement,
        out: &mut Vec<(usize, [f64; 2])>,
        scratch: &mut Vec<(usize, [f64; 2])>,
    ) {
        out.clear();
        if let Some(o) = align_offset(m.sensor) {
            for ax in 0..3 {
                let mut e = nalgebra::Vector3::zeros();
                e[ax] = 1.0;
                let c = -(m.jm * m.b_acs.cross(&e));
                out.push((o + ax, [c.x, c.y]));
            }
        }
        for (i, e) in self.effects.iter().enumerate() {
            scratch.clear();
            let lookup = |h: u32| self.star_index[i].get(&h).copied();
            e.columns(m, &lookup, scratch);
            let o = self.offsets[i];
            out.extend(scratch.iter().map(|(k, v)| (o + k, *v)));
        }
    }

    /// Prior information (1/σ²) per global parameter.
    #[must_use]
    pub fn prior_information(&self) -> DVector<f64> {
        let mut p =
            DVector::from_element(self.total, 1.0 / (ALIGN_PRIOR_ARCSEC * ALIGN_PRIOR_ARCSEC));
        for (i, e) in self.effects.iter().enumerate() {
            for (k, s) in e.prior_sigma.iter().enumerate() {
                p[self.offsets[i] + k] = 1.0 / (s * s);
            }
        }
        p
    }
}

/// Reduced normal equations of the global parameters.
#[derive(Clone, Debug)]
pub struct Normal {
    /// `Σ G'ᵀ W G'` (reduced).
    pub n: DMatrix<f64>,
    /// `Σ G'ᵀ W r'`.
    pub b: DVector<f64>,
    /// `Σ r'ᵀ W r'` after the nuisance.
    pub chi2: f64,
    /// Scalar equations.
    pub rows: usize,
    /// Nuisance parameters eliminated.
    pub nuisance: usize,
}

impl Normal {
    fn zeros(p: usize) -> Self {
        Self {
            n: DMatrix::zeros(p, p),
            b: DVector::zeros(p),
            chi2: 0.0,
            rows: 0,
            nuisance: 0,
        }
    }

    /// This system without `part`, a system of some of its batches (the training system of
    /// a held-out block: [`super::heldout`]).
    #[must_use]
    pub fn without(&self, part: &Self) -> Self {
        Self {
            n: &self.n - &part.n,
            b: &self.b - &part.b,
            chi2: self.chi2 - part.chi2,
            rows: self.rows - part.rows,
            nuisance: self.nuisance - part.nuisance,
        }
    }

    /// Sum of two systems (disjoint data).
    #[must_use]
    pub fn sum(&self, other: &Self) -> Self {
        Self {
            n: &self.n + &other.n,
            b: &self.b + &other.b,
            chi2: self.chi2 + other.chi2,
            rows: self.rows + other.rows,
            nuisance: self.nuisance + other.nuisance,
        }
    }
}

fn nuisance_prior() -> Matrix6<f64> {
    let mut p = Matrix6::zeros();
    for j in 0..3 {
        p[(j, j)] = 1.0 / NUISANCE_ANGLE_PRIOR_ARCSEC.powi(2);
        p[(j + 3, j + 3)] = 1.0 / NUISANCE_RATE_PRIOR.powi(2);
    }
    p
}

fn nuisance_row(m: &Measurement) -> [Vector6<f64>; 2] {
    let a = MeasurementSet::attitude_partial(m);
    let t = m.dt_center_s / RATE_UNIT_S;
    let mut out = [Vector6::zeros(); 2];
    for ax in 0..2 {
        for j in 0..3 {
            out[ax][j] = a[(ax, j)];
            out[ax][j + 3] = a[(ax, j)] * t;
        }
    }
    out
}

/// The measurements of each batch (`set.meas` is in batch order).
pub(super) fn batch_ranges(set: &MeasurementSet) -> Vec<std::ops::Range<usize>> {
    let mut out = vec![0..0; set.batches.len()];
    let mut i = 0;
    while i < set.meas.len() {
        let b = set.meas[i].batch;
        let mut j = i + 1;
        while j < set.meas.len() && set.meas[j].batch == b {
            j += 1;
        }
        out[b] = i..j;
        i = j;
    }
    out
}

/// Accumulate the reduced normal equations over the batches selected by `use_batch`.
#[must_use]
pub fn accumulate(
    set: &MeasurementSet,
    layout: &Layout,
    use_batch: &dyn Fn(usize) -> bool,
) -> Normal {
    accumulate_rows(set, layout, use_batch, true)
}

/// [`accumulate`] over the FHST rows only (the per-star catalog screen,
/// [`super::sparse_catalog`]: the FSS's position-dependent systematic is shared by a
/// batch's Sun samples and is not in their weights).
#[must_use]
pub fn accumulate_fhst_only(set: &MeasurementSet, layout: &Layout) -> Normal {
    accumulate_rows(set, layout, &|_| true, false)
}

/// Each batch `use_batch` selects that has a tracker row (not an outlier): its index and its
/// measurements.
fn tracker_batches<'a>(
    set: &'a MeasurementSet,
    use_batch: &'a dyn Fn(usize) -> bool,
) -> impl Iterator<Item = (usize, &'a [Measurement])> + 'a {
    batch_ranges(set)
        .into_iter()
        .enumerate()
        .filter(move |(bi, range)| use_batch(*bi) && !range.is_empty())
        .map(move |(bi, range)| (bi, &set.meas[range]))
        .filter(|(_, ms)| ms.iter().any(|m| m.sensor < 2 && !m.outlier))
}

fn accumulate_rows(
    set: &MeasurementSet,
    layout: &Layout,
    use_batch: &dyn Fn(usize) -> bool,
    fss_rows: bool,
) -> Normal {
    let mut acc = BatchAccumulator::new(layout.total);
    for (_, ms) in tracker_batches(set, use_batch) {
        let (naa, na) = acc.fhst_rows(ms, layout);
        if let Some((a0, s)) = acc.eliminate_attitude(&naa, &na) {
            if fss_rows {
                acc.fss_rows(ms, layout, naa, &a0, &s);
            }
        }
        acc.release_columns();
    }
    acc.out
}

/// The normal equations being summed over the batches of [`accumulate_rows`], and the
/// scratch of one batch: its global columns (`touched`, with their `local` index) and the
/// attitude's cross terms with them.
struct BatchAccumulator {
    out: Normal,
    /// Global column → its index in `touched` (`usize::MAX` = not in this batch).
    local: Vec<usize>,
    touched: Vec<usize>,
    /// `Aᵀ W G` per touched column (FHST rows).
    nag: Vec<Vector6<f64>>,
    cols: Vec<(usize, [f64; 2])>,
    scratch: Vec<(usize, [f64; 2])>,
    dense: Vec<(usize, f64)>,
}

/// The columns of measurement `m` into `cols`, each one not seen yet in the batch given a
/// local index (`local`, `touched`) and a zero row in `rows` (the tracker rows' `nag` or the
/// FSS rows' own).
fn columns_of(
    layout: &Layout,
    m: &Measurement,
    (cols, scratch): (&mut Vec<(usize, [f64; 2])>, &mut Vec<(usize, [f64; 2])>),
    (local, touched): (&mut [usize], &mut Vec<usize>),
    rows: &mut Vec<Vector6<f64>>,
) {
    layout.row_columns(m, cols, scratch);
    for &(c, _) in cols.iter() {
        if local[c] == usize::MAX {
            local[c] = touched.len();
            touched.push(c);
            rows.push(Vector6::zeros());
        }
    }
}

impl BatchAccumulator {
    fn new(p: usize) -> Self {
        Self {
            out: Normal::zeros(p),
            local: vec![usize::MAX; p],
            touched: Vec::new(),
            nag: Vec::new(),
            cols: Vec::new(),
            scratch: Vec::new(),
            dense: Vec::new(),
        }
    }

    /// A batch's global columns are given back (the next batch starts empty).
    fn release_columns(&mut self) {
        for &c in &self.touched {
            self.local[c] = usize::MAX;
        }
    }

    /// The batch's FHST rows into the global sums, with the attitude's information `naa` and
    /// its right-hand side `na` (the batch's cross terms in `nag`).
    fn fhst_rows(&mut self, ms: &[Measurement], layout: &Layout) -> (Matrix6<f64>, Vector6<f64>) {
        let out = &mut self.out;
        let mut naa = nuisance_prior();
        let mut na = Vector6::<f64>::zeros();
        self.touched.clear();
        self.nag.clear();
        for m in ms.iter().filter(|m| m.sensor < 2 && !m.outlier) {
            columns_of(
                layout,
                m,
                (&mut self.cols, &mut self.scratch),
                (&mut self.local, &mut self.touched),
                &mut self.nag,
            );
            let cols = &self.cols;
            let arow = nuisance_row(m);
            let w = 1.0 / (m.sigma * m.sigma);
            for ax in 0..2 {
                let r = m.r[ax];
                let a = &arow[ax];
                naa += a * a.transpose() * w;
                na += a * (w * r);
                out.chi2 += w * r * r;
                out.rows += 1;
                for &(c1, v1) in cols {
                    let wv = w * v1[ax];
                    if wv == 0.0 {
                        continue;
                    }
                    self.nag[self.local[c1]] += a * wv;
                    out.b[c1] += wv * r;
                    for &(c2, v2) in cols {
                        out.n[(c1, c2)] += wv * v2[ax];
                    }
                }
            }
        }
        (naa, na)
    }

    /// The batch attitude eliminated from the sums (Schur complement): its estimate `â0` from
    /// the FHST rows and `S = naa⁻¹ nag` per touched column; `None` when `naa` is singular
    /// (the batch is not used).
    fn eliminate_attitude(
        &mut self,
        naa: &Matrix6<f64>,
        na: &Vector6<f64>,
    ) -> Option<(Vector6<f64>, Vec<Vector6<f64>>)> {
        let inv = naa.try_inverse()?;
        let out = &mut self.out;
        out.nuisance += NUISANCE;
        let a0 = inv * na;
        out.chi2 -= na.dot(&a0);
        let s: Vec<Vector6<f64>> = self.nag.iter().map(|v| inv * v).collect();
        for (i, &ci) in self.touched.iter().enumerate() {
            out.b[ci] -= self.nag[i].dot(&a0);
            for (j, &cj) in self.touched.iter().enumerate() {
                out.n[(ci, cj)] -= self.nag[i].dot(&s[j]);
            }
        }
        Some((a0, s))
    }

    /// FSS rows against the FHST attitude: r' = r − F â0 = (K − F S) g + F e + noise, where
    /// e = a − â0 is the error of the FHST attitude, with information `naa`. Eliminating e
    /// as well (sequential least squares) gives the exact likelihood: the FSS rows of one
    /// batch share the attitude error.
    fn fss_rows(
        &mut self,
        ms: &[Measurement],
        layout: &Layout,
        naa: Matrix6<f64>,
        a0: &Vector6<f64>,
        s: &[Vector6<f64>],
    ) {
        let out = &mut self.out;
        let mut nee = naa;
        let mut ne = Vector6::<f64>::zeros();
        let mut neg: Vec<Vector6<f64>> = vec![Vector6::zeros(); self.touched.len()];
        let n_fhst_cols = self.touched.len();
        let mut any_fss = false;
        for m in ms.iter().filter(|m| m.sensor >= 2 && !m.outlier) {
            any_fss = true;
            columns_of(
                layout,
                m,
                (&mut self.cols, &mut self.scratch),
                (&mut self.local, &mut self.touched),
                &mut neg,
            );
            let cols = &self.cols;
            let arow = nuisance_row(m);
            let w = 1.0 / (m.sigma * m.sigma);
            for ax in 0..2 {
                let a = &arow[ax];
                let r = m.r[ax] - a.dot(a0);
                let dense = &mut self.dense;
                dense.clear();
                for i in 0..n_fhst_cols {
                    let v = -a.dot(&s[i]);
                    if v != 0.0 {
                        dense.push((self.touched[i], v));
                    }
                }
                for &(c, v) in cols {
                    if v[ax] == 0.0 {
                        continue;
                    }
                    if let Some(e) = dense.iter_mut().find(|(k, _)| *k == c) {
                        e.1 += v[ax];
                    } else {
                        dense.push((c, v[ax]));
                    }
                }
                out.chi2 += w * r * r;
                out.rows += 1;
                nee += a * a.transpose() * w;
                ne += a * (w * r);
                for &(c1, v1) in dense.iter() {
                    let wv = w * v1;
                    out.b[c1] += wv * r;
                    neg[self.local[c1]] += a * wv;
                    for &(c2, v2) in dense.iter() {
                        out.n[(c1, c2)] += wv * v2;
                    }
                }
            }
        }
        if !any_fss {
            return;
        }
        if let Some(inv_e) = nee.try_inverse() {
            let e0 = inv_e * ne;
            out.chi2 -= ne.dot(&e0);
            let se: Vec<Vector6<f64>> = neg.iter().map(|v| inv_e * v).collect();
            for (i, &ci) in self.touched.iter().enumerate() {
                if neg[i] == Vector6::zeros() {
                    continue;
                }
                out.b[ci] -= neg[i].dot(&e0);
                for (j, &cj) in self.touched.iter().enumerate() {
                    out.n[(ci, cj)] -= neg[i].dot(&se[j]);
                }
            }
        }
    }
}

/// What [`batch_quadratic`] evaluates per batch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Quadratic {
    /// χ² of each selected batch for the global vector `g` (full length): the likelihood
    /// [`accumulate`] maximises, evaluated instead of accumulated — the batch attitude
    /// re-estimated from the FHST rows, the FSS rows taken against it with its error
    /// eliminated as well — so that `Σ χ²_b(g) = χ² − 2 gᵀb + gᵀN g` of the same batches'
    /// [`Normal`]. The held-out validation of diagnose's tables ([`super::heldout`]) compares
    /// two vectors batch by batch with it.
    Chi2,
    /// The same of data that are all zero: `gᵀ N_b g`, the χ² by which the batch tells the
    /// vector `g` from zero (with `g` a difference of two models, the expected change of the
    /// batch's χ² between them).
    Information,
}

/// The rows a batch quadratic takes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rows {
    /// Trackers and FSSs.
    All,
    /// Trackers only: what gives the flight attitude.
    Trackers,
}

/// The [`Quadratic`] of each selected batch (`use_batch`) for the global vector `g`, over the
/// rows `rows_taken` takes (the trackers' alone say what the trackers, which give the flight
/// attitude, see of `g`: the held-out judgement of a tracker's table). Returns (batch, value,
/// scalar rows) per batch in batch order.
#[must_use]
pub fn batch_quadratic(
    set: &MeasurementSet,
    layout: &Layout,
    g: &DVector<f64>,
    use_batch: &dyn Fn(usize) -> bool,
    quadratic: Quadratic,
    rows_taken: Rows,
) -> Vec<(usize, f64, usize)> {
    let with_data = quadratic == Quadratic::Chi2;
    let mut out = Vec::new();
    let mut cols = Vec::new();
    let mut scratch = Vec::new();
    let mut shifted = |m: &Measurement| {
        layout.row_columns(m, &mut cols, &mut scratch);
        let mut r = if with_data { m.r } else { [0.0; 2] };
        for &(c, v) in &cols {
            r[0] -= v[0] * g[c];
            r[1] -= v[1] * g[c];
        }
        r
    };
    for (bi, ms) in tracker_batches(set, use_batch) {
        let (mut chi2, mut rows) = (0.0, 0usize);
        let mut naa = nuisance_prior();
        let mut na = Vector6::<f64>::zeros();
        for m in ms.iter().filter(|m| m.sensor < 2 && !m.outlier) {
            let r = shifted(m);
            let arow = nuisance_row(m);
            let w = 1.0 / (m.sigma * m.sigma);
            for ax in 0..2 {
                naa += arow[ax] * arow[ax].transpose() * w;
                na += arow[ax] * (w * r[ax]);
                chi2 += w * r[ax] * r[ax];
                rows += 1;
            }
        }
        let Some(inv) = naa.try_inverse() else {
            continue;
        };
        let a0 = inv * na;
        chi2 -= na.dot(&a0);
        let mut nee = naa;
        let mut ne = Vector6::<f64>::zeros();
        let mut any_fss = false;
        for m in ms
            .iter()
            .filter(|m| rows_taken == Rows::All && m.sensor >= 2 && !m.outlier)
        {
            any_fss = true;
            let r = shifted(m);
            let arow = nuisance_row(m);
            let w = 1.0 / (m.sigma * m.sigma);
            for ax in 0..2 {
                let r = r[ax] - arow[ax].dot(&a0);
                nee += arow[ax] * arow[ax].transpose() * w;
                ne += arow[ax] * (w * r);
                chi2 += w * r * r;
                rows += 1;
            }
        }
        if any_fss {
            if let Some(inv_e) = nee.try_inverse() {
                chi2 -= ne.dot(&(inv_e * ne));
            }
        }
        out.push((bi, chi2, rows));
    }
    out
}

/// Length of the alternating time blocks that make the two halves (s).
pub const HALF_BLOCK_S: f64 = 600.0;

/// The halves are alternating 10-min blocks of batches: each half then covers the same
/// attitudes, Sun positions, temperatures and orbit phases, so a field- or
/// temperature-dependent effect has comparable parameters in both (split-half agreement);
/// contiguous time halves would compare extrapolations of different parts of the field.
#[must_use]
pub fn in_first_half(set: &MeasurementSet, batch: usize) -> bool {
    set.batches
        .get(batch)
        .is_some_and(|b| (b.t_center_s / HALF_BLOCK_S).floor() as i64 % 2 == 0)
}

/// The three systems of the search: first half, second half, both.
#[derive(Clone, Debug)]
pub struct Systems {
    /// First half of the batches (even 10-min blocks, [`in_first_half`]).
    pub first: Normal,
    /// Second half.
    pub second: Normal,
    /// All data.
    pub full: Normal,
}

/// Accumulate both halves and their sum.
#[must_use]
pub fn accumulate_halves(set: &MeasurementSet, layout: &Layout) -> Systems {
    let in_first = |b: usize| in_first_half(set, b);
    let (first, second) = rayon::join(
        || accumulate(set, layout, &|b| in_first(b)),
        || accumulate(set, layout, &|b| !in_first(b)),
    );
    let full = first.sum(&second);
    Systems {
        first,
        second,
        full,
    }
}

/// Solution of a sub-model.
#[derive(Clone, Debug)]
pub struct SubFit {
    /// Global indices solved.
    pub idx: Vec<usize>,
    /// Estimates (same order).
    pub x: DVector<f64>,
    /// Inverse of the normal matrix (unscaled covariance).
    pub cov: DMatrix<f64>,
    /// Data χ² after the fit.
    pub chi2: f64,
    /// Degrees of freedom.
    pub dof: f64,
}

impl SubFit {
    /// Reduced χ² (≥ a small floor).
    #[must_use]
    pub fn s2(&self) -> f64 {
        if self.dof > 0.0 {
            (self.chi2 / self.dof).max(1e-6)
        } else {
            1.0
        }
    }

    /// Full-length vector (zeros outside `idx`).
    #[must_use]
    pub fn expand(&self, total: usize) -> DVector<f64> {
        let mut g = DVector::zeros(total);
        for (k, &i) in self.idx.iter().enumerate() {
            g[i] = self.x[k];
        }
        g
    }

    /// Estimate and 1σ (scaled by max(1, s²)) of global parameter `i`, if solved.
    #[must_use]
    pub fn param(&self, i: usize) -> Option<(f64, f64)> {
        let k = self.idx.iter().position(|&j| j == i)?;
        Some((self.x[k], (self.cov[(k, k)] * self.s2().max(1.0)).sqrt()))
    }
}

/// Solve the sub-model with the given global indices (soft constraints included).
#[must_use]
pub fn solve(normal: &Normal, layout: &Layout, idx: &[usize]) -> Option<SubFit> {
    solve_opt(normal, layout, idx, true)
}

/// [`solve`], optionally without the soft constraints (the split-half comparison of the
/// catalog offsets removes their gauge itself: with the constraints, stars a half does not
/// see would carry the other stars' net rotation).
#[must_use]
pub fn solve_opt(
    normal: &Normal,
    layout: &Layout,
    idx: &[usize],
    constraints: bool,
) -> Option<SubFit> {
    let prior = layout.prior_information();
    let k = idx.len();
    let n = normal.n.select_rows(idx).select_columns(idx);
    let b = normal.b.select_rows(idx);
    let mut np = n.clone();
    for (a, &i) in idx.iter().enumerate() {
        np[(a, a)] += prior[i];
    }
    // Soft constraints whose parameters are all in the sub-model.
    for (ei, e) in layout.effects.iter().enumerate().filter(|_| constraints) {
        let o = layout.offsets[ei];
        for (row, sigma) in &e.constraints {
            let pos: Option<Vec<(usize, f64)>> = row
                .iter()
                .map(|(j, c)| idx.iter().position(|&g| g == o + j).map(|p| (p, *c)))
                .collect();
            let Some(pos) = pos else { continue };
            let w = 1.0 / (sigma * sigma);
            for &(p1, c1) in &pos {
                for &(p2, c2) in &pos {
                    np[(p1, p2)] += w * c1 * c2;
                }
            }
        }
    }
    let chol = np.clone().cholesky()?;
    let x = chol.solve(&b);
    let cov = chol.inverse();
    let chi2 = (normal.chi2 - 2.0 * x.dot(&b) + x.dot(&(&n * &x))).max(0.0);
    // Parameters without information do not consume degrees of freedom.
    let informed = (0..k)
        .filter(|&a| n[(a, a)] > 1e-6 * np[(a, a)].max(1e-30))
        .count();
    let dof = normal.rows as f64 - normal.nuisance as f64 - informed as f64;
    Some(SubFit {
        idx: idx.to_vec(),
        x,
        cov,
        chi2,
        dof,
    })
}

/// A global parameter fixed from outside the batch system, with its 1σ.
#[derive(Clone, Copy, Debug)]
pub struct Fixed {
    /// Global index.
    pub index: usize,
    /// Value (parameter units).
    pub value: f64,
    /// 1σ (parameter units).
    pub sigma: f64,
}

/// [`solve`] with some global parameters fixed. The batch attitudes absorb a time shift
/// common to all sensors, so the time tags are taken from the slew arcs
/// ([`super::time_reference`], where they are absolute against the gyro) and the rest of the
/// model is estimated conditionally on them. The fixed parameters appear in the result with
/// their own σ (no correlation with the free ones) and take no degrees of freedom.
#[must_use]
pub fn solve_fixed(
    normal: &Normal,
    layout: &Layout,
    idx: &[usize],
    fixed: &[Fixed],
) -> Option<SubFit> {
    if fixed.is_empty() {
        return solve(normal, layout, idx);
    }
    let free: Vec<usize> = idx
        .iter()
        .copied()
        .filter(|i| !fixed.iter().any(|f| f.index == *i))
        .collect();
    let mut v = DVector::zeros(normal.b.len());
    for f in fixed {
        v[f.index] = f.value;
    }
    let nv = &normal.n * &v;
    let reduced = Normal {
        n: normal.n.clone(),
        b: &normal.b - &nv,
        chi2: (normal.chi2 - 2.0 * v.dot(&normal.b) + v.dot(&nv)).max(0.0),
        rows: normal.rows,
        nuisance: normal.nuisance,
    };
    let fit = solve(&reduced, layout, &free)?;
    let (k, m) = (free.len(), fixed.len());
    let scale = fit.s2().max(1.0);
    let mut cov = DMatrix::zeros(k + m, k + m);
    cov.view_mut((0, 0), (k, k)).copy_from(&fit.cov);
    let mut x = DVector::zeros(k + m);
    x.rows_mut(0, k).copy_from(&fit.x);
    let mut all = free;
    for (j, f) in fixed.iter().enumerate() {
        x[k + j] = f.value;
        cov[(k + j, k + j)] = f.sigma * f.sigma / scale;
        all.push(f.index);
    }
    Some(SubFit {
        idx: all,
        x,
        cov,
        chi2: fit.chi2,
        dof: fit.dof,
    })
}

/// Global indices of the alignments plus the given effects.
#[must_use]
pub fn indices(layout: &Layout, effects: &[usize]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..N_ALIGN).collect();
    for &e in effects {
        idx.extend(layout.range(e));
    }
    idx
}

/// Post-fit residuals (arcsec) for the full-length global vector `g`, with the batch
/// attitudes re-solved from the FHSTs; also each batch's nuisance estimate and covariance.
#[must_use]
pub fn post_fit(set: &MeasurementSet, layout: &Layout, g: &DVector<f64>) -> PostFit {
    let mut resid = vec![[0.0; 2]; set.meas.len()];
    let mut batch_nuisance = vec![None; set.batches.len()];
    let mut cols = Vec::new();
    let mut scratch = Vec::new();
    let model = |m: &Measurement,
                 cols: &mut Vec<(usize, [f64; 2])>,
                 scratch: &mut Vec<(usize, [f64; 2])>| {
        layout.row_columns(m, cols, scratch);
        let mut r = m.r;
        for &(c, v) in cols.iter() {
            r[0] -= v[0] * g[c];
            r[1] -= v[1] * g[c];
        }
        r
    };
    for (bi, range) in batch_ranges(set).into_iter().enumerate() {
        if range.is_empty() {
            continue;
        }
        let mut naa = nuisance_prior();
        let mut na = Vector6::<f64>::zeros();
        let mut any = false;
        let fhst_only = set.batches[bi].fhst_only;
        for i in range.clone() {
            let m = &set.meas[i];
            let r = model(m, &mut cols, &mut scratch);
            resid[i] = r;
            if (m.sensor >= 2 && fhst_only) || m.outlier {
                continue;
            }
            any |= m.sensor < 2;
            let arow = nuisance_row(m);
            let w = 1.0 / (m.sigma * m.sigma);
            for ax in 0..2 {
                naa += arow[ax] * arow[ax].transpose() * w;
                na += arow[ax] * (w * r[ax]);
            }
        }
        let a_hat = if any {
            naa.try_inverse().map(|inv| (inv * na, inv))
        } else {
            None
        };
        if let Some((a, inv)) = a_hat {
            batch_nuisance[bi] = Some(Box::new((a, inv)));
            for i in range {
                let arow = nuisance_row(&set.meas[i]);
                resid[i][0] -= arow[0].dot(&a);
                resid[i][1] -= arow[1].dot(&a);
            }
        }
    }
    PostFit {
        resid,
        batch_nuisance,
    }
}

/// Output of [`post_fit`].
#[derive(Clone, Debug)]
pub struct PostFit {
    /// Residual per measurement (arcsec).
    pub resid: Vec<[f64; 2]>,
    /// Per batch: nuisance estimate and its covariance ([`PostFit::batch_nuisance`]).
    /// Boxed: on long telemetry at 30-s frames (one frame per batch, issue 22) only a few
    /// thousand of the 524k batches are solved, and an unboxed `Option` (344 B per batch)
    /// cost 180 MB per `PostFit`; three are alive at diagnose's peak.
    batch_nuisance: Vec<Option<Box<(Vector6<f64>, Matrix6<f64>)>>>,
}

impl PostFit {
    /// Nuisance estimate of batch `b` (angle arcsec, rate arcsec/100 s) and its covariance;
    /// `None` when the batch has no FHST row in the fit or its normal matrix is singular.
    #[must_use]
    pub fn batch_nuisance(&self, b: usize) -> Option<&(Vector6<f64>, Matrix6<f64>)> {
        self.batch_nuisance.get(b)?.as_deref()
    }
}
