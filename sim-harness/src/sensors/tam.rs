//! # Three-axis magnetometer (TAM) truth model, two units
//!
//! Why: GRO carries two TAMs; FDF determined the primary TAM's bias in flight
//! ([0, 0, −4] mG, `data/gro_paper.toml` `[sensors.tam]`) and compared FSS/TAM attitudes with
//! FHST attitudes (issue 20). The coarse attitude and the ground's TAM calibration need a TAM
//! whose errors are known to the truth.
//!
//! # Measurement (sensor axes, milligauss; 1 mG = 100 nT)
//! `B_tam = (I + diag(scale_ppm)·1e-6) · M_AS,trueᵀ · (A·B_eci + B_residual,acs + C·m_acs)
//!          + bias + n`, then rounded to counts of `resolution_milligauss_per_count` and
//! saturated at `±range_milligauss` (algorithms.md §10a's `B_meas = (I + D) M_TSᵀ A B_ref + b
//! + n` with the spacecraft's own fields added):
//! - `B_eci`: the geomagnetic field at the spacecraft (IGRF, [`gro_reference::field`]);
//! - `M_AS,true = Rot(misalignment) · M_AS,nominal` (nominal: the TAM axes are the ACS axes;
//!   the paper gives no TAM alignment);
//! - `B_residual,acs`: the spacecraft's residual (hard-iron) field at the TAM, body axes;
//! - `C·m_acs`: the torquer bars' field at the TAM for the dipole `m_acs` (A·m²) the bars
//!   deliver while the TAM samples ([`crate::truth::torquer`]; zero while they are off):
//!   column `k` of `C` is the field per A·m² of bar `k` (bars on the ACS axes);
//! - `bias`: the sensor's own offset, sensor axes; `n`: white Gaussian noise per axis.
//!
//! What a ground bias fit recovers with the bars off is the *effective* bias
//! `bias + (I + D) M_AS,trueᵀ B_residual,acs` ([`Tam::effective_bias_milligauss`]).
//!
//! Defaults (chosen, plausible for a 1990 fluxgate TAM: the paper states only the primary
//! bias): range ±600 mG, 0.3 mG/count (12 bits over ±600 mG), noise 0.2 mG (1σ), scale
//! ±1000 ppm, misalignment ~0.2°, residual field 0 (so that the paper's determined bias is
//! the effective one), torquer coupling 0.1 mG per A·m² on the diagonal (a bar ~2 m away;
//! μ₀m/(2πd³) = 0.25 mG per A·m² at 2 m on its axis).
//!
//! Randomness: one `ChaCha8Rng` per unit, streams [`super::stream::TAM1`] and `TAM1 + 1`,
//! so the existing sensors' draws do not move.

use nalgebra::{Matrix3, Vector3};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use super::{model_rng, quantize_i16, stream, TruthSnapshot};
use fsw_core::attitude::rot;
use fsw_core::units::RAD_PER_ARCSEC;
use gro_reference::run_folder::{TruthTam, TruthTams};

/// Nanotesla per milligauss (1 G = 1e-4 T, so 1 mG = 1e-7 T = 100 nT).
pub const NT_PER_MILLIGAUSS: f64 = 100.0;

/// The primary TAM's bias FDF determined in flight (mG, sensor axes): `data/gro_paper.toml`
/// `[sensors.tam] primary_bias_mG` ("determined, not uplinked"). The default of `[tam1]`.
pub const PAPER_PRIMARY_TAM_BIAS_MILLIGAUSS: [f64; 3] = [0.0, 0.0, -4.0];

