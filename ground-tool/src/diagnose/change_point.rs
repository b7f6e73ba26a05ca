//! # An alignment that moved once: the change-point scan (issue 22)
//!
//! **Why.** A sensor mount that slips, a tracker re-seated, a thermal snap: the alignment is
//! one rotation before a time and another after it. No smooth form describes that — forced
//! onto the orbit-periodic or thermal forms, a 14″ FHST2 step took 40–60″ orbit amplitudes,
//! and with only the lack-of-fit tests it was reported as unexplained time structure while
//! the tables written from the whole span sat between the two alignments. The step is a
//! library candidate ([`super::effects::EffectKind::AlignmentStep`]): three rotation
//! parameters (ACS, arcsec, the alignment columns' convention `M' = Rot(θ) M`) acting on the
//! sensor's data from the step time on.
//!
//! **The scan.** The step time is a nonlinear parameter. It is scanned over every batch
//! boundary of the sensor's data (leaving at least [`MIN_SIDE`] measurements on each side),
//! on the preliminary residuals (alignments and batch attitudes fitted): at each position the
//! generalised least-squares gain of the step's three columns beside a constant rotation of
//! the sensor (a 6×6 system from suffix sums, O(n) for the whole scan). The best position is
//! offered to the search, which fits it with everything else; its F-test p-value is multiplied
//! by the number of positions scanned (Bonferroni over the scan: honest for the maximum over
//! them, conservative because neighbouring positions are correlated), and the BIC counts the
//! time as one more parameter. A step happens once, so the halves test does not apply to it
//! (the half without it cannot fit it).
//!
//! **Which tracker moved.** The batch attitudes are free, so the trackers alone see only their
//! relative rotation: a step of FHST1 by θ and one of FHST2 by −θ at the same time fit their
//! rows alike. What tells them apart is the absolute attitude the Sun sensors give, whose
//! field-position error is shared by every sample at one Sun position and is not in their
//! white weights. [`attribution_notes`] compares the accepted step with its twin on the other
//! tracker on both systems and says so when the trackers cannot choose (the simulator's FHST1
//! step was named on FHST2 in 3 of 3 seeds with the FSS2 rows preferring it by Δχ² 1–110).

use super::effects::{Effect, EffectKind};
use super::fit::{accumulate, accumulate_fhst_only, indices, solve_fixed, Layout, Normal};
use super::measurements::{MeasurementSet, SENSOR_NAMES};
use super::search_result::SearchResult;
use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};

/// Fewest measurements on each side of a scanned step.
pub const MIN_SIDE: usize = 30;

/// The scan's best position for one sensor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepScan {
    /// Step time (s since the first frame): the first measurement after the step.
    pub t_step_s: f64,
    /// Positions scanned (the Bonferroni factor of the step's p-value).
    pub positions: usize,
    /// χ² gain of the step at the best position, on the preliminary residuals.
    pub delta_chi2: f64,
}

