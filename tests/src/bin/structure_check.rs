//! `structure-check`: prints the longest functions outside tests and the import cycles
//! between modules, and fails (exit 1) when a function exceeds the limit or a cycle exists
//! that the baseline (`tests/structure-baseline.txt`) does not list, or when a listed
//! function grew: a ratchet, so that the offenders left from before the check (issue 18) are
//! named and cannot get worse while they are split.
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
    /// The offenders allowed for now, one per line: `fn FILE NAME LINES` (may not grow) or
    /// `cycle CRATE: A <-> B ...` (as printed); `#` starts a comment. Default:
    /// tests/structure-baseline.txt; an empty file = no exception.
    #[arg(long)]
    baseline: Option<PathBuf>,
}

/// The baseline's allowed functions (file, name → lines) and cycles (as printed).
#[derive(Default)]
struct Baseline {
    functions: std::collections::BTreeMap<(String, String), usize>,
    cycles: std::collections::BTreeSet<String>,
}

/// Read the baseline file.
fn read_baseline(path: &std::path::Path) -> Result<Baseline, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read the baseline {}: {e}", path.display()))?;
    let mut b = Baseline::default();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        if let Some(rest) = line.strip_prefix("cycle ") {
            b.cycles.insert(rest.trim().to_owned());
            continue;
        }
        let parts: Vec<&str> = line.split_whitespace().collect();
        match parts.as_slice() {
            ["fn", file, name, lines] => {
                let lines = lines.parse().map_err(|_| {
                    format!(
                        "{}:{}: `{lines}` is not a line count",
                        path.display(),
                        n + 1
                    )
                })?;
                b.functions
                    .insert(((*file).to_owned(), (*name).to_owned()), lines);
            }
            _ => {
                return Err(format!(
                    "{}:{}: expected `fn FILE NAME LINES` or `cycle CRATE: ...`, found `{line}`",
                    path.display(),
                    n + 1
                ))
            }
        }
    }
    Ok(b)
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
    let baseline_path = cli
        .baseline
        .clone()
        .unwrap_or_else(|| root.join("tests/structure-baseline.txt"));
    let baseline = match read_baseline(&baseline_path) {
        Ok(b) => b,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    let over: Vec<_> = lengths.iter().filter(|f| f.lines > cli.max_lines).collect();
    let mut too_long = 0;
    for f in &over {
        let key = (f.file.display().to_string(), f.name.clone());
        match baseline.functions.get(&key) {
            Some(&allowed) if f.lines <= allowed => {}
            Some(&allowed) => {
                eprintln!(
                    "error: {}:{} {} grew to {} lines (baseline {allowed}): split it instead",
                    f.file.display(),
                    f.line,
                    f.name,
                    f.lines
                );
                too_long += 1;
            }
            None => {
                eprintln!(
                    "error: {}:{} {} has {} lines (limit {})",
                    f.file.display(),
                    f.line,
                    f.name,
                    f.lines,
                    cli.max_lines
                );
                too_long += 1;
            }
        }
    }
    println!(
        "{} function(s) over {} lines, {} of them listed in {} (to split)",
        over.len(),
        cli.max_lines,
        over.len() - too_long,
        baseline_path.display()
    );
    let cycles = match structure::workspace_cycles(&root) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    println!("import cycles between modules: {}", cycles.len());
    let mut new_cycles = 0;
    for (krate, cycle) in &cycles {
        let names: Vec<String> = cycle.iter().map(|m| m.join("::")).collect();
        let printed = format!("{krate}: {}", names.join(" <-> "));
        let listed = baseline.cycles.contains(&printed);
        println!("  {printed}{}", if listed { " (baseline)" } else { "" });
        if !listed {
            new_cycles += 1;
        }
    }
    if too_long > 0 {
        eprintln!(
            "error: {too_long} function(s) longer than {} lines and not in the baseline, or grown: split them into named stages (docs/architecture.md)",
            cli.max_lines
        );
    }
    if new_cycles > 0 {
        eprintln!("error: {new_cycles} import cycle(s) between modules not in the baseline");
    }
    if too_long > 0 || new_cycles > 0 {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}
