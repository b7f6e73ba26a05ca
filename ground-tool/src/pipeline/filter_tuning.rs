//! # The filter table's noise terms from what the ground has measured in flight
//!
//! Why: the OBC filter weighs its data by five numbers of its table: the slew uncertainty
//! `gyro_scale_uncertainty` (how far a turn of θ may be wrong, `k θ`, through the gyros'
//! scale factors and misalignments), the gyro's angle random walk σ_v and rate random walk
//! σ_u, and the end points of the FHST noise law σ(m). The boot values are prelaunch
//! knowledge. After a calibration the ground knows better: a filter that keeps prelaunch
//! uncertainty after the G matrix is calibrated is pessimistic after every slew, and one that
//! keeps a noise figure the flight contradicts is wrong one way or the other
//! (`docs/obc_filter.md` §11). Every change here is written only through a held-out test, like
//! the other tables.
//!
//! # Noise terms (rule, [`noise_decision`])
//! Per axis (gyro) or tracker (FHST): the whole data's value with its 95 % interval, and the
//! value of each of two held-out folds. An axis votes for a change when the interval excludes
//! the flown value and both folds differ from it by more than [`MIN_RELATIVE_CHANGE`] on the
//! same side. A term is raised when any axis votes up (to the largest: the filter must not
//! be optimistic on any axis) and lowered only when every axis with evidence votes down.
//! σ_v and σ_u come from the Allan deviation of the holds ([`noise_terms`]) and are never
//! lowered (noise or drift common to both channels of an axis cancels in their difference,
//! which the analysis uses); the FHST law comes from the stars' second differences
//! (`super::fhst_noise`, [`fhst_noise_terms`]) and is lowered only when every tracker with
//! data agrees.
//!
//! # Slew uncertainty from IRUCAL (rule)
//! A residual error `E` of the flown G turns a rotation `θ u` into an attitude error `E u θ`,
//! whose variance on axis `i` is `Σ_j var(E_ij) u_j² θ² ≤ max_j var(E_ij) θ²`. So the
//! isotropic `k` that bounds every slew axis is the largest element σ of `E`:
//! * an element of δM that is uplinked leaves its estimation error, σ_ij;
//! * an element not uplinked (not significant at 3σ) leaves the whole true δM_ij, whose mean
//!   square given the estimate is `δM_ij² + σ_ij²`;
//! * every σ is scaled by `√max(1, m)`, `m` the held-out mean square of the normalised
//!   residuals of the IRU table's validation (the held-out maneuvers say how true σ is).
//!
//! `k` is written only when the IRU table passed its held-out validation, no rate-dependent
//! scale error was found (δM cannot hold it), every triad that flew slews was calibrated, and
//! the new `k` differs from the flown one by more than [`MIN_RELATIVE_CHANGE`]. Otherwise the
//! flown `k` stays and the report says why, with the derived value.

pub use super::tuning_evidence::NoiseEvidence;
use fsw_core::tables::types::FilterTable;
use serde::Serialize;

/// A derived value is written only when it differs from the flown one by more than this
/// fraction: below it the filter's σ changes by less than the NEES band's resolution.
pub const MIN_RELATIVE_CHANGE: f64 = 0.2;

/// The table's range of `gyro_scale_uncertainty` (`FilterTable::validate`).
const MAX_GYRO_SCALE_UNCERTAINTY: f64 = 0.05;

/// The filter-table field a decision is about (serialised as the field's name).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum FilterTerm {
    /// `gyro_scale_uncertainty`.
    #[serde(rename = "gyro_scale_uncertainty")]
    SlewUncertainty,
    /// `arw_rad_per_sqrt_s` (σ_v).
    #[serde(rename = "arw_rad_per_sqrt_s")]
    Arw,
    /// `rrw_rad_per_s_sqrt_s` (σ_u).
    #[serde(rename = "rrw_rad_per_s_sqrt_s")]
    Rrw,
    /// `fhst_sigma_bright_arcsec` (σ(2.0)).
    #[serde(rename = "fhst_sigma_bright_arcsec")]
    FhstBright,
    /// `fhst_sigma_faint_arcsec` (σ(5.7)).
    #[serde(rename = "fhst_sigma_faint_arcsec")]
    FhstFaint,
}

impl FilterTerm {
    /// The filter-table field's name.
    #[must_use]
    pub fn field(self) -> &'static str {
        match self {
            Self::SlewUncertainty => "gyro_scale_uncertainty",
            Self::Arw => "arw_rad_per_sqrt_s",
            Self::Rrw => "rrw_rad_per_s_sqrt_s",
            Self::FhstBright => "fhst_sigma_bright_arcsec",
            Self::FhstFaint => "fhst_sigma_faint_arcsec",
        }
    }

    /// The field of `table`.
    fn field_mut(self, table: &mut FilterTable) -> &mut f64 {
        match self {
            Self::SlewUncertainty => &mut table.gyro_scale_uncertainty,
            Self::Arw => &mut table.arw_rad_per_sqrt_s,
            Self::Rrw => &mut table.rrw_rad_per_s_sqrt_s,
            Self::FhstBright => &mut table.fhst_sigma_bright_arcsec,
            Self::FhstFaint => &mut table.fhst_sigma_faint_arcsec,
        }
    }
}

