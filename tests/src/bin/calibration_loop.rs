//! `calibration-loop`: the main job in one command.
//!
//! Fly a scenario (default `gro-early-mission`) with the paper's prelaunch tables against the
//! true misalignments → calibrate on the ground from the telemetry alone → uplink the new
//! tables → fly again → print and write the before/after comparison.

use anyhow::Context;
use clap::Parser;
use gro_tests::loop_report::{compare, read_truth, render_markdown, LoopReport};
use ground_tool::pipeline::calibrate::{calibrate_run, CalibrateOptions};
use sim_harness::outdir::OutputDir;
use sim_harness::run::{run, RunOptions};
use sim_harness::scenario::resolve;
use sim_harness::InputError;
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    name = "calibration-loop",
    about = "Fly with prelaunch tables, calibrate on the ground, uplink, fly again; print the error before and after",
    long_about = "The whole in-flight calibration loop of the Compton GRO paper in one command.\n\n\
Steps: (1) sim-harness flies SCENARIO with the boot (prelaunch, paper Table 1) tables against the \
scenario's true misalignments and IRU errors; (2) ground-tool calibrates from OUT/1-fly-prelaunch/telemetry.bin \
only (TP -> FADS -> FFCAL -> adjustment -> IRUCAL); (3) the new tables OUT/2-calibration/tables/*.tbl are \
uplinked and the same scenario (same seed) is flown again; (4) the comparison is printed and written to \
OUT/report.md and OUT/report.json (truth is used only here, for scoring). The calibration's own report is \
OUT/2-calibration/report.md, which links its PNG plots (the residuals of every sensor pair before and after, \
the gyro bias history over the whole flight, the OBC's bias minus the ground's), each under the question it \
answers; OUT/2-calibration/tables/provenance.json names the flight and spacecraft the tables were made for.\n\n\
OUT is written as a temporary sibling .OUT.tmp-PID and renamed into place at the end: it holds one \
whole loop or its previous content. A previous calibration-loop output is replaced (so the same \
command can be run again); any other non-empty OUT is refused unless --force; a second loop into \
the same OUT fails (lock file .OUT.lock).\n\n\
Exit codes (every binary of the workspace): 0 success, 1 runtime failure, 2 bad input.\n\n\
Example: calibration-loop --out runs/loop"
)]
struct Args {
    /// Scenario name (scenarios/NAME.toml, built in) or a TOML path.
    #[arg(long, default_value = "gro-early-mission")]
    scenario: String,
    /// Output folder (replaced whole when it is a previous calibration-loop output).
    #[arg(long, default_value = "runs/loop")]
    out: PathBuf,
    /// Replace the whole content of a non-empty OUT that is not a previous calibration-loop
    /// output.
    #[arg(long)]
    force: bool,
    /// Seed (both flights use it, so only the tables differ).
    #[arg(long)]
    seed: Option<u64>,
    /// Shortened run for CI: limit each flight to this many seconds.
    #[arg(long)]
    duration: Option<f64>,
    /// Print report.json instead of the table.
    #[arg(long)]
    json: bool,
    /// Fail (exit code 1, after writing the reports) when any quantity of the table is worse
    /// after the calibration than before: a relative alignment error, a residual RMS, the
    /// fine-attitude error of an axis or the largest post-maneuver error (CI runs this).
    #[arg(long)]
    check: bool,
}

