//! # Events: what happened, with a stable numeric code
//!
//! Events are raised on *transitions* (a table rejected, a channel excluded, a mode change),
//! never every cycle; steady conditions are counted in [`Counters`] instead, so an operator
//! sees both the moment and the total. Codes are the enum discriminants ([`EventId`]) and are
//! listed in `docs/icd.md`; a test checks they are unique.

use serde::{Deserialize, Serialize};

/// Maximum events reported by one cycle (further events in the same cycle are counted in
/// [`Counters::events_dropped`]).
/// Project choice (not in the paper): a fixed bound keeps the cycle output allocation-free.
pub const MAX_EVENTS_PER_CYCLE: usize = 8;

/// Event identifiers. The discriminant is the on-wire code.
/// Codes and parameters: docs/icd.md §3.3.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u16)]
pub enum EventId {
    /// A table image was loaded and validated into the inactive buffer. p1 = table id.
    /// docs/icd.md §3.3.
    TableLoaded = 0x0101,
    /// A table image was rejected. p1 = table id (0 if unreadable), p2 = reason code.
    /// docs/icd.md §3.3; reason codes in docs/tables.md.
    TableRejected = 0x0102,
    /// A table was activated. p1 = table id, p2 = CRC of its image.
    /// docs/icd.md §3.3.
    TableActivated = 0x0103,
    /// Activation refused. p1 = table id, p2 = reason code (0 = nothing pending).
    /// docs/icd.md §3.3; reason codes in docs/tables.md.
    TableActivateFailed = 0x0104,
    /// Inactive buffer cleared by command. p1 = table id, p2 = 1 if something was pending.
    /// docs/icd.md §3.3.
    TableAborted = 0x0105,
    /// IRU channel excluded. p1 = channel 0..5 (X1..Z2), p2 = reason bits (1 failed,
    /// 2 saturated, 4 stuck; e.g. 5 = failed and stuck), [`crate::iru::EXCLUDED_FAILED`] …
    /// docs/icd.md §3.3.
    IruChannelExcluded = 0x0201,
    /// IRU configuration switched. p1 = 0 primary, 1 backup; p2 = 1 if automatic.
    /// docs/icd.md §3.3.
    IruConfigSwitched = 0x0202,
    /// IRU rate mode command changed. p1 = 1 high rate, 0 low rate.
    /// docs/icd.md §3.3.
    IruRateModeChanged = 0x0203,
    /// IRU data unusable this cycle (attitude propagated without gyro). p1 = channel mask.
    /// docs/icd.md §3.3.
    IruDataUnusable = 0x0204,
    /// Filter initialised. p1 = 1 by command, 2 from two vectors.
    /// docs/icd.md §3.3.
    FilterInitialized = 0x0301,
    /// Filter reset by command (attitude kept, covariance reopened).
    /// docs/icd.md §3.3.
    FilterReset = 0x0302,
    /// Filter mode changed. p1 = new mode ([`crate::executive::FilterMode`] code).
    /// docs/icd.md §3.3.
    FilterModeChanged = 0x0303,
    /// A star was identified. p1 = tracker 0/1, p2 = catalog id.
    /// docs/icd.md §3.3.
    StarIdentified = 0x0401,
    /// Star identification failed. p1 = tracker, p2 = 1 no match, 2 ambiguous, 3 no catalog.
    /// docs/icd.md §3.3.
    StarIdFailed = 0x0402,
    /// A sensor's innovations are being gated out (first of a run). p1 = sensor 0..3.
    /// docs/icd.md §3.3.
    MeasurementGated = 0x0403,
    /// A sensor sample failed input validation (first of a run). p1 = sensor 0..4 (4 = IRU),
    /// p2 = reason code.
    /// docs/icd.md §3.3.
    InputRejected = 0x0404,
    /// Frame time not after the previous one, or a jump. p1 = previous coarse s, p2 = new.
    /// docs/icd.md §3.3.
    TimeTagAnomaly = 0x0501,
    /// A slew started. p1 = slew number.
    /// docs/icd.md §3.3.
    SlewStarted = 0x0601,
    /// A slew completed (error below the table threshold). p1 = slew number.
    /// docs/icd.md §3.3.
    SlewCompleted = 0x0602,
    /// The Sun is on the commanded axis and the rates are down in Sun acquisition.
    /// p1 = the Sun's angle from the axis, centidegrees.
    /// docs/icd.md §3.3.
    SunAcquired = 0x0603,
    /// In Sun acquisition no Sun sensor sees the Sun (eclipse, or none lit): rates damped only.
    /// Once per occurrence; p1 = 1 at the mode's first cycle, 0 after the Sun was seen.
    /// docs/icd.md §3.3.
    SunNotSeen = 0x0604,
    /// Sun acquisition commanded.
    /// docs/icd.md §3.3.
    SunAcquisitionStarted = 0x0605,
    /// The acquired Sun left twice the acquisition threshold: the turn resumes (the filter
    /// propagates on the gyros alone again).
    /// docs/icd.md §3.3.
    SunAcquisitionLost = 0x0606,
    /// The control step failed and commanded zero torque (raised when the failure starts or
    /// changes). p1 = 1 invalid target, 2 invalid estimate, 3 unusable table values, 4 Sun
    /// acquisition without its state; p2 = control mode.
    /// docs/icd.md §3.3.
    ControlFault = 0x0607,
    /// A command was refused. p1 = command code, p2 = reason.
    /// docs/icd.md §3.3.
    CommandRejected = 0x0701,
    /// The filter table asks for the orbital aberration correction but the onboard orbit is
    /// not valid: annual aberration only (raised once per status while it lasts). p1 = orbit
    /// status ([`crate::orbit::OrbitStatus::code`]: 0 no table, 1 catching up, 3 invalid),
    /// p2 = invalid reason ([`crate::orbit::OrbitInvalid::code`], 0 otherwise).
    /// docs/icd.md §3.3.
    OrbitalCorrectionUnavailable = 0x0801,
    /// The orbital aberration correction and the Sun parallax are applied (first cycle of a
    /// run). p1 = age of the orbit state, s since the table epoch (saturated, 0 if before).
    /// docs/icd.md §3.3.
    OrbitalCorrectionApplied = 0x0802,
    /// The coarse attitude could not be fixed (raised when the reason changes). p1 = reason
    /// ([`crate::coarse::CoarseUnavailable::code`]), p2 = fixes made since boot.
    /// docs/icd.md §3.3; docs/magnetics.md §5.
    CoarseFixUnavailable = 0x0901,
    /// The coarse attitude was fixed again after an interval without fixes (or for the first
    /// time). p1 = source ([`crate::coarse::CoarseSource`]: 1 FSS + TAM, 2 CSS + TAM), p2 = the
    /// reason code of the interval without fixes (0 none).
    /// docs/icd.md §3.3; docs/magnetics.md §5.
    CoarseFixResumed = 0x0902,
    /// The coarse attitude's fault screening rejected a vector (raised when the kind of
    /// rejection changes). p1 = 1 TAM1 magnitude, 2 TAM2 magnitude, 3 field against the
    /// carried solution, 4 Sun against the carried solution; p2 = rejections since boot.
    /// docs/icd.md §3.3; docs/magnetics.md §5.
    CoarseVectorRejected = 0x0903,
    /// An unexpected field at the TAMs while every torquer bar was commanded off, on 3
    /// blanked samples in a row (a bar stuck on when both TAMs see it, a TAM fault when one
    /// does; raised once until a sample passes). p1 = TAMs that see it (bit 0 TAM1, bit 1
    /// TAM2), p2 = the largest difference from the model field, 0.1 mG.
    /// docs/icd.md §3.3; docs/magnetics.md §7.
    TorquerFieldUnexpected = 0x0A01,
    /// Momentum unloading started (p1 = 1) or stopped (p1 = 0) at the dead band's edges.
    /// p2 = the system momentum `|h|`, N·m·s (rounded).
    /// docs/icd.md §3.3; docs/magnetics.md §7.
    UnloadingStateChanged = 0x0A02,
    /// The source of the OBC's wheel momentum changed: p1 = 1 the tachometers (every wheel of
    /// Table 6 read valid), 2 some of them (the wheels without one carried on with their
    /// share of the commands), 0 the count of the OBC's own torque commands (no usable
    /// tachometer word, or no wheel geometry in the table); p2 = the frame's tachometer
    /// validity bits.
    /// docs/icd.md §3.3 and §3.6; docs/magnetics.md §7.
    WheelMomentumSourceChanged = 0x0A03,
}

