//! `sim-harness`: fly the Compton GRO onboard attitude software (fsw-core) in closed loop
//! against the truth models and write run folders for the ground tool. `--help` teaches.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicU64, Ordering};

use anyhow::Context;
use clap::{Parser, Subcommand};

use sim_harness::campaign::{self, CampaignOptions};
use sim_harness::outdir::OutputDir;
use sim_harness::run::{self, RunOptions};
use sim_harness::scenario::{self, Scenario};
use sim_harness::{exit_code, InputError};

const ABOUT: &str =
    "Closed-loop simulator of the Compton Gamma Ray Observatory (1991) attitude system.

Each 1 s cycle: truth (orbit, Sun, Hipparcos sky, rigid body + wheels) -> sensor words (FHST,
FSS, DRIRU II, temperatures) -> the onboard software fsw-core (FlightCore::step with the
scenario's commands) -> its wheel torque drives the dynamics and its IRU rate-mode request goes
to the gyro model. At t = 0 the harness uplinks the onboard star catalog (the prelaunch ground
system's, built from Hipparcos) and initialises the filter 0.1 deg off the truth.

Scenarios are TOML files (see scenarios/*.toml, each documented). A bare name such as
`gro-early-mission` means scenarios/gro-early-mission.toml (built into the binary too).

Exit codes (every binary of the workspace): 0 ok, 1 runtime failure (I/O, another writer
busy on the same folder), 2 bad input (scenario, option or table file; the message names the
file, the field and the cause).";

const AFTER: &str = "Examples:
  sim-harness run gro-early-mission --out runs/early
  sim-harness run scenarios/normal-ops.toml --out runs/ops --duration 1800 --json
  sim-harness run gro-early-mission --out runs/cal --tables ground-out/tables
  sim-harness monte-carlo normal-ops -n 32 --seed 100 --duration 3600 --out runs/mc
  sim-harness monte-carlo normal-ops -n 32 --seed 100 --out runs/mc --shard $SLURM_ARRAY_TASK_ID/8
  sim-harness merge runs/mc
  sim-harness bench --duration 3600 --json";

#[derive(Parser)]
#[command(name = "sim-harness", version, about = ABOUT, long_about = ABOUT, after_help = AFTER)]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Fly one scenario and write a run folder.
    ///
    /// Writes into DIR (docs/icd.md §5): telemetry.bin (CCSDS packets: raw frame 0x010, magnetics frame 0x013 with `[magnetics] enabled`,
    /// ephemeris 0x020 every 10 s, housekeeping 0x011, events 0x012), metadata.json (what the
    /// operator declares: noise figures, declared effects, boot tables and uploads),
    /// uploads/*.tbl (every table image uplinked), truth.json (true alignments, IRU delta_m
    /// and G, bias history, undeclared effects: for scoring only) and summary.json (attitude
    /// error rms/3-sigma per axis, post-maneuver errors, NEES, rejected measurements, speed).
    /// The folder is written as a temporary sibling (.DIR.tmp-PID) and renamed into place at
    /// the end, so DIR holds one whole run or its previous content; a second writer into the
    /// same DIR fails (lock file .DIR.lock, exit code 1).
    #[command(after_help = "Example: sim-harness run gro-early-mission --out runs/early --json")]
    Run {
        /// Scenario TOML file, or a bare built-in name (gro-early-mission, gro-bias-history,
        /// normal-ops, inertial_hold, undeclared_effects).
        scenario: String,
        /// Run folder. An existing DIR is replaced whole if it is a previous `sim-harness run`
        /// output (its .gro-output.json says so); any other non-empty DIR is refused (exit
        /// code 2) unless --force.
        #[arg(long)]
        out: PathBuf,
        /// Replace the whole content of a non-empty --out that another tool or a person wrote.
        #[arg(long)]
        force: bool,
        /// Override the scenario's duration_s (s).
        #[arg(long)]
        duration: Option<f64>,
        /// Override the scenario's seed (every random stream derives from it).
        #[arg(long)]
        seed: Option<u64>,
        /// Load and activate at t = 0 (after the catalog) the table images that
        /// DIR/manifest.json lists, each checked against its CRC-32: the tables/ folder
        /// written by `ground-tool calibrate` or `diagnose`. A folder without a manifest is
        /// refused (exit code 2); `ground-tool table manifest DIR` writes one for a folder
        /// made by hand. Other *.tbl files in DIR are not loaded. When DIR/provenance.json
        /// (written beside the tables by the ground tool) says they were calibrated on
        /// another spacecraft than the scenario's — other true sensor or gyro parameters — or
        /// on telemetry without a simulator spacecraft identity, a warning says so on stderr
        /// and in summary.json `tables_provenance_warning`: the run's attitude error then says
        /// nothing about those tables.
        #[arg(long, value_name = "DIR")]
        tables: Option<PathBuf>,
        /// Print summary.json to stdout.
        #[arg(long)]
        json: bool,
        /// No progress bar (it is also hidden when stderr is not a terminal).
        #[arg(long, short)]
        quiet: bool,
    },
    /// Fly one scenario with N seeds in parallel (rayon) and aggregate the scores.
    ///
    /// Run i (0 ≤ i < N) has seed S + i and its own run folder DIR/run_<i>/. The aggregate
    /// (mean/std/min/max over runs of the rms error per axis, max error, post-maneuver errors
    /// per slew, NEES, fine-mode fraction, real-time factor) goes to DIR/aggregate.json, or
    /// with --shard K/M to DIR/aggregate.shard-K-of-M.json: the shard flies only runs with
    /// i mod M = K, so M array tasks (Slurm, Kubernetes indexed jobs) fly one campaign;
    /// combine them with `sim-harness merge`. Threads: RAYON_NUM_THREADS (default: all cores).
    #[command(
        name = "monte-carlo",
        after_help = "Example: sim-harness monte-carlo normal-ops -n 16 --seed 1 --duration 3600 --out runs/mc"
    )]
    MonteCarlo {
        /// Scenario file or built-in name.
        scenario: String,
        /// Number of runs in the whole campaign.
        #[arg(short = 'n', long = "runs")]
        runs: u32,
        /// Seed of run 0.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Campaign folder.
        #[arg(long)]
        out: PathBuf,
        /// Fly only the runs of shard K of M (0-based K), e.g. 3/8.
        #[arg(long, value_name = "K/M")]
        shard: Option<String>,
        /// Override the scenario's duration_s (s).
        #[arg(long)]
        duration: Option<f64>,
        /// Table images to activate at t = 0 in every run (DIR/manifest.json, as `run`).
        #[arg(long, value_name = "DIR")]
        tables: Option<PathBuf>,
        /// Replace run folders DIR/run_* that `sim-harness run` did not write.
        #[arg(long)]
        force: bool,
        /// Print the aggregate to stdout.
        #[arg(long)]
        json: bool,
        /// No progress bar.
        #[arg(long, short)]
        quiet: bool,
    },
    /// Combine the runs of campaign folders (e.g. the shards of a job array) into one
    /// aggregate.json.
    ///
    /// Reads every DIR/run_*/summary.json and writes the aggregate to --out or
    /// DIR[0]/aggregate.json, and prints it. Refused (exit code 2) unless the runs are of one
    /// campaign: one scenario and duration, each seed once, and the shards' aggregate files
    /// agree on scenario, runs, first seed, duration and shard count, with every shard given.
    #[command(
        after_help = "Example: sim-harness merge runs/mc-shard0 runs/mc-shard1 --out runs/mc.json"
    )]
    Merge {
        /// Campaign folders.
        #[arg(required = true)]
        dirs: Vec<PathBuf>,
        /// Output file (default: the first DIR's aggregate.json).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Fly fault-injection scenarios with and without their [[faults]] and print the
    /// docs/reliability.md fault table.
    ///
    /// For each scenario (default: every scenarios/faults/*.toml): the worst per-axis attitude
    /// error (truth vs OBC estimate) from the fault start to the recovery, the same interval
    /// without the faults, the recovery time (from the fault end until every later cycle is in
    /// fine mode with every axis inside 0.024° = 86.4″), the events raised more often than
    /// without the faults, and whether the active tables (dumps) are unchanged.
    #[command(
        after_help = "Example: cargo run --release -p sim-harness -- faults scenarios/faults/*.toml --json"
    )]
    Faults {
        /// Scenario files (default: scenarios/faults/*.toml of the workspace).
        scenarios: Vec<String>,
        /// JSON output (one report per scenario).
        #[arg(long)]
        json: bool,
    },
    /// Measure the closed-loop speed on the built-in gro-early-mission (no files written).
    ///
    /// Flies the embedded scenario for --duration seconds with fsw-core in the loop and the
    /// telemetry encoded into a sink, on one thread, and prints real-time factor, simulated
    /// and wall seconds, cycles and ns per cycle (JSON with --json). Build with --release.
    #[command(
        after_help = "Example: cargo run --release -p sim-harness -- bench --duration 3600 --json"
    )]
    Bench {
        /// Simulated seconds.
        #[arg(long, default_value_t = 3600.0)]
        duration: f64,
        /// JSON output: {\"real_time_factor\",\"sim_seconds\",\"wall_seconds\",\"cycles\",\"ns_per_cycle\"}.
        #[arg(long)]
        json: bool,
    },
}

