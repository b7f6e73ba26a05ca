//! # The FHSTs' white noise by magnitude, from the stars' own second differences
//!
//! Why: the OBC weighs every star by the filter table's σ(m) (`FilterTable::fhst_sigma_rad`,
//! the photon-noise law `a + b·10^{0.2(m − 5.7)}` through the end points σ(2.0) and σ(5.7),
//! with the count quantization added in quadrature). The boot end points are the paper's
//! 8–24″ range; a tracker quieter than that makes the filter pessimistic (NEES below its
//! band), a noisier one optimistic. The ground can measure the law from the flight itself.
//!
//! # Method (model-free: no attitude, no alignment, no catalog position)
//! 1. **Samples.** In three consecutive frames with equal spacing, all in the IRU's low-rate
//!    mode, the tracker holds the same identified star (no new acquisition after the first),
//!    and the gyro increments of the two intervals differ by less than
//!    [`MAX_BODY_ACCELERATION_RAD`] (the body's own angular acceleration would enter the
//!    difference): the second difference `h₀ − 2h₁ + h₂` of each focal-plane axis is `√6 σ`
//!    white noise; slow effects (alignment, aberration, distortion, a steady drift) cancel.
//!    Triples do not overlap, so the samples are independent.
//! 2. **Bins.** Per tracker, by the middle frame's instrument magnitude (the OBC's argument
//!    of σ(m)) in [`BIN_MAG`] bins over 2.0–5.7: outliers beyond [`CLIP_SIGMA`] robust σ
//!    (MAD) are dropped (glitches, a star swap inside a triple), the rest give the mean
//!    square `s²`, minus the quantization `q²/12` (the OBC adds it back).
//! 3. **Law.** Weighted least squares of `s_b = a + b f_b` (`f = 10^{0.2(m − 5.7)}`, weight
//!    `2 n_b / s_b²`, the sampling variance of a standard deviation), its covariance scaled
//!    by `max(1, χ²/dof)` when the law does not fit the bins to their precision (e.g. a
//!    tracker's extra noise at the field's edge, which the law has no term for). The end
//!    points σ(2.0) and σ(5.7) with their 95 % intervals are the evidence.
//!    When the law does not fit the bins at all (χ² beyond its [`LAW_MISFIT_P`] quantile)
//!    the tracker gives no evidence: its noise has another shape than the table can hold
//!    (e.g. linear in magnitude), and end points fitted to it would be wrong at one end.
//!    An end point with no bin within [`END_POINT_REACH_MAG`] of it gives no evidence either.
//! 4. **Held-out folds.** The same estimate on alternate [`FOLD_BLOCK_S`] blocks of time;
//!    `super::filter_tuning` writes an end point only when the interval excludes the flown
//!    value and both folds differ from it by more than 20 % on the same side.

use super::observations::FrameObservations;
use super::tuning_evidence::NoiseEvidence;
use fsw_core::fhst::{FHST_MAGNITUDE_MAX, FHST_MAGNITUDE_MIN, FHST_RAD_PER_COUNT};
use fsw_core::tables::types::FilterTable;
use fsw_core::units::ARCSEC_PER_RAD;

/// Largest difference of the two intervals' gyro increments (any axis) in a triple, rad:
/// 0.5″, a tenth of the smallest σ the law can give, so the body's own acceleration adds at
/// most 1 % to the variance.
pub const MAX_BODY_ACCELERATION_RAD: f64 = 0.5 / ARCSEC_PER_RAD;

/// Magnitude bin width, mag.
pub const BIN_MAG: f64 = 0.25;

/// Fewest samples (both axes counted) in a bin that enters the fit.
pub const MIN_BIN_SAMPLES: usize = 40;

/// Samples beyond this many robust σ of their bin are outliers.
pub const CLIP_SIGMA: f64 = 6.0;

/// An end point is evidence only when a magnitude bin lies within this many magnitudes of it:
/// farther, it is the law's extrapolation, which holds only if the tracker follows the law's
/// shape (an outside writer's tracker linear in magnitude gave σ(2.0) = 10.1″ against 6″).
pub const END_POINT_REACH_MAG: f64 = 1.0;

