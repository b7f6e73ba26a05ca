//! # DRIRU II truth model: six rate-integrating channels, pulses, 16-bit counters
//!
//! Why: the onboard software propagates attitude from these counters and the ground
//! calibrates them (Davenport/Keat, paper §5); the model must hold the truth the calibration
//! is meant to recover, and the raw-word behaviour (pulses, remainders, wraps, modes, BIT).
//!
//! # Channel geometry (truth)
//! Channels X1, X2, Y1, Y2, Z1, Z2 (fsw_core::raw order). The paper's prelaunch `G` maps the
//! primary channel angles (X2, Y1, Z1) to ACS, and a perfect calibration gives
//! `Δθ_acs = (I + ΔM) G Δφ`. So the truth channel angles are
//! `Δφ = G⁻¹ (I + ΔM_true)⁻¹ ∫ω dt`, one row per channel. The backup triad (X1, Y2, Z2)
//! uses the same prelaunch `G` (the paper gives no other) with its own `ΔM_true`. Defaults:
//! primary `ΔM_true` = the paper's published ΔM; backup `ΔM_true` = 0. A per-channel
//! scale error and a high-mode scale error (mode-ratio error, §5.4) multiply each channel.
//!
//! # Errors per channel (rad/s unless named)
//! `Δφ = (1 + s) (w · ∫ω dt) + b(t) Δt + σ_v √Δt n`, with
//! `b(t) = b₀ + b_tr e^{−t_rel/τ} + b_rw(t) + k_T ΔT`, `b_rw` a random walk of σ_u:
//! * b₀: the paper's high-rate biases (~1e-4 °/s); a rate bias is common to both modes.
//! * b_tr, τ: the early drift "in x and z (primary) during the first 6 days" (defaults
//!   X2 +3e-5 °/s, Z1 −2e-5 °/s, τ = 1.5 d: chosen).
//! * σ_u = 0.0012″/s / √(6 h) = 8.2e-6 ″/s^1.5 (paper stability read as a random walk,
//!   algorithms.md §2); σ_v = 0.003″/√s (chosen; below the 0.05″ pulse).
//!
//! # Pulses and counters
//! Each channel accumulates angle; whole pulses (`floor(acc / q)`, q = 0.05″ low or 0.8″ high
//! rate) go to a 16-bit wrapping counter and the fraction stays for the next interval. The
//! rate mode commanded by the FSW applies from the next sample interval; the sample's
//! `high_rate` is the mode of the interval that just ended. A failed channel's counter sticks
//! and its BIT bit is set from the failure time on.
//!
//! # Effect hooks (default off)
//! Time-tag offset (counters latched `τ` early: the kinematic increment is blended with the
//! previous one), scale-factor asymmetry (± rates), thermally driven bias, and outside
//! diagnose's library (issue 22): a bias added only while the interval is in high-rate mode,
//! a scale error growing as a power of the channel rate (`k (|ω|/ω_ref)^p`, ω the channel's
//! mean rate over the interval), and a scale-factor step at a time. All per channel (raw
//! order X1, X2, Y1, Y2, Z1, Z2; a channel reads about one ACS axis, so the writer's per-axis
//! values go to both channels of that axis).

use nalgebra::{Matrix3, Vector3};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use super::{model_rng, stream};
use crate::paper::PaperFacts;
use fsw_core::raw::{IruSample, IRU_CHANNELS, IRU_CHANNEL_NAMES};
use fsw_core::units::{RAD_PER_ARCSEC, RAD_PER_DEG};

/// Channel indices of the primary triad (X2, Y1, Z1) in raw order.
pub const PRIMARY_CHANNELS: [usize; 3] = [1, 2, 4];
/// Channel indices of the backup triad (X1, Y2, Z2) in raw order.
pub const BACKUP_CHANNELS: [usize; 3] = [0, 3, 5];

/// Fraction of a pulse added before `floor` so that rounding does not drop exact pulses.
const PULSE_ROUNDING_NUDGE: f64 = 1e-9;

/// A channel failure at a given time.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelFailure {
    /// Channel name, one of X1, X2, Y1, Y2, Z1, Z2.
    pub channel: String,
    /// Failure time (s from the scenario epoch).
    pub at_s: f64,
}

