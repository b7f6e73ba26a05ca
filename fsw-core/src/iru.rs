//! # DRIRU II pulse integration (paper: DRIRU II and `G`; algorithms.md §5)
//!
//! The DRIRU II has three dual-axis gyros, i.e. six rate-integrating channels X1, X2, Y1, Y2,
//! Z1, Z2 (channel indices 0..=5, [`crate::raw::IRU_CHANNEL_NAMES`]). Each channel emits one
//! pulse per `w` of rotation about its input axis and the OBC reads six 16-bit wrapping
//! accumulators once per cycle ([`IruSample`]). Three channels are selected:
//!
//! | configuration | channels (X, Y, Z) | indices |
//! |---|---|---|
//! | [`IruConfiguration::Primary`] | X2, Y1, Z1 | 1, 2, 4 |
//! | [`IruConfiguration::Backup`]  | X1, Y2, Z2 | 0, 3, 5 |
//!
//! ## Equations
//!
//! * Count difference with 16-bit wrap (algorithms.md §5 item 2):
//!   `ΔN = (N_k − N_{k−1}) mod 2¹⁶` read as `i16`, valid while `|ΔN_true| < 2¹⁵` per cycle
//!   (0.45 °/s at 0.05″/pulse, 7.3 °/s at 0.8″/pulse for a 1-s cycle).
//! * Angle increment in ACS (paper `G` and pulse weights; algorithms.md §5 item 3):
//!   `Δθ_acs = G · diag(k) · w · ΔN` with `G` and `k` of the active configuration
//!   ([`IruTable`]) and `w` the pulse weight of the rate mode **of the interval that ended**
//!   ([`IruSample::high_rate`]). Because the hardware reports the mode of the interval that
//!   produced the pulses, a mode switch commanded in cycle `k` is applied to exactly the
//!   pulses it affected and adds no error (algorithms.md §5 item 4); no sample straddles a switch.
//! * The calibrated increment `(I + ΔM)Δθ − b̂Δt` is formed by the filter
//!   ([`crate::mekf::Mekf::propagate`]); this module only converts counts.
//!
//! ## Channel health
//!
//! Evaluated every cycle for all six channels, as bit masks (bit `i` = channel `i`):
//! * **failed**: the channel's built-in-test bit ([`IruSample::channel_failed`]);
//! * **saturated**: `|ΔN| >` [`IruTable::saturation_pulses_per_cycle`] this cycle;
//! * **stuck**: the counter has not changed for at least [`IruTable::stuck_cycles`]
//!   consecutive cycles, or has not changed in a cycle in which its healthy partner on the
//!   same axis turned at least [`PAIR_STUCK_ARCSEC`] (it clears on the next change). On orbit the gyro bias alone makes
//!   every healthy channel count (GRO: ~0.6″/s ≈ 12 low-rate pulses/s).
//!
//! An increment is produced only when all three selected channels are usable; otherwise
//! [`IruOutput::delta_theta_acs_rad`] is `None` and the executive decides (propagate with
//! the bias only, or switch configuration). Unwrapped `i64` running totals are kept per
//! channel (pulses, whatever the mode) for telemetry and for interval-based calibration
//! (algorithms.md §5 item 5: quantization then enters only at the interval ends).

use crate::raw::{IruSample, IRU_CHANNELS};
use crate::tables::types::{matrix_from_rows, IruTable};
use crate::units::RAD_PER_ARCSEC;
use nalgebra::{Matrix3, Vector3};

/// The two channels of each axis (X1/X2, Y1/Y2, Z1/Z2): one of each triad, same input axis.
/// Paper: DRIRU II, three dual-axis gyros.
pub const AXIS_PAIRS: [(usize, usize); 3] = [(0, 1), (2, 3), (4, 5)];

/// Pair cross-check threshold, arcsec per cycle: a channel whose counter did not move while
/// its healthy partner on the same axis turned at least this much is stuck *now*. Two
/// channels of one axis see the same rate to within their bias difference (DRIRU II biases
/// ~0.4″/s) and the 10⁻³ misalignments, so a healthy channel cannot read 0 pulses (< 0.8″ at
/// high rate) while its partner reads 20″; any slew (0.08°/s = 288″/s) trips it in one
/// cycle. Without it a channel that sticks silently (no built-in-test bit) mid-slew is only
/// found after `stuck_cycles` (120 s): 3° of attitude error, outside the star
/// identification window, from which the OBC does not recover (issue 7,
/// `scenarios/faults/iru-stuck-channel-mid-slew.toml`).
/// Project choice (not in the paper); bias size from the paper's high-rate biases (~1e-4 °/s).
pub const PAIR_STUCK_ARCSEC: f64 = 20.0;

