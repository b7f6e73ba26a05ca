//! Gyro noise identification (`ground_tool::calibration::allan`) on synthetic telemetry and
//! synthetic rate series whose noise is known: values, intervals, the pair difference
//! against the body's motion, the typed refusals, and the CLI's exit codes.
//!
//! Tolerances: the identified ARW and RRW within 20 % (issue 19's requirement) on a run of
//! 2^16 samples whose RRW is exaggerated (so that one run holds 8 octaves of it). The 95 %
//! intervals are known to be optimistic: over 40 seeded white + random-walk series of 2^14
//! samples they covered the true N in 80 % and the true K in 75–85 % of the series (a
//! spurious bias-instability floor, kept by the information criterion in a few series,
//! takes variance from K and the bootstrap does not simulate it); the test holds that
//! measured level (≥ 14 of 20) so that a regression shows, not the nominal 95 %.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod support;

use fsw_core::raw::{RawSensorFrame, TimeTag};
use fsw_core::tables::IruTable;
use fsw_core::telemetry::ObcHousekeeping;
use fsw_core::units::RAD_PER_ARCSEC;
use ground_tool::calibration::allan::{
    analyse_segments, identify_gyro_noise, AllanError, AllanOptions, Signal,
};
use ground_tool::tp::Telemetry;
use rand_distr::{Distribution, StandardNormal};

/// A seeded ChaCha8 stream: the draws `sim_harness::sensors::model_rng` gives, without the
/// simulator (the ground tool's tests do not depend on it).
fn model_rng(seed: u64, stream: u64) -> rand_chacha::ChaCha8Rng {
    use rand::SeedableRng;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(stream);
    rng
}

/// Per-channel noise of the synthetic gyro, rad/√s and rad/s/√s.
const ARW: f64 = 2.0e-7;
const RRW: f64 = 2.0e-9;
/// First frame, s TAI since 1958 (1991).
const T0_S: f64 = 1_050_000_000.0;

struct Synth {
    frames: usize,
    /// Control mode of every housekeeping packet.
    control_mode: u8,
    /// Frames (by index) that are not downlinked.
    missing_every: Option<usize>,
    /// Amplitude of the body's common motion, rad/s (sinusoid of 47 s + a slow one).
    body_rad_per_s: f64,
    /// Channel with its BIT bit set throughout.
    failed_channel: Option<usize>,
    seed: u64,
}

impl Default for Synth {
    fn default() -> Self {
        Self {
            frames: 65_537,
            control_mode: 1,
            missing_every: None,
            body_rad_per_s: 5e-6,
            failed_channel: None,
            seed: 7,
        }
    }
}

/// Six channels on three axes (channel = axis rate + own bias, ARW, RRW), counted in whole
/// low-rate pulses with the remainder kept, 16-bit counters; housekeeping every frame.
fn telemetry(s: &Synth) -> Telemetry {
    let mut rng = model_rng(s.seed, 19);
    let mut gauss = move || -> f64 { StandardNormal.sample(&mut rng) };
    let q_rad = 0.05 * RAD_PER_ARCSEC;
    let mut remainder = [0.0_f64; 6];
    let mut counts = [0u16; 6];
    let mut walk = [0.0_f64; 6];
    let bias = [1.1e-6, -0.7e-6, 0.4e-6, 1.9e-6, -1.3e-6, 0.2e-6];
    let mut tm = Telemetry::default();
    for k in 0..s.frames {
        let t = k as f64;
        if k > 0 {
            for ch in 0..6 {
                let axis = ch / 2;
                let body = s.body_rad_per_s
                    * ((t / 47.0 + axis as f64).sin() + 0.5 * (t / 900.0 + axis as f64).cos());
                walk[ch] += RRW * gauss();
                let acc = remainder[ch] + (body + bias[ch] + walk[ch]) + ARW * gauss();
                let pulses = (acc / q_rad).floor();
                remainder[ch] = acc - pulses * q_rad;
                counts[ch] = (i64::from(counts[ch]) + pulses as i64).rem_euclid(65_536) as u16;
            }
        }
        if s.missing_every.is_some_and(|n| k % n == n - 1) {
            continue;
        }
        let time = TimeTag::from_seconds(T0_S + t).unwrap();
        let mut raw = RawSensorFrame {
            time,
            ..RawSensorFrame::default()
        };
        raw.iru.counts = counts;
        raw.iru.channel_failed = s.failed_channel.map_or(0, |c| 1 << c);
        tm.raw.push(raw);
        tm.housekeeping.push(ObcHousekeeping {
            time,
            control_mode: s.control_mode,
            ..ObcHousekeeping::default()
        });
    }
    tm
}