/// Undeclared effects (default off).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IruEffects {
    /// Counters latched this long before the frame time (s).
    pub time_tag_offset_s: f64,
    /// Extra scale error for positive rates, minus for negative (ppm), per channel.
    pub scale_asymmetry_ppm: [f64; IRU_CHANNELS],
    /// Bias change per °C of IRU baseplate deviation (deg/s/°C), per channel.
    pub thermal_bias_deg_per_s_per_c: [f64; IRU_CHANNELS],
    /// Bias added only while the interval is in high-rate mode (deg/s), per channel (outside
    /// diagnose's library: reported as unexplained against `rate_mode`).
    pub high_rate_bias_deg_per_s: [f64; IRU_CHANNELS],
    /// Scale error growing as a power of the rate, per channel: `k (|ω|/ω_ref)^p` with `k`
    /// this value (ppm at the reference rate), ω the channel's mean rate over the interval
    /// (outside the library: unexplained against `slew_rate`).
    pub rate_power_scale_ppm: [f64; IRU_CHANNELS],
    /// Reference rate ω_ref of `rate_power_scale_ppm` (deg/s). Default 1.
    pub rate_power_reference_deg_per_s: f64,
    /// Exponent `p` of `rate_power_scale_ppm`. Default 2.
    pub rate_power_exponent: f64,
    /// Scale-factor change per channel (ppm) from `scale_step_at_s` on, both modes (outside
    /// the library: unexplained against `time_s`).
    pub scale_step_ppm: [f64; IRU_CHANNELS],
    /// Time of the scale step (s from the scenario start, the interval's midpoint);
    /// `None` = no step.
    pub scale_step_at_s: Option<f64>,
}

impl Default for IruEffects {
    fn default() -> Self {
        Self {
            time_tag_offset_s: 0.0,
            scale_asymmetry_ppm: [0.0; IRU_CHANNELS],
            thermal_bias_deg_per_s_per_c: [0.0; IRU_CHANNELS],
            high_rate_bias_deg_per_s: [0.0; IRU_CHANNELS],
            rate_power_scale_ppm: [0.0; IRU_CHANNELS],
            rate_power_reference_deg_per_s: 1.0,
            rate_power_exponent: 2.0,
            scale_step_ppm: [0.0; IRU_CHANNELS],
            scale_step_at_s: None,
        }
    }
}

/// IRU parameters (scenario `[iru]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IruParams {
    /// True ΔM of the primary triad; `None` = the paper's published ΔM.
    pub delta_m_true_primary: Option<[[f64; 3]; 3]>,
    /// True ΔM of the backup triad.
    pub delta_m_true_backup: [[f64; 3]; 3],
    /// Extra scale error per channel, both modes (ppm).
    pub channel_scale_ppm: [f64; IRU_CHANNELS],
    /// Extra scale error per channel in high-rate mode only (ppm): the mode-ratio error.
    pub high_rate_scale_ppm: [f64; IRU_CHANNELS],
    /// Constant bias per channel (deg/s); `None` = the paper's high-rate biases.
    pub bias_deg_per_s: Option<[f64; IRU_CHANNELS]>,
    /// Initial amplitude of the decaying early-drift bias (deg/s).
    pub bias_transient_deg_per_s: [f64; IRU_CHANNELS],
    /// Time constant of the early drift (s).
    pub bias_transient_time_constant_s: f64,
    /// Time since release at the scenario epoch (s): where on the transient the run starts.
    pub time_since_release_at_start_s: f64,
    /// A step in the bias per channel (deg/s) from `bias_step_at_s` on (a gyro event outside
    /// the random walk, for testing the ground's bias model; 0 = none).
    pub bias_step_deg_per_s: [f64; IRU_CHANNELS],
    /// Time of the bias step (s from the scenario start); `None` = no step.
    pub bias_step_at_s: Option<f64>,
    /// Bias random walk σ_u (arcsec/s^1.5).
    pub bias_random_walk_arcsec_per_s15: f64,
    /// Angle random walk σ_v (arcsec/√s).
    pub angle_random_walk_arcsec_per_sqrt_s: f64,
    /// Pulse weight in low-rate mode (arcsec). Paper: 0.05.
    pub low_rate_arcsec_per_pulse: f64,
    /// Pulse weight in high-rate mode (arcsec). Paper: 0.8.
    pub high_rate_arcsec_per_pulse: f64,
    /// Rate mode before the first command.
    pub initial_high_rate: bool,
    /// Initial counter values.
    pub initial_counts: [u16; IRU_CHANNELS],
    /// Optional channel failure.
    pub failure: Option<ChannelFailure>,
    /// Undeclared effects.
    pub effects: IruEffects,
}

