//! # Momentum unloading with the magnetic torquer bars (issue 20)
//!
//! Why: in an inertial hold the gravity gradient has a secular part (≈ 0.05 N·m for this
//! spacecraft in `normal-ops`) that the wheels absorb until they saturate (250 N·m·s within
//! hours). GRO dumped that momentum with magnetic torquer bars: the only external torque an
//! observatory without thrusters in routine use has. Phase 7c of
//! [`crate::executive::FlightCore::step`] runs this module every cycle.
//!
//! ## The law (cross product)
//! `m = k (h × B) / |B|²` (A·m²; `h` the momentum to unload in ACS, N·m·s; `B` the field in
//! ACS, tesla; `k` the table gain, 1/s). The torque on the spacecraft is
//! `τ = m × B = (k/|B|²)(h × B) × B = −k (h − (h·B̂)B̂) = −k h⊥`: it removes the part of `h`
//! perpendicular to the field at the rate `k` and cannot touch the part along it, which the
//! field's turning over the orbit brings into reach later. Markley & Crassidis,
//! *Fundamentals of Spacecraft Attitude Determination and Control* (2014), ch. 7 (momentum
//! management); Sidi, *Spacecraft Dynamics and Control* (1997), ch. 7 (magnetic unloading).
//!
//! * **Saturation per bar**: the bars are on the ACS axes; when any bar's share exceeds the
//!   table's `torquer_dipole_limit_am2` the whole vector is scaled down, so the torque stays
//!   along `−h⊥` (clipping bars one at a time would turn it).
//! * **Dead band with hysteresis**: unloading starts when `|h|` exceeds
//!   `unloading_start_nms` and stops below `unloading_stop_nms`: the orbit's cyclic
//!   gravity-gradient momentum (tens of N·m·s) is stored by the wheels, not dumped.
//! * **What `h` is**: the system momentum, the wheels' `h_w` plus the body's `J ω̂` (filter
//!   table inertia), so the momentum of a slew, which goes back into the wheels at its end, is
//!   not dumped. `h_w` comes from the **wheel tachometers** (`docs/icd.md` §3.6, format
//!   version 4): `h_w = Σ a_i J_s ω_i` with Table 6's spin axes `a_i` and rotor inertia `J_s`
//!   ([`wheel_momentum_from_tachometers`]), whenever every wheel of the table reads valid.
//!   Otherwise (no tachometer words, a wheel's word invalid or saturated, no geometry in the
//!   table) the OBC falls back to counting its own torque commands from the last tachometer
//!   value (`h_w -= τ_cmd dt`). That count is exact only while the wheels deliver the command:
//!   on a torque-limited slew the four wheels clip at their own limit (0.4 N·m each in the
//!   truth) while the command is limited per ACS axis (0.5 N·m), and the count drifted 54.6
//!   N·m·s over the main job's nine slews (`docs/magnetics.md` §7). Every change of source is
//!   an event (0x0A03), so a count that can drift is never silent.
//!
//! ## The field, and the TAMs while the bars are on (blanking)
//! A bar's own field at the TAMs (≈ 0.1 mG per A·m², tens of mG at the rating) is as large as
//! the errors the coarse attitude cares about. The OBC **blanks** rather than subtracts: the
//! bars are commanded off for the one cycle before each TAM sample it uses (the coarse fix
//! cycles, every `coarse_fix_every_n_cycles`), so that sample sees no bar field; the dipole is
//! recomputed from it and held for the other cycles (90 % duty with a fix every 10 cycles).
//! Why blanking: it needs no knowledge of the bar-to-TAM coupling (a subtraction is only as
//! good as the coupling matrix, and a wrong matrix or a bar not delivering its command — the
//! stuck bar below — would corrupt every TAM sample, and with it the coarse attitude);
//! the price is 10 % of the unloading authority and a dipole 10 s old.
//!
//! Field source for the law, on each blanked sample: TAM1, else TAM2 (Table 6 calibration,
//! [`crate::coarse::tam_field_acs_milligauss`], magnitude 50–1,000 mG), else the onboard field
//! model ([`crate::field_model`]) at the onboard orbit turned to ACS with the fine attitude;
//! none: bars off.
//!
//! ## The bars-off check (a bar stuck on)
//! On each blanked sample, with a field model, a valid onboard orbit and an initialised
//! filter, each TAM's field is compared with the model's: a difference above
//! `torquer_check_milligauss` on [`CHECK_CONSECUTIVE`] samples in a row is an unexpected
//! field at the TAM while every bar is commanded off — a bar stuck on (both TAMs see it) or a
//! TAM fault (one does). Event 0x0A01 (p1 = TAMs that see it, bit 0 TAM1, bit 1 TAM2; p2 =
//! the difference, 0.1 mG); while it lasts the law uses the model field.
//!
//! Deterministic, allocation-free, constant work per cycle (one field synthesis on a blanked
//! sample when the check or the model path needs it).

use nalgebra::Vector3;

/// Number of torquer bars (on the ACS x, y, z axes).
/// Project choice (not in the paper): three orthogonal bars, as the truth's default.
pub const BARS: usize = 3;
/// Tesla per milligauss (1 G = 1e-4 T).
/// SI definition of the gauss; docs/magnetics.md §2 (1 mG = 100 nT).
pub const TESLA_PER_MILLIGAUSS: f64 = 1.0e-7;
/// Smallest field the law divides by, tesla (10 mG; the field at GRO's altitude is
/// 250–450 mG): a weaker one is a failed sensor, not the Earth.
/// Project choice (not in the paper): guards the division by `|B|²`.
pub const MIN_FIELD_TESLA: f64 = 1.0e-6;
/// TAM fields the law accepts, mG (the Earth's at 450 km is 250–450 mG).
/// Project choice (not in the paper): a dead or saturated TAM is not the field.
pub const TAM_PLAUSIBLE_MILLIGAUSS: (f64, f64) = (50.0, 1_000.0);
/// Consecutive blanked samples over the check threshold before event 0x0A01.
/// Project choice (not in the paper): one noisy sample is not a fault.
pub const CHECK_CONSECUTIVE: u8 = 3;
/// Largest wheel momentum the OBC's count holds, N·m·s (4 × the 250-N·m·s wheel limit): a
/// bound that keeps the count finite whatever the commands were.
/// Project choice (not in the paper): bounds the estimate.
pub const MAX_MOMENTUM_NMS: f64 = 1_000.0;

