//! # Into the flight model: detected effects as table data that `fsw-core` applies
//!
//! | effect | table field | what the OBC does (fsw-core) |
//! |---|---|---|
//! | alignments (joint fit) | `AlignmentTable.m_acs_from_*` (re-adjusted so the OBC's two-tracker frame is kept, paper appendix) | `M_AS` |
//! | `time_tag_offset` | `corrections.time_offset_s[i] += τ` | `executive::time_align`: `b(t) = Rot(ω τ) b(t − τ)` |
//! | `fhst_distortion` | `corrections.fhst_distortion[i] += [d0, d1, d2]` with `d0 = Δρ(4°)/F³`, `d1,2 = c/F²` (rad) | `fhst::correct_distortion`: `H = H_m − (d0 ρ² H_m + d1 H_m V_m)` |
//! | `fss_transfer_function` | `corrections.fss_transfer[i] += [scale, cross/E³, 0, scale, cross/E³, 0]` | `fss::correct_transfer`: `α = α_m − (c0 α_m + c1 α_m β_m² + c2)` |
//! | `aberration_annual` | `FilterTable.aberration_correction = true` | annual aberration of catalog stars and the Sun |
//! | `catalog_proper_motion_error` | the flown `StarCatalogTable`, each star the data determine moved by its offset (net rotation removed, shrunk by τ²/(τ² + σ²)), `u' = u + x_E e_E + x_N e_N` | the onboard catalog (identification and reference directions) |
//!
//! Only terms whose estimate exceeds 3σ are written (the others stay as flown); catalog offsets
//! go up for every star the data determine (their σ carries the gauge, see
//! [`corrected_catalog`]).
//!
//! Signs: every library column is the effect's addition to the *measured* angle, and the
//! tables subtract that addition from the measurement (distortion, transfer) or carry the
//! measurement forward by τ (time tag), so the estimate goes in with the sign it has.
//! Effects without a flight hook (orbital aberration — the OBC has no orbit —, thermal or
//! orbit-periodic alignment, magnitude bias, the FSS cubic and cyclic terms, catalog
//! offsets, gyro effects) are listed as ground-only.

use super::effects::{EffectKind, FHST_REF_RAD, FSS_EDGE_RAD};
use super::fit::align_offset;
use super::search::SearchResult;
use crate::calibration::adjust::{preserve_obc_attitude, BoresightFrame};
use fsw_core::attitude::{rot, Quat};
use fsw_core::tables::types::{matrix_from_rows, rows_from_matrix};
use fsw_core::tables::{AlignmentTable, FilterTable, StarCatalogTable};
use fsw_core::units::RAD_PER_ARCSEC;
use nalgebra::{Matrix3, Vector3};
use serde::Serialize;

/// What goes up.
#[derive(Clone, Debug, Serialize)]
pub struct FlightUpdate {
    /// New alignment table.
    #[serde(skip)]
    pub alignment: AlignmentTable,
    /// The ground model's alignments (the final fit, adjusted the same way), for scoring.
    #[serde(skip)]
    pub ground_alignment: AlignmentTable,
    /// New filter table, when a filter setting changes.
    #[serde(skip)]
    pub filter: Option<FilterTable>,
    /// Corrected onboard star catalog, when catalog offsets were found.
    #[serde(skip)]
    pub catalog: Option<StarCatalogTable>,
    /// What went into the tables.
    pub applied: Vec<String>,
    /// Effects with no flight-table hook (corrected on the ground only).
    pub ground_only: Vec<String>,
}

