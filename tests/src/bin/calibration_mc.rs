//! `calibration-mc`: Monte Carlo of the ground calibration over seeds (issue 4's must-show).
//!
//! For each seed: fly the scenario with the prelaunch tables, run `ground-tool`'s chain on the
//! telemetry, and score against the truth: the relative alignment errors of FHST2, FSS1 and
//! FSS2 with respect to FHST1 normalised by the stated covariance (NEES, 3 degrees of freedom:
//! mean 3 when the covariance is right), the FHST1–FHST2 error against 5″, the stated σ against
//! the Cramér–Rao bound of the same data, and δM normalised by its σ (mean square 1).
//!
//! ```text
//! cargo run --release -p tests --bin calibration-mc -- -n 20 --first-seed 1 [--json]
//! ```

use anyhow::Context;
use clap::Parser;
use gro_tests::loop_report::{read_truth, relative_error_and_nees, true_delta_m};
use gro_tests::mc_campaign::{
    merge_shards, nums3, recorded, shard_file_name, summarise, Campaign, McSummary, Num,
    SeedResult, ShardFile,
};
use ground_tool::calibration::alignment::Weighting;
use ground_tool::pipeline::calibrate::{calibrate_run, CalibrateOptions, FhstStage};
use sim_harness::run::{run, RunOptions};
use sim_harness::scenario::resolve;
use sim_harness::{exit_code, InputError};
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    name = "calibration-mc",
    about = "Monte Carlo of the alignment and IRU calibration over seeds: normalised errors against the stated covariance and the Cramér–Rao bound",
    long_about = "Flies SCENARIO with the prelaunch tables for N seeds, calibrates each run from its \
telemetry alone (ground-tool's chain), and scores against truth.json.\n\n\
Per seed the table prints the FHST2 error w.r.t. FHST1 (arcsec, ACS), the NEES e'P^-1 e of FHST2, \
FSS1 and FSS2 relative to FHST1 with the stated covariance P (3 dof: mean 3 if P is right), and \
the largest δM error over its σ. Each seed flies its own FSS transfer functions, drawn \
from the population whose 1σ spreads are the scenario's coefficients (--fixed-fss-tf: the \
scenario's unit in every seed), and the metadata declares that population's level; --json gives every sensor's error vector per seed (the FSS \
errors and the within-36-arcsec counts of the README come from it). The summary gives the mean NEES, the fraction of seeds with FHST1-FHST2 \
within 5 arcsec, the RMS error per axis against the mean stated σ and the mean Cramér–Rao bound \
of the same data, and the fraction of δM elements within 3σ.\n\n\
--work W: each seed's folder W/seed-N is created by this run (refused, exit code 2, if it \
already exists) and removed after scoring; nothing else in W is touched.\n\n\
On a cluster: each task flies one shard (--shard K/M: the seeds first_seed + i with i mod M = K) \
and writes its results file (--shard-out DIR/results.shard-K-of-M.json); --merge FILES... then \
checks that the files make one campaign (same scenario, seeds and options; every shard once) \
and prints the same summary, bit for bit, as the unsharded run (scripts/slurm_campaign.sh runs \
it as a Slurm job array).\n\n\
Exit codes (every binary of the workspace): 0 success, 1 runtime failure, 2 bad input (e.g. -n 0).\n\n\
Example: calibration-mc -n 20 --first-seed 1 --json > mc.json"
)]
struct Args {
    /// Scenario name or TOML path.
    #[arg(long, default_value = "gro-early-mission")]
    scenario: String,
    /// Number of seeds.
    #[arg(short = 'n', long, default_value_t = 20)]
    runs: u64,
    /// First seed.
    #[arg(long, default_value_t = 1)]
    first_seed: u64,
    /// Work folder: each seed's W/seed-N is created here (it must not exist yet) and removed
    /// after scoring; nothing else in W is touched.
    #[arg(long, default_value = "runs/mc")]
    work: PathBuf,
    /// FFCAL with Shuster's 1982 scalar weights (covariance by the sandwich formula) instead of
    /// the optimal 1990 weighting.
    #[arg(long)]
    shuster1982: bool,
    /// One joint FFCAL of all sensors instead of the staged one.
    #[arg(long)]
    single_stage: bool,
    /// The FHST stage from Shuster's simultaneous star pairs only (the paper's FFCAL data)
    /// instead of every star in gyro batches.
    #[arg(long)]
    star_pairs: bool,
    /// Fly the scenario's FSS transfer functions as written in every seed (one unit, the
    /// same errors each seed) instead of drawing each seed's from the population whose 1σ
    /// spreads are the scenario's coefficients (`transfer_function_per_seed`).
    #[arg(long)]
    fixed_fss_tf: bool,
    /// Fly only shard K of M (0 ≤ K < M): the seeds `first_seed + i` with `i mod M = K`, and
    /// write their results to `--shard-out`/results.shard-K-of-M.json instead of a summary
    /// (for a Slurm job array: `--shard $SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT`).
    #[arg(long, value_name = "K/M", conflicts_with = "merge")]
    shard: Option<String>,
    /// Folder of the shard's results file (default: the work folder).
    #[arg(long, value_name = "DIR", requires = "shard")]
    shard_out: Option<PathBuf>,
    /// Summarise the shard files of one campaign instead of flying (every shard of one M once;
    /// the campaign, seeds and options must agree). The summary equals the unsharded run's.
    #[arg(long, value_name = "FILE", num_args = 1..)]
    merge: Vec<PathBuf>,
    /// Print the result as JSON.
    #[arg(long)]
    json: bool,
}

