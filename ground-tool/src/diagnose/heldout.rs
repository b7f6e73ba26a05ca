//! # Held-out validation of diagnose's flight tables against calibrate's
//!
//! Why: diagnose's tables come from a larger model (the alignments and the effects it named)
//! fitted to the same data, so their in-sample χ² is always lower than calibrate's. That says
//! nothing about the next flight: an alignment that changed during the span, an effect named
//! wrongly (a focal-plane error taken for catalog offsets), or a term that trades with an
//! alignment all fit better in sample and fly worse (issue 22: diagnose's FHST1–FHST2
//! alignment 26–33″ from the truth where calibrate's was 14–19″, and uplinked). And a table
//! that is better as a whole can still carry a part that is worse: a real time tag found, and
//! the alignments re-estimated with noise where the flown ones were already right.
//!
//! What is compared is what would fly. The *flight model* is the final model restricted to
//! what the OBC applies ([`super::flight::flight_update`]: the alignments and the table terms
//! that pass 3σ, the time tags at their estimates against the gyro). The *reference* is the
//! alignment table `calibrate` writes for the same telemetry (its own alignments when its
//! held-out validation passed, else the flown ones), with no effect terms. The flight model is
//! cut into *components* — each sensor's alignment, each effect's terms — and built up from the
//! reference by forward selection: in each round every component not yet taken is added in
//! turn, the one that lowers the held-out χ² most is taken if its decrease exceeds
//! [`MIN_IMPROVEMENT_Z`] standard errors (the held-out likelihood ratio with a dispersion
//! estimated over the error groups, `Folds::compare`); a component that changes a
//! tracker's table is judged instead on the trackers' own held-out χ² (they give the flight
//! attitude; the FSS rows, white-weighted against their batch attitude, can pull a tracker's
//! alignment with an error of their own), all rows not preferring the reference; the
//! selection stops when none passes. A component not taken stays at the reference (an
//! alignment at calibrate's, an effect term not written); nothing taken = calibrate's table.
//!
//! The held-out χ²: the span is cut into K ([`MAX_FOLDS`], the chain's) contiguous blocks of
//! equal duration; for each block the model is refitted on the batch systems of the others
//! ([`super::fit::accumulate`] per block, summed) and every held-out batch's χ² is evaluated
//! ([`super::fit::batch_quadratic`] with `Quadratic::Chi2`: the exact likelihood of the fit, the batch attitude
//! re-estimated). A parameter that a fold's training data do not determine (σ more than
//! [`UNDETERMINED_SIGMA_RATIO`] × the whole span's: a sensor seen in one block only, a star
//! tracked once) is held at the reference in that fold: the block validates nothing about it,
//! and its wandering estimate would charge the table for the design of the folds.
//! The held-out mean square of the normalised residuals is reported, not gated on: the
//! reference is what flies otherwise, so a table that beats it is the better choice even where
//! neither describes the data to the noise (an effect outside the library stays in both, and
//! is in the report's `unexplained`).
//!
//! Limits: the time tags keep their estimates from the whole span's slew arcs (a fold refit
//! would need the arcs again); the catalog offsets are evaluated as fitted, before the
//! shrinkage and net-rotation removal [`super::flight`] applies to the uplinked catalog.

use super::fit::{
    accumulate, batch_quadratic, solve_fixed, Fixed, Layout, Normal, Quadratic, Rows, NUISANCE,
    N_ALIGN,
};
use super::measurements::{MeasurementSet, SENSOR_NAMES};
use crate::calibration::iru_chain::MAX_FOLDS;
use crate::pipeline::alignment_heldout::paired_improvement;
pub use crate::pipeline::alignment_heldout::MIN_IMPROVEMENT_Z;
use crate::pipeline::ffcal_stages::FSS_CELL_DEG;
use fsw_core::attitude::rotvec_from_rot;
use fsw_core::units::ARCSEC_PER_RAD;
use nalgebra::{DVector, Matrix3, Vector3};
use rayon::prelude::*;
use serde::Serialize;
use std::collections::BTreeMap;

/// A fold's training σ of a parameter beyond this multiple of the whole span's means the
/// held-out block holds nearly all (≥ 89 %) of the information on it.
pub const UNDETERMINED_SIGMA_RATIO: f64 = 3.0;

/// Least expected χ² change between two models for a held-out test: below it the component
/// changes nothing the held-out data can see (a sensor without data) and its z is not formed.
pub const MIN_SEPARATION: f64 = 1.0;

/// One component's held-out test in the forward selection.
#[derive(Clone, Debug, Serialize)]
pub struct ComponentTest {
    /// The component: `FHST2 alignment`, or an effect's label.
    pub component: String,
    /// The decrease of the held-out χ² from adding it to the components taken before.
    pub improvement: HeldOutTest,
    /// The same over the trackers' rows alone (`None` when the component does not change
    /// what the trackers see). A component that changes a tracker's table (a tracker's
    /// alignment, an effect of a tracker or of every sensor) is judged on it (with `z` of all
    /// rows > 0).
    pub trackers: Option<HeldOutTest>,
}