/// One TAM's error parameters (scenario `[tam1]`, `[tam2]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TamParams {
    /// Bias, sensor axes (mG).
    pub bias_milligauss: [f64; 3],
    /// Scale-factor error per sensor axis (ppm): `D = diag(scale_ppm)·1e-6`.
    pub scale_ppm: [f64; 3],
    /// True misalignment θ, ACS (arcsec): `M_AS,true = Rot(θ) M_AS,nominal`.
    pub misalignment_arcsec: [f64; 3],
    /// White noise per axis (mG, 1σ).
    pub noise_milligauss_1sigma: f64,
    /// Count size (mG per count).
    pub resolution_milligauss_per_count: f64,
    /// Saturation (mG): readings are clamped to ±range.
    pub range_milligauss: f64,
    /// The spacecraft's residual field at this TAM, ACS axes (mG).
    pub residual_field_acs_milligauss: [f64; 3],
    /// Field at this TAM per unit torquer-bar dipole (mG per A·m²), ACS ← ACS, row-major:
    /// `B_tb,acs = C m_acs`.
    pub torquer_coupling_milligauss_per_am2: [[f64; 3]; 3],
}

impl Default for TamParams {
    fn default() -> Self {
        Self {
            bias_milligauss: [0.0; 3],
            scale_ppm: [1_000.0, -800.0, 600.0],
            misalignment_arcsec: [500.0, -300.0, 700.0],
            noise_milligauss_1sigma: 0.2,
            resolution_milligauss_per_count: 0.3,
            range_milligauss: 600.0,
            residual_field_acs_milligauss: [0.0; 3],
            torquer_coupling_milligauss_per_am2: [
                [0.1, 0.0, 0.0],
                [0.0, 0.1, 0.0],
                [0.0, 0.0, 0.1],
            ],
        }
    }
}

impl TamParams {
    /// The default of `[tam1]`: [`Self::default`] with the paper's primary bias.
    #[must_use]
    pub fn primary_default() -> Self {
        Self {
            bias_milligauss: PAPER_PRIMARY_TAM_BIAS_MILLIGAUSS,
            ..Self::default()
        }
    }

    /// Check the parameters (finite values are checked for the whole scenario).
    ///
    /// # Errors
    /// A non-positive resolution or range, a negative noise, or a range under one count.
    pub fn validate(&self, name: &str) -> anyhow::Result<()> {
        if !(self.resolution_milligauss_per_count > 0.0) {
            anyhow::bail!(
                "{name}.resolution_milligauss_per_count must be > 0, got {}",
                self.resolution_milligauss_per_count
            );
        }
        if !(self.range_milligauss >= self.resolution_milligauss_per_count) {
            anyhow::bail!(
                "{name}.range_milligauss must be ≥ one count, got {}",
                self.range_milligauss
            );
        }
        if !(self.noise_milligauss_1sigma >= 0.0) {
            anyhow::bail!(
                "{name}.noise_milligauss_1sigma must be ≥ 0, got {}",
                self.noise_milligauss_1sigma
            );
        }
        if self.range_milligauss / self.resolution_milligauss_per_count > f64::from(i16::MAX) {
            anyhow::bail!(
                "{name}: range_milligauss / resolution_milligauss_per_count must fit 16-bit counts (≤ 32767), got {}",
                self.range_milligauss / self.resolution_milligauss_per_count
            );
        }
        Ok(())
    }
}

/// One TAM reading: signed counts per sensor axis; `valid = false` when the field is unknown
/// (an epoch outside the field model) and the counts are zero.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct TamReading {
    /// Field per sensor axis (counts of `resolution_milligauss_per_count`).
    pub field_counts: [i16; 3],
    /// The reading carries a field.
    pub valid: bool,
}

/// One TAM unit.
#[derive(Clone, Debug)]
pub struct Tam {
    params: TamParams,
    m_acs_from_tam_true: Matrix3<f64>,
    rng: ChaCha8Rng,
}

impl Tam {
    /// TAM `unit` (0 = primary, 1 = secondary) of scenario seed `seed`; nominal axes = ACS.
    #[must_use]
    pub fn new(unit: usize, params: TamParams, seed: u64) -> Self {
        let theta = Vector3::from(params.misalignment_arcsec) * RAD_PER_ARCSEC;
        let m_true = rot(&theta);
        Self::with_alignment(
            m_true,
            params,
            model_rng(seed, stream::TAM1 + unit.min(1) as u64),
        )
    }

    /// A TAM with an explicit true alignment (`M_AS,true`; its misalignment parameter is
    /// then only a label).
    #[must_use]
    pub fn with_alignment(
        m_acs_from_tam_true: Matrix3<f64>,
        params: TamParams,
        rng: ChaCha8Rng,
    ) -> Self {
        Self {
            params,
            m_acs_from_tam_true,
            rng,
        }
    }