/// A law whose χ² exceeds its quantile at `1 − LAW_MISFIT_P` is refused.
pub const LAW_MISFIT_P: f64 = 1e-3;

/// Length of the alternating time blocks of the two held-out folds, s.
pub const FOLD_BLOCK_S: f64 = 600.0;

/// `10^{0.2 (2.0 − 5.7)}`: the bright end's flux term relative to the faint end's.
const BRIGHT_FLUX_TERM: f64 = 0.181_970_085_860_998_4;

/// One second-difference sample: magnitude, `(h₀ − 2h₁ + h₂)/√6` per axis (arcsec), time.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Sample {
    magnitude: f64,
    z_arcsec: [f64; 2],
    t_s: f64,
}

/// The second-difference samples of one tracker (method step 1).
fn samples(frames: &[FrameObservations], tracker: usize) -> Vec<Sample> {
    let mut out = Vec::new();
    let mut k = 0;
    while k + 2 < frames.len() {
        match triple(&frames[k..k + 3], tracker) {
            Some(s) => {
                out.push(s);
                k += 3;
            }
            None => k += 1,
        }
    }
    out
}

/// A sample from three consecutive frames, when they qualify (method step 1).
fn triple(f: &[FrameObservations], tracker: usize) -> Option<Sample> {
    let [a, b, c] = f else {
        return None;
    };
    let (t0, t1, t2) = (a.time.seconds(), b.time.seconds(), c.time.seconds());
    let (d1, d2) = (t1 - t0, t2 - t1);
    if !(d1 > 0.0 && (d2 - d1).abs() <= 1e-3 * d1) || a.high_rate || b.high_rate || c.high_rate {
        return None;
    }
    let (ga, gb) = (b.gyro.as_ref()?, c.gyro.as_ref()?);
    if (gb.dtheta_acs_rad - ga.dtheta_acs_rad).amax() > MAX_BODY_ACCELERATION_RAD {
        return None;
    }
    let star = |fr: &FrameObservations| fr.stars.get(tracker).copied().flatten();
    let (sa, sb, sc) = (star(a)?, star(b)?, star(c)?);
    let hip = sa.identified?.0;
    if sb.identified?.0 != hip || sc.identified?.0 != hip || sb.meas.new_star || sc.meas.new_star {
        return None;
    }
    let second = |x0: f64, x1: f64, x2: f64| (x0 - 2.0 * x1 + x2) / 6f64.sqrt() * ARCSEC_PER_RAD;
    Some(Sample {
        magnitude: sb.meas.magnitude,
        z_arcsec: [
            second(sa.meas.h_rad, sb.meas.h_rad, sc.meas.h_rad),
            second(sa.meas.v_rad, sb.meas.v_rad, sc.meas.v_rad),
        ],
        t_s: t1,
    })
}

/// One magnitude bin: mean magnitude, white σ (quantization removed), arcsec, samples.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Bin {
    magnitude: f64,
    sigma_arcsec: f64,
    n: usize,
}

/// The bins of a set of samples (method step 2).
fn bins(samples: &[&Sample]) -> Vec<Bin> {
    let q_var = (FHST_RAD_PER_COUNT * ARCSEC_PER_RAD).powi(2) / 12.0;
    let count = ((FHST_MAGNITUDE_MAX - FHST_MAGNITUDE_MIN) / BIN_MAG).ceil() as usize;
    let mut per: Vec<Vec<(f64, f64)>> = vec![Vec::new(); count];
    for s in samples {
        let m = s.magnitude.clamp(FHST_MAGNITUDE_MIN, FHST_MAGNITUDE_MAX);
        let i = (((m - FHST_MAGNITUDE_MIN) / BIN_MAG) as usize).min(count - 1);
        for z in s.z_arcsec {
            per[i].push((m, z));
        }
    }
    per.into_iter()
        .filter_map(|v| {
            if v.len() < MIN_BIN_SAMPLES {
                return None;
            }
            let mut abs: Vec<f64> = v.iter().map(|(_, z)| z.abs()).collect();
            let mid = abs.len() / 2;
            let (_, med, _) = abs.select_nth_unstable_by(mid, f64::total_cmp);
            let robust = 1.4826 * *med;
            let kept: Vec<&(f64, f64)> = v
                .iter()
                .filter(|(_, z)| z.abs() <= CLIP_SIGMA * robust)
                .collect();
            let n = kept.len();
            if n < MIN_BIN_SAMPLES {
                return None;
            }
            let ms = kept.iter().map(|(_, z)| z * z).sum::<f64>() / n as f64;
            let magnitude = kept.iter().map(|(m, _)| m).sum::<f64>() / n as f64;
            Some(Bin {
                magnitude,
                sigma_arcsec: (ms - q_var).max(0.01).sqrt(),
                n,
            })
        })
        .collect()
}