/// One derived filter-table gyro term and the decision on it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TermDecision {
    /// Filter-table field.
    pub field: FilterTerm,
    /// The flown value.
    pub flown: f64,
    /// The value the ground derives, when it can.
    pub derived: Option<f64>,
    /// Whether `derived` is written into the new table.
    pub written: bool,
    /// `gyro_scale_uncertainty` only: the residual error's 1σ per element of G
    /// (`gyro_calibration_sigma`, row = error axis, column = axis turned), written with it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub derived_per_element: Option<[[f64; 3]; 3]>,
    /// Why, with the numbers.
    pub reason: String,
}

impl TermDecision {
    /// The flown value kept, nothing derived, with why.
    fn kept(field: FilterTerm, flown: f64, reason: String) -> Self {
        Self {
            field,
            flown,
            derived: None,
            written: false,
            derived_per_element: None,
            reason,
        }
    }

    /// Each of `terms` (field, flown value) kept for want of the data of a held-out test:
    /// `lacking` says which, `why` the numbers.
    fn kept_for_want_of_data(
        terms: [(FilterTerm, f64); 2],
        lacking: &str,
        why: &dyn std::fmt::Display,
    ) -> [Self; 2] {
        terms.map(|(field, f)| {
            let reason = format!("kept {f:.3e}: {lacking} for a held-out test ({why})");
            Self::kept(field, f, reason)
        })
    }

    /// Write the derived value into `table` when the decision is to write it; true if it did.
    pub fn apply(&self, table: &mut FilterTable) -> bool {
        match (self.written, self.derived) {
            (true, Some(v)) => {
                *self.field.field_mut(table) = v;
                if let Some(e) = self.derived_per_element {
                    table.gyro_calibration_sigma = e;
                }
                true
            }
            _ => false,
        }
    }
}

/// Each residual element σ of a triad's G after the calibration (rule in the module doc).
fn residual_element_sigmas(
    delta_m: &[[f64; 3]; 3],
    sigma: &[[f64; 3]; 3],
    uplinked: &[[f64; 3]; 3],
    scale: f64,
) -> [[f64; 3]; 3] {
    let mut out = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            let s = scale * sigma[i][j];
            out[i][j] = if uplinked[i][j] == 0.0 {
                delta_m[i][j].hypot(s)
            } else {
                s
            };
        }
    }
    out
}

/// The largest residual element σ of a triad's G after the calibration (rule in the module
/// doc), and where it is: `(k, row, column)`.
fn largest_element(sigmas: &[[f64; 3]; 3]) -> (f64, usize, usize) {
    let mut best = (0.0, 0, 0);
    for (i, row) in sigmas.iter().enumerate() {
        for (j, left) in row.iter().enumerate() {
            if *left > best.0 {
                best = (*left, i, j);
            }
        }
    }
    best
}

