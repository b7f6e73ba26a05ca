//! # Binary table images: header + postcard payload + CRC-32
//!
//! One definition of the uplink format, used by the OBC to load and by the ground tool to
//! write (byte layout in `docs/tables.md`):
//!
//! | offset | size | field | notes |
//! |---|---|---|---|
//! | 0 | 4 | magic | `0x4752_4F54` ("GROT"), big-endian |
//! | 4 | 1 | table id | [`TableId`] |
//! | 5 | 1 | format version | [`FORMAT_VERSION`] |
//! | 6 | 2 | reserved | zero |
//! | 8 | 4 | payload length | bytes, big-endian |
//! | 12 | 6 | creation time | CUC: 4 octets seconds + 2 octets 2⁻¹⁶ s since 1958 TAI |
//! | 18 | 2 | reserved | zero |
//! | 20 | n | payload | postcard encoding of the table struct |
//! | 20+n | 4 | CRC-32 | ISO-HDLC (zlib) over bytes 0..20+n, big-endian |

use crate::raw::TimeTag;
use serde::{de::DeserializeOwned, Serialize};

/// Image magic, "GROT".
/// docs/tables.md ("Image = header + payload + CRC", offset 0).
pub const MAGIC: u32 = 0x4752_4F54;
/// Current image format version.
/// docs/tables.md (offset 5).
pub const FORMAT_VERSION: u8 = 1;
/// Header length in bytes.
/// docs/tables.md (octets 0..20).
pub const HEADER_LEN: usize = 20;
/// CRC trailer length in bytes.
/// docs/tables.md (trailer).
pub const CRC_LEN: usize = 4;
/// The CRC used for images: CRC-32/ISO-HDLC (the zlib/PNG CRC).
/// docs/tables.md; the CRC-32 of ISO/IEC 13239 HDLC, as zlib.
pub const IMAGE_CRC: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// Which table an image holds. Discriminants are the on-wire ids.
/// docs/tables.md (offset 4); project choice (not in the paper): five tables.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum TableId {
    /// Sensor alignments M_AS (FHST1, FHST2, FSS1, FSS2) and sensor corrections.
    /// docs/tables.md (Table 1: alignment); paper Table 1 at boot, Table 3 after calibration.
    Alignment = 1,
    /// DRIRU II alignment/scale factors G, k and pulse weights.
    /// docs/tables.md (Table 2: IRU); paper: DRIRU II and prelaunch `G`.
    Iru = 2,
    /// Kalman filter, star identification and control settings.
    /// docs/tables.md (Table 3: filter); project choice (not in the paper).
    Filter = 3,
    /// The onboard star catalog.
    /// docs/tables.md (Table 4: star catalog); Hipparcos subset.
    StarCatalog = 4,
    /// The onboard orbit (state vector at an epoch), propagated on board.
    /// docs/tables.md (Table 5: orbit); algorithms.md §3.3 (orbital aberration, parallax).
    Orbit = 5,
}

impl TableId {
    /// All table ids, in id order.
    /// docs/tables.md (table ids 1–5).
    pub const ALL: [TableId; 5] = [
        TableId::Alignment,
        TableId::Iru,
        TableId::Filter,
        TableId::StarCatalog,
        TableId::Orbit,
    ];

    /// From the on-wire id.
    /// docs/tables.md (offset 4).
    #[must_use]
    pub fn from_u8(id: u8) -> Option<Self> {
        match id {
            1 => Some(Self::Alignment),
            2 => Some(Self::Iru),
            3 => Some(Self::Filter),
            4 => Some(Self::StarCatalog),
            5 => Some(Self::Orbit),
            _ => None,
        }
    }

    /// Index 0..5 for per-table arrays.
    /// Project choice (not in the paper): dense arrays indexed by id − 1.
    #[must_use]
    pub fn index(self) -> usize {
        match self {
            Self::Alignment => 0,
            Self::Iru => 1,
            Self::Filter => 2,
            Self::StarCatalog => 3,
            Self::Orbit => 4,
        }
    }

    /// Human name.
    /// docs/tables.md section names.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Alignment => "alignment",
            Self::Iru => "iru",
            Self::Filter => "filter",
            Self::StarCatalog => "star_catalog",
            Self::Orbit => "orbit",
        }
    }
}

