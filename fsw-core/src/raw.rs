//! # Raw sensor data as the OBC sees it, once per cycle
//!
//! These are the hardware words the flight software reads each cycle and the contents of the
//! raw-sensor telemetry packet (`docs/icd.md`, APID 0x010). Everything is integer counts and
//! flags; conversion to engineering units happens in [`crate::fhst`], [`crate::fss`] and
//! [`crate::iru`], never here.
//!
//! Sensor geometry shared by FHST and FSS (tangent-plane form, `docs/conventions.md`): a
//! sensor-frame unit vector `s` has focal-plane angles `H = atan2(s_x, s_z)`,
//! `V = atan2(s_y, s_z)` and back `s = normalize([tan H, tan V, 1])`.

use serde::{Deserialize, Serialize};

/// Number of DRIRU II channels.
/// Paper: DRIRU II, three dual-axis gyros = 6 channels.
pub const IRU_CHANNELS: usize = 6;
/// Channel order used everywhere (arrays, telemetry): X1, X2, Y1, Y2, Z1, Z2.
/// Paper channel names; order per docs/icd.md §3.1.
pub const IRU_CHANNEL_NAMES: [&str; IRU_CHANNELS] = ["X1", "X2", "Y1", "Y2", "Z1", "Z2"];
/// Number of temperature sensors in the raw frame: FHST1, FHST2, FSS1, FSS2, IRU baseplate.
/// docs/icd.md §3.1 (offset 38); the paper gives no temperatures (project choice, for
/// thermal-drift studies).
pub const TEMPERATURE_SENSORS: usize = 5;

/// Spacecraft time: CCSDS unsegmented time code (CUC), 4 octets of seconds and 2 of
/// fraction (units of 2⁻¹⁶ s), epoch 1958-01-01T00:00:00 TAI (CCSDS level-1 epoch).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TimeTag {
    /// Whole seconds since 1958-01-01 TAI.
    /// CCSDS 301.0-B-4 CUC, 4 octets coarse (docs/icd.md §2).
    pub coarse_s: u32,
    /// Fraction of a second in units of 2⁻¹⁶ s.
    /// CCSDS 301.0-B-4 CUC fine octets (docs/icd.md §2).
    pub fine: u16,
}

/// Seconds from the CCSDS epoch (1958-01-01 TAI) to J2000.0 (2000-01-01T12:00:00 TT):
/// 15 340 days + 12 h − 32.184 s (TT − TAI).
pub const TAI1958_S_AT_J2000_TT: f64 = 15_340.0 * 86_400.0 + 43_200.0 - 32.184;

impl TimeTag {
    /// Seconds since 1958-01-01 TAI as `f64` (exact to 2⁻¹⁶ s for the next century).
    /// CCSDS 301.0-B-4 CUC epoch 1958 TAI (docs/conventions.md "Time").
    #[must_use]
    pub fn seconds(&self) -> f64 {
        f64::from(self.coarse_s) + f64::from(self.fine) / 65_536.0
    }

    /// The time tag nearest to `seconds` since 1958-01-01 TAI; `None` if out of range or not finite.
    /// CCSDS 301.0-B-4 CUC, fine part 2⁻¹⁶ s (docs/icd.md §2).
    #[must_use]
    pub fn from_seconds(seconds: f64) -> Option<Self> {
        if !(0.0..4_294_967_295.0).contains(&seconds) {
            return None;
        }
        let ticks = libm::round(seconds * 65_536.0);
        let coarse = libm::floor(ticks / 65_536.0);
        let fine = ticks - coarse * 65_536.0;
        // Both are in range by the check above; `as` saturates anyway.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        Some(Self {
            coarse_s: coarse as u32,
            fine: fine as u16,
        })
    }

    /// Seconds since J2000.0 TT (the argument of the onboard Sun ephemeris).
    /// docs/conventions.md ("Time"); J2000.0 = 2000-01-01T12:00:00 TT, TT − TAI = 32.184 s (IAU).
    #[must_use]
    pub fn seconds_since_j2000_tt(&self) -> f64 {
        self.seconds() - TAI1958_S_AT_J2000_TT
    }
}

/// One DRIRU II sample: the six accumulated pulse counters, read at the cycle boundary.
/// Paper: DRIRU II; word layout docs/icd.md §3.1.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct IruSample {
    /// Accumulated pulse counters (16-bit, wrapping), channel order X1, X2, Y1, Y2, Z1, Z2.
    /// docs/icd.md §3.1 (16-bit counter width is a project choice; the paper does not give it).
    pub counts: [u16; IRU_CHANNELS],
    /// Built-in-test failure bits, bit `i` = channel `i` reports a failure.
    /// docs/icd.md §3.1 (offset 12).
    pub channel_failed: u8,
    /// Rate mode in effect during the interval that *ended* at this sample:
    /// `true` = high rate (0.8 arcsec/pulse), `false` = low rate (0.05 arcsec/pulse).
    /// Paper: DRIRU II 0.05″/pulse low rate, 0.8″/pulse high rate; docs/icd.md §3.1.
    pub high_rate: bool,
}