/// A held-out comparison of two models, batch by batch (module doc).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct HeldOutTest {
    /// Σ (χ²_before − χ²_after) over the held-out batches.
    pub chi2_decrease: f64,
    /// Σ Δgᵀ N_b Δg (Δg the two fold fits' difference): the decrease expected if the new
    /// model were exact, and minus it if the old one were.
    pub separation: f64,
    /// σ² scale of the differences, from their own scatter (`dispersion`), at least 1.
    pub noise_scale: f64,
    /// Standard error of the decrease from the noise: `2 √(noise_scale · separation)`.
    pub standard_error: f64,
    /// `chi2_decrease / standard_error`, as the normal deviate of the same tail probability
    /// when the noise scale was estimated from the data (Student's t over `groups − 1`).
    pub z: f64,
    /// Error groups the noise scale came from (`dispersion`, `error_groups`).
    pub groups: usize,
    /// z of the same differences with the standard error by batch means (reported: it
    /// cannot exceed ≈ √m when only m of its groups see the change, a sensor tracking in a
    /// few holds).
    pub batch_means_z: f64,
    /// Held-out batches compared.
    pub batches: usize,
}

impl HeldOutTest {
    /// `z 2.4` for people, or why there is no z: the held-out batches barely tell the two
    /// tables apart (separation at most [`MIN_SEPARATION`]), or their differences come from
    /// fewer than two groups of shared errors, from which the noise scale cannot be estimated.
    #[must_use]
    pub fn z_text(&self) -> String {
        if self.z.is_finite() {
            format!("z {:.1}", self.z)
        } else if self.separation <= MIN_SEPARATION {
            format!(
                "no z: the held-out batches barely see it, separation {:.2} ≤ {MIN_SEPARATION}",
                self.separation
            )
        } else {
            format!(
                "no z: only {} error group{}, the noise scale cannot be estimated",
                self.groups,
                if self.groups == 1 { "" } else { "s" }
            )
        }
    }
}

/// The held-out χ² of diagnose's tables (the components taken) against the reference table,
/// over the same held-out batches.
#[derive(Clone, Debug, Serialize)]
pub struct HeldOutChi2 {
    /// Held-out batches evaluated.
    pub batches: usize,
    /// Held-out scalar residuals minus the batch attitudes' parameters.
    pub dof: usize,
    /// Held-out χ² with the components taken.
    pub chi2_diagnose: f64,
    /// Held-out χ² with the reference table.
    pub chi2_reference: f64,
    /// The decrease from the reference to the components taken.
    pub improvement: HeldOutTest,
    /// χ²_diagnose / dof.
    pub mean_square_diagnose: f64,
    /// χ²_reference / dof.
    pub mean_square_reference: f64,
}

impl HeldOutChi2 {
    /// The figures of `batches` held-out batches with `dof` degrees of freedom.
    #[must_use]
    pub fn new(
        batches: usize,
        dof: usize,
        chi2_diagnose: f64,
        chi2_reference: f64,
        improvement: HeldOutTest,
    ) -> Self {
        let ms = |c: f64| if dof > 0 { c / dof as f64 } else { f64::NAN };
        Self {
            batches,
            dof,
            chi2_diagnose,
            chi2_reference,
            improvement,
            mean_square_diagnose: ms(chi2_diagnose),
            mean_square_reference: ms(chi2_reference),
        }
    }
}

/// The held-out validation of diagnose's flight tables (module doc).
#[derive(Clone, Debug, Serialize)]
pub struct FlightTableValidation {
    /// The table compared against.
    pub reference: String,
    /// Blocks of time held out in turn.
    pub folds: usize,
    /// Why a fold was not used in the final model's evaluation (one line each).
    pub folds_skipped: Vec<String>,
    /// Parameters held at the reference in a fold of the final model's evaluation (one line
    /// per fold; module doc).
    pub held_at_reference: Vec<String>,
    /// The held-out χ² of both tables (report keys `batches` … `mean_square_reference`).
    #[serde(flatten)]
    pub chi2: HeldOutChi2,
    /// The components taken, in order, each with its test when it was taken.
    pub taken: Vec<ComponentTest>,
    /// The components left at the reference, with their test in the last round.
    pub not_taken: Vec<ComponentTest>,
    /// The layout's parameters of the components taken (what the tables may change).
    #[serde(skip)]
    pub taken_params: Vec<usize>,
    /// Whether any of diagnose's table terms may be written.
    pub passed: bool,
    /// Why, with the numbers.
    pub reason: String,
}