/// Where the OBC's wheel momentum comes from (module doc).
/// docs/icd.md §3.3 (event 0x0A03); docs/magnetics.md §7.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MomentumSource {
    /// Counted from the OBC's own wheel torque commands (no usable tachometers).
    /// docs/magnetics.md §7.
    #[default]
    CommandCount,
    /// Measured by every wheel's tachometer this cycle.
    /// docs/icd.md §3.6.
    Tachometers,
    /// Measured by some wheels' tachometers; each wheel without one carried on from its last
    /// value with its share of the torque command (minimum-norm allocation over Table 6's
    /// wheels).
    /// docs/magnetics.md §7.
    PartialTachometers,
}

impl MomentumSource {
    /// The code of event 0x0A03's p1: 0 count, 1 tachometers, 2 partly.
    /// docs/icd.md §3.3.
    #[must_use]
    pub const fn code(self) -> u32 {
        match self {
            Self::CommandCount => 0,
            Self::Tachometers => 1,
            Self::PartialTachometers => 2,
        }
    }
}

/// Radians per second per tachometer count (0.1 rpm).
const RAD_PER_S_PER_COUNT: f64 = crate::raw::WHEEL_RPM_PER_COUNT * core::f64::consts::TAU / 60.0;

/// The wheels' momentum in ACS from the tachometers, `Σ a_i J_s ω_i` (N·m·s), when the table
/// gives a geometry and every wheel in it has a valid, unsaturated word; `None` otherwise.
/// Module doc; docs/icd.md §3.6; docs/tables.md (Table 6, fields 24–25).
#[must_use]
pub fn wheel_momentum_from_tachometers(
    sample: &crate::raw::WheelSample,
    table: &crate::tables::MagneticsTable,
) -> Option<Vector3<f64>> {
    if !table.has_wheel_geometry() {
        return None;
    }
    let mut h = Vector3::zeros();
    for (i, axis) in table.wheel_spin_axes_acs.iter().enumerate() {
        if axis.iter().all(|x| *x == 0.0) {
            continue;
        }
        let h_wheel = tachometer_nms(sample, table, i)?;
        h += Vector3::new(axis[0], axis[1], axis[2]) * h_wheel;
    }
    h.iter().all(|x| x.is_finite()).then_some(h)
}

/// Wheel `i`'s momentum along its spin axis from its tachometer, N·m·s: `None` when the
/// word is invalid or saturated (±32,767 and −32,768, docs/icd.md §3.6).
fn tachometer_nms(
    sample: &crate::raw::WheelSample,
    table: &crate::tables::MagneticsTable,
    i: usize,
) -> Option<f64> {
    let counts = *sample.speed_counts.get(i)?;
    let valid = i < 8 && sample.speed_valid & (1u8 << i) != 0;
    (valid && counts.unsigned_abs() < i16::MAX.unsigned_abs())
        .then(|| table.wheel_spin_inertia_kg_m2 * f64::from(counts) * RAD_PER_S_PER_COUNT)
}

/// Each wheel's share of the ACS torque `τ` (N·m) under the minimum-norm allocation over the
/// table's wheels, `W⁺ τ = Wᵀ (W Wᵀ)⁻¹ τ`: what each wheel is driven with when the command is
/// met. `None` without a geometry (the table validation keeps `W Wᵀ` invertible otherwise).
/// Minimum-norm allocation (Markley & Crassidis 2014, ch. 7, reaction wheels); module doc.
#[must_use]
pub fn wheel_torque_shares_nm(
    table: &crate::tables::MagneticsTable,
    torque_acs_nm: &Vector3<f64>,
) -> Option<[f64; crate::raw::WHEELS]> {
    let mut gram = nalgebra::Matrix3::zeros();
    for a in &table.wheel_spin_axes_acs {
        let v = Vector3::new(a[0], a[1], a[2]);
        gram += v * v.transpose();
    }
    let g = gram.try_inverse()? * torque_acs_nm;
    let shares = table
        .wheel_spin_axes_acs
        .map(|a| a[0] * g.x + a[1] * g.y + a[2] * g.z);
    shares.iter().all(|x| x.is_finite()).then_some(shares)
}

/// Why the law gave no dipole.
/// Project choice (not in the paper): typed errors instead of panics in the flight core.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum UnloadingError {
    /// Momentum not finite.
    /// Project choice (not in the paper): NaN input is refused.
    InvalidMomentum,
    /// Field not finite or weaker than [`MIN_FIELD_TESLA`].
    /// Project choice (not in the paper): see [`MIN_FIELD_TESLA`].
    InvalidField,
    /// Gain or dipole limit negative or not finite.
    /// docs/tables.md (Table 6, fields 19–20).
    InvalidTable,
}

/// The cross-product law's dipole (module doc), saturated per bar.
/// Markley & Crassidis (2014) ch. 7 (momentum management).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Dipole {
    /// Commanded dipole per bar (ACS axes), A·m².
    /// docs/magnetics.md §7.
    pub dipole_acs_am2: [f64; BARS],
    /// The vector was scaled down to the bars' limit.
    /// docs/magnetics.md §7.
    pub saturated: bool,
}

