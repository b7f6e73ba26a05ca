//! # Downlink records and their exact byte layout (`docs/icd.md`)
//!
//! Every telemetry packet is a CCSDS space packet (primary header, 6 octets) whose data field
//! starts with a 6-octet CUC time code (secondary header) followed by one of the fixed,
//! big-endian user-data layouts below. The framing (primary header) is written by the host
//! crates with the `spacepackets` crate; this module owns the *user data*: one encoder and
//! one decoder per record, shared by the harness (writer) and the ground tool (reader), with a
//! round-trip test. Floats are IEEE-754 big-endian.
//!
//! | APID | record | user data length (octets, after the 6-octet time code) |
//! |---|---|---|
//! | 0x010 | [`RawSensorFrame`] | [`RAW_FRAME_LEN`] |
//! | 0x011 | [`ObcHousekeeping`] | [`HOUSEKEEPING_LEN`] |
//! | 0x012 | [`Event`] | [`EVENT_LEN`] |
//! | 0x013 | [`MagneticsFrame`] (TAM1, TAM2, CSS words of the [`RawSensorFrame`]) | [`MAGNETICS_LEN`] |
//! | 0x014 | [`WheelFrame`] (wheel tachometers and torquer-bar monitors of the [`RawSensorFrame`]) | [`WHEEL_FRAME_LEN`] |
//! | 0x020 | [`EphemerisRecord`] | [`EPHEMERIS_LEN`] |

use crate::attitude::Quat;
use crate::events::{Counters, Event, EventId};
use crate::raw::{
    CssSample, FhstSample, FssSample, IruSample, RawSensorFrame, TamSample, TimeTag, WheelSample,
    CSS_EYES, TAMS, TORQUER_MONITORS, WHEELS,
};
use serde::{Deserialize, Serialize};

/// APID of the raw sensor frame.
/// docs/icd.md §3.1.
pub const APID_RAW_SENSORS: u16 = 0x010;
/// APID of the OBC housekeeping (estimates, residuals, status).
/// docs/icd.md §3.2.
pub const APID_HOUSEKEEPING: u16 = 0x011;
/// APID of event packets.
/// docs/icd.md §3.3.
pub const APID_EVENT: u16 = 0x012;
/// APID of the magnetics frame (TAM1, TAM2 and the CSS eyes), written after the raw frame
/// of the same cycle with the same time code when the spacecraft carries them.
/// docs/icd.md §3.5 (format version 2).
pub const APID_MAGNETICS: u16 = 0x013;
/// APID of the wheel frame (reaction-wheel tachometers and torquer-bar current monitors),
/// written after the raw frame (and magnetics frame) of the same cycle with the same time
/// code when the spacecraft carries them.
/// docs/icd.md §3.6 (format version 4).
pub const APID_WHEELS: u16 = 0x014;
/// APID of the definitive-orbit ephemeris record.
/// docs/icd.md §3.4.
pub const APID_EPHEMERIS: u16 = 0x020;
/// Every APID of the downlink, in the order raw, housekeeping, event, ephemeris, magnetics,
/// wheels: the writer's sequence counters and the reader's record lists follow it.
/// docs/icd.md §3.
pub const APIDS: [u16; 6] = [
    APID_RAW_SENSORS,
    APID_HOUSEKEEPING,
    APID_EVENT,
    APID_EPHEMERIS,
    APID_MAGNETICS,
    APID_WHEELS,
];

/// CUC time code length (secondary header).
/// CCSDS 301.0-B-4 CUC 4+2 octets (docs/icd.md §2).
pub const TIME_CODE_LEN: usize = 6;
/// Raw frame user data length (after the time code).
/// docs/icd.md §3.1.
pub const RAW_FRAME_LEN: usize = 48;
/// Housekeeping user data length.
/// docs/icd.md §3.2.
pub const HOUSEKEEPING_LEN: usize = 230;
/// Event user data length.
/// docs/icd.md §3.3.
pub const EVENT_LEN: usize = 10;
/// Magnetics frame user data length: 2 × (3 × i16 + u8) + 6 × u16 + u8.
/// docs/icd.md §3.5.
pub const MAGNETICS_LEN: usize = 27;
/// Wheel frame user data length: 4 × i16 + u8 + 3 × i16 + u8.
/// docs/icd.md §3.6.
pub const WHEEL_FRAME_LEN: usize = 16;
/// Ephemeris user data length.
/// docs/icd.md §3.4.
pub const EPHEMERIS_LEN: usize = 48;

