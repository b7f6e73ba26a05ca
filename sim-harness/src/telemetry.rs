//! # telemetry.bin writer: CCSDS space packets in the ICD order (docs/icd.md §1–4)
//!
//! Framing with the `spacepackets` crate: primary header version 0, type TM, secondary
//! header flag 1, the record's APID, sequence flags "unsegmented", a 14-bit sequence count
//! per APID (from 0, wrapping at 16384), data length = data-field octets − 1. The data field
//! is the 6-octet CUC time code (`fsw_core::telemetry::encode_time_code`) followed by the
//! user data of `fsw_core::telemetry`'s encoders. Within a cycle the order is raw frame
//! (0x010), the magnetics frame (0x013) when the scenario has `[magnetics] enabled`, the
//! wheel frame (0x014) when it has `[wheel_tachometers] enabled`, ephemeris (0x020) when due, housekeeping (0x011), events (0x012), all with the cycle's time
//! code.
//!
//! The writer never allocates per packet (one fixed scratch buffer) and writes into any
//! `io::Write` (a `BufWriter<File>` for runs, `io::sink()` for the bench).

use std::io::Write;

use arbitrary_int::{u11, u14};
use spacepackets::{PacketId, PacketSequenceControl, PacketType, SequenceFlags, SpHeader};

use fsw_core::events::Event;
use fsw_core::raw::{RawSensorFrame, TimeTag};
use fsw_core::telemetry::{
    encode_ephemeris, encode_event, encode_housekeeping, encode_magnetics, encode_raw_frame,
    encode_time_code, encode_wheels, EphemerisRecord, MagneticsFrame, ObcHousekeeping, WheelFrame,
    APID_EPHEMERIS, APID_EVENT, APID_HOUSEKEEPING, APID_MAGNETICS, APID_RAW_SENSORS, APID_WHEELS,
    TIME_CODE_LEN,
};

/// Primary header length.
pub const PRIMARY_HEADER_LEN: usize = 6;
/// Scratch buffer size (largest packet: housekeeping, 6 + 6 + 230).
const SCRATCH: usize = 256;

// Per-APID sequence counters, in the order of `fsw_core::telemetry::APIDS`.
use fsw_core::telemetry::APIDS;

/// Packet writer.
pub struct PacketWriter<W: Write> {
    out: W,
    seq: [u16; APIDS.len()],
    buf: [u8; SCRATCH],
    packets: u64,
    bytes: u64,
}

impl<W: Write> PacketWriter<W> {
    /// A writer into `out`, all sequence counts at 0.
    pub fn new(out: W) -> Self {
        Self {
            out,
            seq: [0; APIDS.len()],
            buf: [0; SCRATCH],
            packets: 0,
            bytes: 0,
        }
    }

    /// Packets written.
    #[must_use]
    pub fn packets(&self) -> u64 {
        self.packets
    }

    /// Octets written.
    #[must_use]
    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    /// Flush and return the inner writer.
    ///
    /// # Errors
    /// I/O.
    pub fn finish(mut self) -> std::io::Result<W> {
        self.out.flush()?;
        Ok(self.out)
    }

    /// Frame the user data already in `buf[12..12 + user_len]` and write the packet.
    fn emit(&mut self, apid: u16, time: TimeTag, user_len: usize) -> std::io::Result<()> {
        let slot = APIDS.iter().position(|a| *a == apid).unwrap_or(0);
        let data_field = TIME_CODE_LEN + user_len;
        let total = PRIMARY_HEADER_LEN + data_field;
        let err = |what: &str| std::io::Error::other(format!("telemetry framing: {what}"));
        #[allow(clippy::cast_possible_truncation)]
        let header = SpHeader::new(
            PacketId::new(PacketType::Tm, true, u11::new(apid & 0x7ff)),
            PacketSequenceControl::new(
                SequenceFlags::Unsegmented,
                u14::new(self.seq[slot] & 0x3fff),
            ),
            (data_field - 1) as u16,
        );
        header
            .write_to_slice(&mut self.buf[..PRIMARY_HEADER_LEN])
            .map_err(|_| err("primary header"))?;
        encode_time_code(
            time,
            &mut self.buf[PRIMARY_HEADER_LEN..PRIMARY_HEADER_LEN + TIME_CODE_LEN],
        )
        .map_err(|_| err("time code"))?;
        self.out.write_all(&self.buf[..total])?;
        self.seq[slot] = (self.seq[slot] + 1) & 0x3fff;
        self.packets += 1;
        self.bytes += total as u64;
        Ok(())
    }

    fn user(&mut self) -> &mut [u8] {
        &mut self.buf[PRIMARY_HEADER_LEN + TIME_CODE_LEN..]
    }

    /// Raw sensor frame (APID 0x010).
    ///
    /// # Errors
    /// I/O or encoding.
    pub fn raw(&mut self, frame: &RawSensorFrame) -> std::io::Result<()> {
        let n = encode_raw_frame(frame, self.user())
            .map_err(|e| std::io::Error::other(format!("raw frame: {e:?}")))?;
        self.emit(APID_RAW_SENSORS, frame.time, n)
    }

    /// Magnetics frame (APID 0x013): TAM1, TAM2 and the CSS eyes, with the raw frame's time.
    ///
    /// # Errors
    /// I/O or encoding.
    pub fn magnetics(&mut self, m: &MagneticsFrame) -> std::io::Result<()> {
        let n = encode_magnetics(m, self.user())
            .map_err(|e| std::io::Error::other(format!("magnetics frame: {e:?}")))?;
        self.emit(APID_MAGNETICS, m.time, n)
    }

    /// Wheel frame (APID 0x014): the tachometers and bar monitors, with the raw frame's time.
    ///
    /// # Errors
    /// I/O or encoding.
    pub fn wheels(&mut self, w: &WheelFrame) -> std::io::Result<()> {
        let n = encode_wheels(w, self.user())
            .map_err(|e| std::io::Error::other(format!("wheel frame: {e:?}")))?;
        self.emit(APID_WHEELS, w.time, n)
    }

    /// Definitive orbit (APID 0x020).
    ///
    /// # Errors
    /// I/O or encoding.
    pub fn ephemeris(&mut self, rec: &EphemerisRecord) -> std::io::Result<()> {
        let n = encode_ephemeris(rec, self.user())
            .map_err(|e| std::io::Error::other(format!("ephemeris: {e:?}")))?;
        self.emit(APID_EPHEMERIS, rec.time, n)
    }

    /// OBC housekeeping (APID 0x011).
    ///
    /// # Errors
    /// I/O or encoding.
    pub fn housekeeping(&mut self, hk: &ObcHousekeeping) -> std::io::Result<()> {
        let n = encode_housekeeping(hk, self.user())
            .map_err(|e| std::io::Error::other(format!("housekeeping: {e:?}")))?;
        self.emit(APID_HOUSEKEEPING, hk.time, n)
    }

    /// One event (APID 0x012) with the cycle's time code.
    ///
    /// # Errors
    /// I/O or encoding.
    pub fn event(&mut self, time: TimeTag, e: &Event) -> std::io::Result<()> {
        let n = encode_event(e, self.user())
            .map_err(|err| std::io::Error::other(format!("event: {err:?}")))?;
        self.emit(APID_EVENT, time, n)
    }
}
