//! # TP: telemetry processing (paper §3.3)
//!
//! Reads `telemetry.bin` (CCSDS space packets, `docs/icd.md`) into engineering records. A
//! damaged file still yields everything readable: a packet that is truncated, has an unknown
//! APID, a wrong length for its APID or a field that does not decode is counted, reported with
//! its file offset, and skipped; after garbage the reader re-synchronises on the next offset
//! where a plausible packet header (version 0, TM, secondary header, known APID, the exact
//! length of that APID) is followed by another plausible header or the end of the file.
//! Duplicated packets (same APID, sequence count and time as one already read) are dropped;
//! time going backwards is reported; records are finally sorted by time (stable), so reordered
//! packets are put back in order and the reordering is reported.
//!
//! The magnetics frame (APID 0x013, format version 2 of `docs/icd.md` §3.5) and the wheel
//! frame (APID 0x014, version 4, §3.6) are read like the others; a file without them reads as
//! before, with no such records.

use fsw_core::events::Event;
use fsw_core::raw::{RawSensorFrame, TimeTag};
use fsw_core::telemetry::{
    decode_ephemeris, decode_event, decode_housekeeping, decode_magnetics, decode_raw_frame,
    decode_time_code, decode_wheels, EphemerisRecord, MagneticsFrame, ObcHousekeeping, RecordError,
    WheelFrame, APID_EPHEMERIS, APID_EVENT, APID_HOUSEKEEPING, APID_MAGNETICS, APID_RAW_SENSORS,
    APID_WHEELS, EPHEMERIS_LEN, EVENT_LEN, HOUSEKEEPING_LEN, MAGNETICS_LEN, RAW_FRAME_LEN,
    TIME_CODE_LEN, WHEEL_FRAME_LEN,
};
use serde::Serialize;
use std::collections::HashMap;
use std::path::Path;

/// CCSDS primary header length.
const PRIMARY_HEADER_LEN: usize = 6;

/// One skipped region of the file.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Skipped {
    /// File offset of the first skipped octet.
    pub offset: usize,
    /// Octets skipped.
    pub len: usize,
    /// Why.
    pub reason: String,
}

/// Packets decoded per APID, after duplicates and time-code outliers were dropped: the
/// lengths of [`Telemetry`]'s record lists (docs/icd.md §3).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct PacketCounts {
    /// Raw sensor frames (APID 0x010).
    #[serde(rename = "packets_raw")]
    pub raw: usize,
    /// Housekeeping packets (APID 0x011).
    #[serde(rename = "packets_housekeeping")]
    pub housekeeping: usize,
    /// Event packets (APID 0x012).
    #[serde(rename = "packets_event")]
    pub event: usize,
    /// Ephemeris records (APID 0x020).
    #[serde(rename = "packets_ephemeris")]
    pub ephemeris: usize,
    /// Magnetics frames (APID 0x013, TAM and CSS words); 0 for a file without them.
    #[serde(rename = "packets_magnetics")]
    pub magnetics: usize,
    /// Wheel frames (APID 0x014, tachometer and bar-monitor words); 0 for a file without
    /// them.
    #[serde(rename = "packets_wheels")]
    pub wheels: usize,
}

impl PacketCounts {
    /// The counts of `tm`'s record lists.
    #[must_use]
    pub fn of(tm: &Telemetry) -> Self {
        Self {
            raw: tm.raw.len(),
            housekeeping: tm.housekeeping.len(),
            event: tm.events.len(),
            ephemeris: tm.ephemeris.len(),
            magnetics: tm.magnetics.len(),
            wheels: tm.wheels.len(),
        }
    }

    /// `(APID, count)` for every APID of the downlink, in [`fsw_core::telemetry::APIDS`]'
    /// order: a check that sums over it covers an APID added later.
    #[must_use]
    pub fn by_apid(&self) -> [(u16, usize); 6] {
        let counts = [
            self.raw,
            self.housekeeping,
            self.event,
            self.ephemeris,
            self.magnetics,
            self.wheels,
        ];
        let mut out = [(0, 0); 6];
        for ((o, apid), n) in out.iter_mut().zip(fsw_core::telemetry::APIDS).zip(counts) {
            *o = (apid, n);
        }
        out
    }
}