fn load_scenario(arg: &str, duration: Option<f64>, seed: Option<u64>) -> anyhow::Result<Scenario> {
    let mut s = scenario::resolve(arg).map_err(InputError::from)?;
    if let Some(d) = duration {
        s.duration_s = d;
        s.validate()
            .context("--duration")
            .map_err(InputError::from)?;
    }
    if let Some(seed) = seed {
        s.seed = seed;
    }
    Ok(s)
}

fn print_json(v: &impl serde::Serialize) -> anyhow::Result<()> {
    println!("{}", serde_json::to_string_pretty(v)?);
    Ok(())
}

/// The few lines `sim-harness run` prints without `--json`.
fn print_run_summary(name: &str, summary: &run::Summary, out: &std::path::Path) {
    let e = &summary.attitude_error_arcsec;
    eprintln!(
        "{name}: {} cycles, {:.0} s simulated in {:.2} s ({:.0}x real time)\n\
         attitude error (t >= 600 s, outside slews): rms [{:.2}, {:.2}, {:.2}] arcsec, max {:.2} arcsec; NEES mean {}\n\
         post-maneuver errors (deg): {}\n\
         wrote {}",
        summary.timing.cycles,
        summary.timing.sim_seconds,
        summary.timing.wall_seconds,
        summary.timing.real_time_factor,
        e.rms[0],
        e.rms[1],
        e.rms[2],
        e.max,
        summary
            .filter_nees_mean
            .map_or_else(|| "n/a".to_owned(), |n| format!("{n:.2}")),
        post_maneuver_text(&summary.post_maneuver_error_deg),
        out.display()
    );
}

