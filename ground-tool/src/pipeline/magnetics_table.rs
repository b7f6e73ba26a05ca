//! # The OBC's magnetics table (Table 6) from the ground's TAM calibration
//!
//! Why: the ground determines the magnetometers' bias, scale and misalignment against the FHST
//! fine attitude (`super::tam`); the OBC's coarse attitude only benefits when they are
//! uplinked, with a field σ that says what is left. Like every other table, it is written only
//! when its held-out check passes: each half of the samples in time, fitted alone, must
//! predict the other half (χ²/dof against the estimated noise at most
//! [`MAX_HELDOUT_CHI2_PER_DOF`]) better than the uncalibrated TAM does (residual RMS lower by
//! more than [`MIN_IMPROVEMENT`] on the worst axis).
//!
//! What goes in (`fsw_core::tables::MagneticsTable`; the OBC computes
//! `B_acs = M_AS (s ∘ counts − b)`):
//! * the field model at the telemetry's start (`gro_reference::field::onboard_field_table`:
//!   DGRF 1990/1995, valid five years on board);
//! * per calibrated TAM, from `y = T x + b`, `T = (I + D) M_ASᵀ`: `M_AS = Rot(θ)` (θ the fitted
//!   misalignment), count size `s₀ / (1 + Dᵢ)`, bias `bᵢ / (1 + Dᵢ)`; a TAM without a fit keeps
//!   its entries of the table flying (nominal ones when none was uplinked), and the reason
//!   says so;
//! * `field_sigma_milligauss`, per TAM: the worst held-out residual RMS of its fit (what a
//!   corrected field differs from the model by, noise and calibration error together), with the
//!   part of `T` the table cannot hold (non-orthogonality) added; a TAM without a fit keeps the
//!   σ it flew with (the boot one when nothing was uplinked). The table starts from the one
//!   flying, so what the ground does not recompute is not reset. No
//!   field-model error is added: the simulator's field is the model; a real mission adds the
//!   IGRF's omission, ~1 mG at 450 km (`docs/magnetics.md` §4);
//! * `fss_sun_sigma_rad`: when the new alignments fly, the larger over FSS1 and FSS2 of the
//!   alignment's largest per-axis σ relative to FHST1 (FFCAL) and the FSS's FFCAL residual RMS
//!   after calibration, in quadrature (a Sun direction through the uplinked alignment is good
//!   to that); otherwise the boot value (the prelaunch misalignments).

use fsw_core::tables::MagneticsTable;
use fsw_core::units::RAD_PER_ARCSEC;

use super::tam::{MagneticsTableDecision, TamReport, TamUnitFit, TAM_MILLIGAUSS_PER_COUNT};

/// The held-out half must be predicted with χ²/dof at most this (the fitted model carries
/// over to data it was not fitted to).
pub const MAX_HELDOUT_CHI2_PER_DOF: f64 = 3.0;

/// The calibrated prediction must lower the uncalibrated residual RMS by more than this
/// fraction on its worst axis.
pub const MIN_IMPROVEMENT: f64 = 0.2;

/// Whether a unit's fit carries over to held-out data and beats the uncalibrated TAM; the
/// worst held-out RMS per axis when it does, the reason when not.
fn heldout_check(name: &str, fit: &TamUnitFit) -> Result<f64, String> {
    if fit.heldout.len() < 2 {
        return Err(format!(
            "{name}: no held-out halves ({} samples)",
            fit.samples
        ));
    }
    let mut worst_rms = 0.0_f64;
    for h in &fit.heldout {
        if !(h.chi2_per_dof <= MAX_HELDOUT_CHI2_PER_DOF) {
            return Err(format!(
                "{name}: the fit on the {} predicts the other half with χ²/dof {:.2} > {MAX_HELDOUT_CHI2_PER_DOF}",
                h.fitted, h.chi2_per_dof
            ));
        }
        for predicted in h.predicted_rms_milligauss {
            worst_rms = worst_rms.max(predicted);
        }
    }
    let uncal_worst = fit
        .residual_rms_uncalibrated_milligauss
        .iter()
        .fold(0.0_f64, |a, b| a.max(*b));
    if !(worst_rms < (1.0 - MIN_IMPROVEMENT) * uncal_worst) {
        return Err(format!(
            "{name}: held-out residual RMS {worst_rms:.3} mG is not {:.0} % below the uncalibrated {uncal_worst:.3} mG",
            MIN_IMPROVEMENT * 100.0
        ));
    }
    Ok(worst_rms)
}