/// What the reader found, for reports and exit codes.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct TpReport {
    /// File size in octets.
    pub file_len: usize,
    /// Packets decoded per APID (report.json keys `packets_raw` … `packets_wheels`).
    #[serde(flatten)]
    pub packets: PacketCounts,
    /// Regions skipped (truncated, unknown, corrupt), with offsets.
    pub skipped: Vec<Skipped>,
    /// Duplicated packets dropped (offsets): identical octets to an earlier copy.
    pub duplicates: Vec<usize>,
    /// Packets with the key (APID, sequence count, time) of an earlier one but other octets:
    /// both kept (offsets of the later ones).
    pub duplicate_conflicts: Vec<usize>,
    /// Copies of an earlier packet (same APID, sequence count and data) under another time
    /// code, less than [`RETIMED_COPY_WINDOW_S`] apart: dropped like a duplicate (their
    /// offsets are in `duplicates` too), the first copy kept. `(offset, time s, the first
    /// copy's time s)`. A stream that repeats packets with shifted time codes would otherwise
    /// count every star and gyro sample twice.
    pub retimed_copies: Vec<(usize, f64, f64)>,
    /// Places where a packet's time was earlier than the previous packet of the same APID:
    /// `(offset, previous time s, time s)` (after the time-code outliers were dropped).
    pub time_reversals: Vec<(usize, f64, f64)>,
    /// Packets dropped because their time code is an isolated outlier (a damaged time code:
    /// far from both neighbours of its APID, which agree with each other).
    pub time_outliers: Vec<TimeOutlier>,
    /// Backward jumps of an APID's time codes too large for reordered packets, after which the
    /// packets continue from the earlier time (a block with shifted time codes). Re-sorting
    /// would interleave two stretches of flight: the run check refuses such a file.
    pub time_jumps: Vec<TimeJump>,
}

impl TpReport {
    /// Record the octets `offset..end` as skipped, and why.
    fn skip(&mut self, offset: usize, end: usize, reason: impl Into<String>) {
        self.skipped.push(Skipped {
            offset,
            len: end - offset,
            reason: reason.into(),
        });
    }
}

/// A packet dropped for its time code.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TimeOutlier {
    /// File offset of the packet.
    pub offset: usize,
    /// Its length, octets.
    pub len: usize,
    /// APID.
    pub apid: u16,
    /// Its time code, s (TAI since 1958).
    pub time_s: f64,
    /// The times of the APID's packets before and after it, s.
    pub neighbours_s: (f64, f64),
}

/// A backward jump of one APID's time codes (file order).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TimeJump {
    /// File offset of the first packet after the jump.
    pub offset: usize,
    /// APID.
    pub apid: u16,
    /// Time of the packet before, s.
    pub from_s: f64,
    /// Time of the packet at `offset`, s.
    pub to_s: f64,
}

/// The largest backward step of an APID's time codes that reordered packets explain: this
/// many median steps of that APID (4 cycles for the 1 s raw frames), and at least
/// [`MIN_TIME_TOLERANCE_S`]. An isolated packet further than this from both neighbours is a
/// damaged time code; a larger backward step followed by consistent packets is a jump.
pub const TIME_TOLERANCE_STEPS: f64 = 4.0;

/// Lower bound of the time tolerance, s (see [`TIME_TOLERANCE_STEPS`]).
pub const MIN_TIME_TOLERANCE_S: f64 = 2.0;

/// The first or last packet of an APID further than this many median steps from its one
/// neighbour (and at least [`FAR_TIME_S`]) has a damaged time code: a gap that long right at
/// the start or the end of a file is not credible, a flipped high bit of the time code is.
pub const FAR_TIME_STEPS: f64 = 1000.0;

/// Lower bound of the far distance of the first or last packet, s (one hour).
pub const FAR_TIME_S: f64 = 3600.0;

impl TpReport {
    /// Octets that could not be used.
    #[must_use]
    pub fn skipped_octets(&self) -> usize {
        self.skipped.iter().map(|s| s.len).sum()
    }

    /// True if nothing was skipped, duplicated or out of order.
    #[must_use]
    pub fn is_clean(&self) -> bool {
        self.skipped.is_empty()
            && self.duplicates.is_empty()
            && self.time_reversals.is_empty()
            && self.time_outliers.is_empty()
            && self.time_jumps.is_empty()
    }
}