/// The alignment parameters of the joint fit (`M' = Rot(θ) M` for FHST2, FSS1, FSS2, arcsec;
/// FHST1 the reference) that take the alignments `m_base` to `m_new`, the common rotation of
/// the four removed (it is a change of the ACS frame, absorbed by the batch attitudes).
#[must_use]
pub fn alignment_parameters_arcsec(
    m_new: &[Matrix3<f64>; 4],
    m_base: &[Matrix3<f64>; 4],
) -> [f64; N_ALIGN] {
    let r: Vec<Matrix3<f64>> = (0..4).map(|s| m_new[s] * m_base[s].transpose()).collect();
    let mut out = [0.0; N_ALIGN];
    for s in 1..4 {
        let theta = rotvec_from_rot(&(r[0].transpose() * r[s])) * ARCSEC_PER_RAD;
        for ax in 0..3 {
            out[3 * (s - 1) + ax] = theta[ax];
        }
    }
    out
}

/// A part of the flight model taken or left as a whole: a sensor's alignment or an effect's
/// terms. `params` are indices of the validation's own layout.
struct Component {
    name: String,
    params: Vec<usize>,
    /// It changes a tracker's table (a tracker's alignment, an effect of a tracker or of all
    /// sensors): the trackers' own held-out χ² judges it.
    trackers: bool,
}

/// The layout of the effects that hold the parameters `idx` of `layout`, where each of `idx`
/// sits in it, and the components (each sensor's alignment, each effect's terms).
fn sub_layout(layout: &Layout, idx: &[usize]) -> (Layout, Vec<usize>, Vec<Component>) {
    let holds = |e: usize| idx.iter().any(|i| layout.range(e).contains(i));
    let kept: Vec<usize> = (0..layout.effects.len()).filter(|&e| holds(e)).collect();
    let sub = Layout::new(kept.iter().map(|&e| layout.effects[e].clone()).collect());
    let map: Vec<usize> = idx
        .iter()
        .map(|&i| {
            kept.iter()
                .enumerate()
                .find(|(_, &e)| layout.range(e).contains(&i))
                .map_or(i, |(k, &e)| sub.offsets[k] + (i - layout.offsets[e]))
        })
        .collect();
    let mut components: Vec<Component> = (1..4)
        .map(|s| Component {
            name: format!("{} alignment", SENSOR_NAMES[s]),
            params: map
                .iter()
                .copied()
                .filter(|&i| i < N_ALIGN && i / 3 + 1 == s)
                .collect(),
            trackers: s < 2,
        })
        .collect();
    components.extend(sub.effects.iter().enumerate().map(|(e, effect)| {
        Component {
            name: effect.label(),
            params: map
                .iter()
                .copied()
                .filter(|i| sub.range(e).contains(i))
                .collect(),
            trackers: effect.sensor.is_none_or(|s| s < 2),
        }
    }));
    components.retain(|c| !c.params.is_empty());
    (sub, map, components)
}

/// Fold of every batch: K contiguous blocks of equal duration over the batches that enter
/// the fit (a non-outlier FHST row); `None` for the others.
fn folds_of_batches(set: &MeasurementSet, k: usize) -> Vec<Option<usize>> {
    let mut in_fit = vec![false; set.batches.len()];
    for m in set.meas.iter().filter(|m| m.sensor < 2 && !m.outlier) {
        if let Some(b) = in_fit.get_mut(m.batch) {
            *b = true;
        }
    }
    let times: Vec<f64> = (0..set.batches.len())
        .filter(|&b| in_fit[b])
        .map(|b| set.batches[b].t_center_s)
        .collect();
    let (t0, t1) = times
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &t| {
            (a.min(t), b.max(t))
        });
    let span = (t1 - t0).max(1e-9);
    (0..set.batches.len())
        .map(|b| {
            in_fit[b].then(|| {
                (((set.batches[b].t_center_s - t0) / span * k as f64).floor() as usize).min(k - 1)
            })
        })
        .collect()
}

/// Names of the parameters `params` of `layout` (alignment axes and effect labels, once each).
fn parameter_names(layout: &Layout, params: &[usize]) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for &i in params {
        let name = if i < N_ALIGN {
            format!("{} alignment", SENSOR_NAMES[i / 3 + 1])
        } else {
            (0..layout.effects.len())
                .find(|&e| layout.range(e).contains(&i))
                .map_or_else(|| format!("parameter {i}"), |e| layout.effects[e].label())
        };
        if !out.contains(&name) {
            out.push(name);
        }
    }
    out
}

/// The data of the validation: the blocks' systems and what every model shares.
struct Folds<'a> {
    set: &'a MeasurementSet,
    sub: Layout,
    /// The flight model's parameters (validation layout).
    idx: Vec<usize>,
    /// Parameters fixed from outside (the time tags), validation layout.
    fixed: Vec<Fixed>,
    components: Vec<Component>,
    fold: Vec<Option<usize>>,
    /// Error group of each batch ([`error_groups`], FSS cells shared): the groups of the
    /// dispersion over all rows.
    group_all: Vec<usize>,
    /// The same by pointing alone: the groups over the trackers' rows.
    group_trackers: Vec<usize>,
    normals: Vec<Normal>,
    total: Normal,
    g_ref: DVector<f64>,
}

