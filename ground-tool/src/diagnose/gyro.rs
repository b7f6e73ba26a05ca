//! # Gyro-side effects: bias drift, thermal bias, scale-factor asymmetry
//!
//! The batch attitudes of the sensor-side fit (FHST batches, corrected by the joint fit) are
//! attitude measurements every ≤ 60 s. Between two of them the calibrated gyro predicts the
//! rotation; the difference is the gyro's error (docs/algorithms.md §7–§8).
//!
//! **Bias history.** For consecutive hold batches (low rate, contiguous), the bias error
//! relative to a constant reference `b_ref` is `y = −z/Δt` with
//! `z = rotvec(A_{k+1} (Φ A_k)ᵀ)` (Φ propagated with `b_ref`). Per axis, `y` is fitted by
//! generalised least squares with the covariance of the declared bias random walk
//! (`σ_u² min(tᵢ, tⱼ)`), the angle random walk, and each sample's batch attitude errors
//! (consecutive samples share a batch, but that anti-correlation is left out on purpose:
//! [`Whitener`] says why), whitened by a Kalman filter in O(n). Candidates: a **ramp**, an **exponential transient**
//! `A e^{−t/τ}` (τ grid-searched over 29 values, counted as one more parameter, its p-value
//! × 29 for the scan), a **step** at an unknown
//! time (the position scanned over 39 sample indices, counted as one more parameter, its
//! p-value × 39 for the scan) and a **thermal bias** `k ΔT_IRU`, each with one parameter per
//! ACS axis, kept with the same evidence rules as the
//! sensor side (F-test, ΔBIC > 10, halves within 3σ).
//!
//! **Scale-factor asymmetry.** For every slew, the last hold batch before and the first after
//! give `z = S x` (the Davenport/Keat transition recursion, §7) with a common bias correction
//! and the full δM (on top of IRUCAL's) as the baseline and, as the candidate, a rectified term
//! `a_j |Δθ_j|` per ACS axis (a channel whose scale is `1 + a` for positive and `1 − a` for
//! negative rates over-reads by `a |Δθ|` in both directions). The IRU mode-ratio error is not
//! separable from the scale factor when all slews run in high-rate mode (not a candidate).

use super::fit::PostFit;
use super::gyro_data::{batch_attitude, delta_bic, BatchAttitude, HoldBias, SlewInput};
pub use super::gyro_data::{GyroAnalysis, GyroConfig, GyroFrame, GyroInput, GyroLeftover};
use super::measurements::MeasurementSet;
use super::search::Evidence;
use super::stats::{chi2_sf, f_sf};
use super::Detected;
use fsw_core::attitude::{rot, rotvec_from_rot};
use fsw_core::units::{ARCSEC_PER_RAD, RAD_PER_ARCSEC};
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use std::collections::BTreeMap;

/// A gyro attitude-difference sample.
#[derive(Clone, Debug)]
struct BiasSample {
    t_s: f64,
    dt_s: f64,
    /// Bias error (arcsec/s), ACS.
    y: Vector3<f64>,
    /// Attitude variance (arcsec²) of the start and end batch, per axis.
    var_start: Vector3<f64>,
    var_end: Vector3<f64>,
    /// The end batch is the next sample's start batch.
    chained: bool,
    /// IRU temperature deviation (°C) at the mid time.
    dtemp_iru: f64,
    /// The backup triad produced the gyro steps (each triad has its own bias).
    backup: bool,
}

/// RMS over the samples of the term `est[axis] × column(sample)` (column centred), norm over
/// the three axes: the size of a bias-history candidate.
fn term_rms(samples: &[BiasSample], column: &dyn Fn(&BiasSample) -> f64, est: &[f64]) -> f64 {
    let n = samples.len().max(1) as f64;
    let cols: Vec<f64> = samples.iter().map(column).collect();
    let mean = cols.iter().sum::<f64>() / n;
    let spread = (cols.iter().map(|c| (c - mean).powi(2)).sum::<f64>() / n).sqrt();
    spread * est.iter().map(|e| e * e).sum::<f64>().sqrt()
}

fn batch_attitudes(set: &MeasurementSet, post: &PostFit) -> Vec<BatchAttitude> {
    set.batches
        .iter()
        .enumerate()
        .map(|(i, b)| {
            if !b.usable {
                return None;
            }
            let (a, cov) = post.batch_nuisance(i)?;
            let dtheta = Vector3::new(a[0], a[1], a[2]) * RAD_PER_ARCSEC;
            let var = Vector3::new(cov[(0, 0)], cov[(1, 1)], cov[(2, 2)]);
            Some(Box::new((rot(&dtheta) * b.m_acs_from_eci, var)))
        })
        .collect()
}

fn propagate(input: &GyroInput<'_>, from: usize, to: usize, bias: &Vector3<f64>) -> Matrix3<f64> {
    let mut m = Matrix3::identity();
    for k in from + 1..=to {
        let f = &input.frames[k];
        if let Some(g) = f.gyro {
            let phi = (Matrix3::identity() + input.delta_m(f)) * g.dtheta_acs_rad - bias * g.dt_s;
            m = rot(&phi) * m;
        }
    }
    m
}