impl Args {
    /// The campaign these arguments describe.
    fn campaign(&self) -> Campaign {
        let flags = [
            (self.shuster1982, "--shuster1982"),
            (self.single_stage, "--single-stage"),
            (self.star_pairs, "--star-pairs"),
            (self.fixed_fss_tf, "--fixed-fss-tf"),
        ];
        Campaign {
            scenario: self.scenario.clone(),
            runs: self.runs,
            first_seed: self.first_seed,
            options: flags
                .iter()
                .filter(|(on, _)| *on)
                .map(|(_, f)| (*f).to_owned())
                .collect(),
        }
    }
}

fn one_seed(args: &Args, seed: u64) -> anyhow::Result<SeedResult> {
    let mut scenario = resolve(&args.scenario)?;
    scenario.seed = seed;
    if !args.fixed_fss_tf {
        scenario.fss1.transfer_function_per_seed = true;
        scenario.fss2.transfer_function_per_seed = true;
    }
    let dir = args.work.join(format!("seed-{seed}"));
    // Only a folder this run creates is removed afterwards.
    if let Err(e) = std::fs::create_dir(&dir) {
        if e.kind() == std::io::ErrorKind::AlreadyExists {
            return Err(InputError::msg(format!(
                "{} already exists and was not created by this run: calibration-mc removes its seed folders after scoring, so it does not write into one it did not create; remove it or choose another --work",
                dir.display()
            ))
            .into());
        }
        return Err(anyhow::Error::new(e).context(format!("cannot create {}", dir.display())));
    }
    let scored = score_seed(args, seed, scenario, &dir);
    let _ = std::fs::remove_dir_all(&dir);
    scored
}

fn score_seed(
    args: &Args,
    seed: u64,
    scenario: sim_harness::scenario::Scenario,
    dir: &std::path::Path,
) -> anyhow::Result<SeedResult> {
    run(
        scenario,
        &RunOptions {
            out_dir: Some(dir.join("run")),
            ..RunOptions::default()
        },
    )?;
    let options = CalibrateOptions {
        weighting: if args.shuster1982 {
            Weighting::Shuster1982
        } else {
            Weighting::Optimal1990
        },
        staged_ffcal: !args.single_stage,
        fhst_stage: if args.star_pairs {
            FhstStage::StarPairs
        } else {
            FhstStage::GyroBatches
        },
        ..CalibrateOptions::default()
    };
    let cal = calibrate_run(&dir.join("run"), &dir.join("cal"), &options)?;
    let truth = read_truth(&dir.join("run"))?;
    let sol = &cal.ffcal;
    let mut relative = Vec::new();
    let mut nees = Vec::new();
    for j in 1..sol.sensors.len() {
        let (e, n) = relative_error_and_nees(sol, &truth, j)?;
        relative.push((sol.sensors[j].id.clone(), nums3([e.x, e.y, e.z])));
        nees.push((sol.sensors[j].id.clone(), Num(n)));
    }
    let delta_m_normalised = match (&cal.irucal, true_delta_m(&truth)) {
        (Some(s), Some(t)) => {
            let d = (s.calibration.delta_m - t).component_div(&s.sigma_delta_m);
            let mut out = [Num(0.0); 9];
            for i in 0..3 {
                for j in 0..3 {
                    out[3 * i + j] = Num(d[(i, j)]);
                }
            }
            Some(out)
        }
        _ => None,
    };
    Ok(SeedResult {
        seed,
        relative_error_arcsec: relative,
        nees,
        sigma_fhst2_rel_fhst1_arcsec: nums3(cal.report.ffcal.sigma_fhst2_rel_fhst1_arcsec),
        crb_fhst2_rel_fhst1_arcsec: nums3(
            cal.report.ffcal.crb_sigma_fhst2_rel_fhst1_fhst_only_arcsec,
        ),
        crb_batches_fhst2_rel_fhst1_arcsec: nums3(
            cal.report
                .ffcal
                .gyro_batches
                .as_ref()
                .map_or([f64::NAN; 3], |g| {
                    g.crb_sigma_arcsec.map(|x| x * g.variance_factor.sqrt())
                }),
        ),
        delta_m_normalised,
    })
}