impl Default for IruParams {
    fn default() -> Self {
        Self {
            delta_m_true_primary: None,
            delta_m_true_backup: [[0.0; 3]; 3],
            channel_scale_ppm: [0.0; IRU_CHANNELS],
            high_rate_scale_ppm: [0.0; IRU_CHANNELS],
            bias_deg_per_s: None,
            bias_transient_deg_per_s: [0.0, 3.0e-5, 0.0, 0.0, -2.0e-5, 0.0],
            bias_transient_time_constant_s: 1.5 * 86_400.0,
            time_since_release_at_start_s: 0.0,
            bias_step_deg_per_s: [0.0; IRU_CHANNELS],
            bias_step_at_s: None,
            bias_random_walk_arcsec_per_s15: 0.0012 / (6.0_f64 * 3600.0).sqrt(),
            angle_random_walk_arcsec_per_sqrt_s: 0.003,
            low_rate_arcsec_per_pulse: 0.05,
            high_rate_arcsec_per_pulse: 0.8,
            initial_high_rate: false,
            initial_counts: [0; IRU_CHANNELS],
            failure: None,
            effects: IruEffects::default(),
        }
    }
}

/// The IRU.
#[derive(Clone, Debug)]
pub struct Iru {
    params: IruParams,
    /// Channel input vectors (ACS, scaled), row i = channel i.
    input_acs: [Vector3<f64>; IRU_CHANNELS],
    bias0_rad_per_s: [f64; IRU_CHANNELS],
    bias_rw_rad_per_s: [f64; IRU_CHANNELS],
    remainder_rad: [f64; IRU_CHANNELS],
    counts: [u16; IRU_CHANNELS],
    /// Unwrapped pulse totals (truth, for tests and logs).
    total_pulses: [i64; IRU_CHANNELS],
    /// (channel, failure time, the BIT bit reports it): `[iru] failure` and the
    /// `iru_channel_failure` faults ([`crate::faults`]).
    failures: Vec<(usize, f64, bool)>,
    interval_high_rate: bool,
    commanded_high_rate: bool,
    previous_integral_acs_rad: Vector3<f64>,
    rng: ChaCha8Rng,
}

fn mat(a: &[[f64; 3]; 3]) -> Matrix3<f64> {
    Matrix3::from_fn(|r, c| a[r][c])
}

impl Iru {
    /// The IRU with the paper's prelaunch `G` and the scenario's truth errors.
    ///
    /// # Errors
    /// A singular `(I + ΔM) G` or an unknown failure channel name.
    pub fn new(params: IruParams, paper: &PaperFacts, seed: u64) -> anyhow::Result<Self> {
        let dm_p = params
            .delta_m_true_primary
            .as_ref()
            .map_or(paper.iru_delta_m, mat);
        let dm_b = mat(&params.delta_m_true_backup);
        let mut input = [Vector3::zeros(); IRU_CHANNELS];
        for (triad, dm, name) in [
            (PRIMARY_CHANNELS, dm_p, "primary"),
            (BACKUP_CHANNELS, dm_b, "backup"),
        ] {
            let w = ((Matrix3::identity() + dm) * paper.iru_g)
                .try_inverse()
                .ok_or_else(|| {
                    anyhow::anyhow!("iru: (I + ΔM) G of the {name} triad is singular")
                })?;
            for (row, ch) in triad.iter().enumerate() {
                input[*ch] = w.row(row).transpose();
            }
        }
        let bias = params.bias_deg_per_s.unwrap_or(paper.iru_bias_deg_per_s);
        Self::with_geometry(input, bias, params, model_rng(seed, stream::IRU))
    }

    /// An IRU with explicit channel input vectors (ACS) and constant biases (deg/s).
    ///
    /// # Errors
    /// An unknown failure channel name.
    pub fn with_geometry(
        input_acs: [Vector3<f64>; IRU_CHANNELS],
        bias_deg_per_s: [f64; IRU_CHANNELS],
        params: IruParams,
        rng: ChaCha8Rng,
    ) -> anyhow::Result<Self> {
        let failed_channel = match &params.failure {
            None => None,
            Some(f) => Some((
                IRU_CHANNEL_NAMES
                    .iter()
                    .position(|n| *n == f.channel)
                    .ok_or_else(|| {
                        anyhow::anyhow!(
                            "iru.failure.channel: unknown channel {:?} (X1, X2, Y1, Y2, Z1, Z2)",
                            f.channel
                        )
                    })?,
                f.at_s,
            )),
        };
        let mut input = input_acs;
        for (ch, v) in input.iter_mut().enumerate() {
            *v *= 1.0 + params.channel_scale_ppm[ch] * 1e-6;
        }
        Ok(Self {
            input_acs: input,
            bias0_rad_per_s: bias_deg_per_s.map(|b| b * RAD_PER_DEG),
            bias_rw_rad_per_s: [0.0; IRU_CHANNELS],
            remainder_rad: [0.0; IRU_CHANNELS],
            counts: params.initial_counts,
            total_pulses: [0; IRU_CHANNELS],
            failures: failed_channel
                .map(|(c, at)| (c, at, true))
                .into_iter()
                .collect(),
            interval_high_rate: params.initial_high_rate,
            commanded_high_rate: params.initial_high_rate,
            previous_integral_acs_rad: Vector3::zeros(),
            rng,
            params,
        })
    }

