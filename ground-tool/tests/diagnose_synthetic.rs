//! Diagnose on synthetic frames with known effects (fast; the sim-harness runs are in
//! scenarios/undeclared and the bench script).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use ground_tool::diagnose::search::SearchConfig;
use ground_tool::diagnose::synthetic::{generate, SynthConfig, SynthEffects};
use ground_tool::diagnose::{analyse, Analysis};

fn run(effects: SynthEffects, seed: u64, aberration_applied: bool, declared: &[&str]) -> Analysis {
    let cfg = SynthConfig {
        seed,
        aberration_applied,
        effects,
        ..SynthConfig::default()
    };
    let t = std::time::Instant::now();
    let synth = generate(&cfg);
    let gen = t.elapsed();
    let a = analyse(&synth.input(declared), &SearchConfig::default()).unwrap();
    eprintln!(
        "generate {gen:?}, analyse {:?}, {} measurements",
        t.elapsed() - gen,
        a.set.meas.len()
    );
    eprintln!(
        "noise floor {:?} scale {:?}",
        a.set.noise_floor_arcsec, a.set.sigma_scale
    );
    eprintln!("rms before {:?} after {:?}", a.rms_before, a.rms_after);
    for d in &a.detected {
        if d.parameters.len() > 12 {
            eprintln!(
                "DETECTED {} {} ({} params) ΔBIC {:.1}",
                d.effect,
                d.sensor,
                d.parameters.len(),
                d.evidence.delta_bic
            );
        } else {
            eprintln!(
                "DETECTED {} {} {:?} ± {:?} ΔBIC {:.1}",
                d.effect, d.sensor, d.parameters, d.sigma, d.evidence.delta_bic
            );
        }
    }
    let mut tb: Vec<_> = a.search.tests_before.iter().collect();
    tb.sort_by(|x, y| x.p_value.total_cmp(&y.p_value));
    for t in tb.iter().take(6) {
        eprintln!(
            "TEST-BEFORE {} {} {:?} {:?} F {:.2} p {:.2e} holm {:.2e} size {:.2} n {}",
            t.sensor_name,
            t.axis_name,
            t.regressor,
            t.method,
            t.f,
            t.p_value,
            t.p_holm,
            t.size_arcsec,
            t.n
        );
    }
    for u in &a.unexplained {
        eprintln!("UNEXPLAINED {:?}", u);
    }
    for it in &a.search.iterations {
        for c in &it.candidates {
            if c.delta_bic > -50.0 {
                eprintln!("  it{} {} dchi2 {:.1} F {:.2} p {:.2e} bic {:.1} halves p {:.3} adequate {} {:?}", it.number, c.effect, c.delta_chi2, c.f, c.p_holm, c.delta_bic, c.halves_p, c.adequate, c.rejected_because);
            }
        }
    }
    a
}

#[test]
fn clean_synthetic_reports_nothing() {
    let a = run(SynthEffects::default(), 3, true, &[]);
    assert!(
        a.detected.is_empty(),
        "{:?}",
        a.detected
            .iter()
            .map(|d| d.effect.clone())
            .collect::<Vec<_>>()
    );
    assert!(a.unexplained.is_empty());
}

#[test]
fn debug_noise_free() {
    let cfg = SynthConfig {
        noise_scale: 0.0,
        seed: 3,
        ..SynthConfig::default()
    };
    let synth = generate(&cfg);
    let input = synth.input(&[]);
    let set = ground_tool::diagnose::measurements::MeasurementSet::build(&input);
    let mut worst = [0.0f64; 4];
    let mut rms = [0.0f64; 4];
    let mut n = [0usize; 4];
    for m in &set.meas {
        let r = m.r[0].abs().max(m.r[1].abs());
        worst[m.sensor] = worst[m.sensor].max(r);
        rms[m.sensor] += m.r[0] * m.r[0] + m.r[1] * m.r[1];
        n[m.sensor] += 1;
    }
    eprintln!(
        "noise-free raw residual max {:?} rms {:?}",
        worst,
        (0..4)
            .map(|i| (rms[i] / n[i].max(1) as f64 / 2.0).sqrt())
            .collect::<Vec<_>>()
    );
    let a = analyse(&input, &SearchConfig::default()).unwrap();
    eprintln!("rms before {:?} after {:?}", a.rms_before, a.rms_after);
    for d in &a.detected {
        eprintln!("DETECTED {} {} {:?}", d.effect, d.sensor, d.parameters);
    }
}

