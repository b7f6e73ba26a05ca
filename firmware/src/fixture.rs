// The replay fixture format and the replay step shared by the host recorder
// (`fsw-core/examples/replay_record.rs`, which `include!`s this file) and the firmware
// (`firmware/src/lib.rs`, `mod fixture`). One definition, so host and target decode the same
// bytes into the same commands and digest the same output bytes.
//
// `no_std`, allocation-free and panic-free: only checked slicing, saturating arithmetic and
// `Result`s. Uses only `fsw_core`, `serde`, `postcard` and `heapless`.
//
// ## Input file (`firmware/fixtures/replay_inputs.bin`)
// postcard, in this order:
// 1. `InputHeader` (magic "GROI", version, number of table images, number of cycles);
// 2. `images` table images, each a postcard byte string (`&[u8]`: varint length + bytes);
// 3. `cycles` × `RecordedCycle` (the raw sensor frame and up to 8 commands).
//
// ## Expected file (`firmware/fixtures/replay_expected.bin`)
// postcard: `ExpectedHeader` (magic "GROE", version, cycles, CRC-32 of the whole input file,
// interval of full records) then `cycles` × `ExpectedCycle` (CRC-32 of the cycle record,
// event count, and the full cycle record every `full_every` cycles and on the last one).
//
// The *cycle record* of one `CycleOutput` is
// `[CUC time code, 6][housekeeping user data, 230][event count, 1][events, 10 each]`
// with the ICD encoders of `fsw_core::telemetry`; its digest is CRC-32/ISO-HDLC
// (`fsw_core::tables::image::IMAGE_CRC`).

use fsw_core::attitude::Quat;
use fsw_core::events::MAX_EVENTS_PER_CYCLE;
use fsw_core::executive::{Command, CycleOutput, MAX_COMMANDS_PER_CYCLE};
use fsw_core::iru::IruConfiguration;
use fsw_core::raw::RawSensorFrame;
use fsw_core::tables::image::IMAGE_CRC;
use fsw_core::tables::TableId;
use fsw_core::telemetry::{
    encode_event, encode_housekeeping, encode_time_code, EVENT_LEN, HOUSEKEEPING_LEN, TIME_CODE_LEN,
};
use serde::{Deserialize, Serialize};

/// Input file magic, "GROI".
pub const INPUT_MAGIC: u32 = 0x4752_4F49;
/// Expected-output file magic, "GROE".
pub const EXPECTED_MAGIC: u32 = 0x4752_4F45;
/// Version of both files.
pub const FIXTURE_VERSION: u16 = 1;
/// Most table images one input file may carry.
pub const MAX_IMAGES: usize = 8;
/// Most commands recorded for one cycle (the executive's own limit).
pub const MAX_RECORDED_COMMANDS: usize = MAX_COMMANDS_PER_CYCLE;
/// Length of the longest cycle record.
pub const CYCLE_RECORD_MAX: usize =
    TIME_CODE_LEN + HOUSEKEEPING_LEN + 1 + EVENT_LEN * MAX_EVENTS_PER_CYCLE;

/// Header of the input file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct InputHeader {
    /// [`INPUT_MAGIC`].
    pub magic: u32,
    /// [`FIXTURE_VERSION`].
    pub version: u16,
    /// Number of table images that follow.
    pub images: u8,
    /// Number of recorded cycles after the images.
    pub cycles: u32,
}

/// A ground command as recorded (table images by index into the file's image list,
/// table ids and IRU configurations by their on-wire codes, quaternions `[x, y, z, w]`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum RecordedCommand {
    /// `Command::SlewTo`.
    SlewTo([f64; 4]),
    /// `Command::Hold`.
    Hold,
    /// `Command::SelectIruConfig` (0 primary, 1 backup).
    SelectIruConfig(u8),
    /// `Command::TableLoad` of image number `n` of the file.
    TableLoad(u8),
    /// `Command::TableActivate` (table id 1..=4).
    TableActivate(u8),
    /// `Command::TableAbort` (table id 1..=4).
    TableAbort(u8),
    /// `Command::FilterInitialize`.
    FilterInitialize([f64; 4]),
    /// `Command::FilterReset`.
    FilterReset,
}