/// Decoded telemetry in engineering records, sorted by time.
#[derive(Clone, Debug, Default)]
pub struct Telemetry {
    /// Raw sensor frames (APID 0x010).
    pub raw: Vec<RawSensorFrame>,
    /// OBC housekeeping (APID 0x011).
    pub housekeeping: Vec<ObcHousekeeping>,
    /// Events with their time (APID 0x012).
    pub events: Vec<(TimeTag, Event)>,
    /// Definitive orbit (APID 0x020).
    pub ephemeris: Vec<EphemerisRecord>,
    /// Magnetics frames (APID 0x013): TAM1, TAM2, CSS words at the raw frames' time codes.
    pub magnetics: Vec<MagneticsFrame>,
    /// Wheel frames (APID 0x014): tachometers and bar monitors at the raw frames' time codes.
    pub wheels: Vec<WheelFrame>,
    /// What the reader found.
    pub report: TpReport,
}

/// Errors that stop telemetry processing altogether.
#[derive(Debug, thiserror::Error)]
pub enum TpError {
    /// The file could not be read.
    #[error("cannot read telemetry file {path}")]
    Io {
        /// Path.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
}

/// Length of a whole packet of `apid` (primary header, time code, user data; docs/icd.md
/// §2–3), `None` for an APID outside the ICD.
#[must_use]
pub fn packet_len(apid: u16) -> Option<usize> {
    user_len(apid).map(|n| PRIMARY_HEADER_LEN + TIME_CODE_LEN + n)
}

fn user_len(apid: u16) -> Option<usize> {
    match apid {
        APID_RAW_SENSORS => Some(RAW_FRAME_LEN),
        APID_HOUSEKEEPING => Some(HOUSEKEEPING_LEN),
        APID_EVENT => Some(EVENT_LEN),
        APID_EPHEMERIS => Some(EPHEMERIS_LEN),
        APID_MAGNETICS => Some(MAGNETICS_LEN),
        APID_WHEELS => Some(WHEEL_FRAME_LEN),
        _ => None,
    }
}

/// Parsed primary header fields.
struct Header {
    apid: u16,
    seq: u16,
    total_len: usize,
}

fn parse_header(bytes: &[u8]) -> Option<Header> {
    let (sp, _) = spacepackets::SpHeader::from_be_bytes(bytes.get(..PRIMARY_HEADER_LEN)?).ok()?;
    use spacepackets::CcsdsPacket;
    let apid = sp.apid().value();
    let seq = sp.seq_count().value();
    let total_len = sp.packet_len();
    let ok = sp.ccsds_version().value() == 0
        && sp.packet_type() == spacepackets::PacketType::Tm
        && sp.sec_header_flag();
    ok.then_some(Header {
        apid,
        seq,
        total_len,
    })
}

/// A header is plausible when it is well formed and has the exact length of a known APID.
fn plausible_at(bytes: &[u8], at: usize) -> Option<Header> {
    let h = parse_header(bytes.get(at..)?)?;
    let expected = PRIMARY_HEADER_LEN + TIME_CODE_LEN + user_len(h.apid)?;
    (h.total_len == expected).then_some(h)
}

/// First confirmed packet start in `[from, before)` (a plausible header followed by another
/// plausible header or the end of the file), if any.
fn confirmed_start_before(bytes: &[u8], from: usize, before: usize) -> Option<usize> {
    (from..before.min(bytes.len())).find(|&at| {
        plausible_at(bytes, at).is_some_and(|h| {
            let next = at + h.total_len;
            next == bytes.len() || (next < bytes.len() && plausible_at(bytes, next).is_some())
        })
    })
}

/// Whether the whole packet at `at` (header `h`) is in the file and decodes: time code and
/// record fields valid.
fn decodes_at(bytes: &[u8], at: usize, h: &Header) -> bool {
    let Some(data) = bytes.get(at + PRIMARY_HEADER_LEN..at + h.total_len) else {
        return false;
    };
    let Ok(time) = decode_time_code(data) else {
        return false;
    };
    let user = &data[TIME_CODE_LEN..];
    match h.apid {
        APID_RAW_SENSORS => decode_raw_frame(time, user).is_ok(),
        APID_HOUSEKEEPING => decode_housekeeping(time, user).is_ok(),
        APID_EVENT => decode_event(user).is_ok(),
        APID_EPHEMERIS => decode_ephemeris(time, user).is_ok(),
        APID_MAGNETICS => decode_magnetics(time, user).is_ok(),
        APID_WHEELS => decode_wheels(time, user).is_ok(),
        _ => false,
    }
}

/// Next packet start at or after `from` once the stream is known to be damaged: a plausible
/// header followed by another plausible header or the end of the file, or a plausible header
/// whose whole packet decodes (so that an intact packet between two damaged regions is not
/// lost for want of a second header).
fn resync(bytes: &[u8], from: usize) -> usize {
    let mut at = from;
    while at < bytes.len() {
        if let Some(h) = plausible_at(bytes, at) {
            let next = at + h.total_len;
            if next == bytes.len()
                || (next < bytes.len() && plausible_at(bytes, next).is_some())
                || decodes_at(bytes, at, &h)
            {
                return at;
            }
        }
        at += 1;
    }
    bytes.len()
}

/// Read and decode a telemetry file.
///
/// # Errors
/// Only when the file cannot be read; damage inside the file is reported, not an error.
pub fn read_file(path: &Path) -> Result<Telemetry, TpError> {
    let bytes = std::fs::read(path).map_err(|source| TpError::Io {
        path: path.display().to_string(),
        source,
    })?;
    Ok(decode(&bytes))
}

/// The OBC housekeeping packets (APID 0x011) of `path`, for a reader that needs nothing else
/// (the calibration report's bias plot). Why not [`read_file`]: its damage checks look for a
/// packet start inside every packet, and six months of telemetry took 3.7 s to decode in full
/// a second time. Here a clean stream is walked header to header and only the housekeeping is
/// decoded; at the first sign of damage (a header that is not a known APID's exact length, a
/// cut packet, a time code that does not decode or does not advance) the file is decoded by
/// [`decode`] and its housekeeping returned, so a damaged file gets the chain's own packets.
///
/// # Errors
/// The file cannot be read.
pub fn read_housekeeping(path: &Path) -> Result<Vec<ObcHousekeeping>, TpError> {
    let bytes = std::fs::read(path).map_err(|source| TpError::Io {
        path: path.display().to_string(),
        source,
    })?;
    Ok(housekeeping_of_clean(&bytes).unwrap_or_else(|| decode(&bytes).housekeeping))
}

/// The housekeeping of a stream without any damage; `None` at the first anomaly.
fn housekeeping_of_clean(bytes: &[u8]) -> Option<Vec<ObcHousekeeping>> {
    let mut out: Vec<ObcHousekeeping> = Vec::new();
    let mut at = 0usize;
    while at < bytes.len() {
        let h = plausible_at(bytes, at)?;
        let data = bytes.get(at + PRIMARY_HEADER_LEN..at + h.total_len)?;
        let time = decode_time_code(data).ok()?;
        if h.apid == APID_HOUSEKEEPING {
            let hk = decode_housekeeping(time, &data[TIME_CODE_LEN..]).ok()?;
            if out
                .last()
                .is_some_and(|p| p.time.seconds() >= hk.time.seconds())
            {
                return None;
            }
            out.push(hk);
        }
        at += h.total_len;
    }
    Some(out)
}

/// Two packets of one APID with the same sequence count and data this close in time are one
/// packet sent twice (a sequence count comes back after 16,384 packets of its APID: hours).
pub const RETIMED_COPY_WINDOW_S: f64 = 60.0;

/// The last packet of each APID and sequence count (offset, length, time), for finding a
/// packet repeated under another time code: at most 6 × 16,384 entries, and only as many as
/// the file has packets (a short file or a fuzz input allocates little).
struct LastBySeq(HashMap<(u16, u16), (usize, usize, TimeTag)>);

impl LastBySeq {
    fn new() -> Self {
        Self(HashMap::new())
    }