/// The whitening of a run of bias samples, per axis: `L⁻¹ z` for the covariance `C = L Lᵀ`
/// of the samples (the declared bias random walk `σ_u² min(tᵢ, tⱼ)`, the angle random walk,
/// and the batch attitude errors).
///
/// Chained samples (the end batch of one is the start batch of the next) share an attitude
/// error, which makes them anti-correlated; the analysis does **not** model that
/// ([`MODEL_CHAINED_ERRORS`]): the differenced attitude error then has almost no power at low
/// frequency, and the GLS takes a slow bias structure (a step, a thermal term) as measured far
/// better than the data measure it, because the batch attitude errors are not independent
/// from batch to batch (the same stars, the same tracker systematic through a hold). With the
/// anti-correlation, 5 of 20 clean runs (`scenarios/undeclared/false_alarm.sh 20 100`) named a
/// gyro bias step or a thermal bias; without it, 0 of 20 (`docs/investigations.md`).
///
/// `L⁻¹ z` is the sequence of normalised innovations of `z` under that model (Cholesky in
/// sample order is sequential conditioning), so it is computed by a three-state Kalman filter
/// over the samples (the walk's bias `b`, the start attitude error `α`, the end attitude
/// error `β`: `zᵢ = bᵢ + (βᵢ − αᵢ)/Δtᵢ + vᵢ`, `αᵢ₊₁ = βᵢ` when chained) whose gains do not
/// depend on the data: O(n) memory and time per column instead of a dense n² factor (six
/// months give 2,529 samples: 51 MB and 5·10⁹ operations per factor, nine factors).
struct Whitener {
    axes: [Vec<WhitenStep>; 3],
}

/// Whether the whitening models the shared attitude error of chained samples (see
/// [`Whitener`]: it does not).
const MODEL_CHAINED_ERRORS: bool = false;

/// One sample's step of the whitening filter (per axis).
#[derive(Clone, Copy, Debug)]
struct WhitenStep {
    /// The start attitude error is the previous sample's end error (chained).
    chained_from_previous: bool,
    /// Gain on `[b, α, β]`.
    gain: [f64; 3],
    /// `1/Δt` (the measurement is `b − α/Δt + β/Δt`).
    inv_dt: f64,
    /// `√S`, the innovation's σ.
    sqrt_s: f64,
}

impl Whitener {
    /// `None` when an innovation variance is not positive (the covariance is not).
    /// `chained`: model the shared attitude error of chained samples.
    fn new(samples: &[BiasSample], cfg: &GyroConfig, chained: bool) -> Option<Self> {
        let t0 = samples.first()?.t_s;
        let sigma_u = cfg.rrw_rad_per_s15 * ARCSEC_PER_RAD;
        let sigma_v = cfg.arw_rad_per_sqrt_s * ARCSEC_PER_RAD;
        let mut axes: [Vec<WhitenStep>; 3] = Default::default();
        for (axis, steps) in axes.iter_mut().enumerate() {
            steps.reserve_exact(samples.len());
            // Covariance of [b, β of the previous sample].
            let (mut p_bb, mut p_bbeta, mut p_betabeta) = (0.0, 0.0, 0.0);
            let mut t_prev = t0;
            let mut previous_chained = false;
            for s in samples {
                p_bb += sigma_u * sigma_u * (s.t_s - t_prev).max(0.0);
                t_prev = s.t_s;
                // [b, α, β] before the measurement.
                let (p_ba, p_aa) = if previous_chained {
                    (p_bbeta, p_betabeta)
                } else {
                    (0.0, s.var_start[axis])
                };
                let p = Matrix3::new(
                    p_bb,
                    p_ba,
                    0.0, //
                    p_ba,
                    p_aa,
                    0.0, //
                    0.0,
                    0.0,
                    s.var_end[axis],
                );
                let inv_dt = 1.0 / s.dt_s;
                let h = Vector3::new(1.0, -inv_dt, inv_dt);
                let ph = p * h;
                let var = h.dot(&ph) + sigma_v * sigma_v * inv_dt;
                if !(var > 0.0) {
                    return None;
                }
                let k = ph / var;
                let p = p - k * ph.transpose();
                steps.push(WhitenStep {
                    chained_from_previous: previous_chained,
                    gain: [k[0], k[1], k[2]],
                    inv_dt,
                    sqrt_s: var.sqrt(),
                });
                (p_bb, p_bbeta, p_betabeta) = (p[(0, 0)], p[(0, 2)], p[(2, 2)]);
                previous_chained = chained && s.chained;
            }
        }
        Some(Self { axes })
    }

