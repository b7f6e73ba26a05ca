//! Fuzz the ground telemetry reader `ground_tool::tp::decode` with arbitrary bytes
//! (docs/reliability.md).
//!
//! Invariants: never panics; the report's file length is the input length; skipped regions
//! are non-empty, inside the file, in increasing order and disjoint; duplicate offsets are
//! inside the file; decoded packets, dropped duplicates, packets dropped for a damaged time
//! code and skipped regions add up to the whole file (every octet is accounted for exactly
//! once); time-code outliers and jumps are inside the file; the record counts match the
//! records returned, which are sorted by time.
#![no_main]

use libfuzzer_sys::fuzz_target;

fn packet_len(apid: u16) -> usize {
    ground_tool::tp::packet_len(apid)
        .unwrap_or_else(|| panic!("duplicate with unknown APID 0x{apid:03x}"))
}

fuzz_target!(|data: &[u8]| {
    let tm = ground_tool::tp::decode(data);
    let r = &tm.report;
    assert_eq!(r.file_len, data.len());
    let mut end = 0usize;
    for s in &r.skipped {
        assert!(s.len > 0, "empty skipped region {s:?}");
        assert!(
            s.offset >= end,
            "skipped regions overlap or are out of order: {:?}",
            r.skipped
        );
        end = s.offset.checked_add(s.len).expect("no overflow");
        assert!(
            end <= data.len(),
            "skipped region beyond the end of the file: {s:?}"
        );
    }
    let mut dup_octets = 0usize;
    for &d in &r.duplicates {
        assert!(d + 6 <= data.len());
        let apid = u16::from_be_bytes([data[d], data[d + 1]]) & 0x07ff;
        let n = packet_len(apid);
        assert!(d + n <= data.len());
        dup_octets += n;
    }
    for &(off, _, _) in &r.time_reversals {
        assert!(off < data.len());
    }
    // The report's counts are those of the records returned (not of an earlier stage).
    assert_eq!(r.packets, ground_tool::tp::PacketCounts::of(&tm));
    let decoded: usize = r
        .packets
        .by_apid()
        .iter()
        .map(|&(apid, n)| n * packet_len(apid))
        .sum();
    let mut outlier_octets = 0;
    for o in &r.time_outliers {
        assert!(o.offset + o.len <= data.len());
        outlier_octets += o.len;
    }
    for j in &r.time_jumps {
        assert!(j.offset < data.len() && j.to_s < j.from_s);
    }
    assert_eq!(
        decoded + dup_octets + outlier_octets + r.skipped_octets(),
        data.len(),
        "octets not accounted for exactly once"
    );
    assert!(tm.raw.windows(2).all(|w| w[0].time <= w[1].time));
    assert!(tm.housekeeping.windows(2).all(|w| w[0].time <= w[1].time));
    assert!(tm.events.windows(2).all(|w| w[0].0 <= w[1].0));
    assert!(tm.ephemeris.windows(2).all(|w| w[0].time <= w[1].time));
    assert!(tm.magnetics.windows(2).all(|w| w[0].time <= w[1].time));
    assert!(tm.wheels.windows(2).all(|w| w[0].time <= w[1].time));
});
