//! `ground-tool`: command-line front end of the flight-dynamics ground tool.
use anyhow::Result;
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "ground-tool", about = "CGRO flight-dynamics ground tool")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Reproduce the paper's numbers from data/gro_paper.toml.
    Paper {
        /// Machine-readable JSON instead of the table.
        #[arg(long)]
        json: bool,
    },
    /// Time FFCAL on synthetic data (requirement: 10^6 pairs in <= 2 s, release build).
    Bench {
        /// Number of dot-product pairs per Gauss-Newton pass.
        #[arg(long, default_value_t = 1_000_000)]
        pairs: usize,
        /// Use the 1982 scalar weights instead of the optimal (1990) ones.
        #[arg(long)]
        shuster1982: bool,
        /// Machine-readable JSON.
        #[arg(long)]
        json: bool,
    },
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Paper { json } => {
            let r = ground_tool::paper::reproduce()?;
            if json {
                println!("{}", serde_json::to_string_pretty(&ground_tool::paper::to_json(&r))?);
            } else {
                print!("{}", ground_tool::paper::render_table(&r));
            }
        }
        Command::Bench { pairs, shuster1982, json } => {
            use ground_tool::calibration::alignment::Weighting;
            let weighting = if shuster1982 { Weighting::Shuster1982 } else { Weighting::Optimal1990 };
            let t = ground_tool::bench::ffcal_timing(pairs, weighting, 1)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&t)?);
            } else {
                println!(
                    "FFCAL {:?}: {} epochs, {} pairs/pass, {} passes: {:.3} s ({:.3} s/pass); data generation {:.3} s",
                    t.weighting, t.epochs, t.pairs_per_pass, t.passes, t.ffcal_s, t.per_pass_s, t.generate_s
                );
                if t.ffcal_s * 1e6 / t.pairs_per_pass.max(1) as f64 > 2.0 {
                    eprintln!("warning: slower than the requirement of 2 s per 10^6 pairs (is this a release build?)");
                }
            }
        }
    }
    Ok(())
}