/// Why a record could not be decoded or encoded.
/// Project choice (not in the paper): decoding errors carry evidence (docs/icd.md §2).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RecordError {
    /// Wrong length for the record.
    /// docs/icd.md §2 (fixed user-data length per APID).
    Length {
        /// Octets expected.
        /// docs/icd.md §3.
        expected: usize,
        /// Octets found.
        /// docs/icd.md §3.
        found: usize,
    },
    /// An enumerated field holds an unknown value. `offset` is within the user data.
    /// docs/icd.md §3 (enumerated octets).
    BadEnum {
        /// Octet offset of the field.
        /// docs/icd.md §3.
        offset: usize,
    },
    /// The output buffer is too small.
    /// Project choice (not in the paper): encoders never write past `out`.
    BufferTooSmall,
}

/// A sentence for people (offsets are within the packet's user data, docs/icd.md §3).
impl core::fmt::Display for RecordError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::Length { expected, found } => write!(
                f,
                "the user data is {found} octets where this record has {expected}"
            ),
            Self::BadEnum { offset } => write!(
                f,
                "user-data octet {offset} holds a value outside its enumeration (docs/icd.md §3)"
            ),
            Self::BufferTooSmall => write!(f, "the output buffer is too small for the record"),
        }
    }
}

/// Status of one sensor's measurement in a cycle.
/// Residual-block status, docs/icd.md §3.2.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum MeasurementStatus {
    /// No measurement this cycle (sensor not valid / not present).
    /// docs/icd.md §3.2 (status 0).
    #[default]
    None = 0,
    /// Used by the filter.
    /// docs/icd.md §3.2 (status 1).
    Accepted = 1,
    /// Refused by the χ² gate.
    /// docs/icd.md §3.2 (status 2); gate per algorithms.md §2.
    Gated = 2,
    /// Refused by input validation.
    /// docs/icd.md §3.2 (status 3).
    Rejected = 3,
    /// FHST star not identified (unmatched or ambiguous), not used.
    /// docs/icd.md §3.2 (status 4); star ID per algorithms.md §3.2.
    Unidentified = 4,
    /// Valid but not used (filter not initialised or no reference).
    /// docs/icd.md §3.2 (status 5).
    NotUsed = 5,
}

impl MeasurementStatus {
    fn from_u8(v: u8) -> Option<Self> {
        match v {
            0 => Some(Self::None),
            1 => Some(Self::Accepted),
            2 => Some(Self::Gated),
            3 => Some(Self::Rejected),
            4 => Some(Self::Unidentified),
            5 => Some(Self::NotUsed),
            _ => None,
        }
    }
}

/// One sensor's residual report: innovation before the update, in the sensor's two
/// measured axes (FHST: H, V; FSS: α, β), arcsec, measured − predicted.
/// Residual block of docs/icd.md §3.2.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SensorResidual {
    /// What happened to the measurement.
    /// docs/icd.md §3.2.
    pub status: MeasurementStatus,
    /// Innovation, arcsec (0 when no measurement).
    /// docs/icd.md §3.2.
    pub innovation_arcsec: [f32; 2],
    /// Catalog id of the identified star (FHST), 0 otherwise.
    /// docs/icd.md §3.2 (HIP number of the Hipparcos catalog).
    pub star_id: u32,
}