/// Held-out χ² of one model, batch by batch.
struct Evaluation {
    /// (batch, χ², dof) over the held-out batches of every fold used, in batch order.
    rows: Vec<(usize, f64, usize)>,
    /// The same over the trackers' rows.
    rows_fhst: Vec<(usize, f64, usize)>,
    /// Each fold's fitted vector (None: fold not used).
    g: Vec<Option<DVector<f64>>>,
    skipped: Vec<String>,
    held: Vec<String>,
}

impl Folds<'_> {
    /// The model with the components `free` fitted and the rest held at the reference.
    fn evaluate(&self, free: &[usize]) -> Evaluation {
        let mut held: Vec<Fixed> = Vec::new();
        for (c, comp) in self.components.iter().enumerate() {
            let taken = free.contains(&c);
            for &i in &comp.params {
                match self.fixed.iter().find(|f| f.index == i) {
                    Some(f) if taken => held.push(*f),
                    _ if taken => {}
                    _ => held.push(Fixed {
                        index: i,
                        value: self.g_ref[i],
                        sigma: 0.0,
                    }),
                }
            }
        }
        let all_held = held.len() == self.idx.len();
        let full_sigma: Vec<(usize, f64)> = if all_held {
            Vec::new()
        } else {
            solve_fixed(&self.total, &self.sub, &self.idx, &held).map_or_else(Vec::new, |full| {
                full.idx
                    .iter()
                    .enumerate()
                    .map(|(a, &i)| (i, full.cov[(a, a)].sqrt()))
                    .collect()
            })
        };
        let mut out = Evaluation {
            rows: Vec::new(),
            rows_fhst: Vec::new(),
            g: vec![None; self.normals.len()],
            skipped: Vec::new(),
            held: Vec::new(),
        };
        for (f, held_out) in self.normals.iter().enumerate() {
            if held_out.rows == 0 {
                out.skipped.push(format!("block {}: no batch", f + 1));
                continue;
            }
            let g = if all_held {
                let mut g = self.g_ref.clone();
                for f in &held {
                    g[f.index] = f.value;
                }
                g
            } else {
                let train = self.total.without(held_out);
                let Some((g, at_reference)) = self.fold_fit(&train, &held, &full_sigma) else {
                    out.skipped.push(format!(
                        "block {}: the model is singular on the other blocks",
                        f + 1
                    ));
                    continue;
                };
                if !at_reference.is_empty() {
                    out.held.push(format!(
                        "block {}: {} (the data that determine it are mostly in the block)",
                        f + 1,
                        parameter_names(&self.sub, &at_reference).join(", ")
                    ));
                }
                g
            };
            let in_fold = |b: usize| self.fold[b] == Some(f);
            for (rows, taken) in [
                (&mut out.rows, Rows::All),
                (&mut out.rows_fhst, Rows::Trackers),
            ] {
                let chi2 =
                    batch_quadratic(self.set, &self.sub, &g, &in_fold, Quadratic::Chi2, taken);
                rows.extend(
                    chi2.into_iter()
                        .map(|(b, c, n)| (b, c, n.saturating_sub(NUISANCE))),
                );
            }
            out.g[f] = Some(g);
        }
        out.rows.sort_by_key(|r| r.0);
        out.rows_fhst.sort_by_key(|r| r.0);
        out
    }

    /// The model fitted on a fold's training system, the parameters it does not determine
    /// ([`UNDETERMINED_SIGMA_RATIO`]) held at the reference; also which were held.
    fn fold_fit(
        &self,
        train: &Normal,
        held: &[Fixed],
        full_sigma: &[(usize, f64)],
    ) -> Option<(DVector<f64>, Vec<usize>)> {
        let fit = solve_fixed(train, &self.sub, &self.idx, held)?;
        let undetermined: Vec<usize> = fit
            .idx
            .iter()
            .enumerate()
            .filter(|(_, i)| !held.iter().any(|f| f.index == **i))
            .filter(|(a, i)| {
                full_sigma
                    .iter()
                    .find(|(j, _)| j == *i)
                    .is_some_and(|(_, s)| fit.cov[(*a, *a)].sqrt() > UNDETERMINED_SIGMA_RATIO * s)
            })
            .map(|(_, &i)| i)
            .collect();
        if undetermined.is_empty() {
            return Some((fit.expand(self.sub.total), undetermined));
        }
        let mut more: Vec<Fixed> = held.to_vec();
        more.extend(undetermined.iter().map(|&i| Fixed {
            index: i,
            value: self.g_ref[i],
            sigma: 0.0,
        }));
        let fit = solve_fixed(train, &self.sub, &self.idx, &more)?;
        Some((fit.expand(self.sub.total), undetermined))
    }
}