/// Why an image or a table was refused. Every variant carries the evidence an operator needs.
/// Reason codes of docs/tables.md (event 0x0102 p2, 0x0104 p2).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TableError {
    /// Fewer bytes than a header and a CRC.
    /// docs/tables.md (header 20 + CRC 4 octets).
    TooShort {
        /// Bytes received.
        /// docs/tables.md ("Reason codes").
        len: usize,
    },
    /// Image larger than the load buffer.
    /// Project choice (not in the paper): a fixed load buffer, no heap.
    TooLong {
        /// Bytes received.
        /// docs/tables.md ("Reason codes").
        len: usize,
        /// Capacity.
        /// docs/tables.md ("Reason codes").
        max: usize,
    },
    /// The magic word is wrong.
    /// docs/tables.md (offset 0, "GROT").
    BadMagic {
        /// Magic found.
        /// docs/tables.md ("Reason codes").
        found: u32,
    },
    /// Unknown table id byte.
    /// docs/tables.md (offset 4).
    UnknownTableId {
        /// Id found.
        /// docs/tables.md ("Reason codes").
        found: u8,
    },
    /// The image is for another table than the one expected.
    /// docs/tables.md ("Lifecycle").
    WrongTableId {
        /// Id expected.
        /// docs/tables.md ("Reason codes").
        expected: TableId,
        /// Id found.
        /// docs/tables.md ("Reason codes").
        found: TableId,
    },
    /// Unsupported format version.
    /// docs/tables.md (offset 5).
    UnsupportedVersion {
        /// Version found.
        /// docs/tables.md ("Reason codes").
        found: u8,
    },
    /// Reserved header bytes not zero.
    /// docs/tables.md (offsets 6 and 18).
    ReservedNotZero,
    /// Declared payload length disagrees with the image length.
    /// docs/tables.md (offset 8).
    LengthMismatch {
        /// Payload length in the header.
        /// docs/tables.md ("Reason codes").
        declared: u32,
        /// Payload bytes actually present.
        /// docs/tables.md ("Reason codes").
        actual: usize,
    },
    /// CRC-32 check failed.
    /// docs/tables.md (CRC-32 trailer).
    CrcMismatch {
        /// CRC computed over the image.
        /// docs/tables.md ("Reason codes").
        computed: u32,
        /// CRC stored in the image.
        /// docs/tables.md ("Reason codes").
        stored: u32,
    },
    /// The payload does not decode as the table (or has trailing bytes).
    /// docs/tables.md ("Postcard payload rules").
    PayloadDecode,
    /// The payload does not fit the output buffer when encoding.
    /// Project choice (not in the paper): encoders never write past `out`.
    BufferTooSmall,
    /// A value is NaN or infinite.
    /// docs/tables.md ("Reason codes").
    NotFinite {
        /// Field index (table-specific, see `docs/tables.md`).
        field: u8,
    },
    /// An alignment matrix is not a proper rotation (orthonormal to 1e-6, det +1).
    /// docs/tables.md (Table 1: alignment, "proper rotation").
    NotRotation {
        /// Sensor index: 0 FHST1, 1 FHST2, 2 FSS1, 3 FSS2.
        /// docs/tables.md ("Reason codes").
        sensor: u8,
    },
    /// A value is outside its documented range.
    /// docs/tables.md (field ranges of each table).
    OutOfRange {
        /// Field index (table-specific, see `docs/tables.md`).
        field: u8,
    },
    /// The change from the active table exceeds the FilterTable bound.
    /// docs/tables.md (`max_alignment_change_arcsec`, `max_iru_change_ppm`).
    ChangeTooLarge {
        /// Field index (table-specific).
        /// docs/tables.md ("Reason codes").
        field: u8,
        /// The change (arcsec for rotations, ppm for G elements).
        /// docs/tables.md ("Reason codes").
        change: f32,
        /// The allowed change, same unit.
        /// docs/tables.md ("Reason codes").
        limit: f32,
    },
}

impl TableError {
    /// Stable numeric reason code for events and telemetry (`docs/tables.md`).
    #[must_use]
    pub fn code(&self) -> u8 {
        match self {
            Self::TooShort { .. } => 1,
            Self::TooLong { .. } => 2,
            Self::BadMagic { .. } => 3,
            Self::UnknownTableId { .. } => 4,
            Self::WrongTableId { .. } => 5,
            Self::UnsupportedVersion { .. } => 6,
            Self::ReservedNotZero => 7,
            Self::LengthMismatch { .. } => 8,
            Self::CrcMismatch { .. } => 9,
            Self::PayloadDecode => 10,
            Self::BufferTooSmall => 11,
            Self::NotFinite { .. } => 12,
            Self::NotRotation { .. } => 13,
            Self::OutOfRange { .. } => 14,
            Self::ChangeTooLarge { .. } => 15,
        }
    }
}

