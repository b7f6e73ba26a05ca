//! # Simulation time: UTC, TAI, TT, the onboard CUC time tag and seconds since J2000 TT
//!
//! Scenarios are written in UTC (the paper's release epoch is 1991-04-07T22:37:00 UTC), the
//! spacecraft clock counts TAI seconds since 1958-01-01 ([`fsw_core::raw::TimeTag`]) and the
//! ephemerides run on TT (TDB − TT ≤ 1.7 ms, which moves the Sun by 7e-5″ and is ignored).
//! hifitime does the leap-second bookkeeping at the edges; inside the per-cycle loop
//! [`SimClock`] works in plain `f64` seconds from a fixed start epoch, so no calendar or
//! leap-second arithmetic is done per cycle (a run never crosses a leap second in 1991: the
//! next one after 1991-01-01 is 1992-07-01; [`SimClock`] is exact anyway because it counts
//! TAI-uniform seconds).

use fsw_core::raw::{TimeTag, TAI1958_S_AT_J2000_TT};
use hifitime::{Epoch, TimeScale, Unit};

/// TT − TAI, exactly 32.184 s by definition.
pub const TT_MINUS_TAI_S: f64 = 32.184;
/// Julian date (TT) of J2000.0.
pub const JD_J2000: f64 = 2_451_545.0;
/// Seconds per Julian year (365.25 d).
pub const S_PER_JULIAN_YEAR: f64 = 365.25 * 86_400.0;
/// Seconds per Julian century.
pub const S_PER_JULIAN_CENTURY: f64 = 100.0 * S_PER_JULIAN_YEAR;

/// The CCSDS level-1 epoch 1958-01-01T00:00:00 TAI.
#[must_use]
pub fn ccsds_epoch() -> Epoch {
    Epoch::from_gregorian_tai_at_midnight(1958, 1, 1)
}

/// Parse an ISO 8601 / RFC 3339 UTC string such as `1991-04-07T22:37:00Z`.
///
/// A trailing `Z` is optional; a time-scale suffix (`TAI`, `TT`) is honoured as hifitime
/// reads it.
///
/// # Errors
/// The hifitime parse error, with the offending text.
pub fn epoch_from_iso(text: &str) -> anyhow::Result<Epoch> {
    Epoch::from_gregorian_str(text.trim())
        .map_err(|e| anyhow::anyhow!("cannot parse epoch {text:?}: {e}"))
}

/// Seconds since 1958-01-01 TAI (the spacecraft clock) at `epoch`.
#[must_use]
pub fn tai1958_s(epoch: Epoch) -> f64 {
    // Subtract on the TAI scale: hifitime subtracts in the left operand's scale, and UTC
    // "seconds" skip leap seconds.
    (epoch.to_tai_duration() - ccsds_epoch().to_tai_duration()).to_seconds()
}

/// The epoch `s` TAI seconds after 1958-01-01 TAI.
#[must_use]
pub fn epoch_from_tai1958_s(s: f64) -> Epoch {
    ccsds_epoch() + Unit::Second * s
}

/// Seconds since J2000.0 (2000-01-01T12:00:00 TT), on the TT scale.
#[must_use]
pub fn j2000_tt_s(epoch: Epoch) -> f64 {
    tai1958_s(epoch) - TAI1958_S_AT_J2000_TT
}

/// Julian date on the TT scale.
#[must_use]
pub fn jd_tt(epoch: Epoch) -> f64 {
    JD_J2000 + j2000_tt_s(epoch) / 86_400.0
}

/// The epoch of a TT Julian date.
#[must_use]
pub fn epoch_from_jd_tt(jd_tt: f64) -> Epoch {
    // Split the day count to keep sub-microsecond precision.
    let days_from_j2000 = jd_tt - JD_J2000;
    epoch_from_tai1958_s(TAI1958_S_AT_J2000_TT + days_from_j2000 * 86_400.0)
}

/// TT − UTC (s) at `epoch`: 32.184 s + the leap-second count TAI − UTC.
#[must_use]
pub fn tt_minus_utc_s(epoch: Epoch) -> f64 {
    let tai_minus_utc = epoch.leap_seconds(true).unwrap_or(0.0);
    TT_MINUS_TAI_S + tai_minus_utc
}

/// The spacecraft time tag at `epoch`, `None` before 1958 or after 2094.
#[must_use]
pub fn time_tag(epoch: Epoch) -> Option<TimeTag> {
    TimeTag::from_seconds(tai1958_s(epoch))
}

/// The epoch of a spacecraft time tag.
#[must_use]
pub fn epoch_from_time_tag(tag: TimeTag) -> Epoch {
    epoch_from_tai1958_s(tag.seconds())
}

/// UTC calendar text of `epoch` (`1991-04-07T22:37:00 UTC`).
#[must_use]
pub fn utc_string(epoch: Epoch) -> String {
    epoch.to_gregorian_str(TimeScale::UTC)
}