impl Folds<'_> {
    /// The held-out decrease from `base` to `new` over the batches both evaluated, its
    /// standard error from the noise: with `Δg` the folds' difference of the two models, a
    /// batch's χ² changes by `δ_b = Δgᵀ N_b Δg` in expectation (up if `base` is exact, down if
    /// `new` is) and by `2 √δ_b` σ of noise, so `Σ d_b / (2 √(s² Σ δ_b))` is the held-out
    /// likelihood-ratio z of the two; `s²` (the dispersion over the error groups,
    /// [`dispersion`], at least 1) widens it for noise the σ understate, and the z is then read
    /// through Student's t ([`normal_equivalent`]). Why not batch means alone (the chain's rule): a change
    /// seen in m of its groups cannot get past z ≈ √m there, however large it is.
    fn compare(&self, new: &Evaluation, base: &Evaluation) -> HeldOutTest {
        self.compare_rows(new, base, Rows::All)
    }

    /// [`Self::compare`] over the trackers' rows; `None` when the two models do not differ
    /// there.
    fn compare_trackers(&self, new: &Evaluation, base: &Evaluation) -> Option<HeldOutTest> {
        let t = self.compare_rows(new, base, Rows::Trackers);
        (t.separation > MIN_SEPARATION).then_some(t)
    }

    fn compare_rows(&self, new: &Evaluation, base: &Evaluation, which: Rows) -> HeldOutTest {
        let (new_rows, base_rows, groups_of) = match which {
            Rows::All => (&new.rows, &base.rows, &self.group_all),
            Rows::Trackers => (&new.rows_fhst, &base.rows_fhst, &self.group_trackers),
        };
        // δ_b per batch.
        let mut delta: Vec<(usize, f64)> = Vec::new();
        for (f, (gn, gb)) in new.g.iter().zip(&base.g).enumerate() {
            let (Some(gn), Some(gb)) = (gn, gb) else {
                continue;
            };
            let dg = gn - gb;
            if dg.iter().all(|x| *x == 0.0) {
                continue;
            }
            let in_fold = |b: usize| self.fold[b] == Some(f);
            let info = batch_quadratic(
                self.set,
                &self.sub,
                &dg,
                &in_fold,
                Quadratic::Information,
                which,
            );
            delta.extend(info.into_iter().map(|(b, d, _)| (b, d)));
        }
        delta.sort_by_key(|d| d.0);
        // (χ²_new, χ²_base, δ, segment) of the batches both evaluated, in batch order.
        let mut pairs: Vec<(f64, f64, f64, usize)> = Vec::new();
        let (mut j, mut k) = (0usize, 0usize);
        for r in new_rows {
            while j < base_rows.len() && base_rows[j].0 < r.0 {
                j += 1;
            }
            while k < delta.len() && delta[k].0 < r.0 {
                k += 1;
            }
            if let Some(o) = base_rows.get(j).filter(|o| o.0 == r.0) {
                let d = delta.get(k).filter(|d| d.0 == r.0).map_or(0.0, |d| d.1);
                pairs.push((r.1, o.1, d, groups_of.get(r.0).copied().unwrap_or(0)));
            }
        }
        let separation: f64 = pairs.iter().map(|p| p.2).sum();
        let decrease: f64 = pairs.iter().map(|p| p.1 - p.0).sum();
        let (noise_scale, groups) = dispersion(&pairs, decrease, separation);

        let standard_error = 2.0 * (noise_scale * separation).sqrt();
        let z_raw = decrease / standard_error;
        let (a, b): (Vec<f64>, Vec<f64>) = pairs.iter().map(|p| (p.0, p.1)).unzip();
        HeldOutTest {
            chi2_decrease: decrease,
            separation,
            noise_scale,
            standard_error,
            // One group of shared errors cannot tell the change from the error it shares.
            z: if separation > MIN_SEPARATION && groups >= 2 {
                normal_equivalent(z_raw, noise_scale, groups)
            } else {
                f64::NAN
            },
            groups,
            batch_means_z: paired_improvement(&a, &b).z,
            batches: pairs.len(),
        }
    }
}

/// The attitude segment of each batch: a new one at every change of rate mode (a slew starts
/// or ends) and after a gap of more than [`SEGMENT_GAP_S`]. The errors the tables leave are
/// shared by a whole segment: a Sun position's transfer-function error by every FSS sample of
/// a hold, a star's catalog error by its track, a tracker's field error by the stars of one
/// pointing.
fn attitude_segments(set: &MeasurementSet) -> Vec<usize> {
    let mut out = Vec::with_capacity(set.batches.len());
    let mut id = 0usize;
    let mut last: Option<(bool, f64)> = None;
    for b in &set.batches {
        if let Some((rate, t)) = last {
            if rate != b.high_rate || b.t_center_s - t > SEGMENT_GAP_S {
                id += 1;
            }
        }
        last = Some((b.high_rate, b.t_center_s));
        out.push(id);
    }
    out
}

/// Largest gap between batches of one attitude segment (s).
const SEGMENT_GAP_S: f64 = 600.0;

/// Two holds closer than this (deg) in inertial pointing see the same stars and share their
/// errors ([`error_groups`]).
const SHARED_POINTING_DEG: f64 = 1.0;

