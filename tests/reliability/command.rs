//! Running a binary of the workspace on bad input, shared by the bad-input tests of the three
//! crates with binaries (`ground-tool/tests/reliability.rs`, `sim-harness/tests/reliability.rs`,
//! `tests/tests/reliability.rs`; the whole table: `tests/reliability/run_all.sh`,
//! docs/reliability.md). Each includes this file with `#[path]`.

use std::path::Path;
use std::process::{Command, Output};

/// `bin args…` run in the folder `dir`, its exit status and output.
pub fn run(bin: &str, args: &[&str], dir: &Path) -> Output {
    Command::new(bin)
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap()
}

/// What the run wrote to stderr, as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}