/// The law's end points σ(2.0), σ(5.7) (arcsec) with their 1σ, and the fit's χ² and dof,
/// from the bins (method step 3); `None` with fewer than two bins or less than one magnitude
/// of span.
fn end_points(bins: &[Bin]) -> Option<([(f64, f64); 2], f64, usize)> {
    let span = bins
        .iter()
        .map(|b| b.magnitude)
        .fold(f64::NEG_INFINITY, f64::max)
        - bins
            .iter()
            .map(|b| b.magnitude)
            .fold(f64::INFINITY, f64::min);
    if bins.len() < 2 || !(span >= 1.0) {
        return None;
    }
    let flux = |m: f64| 10f64.powf(0.2 * (m - FHST_MAGNITUDE_MAX));
    let (mut n00, mut n01, mut n11, mut r0, mut r1) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for b in bins {
        let (f, w) = (
            flux(b.magnitude),
            2.0 * b.n as f64 / (b.sigma_arcsec * b.sigma_arcsec),
        );
        n00 += w;
        n01 += w * f;
        n11 += w * f * f;
        r0 += w * b.sigma_arcsec;
        r1 += w * f * b.sigma_arcsec;
    }
    let det = n00 * n11 - n01 * n01;
    if !(det > 0.0) {
        return None;
    }
    let (c00, c01, c11) = (n11 / det, -n01 / det, n00 / det);
    let a = c00 * r0 + c01 * r1;
    let b = c01 * r0 + c11 * r1;
    let chi2: f64 = bins
        .iter()
        .map(|bin| {
            let w = 2.0 * bin.n as f64 / (bin.sigma_arcsec * bin.sigma_arcsec);
            w * (bin.sigma_arcsec - a - b * flux(bin.magnitude)).powi(2)
        })
        .sum();
    let dof = bins.len().saturating_sub(2);
    let scale = (chi2 / dof.max(1) as f64).max(1.0);
    let at = |f: f64| {
        let var = (c00 + 2.0 * f * c01 + f * f * c11) * scale;
        (a + b * f, var.max(0.0).sqrt())
    };
    Some(([at(BRIGHT_FLUX_TERM), at(1.0)], chi2, dof))
}

/// Why the law does not fit the bins (χ² beyond its `1 − LAW_MISFIT_P` quantile), if so.
fn law_misfit(chi2: f64, dof: usize) -> Option<String> {
    use statrs::distribution::{ChiSquared, ContinuousCDF};
    let p = ChiSquared::new(dof.max(1) as f64).ok()?.sf(chi2);
    (dof > 0 && p < LAW_MISFIT_P).then(|| {
        format!("its noise does not follow the table's law of magnitude (χ² {chi2:.1} over {dof} dof, p = {p:.1e})")
    })
}

/// Fewest second-difference samples for a tracker to count: with fewer it neither gives
/// evidence nor blocks a lowering (it has hardly seen a star).
pub const MIN_TRACKER_SAMPLES: usize = 20;

/// How far the bins lie above the flown law, where the law's own end points cannot be used
/// (the law misfits or an end is out of reach): the largest ratio of a bin's σ to the flown
/// σ(m) and that bin's lower 95 % ratio. The caller passes the bins within
/// [`END_POINT_REACH_MAG`] of the end it decides.
fn ratio_to_flown(bins: &[Bin], flown: &FilterTable) -> Option<(f64, f64)> {
    const Z95: f64 = 1.959_964;
    bins.iter()
        .map(|b| {
            let f = flown.fhst_sigma_rad(b.magnitude) * ARCSEC_PER_RAD;
            let r = b.sigma_arcsec / f;
            (r, r * (1.0 - Z95 / (2.0 * b.n as f64).sqrt()))
        })
        .max_by(|x, y| x.0.total_cmp(&y.0))
}