/// Scan `sensor`'s data for an alignment step on the residuals `resid` (arcsec, one pair per
/// measurement of `set`). `None` when the sensor has too few measurements for two sides.
#[must_use]
pub fn alignment_step(set: &MeasurementSet, resid: &[[f64; 2]], sensor: usize) -> Option<StepScan> {
    // (time, batch, AᵀWA, AᵀWr) per measurement, in time order.
    let mut rows: Vec<(f64, usize, Matrix3<f64>, Vector3<f64>)> = set
        .meas
        .iter()
        .zip(resid)
        .filter(|(m, _)| m.sensor == sensor && !m.outlier && m.sigma > 0.0)
        .map(|(m, r)| {
            let w = 1.0 / (m.sigma * m.sigma);
            let a = nalgebra::Matrix2x3::from_columns(&[0, 1, 2].map(|ax| {
                let mut e = Vector3::zeros();
                e[ax] = 1.0;
                -(m.jm * m.b_acs.cross(&e))
            }));
            let rv = nalgebra::Vector2::new(r[0], r[1]);
            (
                m.t_s,
                m.batch,
                a.transpose() * a * w,
                a.transpose() * rv * w,
            )
        })
        .collect();
    if rows.len() < 2 * MIN_SIDE {
        return None;
    }
    rows.sort_by(|a, b| a.0.total_cmp(&b.0));
    let n_all: Matrix3<f64> = rows.iter().map(|r| r.2).sum();
    let b_all: Vector3<f64> = rows.iter().map(|r| r.3).sum();
    let base_gain = n_all
        .try_inverse()
        .map_or(0.0, |inv| b_all.dot(&(inv * b_all)));
    // Suffix sums from the end; a position is the first measurement of a batch.
    let mut n_s = Matrix3::zeros();
    let mut b_s = Vector3::zeros();
    let mut best: Option<(f64, f64)> = None;
    let mut positions = 0;
    for i in (MIN_SIDE..rows.len()).rev() {
        n_s += rows[i].2;
        b_s += rows[i].3;
        let new_batch = rows[i].1 != rows[i - 1].1;
        if !new_batch || rows.len() - i < MIN_SIDE {
            continue;
        }
        positions += 1;
        let mut n6 = Matrix6::zeros();
        n6.fixed_view_mut::<3, 3>(0, 0).copy_from(&n_all);
        n6.fixed_view_mut::<3, 3>(0, 3).copy_from(&n_s);
        n6.fixed_view_mut::<3, 3>(3, 0).copy_from(&n_s);
        n6.fixed_view_mut::<3, 3>(3, 3).copy_from(&n_s);
        let mut b6 = Vector6::zeros();
        b6.fixed_rows_mut::<3>(0).copy_from(&b_all);
        b6.fixed_rows_mut::<3>(3).copy_from(&b_s);
        let Some(ch) = n6.cholesky() else {
            continue;
        };
        let gain = b6.dot(&ch.solve(&b6)) - base_gain;
        if best.is_none_or(|(_, g)| gain > g) {
            best = Some((rows[i].0, gain));
        }
    }
    best.map(|(t_step_s, delta_chi2)| StepScan {
        t_step_s,
        positions,
        delta_chi2,
    })
}

/// The step candidates: for every sensor with data on both sides, an alignment step at the
/// scan's best position ([`alignment_step`]) on the residuals `resid`, or at the time in
/// `forced` (time, positions of the first scan) where it gives one.
#[must_use]
pub fn step_effects(
    set: &MeasurementSet,
    resid: &[[f64; 2]],
    forced: Option<[Option<(f64, usize)>; 4]>,
) -> Vec<Effect> {
    (0..4)
        .filter_map(|s| {
            let (t, positions) = match forced.and_then(|f| f[s]) {
                Some(tp) => tp,
                None => {
                    let scan = alignment_step(set, resid, s)?;
                    (scan.t_step_s, scan.positions)
                }
            };
            if std::env::var_os("DIAGNOSE_DEBUG").is_some() {
                crate::note!(
                    "alignment step candidate sensor {s}: t {t:.0} s over {positions} positions"
                );
            }
            Some(Effect::alignment_step(s, t, positions))
        })
        .collect()
}