/// One recorded cycle: what the OBC reads and what the ground sent.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RecordedCycle {
    /// The raw sensor frame.
    pub frame: RawSensorFrame,
    /// Commands in execution order.
    pub commands: heapless::Vec<RecordedCommand, MAX_RECORDED_COMMANDS>,
}

/// Header of the expected-output file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ExpectedHeader {
    /// [`EXPECTED_MAGIC`].
    pub magic: u32,
    /// [`FIXTURE_VERSION`].
    pub version: u16,
    /// Number of cycles.
    pub cycles: u32,
    /// CRC-32/ISO-HDLC of the whole input file these outputs belong to.
    pub inputs_crc: u32,
    /// A full cycle record is stored every `full_every` cycles (and for the last cycle).
    pub full_every: u32,
}

/// Expected output of one cycle.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ExpectedCycle<'a> {
    /// CRC-32 of the cycle record.
    pub digest: u32,
    /// Number of events in the cycle.
    pub events: u8,
    /// The full cycle record, for some cycles.
    #[serde(borrow)]
    pub record: Option<&'a [u8]>,
}

/// Why a fixture could not be read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FixtureError {
    /// postcard could not decode the item at this byte offset.
    Decode {
        /// Offset of the item in the file.
        offset: u32,
    },
    /// Wrong magic or version.
    BadHeader,
    /// More table images than [`MAX_IMAGES`].
    TooManyImages,
    /// A command refers to an image, table id or configuration that does not exist.
    BadCommand,
    /// The file has bytes after the last cycle.
    TrailingBytes,
    /// A cycle record did not fit its buffer.
    Encode,
}

fn offset_of(all: &[u8], rest: &[u8]) -> u32 {
    u32::try_from(all.len().saturating_sub(rest.len())).unwrap_or(u32::MAX)
}

/// The counted records after a file's header: `remaining` postcard values, then nothing.
#[derive(Clone, Debug)]
struct Records<'a> {
    all: &'a [u8],
    rest: &'a [u8],
    remaining: u32,
}

impl<'a> Records<'a> {
    /// The next record, `None` after the last one; [`FixtureError::TrailingBytes`] once when
    /// bytes follow the last one, [`FixtureError::Decode`] (and nothing more) for a record
    /// that does not decode.
    fn next<T: Deserialize<'a>>(&mut self) -> Option<Result<T, FixtureError>> {
        if self.remaining == 0 {
            if self.rest.is_empty() {
                return None;
            }
            self.rest = &[];
            return Some(Err(FixtureError::TrailingBytes));
        }
        self.remaining = self.remaining.saturating_sub(1);
        let offset = offset_of(self.all, self.rest);
        match postcard::take_from_bytes::<T>(self.rest) {
            Ok((record, after)) => {
                self.rest = after;
                Some(Ok(record))
            }
            Err(_) => {
                self.remaining = 0;
                self.rest = &[];
                Some(Err(FixtureError::Decode { offset }))
            }
        }
    }
}

/// Streaming reader of the input file (no allocation: images and frames borrow or copy
/// from the file bytes).
#[derive(Clone, Debug)]
pub struct InputReader<'a> {
    /// The file header.
    pub header: InputHeader,
    images: heapless::Vec<&'a [u8], MAX_IMAGES>,
    records: Records<'a>,
}