/// The groups of the dispersion: the attitude segments ([`attitude_segments`]), with the holds
/// that share their errors merged. A plan that returns to one attitude between excursions
/// revisits the same stars, and one that moves the Sun by a few degrees keeps it in the same
/// part of the FSS field: the catalog errors of those stars, and the transfer-function error
/// of that part of the field (smooth over the field: scale, cross and cubic terms), are one
/// draw, not one per hold. Counted as independent they let an FSS2 alignment that fits the
/// transfer-function error of its one field cell pass the gate at z 3.05 over 9 "groups" and
/// fly 5.5″ worse than calibrate's (effects table, `catalog` seed 2; the simulator's
/// three-rate plan, 3 of 3). Holds merge when their inertial pointing differs by less than
/// [`SHARED_POINTING_DEG`] or, with `fss_cells`, when an FSS sees the Sun within a field cell's
/// width ([`FSS_CELL_DEG`], calibrate's unit of the shared FSS error) in both, by their mean
/// directions (distance, not fixed cells: a patch of a few degrees straddles a cell boundary
/// half the time). Slews stay groups of
/// their own: they sweep the fields, and merging through them would join every hold.
fn error_groups(set: &MeasurementSet, fss_cells: bool) -> Vec<usize> {
    let segment = attitude_segments(set);
    let n_seg = segment.last().map_or(0, |s| s + 1);
    let mut first = vec![usize::MAX; n_seg];
    let mut last = vec![0usize; n_seg];
    for (b, &g) in segment.iter().enumerate() {
        first[g] = first[g].min(b);
        last[g] = b;
    }
    let hold: Vec<bool> = (0..n_seg)
        .map(|g| first[g] != usize::MAX && !set.batches[first[g]].high_rate)
        .collect();
    let mut parent: Vec<usize> = (0..n_seg).collect();
    let root = |parent: &mut Vec<usize>, mut i: usize| {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    };
    let join = |parent: &mut Vec<usize>, i: usize, j: usize| {
        let (ri, rj) = (root(parent, i), root(parent, j));
        parent[ri] = rj;
    };
    // The same part of one FSS's field: mean Sun directions within a cell's width.
    if fss_cells {
        let mut sun = vec![[Vector3::<f64>::zeros(); 2]; n_seg];
        for m in set.meas.iter().filter(|m| m.sensor >= 2 && !m.outlier) {
            if let Some(&g) = segment.get(m.batch) {
                sun[g][m.sensor - 2] +=
                    Vector3::new(m.ang[0].tan(), m.ang[1].tan(), 1.0).normalize();
            }
        }
        let cos_cell = FSS_CELL_DEG.to_radians().cos();
        for i in (0..n_seg).filter(|&g| hold[g]) {
            for j in (0..i).filter(|&g| hold[g]) {
                let shared = (0..2).any(|k| {
                    let (a, b) = (sun[i][k], sun[j][k]);
                    a.norm() > 0.0 && b.norm() > 0.0 && a.normalize().dot(&b.normalize()) > cos_cell
                });
                if shared {
                    join(&mut parent, i, j);
                }
            }
        }
    }
    // The same pointing: cos θ = (tr(Rᵢ Rⱼᵀ) − 1)/2 between the middle batches.
    let pointing: Vec<Option<Matrix3<f64>>> = (0..n_seg)
        .map(|g| {
            hold[g]
                .then(|| set.batches.get((first[g] + last[g]) / 2))
                .flatten()
                .map(|b| b.m_acs_from_eci)
        })
        .collect();
    let cos_lim = SHARED_POINTING_DEG.to_radians().cos();
    for i in 0..n_seg {
        let Some(ri) = pointing[i] else { continue };
        for j in 0..i {
            let Some(rj) = pointing[j] else { continue };
            if ((ri * rj.transpose()).trace() - 1.0) / 2.0 > cos_lim {
                join(&mut parent, i, j);
            }
        }
    }
    segment.iter().map(|&g| root(&mut parent, g)).collect()
}

