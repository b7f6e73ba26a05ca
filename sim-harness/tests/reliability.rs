//! Bad inputs against `sim-harness` (issue 17; the whole table: `tests/reliability/run_all.sh`,
//! docs/reliability.md): each gives the documented exit code, a message that names the field
//! or file, and leaves nothing half written or foreign deleted.

#[path = "../../tests/reliability/command.rs"]
mod command;

use command::stderr;
use std::path::Path;
use std::process::Output;

use fsw_core::tables::{image::encode_image, AlignmentTable, FilterTable, IruTable, TableId};

fn sim(args: &[&str], dir: &Path) -> Output {
    command::run(env!("CARGO_BIN_EXE_sim-harness"), args, dir)
}

fn image<T: serde::Serialize>(id: TableId, t: &T) -> Vec<u8> {
    let mut buf = vec![0u8; 4096];
    let n = encode_image(id, Default::default(), t, &mut buf).unwrap();
    buf.truncate(n);
    buf
}

/// Write the image of table `t` (as `id`) to `path`.
fn write_image<T: serde::Serialize>(path: &Path, id: TableId, t: &T) {
    std::fs::write(path, image(id, t)).unwrap();
}

fn scenario_with(dir: &Path, name: &str, key: &str, value: &str) -> String {
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/gro-early-mission.toml"),
    )
    .unwrap();
    let out: String = text
        .lines()
        .map(|l| {
            if l.starts_with(&format!("{key} =")) {
                format!("{key} = {value}")
            } else {
                l.to_owned()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    assert_ne!(out, text, "{key} not found");
    std::fs::write(dir.join(name), out).unwrap();
    name.to_owned()
}

/// Non-finite or out-of-range scenario values are refused with the field named (exit 2),
/// no run folder written. Before: `duration_s = 1e30` simulated 0 s with exit 0 and
/// `raan_deg = inf` wrote nulls into truth.json.
#[test]
fn scenario_values_out_of_range_are_refused_with_the_field_named() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    for (key, value, field) in [
        ("duration_s", "1e30", "duration_s"),
        ("raan_deg", "inf", "orbit.raan_deg"),
        ("raan_deg", "nan", "orbit.raan_deg"),
    ] {
        let f = scenario_with(d, &format!("{key}.toml"), key, value);
        let o = sim(&["run", &f, "--out", "o", "-q"], d);
        assert_eq!(o.status.code(), Some(2), "{key} = {value}: {}", stderr(&o));
        assert!(stderr(&o).contains(field), "{}", stderr(&o));
        assert!(!d.join("o").exists());
    }
    let o = sim(
        &[
            "run",
            "gro-early-mission",
            "--duration",
            "1e30",
            "--out",
            "o",
        ],
        d,
    );
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let o = sim(&["monte-carlo", "normal-ops", "-n", "0", "--out", "mc"], d);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
}

/// `--tables DIR` loads what DIR/manifest.json lists, checked by CRC; a folder that does not
/// exist, has no manifest, or holds a changed image is refused (exit 2); an image the
/// manifest does not list is not flown.
#[test]
fn tables_folders_are_loaded_from_their_manifest_only() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let run = |out: &str, tables: &str| {
        sim(
            &[
                "run",
                "gro-early-mission",
                "--duration",
                "30",
                "--out",
                out,
                "--tables",
                tables,
                "-q",
            ],
            d,
        )
    };
    let o = run("a", "no-such-dir");
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("no-such-dir") && !d.join("a").exists());
    let t = d.join("t");
    std::fs::create_dir_all(&t).unwrap();
    write_image(
        &t.join("alignment.tbl"),
        TableId::Alignment,
        &AlignmentTable::prelaunch(),
    );
    write_image(&t.join("iru.tbl"), TableId::Iru, &IruTable::prelaunch());
    let o = run("a", "t");
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("table manifest"), "{}", stderr(&o));
    sim_harness::manifest::write(&t, &["alignment.tbl".into(), "iru.tbl".into()], "test").unwrap();
    // A stale filter table beside the listed images.
    write_image(
        &t.join("filter.tbl"),
        TableId::Filter,
        &FilterTable::default_boot(),
    );
    let o = run("a", "t");
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stderr(&o).contains("filter.tbl is not listed"));
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("a/metadata.json")).unwrap()).unwrap();
    let flown: Vec<&str> = meta["uploads"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|u| u["table"].as_str())
        .collect();
    // The folder's two tables, between the catalog (0 s) and the orbit (1 s) and magnetics
    // (2 s) tables of the scenario (issue 20).
    assert_eq!(
        flown,
        ["star_catalog", "alignment", "iru", "orbit", "magnetics"]
    );
    // A listed image changed after the manifest was written.
    let mut changed = image(TableId::Alignment, &AlignmentTable::prelaunch());
    changed[100] ^= 1;
    std::fs::write(t.join("alignment.tbl"), changed).unwrap();
    let o = run("b", "t");
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("CRC-32") && !d.join("b").exists());
}

/// Output folders: a foreign non-empty `--out` is refused (its files kept) unless `--force`;
/// a previous run is replaced whole (no old upload left); a second writer fails with exit 1
/// and leaves the folder alone.
#[test]
fn output_folders_are_replaced_whole_by_one_writer() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let run = |extra: &[&str]| {
        let mut a = vec![
            "run",
            "gro-early-mission",
            "--duration",
            "30",
            "--out",
            "o",
            "-q",
        ];
        a.extend_from_slice(extra);
        sim(&a, d)
    };
    std::fs::create_dir_all(d.join("o")).unwrap();
    std::fs::write(d.join("o/notes.txt"), "mine").unwrap();
    let o = run(&[]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--force"));
    assert_eq!(
        std::fs::read_to_string(d.join("o/notes.txt")).unwrap(),
        "mine"
    );
    let o = run(&["--force"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(!d.join("o/notes.txt").exists() && d.join("o/summary.json").exists());
    // Run again over its own output: replaced whole.
    std::fs::write(d.join("o/uploads/99_old.tbl"), b"old").unwrap();
    let o = run(&[]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(!d.join("o/uploads/99_old.tbl").exists());
    // Another writer holds the lock (this test process: alive).
    std::fs::write(d.join(".o.lock"), format!("{}\n", std::process::id())).unwrap();
    let before = std::fs::read(d.join("o/telemetry.bin")).unwrap();
    let o = run(&["--seed", "7"]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("being written by another process"));
    assert_eq!(std::fs::read(d.join("o/telemetry.bin")).unwrap(), before);
    // A lock left by a process that no longer exists is taken over.
    std::fs::write(d.join(".o.lock"), "4000000000\n").unwrap();
    let o = run(&[]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(!d.join(".o.lock").exists());
}

/// `merge` combines only runs of one campaign.
#[test]
fn merge_refuses_runs_of_different_campaigns() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let mc = |dur: &str, out: &str, shard: Option<&str>| {
        let mut a = vec![
            "monte-carlo",
            "normal-ops",
            "-n",
            "2",
            "--duration",
            dur,
            "--out",
            out,
            "-q",
        ];
        if let Some(s) = shard {
            a.extend_from_slice(&["--shard", s]);
        }
        let o = sim(&a, d);
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    };
    mc("30", "a", None);
    mc("40", "b", None);
    let o = sim(&["merge", "a", "b", "--out", "m.json"], d);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("simulated") && !d.join("m.json").exists());
    mc("30", "s0", Some("0/2"));
    let o = sim(&["merge", "s0", "--out", "m.json"], d);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("missing"));
    mc("30", "s1", Some("1/2"));
    let o = sim(&["merge", "s0", "s1", "--out", "m.json"], d);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
}