/// A progress bar over `n` runs on a terminal, unless quiet.
fn progress_bar(quiet: bool, n: u64) -> Option<indicatif::ProgressBar> {
    use std::io::IsTerminal;
    (!quiet && std::io::stderr().is_terminal()).then(|| {
        let pb = indicatif::ProgressBar::new(n);
        pb.set_style(
            indicatif::ProgressStyle::with_template(
                "[{elapsed_precise}] {wide_bar} {pos}/{len} runs (eta {eta})",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        pb
    })
}

/// `sim-harness faults`: assess the fault scenarios given, or the shipped ones.
fn faults_command(scenarios: Vec<String>, json: bool) -> anyhow::Result<()> {
    let files = if scenarios.is_empty() {
        sim_harness::faults::shipped_fault_scenarios()
            .map_err(InputError::from)?
            .into_iter()
            .map(|p| p.display().to_string())
            .collect()
    } else {
        scenarios
    };
    let mut reports = Vec::new();
    for f in &files {
        let s = scenario::resolve(f).map_err(InputError::from)?;
        let r = sim_harness::faults::assess(&s).with_context(|| f.clone())?;
        eprintln!("{f}: done");
        reports.push(r);
    }
    if json {
        print_json(&reports)?;
    } else {
        print!("{}", sim_harness::faults::markdown_table(&reports));
    }
    Ok(())
}

/// `sim-harness bench`: the closed loop's speed.
fn bench_command(duration: f64, json: bool) -> anyhow::Result<()> {
    if !(duration.is_finite() && duration > 0.0) {
        return Err(InputError::msg(format!("--duration must be > 0, got {duration}")).into());
    }
    let v = run::bench(duration)?;
    if json {
        println!("{}", serde_json::to_string(&v)?);
    } else {
        println!(
            "gro-early-mission, {} s simulated in {:.3} s: {:.0}x real time, {:.0} ns/cycle",
            v["sim_seconds"],
            v["wall_seconds"].as_f64().unwrap_or(0.0),
            v["real_time_factor"].as_f64().unwrap_or(0.0),
            v["ns_per_cycle"].as_f64().unwrap_or(0.0)
        );
    }
    Ok(())
}

fn main_inner(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Cmd::Run {
            scenario,
            out,
            force,
            duration,
            seed,
            tables,
            json,
            quiet,
        } => {
            let s = load_scenario(&scenario, duration, seed)?;
            let name = s.name.clone();
            // The scenario file and the tables folder are inputs: --out must not contain them.
            let scenario_path = std::path::Path::new(&scenario);
            let inputs: Vec<&std::path::Path> = [Some(scenario_path), tables.as_deref()]
                .into_iter()
                .flatten()
                .collect();
            let dir = OutputDir::begin(&out, "sim-harness run", force, &inputs)?;
            let summary = run::run(
                s,
                &RunOptions {
                    out_dir: Some(dir.path().to_path_buf()),
                    tables_dir: tables,
                    progress: !quiet,
                },
            )?;
            dir.commit()?;
            if json {
                print_json(&summary)?;
            } else {
                print_run_summary(&name, &summary, &out);
            }
        }
        Cmd::MonteCarlo {
            scenario,
            runs,
            seed,
            out,
            shard,
            duration,
            tables,
            force,
            json,
            quiet,
        } => {
            let s = load_scenario(&scenario, duration, None)?;
            let shard = match shard {
                Some(t) => campaign::parse_shard(&t).map_err(InputError::from)?,
                None => (0, 1),
            };
            if runs == 0 {
                return Err(InputError::msg("-n must be ≥ 1").into());
            }
            let mine = (0..runs).filter(|i| i % shard.1 == shard.0).count() as u64;
            let pb = progress_bar(quiet, mine);
            let done = AtomicU64::new(0);
            let on_done = || {
                let n = done.fetch_add(1, Ordering::Relaxed) + 1;
                if let Some(pb) = &pb {
                    pb.set_position(n);
                }
            };
            let (agg, path) = campaign::monte_carlo(
                &s,
                &CampaignOptions {
                    runs,
                    seed,
                    out_dir: out,
                    shard,
                    tables_dir: tables,
                    duration_s: duration,
                    force,
                },
                &on_done,
            )?;
            if let Some(pb) = pb {
                pb.finish_and_clear();
            }
            if json {
                print_json(&agg)?;
            }
            eprintln!("{} runs aggregated into {}", agg.runs, path.display());
        }
        Cmd::Merge { dirs, out } => {
            let (agg, path) = campaign::merge(&dirs, out.as_deref()).context("merge")?;
            print_json(&agg)?;
            eprintln!("{} runs aggregated into {}", agg.runs, path.display());
        }
        Cmd::Faults { scenarios, json } => faults_command(scenarios, json)?,
        Cmd::Bench { duration, json } => bench_command(duration, json)?,
    }
    Ok(())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match main_inner(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("sim-harness: error: {e:#}");
            ExitCode::from(exit_code(&e))
        }
    }
}

/// The post-maneuver errors for people: every value when there are a few, else the count,
/// median, 95th percentile and largest (with the slew number); all of them are in
/// summary.json.
fn post_maneuver_text(errors_deg: &[f64]) -> String {
    const LIST_UP_TO: usize = 12;
    if errors_deg.len() <= LIST_UP_TO {
        let v: Vec<String> = errors_deg.iter().map(|x| format!("{x:.4}")).collect();
        return format!("[{}]", v.join(", "));
    }
    let mut sorted = errors_deg.to_vec();
    sorted.sort_by(f64::total_cmp);
    let at =
        |q: f64| sorted[((q * (sorted.len() - 1) as f64).round() as usize).min(sorted.len() - 1)];
    let (k_max, max) =
        errors_deg
            .iter()
            .enumerate()
            .fold(
                (0, f64::NEG_INFINITY),
                |(k, m), (i, &x)| if x > m { (i, x) } else { (k, m) },
            );
    format!(
        "{} slews: median {:.4}, 95th percentile {:.4}, largest {max:.4} (slew {}); all in summary.json",
        errors_deg.len(),
        at(0.5),
        at(0.95),
        k_max + 1
    )
}