/// The σ² scale of the held-out differences, from their own scatter, and the number of groups
/// it came from: over the error groups ([`error_groups`]), `d_g = λ δ_g + e_g` with
/// `var e_g = 4 s² δ_g`; `λ̂ = Σd/Σδ` and `s² = Σ (d_g − λ̂ δ_g)² / (4 δ_g) / (G − 1)` over the
/// groups that see the change. At least 1 (the σ of the measurements are a floor). This is the
/// quasi-likelihood dispersion of the held-out likelihood ratio: a change seen in a few groups
/// keeps its size (unlike batch means, where it cannot pass z ≈ √m), and errors the σ do not
/// hold widen it as they scatter. Why segments, not groups of ten batches: an error shared by
/// a whole hold (a Sun position's transfer-function error, 16 min to an orbit) is common to
/// every group inside it, and groups shorter than the hold counted it as independent draws —
/// on 7 of the 39 effects-table runs the FSS2 alignment was taken at z > 3 and came out
/// 6–8″ worse than calibrate's (`docs/investigations.md`).
fn dispersion(pairs: &[(f64, f64, f64, usize)], decrease: f64, separation: f64) -> (f64, usize) {
    if separation <= 0.0 {
        return (1.0, 0);
    }
    let lambda = decrease / separation;
    let mut by_group: BTreeMap<usize, (f64, f64)> = BTreeMap::new();
    for p in pairs {
        let e = by_group.entry(p.3).or_insert((0.0, 0.0));
        e.0 += p.1 - p.0;
        e.1 += p.2;
    }
    let mut sum = 0.0;
    let mut used = 0usize;
    for &(d, delta) in by_group.values() {
        if delta > 1e-9 * separation {
            sum += (d - lambda * delta).powi(2) / (4.0 * delta);
            used += 1;
        }
    }
    if used < 2 {
        return (1.0, used);
    }
    ((sum / (used - 1) as f64).max(1.0), used)
}

/// The z of a held-out decrease whose noise scale was estimated from `groups` groups, as the
/// normal deviate of the same tail probability: Student's t with `groups − 1` degrees of
/// freedom when the scale came from the data (above its floor of 1), the z itself when the
/// measurement σ set it. With a dozen holds, an estimated scale is itself uncertain by ±40 %;
/// with two groups it rests on one degree of freedom, and a z of 5 is a tail of 6 % (the
/// simulator's three-rate plan took an FSS2 alignment at "z 5.1" from two groups, 4.6″ worse
/// than calibrate's, before two groups were converted too).
fn normal_equivalent(z: f64, noise_scale: f64, groups: usize) -> f64 {
    use statrs::distribution::{ContinuousCDF, Normal as Gauss, StudentsT};
    if !z.is_finite() || noise_scale <= 1.0 || groups < 2 {
        return z;
    }
    let (Ok(t), Ok(n)) = (
        StudentsT::new(0.0, 1.0, (groups - 1) as f64),
        Gauss::new(0.0, 1.0),
    ) else {
        return z;
    };
    let tail = t.sf(z.abs());
    if tail <= 0.0 || tail >= 0.5 {
        return z;
    }
    n.inverse_cdf(1.0 - tail).copysign(z)
}

/// Validate the flight model (`flight_idx` of `layout`, with the parameters `fixed` held at
/// their values) against the reference alignments `reference_arcsec` (the joint fit's
/// alignment parameters of the table compared with, relative to the alignments the
/// measurements were built with; effect terms zero), described by `reference`: the forward
/// selection of the module doc.
#[must_use]
pub fn validate_flight_tables(
    set: &MeasurementSet,
    layout: &Layout,
    flight_idx: &[usize],
    fixed: &[Fixed],
    reference_arcsec: &[f64; N_ALIGN],
    reference: &str,
) -> FlightTableValidation {
    let (sub, idx, components) = sub_layout(layout, flight_idx);
    let fixed: Vec<Fixed> = fixed
        .iter()
        .filter_map(|f| {
            let p = flight_idx.iter().position(|&i| i == f.index)?;
            Some(Fixed {
                index: idx[p],
                ..*f
            })
        })
        .collect();
    let k = MAX_FOLDS;
    let fold = folds_of_batches(set, k);
    let normals: Vec<Normal> = (0..k)
        .into_par_iter()
        .map(|f| accumulate(set, &sub, &|b| fold[b] == Some(f)))
        .collect();
    let total = normals
        .iter()
        .skip(1)
        .fold(normals[0].clone(), |acc, n| acc.sum(n));
    let mut g_ref = DVector::zeros(sub.total);
    for (i, v) in reference_arcsec.iter().enumerate() {
        g_ref[i] = *v;
    }
    let folds = Folds {
        set,
        sub,
        idx,
        fixed,
        components,
        fold,
        group_all: error_groups(set, true),
        group_trackers: error_groups(set, false),
        normals,
        total,
        g_ref,
    };
    // Forward selection from the reference.
    let reference_eval = folds.evaluate(&[]);
    let mut taken: Vec<usize> = Vec::new();
    let mut taken_tests: Vec<ComponentTest> = Vec::new();
    let mut current = folds.evaluate(&[]);
    let mut last_round: Vec<(usize, HeldOutTest, Option<HeldOutTest>)> = Vec::new();
    while taken.len() < folds.components.len() {
        let candidates: Vec<usize> = (0..folds.components.len())
            .filter(|c| !taken.contains(c))
            .collect();
        type Tested = (usize, HeldOutTest, Option<HeldOutTest>, Evaluation);
        let results: Vec<Tested> = candidates
            .par_iter()
            .map(|&c| {
                let mut free = taken.clone();
                free.push(c);
                let e = folds.evaluate(&free);
                let all = folds.compare(&e, &current);
                let trackers = folds.compare_trackers(&e, &current);
                (c, all, trackers, e)
            })
            .collect();
        last_round = results
            .iter()
            .map(|(c, imp, t, _)| (*c, *imp, *t))
            .collect();
        // A change to a tracker's table is judged on the trackers' own held-out χ² (they give
        // the flight attitude): the FSS rows are taken against the trackers' batch attitude
        // with white weights, so a Sun-sensor error the model lacks can pull a tracker's
        // alignment alike in every block, and their dispersion can hide a tracker's time tag
        // the trackers confirm at z 27 (`docs/investigations.md`, the segment-grouped gate).
        // All rows must still not prefer the reference (z > 0). Other components: all rows.
        let decisive = |c: usize, imp: &HeldOutTest, t: &Option<HeldOutTest>| -> f64 {
            if !folds.components[c].trackers {
                return imp.z;
            }
            match t {
                Some(t) if imp.z > 0.0 => t.z,
                Some(_) => f64::NAN,
                None => imp.z,
            }
        };
        let Some((c, imp, trackers, e, z)) = results
            .into_iter()
            .map(|(c, imp, t, e)| {
                let z = decisive(c, &imp, &t);
                (c, imp, t, e, z)
            })
            .filter(|r| r.4.is_finite())
            .max_by(|a, b| a.4.total_cmp(&b.4))
        else {
            break;
        };
        if z <= MIN_IMPROVEMENT_Z {
            break;
        }
        taken.push(c);
        taken_tests.push(ComponentTest {
            component: folds.components[c].name.clone(),
            improvement: imp,
            trackers,
        });
        last_round.retain(|(d, _, _)| *d != c);
        current = e;
    }
    let not_taken: Vec<ComponentTest> = last_round
        .iter()
        .filter(|(c, _, _)| !taken.contains(c))
        .map(|(c, imp, t)| ComponentTest {
            component: folds.components[*c].name.clone(),
            improvement: *imp,
            trackers: *t,
        })
        .collect();
    let taken_params: Vec<usize> = taken
        .iter()
        .flat_map(|&c| folds.components[c].params.iter().copied())
        .filter_map(|i| folds.idx.iter().position(|&j| j == i))
        .map(|p| flight_idx[p])
        .collect();
    summary(
        &folds,
        reference,
        &reference_eval,
        &current,
        taken_tests,
        not_taken,
        taken_params,
    )
}