#[test]
fn debug_noise_free_fit() {
    use ground_tool::diagnose::fit::*;
    let cfg = SynthConfig {
        noise_scale: 0.0,
        seed: 3,
        ..SynthConfig::default()
    };
    let synth = generate(&cfg);
    let input = synth.input(&[]);
    let set = ground_tool::diagnose::measurements::MeasurementSet::build(&input);
    let layout = Layout::new(ground_tool::diagnose::effects::library(&set, [None, None]));
    let sys = accumulate_halves(&set, &layout);
    eprintln!(
        "chi2 {} rows {} nuisance {} outliers {} batches {} sig {:?}",
        sys.full.chi2,
        sys.full.rows,
        sys.full.nuisance,
        set.meas.iter().filter(|m| m.outlier).count(),
        set.batches.len(),
        set.meas
            .iter()
            .take(3)
            .map(|m| (m.sigma, m.r, m.batch))
            .collect::<Vec<_>>()
    );
    let fit = solve(&sys.full, &layout, &indices(&layout, &[])).unwrap();
    eprintln!("x {:?} chi2 {}", fit.x.as_slice(), fit.chi2);
    let pf = post_fit(&set, &layout, &fit.expand(layout.total));
    let mut rms = [0.0f64; 4];
    let mut n = [0usize; 4];
    for (m, r) in set.meas.iter().zip(&pf.resid) {
        rms[m.sensor] += r[0] * r[0] + r[1] * r[1];
        n[m.sensor] += 1;
    }
    eprintln!(
        "post rms {:?}",
        (0..4)
            .map(|i| (rms[i] / n[i].max(1) as f64 / 2.0).sqrt())
            .collect::<Vec<_>>()
    );
}

#[test]
fn debug_noisy_structure() {
    use ground_tool::diagnose::fit::*;
    use ground_tool::diagnose::structure::*;
    let ns: f64 = std::env::var("NS")
        .map(|v| v.parse().unwrap())
        .unwrap_or(1.0);
    let cfg = SynthConfig {
        seed: 3,
        noise_scale: ns,
        ..SynthConfig::default()
    };
    let synth = generate(&cfg);
    let input = synth.input(&[]);
    let set = ground_tool::diagnose::measurements::MeasurementSet::build(&input);
    eprintln!(
        "floor {:?} scale {:?}",
        set.noise_floor_arcsec, set.sigma_scale
    );
    let layout = Layout::new(ground_tool::diagnose::effects::library(&set, [None, None]));
    let sys = accumulate_halves(&set, &layout);
    let fit = solve(&sys.full, &layout, &indices(&layout, &[])).unwrap();
    eprintln!("x {:?} chi2 {} dof {}", fit.x.as_slice(), fit.chi2, fit.dof);
    let pf = post_fit(&set, &layout, &fit.expand(layout.total));
    for (s, ax, reg) in [
        (2, 1, Regressor::FovV),
        (2, 1, Regressor::Time),
        (3, 1, Regressor::FovV),
        (0, 0, Regressor::FovH),
        (0, 0, Regressor::Time),
    ] {
        eprintln!(
            "sensor {s} axis {ax} {:?}: {:?}",
            reg,
            binned_means(&set, &pf, s, ax, reg, 12)
                .iter()
                .map(|(x, m, e)| format!("{x:.2}:{m:.2}±{e:.2}"))
                .collect::<Vec<_>>()
        );
    }
}

#[test]
fn debug_raw_obc() {
    let cfg = SynthConfig {
        seed: 3,
        ..SynthConfig::default()
    };
    let synth = generate(&cfg);
    let input = synth.input(&[]);
    let set = ground_tool::diagnose::measurements::MeasurementSet::build(&input);
    for s in 0..4 {
        let v: Vec<&ground_tool::diagnose::measurements::Measurement> =
            set.meas.iter().filter(|m| m.sensor == s).collect();
        let n = v.len() as f64;
        let mean0 = v.iter().map(|m| m.r[0]).sum::<f64>() / n;
        let mean1 = v.iter().map(|m| m.r[1]).sum::<f64>() / n;
        let rms0 = (v.iter().map(|m| m.r[0] * m.r[0]).sum::<f64>() / n).sqrt();
        let chi = v
            .iter()
            .map(|m| (m.r[0] * m.r[0] + m.r[1] * m.r[1]) / (m.sigma * m.sigma))
            .sum::<f64>()
            / (2.0 * n);
        eprintln!("sensor {s}: n {n} mean {mean0:.2} {mean1:.2} rms0 {rms0:.2} chi2/n {chi:.2}");
        // Per-batch means of FHST residual.
        if s == 0 {
            let mut out = String::new();
            for b in 0..20 {
                let w: Vec<_> = v.iter().filter(|m| m.batch == b).collect();
                if w.is_empty() {
                    continue;
                }
                let m0 = w.iter().map(|m| m.r[0]).sum::<f64>() / w.len() as f64;
                out += &format!("{b}:{m0:.1}({}) ", w.len());
            }
            eprintln!("{out}");
        }
    }
}

