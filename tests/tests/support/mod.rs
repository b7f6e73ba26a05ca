//! What the integration tests of this crate share (each test binary uses part of it).
#![allow(dead_code)]

use std::path::{Path, PathBuf};

/// A folder `name` under the tests' target tmp folder, its previous content removed (a later
/// test run replaces it, nothing accumulates). Not created.
pub fn fresh_dir(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// [`fresh_dir`] `name`, created, holding one file `file` (its folders created) with `text`:
/// data a command was not asked to touch.
pub fn fresh_dir_with_file(name: &str, file: &str, text: &str) -> PathBuf {
    let d = fresh_dir(name);
    let path = d.join(file);
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).unwrap();
    }
    std::fs::write(path, text).unwrap();
    d
}

/// Fly `scenario` into the run folder `out` (no progress bar), with the tables folder
/// `tables` uplinked when given.
pub fn fly(
    scenario: sim_harness::scenario::Scenario,
    out: &Path,
    tables: Option<&Path>,
) -> sim_harness::run::Summary {
    sim_harness::run::run(
        scenario,
        &sim_harness::run::RunOptions {
            out_dir: Some(out.to_path_buf()),
            tables_dir: tables.map(Path::to_path_buf),
            progress: false,
        },
    )
    .unwrap()
}

/// A copy of the run folder `run` in `dest` (created) without the packets of APID `apid`:
/// its `telemetry.bin` filtered (CCSDS primary header: APID in the low 11 bits of octets 0-1,
/// data length − 1 in octets 4-5) and its `metadata.json`.
pub fn copy_run_without_apid(run: &Path, dest: &Path, apid: u16) {
    let bytes = std::fs::read(run.join("telemetry.bin")).unwrap();
    let mut kept = Vec::new();
    let mut at = 0;
    while at + 6 <= bytes.len() {
        let packet_apid = u16::from_be_bytes([bytes[at], bytes[at + 1]]) & 0x07ff;
        let len = usize::from(u16::from_be_bytes([bytes[at + 4], bytes[at + 5]])) + 7;
        if packet_apid != apid {
            kept.extend_from_slice(&bytes[at..at + len]);
        }
        at += len;
    }
    std::fs::create_dir_all(dest).unwrap();
    std::fs::write(dest.join("telemetry.bin"), &kept).unwrap();
    std::fs::copy(run.join("metadata.json"), dest.join("metadata.json")).unwrap();
}