    /// `L⁻¹ z` for the axis: the normalised innovations of `z` under the samples' model.
    fn whiten(&self, axis: usize, z: impl Iterator<Item = f64>) -> Vec<f64> {
        let mut out = Vec::with_capacity(self.axes[axis].len());
        // Mean of [b, β of the previous sample].
        let (mut b, mut beta) = (0.0, 0.0);
        for (step, zi) in self.axes[axis].iter().zip(z) {
            let alpha = if step.chained_from_previous {
                beta
            } else {
                0.0
            };
            let nu = zi - (b - alpha * step.inv_dt);
            out.push(nu / step.sqrt_s);
            b += step.gain[0] * nu;
            beta = step.gain[2] * nu;
        }
        out
    }

    /// The whitened design matrix (columns as `x`'s).
    fn whiten_columns(&self, axis: usize, x: &DMatrix<f64>) -> DMatrix<f64> {
        let mut out = DMatrix::zeros(x.nrows(), x.ncols());
        for (c, col) in x.column_iter().enumerate() {
            let w = self.whiten(axis, col.iter().copied());
            out.set_column(c, &DVector::from_vec(w));
        }
        out
    }
}

struct BiasModel {
    name: &'static str,
    unit: &'static str,
    column: Box<dyn Fn(&BiasSample) -> f64>,
    /// Nonlinear parameters chosen on a grid (counted in the BIC).
    extra: usize,
    /// Grid positions the nonlinear parameter was chosen from: the look-elsewhere factor of
    /// the p-value (Bonferroni over the positions; 1 for a linear form).
    scan_positions: usize,
}

/// The transient's τ grid: 600 s to 4 days in steps of ×1.25 (29 values).
fn transient_taus() -> impl Iterator<Item = f64> {
    std::iter::successors(Some(600.0_f64), |t| Some(t * 1.25)).take_while(|t| *t <= 4.0 * 86_400.0)
}

/// An exponential transient `e^{−(t − t0)/τ}`.
fn transient_form(t0: f64, tau: f64) -> BiasModel {
    BiasModel {
        name: "gyro_bias_transient",
        unit: "arcsec/s",
        column: Box::new(move |s: &BiasSample| (-(s.t_s - t0) / tau).exp()),
        extra: 1,
        scan_positions: transient_taus().count(),
    }
}

/// Name of the baseline term that gives each gyro triad its own bias.
const TRIAD_BIAS: &str = "iru_triad_bias";

/// A step at `t_step`.
fn step_form(t_step: f64) -> BiasModel {
    BiasModel {
        name: "gyro_bias_step",
        unit: "arcsec/s",
        column: Box::new(move |s: &BiasSample| f64::from(u8::from(s.t_s >= t_step))),
        extra: 1,
        scan_positions: STEP_POSITIONS,
    }
}

/// The value of a candidate's nonlinear parameter (a transient's τ, a step's time) on `grid`
/// with the lowest χ² of `base` + `form(value)`; `None` when no fit succeeds.
fn best_on_grid(
    samples: &[BiasSample],
    w: &Whitener,
    base: &[&BiasModel],
    grid: impl Iterator<Item = f64>,
    form: &dyn Fn(f64) -> BiasModel,
) -> Option<f64> {
    let mut best: Option<(f64, f64)> = None;
    for v in grid {
        let m = form(v);
        let mut ms = base.to_vec();
        ms.push(&m);
        if let Some((c2, ..)) = bias_fit(samples, w, &ms) {
            if best.is_none_or(|(_, b)| c2 < b) {
                best = Some((v, c2));
            }
        }
    }
    best.map(|b| b.0)
}

/// GLS fit of `y = b0 + Σ models` per axis: (χ², β per axis, covariance per axis, equations).
fn bias_fit(
    samples: &[BiasSample],
    w: &Whitener,
    models: &[&BiasModel],
) -> Option<(f64, Vec<DVector<f64>>, Vec<DMatrix<f64>>, usize)> {
    let n = samples.len();
    let k = 1 + models.len();
    let mut x = DMatrix::zeros(n, k);
    for (i, s) in samples.iter().enumerate() {
        x[(i, 0)] = 1.0;
        for (j, m) in models.iter().enumerate() {
            x[(i, j + 1)] = (m.column)(s);
        }
    }
    let mut chi2 = 0.0;
    let mut betas = Vec::new();
    let mut covs = Vec::new();
    for axis in 0..3 {
        let wx = w.whiten_columns(axis, &x);
        let wy = DVector::from_vec(w.whiten(axis, samples.iter().map(|s| s.y[axis])));
        let nm = wx.transpose() * &wx;
        let ch = nm.cholesky()?;
        let beta = ch.solve(&(wx.transpose() * &wy));
        let r = &wy - &wx * &beta;
        chi2 += r.dot(&r);
        betas.push(beta);
        covs.push(ch.inverse());
    }
    Some((chi2, betas, covs, 3 * n))
}

