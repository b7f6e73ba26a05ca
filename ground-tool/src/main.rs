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
    }
    Ok(())
}
