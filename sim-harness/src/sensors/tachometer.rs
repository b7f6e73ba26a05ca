//! # Reaction-wheel tachometers and torquer-bar current monitors (`docs/icd.md` §3.6)
//!
//! Why: the flight core's momentum unloading needs the wheels' momentum. Counting its own
//! torque commands drifts whenever a wheel does not deliver the command (54.6 N·m·s after the
//! main job's nine torque-limited slews, `docs/magnetics.md` §7); a real attitude control
//! system reads each wheel's speed. The bars' drive electronics report the current each bar
//! carries, which is the dipole the spacecraft actually flew (a bar stuck on shows there).
//!
//! # Model (scenario `[wheel_tachometers]`)
//! * Wheel `i`'s speed `ω_i = h_i / J_s` (rad/s; `h_i` the truth momentum along its spin
//!   axis, [`crate::truth::dynamics`]), plus white noise of `noise_rpm` (1σ), rounded to
//!   counts of [`fsw_core::raw::WHEEL_RPM_PER_COUNT`] and clamped to the `i16` word (a word at
//!   ±32,767 is saturated: the OBC does not use it). `J_s` = `spin_inertia_kg_m2`, the truth
//!   rotor inertia (the flight core's is Table 6 field 25: equal by default, and a mismatch
//!   is a scale-factor error of the OBC's momentum, like a wrong table).
//! * Wheels past the truth's wheel count read invalid.
//! * Fault `tachometer_failed` ([`crate::faults`]): that wheel's valid bit is cleared.
//! * Current monitors: the dipole each bar carried over the interval that ended at the
//!   sample (what the TAMs saw, [`crate::truth::torquer`]), rounded to
//!   [`fsw_core::raw::TORQUER_AM2_PER_COUNT`]; valid only with `[dynamics] momentum_unloading
//!   = "bars"`.
//!
//! Off by default: the scenarios that fly the torquer bars (`normal-ops`,
//! `gro-early-mission`) turn it on; the others keep their telemetry (no APID 0x014).

use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use fsw_core::raw::{
    WheelSample, TORQUER_AM2_PER_COUNT, TORQUER_MONITORS, WHEELS, WHEEL_RPM_PER_COUNT,
};

/// The tachometers' parameters (scenario `[wheel_tachometers]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TachometerParams {
    /// Read the tachometers and monitors into the OBC's frame and downlink APID 0x014.
    pub enabled: bool,
    /// Rotor inertia about the spin axis, kg·m² (every wheel; module doc).
    pub spin_inertia_kg_m2: f64,
    /// Speed noise, rpm (1σ per sample).
    pub noise_rpm: f64,
}

impl Default for TachometerParams {
    fn default() -> Self {
        Self {
            enabled: false,
            spin_inertia_kg_m2: 0.8,
            noise_rpm: 0.05,
        }
    }
}

impl TachometerParams {
    /// Inertia within 1e-3–100 kg·m², noise within 0–100 rpm.
    ///
    /// # Errors
    /// The offending field, by its TOML path.
    pub fn validate(&self) -> anyhow::Result<()> {
        if !(self.spin_inertia_kg_m2.is_finite()
            && (1e-3..=100.0).contains(&self.spin_inertia_kg_m2))
        {
            anyhow::bail!(
                "wheel_tachometers.spin_inertia_kg_m2 must be within 0.001–100 kg·m², got {}",
                self.spin_inertia_kg_m2
            );
        }
        if !(self.noise_rpm.is_finite() && (0.0..=100.0).contains(&self.noise_rpm)) {
            anyhow::bail!(
                "wheel_tachometers.noise_rpm must be within 0–100 rpm, got {}",
                self.noise_rpm
            );
        }
        Ok(())
    }
}

/// The tachometers and monitors of one spacecraft.
#[derive(Clone, Debug)]
pub struct Tachometers {
    params: TachometerParams,
    rng: ChaCha8Rng,
}

