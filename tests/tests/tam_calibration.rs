//! e2e: the ground's TAM calibration (issue 20) on one short flight of `gro-early-mission`.
//!
//! Fly the first hour (seed 1; `[magnetics] enabled`, so the telemetry carries APID 0x013),
//! calibrate from the telemetry alone, and check the primary TAM's bias against `truth.json`
//! `tam.effective_bias_mG` ([0, 0, −4] mG: the paper's bias, no residual field): within 3σ
//! of its stated σ on every axis, σ small enough to say something (< 0.5 mG), the estimated
//! noise near the a-priori 0.22 mG, the held-out halves reported, and the FSS/TAM TRIAD
//! attitude within the 2° coarse requirement of the FHST fine attitude. Then the
//! same telemetry without its 0x013 packets: `tam` says why it is not determined, and the
//! calibration still succeeds. The statistics over seeds are in docs/magnetics.md §4.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod support;

use ground_tool::pipeline::calibrate::{calibrate_run, CalibrateOptions};
use sim_harness::scenario::resolve;

/// One simulated hour: 77 TAM samples with a fine attitude, the field turning enough in the
/// body for the full model (condition ≈ 5e2), about 0.5 s of calibration in a dev build.
const DURATION_S: f64 = 3600.0;

#[test]
fn e2e_tam_bias_recovered_within_its_sigma() {
    let out = support::fresh_dir("gro-e2e-tam");
    let fly = out.join("run");
    let mut scenario = resolve("gro-early-mission").unwrap();
    assert!(
        scenario.magnetics.enabled,
        "gro-early-mission flies the TAMs"
    );
    scenario.duration_s = DURATION_S;
    support::fly(scenario, &fly, None);
    let c = calibrate_run(&fly, &out.join("cal"), &CalibrateOptions::default()).unwrap();
    let tam = &c.report.tam;
    assert_eq!(tam.status, "determined", "{:?}", tam.reason);
    let truth = gro_tests::loop_report::read_truth(&fly).unwrap();
    let true_bias = truth
        .tam
        .expect("the truth's TAMs")
        .tam1
        .effective_bias_milligauss;
    let (bias, sigma) = (
        tam.bias_milligauss.unwrap(),
        tam.bias_sigma_milligauss.unwrap(),
    );
    for i in 0..3 {
        let z = (bias[i] - true_bias[i]) / sigma[i];
        assert!(
            z.abs() < 3.0 && sigma[i] < 0.5,
            "axis {i}: {:.3} ± {:.3} mG against {:.3} (z {z:.2})",
            bias[i],
            sigma[i],
            true_bias[i]
        );
    }
    let tam1 = tam.tam1.as_ref().unwrap();
    assert!(tam1.samples >= 50, "{} samples", tam1.samples);
    for s in tam1.noise_estimated_milligauss {
        assert!(
            (0.15..0.35).contains(&s),
            "noise {s} mG against 0.22 a priori"
        );
    }
    assert_eq!(tam1.heldout.len(), 2);
    // The TRIAD check is reported; within the 2° (3σ) coarse requirement after the bias
    // correction. Whether the correction improves it depends on the field's direction in the
    // body (a bias along the field changes only its length): on the full 5.2 h flight it
    // does (docs/magnetics.md §4), on this hour it does not, so that is not asserted.
    let triad = tam.triad_comparison.as_ref().unwrap();
    assert!(triad.samples >= 10, "{} TRIAD frames", triad.samples);
    for x in triad.bias_corrected.three_rms_deg {
        assert!(x < 2.0, "TRIAD 3×RMS {x}° after the bias correction");
    }
    // The magnetics table (Table 6): decided, and when written, on disk, listed, accepted by
    // the OBC's validation, with the determined bias.
    let decision = tam.table.as_ref().unwrap();
    let path = out.join("cal/tables/magnetics.tbl");
    println!("magnetics table: {}", decision.reason);
    assert!(!decision.reason.is_empty());
    assert_eq!(path.exists(), decision.written);
    if decision.written {
        let (_, table) =
            ground_tool::table::decode_image(&std::fs::read(&path).unwrap(), "magnetics").unwrap();
        let ground_tool::table::AnyTable::Magnetics(t) = table else {
            panic!("not a magnetics table");
        };
        assert_eq!(t.validate(), Ok(()));
        assert_eq!(t.field_degree, 10);
        let b = tam.bias_milligauss.unwrap();
        assert!((t.tam_bias_milligauss[0][2] - b[2]).abs() < 0.01);
        let manifest = std::fs::read_to_string(out.join("cal/tables/manifest.json")).unwrap();
        assert!(manifest.contains("magnetics.tbl"));
    }

    // The same telemetry without APID 0x013 (a format-version-1 file): not determined, and why.
    let old = out.join("v1");
    support::copy_run_without_apid(&fly, &old, 0x013);
    // As `ground-tool calibrate` does: the flown magnetics table from the run's uploads (here
    // listed without their files).
    let meta = ground_tool::pipeline::flown::metadata_or_default(&old);
    let options = CalibrateOptions {
        flown_magnetics: ground_tool::pipeline::flown::flown_magnetics(&old, &meta)
            .map_err(|e| format!("{e:#}")),
        ..CalibrateOptions::default()
    };
    let c = calibrate_run(&old, &out.join("cal-v1"), &options).unwrap();
    assert_eq!(c.report.tam.status, "not_determined");
    assert!(c.report.tam.bias_milligauss.is_none());
    let reason = c.report.tam.reason.clone().unwrap();
    assert!(reason.contains("APID 0x013"), "{reason}");
    let decision = c.report.tam.table.as_ref().unwrap();
    assert!(!decision.written && decision.reason.contains("no TAM1 calibration"));
    // The v1 copy lists the uploads without their files: said, not fatal.
    assert!(
        decision.reason.contains("flown magnetics table is unknown"),
        "{}",
        decision.reason
    );
    assert!(!out.join("cal-v1/tables/magnetics.tbl").exists());
    let _ = std::fs::remove_dir_all(&out);
}
