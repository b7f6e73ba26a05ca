//! `structure-check`: prints the longest functions outside tests and the import cycles
//! between modules, and fails (exit 1) when a function exceeds the limit or a cycle exists.
//!
//! The rules (what is measured, what counts as an import) are in the module doc of
//! `gro_tests::structure`; `.ci/run` runs this binary (issue 18).

use clap::Parser;
use gro_tests::structure;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "structure-check",
    about = "Longest functions outside tests (fails above --max-lines) and import cycles between modules (fails on any)"
)]
struct Cli {
    /// Workspace root (default: the one this binary was built from).
    #[arg(long)]
    root: Option<PathBuf>,
    /// Longest function allowed outside tests, in lines (`fn` to closing brace).
    #[arg(long, default_value_t = structure::MAX_FN_LINES)]
    max_lines: usize,
    /// How many of the longest functions to print.
    #[arg(long, default_value_t = 10)]
    top: usize,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let root = cli
        .root
        .unwrap_or_else(|| PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/..")));
    let lengths = match structure::workspace_function_lengths(&root) {
        Ok(l) => l,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    println!(
        "longest functions outside tests ({} measured, limit {} lines):",
        lengths.len(),
        cli.max_lines
    );
    for f in lengths.iter().take(cli.top) {
        println!("{:6}  {}:{}  {}", f.lines, f.file.display(), f.line, f.name);
    }
    let too_long = lengths.iter().filter(|f| f.lines > cli.max_lines).count();
    let cycles = match structure::workspace_cycles(&root) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    println!("import cycles between modules: {}", cycles.len());
    for (krate, cycle) in &cycles {
        let names: Vec<String> = cycle.iter().map(|m| m.join("::")).collect();
        println!("  {krate}: {}", names.join(" <-> "));
    }
    if too_long > 0 {
        eprintln!(
            "error: {too_long} function(s) longer than {} lines: split them into named stages (docs/architecture.md)",
            cli.max_lines
        );
    }
    if !cycles.is_empty() {
        eprintln!("error: {} import cycle(s) between modules", cycles.len());
    }
    if too_long > 0 || !cycles.is_empty() {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}
