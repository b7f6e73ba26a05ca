//! # Into the flight model: detected effects as table data that `fsw-core` applies
//!
//! | effect | table field | what the OBC does (fsw-core) |
//! |---|---|---|
//! | alignments (joint fit) | `AlignmentTable.m_acs_from_*` (re-adjusted so the OBC's two-tracker frame is kept, paper appendix) | `M_AS` |
//! | `time_tag_offset` | `corrections.time_offset_s[i] += τ` | `executive::time_align`: `b(t) = Rot(ω τ) b(t − τ)` |
//! | `fhst_distortion` | `corrections.fhst_distortion[i] += [d0, d1, d2]` with `d0 = Δρ(4°)/F³`, `d1,2 = c/F²` (rad) | `fhst::correct_distortion`: `H = H_m − (d0 ρ² H_m + d1 H_m V_m)` |
//! | `magnitude_bias` | `corrections.fhst_magnitude_bias_rad_per_mag[i] += [b_H, b_V]` (″/mag → rad/mag, reference magnitude 4 on both sides) | `fhst::correct_magnitude_bias`: `H −= b_H (m − 4)` with the sample's instrument magnitude |
//! | `thermal_alignment_drift` | `corrections.thermal_alignment_rad_per_c[i] += k` (″/°C → rad/°C), `thermal_reference_c[i]` = the run mean of the sensor's temperature (the regressor's reference; kept when the flown table already has a drift for the sensor, the constant `k (T_ref − T̄)` then going into the alignment) | `AlignmentTable::m_acs_from_sensor_rows_at`: `M_AS(T) = Rot(k (T − T_ref)) M_AS` at the raw frame's temperature |
//! | `fss_transfer_function` | `corrections.fss_transfer[i] += [scale, cross/E³, 0, scale, cross/E³, 0]`, `fss_cubic[i] += [cubic/E³, cubic/E³]`, `fss_cyclic[i] = [p, s_α, c_α, s_β, c_β]` (amplitudes added when the flown pitch is the same or zero) | `fss::correct_transfer_full`: `α = α_m − (c0 α_m + c1 α_m β_m² + c2) − k_α α_m³ − s_α sin(2π α_m/p) − c_α cos(2π α_m/p)` |
//! | `gyro_scale_asymmetry` ([`iru_update`]) | `IruTable.scale_asymmetry_{primary,backup}[j] += a_j` (ppm → unitless; ACS axis j = channel j of the configuration flown, G ≈ I) | `iru::delta_theta_from_pulses`: `Δθ = G diag(k_j (1 − a_j sgn ΔN_j)) w ΔN` |
//! | `aberration_annual` | `FilterTable.aberration_correction = true` | annual aberration of catalog stars and the Sun |
//! | `alignment_step` | the step's rotation (all three components) folded into the sensor's `M_AS`: the table flies the alignment after the step | `M_AS` |
//! | `catalog_proper_motion_error` | the flown `StarCatalogTable`, each star the data determine moved by its offset (net rotation removed, shrunk by τ²/(τ² + σ²)), `u' = u + x_E e_E + x_N e_N` | the onboard catalog (identification and reference directions) |
//!
//! Only terms whose estimate exceeds 3σ are written (the others stay as flown); catalog offsets
//! go up for every star the data determine (their σ carries the gauge, see
//! [`corrected_catalog`]).
//!
//! Signs: every library column is the effect's addition to the *measured* angle (for the
//! gyro, to the measured rotation: `+a |Δθ|`), and the tables subtract that addition from
//! the measurement (distortion, magnitude bias, transfer function, asymmetry), rotate the
//! alignment as the drift does (`M' = Rot(θ) M`, the alignment columns' convention) or carry
//! the measurement forward by τ (time tag), so the estimate goes in with the sign it has (the
//! sim-harness truth models add exactly these terms: `sensors/{fhst,fss,iru}.rs`).
//! Effects without a flight hook are listed as ground-only: orbital aberration and
//! orbit-periodic alignment (the OBC has no orbit), the gyro bias drift and thermal bias (the
//! OBC estimates its bias itself), and the non-library extension terms.

