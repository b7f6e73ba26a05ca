//! The table and record errors read as sentences for people (issue 17: operators saw
//! `CrcMismatch { computed: 3292253094, stored: … }` and `BadEnum { offset: 13 }`), each
//! carrying its evidence and, for tables, its reason code (docs/tables.md).

use fsw_core::tables::{TableError, TableId};
use fsw_core::telemetry::RecordError;

#[test]
fn every_table_error_is_a_sentence_with_its_reason_code() {
    let all = [
        TableError::TooShort { len: 12 },
        TableError::TooLong { len: 9, max: 8 },
        TableError::BadMagic { found: 0x1234 },
        TableError::UnknownTableId { found: 9 },
        TableError::WrongTableId {
            expected: TableId::Alignment,
            found: TableId::Iru,
        },
        TableError::UnsupportedVersion { found: 7 },
        TableError::ReservedNotZero,
        TableError::LengthMismatch {
            declared: 10,
            actual: 9,
        },
        TableError::CrcMismatch {
            computed: 0xdead_beef,
            stored: 0x0bad_f00d,
        },
        TableError::PayloadDecode,
        TableError::BufferTooSmall,
        TableError::NotFinite { field: 3 },
        TableError::NotRotation { sensor: 2 },
        TableError::OutOfRange { field: 4 },
        TableError::ChangeTooLarge {
            field: 0,
            change: 36_000.0,
            limit: 3600.0,
        },
    ];
    for e in all {
        let text = e.to_string();
        assert!(
            text.ends_with(&format!("[reason {}]", e.code())),
            "{e:?}: {text}"
        );
        assert!(!text.contains('{') && text.len() > 30, "{e:?}: {text}");
    }
    let crc = TableError::CrcMismatch {
        computed: 0xdead_beef,
        stored: 0x0bad_f00d,
    }
    .to_string();
    assert!(crc.contains("0xdeadbeef") && crc.contains("0x0badf00d") && crc.contains("damaged"));
    assert!(TableError::NotRotation { sensor: 2 }
        .to_string()
        .contains("FSS1"));
}

#[test]
fn record_errors_are_sentences_with_their_evidence() {
    let e = RecordError::BadEnum { offset: 13 }.to_string();
    assert!(e.contains("octet 13") && !e.contains('{'), "{e}");
    let e = RecordError::Length {
        expected: 48,
        found: 47,
    }
    .to_string();
    assert!(
        e.contains("47") && e.contains("48") && !e.contains('{'),
        "{e}"
    );
}
