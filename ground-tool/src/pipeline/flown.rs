//! # What the OBC flew during a run, and what the operator declares about it
//!
//! Why: the chain's corrections are relative to the tables the OBC actually used (the
//! adjustment keeps the OBC's own two-tracker frame), so calibrating a run that flew uploaded
//! tables against the boot tables would be wrong without any error. One rule for `calibrate`
//! and `diagnose`: `--tables DIR` if given, else the run's uploads that were activated and
//! accepted (`metadata.json` `uploads`, docs/icd.md §5), else the boot tables (`None` here).

use std::path::Path;

use fsw_core::tables::{AlignmentTable, FilterTable, IruTable, StarCatalogTable};

use super::calibrate::{decode_table_image, CalibrateOptions, Metadata};
use crate::run_check::InputError;
use gro_reference::run_folder::METADATA_FILE;

/// The effects every GRO analyst's model includes when `metadata.json` does not list
/// `declared_effects`: part of the file's contract, defined with it (one definition, which
/// the simulator declares by default too).
pub use gro_reference::run_folder::DEFAULT_DECLARED_EFFECTS;

/// `metadata.json` for the callers that need only its uploads and epoch before the chain's
/// own strict read (`read_run`): the defaults when it is absent or unreadable (the chain then
/// reports an unreadable file, naming the field).
#[must_use]
pub fn metadata_or_default(run_dir: &Path) -> Metadata {
    Metadata::read(run_dir).unwrap_or_default()
}

/// `metadata.json` read strictly and checked (`run_check::validate_metadata`), the defaults
/// when it is absent: what a command reads before it takes the flown tables from the file's
/// uploads, so that a malformed file or an unknown table name is refused for what it is, not
/// for the boot tables it would otherwise be read as.
///
/// # Errors
/// [`InputError`] naming the file, the field and the cause.
pub fn metadata_checked(run_dir: &Path) -> anyhow::Result<Metadata> {
    let meta = Metadata::read(run_dir)?;
    crate::run_check::validate_metadata(&run_dir.join(METADATA_FILE), &meta)?;
    Ok(meta)
}

/// The image files of the activated, accepted uploads of `table` ("alignment", "iru",
/// "filter", "star_catalog"), in upload order.
///
/// # Errors
/// [`InputError`] when a listed upload's file is missing: the flown table cannot be known
/// (reading it as "the boot table was flown" would calibrate against the wrong table).
fn activated_uploads(
    run_dir: &Path,
    meta: &Metadata,
    table: &str,
) -> Result<Vec<std::path::PathBuf>, InputError> {
    let mut out = Vec::new();
    for (i, u) in meta.uploads.iter().enumerate() {
        if !u.flown() || u.table != table {
            continue;
        }
        let (Some(f), Some(at_s)) = (&u.file, u.activated_at_s) else {
            continue;
        };
        let p = run_dir.join(f);
        if !p.is_file() {
            return Err(InputError::msg(format!(
                "{}: uploads[{i}] lists {} ({table} table, activated at t = {at_s:?} s) but the file is missing: the table the OBC flew cannot be known. Restore the file, or give the flown tables with --tables DIR",
                run_dir.join(METADATA_FILE).display(),
                p.display(),
            )));
        }
        out.push(p);
    }
    Ok(out)
}

/// The last flown image of `table` (its path and octets): the one `tables/manifest.json`
/// lists when `tables` is given (only that folder counts then), else the run's last activated
/// upload; `None` = the boot table.
fn flown_image(
    run_dir: &Path,
    meta: &Metadata,
    tables: Option<&Path>,
    table: &str,
) -> anyhow::Result<Option<(std::path::PathBuf, Vec<u8>)>> {
    match tables {
        Some(dir) => {
            let (listed, _) = gro_reference::manifest::read(dir)?;
            Ok(listed
                .into_iter()
                .rev()
                .find(|(_, t, _)| t == table)
                .map(|(p, _, bytes)| (p, bytes)))
        }
        None => activated_uploads(run_dir, meta, table)?
            .pop()
            .map(|p| {
                let bytes = std::fs::read(&p).map_err(|e| {
                    InputError(
                        anyhow::Error::new(e).context(format!("cannot read {}", p.display())),
                    )
                })?;
                Ok((p, bytes))
            })
            .transpose(),
    }
}