use super::effects::{EffectKind, FHST_REF_RAD, FSS_EDGE_RAD};
use super::fit::{align_offset, N_ALIGN};
use super::search::SearchResult;
use super::Detected;
use crate::calibration::adjust::{preserve_obc_attitude, BoresightFrame};
use fsw_core::attitude::{rot, Quat};
use fsw_core::tables::types::{matrix_from_rows, rows_from_matrix};
use fsw_core::tables::{AlignmentTable, FilterTable, IruTable, StarCatalogTable};
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
    /// The layout's parameters the tables hold (the alignments and the terms written), for
    /// the held-out validation ([`super::heldout`]).
    #[serde(skip)]
    pub flight_idx: Vec<usize>,
    /// The fit of those parameters (the tables' values, before the adjustment that keeps the
    /// OBC's FHST frame), for scoring.
    #[serde(skip)]
    pub flight_fit: super::fit::SubFit,
    /// What went into the tables.
    pub applied: Vec<String>,
    /// Effects with no flight-table hook (corrected on the ground only).
    pub ground_only: Vec<String>,
}

/// What the held-out validation let through ([`super::heldout`]): the tables are rebuilt with
/// only these parameters free and the alignments of the other sensors held at the reference's.
#[derive(Clone, Copy, Debug)]
pub struct Restriction<'a> {
    /// The layout's parameters that may change (the components taken).
    pub free: &'a [usize],
    /// The reference table's alignment parameters relative to the alignments the
    /// measurements were built with ([`super::heldout::alignment_parameters_arcsec`]); the
    /// `base` of [`flight_update`] is then the reference table itself.
    pub reference_arcsec: [f64; N_ALIGN],
}

/// Whether flight parameter `p` may move under `restrict` (every one without).
fn is_free(restrict: Option<Restriction<'_>>, p: usize) -> bool {
    restrict.is_none_or(|r| r.free.contains(&p))
}

/// The flight fit and the terms it holds, which every table term is read from.
struct FlightFit<'a> {
    res: &'a SearchResult,
    fit: super::fit::SubFit,
    /// Terms that go up only when determined at 3σ.
    gated: Vec<usize>,
}

impl FlightFit<'_> {
    /// Parameter `i` when it is a gated term determined at 3σ, else 0.
    fn p3(&self, i: usize) -> f64 {
        if !self.gated.contains(&i) {
            return 0.0;
        }
        match self.fit.param(i) {
            Some((x, s)) if x.abs() > 3.0 * s => x,
            _ => 0.0,
        }
    }

    /// Rotations folded into each sensor's alignment (arcsec, ACS): a thermal drift's
    /// constant `k (T_ref − T̄)` that moves the fit's reference temperature (the run mean T̄)
    /// to the table's, and an alignment step (the table flies the alignment after it, the
    /// flight going on from the end of the span). Also the thermal reference temperatures.
    fn folded_rotations(
        &self,
        effects: &[usize],
        base: &AlignmentTable,
        temperature_mean_c: [f64; 5],
    ) -> ([f64; 4], [Vector3<f64>; 4]) {
        let res = self.res;
        let mut thermal_reference = base.corrections.thermal_reference_c;
        let mut fixed_rotation_arcsec = [Vector3::zeros(); 4];
        for &i in effects {
            let e = &res.layout.effects[i];
            if let (EffectKind::ThermalAlignmentDrift, Some(s)) = (e.kind, e.sensor) {
                let start = res.layout.range(i).start;
                let k = Vector3::new(self.p3(start), self.p3(start + 1), self.p3(start + 2));
                if k == Vector3::zeros() {
                    continue;
                }
                let flown = base.corrections.thermal_alignment_rad_per_c[s];
                if flown.iter().all(|x| *x == 0.0) {
                    thermal_reference[s] = temperature_mean_c[s];
                }
                fixed_rotation_arcsec[s] += k * (thermal_reference[s] - temperature_mean_c[s]);
            }
            if let (EffectKind::AlignmentStep, Some(s)) = (e.kind, e.sensor) {
                let start = res.layout.range(i).start;
                let x = |k: usize| self.fit.param(start + k).map_or(0.0, |(x, _)| x);
                fixed_rotation_arcsec[s] += Vector3::new(x(0), x(1), x(2));
            }
        }
        (thermal_reference, fixed_rotation_arcsec)
    }
}