/// Build the tables from the final fit.
///
/// # Errors
/// The adjusted table does not validate (an effect too large for the table's range).
pub fn flight_update(
    res: &SearchResult,
    base: &AlignmentTable,
    flown_filter: &FilterTable,
    flown_catalog: Option<&StarCatalogTable>,
    counts: [usize; 4],
) -> anyhow::Result<FlightUpdate> {
    // The flight fit: the final model restricted to what the OBC can apply (alignments, time
    // offsets, distortion, the FSS scale and cross terms, annual aberration). The alignments
    // then absorb the rest as well as they can for the OBC's own model; taking the full
    // model's alignments would leave the OBC with alignments that were estimated together
    // with terms it does not have (an FSS cubic or cyclic term trades with its alignment).
    let mut effects: Vec<usize> = res.baseline.clone();
    effects.extend(&res.added);
    let mut idx: Vec<usize> = (0..super::fit::N_ALIGN).collect();
    for &i in &effects {
        let r = res.layout.range(i);
        let keep: Vec<usize> = match res.layout.effects[i].kind {
            EffectKind::TimeTagOffset | EffectKind::AberrationAnnual | EffectKind::Aberration => {
                vec![0]
            }
            EffectKind::FhstDistortion => vec![0, 1, 2],
            EffectKind::FssTransferFunction => vec![0, 1, 3, 4],
            // The onboard catalog takes every per-star offset.
            EffectKind::CatalogProperMotionError => (0..r.len()).collect(),
            _ => Vec::new(),
        };
        idx.extend(keep.iter().map(|k| r.start + k));
    }
    let flight_fit = super::fit::solve(&res.systems.full, &res.layout, &idx)
        .unwrap_or_else(|| res.final_fit.clone());
    let g = flight_fit.expand(res.layout.total);
    let mut applied = Vec::new();
    let mut ground_only = Vec::new();
    let mut table = adjusted_alignment(base, &g, counts)?;
    let ground_alignment =
        adjusted_alignment(base, &res.final_fit.expand(res.layout.total), counts)?;
    applied.push(
        "alignments re-estimated jointly with the effects (FHST frame of the OBC kept)".to_owned(),
    );
    let mut filter = None;
    let mut catalog = None;
    let names = super::measurements::SENSOR_NAMES;
    for i in effects {
        let e = &res.layout.effects[i];
        let r = res.layout.range(i);
        // Only terms determined at 3σ go up: an ill-determined polynomial term (a transfer
        // function seen over a small part of the field) would make the OBC worse elsewhere.
        let p = |k: usize| match flight_fit.param(r.start + k) {
            Some((x, s)) if x.abs() > 3.0 * s => x,
            _ => 0.0,
        };
        let _ = &g;
        let label = e.label();
        match (e.kind, e.sensor) {
            (EffectKind::TimeTagOffset, Some(s)) => {
                table.corrections.time_offset_s[s] += p(0) * 1e-3;
                applied.push(format!(
                    "{label}: alignment.corrections.time_offset_s[{}] = {:.4} s",
                    names[s], table.corrections.time_offset_s[s]
                ));
            }
            (EffectKind::FhstDistortion, Some(s)) if s < 2 => {
                let d = &mut table.corrections.fhst_distortion[s];
                d[0] += p(0) * RAD_PER_ARCSEC / FHST_REF_RAD.powi(3);
                d[1] += p(1) * RAD_PER_ARCSEC / FHST_REF_RAD.powi(2);
                d[2] += p(2) * RAD_PER_ARCSEC / FHST_REF_RAD.powi(2);
                applied.push(format!(
                    "{label}: alignment.corrections.fhst_distortion[{}] = [{:.5}, {:.5}, {:.5}]",
                    names[s], d[0], d[1], d[2]
                ));
            }
            (EffectKind::FssTransferFunction, Some(s)) if s >= 2 => {
                let c = &mut table.corrections.fss_transfer[s - 2];
                let e3 = FSS_EDGE_RAD.powi(3);
                c[0] += p(0) * 1e-6;
                c[1] += p(1) * RAD_PER_ARCSEC / e3;
                c[3] += p(3) * 1e-6;
                c[4] += p(4) * RAD_PER_ARCSEC / e3;
                applied.push(format!(
                    "{label}: alignment.corrections.fss_transfer[{}] = [{:.3e}, {:.3e}, {:.3e}, {:.3e}, {:.3e}, {:.3e}] (scale and cross terms)",
                    names[s], c[0], c[1], c[2], c[3], c[4], c[5]
                ));
                ground_only.push(format!("{label}: cubic and cyclic terms (no table field)"));
            }
            (EffectKind::CatalogProperMotionError, _) => match flown_catalog {
                Some(flown) => {
                    let (c, n) = corrected_catalog(flown, e, r.start, &flight_fit);
                    applied.push(format!(
                        "{label}: star_catalog: {n} of {} stars moved by their offsets (net rotation removed, shrunk to the minimum-variance estimate)",
                        e.stars.len()
                    ));
                    catalog = Some(c);
                }
                None => ground_only.push(format!(
                    "{label}: no flown star catalog in the run folder to correct"
                )),
            },
            (EffectKind::AberrationAnnual | EffectKind::Aberration, _) => {
                let mut f = *flown_filter;
                f.aberration_correction = true;
                filter = Some(f);
                applied.push(format!("{label}: filter.aberration_correction = true"));
            }
            _ => ground_only.push(format!("{label}: no flight-table hook")),
        }
    }
    table.validate().map_err(|e| {
        anyhow::anyhow!("diagnose: the corrected alignment table does not validate ({e:?})")
    })?;
    if let Some(f) = &filter {
        f.validate()
            .map_err(|e| anyhow::anyhow!("diagnose: the filter table does not validate ({e:?})"))?;
    }
    if let Some(c) = &catalog {
        c.validate().map_err(|e| {
            anyhow::anyhow!("diagnose: the corrected star catalog does not validate ({e:?})")
        })?;
    }
    Ok(FlightUpdate {
        alignment: table,
        ground_alignment,
        filter,
        catalog,
        applied,
        ground_only,
    })
}