/// The part of the fitted `T` the table cannot hold (its `M_AS` is a rotation and its scale
/// diagonal: the non-orthogonality is dropped), as a field error per axis at the TAM's full
/// range, mG: `‖T − diag(1 + D) Rot(θ)ᵀ‖_F / √3 × 600 mG`. Added to the σ in quadrature, so
/// that what is written is what the validated fit minus the dropped part can promise.
fn dropped_part_milligauss(fit: &TamUnitFit) -> f64 {
    /// The TAMs' range, mG (`docs/magnetics.md` §2): the largest field the error multiplies.
    const RANGE_MILLIGAUSS: f64 = 600.0;
    let (Some(scale_ppm), Some(theta_arcsec)) = (fit.scale_ppm, fit.misalignment_acs_arcsec) else {
        return 0.0;
    };
    let theta = nalgebra::Vector3::from(theta_arcsec.map(|a| a * RAD_PER_ARCSEC));
    let d = nalgebra::Matrix3::from_diagonal(&nalgebra::Vector3::from(
        scale_ppm.map(|p| 1.0 + p * 1e-6),
    ));
    let model = d * fsw_core::attitude::rot(&theta).transpose();
    let fitted = fsw_core::tables::types::matrix_from_rows(&fit.t_tam_from_acs);
    (fitted - model).norm() / 3.0_f64.sqrt() * RANGE_MILLIGAUSS
}

/// Write a unit's calibration into the table's entries `unit`.
fn apply_fit(table: &mut MagneticsTable, unit: usize, fit: &TamUnitFit) {
    let scale = fit.scale_ppm.unwrap_or([0.0; 3]).map(|p| 1.0 + p * 1e-6);
    let theta = fit
        .misalignment_acs_arcsec
        .unwrap_or([0.0; 3])
        .map(|a| a * RAD_PER_ARCSEC);
    let m = fsw_core::attitude::rot(&nalgebra::Vector3::from(theta));
    if let (Some(rows), Some(s), Some(b)) = (
        table.m_acs_from_tam.get_mut(unit),
        table.tam_milligauss_per_count.get_mut(unit),
        table.tam_bias_milligauss.get_mut(unit),
    ) {
        *rows = fsw_core::tables::types::rows_from_matrix(&m);
        for i in 0..3 {
            s[i] = TAM_MILLIGAUSS_PER_COUNT / scale[i];
            b[i] = fit.bias_milligauss[i] / scale[i];
        }
    }
}