/// `m = k (h × B)/|B|²`, scaled down as a whole so that no bar exceeds `limit_am2`.
/// Markley & Crassidis (2014) ch. 7 (cross-product law); module doc.
///
/// # Errors
/// [`UnloadingError`] for a non-finite momentum, a non-finite or too weak field, or a
/// negative or non-finite gain or limit.
pub fn cross_product_dipole(
    h_excess_acs_nms: &Vector3<f64>,
    b_acs_tesla: &Vector3<f64>,
    gain_per_s: f64,
    limit_am2: f64,
) -> Result<Dipole, UnloadingError> {
    if !(gain_per_s.is_finite() && gain_per_s >= 0.0 && limit_am2.is_finite() && limit_am2 >= 0.0) {
        return Err(UnloadingError::InvalidTable);
    }
    if !h_excess_acs_nms.iter().all(|x| x.is_finite()) {
        return Err(UnloadingError::InvalidMomentum);
    }
    let b2 = b_acs_tesla.norm_squared();
    if !(b2.is_finite() && b2 >= MIN_FIELD_TESLA * MIN_FIELD_TESLA) {
        return Err(UnloadingError::InvalidField);
    }
    let mut m = h_excess_acs_nms.cross(b_acs_tesla) * (gain_per_s / b2);
    let peak = m.amax();
    let saturated = peak > limit_am2;
    if saturated {
        m *= limit_am2 / peak;
    }
    if !m.iter().all(|x| x.is_finite()) {
        return Err(UnloadingError::InvalidMomentum);
    }
    Ok(Dipole {
        dipole_acs_am2: [m.x, m.y, m.z],
        saturated,
    })
}

/// What one blanked TAM sample gave the unloading (the executive fills it).
/// docs/magnetics.md §7.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FieldSample {
    /// TAM1, TAM2 fields in ACS (Table 6 calibration), mG, when valid and plausible.
    /// docs/magnetics.md §7.
    pub tam_acs_milligauss: [Option<Vector3<f64>>; 2],
    /// The onboard model field in ACS at the fine attitude, mG, when available.
    /// docs/magnetics.md §5, §7.
    pub model_acs_milligauss: Option<Vector3<f64>>,
    /// 1σ of the model field's error from the fine attitude's uncertainty, mG
    /// (`|B| σ_θ`, σ_θ the largest attitude σ of the filter): the bars-off check's threshold
    /// grows by 3 of these, so that an uncertain attitude is not taken for a stuck bar.
    /// docs/magnetics.md §7.
    pub model_sigma_milligauss: f64,
}

/// What the unloading reports for events (the executive raises them).
/// docs/icd.md §3.3 (events 0x0A01, 0x0A02).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct UnloadingReport {
    /// Unloading started (`Some(true)`) or stopped (`Some(false)`) this cycle; p2 = `|h|`.
    /// docs/icd.md §3.3 (event 0x0A02).
    pub state_changed: Option<bool>,
    /// The bars-off check has just failed [`CHECK_CONSECUTIVE`] times: (TAM mask, 0.1 mG).
    /// docs/icd.md §3.3 (event 0x0A01).
    pub unexpected_field: Option<(u32, u32)>,
}

/// The OBC's momentum-unloading state (module doc).
/// Project choice (not in the paper): the paper does not describe the OBC's unloading.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MomentumUnloading {
    /// The wheels' momentum (ACS, N·m·s): the tachometers', else the command count.
    wheel_momentum_acs_nms: Vector3<f64>,
    /// Where `wheel_momentum_acs_nms` came from this cycle.
    source: MomentumSource,
    /// Each wheel's momentum along its axis, N·m·s: measured, or carried on with its share of
    /// the commands while its tachometer is out (kept only while some tachometer is out).
    wheel_nms: [f64; crate::raw::WHEELS],
    /// The last frame in which every wheel read its tachometer (`wheel_nms` starts from it
    /// when one goes out).
    last_full: crate::raw::WheelSample,
    /// A source has been reported (event 0x0A03) since boot.
    source_reported: bool,
    /// Unloading (outside the dead band).
    active: bool,
    /// The dipole computed at the last blanked sample (ACS, A·m²).
    hold_acs_am2: [f64; BARS],
    /// The command going out this cycle (ACS, A·m²), in effect until the next cycle.
    command_acs_am2: [f64; BARS],
    /// The bars were blanked for the coming interval: the next frame is a sample.
    sample_next: bool,
    /// Consecutive blanked samples over the check threshold.
    check_failures: u8,
    /// The check has failed (event raised; the law uses the model field).
    field_unexpected: bool,
    /// `|h|` at the last blanked sample, N·m·s.
    last_momentum_nms: f64,
}

impl MomentumUnloading {
    /// Bars off, wheels counted from rest.
    /// docs/magnetics.md §7.
    #[must_use]
    pub const fn new() -> Self {
        Self {
            wheel_momentum_acs_nms: Vector3::new(0.0, 0.0, 0.0),
            source: MomentumSource::CommandCount,
            wheel_nms: [0.0; crate::raw::WHEELS],
            last_full: crate::raw::WheelSample {
                speed_counts: [0; crate::raw::WHEELS],
                speed_valid: 0,
                dipole_counts: [0; crate::raw::TORQUER_MONITORS],
                dipole_valid: 0,
            },
            source_reported: false,
            active: false,
            hold_acs_am2: [0.0; BARS],
            command_acs_am2: [0.0; BARS],
            sample_next: true,
            check_failures: 0,
            field_unexpected: false,
            last_momentum_nms: 0.0,
        }
    }

    /// The dipole command for the coming interval, per bar (ACS axes), A·m².
    /// docs/magnetics.md §7.
    #[must_use]
    pub const fn command_acs_am2(&self) -> [f64; BARS] {
        self.command_acs_am2
    }