/// FHST status flag: the data words hold a valid star measurement.
/// docs/icd.md §3.1 (offset 20, bit0).
pub const FHST_FLAG_VALID: u8 = 0x01;
/// FHST status flag: the tracker is in track (not searching).
/// docs/icd.md §3.1 (offset 20, bit1).
pub const FHST_FLAG_TRACKING: u8 = 0x02;
/// FHST status flag: the star tracked now is a different star from the previous sample
/// (a new acquisition).
/// docs/icd.md §3.1 (bit2); the paper: an FHST tracks one star at a time.
pub const FHST_FLAG_NEW_STAR: u8 = 0x04;

/// One fixed-head star tracker sample (one star at a time).
/// Paper: NASA standard FHST, two units, 8° FOV; layout docs/icd.md §3.1.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FhstSample {
    /// Horizontal focal-plane coordinate, 7.78 arcsec per count, 0 at the boresight.
    /// Paper: FHST resolution 7.78″/count.
    pub h_counts: i16,
    /// Vertical focal-plane coordinate, 7.78 arcsec per count, 0 at the boresight.
    /// Paper: FHST resolution 7.78″/count.
    pub v_counts: i16,
    /// Instrument magnitude in units of 0.01 mag.
    /// docs/icd.md §3.1 (Hp-like instrument magnitude, docs/conventions.md); paper range 2.0–5.7.
    pub magnitude_centimag: i16,
    /// Status bits `FHST_FLAG_*`.
    /// docs/icd.md §3.1.
    pub flags: u8,
}

/// FSS status flag: Sun presence on the α head.
/// docs/icd.md §3.1 (offset 32, bit0).
pub const FSS_FLAG_SUN_ALPHA: u8 = 0x01;
/// FSS status flag: Sun presence on the β head.
/// docs/icd.md §3.1 (offset 32, bit1).
pub const FSS_FLAG_SUN_BETA: u8 = 0x02;

/// One fine Sun sensor sample: two orthogonal single-axis heads.
/// Paper: Adcole FSS, two units with two orthogonal heads each; layout docs/icd.md §3.1.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FssSample {
    /// α head angle, 0.004° per count, 0 at the boresight: α = atan2(s_x, s_z).
    /// Paper: FSS resolution about 0.004°/count; geometry algorithms.md §4.
    pub alpha_counts: i16,
    /// β head angle, 0.004° per count, 0 at the boresight: β = atan2(s_y, s_z).
    /// Paper: FSS resolution about 0.004°/count; geometry algorithms.md §4.
    pub beta_counts: i16,
    /// Status bits `FSS_FLAG_*`.
    /// docs/icd.md §3.1.
    pub flags: u8,
}

/// Number of three-axis magnetometers: TAM1 (primary), TAM2.
/// Paper: two TAMs (issue 20); docs/icd.md §3.5.
pub const TAMS: usize = 2;
/// Number of coarse Sun sensor eyes the OBC reads: ±X, ±Y, ±Z of ACS.
/// Project choice (the paper gives no CSS layout); docs/magnetics.md §2, docs/icd.md §3.5.
pub const CSS_EYES: usize = 6;

/// TAM status flag: the three field words hold a measurement.
/// docs/icd.md §3.5.
pub const TAM_FLAG_VALID: u8 = 0x01;
/// TAM status flag (hardware status, ICD format version 3): a magnetic torquer bar was driven
/// while the TAM sampled (the bar drive's current monitor), so the words include the bars'
/// own field. The OBC blanks the bars before the samples it uses, so on those the flag means a
/// bar is stuck on: the coarse fix refuses such a sample (event 0x0903, p1 = 5 or 6); the
/// ground uses the flag to keep bars-off samples only.
/// docs/icd.md §3.5; docs/magnetics.md §7.
pub const TAM_FLAG_TORQUERS_ON: u8 = 0x02;
/// CSS status flag: the six eye words hold a measurement.
/// docs/icd.md §3.5.
pub const CSS_FLAG_VALID: u8 = 0x01;

