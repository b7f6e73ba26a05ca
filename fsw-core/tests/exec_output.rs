//! The executive's output is postcard-serializable and round-trips (stable layout), and bad
//! input (non-monotonic time, NaN-free garbage counts) is flagged without touching the estimate.

use fsw_core::attitude::Quat;
use fsw_core::executive::{Command, CycleOutput, FlightCore};
use fsw_core::raw::{RawSensorFrame, TimeTag, FHST_FLAG_TRACKING, FHST_FLAG_VALID};

fn frame(t: f64) -> RawSensorFrame {
    RawSensorFrame {
        time: TimeTag::from_seconds(t).unwrap(),
        ..RawSensorFrame::default()
    }
}

#[test]
fn prop_cycle_output_postcard_round_trip() {
    let mut core = FlightCore::new();
    let q = Quat::new(0.1, -0.2, 0.3, 0.927).normalized();
    let out = core.step(&frame(1.0e9), &[Command::FilterInitialize(q)]);
    let mut buf = [0u8; 1024];
    let bytes = postcard::to_slice(&out, &mut buf).unwrap();
    let back: CycleOutput = postcard::from_bytes(bytes).unwrap();
    assert_eq!(back, out);
    assert!(!out.events.is_empty(), "initialisation raises an event");
}

#[test]
fn time_going_backwards_is_flagged_and_estimate_kept() {
    let mut core = FlightCore::new();
    let q = Quat::new(0.0, 0.0, 0.0, 1.0);
    core.step(&frame(1.0e9), &[Command::FilterInitialize(q)]);
    core.step(&frame(1.0e9 + 1.0), &[]);
    let before = core.attitude();
    let mut bad = frame(1.0e9 - 50.0);
    // An out-of-field star that must be refused by input validation.
    bad.fhst[0].h_counts = i16::MAX;
    bad.fhst[0].flags = FHST_FLAG_VALID | FHST_FLAG_TRACKING;
    bad.fhst[0].magnitude_centimag = 400;
    let out = core.step(&bad, &[]);
    assert_eq!(out.housekeeping.counters.time_tag_anomalies, 1);
    assert!(out.housekeeping.counters.rejected_inputs >= 1);
    // No gyro motion and no accepted measurement: the attitude is unchanged.
    assert!(core.attitude().angle_to_rad(&before) < 1e-9);
}