    /// Whether every bar is commanded off (the TAM sample of the next frame is clean).
    /// docs/magnetics.md §7 (blanking).
    #[must_use]
    pub fn bars_off(&self) -> bool {
        self.command_acs_am2.iter().all(|m| *m == 0.0)
    }

    /// Whether this cycle's frame is a blanked sample: the bars were commanded off for it
    /// because a coarse fix was due (the first cycle too). Only these frames are read, also
    /// in the dead band, so that the field work is done once per fix interval.
    /// docs/magnetics.md §7 (blanking).
    #[must_use]
    pub fn sample_due(&self) -> bool {
        self.sample_next && self.bars_off()
    }

    /// Unloading outside the dead band.
    /// docs/magnetics.md §7.
    #[must_use]
    pub const fn active(&self) -> bool {
        self.active
    }

    /// The bars-off check has failed (module doc).
    /// docs/icd.md §3.3 (event 0x0A01).
    #[must_use]
    pub const fn field_unexpected(&self) -> bool {
        self.field_unexpected
    }

    /// The OBC's wheel momentum (ACS, N·m·s): measured or counted ([`Self::source`]).
    /// docs/magnetics.md §7.
    #[must_use]
    pub const fn wheel_momentum_acs_nms(&self) -> Vector3<f64> {
        self.wheel_momentum_acs_nms
    }

    /// Where the wheel momentum came from this cycle.
    /// docs/magnetics.md §7.
    #[must_use]
    pub const fn source(&self) -> MomentumSource {
        self.source
    }

    /// This frame's wheel momentum: the tachometers when they all read
    /// ([`wheel_momentum_from_tachometers`]), else the count of the previous cycle's torque
    /// command from the last value ([`Self::account_wheel_torque`]). Returns the new source
    /// when it changed (event 0x0A03), and the count on the first frame whose tachometer words
    /// cannot be used (so that counting from boot is not silent). A measured momentum above
    /// [`MAX_MOMENTUM_NMS`] (a wrong inertia in the table) is not used either.
    /// Module doc; docs/magnetics.md §7.
    pub fn update_wheel_momentum(
        &mut self,
        sample: &crate::raw::WheelSample,
        torque_cmd_acs_nm: &Vector3<f64>,
        dt_s: f64,
        table: &crate::tables::MagneticsTable,
    ) -> Option<MomentumSource> {
        let words = if sample.speed_valid == 0 {
            None // no tachometer words (a spacecraft without them): straight to the count
        } else {
            wheel_momentum_from_tachometers(sample, table)
        };
        let source = match words {
            Some(h) if h.norm() <= MAX_MOMENTUM_NMS => {
                self.wheel_momentum_acs_nms = h;
                self.last_full = *sample;
                MomentumSource::Tachometers
            }
            _ => match self.partial_wheel_momentum(sample, torque_cmd_acs_nm, dt_s, table) {
                Some(h) => {
                    self.wheel_momentum_acs_nms = h;
                    MomentumSource::PartialTachometers
                }
                None => {
                    self.account_wheel_torque(torque_cmd_acs_nm, dt_s);
                    MomentumSource::CommandCount
                }
            },
        };
        // A change is reported; so is the count on the first frame that carries tachometer
        // words it cannot use (a wheel invalid from boot, no geometry in the table), which
        // would otherwise start counting in silence.
        let first_unusable = !self.source_reported
            && sample.speed_valid != 0
            && source == MomentumSource::CommandCount;
        let changed = source != self.source || first_unusable;
        self.source = source;
        self.source_reported |= changed;
        changed.then_some(source)
    }

    /// Some of the table's wheels read their tachometers, not all: those are measured, the
    /// others carried on from their last value with their share of the previous command
    /// (`h_i −= [W⁺ τ]_i dt`). `None` when no wheel reads, without a geometry, or for a
    /// non-finite or out-of-bound result (the whole count then takes over).
    fn partial_wheel_momentum(
        &mut self,
        sample: &crate::raw::WheelSample,
        torque_cmd_acs_nm: &Vector3<f64>,
        dt_s: f64,
        table: &crate::tables::MagneticsTable,
    ) -> Option<Vector3<f64>> {
        if sample.speed_valid == 0 {
            return None;
        }
        let any_reads = (0..crate::raw::WHEELS).any(|i| tachometer_nms(sample, table, i).is_some());
        if !(any_reads && table.has_wheel_geometry() && dt_s.is_finite()) {
            return None;
        }
        let shares = wheel_torque_shares_nm(table, torque_cmd_acs_nm)?;
        let mut next = self.wheel_nms;
        if self.source == MomentumSource::Tachometers {
            // Coming from a frame where every wheel read: start from it.
            for (i, slot) in next.iter_mut().enumerate() {
                *slot = tachometer_nms(&self.last_full, table, i).unwrap_or(0.0);
            }
        }
        let mut measured = 0usize;
        let mut h = Vector3::zeros();
        for (i, ((slot, a), share)) in next
            .iter_mut()
            .zip(&table.wheel_spin_axes_acs)
            .zip(shares)
            .enumerate()
        {
            if a.iter().all(|x| *x == 0.0) {
                *slot = 0.0;
                continue;
            }
            match tachometer_nms(sample, table, i) {
                Some(h_i) => {
                    *slot = h_i;
                    measured = measured.saturating_add(1);
                }
                None => *slot -= share * dt_s,
            }
            h += Vector3::new(a[0], a[1], a[2]) * *slot;
        }
        let ok = measured > 0 && h.iter().all(|x| x.is_finite()) && h.norm() <= MAX_MOMENTUM_NMS;
        ok.then(|| {
            self.wheel_nms = next;
            h
        })
    }

