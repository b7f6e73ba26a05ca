//! Bad inputs against `ground-tool` (issue 17; the whole table: `tests/reliability/run_all.sh`,
//! docs/reliability.md): exit code 2 with a sentence naming the file, field and cause, and no
//! output written; damaged time codes dropped and reported or refused, never re-sorted into a
//! different timeline. python3 is required (the ICD writer makes the runs; CI has it).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

#[path = "../../tests/reliability/command.rs"]
mod command;
mod support;

use command::stderr;

use serde_json::Value;
use std::path::Path;
use std::process::Output;

fn gt(args: &[&str], dir: &Path) -> Output {
    command::run(env!("CARGO_BIN_EXE_ground-tool"), args, dir)
}

/// Table errors are sentences (no Rust debug values), the OS error once, the path named, and
/// the same exit code (2) as in `sim-harness`.
#[test]
fn table_errors_are_sentences_with_exit_code_2() {
    let tmp = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("rel-table");
    let _ = std::fs::remove_dir_all(&tmp);
    std::fs::create_dir_all(&tmp).unwrap();
    let o = gt(&["table", "write-prelaunch-alignment", "a.tbl"], &tmp);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let mut img = std::fs::read(tmp.join("a.tbl")).unwrap();
    img[100] ^= 1;
    std::fs::write(tmp.join("crc.tbl"), &img).unwrap();
    let o = gt(&["table", "inspect", "crc.tbl"], &tmp);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(e.contains("crc.tbl") && e.contains("CRC-32") && !e.contains("CrcMismatch"));
    let o = gt(&["table", "inspect", "no-such.tbl"], &tmp);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert_eq!(
        stderr(&o).matches("os error 2").count(),
        1,
        "{}",
        stderr(&o)
    );
    assert!(stderr(&o).contains("no-such.tbl"));
    let _ = std::fs::remove_dir_all(&tmp);
}

/// Declared noise figures outside their physical range, a `--tables` folder that does not
/// exist: exit code 2 naming the field or folder, no output folder.
#[test]
fn bad_metadata_and_missing_tables_are_refused() {
    let run = support::write_run("reliability", "meta", &["--duration", "600"]);
    let meta_path = run.join("metadata.json");
    let good: Value = serde_json::from_str(&std::fs::read_to_string(&meta_path).unwrap()).unwrap();
    for (key, value) in [
        ("iru_arw_rad_per_sqrt_s", serde_json::json!(-1.0)),
        ("fss_sigma_arcsec", serde_json::json!(-15.0)),
        ("fhst_sigma_arcsec", serde_json::json!([0.0, 0.0])),
    ] {
        let mut m = good.clone();
        m["sensors"][key] = value;
        std::fs::write(&meta_path, serde_json::to_string(&m).unwrap()).unwrap();
        let o = gt(&["calibrate", ".", "--out", "out-bad"], &run);
        assert_eq!(o.status.code(), Some(2), "{key}: {}", stderr(&o));
        assert!(stderr(&o).contains(key), "{}", stderr(&o));
        assert!(!run.join("out-bad").exists());
    }
    std::fs::write(&meta_path, serde_json::to_string(&good).unwrap()).unwrap();
    let o = gt(
        &["calibrate", ".", "--out", "out-bad", "--tables", "no-such"],
        &run,
    );
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("no-such") && !run.join("out-bad").exists());
    let _ = std::fs::remove_dir_all(&run);
}

/// One flipped bit in one raw frame's time code: that frame is dropped and reported (offset,
/// time, neighbours) and the run calibrates like the undamaged one; the second half's time
/// codes shifted by −3600 s: refused (exit 2) naming the offset and the size of the jump, no
/// tables. Before: the flipped bit refused the whole run (the epoch check read the damaged
/// frame), the shift was re-sorted into one timeline and gave a 1.6° wrong FSS2 alignment.
#[test]
fn damaged_time_codes_are_dropped_and_shifted_blocks_refused() {
    let calibrate = |run: &Path| {
        let o = gt(&["calibrate", ".", "--out", "out", "--json"], run);
        let checks: Vec<Value> = std::fs::read_to_string(run.join("out/input_check.json"))
            .ok()
            .and_then(|t| serde_json::from_str(&t).ok())
            .unwrap_or_default();
        (o, checks)
    };
    let clean = support::write_run("reliability", "time-clean", &[]);
    let (o, _) = calibrate(&clean);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let base: Value = serde_json::from_slice(&o.stdout).unwrap();
    let flip = support::write_run("reliability", "time-flip", &["--flip-time-bit", "2000:36"]);
    let (o, checks) = calibrate(&flip);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let r: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(
        r["data"]["frames"].as_u64().unwrap() + 1,
        base["data"]["frames"].as_u64().unwrap()
    );
    assert_eq!(r["telemetry"]["time_outliers"].as_array().unwrap().len(), 1);
    assert!(checks
        .iter()
        .any(|c| c["code"] == "time_code_outliers" && c["severity"] == "Warning"));
    // The same alignments as the undamaged run (one frame of 4 909 fewer), within 0.5″.
    for s in ["FHST1", "FHST2", "FSS1", "FSS2"] {
        for k in 0..3 {
            let a = r["alignments"][s]["theta_acs_arcsec"][k].as_f64().unwrap();
            let b = base["alignments"][s]["theta_acs_arcsec"][k]
                .as_f64()
                .unwrap();
            assert!((a - b).abs() < 0.5, "{s}[{k}]: {a} vs {b}");
        }
    }
    let shift = support::write_run(
        "reliability",
        "time-shift",
        &["--time-shift-after", "2500:-3600"],
    );
    let (o, _) = calibrate(&shift);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("jump back by 3599 s"), "{}", stderr(&o));
    assert!(!shift.join("out").exists());
    for d in [clean, flip, shift] {
        let _ = std::fs::remove_dir_all(d);
    }
}