/// The OBC housekeeping record downlinked every cycle.
/// APID 0x011, docs/icd.md §3.2.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ObcHousekeeping {
    /// Cycle time.
    /// docs/icd.md §3.2 (the packet's CUC time code).
    pub time: TimeTag,
    /// Estimated attitude `q_acs_from_eci` (scalar last).
    /// docs/icd.md §3.2 (offset 0); convention algorithms.md §1.
    pub q_acs_from_eci: Quat,
    /// Estimated gyro bias in ACS, rad/s.
    /// docs/icd.md §3.2 (offset 32); b of algorithms.md §2.
    pub bias_acs_rad_per_s: [f64; 3],
    /// Diagonal of the error covariance: δθ (rad²) then δb ((rad/s)²).
    /// docs/icd.md §3.2 (offset 56); P of algorithms.md §2.
    pub covariance_diag: [f64; 6],
    /// Filter mode code ([`crate::executive::FilterMode`]).
    /// docs/icd.md §3.2 (offset 104).
    pub filter_mode: u8,
    /// Control mode code ([`crate::executive::ControlMode`]).
    /// docs/icd.md §3.2 (offset 105).
    pub control_mode: u8,
    /// IRU configuration: 0 primary, 1 backup.
    /// docs/icd.md §3.2 (offset 106); paper: primary X2, Y1, Z1, backup X1, Y2, Z2.
    pub iru_config: u8,
    /// IRU rate mode commanded for the next interval: 1 high, 0 low.
    /// docs/icd.md §3.2 (offset 107).
    pub iru_high_rate_cmd: u8,
    /// Wheel torque command in ACS, N m.
    /// docs/icd.md §3.2 (offset 108).
    pub wheel_torque_cmd_nm: [f32; 3],
    /// Residuals of FHST1, FHST2, FSS1, FSS2.
    /// docs/icd.md §3.2 (offset 120).
    pub residuals: [SensorResidual; 4],
    /// IRU channels currently excluded, bit i = channel i.
    /// docs/icd.md §3.2 (offset 172).
    pub iru_excluded_mask: u8,
    /// Cumulative counters.
    /// docs/icd.md §3.2 (offset 173).
    pub counters: Counters,
    /// CRC of each active table image (0 = boot table), id order.
    /// docs/icd.md §3.2 (offset 213); CRC per docs/tables.md.
    pub table_crc: [u32; 4],
    /// Bit i set = table id i+1 has a validated image pending.
    /// docs/icd.md §3.2 (offset 229).
    pub table_pending_mask: u8,
}

/// The magnetometer and coarse-Sun-sensor words of one cycle, as downlinked: the `tam` and
/// `css` of the cycle's [`RawSensorFrame`] (same time code as its APID 0x010 packet).
/// APID 0x013, docs/icd.md §3.5.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MagneticsFrame {
    /// Sample time (the raw frame's).
    /// docs/icd.md §3.5 (the packet's CUC time code).
    pub time: TimeTag,
    /// TAM1 (primary), TAM2.
    /// docs/icd.md §3.5 (offsets 0, 7).
    pub tam: [TamSample; TAMS],
    /// The six CSS eyes.
    /// docs/icd.md §3.5 (offset 14).
    pub css: CssSample,
}

impl MagneticsFrame {
    /// The magnetics words of a raw frame.
    /// docs/icd.md §3.5.
    #[must_use]
    pub fn of_raw_frame(f: &RawSensorFrame) -> Self {
        Self {
            time: f.time,
            tam: f.tam,
            css: f.css,
        }
    }

    /// True when any unit carries data (a flag octet not 0): a writer may leave the packet out
    /// otherwise.
    /// docs/icd.md §3.5.
    #[must_use]
    pub fn has_data(&self) -> bool {
        self.tam.iter().any(|t| t.flags != 0) || self.css.flags != 0
    }
}

/// The wheel tachometer and torquer-bar monitor words of one cycle, as downlinked: the
/// `wheels` of the cycle's [`RawSensorFrame`] (same time code as its APID 0x010 packet).
/// APID 0x014, docs/icd.md §3.6.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct WheelFrame {
    /// Sample time (the raw frame's).
    /// docs/icd.md §3.6 (the packet's CUC time code).
    pub time: TimeTag,
    /// Tachometers and monitors.
    /// docs/icd.md §3.6.
    pub wheels: WheelSample,
}

impl WheelFrame {
    /// The wheel words of a raw frame.
    /// docs/icd.md §3.6.
    #[must_use]
    pub fn of_raw_frame(f: &RawSensorFrame) -> Self {
        Self {
            time: f.time,
            wheels: f.wheels,
        }
    }