/// Round to an `i16` word, saturating symmetrically at ±32,767 (the saturated words of
/// `docs/icd.md` §3.6).
#[allow(clippy::cast_possible_truncation)] // clamped to the i16 range first
fn word(x: f64) -> i16 {
    x.round().clamp(-f64::from(i16::MAX), f64::from(i16::MAX)) as i16
}

impl Tachometers {
    /// The model of `params`, drawing its noise from `rng`.
    #[must_use]
    pub fn new(params: &TachometerParams, rng: ChaCha8Rng) -> Self {
        Self {
            params: params.clone(),
            rng,
        }
    }

    /// This sample's words: wheel momenta along the spin axes (N·m·s, `wheel_count` of them),
    /// wheels whose tachometer failed, and the bars' dipoles over the last interval (A·m²,
    /// `None` without bars).
    pub fn sample(
        &mut self,
        wheel_momentum_nms: &[f64],
        failed: &[bool; WHEELS],
        bar_dipoles_am2: Option<[f64; TORQUER_MONITORS]>,
    ) -> WheelSample {
        let mut s = WheelSample::default();
        let rpm_per_rad_per_s = 60.0 / std::f64::consts::TAU;
        for (i, h) in wheel_momentum_nms.iter().enumerate().take(WHEELS) {
            let noise: f64 = StandardNormal.sample(&mut self.rng);
            let rpm = h / self.params.spin_inertia_kg_m2 * rpm_per_rad_per_s
                + self.params.noise_rpm * noise;
            if let (Some(slot), Some(false)) = (s.speed_counts.get_mut(i), failed.get(i)) {
                *slot = word(rpm / WHEEL_RPM_PER_COUNT);
                s.speed_valid |= 1 << i;
            }
        }
        if let Some(d) = bar_dipoles_am2 {
            s.dipole_counts = d.map(|m| word(m / TORQUER_AM2_PER_COUNT));
            s.dipole_valid = (1 << TORQUER_MONITORS) - 1;
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensors::model_rng;

    #[test]
    fn speeds_carry_the_momentum_and_failed_or_missing_wheels_read_invalid() {
        let p = TachometerParams {
            enabled: true,
            noise_rpm: 0.0,
            ..TachometerParams::default()
        };
        let mut t = Tachometers::new(&p, model_rng(1, 99));
        let s = t.sample(&[100.0, -50.0, 0.0], &[false, true, false, false], None);
        let nms_per_count =
            p.spin_inertia_kg_m2 * WHEEL_RPM_PER_COUNT * std::f64::consts::TAU / 60.0;
        assert!((f64::from(s.speed_counts[0]) * nms_per_count - 100.0).abs() <= nms_per_count);
        assert_eq!(s.speed_valid, 0b101, "wheel 2 failed, wheel 4 absent");
        assert_eq!(s.dipole_valid, 0);
        let s = t.sample(&[1.0e4], &[false; WHEELS], Some([4_000.0, -1.4, 0.0]));
        assert_eq!(s.speed_counts[0], i16::MAX, "saturated word");
        assert_eq!(s.dipole_counts, [4_000, -1, 0]);
        assert_eq!(s.dipole_valid, 0b111);
        let s = t.sample(&[-1.0e4], &[false; WHEELS], None);
        assert_eq!(s.speed_counts[0], -i16::MAX, "saturated word, negative");
    }

    #[test]
    fn bad_parameters_are_named() {
        let p = TachometerParams {
            spin_inertia_kg_m2: 0.0,
            ..TachometerParams::default()
        };
        let e = p.validate().unwrap_err().to_string();
        assert!(e.contains("spin_inertia_kg_m2"), "{e}");
        let p = TachometerParams {
            noise_rpm: f64::NAN,
            ..TachometerParams::default()
        };
        assert!(p.validate().unwrap_err().to_string().contains("noise_rpm"));
        assert!(TachometerParams::default().validate().is_ok());
    }
}