fn within(got: f64, want: f64, tol: f64) -> bool {
    ((got - want) / want).abs() <= tol
}

#[test]
fn val_pair_difference_recovers_arw_and_rrw_under_body_motion() {
    let tm = telemetry(&Synth::default());
    let r = identify_gyro_noise(&tm, &IruTable::prelaunch(), &AllanOptions::default()).unwrap();
    assert_eq!(r.axes.len(), 3);
    for a in &r.axes {
        assert_eq!(a.samples, 65_536);
        assert_eq!(a.segments, 1);
        let [n, n_lo, n_hi] = a.arw_rad_per_sqrt_s;
        let [k, k_lo, k_hi] = a.rrw_rad_per_s_sqrt_s;
        assert!(within(n, ARW, 0.2), "{}: ARW {n:e} vs {ARW:e}", a.axis);
        assert!(within(k, RRW, 0.2), "{}: RRW {k:e} vs {RRW:e}", a.axis);
        assert!(n_lo < n && n < n_hi && k_lo < k && k < k_hi);
        // Where each came from: the ARW below the crossing √3 N/K ≈ 170 s, the RRW above.
        let [a0, a1] = a.fit.arw_rad_per_sqrt_s.dominant_tau_s.unwrap();
        let [r0, r1] = a.fit.rrw_rad_per_s_sqrt_s.dominant_tau_s.unwrap();
        assert!(
            a1 < 400.0 && a0 >= 1.0 && r0 > 100.0 && r1 > 1000.0,
            "{a0} {a1} {r0} {r1}"
        );
        // No flicker noise in the data: no flat floor is claimed.
        assert!(!a.fit.bias_instability_rad_per_s.detected);
    }
    // The same run through the active channel alone: the body's motion (5e-6 rad/s) swamps
    // the gyro's noise over tens of seconds, and the figures are far off.
    let opts = AllanOptions {
        signal: Signal::ActiveChannel,
        ..AllanOptions::default()
    };
    let r1 = identify_gyro_noise(&tm, &IruTable::prelaunch(), &opts).unwrap();
    for a in &r1.axes {
        let n = a.arw_rad_per_sqrt_s[0];
        assert!(
            !a.fit.arw_rad_per_sqrt_s.detected || !within(n, ARW, 0.5),
            "{}: body motion should spoil the ARW, got {n:e}",
            a.axis
        );
    }
}

#[test]
fn val_intervals_cover_the_truth_monte_carlo() {
    let (seeds, n) = (20, 16_384);
    let (mut cover_n, mut cover_k) = (0, 0);
    let (mut err2_n, mut err2_k) = (0.0, 0.0);
    for seed in 0..seeds {
        let mut rng = model_rng(seed, 3);
        let mut walk = 0.0;
        let y: Vec<f64> = (0..n)
            .map(|_| {
                let (a, b): (f64, f64) = (
                    StandardNormal.sample(&mut rng),
                    StandardNormal.sample(&mut rng),
                );
                walk += RRW * b;
                ARW * a + walk
            })
            .collect();
        let (_, fit) = analyse_segments("X", &[y], 1.0, 0.95).unwrap();
        let (tn, tk) = (&fit.arw_rad_per_sqrt_s, &fit.rrw_rad_per_s_sqrt_s);
        cover_n += usize::from(tn.low <= ARW && ARW <= tn.high);
        cover_k += usize::from(tk.low <= RRW && RRW <= tk.high);
        err2_n += ((tn.value - ARW) / ARW).powi(2);
        err2_k += ((tk.value - RRW) / RRW).powi(2);
    }
    let (rms_n, rms_k) = (
        (err2_n / seeds as f64).sqrt(),
        (err2_k / seeds as f64).sqrt(),
    );
    assert!(
        cover_n >= 14 && cover_k >= 14,
        "coverage N {cover_n}/20, K {cover_k}/20"
    );
    // The point estimates (measured: RMS 5.5 % for N, 28 % for K over these 20 series of
    // 2^14 samples; the five-term fit trades N against a quantization term and K against a
    // floor, so N is not as good as one τ = 1 s point alone would give).
    assert!(
        rms_n < 0.08 && rms_k < 0.35,
        "RMS relative error N {rms_n:.3}, K {rms_k:.3}"
    );
}