#[test]
fn debug_compare_truth_x() {
    use ground_tool::diagnose::fit::*;
    let cfg = SynthConfig {
        seed: 3,
        ..SynthConfig::default()
    };
    let synth = generate(&cfg);
    let input = synth.input(&[]);
    let set = ground_tool::diagnose::measurements::MeasurementSet::build(&input);
    let layout = Layout::new(ground_tool::diagnose::effects::library(&set, [None, None]));
    let sys = accumulate_halves(&set, &layout);
    let fit = solve(&sys.full, &layout, &indices(&layout, &[])).unwrap();
    let chi = |g: &nalgebra::DVector<f64>| {
        let pf = post_fit(&set, &layout, g);
        set.meas
            .iter()
            .zip(&pf.resid)
            .filter(|(m, _)| !m.outlier)
            .map(|(m, r)| (r[0] * r[0] + r[1] * r[1]) / (m.sigma * m.sigma))
            .sum::<f64>()
    };
    let mut gt = nalgebra::DVector::zeros(layout.total);
    let t = [-3.0, 2.0, -4.0, -20.0, 15.0, -10.0, 10.0, -12.0, -8.0];
    for i in 0..9 {
        gt[i] = t[i];
    }
    let gh = fit.expand(layout.total);
    eprintln!(
        "chi2 solver {} post(hat) {} post(true) {} post(0) {}",
        fit.chi2,
        chi(&gh),
        chi(&gt),
        chi(&nalgebra::DVector::zeros(layout.total))
    );
    let pf = post_fit(&set, &layout, &gt);
    for s in 0..4 {
        let v: Vec<_> = set
            .meas
            .iter()
            .zip(&pf.resid)
            .filter(|(m, _)| m.sensor == s && !m.outlier)
            .collect();
        let c = v
            .iter()
            .map(|(m, r)| (r[0] * r[0] + r[1] * r[1]) / (m.sigma * m.sigma))
            .sum::<f64>()
            / (2.0 * v.len() as f64);
        let raw = v
            .iter()
            .map(|(m, _)| (m.r[0] * m.r[0] + m.r[1] * m.r[1]) / (m.sigma * m.sigma))
            .sum::<f64>()
            / (2.0 * v.len() as f64);
        eprintln!("sensor {s} chi2/n post(true) {c:.2} raw {raw:.2}");
    }
    let mut out = String::new();
    for (b, nu) in pf.batch_nuisance.iter().enumerate().take(40) {
        if let Some((a, _)) = nu {
            out += &format!(
                "{b}:[{:.1},{:.1},{:.1}|{:.1},{:.1},{:.1}] ",
                a[0], a[1], a[2], a[3], a[4], a[5]
            );
        }
    }
    eprintln!("{out}");
}

fn effect_from_env() -> (SynthEffects, bool) {
    let mut fx = SynthEffects::default();
    let mut ab = true;
    match std::env::var("FX").unwrap_or_default().as_str() {
        "tt" => fx.time_tag_s[0] = 0.05,
        "tt_fss" => fx.time_tag_s[2] = 0.05,
        "thermal" => fx.thermal_arcsec_per_c[1] = [3.0, -2.0, 0.5],
        "thermal_fss" => fx.thermal_arcsec_per_c[2] = [3.0, -2.0, 0.5],
        "dist" => fx.distortion_arcsec[0] = [15.0, 8.0, -6.0],
        "mag" => fx.magnitude_bias[0] = [1.5, 0.0],
        "fss" => {
            fx.fss_tf[0] = Some((
                sim_harness::sensors::fss::FssHeadErrors::default(),
                sim_harness::sensors::fss::FssHeadErrors {
                    scale_ppm: -120.0,
                    cross_arcsec_at_corner: -25.0,
                    ..Default::default()
                },
            ))
        }
        "cat" => fx.catalog_sigma_arcsec = 5.0,
        "ab" => ab = false,
        "t2" => fx.thermal_squared[1] = [0.0, 0.0, 2.0],
        "osc" => fx.post_slew_oscillation = Some((1, 10.0, 60.0, 200.0, 2)),
        _ => {}
    }
    (fx, ab)
}

#[test]
fn debug_effect_env() {
    let (fx, ab) = effect_from_env();
    let _ = run(fx, 5, ab, &[]);
}

#[test]
#[ignore = "study: cargo test -p ground-tool --test diagnose_synthetic clean_study -- --ignored --nocapture"]
fn clean_study() {
    let n: u64 = std::env::var("SEEDS")
        .map(|v| v.parse().unwrap())
        .unwrap_or(10);
    let mut alarms = 0;
    for seed in 100..100 + n {
        let cfg = SynthConfig {
            seed,
            ..SynthConfig::default()
        };
        let synth = generate(&cfg);
        let a = analyse(&synth.input(&[]), &SearchConfig::default()).unwrap();
        let alarm = !a.detected.is_empty() || !a.unexplained.is_empty();
        alarms += usize::from(alarm);
        eprintln!(
            "seed {seed}: detected {:?} unexplained {:?}",
            a.detected
                .iter()
                .map(|d| format!("{}[{}]", d.effect, d.sensor))
                .collect::<Vec<_>>(),
            a.unexplained
                .iter()
                .map(|u| format!(
                    "{}:{}:{} p {:.1e}",
                    u.sensor, u.regressor, u.method, u.p_value
                ))
                .collect::<Vec<_>>()
        );
    }
    eprintln!("false alarms {alarms}/{n}");
}