/// The evidence for the two end points (σ(2.0), σ(5.7)) of every tracker with at least
/// [`MIN_TRACKER_SAMPLES`] samples: whole data with 95 % intervals and the two folds' values
/// (method steps 2–4). Where the law's end points cannot be used (too few bins, a misfit, an
/// end out of reach) the tracker still gives evidence to raise an end when its bins near that
/// end lie above the flown law (the flown end scaled by their largest ratio, in the whole
/// data and in each fold), and otherwise none, with the reason: a tracker with data but no evidence blocks a
/// lowering (`super::filter_tuning::fhst_noise_terms`).
///
/// # Errors
/// No tracker has [`MIN_TRACKER_SAMPLES`] qualifying samples (the message counts them).
pub fn fhst_noise_evidence(
    frames: &[FrameObservations],
    flown: &FilterTable,
) -> Result<[Vec<NoiseEvidence>; 2], String> {
    const Z95: f64 = 1.959_964;
    let names = ["FHST1", "FHST2"];
    let flown_ends = [
        flown.fhst_sigma_bright_arcsec,
        flown.fhst_sigma_faint_arcsec,
    ];
    let mut bright = Vec::new();
    let mut faint = Vec::new();
    let mut why_not = Vec::new();
    for (tracker, name) in names.into_iter().enumerate() {
        let all = samples(frames, tracker);
        if all.len() < MIN_TRACKER_SAMPLES {
            why_not.push(format!("{name}: {} second-difference samples", all.len()));
            continue;
        }
        let whole_refs: Vec<&Sample> = all.iter().collect();
        let fold_refs = [0, 1].map(|k| -> Vec<&Sample> {
            all.iter()
                .filter(|s| ((s.t_s / FOLD_BLOCK_S).floor() as i64).rem_euclid(2) as usize == k)
                .collect()
        });
        let whole_bins = bins(&whole_refs);
        let fold_bins = [bins(&fold_refs[0]), bins(&fold_refs[1])];
        let law = end_points(&whole_bins);
        let fold_law = [end_points(&fold_bins[0]), end_points(&fold_bins[1])];
        for (j, out) in [&mut bright, &mut faint].into_iter().enumerate() {
            let end = [FHST_MAGNITUDE_MIN, FHST_MAGNITUDE_MAX][j];
            let unusable = match &law {
                None => Some(format!(
                    "{} second-difference samples do not give {MIN_BIN_SAMPLES} per magnitude bin over at least one magnitude",
                    all.len()
                )),
                Some((_, chi2, dof)) => law_misfit(*chi2, *dof).or_else(|| {
                    (!whole_bins
                        .iter()
                        .any(|b| (b.magnitude - end).abs() <= END_POINT_REACH_MAG))
                    .then(|| {
                        format!(
                            "no magnitude bin within {END_POINT_REACH_MAG} mag of {end}: the end point would be an extrapolation of the law"
                        )
                    })
                }),
            };
            let evidence = match (unusable, &law) {
                (None, Some((ends, _, _))) => {
                    let (v, s) = ends[j];
                    NoiseEvidence {
                        axis: name,
                        samples: all.len(),
                        whole: Some([v, v - Z95 * s, v + Z95 * s]),
                        folds: [0, 1].map(|k| fold_law[k].as_ref().map(|f| f.0[j].0)),
                        note: None,
                    }
                }
                (why, _) => {
                    let why = why.unwrap_or_default();
                    // Only the bins near this end speak for it: a law raised as a whole by
                    // its worst bin overstated the other end (seed 2 of the main job: bright
                    // bins 1.3× over, the faint end raised to 31″ against ≤ 24″).
                    let near = |bins: &[Bin]| -> Vec<Bin> {
                        bins.iter()
                            .filter(|b| (b.magnitude - end).abs() <= END_POINT_REACH_MAG)
                            .copied()
                            .collect()
                    };
                    let above =
                        ratio_to_flown(&near(&whole_bins), flown).filter(|(_, lo)| *lo > 1.0);
                    match above {
                        Some((r, lo)) => NoiseEvidence {
                            axis: name,
                            samples: all.len(),
                            whole: Some([r, lo, r].map(|x| x * flown_ends[j])),
                            folds: [0, 1].map(|k| {
                                ratio_to_flown(&near(&fold_bins[k]), flown)
                                    .map(|f| f.0 * flown_ends[j])
                            }),
                            note: Some(format!(
                                "{why}; its bins lie above the flown law by up to ×{r:.2}"
                            )),
                        },
                        None => NoiseEvidence {
                            axis: name,
                            samples: all.len(),
                            whole: None,
                            folds: [None, None],
                            note: Some(why),
                        },
                    }
                }
            };
            out.push(evidence);
        }
    }
    if bright.is_empty() {
        return Err(why_not.join("; "));
    }
    Ok([bright, faint])
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;

    /// Bins that follow the law through σ(2.0) = 6″ and σ(5.7) = 18″ exactly give back its
    /// end points, with a σ from the bins' sample counts.
    #[test]
    fn the_law_is_recovered_from_bins_at_their_precision() {
        let law = |m: f64| {
            let bb = (18.0 - 6.0) / (1.0 - BRIGHT_FLUX_TERM);
            18.0 - bb + bb * 10f64.powf(0.2 * (m - 5.7))
        };
        let bins: Vec<Bin> = (0..14)
            .map(|i| {
                let m = 2.125 + 0.25 * i as f64;
                Bin {
                    magnitude: m,
                    sigma_arcsec: law(m),
                    n: 1000,
                }
            })
            .collect();
        let ([(lo, slo), (hi, shi)], chi2, dof) = end_points(&bins).unwrap();
        assert!(chi2 < 1e-12 && dof == 12 && law_misfit(chi2, dof).is_none());
        assert!(
            (lo - 6.0).abs() < 1e-9 && (hi - 18.0).abs() < 1e-9,
            "{lo} {hi}"
        );
        assert!(slo > 0.0 && shi > 0.0 && shi < 1.0, "{slo} {shi}");
        // One bin cannot give a law.
        assert!(end_points(&bins[..1]).is_none());
        // A noise linear in magnitude (6″ at 2.0 to 18″ at 5.7, as an outside writer may
        // make it) measured to 1 % per bin is refused: no end points of the law hold it.
        let linear: Vec<Bin> = bins
            .iter()
            .map(|b| Bin {
                sigma_arcsec: 6.0 + 12.0 * (b.magnitude - 2.0) / 3.7,
                n: 5000,
                ..*b
            })
            .collect();
        let (_, chi2, dof) = end_points(&linear).unwrap();
        assert!(law_misfit(chi2, dof).is_some(), "χ² {chi2} over {dof}");
    }

    /// Bins twice the flown law (whatever their shape) give the raise evidence ×2 with a
    /// lower bound above 1; bins at the law give none above 1.
    #[test]
    fn bins_above_the_flown_law_give_a_raise_ratio() {
        let flown = FilterTable::default_boot();
        let at = |m: f64| flown.fhst_sigma_rad(m) * ARCSEC_PER_RAD;
        let bins = |k: f64| -> Vec<Bin> {
            (0..6)
                .map(|i| {
                    let m = 4.0 + 0.25 * i as f64;
                    Bin {
                        magnitude: m,
                        sigma_arcsec: k * at(m),
                        n: 2000,
                    }
                })
                .collect()
        };
        let (r, lo) = ratio_to_flown(&bins(2.0), &flown).unwrap();
        assert!((r - 2.0).abs() < 1e-9 && lo > 1.8, "{r} {lo}");
        let (r, lo) = ratio_to_flown(&bins(1.0), &flown).unwrap();
        assert!((r - 1.0).abs() < 1e-9 && lo < 1.0, "{r} {lo}");
    }
}
