//! Write the JSON Schemas of the run-folder files into `docs/schema/` (or the folder given):
//! `cargo run -p gro-reference --example write_schemas [-- DIR]`. The test
//! `gro-reference/tests/schema.rs` fails when the shipped files differ from what this writes.

fn main() -> anyhow::Result<()> {
    let dir = std::env::args_os().nth(1).map_or_else(
        || std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/schema"),
        std::path::PathBuf::from,
    );
    std::fs::create_dir_all(&dir)?;
    for (name, text) in gro_reference::run_folder::schemas() {
        let p = dir.join(name);
        std::fs::write(&p, text).map_err(|e| anyhow::anyhow!("writing {}: {e}", p.display()))?;
        eprintln!("wrote {}", p.display());
    }
    Ok(())
}