/// `base` with the alignment corrections of `g` (M' = Rot(θ) M for FHST2, FSS1, FSS2; FHST1
/// is the reference), then the common rotation that keeps the OBC's FHST frame.
fn adjusted_alignment(
    base: &AlignmentTable,
    g: &nalgebra::DVector<f64>,
    counts: [usize; 4],
) -> anyhow::Result<AlignmentTable> {
    // Alignments: M' = Rot(θ) M for FHST2, FSS1, FSS2 (FHST1 is the reference), then the
    // common rotation that keeps the OBC's FHST frame.
    let m_base: Vec<Matrix3<f64>> = base
        .matrices()
        .iter()
        .map(|m| matrix_from_rows(m))
        .collect();
    let mut m_new = m_base.clone();
    for (s, m) in m_new.iter_mut().enumerate() {
        if let Some(o) = align_offset(s) {
            let theta = Vector3::new(g[o], g[o + 1], g[o + 2]) * RAD_PER_ARCSEC;
            *m = rot(&theta) * *m;
        }
    }
    let adj = preserve_obc_attitude(&m_base, &m_new, 0, 1, BoresightFrame::Bisector)?;
    let ortho = |m: &Matrix3<f64>| rows_from_matrix(&Quat::from_dcm(m).to_dcm());
    let mut table = *base;
    table.m_acs_from_fhst1 = ortho(&adj.m_acs_from_sensor_adjusted[0]);
    table.m_acs_from_fhst2 = ortho(&adj.m_acs_from_sensor_adjusted[1]);
    table.m_acs_from_fss1 = ortho(&adj.m_acs_from_sensor_adjusted[2]);
    table.m_acs_from_fss2 = ortho(&adj.m_acs_from_sensor_adjusted[3]);
    // A sensor without data keeps its flown alignment (the common rotation of the adjustment
    // is a change of gauge, not information about it).
    for (s, &c) in counts.iter().enumerate() {
        if c < 50 {
            let rows = *base.matrices()[s];
            match s {
                0 => table.m_acs_from_fhst1 = rows,
                1 => table.m_acs_from_fhst2 = rows,
                2 => table.m_acs_from_fss1 = rows,
                _ => table.m_acs_from_fss2 = rows,
            }
        }
    }
    Ok(table)
}

/// The flown catalog with the offsets of effect `e` (parameters from `start` in `fit`, east
/// and north per star, arcsec, true − catalog) applied to every star the data determine (σ
/// of both components below half the prior, as in the halves check of the search). The
/// per-star σ carries the gauge freedom (a common rotation of the stars is a rotation of the
/// attitude), so it is not a test of each offset; the offsets go up with their weighted net
/// rotation removed, which keeps the OBC's frame. Returns the table and the stars moved.
fn corrected_catalog(
    flown: &StarCatalogTable,
    e: &super::effects::Effect,
    start: usize,
    fit: &super::fit::SubFit,
) -> (StarCatalogTable, usize) {
    let n = e.stars.len();
    let mut x = vec![0.0; 2 * n];
    let mut var = vec![f64::INFINITY; 2 * n];
    let mut determined = vec![false; n];
    for k in 0..n {
        let (Some((xe, se)), Some((xn, sn))) =
            (fit.param(start + 2 * k), fit.param(start + 2 * k + 1))
        else {
            continue;
        };
        if se < 0.5 * e.prior_sigma[2 * k] && sn < 0.5 * e.prior_sigma[2 * k + 1] {
            determined[k] = true;
            x[2 * k] = xe;
            x[2 * k + 1] = xn;
            var[2 * k] = se * se;
            var[2 * k + 1] = sn * sn;
        }
    }
    let x = super::effects::remove_net_rotation(&e.star_dirs, &x, &var);
    // Each offset is known to about its σ (≈ the size of the offsets themselves in a few
    // hours of data): the table gets the linear minimum-variance estimate given the spread
    // of the offsets over the stars, τ² = mean(x² − σ²) (empirical Bayes), i.e. each offset
    // shrunk by τ²/(τ² + σ²). A noisy offset then moves its star little, and on average the
    // catalog gets closer to the sky, never farther.
    let comps: Vec<usize> = (0..2 * n).filter(|&i| var[i].is_finite()).collect();
    let tau2 = if comps.is_empty() {
        0.0
    } else {
        (comps.iter().map(|&i| x[i] * x[i] - var[i]).sum::<f64>() / comps.len() as f64).max(0.0)
    };
    let x: Vec<f64> = (0..2 * n)
        .map(|i| {
            if var[i].is_finite() {
                x[i] * tau2 / (tau2 + var[i])
            } else {
                0.0
            }
        })
        .collect();
    let mut out = flown.clone();
    let mut moved = 0;
    for (k, hip) in e.stars.iter().enumerate() {
        if !determined[k] {
            continue;
        }
        let Some(star) = out.stars.iter_mut().find(|s| s.id == *hip) else {
            continue;
        };
        let u = star.dir();
        let [east, north] = super::effects::tangent_basis_eci(&u);
        let v = (u + (east * x[2 * k] + north * x[2 * k + 1]) * RAD_PER_ARCSEC).normalize();
        #[allow(clippy::cast_possible_truncation)]
        {
            star.dir_eci = [v.x as f32, v.y as f32, v.z as f32];
        }
        moved += 1;
    }
    (out, moved)
}