    /// Fail channel `ch` from `at_s` on: its counter stops; `report_bit` sets its
    /// built-in-test bit (otherwise it sticks silently).
    pub fn add_failure(&mut self, ch: usize, at_s: f64, report_bit: bool) {
        self.failures
            .push((ch.min(IRU_CHANNELS - 1), at_s, report_bit));
    }

    /// Preset the six counters so that each wraps about `at_s` from now, `margin_pulses`
    /// short of the wrap after counting its true bias at low rate until then (fault
    /// `iru_counter_wrap`). Call before the first sample.
    pub fn preset_counters_to_wrap(&mut self, at_s: f64, margin_pulses: u16) {
        let q = self.params.low_rate_arcsec_per_pulse * RAD_PER_ARCSEC;
        for ch in 0..IRU_CHANNELS {
            let drift = self.bias_rad_per_s(ch, 0.5 * at_s, 0.0) * at_s / q;
            let margin = f64::from(margin_pulses);
            let target = if drift >= 0.0 {
                65_536.0 - margin
            } else {
                margin
            };
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let start = ((target - drift).round() as i64).rem_euclid(65_536) as u16;
            self.counts[ch] = start;
        }
    }

    /// The six counters as they read now.
    #[must_use]
    pub fn counts(&self) -> [u16; IRU_CHANNELS] {
        self.counts
    }

    /// Command the rate mode; it takes effect from the next sample interval.
    pub fn command_high_rate(&mut self, high: bool) {
        self.commanded_high_rate = high;
    }

    /// Unwrapped pulse totals since the start (truth).
    #[must_use]
    pub fn total_pulses(&self) -> [i64; IRU_CHANNELS] {
        self.total_pulses
    }

    /// Channel input vectors in ACS including scale errors (truth).
    #[must_use]
    pub fn input_acs(&self) -> &[Vector3<f64>; IRU_CHANNELS] {
        &self.input_acs
    }

    /// Current true bias of channel `ch` at `t_s` (rad/s) for baseplate deviation `dev_c`.
    #[must_use]
    pub fn bias_rad_per_s(&self, ch: usize, t_s: f64, dev_c: f64) -> f64 {
        let ch = ch.min(IRU_CHANNELS - 1);
        let p = &self.params;
        let t_rel = p.time_since_release_at_start_s + t_s;
        let tau = p.bias_transient_time_constant_s.max(1.0);
        self.bias0_rad_per_s[ch]
            + p.bias_transient_deg_per_s[ch] * RAD_PER_DEG * (-t_rel.max(0.0) / tau).exp()
            + self.bias_rw_rad_per_s[ch]
            + p.effects.thermal_bias_deg_per_s_per_c[ch] * RAD_PER_DEG * dev_c
            + if p.bias_step_at_s.is_some_and(|at| t_s >= at) {
                p.bias_step_deg_per_s[ch] * RAD_PER_DEG
            } else {
                0.0
            }
    }