/// `gyro_scale_uncertainty` from IRUCAL's report (module doc); the backup triad counts when
/// it flew slews (then `IruReport::backup` holds its calibration).
#[must_use]
pub fn slew_uncertainty(
    flown_k: f64,
    iru: Option<&IruEvidence>,
    skipped: Option<&str>,
) -> TermDecision {
    let mut d = TermDecision::kept(FilterTerm::SlewUncertainty, flown_k, String::new());
    let Some(r) = iru else {
        d.reason = format!(
            "kept: no IRU calibration ({}), nothing new is known of the gyros' scale factors and misalignments",
            skipped.unwrap_or("none ran")
        );
        return d;
    };
    let p = &r.primary;
    let Some(v) = p.validation.as_ref() else {
        d.reason = format!(
            "kept: the IRU calibration has no held-out validation ({})",
            r.decision
        );
        return d;
    };
    let scale = v.mean_square_normalised.max(1.0).sqrt();
    let primary = residual_element_sigmas(&p.delta_m, &p.delta_m_sigma, &p.delta_m_uplinked, scale);
    let backup = r.backup.as_ref().map(|b| {
        let bs = b
            .validation
            .as_ref()
            .map_or(1.0, |bv| bv.mean_square_normalised.max(1.0).sqrt());
        let sigmas = residual_element_sigmas(&b.delta_m, &b.delta_m_sigma, &b.delta_m_uplinked, bs);
        (b, bs, sigmas)
    });
    let (k_primary, i, j) = largest_element(&primary);
    let mut k = k_primary;
    let mut origin = format!(
        "primary triad's δM[{i}][{j}]: σ {:.0} ppm × {scale:.2} (held-out √m.s.){}",
        p.delta_m_sigma[i][j] * 1e6,
        if p.delta_m_uplinked[i][j] == 0.0 {
            format!(
                " ⊕ its estimate {:.0} ppm (not uplinked)",
                p.delta_m[i][j] * 1e6
            )
        } else {
            String::new()
        }
    );
    let mut per_element = primary;
    if let Some((b, bs, sigmas)) = backup.as_ref() {
        let (kb, bi, bj) = largest_element(sigmas);
        if kb > k {
            k = kb;
            origin = format!(
                "backup triad's δM[{bi}][{bj}]: σ {:.0} ppm × {bs:.2}",
                b.delta_m_sigma[bi][bj] * 1e6
            );
        }
        for (p, q) in per_element
            .iter_mut()
            .flatten()
            .zip(sigmas.iter().flatten())
        {
            *p = p.max(*q);
        }
    }
    let k = k.min(MAX_GYRO_SCALE_UNCERTAINTY);
    d.derived = Some(k);
    for e in per_element.iter_mut().flatten() {
        *e = e.min(MAX_GYRO_SCALE_UNCERTAINTY);
    }
    d.derived_per_element = Some(per_element);
    let why_not = if !v.passed {
        Some(format!(
            "the IRU table failed its held-out validation ({})",
            v.reason
        ))
    } else if !r.g_updated {
        Some(format!(
            "G is not updated ({}), so the flown G flies on",
            r.decision
        ))
    } else if r.rate_scale.significant {
        Some(format!(
            "a rate-dependent scale error is significant (p = {:.3}): δM cannot hold it, so slews keep the flown uncertainty",
            r.rate_scale.p_value
        ))
    } else if r
        .backup
        .as_ref()
        .is_some_and(|b| b.validation.as_ref().is_some_and(|bv| !bv.passed))
    {
        Some("the backup triad flew slews and its δM failed its held-out validation".to_owned())
    } else if (k - flown_k).abs() <= MIN_RELATIVE_CHANGE * flown_k {
        Some(format!(
            "within {:.0} % of the flown value",
            MIN_RELATIVE_CHANGE * 100.0
        ))
    } else {
        None
    };
    match why_not {
        Some(w) => {
            d.reason = format!("kept {flown_k:.2e}: {w}; derived {k:.2e} from the {origin}");
        }
        None => {
            d.written = true;
            d.reason = format!(
                "{flown_k:.2e} -> {k:.2e}: the largest residual error of G after the calibration, from the {origin}; the IRU table passed its held-out validation ({})",
                v.reason
            );
        }
    }
    d
}

/// Confidence of the Allan-deviation intervals the noise decisions use.
const NOISE_CONFIDENCE: f64 = 0.95;

/// Bootstrap replicas of the whole-data Allan fit (`allan::analyse_segments_with`); the two
/// folds use point estimates only.
const NOISE_REPLICAS: usize = crate::calibration::allan::BOOTSTRAP_REPLICAS;

/// Above this many samples per axis the whole data's intervals are the χ² ones (no
/// bootstrap): they are optimistic (≈ 75–85 % coverage at 95 %, `allan` module doc) but at
/// this size far narrower than the [`MIN_RELATIVE_CHANGE`] both folds must show, which then
/// decides; the bootstrap costs ≈ 25 s CPU on six months of 30-s frames (≈ 5·10⁵ samples
/// per axis), the χ² intervals a few.
const BOOTSTRAP_MAX_SAMPLES: usize = 1 << 17;

/// The two held-out folds of a set of hold segments: alternate segments when there are at
/// least four (each fold then spans the run, so a slow trend falls in both), else each
/// segment's first and second halves.
fn folds(segments: &[Vec<f64>]) -> [Vec<Vec<f64>>; 2] {
    use crate::calibration::allan::MIN_SEGMENT_SAMPLES;
    let mut out = [Vec::new(), Vec::new()];
    if segments.len() >= 4 {
        for (i, s) in segments.iter().enumerate() {
            out[i % 2].push(s.clone());
        }
    } else {
        for s in segments {
            let half = s.len() / 2;
            if half >= MIN_SEGMENT_SAMPLES {
                out[0].push(s[..half].to_vec());
                out[1].push(s[half..].to_vec());
            }
        }
    }
    out
}

/// A held-out validation's verdict, as far as the slew uncertainty needs it.
#[derive(Clone, Debug, PartialEq)]
pub struct HeldOut {
    /// Passed.
    pub passed: bool,
    /// Mean square of the held-out normalised residuals (1 = σ true).
    pub mean_square_normalised: f64,
    /// The validation's reason, with its numbers.
    pub reason: String,
}

/// One triad's δM after the calibration (unitless, row-major) and its validation.
#[derive(Clone, Debug, PartialEq)]
pub struct TriadCalibration {
    /// δM.
    pub delta_m: [[f64; 3]; 3],
    /// 1σ of δM.
    pub delta_m_sigma: [[f64; 3]; 3],
    /// The δM applied to G (0 where not uplinked).
    pub delta_m_uplinked: [[f64; 3]; 3],
    /// Held-out validation, when attempted.
    pub validation: Option<HeldOut>,
}