    /// Remember the packet at `at`; the earlier packet's time when it is the same packet
    /// (APID, sequence count, octets after the time code) under another time code within
    /// [`RETIMED_COPY_WINDOW_S`].
    fn retimed_copy(
        &mut self,
        bytes: &[u8],
        h: &Header,
        at: usize,
        time: TimeTag,
    ) -> Option<TimeTag> {
        let user = |p: usize, n: usize| bytes.get(p + PRIMARY_HEADER_LEN + TIME_CODE_LEN..p + n);
        let previous = self
            .0
            .insert((h.apid, h.seq & 0x3fff), (at, h.total_len, time))?;
        let (p, n, t) = previous;
        let same = n == h.total_len && user(p, n) == user(at, h.total_len);
        if same && t != time && (t.seconds() - time.seconds()).abs() < RETIMED_COPY_WINDOW_S {
            // The first copy stays the one remembered (a third copy is compared with it).
            self.0.insert((h.apid, h.seq & 0x3fff), previous);
            return Some(t);
        }
        None
    }
}

/// Decode telemetry from memory (see the module doc for the damage policy).
#[must_use]
pub fn decode(bytes: &[u8]) -> Telemetry {
    let mut tm = Telemetry::default();
    tm.report.file_len = bytes.len();
    let mut seen: HashMap<(u16, u16, u32, u16), usize> = HashMap::new();
    // Per APID slot (`SLOT_APIDS`), in file order: (offset, length, sequence count).
    let mut placed: [Vec<(usize, usize, u16)>; SLOTS] = Default::default();
    let mut last_by_seq = LastBySeq::new();
    let mut at = 0usize;
    while at < bytes.len() {
        let Some(h) = parse_header(&bytes[at..]) else {
            let next = resync(bytes, at + 1);
            let reason = if bytes.len() - at < PRIMARY_HEADER_LEN {
                "truncated primary header at end of file"
            } else {
                "not a valid TM packet header"
            };
            tm.report.skip(at, next, reason);
            at = next;
            continue;
        };
        let Some(expected_user) = user_len(h.apid) else {
            // Unknown APID: trust its length if it fits, otherwise resync.
            // Never skip past a confirmed known-APID packet inside the claimed length.
            let end = at + h.total_len;
            // (Searching only inside the claimed length keeps decoding linear: REL-3.)
            let next = if end <= bytes.len()
                && (end == bytes.len() || plausible_at(bytes, end).is_some())
            {
                confirmed_start_before(bytes, at + 1, end).unwrap_or(end)
            } else {
                resync(bytes, at + 1)
            };
            tm.report
                .skip(at, next, format!("unknown APID 0x{:03x}", h.apid));
            at = next;
            continue;
        };
        let expected_total = PRIMARY_HEADER_LEN + TIME_CODE_LEN + expected_user;
        if h.total_len != expected_total {
            let next = resync(bytes, at + 1);
            tm.report.skip(
                at,
                next,
                format!(
                    "APID 0x{:03x}: packet length {} but the ICD fixes {}",
                    h.apid, h.total_len, expected_total
                ),
            );
            at = next;
            continue;
        }
        if at + h.total_len > bytes.len() {
            // Cut by the end of the file, or by a drop-out before packets that end it: those
            // packets start inside the claimed length.
            let next = resync(bytes, at + 1);
            tm.report.skip(
                at,
                next,
                format!(
                    "APID 0x{:03x}: truncated packet ({} of {} octets)",
                    h.apid,
                    bytes.len() - at,
                    h.total_len
                ),
            );
            at = next;
            continue;
        }
        // A packet cut short by a drop-out or splice would swallow the packets after it:
        // when its end is not a packet boundary, look for a confirmed packet start inside it.
        // Even when its end lands on a packet boundary or the end of the file (a splice can
        // do that), a confirmed packet start inside it means it was cut.
        let end = at + h.total_len;
        if end <= bytes.len() {
            if let Some(q) = confirmed_start_before(bytes, at + 1, end) {
                tm.report.skip(
                    at,
                    q,
                    format!(
                        "APID 0x{:03x}: packet cut short (a packet starts inside it)",
                        h.apid
                    ),
                );
                at = q;
                continue;
            }
        }
        let data = &bytes[at + PRIMARY_HEADER_LEN..at + h.total_len];
        let time = match decode_time_code(data) {
            Ok(t) => t,
            Err(_) => {
                tm.report.skip(at, at + h.total_len, "bad time code");
                at += h.total_len;
                continue;
            }
        };
        let user = &data[TIME_CODE_LEN..];
        // A duplicate is a packet whose octets equal an earlier copy's; the same key with
        // other octets (e.g. a flipped sequence count) is kept and reported as a conflict.
        let key = (h.apid, h.seq, time.coarse_s, time.fine);
        if let Some(&first) = seen.get(&key) {
            if bytes.get(first..first + h.total_len) == bytes.get(at..at + h.total_len) {
                tm.report.duplicates.push(at);
                at += h.total_len;
                continue;
            }
            tm.report.duplicate_conflicts.push(at);
        } else {
            seen.insert(key, at);
        }
        if let Some(first) = last_by_seq.retimed_copy(bytes, &h, at, time) {
            tm.report.duplicates.push(at);
            tm.report
                .retimed_copies
                .push((at, time.seconds(), first.seconds()));
            at += h.total_len;
            continue;
        }
        let decoded = store_record(&mut tm, h.apid, time, user);
        if let Ok(slot) = decoded {
            placed[slot].push((at, h.total_len, h.seq));
        }
        if let Err(e) = decoded {
            tm.report.skip(
                at,
                at + h.total_len,
                format!("APID 0x{:03x}: field does not decode ({e})", h.apid),
            );
        }
        at += h.total_len;
    }
    screen_time_codes(&mut tm, &placed);
    tm.raw.sort_by_key(|r| r.time);
    tm.housekeeping.sort_by_key(|r| r.time);
    tm.events.sort_by_key(|(t, _)| *t);
    tm.ephemeris.sort_by_key(|r| r.time);
    tm.magnetics.sort_by_key(|r| r.time);
    tm.wheels.sort_by_key(|r| r.time);
    tm
}

/// Number of APID slots of the reader ([`SLOT_APIDS`]).
const SLOTS: usize = 6;

/// The APIDs in slot order (the index of `placed` in [`decode`]).
const SLOT_APIDS: [u16; SLOTS] = fsw_core::telemetry::APIDS;

/// Decode one packet's user data (a known APID of the right length) into its list in `tm`,
/// returning its slot in [`SLOT_APIDS`].
fn store_record(
    tm: &mut Telemetry,
    apid: u16,
    time: TimeTag,
    user: &[u8],
) -> Result<usize, RecordError> {
    match apid {
        APID_RAW_SENSORS => decode_raw_frame(time, user).map(|x| keep(&mut tm.raw, x, 0)),
        APID_HOUSEKEEPING => {
            decode_housekeeping(time, user).map(|x| keep(&mut tm.housekeeping, x, 1))
        }
        APID_EVENT => decode_event(user).map(|x| keep(&mut tm.events, (time, x), 2)),
        APID_MAGNETICS => decode_magnetics(time, user).map(|x| keep(&mut tm.magnetics, x, 4)),
        APID_WHEELS => decode_wheels(time, user).map(|x| keep(&mut tm.wheels, x, 5)),
        _ => decode_ephemeris(time, user).map(|x| keep(&mut tm.ephemeris, x, 3)),
    }
}

/// `record` appended to `list`; its slot `slot` returned.
fn keep<T>(list: &mut Vec<T>, record: T, slot: usize) -> usize {
    list.push(record);
    slot
}

/// Largest forward step of the CCSDS sequence count between two packets of one APID that
/// counts as "in sequence" (a few packets may be lost between them).
const SEQ_IN_ORDER_MAX: u16 = 64;

/// Sequence count `b` follows `a` (1..=[`SEQ_IN_ORDER_MAX`] later, 14-bit wrap-around).
fn follows(a: u16, b: u16) -> bool {
    let d = b.wrapping_sub(a) & 0x3fff;
    (1..=SEQ_IN_ORDER_MAX).contains(&d)
}

/// Which records of one APID (times and sequence counts in file order) are isolated time-code
/// outliers, and the backward jumps among the others: `(outlier indices, jump indices)`.
///
/// In a well-formed file an APID's times never decrease, so a packet in sequence (its
/// sequence count 1–64 after its predecessor's and 1–64 before its successor's: it is where
/// it belongs) lies between its neighbours' times. It is an outlier (a damaged time code)
/// when it lies outside them by more than the tolerance while they agree with each other.
/// The first and the last packet have one neighbour: they are outliers when they are out of
/// order with it by more than the tolerance, or more than [`FAR_TIME_STEPS`] median steps
/// (and at least [`FAR_TIME_S`]) from it. A jump is a backward time step beyond the tolerance
/// between packets in sequence: the packets that follow carry shifted time codes. A packet
/// moved in the file (reordered) is out of sequence with its neighbours and is neither: the
/// reader puts it back by time.
#[must_use]
pub fn screen_times(times: &[f64], seqs: &[u16]) -> (Vec<usize>, Vec<usize>) {
    let mut steps: Vec<f64> = times
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|d| *d > 0.0)
        .collect();
    steps.sort_by(f64::total_cmp);
    let median = steps.get(steps.len() / 2).copied().unwrap_or(0.0);
    let tol = (TIME_TOLERANCE_STEPS * median).max(MIN_TIME_TOLERANCE_S);
    let far = (FAR_TIME_STEPS * median).max(FAR_TIME_S);
    let n = times.len().min(seqs.len());
    let in_seq = |i: usize, j: usize| follows(seqs[i], seqs[j]);
    let mut outliers = Vec::new();
    if n >= 3 {
        // The packets inside: both neighbours known.
        for i in 1..n - 1 {
            let (t, a, b) = (times[i], times[i - 1], times[i + 1]);
            // Beyond the tolerance from *both* neighbours (docs/icd.md §4): with the
            // neighbours in order that is `t < a − tol` or `t > b + tol`; when they are out
            // of order by less than the tolerance (one of them may be the damaged one), a
            // time within the tolerance of either is not accused.
            let (lo, hi) = (a.min(b), a.max(b));
            if in_seq(i - 1, i)
                && in_seq(i, i + 1)
                && a <= b + tol
                && (t < lo - tol || t > hi + tol)
            {
                outliers.push(i);
            }
        }
        // The first and the last packet, against their nearest two packets that are not
        // outliers themselves.
        let kept: Vec<usize> = (0..n).filter(|i| !outliers.contains(i)).collect();
        if let [_, j, k, ..] = kept[..] {
            let (t, b, c) = (times[0], times[j], times[k]);
            if j == 1
                && in_seq(0, j)
                && in_seq(j, k)
                && b <= c + tol
                && (t > b + tol || b - t > far)
            {
                outliers.insert(0, 0);
            }
        }
        if let [.., k, j, last] = kept[..] {
            let (t, a, y) = (times[last], times[j], times[k]);
            if last == n - 1
                && j == n - 2
                && in_seq(k, j)
                && in_seq(j, last)
                && y <= a + tol
                && (t < a - tol || t - a > far)
            {
                outliers.push(last);
            }
        }
    }
    let mut jumps = Vec::new();
    let mut prev: Option<usize> = None;
    for i in 0..n {
        if outliers.binary_search(&i).is_ok() {
            continue;
        }
        if let Some(p) = prev {
            if times[i] < times[p] - tol && in_seq(p, i) {
                jumps.push(i);
            }
        }
        prev = Some(i);
    }
    (outliers, jumps)
}