    /// Sample at the end of an interval of `dt_s` ending at `t_s`, during which the body
    /// turned by `rate_integral_acs_rad` (∫ω dt from the dynamics). `dev_c` is the IRU
    /// baseplate temperature deviation.
    pub fn sample(
        &mut self,
        rate_integral_acs_rad: &Vector3<f64>,
        dt_s: f64,
        t_s: f64,
        dev_c: f64,
    ) -> IruSample {
        let p = &self.params;
        let high = self.interval_high_rate;
        let q_rad = if high {
            p.high_rate_arcsec_per_pulse
        } else {
            p.low_rate_arcsec_per_pulse
        } * RAD_PER_ARCSEC;
        let tau = p.effects.time_tag_offset_s;
        let kinematic = if tau != 0.0 && dt_s > 0.0 {
            let f = (tau / dt_s).clamp(0.0, 1.0);
            rate_integral_acs_rad * (1.0 - f) + self.previous_integral_acs_rad * f
        } else {
            *rate_integral_acs_rad
        };
        self.previous_integral_acs_rad = *rate_integral_acs_rad;
        let sigma_u = p.bias_random_walk_arcsec_per_s15 * RAD_PER_ARCSEC * dt_s.max(0.0).sqrt();
        let sigma_v = p.angle_random_walk_arcsec_per_sqrt_s * RAD_PER_ARCSEC * dt_s.max(0.0).sqrt();
        let t_mid = t_s - 0.5 * dt_s;
        let mut failed_bits = 0_u8;
        for ch in 0..IRU_CHANNELS {
            let p = &self.params;
            let mut d = self.input_acs[ch].dot(&kinematic);
            let mut scale = if high {
                p.high_rate_scale_ppm[ch] * 1e-6
            } else {
                0.0
            };
            let fx = &p.effects;
            scale += fx.scale_asymmetry_ppm[ch] * 1e-6 * d.signum();
            if fx.rate_power_scale_ppm[ch] != 0.0 && dt_s > 0.0 {
                let w_ref = fx.rate_power_reference_deg_per_s.abs().max(1e-12) * RAD_PER_DEG;
                let w = d.abs() / dt_s;
                scale +=
                    fx.rate_power_scale_ppm[ch] * 1e-6 * (w / w_ref).powf(fx.rate_power_exponent);
            }
            if fx.scale_step_at_s.is_some_and(|at| t_mid >= at) {
                scale += fx.scale_step_ppm[ch] * 1e-6;
            }
            d *= 1.0 + scale;
            let mut bias = self.bias_rad_per_s(ch, t_mid, dev_c);
            if high {
                bias += fx.high_rate_bias_deg_per_s[ch] * RAD_PER_DEG;
            }
            let nv: f64 = StandardNormal.sample(&mut self.rng);
            let nu: f64 = StandardNormal.sample(&mut self.rng);
            self.bias_rw_rad_per_s[ch] += sigma_u * nu;
            let acc = self.remainder_rad[ch] + d + bias * dt_s + sigma_v * nv;
            // The 1e-9-pulse nudge makes exact multiples (8″/s at 0.05″) count as such instead of
            // losing a pulse to rounding; the remainder may then be −1e-9 q, harmless.
            let pulses = (acc / q_rad + PULSE_ROUNDING_NUDGE).floor();
            self.remainder_rad[ch] = acc - pulses * q_rad;
            #[allow(clippy::cast_possible_truncation)]
            let pulses = pulses as i64;
            let mut failed = false;
            for &(c, at, bit) in &self.failures {
                if c == ch && t_s >= at {
                    failed = true;
                    if bit {
                        failed_bits |= 1 << ch;
                    }
                }
            }
            if !failed {
                self.total_pulses[ch] += pulses;
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                let wrapped = (i64::from(self.counts[ch]) + pulses).rem_euclid(65_536) as u16;
                self.counts[ch] = wrapped;
            }
        }
        self.interval_high_rate = self.commanded_high_rate;
        IruSample {
            counts: self.counts,
            channel_failed: failed_bits,
            high_rate: high,
        }
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)]
mod tests {
    use super::*;

    fn axes() -> [Vector3<f64>; IRU_CHANNELS] {
        [
            Vector3::x(),
            Vector3::x(),
            Vector3::y(),
            Vector3::y(),
            Vector3::z(),
            Vector3::z(),
        ]
    }

    fn ideal() -> IruParams {
        IruParams {
            bias_transient_deg_per_s: [0.0; IRU_CHANNELS],
            bias_random_walk_arcsec_per_s15: 0.0,
            angle_random_walk_arcsec_per_sqrt_s: 0.0,
            ..IruParams::default()
        }
    }

    fn ideal_iru(p: IruParams) -> Iru {
        Iru::with_geometry(axes(), [0.0; IRU_CHANNELS], p, model_rng(1, 5)).unwrap()
    }

    /// One sample of 1 s ending at t = 1 s, the body turning by `increment_acs_arcsec` in it,
    /// at the reference temperature.
    fn sample_one_second(iru: &mut Iru, increment_acs_arcsec: [f64; 3]) {
        iru.sample(
            &Vector3::from(increment_acs_arcsec).scale(RAD_PER_ARCSEC),
            1.0,
            1.0,
            0.0,
        );
    }