fn summary(
    folds: &Folds<'_>,
    reference: &str,
    reference_eval: &Evaluation,
    current: &Evaluation,
    taken: Vec<ComponentTest>,
    not_taken: Vec<ComponentTest>,
    taken_params: Vec<usize>,
) -> FlightTableValidation {
    let improvement = folds.compare(current, reference_eval);
    let chi2_new: f64 = current.rows.iter().map(|r| r.1).sum();
    let chi2_ref: f64 = reference_eval.rows.iter().map(|r| r.1).sum();
    let dof: usize = current.rows.iter().map(|r| r.2).sum();
    let ms_text = |c: f64| {
        if dof > 0 {
            format!("{:.3}", c / dof as f64)
        } else {
            "– (no degrees of freedom left: the batches hold too few samples)".to_owned()
        }
    };
    let list = |t: &[ComponentTest]| {
        t.iter()
            .map(|c| {
                let trackers = c
                    .trackers
                    .map_or_else(String::new, |t| format!(", trackers' rows {}", t.z_text()));
                format!(
                    "{} ({}, batch means {:.1}{trackers})",
                    c.component,
                    c.improvement.z_text(),
                    c.improvement.batch_means_z
                )
            })
            .collect::<Vec<_>>()
            .join(", ")
    };
    let passed = !taken.is_empty();
    let mut reason = if passed {
        format!(
            "taken: {}; together they lower the held-out χ² by {:.0} ± {:.0} (z {:.1}) over {} batches in {} blocks; χ²/dof {} against {} ({reference})",
            list(&taken),
            improvement.chi2_decrease,
            improvement.standard_error,
            improvement.z,
            current.rows.len(),
            folds.normals.len() - current.skipped.len(),
            ms_text(chi2_new),
            ms_text(chi2_ref),
        )
    } else {
        format!(
            "no part of diagnose's tables lowers the held-out χ² by more than {MIN_IMPROVEMENT_Z} standard errors against {reference} (and, for a part the trackers see, the trackers' own) ({} batches in {} blocks, χ²/dof {})",
            reference_eval.rows.len(),
            folds.normals.len() - reference_eval.skipped.len(),
            ms_text(chi2_ref),
        )
    };
    if !not_taken.is_empty() {
        reason.push_str(&format!("; left at the reference: {}", list(&not_taken)));
    }
    FlightTableValidation {
        reference: reference.to_owned(),
        folds: folds.normals.len(),
        folds_skipped: current.skipped.clone(),
        held_at_reference: current.held.clone(),
        chi2: HeldOutChi2::new(current.rows.len(), dof, chi2_new, chi2_ref, improvement),
        taken,
        not_taken,
        taken_params,
        passed,
        reason,
    }
}