/// Drop isolated time-code outliers, report them, the remaining reversals and the backward
/// jumps (`placed`: offset and length of each decoded record, per APID slot, file order).
fn screen_time_codes(tm: &mut Telemetry, placed: &[Vec<(usize, usize, u16)>; SLOTS]) {
    let apids = SLOT_APIDS;
    let times: [Vec<f64>; SLOTS] = [
        tm.raw.iter().map(|r| r.time.seconds()).collect(),
        tm.housekeeping.iter().map(|r| r.time.seconds()).collect(),
        tm.events.iter().map(|(t, _)| t.seconds()).collect(),
        tm.ephemeris.iter().map(|r| r.time.seconds()).collect(),
        tm.magnetics.iter().map(|r| r.time.seconds()).collect(),
        tm.wheels.iter().map(|r| r.time.seconds()).collect(),
    ];
    let mut reversals = Vec::new();
    for slot in 0..SLOTS {
        let (t, pl) = (&times[slot], &placed[slot]);
        if t.len() != pl.len() {
            continue; // cannot happen: one placement per decoded record
        }
        let seqs: Vec<u16> = pl.iter().map(|p| p.2).collect();
        let (outliers, jumps) = screen_times(t, &seqs);
        for &i in &outliers {
            tm.report.time_outliers.push(TimeOutlier {
                offset: pl[i].0,
                len: pl[i].1,
                apid: apids[slot],
                time_s: t[i],
                neighbours_s: (
                    t.get(i.wrapping_sub(1)).copied().unwrap_or(f64::NAN),
                    t.get(i + 1).copied().unwrap_or(f64::NAN),
                ),
            });
        }
        let mut prev: Option<f64> = None;
        for (i, &ti) in t.iter().enumerate() {
            if outliers.binary_search(&i).is_ok() {
                continue;
            }
            if let Some(p) = prev {
                if ti < p {
                    reversals.push((pl[i].0, p, ti));
                }
                if jumps.binary_search(&i).is_ok() {
                    tm.report.time_jumps.push(TimeJump {
                        offset: pl[i].0,
                        apid: apids[slot],
                        from_s: p,
                        to_s: ti,
                    });
                }
            }
            prev = Some(ti);
        }
        let keep = |i: usize| outliers.binary_search(&i).is_err();
        match slot {
            0 => retain_indexed(&mut tm.raw, keep),
            1 => retain_indexed(&mut tm.housekeeping, keep),
            2 => retain_indexed(&mut tm.events, keep),
            3 => retain_indexed(&mut tm.ephemeris, keep),
            4 => retain_indexed(&mut tm.magnetics, keep),
            _ => retain_indexed(&mut tm.wheels, keep),
        }
    }
    reversals.sort_by_key(|r| r.0);
    tm.report.time_reversals = reversals;
    tm.report.time_outliers.sort_by_key(|o| o.offset);
    tm.report.time_jumps.sort_by_key(|j| j.offset);
    tm.report.packets = PacketCounts::of(tm);
}