    /// Count the previous cycle's wheel torque command (held over `dt_s`): the wheels take
    /// `−τ dt`. Non-finite input is ignored; the count is bounded by [`MAX_MOMENTUM_NMS`].
    /// docs/magnetics.md §7.
    pub fn account_wheel_torque(&mut self, torque_cmd_acs_nm: &Vector3<f64>, dt_s: f64) {
        let dh = torque_cmd_acs_nm * dt_s;
        if !(dt_s.is_finite() && dh.iter().all(|x| x.is_finite())) {
            return;
        }
        let h = self.wheel_momentum_acs_nms - dh;
        let n = h.norm();
        self.wheel_momentum_acs_nms = if n > MAX_MOMENTUM_NMS {
            h * (MAX_MOMENTUM_NMS / n)
        } else {
            h
        };
    }

    /// Bars off and the state cleared (no table unloading, control idle).
    /// docs/magnetics.md §7.
    pub fn switch_off(&mut self) {
        self.active = false;
        self.hold_acs_am2 = [0.0; BARS];
        self.command_acs_am2 = [0.0; BARS];
        self.sample_next = true;
    }

    /// One cycle. `sample`: the field of this frame when the bars were off during it
    /// (`None` otherwise: the dipole computed at the last blanked sample is held);
    /// `h_system_acs_nms`: the momentum to unload; `blank_next`: the next frame's TAM sample
    /// is used (the bars are then commanded off for the coming interval).
    /// Module doc; Markley & Crassidis (2014) ch. 7.
    pub fn update(
        &mut self,
        sample: Option<&FieldSample>,
        h_system_acs_nms: &Vector3<f64>,
        table: &crate::tables::MagneticsTable,
        blank_next: bool,
    ) -> UnloadingReport {
        let mut report = UnloadingReport::default();
        if let Some(s) = sample {
            report.unexpected_field = self.check(s, table);
            let field = if self.field_unexpected {
                s.model_acs_milligauss
            } else {
                s.tam_acs_milligauss
                    .iter()
                    .flatten()
                    .next()
                    .copied()
                    .or(s.model_acs_milligauss)
            };
            let h = h_system_acs_nms.norm();
            if h.is_finite() {
                self.last_momentum_nms = h;
                let was = self.active;
                if self.active && h < table.unloading_stop_nms {
                    self.active = false;
                } else if !self.active && h > table.unloading_start_nms {
                    self.active = true;
                }
                if was != self.active {
                    report.state_changed = Some(self.active);
                }
            }
            self.hold_acs_am2 = match (self.active, field) {
                (true, Some(b_mg)) => cross_product_dipole(
                    h_system_acs_nms,
                    &(b_mg * TESLA_PER_MILLIGAUSS),
                    table.unloading_gain_per_s,
                    table.torquer_dipole_limit_am2,
                )
                .map_or([0.0; BARS], |d| d.dipole_acs_am2),
                _ => [0.0; BARS],
            };
        }
        self.command_acs_am2 = if blank_next {
            [0.0; BARS]
        } else {
            self.hold_acs_am2
        };
        self.sample_next = blank_next;
        report
    }

    /// `|h|` at the last blanked sample, N·m·s (event 0x0A02 p2).
    /// docs/icd.md §3.3 (event 0x0A02).
    #[must_use]
    pub const fn last_momentum_nms(&self) -> f64 {
        self.last_momentum_nms
    }

