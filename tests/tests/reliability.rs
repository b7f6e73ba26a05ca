//! Bad inputs against the main-job binaries (issue 17; the whole table:
//! `tests/reliability/run_all.sh`, docs/reliability.md).

#[path = "../reliability/command.rs"]
mod command;
mod support;

use command::{run, stderr};
use std::process::Output;

/// `calibration-mc -n 0` is bad input (exit 2, as `monte-carlo -n 0`), and `--work W` never
/// deletes a seed folder it did not create.
#[test]
fn calibration_mc_refuses_zero_runs_and_foreign_seed_folders() {
    let tmp = support::fresh_dir_with_file("rel-mc", "w/seed-1/precious.txt", "keep");
    let mc = env!("CARGO_BIN_EXE_calibration-mc");
    let o = run(mc, &["-n", "0", "--work", "w"], &tmp);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let o = run(mc, &["-n", "1", "--work", "w"], &tmp);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("not created by this run"),
        "{}",
        stderr(&o)
    );
    assert_eq!(
        std::fs::read_to_string(tmp.join("w/seed-1/precious.txt")).unwrap(),
        "keep"
    );
    let _ = std::fs::remove_dir_all(&tmp);
}

/// The README's main-job command works when run twice (the loop replaces its own previous
/// output whole: the same table, no file of the first run left), and refuses a folder it did
/// not write.
#[test]
fn calibration_loop_runs_twice_into_its_own_folder() {
    let tmp = support::fresh_dir_with_file("rel-loop", "other/notes.txt", "mine");
    let lp = env!("CARGO_BIN_EXE_calibration-loop");
    let args = ["--duration", "7200", "--out", "loop"];
    let first = run(lp, &args, &tmp);
    assert_eq!(first.status.code(), Some(0), "{}", stderr(&first));
    std::fs::write(tmp.join("loop/2-calibration/tables/stale.tbl"), b"old").unwrap();
    let second = run(lp, &args, &tmp);
    assert_eq!(second.status.code(), Some(0), "{}", stderr(&second));
    let table = |o: &Output| -> Vec<String> {
        String::from_utf8_lossy(&o.stdout)
            .lines()
            .filter(|l| l.starts_with('|'))
            .map(str::to_owned)
            .collect()
    };
    assert!(table(&first).len() > 10);
    assert_eq!(table(&first), table(&second), "the same before/after table");
    assert!(!tmp.join("loop/2-calibration/tables/stale.tbl").exists());
    assert!(tmp.join("loop/2-calibration/tables/manifest.json").exists());
    let o = run(lp, &["--duration", "7200", "--out", "other"], &tmp);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(tmp.join("other/notes.txt").exists());
    let _ = std::fs::remove_dir_all(&tmp);
}
