//! e2e: the whole loop on the built-in `gro-early-mission` — fly with the prelaunch tables,
//! calibrate from telemetry alone, uplink, fly again — scored against truth.
//!
//! Verifies issue 4's must-shows on one seed: relative alignments improve, FHST–FSS within
//! 36″ of truth, the FHST1–FHST2 error consistent with its stated covariance, residual RMS
//! lower after, δM within 3σ of truth, fine attitude inside the paper's requirement after the
//! uplink, post-maneuver errors inside 0.5° in both flights and lower (RMS) after. The
//! FHST1–FHST2 5″ aim is *not* asserted: its Cramér–Rao bound on this data is ≈ 9″ on two
//! axes (README "Known gaps"; `calibration-mc` measures it over seeds).

mod support;

use gro_tests::loop_report::{compare, read_truth, relative_error_and_nees, true_delta_m};
use ground_tool::pipeline::calibrate::{calibrate_run, CalibrateOptions};
use sim_harness::scenario::resolve;

#[test]
fn e2e_calibration_loop_gro_early_mission() {
    let out = support::fresh_dir("gro-e2e-loop");
    let scenario = resolve("gro-early-mission").unwrap();
    let fly_a = out.join("a");
    let cal = out.join("cal");
    let a = support::fly(scenario.clone(), &fly_a, None);
    let calibration = calibrate_run(&fly_a, &cal, &CalibrateOptions::default()).unwrap();
    let b = support::fly(scenario, &out.join("b"), Some(&cal.join("tables")));
    let truth = read_truth(&fly_a).unwrap();
    let r = compare(&a, &b, &calibration, &truth).unwrap();

    // Relative alignments: every pair closer to truth after calibration; the FSS pairs by a
    // large factor (FSS1 starts 0.2° off).
    for (pair, before) in &r.relative_alignment_error_arcsec.before {
        let after = r.relative_alignment_error_arcsec.after[pair];
        assert!(after < *before, "{pair}: {before:.1}″ → {after:.1}″");
        if pair.contains("FSS1") && !pair.starts_with("FSS1") {
            assert!(after < 0.2 * before, "{pair}: {before:.1}″ → {after:.1}″");
        }
    }
    // FHST–FSS relative alignments within the 36″.
    for pair in ["FHST1-FSS1", "FHST1-FSS2", "FHST2-FSS1", "FHST2-FSS2"] {
        let after = r.relative_alignment_error_arcsec.after[pair];
        assert!(after < 36.0, "{pair}: {after:.1}″ after calibration");
    }
    // FHST2 relative to FHST1: error consistent with the stated covariance (χ²₃ at 99.9 %).
    let sol = &calibration.ffcal;
    let (e, nees) = relative_error_and_nees(sol, &truth, 1).unwrap();
    assert!(nees < 16.27, "FHST2 rel FHST1 error {e:?}″, NEES {nees:.1}");
    // The FSSs likewise, with the declared transfer-function spreads carried as consider
    // parameters (the simulator declares them): each FSS error within χ²₃ at 99.9 % of its σ.
    assert_eq!(calibration.report.ffcal.fss_covariance, "consider");
    for j in [2, 3] {
        let (e, nees) = relative_error_and_nees(sol, &truth, j).unwrap();
        assert!(
            nees < 16.27,
            "sensor {j} rel FHST1 error {e:?}″, NEES {nees:.1}"
        );
    }
    // The FHST stage used every star (gyro batches): on the two roll axes its σ is well below
    // the Cramér–Rao bound of the simultaneous star pairs alone (5 against 9–10″ here), and it
    // equals its own bound scaled by the fit's χ²/dof.
    let f = &calibration.report.ffcal;
    assert_eq!(
        f.fhst_stage,
        Some(ground_tool::pipeline::calibrate::FhstStage::GyroBatches)
    );
    let g = f.gyro_batches.as_ref().expect("gyro-batch summary");
    for axis in 0..2 {
        let pairs = f.crb_sigma_fhst2_rel_fhst1_fhst_only_arcsec[axis];
        assert!(
            f.sigma_fhst2_rel_fhst1_arcsec[axis] < 0.7 * pairs,
            "axis {axis}: σ {:?} vs star-pair bound {pairs:.1}″",
            f.sigma_fhst2_rel_fhst1_arcsec
        );
        let scaled = g.crb_sigma_arcsec[axis] * g.variance_factor.sqrt();
        assert!((g.sigma_arcsec[axis] - scaled).abs() < 1e-9 * scaled);
    }
    assert!(
        g.variance_factor > 0.3 && g.variance_factor < 3.0,
        "χ²/dof {}",
        g.variance_factor
    );
    // IRU: every δM element within 3σ of truth.
    assert_eq!(r.iru_delta_m_within_3sigma, Some(true), "δM vs truth");
    // Residual RMS lower after, for every sensor.
    for (sensor, before) in &r.residual_rms_arcsec.before {
        let after = r.residual_rms_arcsec.after[sensor];
        assert!(
            after < *before,
            "{sensor}: residual {before:.1}″ → {after:.1}″"
        );
    }
    // Fine attitude (3 × RMS per axis, bias included) inside the paper's 0.024° after the uplink.
    for axis in 0..3 {
        let after = r.fine_attitude_error_3rms_arcsec.after[axis];
        let before = r.fine_attitude_error_3rms_arcsec.before[axis];
        assert!(
            after < 86.4,
            "axis {axis}: 3×RMS {after:.1}″ (before {before:.1}″)"
        );
        assert!(after < before, "axis {axis}: {before:.1}″ → {after:.1}″");
    }
    // Post-maneuver errors inside the paper's 0.5° in both flights.
    assert!(!r.post_maneuver_error_deg.before.is_empty());
    for e in r
        .post_maneuver_error_deg
        .before
        .iter()
        .chain(&r.post_maneuver_error_deg.after)
    {
        assert!(*e < 0.5, "post-maneuver error {e}°");
    }
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    let (pb, pa) = (
        rms(&r.post_maneuver_error_deg.before),
        rms(&r.post_maneuver_error_deg.after),
    );
    assert!(pa < pb, "post-maneuver RMS {pb:.4}° → {pa:.4}°");
    // The uplink carried the onboard annual-aberration correction (aberration is declared,
    // the boot filter table had it off).
    assert!(!calibration.report.filter_changes.is_empty());
    assert!(cal.join("tables").join("filter.tbl").exists());
    // The slew uncertainty follows IRUCAL (`pipeline::filter_tuning`): written below the boot
    // 1e-3, and every element of G's true residual error after the uplink (true δM minus the
    // uplinked one) within 3k of zero, so the OBC's post-slew σ covers it.
    let slew = &calibration.report.filter_tuning[0];
    assert_eq!(
        slew.field,
        ground_tool::pipeline::filter_tuning::FilterTerm::SlewUncertainty
    );
    let k = slew.derived.expect("derived slew uncertainty");
    assert!(slew.written && k < 1e-3, "{}", slew.reason);
    let true_dm = true_delta_m(&truth).expect("the truth's IRU");
    let iru = calibration.report.iru.as_ref().expect("IRU report");
    residual_within_3_sigma(&true_dm, &iru.delta_m_uplinked, "k", |_, _| k);
    // Per element (field 23): every element of the true residual within 3σ of its own σ.
    let per = slew.derived_per_element.expect("per-element slew σ");
    residual_within_3_sigma(&true_dm, &iru.delta_m_uplinked, "its σ", |i, j| per[i][j]);
    coarse_attitude_improves(&calibration, &cal, &r);
    // The gyro noise of the holds agrees with the boot table (the simulator's own noise):
    // σ_v and σ_u are kept.
    assert!(calibration.report.filter_tuning[1..]
        .iter()
        .all(|t| !t.written));

    // The loop again, on the second flight, with no --tables: the chain takes the flown
    // tables from the run's activated uploads (`pipeline::flown`), so it starts from the
    // calibrated tables and finds nothing left to fix: residuals at the floor before as
    // after, every correction within 3σ of zero, and no filter change. With the boot tables
    // assumed instead, the "before" residuals would be the prelaunch ones (223″ on FHST1).
    let fly_b = out.join("b");
    let meta = ground_tool::pipeline::flown::metadata_or_default(&fly_b);
    let (fa, fi, ff) = ground_tool::pipeline::flown::flown_tables(&fly_b, &meta, None).unwrap();
    assert!(fa.is_some() && fi.is_some() && ff.is_some_and(|f| f.aberration_correction));
    let again = calibrate_run(
        &fly_b,
        &out.join("cal2"),
        &CalibrateOptions {
            flown_alignment: fa,
            flown_iru: fi,
            flown_filter: ff,
            ..CalibrateOptions::default()
        },
    )
    .unwrap();
    let rep = &again.report;
    assert!(rep.filter_changes.is_empty(), "{:?}", rep.filter_changes);
    for (sensor, before) in &rep.residual_rms_arcsec.before {
        let after = rep.residual_rms_arcsec.after[sensor];
        assert!(
            *before < 1.05 * after,
            "{sensor}: second pass residual {before:.1}″ → {after:.1}″"
        );
    }
    for (sensor, a) in &rep.alignments {
        for axis in 0..3 {
            assert!(
                a.theta_acs_arcsec[axis].abs() < 3.0 * a.sigma_arcsec[axis],
                "{sensor} axis {axis}: second-pass correction {:.1}″, σ {:.1}″",
                a.theta_acs_arcsec[axis],
                a.sigma_arcsec[axis]
            );
        }
    }
    let _ = std::fs::remove_dir_all(&out);
}