    /// The bars-off check (module doc): each TAM against the model field.
    fn check(
        &mut self,
        s: &FieldSample,
        table: &crate::tables::MagneticsTable,
    ) -> Option<(u32, u32)> {
        let model = s.model_acs_milligauss?;
        let sigma = if s.model_sigma_milligauss.is_finite() {
            s.model_sigma_milligauss.max(0.0)
        } else {
            return None;
        };
        if 3.0 * sigma >= table.torquer_check_milligauss {
            // The attitude is too uncertain for the model field to tell a bar's field from
            // its own error: no evidence either way (a raised alarm stays raised).
            return None;
        }
        let limit = table.torquer_check_milligauss + 3.0 * sigma;
        let mut mask = 0u32;
        let mut worst = 0.0_f64;
        let mut compared = false;
        for (bit, tam) in [1u32, 2].iter().zip(s.tam_acs_milligauss.iter()) {
            if let Some(b) = tam {
                compared = true;
                let d = (b - model).norm();
                if d > limit {
                    mask |= bit;
                    worst = worst.max(d);
                }
            }
        }
        if !compared {
            // No TAM to compare: no evidence either way; the run of failures and the state
            // stay as they were (a failed TAM must not re-arm the check).
            return None;
        }
        if mask == 0 {
            self.check_failures = 0;
            self.field_unexpected = false;
            return None;
        }
        self.check_failures = self.check_failures.saturating_add(1);
        if self.check_failures >= CHECK_CONSECUTIVE && !self.field_unexpected {
            self.field_unexpected = true;
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let tenths = (worst * 10.0).clamp(0.0, 4.0e9) as u32;
            return Some((mask, tenths));
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tables::MagneticsTable;

    fn torque(d: &Dipole, b: &Vector3<f64>) -> Vector3<f64> {
        Vector3::from(d.dipole_acs_am2).cross(b)
    }

    /// The torque `m × B` is perpendicular to `B` and equals `−k h⊥` when no bar
    /// saturates: it removes the momentum perpendicular to the field and leaves the part
    /// along it.
    #[test]
    fn torque_is_perpendicular_to_b_and_reduces_the_perpendicular_momentum() {
        let b = Vector3::new(12.0e-6, -25.0e-6, 18.0e-6);
        let h = Vector3::new(30.0, 5.0, -12.0);
        let k = 1.0e-3;
        let d = cross_product_dipole(&h, &b, k, 1.0e6).unwrap();
        assert!(!d.saturated);
        let tau = torque(&d, &b);
        assert!(tau.dot(&b).abs() < 1e-12 * tau.norm() * b.norm());
        let bh = b.normalize();
        let h_perp = h - bh * h.dot(&bh);
        assert!((tau + h_perp * k).norm() < 1e-12 * h.norm() * k, "{tau}");
        // Integrating Ḣ = τ for 100 s at the fixed field: |h⊥| falls as exp(−k t), h∥ stays.
        let mut hh = h;
        for _ in 0..100 {
            let d = cross_product_dipole(&hh, &b, k, 1.0e6).unwrap();
            hh += torque(&d, &b);
        }
        let perp = |v: Vector3<f64>| (v - bh * v.dot(&bh)).norm();
        assert!(perp(hh) < perp(h) * (-0.099_f64).exp());
        assert!((hh.dot(&bh) - h.dot(&bh)).abs() < 1e-9);
    }

    /// Over the limit the whole vector is scaled: the largest bar sits at the limit, the
    /// direction (and so the torque's direction) is kept.
    #[test]
    fn saturation_scales_the_whole_dipole() {
        let b = Vector3::new(0.0, 30.0e-6, 10.0e-6);
        let h = Vector3::new(200.0, 0.0, 40.0);
        let free = cross_product_dipole(&h, &b, 1.0e-2, 1.0e9).unwrap();
        let d = cross_product_dipole(&h, &b, 1.0e-2, 400.0).unwrap();
        assert!(d.saturated);
        let m = Vector3::from(d.dipole_acs_am2);
        assert!((m.amax() - 400.0).abs() < 1e-9);
        let mf = Vector3::from(free.dipole_acs_am2);
        assert!(m.normalize().dot(&mf.normalize()) > 1.0 - 1e-12);
        // Still against the perpendicular momentum.
        assert!(torque(&d, &b).dot(&h) < 0.0);
    }

    #[test]
    fn invalid_inputs_are_refused() {
        let b = Vector3::new(0.0, 30.0e-6, 0.0);
        let h = Vector3::new(1.0, 0.0, 0.0);
        let nan = Vector3::new(f64::NAN, 0.0, 0.0);
        assert_eq!(
            cross_product_dipole(&nan, &b, 1e-3, 1e3),
            Err(UnloadingError::InvalidMomentum)
        );
        assert_eq!(
            cross_product_dipole(&h, &nan, 1e-3, 1e3),
            Err(UnloadingError::InvalidField)
        );
        assert_eq!(
            cross_product_dipole(&h, &(b * 1e-3), 1e-3, 1e3),
            Err(UnloadingError::InvalidField)
        );
        assert_eq!(
            cross_product_dipole(&h, &b, -1.0, 1e3),
            Err(UnloadingError::InvalidTable)
        );
        assert_eq!(
            cross_product_dipole(&h, &b, 1e-3, f64::INFINITY),
            Err(UnloadingError::InvalidTable)
        );
    }

    /// The dead band with hysteresis, the hold between blanked samples and the blank.
    #[test]
    #[allow(clippy::float_cmp)] // a held command is the same bits
    fn dead_band_hold_and_blank() {
        let t = MagneticsTable::boot();
        let mut u = MomentumUnloading::new();
        let b = Vector3::new(0.0, 300.0, 100.0);
        let s = FieldSample {
            tam_acs_milligauss: [Some(b), None],
            model_acs_milligauss: None,
            model_sigma_milligauss: 0.0,
        };
        let small = Vector3::new(t.unloading_start_nms * 0.9, 0.0, 0.0);
        let r = u.update(Some(&s), &small, &t, false);
        assert_eq!(r.state_changed, None);
        assert!(u.bars_off());
        let big = Vector3::new(t.unloading_start_nms * 1.5, 0.0, 0.0);
        let r = u.update(Some(&s), &big, &t, false);
        assert_eq!(r.state_changed, Some(true));
        assert!(!u.bars_off());
        let held = u.command_acs_am2();
        // Between samples the dipole is held; the cycle before a sample blanks the bars.
        u.update(None, &small, &t, false);
        assert_eq!(u.command_acs_am2(), held);
        u.update(None, &small, &t, true);
        assert!(u.bars_off());
        // Inside the hysteresis band it keeps unloading; below the stop it stops.
        let mid = Vector3::new(
            0.5 * (t.unloading_start_nms + t.unloading_stop_nms),
            0.0,
            0.0,
        );
        assert_eq!(u.update(Some(&s), &mid, &t, false).state_changed, None);
        assert!(u.active());
        let low = Vector3::new(t.unloading_stop_nms * 0.5, 0.0, 0.0);
        assert_eq!(
            u.update(Some(&s), &low, &t, false).state_changed,
            Some(false)
        );
        assert!(u.bars_off());
    }

    /// A field at both TAMs that the model does not have, three blanked samples in a row:
    /// event data once, the law then on the model field; a good sample re-arms it.
    #[test]
    #[allow(clippy::float_cmp)] // the same computation gives the same bits
    fn bars_off_check_fires_once_and_rearms() {
        let t = MagneticsTable::boot();
        let mut u = MomentumUnloading::new();
        let model = Vector3::new(0.0, 300.0, 100.0);
        let stray = Vector3::new(40.0, 0.0, 0.0);
        let bad = FieldSample {
            tam_acs_milligauss: [Some(model + stray), Some(model + stray * 0.8)],
            model_acs_milligauss: Some(model),
            model_sigma_milligauss: 0.0,
        };
        let h = Vector3::new(100.0, 0.0, 0.0);
        let mut fired = 0;
        for k in 0..6 {
            let r = u.update(Some(&bad), &h, &t, false);
            if let Some((mask, tenths)) = r.unexpected_field {
                fired += 1;
                assert_eq!(k, usize::from(CHECK_CONSECUTIVE) - 1);
                assert_eq!(mask, 3);
                assert_eq!(tenths, 400);
            }
        }
        assert_eq!(fired, 1);
        assert!(u.field_unexpected());
        // The law uses the model field: the dipole is the one from the model.
        let from_model = cross_product_dipole(
            &h,
            &(model * TESLA_PER_MILLIGAUSS),
            t.unloading_gain_per_s,
            t.torquer_dipole_limit_am2,
        )
        .unwrap();
        assert_eq!(u.command_acs_am2(), from_model.dipole_acs_am2);
        let good = FieldSample {
            tam_acs_milligauss: [Some(model), Some(model)],
            model_acs_milligauss: Some(model),
            model_sigma_milligauss: 0.0,
        };
        u.update(Some(&good), &h, &t, false);
        assert!(!u.field_unexpected());
    }

    /// A blanked sample with no TAM to compare is no evidence: it neither re-arms the check
    /// nor resets its run of failures. An uncertain attitude widens the threshold by 3σ of
    /// the model field's error, and when that 3σ alone reaches the threshold the sample is no
    /// evidence either: a 3° attitude error (21 mG at 400 mG) is not a bar, and a raised alarm
    /// is not cleared by an inconclusive sample.
    #[test]
    fn bars_off_check_needs_a_tam_and_allows_for_the_attitude_sigma() {
        let t = MagneticsTable::boot();
        let model = Vector3::new(0.0, 380.0, 130.0);
        let stray = Vector3::new(40.0, 0.0, 0.0);
        let sample = |tam: Option<Vector3<f64>>, sigma: f64| FieldSample {
            tam_acs_milligauss: [tam, tam],
            model_acs_milligauss: Some(model),
            model_sigma_milligauss: sigma,
        };
        let h = Vector3::new(100.0, 0.0, 0.0);
        let mut u = MomentumUnloading::new();
        u.update(Some(&sample(Some(model + stray), 0.0)), &h, &t, false);
        u.update(Some(&sample(Some(model + stray), 0.0)), &h, &t, false);
        // Dead TAMs in between: the run of two failures stands.
        u.update(Some(&sample(None, 0.0)), &h, &t, false);
        let r = u.update(Some(&sample(Some(model + stray), 0.0)), &h, &t, false);
        assert!(r.unexpected_field.is_some(), "third failure in a row");
        // Once raised, a sample without TAMs does not clear it.
        u.update(Some(&sample(None, 0.0)), &h, &t, false);
        assert!(u.field_unexpected());

        // The field of a 3° attitude error: 400 mG × 0.052 rad ≈ 21 mG, above the 20-mG
        // threshold, but within it plus 3σ when the filter's σ is 1.5°.
        let tilt =
            Vector3::new(0.0, 130.0, -380.0).normalize() * model.norm() * 3.0_f64.to_radians();
        let sigma_deg = 1.5_f64;
        let sigma_mg = model.norm() * sigma_deg.to_radians();
        let mut u = MomentumUnloading::new();
        for _ in 0..5 {
            let r = u.update(Some(&sample(Some(model + tilt), sigma_mg)), &h, &t, false);
            assert_eq!(r.unexpected_field, None);
        }
        let mut u = MomentumUnloading::new();
        let fired = (0..5).any(|_| {
            u.update(Some(&sample(Some(model + tilt), 0.0)), &h, &t, false)
                .unexpected_field
                .is_some()
        });
        assert!(
            fired,
            "with a certain attitude the same difference is a field"
        );
        // Raised, then a sample while the attitude is uncertain (after a filter reset): the
        // alarm stays; a moderately uncertain attitude (3σ below the threshold) still sees it.
        u.update(Some(&sample(Some(model + stray), sigma_mg)), &h, &t, false);
        assert!(
            u.field_unexpected(),
            "an inconclusive sample does not clear the alarm"
        );
        let r = u.update(Some(&sample(Some(model + stray), 2.0)), &h, &t, false);
        assert_eq!(r.unexpected_field, None, "raised once");
        assert!(u.field_unexpected(), "40 mG > 20 + 3 × 2 mG: still a field");
    }

    /// Wheel speeds that carry a known momentum per wheel come back as `Σ a_i h_i` (to the
    /// 0.1-rpm quantisation); a missing or saturated word, or no geometry, gives `None`.
    #[test]
    fn tachometers_give_the_wheel_momentum_through_the_table_geometry() {
        let t = MagneticsTable::boot();
        let per_count = t.wheel_spin_inertia_kg_m2 * RAD_PER_S_PER_COUNT;
        let h_wheel = [120.0, -40.0, 7.5, 60.0];
        let mut s = crate::raw::WheelSample {
            speed_counts: h_wheel.map(|h| libm::round(h / per_count) as i16),
            speed_valid: 0x0F,
            ..Default::default()
        };
        let k = 1.0 / libm::sqrt(3.0);
        let expected = Vector3::new(120.0 + 60.0 * k, -40.0 + 60.0 * k, 7.5 + 60.0 * k);
        let h = wheel_momentum_from_tachometers(&s, &t).unwrap();
        assert!((h - expected).norm() < 2.0 * per_count, "{h} vs {expected}");
        s.speed_valid = 0x07;
        assert_eq!(wheel_momentum_from_tachometers(&s, &t), None);
        s.speed_valid = 0x0F;
        s.speed_counts[2] = i16::MAX;
        assert_eq!(wheel_momentum_from_tachometers(&s, &t), None, "saturated");
        s.speed_counts[2] = -i16::MAX;
        assert_eq!(
            wheel_momentum_from_tachometers(&s, &t),
            None,
            "saturated, negative"
        );
        s.speed_counts[2] = -i16::MAX + 1;
        assert!(wheel_momentum_from_tachometers(&s, &t).is_some());
        let mut no_geometry = t;
        no_geometry.wheel_spin_axes_acs = [[0.0; 3]; crate::raw::WHEELS];
        assert_eq!(wheel_momentum_from_tachometers(&s, &no_geometry), None);
        // A wheel the table does not hold needs no word.
        let mut three = t;
        three.wheel_spin_axes_acs[3] = [0.0; 3];
        s.speed_counts[2] = 100;
        s.speed_valid = 0x07;
        assert!(wheel_momentum_from_tachometers(&s, &three).is_some());
    }

    /// The tachometers replace the count; without them the count carries on from the last
    /// measured value; each change of source is reported once.
    #[test]
    fn momentum_source_follows_the_tachometers_and_reports_each_change() {
        let t = MagneticsTable::boot();
        let per_count = t.wheel_spin_inertia_kg_m2 * RAD_PER_S_PER_COUNT;
        let mut u = MomentumUnloading::new();
        let tau = Vector3::new(0.5, 0.0, 0.0);
        let s = crate::raw::WheelSample {
            speed_counts: [1000, 0, 0, 0],
            speed_valid: 0x0F,
            ..Default::default()
        };
        assert_eq!(
            u.update_wheel_momentum(&s, &tau, 1.0, &t),
            Some(MomentumSource::Tachometers)
        );
        assert!((u.wheel_momentum_acs_nms().x - 1000.0 * per_count).abs() < 1e-9);
        assert_eq!(u.update_wheel_momentum(&s, &tau, 1.0, &t), None);
        let lost = crate::raw::WheelSample::default();
        assert_eq!(
            u.update_wheel_momentum(&lost, &tau, 1.0, &t),
            Some(MomentumSource::CommandCount)
        );
        assert!((u.wheel_momentum_acs_nms().x - (1000.0 * per_count - 0.5)).abs() < 1e-9);
        assert_eq!(u.update_wheel_momentum(&lost, &tau, 1.0, &t), None);
        assert_eq!(u.source(), MomentumSource::CommandCount);
        assert_eq!(
            u.update_wheel_momentum(&s, &tau, 1.0, &t),
            Some(MomentumSource::Tachometers)
        );
        // Tachometer words from boot that cannot be used (no geometry in the table): the count
        // is reported on the first frame, once.
        let mut u = MomentumUnloading::new();
        let mut no_geometry = t;
        no_geometry.wheel_spin_axes_acs = [[0.0; 3]; crate::raw::WHEELS];
        assert_eq!(
            u.update_wheel_momentum(&s, &tau, 1.0, &no_geometry),
            Some(MomentumSource::CommandCount)
        );
        assert_eq!(u.update_wheel_momentum(&s, &tau, 1.0, &no_geometry), None);
        // No tachometer words at all (a spacecraft without them): nothing to report.
        let mut u = MomentumUnloading::new();
        assert_eq!(u.update_wheel_momentum(&lost, &tau, 1.0, &t), None);
    }

    /// One tachometer lost: the other wheels stay measured and the lost one is carried on
    /// with its minimum-norm share of the commands; the shares meet the command exactly.
    #[test]
    fn a_lost_tachometer_counts_only_its_wheels_share() {
        let t = MagneticsTable::boot();
        let per_count = t.wheel_spin_inertia_kg_m2 * RAD_PER_S_PER_COUNT;
        let tau = Vector3::new(0.3, -0.2, 0.1);
        let shares = wheel_torque_shares_nm(&t, &tau).unwrap();
        let met = t
            .wheel_spin_axes_acs
            .iter()
            .zip(shares)
            .fold(Vector3::zeros(), |acc, (a, s)| {
                acc + Vector3::new(a[0], a[1], a[2]) * s
            });
        assert!((met - tau).norm() < 1e-12, "W W⁺ τ = τ");
        let all = crate::raw::WheelSample {
            speed_counts: [1000, -2000, 300, 500],
            speed_valid: 0x0F,
            ..Default::default()
        };
        let mut u = MomentumUnloading::new();
        u.update_wheel_momentum(&all, &tau, 1.0, &t);
        let before = u.wheel_momentum_acs_nms();
        // Wheel 2 lost; the others read the same; 10 s of τ: wheel 2 takes −share₂ × 10 s.
        let lost2 = crate::raw::WheelSample {
            speed_valid: 0x0D,
            ..all
        };
        assert_eq!(
            u.update_wheel_momentum(&lost2, &tau, 10.0, &t),
            Some(MomentumSource::PartialTachometers)
        );
        let a2 = t.wheel_spin_axes_acs[1];
        let expect = before - Vector3::new(a2[0], a2[1], a2[2]) * (shares[1] * 10.0);
        assert!((u.wheel_momentum_acs_nms() - expect).norm() < 1e-9);
        assert!(
            (f64::from(all.speed_counts[1]) * per_count - 10.0 * shares[1] - u.wheel_nms[1]).abs()
                < 1e-9
        );
        // Every word lost: the whole count.
        assert_eq!(
            u.update_wheel_momentum(&crate::raw::WheelSample::default(), &tau, 1.0, &t),
            Some(MomentumSource::CommandCount)
        );
        assert_eq!(MomentumSource::PartialTachometers.code(), 2);
    }

    #[test]
    fn wheel_count_integrates_and_is_bounded() {
        let mut u = MomentumUnloading::new();
        u.account_wheel_torque(&Vector3::new(0.1, -0.2, 0.0), 10.0);
        assert!((u.wheel_momentum_acs_nms() - Vector3::new(-1.0, 2.0, 0.0)).norm() < 1e-12);
        u.account_wheel_torque(&Vector3::new(f64::NAN, 0.0, 0.0), 1.0);
        assert!((u.wheel_momentum_acs_nms() - Vector3::new(-1.0, 2.0, 0.0)).norm() < 1e-12);
        u.account_wheel_torque(&Vector3::new(1e9, 0.0, 0.0), 1.0);
        assert!((u.wheel_momentum_acs_nms().norm() - MAX_MOMENTUM_NMS).abs() < 1e-6);
    }
}