    /// True when any word carries data (a validity octet not 0): a writer may leave the packet
    /// out otherwise.
    /// docs/icd.md §3.6.
    #[must_use]
    pub fn has_data(&self) -> bool {
        self.wheels.speed_valid != 0 || self.wheels.dipole_valid != 0
    }
}

/// Definitive orbit record (provided by orbit determination on the ground, or by the harness),
/// J2000/GCRS axes.
/// APID 0x020, docs/icd.md §3.4.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct EphemerisRecord {
    /// Epoch of the state.
    /// docs/icd.md §3.4 (the packet's CUC time code).
    pub time: TimeTag,
    /// Position, km.
    /// docs/icd.md §3.4.
    pub pos_eci_km: [f64; 3],
    /// Velocity, km/s.
    /// docs/icd.md §3.4.
    pub vel_eci_km_per_s: [f64; 3],
}

/// Bounded big-endian writer (never panics; reports overflow once at the end).
struct Writer<'a> {
    buf: &'a mut [u8],
    at: usize,
    overflow: bool,
}

impl<'a> Writer<'a> {
    fn new(buf: &'a mut [u8]) -> Self {
        Self {
            buf,
            at: 0,
            overflow: false,
        }
    }
    fn put(&mut self, bytes: &[u8]) {
        let end = self.at.saturating_add(bytes.len());
        match self.buf.get_mut(self.at..end) {
            Some(dst) => {
                dst.copy_from_slice(bytes);
                self.at = end;
            }
            None => self.overflow = true,
        }
    }
    fn u8(&mut self, v: u8) {
        self.put(&[v]);
    }
    fn u16(&mut self, v: u16) {
        self.put(&v.to_be_bytes());
    }
    fn i16(&mut self, v: i16) {
        self.put(&v.to_be_bytes());
    }
    fn u32(&mut self, v: u32) {
        self.put(&v.to_be_bytes());
    }
    fn f32(&mut self, v: f32) {
        self.put(&v.to_be_bytes());
    }
    fn f64(&mut self, v: f64) {
        self.put(&v.to_be_bytes());
    }
    fn time(&mut self, t: TimeTag) {
        self.u32(t.coarse_s);
        self.u16(t.fine);
    }
    fn finish(self) -> Result<usize, RecordError> {
        if self.overflow {
            Err(RecordError::BufferTooSmall)
        } else {
            Ok(self.at)
        }
    }
}

/// Big-endian reader over a slice whose length was checked beforehand; missing bytes read
/// as zero (cannot happen after the length check, and never panics).
struct Reader<'a> {
    buf: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn new(buf: &'a [u8]) -> Self {
        Self { buf, at: 0 }
    }
    fn take<const N: usize>(&mut self) -> [u8; N] {
        let end = self.at.saturating_add(N);
        let out = self
            .buf
            .get(self.at..end)
            .and_then(|s| <[u8; N]>::try_from(s).ok())
            .unwrap_or([0; N]);
        self.at = end;
        out
    }
    fn u8(&mut self) -> u8 {
        let [b] = self.take::<1>();
        b
    }
    fn u16(&mut self) -> u16 {
        u16::from_be_bytes(self.take())
    }
    fn i16(&mut self) -> i16 {
        i16::from_be_bytes(self.take())
    }
    fn u32(&mut self) -> u32 {
        u32::from_be_bytes(self.take())
    }
    fn f32(&mut self) -> f32 {
        f32::from_be_bytes(self.take())
    }
    fn f64(&mut self) -> f64 {
        f64::from_be_bytes(self.take())
    }
    fn time(&mut self) -> TimeTag {
        let coarse_s = self.u32();
        let fine = self.u16();
        TimeTag { coarse_s, fine }
    }
}

fn check_len(data: &[u8], expected: usize) -> Result<(), RecordError> {
    if data.len() == expected {
        Ok(())
    } else {
        Err(RecordError::Length {
            expected,
            found: data.len(),
        })
    }
}

/// Write the 6-octet CUC time code.
/// docs/icd.md §2.
///
/// # Errors
/// [`RecordError::BufferTooSmall`].
pub fn encode_time_code(t: TimeTag, out: &mut [u8]) -> Result<usize, RecordError> {
    let mut w = Writer::new(out);
    w.time(t);
    w.finish()
}

