//! Fuzz every `fsw_core::telemetry` decoder with arbitrary bytes (docs/reliability.md).
//!
//! Input: a packet data field, i.e. the 6-octet CUC time code then the user data. Each
//! decoder runs on the user data; a decoded record must re-encode to exactly the same octets
//! (the layouts are fixed and every bit pattern of a float is kept), and a refusal must be a
//! length error exactly when the length is wrong, or a bad enumeration at the documented
//! offset.
#![no_main]

use fsw_core::raw::TimeTag;
use fsw_core::telemetry::{
    decode_ephemeris, decode_event, decode_housekeeping, decode_magnetics, decode_raw_frame,
    decode_time_code, encode_ephemeris, encode_event, encode_housekeeping, encode_magnetics,
    encode_raw_frame, encode_time_code, RecordError, EPHEMERIS_LEN, EVENT_LEN, HOUSEKEEPING_LEN,
    MAGNETICS_LEN, RAW_FRAME_LEN, TIME_CODE_LEN,
};
use libfuzzer_sys::fuzz_target;

fn check<T>(
    user: &[u8],
    len: usize,
    enum_offsets: &[usize],
    decoded: Result<T, RecordError>,
    encode: impl Fn(&T, &mut [u8]) -> Result<usize, RecordError>,
) {
    match decoded {
        Ok(r) => {
            assert_eq!(user.len(), len);
            let mut buf = [0u8; 256];
            let n = encode(&r, &mut buf).expect("record fits");
            assert_eq!(&buf[..n], user, "decode/encode is not the identity");
            // A too-small buffer is an error, never a panic.
            assert_eq!(
                encode(&r, &mut buf[..len - 1]),
                Err(RecordError::BufferTooSmall)
            );
        }
        Err(RecordError::Length { expected, found }) => {
            assert_eq!((expected, found), (len, user.len()));
            assert_ne!(user.len(), len);
        }
        Err(RecordError::BadEnum { offset }) => {
            assert_eq!(user.len(), len);
            assert!(enum_offsets.contains(&offset), "offset {offset}");
        }
        Err(RecordError::BufferTooSmall) => panic!("decoder returned BufferTooSmall"),
    }
}

fuzz_target!(|data: &[u8]| {
    let time = match decode_time_code(data) {
        Ok(t) => {
            let mut buf = [0u8; TIME_CODE_LEN];
            assert_eq!(encode_time_code(t, &mut buf), Ok(TIME_CODE_LEN));
            assert_eq!(&buf[..], &data[..TIME_CODE_LEN]);
            t
        }
        Err(e) => {
            assert!(data.len() < TIME_CODE_LEN, "{e:?}");
            TimeTag::default()
        }
    };
    let user = data.get(TIME_CODE_LEN..).unwrap_or(&[]);
    check(
        user,
        RAW_FRAME_LEN,
        &[13],
        decode_raw_frame(time, user),
        encode_raw_frame,
    );
    check(
        user,
        HOUSEKEEPING_LEN,
        &[120, 133, 146, 159],
        decode_housekeeping(time, user),
        encode_housekeeping,
    );
    check(user, EVENT_LEN, &[0], decode_event(user), encode_event);
    check(
        user,
        EPHEMERIS_LEN,
        &[],
        decode_ephemeris(time, user),
        encode_ephemeris,
    );
    check(
        user,
        MAGNETICS_LEN,
        &[],
        decode_magnetics(time, user),
        encode_magnetics,
    );
    // Records carry the time of the secondary header.
    if let Ok(r) = decode_raw_frame(time, user) {
        assert_eq!(r.time, time);
    }
    if let Ok(r) = decode_housekeeping(time, user) {
        assert_eq!(r.time, time);
    }
    if let Ok(r) = decode_ephemeris(time, user) {
        assert_eq!(r.time, time);
    }
    if let Ok(r) = decode_magnetics(time, user) {
        assert_eq!(r.time, time);
    }
});
