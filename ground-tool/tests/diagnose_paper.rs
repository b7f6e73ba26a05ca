//! The paper's case (issue 5): the FSS transfer-function error in the truth of
//! `gro-early-mission`, and the IRU calibration (IRUCAL, Davenport δM) with and without that
//! effect modelled, against the paper's δM uncertainties (`data/gro_paper.toml`).
//!
//! A study over run folders (`scenarios/undeclared/paper_case.sh` flies them and calls this):
//!
//! `PAIRS=/tmp/tf-1:/tmp/notf-1,... cargo test --release -p ground-tool --test diagnose_paper -- --ignored --nocapture`
//!
//! Each pair is the same scenario and seed flown with the harness's FSS transfer-function
//! errors (the default truth) and without them (every head coefficient zero: the ceiling a
//! perfect transfer-function model could reach). On the first run IRUCAL is run through the
//! calibration chain's API (`calibrate_telemetry`) with the ground's FSS conversion
//!
//! * `none`: as flown (no transfer-function correction: the effect not modelled);
//! * `diagnose`: the correction `ground-tool diagnose` writes (`alignment.corrections.fss_transfer`,
//!   the scale and cross terms it determines at 3σ; the cubic and cyclic terms have no table
//!   field, so the chain cannot apply them);
//! * `truth-table`: the truth's scale and cross terms in the same fields (what the table can
//!   carry at best);
//!
//! and on the second run `none` again (`no-TF truth`).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use fsw_core::tables::AlignmentTable;
use fsw_core::units::RAD_PER_ARCSEC;
use ground_tool::diagnose::effects::FSS_EDGE_RAD;
use ground_tool::diagnose::run::{diagnose_run, DiagnoseOptions};
use ground_tool::diagnose::scoring::read_truth;
use ground_tool::pipeline::calibrate::{calibrate_telemetry, read_metadata, CalibrateOptions};
use nalgebra::Matrix3;
use std::path::Path;

/// The paper's δM 1σ (ppm), data/gro_paper.toml `[iru_calibration_published]`.
const PAPER_SIGMA_PPM: [[f64; 3]; 3] = [
    [507.0, 229.0, 610.0],
    [524.0, 223.0, 602.0],
    [527.0, 229.0, 608.0],
];

struct Irucal {
    dm: Matrix3<f64>,
    sigma: Matrix3<f64>,
    intervals: usize,
}

fn irucal(run: &Path, transfer: [[f64; 6]; 2]) -> Option<Irucal> {
    let tm = ground_tool::tp::read_file(&run.join("telemetry.bin")).unwrap();
    let md = read_metadata(run).unwrap();
    let mut a = AlignmentTable::prelaunch();
    a.corrections.fss_transfer = transfer;
    let copt = CalibrateOptions {
        flown_alignment: Some(a),
        ..CalibrateOptions::default()
    };
    let c = match calibrate_telemetry(&tm, &md, &copt) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("   calibration chain failed: {e:#}");
            return None;
        }
    };
    let s = c.irucal.as_ref()?;
    Some(Irucal {
        dm: s.calibration.delta_m,
        sigma: s.sigma_delta_m,
        intervals: c.report.iru.as_ref().map_or(0, |r| r.intervals),
    })
}

/// The truth's scale and cross terms as table coefficients (FSS1, FSS2).
fn truth_transfer(run: &Path) -> [[f64; 6]; 2] {
    let t = read_truth(run).unwrap().unwrap();
    let s = t.scenario_file.expect("truth.json names its scenario");
    let e3 = FSS_EDGE_RAD.powi(3);
    let mut out = [[0.0; 6]; 2];
    for (k, f) in [&s.fss1, &s.fss2].iter().enumerate() {
        out[k][0] = f.alpha.scale_ppm * 1e-6;
        out[k][1] = f.alpha.cross_arcsec_at_corner * RAD_PER_ARCSEC / e3;
        out[k][3] = f.beta.scale_ppm * 1e-6;
        out[k][4] = f.beta.cross_arcsec_at_corner * RAD_PER_ARCSEC / e3;
    }
    out
}