/// Read the 6-octet CUC time code from the start of a packet data field.
/// docs/icd.md §2.
///
/// # Errors
/// [`RecordError::Length`] when fewer than 6 octets are present.
pub fn decode_time_code(data: &[u8]) -> Result<TimeTag, RecordError> {
    let head = data.get(..TIME_CODE_LEN).ok_or(RecordError::Length {
        expected: TIME_CODE_LEN,
        found: data.len(),
    })?;
    Ok(Reader::new(head).time())
}

/// Encode a raw frame's user data (without its time, which is the secondary header).
/// docs/icd.md §3.1.
///
/// # Errors
/// [`RecordError::BufferTooSmall`].
pub fn encode_raw_frame(f: &RawSensorFrame, out: &mut [u8]) -> Result<usize, RecordError> {
    let mut w = Writer::new(out);
    for c in f.iru.counts {
        w.u16(c);
    }
    w.u8(f.iru.channel_failed);
    w.u8(u8::from(f.iru.high_rate));
    for s in &f.fhst {
        w.i16(s.h_counts);
        w.i16(s.v_counts);
        w.i16(s.magnitude_centimag);
        w.u8(s.flags);
    }
    for s in &f.fss {
        w.i16(s.alpha_counts);
        w.i16(s.beta_counts);
        w.u8(s.flags);
    }
    for t in f.temperatures_centi_c {
        w.i16(t);
    }
    w.finish()
}

/// Decode a raw frame's user data; `time` comes from the secondary header.
/// docs/icd.md §3.1.
///
/// # Errors
/// [`RecordError::Length`] or [`RecordError::BadEnum`] (rate-mode octet not 0/1).
pub fn decode_raw_frame(time: TimeTag, data: &[u8]) -> Result<RawSensorFrame, RecordError> {
    check_len(data, RAW_FRAME_LEN)?;
    let mut r = Reader::new(data);
    let mut counts = [0u16; 6];
    for c in &mut counts {
        *c = r.u16();
    }
    let channel_failed = r.u8();
    let high_rate = match r.u8() {
        0 => false,
        1 => true,
        _ => return Err(RecordError::BadEnum { offset: 13 }),
    };
    let mut fhst = [FhstSample::default(); 2];
    for s in &mut fhst {
        s.h_counts = r.i16();
        s.v_counts = r.i16();
        s.magnitude_centimag = r.i16();
        s.flags = r.u8();
    }
    let mut fss = [FssSample::default(); 2];
    for s in &mut fss {
        s.alpha_counts = r.i16();
        s.beta_counts = r.i16();
        s.flags = r.u8();
    }
    let mut temperatures_centi_c = [0i16; 5];
    for t in &mut temperatures_centi_c {
        *t = r.i16();
    }
    Ok(RawSensorFrame {
        time,
        iru: IruSample {
            counts,
            channel_failed,
            high_rate,
        },
        fhst,
        fss,
        temperatures_centi_c,
        tam: Default::default(),
        css: Default::default(),
        wheels: WheelSample::default(),
    })
}

/// Encode a magnetics frame's user data (without its time, which is the secondary header).
/// docs/icd.md §3.5.
///
/// # Errors
/// [`RecordError::BufferTooSmall`].
pub fn encode_magnetics(m: &MagneticsFrame, out: &mut [u8]) -> Result<usize, RecordError> {
    let mut w = Writer::new(out);
    for t in &m.tam {
        for c in t.field_counts {
            w.i16(c);
        }
        w.u8(t.flags);
    }
    for c in m.css.counts {
        w.u16(c);
    }
    w.u8(m.css.flags);
    w.finish()
}

/// Decode a magnetics frame's user data; `time` comes from the secondary header. Flag bits
/// other than bit 0 are reserved and kept as read.
/// docs/icd.md §3.5.
///
/// # Errors
/// [`RecordError::Length`].
pub fn decode_magnetics(time: TimeTag, data: &[u8]) -> Result<MagneticsFrame, RecordError> {
    check_len(data, MAGNETICS_LEN)?;
    let mut r = Reader::new(data);
    let mut tam = [TamSample::default(); TAMS];
    for t in &mut tam {
        t.field_counts = [r.i16(), r.i16(), r.i16()];
        t.flags = r.u8();
    }
    let mut counts = [0u16; CSS_EYES];
    for c in &mut counts {
        *c = r.u16();
    }
    let flags = r.u8();
    Ok(MagneticsFrame {
        time,
        tam,
        css: CssSample { counts, flags },
    })
}