/// Bit of each channel in the health masks, channel order X1, X2, Y1, Y2, Z1, Z2.
/// docs/icd.md §3.2 (offset 172) and §3.3 (event 0x0204).
pub const CHANNEL_BITS: [u8; IRU_CHANNELS] = [0x01, 0x02, 0x04, 0x08, 0x10, 0x20];
/// All six channel bits.
/// docs/icd.md §3.2 (offset 172).
pub const ALL_CHANNELS_MASK: u8 = 0x3F;

/// Which three DRIRU II channels feed the attitude.
/// Paper: primary X2, Y1, Z1; backup X1, Y2, Z2.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum IruConfiguration {
    /// X2, Y1, Z1 (channel indices 1, 2, 4).
    /// Paper: primary configuration.
    #[default]
    Primary,
    /// X1, Y2, Z2 (channel indices 0, 3, 5).
    /// Paper: backup configuration.
    Backup,
}

impl IruConfiguration {
    /// Channel indices of the X, Y, Z inputs.
    /// Paper: primary X2, Y1, Z1; backup X1, Y2, Z2 (docs/icd.md §3.1 order).
    #[must_use]
    pub const fn channels(self) -> [usize; 3] {
        match self {
            Self::Primary => [1, 2, 4],
            Self::Backup => [0, 3, 5],
        }
    }

    /// Telemetry/event code: 0 primary, 1 backup.
    /// docs/icd.md §3.2 (offset 106) and §3.3 (event 0x0202).
    #[must_use]
    pub const fn code(self) -> u32 {
        match self {
            Self::Primary => 0,
            Self::Backup => 1,
        }
    }

    /// Health-mask bits of the three selected channels.
    /// docs/icd.md §3.2 (offset 172).
    #[must_use]
    pub const fn channel_mask(self) -> u8 {
        match self {
            Self::Primary => 0x02 | 0x04 | 0x10,
            Self::Backup => 0x01 | 0x08 | 0x20,
        }
    }

    /// `G` of this configuration (unitless).
    /// Paper: `G`, the prelaunch IRU alignment/scale-factor matrix (docs/tables.md Table 2: IRU).
    #[must_use]
    pub fn g(self, table: &IruTable) -> Matrix3<f64> {
        match self {
            Self::Primary => matrix_from_rows(&table.g_primary),
            Self::Backup => matrix_from_rows(&table.g_backup),
        }
    }

    /// Scale factors `k` of this configuration's X, Y, Z channels (unitless).
    /// docs/tables.md (IRU table, `k`); project choice (not in the paper): 1 at boot.
    #[must_use]
    pub fn scale_factors(self, table: &IruTable) -> [f64; 3] {
        match self {
            Self::Primary => table.scale_factor_primary,
            Self::Backup => table.scale_factor_backup,
        }
    }

    /// Scale-factor asymmetries `a` of this configuration's X, Y, Z channels (unitless).
    /// docs/tables.md (IRU table fields 8–9); effect 9 of algorithms.md §9.
    #[must_use]
    pub fn scale_asymmetries(self, table: &IruTable) -> [f64; 3] {
        match self {
            Self::Primary => table.scale_asymmetry_primary,
            Self::Backup => table.scale_asymmetry_backup,
        }
    }
}

/// Pulse weight (rad per pulse) of a rate mode.
/// Paper: DRIRU II 0.05″/pulse low rate, 0.8″/pulse high rate.
#[must_use]
pub fn pulse_weight_rad(high_rate: bool, table: &IruTable) -> f64 {
    let arcsec = if high_rate {
        table.high_rate_arcsec_per_pulse
    } else {
        table.low_rate_arcsec_per_pulse
    };
    arcsec * RAD_PER_ARCSEC
}

/// `Δθ_acs = G · diag(k_i (1 − a_i sgn ΔN_i)) · w · ΔN` (rad) for count differences of the
/// X, Y, Z channels of `config`, all taken in one rate mode, with the table's scale-factor
/// asymmetries `a` (0 = off). Also usable for interval totals (algorithms.md §5 item 5) of
/// one rotation sense.
#[must_use]
#[inline]
pub fn delta_theta_from_pulses(
    delta_pulses_xyz: &[f64; 3],
    high_rate: bool,
    config: IruConfiguration,
    table: &IruTable,
) -> Vector3<f64> {
    let w = pulse_weight_rad(high_rate, table);
    let [kx, ky, kz] = config.scale_factors(table);
    let [nx, ny, nz] = *delta_pulses_xyz;
    let [ax, ay, az] = config.scale_asymmetries(table);
    let phi = if ax == 0.0 && ay == 0.0 && az == 0.0 {
        Vector3::new(kx * nx, ky * ny, kz * nz)
    } else {
        Vector3::new(
            kx * asymmetry_factor(ax, nx) * nx,
            ky * asymmetry_factor(ay, ny) * ny,
            kz * asymmetry_factor(az, nz) * nz,
        )
    } * w;
    config.g(table) * phi
}

