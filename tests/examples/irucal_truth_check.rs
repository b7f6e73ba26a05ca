//! Developer check of IRUCAL against a simulation's truth: flies a scenario, runs the
//! calibration chain on its telemetry, and prints for every attitude fix of the gyro chain its
//! error against the true attitude (with the random and systematic σ IRUCAL gives it), the relative alignment
//! errors, the stars far from the truth, and the OBC's bias error.
//!
//! ```text
//! cargo run --release -p tests --example irucal_truth_check -- [SCENARIO] [SEED]
//! ```
use fsw_core::attitude::rotvec_from_rot;
use fsw_core::tables::types::matrix_from_rows;
use fsw_core::units::ARCSEC_PER_RAD;
use gro_reference::run_folder::Truth as TruthFile;
use ground_tool::pipeline::calibrate::{calibrate_run, CalibrateOptions, CalibrationOutput};
use nalgebra::{Matrix3, Vector3};
use sim_harness::closed_loop::Simulation;
use sim_harness::run::{run, RunOptions};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let name = args.get(1).map_or("gro-early-mission", String::as_str);
    let mut scenario = sim_harness::scenario::resolve(name)?;
    if let Some(seed) = args.get(2) {
        scenario.seed = seed.parse()?;
    }
    let dir = std::env::temp_dir().join(format!("irucal-truth-{}", std::process::id()));
    let truth = Truth::fly(scenario, &dir)?;
    let out = calibrate_run(
        &dir.join("run"),
        &dir.join("cal"),
        &CalibrateOptions::default(),
    )?;
    let t = gro_tests::loop_report::read_truth(&dir.join("run"))?;
    print_alignments(&out, &t);
    print_fixes(&out, &truth);
    let t0 = out.frames.first().map_or(0.0, |f| f.time.seconds());
    print_star_residuals(&out, &truth, t0);
    if std::env::var("IRUCAL_CHECK_STARS").is_ok() {
        print_star_counts(&out, t0);
    }
    print_bias_errors(&dir, &t, t0)?;
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}

/// The true attitude of every cycle.
struct Truth {
    attitudes: Vec<(f64, Matrix3<f64>)>,
}

impl Truth {
    /// Fly `scenario` into `dir/run`, then again keeping the true attitude of every cycle.
    fn fly(
        scenario: sim_harness::scenario::Scenario,
        dir: &std::path::Path,
    ) -> anyhow::Result<Self> {
        run(
            scenario.clone(),
            &RunOptions {
                out_dir: Some(dir.join("run")),
                ..RunOptions::default()
            },
        )?;
        // The same scenario and seed again, keeping the true attitude of every cycle.
        let mut sim = Simulation::new(scenario, None)?;
        let mut truth: Vec<(f64, Matrix3<f64>)> = Vec::new();
        while let Some(rec) = sim.step() {
            truth.push((rec.truth.t_s, rec.truth.m_acs_from_eci));
        }
        Ok(Self { attitudes: truth })
    }

    /// The true attitude at `t` (s).
    fn a_true(&self, t: f64) -> Matrix3<f64> {
        let truth = &self.attitudes;
        let i = truth.partition_point(|(ti, _)| *ti < t - 1e-6);
        truth[i.min(truth.len() - 1)].1
    }
}

/// The relative alignment errors against the truth, FFCAL's σ, and δM true and fitted.
fn print_alignments(out: &CalibrationOutput, t: &TruthFile) {
    let delta_m_true = gro_tests::loop_report::true_delta_m(t).unwrap_or_else(Matrix3::zeros);
    let names = ["FHST1", "FHST2", "FSS1", "FSS2"];
    let m_true = t.alignments.into_array().map(|m| matrix_from_rows(&m));
    let est = out.alignment.matrices().map(matrix_from_rows);
    let r: Vec<Matrix3<f64>> = (0..4).map(|k| est[k] * m_true[k].transpose()).collect();
    for (i, j) in [(0, 1), (0, 2), (0, 3)] {
        let e = rotvec_from_rot(&(r[i].transpose() * r[j])) * ARCSEC_PER_RAD;
        println!(
            "relative error {}-{}: [{:.1}, {:.1}, {:.1}] |{:.1}|″",
            names[i],
            names[j],
            e.x,
            e.y,
            e.z,
            e.norm()
        );
    }
    println!(
        "FFCAL σ FHST2 rel FHST1: {:?}",
        out.report.ffcal.sigma_fhst2_rel_fhst1_arcsec
    );
    println!("true δM (ppm):\n{}", delta_m_true * 1e6);
    if let Some(r) = &out.report.iru {
        println!(
            "fitted δM (ppm):\n{}",
            Matrix3::from_row_slice(&r.delta_m.concat()) * 1e6
        );
    }
}