/// The lack-of-fit test of a scale error that changes with rate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RateScale {
    /// Significant.
    pub significant: bool,
    /// Its p-value.
    pub p_value: f64,
}

/// What IRUCAL says of G (calibrate's `IruReport`, in the terms the slew uncertainty needs).
#[derive(Clone, Debug, PartialEq)]
pub struct IruEvidence {
    /// The primary triad's δM, its σ, what was applied to G, and its held-out validation.
    pub primary: TriadCalibration,
    /// Whether G was updated.
    pub g_updated: bool,
    /// Why G was or was not updated.
    pub decision: String,
    /// The rate-dependent scale test.
    pub rate_scale: RateScale,
    /// The backup triad, when it flew slews.
    pub backup: Option<TriadCalibration>,
}

/// One term's [value, low, high] of the fit, when detected.
fn detected(t: &crate::calibration::allan::NoiseTerm) -> Option<[f64; 3]> {
    t.detected.then_some([t.value, t.low, t.high])
}

/// The filter's σ_u from a fit: `√(K² + R² T)` with `T` = [`RAMP_HORIZON_S`] ([value, low,
/// high]): the rate random walk plus a rate ramp (the early bias transient) taken as a walk
/// over one orbit, as the boot table's σ_u is derived (docs/obc_filter.md §2). An undetected
/// ramp enters with its upper bound at all three places, so a σ_u is never lowered below a
/// ramp the data cannot exclude. `None` when neither K nor a ramp is seen.
/// Without K but with a detected ramp, K enters at its upper bound (0 in the low end): a
/// ramp alone can show the flown σ_u too small.
fn filter_rrw(fit: &crate::calibration::allan::NoiseFit) -> Option<[f64; 3]> {
    let r = &fit.rate_ramp_rad_per_s2;
    let ramp = detected(r).unwrap_or([r.high; 3]);
    let k = match detected(&fit.rrw_rad_per_s_sqrt_s) {
        Some(k) => k,
        None if r.detected => {
            let high = fit.rrw_rad_per_s_sqrt_s.high;
            [high, 0.0, high]
        }
        None => return None,
    };
    Some([0, 1, 2].map(|i| (k[i] * k[i] + ramp[i] * ramp[i] * RAMP_HORIZON_S).sqrt()))
}

/// The time over which a rate ramp is carried as a random walk, s: one GRO orbit, the
/// horizon of the boot table's σ_u (docs/obc_filter.md §2).
pub const RAMP_HORIZON_S: f64 = 5760.0;

/// One axis's evidence for σ_v and σ_u from the rate segments of its channel-pair difference
/// (per channel = ÷ √2): the whole data with bootstrap intervals, and the two folds' point
/// estimates; or why not (a fold too short, or the fit failed).
fn axis_evidence(
    axis: &'static str,
    segments: &[Vec<f64>],
    tau0_s: f64,
    per_channel: f64,
    bootstrap: bool,
) -> Result<[NoiseEvidence; 2], String> {
    use crate::calibration::allan::{analyse_segments_with, MIN_TOTAL_SAMPLES};
    let samples: usize = segments.iter().map(Vec::len).sum();
    let [fa, fb] = folds(segments);
    let fold_samples = |f: &[Vec<f64>]| f.iter().map(Vec::len).sum::<usize>();
    if fold_samples(&fa).min(fold_samples(&fb)) < MIN_TOTAL_SAMPLES {
        return Err(format!(
            "axis {axis}: {samples} hold samples in {} segment(s) of at least {} samples, fewer than {MIN_TOTAL_SAMPLES} per held-out fold",
            segments.len(),
            crate::calibration::allan::MIN_SEGMENT_SAMPLES
        ));
    }
    let replicas = if bootstrap && samples <= BOOTSTRAP_MAX_SAMPLES {
        NOISE_REPLICAS
    } else {
        0
    };
    let (_, whole) = analyse_segments_with(axis, segments, tau0_s, NOISE_CONFIDENCE, replicas)
        .map_err(|e| format!("axis {axis}: the Allan fit failed ({e})"))?;
    let fold_fits =
        [&fa, &fb].map(|f| analyse_segments_with(axis, f, tau0_s, NOISE_CONFIDENCE, 0).ok());
    let term = |f: &crate::calibration::allan::NoiseFit, rrw: bool| {
        if rrw {
            filter_rrw(f)
        } else {
            detected(&f.arw_rad_per_sqrt_s)
        }
    };
    Ok([false, true].map(|rrw| NoiseEvidence {
        axis,
        samples,
        note: None,
        whole: term(&whole, rrw).map(|v| v.map(|x| x / per_channel)),
        folds: [0, 1].map(|k| {
            fold_fits[k]
                .as_ref()
                .and_then(|(_, f)| term(f, rrw))
                .map(|v| v[0] / per_channel)
        }),
    }))
}

