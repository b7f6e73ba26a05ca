//! Diagnose on sim-harness run folders (studies; the CLI is `ground-tool diagnose`).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use ground_tool::diagnose::run::{diagnose_run, DiagnoseOptions};

/// `RUN_DIR=... OUT=... cargo test -p ground-tool --test diagnose_run -- --ignored --nocapture`
#[test]
#[ignore = "needs a run folder: RUN_DIR=... OUT=..."]
fn diagnose_env_run() {
    let run = std::path::PathBuf::from(std::env::var("RUN_DIR").unwrap());
    let out = std::path::PathBuf::from(std::env::var("OUT").unwrap());
    let t = std::time::Instant::now();
    let o = diagnose_run(&run, &out, &DiagnoseOptions::default()).unwrap();
    eprintln!("diagnose took {:?}", t.elapsed());
    eprintln!("{}", serde_json::to_string_pretty(&serde_json::json!({
        "detected": o.report.detected.iter().map(|d| (d.effect.clone(), d.sensor.clone(), if d.parameters.len() < 14 { serde_json::json!({"p": d.parameters, "s": d.sigma}) } else { serde_json::json!(d.parameters.len()) })).collect::<Vec<_>>(),
        "unexplained": o.report.unexplained,
        "rms": o.report.residual_rms_arcsec,
        "floor": o.report.noise_floor_arcsec,
        "n": o.report.measurements,
        "cal_err": o.report.calibration_error_arcsec,
        "scoring": o.report.scoring.as_ref().map(|s| (&s.detections_in_truth, &s.parameters)),
        "gyro": (&o.report.gyro.bias_samples, &o.report.gyro.slews, &o.report.gyro.notes, o.report.gyro.candidates.iter().map(|c| (c.effect.clone(), c.delta_bic, c.halves_p, c.rejected_because.clone())).collect::<Vec<_>>()),
        "flight": o.report.flight_tables,
    })).unwrap());
}

#[test]
#[ignore = "needs RUN_DIR"]
fn debug_run_batches() {
    use ground_tool::pipeline::calibrate::*;
    let run = std::path::PathBuf::from(std::env::var("RUN_DIR").unwrap());
    let tm = ground_tool::tp::read_file(&run.join("telemetry.bin")).unwrap();
    let md = read_metadata(&run).unwrap();
    let cal = calibrate_telemetry(&tm, &md, &CalibrateOptions::default()).unwrap();
    let f = &cal.frames;
    let mut c = [0usize; 8];
    for fr in f {
        for i in 0..2 {
            if let Some(s) = &fr.stars[i] {
                c[i] += 1;
                if s.identified.is_some() {
                    c[2 + i] += 1;
                }
            }
        }
        for i in 0..2 {
            if fr.suns[i].is_some() {
                c[4 + i] += 1;
            }
        }
        if fr.high_rate {
            c[6] += 1;
        }
        if fr.gyro.is_none() {
            c[7] += 1;
        }
    }
    eprintln!(
        "frames {} stars {:?} ident {:?} suns {:?} high {} nogyro {}",
        f.len(),
        &c[0..2],
        &c[2..4],
        &c[4..6],
        c[6],
        c[7]
    );
    // Coverage over time in 600-s windows: both trackers identified.
    let mut line = String::new();
    for w in f.chunks(600) {
        let a = w
            .iter()
            .filter(|fr| fr.stars[0].as_ref().is_some_and(|s| s.identified.is_some()))
            .count();
        let b = w
            .iter()
            .filter(|fr| fr.stars[1].as_ref().is_some_and(|s| s.identified.is_some()))
            .count();
        let s1 = w.iter().filter(|fr| fr.suns[0].is_some()).count();
        let s2 = w.iter().filter(|fr| fr.suns[1].is_some()).count();
        let h = w.iter().filter(|fr| fr.high_rate).count();
        line += &format!("[{a},{b}|{s1},{s2}|{h}] ");
    }
    eprintln!("{line}");
}