/// The tables as the effects change them, and what is said of each change.
struct TableChanges<'a> {
    table: AlignmentTable,
    filter: Option<FilterTable>,
    catalog: Option<StarCatalogTable>,
    applied: Vec<String>,
    ground_only: Vec<String>,
    flown_filter: &'a FilterTable,
    flown_catalog: Option<&'a StarCatalogTable>,
    thermal_reference: [f64; 4],
}

/// Which alignments the flight fit re-estimated: the line of `applied` that says so.
fn refit_note(restrict: Option<Restriction<'_>>) -> Option<String> {
    let names = super::measurements::SENSOR_NAMES;
    let refit: Vec<&str> = (1..4)
        .filter(|s| (0..3).any(|ax| is_free(restrict, 3 * (s - 1) + ax)))
        .map(|s| names[s])
        .collect();
    if refit.len() == 3 {
        Some(
            "alignments re-estimated jointly with the effects (FHST frame of the OBC kept)"
                .to_owned(),
        )
    } else if !refit.is_empty() {
        Some(format!(
            "alignments of {} re-estimated jointly with the effects, the others as the reference table (FHST frame of the OBC kept)",
            refit.join(", ")
        ))
    } else {
        None
    }
}

impl TableChanges<'_> {
    /// Puts effect `i`'s terms into the table that has a hook for it, or says it has none.
    fn apply_effect(&mut self, ff: &FlightFit<'_>, i: usize) {
        let names = super::measurements::SENSOR_NAMES;
        let e = &ff.res.layout.effects[i];
        let r = ff.res.layout.range(i);
        let p = |k: usize| ff.p3(r.start + k);
        let label = e.label();
        let table = &mut self.table;
        match (e.kind, e.sensor) {
            (EffectKind::TimeTagOffset, Some(s)) => {
                table.corrections.time_offset_s[s] += p(0) * 1e-3;
                self.applied.push(format!(
                    "{label}: alignment.corrections.time_offset_s[{}] = {:.4} s",
                    names[s], table.corrections.time_offset_s[s]
                ));
            }
            (EffectKind::FhstDistortion, Some(s)) if s < 2 => {
                let d = &mut table.corrections.fhst_distortion[s];
                d[0] += p(0) * RAD_PER_ARCSEC / FHST_REF_RAD.powi(3);
                d[1] += p(1) * RAD_PER_ARCSEC / FHST_REF_RAD.powi(2);
                d[2] += p(2) * RAD_PER_ARCSEC / FHST_REF_RAD.powi(2);
                self.applied.push(format!(
                    "{label}: alignment.corrections.fhst_distortion[{}] = [{:.5}, {:.5}, {:.5}]",
                    names[s], d[0], d[1], d[2]
                ));
            }
            (EffectKind::MagnitudeBias, Some(s)) if s < 2 => {
                let b = &mut table.corrections.fhst_magnitude_bias_rad_per_mag[s];
                b[0] += p(0) * RAD_PER_ARCSEC;
                b[1] += p(1) * RAD_PER_ARCSEC;
                self.applied.push(format!(
                    "{label}: alignment.corrections.fhst_magnitude_bias_rad_per_mag[{}] = [{:.3}, {:.3}] arcsec/mag",
                    names[s],
                    b[0] / RAD_PER_ARCSEC,
                    b[1] / RAD_PER_ARCSEC
                ));
            }
            (EffectKind::ThermalAlignmentDrift, Some(s)) => {
                let k = &mut table.corrections.thermal_alignment_rad_per_c[s];
                for (ax, kx) in k.iter_mut().enumerate() {
                    *kx += p(ax) * RAD_PER_ARCSEC;
                }
                table.corrections.thermal_reference_c[s] = self.thermal_reference[s];
                self.applied.push(format!(
                    "{label}: alignment.corrections.thermal_alignment_rad_per_c[{}] = [{:.3}, {:.3}, {:.3}] arcsec/degC about ACS x, y, z, thermal_reference_c = {:.2} degC",
                    names[s],
                    k[0] / RAD_PER_ARCSEC,
                    k[1] / RAD_PER_ARCSEC,
                    k[2] / RAD_PER_ARCSEC,
                    self.thermal_reference[s]
                ));
            }
            (EffectKind::AlignmentStep, Some(s)) => {
                let x = |k: usize| ff.fit.param(r.start + k).unwrap_or((f64::NAN, f64::NAN));
                self.applied.push(format!(
                    "{label}: the alignment of {} after the step at t = {:.0} s flies (step [{:.2} ± {:.2}, {:.2} ± {:.2}, {:.2} ± {:.2}] arcsec about ACS x, y, z)",
                    names[s],
                    e.step_time_s.unwrap_or(f64::NAN),
                    x(0).0,
                    x(0).1,
                    x(1).0,
                    x(1).1,
                    x(2).0,
                    x(2).1
                ));
            }
            (EffectKind::FssTransferFunction, Some(s)) if s >= 2 => {
                self.apply_fss_transfer(e, s, &p);
            }
            (EffectKind::CatalogProperMotionError, _) => match self.flown_catalog {
                Some(flown) => {
                    let (c, n) = corrected_catalog(flown, e, r.start, &ff.fit);
                    self.applied.push(format!(
                        "{label}: star_catalog: {n} of {} stars moved by their offsets (net rotation removed, shrunk to the minimum-variance estimate)",
                        e.stars.len()
                    ));
                    self.catalog = Some(c);
                }
                None => self.ground_only.push(format!(
                    "{label}: no flown star catalog in the run folder to correct"
                )),
            },
            (EffectKind::AberrationAnnual | EffectKind::Aberration, _) => {
                let mut f = *self.flown_filter;
                f.aberration_correction = true;
                self.filter = Some(f);
                self.applied
                    .push(format!("{label}: filter.aberration_correction = true"));
            }
            _ => self
                .ground_only
                .push(format!("{label}: no flight-table hook")),
        }
    }

    /// An FSS transfer function (sensor `s`, parameters `p`): its polynomial into
    /// `fss_transfer`/`fss_cubic`, its cyclic term into `fss_cyclic` when determined and of
    /// the flown pitch (one pitch per sensor).
    fn apply_fss_transfer(
        &mut self,
        e: &super::effects::Effect,
        s: usize,
        p: &dyn Fn(usize) -> f64,
    ) {
        let names = super::measurements::SENSOR_NAMES;
        let label = e.label();
        let corr = &mut self.table.corrections;
        let e3 = FSS_EDGE_RAD.powi(3);
        let c = &mut corr.fss_transfer[s - 2];
        c[0] += p(0) * 1e-6;
        c[1] += p(1) * RAD_PER_ARCSEC / e3;
        c[3] += p(3) * 1e-6;
        c[4] += p(4) * RAD_PER_ARCSEC / e3;
        let c = *c;
        let k = &mut corr.fss_cubic[s - 2];
        k[0] += p(2) * RAD_PER_ARCSEC / e3;
        k[1] += p(5) * RAD_PER_ARCSEC / e3;
        let k = *k;
        self.applied.push(format!(
            "{label}: alignment.corrections.fss_transfer[{}] = [{:.3e}, {:.3e}, {:.3e}, {:.3e}, {:.3e}, {:.3e}], fss_cubic = [{:.3e}, {:.3e}]",
            names[s], c[0], c[1], c[2], c[3], c[4], c[5], k[0], k[1]
        ));
        let Some(pitch) = e.pitch_rad else {
            return;
        };
        let amp = [p(6), p(7), p(8), p(9)].map(|a| a * RAD_PER_ARCSEC);
        let cyc = &mut corr.fss_cyclic[s - 2];
        if amp.iter().all(|a| *a == 0.0) {
            self.ground_only.push(format!(
                "{label}: cyclic term at pitch {:.3} deg not determined at 3 sigma",
                pitch.to_degrees()
            ));
        } else if cyc[0] == 0.0 || (cyc[0] - pitch).abs() < 1e-9 {
            cyc[0] = pitch;
            for (c, a) in cyc[1..].iter_mut().zip(amp) {
                *c += a;
            }
            self.applied.push(format!(
                "{label}: alignment.corrections.fss_cyclic[{}] = [{:.4} deg, {:.2}, {:.2}, {:.2}, {:.2} arcsec]",
                names[s],
                cyc[0].to_degrees(),
                cyc[1] / RAD_PER_ARCSEC,
                cyc[2] / RAD_PER_ARCSEC,
                cyc[3] / RAD_PER_ARCSEC,
                cyc[4] / RAD_PER_ARCSEC
            ));
        } else {
            self.ground_only.push(format!(
                "{label}: cyclic term at pitch {:.3} deg (the flown table has one at {:.3} deg; one pitch per sensor)",
                pitch.to_degrees(),
                cyc[0].to_degrees()
            ));
        }
    }

    /// Every changed table validates.
    fn validate(&self) -> anyhow::Result<()> {
        self.table.validate().map_err(|e| {
            anyhow::anyhow!("diagnose: the corrected alignment table does not validate ({e:?})")
        })?;
        if let Some(f) = &self.filter {
            f.validate().map_err(|e| {
                anyhow::anyhow!("diagnose: the filter table does not validate ({e:?})")
            })?;
        }
        if let Some(c) = &self.catalog {
            c.validate().map_err(|e| {
                anyhow::anyhow!("diagnose: the corrected star catalog does not validate ({e:?})")
            })?;
        }
        Ok(())
    }
}