/// Every attitude fix of the gyro chain: its error against the truth, its σ.
fn print_fixes(out: &CalibrationOutput, truth: &Truth) {
    println!("fix   t_s      err(″ acs)                 σ random (″)          σ systematic (″)");
    for (k, f) in out.gyro_chain.fixes.iter().enumerate() {
        let e = rotvec_from_rot(&(truth.a_true(f.t_s) * f.fix.m_acs_from_eci.transpose()))
            * ARCSEC_PER_RAD;
        let sd = |m: &Matrix3<f64>| [0, 1, 2].map(|i| m[(i, i)].max(0.0).sqrt() * ARCSEC_PER_RAD);
        let (r, sy) = (
            sd(&(f.fix.cov_acs_rad2 - f.systematic_cov_rad2)),
            sd(&f.systematic_cov_rad2),
        );
        println!(
            "{k:4} {:8.0} [{:7.1},{:7.1},{:7.1}] [{:5.1},{:5.1},{:5.1}] [{:5.1},{:5.1},{:5.1}]",
            f.t_s, e.x, e.y, e.z, r[0], r[1], r[2], sy[0], sy[1], sy[2],
        );
    }
}

/// Per-star residual against the truth per 100-s block.
fn print_star_residuals(out: &CalibrationOutput, truth: &Truth, t0: f64) {
    // Per-star residual against the truth (flown = calibrated alignments, so tens of arcsec
    // of alignment error remain): how many identified stars are far off, per 100-s block.
    let mut block = (0usize, 0usize, 0.0f64, -1i64);
    for f in &out.frames {
        let t = f.time.seconds() - t0;
        let b = (t / 100.0) as i64;
        if b != block.3 {
            if block.0 > 0 && block.1 > 0 {
                println!(
                    "t {:6}..: stars {:4}, > 60″ off: {:4}, max {:8.1}″",
                    block.3 * 100,
                    block.0,
                    block.1,
                    block.2
                );
            }
            block = (0, 0, 0.0, b);
        }
        for s in f.stars.iter().flatten() {
            if let Some((_, dir_eci)) = s.identified {
                let r = (truth.a_true(t) * dir_eci).angle(&s.meas.dir_acs) * ARCSEC_PER_RAD;
                block.0 += 1;
                if r > 60.0 {
                    block.1 += 1;
                }
                block.2 = block.2.max(r);
            }
        }
    }
}

/// Identified stars per tracker per 100-s block, with the distinct stars.
fn print_star_counts(out: &CalibrationOutput, t0: f64) {
    let mut b = -1i64;
    let mut counts = [0usize; 2];
    let mut hips: [std::collections::BTreeSet<u32>; 2] = Default::default();
    for f in &out.frames {
        let blk = ((f.time.seconds() - t0) / 100.0) as i64;
        if blk != b {
            if b >= 0 {
                println!(
                    "stars {:6}: T1 {:3} ({:?}) T2 {:3} ({:?}) high_rate {}",
                    b * 100,
                    counts[0],
                    hips[0],
                    counts[1],
                    hips[1],
                    f.high_rate
                );
            }
            b = blk;
            counts = [0; 2];
            hips = Default::default();
        }
        for k in 0..2 {
            if let Some(s) = &f.stars[k] {
                if let Some((hip, _)) = s.identified {
                    counts[k] += 1;
                    hips[k].insert(hip);
                }
            }
        }
    }
}

/// The OBC's bias error against the truth every 300 s (″/s).
fn print_bias_errors(dir: &std::path::Path, t: &TruthFile, t0: f64) -> anyhow::Result<()> {
    let samples = t
        .bias_history
        .as_ref()
        .map(|h| h.samples.as_slice())
        .unwrap_or_default();
    let tm = ground_tool::tp::read_file(&dir.join("run").join("telemetry.bin"))?;
    for s in samples.iter().step_by(5) {
        let ts = s.t_s;
        let i = tm
            .housekeeping
            .partition_point(|h| h.time.seconds() - t0 < ts);
        if let Some(h) = tm.housekeeping.get(i) {
            let e = Vector3::from_fn(|k, _| {
                (h.bias_acs_rad_per_s[k] - s.bias_acs_rad_per_s[k]) * ARCSEC_PER_RAD
            });
            println!(
                "bias err t {ts:6.0}: [{:6.3}, {:6.3}, {:6.3}] ″/s",
                e.x, e.y, e.z
            );
        }
    }
    Ok(())
}