/// Encode a wheel frame's user data (without its time, which is the secondary header).
/// docs/icd.md §3.6.
///
/// # Errors
/// [`RecordError::BufferTooSmall`].
pub fn encode_wheels(f: &WheelFrame, out: &mut [u8]) -> Result<usize, RecordError> {
    let mut w = Writer::new(out);
    for c in f.wheels.speed_counts {
        w.i16(c);
    }
    w.u8(f.wheels.speed_valid);
    for c in f.wheels.dipole_counts {
        w.i16(c);
    }
    w.u8(f.wheels.dipole_valid);
    w.finish()
}

/// Decode a wheel frame's user data; `time` comes from the secondary header. Validity bits
/// beyond the units (bits 4–7, 3–7) are reserved and kept as read.
/// docs/icd.md §3.6.
///
/// # Errors
/// [`RecordError::Length`].
pub fn decode_wheels(time: TimeTag, data: &[u8]) -> Result<WheelFrame, RecordError> {
    check_len(data, WHEEL_FRAME_LEN)?;
    let mut r = Reader::new(data);
    let mut speed_counts = [0i16; WHEELS];
    for c in &mut speed_counts {
        *c = r.i16();
    }
    let speed_valid = r.u8();
    let mut dipole_counts = [0i16; TORQUER_MONITORS];
    for c in &mut dipole_counts {
        *c = r.i16();
    }
    let dipole_valid = r.u8();
    Ok(WheelFrame {
        time,
        wheels: WheelSample {
            speed_counts,
            speed_valid,
            dipole_counts,
            dipole_valid,
        },
    })
}

/// Encode the housekeeping user data (without its time).
/// docs/icd.md §3.2.
///
/// # Errors
/// [`RecordError::BufferTooSmall`].
pub fn encode_housekeeping(h: &ObcHousekeeping, out: &mut [u8]) -> Result<usize, RecordError> {
    let mut w = Writer::new(out);
    for v in [
        h.q_acs_from_eci.x,
        h.q_acs_from_eci.y,
        h.q_acs_from_eci.z,
        h.q_acs_from_eci.w,
    ] {
        w.f64(v);
    }
    for v in h.bias_acs_rad_per_s {
        w.f64(v);
    }
    for v in h.covariance_diag {
        w.f64(v);
    }
    w.u8(h.filter_mode);
    w.u8(h.control_mode);
    w.u8(h.iru_config);
    w.u8(h.iru_high_rate_cmd);
    for v in h.wheel_torque_cmd_nm {
        w.f32(v);
    }
    for r in &h.residuals {
        w.u8(r.status as u8);
        w.f32(r.innovation_arcsec[0]);
        w.f32(r.innovation_arcsec[1]);
        w.u32(r.star_id);
    }
    w.u8(h.iru_excluded_mask);
    for v in h.counters.wire_order() {
        w.u32(v);
    }
    for v in h.table_crc {
        w.u32(v);
    }
    w.u8(h.table_pending_mask);
    w.finish()
}