#[test]
fn refusals_name_the_evidence() {
    let prelaunch = IruTable::prelaunch();
    let opts = AllanOptions::default();
    // Every frame in a slew.
    let slewing = telemetry(&Synth {
        frames: 3000,
        control_mode: 2,
        ..Synth::default()
    });
    match identify_gyro_noise(&slewing, &prelaunch, &opts) {
        Err(AllanError::NoHolds {
            frames,
            hold_frames,
            ..
        }) => assert_eq!((frames, hold_frames), (3000, 0)),
        other => panic!("expected NoHolds, got {other:?}"),
    }
    // A frame missing every 200: segments of 198–199 samples, too few in total.
    let gappy = telemetry(&Synth {
        frames: 1000,
        missing_every: Some(200),
        ..Synth::default()
    });
    match identify_gyro_noise(&gappy, &prelaunch, &opts) {
        Err(AllanError::Gaps {
            gaps,
            largest_gap_s,
            longest_segment,
            ..
        }) => {
            assert_eq!(gaps, 4);
            assert!((largest_gap_s - 2.0).abs() < 1e-6);
            assert!(longest_segment < 200);
        }
        other => panic!("expected Gaps, got {other:?}"),
    }
    // One short hold without gaps.
    let short = telemetry(&Synth {
        frames: 700,
        ..Synth::default()
    });
    match identify_gyro_noise(&short, &prelaunch, &opts) {
        Err(AllanError::TooFewSamples {
            usable, segments, ..
        }) => assert_eq!((usable, segments), (699, 1)),
        other => panic!("expected TooFewSamples, got {other:?}"),
    }
    // A failed channel takes its axis out, the others stay.
    let failed = telemetry(&Synth {
        frames: 4097,
        failed_channel: Some(0),
        ..Synth::default()
    });
    let r = identify_gyro_noise(&failed, &prelaunch, &opts).unwrap();
    assert_eq!(
        r.axes.iter().map(|a| a.axis).collect::<Vec<_>>(),
        ["Y", "Z"]
    );
    assert!(
        r.notes.iter().any(|n| n.contains("axis X not identified")),
        "{:?}",
        r.notes
    );
}

#[test]
fn cli_writes_outputs_and_refuses_short_runs_with_exit_2() {
    let run = support::write_run("allan", "hold", &["--no-slews", "--duration", "3000"]);
    let out = run.with_extension("allan-out");
    let _ = std::fs::remove_dir_all(&out);
    let gt = env!("CARGO_BIN_EXE_ground-tool");
    support::ground_tool_ok(gt, "allan", &run, &out, &[]);
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("allan.json")).unwrap()).unwrap();
    assert_eq!(json["axes"].as_array().unwrap().len(), 3);
    assert!(out.join("allan.md").exists() && out.join("allan.png").exists());
    // 600 s of hold: fewer than 1024 samples.
    let short = support::write_run("allan", "short", &["--no-slews", "--duration", "600"]);
    let o = support::ground_tool(gt, "allan", &short, &short.with_extension("allan-out"), &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("600 samples") && err.contains("1024 needed"),
        "{err}"
    );
    for d in [
        run.clone(),
        out,
        short.clone(),
        short.with_extension("allan-out"),
    ] {
        let _ = std::fs::remove_dir_all(d);
    }
}
