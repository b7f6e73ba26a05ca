//! `diagnose-scored`: `ground-tool diagnose` with the scoring against the simulator's truth.
//!
//! Why a binary of the `tests` crate: scoring needs the simulator's sensor models (the true
//! FSS transfer function and FHST distortion from the scenario as flown), which the ground
//! tool must not carry (issue 18). The diagnosis itself is the ground tool's, run through the
//! same code (`ground_tool::diagnose::run::diagnose_command`): the output folder is what
//! `ground-tool diagnose` writes, plus, when RUN_DIR/truth.json exists, report.json's
//! `scoring`, `calibration_error_arcsec`, `calibration_rotation_error_arcsec`,
//! `written_table_error_arcsec`, `unvalidated_table_error_arcsec` and their report.md section.

use clap::Parser;
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    name = "diagnose-scored",
    about = "ground-tool diagnose, scored against RUN_DIR/truth.json when it exists (evaluation only: the analysis never reads the truth)"
)]
struct Cli {
    /// Run folder with telemetry.bin (and truth.json to score against).
    run_dir: PathBuf,
    /// Output folder (replaced whole when it is a previous `diagnose` output).
    #[arg(long)]
    out: PathBuf,
    /// Replace the whole content of a non-empty OUT that is not a previous `diagnose` output.
    #[arg(long)]
    force: bool,
    /// Tables folder of the tables flown (its manifest.json lists them); default: the run's
    /// activated uploads, else the boot tables.
    #[arg(long)]
    tables: Option<PathBuf>,
    /// Print report.json to stdout.
    #[arg(long)]
    json: bool,
    /// No progress on stderr.
    #[arg(long, short)]
    quiet: bool,
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    match ground_tool::diagnose::run::diagnose_command(
        &ground_tool::run_check::CommandArgs {
            run_dir: &cli.run_dir,
            out: &cli.out,
            force: cli.force,
            tables: cli.tables.as_deref(),
            json: cli.json,
            quiet: cli.quiet,
            trust_tables: false,
        },
        Some(std::sync::Arc::new(
            gro_tests::diagnose::scoring::TruthScorer,
        )),
    ) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::from(gro_reference::exit_code(&e))
        }
    }
}