/// The magnetics table to uplink, or why none is.
///
/// `start`: the telemetry's first time tag (the field model's epoch); `fss_residual_after_arcsec`: the
/// larger FSS residual RMS of FFCAL after calibration when the new alignments fly.
#[must_use]
pub fn magnetics_table(
    tam: &TamReport,
    start: fsw_core::raw::TimeTag,
    fss_residual_after_arcsec: Option<f64>,
    flown: Option<&MagneticsTable>,
) -> (Option<MagneticsTable>, MagneticsTableDecision) {
    let mut d = MagneticsTableDecision::default();
    let Some(fit1) = tam.tam1.as_ref() else {
        d.reason = format!(
            "not written: no TAM1 calibration ({})",
            tam.reason.as_deref().unwrap_or(tam.status)
        );
        return (None, d);
    };
    let sigma1 = match heldout_check("TAM1", fit1) {
        Ok(s) => s,
        Err(why) => {
            d.reason = format!("not written: {why}");
            return (None, d);
        }
    };
    // From the table flying (what the ground does not recompute stays as flown), else the
    // boot table with the TAMs' nominal count size.
    let mut base = flown.copied().unwrap_or_else(|| {
        let mut b = MagneticsTable::boot();
        b.tam_milligauss_per_count = [[TAM_MILLIGAUSS_PER_COUNT; 3]; 2];
        b
    });
    let kept = if flown.is_some() {
        "as flown"
    } else {
        "nominal with the boot σ"
    };
    apply_fit(&mut base, 0, fit1);
    let sigma1 = sigma1.hypot(dropped_part_milligauss(fit1));
    let mut notes = Vec::new();
    // A TAM without a passing fit keeps its flown entries and σ (the boot ones when nothing
    // was uplinked: its bias and alignment are then unknown to the OBC).
    let sigma2 = match tam.tam2.as_ref().map(|f| (f, heldout_check("TAM2", f))) {
        Some((fit2, Ok(s2))) => {
            apply_fit(&mut base, 1, fit2);
            s2.hypot(dropped_part_milligauss(fit2))
        }
        Some((_, Err(why))) => {
            notes.push(format!("TAM2 kept {kept} ({why})"));
            base.field_sigma_milligauss[1]
        }
        None => {
            notes.push(format!("TAM2 kept {kept} (no fit)"));
            base.field_sigma_milligauss[1]
        }
    };
    base.field_sigma_milligauss = [sigma1, sigma2];
    if let Some(fss) = fss_residual_after_arcsec.filter(|x| x.is_finite() && *x > 0.0) {
        base.fss_sun_sigma_rad = fss * RAD_PER_ARCSEC;
    } else {
        notes.push(if flown.is_some() {
            "FSS σ kept as flown (no new alignments passed their held-out validation)".to_owned()
        } else {
            "FSS σ kept at the boot value (no new alignments passed their held-out validation)"
                .to_owned()
        });
    }
    let model = match gro_reference::field::FieldModel::dgrf_1990_1995() {
        Ok(m) => m,
        Err(e) => {
            d.reason = format!("not written: the field model did not load ({e})");
            return (None, d);
        }
    };
    let epoch = gro_reference::time::epoch_from_time_tag(start);
    let table = match gro_reference::field::onboard_field_table(&model, epoch, &base) {
        Ok(t) => t,
        Err(e) => {
            d.reason = format!("not written: {e}");
            return (None, d);
        }
    };
    if let Err(e) = table.validate() {
        d.reason = format!("not written: the OBC would refuse it ({e})");
        return (None, d);
    }
    d.written = true;
    d.field_sigma_milligauss = Some(table.field_sigma_milligauss);
    d.fss_sun_sigma_arcsec = Some(table.fss_sun_sigma_rad / RAD_PER_ARCSEC);
    d.tam_bias_milligauss = Some(table.tam_bias_milligauss);
    d.reason = format!(
        "written: TAM1 ({}) predicts each held-out half with χ²/dof ≤ {MAX_HELDOUT_CHI2_PER_DOF} against {:.3} mG uncalibrated; field σ TAM1 {sigma1:.3}, TAM2 {sigma2:.3} mG{}",
        fit1.model,
        fit1.residual_rms_uncalibrated_milligauss
            .iter()
            .fold(0.0_f64, |a, b| a.max(*b)),
        if notes.is_empty() {
            String::new()
        } else {
            format!("; {}", notes.join("; "))
        }
    );
    (Some(table), d)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::pipeline::tam::TamHeldOut;

    fn fit(chi2: [f64; 2], predicted: f64, uncalibrated: f64) -> TamUnitFit {
        let theta = nalgebra::Vector3::new(500.0, -300.0, 700.0) * RAD_PER_ARCSEC;
        let d = nalgebra::Matrix3::from_diagonal(&nalgebra::Vector3::new(1.001, 0.9992, 1.0006));
        let t = d * fsw_core::attitude::rot(&theta).transpose();
        TamUnitFit {
            t_tam_from_acs: fsw_core::tables::types::rows_from_matrix(&t),
            model: "bias, scale and misalignment (full 3x3 T)",
            bias_milligauss: [0.1, -0.2, -4.0],
            scale_ppm: Some([1000.0, -800.0, 600.0]),
            misalignment_acs_arcsec: Some([500.0, -300.0, 700.0]),
            residual_rms_uncalibrated_milligauss: [uncalibrated; 3],
            samples: 400,
            heldout: ["first half", "second half"]
                .iter()
                .zip(chi2)
                .map(|(f, c)| TamHeldOut {
                    fitted: f,
                    samples: [200, 200],
                    bias_milligauss: [0.0; 3],
                    predicted_rms_milligauss: [predicted; 3],
                    chi2_per_dof: c,
                })
                .collect(),
            ..TamUnitFit::default()
        }
    }

    fn report(tam1: TamUnitFit) -> TamReport {
        TamReport {
            status: "determined",
            tam1: Some(tam1),
            ..TamReport::default()
        }
    }

    fn start() -> fsw_core::raw::TimeTag {
        let epoch = gro_reference::time::epoch_from_iso("1991-04-09T00:00:00Z").unwrap();
        gro_reference::time::time_tag(epoch).unwrap()
    }

    /// A fit that carries over and beats the uncalibrated TAM is written: the OBC accepts the
    /// table, its bias and count size undo `(I + D)`, its field σ is the held-out RMS.
    #[test]
    fn a_fit_that_carries_over_is_written() {
        let (t, d) = magnetics_table(
            &report(fit([1.1, 1.3], 0.25, 3.8)),
            start(),
            Some(20.0),
            None,
        );
        let t = t.unwrap();
        assert!(d.written, "{}", d.reason);
        assert_eq!(t.validate(), Ok(()));
        assert!((t.tam_bias_milligauss[0][2] - (-4.0 / 1.0006)).abs() < 1e-9);
        assert!((t.tam_milligauss_per_count[0][0] - 0.3 / 1.001).abs() < 1e-12);
        // TAM1: the held-out RMS (the test's T has no dropped part); TAM2 nominal: boot σ.
        assert!((t.field_sigma_milligauss[0] - 0.25).abs() < 1e-12);
        assert_eq!(t.field_sigma_milligauss[1], 2.5);
        assert!((t.fss_sun_sigma_rad / RAD_PER_ARCSEC - 20.0).abs() < 1e-9);
        assert!(d.reason.contains("TAM2 kept nominal"));
        // With a flown table whose TAM2 was calibrated before, a TAM2 without a fit keeps
        // the flown calibration and σ, not the boot ones.
        let mut flown = MagneticsTable::boot();
        flown.tam_bias_milligauss[1] = [0.6, -0.4, 0.3];
        flown.field_sigma_milligauss[1] = 0.31;
        let (t, d) = magnetics_table(
            &report(fit([1.1, 1.3], 0.25, 3.8)),
            start(),
            Some(20.0),
            Some(&flown),
        );
        let t = t.unwrap();
        assert_eq!(t.tam_bias_milligauss[1], [0.6, -0.4, 0.3]);
        assert_eq!(t.field_sigma_milligauss[1], 0.31);
        assert!(d.reason.contains("TAM2 kept as flown"), "{}", d.reason);
    }

    /// A half-fit that does not predict the other half, or no gain over the uncalibrated TAM,
    /// or no TAM1 fit: nothing written, and the reason names it.
    #[test]
    fn refusals_name_their_reason() {
        let (t, d) = magnetics_table(&report(fit([1.2, 3.6], 0.25, 3.8)), start(), None, None);
        assert!(t.is_none() && !d.written);
        assert!(d.reason.contains("χ²/dof 3.60"), "{}", d.reason);
        let (t, d) = magnetics_table(&report(fit([1.0, 1.0], 0.25, 0.28)), start(), None, None);
        assert!(
            t.is_none() && d.reason.contains("not 20 % below"),
            "{}",
            d.reason
        );
        let none = TamReport {
            status: "not_determined",
            reason: Some("no magnetics frames".into()),
            ..TamReport::default()
        };
        let (t, d) = magnetics_table(&none, start(), None, None);
        assert!(
            t.is_none() && d.reason.contains("no magnetics frames"),
            "{}",
            d.reason
        );
    }
}