/// `1 − a sgn ΔN`: a channel over-reading by `a |Δθ|` in both senses (scale `1 + a` for
/// positive rates, `1 − a` for negative) is corrected to first order in `a`.
/// docs/tables.md (IRU table fields 8–9); effect 9 of algorithms.md §9.
fn asymmetry_factor(a: f64, delta_pulses: f64) -> f64 {
    if delta_pulses > 0.0 {
        1.0 - a
    } else if delta_pulses < 0.0 {
        1.0 + a
    } else {
        1.0
    }
}

/// Per-channel health, bit `i` = channel `i` (X1, X2, Y1, Y2, Z1, Z2).
/// docs/icd.md §3.3 (event 0x0201 reason bits).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ChannelHealth {
    /// Built-in-test failure reported by the hardware.
    /// docs/icd.md §3.1 (IRU BIT bits, offset 12).
    pub failed: u8,
    /// `|ΔN|` above the table's saturation threshold this cycle.
    /// docs/tables.md (IRU table, `saturation_pulses_per_cycle`).
    pub saturated: u8,
    /// Counter unchanged for at least the table's stuck-cycle count.
    /// docs/tables.md (IRU table, `stuck_cycles`); see also [`PAIR_STUCK_ARCSEC`].
    pub stuck: u8,
}

impl ChannelHealth {
    /// Channels that must not be used this cycle.
    /// Project choice (not in the paper): failed, saturated or stuck.
    #[must_use]
    pub const fn unusable(&self) -> u8 {
        self.failed | self.saturated | self.stuck
    }
}

/// Result of one IRU cycle.
/// algorithms.md §5.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct IruOutput {
    /// Angle increment over the interval that ended, ACS axes (rad). `None` on the first
    /// sample after (re)initialisation, when a selected channel is unusable, or when the
    /// result is not finite.
    /// Paper `G`; algorithms.md §5 item 3.
    pub delta_theta_acs_rad: Option<Vector3<f64>>,
    /// Count differences of all six channels this cycle (0 on the first sample).
    /// algorithms.md §5 item 2.
    pub delta_counts: [i16; IRU_CHANNELS],
    /// Health of all six channels.
    /// docs/icd.md §3.3 (event 0x0201).
    pub health: ChannelHealth,
    /// All three selected channels usable (health only: also true on the first sample, whose
    /// increment is `None` for lack of a previous count).
    /// Project choice (not in the paper): lets the executive switch configuration.
    pub selected_usable: bool,
    /// Rate mode of the interval that ended (copied from the sample).
    /// docs/icd.md §3.1 (offset 13); algorithms.md §5 item 4.
    pub high_rate: bool,
    /// Configuration used.
    /// Paper: primary or backup configuration.
    pub configuration: IruConfiguration,
}

#[cfg(feature = "defmt")]
impl defmt::Format for IruOutput {
    fn format(&self, f: defmt::Formatter) {
        let d = self.delta_theta_acs_rad.map(|v| [v.x, v.y, v.z]);
        defmt::write!(
            f,
            "IruOutput {{ dtheta: {}, dN: {}, health: {}, usable: {}, high: {}, cfg: {} }}",
            d,
            self.delta_counts,
            self.health,
            self.selected_usable,
            self.high_rate,
            self.configuration
        );
    }
}

/// Exclusion reason bit: built-in-test failure.
/// docs/icd.md §3.3 (event 0x0201, p2 bit 1).
pub const EXCLUDED_FAILED: u32 = 0x1;
/// Exclusion reason bit: saturated this cycle.
/// docs/icd.md §3.3 (event 0x0201, p2 bit 2).
pub const EXCLUDED_SATURATED: u32 = 0x2;
/// Exclusion reason bit: stuck.
/// docs/icd.md §3.3 (event 0x0201, p2 bit 4).
pub const EXCLUDED_STUCK: u32 = 0x4;

/// What the last processed sample produced (for [`IruIntegrator::reprocess`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
struct LastCycle {
    delta_counts: [i16; IRU_CHANNELS],
    health: ChannelHealth,
    high_rate: bool,
    has_delta: bool,
}

/// Pulse-count integrator: remembers the previous counters and per-channel state.
/// algorithms.md §5 (items 1, 2, 5).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct IruIntegrator {
    previous_counts: [u16; IRU_CHANNELS],
    initialised: bool,
    unchanged_cycles: [u16; IRU_CHANNELS],
    totals_pulses: [i64; IRU_CHANNELS],
    last: LastCycle,
}