impl<'a> InputReader<'a> {
    /// Read the header and the table images.
    ///
    /// # Errors
    /// [`FixtureError`].
    pub fn new(bytes: &'a [u8]) -> Result<Self, FixtureError> {
        let (header, mut rest) = postcard::take_from_bytes::<InputHeader>(bytes)
            .map_err(|_| FixtureError::Decode { offset: 0 })?;
        if header.magic != INPUT_MAGIC || header.version != FIXTURE_VERSION {
            return Err(FixtureError::BadHeader);
        }
        let mut images = heapless::Vec::new();
        for _ in 0..header.images {
            let offset = offset_of(bytes, rest);
            let (image, after) = postcard::take_from_bytes::<&'a [u8]>(rest)
                .map_err(|_| FixtureError::Decode { offset })?;
            images
                .push(image)
                .map_err(|_| FixtureError::TooManyImages)?;
            rest = after;
        }
        Ok(Self {
            header,
            images,
            records: Records {
                all: bytes,
                rest,
                remaining: header.cycles,
            },
        })
    }

    /// The table images of the file.
    #[must_use]
    pub fn images(&self) -> &[&'a [u8]] {
        &self.images
    }

    /// The next cycle, `None` after the last one.
    ///
    /// # Errors
    /// [`FixtureError::Decode`], or [`FixtureError::TrailingBytes`] after the last cycle.
    pub fn next_cycle(&mut self) -> Option<Result<RecordedCycle, FixtureError>> {
        self.records.next()
    }

    /// The executive commands of a recorded cycle, table images borrowed from the file.
    ///
    /// # Errors
    /// [`FixtureError::BadCommand`].
    pub fn commands(
        &self,
        cycle: &RecordedCycle,
    ) -> Result<heapless::Vec<Command<'a>, MAX_RECORDED_COMMANDS>, FixtureError> {
        let mut out = heapless::Vec::new();
        for rc in &cycle.commands {
            let cmd = to_command(rc, &self.images)?;
            out.push(cmd).map_err(|_| FixtureError::BadCommand)?;
        }
        Ok(out)
    }
}

fn quat(q: &[f64; 4]) -> Quat {
    let [x, y, z, w] = *q;
    Quat::new(x, y, z, w)
}

fn table_id(code: u8) -> Result<TableId, FixtureError> {
    TableId::from_u8(code).ok_or(FixtureError::BadCommand)
}

/// Convert a recorded command to the executive's command.
///
/// # Errors
/// [`FixtureError::BadCommand`] for an unknown image index, table id or configuration.
pub fn to_command<'a>(
    rc: &RecordedCommand,
    images: &[&'a [u8]],
) -> Result<Command<'a>, FixtureError> {
    Ok(match rc {
        RecordedCommand::SlewTo(q) => Command::SlewTo(quat(q)),
        RecordedCommand::Hold => Command::Hold,
        RecordedCommand::SelectIruConfig(0) => Command::SelectIruConfig(IruConfiguration::Primary),
        RecordedCommand::SelectIruConfig(1) => Command::SelectIruConfig(IruConfiguration::Backup),
        RecordedCommand::SelectIruConfig(_) => return Err(FixtureError::BadCommand),
        RecordedCommand::TableLoad(n) => Command::TableLoad(
            images
                .get(usize::from(*n))
                .copied()
                .ok_or(FixtureError::BadCommand)?,
        ),
        RecordedCommand::TableActivate(id) => Command::TableActivate(table_id(*id)?),
        RecordedCommand::TableAbort(id) => Command::TableAbort(table_id(*id)?),
        RecordedCommand::FilterInitialize(q) => Command::FilterInitialize(quat(q)),
        RecordedCommand::FilterReset => Command::FilterReset,
    })
}

/// Streaming reader of the expected-output file.
#[derive(Clone, Debug)]
pub struct ExpectedReader<'a> {
    /// The file header.
    pub header: ExpectedHeader,
    records: Records<'a>,
}

impl<'a> ExpectedReader<'a> {
    /// Read the header.
    ///
    /// # Errors
    /// [`FixtureError`].
    pub fn new(bytes: &'a [u8]) -> Result<Self, FixtureError> {
        let (header, rest) = postcard::take_from_bytes::<ExpectedHeader>(bytes)
            .map_err(|_| FixtureError::Decode { offset: 0 })?;
        if header.magic != EXPECTED_MAGIC || header.version != FIXTURE_VERSION {
            return Err(FixtureError::BadHeader);
        }
        Ok(Self {
            header,
            records: Records {
                all: bytes,
                rest,
                remaining: header.cycles,
            },
        })
    }