/// One three-axis magnetometer sample, in counts along the TAM's own axes.
/// The count size (mG per count) is a TAM table field, not a constant.
/// docs/icd.md §3.5; docs/magnetics.md §2.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TamSample {
    /// Field along the TAM's X, Y, Z axes, signed counts.
    /// docs/icd.md §3.5.
    pub field_counts: [i16; 3],
    /// Status bits `TAM_FLAG_*`; 0 (the default) means no data.
    /// docs/icd.md §3.5.
    pub flags: u8,
}

/// One sample of the coarse Sun sensor eyes (cosine-law photocells), in counts.
/// docs/icd.md §3.5; docs/magnetics.md §2.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CssSample {
    /// Eye outputs, order +X, −X, +Y, −Y, +Z, −Z of ACS.
    /// docs/icd.md §3.5.
    pub counts: [u16; CSS_EYES],
    /// Status bits `CSS_FLAG_*`; 0 (the default) means no data.
    /// docs/icd.md §3.5.
    pub flags: u8,
}

/// Number of reaction wheels whose tachometers the OBC reads.
/// Project choice (the paper gives no wheel layout): three orthogonal wheels and a skewed
/// fourth, as the truth's default; docs/icd.md §3.6.
pub const WHEELS: usize = 4;
/// Number of torquer-bar current monitors (one per bar, ACS x, y, z).
/// docs/icd.md §3.6; docs/magnetics.md §7.
pub const TORQUER_MONITORS: usize = 3;
/// Wheel tachometer count size, rpm per count (±3,276.6 rpm usable in an `i16`; ±32,767
/// and −32,768 are saturated words).
/// Project choice (not in the paper); docs/icd.md §3.6.
pub const WHEEL_RPM_PER_COUNT: f64 = 0.1;
/// Torquer-bar current monitor count size, A·m² of dipole per count.
/// Project choice (not in the paper); docs/icd.md §3.6.
pub const TORQUER_AM2_PER_COUNT: f64 = 1.0;

/// One cycle's reaction-wheel tachometers and torquer-bar current monitors (ICD format
/// version 4). The OBC takes the wheel momentum from the tachometers (Table 6's wheel geometry
/// and inertia); the monitors are the dipoles the bars actually carried.
/// docs/icd.md §3.6; docs/magnetics.md §7.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct WheelSample {
    /// Wheel speeds, signed counts of [`WHEEL_RPM_PER_COUNT`] about each wheel's spin axis,
    /// wheel 1 to 4; ±32,767 and −32,768 are saturated words.
    /// docs/icd.md §3.6.
    pub speed_counts: [i16; WHEELS],
    /// Bit `i` set: wheel `i + 1`'s tachometer word holds a measurement; 0 (the default)
    /// means no tachometer data.
    /// docs/icd.md §3.6.
    pub speed_valid: u8,
    /// Dipole each bar carried over the interval that ended at this sample (the drive's
    /// current monitor; the interval whose field the TAMs saw), signed counts of
    /// [`TORQUER_AM2_PER_COUNT`], bars along ACS x, y, z.
    /// docs/icd.md §3.6.
    pub dipole_counts: [i16; TORQUER_MONITORS],
    /// Bit `k` set: bar `k + 1`'s monitor word holds a measurement.
    /// docs/icd.md §3.6.
    pub dipole_valid: u8,
}

/// Everything the OBC reads from its sensors in one cycle.
/// APID 0x010, docs/icd.md §3.1.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RawSensorFrame {
    /// Time at which all sensors were sampled.
    /// docs/icd.md §3.1 (the packet's CUC time code).
    pub time: TimeTag,
    /// Gyro counters.
    /// docs/icd.md §3.1.
    pub iru: IruSample,
    /// FHST1, FHST2.
    /// Paper: two FHSTs; docs/icd.md §3.1.
    pub fhst: [FhstSample; 2],
    /// FSS1, FSS2.
    /// Paper: two FSSs; docs/icd.md §3.1.
    pub fss: [FssSample; 2],
    /// Temperatures in 0.01 °C: FHST1, FHST2, FSS1, FSS2, IRU baseplate.
    /// docs/icd.md §3.1 (offset 38).
    pub temperatures_centi_c: [i16; TEMPERATURE_SENSORS],
    /// TAM1, TAM2 (all flags 0 when the spacecraft carries no magnetics data this cycle).
    /// Not in APID 0x010: docs/icd.md §3.5 (APID 0x013).
    pub tam: [TamSample; TAMS],
    /// The coarse Sun sensor eyes.
    /// Not in APID 0x010: docs/icd.md §3.5 (APID 0x013).
    pub css: CssSample,
    /// Wheel tachometers and torquer-bar current monitors (all flags 0 without them).
    /// Not in APID 0x010: docs/icd.md §3.6 (APID 0x014).
    pub wheels: WheelSample,
}