fn main() {
    let args = Args::parse();
    match monte_carlo(&args) {
        Ok(None) => {}
        Ok(Some(s)) => {
            if args.json {
                match serde_json::to_string_pretty(&s) {
                    Ok(j) => println!("{j}"),
                    Err(e) => {
                        eprintln!("error: {e}");
                        std::process::exit(i32::from(sim_harness::exit::FAILURE));
                    }
                }
            } else {
                print_table(&s);
            }
        }
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::exit(i32::from(exit_code(&e)));
        }
    }
}

/// Fly the campaign (or its shard) or merge shard files. `None` for a shard: its results
/// file is the output.
fn monte_carlo(args: &Args) -> anyhow::Result<Option<McSummary>> {
    if !args.merge.is_empty() {
        let (campaign, seeds) = merge_shards(&args.merge).map_err(InputError::from)?;
        eprintln!(
            "merged {} shard files: {} seeds of {}",
            args.merge.len(),
            seeds.len(),
            campaign.scenario
        );
        return Ok(Some(summarise(&campaign.scenario, seeds)));
    }
    if args.runs == 0 {
        return Err(InputError::msg("-n must be ≥ 1 (the number of seeds)").into());
    }
    let shard = match &args.shard {
        Some(text) => Some(sim_harness::campaign::parse_shard(text).map_err(InputError::from)?),
        None => None,
    };
    resolve(&args.scenario).map_err(InputError::from)?;
    std::fs::create_dir_all(&args.work)
        .with_context(|| format!("creating {}", args.work.display()))?;
    let campaign = args.campaign();
    let todo = campaign.seeds(shard.unwrap_or((0, 1)));
    let mut seeds = Vec::new();
    for (k, seed) in todo.iter().enumerate() {
        eprintln!("[{}/{}] seed {seed} ...", k + 1, todo.len());
        seeds.push(one_seed(args, *seed).with_context(|| format!("seed {seed}"))?);
    }
    // Both paths summarise the results as recorded (module doc of `mc_campaign`).
    let seeds = recorded(&seeds)?;
    let Some(shard) = shard else {
        return Ok(Some(summarise(&args.scenario, seeds)));
    };
    let dir = args.shard_out.as_ref().unwrap_or(&args.work);
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let path = dir.join(shard_file_name(shard));
    let partial = dir.join(format!("{}.partial", shard_file_name(shard)));
    let file = ShardFile {
        campaign,
        shard,
        seeds,
    };
    std::fs::write(&partial, serde_json::to_string_pretty(&file)? + "\n")
        .with_context(|| format!("writing {}", partial.display()))?;
    std::fs::rename(&partial, &path).with_context(|| format!("renaming to {}", path.display()))?;
    eprintln!(
        "wrote {} ({} seeds); summarise with --merge over every shard's file",
        path.display(),
        file.seeds.len()
    );
    Ok(None)
}

fn print_table(s: &McSummary) {
    println!(
        "| seed | FHST2 rel FHST1 error (″, ACS) | NEES FHST2 / FSS1 / FSS2 | max |δM err|/σ |"
    );
    println!("|---|---|---|---|");
    for r in &s.seeds {
        let e = r.fhst2();
        let nees: Vec<String> = r.nees.iter().map(|(_, v)| format!("{:.1}", v.0)).collect();
        let dm = r.delta_m_normalised.map_or("-".to_owned(), |d| {
            format!("{:.1}", d.iter().fold(0.0_f64, |m, x| m.max(x.0.abs())))
        });
        println!(
            "| {} | [{:.1}, {:.1}, {:.1}] | {} | {} |",
            r.seed,
            e[0],
            e[1],
            e[2],
            nees.join(" / "),
            dm
        );
    }
    println!();
    println!("runs: {}", s.runs);
    for (id, v) in &s.mean_nees {
        println!(
            "mean NEES {id} rel FHST1: {:.2} (3 = covariance right)",
            v.0
        );
    }
    println!(
        "FHST1-FHST2 within 5″: {:.0} % of seeds",
        100.0 * s.fhst1_fhst2_within_5_arcsec_fraction
    );
    let f = |a: [Num; 3]| format!("[{:.1}, {:.1}, {:.1}]", a[0].0, a[1].0, a[2].0);
    println!(
        "FHST1-FHST2 per axis: RMS error {} ″, mean stated σ {} ″; mean Cramér–Rao σ: every star in gyro batches {} ″, simultaneous star pairs {} ″",
        f(s.fhst1_fhst2_error_rms_per_axis_arcsec),
        f(s.fhst1_fhst2_mean_stated_sigma_arcsec),
        f(s.fhst1_fhst2_mean_crb_batches_sigma_arcsec),
        f(s.fhst1_fhst2_mean_crb_sigma_arcsec)
    );
    if let (Some(ms), Some(w)) = (
        s.delta_m_mean_square_normalised,
        s.delta_m_within_3sigma_fraction,
    ) {
        println!(
            "δM: mean (error/σ)² = {ms:.2} (1 = σ right); {:.0} % of elements within 3σ",
            100.0 * w
        );
    }
}