/// The quantities of the loop's table that are worse after the calibration than before.
fn regressions(r: &LoopReport) -> Vec<String> {
    let mut out = Vec::new();
    let mut pair = |what: &str, before: f64, after: f64| {
        if after > before {
            out.push(format!("{what}: {before:.1} -> {after:.1}"));
        }
    };
    for (k, b) in &r.relative_alignment_error_arcsec.before {
        if let Some(a) = r.relative_alignment_error_arcsec.after.get(k) {
            // A pair the data determine only to σ larger than the change is not a regression
            // of the calibration (its stated uncertainty covers it); it is printed as a note.
            let sigma = r
                .relative_alignment_sigma_arcsec
                .get(k)
                .copied()
                .unwrap_or(0.0);
            if *a > *b && *a <= 3.0 * sigma {
                if sigma.is_finite() {
                    eprintln!(
                        "--check note: relative alignment {k} {b:.1} -> {a:.1}″, within 3σ of the calibration's stated σ {sigma:.1}″ (the data do not determine it better)"
                    );
                } else {
                    eprintln!(
                        "--check note: relative alignment {k} {b:.1} -> {a:.1}″: a sensor of the pair is not observed in these data (its alignment only follows the adjustment's common rotation)"
                    );
                }
                continue;
            }
            pair(&format!("relative alignment error {k} (″)"), *b, *a);
        }
    }
    for (k, b) in &r.residual_rms_arcsec.before {
        if let Some(a) = r.residual_rms_arcsec.after.get(k) {
            pair(&format!("residual RMS {k} (″)"), *b, *a);
        }
    }
    for i in 0..3 {
        pair(
            &format!("fine-attitude error 3×RMS axis {i} (″)"),
            r.fine_attitude_error_3rms_arcsec.before[i],
            r.fine_attitude_error_3rms_arcsec.after[i],
        );
    }
    let max = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
    pair(
        "largest post-maneuver error (°)",
        max(&r.post_maneuver_error_deg.before),
        max(&r.post_maneuver_error_deg.after),
    );
    out
}

fn main() {
    let args = Args::parse();
    if let Err(e) = run_loop(&args) {
        eprintln!("error: {e:#}");
        std::process::exit(i32::from(sim_harness::exit_code(&e)));
    }
}

fn run_loop(args: &Args) -> anyhow::Result<()> {
    let t_start = std::time::Instant::now();
    let mut scenario = resolve(&args.scenario).map_err(InputError::from)?;
    if let Some(seed) = args.seed {
        scenario.seed = seed;
    }
    if let Some(d) = args.duration {
        scenario.duration_s = scenario.duration_s.min(d);
        scenario
            .validate()
            .context("--duration")
            .map_err(InputError::from)?;
    }
    let out = OutputDir::begin(&args.out, "calibration-loop", args.force, &[])?;
    let fly_a = out.path().join("1-fly-prelaunch");
    let cal = out.path().join("2-calibration");
    let fly_b = out.path().join("3-fly-calibrated");

    eprintln!(
        "[1/3] flying {} with the prelaunch tables ...",
        scenario.name
    );
    let summary_a = run(
        scenario.clone(),
        &RunOptions {
            out_dir: Some(fly_a.clone()),
            tables_dir: None,
            progress: true,
        },
    )?;
    eprintln!(
        "[2/3] calibrating from {}/telemetry.bin ...",
        args.out.join("1-fly-prelaunch").display()
    );
    let obc_bias = ground_tool::report::ObcBiasSeries::read(&fly_a)?;
    let calibration = calibrate_run(&fly_a, &cal, &CalibrateOptions::default())?;
    gro_reference::provenance::write(
        &cal.join("tables"),
        &args.out.join("1-fly-prelaunch"),
        &ground_tool::pipeline::flown::metadata_or_default(&fly_a),
        "calibration-loop",
    )?;
    ground_tool::report::write_calibration_report(
        &cal,
        &calibration,
        &fsw_core::tables::AlignmentTable::prelaunch(),
        Some(&obc_bias),
    )?;
    eprintln!(
        "[3/3] flying again with the uplinked tables {}/tables ...",
        args.out.join("2-calibration").display()
    );
    let summary_b = run(
        scenario,
        &RunOptions {
            out_dir: Some(fly_b.clone()),
            tables_dir: Some(cal.join("tables")),
            progress: true,
        },
    )?;
    let truth = read_truth(&fly_a)?;
    let mut report: LoopReport = compare(&summary_a, &summary_b, &calibration, &truth)?;
    report.wall_seconds = t_start.elapsed().as_secs_f64();
    std::fs::write(
        out.path().join("report.json"),
        serde_json::to_string_pretty(&report)?,
    )?;
    let md = render_markdown(&report);
    std::fs::write(out.path().join("report.md"), &md)?;
    out.commit()?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!("{md}");
        eprintln!(
            "wrote {}/report.md, report.json; calibration report and plots in {}",
            args.out.display(),
            args.out.join("2-calibration").display()
        );
    }
    if args.check {
        let worse = regressions(&report);
        if !worse.is_empty() {
            anyhow::bail!(
                "--check: worse after the calibration than before: {}",
                worse.join("; ")
            );
        }
        eprintln!("--check: every quantity of the table is better after the calibration");
    }
    Ok(())
}