/// Decode the housekeeping user data; `time` comes from the secondary header.
/// docs/icd.md §3.2.
///
/// # Errors
/// [`RecordError::Length`] or [`RecordError::BadEnum`] (residual status).
pub fn decode_housekeeping(time: TimeTag, data: &[u8]) -> Result<ObcHousekeeping, RecordError> {
    check_len(data, HOUSEKEEPING_LEN)?;
    let mut r = Reader::new(data);
    let q_acs_from_eci = Quat::new(r.f64(), r.f64(), r.f64(), r.f64());
    let bias_acs_rad_per_s = [r.f64(), r.f64(), r.f64()];
    let covariance_diag = [r.f64(), r.f64(), r.f64(), r.f64(), r.f64(), r.f64()];
    let filter_mode = r.u8();
    let control_mode = r.u8();
    let iru_config = r.u8();
    let iru_high_rate_cmd = r.u8();
    let wheel_torque_cmd_nm = [r.f32(), r.f32(), r.f32()];
    let mut residuals = [SensorResidual::default(); 4];
    for (i, res) in residuals.iter_mut().enumerate() {
        let offset = 120usize.saturating_add(i.saturating_mul(13));
        res.status = MeasurementStatus::from_u8(r.u8()).ok_or(RecordError::BadEnum { offset })?;
        res.innovation_arcsec = [r.f32(), r.f32()];
        res.star_id = r.u32();
    }
    let iru_excluded_mask = r.u8();
    let counters = Counters {
        cycles: r.u32(),
        rejected_inputs: r.u32(),
        gated_measurements: r.u32(),
        accepted_measurements: r.u32(),
        stars_identified: r.u32(),
        star_id_unmatched: r.u32(),
        star_id_ambiguous: r.u32(),
        time_tag_anomalies: r.u32(),
        iru_unusable_cycles: r.u32(),
        events_dropped: r.u32(),
    };
    let table_crc = [r.u32(), r.u32(), r.u32(), r.u32()];
    let table_pending_mask = r.u8();
    Ok(ObcHousekeeping {
        time,
        q_acs_from_eci,
        bias_acs_rad_per_s,
        covariance_diag,
        filter_mode,
        control_mode,
        iru_config,
        iru_high_rate_cmd,
        wheel_torque_cmd_nm,
        residuals,
        iru_excluded_mask,
        counters,
        table_crc,
        table_pending_mask,
    })
}

/// Encode an event's user data.
/// docs/icd.md §3.3.
///
/// # Errors
/// [`RecordError::BufferTooSmall`].
pub fn encode_event(e: &Event, out: &mut [u8]) -> Result<usize, RecordError> {
    let mut w = Writer::new(out);
    w.u16(e.id.code());
    w.u32(e.p1);
    w.u32(e.p2);
    w.finish()
}

/// Decode an event's user data.
/// docs/icd.md §3.3.
///
/// # Errors
/// [`RecordError::Length`] or [`RecordError::BadEnum`] for an unknown event code.
pub fn decode_event(data: &[u8]) -> Result<Event, RecordError> {
    check_len(data, EVENT_LEN)?;
    let mut r = Reader::new(data);
    let id = EventId::from_code(r.u16()).ok_or(RecordError::BadEnum { offset: 0 })?;
    Ok(Event {
        id,
        p1: r.u32(),
        p2: r.u32(),
    })
}

/// Encode an ephemeris record's user data (without its time).
/// docs/icd.md §3.4.
///
/// # Errors
/// [`RecordError::BufferTooSmall`].
pub fn encode_ephemeris(e: &EphemerisRecord, out: &mut [u8]) -> Result<usize, RecordError> {
    let mut w = Writer::new(out);
    for v in e.pos_eci_km.iter().chain(e.vel_eci_km_per_s.iter()) {
        w.f64(*v);
    }
    w.finish()
}

/// Decode an ephemeris record's user data; `time` comes from the secondary header.
/// docs/icd.md §3.4.
///
/// # Errors
/// [`RecordError::Length`].
pub fn decode_ephemeris(time: TimeTag, data: &[u8]) -> Result<EphemerisRecord, RecordError> {
    check_len(data, EPHEMERIS_LEN)?;
    let mut r = Reader::new(data);
    Ok(EphemerisRecord {
        time,
        pos_eci_km: [r.f64(), r.f64(), r.f64()],
        vel_eci_km_per_s: [r.f64(), r.f64(), r.f64()],
    })
}

#[cfg(test)]
#[allow(clippy::field_reassign_with_default)]
mod tests {
    use super::*;