/// Run the gyro analysis on the final sensor-side fit, in three stages: the hold-to-hold
/// bias samples ([`bias_samples`]), the bias history's forward search over its candidate
/// forms ([`bias_history`]), and the slews ([`super::gyro_slews`]) with the bias the holds
/// measured.
#[must_use]
pub fn analyse(
    input: &GyroInput<'_>,
    set: &MeasurementSet,
    post: &PostFit,
    cfg: &GyroConfig,
) -> GyroAnalysis {
    let mut out = GyroAnalysis::default();
    let att = batch_attitudes(set, post);
    let frames = input.frames;
    let b_ref = reference_bias(input);
    let tmean_iru =
        frames.iter().map(|f| f.iru_temperature_c).sum::<f64>() / frames.len().max(1) as f64;
    // 1. Bias samples.
    let samples = bias_samples(input, set, &att, &b_ref, tmean_iru);
    out.bias_samples = samples.len();
    out.bias_series = samples
        .iter()
        .map(|s| (s.t_s, [s.y.x, s.y.y, s.y.z]))
        .collect();
    // 2. The hold bias history (accepted models) per frame.
    let hold_bias = bias_history(&samples, input, &b_ref, tmean_iru, cfg, &mut out);
    // 3. The slews.
    let slews = SlewInput {
        input,
        set,
        att: &att,
        b_ref: &b_ref,
        hold_bias: hold_bias.as_ref(),
        cfg,
    };
    super::gyro_slews::analyse(&slews, &mut out);
    out
}

/// The constant reference bias `b_ref`: the mean of the per-frame bias when given, else the
/// calibration's.
fn reference_bias(input: &GyroInput<'_>) -> Vector3<f64> {
    input
        .bias_per_frame
        .and_then(|b| {
            let n = b.len().max(1) as f64;
            Some(b.iter().sum::<Vector3<f64>>() / n)
        })
        .unwrap_or(input.gyro.bias_acs_rad_per_s)
}

/// Stage 1: one bias sample per pair of consecutive, contiguous low-rate batches with usable
/// attitudes more than 1 s apart (`y = −z/Δt` against `b_ref`).
fn bias_samples(
    input: &GyroInput<'_>,
    set: &MeasurementSet,
    att: &[BatchAttitude],
    b_ref: &Vector3<f64>,
    tmean_iru: f64,
) -> Vec<BiasSample> {
    let frames = input.frames;
    let mut samples: Vec<BiasSample> = Vec::new();
    for i in 0..set.batches.len().saturating_sub(1) {
        let (a, b) = (&set.batches[i], &set.batches[i + 1]);
        if a.high_rate || b.high_rate || a.hi != b.lo {
            continue;
        }
        let (Some((ma, va)), Some((mb, vb))) = (batch_attitude(att, i), batch_attitude(att, i + 1))
        else {
            continue;
        };
        // A sample across the OBC's triad switch mixes two biases: left out (the switch is
        // known, housekeeping octet 106).
        let backup = frames[b.center].iru_backup;
        if frames[a.center + 1..=b.center]
            .iter()
            .any(|f| f.iru_backup != backup)
        {
            continue;
        }
        let phi = propagate(input, a.center, b.center, b_ref);
        let z = rotvec_from_rot(&(mb * (phi * ma).transpose())) * ARCSEC_PER_RAD;
        let dt = b.t_center_s - a.t_center_s;
        if dt <= 1.0 {
            continue;
        }
        let mid = (a.center + b.center) / 2;
        if let Some(prev) = samples.last_mut() {
            prev.chained = (prev.t_s + 0.5 * prev.dt_s - a.t_center_s).abs() < 1e-6;
        }
        samples.push(BiasSample {
            t_s: 0.5 * (a.t_center_s + b.t_center_s),
            dt_s: dt,
            y: -z / dt,
            var_start: va,
            var_end: vb,
            chained: false,
            dtemp_iru: frames[mid].iru_temperature_c - tmean_iru,
            backup,
        });
    }
    samples
}

