//! # The tables to fly are named: `tables/manifest.json`
//!
//! Why (issue 17): `--tables DIR` loaded every `*.tbl` of the folder, so a stale image left by
//! an earlier run (a `filter.tbl` the new calibration did not propose) was uplinked too. A
//! tables folder written by `ground-tool calibrate` or `diagnose` now holds a manifest that
//! lists exactly the images the report lists, each with its table id, length and CRC-32 of
//! the whole file; a loader takes the manifest, not the folder listing:
//!
//! ```json
//! { "format": "gro-tables-manifest-1", "written_by": "ground-tool calibrate",
//!   "tables": [ { "file": "alignment.tbl", "table": "alignment", "table_id": 1,
//!                 "octets": 760, "crc32": "0x1c291ca3" } ] }
//! ```
//!
//! A listed file that is missing, of another length or CRC, or whose header names another
//! table, is refused ([`InputError`], exit code 2); a folder without a manifest is refused
//! with the way to proceed (`ground-tool table manifest DIR` writes one for hand-made
//! folders, after the operator has checked what is in them). Images in the folder that the
//! manifest does not list are not loaded (a warning names them).

use std::path::{Path, PathBuf};

use anyhow::Context;
use fsw_core::tables::image::{parse_image, IMAGE_CRC};
use serde::{Deserialize, Serialize};

use crate::InputError;

/// File name of the manifest inside a tables folder.
pub const MANIFEST: &str = "manifest.json";

/// Value of the manifest's `format` key.
pub const FORMAT: &str = "gro-tables-manifest-1";

/// One listed image.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Entry {
    /// File name inside the tables folder.
    pub file: String,
    /// Table name (`alignment`, `iru`, `filter`, `star_catalog`).
    pub table: String,
    /// Table id of the image header (docs/tables.md).
    pub table_id: u8,
    /// Length of the file, octets.
    pub octets: usize,
    /// CRC-32 (ISO-HDLC, the image's own polynomial) of the whole file, `0x%08x`.
    pub crc32: String,
}

/// `manifest.json`.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Manifest {
    /// [`FORMAT`].
    pub format: String,
    /// The command that wrote the folder.
    pub written_by: String,
    /// The images to fly, in load order.
    pub tables: Vec<Entry>,
}

fn crc_text(bytes: &[u8]) -> String {
    format!("0x{:08x}", IMAGE_CRC.checksum(bytes))
}

/// The entry of one image file (its header must parse: CRC and length checked).
///
/// # Errors
/// Unreadable file or an image that does not parse (naming the file and the cause).
pub fn entry_of(path: &Path) -> anyhow::Result<Entry> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let (header, _) = parse_image(&bytes).map_err(|e| {
        InputError::msg(format!(
            "{} is not a valid table image: {e}",
            path.display()
        ))
    })?;
    Ok(Entry {
        file: path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
        table: header.table_id.name().to_owned(),
        table_id: header.table_id as u8,
        octets: bytes.len(),
        crc32: crc_text(&bytes),
    })
}

fn tbl_files(dir: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot read {}", dir.display()))?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.is_file() && p.extension().is_some_and(|e| e == "tbl"))
        .collect();
    files.sort();
    Ok(files)
}

/// Write `dir/manifest.json` listing `files` (names inside `dir`, in load order).
///
/// # Errors
/// A file that is not a valid image; I/O.
pub fn write(dir: &Path, files: &[String], written_by: &str) -> anyhow::Result<Manifest> {
    let tables = files
        .iter()
        .map(|f| entry_of(&dir.join(f)))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let m = Manifest {
        format: FORMAT.to_owned(),
        written_by: written_by.to_owned(),
        tables,
    };
    let path = dir.join(MANIFEST);
    std::fs::write(&path, serde_json::to_string_pretty(&m)? + "\n")
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(m)
}

/// Write `dir/manifest.json` listing every `*.tbl` of `dir` (file-name order): for a folder
/// just written by one command (nothing else in it), or one the operator has checked.
///
/// # Errors
/// No image in the folder, an invalid image, I/O.
pub fn write_for_all(dir: &Path, written_by: &str) -> anyhow::Result<Manifest> {
    let files: Vec<String> = tbl_files(dir)?
        .iter()
        .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect();
    if files.is_empty() {
        return Err(InputError::msg(format!("{}: no *.tbl table images", dir.display())).into());
    }
    write(dir, &files, written_by)
}