/// Build the tables from the final fit. `temperature_mean_c` is the run mean of each
/// temperature slot, the reference of the thermal parameters
/// ([`super::measurements::MeasurementSet::temperature_mean_c`]). `base` is the table the
/// measurements were built with, or with a `restrict`ion the reference table it holds.
///
/// # Errors
/// The adjusted table does not validate (an effect too large for the table's range).
pub fn flight_update(
    res: &SearchResult,
    base: &AlignmentTable,
    flown_filter: &FilterTable,
    flown_catalog: Option<&StarCatalogTable>,
    counts: [usize; 4],
    temperature_mean_c: [f64; 5],
    restrict: Option<Restriction<'_>>,
) -> anyhow::Result<FlightUpdate> {
    // 1. The flight model: the final model restricted to what the OBC can apply (alignments,
    //    time offsets, distortion, magnitude bias, thermal drift, the FSS transfer function,
    //    annual aberration). The alignments then absorb the rest as well as they can for the
    //    OBC's own model; taking the full model's alignments would leave the OBC with
    //    alignments that were estimated together with terms it does not have (an
    //    orbit-periodic term trades with its alignment).
    let mut effects: Vec<usize> = res.baseline.clone();
    effects.extend(&res.added);
    let free = |p: usize| is_free(restrict, p);
    effects.retain(|&i| res.layout.range(i).any(free));
    // Alignments not let through stay at the reference's.
    let held_alignment: Vec<super::fit::Fixed> = restrict.map_or_else(Vec::new, |r| {
        (0..N_ALIGN)
            .filter(|&p| !free(p))
            .map(|p| super::fit::Fixed {
                index: p,
                value: r.reference_arcsec[p],
                sigma: 0.0,
            })
            .collect()
    });
    // 2. Its fit, the gated terms kept at 3σ.
    let (always, gated) = flight_terms(res, &effects, &free);
    let (fit, gated) = gated_fit(res, &always, gated, &held_alignment);
    let ff = FlightFit { res, fit, gated };
    let g_table = relative_to_base(ff.fit.expand(res.layout.total), restrict);
    // 3. The alignments, with the rotations folded in; the ground's for comparison.
    let (thermal_reference, fixed_rotation_arcsec) =
        ff.folded_rotations(&effects, base, temperature_mean_c);
    let table = adjusted_alignment(base, &g_table, &fixed_rotation_arcsec, counts)?;
    let g_ground = relative_to_base(res.final_fit.expand(res.layout.total), restrict);
    let ground_alignment = adjusted_alignment(base, &g_ground, &[Vector3::zeros(); 4], counts)?;
    // 4. Every effect into the table that has a hook for it.
    let mut changes = TableChanges {
        table,
        filter: None,
        catalog: None,
        applied: refit_note(restrict).into_iter().collect(),
        ground_only: Vec::new(),
        flown_filter,
        flown_catalog,
        thermal_reference,
    };
    for i in effects {
        changes.apply_effect(&ff, i);
    }
    // 5. Every changed table validates.
    changes.validate()?;
    Ok(FlightUpdate {
        alignment: changes.table,
        ground_alignment,
        filter: changes.filter,
        catalog: changes.catalog,
        flight_idx: always.iter().chain(&ff.gated).copied().collect(),
        flight_fit: ff.fit,
        applied: changes.applied,
        ground_only: changes.ground_only,
    })
}