/// Stage 2: the bias history. With at least 20 samples and positive-definite whitenings,
/// the candidate forms ([`BiasForms`]) are added one per round ([`History::forward_round`],
/// at most three rounds); the fitted history is then evaluated at every frame for the slews
/// ([`hold_bias_per_frame`]). Otherwise a note says why, and the slews use the OBC's bias.
fn bias_history(
    samples: &[BiasSample],
    input: &GyroInput<'_>,
    b_ref: &Vector3<f64>,
    tmean_iru: f64,
    cfg: &GyroConfig,
    out: &mut GyroAnalysis,
) -> Option<HoldBias> {
    let half = samples.len() / 2;
    let whiteners = (
        Whitener::new(samples, cfg, MODEL_CHAINED_ERRORS),
        Whitener::new(&samples[..half], cfg, MODEL_CHAINED_ERRORS),
        Whitener::new(&samples[half..], cfg, MODEL_CHAINED_ERRORS),
    );
    let (true, (Some(w_all), Some(w_a), Some(w_b))) = (samples.len() >= 20, &whiteners) else {
        out.notes.push(format!(
            "bias history: {} hold-to-hold samples (need 20 and a positive-definite covariance)",
            samples.len()
        ));
        return None;
    };
    let history = History {
        samples,
        half,
        w_all,
        w_a,
        w_b,
        cfg,
        b_ref_arcsec: b_ref * ARCSEC_PER_RAD,
    };
    let forms = BiasForms::new(samples, w_all, cfg);
    if forms.triad.is_some() {
        out.notes.push(
            "bias history: the OBC switched gyro triads (event 0x0202, housekeeping octet 106): each triad's own bias is in the baseline (known, not an effect), the samples across the switch are left out, and the slews take each triad's bias and IRUCAL δM".into(),
        );
    }
    let candidates = forms.candidates(cfg);
    let mut model = forms.baseline(cfg);
    out.bias_fit_before = history.fitted(&model);
    for _round in 0..3 {
        if !history.forward_round(&forms, &candidates, &mut model, out) {
            break;
        }
    }
    out.bias_fit_after = history.fitted(&model);
    // The bias the slews see: the fitted history, not the constant reference (a ramp of
    // 0.009″/s per hour left the slew model's residual scale at 10–37 and hid a 100-ppm
    // scale asymmetry; helper-20's review). Kept with its prediction variance also when
    // no candidate was accepted (the constant hold bias): the slews compare their own
    // bias with it (`gyro_slews::rate_mode_bias`).
    let frames = input.frames;
    hold_bias_per_frame(
        frames,
        samples,
        w_all,
        &model,
        frames.first().map_or(0.0, |f| f.time.seconds()),
        tmean_iru,
        cfg.rrw_rad_per_s15 * ARCSEC_PER_RAD,
    )
}

/// The bias history's candidate forms: ramp, thermal bias, and the transient and the step
/// with their nonlinear parameter (τ, the step time) chosen on a grid given the baseline.
struct BiasForms {
    /// Each triad's own bias (the backup's offset from the primary's), when the samples
    /// hold both: the OBC's switch is known (event 0x0202, housekeeping octet 106), so this
    /// is in the baseline, never a candidate.
    triad: Option<BiasModel>,
    ramp: BiasModel,
    thermal: BiasModel,
    transient: BiasModel,
    step: BiasModel,
    /// The transient's τ (s).
    tau_best: f64,
    /// The step's time (s since the first frame).
    t_step_best: f64,
}

impl BiasForms {
    fn new(samples: &[BiasSample], w_all: &Whitener, cfg: &GyroConfig) -> Self {
        let t0 = samples[0].t_s;
        let span = samples.last().map_or(1.0, |s| s.t_s - t0).max(1.0);
        let t_mid = t0 + 0.5 * span;
        let ramp = BiasModel {
            name: "gyro_bias_ramp",
            unit: "arcsec/s per hour",
            column: Box::new(move |s: &BiasSample| (s.t_s - t_mid) / 3600.0),
            extra: 0,
            scan_positions: 1,
        };
        let thermal = BiasModel {
            name: "gyro_thermal_bias",
            unit: "arcsec/s per degC",
            column: Box::new(|s: &BiasSample| s.dtemp_iru),
            extra: 0,
            scan_positions: 1,
        };
        let triad =
            (samples.iter().any(|s| s.backup) && samples.iter().any(|s| !s.backup)).then(|| {
                BiasModel {
                    name: TRIAD_BIAS,
                    unit: "arcsec/s",
                    column: Box::new(|s: &BiasSample| f64::from(u8::from(s.backup))),
                    extra: 0,
                    scan_positions: 1,
                }
            });
        // Exponential transient: τ on a grid, best by χ² given the baseline.
        let mut base_models: Vec<&BiasModel> = triad.iter().collect();
        if cfg.transient_declared {
            base_models.push(&ramp);
        }
        let tau_best = best_on_grid(samples, w_all, &base_models, transient_taus(), &|tau| {
            transient_form(t0, tau)
        })
        .unwrap_or(86_400.0);
        let transient = transient_form(t0, tau_best);
        // A step at an unknown time: the position on a grid of STEP_POSITIONS sample indices,
        // best by χ² given the baseline, counted as one more parameter; its p-value carries
        // the scan (Bonferroni over the positions).
        let positions = (1..=STEP_POSITIONS)
            .filter_map(|q| samples.get(q * samples.len() / (STEP_POSITIONS + 1)))
            .map(|s| s.t_s);
        let t_step_best =
            best_on_grid(samples, w_all, &base_models, positions, &step_form).unwrap_or(t_mid);
        let step = step_form(t_step_best);
        Self {
            triad,
            ramp,
            thermal,
            transient,
            step,
            tau_best,
            t_step_best,
        }
    }

    /// The model before any candidate: each triad's own bias when both flew, the ramp when
    /// the transient is declared.
    fn baseline(&self, cfg: &GyroConfig) -> Vec<&BiasModel> {
        let mut base: Vec<&BiasModel> = self.triad.iter().collect();
        if cfg.transient_declared {
            base.push(&self.ramp);
        }
        base
    }