/// Above this ratio of the active channel's ARW to the channel-pair difference's (per
/// channel), with disjoint intervals, the channels share noise: 1.08–1.13 on the writer's
/// clean runs (the body's own motion in the holds), 3.1 with 90 % of the noise common to both
/// channels.
pub const COMMON_NOISE_RATIO: f64 = 1.5;

/// σ_v evidence of one axis: the channel-pair difference's (it cancels the body's motion in
/// the holds, but also any noise the two channels share), unless the active channel alone
/// (body motion and all the gyro's noise) shows [`COMMON_NOISE_RATIO`] times more with
/// disjoint intervals: then the channels share noise the difference cannot see, and σ_v
/// takes the active channel's figure, an upper bound (the filter must not be told its gyro
/// is quieter than the channel it flies).
fn arw_upper_bound(pair: NoiseEvidence, active: Option<NoiseEvidence>) -> NoiseEvidence {
    let (Some([p, _, p_hi]), Some(a)) = (pair.whole, active) else {
        return pair;
    };
    match a.whole {
        Some([v, lo, _]) if v > COMMON_NOISE_RATIO * p && lo > p_hi => NoiseEvidence {
            note: Some(format!(
                "the active channel alone shows {v:.3e}, {:.1} × the channel-pair difference's {p:.3e}: the channels share noise the difference cannot see; taken from the active channel, an upper bound",
                v / p
            )),
            ..a
        },
        _ => pair,
    }
}