/// Determinism of the ground side (issue 7): the same telemetry calibrated twice gives
/// byte-identical tables and the same report (up to the output paths it names).
#[test]
fn calibration_is_deterministic() {
    let (out, fly) = prelaunch_run("gro-e2e-determinism");
    let mut reports = Vec::new();
    let mut tables = Vec::new();
    for k in 0..2 {
        let dir = out.join(format!("cal-{k}"));
        let c = calibrate_run(&fly, &dir, &CalibrateOptions::default()).unwrap();
        let mut json = serde_json::to_value(&c.report).unwrap();
        json["tables"] = serde_json::Value::Null;
        reports.push(json.to_string());
        tables.push([
            std::fs::read(dir.join("tables/alignment.tbl")).unwrap(),
            std::fs::read(dir.join("tables/iru.tbl")).unwrap(),
        ]);
    }
    assert!(
        reports[0] == reports[1],
        "report.json differs between two runs"
    );
    assert!(
        tables[0] == tables[1],
        "table images differ between two runs"
    );
    let _ = std::fs::remove_dir_all(&out);
}

/// Raw frames and ephemeris only (no OBC housekeeping, as an outside program may write per
/// `docs/icd.md`): the ground bootstraps its own attitude for star identification (Sun and
/// both trackers, then the gyro and every identified star), calibrates, and its FHST2
/// relative alignment is consistent with its stated covariance.
#[test]
fn calibration_without_housekeeping() {
    let (out, fly) = prelaunch_run("gro-e2e-nohk");
    // Drop every APID 0x011 packet.
    let nohk = out.join("nohk");
    support::copy_run_without_apid(&fly, &nohk, 0x011);
    let c = calibrate_run(&nohk, &out.join("cal"), &CalibrateOptions::default()).unwrap();
    assert_eq!(c.report.telemetry.packets.housekeeping, 0);
    assert!(
        c.report.data.stars_identified.iter().all(|&n| n > 1000),
        "identified {:?}",
        c.report.data.stars_identified
    );
    let truth = read_truth(&fly).unwrap();
    let sol = &c.ffcal;
    let (e, nees) = relative_error_and_nees(sol, &truth, 1).unwrap();
    assert!(nees < 16.27, "FHST2 rel FHST1 error {e:?}″, NEES {nees:.1}");
    let _ = std::fs::remove_dir_all(&out);
}