    /// The candidates, in the order they are tested.
    fn candidates(&self, cfg: &GyroConfig) -> Vec<&BiasModel> {
        let mut candidates: Vec<&BiasModel> = vec![&self.thermal, &self.transient, &self.step];
        if !cfg.transient_declared {
            candidates.insert(0, &self.ramp);
        }
        candidates
    }
}

/// What the bias history's rounds share: the samples, their whitenings (all, each half), the
/// settings and the reference bias.
struct History<'a> {
    samples: &'a [BiasSample],
    /// First sample of the second half.
    half: usize,
    w_all: &'a Whitener,
    w_a: &'a Whitener,
    w_b: &'a Whitener,
    cfg: &'a GyroConfig,
    /// `b_ref` (arcsec/s).
    b_ref_arcsec: Vector3<f64>,
}

/// One candidate tested against the current model.
struct CandidateTest {
    evidence: Evidence,
    leftover: GyroLeftover,
    /// Estimate and σ per ACS axis.
    est: Vec<f64>,
    sig: Vec<f64>,
    /// Every evidence rule passed.
    passes: bool,
}

impl History<'_> {
    /// The fit of `ms` evaluated at every sample (t s, arcsec/s per axis); empty when the fit
    /// fails.
    fn fitted(&self, ms: &[&BiasModel]) -> Vec<(f64, [f64; 3])> {
        match bias_fit(self.samples, self.w_all, ms) {
            Some((_, betas, _, _)) => self
                .samples
                .iter()
                .map(|s| {
                    let mut v = [0.0; 3];
                    for (ax, b) in betas.iter().enumerate() {
                        v[ax] = b[0]
                            + ms.iter()
                                .enumerate()
                                .map(|(j, m)| b[j + 1] * (m.column)(s))
                                .sum::<f64>();
                    }
                    (s.t_s, v)
                })
                .collect(),
            None => Vec::new(),
        }
    }

    /// One round: every candidate not yet in `model` tested ([`Self::test_candidate`]); the
    /// one with the largest ΔBIC among those that pass joins the model and is reported as
    /// detected ([`Self::detected`]). `false` when none passed (the round's candidates were
    /// then tested against the final model: they are the leftovers) or the fit failed.
    fn forward_round<'m>(
        &self,
        forms: &BiasForms,
        candidates: &[&'m BiasModel],
        model: &mut Vec<&'m BiasModel>,
        out: &mut GyroAnalysis,
    ) -> bool {
        let Some((c0, ..)) = bias_fit(self.samples, self.w_all, model) else {
            return false;
        };
        let mut best: Option<(usize, Evidence, Vec<f64>, Vec<f64>)> = None;
        let mut round_evs = Vec::new();
        let mut round_left = Vec::new();
        for (ci, cand) in candidates.iter().enumerate() {
            if model.iter().any(|m| m.name == cand.name) {
                continue;
            }
            let Some(t) = self.test_candidate(c0, model, cand, candidates.len()) else {
                continue;
            };
            round_left.push(t.leftover);
            if t.passes
                && best
                    .as_ref()
                    .is_none_or(|b| t.evidence.delta_bic > b.1.delta_bic)
            {
                best = Some((ci, t.evidence.clone(), t.est, t.sig));
            }
            round_evs.push(t.evidence);
        }
        let Some((ci, mut ev, est, sig)) = best else {
            out.candidates.extend(round_evs);
            // Nothing passed: this round tested every remaining candidate against the
            // final model.
            out.leftover.extend(round_left);
            return false;
        };
        ev.accepted = true;
        for e in &mut round_evs {
            if e.effect == ev.effect {
                e.accepted = true;
                e.rejected_because = None;
            }
        }
        out.candidates.extend(round_evs);
        let cand = candidates[ci];
        model.push(cand);
        out.detected
            .push(self.detected(forms, cand, &est, &sig, ev));
        true
    }

    /// `cand` added to `model` (χ² `c0`): F test with the scan's Bonferroni factor, ΔBIC,
    /// and the halves (not when a step is involved); `None` when the fit fails.
    fn test_candidate(
        &self,
        c0: f64,
        model: &[&BiasModel],
        cand: &BiasModel,
        n_candidates: usize,
    ) -> Option<CandidateTest> {
        let (samples, half, cfg) = (self.samples, self.half, self.cfg);
        let mut ms = model.to_vec();
        ms.push(cand);
        let (c1, betas, covs, n) = bias_fit(samples, self.w_all, &ms)?;
        let k = 3usize;
        let dof = n as f64 - (3 * (ms.len() + 1)) as f64;
        let s2 = (c1 / dof).max(1e-9);
        let f = ((c0 - c1) / k as f64) / s2.max(1.0);
        let p = (f_sf(f, k as f64, dof) * cand.scan_positions as f64).min(1.0);
        let dbic = delta_bic(c0, c1, s2, n, k + cand.extra);
        let j = ms.len();
        let est: Vec<f64> = betas.iter().map(|b| b[j]).collect();
        let sig: Vec<f64> = covs
            .iter()
            .map(|c| (c[(j, j)] * s2.max(1.0)).sqrt())
            .collect();
        // Halves.
        let (fa, fb) = (
            bias_fit(&samples[..half], self.w_a, &ms),
            bias_fit(&samples[half..], self.w_b, &ms),
        );
        let (mut hchi2, mut hp, mut hest) = (f64::NAN, 0.0, (Vec::new(), Vec::new()));
        if let (Some((_, ba, ca, _)), Some((_, bb, cb, _))) = (fa, fb) {
            hchi2 = (0..3)
                .map(|ax| (ba[ax][j] - bb[ax][j]).powi(2) / (ca[ax][(j, j)] + cb[ax][(j, j)]))
                .sum::<f64>();
            hp = chi2_sf(hchi2, 3.0);
            hest = (
                (0..3).map(|ax| ba[ax][j]).collect(),
                (0..3).map(|ax| bb[ax][j]).collect(),
            );
        }
        let mut why = Vec::new();
        if !(p * (n_candidates as f64) < cfg.alpha) {
            why.push(format!(
                "LR p {p:.2e} (×{n_candidates} candidates) ≥ {}",
                cfg.alpha
            ));
        }
        if !(dbic > cfg.min_delta_bic) {
            why.push(format!("ΔBIC {dbic:.1} ≤ {}", cfg.min_delta_bic));
        }
        // A step happens once: one half holds it and the other cannot fit it, so the
        // halves test neither the step nor a candidate fitted with one in the model
        // (the step's scan has its own Bonferroni p-value).
        // The triad switch is such a step, known.
        let step_involved = ms
            .iter()
            .any(|m| m.name == "gyro_bias_step" || m.name == TRIAD_BIAS);
        if !step_involved && !(hp > 0.0027) {
            why.push(format!("halves differ (χ² {hchi2:.1}, p {hp:.2e})"));
        }
        let evidence = Evidence {
            p_holm: (p * n_candidates as f64).min(1.0),
            adequate: true,
            rejected_because: (!why.is_empty()).then(|| why.join("; ")),
            ..Evidence::likelihood_test(
                format!("{}[IRU]", cand.name),
                k,
                (c0 - c1, f, p),
                dbic,
                (hchi2, hp, hest),
            )
        };
        let leftover = GyroLeftover {
            evidence: evidence.clone(),
            regressor: if cand.name == "gyro_thermal_bias" {
                "iru_temperature_c"
            } else {
                "time_s"
            },
            size: term_rms(samples, &*cand.column, &est),
            unit: "arcsec/s",
        };
        Some(CandidateTest {
            evidence,
            leftover,
            est,
            sig,
            passes: why.is_empty(),
        })
    }

    /// The accepted candidate as a detected effect: its estimate per axis, the grid
    /// parameter of a transient or a step, and the reference bias it is relative to.
    fn detected(
        &self,
        forms: &BiasForms,
        cand: &BiasModel,
        est: &[f64],
        sig: &[f64],
        evidence: Evidence,
    ) -> Detected {
        let mut parameters = BTreeMap::new();
        let mut sigma = BTreeMap::new();
        let mut units = BTreeMap::new();
        for (ax, name) in ["x", "y", "z"].iter().enumerate() {
            parameters.insert((*name).to_owned(), est[ax]);
            sigma.insert((*name).to_owned(), sig[ax]);
            units.insert((*name).to_owned(), cand.unit.to_owned());
        }
        if cand.name == "gyro_bias_transient" {
            parameters.insert("tau_s".into(), forms.tau_best);
            units.insert("tau_s".into(), "s".into());
        }
        if cand.name == "gyro_bias_step" {
            parameters.insert("t_step_s".into(), forms.t_step_best);
            units.insert("t_step_s".into(), "s since the first frame".into());
        }
        for (ax, name) in ["ref_bias_x", "ref_bias_y", "ref_bias_z"]
            .iter()
            .enumerate()
        {
            parameters.insert((*name).to_owned(), self.b_ref_arcsec[ax]);
            units.insert((*name).to_owned(), "arcsec/s".into());
        }
        Detected {
            effect: cand.name.to_owned(),
            sensor: "IRU".into(),
            parameters,
            sigma,
            units,
            evidence,
            star_dirs: BTreeMap::new(),
        }
    }
}