impl EventId {
    /// Every event id (for the uniqueness test and the ICD table).
    pub const ALL: [EventId; 33] = [
        Self::TableLoaded,
        Self::TableRejected,
        Self::TableActivated,
        Self::TableActivateFailed,
        Self::TableAborted,
        Self::IruChannelExcluded,
        Self::IruConfigSwitched,
        Self::IruRateModeChanged,
        Self::IruDataUnusable,
        Self::FilterInitialized,
        Self::FilterReset,
        Self::FilterModeChanged,
        Self::StarIdentified,
        Self::StarIdFailed,
        Self::MeasurementGated,
        Self::InputRejected,
        Self::TimeTagAnomaly,
        Self::SlewStarted,
        Self::SlewCompleted,
        Self::SunAcquired,
        Self::SunNotSeen,
        Self::SunAcquisitionStarted,
        Self::SunAcquisitionLost,
        Self::ControlFault,
        Self::CommandRejected,
        Self::OrbitalCorrectionUnavailable,
        Self::OrbitalCorrectionApplied,
        Self::CoarseFixUnavailable,
        Self::CoarseFixResumed,
        Self::CoarseVectorRejected,
        Self::TorquerFieldUnexpected,
        Self::UnloadingStateChanged,
        Self::WheelMomentumSourceChanged,
    ];