/// Uniform simulation clock: `t_s` seconds (TAI rate) after a start epoch.
///
/// Everything per cycle is derived from two `f64` offsets, so the conversions cost an add.
/// The precision of `tai1958_s` is about 1e-7 s (an `f64` near 1e9), far below the CUC
/// resolution of 2⁻¹⁶ s.
#[derive(Clone, Copy, Debug)]
pub struct SimClock {
    start: Epoch,
    tai1958_s_at_start: f64,
    j2000_tt_s_at_start: f64,
}

impl SimClock {
    /// A clock whose `t_s = 0` is `start`.
    #[must_use]
    pub fn new(start: Epoch) -> Self {
        let tai1958_s_at_start = tai1958_s(start);
        Self {
            // Hold the start on the TAI scale so that `start + Δt` is uniform.
            start: start.to_time_scale(TimeScale::TAI),
            tai1958_s_at_start,
            j2000_tt_s_at_start: tai1958_s_at_start - TAI1958_S_AT_J2000_TT,
        }
    }

    /// The start epoch.
    #[must_use]
    pub fn start(&self) -> Epoch {
        self.start
    }

    /// The epoch at `t_s` (hifitime; not for the per-cycle path).
    #[must_use]
    pub fn epoch(&self, t_s: f64) -> Epoch {
        self.start + Unit::Second * t_s
    }

    /// Seconds since 1958-01-01 TAI at `t_s`.
    #[must_use]
    pub fn tai1958_s(&self, t_s: f64) -> f64 {
        self.tai1958_s_at_start + t_s
    }

    /// Seconds since J2000.0 TT at `t_s`.
    #[must_use]
    pub fn j2000_tt_s(&self, t_s: f64) -> f64 {
        self.j2000_tt_s_at_start + t_s
    }

    /// Julian centuries (TT) since J2000.0 at `t_s`.
    #[must_use]
    pub fn centuries_tt(&self, t_s: f64) -> f64 {
        self.j2000_tt_s(t_s) / S_PER_JULIAN_CENTURY
    }

    /// The spacecraft time tag at `t_s` (nearest 2⁻¹⁶ s).
    #[must_use]
    pub fn time_tag(&self, t_s: f64) -> Option<TimeTag> {
        TimeTag::from_seconds(self.tai1958_s(t_s))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// TT − UTC in 1991 is 58.184 s (TAI − UTC = 26 s from 1991-01-01 to 1992-07-01);
    /// data/sun_reference.csv row 0 gives jd_tt 2448347.5 = 1991-03-31T23:59:01.816 UTC.
    #[test]
    fn val_tt_minus_utc_1991_matches_sun_reference() {
        let utc = epoch_from_iso("1991-03-31T23:59:01.816Z").unwrap();
        assert!((tt_minus_utc_s(utc) - 58.184).abs() < 1e-9);
        assert!((jd_tt(utc) - 2_448_347.5).abs() * 86_400.0 < 1e-5);
        let back = epoch_from_jd_tt(2_448_347.5);
        assert!((tai1958_s(back) - tai1958_s(utc)).abs() < 1e-5);
    }

    #[test]
    fn j2000_is_tai1958_constant() {
        let j2000 = Epoch::from_gregorian_str("2000-01-01T12:00:00 TT").unwrap();
        assert!(j2000_tt_s(j2000).abs() < 1e-6);
        assert!((tai1958_s(j2000) - TAI1958_S_AT_J2000_TT).abs() < 1e-6);
    }

    #[test]
    fn release_epoch_time_tag_round_trip() {
        let release = epoch_from_iso("1991-04-07T22:37:00Z").unwrap();
        let tag = time_tag(release).unwrap();
        // 1958 .. 1991-04-07 = 12 149 days; + 22:37:00 UTC + 26 s (TAI − UTC).
        let expect = 12_149.0 * 86_400.0 + 22.0 * 3600.0 + 37.0 * 60.0 + 26.0;
        assert!((tag.seconds() - expect).abs() < 1e-9, "{}", tag.seconds());
        assert_eq!(tag.fine, 0);
        let back = epoch_from_time_tag(tag);
        assert!((tai1958_s(back) - tai1958_s(release)).abs() < 1e-6);
        let clock = SimClock::new(release);
        let t = clock.time_tag(1.5).unwrap();
        assert_eq!(t.coarse_s, tag.coarse_s + 1);
        assert_eq!(t.fine, 32_768);
        assert!(
            (clock.j2000_tt_s(0.0) - tag.seconds_since_j2000_tt()).abs() < 1e-6,
            "clock and fsw-core agree on J2000"
        );
        assert!(utc_string(clock.epoch(60.0)).starts_with("1991-04-07T22:38:00"));
    }
}