    /// The model's parameters.
    #[must_use]
    pub fn params(&self) -> &TamParams {
        &self.params
    }

    /// True alignment `M_AS,true`.
    #[must_use]
    pub fn m_acs_from_tam_true(&self) -> &Matrix3<f64> {
        &self.m_acs_from_tam_true
    }

    /// `I + D`.
    fn scale_matrix(&self) -> Matrix3<f64> {
        Matrix3::identity() + Matrix3::from_diagonal(&(Vector3::from(self.params.scale_ppm) * 1e-6))
    }

    /// The noise-free, unquantised reading (mG, sensor axes) for the field `field_acs_nt`
    /// (body axes) and the torquer dipole `dipole_acs_am2`.
    #[must_use]
    pub fn ideal_reading_milligauss(
        &self,
        field_acs_nt: &Vector3<f64>,
        dipole_acs_am2: &Vector3<f64>,
    ) -> Vector3<f64> {
        let p = &self.params;
        let c = Matrix3::from_fn(|i, j| p.torquer_coupling_milligauss_per_am2[i][j]);
        let at_tam_acs = field_acs_nt / NT_PER_MILLIGAUSS
            + Vector3::from(p.residual_field_acs_milligauss)
            + c * dipole_acs_am2;
        self.scale_matrix() * (self.m_acs_from_tam_true.transpose() * at_tam_acs)
            + Vector3::from(p.bias_milligauss)
    }

    /// What a bias fit with the bars off recovers (mG, sensor axes): the bias plus the
    /// residual field as this TAM sees it.
    #[must_use]
    pub fn effective_bias_milligauss(&self) -> Vector3<f64> {
        self.ideal_reading_milligauss(&Vector3::zeros(), &Vector3::zeros())
    }

    /// Counts to mG.
    #[must_use]
    pub fn reading_milligauss(&self, reading: &TamReading) -> Vector3<f64> {
        Vector3::from(reading.field_counts.map(f64::from))
            * self.params.resolution_milligauss_per_count
    }

    /// This cycle's reading. `field_eci_nt`: the geomagnetic field at the spacecraft (GCRS
    /// axes, nT), `None` when unknown (the reading is then invalid and draws no noise);
    /// `dipole_acs_am2`: the torquer bars' commanded dipole (zero while off).
    pub fn sample(
        &mut self,
        truth: &TruthSnapshot,
        field_eci_nt: Option<&Vector3<f64>>,
        dipole_acs_am2: &Vector3<f64>,
    ) -> TamReading {
        let Some(field_eci_nt) = field_eci_nt else {
            return TamReading::default();
        };
        let field_acs_nt = truth.m_acs_from_eci * field_eci_nt;
        let ideal = self.ideal_reading_milligauss(&field_acs_nt, dipole_acs_am2);
        let p = &self.params;
        let mut counts = [0_i16; 3];
        for (k, count) in counts.iter_mut().enumerate() {
            let n: f64 = StandardNormal.sample(&mut self.rng);
            let v = (ideal[k] + p.noise_milligauss_1sigma * n)
                .clamp(-p.range_milligauss, p.range_milligauss);
            *count = quantize_i16(v, p.resolution_milligauss_per_count);
        }
        TamReading {
            field_counts: counts,
            valid: true,
        }
    }
}