/// The bias history's fit of `model` evaluated at every frame ([`HoldBias`]).
fn hold_bias_per_frame(
    frames: &[GyroFrame],
    samples: &[BiasSample],
    w: &Whitener,
    model: &[&BiasModel],
    t_first: f64,
    tmean_iru: f64,
    rrw_arcsec_per_s15: f64,
) -> Option<HoldBias> {
    let t_walk0 = samples.first()?.t_s;
    let (chi2, betas, covs, n) = bias_fit(samples, w, model)?;
    let dof = n as f64 - (3 * (model.len() + 1)) as f64;
    let scale = if dof > 0.0 {
        (chi2 / dof).max(1.0)
    } else {
        1.0
    };
    let mut bias_rad_per_s = Vec::with_capacity(frames.len());
    let mut var_arcsec2_per_s2 = Vec::with_capacity(frames.len());
    for f in frames {
        let s = BiasSample {
            t_s: f.time.seconds() - t_first,
            dt_s: 0.0,
            y: Vector3::zeros(),
            var_start: Vector3::zeros(),
            var_end: Vector3::zeros(),
            chained: false,
            dtemp_iru: f.iru_temperature_c - tmean_iru,
            backup: f.iru_backup,
        };
        let c = DVector::from_iterator(
            model.len() + 1,
            std::iter::once(1.0).chain(model.iter().map(|m| (m.column)(&s))),
        );
        bias_rad_per_s.push(Vector3::from_fn(|ax, _| betas[ax].dot(&c)) * RAD_PER_ARCSEC);
        // The fit's constant is the bias where the walk starts; the walk since then is in
        // the samples' covariance, not in the fit, so it is added here.
        let walk = rrw_arcsec_per_s15.powi(2) * (s.t_s - t_walk0).max(0.0);
        var_arcsec2_per_s2.push(Vector3::from_fn(|ax, _| {
            (c.transpose() * &covs[ax] * &c)[(0, 0)] * scale + walk
        }));
    }
    Some(HoldBias {
        bias_rad_per_s,
        var_arcsec2_per_s2,
        modelled: !model.is_empty(),
    })
}

