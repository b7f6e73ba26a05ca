//! Shared by the tests that run the independent ICD writer (`tests/icd/write_run.py`).
#![allow(dead_code, clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The workspace root.
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

/// The writer's calibration day (`--plan long`, 20-min holds) with the paper's δM and the OBC
/// switching to the backup gyro triad halfway (t = 10,166 s), raw frames every 10 s: the
/// triad-switch tests of calibrate and diagnose.
pub const BACKUP_HALFWAY_10S: [&str; 9] = [
    "--plan",
    "long",
    "--hold-s",
    "1200",
    "--iru-delta-m",
    "paper",
    "--backup-halfway",
    "--downlink-every",
    "10",
];

/// Write a run with the writer's `flags` into a fresh folder `<prefix>-<case>` under the
/// target's tmp folder (replaced by the next test run: nothing accumulates).
pub fn write_run(prefix: &str, case: &str, flags: &[&str]) -> PathBuf {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("{prefix}-{case}"));
    let _ = std::fs::remove_dir_all(&dir);
    let out = Command::new("python3")
        .arg(root().join("tests/icd/write_run.py"))
        .arg("--out")
        .arg(&dir)
        .args(flags)
        .output()
        .expect("python3 is required for the tests that run the ICD writer (CI has it)");
    assert!(
        out.status.success(),
        "writer failed for {case}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    dir
}

/// `ground-tool CMD RUN --out OUT EXTRA...` (the binary of the test's own crate, `bin`).
pub fn ground_tool(bin: &str, cmd: &str, run: &Path, out: &Path, extra: &[&str]) -> Output {
    Command::new(bin)
        .arg(cmd)
        .arg(run)
        .arg("--out")
        .arg(out)
        .args(extra)
        .output()
        .unwrap()
}

/// [`ground_tool`], asserting success (its stderr in the message).
pub fn ground_tool_ok(bin: &str, cmd: &str, run: &Path, out: &Path, extra: &[&str]) -> Output {
    let o = ground_tool(bin, cmd, run, out, extra);
    assert!(
        o.status.success(),
        "{cmd} {}: {}",
        run.display(),
        String::from_utf8_lossy(&o.stderr)
    );
    o
}

/// `ground-tool calibrate RUN --out OUT --force --json EXTRA...` (the binary of the test's
/// own crate, `bin`): the report, after asserting success.
pub fn calibrate_json(bin: &str, run: &Path, out: &Path, extra: &[&str]) -> serde_json::Value {
    let args: Vec<&str> = ["--force", "--json"].iter().chain(extra).copied().collect();
    let o = ground_tool_ok(bin, "calibrate", run, out, &args);
    serde_json::from_slice(&o.stdout).unwrap()
}
