//! `calibrate` across the OBC's switch to the backup gyro triad (event 0x0202, housekeeping
//! octet 106), on telemetry from the independent ICD writer (`tests/icd/write_run.py
//! --backup-halfway`): each triad has its own bias, so every entry of the bias history must
//! be the bias of the triad active at its time, labelled so, within its σ of the writer's
//! truth. Before: the fix between the switch and the backup triad's first link carried the
//! primary triad's smoothed bias with σ 0.0007″/s (z ≈ −900 at the 1-s downlink, −220 at 10 s).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod support;

use serde_json::Value;

const ARCSEC_PER_RAD: f64 = 206_264.806_247_096_36;

#[test]
fn bias_history_after_a_triad_switch_is_the_new_triads_bias() {
    let mut flags = vec!["--seed", "1"];
    flags.extend(support::BACKUP_HALFWAY_10S);
    let dir = support::write_run("calibrate-triad-switch", "backup-halfway", &flags);
    let report = support::calibrate_json(
        env!("CARGO_BIN_EXE_ground-tool"),
        &dir,
        &dir.join("cal"),
        &["-q"],
    );
    let truth: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("truth_icd.json")).unwrap())
            .unwrap();
    let iru = &truth["iru"];
    let switch_s = iru["backup_selected_at_s"].as_f64().unwrap();
    let history = report["bias_history"].as_array().unwrap();
    let (mut before, mut after) = (0, 0);
    for h in history {
        let t = h["t_s"].as_f64().unwrap();
        let (triad, label) = if t >= switch_s {
            after += 1;
            ("backup", "Backup")
        } else {
            before += 1;
            ("primary", "Primary")
        };
        assert_eq!(h["triad"], label, "t = {t:.0} s: {h}");
        for k in 0..3 {
            let est = h["bias_rad_per_s"][k].as_f64().unwrap();
            let sigma = h["sigma_rad_per_s"][k].as_f64().unwrap();
            let truth_k = iru[triad]["bias_acs_rad_per_s"][k].as_f64().unwrap();
            let z = (est - truth_k) / sigma;
            assert!(
                z.abs() < 5.0,
                "t = {t:.0} s ({label}), axis {k}: ground {:.4} ± {:.4}″/s against the truth {:.4}″/s (z {z:.0})",
                est * ARCSEC_PER_RAD,
                sigma * ARCSEC_PER_RAD,
                truth_k * ARCSEC_PER_RAD
            );
        }
    }
    assert!(
        before >= 5 && after >= 5,
        "{before} fixes before the switch, {after} after"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
