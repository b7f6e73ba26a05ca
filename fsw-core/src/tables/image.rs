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

pub use super::error::{TableError, TableId};
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