/// The `truth.json` `tam` object ([`TruthTams`]): the primary TAM's `bias_mG` (sensor axes,
/// mG; the key issue 20 names) and `effective_bias_mG` (what a bias fit with the torquer bars
/// off recovers: bias plus the residual field as the TAM sees it), its `scale_ppm`,
/// `misalignment_acs_arcsec` and `residual_field_acs_mG`, and the same under `tam2`.
#[must_use]
pub fn truth_tams(tam1: &TamParams, tam2: &TamParams) -> TruthTams {
    let one = |p: &TamParams| {
        let tam = Tam::new(0, p.clone(), 0);
        let eff = tam.effective_bias_milligauss();
        TruthTam {
            bias_milligauss: p.bias_milligauss,
            effective_bias_milligauss: [eff.x, eff.y, eff.z],
            scale_ppm: p.scale_ppm,
            misalignment_acs_arcsec: p.misalignment_arcsec,
            residual_field_acs_milligauss: p.residual_field_acs_milligauss,
            noise_milligauss_1sigma: p.noise_milligauss_1sigma,
            resolution_milligauss_per_count: p.resolution_milligauss_per_count,
        }
    };
    TruthTams {
        tam1: one(tam1),
        tam2: one(tam2),
        note: "primary TAM (TAM1) at the top level, TAM2 under tam2; sensor axes; 1 mG = 100 nT; the torquer bars' field is not included".into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fsw_core::attitude::Quat;

    /// Sample and convert to mG.
    fn read_mg(
        tam: &mut Tam,
        (truth, field, dipole): (&TruthSnapshot, Option<&Vector3<f64>>, &Vector3<f64>),
    ) -> Vector3<f64> {
        let r = tam.sample(truth, field, dipole);
        tam.reading_milligauss(&r)
    }

    fn noiseless(params: TamParams) -> TamParams {
        TamParams {
            noise_milligauss_1sigma: 0.0,
            resolution_milligauss_per_count: 1e-3,
            range_milligauss: 30.0,
            ..params
        }
    }

    fn zero_error() -> TamParams {
        noiseless(TamParams {
            bias_milligauss: [0.0; 3],
            scale_ppm: [0.0; 3],
            misalignment_arcsec: [0.0; 3],
            ..TamParams::default()
        })
    }

    /// The paper's primary bias, as `data/gro_paper.toml` states it.
    #[test]
    fn val_primary_bias_is_the_papers() {
        let paper = gro_reference::paper::PaperData::embedded().unwrap();
        assert_eq!(
            paper.sensors.tam.primary_bias_milligauss,
            PAPER_PRIMARY_TAM_BIAS_MILLIGAUSS
        );
        assert_eq!(
            TamParams::primary_default().bias_milligauss,
            PAPER_PRIMARY_TAM_BIAS_MILLIGAUSS
        );
    }

    /// A zero-error TAM reads the field rotated into the body frame (to the 1e-3 mG count).
    #[test]
    fn zero_error_tam_reads_the_field_in_body_axes() {
        let q = Quat::from_rotation_vector(&Vector3::new(0.3, -1.1, 0.7));
        let truth = TruthSnapshot::at_rest(q);
        let mut tam = Tam::new(0, zero_error(), 1);
        let field_eci_nt = Vector3::new(1_200.0, -2_300.0, 1_700.0);
        let r = tam.sample(&truth, Some(&field_eci_nt), &Vector3::zeros());
        assert!(r.valid);
        let expect = truth.m_acs_from_eci * field_eci_nt / NT_PER_MILLIGAUSS;
        assert!((tam.reading_milligauss(&r) - expect).abs().max() <= 0.5e-3 + 1e-12);
        // Unknown field: invalid, zero.
        assert_eq!(
            tam.sample(&truth, None, &Vector3::zeros()),
            TamReading::default()
        );
    }

    /// Misalignment and scale enter as `(I + D) M_ASᵀ`; the residual field and the torquer
    /// dipole add in body axes before the rotation; the bias after it.
    #[test]
    fn error_terms_enter_where_the_model_says() {
        let p = noiseless(TamParams {
            bias_milligauss: [0.5, -1.0, 2.0],
            scale_ppm: [2_000.0, 0.0, -1_000.0],
            misalignment_arcsec: [0.0, 0.0, 3_600.0],
            residual_field_acs_milligauss: [1.0, 0.0, 0.0],
            ..TamParams::default()
        });
        let truth = TruthSnapshot::at_rest(Quat::IDENTITY);
        let mut tam = Tam::new(0, p.clone(), 1);
        let field = Vector3::new(2_000.0, 0.0, 0.0); // 20 mG along ACS x
        let dipole = Vector3::new(0.0, 10.0, 0.0); // 1 mG along ACS y through C = 0.1 I
        let r = read_mg(&mut tam, (&truth, Some(&field), &dipole));
        let at_tam_acs = Vector3::new(21.0, 1.0, 0.0);
        let m = rot(&Vector3::new(0.0, 0.0, 3_600.0 * RAD_PER_ARCSEC));
        let d = Matrix3::from_diagonal(&Vector3::new(1.002, 1.0, 0.999));
        let expect = d * (m.transpose() * at_tam_acs) + Vector3::from(p.bias_milligauss);
        assert!(
            (r - expect).abs().max() <= 0.5e-3 + 1e-12,
            "{r} vs {expect}"
        );
        // Effective bias: bias + (I + D) M_ASᵀ residual.
        let eff =
            d * (m.transpose() * Vector3::new(1.0, 0.0, 0.0)) + Vector3::from(p.bias_milligauss);
        assert!((tam.effective_bias_milligauss() - eff).norm() < 1e-12);
    }

    /// Averaging N readings of a constant field recovers the bias to σ/√N (and the
    /// quantisation is dithered by the noise); the saturation clamps.
    #[test]
    fn bias_recovered_by_averaging_and_range_saturates() {
        let p = TamParams {
            scale_ppm: [0.0; 3],
            misalignment_arcsec: [0.0; 3],
            ..TamParams::primary_default()
        };
        let truth = TruthSnapshot::at_rest(Quat::IDENTITY);
        let mut tam = Tam::new(0, p.clone(), 42);
        let n = 20_000;
        let mut sum = Vector3::zeros();
        for _ in 0..n {
            sum += read_mg(
                &mut tam,
                (&truth, Some(&Vector3::zeros()), &Vector3::zeros()),
            );
        }
        let mean = sum / f64::from(n);
        // σ/√N = 0.2/141 = 0.0014 mG; allow 5σ.
        let tol = 5.0 * p.noise_milligauss_1sigma / f64::from(n).sqrt();
        assert!(
            (mean - Vector3::from(PAPER_PRIMARY_TAM_BIAS_MILLIGAUSS))
                .abs()
                .max()
                < tol,
            "{mean}"
        );
        let huge = Vector3::new(1e6, -1e6, 0.0);
        let r = read_mg(&mut tam, (&truth, Some(&huge), &Vector3::zeros()));
        assert!(
            (r.x - 600.0).abs() <= 0.3 && (r.y + 600.0).abs() <= 0.3,
            "{r}"
        );
    }

    /// The two units draw from their own streams: same seed, different noise; the same unit
    /// twice, the same noise.
    #[test]
    fn units_have_their_own_streams() {
        let truth = TruthSnapshot::at_rest(Quat::IDENTITY);
        let p = TamParams::default();
        let f = Vector3::new(10_000.0, 0.0, 0.0);
        let mut a = Tam::new(0, p.clone(), 3);
        let mut a2 = Tam::new(0, p.clone(), 3);
        let mut b = Tam::new(1, p, 3);
        let (ra, ra2, rb): (Vec<_>, Vec<_>, Vec<_>) = (0..20)
            .map(|_| {
                (
                    a.sample(&truth, Some(&f), &Vector3::zeros()),
                    a2.sample(&truth, Some(&f), &Vector3::zeros()),
                    b.sample(&truth, Some(&f), &Vector3::zeros()),
                )
            })
            .fold((vec![], vec![], vec![]), |mut acc, (x, y, z)| {
                acc.0.push(x);
                acc.1.push(y);
                acc.2.push(z);
                acc
            });
        assert_eq!(ra, ra2);
        assert_ne!(ra, rb);
    }

    #[test]
    fn validate_refuses_bad_counts() {
        assert!(TamParams::default().validate("tam1").is_ok());
        let bad = TamParams {
            resolution_milligauss_per_count: 0.0,
            ..TamParams::default()
        };
        assert!(bad.validate("tam1").is_err());
        let too_wide = TamParams {
            resolution_milligauss_per_count: 1e-3,
            range_milligauss: 600.0,
            ..TamParams::default()
        };
        assert!(too_wide.validate("tam1").is_err());
    }
}