    /// A constant rate gives floor(total angle / q) pulses in total, the fraction carried
    /// between samples (no pulse lost or gained), and the 16-bit deltas decode with
    /// `wrapping_sub as i16`.
    #[test]
    fn constant_rate_pulse_total_with_remainder() {
        let mut iru = ideal_iru(ideal());
        let rate = Vector3::new(0.0123, -0.0456, 0.0789) * RAD_PER_ARCSEC * 100.0; // arcsec/s·100
        let mut prev = [0_u16; IRU_CHANNELS];
        let mut decoded = [0_i64; IRU_CHANNELS];
        let n = 1000;
        for k in 1..=n {
            let s = iru.sample(&rate, 1.0, f64::from(k), 0.0);
            for ch in 0..IRU_CHANNELS {
                decoded[ch] += i64::from(s.counts[ch].wrapping_sub(prev[ch]) as i16);
            }
            prev = s.counts;
            assert!(!s.high_rate);
        }
        for ch in 0..IRU_CHANNELS {
            let total_arcsec = axes()[ch].dot(&rate) * f64::from(n) / RAD_PER_ARCSEC;
            let expect = (total_arcsec / 0.05 + 1e-9).floor() as i64;
            assert_eq!(iru.total_pulses()[ch], expect, "channel {ch}");
            assert_eq!(decoded[ch], expect);
        }
    }

    /// 16-bit wrap: at 1°/s in high-rate mode (4500 pulses/s) the counter wraps after 14.6 s;
    /// the per-sample wrapping differences still give the pulses.
    #[test]
    fn counter_wraps() {
        let mut iru = ideal_iru(IruParams {
            initial_high_rate: true,
            initial_counts: [65_000; IRU_CHANNELS],
            ..ideal()
        });
        let rate = Vector3::new(1.0, -1.0, 0.5) * RAD_PER_DEG;
        let mut prev = [65_000_u16; IRU_CHANNELS];
        for k in 1..=30 {
            let s = iru.sample(&rate, 1.0, f64::from(k), 0.0);
            assert!(s.high_rate);
            let d = i64::from(s.counts[0].wrapping_sub(prev[0]) as i16);
            assert!((d - 4500).abs() <= 1, "{d}");
            let d2 = i64::from(s.counts[2].wrapping_sub(prev[2]) as i16);
            assert!((d2 + 4500).abs() <= 1, "{d2}");
            prev = s.counts;
        }
        assert_eq!(
            i64::from(prev[0]),
            (65_000 + iru.total_pulses()[0]).rem_euclid(65_536)
        );
        assert!(iru.total_pulses()[0] > 65_536);
    }

    /// The commanded mode applies from the next interval; `high_rate` reports the interval
    /// that ended. The remainder angle carries across the switch.
    #[test]
    fn rate_mode_switch_timing() {
        let mut iru = ideal_iru(ideal());
        let rate = Vector3::new(8.0, 0.0, 0.0) * RAD_PER_ARCSEC; // 8″/s
        let s1 = iru.sample(&rate, 1.0, 1.0, 0.0);
        assert_eq!((s1.high_rate, s1.counts[0]), (false, 160));
        iru.command_high_rate(true);
        let s2 = iru.sample(&rate, 1.0, 2.0, 0.0);
        assert_eq!((s2.high_rate, s2.counts[0] - s1.counts[0]), (false, 160));
        let s3 = iru.sample(&rate, 1.0, 3.0, 0.0);
        assert_eq!((s3.high_rate, s3.counts[0] - s2.counts[0]), (true, 10));
        iru.command_high_rate(false);
        let s4 = iru.sample(&rate, 1.0, 4.0, 0.0);
        assert!(s4.high_rate);
        let s5 = iru.sample(&rate, 1.0, 5.0, 0.0);
        assert!(!s5.high_rate);
    }