/// The flight model's parameters: `always` — the alignments, the aberration scale (its table
/// field is a switch) and the catalog offsets (every star goes up, shrunk) — and `gated`, the
/// terms that go up only when determined at 3σ (only those `free` lets through).
fn flight_terms(
    res: &SearchResult,
    effects: &[usize],
    free: &dyn Fn(usize) -> bool,
) -> (Vec<usize>, Vec<usize>) {
    let mut always: Vec<usize> = (0..N_ALIGN).collect();
    let mut gated: Vec<usize> = Vec::new();
    for &i in effects {
        let r = res.layout.range(i);
        let (a, g): (Vec<usize>, Vec<usize>) = match res.layout.effects[i].kind {
            EffectKind::AberrationAnnual | EffectKind::Aberration => (vec![0], Vec::new()),
            EffectKind::TimeTagOffset => (Vec::new(), vec![0]),
            EffectKind::FhstDistortion | EffectKind::ThermalAlignmentDrift => {
                (Vec::new(), vec![0, 1, 2])
            }
            // A step is one rotation: once it is accepted (and the held-out gate takes it),
            // all three components go up, each at its estimate. Zeroing a component under
            // 3σ would fly the alignment before the step about that axis: the writer's 12″
            // FHST1 step about y, at 7 ± 7″ in six hours, flew 17.7″ from the truth.
            EffectKind::AlignmentStep => ((0..3).collect(), Vec::new()),
            EffectKind::MagnitudeBias => (Vec::new(), vec![0, 1]),
            // Scale, cross, cubic and (with a pitch) the cyclic sin/cos of both heads.
            EffectKind::FssTransferFunction => (Vec::new(), (0..r.len()).collect()),
            // The onboard catalog takes every per-star offset.
            EffectKind::CatalogProperMotionError => ((0..r.len()).collect(), Vec::new()),
            _ => (Vec::new(), Vec::new()),
        };
        always.extend(a.iter().map(|k| r.start + k));
        gated.extend(g.iter().map(|k| r.start + k).filter(|&p| free(p)));
    }
    (always, gated)
}