fn retain_indexed<T>(v: &mut Vec<T>, keep: impl Fn(usize) -> bool) {
    let mut i = 0;
    v.retain(|_| {
        let k = keep(i);
        i += 1;
        k
    });
}

#[cfg(test)]
mod time_screen_tests {
    use super::screen_times;

    #[test]
    fn one_bad_time_code_is_an_outlier_a_shifted_block_is_a_jump() {
        let clean: Vec<f64> = (0..100).map(f64::from).collect();
        let seq: Vec<u16> = (0..100u16).map(|i| (16_350 + i) & 0x3fff).collect();
        assert_eq!(screen_times(&clean, &seq), (vec![], vec![]));
        // One flipped bit (±2^20 s, ±16 s) in one frame, also the first or the last.
        for k in [0usize, 37, 99] {
            for d in [1_048_576.0, -1_048_576.0, 16.0, -16.0] {
                let mut t = clean.clone();
                t[k] += d;
                let expect = if (k == 0 && d == -16.0) || (k == 99 && d == 16.0) {
                    vec![] // a 16 s gap at an end: possible, kept
                } else {
                    vec![k]
                };
                assert_eq!(screen_times(&t, &seq), (expect, vec![]), "frame {k} {d}");
            }
        }
        // An irregular clean stream (records every 5 s and at random in between): nothing.
        let t: Vec<f64> = vec![0.0, 5.0, 6.0, 10.0, 15.0, 15.5, 20.0, 60.0, 61.0, 65.0];
        let q: Vec<u16> = (0..10).collect();
        assert_eq!(screen_times(&t, &q), (vec![], vec![]));
        // Reordered packets (time and sequence count move together) and a real gap: nothing.
        let (mut t, mut q) = (clean.clone(), seq.clone());
        for (a, b) in [(10, 11), (50, 52), (20, 40)] {
            t.swap(a, b);
            q.swap(a, b);
        }
        t[60..68].reverse();
        q[60..68].reverse();
        for x in t.iter_mut().skip(70) {
            *x += 5000.0;
        }
        assert_eq!(screen_times(&t, &q), (vec![], vec![]));
        // The second half 3600 s earlier, sequence counts unbroken: one jump at its start.
        let mut t = clean.clone();
        for x in t.iter_mut().skip(50) {
            *x -= 3600.0;
        }
        assert_eq!(screen_times(&t, &seq), (vec![], vec![50]));
        // Sparse records with a gap before the last two: not outliers.
        let s5: Vec<u16> = (0..5).collect();
        assert!(screen_times(&[100.0, 200.0, 300.0, 5000.0, 5001.0], &s5)
            .0
            .is_empty());
    }

    /// A good time code next to a damaged one that is earlier than its other neighbour by
    /// less than the tolerance (the neighbours out of order): only the damaged one is
    /// accused; the good one is within the tolerance of its in-order neighbour (docs/icd.md
    /// §4: beyond the tolerance from *both* neighbours). Sparse records, median step 2 s:
    /// tolerance 8 s.
    #[test]
    fn a_good_time_code_beside_a_damaged_one_is_kept() {
        let mut t: Vec<f64> = (0..40).map(|i| 2.0 * f64::from(i)).collect();
        let q: Vec<u16> = (0..40).collect();
        // Frame 21 damaged to 7 s before frame 19 (38 s): frame 20 (40 s) now has the
        // neighbours 38 s and 31 s, out of order by less than the 8-s tolerance.
        t[21] = 31.0;
        let (outliers, jumps) = screen_times(&t, &q);
        assert_eq!(outliers, vec![21], "only the damaged frame");
        assert!(jumps.is_empty());
    }
}