/// The last flown `table` ([`flown_image`]) decoded; `None` = the boot table.
fn flown<T: serde::de::DeserializeOwned + serde::Serialize>(
    run_dir: &Path,
    meta: &Metadata,
    tables: Option<&Path>,
    table: &str,
) -> anyhow::Result<Option<T>> {
    let Some((path, bytes)) = flown_image(run_dir, meta, tables, table)? else {
        return Ok(None);
    };
    let source = if tables.is_some() {
        format!("the flown {table} table, given with --tables")
    } else {
        format!("the flown {table} table: the last activated upload of metadata.json `uploads`; pass --tables DIR to use other tables")
    };
    decode_table_image(&bytes, &path)
        .map(Some)
        .map_err(|e| InputError(e.context(source)).into())
}

/// The tables the ground takes as flown that the housekeeping reports the CRC of (alignment,
/// IRU, filter, star catalog: docs/icd.md §3.2 octet 213), for the run check's cross-check
/// against the telemetry ([`crate::run_check::AssumedTable`]).
///
/// # Errors
/// As [`flown_tables`].
pub fn assumed_tables(
    run_dir: &Path,
    meta: &Metadata,
    tables: Option<&Path>,
) -> anyhow::Result<Vec<crate::run_check::AssumedTable>> {
    use fsw_core::tables::{TableId, TableSet};
    let boot = TableSet::boot();
    let mut out = Vec::new();
    for id in [
        TableId::Alignment,
        TableId::Iru,
        TableId::Filter,
        TableId::StarCatalog,
    ] {
        let mut image = flown_image(run_dir, meta, tables, id.name())?;
        if image.is_none() && id == TableId::StarCatalog && tables.is_some() {
            // As [`flown_catalog`]: a tables folder without a catalog leaves the run's own.
            image = flown_image(run_dir, meta, None, id.name())?;
        }
        let (image_crc, equals_boot, source) = match &image {
            None => (None, true, "the boot table".to_owned()),
            Some((path, bytes)) => {
                let equals_boot = match id {
                    TableId::Alignment => {
                        decode_table_image::<AlignmentTable>(bytes, path)? == *boot.alignment()
                    }
                    TableId::Iru => decode_table_image::<IruTable>(bytes, path)? == *boot.iru(),
                    TableId::Filter => {
                        decode_table_image::<FilterTable>(bytes, path)? == *boot.filter()
                    }
                    _ => decode_table_image::<StarCatalogTable>(bytes, path)? == *boot.catalog(),
                };
                let crc = bytes.last_chunk::<4>().map(|c| u32::from_be_bytes(*c));
                (crc, equals_boot, path.display().to_string())
            }
        };
        out.push(crate::run_check::AssumedTable {
            id,
            image_crc,
            equals_boot,
            source,
        });
    }
    Ok(out)
}

/// [`CalibrateOptions::default`] with the tables the run flew, as `ground-tool calibrate`
/// reads them: alignment, IRU and filter ([`flown_tables`]: an unreadable image is an error)
/// and the magnetics table ([`flown_magnetics`]: an unknown one is said in the report, not
/// fatal).
///
/// # Errors
/// As [`flown_tables`].
pub fn calibrate_options(
    run_dir: &Path,
    meta: &Metadata,
    tables: Option<&Path>,
) -> anyhow::Result<CalibrateOptions> {
    let (flown_alignment, flown_iru, flown_filter) = flown_tables(run_dir, meta, tables)?;
    Ok(CalibrateOptions {
        flown_alignment,
        flown_iru,
        flown_filter,
        flown_magnetics: flown_magnetics(run_dir, meta).map_err(|e| format!("{e:#}")),
        ..CalibrateOptions::default()
    })
}

/// Alignment, IRU and filter tables flown (`None` = boot).
///
/// # Errors
/// A table image that does not parse (the message names the file).
pub fn flown_tables(
    run_dir: &Path,
    meta: &Metadata,
    tables: Option<&Path>,
) -> anyhow::Result<(
    Option<AlignmentTable>,
    Option<IruTable>,
    Option<FilterTable>,
)> {
    Ok((
        flown(run_dir, meta, tables, "alignment")?,
        flown(run_dir, meta, tables, "iru")?,
        flown(run_dir, meta, tables, "filter")?,
    ))
}

/// The magnetics table (Table 6) flown: the run's last activated magnetics upload (`None`
/// when there is none: the OBC flew its boot table, no field model).
///
/// # Errors
/// As [`flown_tables`].
pub fn flown_magnetics(
    run_dir: &Path,
    meta: &Metadata,
) -> anyhow::Result<Option<fsw_core::tables::MagneticsTable>> {
    flown(run_dir, meta, None, "magnetics")
}