    /// On-wire code.
    /// docs/icd.md §3.3.
    #[must_use]
    pub fn code(self) -> u16 {
        self as u16
    }

    /// From the on-wire code.
    /// `None` for a code not in docs/icd.md §3.3.
    #[must_use]
    pub fn from_code(code: u16) -> Option<Self> {
        Self::ALL.iter().copied().find(|e| e.code() == code)
    }
}

/// One event with two parameters.
/// APID 0x012 record, docs/icd.md §3.3.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Event {
    /// What happened.
    /// docs/icd.md §3.3 (event code).
    pub id: EventId,
    /// First parameter (meaning per [`EventId`]).
    /// docs/icd.md §3.3.
    pub p1: u32,
    /// Second parameter.
    /// docs/icd.md §3.3.
    pub p2: u32,
}

/// Cumulative counters since boot (saturating).
/// Housekeeping offset 173, docs/icd.md §3.2.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Counters {
    /// Cycles executed.
    /// docs/icd.md §3.2.
    pub cycles: u32,
    /// Sensor samples refused by input validation (bad flags, range, NaN).
    /// docs/icd.md §3.2.
    pub rejected_inputs: u32,
    /// Measurements refused by the χ² gate.
    /// docs/icd.md §3.2.
    pub gated_measurements: u32,
    /// Measurements accepted by the filter.
    /// docs/icd.md §3.2.
    pub accepted_measurements: u32,
    /// Star identifications that succeeded.
    /// docs/icd.md §3.2.
    pub stars_identified: u32,
    /// Star identifications that found no candidate.
    /// docs/icd.md §3.2.
    pub star_id_unmatched: u32,
    /// Star identifications with more than one candidate (rejected).
    /// docs/icd.md §3.2.
    pub star_id_ambiguous: u32,
    /// Frames whose time tag was not after the previous one.
    /// docs/icd.md §3.2.
    pub time_tag_anomalies: u32,
    /// Cycles without usable gyro data.
    /// docs/icd.md §3.2.
    pub iru_unusable_cycles: u32,
    /// Events that did not fit in a cycle's output.
    /// docs/icd.md §3.2.
    pub events_dropped: u32,
}

impl Counters {
    /// The counters in their housekeeping wire order (offset 173, ten `u32`).
    /// docs/icd.md §3.2 (counters).
    #[must_use]
    pub fn wire_order(&self) -> [u32; 10] {
        [
            self.cycles,
            self.rejected_inputs,
            self.gated_measurements,
            self.accepted_measurements,
            self.stars_identified,
            self.star_id_unmatched,
            self.star_id_ambiguous,
            self.time_tag_anomalies,
            self.iru_unusable_cycles,
            self.events_dropped,
        ]
    }
}

/// Push an event into a cycle's list, counting it if the list is full.
/// Project choice (not in the paper): events never block the cycle; overflow is counted.
pub fn raise(
    events: &mut heapless::Vec<Event, MAX_EVENTS_PER_CYCLE>,
    counters: &mut Counters,
    id: EventId,
    p1: u32,
    p2: u32,
) {
    if events.push(Event { id, p1, p2 }).is_err() {
        counters.events_dropped = counters.events_dropped.saturating_add(1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn event_codes_are_unique_and_round_trip() {
        for (i, a) in EventId::ALL.iter().enumerate() {
            assert_eq!(EventId::from_code(a.code()), Some(*a));
            for b in &EventId::ALL[i + 1..] {
                assert_ne!(a.code(), b.code());
            }
        }
    }
}