fn truth_delta_m(run: &Path) -> Matrix3<f64> {
    let t: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("truth.json")).unwrap()).unwrap();
    let d = &t["iru"]["primary"]["delta_m"];
    Matrix3::from_fn(|i, j| d[i][j].as_f64().unwrap())
}

fn line(name: &str, r: Option<&Irucal>, truth: &Matrix3<f64>) -> Option<(f64, f64, f64)> {
    let Some(r) = r else {
        eprintln!("   {name:<12} no IRUCAL solution");
        return None;
    };
    let err = (r.dm - truth) * 1e6;
    let sig = r.sigma * 1e6;
    let rms_err = (err.iter().map(|x| x * x).sum::<f64>() / 9.0).sqrt();
    let rms_sig = (sig.iter().map(|x| x * x).sum::<f64>() / 9.0).sqrt();
    let chi2 = err
        .iter()
        .zip(sig.iter())
        .map(|(e, s)| (e / s).powi(2))
        .sum::<f64>();
    let paper = (PAPER_SIGMA_PPM.iter().flatten().map(|x| x * x).sum::<f64>() / 9.0).sqrt();
    eprintln!(
        "   {name:<12} {} intervals: δM error rms {rms_err:6.0} ppm (max {:5.0}), σ rms {rms_sig:5.0} ppm (paper {paper:.0}), Σz²/9 {:6.2}, error/paper σ {:.2}",
        r.intervals,
        err.amax(),
        chi2 / 9.0,
        rms_err / paper
    );
    eprintln!(
        "   {:<12} error (ppm) {:?}",
        "",
        err.transpose()
            .iter()
            .map(|x| x.round())
            .collect::<Vec<_>>()
            .chunks(3)
            .map(<[f64]>::to_vec)
            .collect::<Vec<_>>()
    );
    Some((rms_err, rms_sig, chi2 / 9.0))
}

#[test]
#[ignore = "a study over run folders: PAIRS=tf:notf,... (scenarios/undeclared/paper_case.sh)"]
fn paper_case_irucal() {
    let pairs = std::env::var("PAIRS").unwrap();
    let out_root = std::env::temp_dir().join("diagnose-paper-case");
    let mut sums: std::collections::BTreeMap<&str, (f64, f64, f64, usize)> = Default::default();
    for pair in pairs.split(',') {
        let (tf, notf) = pair.split_once(':').unwrap();
        let (tf, notf) = (Path::new(tf), Path::new(notf));
        let truth = truth_delta_m(tf);
        eprintln!("== {}", tf.display());
        let d = diagnose_run(
            tf,
            &out_root.join(tf.file_name().unwrap()),
            &DiagnoseOptions::default(),
        )
        .unwrap();
        let diag_tf = d.alignment.corrections.fss_transfer;
        eprintln!(
            "   diagnose fss_transfer FSS1 {:?} FSS2 {:?}; truth-table {:?}",
            diag_tf[0],
            diag_tf[1],
            truth_transfer(tf)
        );
        for (name, run, transfer) in [
            ("none", tf, [[0.0; 6]; 2]),
            ("diagnose", tf, diag_tf),
            ("truth-table", tf, truth_transfer(tf)),
            ("no-TF truth", notf, [[0.0; 6]; 2]),
        ] {
            if let Some((e, s, c)) = line(name, irucal(run, transfer).as_ref(), &truth) {
                let x = sums.entry(name).or_default();
                x.0 += e * e;
                x.1 += s * s;
                x.2 += c;
                x.3 += 1;
            }
        }
    }
    eprintln!("== over the runs (rms over runs of the per-run rms over the 9 elements)");
    for (name, (e, s, c, n)) in sums {
        let n = n as f64;
        eprintln!(
            "   {name:<12} δM error {:5.0} ppm, σ {:5.0} ppm, mean Σz²/9 {:.2} ({n} runs)",
            (e / n).sqrt(),
            (s / n).sqrt(),
            c / n
        );
    }
}