/// The onboard star catalog flown: the catalog `--tables DIR/manifest.json` lists, else the
/// run's last activated catalog upload (`None` when neither exists).
///
/// # Errors
/// As [`flown_tables`].
pub fn flown_catalog(
    run_dir: &Path,
    meta: &Metadata,
    tables: Option<&Path>,
) -> anyhow::Result<Option<StarCatalogTable>> {
    if let Some(dir) = tables {
        if let Some(c) = flown(run_dir, meta, Some(dir), "star_catalog")? {
            return Ok(Some(c));
        }
    }
    flown(run_dir, meta, None, "star_catalog")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::calibrate::filter_update;

    /// The chain proposes the onboard annual-aberration correction only when the operator's
    /// model includes aberration and the flown table leaves it off.
    #[test]
    fn filter_table_written_only_when_aberration_is_declared_and_off_on_board() {
        let boot = FilterTable::default_boot();
        assert!(!boot.aberration_correction);
        let gro = Metadata::default();
        let (new, why) = filter_update(&boot, &gro).unwrap_or((None, Vec::new()));
        assert!(new.is_some_and(|f| f.aberration_correction && f.validate().is_ok()));
        assert_eq!(why.len(), 1);
        let on = FilterTable {
            aberration_correction: true,
            ..boot
        };
        assert!(matches!(filter_update(&on, &gro), Ok((None, _))));
        let without: Metadata =
            serde_json::from_value(serde_json::json!({ "declared_effects": [] }))
                .unwrap_or_default();
        assert!(matches!(filter_update(&boot, &without), Ok((None, _))));
    }

    /// A run with an activated alignment upload: that table is the flown one; `--tables`
    /// overrides; a rejected or never-activated upload does not count.
    #[test]
    fn flown_tables_follow_the_activated_uploads() {
        let dir = std::env::temp_dir().join(format!("flown-tables-{}", std::process::id()));
        let _ = std::fs::create_dir_all(dir.join("uploads"));
        let mut moved = AlignmentTable::prelaunch();
        moved.m_acs_from_fss1[0][1] += 1e-4;
        let write = |name: &str, t: &AlignmentTable| {
            crate::pipeline::calibrate::write_table(
                &dir.join(name),
                fsw_core::tables::TableId::Alignment,
                t,
                0.0,
            )
        };
        assert!(write("uploads/01_alignment.tbl", &moved).is_ok());
        assert!(write("uploads/02_alignment.tbl", &AlignmentTable::prelaunch()).is_ok());
        let meta: Metadata = serde_json::from_value(serde_json::json!({ "uploads": [
            { "table": "alignment", "file": "uploads/01_alignment.tbl", "activated_at_s": 0.0, "accepted": true },
            { "table": "alignment", "file": "uploads/02_alignment.tbl", "activated_at_s": null, "accepted": true },
        ]}))
        .unwrap_or_default();
        assert_eq!(meta.uploads.len(), 2);
        let (a, i, f) = flown_tables(&dir, &meta, None).unwrap_or((None, None, None));
        assert_eq!(a, Some(moved));
        assert!(i.is_none() && f.is_none());
        let (a, _, _) =
            flown_tables(&dir, &Metadata::default(), None).unwrap_or((None, None, None));
        assert!(a.is_none(), "no uploads: the boot table");
        // --tables that does not exist: refused, not read as "the boot tables".
        let r = flown_tables(&dir, &meta, Some(&dir.join("none")));
        assert!(matches!(&r, Err(e) if gro_reference::is_input_error(e)));
        // --tables with a manifest that lists no alignment: only that folder counts.
        let _ = std::fs::create_dir_all(dir.join("t"));
        assert!(crate::pipeline::calibrate::write_table(
            &dir.join("t/iru.tbl"),
            fsw_core::tables::TableId::Iru,
            &IruTable::prelaunch(),
            0.0
        )
        .is_ok());
        assert!(
            gro_reference::manifest::write(&dir.join("t"), &["iru.tbl".into()], "test").is_ok()
        );
        let (a, i, _) =
            flown_tables(&dir, &meta, Some(&dir.join("t"))).unwrap_or((None, None, None));
        assert!(
            a.is_none() && i == Some(IruTable::prelaunch()),
            "--tables given: only that folder counts"
        );
        // An activated upload whose file is gone: refused, not "the boot table was flown".
        let _ = std::fs::remove_file(dir.join("uploads/01_alignment.tbl"));
        let r = flown_tables(&dir, &meta, None);
        assert!(matches!(&r, Err(e)
            if gro_reference::is_input_error(e) && format!("{e:#}").contains("missing")));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