/// The images a tables folder's manifest lists, checked: `(path, table name, image)` in load
/// order. Also returns the `*.tbl` files of the folder the manifest does not list.
///
/// # Errors
/// [`InputError`] (exit code 2): the folder does not exist, has no manifest, the manifest is
/// malformed, a listed file is missing or differs from its entry.
pub fn read(dir: &Path) -> anyhow::Result<(Vec<(PathBuf, String, Vec<u8>)>, Vec<PathBuf>)> {
    if !dir.is_dir() {
        return Err(InputError::msg(format!(
            "--tables {}: no such folder (give the tables/ folder written by `ground-tool calibrate` or `diagnose`)",
            dir.display()
        ))
        .into());
    }
    let path = dir.join(MANIFEST);
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(InputError::msg(format!(
                "--tables {}: no {MANIFEST} naming the tables to fly (docs/tables.md, \"Tables folders\"). `ground-tool calibrate` and `diagnose` write one; for a folder made by hand, check that it holds exactly the images to fly and run `ground-tool table manifest {}`",
                dir.display(),
                dir.display()
            ))
            .into())
        }
        Err(e) => {
            return Err(InputError(
                anyhow::Error::new(e).context(format!("cannot read {}", path.display())),
            )
            .into())
        }
    };
    let m: Manifest = serde_json::from_str(&text).map_err(|e| {
        InputError::msg(format!(
            "{} is not a tables manifest ({e}; docs/tables.md, \"Tables folders\")",
            path.display()
        ))
    })?;
    if m.format != FORMAT {
        return Err(InputError::msg(format!(
            "{}: format {:?}, expected {FORMAT:?}",
            path.display(),
            m.format
        ))
        .into());
    }
    let mut out = Vec::new();
    for e in &m.tables {
        if e.file.contains('/') || e.file.contains('\\') || e.file.starts_with('.') {
            return Err(InputError::msg(format!(
                "{}: file {:?} is not a plain file name inside the folder",
                path.display(),
                e.file
            ))
            .into());
        }
        let f = dir.join(&e.file);
        let bytes = std::fs::read(&f).map_err(|err| {
            InputError::msg(format!(
                "{} lists {} ({} table) but it cannot be read ({err}): the folder is incomplete; write it again with the command that made it",
                path.display(),
                f.display(),
                e.table
            ))
        })?;
        let crc = crc_text(&bytes);
        if bytes.len() != e.octets || crc != e.crc32 {
            return Err(InputError::msg(format!(
                "{} is not the image {} lists ({} octets, CRC-32 {} in the file; {} octets, CRC-32 {} in the manifest): it was changed or replaced after the manifest was written",
                f.display(),
                path.display(),
                bytes.len(),
                crc,
                e.octets,
                e.crc32
            ))
            .into());
        }
        let (header, _) = parse_image(&bytes).map_err(|err| {
            InputError::msg(format!("{} is not a valid table image: {err}", f.display()))
        })?;
        if header.table_id.name() != e.table {
            return Err(InputError::msg(format!(
                "{} holds a {} table but {} lists it as {}",
                f.display(),
                header.table_id.name(),
                path.display(),
                e.table
            ))
            .into());
        }
        out.push((f, e.table.clone(), bytes));
    }
    let listed: Vec<&str> = m.tables.iter().map(|e| e.file.as_str()).collect();
    let unlisted = tbl_files(dir)?
        .into_iter()
        .filter(|p| {
            p.file_name()
                .is_some_and(|n| !listed.contains(&n.to_string_lossy().as_ref()))
        })
        .collect();
    Ok((out, unlisted))
}

#[cfg(test)]
mod tests {
    use super::*;
    use fsw_core::tables::{AlignmentTable, FilterTable, TableId};

    fn image<T: Serialize>(id: TableId, t: &T) -> Vec<u8> {
        let mut buf = vec![0u8; 4096];
        let n =
            fsw_core::tables::image::encode_image(id, Default::default(), t, &mut buf).unwrap_or(0);
        buf.truncate(n);
        buf
    }

    #[test]
    fn loaders_take_the_manifest_not_the_folder() {
        let dir = std::env::temp_dir().join(format!("manifest-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        // No manifest: refused with the way to proceed.
        let e = read(&dir).unwrap_err();
        assert!(crate::is_input_error(&e) && format!("{e:#}").contains("table manifest"));
        // No folder: refused.
        assert!(crate::is_input_error(&read(&dir.join("nope")).unwrap_err()));
        let align = image(TableId::Alignment, &AlignmentTable::prelaunch());
        std::fs::write(dir.join("alignment.tbl"), &align).unwrap();
        write(&dir, &["alignment.tbl".into()], "test").unwrap();
        // A stale image beside the listed one is not loaded.
        std::fs::write(
            dir.join("filter.tbl"),
            image(TableId::Filter, &FilterTable::default_boot()),
        )
        .unwrap();
        let (tables, unlisted) = read(&dir).unwrap();
        assert_eq!(tables.len(), 1);
        assert_eq!(tables[0].1, "alignment");
        assert_eq!(unlisted, vec![dir.join("filter.tbl")]);
        // A listed image replaced: refused.
        let mut other = align.clone();
        if let Some(x) = other.get_mut(30) {
            *x ^= 1;
        }
        std::fs::write(dir.join("alignment.tbl"), &other).unwrap();
        let e = read(&dir).unwrap_err();
        assert!(format!("{e:#}").contains("CRC-32"), "{e:#}");
        // A listed image missing: refused.
        std::fs::remove_file(dir.join("alignment.tbl")).unwrap();
        let e = read(&dir).unwrap_err();
        assert!(format!("{e:#}").contains("incomplete"), "{e:#}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