/// [`arw_upper_bound`] of the pair difference's evidence and the flown channel `a`'s: the
/// active channel first without the bootstrap (its point value decides whether it can
/// matter: a fifth of the chain's time on the main job otherwise), then with it.
fn with_active_channel(
    tm: &crate::tp::Telemetry,
    iru: &fsw_core::tables::IruTable,
    (axis, a): (&'static str, usize),
    tau0_s: f64,
    pair: NoiseEvidence,
) -> NoiseEvidence {
    let active = crate::calibration::allan::hold_segments(tm, iru, (a, None), tau0_s);
    let evidence = |bootstrap: bool| {
        axis_evidence(axis, &active.used, tau0_s, 1.0, bootstrap)
            .ok()
            .map(|[e, _]| e)
    };
    let screen = evidence(false).and_then(|e| e.whole);
    match (screen, pair.whole) {
        (Some([v, _, _]), Some([p, _, _])) if v > COMMON_NOISE_RATIO * p => {
            arw_upper_bound(pair, evidence(true))
        }
        (None, Some(_)) => NoiseEvidence {
            note: Some(
                "the active channel alone could not be analysed: noise common to both channels would not show".to_owned(),
            ),
            ..pair
        },
        _ => pair,
    }
}

/// The noise evidence of every axis for both terms, from the pair difference of each axis's
/// channels in the low-rate holds (`allan::hold_segments`; per channel = ÷ √2), or why there
/// is none.
fn noise_evidence(
    tm: &crate::tp::Telemetry,
    iru: &fsw_core::tables::IruTable,
) -> Result<[Vec<NoiseEvidence>; 2], String> {
    use crate::calibration::allan::{hold_segments, median_spacing_s, AXES};
    let tau0_s = median_spacing_s(tm).ok_or("no raw frames")?;
    // The channel the OBC flies: the backup triad's (X1, Y2, Z2) when most housekeeping
    // packets say so (octet 106), else the primary's (X2, Y1, Z1; `AXES` lists it first).
    let backup_flown =
        2 * tm.housekeeping.iter().filter(|h| h.iru_config == 1).count() > tm.housekeeping.len();
    let mut arw = Vec::new();
    let mut rrw = Vec::new();
    let mut why_not = Vec::new();
    for (axis, a, b) in AXES {
        let seg = hold_segments(tm, iru, (a, Some(b)), tau0_s);
        match axis_evidence(axis, &seg.used, tau0_s, std::f64::consts::SQRT_2, true) {
            Ok([pair_arw, r]) => {
                let active = if backup_flown { b } else { a };
                arw.push(with_active_channel(tm, iru, (axis, active), tau0_s, pair_arw));
                rrw.push(r);
            }
            Err(e) if seg.dropped > 0 => why_not.push(format!(
                "{e} ({} shorter hold segment(s) dropped, the longest {} samples of τ₀ = {tau0_s} s)",
                seg.dropped, seg.longest
            )),
            Err(e) => why_not.push(e),
        }
    }
    if arw.is_empty() {
        return Err(why_not.join("; "));
    }
    Ok([arw, rrw])
}

/// The decision on one noise term (σ_v or σ_u) from the axes' evidence. An axis votes to
/// change the flown value `f` when the whole data's interval excludes `f` and both held-out
/// folds detect the term on the same side of `f`, each by more than [`MIN_RELATIVE_CHANGE`].
/// Raised when any axis votes up (to the largest such axis's value: the filter must not be
/// optimistic on any axis); lowered only when `may_lower`, at least `lower_needs` axes have
/// evidence and every one of them votes down (to the largest of them).
pub fn noise_decision(
    field: FilterTerm,
    flown: f64,
    evidence: &[NoiseEvidence],
    may_lower: bool,
    lower_needs: usize,
) -> TermDecision {
    let vote = |e: &NoiseEvidence| -> Option<(f64, bool)> {
        let [v, lo, hi] = e.whole?;
        let [Some(a), Some(b)] = e.folds else {
            return None;
        };
        let up = lo > flown
            && a > flown * (1.0 + MIN_RELATIVE_CHANGE)
            && b > flown * (1.0 + MIN_RELATIVE_CHANGE);
        let down = hi < flown
            && a < flown * (1.0 - MIN_RELATIVE_CHANGE)
            && b < flown * (1.0 - MIN_RELATIVE_CHANGE);
        (up || down).then_some((v, up))
    };
    let votes: Vec<Option<(f64, bool)>> = evidence.iter().map(vote).collect();
    let up = votes
        .iter()
        .flatten()
        .filter(|(_, up)| *up)
        .map(|(v, _)| *v)
        .fold(None, |m: Option<f64>, v| Some(m.map_or(v, |m| m.max(v))));
    let all_down =
        votes.len() >= lower_needs.max(1) && votes.iter().all(|v| matches!(v, Some((_, false))));
    let derived = up
        .or_else(|| all_down.then(|| votes.iter().flatten().map(|(v, _)| *v).fold(0.0, f64::max)));
    let describe = |e: &NoiseEvidence| {
        let fold = |f: Option<f64>| f.map_or("not detected".to_owned(), |v| format!("{v:.3e}"));
        match e.whole {
            Some([v, lo, hi]) => format!(
                "{}: {v:.3e} [{lo:.3e}, {hi:.3e}], folds {} / {}{}",
                e.axis,
                fold(e.folds[0]),
                fold(e.folds[1]),
                e.note.as_ref().map_or(String::new(), |n| format!(" ({n})"))
            ),
            None => format!(
                "{}: {}",
                e.axis,
                e.note.as_deref().unwrap_or("not detected")
            ),
        }
    };
    let evidence_text = evidence.iter().map(describe).collect::<Vec<_>>().join("; ");
    let mut d = TermDecision {
        derived,
        ..TermDecision::kept(field, flown, String::new())
    };
    d.reason = match (up, all_down && may_lower) {
        (Some(v), _) => {
            d.written = true;
            format!(
                "{flown:.3e} -> {v:.3e}: the data exclude the flown value and both held-out folds agree (95 %: {evidence_text})"
            )
        }
        (None, true) => {
            let v = derived.unwrap_or(flown);
            d.written = true;
            format!(
                "{flown:.3e} -> {v:.3e}: every axis's evidence lies below the flown value and both held-out folds agree (95 %: {evidence_text})"
            )
        }
        (None, false) if all_down => format!(
            "kept {flown:.3e}: the data show less ({evidence_text}), but this term is not lowered from flight data"
        ),
        (None, false) => format!(
            "kept {flown:.3e}: no axis where the whole data exclude it and both held-out folds differ by > {:.0} % on the same side (95 %: {evidence_text})",
            MIN_RELATIVE_CHANGE * 100.0
        ),
    };
    d
}

/// The FHST noise law's end points (`fhst_sigma_bright_arcsec`, `fhst_sigma_faint_arcsec`)
/// from the stars' second differences (`super::fhst_noise`), each through the two-fold
/// held-out test of [`noise_decision`]; lowered only when every tracker with data agrees.
#[must_use]
pub fn fhst_noise_terms(
    flown: &FilterTable,
    frames: &[super::observations::FrameObservations],
) -> [TermDecision; 2] {
    match super::fhst_noise::fhst_noise_evidence(frames, flown) {
        Ok([bright, faint]) => [
            noise_decision(
                FilterTerm::FhstBright,
                flown.fhst_sigma_bright_arcsec,
                &bright,
                true,
                bright.len(),
            ),
            noise_decision(
                FilterTerm::FhstFaint,
                flown.fhst_sigma_faint_arcsec,
                &faint,
                true,
                faint.len(),
            ),
        ],
        Err(why) => TermDecision::kept_for_want_of_data(
            [
                (FilterTerm::FhstBright, flown.fhst_sigma_bright_arcsec),
                (FilterTerm::FhstFaint, flown.fhst_sigma_faint_arcsec),
            ],
            "too few star samples",
            &why,
        ),
    }
}

/// σ_v (`arw_rad_per_sqrt_s`) and σ_u (`rrw_rad_per_s_sqrt_s`, `filter_rrw`: the rate
/// random walk with any rate ramp the holds show or cannot exclude) from the Allan deviation
/// of the low-rate holds, each through the two-fold held-out test of [`noise_decision`], and
/// only raised (noise or drift common to both channels of an axis cancels in their
/// difference). Without enough hold data both are kept, with the reason.
#[must_use]
pub fn noise_terms(
    flown: &FilterTable,
    tm: &crate::tp::Telemetry,
    iru: &fsw_core::tables::IruTable,
) -> [TermDecision; 2] {
    match noise_evidence(tm, iru) {
        Ok([arw, rrw]) => {
            // σ_u is never lowered: a drift common to both channels of an axis cancels in
            // their difference, and neither the OBC's bias estimate (its own noise raised σ_u
            // by a third on `normal-ops`) nor a single slope over the run (blind to an
            // orbit-periodic drift) bounds it safely (docs/obc_filter.md §11).
            let mut rrw_decision =
                noise_decision(FilterTerm::Rrw, flown.rrw_rad_per_s_sqrt_s, &rrw, false, 3);
            rrw_decision.reason.push_str(
                "; σ_u is never lowered, and a drift common to both channels of an axis (which cancels in their difference) is not in it",
            );
            // σ_v is never lowered: noise common to both channels of an axis cancels in
            // their difference (an outside probe's 90 % common noise read 2.4× low).
            let mut arw_decision =
                noise_decision(FilterTerm::Arw, flown.arw_rad_per_sqrt_s, &arw, false, 3);
            if !arw_decision.written {
                arw_decision.reason.push_str(
                    "; σ_v is never lowered from the channel difference: noise common to both channels of an axis cancels in it",
                );
            }
            [arw_decision, rrw_decision]
        }
        Err(why) => TermDecision::kept_for_want_of_data(
            [
                (FilterTerm::Arw, flown.arw_rad_per_sqrt_s),
                (FilterTerm::Rrw, flown.rrw_rad_per_s_sqrt_s),
            ],
            "too little hold data",
            &why,
        ),
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;

    /// σ_v takes the active channel only when it shows clearly more than the pair difference
    /// (noise common to both channels), never less.
    #[test]
    fn arw_takes_the_active_channel_only_when_the_channels_share_noise() {
        let ev = |v: f64, lo: f64, hi: f64| NoiseEvidence {
            axis: "X",
            samples: 1000,
            whole: Some([v, lo, hi]),
            folds: [Some(v), Some(v)],
            note: None,
        };
        let pair = ev(3.2e-8, 3.1e-8, 3.4e-8);
        let common = arw_upper_bound(pair.clone(), Some(ev(1.0e-7, 0.97e-7, 1.03e-7)));
        assert_eq!(common.whole, Some([1.0e-7, 0.97e-7, 1.03e-7]));
        assert!(common.note.is_some_and(|n| n.contains("share noise")));
        // The body's own motion in the holds: 8 % more, kept from the pair difference.
        let clean = arw_upper_bound(pair.clone(), Some(ev(3.46e-8, 3.35e-8, 3.6e-8)));
        assert_eq!(clean, pair);
        // Twice as large but overlapping intervals: not evidence enough.
        let wide = arw_upper_bound(pair.clone(), Some(ev(6.4e-8, 3.0e-8, 9.0e-8)));
        assert_eq!(wide, pair);
        assert_eq!(arw_upper_bound(pair.clone(), None), pair);
    }

    #[test]
    fn residual_sigma_takes_the_whole_estimate_of_elements_not_uplinked() {
        let dm = [[4e-4, 0.0, 1.7e-4], [0.0; 3], [0.0; 3]];
        let sigma = [[3e-5, 3e-5, 6e-5], [3e-5; 3], [3e-5; 3]];
        let up = [[4e-4, 0.0, 0.0], [0.0; 3], [0.0; 3]];
        let (k, i, j) = largest_element(&residual_element_sigmas(&dm, &sigma, &up, 1.0));
        assert_eq!((i, j), (0, 2));
        assert!((k - 1.7e-4f64.hypot(6e-5)).abs() < 1e-12);
        // Uplinked: only the estimation error is left; the held-out scale multiplies σ.
        let up_all = dm;
        let (k, _, _) = largest_element(&residual_element_sigmas(&dm, &sigma, &up_all, 1.5));
        assert!((k - 1.5 * 6e-5).abs() < 1e-12);
    }

    fn evidence(whole: Option<[f64; 3]>, folds: [Option<f64>; 2]) -> NoiseEvidence {
        NoiseEvidence {
            axis: "X",
            samples: 10_000,
            whole,
            folds,
            note: None,
        }
    }

    #[test]
    fn noise_is_raised_only_when_the_interval_and_both_folds_agree() {
        let f = 1.0e-8;
        let up = evidence(Some([3e-8, 2.8e-8, 3.2e-8]), [Some(3.1e-8), Some(2.9e-8)]);
        let d = noise_decision(
            FilterTerm::Arw,
            f,
            &[up.clone(), evidence(None, [None; 2])],
            true,
            3,
        );
        assert!(d.written && d.derived == Some(3e-8), "{}", d.reason);
        // One fold within 20 % of the flown value: kept.
        let split = evidence(Some([3e-8, 2.8e-8, 3.2e-8]), [Some(3.1e-8), Some(1.1e-8)]);
        let d = noise_decision(FilterTerm::Arw, f, &[split], true, 3);
        assert!(!d.written && d.derived.is_none(), "{}", d.reason);
        // The whole interval contains the flown value: kept.
        let wide = evidence(Some([3e-8, 0.9e-8, 5e-8]), [Some(3.1e-8), Some(2.9e-8)]);
        assert!(!noise_decision(FilterTerm::Arw, f, &[wide], true, 3).written);
        // The largest axis wins.
        let up2 = evidence(Some([5e-8, 4.5e-8, 5.5e-8]), [Some(5e-8), Some(5.1e-8)]);
        let d = noise_decision(FilterTerm::Arw, f, &[up, up2], true, 3);
        assert_eq!(d.derived, Some(5e-8));
    }

    #[test]
    fn noise_is_lowered_only_when_every_axis_agrees_and_the_term_may_be_lowered() {
        let f = 1.0e-8;
        let down = evidence(Some([3e-9, 2.8e-9, 3.2e-9]), [Some(3.1e-9), Some(2.9e-9)]);
        let three = vec![down.clone(), down.clone(), down.clone()];
        let d = noise_decision(FilterTerm::Arw, f, &three, true, 3);
        assert!(d.written && d.derived == Some(3e-9), "{}", d.reason);
        let d = noise_decision(FilterTerm::Rrw, f, &three, false, 3);
        assert!(!d.written, "{}", d.reason);
        assert!(d.reason.contains("not lowered"));
        let two = vec![down.clone(), down, evidence(None, [None; 2])];
        assert!(!noise_decision(FilterTerm::Arw, f, &two, true, 3).written);
    }

    /// White rate noise of `n` rad/√s sampled at 1 s plus the low-rate pulse quantization,
    /// as the pair difference of two channels (√2 n).
    fn white_segments(n: f64, lens: &[usize], seed: u64) -> Vec<Vec<f64>> {
        let mut state = seed;
        let mut normal = move || {
            // Sum of 12 uniforms − 6: a unit normal to the precision this test needs.
            (0..12)
                .map(|_| {
                    state = state
                        .wrapping_mul(6_364_136_223_846_793_005)
                        .wrapping_add(1_442_695_040_888_963_407);
                    (state >> 11) as f64 / (1u64 << 53) as f64
                })
                .sum::<f64>()
                - 6.0
        };
        lens.iter()
            .map(|&len| {
                (0..len)
                    .map(|_| std::f64::consts::SQRT_2 * n * normal())
                    .collect()
            })
            .collect()
    }

    #[test]
    fn a_noisier_gyro_than_the_table_is_found_on_both_folds_and_written() {
        let flown = 1.454e-8;
        let truth = 4.0 * flown;
        let segs = white_segments(truth, &[3000, 2500, 2800, 3100, 2600, 2900], 7);
        let [arw, _] = axis_evidence("X", &segs, 1.0, std::f64::consts::SQRT_2, true).unwrap();
        let d = noise_decision(FilterTerm::Arw, flown, &[arw], true, 3);
        let v = d.derived.expect("derived");
        assert!(d.written, "{}", d.reason);
        assert!((v / truth - 1.0).abs() < 0.2, "{v:e} against {truth:e}");
        // The same noise as the table: kept.
        let segs = white_segments(flown, &[3000, 2500, 2800, 3100, 2600, 2900], 8);
        let [arw, _] = axis_evidence("X", &segs, 1.0, std::f64::consts::SQRT_2, true).unwrap();
        assert!(!noise_decision(FilterTerm::Arw, flown, &[arw], true, 3).written);
    }

    #[test]
    fn too_little_hold_data_is_refused_with_the_count() {
        let segs = white_segments(1e-8, &[900, 800], 3);
        let e = axis_evidence("Y", &segs, 1.0, std::f64::consts::SQRT_2, true).unwrap_err();
        assert!(e.contains("1700 hold samples"), "{e}");
    }

    #[test]
    fn folds_alternate_segments_or_halve_them() {
        let segs: Vec<Vec<f64>> = (0..5).map(|k| vec![k as f64; 100]).collect();
        let [a, b] = folds(&segs);
        assert_eq!((a.len(), b.len()), (3, 2));
        assert_eq!(a[1][0], 2.0);
        let [a, b] = folds(&segs[..2]);
        assert_eq!(
            (a.len(), b.len()),
            (0, 0),
            "halves of 50 < 64 samples are dropped"
        );
        let long = vec![vec![1.0; 1000]];
        let [a, b] = folds(&long);
        assert_eq!((a[0].len(), b[0].len()), (500, 500));
    }
}