/// The output for given count differences and health, in configuration `config`.
fn output_for(last: &LastCycle, config: IruConfiguration, table: &IruTable) -> IruOutput {
    let selected_usable = last.health.unusable() & config.channel_mask() == 0;
    let delta_theta_acs_rad = if selected_usable && last.has_delta {
        let [ix, iy, iz] = config.channels();
        let pick = |i: usize| f64::from(last.delta_counts.get(i).copied().unwrap_or(0));
        let dtheta = delta_theta_from_pulses(
            &[pick(ix), pick(iy), pick(iz)],
            last.high_rate,
            config,
            table,
        );
        dtheta.iter().all(|x| x.is_finite()).then_some(dtheta)
    } else {
        None
    };
    IruOutput {
        delta_theta_acs_rad,
        delta_counts: last.delta_counts,
        health: last.health,
        selected_usable,
        high_rate: last.high_rate,
        configuration: config,
    }
}

impl IruIntegrator {
    /// A fresh integrator: the next sample only initialises it.
    /// Project choice (not in the paper): no increment until two samples exist.
    #[must_use]
    pub const fn new() -> Self {
        Self {
            previous_counts: [0; IRU_CHANNELS],
            initialised: false,
            unchanged_cycles: [0; IRU_CHANNELS],
            totals_pulses: [0; IRU_CHANNELS],
            last: LastCycle {
                delta_counts: [0; IRU_CHANNELS],
                health: ChannelHealth {
                    failed: 0,
                    saturated: 0,
                    stuck: 0,
                },
                high_rate: false,
                has_delta: false,
            },
        }
    }

    /// Forget the previous sample (e.g. after an IRU power cycle); totals are kept.
    /// Project choice (not in the paper): totals stay continuous for ground calibration.
    pub fn reset(&mut self) {
        self.initialised = false;
        self.unchanged_cycles = [0; IRU_CHANNELS];
        self.last = LastCycle::default();
    }

    /// Has a previous sample.
    /// algorithms.md §5 item 2 (a difference needs two samples).
    #[must_use]
    pub const fn is_initialized(&self) -> bool {
        self.initialised
    }

    /// Channels unusable in the last processed sample (bit `i` = channel `i`).
    /// docs/icd.md §3.2 (offset 172).
    #[must_use]
    pub const fn excluded_mask(&self) -> u8 {
        self.last.health.unusable()
    }

    /// Why channel `channel` was unusable in the last sample: a combination of
    /// [`EXCLUDED_FAILED`], [`EXCLUDED_SATURATED`], [`EXCLUDED_STUCK`] (0 = usable or no such
    /// channel).
    /// docs/icd.md §3.3 (event 0x0201, p2).
    #[must_use]
    pub fn exclusion_reason(&self, channel: usize) -> u32 {
        let Some(&bit) = CHANNEL_BITS.get(channel) else {
            return 0;
        };
        let h = &self.last.health;
        let mut reason = 0;
        if h.failed & bit != 0 {
            reason |= EXCLUDED_FAILED;
        }
        if h.saturated & bit != 0 {
            reason |= EXCLUDED_SATURATED;
        }
        if h.stuck & bit != 0 {
            reason |= EXCLUDED_STUCK;
        }
        reason
    }

    /// The last sample's output again, for another configuration (all six counters are
    /// tracked every cycle, so switching to the backup channels loses no interval).
    /// Paper: primary/backup configurations; project choice: no lost interval on a switch.
    #[must_use]
    pub fn reprocess(&self, config: IruConfiguration, table: &IruTable) -> IruOutput {
        output_for(&self.last, config, table)
    }

    /// Unwrapped running totals of pulses per channel (any mode) since construction.
    /// algorithms.md §5 item 2 (unwrapped `i64` totals).
    #[must_use]
    pub const fn totals_pulses(&self) -> [i64; IRU_CHANNELS] {
        self.totals_pulses
    }