/// The flight fit and the gated terms that pass. Only terms determined at 3σ go up: an
/// ill-determined polynomial term (a transfer function seen over a small part of the field)
/// would make the OBC worse elsewhere. The fit is repeated without the terms that fail, until
/// every term left passes, so that the alignments that go up were estimated with exactly the
/// terms that go up (an FSS cubic term left out after a joint fit would leave its alignment
/// wrong for the OBC). Terms only leave, so this ends within `gated.len()` fits. The time
/// tags stay at their estimates against the gyro (the batch system alone does not determine
/// their common part), and `held` alignments at their values.
fn gated_fit(
    res: &SearchResult,
    always: &[usize],
    mut gated: Vec<usize>,
    held: &[super::fit::Fixed],
) -> (super::fit::SubFit, Vec<usize>) {
    let solve = |gated: &[usize]| {
        let mut idx = always.to_vec();
        idx.extend(gated);
        let mut fixed: Vec<super::fit::Fixed> = res
            .fixed
            .iter()
            .filter(|f| idx.contains(&f.index))
            .copied()
            .collect();
        fixed.extend(held);
        super::fit::solve_fixed(&res.systems.full, &res.layout, &idx, &fixed)
    };
    let mut flight_fit = res.final_fit.clone();
    for _ in 0..=gated.len() {
        let Some(fit) = solve(&gated) else {
            break;
        };
        let before = gated.len();
        gated.retain(|&i| matches!(fit.param(i), Some((x, s)) if x.abs() > 3.0 * s));
        flight_fit = fit;
        if gated.len() == before {
            break;
        }
    }
    (flight_fit, gated)
}