    /// The next cycle's expected output, `None` after the last one.
    ///
    /// # Errors
    /// [`FixtureError::Decode`] or [`FixtureError::TrailingBytes`].
    pub fn next_cycle(&mut self) -> Option<Result<ExpectedCycle<'a>, FixtureError>> {
        self.records.next()
    }
}

/// A cycle record in a fixed buffer.
#[derive(Clone, Debug)]
pub struct CycleRecord {
    buf: [u8; CYCLE_RECORD_MAX],
    len: usize,
}

impl CycleRecord {
    /// Encode one cycle's output with the ICD encoders.
    ///
    /// # Errors
    /// [`FixtureError::Encode`] (cannot happen with the ICD lengths).
    pub fn encode(out: &CycleOutput) -> Result<Self, FixtureError> {
        let mut buf = [0u8; CYCLE_RECORD_MAX];
        let mut at = 0usize;
        {
            let dst = buf.get_mut(at..).ok_or(FixtureError::Encode)?;
            at = at.saturating_add(
                encode_time_code(out.housekeeping.time, dst).map_err(|_| FixtureError::Encode)?,
            );
        }
        {
            let dst = buf.get_mut(at..).ok_or(FixtureError::Encode)?;
            at = at.saturating_add(
                encode_housekeeping(&out.housekeeping, dst).map_err(|_| FixtureError::Encode)?,
            );
        }
        let n_events = u8::try_from(out.events.len()).map_err(|_| FixtureError::Encode)?;
        *buf.get_mut(at).ok_or(FixtureError::Encode)? = n_events;
        at = at.saturating_add(1);
        for e in &out.events {
            let dst = buf.get_mut(at..).ok_or(FixtureError::Encode)?;
            at = at.saturating_add(encode_event(e, dst).map_err(|_| FixtureError::Encode)?);
        }
        Ok(Self { buf, len: at })
    }

    /// The record bytes.
    #[must_use]
    pub fn bytes(&self) -> &[u8] {
        self.buf.get(..self.len).unwrap_or(&[])
    }

    /// CRC-32/ISO-HDLC of the record.
    #[must_use]
    pub fn digest(&self) -> u32 {
        IMAGE_CRC.checksum(self.bytes())
    }
}

/// CRC-32/ISO-HDLC of a whole file (the `inputs_crc` of the expected file).
#[must_use]
pub fn file_crc(bytes: &[u8]) -> u32 {
    IMAGE_CRC.checksum(bytes)
}

/// How one replayed cycle compares with the expected output.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CycleCheck {
    /// Digest (and full record when stored) identical.
    Match,
    /// The digests differ; `first_byte` is the first differing byte of the record when the
    /// expected record is stored.
    Mismatch {
        /// Digest of the replayed cycle.
        got: u32,
        /// Expected digest.
        expected: u32,
        /// First differing byte offset in the cycle record, when known.
        first_byte: Option<u16>,
    },
}

/// Compare a replayed cycle record with its expected output.
#[must_use]
pub fn check_cycle(record: &CycleRecord, expected: &ExpectedCycle<'_>) -> CycleCheck {
    let got = record.digest();
    let first_byte =
        expected.record.and_then(|exp| {
            let mine = record.bytes();
            let diff = mine.iter().zip(exp.iter()).position(|(a, b)| a != b).or(
                if mine.len() == exp.len() {
                    None
                } else {
                    Some(mine.len().min(exp.len()))
                },
            );
            diff.map(|d| u16::try_from(d).unwrap_or(u16::MAX))
        });
    if got == expected.digest && first_byte.is_none() {
        CycleCheck::Match
    } else {
        CycleCheck::Mismatch {
            got,
            expected: expected.digest,
            first_byte,
        }
    }
}