    /// A failed channel sticks and reports its BIT bit from the failure time.
    #[test]
    fn channel_failure() {
        let p = IruParams {
            failure: Some(ChannelFailure {
                channel: "Y1".into(),
                at_s: 3.0,
            }),
            ..ideal()
        };
        let mut iru = ideal_iru(p);
        let rate = Vector3::new(1.0, 1.0, 1.0) * RAD_PER_ARCSEC;
        let mut last = IruSample::default();
        for k in 1..=6 {
            let s = iru.sample(&rate, 1.0, f64::from(k), 0.0);
            if k >= 3 {
                assert_eq!(s.channel_failed, 1 << 2);
                assert_eq!(s.counts[2], 40, "stuck at the value of t = 2");
                assert_eq!(s.counts[3], 20 * k as u16);
            } else {
                assert_eq!(s.channel_failed, 0);
            }
            last = s;
        }
        assert_eq!(last.counts[0], 120);
        let bad = IruParams {
            failure: Some(ChannelFailure {
                channel: "Q9".into(),
                at_s: 0.0,
            }),
            ..ideal()
        };
        assert!(Iru::with_geometry(axes(), [0.0; 6], bad, model_rng(1, 5)).is_err());
    }

    /// At rest the pulses measure the bias (with the early transient decaying), within one
    /// pulse of the integral.
    #[test]
    fn bias_and_transient_at_rest() {
        let bias = [1e-4, -2e-4, 0.0, 5e-5, 0.0, 0.0];
        let p = IruParams {
            bias_transient_deg_per_s: [0.0, 0.0, 0.0, 0.0, 1e-4, 0.0],
            bias_transient_time_constant_s: 1000.0,
            ..ideal()
        };
        let mut iru = Iru::with_geometry(axes(), bias, p, model_rng(1, 5)).unwrap();
        for k in 1..=10_000 {
            iru.sample(&Vector3::zeros(), 1.0, f64::from(k), 0.0);
        }
        let to_pulses = |deg: f64| deg * 3600.0 / 0.05;
        assert!((iru.total_pulses()[0] as f64 - to_pulses(1e-4 * 10_000.0)).abs() <= 1.0);
        assert!((iru.total_pulses()[1] as f64 - to_pulses(-2e-4 * 10_000.0)).abs() <= 1.0);
        // ∫ 1e-4 e^{−t/1000} dt over 10 000 s = 1e-4·1000·(1 − e^{−10}).
        let transient = to_pulses(1e-4 * 1000.0 * (1.0 - (-10.0_f64).exp()));
        assert!(
            (iru.total_pulses()[4] as f64 - transient).abs() <= 2.0,
            "{}",
            iru.total_pulses()[4]
        );
    }

    /// The paper geometry: with the true ΔM, `(I + ΔM) G Δφ` of the primary channels returns
    /// the body rotation (the definition of a perfect calibration).
    #[test]
    fn val_paper_geometry_is_consistent_with_g_and_delta_m() {
        let paper = PaperFacts::load().unwrap();
        let iru = Iru::new(ideal(), &paper, 3).unwrap();
        let theta = Vector3::new(0.3, -0.2, 0.9);
        let phi = Vector3::new(
            iru.input_acs()[1].dot(&theta),
            iru.input_acs()[2].dot(&theta),
            iru.input_acs()[4].dot(&theta),
        );
        let back = (Matrix3::identity() + paper.iru_delta_m) * paper.iru_g * phi;
        assert!((back - theta).norm() < 1e-12);
    }

    /// Bias random walk: the spread of the bias change over 6 h is the paper's 0.0012″/s.
    #[test]
    fn bias_random_walk_matches_paper_stability() {
        let runs = 200;
        let mut sum2 = 0.0;
        for seed in 0..runs {
            let p = IruParams {
                bias_transient_deg_per_s: [0.0; IRU_CHANNELS],
                angle_random_walk_arcsec_per_sqrt_s: 0.0,
                ..IruParams::default()
            };
            let mut iru = Iru::with_geometry(axes(), [0.0; 6], p, model_rng(seed, 5)).unwrap();
            for k in 1..=360 {
                iru.sample(&Vector3::zeros(), 60.0, 60.0 * f64::from(k), 0.0);
            }
            for ch in 0..IRU_CHANNELS {
                sum2 += (iru.bias_rad_per_s(ch, 21_600.0, 0.0) / RAD_PER_ARCSEC).powi(2);
            }
        }
        let sd = (sum2 / f64::from(runs as u32 * 6)).sqrt();
        assert!((sd - 0.0012).abs() < 0.0001, "{sd}″/s");
    }