/// The alignment parameters of `g` relative to the table the tables are built on: with a
/// restriction, the reference table, whose parameters are subtracted.
fn relative_to_base(
    mut g: nalgebra::DVector<f64>,
    restrict: Option<Restriction<'_>>,
) -> nalgebra::DVector<f64> {
    if let Some(r) = restrict {
        for (p, v) in r.reference_arcsec.iter().enumerate() {
            g[p] -= v;
        }
    }
    g
}

/// The IRU table with the gyro-side effects: the scale-factor asymmetry (`gyro_scale_asymmetry`,
/// ppm per ACS axis, `+` = over-reads both ways) added to the asymmetry of the configuration
/// flown (`backup`: the backup channels flew), each axis only when determined at 3σ; ACS axis
/// j is channel j of the configuration (X, Y, Z), as `G` is the identity to 2e-3. The bias
/// effects are ground-only (the OBC estimates its bias). Returns the table, what was applied
/// and what stays on the ground.
#[must_use]
pub fn iru_update(
    flown: &IruTable,
    detected: &[Detected],
    backup: bool,
) -> (IruTable, Vec<String>, Vec<String>) {
    let mut out = *flown;
    let mut applied = Vec::new();
    let mut ground_only = Vec::new();
    for d in detected.iter().filter(|d| d.sensor == "IRU") {
        if d.effect != "gyro_scale_asymmetry" {
            ground_only.push(format!(
                "{}[IRU]: no flight-table hook (the OBC estimates its gyro bias)",
                d.effect
            ));
            continue;
        }
        let a = if backup {
            &mut out.scale_asymmetry_backup
        } else {
            &mut out.scale_asymmetry_primary
        };
        let mut determined = 0;
        for (j, axis) in ["x", "y", "z"].iter().enumerate() {
            let (Some(&x), Some(&sx)) = (d.parameters.get(*axis), d.sigma.get(*axis)) else {
                continue;
            };
            if x.abs() > 3.0 * sx {
                a[j] += x * 1e-6;
                determined += 1;
            }
        }
        if determined == 0 {
            ground_only.push("gyro_scale_asymmetry[IRU]: no axis determined at 3 sigma".into());
        } else {
            applied.push(format!(
                "gyro_scale_asymmetry[IRU]: iru.scale_asymmetry_{} = [{:.0}, {:.0}, {:.0}] ppm",
                if backup { "backup" } else { "primary" },
                a[0] * 1e6,
                a[1] * 1e6,
                a[2] * 1e6
            ));
        }
    }
    (out, applied, ground_only)
}