/// A sentence for people (the field index is the table's field number of `docs/tables.md`);
/// the reason code is in brackets so logs and events can be matched.
impl core::fmt::Display for TableError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::TooShort { len } => write!(
                f,
                "the image is {len} octets, shorter than a header and a CRC (24 octets) [reason 1]"
            ),
            Self::TooLong { len, max } => write!(
                f,
                "the image is {len} octets, longer than the {max}-octet load buffer [reason 2]"
            ),
            Self::BadMagic { found } => write!(
                f,
                "octets 0-3 hold 0x{found:08x}, not the magic word \"GROT\": not a table image [reason 3]"
            ),
            Self::UnknownTableId { found } => write!(
                f,
                "octet 4 (table id) holds {found}, not 1 alignment, 2 IRU, 3 filter, 4 star catalog or 5 orbit [reason 4]"
            ),
            Self::WrongTableId { expected, found } => write!(
                f,
                "the image holds a {} table where a {} table was expected [reason 5]",
                found.name(),
                expected.name()
            ),
            Self::UnsupportedVersion { found } => write!(
                f,
                "octet 5 (format version) holds {found}, a version this software does not read [reason 6]"
            ),
            Self::ReservedNotZero => write!(
                f,
                "reserved header octets (6-7 or 18-19) are not zero [reason 7]"
            ),
            Self::LengthMismatch { declared, actual } => write!(
                f,
                "the header declares a {declared}-octet payload but {actual} octets follow (truncated or extended file) [reason 8]"
            ),
            Self::CrcMismatch { computed, stored } => write!(
                f,
                "the CRC-32 stored in the last 4 octets (0x{stored:08x}) does not match the CRC-32 of the image (0x{computed:08x}): the file is damaged [reason 9]"
            ),
            Self::PayloadDecode => write!(
                f,
                "the payload does not decode as the table named in the header (or has trailing octets) [reason 10]"
            ),
            Self::BufferTooSmall => {
                write!(f, "the payload does not fit the output buffer [reason 11]")
            }
            Self::NotFinite { field } => write!(
                f,
                "field {field} (docs/tables.md) holds NaN or an infinity [reason 12]"
            ),
            Self::NotRotation { sensor } => write!(
                f,
                "the alignment matrix of {} is not a proper rotation (orthonormal to 1e-6, det +1) [reason 13]",
                match sensor {
                    0 => "FHST1",
                    1 => "FHST2",
                    2 => "FSS1",
                    3 => "FSS2",
                    _ => "an unknown sensor",
                }
            ),
            Self::OutOfRange { field } => write!(
                f,
                "field {field} (docs/tables.md) is outside its documented range [reason 14]"
            ),
            Self::ChangeTooLarge {
                field,
                change,
                limit,
            } => write!(
                f,
                "field {field} would change by {change} from the active table, above the filter table's bound {limit} [reason 15]"
            ),
        }
    }
}

/// The parsed, CRC-checked header of an image.
/// docs/tables.md ("Image = header + payload + CRC").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ImageHeader {
    /// Which table.
    /// docs/tables.md (offset 4).
    pub table_id: TableId,
    /// Format version.
    /// docs/tables.md (offset 5).
    pub format_version: u8,
    /// Payload length in bytes.
    /// docs/tables.md (offset 8).
    pub payload_len: u32,
    /// Creation time tag.
    /// docs/tables.md (offsets 12–17, CUC; CCSDS 301.0-B-4).
    pub created: TimeTag,
}

fn be_u32(bytes: &[u8], at: usize) -> Option<u32> {
    let end = at.checked_add(4)?;
    let s = bytes.get(at..end)?;
    let arr: [u8; 4] = s.try_into().ok()?;
    Some(u32::from_be_bytes(arr))
}

fn be_u16(bytes: &[u8], at: usize) -> Option<u16> {
    let end = at.checked_add(2)?;
    let s = bytes.get(at..end)?;
    let arr: [u8; 2] = s.try_into().ok()?;
    Some(u16::from_be_bytes(arr))
}