    /// Process one sample: count differences, channel health, and the ACS angle increment
    /// of the selected configuration over the interval that ended at this sample.
    /// algorithms.md §5 items 2–4.
    pub fn process(
        &mut self,
        sample: &IruSample,
        config: IruConfiguration,
        table: &IruTable,
    ) -> IruOutput {
        let mut health = ChannelHealth {
            failed: sample.channel_failed & ALL_CHANNELS_MASK,
            saturated: 0,
            stuck: 0,
        };
        let mut delta_counts = [0i16; IRU_CHANNELS];

        if !self.initialised {
            self.previous_counts = sample.counts;
            self.unchanged_cycles = [0; IRU_CHANNELS];
            self.initialised = true;
            self.last = LastCycle {
                delta_counts,
                health,
                high_rate: sample.high_rate,
                has_delta: false,
            };
            return output_for(&self.last, config, table);
        }

        let channels = sample
            .counts
            .iter()
            .zip(self.previous_counts.iter_mut())
            .zip(self.unchanged_cycles.iter_mut())
            .zip(self.totals_pulses.iter_mut())
            .zip(delta_counts.iter_mut())
            .zip(CHANNEL_BITS.iter());
        for (((((now, prev), unchanged), total), delta), bit) in channels {
            // Two's-complement reinterpretation of the 16-bit difference (§5.2).
            #[allow(clippy::cast_possible_wrap)]
            let dn = now.wrapping_sub(*prev) as i16;
            *delta = dn;
            *prev = *now;
            *total = total.saturating_add(i64::from(dn));
            if dn.unsigned_abs() > table.saturation_pulses_per_cycle {
                health.saturated |= bit;
            }
            *unchanged = if dn == 0 {
                unchanged.saturating_add(1)
            } else {
                0
            };
            if *unchanged >= table.stuck_cycles {
                health.stuck |= bit;
            }
        }
        // Pair cross-check (`PAIR_STUCK_ARCSEC`): a stuck channel is latched through the
        // unchanged-cycle count, so it stays excluded until its counter moves again.
        let weight_arcsec = if sample.high_rate {
            table.high_rate_arcsec_per_pulse
        } else {
            table.low_rate_arcsec_per_pulse
        };
        let bad = health.failed | health.saturated;
        for (a, b) in AXIS_PAIRS {
            for (me, partner) in [(a, b), (b, a)] {
                let (Some(&d_me), Some(&d_partner), Some(&bit_me), Some(&bit_partner)) = (
                    delta_counts.get(me),
                    delta_counts.get(partner),
                    CHANNEL_BITS.get(me),
                    CHANNEL_BITS.get(partner),
                ) else {
                    continue;
                };
                let partner_turned_arcsec = f64::from(d_partner.unsigned_abs()) * weight_arcsec;
                if d_me == 0 && bad & bit_partner == 0 && partner_turned_arcsec >= PAIR_STUCK_ARCSEC
                {
                    health.stuck |= bit_me;
                    if let Some(u) = self.unchanged_cycles.get_mut(me) {
                        *u = (*u).max(table.stuck_cycles);
                    }
                }
            }
        }
        self.last = LastCycle {
            delta_counts,
            health,
            high_rate: sample.high_rate,
            has_delta: true,
        };
        output_for(&self.last, config, table)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::attitude::Quat;

    /// Pulse generator of one channel: emits a pulse each time the angle not yet pulsed
    /// exceeds the current weight (the fraction is carried across mode switches).
    #[derive(Default, Clone, Copy)]
    struct Channel {
        pulsed_rad: f64,
        counter: u16,
    }

    impl Channel {
        fn advance(&mut self, true_angle_rad: f64, weight_rad: f64) {
            let n = ((true_angle_rad - self.pulsed_rad) / weight_rad).floor();
            self.pulsed_rad += n * weight_rad;
            self.counter = self.counter.wrapping_add((n as i64) as u16);
        }
    }

    /// Simulated IRU under a constant body rate, with the channel input angles
    /// φ = diag(k)⁻¹ G⁻¹ θ so that the calibration in the table is exact.
    struct Sim {
        channels: [Channel; 6],
        ginv: Matrix3<f64>,
        k: [f64; 3],
        config: IruConfiguration,
    }

    impl Sim {
        fn new(table: &IruTable, config: IruConfiguration, start: [u16; 6]) -> Self {
            let mut channels = [Channel::default(); 6];
            for (c, s) in channels.iter_mut().zip(start) {
                c.counter = s;
            }
            Self {
                channels,
                ginv: config.g(table).try_inverse().unwrap(),
                k: config.scale_factors(table),
                config,
            }
        }
        fn sample(&mut self, theta_body: &Vector3<f64>, high: bool, table: &IruTable) -> IruSample {
            let phi = self.ginv * theta_body;
            let w = pulse_weight_rad(high, table);
            for (axis, ch) in self.config.channels().into_iter().enumerate() {
                self.channels[ch].advance(phi[axis] / self.k[axis], w);
            }
            let mut counts = [0u16; 6];
            for (c, ch) in counts.iter_mut().zip(self.channels.iter()) {
                *c = ch.counter;
            }
            IruSample {
                counts,
                channel_failed: 0,
                high_rate: high,
            }
        }
    }

    fn table_with_scale() -> IruTable {
        let mut t = IruTable::prelaunch();
        t.scale_factor_primary = [1.0002, 0.9997, 1.0001];
        // Keep the stuck detector out of the way of the pure-integration tests.
        t.stuck_cycles = 1000;
        t
    }

    /// Integrate a constant body rate for `cycles` 1-s cycles with the exact rotation-vector
    /// update (as the filter does) and check the attitude against the exact `Rot(ω t)`:
    ///
    /// * along the fixed rotation axis `e` the error telescopes to the final channel
    ///   remainders, each below one pulse of the final mode:
    ///   `|e·δθ| ≤ |eᵀ G diag(k)|₁ · w_final` — the rotation angle is exact to one pulse;
    /// * perpendicular to `e`, a pulse that lags while the body turns is reported about a
    ///   body axis that has moved on; this is bounded (it does not grow with time) by the
    ///   lag swing, `2 √3 ‖G diag(k)‖ w_max`, plus a random walk of `√n |ωΔt| w/√12`, far
    ///   smaller over these runs.
    ///
    /// Returns (|along|, along bound, |perp|, perp bound).
    fn run_constant_rate(
        rate: Vector3<f64>,
        cycles: u32,
        high_of: impl Fn(u32) -> bool,
    ) -> [f64; 4] {
        let table = table_with_scale();
        let cfg = IruConfiguration::Primary;
        let mut sim = Sim::new(&table, cfg, [65_000, 12, 40_000, 3, 65_535, 100]);
        let mut integ = IruIntegrator::new();
        let first = sim.sample(&Vector3::zeros(), high_of(0), &table);
        assert!(integ
            .process(&first, cfg, &table)
            .delta_theta_acs_rad
            .is_none());
        let mut q = Quat::IDENTITY;
        let mut w_final = 0.0;
        let mut w_max: f64 = 0.0;
        for k in 1..=cycles {
            let t = f64::from(k);
            let high = high_of(k);
            let s = sim.sample(&(rate * t), high, &table);
            let out = integ.process(&s, cfg, &table);
            let d = out.delta_theta_acs_rad.expect("usable");
            q = Quat::from_rotation_vector(&d).compose(&q).normalized();
            w_final = pulse_weight_rad(high, &table);
            w_max = w_max.max(w_final);
        }
        let truth = Quat::from_rotation_vector(&(rate * f64::from(cycles)));
        let err = crate::attitude::attitude_error_rad(&truth, &q);
        let e = rate.normalize();
        let gk = cfg.g(&table) * Matrix3::from_diagonal(&Vector3::from(cfg.scale_factors(&table)));
        let along_bound = (gk.transpose() * e).abs().sum() * w_final;
        let perp_bound = 2.0 * 3f64.sqrt() * gk.norm() * w_max;
        let along = e.dot(&err);
        [
            along.abs(),
            along_bound,
            (err - e * along).norm(),
            perp_bound,
        ]
    }

    fn assert_within(r: [f64; 4]) {
        let [along, along_bound, perp, perp_bound] = r;
        assert!(
            along <= along_bound,
            "along-axis error {along:e} > {along_bound:e}"
        );
        assert!(
            perp <= perp_bound,
            "cross-axis error {perp:e} > {perp_bound:e}"
        );
    }

    #[test]
    fn constant_rate_low_mode_for_four_hours_is_exact_to_one_pulse() {
        // 0.02 deg/s about a skew axis: 1440 pulses/s, the counters wrap every ~45 s.
        let rate = Vector3::new(0.6, -0.48, 0.64).normalize() * 0.02_f64.to_radians();
        assert_within(run_constant_rate(rate, 4 * 3600, |_| false));
    }

    #[test]
    fn constant_rate_high_mode_for_two_hours_is_exact_to_one_pulse() {
        // 0.1 deg/s: 720 deg in total.
        let rate = Vector3::new(-0.2, 0.9, 0.3).normalize() * 0.1_f64.to_radians();
        assert_within(run_constant_rate(rate, 2 * 3600, |_| true));
    }

    #[test]
    fn mode_switches_in_the_middle_of_a_slew_add_no_error() {
        // Switch every 600 s; end in low mode so the along-axis bound is one low-rate pulse.
        let rate = Vector3::new(0.3, 0.3, -0.9).normalize() * 0.05_f64.to_radians();
        let r = run_constant_rate(rate, 3000, |k| (k / 600) % 2 == 1 && k < 2400);
        assert!(r[1] < 2.0 * 0.05 * RAD_PER_ARCSEC);
        assert_within(r);
    }

    #[test]
    fn applying_the_new_mode_one_cycle_early_would_be_a_large_error() {
        // Negative control: the sample flag is what makes the switch exact.
        let table = table_with_scale();
        let cfg = IruConfiguration::Primary;
        let mut integ = IruIntegrator::new();
        let mut s = IruSample::default();
        integ.process(&s, cfg, &table);
        // 1000 low-rate pulses on X2, read with the high-rate weight:
        s.counts[1] = 1000;
        s.high_rate = true;
        let wrong = integ.process(&s, cfg, &table).delta_theta_acs_rad.unwrap();
        assert!((wrong.x - 1000.0 * 0.8 * 1.0002 * RAD_PER_ARCSEC).abs() < 1e-12);
    }

    /// A channel with the truth model's asymmetry (sim-harness `scale_asymmetry_ppm`: scale
    /// `1 + a sgn(rate)`) read through the table's `a`: both rotation senses come back to
    /// `a²` (1.6e-7 for 400 ppm) instead of `a` (4e-4).
    #[test]
    fn scale_asymmetry_corrects_both_rotation_senses() {
        let mut table = IruTable::prelaunch();
        table.scale_asymmetry_primary = [4.0e-4, -3.0e-4, 0.0];
        assert_eq!(table.validate(), Ok(()));
        let cfg = IruConfiguration::Primary;
        let plain = IruTable::prelaunch();
        let w = pulse_weight_rad(true, &table);
        for sign in [1.0, -1.0] {
            // True channel angles (X, Y, Z) and the pulses the asymmetric channels emit.
            let phi = Vector3::new(2.0e-2, -1.5e-2, 1.0e-2) * sign;
            let a = Vector3::new(4.0e-4, -3.0e-4, 0.0);
            let n = phi.zip_map(&a, |p: f64, a: f64| p * (1.0 + a * p.signum()) / w);
            let pulses = [n.x, n.y, n.z];
            let truth = cfg.g(&table) * phi;
            let corrected = delta_theta_from_pulses(&pulses, true, cfg, &table);
            let uncorrected = delta_theta_from_pulses(&pulses, true, cfg, &plain);
            assert!((corrected - truth).norm() < 2.0e-7 * phi.norm(), "{sign}");
            assert!((uncorrected - truth).norm() > 3.0e-4 * 1.0e-2);
        }
        // Zero count: no sign, no change; backup configuration untouched by the primary's a.
        let zero = delta_theta_from_pulses(&[0.0, 10.0, 0.0], false, cfg, &table);
        let zero_plain = delta_theta_from_pulses(&[0.0, 10.0, 0.0], false, cfg, &plain);
        assert!((zero - zero_plain * (1.0 + 3.0e-4)).norm() < 1e-20);
        assert_eq!(
            delta_theta_from_pulses(&[5.0, -7.0, 9.0], false, IruConfiguration::Backup, &table),
            delta_theta_from_pulses(&[5.0, -7.0, 9.0], false, IruConfiguration::Backup, &plain)
        );
    }

    #[test]
    fn counter_wrap_both_directions() {
        let table = IruTable::prelaunch();
        let cfg = IruConfiguration::Backup;
        let mut integ = IruIntegrator::new();
        let mut s = IruSample {
            counts: [65_530, 0, 0, 5, 0, 65_535],
            channel_failed: 0,
            high_rate: false,
        };
        integ.process(&s, cfg, &table);
        s.counts = [4, 1, 1, 65_530, 1, 9];
        let out = integ.process(&s, cfg, &table);
        assert_eq!(out.delta_counts, [10, 1, 1, -11, 1, 10]);
        assert_eq!(integ.totals_pulses(), [10, 1, 1, -11, 1, 10]);
        let d = out.delta_theta_acs_rad.unwrap();
        let expect = cfg.g(&table) * Vector3::new(10.0, -11.0, 10.0) * 0.05 * RAD_PER_ARCSEC;
        assert!((d - expect).norm() < 1e-15);
    }

    #[test]
    fn failed_saturated_and_stuck_channels_are_flagged_and_excluded() {
        let mut table = IruTable::prelaunch();
        table.stuck_cycles = 3;
        table.saturation_pulses_per_cycle = 1000;
        let cfg = IruConfiguration::Primary;
        let mut integ = IruIntegrator::new();
        let mut s = IruSample::default();
        integ.process(&s, cfg, &table);

        // Failed bit on Y1 (index 2): flagged, no increment.
        s.counts = [1, 1, 1, 1, 1, 1];
        s.channel_failed = CHANNEL_BITS[2];
        let out = integ.process(&s, cfg, &table);
        assert_eq!(out.health.failed, CHANNEL_BITS[2]);
        assert!(!out.selected_usable && out.delta_theta_acs_rad.is_none());
        // A failure on a backup channel does not affect the primary configuration.
        s.counts = [2, 2, 2, 2, 2, 2];
        s.channel_failed = CHANNEL_BITS[3];
        let out = integ.process(&s, cfg, &table);
        assert!(out.selected_usable && out.delta_theta_acs_rad.is_some());
        s.channel_failed = 0;

        // Saturation on Z1 (index 4): |ΔN| = 1001 > 1000.
        s.counts = [3, 3, 3, 3, 1003, 3];
        let out = integ.process(&s, cfg, &table);
        assert_eq!(out.health.saturated, CHANNEL_BITS[4]);
        assert!(out.delta_theta_acs_rad.is_none());
        // Exactly at the threshold is accepted.
        s.counts = [4, 4, 4, 4, 3, 4];
        let out = integ.process(&s, cfg, &table);
        assert_eq!(out.health.saturated, 0);
        assert!(out.delta_theta_acs_rad.is_some());

        // X2 (index 1) stops changing: stuck after 3 unchanged cycles, clears on change.
        let mut flagged_at = None;
        for k in 0..5u16 {
            s.counts = [5 + k, 4, 5 + k, 5 + k, 5 + k, 5 + k];
            let out = integ.process(&s, cfg, &table);
            if out.health.stuck != 0 && flagged_at.is_none() {
                flagged_at = Some(k);
                assert_eq!(out.health.stuck, CHANNEL_BITS[1]);
                assert!(out.delta_theta_acs_rad.is_none());
            }
        }
        assert_eq!(flagged_at, Some(2));
        s.counts = [20, 5, 20, 20, 20, 20];
        let out = integ.process(&s, cfg, &table);
        assert_eq!(out.health.stuck, 0);
        assert!(out.delta_theta_acs_rad.is_some());
    }

    #[test]
    fn reprocess_switches_to_backup_on_the_same_interval() {
        let table = IruTable::prelaunch();
        let mut integ = IruIntegrator::new();
        let mut s = IruSample::default();
        integ.process(&s, IruConfiguration::Primary, &table);
        s.counts = [10, 20, 30, 40, 50, 60];
        s.channel_failed = CHANNEL_BITS[1];
        let out = integ.process(&s, IruConfiguration::Primary, &table);
        assert!(!out.selected_usable);
        assert_eq!(integ.excluded_mask(), CHANNEL_BITS[1]);
        assert_eq!(integ.exclusion_reason(1), EXCLUDED_FAILED);
        assert_eq!(integ.exclusion_reason(0), 0);
        assert_eq!(integ.exclusion_reason(99), 0);
        let backup = integ.reprocess(IruConfiguration::Backup, &table);
        let expect = IruConfiguration::Backup.g(&table)
            * Vector3::new(10.0, 40.0, 60.0)
            * (0.05 * RAD_PER_ARCSEC);
        assert!((backup.delta_theta_acs_rad.unwrap() - expect).norm() < 1e-15);
        assert_eq!(IruConfiguration::Backup.code(), 1);
    }

    #[test]
    fn reset_restarts_without_an_increment() {
        let table = IruTable::prelaunch();
        let mut integ = IruIntegrator::new();
        let s = IruSample::default();
        let first = integ.process(&s, IruConfiguration::Primary, &table);
        assert!(first.selected_usable && first.delta_theta_acs_rad.is_none());
        assert!(integ.is_initialized());
        integ.reset();
        let out = integ.process(&s, IruConfiguration::Primary, &table);
        assert!(out.delta_theta_acs_rad.is_none());
    }

    /// A channel that does not move while its partner on the same axis turns ≥ 20″ is stuck
    /// at once (no built-in-test bit needed), stays excluded while it does not move, and is
    /// usable again when it counts; a small partner increment (low rate, bias level) does not
    /// trip the check.
    #[test]
    fn pair_cross_check_finds_a_silently_stuck_channel_at_once() {
        let table = IruTable::prelaunch();
        let mut integ = IruIntegrator::new();
        let mut counts = [100_u16; IRU_CHANNELS];
        let sample = |counts: [u16; IRU_CHANNELS], high_rate: bool| IruSample {
            counts,
            channel_failed: 0,
            high_rate,
        };
        let _ = integ.process(&sample(counts, false), IruConfiguration::Primary, &table);
        // Low rate, Y2 moves 5 pulses (0.25″), Y1 not: within bias differences, usable.
        counts[3] = counts[3].wrapping_add(5);
        let out = integ.process(&sample(counts, false), IruConfiguration::Primary, &table);
        assert_eq!(out.health.stuck, 0);
        assert!(out.selected_usable);
        // High rate, every channel but Y1 turns 300 pulses (240″): Y1 (bit 2) stuck now.
        for (i, c) in counts.iter_mut().enumerate() {
            if i != 2 {
                *c = c.wrapping_add(300);
            }
        }
        let out = integ.process(&sample(counts, true), IruConfiguration::Primary, &table);
        assert_eq!(out.health.stuck, 0x04);
        assert!(!out.selected_usable);
        assert_eq!(integ.exclusion_reason(2), EXCLUDED_STUCK);
        assert!(
            integ
                .reprocess(IruConfiguration::Backup, &table)
                .selected_usable
        );
        // The slew ends: nothing moves, Y1 stays excluded (latched).
        let out = integ.process(&sample(counts, false), IruConfiguration::Primary, &table);
        assert_eq!(out.health.stuck & 0x04, 0x04);
        // Y1 counts again: usable.
        counts[2] = counts[2].wrapping_add(7);
        let out = integ.process(&sample(counts, false), IruConfiguration::Primary, &table);
        assert_eq!(out.health.stuck & 0x04, 0);
        // A saturated partner does not condemn a healthy channel.
        let mut t2 = table;
        t2.saturation_pulses_per_cycle = 100;
        counts[3] = counts[3].wrapping_add(300);
        let out = integ.process(&sample(counts, true), IruConfiguration::Primary, &t2);
        assert_eq!(out.health.saturated & 0x08, 0x08);
        assert_eq!(out.health.stuck & 0x04, 0);
    }
}