/// `base` with the alignment corrections of `g` (M' = Rot(θ) M for FHST2, FSS1, FSS2; FHST1
/// is the reference) and the extra rotations `extra_arcsec` per sensor (ACS, arcsec), then the
/// common rotation that keeps the OBC's FHST frame.
fn adjusted_alignment(
    base: &AlignmentTable,
    g: &nalgebra::DVector<f64>,
    extra_arcsec: &[Vector3<f64>; 4],
    counts: [usize; 4],
) -> anyhow::Result<AlignmentTable> {
    // Alignments: M' = Rot(θ) M for FHST2, FSS1, FSS2 (FHST1 is the reference), then the
    // common rotation that keeps the OBC's FHST frame.
    let m_base = base.matrices().map(matrix_from_rows).to_vec();
    let mut m_new = m_base.clone();
    for (s, m) in m_new.iter_mut().enumerate() {
        let mut theta = extra_arcsec[s];
        if let Some(o) = align_offset(s) {
            theta += Vector3::new(g[o], g[o + 1], g[o + 2]);
        }
        if theta != Vector3::zeros() {
            *m = rot(&(theta * RAD_PER_ARCSEC)) * *m;
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
            *table.matrices_mut()[s] = *base.matrices()[s];
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
    // The full form's offsets carry the gauge; the sparse form's few stars do not (their
    // common rotation is data: removing it would take most of three stars' offsets away).
    let x = if e.sparse {
        x
    } else {
        super::effects::remove_net_rotation(&e.star_dirs, &x, &var)
    };
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::search::Evidence;
    use std::collections::BTreeMap;

    fn detected(effect: &str, values: [(f64, f64); 3]) -> Detected {
        let mut parameters = BTreeMap::new();
        let mut sigma = BTreeMap::new();
        for (name, (x, s)) in ["x", "y", "z"].iter().zip(values) {
            parameters.insert((*name).to_owned(), x);
            sigma.insert((*name).to_owned(), s);
        }
        Detected {
            effect: effect.into(),
            sensor: "IRU".into(),
            parameters,
            sigma,
            units: BTreeMap::new(),
            evidence: Evidence {
                effect: effect.into(),
                k: 3,
                delta_chi2: 0.0,
                f: 0.0,
                p_value: 0.0,
                p_holm: 0.0,
                delta_bic: 0.0,
                halves_chi2: 0.0,
                halves_p: 1.0,
                halves_estimates: (Vec::new(), Vec::new()),
                signature_excess: (0.0, 0.0),
                adequate: true,
                accepted: true,
                rejected_because: None,
            },
            star_dirs: BTreeMap::new(),
        }
    }

    /// The asymmetry goes into the flown configuration's channels with its sign (ppm →
    /// unitless, `+` = over-reads both ways, as `fsw_core::iru` corrects), only the axes
    /// determined at 3σ, added to what flew; the bias effects stay on the ground.
    #[test]
    fn iru_asymmetry_into_the_flown_configuration_at_3_sigma() {
        let mut flown = IruTable::prelaunch();
        flown.scale_asymmetry_primary = [1.0e-4, 0.0, 0.0];
        let d = [
            detected(
                "gyro_scale_asymmetry",
                [(380.0, 40.0), (-310.0, 50.0), (90.0, 45.0)],
            ),
            detected("gyro_bias_ramp", [(1.0, 0.1); 3]),
        ];
        let (t, applied, ground) = iru_update(&flown, &d, false);
        assert_eq!(t.validate(), Ok(()));
        let a = t.scale_asymmetry_primary;
        assert!((a[0] - 4.8e-4).abs() < 1e-12 && (a[1] + 3.1e-4).abs() < 1e-12);
        assert!(a[2].abs() < 1e-15, "90 ± 45 ppm is not determined at 3σ");
        assert_eq!(t.scale_asymmetry_backup, [0.0; 3]);
        assert_eq!(t.g_primary, flown.g_primary);
        assert_eq!(applied.len(), 1);
        assert_eq!(ground.len(), 1);
        assert!(ground[0].starts_with("gyro_bias_ramp"));
        let (t, _, _) = iru_update(&flown, &d, true);
        assert_eq!(t.scale_asymmetry_primary, flown.scale_asymmetry_primary);
        assert!((t.scale_asymmetry_backup[0] - 3.8e-4).abs() < 1e-12);
    }
}