/// Positions of the bias-step scan (sample indices evenly spaced, the ends excluded).
const STEP_POSITIONS: usize = 39;

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;

    /// The samples' covariance written out (per axis), as the model states it (`chained`:
    /// with the shared attitude error of chained samples).
    fn dense_covariance(
        samples: &[BiasSample],
        cfg: &GyroConfig,
        axis: usize,
        chained: bool,
    ) -> DMatrix<f64> {
        let n = samples.len();
        let t0 = samples[0].t_s;
        let su = cfg.rrw_rad_per_s15 * ARCSEC_PER_RAD;
        let sv = cfg.arw_rad_per_sqrt_s * ARCSEC_PER_RAD;
        let c_walk = DMatrix::from_fn(n, n, |i, j| {
            su * su * (samples[i].t_s - t0).min(samples[j].t_s - t0)
        });
        let mut c = c_walk;
        for i in 0..n {
            let s = &samples[i];
            c[(i, i)] +=
                (s.var_start[axis] + s.var_end[axis]) / (s.dt_s * s.dt_s) + sv * sv / s.dt_s;
            if chained && s.chained && i + 1 < n {
                let v = -s.var_end[axis] / (s.dt_s * samples[i + 1].dt_s);
                c[(i, i + 1)] += v;
                c[(i + 1, i)] += v;
            }
        }
        c
    }

    /// The filter's whitening is `L⁻¹ z` of the dense Cholesky factor, on samples with
    /// chained runs, breaks, uneven spacing and per-axis attitude variances, with and without
    /// the chained samples' shared attitude error.
    #[test]
    fn whitener_equals_the_dense_cholesky_factor() {
        let cfg = GyroConfig {
            alpha: 0.01,
            min_delta_bic: 10.0,
            rrw_rad_per_s15: 3e-11,
            arw_rad_per_sqrt_s: 2e-8,
            transient_declared: false,
        };
        let mut samples = Vec::new();
        let mut t = 1000.0;
        let mut var_prev = Vector3::new(4.0, 9.0, 1.0);
        for i in 0..120 {
            let dt = 30.0 + 17.0 * ((i * 7) % 5) as f64;
            let chained = i % 11 != 10;
            let var_end = Vector3::new(
                3.0 + (i % 3) as f64,
                8.0 - (i % 4) as f64,
                0.5 + 0.1 * i as f64,
            );
            samples.push(BiasSample {
                t_s: t + 0.5 * dt,
                dt_s: dt,
                y: Vector3::new(
                    (i as f64 * 0.37).sin(),
                    (i as f64 * 0.11).cos(),
                    0.01 * i as f64,
                ),
                var_start: var_prev,
                var_end,
                chained,
                dtemp_iru: 0.0,
                backup: false,
            });
            t += dt + if chained { 0.0 } else { 500.0 };
            var_prev = if chained {
                var_end
            } else {
                Vector3::new(2.0, 2.0, 2.0)
            };
        }
        for (axis, chained) in [(0, true), (1, true), (2, true), (0, false), (2, false)] {
            let w = Whitener::new(&samples, &cfg, chained).unwrap();
            let c = dense_covariance(&samples, &cfg, axis, chained);
            let l = c.cholesky().unwrap().unpack();
            let z = DVector::from_iterator(samples.len(), samples.iter().map(|s| s.y[axis]));
            let dense = l.solve_lower_triangular(&z).unwrap();
            let filter = w.whiten(axis, z.iter().copied());
            let worst = dense
                .iter()
                .zip(&filter)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(
                worst < 1e-9 * dense.amax().max(1.0),
                "axis {axis}, chained {chained}: {worst:e}"
            );
        }
    }
}
