//! # Which table, and why a table or its image is refused
//!
//! [`TableId`] (the on-wire id of octet 4) and [`TableError`] (the reason codes of events
//! 0x0102/0x0104) are shared by the image format ([`super::image`]: parsing, CRC, decoding)
//! and the tables' own validation ([`super::types`]: finite values, rotations, ranges).
//! Why a module of their own: with them in `image.rs`, `types.rs` imported the image module
//! for its error while the image module imported `types.rs` for the star catalog it decodes
//! in place; here both import them and not each other. Reason codes in `docs/tables.md`.

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
    /// The onboard geomagnetic field model, the TAM calibration and the coarse-attitude
    /// settings.
    /// docs/tables.md (Table 6: magnetics); issue 20.
    Magnetics = 6,
}

impl TableId {
    /// All table ids, in id order.
    /// docs/tables.md (table ids 1–6).
    pub const ALL: [TableId; 6] = [
        TableId::Alignment,
        TableId::Iru,
        TableId::Filter,
        TableId::StarCatalog,
        TableId::Orbit,
        TableId::Magnetics,
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
            6 => Some(Self::Magnetics),
            _ => None,
        }
    }

    /// Index 0..6 for per-table arrays.
    /// Project choice (not in the paper): dense arrays indexed by id − 1.
    #[must_use]
    pub fn index(self) -> usize {
        match self {
            Self::Alignment => 0,
            Self::Iru => 1,
            Self::Filter => 2,
            Self::StarCatalog => 3,
            Self::Orbit => 4,
            Self::Magnetics => 5,
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
            Self::Magnetics => "magnetics",
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
                "octet 4 (table id) holds {found}, not 1 alignment, 2 IRU, 3 filter, 4 star catalog, 5 orbit or 6 magnetics [reason 4]"
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
