//! Diagnose on sim-harness run folders (studies; the CLI is `ground-tool diagnose`).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use ground_tool::diagnose::run::{diagnose_run, DiagnoseOutput};

/// `RUN_DIR=... OUT=... cargo test -p tests --test diagnose_run -- --ignored --nocapture`
#[test]
#[ignore = "needs a run folder: RUN_DIR=... OUT=..."]
fn diagnose_env_run() {
    let run = std::path::PathBuf::from(std::env::var("RUN_DIR").unwrap());
    let out = std::path::PathBuf::from(std::env::var("OUT").unwrap());
    let t = std::time::Instant::now();
    let o = diagnose_run(&run, &out, &gro_tests::diagnose::scoring::scored_options()).unwrap();
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
    let sky = load_catalog().unwrap();
    let frames = ground_tool::pipeline::observations::build_observations(
        &tm,
        &fsw_core::tables::AlignmentTable::prelaunch(),
        &fsw_core::tables::IruTable::prelaunch(),
        &md.sensors,
        &sky,
        &Default::default(),
    );
    let f = &frames;
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

/// `RUNS=/tmp/a,/tmp/b OUT_ROOT=/tmp/o cargo test -p tests --test diagnose_run summary -- --ignored --nocapture`
#[test]
#[ignore = "needs run folders: RUNS=dir1,dir2 OUT_ROOT=..."]
fn summary_runs() {
    let runs = std::env::var("RUNS").unwrap();
    let out_root = std::path::PathBuf::from(std::env::var("OUT_ROOT").unwrap());
    for run in runs.split(',') {
        let run = std::path::PathBuf::from(run);
        let name = run.file_name().unwrap().to_string_lossy().to_string();
        let t = std::time::Instant::now();
        match diagnose_run(
            &run,
            &out_root.join(&name),
            &gro_tests::diagnose::scoring::scored_options(),
        ) {
            Err(e) => eprintln!("== {name}: ERROR {e:#}"),
            Ok(o) => {
                let r = &o.report;
                eprintln!(
                    "== {name} ({:.1} s) truth undeclared {:?}",
                    t.elapsed().as_secs_f64(),
                    r.scoring
                        .as_ref()
                        .map(|s| s.truth_undeclared_effects.clone())
                );
                for d in &r.detected {
                    let p = if d.parameters.len() > 14 {
                        format!("{} params", d.parameters.len())
                    } else {
                        d.parameters
                            .iter()
                            .map(|(k, v)| {
                                format!(
                                    "{k}={v:.3}±{:.3}",
                                    d.sigma.get(k).copied().unwrap_or(f64::NAN)
                                )
                            })
                            .collect::<Vec<_>>()
                            .join(" ")
                    };
                    eprintln!(
                        "   DETECTED {}[{}] ΔBIC {:.0}: {p}",
                        d.effect, d.sensor, d.evidence.delta_bic
                    );
                }
                for u in &r.unexplained {
                    eprintln!(
                        "   UNEXPLAINED {} {} vs {} ({}) size {:.2} p {:.1e}",
                        u.sensor, u.axis, u.regressor, u.method, u.size, u.p_value
                    );
                }
                if let Some(s) = &r.scoring {
                    for p in &s.parameters {
                        if p.parameter.starts_with("HIP") {
                            continue;
                        }
                        eprintln!(
                            "   PARAM {}[{}].{} est {:.3} ± {:.3} truth {:.3} z {:.2}",
                            p.effect, p.sensor, p.parameter, p.estimate, p.sigma, p.truth, p.z
                        );
                    }
                }
                eprintln!(
                    "   rms before {:?}",
                    rounded(r.residual_rms_arcsec.before.values(), 2)
                );
                eprintln!(
                    "   rms after  {:?}",
                    rounded(r.residual_rms_arcsec.after.values(), 2)
                );
                eprintln!(
                    "   floor      {:?} n {:?}",
                    rounded(r.noise_floor_arcsec.values(), 2),
                    r.measurements.values().collect::<Vec<_>>()
                );
                if let Some(c) = &r.calibration_error_arcsec {
                    eprintln!(
                        "   cal err before {:?} after {:?}",
                        rounded(c.before.values(), 1),
                        rounded(c.after.values(), 1)
                    );
                }
                for c in &r.gyro.candidates {
                    eprintln!(
                        "   gyro {} ΔBIC {:.1} halves {:.3} {}",
                        c.effect,
                        c.delta_bic,
                        c.halves_p,
                        c.rejected_because.clone().unwrap_or_else(|| "KEPT".into())
                    );
                }
                for n in r.notes.iter().chain(&r.gyro.notes) {
                    eprintln!("   note: {}", &n[..n.len().min(160)]);
                }
            }
        }
    }
}

/// `RUN_DIR` diagnosed (scored) into `/tmp/dg/dbg`, for the debugging studies below.
fn diagnose_env_run_dir() -> (std::path::PathBuf, DiagnoseOutput) {
    let run = std::path::PathBuf::from(std::env::var("RUN_DIR").unwrap());
    let o = diagnose_run(
        &run,
        &std::path::PathBuf::from("/tmp/dg/dbg"),
        &gro_tests::diagnose::scoring::scored_options(),
    )
    .unwrap();
    (run, o)
}

#[test]
#[ignore = "needs RUN_DIR"]
fn debug_fss_truth_fit() {
    use ground_tool::diagnose::effects::EffectKind;
    use ground_tool::diagnose::fit::*;
    let (_, o) = diagnose_env_run_dir();
    let res = &o.analysis.search;
    let lay = &res.layout;
    let tf = lay.find(EffectKind::FssTransferFunction, Some(3)).unwrap();
    let e = &lay.effects[tf];
    eprintln!(
        "params {:?} pitch {:?}",
        e.params,
        e.pitch_rad.map(f64::to_degrees)
    );
    let truth = [150.0, 30.0, 20.0, -120.0, -25.0, 20.0, 6.0, 0.0, 6.0, 0.0];
    for (name, sys) in [
        ("full", &res.systems.full),
        ("first", &res.systems.first),
        ("second", &res.systems.second),
    ] {
        let idx = indices(lay, &[tf]);
        let fit = solve(sys, lay, &idx).unwrap();
        let base = solve(sys, lay, &indices(lay, &[])).unwrap();
        // TF fixed at truth: move its columns to the right-hand side.
        let r = lay.range(tf);
        let others: Vec<usize> = indices(lay, &[]);
        let mut b = nalgebra::DVector::zeros(others.len());
        let mut n = nalgebra::DMatrix::zeros(others.len(), others.len());
        let prior = lay.prior_information();
        for (a, &i) in others.iter().enumerate() {
            b[a] = sys.b[i]
                - r.clone()
                    .enumerate()
                    .map(|(k, j)| sys.n[(i, j)] * truth[k.min(truth.len() - 1)])
                    .sum::<f64>();
            for (c, &j) in others.iter().enumerate() {
                n[(a, c)] = sys.n[(i, j)];
            }
            n[(a, a)] += prior[i];
        }
        let x = n.clone().cholesky().unwrap().solve(&b);
        let mut full = nalgebra::DVector::zeros(lay.total);
        for (a, &i) in others.iter().enumerate() {
            full[i] = x[a];
        }
        for (k, j) in r.clone().enumerate() {
            full[j] = truth[k];
        }
        let chi2 = sys.chi2 - 2.0 * full.dot(&sys.b) + full.dot(&(&sys.n * &full));
        eprintln!(
            "{name}: chi2 base {:.1} fit {:.1} truth-TF {:.1}; fitted TF {:?}",
            base.chi2,
            fit.chi2,
            chi2,
            r.clone()
                .map(|j| fit.param(j).map(|p| (p.0 * 10.0).round() / 10.0))
                .collect::<Vec<_>>()
        );
    }
}

#[test]
#[ignore = "needs RUN_DIR (a catalog scenario)"]
fn debug_catalog() {
    use ground_tool::diagnose::effects::EffectKind;
    use ground_tool::diagnose::fit::*;
    let (run, o) = diagnose_env_run_dir();
    let res = &o.analysis.search;
    let lay = &res.layout;
    let ci = lay
        .find(EffectKind::CatalogProperMotionError, None)
        .unwrap();
    let truth = gro_tests::diagnose::scoring::read_truth(&run)
        .unwrap()
        .unwrap();
    let tt = o.first_frame_j2000_tt_s;
    let cat = gro_tests::diagnose::scoring::catalog_truth(&truth, tt);
    let stars = &lay.effects[ci].stars;
    let idx = indices(lay, &[ci]);
    let fits: Vec<SubFit> = [&res.systems.full, &res.systems.first, &res.systems.second]
        .iter()
        .map(|s| solve(s, lay, &idx).unwrap())
        .collect();
    let mut zs = Vec::new();
    for (k, h) in stars.iter().enumerate() {
        let r = lay.range(ci);
        let g = |f: &SubFit, j: usize| f.param(r.start + 2 * k + j).unwrap();
        let t = cat.get(h).copied().unwrap_or([f64::NAN; 2]);
        let n = o
            .analysis
            .set
            .meas
            .iter()
            .filter(|m| m.star == *h && !m.outlier)
            .count();
        let (e, n_) = (g(&fits[0], 0), g(&fits[0], 1));
        let (a, b) = (g(&fits[1], 0), g(&fits[2], 0));
        zs.push((e.0 - t[0]) / e.1);
        zs.push((n_.0 - t[1]) / n_.1);
        eprintln!("HIP{h} n {n}: east {:.1}±{:.1} (truth {:.1}) halves {:.1}±{:.1}/{:.1}±{:.1}; north {:.1}±{:.1} (truth {:.1})", e.0, e.1, t[0], a.0, a.1, b.0, b.1, n_.0, n_.1, t[1]);
    }
    let chi2: f64 = zs.iter().filter(|z| z.is_finite()).map(|z| z * z).sum();
    eprintln!(
        "chi2 vs truth {chi2:.1} over {}",
        zs.iter().filter(|z| z.is_finite()).count()
    );
}

/// Not in the library, on real harness telemetry:
/// `SRC=/tmp/clean OUT_ROOT=/tmp/o cargo test -p tests --test diagnose_run inject -- --ignored --nocapture`
/// (SRC = a run of scenarios/undeclared/clean.toml).
#[test]
#[ignore = "needs a run folder: SRC=... OUT_ROOT=..."]
fn inject_non_library_effects() {
    use gro_tests::diagnose::inject::{inject_run, NON_LIBRARY};
    let src = std::path::PathBuf::from(std::env::var("SRC").unwrap());
    let out_root = std::path::PathBuf::from(std::env::var("OUT_ROOT").unwrap());
    for (name, effect, _) in NON_LIBRARY {
        let run = out_root.join(format!("inject-{name}"));
        inject_run(&src, &run, effect).unwrap();
        let o = diagnose_run(
            &run,
            &out_root.join(format!("inject-{name}-diag")),
            &gro_tests::diagnose::scoring::scored_options(),
        )
        .unwrap();
        eprintln!("== {name}: {effect:?}");
        for d in &o.report.detected {
            eprintln!(
                "   DETECTED {}[{}] ΔBIC {:.1}",
                d.effect, d.sensor, d.evidence.delta_bic
            );
        }
        for u in &o.report.unexplained {
            eprintln!(
                "   UNEXPLAINED {} {} vs {} ({}) size {:.2} p {:.1e}; also {:?}",
                u.sensor, u.axis, u.regressor, u.method, u.size, u.p_value, u.also_follows
            );
        }
    }
}

/// Each value with `decimals` decimals (for the printed summaries).
fn rounded<'a>(values: impl Iterator<Item = &'a f64>, decimals: usize) -> Vec<String> {
    values.map(|v| format!("{v:.decimals$}")).collect()
}
