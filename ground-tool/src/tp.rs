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

use fsw_core::events::Event;
use fsw_core::raw::{RawSensorFrame, TimeTag};
use fsw_core::telemetry::{
    decode_ephemeris, decode_event, decode_housekeeping, decode_raw_frame, decode_time_code,
    EphemerisRecord, ObcHousekeeping, APID_EPHEMERIS, APID_EVENT, APID_HOUSEKEEPING,
    APID_RAW_SENSORS, EPHEMERIS_LEN, EVENT_LEN, HOUSEKEEPING_LEN, RAW_FRAME_LEN, TIME_CODE_LEN,
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

/// What the reader found, for reports and exit codes.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct TpReport {
    /// File size in octets.
    pub file_len: usize,
    /// Packets decoded per APID: raw, housekeeping, event, ephemeris.
    pub packets_raw: usize,
    /// Housekeeping packets decoded.
    pub packets_housekeeping: usize,
    /// Event packets decoded.
    pub packets_event: usize,
    /// Ephemeris packets decoded.
    pub packets_ephemeris: usize,
    /// Regions skipped (truncated, unknown, corrupt), with offsets.
    pub skipped: Vec<Skipped>,
    /// Duplicated packets dropped (offsets): identical octets to an earlier copy.
    pub duplicates: Vec<usize>,
    /// Packets with the key (APID, sequence count, time) of an earlier one but other octets:
    /// both kept (offsets of the later ones).
    pub duplicate_conflicts: Vec<usize>,
    /// Places where a packet's time was earlier than the previous packet of the same APID:
    /// `(offset, previous time s, time s)`.
    pub time_reversals: Vec<(usize, f64, f64)>,
}

impl TpReport {
    /// Octets that could not be used.
    #[must_use]
    pub fn skipped_octets(&self) -> usize {
        self.skipped.iter().map(|s| s.len).sum()
    }

    /// True if nothing was skipped, duplicated or out of order.
    #[must_use]
    pub fn is_clean(&self) -> bool {
        self.skipped.is_empty() && self.duplicates.is_empty() && self.time_reversals.is_empty()
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
    /// What the reader found.
    pub report: TpReport,
}

/// Errors that stop telemetry processing altogether.
#[derive(Debug, thiserror::Error)]
pub enum TpError {
    /// The file could not be read.
    #[error("cannot read telemetry file {path}: {source}")]
    Io {
        /// Path.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
}

fn user_len(apid: u16) -> Option<usize> {
    match apid {
        APID_RAW_SENSORS => Some(RAW_FRAME_LEN),
        APID_HOUSEKEEPING => Some(HOUSEKEEPING_LEN),
        APID_EVENT => Some(EVENT_LEN),
        APID_EPHEMERIS => Some(EPHEMERIS_LEN),
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

/// Decode telemetry from memory (see the module doc for the damage policy).
#[must_use]
pub fn decode(bytes: &[u8]) -> Telemetry {
    let mut tm = Telemetry::default();
    tm.report.file_len = bytes.len();
    let mut seen: HashMap<(u16, u16, u32, u16), usize> = HashMap::new();
    let mut last_time: [Option<f64>; 4] = [None; 4];
    let mut at = 0usize;
    while at < bytes.len() {
        let Some(h) = parse_header(&bytes[at..]) else {
            let next = resync(bytes, at + 1);
            let reason = if bytes.len() - at < PRIMARY_HEADER_LEN {
                "truncated primary header at end of file"
            } else {
                "not a valid TM packet header"
            };
            tm.report.skipped.push(Skipped {
                offset: at,
                len: next - at,
                reason: reason.into(),
            });
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
            tm.report.skipped.push(Skipped {
                offset: at,
                len: next - at,
                reason: format!("unknown APID 0x{:03x}", h.apid),
            });
            at = next;
            continue;
        };
        let expected_total = PRIMARY_HEADER_LEN + TIME_CODE_LEN + expected_user;
        if h.total_len != expected_total {
            let next = resync(bytes, at + 1);
            tm.report.skipped.push(Skipped {
                offset: at,
                len: next - at,
                reason: format!(
                    "APID 0x{:03x}: packet length {} but the ICD fixes {}",
                    h.apid, h.total_len, expected_total
                ),
            });
            at = next;
            continue;
        }
        if at + h.total_len > bytes.len() {
            // Cut by the end of the file, or by a drop-out before packets that end it: those
            // packets start inside the claimed length.
            let next = resync(bytes, at + 1);
            tm.report.skipped.push(Skipped {
                offset: at,
                len: next - at,
                reason: format!(
                    "APID 0x{:03x}: truncated packet ({} of {} octets)",
                    h.apid,
                    bytes.len() - at,
                    h.total_len
                ),
            });
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
                tm.report.skipped.push(Skipped {
                    offset: at,
                    len: q - at,
                    reason: format!(
                        "APID 0x{:03x}: packet cut short (a packet starts inside it)",
                        h.apid
                    ),
                });
                at = q;
                continue;
            }
        }
        let data = &bytes[at + PRIMARY_HEADER_LEN..at + h.total_len];
        let time = match decode_time_code(data) {
            Ok(t) => t,
            Err(_) => {
                tm.report.skipped.push(Skipped {
                    offset: at,
                    len: h.total_len,
                    reason: "bad time code".into(),
                });
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
        let slot = match h.apid {
            APID_RAW_SENSORS => 0,
            APID_HOUSEKEEPING => 1,
            APID_EVENT => 2,
            _ => 3,
        };
        let t = time.seconds();
        if let Some(prev) = last_time[slot] {
            if t < prev {
                tm.report.time_reversals.push((at, prev, t));
            }
        }
        last_time[slot] = Some(t);
        let decoded = match h.apid {
            APID_RAW_SENSORS => decode_raw_frame(time, user).map(|r| {
                tm.raw.push(r);
                tm.report.packets_raw += 1;
            }),
            APID_HOUSEKEEPING => decode_housekeeping(time, user).map(|r| {
                tm.housekeeping.push(r);
                tm.report.packets_housekeeping += 1;
            }),
            APID_EVENT => decode_event(user).map(|e| {
                tm.events.push((time, e));
                tm.report.packets_event += 1;
            }),
            _ => decode_ephemeris(time, user).map(|e| {
                tm.ephemeris.push(e);
                tm.report.packets_ephemeris += 1;
            }),
        };
        if let Err(e) = decoded {
            tm.report.skipped.push(Skipped {
                offset: at,
                len: h.total_len,
                reason: format!("APID 0x{:03x}: field does not decode ({e:?})", h.apid),
            });
        }
        at += h.total_len;
    }
    tm.raw.sort_by_key(|r| r.time);
    tm.housekeeping.sort_by_key(|r| r.time);
    tm.events.sort_by_key(|(t, _)| *t);
    tm.ephemeris.sort_by_key(|r| r.time);
    tm
}
