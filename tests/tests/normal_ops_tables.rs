//! e2e: the filter table `normal-ops` flies is the one the ground derives.
//!
//! `scenarios/normal-ops.toml` uplinks σ_u = 7.368e-11 (docs/obc_filter.md §12): the gyro
//! model's σ_u at its epoch (55 days after release: K, sim-harness
//! `onboard::filter_rrw_for_epoch_rad_per_s_sqrt_s`) raised by `ground-tool calibrate` on one
//! day flown with it (seed 1). Fly that day again, calibrate from the telemetry alone, and
//! check that the ground still writes the shipped value (within 1 %): a change to the gyro
//! model, the flight or the ground's Allan gate that moves it fails here.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use ground_tool::pipeline::calibrate::calibrate_run;
use ground_tool::pipeline::filter_tuning::FilterTerm;
use sim_harness::onboard::filter_rrw_for_epoch_rad_per_s_sqrt_s;
use sim_harness::scenario::resolve;

mod support;

#[test]
fn e2e_normal_ops_flies_the_grounds_rate_random_walk() {
    let out = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("gro-e2e-normal-ops-rrw");
    let _ = std::fs::remove_dir_all(&out);
    let fly = out.join("run");
    let mut scenario = resolve("normal-ops").unwrap();
    let shipped = scenario
        .filter_table
        .as_ref()
        .and_then(|t| t.get("rrw_rad_per_s_sqrt_s"))
        .and_then(toml::Value::as_float)
        .unwrap();
    let model = filter_rrw_for_epoch_rad_per_s_sqrt_s(scenario.iru.time_since_release_at_start_s);
    scenario.duration_s = 86_400.0;
    scenario.seed = 1;
    scenario
        .filter_table
        .as_mut()
        .unwrap()
        .insert("rrw_rad_per_s_sqrt_s".into(), toml::Value::Float(model));
    support::fly(scenario, &fly, None);
    // The tables flown, read from the run as `ground-tool calibrate` reads them.
    let meta = ground_tool::pipeline::flown::metadata_or_default(&fly);
    let options = ground_tool::pipeline::flown::calibrate_options(&fly, &meta, None).unwrap();
    let c = calibrate_run(&fly, &out.join("cal"), &options).unwrap();
    let rrw = c
        .report
        .filter_tuning
        .iter()
        .find(|d| d.field == FilterTerm::Rrw)
        .unwrap();
    eprintln!(
        "flown {:.4e} (the model at the epoch), derived {:?}, written {}: {}",
        rrw.flown, rrw.derived, rrw.written, rrw.reason
    );
    assert!((rrw.flown / model - 1.0).abs() < 1e-9);
    assert!(rrw.written, "{}", rrw.reason);
    let derived = rrw.derived.unwrap();
    assert!(
        (derived / shipped - 1.0).abs() < 0.01,
        "the ground derives {derived:.4e}, normal-ops flies {shipped:.4e}"
    );
}