/// Check magic, id, version, reserved bytes, length and CRC; return the header and the payload.
/// docs/tables.md ("Image = header + payload + CRC").
///
/// # Errors
/// The first check that fails, as a [`TableError`].
pub fn parse_image(bytes: &[u8]) -> Result<(ImageHeader, &[u8]), TableError> {
    let len = bytes.len();
    let min = HEADER_LEN.saturating_add(CRC_LEN);
    if len < min {
        return Err(TableError::TooShort { len });
    }
    let magic = be_u32(bytes, 0).ok_or(TableError::TooShort { len })?;
    if magic != MAGIC {
        return Err(TableError::BadMagic { found: magic });
    }
    let id_byte = *bytes.get(4).ok_or(TableError::TooShort { len })?;
    let table_id =
        TableId::from_u8(id_byte).ok_or(TableError::UnknownTableId { found: id_byte })?;
    let format_version = *bytes.get(5).ok_or(TableError::TooShort { len })?;
    if format_version != FORMAT_VERSION {
        return Err(TableError::UnsupportedVersion {
            found: format_version,
        });
    }
    let reserved_a = be_u16(bytes, 6).ok_or(TableError::TooShort { len })?;
    let reserved_b = be_u16(bytes, 18).ok_or(TableError::TooShort { len })?;
    if reserved_a != 0 || reserved_b != 0 {
        return Err(TableError::ReservedNotZero);
    }
    let payload_len = be_u32(bytes, 8).ok_or(TableError::TooShort { len })?;
    let actual = len.saturating_sub(min);
    if usize::try_from(payload_len).ok() != Some(actual) {
        return Err(TableError::LengthMismatch {
            declared: payload_len,
            actual,
        });
    }
    let crc_at = len.saturating_sub(CRC_LEN);
    let stored = be_u32(bytes, crc_at).ok_or(TableError::TooShort { len })?;
    let covered = bytes.get(..crc_at).ok_or(TableError::TooShort { len })?;
    let computed = IMAGE_CRC.checksum(covered);
    if computed != stored {
        return Err(TableError::CrcMismatch { computed, stored });
    }
    let coarse_s = be_u32(bytes, 12).ok_or(TableError::TooShort { len })?;
    let fine = be_u16(bytes, 16).ok_or(TableError::TooShort { len })?;
    let payload = bytes
        .get(HEADER_LEN..crc_at)
        .ok_or(TableError::TooShort { len })?;
    Ok((
        ImageHeader {
            table_id,
            format_version,
            payload_len,
            created: TimeTag { coarse_s, fine },
        },
        payload,
    ))
}

/// Decode a postcard payload completely (trailing bytes are an error) and require it to be
/// the *canonical* encoding of the value (postcard accepts over-long varints such as
/// `85 00` for 5): otherwise the dump of the activated table would differ from the image the
/// ground uplinked and telemetered (TBL-002). The check re-encodes without a buffer, comparing
/// each octet with the payload ([`CompareFlavor`]).
/// docs/tables.md ("Postcard payload rules"); project choice: one image per table.
///
/// # Errors
/// [`TableError::PayloadDecode`].
pub fn decode_payload<T: DeserializeOwned + Serialize>(payload: &[u8]) -> Result<T, TableError> {
    match postcard::take_from_bytes::<T>(payload) {
        Ok((value, [])) if is_canonical(&value, payload) => Ok(value),
        _ => Err(TableError::PayloadDecode),
    }
}