/// A fresh folder `name` with `gro-early-mission` flown with the prelaunch tables into its
/// `run`: (the folder, the run folder).
fn prelaunch_run(name: &str) -> (std::path::PathBuf, std::path::PathBuf) {
    let out = support::fresh_dir(name);
    let fly = out.join("run");
    support::fly(resolve("gro-early-mission").unwrap(), &fly, None);
    (out, fly)
}

/// Every element of G's true residual error after the uplink (true δM minus the uplinked one)
/// within 3 × `sigma(i, j)` of zero.
fn residual_within_3_sigma(
    true_dm: &nalgebra::Matrix3<f64>,
    uplinked: &[[f64; 3]; 3],
    what: &str,
    sigma: impl Fn(usize, usize) -> f64,
) {
    for i in 0..3 {
        for j in 0..3 {
            let left = true_dm[(i, j)] - uplinked[i][j];
            assert!(
                left.abs() <= 3.0 * sigma(i, j),
                "G residual [{i}][{j}] {:.0} ppm against {what} {:.0} ppm",
                left * 1e6,
                sigma(i, j) * 1e6
            );
        }
    }
}

/// Issue 20: the ground's TAM calibration becomes the magnetics table, and the OBC's coarse
/// attitude with it is better on every axis and inside the 2° (3σ) requirement.
fn coarse_attitude_improves(
    calibration: &ground_tool::pipeline::calibrate::CalibrationOutput,
    cal: &std::path::Path,
    r: &gro_tests::loop_report::LoopReport,
) {
    let mag = calibration
        .report
        .tam
        .table
        .as_ref()
        .expect("magnetics decision");
    assert!(mag.written, "{}", mag.reason);
    assert!(cal.join("tables").join("magnetics.tbl").exists());
    let (cb, ca) = (
        r.coarse_attitude_error_3sigma_deg
            .before
            .expect("coarse before"),
        r.coarse_attitude_error_3sigma_deg
            .after
            .expect("coarse after"),
    );
    for axis in 0..3 {
        assert!(
            ca[axis] < cb[axis] && ca[axis] <= 2.0,
            "coarse {cb:?} → {ca:?}"
        );
    }
}