    #[test]
    fn raw_frame_round_trip_and_length() {
        let mut f = RawSensorFrame::default();
        f.time = TimeTag {
            coarse_s: 1_049_000_000,
            fine: 123,
        };
        f.iru.counts = [1, 65535, 3, 4, 5, 6];
        f.iru.high_rate = true;
        f.fhst[1].h_counts = -1800;
        f.fss[0].beta_counts = 7999;
        f.temperatures_centi_c[4] = -1234;
        let mut buf = [0u8; 64];
        let n = encode_raw_frame(&f, &mut buf).unwrap();
        assert_eq!(n, RAW_FRAME_LEN);
        assert_eq!(decode_raw_frame(f.time, &buf[..n]), Ok(f));
        assert!(decode_raw_frame(f.time, &buf[..n - 1]).is_err());
    }

    #[test]
    fn housekeeping_round_trip_and_length() {
        let mut h = ObcHousekeeping::default();
        h.q_acs_from_eci = Quat::new(0.1, 0.2, 0.3, 0.927);
        h.residuals[2].status = MeasurementStatus::Gated;
        h.residuals[0].star_id = 32349;
        h.counters.cycles = 77;
        h.table_crc[3] = 0xdead_beef;
        let mut buf = [0u8; 256];
        let n = encode_housekeeping(&h, &mut buf).unwrap();
        assert_eq!(n, HOUSEKEEPING_LEN);
        assert_eq!(decode_housekeeping(h.time, &buf[..n]), Ok(h));
        let mut small = [0u8; 100];
        assert_eq!(
            encode_housekeeping(&h, &mut small),
            Err(RecordError::BufferTooSmall)
        );
    }

    #[test]
    fn magnetics_round_trip_and_length() {
        let mut f = RawSensorFrame::default();
        f.time.coarse_s = 1_049_000_001;
        f.tam[0].field_counts = [-1234, 0, 2047];
        f.tam[0].flags = 1;
        f.tam[1].field_counts = [-2048, 7, -1];
        f.css.counts = [0, 1000, 65535, 3, 4, 5];
        f.css.flags = 1;
        let m = MagneticsFrame::of_raw_frame(&f);
        assert!(m.has_data());
        let mut buf = [0u8; 64];
        let n = encode_magnetics(&m, &mut buf).unwrap();
        assert_eq!(n, MAGNETICS_LEN);
        assert_eq!(decode_magnetics(m.time, &buf[..n]), Ok(m));
        assert!(decode_magnetics(m.time, &buf[..n - 1]).is_err());
        assert!(!MagneticsFrame::default().has_data());
    }

    #[test]
    fn wheel_frame_round_trip_and_length() {
        let mut f = RawSensorFrame::default();
        f.time.coarse_s = 1_049_000_001;
        f.wheels.speed_counts = [-29_842, 0, 32_767, -1];
        f.wheels.speed_valid = 0x0F;
        f.wheels.dipole_counts = [-4_000, 1, 3_999];
        f.wheels.dipole_valid = 0x05;
        let m = WheelFrame::of_raw_frame(&f);
        assert!(m.has_data());
        let mut buf = [0u8; 64];
        let n = encode_wheels(&m, &mut buf).unwrap();
        assert_eq!(n, WHEEL_FRAME_LEN);
        assert_eq!(decode_wheels(m.time, &buf[..n]), Ok(m));
        assert!(decode_wheels(m.time, &buf[..n - 1]).is_err());
        assert!(!WheelFrame::default().has_data());
        let mut small = [0u8; WHEEL_FRAME_LEN - 1];
        assert_eq!(
            encode_wheels(&m, &mut small),
            Err(RecordError::BufferTooSmall)
        );
    }

    #[test]
    fn event_and_ephemeris_round_trip() {
        let e = Event {
            id: EventId::TableRejected,
            p1: 1,
            p2: 9,
        };
        let mut buf = [0u8; 64];
        let n = encode_event(&e, &mut buf).unwrap();
        assert_eq!(n, EVENT_LEN);
        assert_eq!(decode_event(&buf[..n]), Ok(e));
        let eph = EphemerisRecord {
            time: TimeTag::default(),
            pos_eci_km: [6833.0, 1.0, -2.0],
            vel_eci_km_per_s: [0.0, 7.6, 0.1],
        };
        let n = encode_ephemeris(&eph, &mut buf).unwrap();
        assert_eq!(n, EPHEMERIS_LEN);
        assert_eq!(decode_ephemeris(eph.time, &buf[..n]), Ok(eph));
    }
}