/// The accepted steps of `res` scanned again on its final residuals with each step's own
/// contribution added back (time, positions of the first scan), per sensor.
#[must_use]
pub fn rescan_accepted_steps(
    set: &MeasurementSet,
    res: &SearchResult,
) -> [Option<(f64, usize)>; 4] {
    let mut out = [None; 4];
    for &i in &res.added {
        let e = &res.layout.effects[i];
        let (EffectKind::AlignmentStep, Some(s)) = (e.kind, e.sensor) else {
            continue;
        };
        let start = res.layout.range(i).start;
        let x: Vec<f64> = (0..3)
            .map(|k| res.final_fit.param(start + k).map_or(0.0, |(v, _)| v))
            .collect();
        let mut cols = Vec::new();
        let resid: Vec<[f64; 2]> = set
            .meas
            .iter()
            .zip(&res.after.resid)
            .map(|(m, r)| {
                cols.clear();
                e.columns(m, &|_| None, &mut cols);
                let mut v = *r;
                for (k, c) in &cols {
                    v[0] += c[0] * x[*k];
                    v[1] += c[1] * x[*k];
                }
                v
            })
            .collect();
        out[s] = alignment_step(set, &resid, s)
            .map(|scan| (scan.t_step_s, e.scan_positions))
            .or(e.step_time_s.map(|t| (t, e.scan_positions)));
    }
    out
}

/// χ² difference below which the trackers' rows do not choose between a step on one tracker
/// and its twin on the other (the χ² 9 of the other "same numbers, two names" checks).
pub const ATTRIBUTION_CHI2: f64 = 9.0;

/// For every accepted alignment step of a tracker: the same model with the step on the other
/// tracker instead, at the same time, fitted on the trackers' rows and on all rows. When the
/// trackers' rows differ by less than [`ATTRIBUTION_CHI2`] (with free batch attitudes they
/// nearly always do), a note says that which tracker moved rests on the Sun sensors alone
/// (module doc), with both χ² differences.
#[must_use]
pub fn attribution_notes(set: &MeasurementSet, res: &SearchResult) -> Vec<String> {
    let model: Vec<usize> = res.baseline.iter().chain(&res.added).copied().collect();
    let mut notes = Vec::new();
    for &a in &res.added {
        let step = &res.layout.effects[a];
        let (Some(sensor @ 0..=1), Some(t_step)) = (step.sensor, step.step_time_s) else {
            continue;
        };
        if step.kind != EffectKind::AlignmentStep {
            continue;
        }
        // The twin appended: the existing parameters keep their places (and `res.fixed`).
        let mut effects = res.layout.effects.clone();
        effects.push(Effect::alignment_step(
            1 - sensor,
            t_step,
            step.scan_positions,
        ));
        let layout = Layout::new(effects);
        let twin = layout.effects.len() - 1;
        let swapped: Vec<usize> = model
            .iter()
            .map(|&i| if i == a { twin } else { i })
            .collect();
        let trackers = accumulate_fhst_only(set, &layout);
        let all = accumulate(set, &layout, &|_| true);
        let chi2 = |normal: &Normal, effects: &[usize]| {
            solve_fixed(normal, &layout, &indices(&layout, effects), &res.fixed).map(|f| f.chi2)
        };
        let (Some(t_a), Some(t_b), Some(f_a), Some(f_b)) = (
            chi2(&trackers, &model),
            chi2(&trackers, &swapped),
            chi2(&all, &model),
            chi2(&all, &swapped),
        ) else {
            continue;
        };
        let (d_trk, d_all) = (t_b - t_a, f_b - f_a);
        if d_trk.abs() >= ATTRIBUTION_CHI2 {
            continue;
        }
        let (this, other) = (SENSOR_NAMES[sensor], SENSOR_NAMES[1 - sensor]);
        let trackers_say = format!(
            "which tracker moved is not determined by the trackers (the same step on {other} fits their rows within Δχ² {d_trk:.1}: only their relative rotation is)"
        );
        notes.push(if d_all.abs() < ATTRIBUTION_CHI2 {
            format!(
                "{}: {trackers_say}, nor by the Sun sensors (Δχ² {d_all:.1} over all rows): a step between {this} and {other}, named on {this} because its scanned time fit better; do not read it as {this}'s mount",
                step.label()
            )
        } else {
            format!(
                "{}: {trackers_say}; {this} is chosen by the Sun sensors' rows (Δχ² {d_all:.1} over all rows), whose field-position error is shared by every sample at one Sun position and not in their weights",
                step.label()
            )
        });
    }
    notes
}