    /// The high-rate-mode bias counts only in high-rate intervals: at rest, 36″/s
    /// (0.01°/s) in high rate gives 45 pulses of 0.8″ per second, nothing in low rate.
    #[test]
    fn high_rate_bias_only_in_high_rate_mode() {
        let mut p = ideal();
        p.effects.high_rate_bias_deg_per_s = [0.01, 0.0, 0.0, 0.0, 0.0, 0.0];
        let mut iru = ideal_iru(p);
        for k in 1..=10 {
            iru.sample(&Vector3::zeros(), 1.0, f64::from(k), 0.0);
        }
        assert_eq!(iru.total_pulses(), [0; IRU_CHANNELS], "low rate: no bias");
        iru.command_high_rate(true);
        iru.sample(&Vector3::zeros(), 1.0, 11.0, 0.0); // the switch takes one interval
        for k in 12..=21 {
            let s = iru.sample(&Vector3::zeros(), 1.0, f64::from(k), 0.0);
            assert!(s.high_rate);
        }
        assert_eq!(iru.total_pulses()[0], 450);
        assert_eq!(iru.total_pulses()[1..], [0; IRU_CHANNELS - 1]);
    }

    /// The rate-power scale: `k (|ω|/ω_ref)^p` on the channel's rate; 1000 ppm at 1°/s with
    /// p = 2 is 1000 ppm at 1°/s and 250 ppm at 0.5°/s, either sign.
    #[test]
    fn rate_power_scale_grows_with_rate() {
        let mut p = ideal();
        p.effects.rate_power_scale_ppm = [1000.0; IRU_CHANNELS];
        p.initial_high_rate = true;
        let mut iru = ideal_iru(p);
        // 1°/s on x, −0.5°/s on y, at rest on z; 0.8″ pulses.
        sample_one_second(&mut iru, [3600.0, -1800.0, 0.0]);
        // 3600 × 1.001 / 0.8 = 4504.5; −1800 × 1.00025 / 0.8 = −2250.56.
        assert_eq!(iru.total_pulses()[0], 4504);
        assert_eq!(iru.total_pulses()[2], -2251);
        assert_eq!(iru.total_pulses()[4], 0);
        // The exponent and the reference rate: p = 1, ω_ref = 2°/s gives 500 ppm at 1°/s.
        let mut q = ideal();
        q.effects.rate_power_scale_ppm = [1000.0; IRU_CHANNELS];
        q.effects.rate_power_exponent = 1.0;
        q.effects.rate_power_reference_deg_per_s = 2.0;
        q.initial_high_rate = true;
        let mut iru = ideal_iru(q);
        sample_one_second(&mut iru, [3600.0, 0.0, 0.0]);
        assert_eq!(iru.total_pulses()[0], 4502, "3600 × 1.0005 / 0.8 = 4502.25");
    }

    /// The scale step multiplies the kinematic part from its time on (the interval's midpoint).
    #[test]
    fn scale_step_from_its_time() {
        let mut p = ideal();
        p.effects.scale_step_ppm = [0.0, 0.0, 500.0, 0.0, 0.0, 0.0];
        p.effects.scale_step_at_s = Some(10.0);
        let mut iru = ideal_iru(p);
        let rate = Vector3::new(0.0, 1000.0, 0.0).scale(RAD_PER_ARCSEC); // 20 000 pulses/s
        let mut per_s = Vec::new();
        let mut prev = 0;
        for k in 1..=12 {
            iru.sample(&rate, 1.0, f64::from(k), 0.0);
            per_s.push(iru.total_pulses()[2] - prev);
            prev = iru.total_pulses()[2];
        }
        // Intervals ending at 1..=10 s have midpoints before 10 s; 11 and 12 after.
        assert!(per_s[..10].iter().all(|&n| n == 20_000), "{per_s:?}");
        assert_eq!(per_s[10..], [20_010, 20_010]);
        assert_eq!(
            iru.total_pulses()[3],
            20_000 * 12,
            "the other channel of y: no step"
        );
    }

    /// Scale asymmetry and the high-mode scale error act on the kinematic part.
    #[test]
    fn scale_effects() {
        let mut asym = ideal();
        asym.effects.scale_asymmetry_ppm = [1000.0; IRU_CHANNELS];
        let mut iru = ideal_iru(asym);
        sample_one_second(&mut iru, [1000.0, -1000.0, 0.0]);
        assert_eq!(iru.total_pulses()[0], 20_020);
        assert_eq!(iru.total_pulses()[2], -19_980, "−1000″ × (1 − 1000 ppm)");
        let mut hr = ideal();
        hr.high_rate_scale_ppm = [500.0; IRU_CHANNELS];
        hr.initial_high_rate = true;
        let mut iru = ideal_iru(hr);
        sample_one_second(&mut iru, [8000.0, 0.0, 0.0]);
        assert_eq!(iru.total_pulses()[0], 10_005);
    }
}