/// Decode a star-catalog payload into `out` in place, star by star.
/// docs/tables.md (Table 4; the same bytes as [`decode_payload`] accepts).
///
/// Why not [`decode_payload`]: postcard returns the ~82 KB table by value, and the moves
/// of that value made the load path's stack frame 411 KB on the Cortex-M4
/// (`scripts/qemu-replay.sh`). Here only one 18-byte star is on the stack at a time. The
/// loop is bounded by `MAX_CATALOG_STARS` (a longer list is refused before any star is read).
///
/// # Errors
/// [`TableError::PayloadDecode`] for anything `decode_payload` would refuse (malformed,
/// trailing bytes, more than `MAX_CATALOG_STARS` stars, a non-canonical encoding); `out` is
/// then in an unspecified but valid state (the caller discards it).
pub fn decode_catalog_into(
    payload: &[u8],
    out: &mut crate::tables::types::StarCatalogTable,
) -> Result<(), TableError> {
    use crate::tables::types::{CatalogStar, MAX_CATALOG_STARS};
    let bad = |_| TableError::PayloadDecode;
    let (epoch, rest) = postcard::take_from_bytes::<f64>(payload).map_err(bad)?;
    let (count, mut rest) = postcard::take_from_bytes::<usize>(rest).map_err(bad)?;
    if count > MAX_CATALOG_STARS {
        return Err(TableError::PayloadDecode);
    }
    out.epoch_years_since_j2000 = epoch;
    out.stars.clear();
    for _ in 0..count {
        let (star, tail) = postcard::take_from_bytes::<CatalogStar>(rest).map_err(bad)?;
        out.stars
            .push(star)
            .map_err(|_| TableError::PayloadDecode)?;
        rest = tail;
    }
    if rest.is_empty() && is_canonical(&*out, payload) {
        Ok(())
    } else {
        Err(TableError::PayloadDecode)
    }
}

/// `payload` is exactly the postcard encoding of `value` (no buffer: see [`CompareFlavor`]).
#[inline(never)]
fn is_canonical<T: Serialize>(value: &T, payload: &[u8]) -> bool {
    let flavor = CompareFlavor {
        expected: payload,
        at: 0,
    };
    matches!(
        postcard::serialize_with_flavor::<T, CompareFlavor<'_>, usize>(value, flavor),
        Ok(n) if n == payload.len()
    )
}

/// A postcard output "flavor" that stores nothing: it compares every octet the serializer
/// produces with the expected payload and fails at the first difference.
/// Project choice (not in the paper): canonical-encoding check without a heap buffer.
pub struct CompareFlavor<'a> {
    expected: &'a [u8],
    at: usize,
}

impl postcard::ser_flavors::Flavor for CompareFlavor<'_> {
    type Output = usize;

    fn try_push(&mut self, data: u8) -> postcard::Result<()> {
        match self.expected.get(self.at) {
            Some(&b) if b == data => {
                self.at = self.at.saturating_add(1);
                Ok(())
            }
            _ => Err(postcard::Error::SerializeBufferFull),
        }
    }

    fn finalize(self) -> postcard::Result<usize> {
        Ok(self.at)
    }
}

/// Write header + postcard payload + CRC into `out`; returns the image length.
/// docs/tables.md ("Image = header + payload + CRC").
///
/// # Errors
/// [`TableError::BufferTooSmall`] when `out` cannot hold the image.
pub fn encode_image<T: Serialize>(
    table_id: TableId,
    created: TimeTag,
    table: &T,
    out: &mut [u8],
) -> Result<usize, TableError> {
    let (header, rest) = out
        .split_at_mut_checked(HEADER_LEN)
        .ok_or(TableError::BufferTooSmall)?;
    let payload_len = postcard::to_slice(table, rest)
        .map_err(|_| TableError::BufferTooSmall)?
        .len();
    let payload_len_u32 = u32::try_from(payload_len).map_err(|_| TableError::BufferTooSmall)?;
    header.copy_from_slice(&[0; HEADER_LEN]);
    let fields: [(usize, &[u8]); 5] = [
        (0, &MAGIC.to_be_bytes()),
        (4, &[table_id as u8, FORMAT_VERSION]),
        (8, &payload_len_u32.to_be_bytes()),
        (12, &created.coarse_s.to_be_bytes()),
        (16, &created.fine.to_be_bytes()),
    ];
    for (at, value) in fields {
        let end = at.saturating_add(value.len());
        header
            .get_mut(at..end)
            .ok_or(TableError::BufferTooSmall)?
            .copy_from_slice(value);
    }
    let crc_at = HEADER_LEN
        .checked_add(payload_len)
        .ok_or(TableError::BufferTooSmall)?;
    let total = crc_at
        .checked_add(CRC_LEN)
        .ok_or(TableError::BufferTooSmall)?;
    let crc = IMAGE_CRC.checksum(out.get(..crc_at).ok_or(TableError::BufferTooSmall)?);
    out.get_mut(crc_at..total)
        .ok_or(TableError::BufferTooSmall)?
        .copy_from_slice(&crc.to_be_bytes());
    Ok(total)
}
