//! # What the OBC flew during a run, and what the operator declares about it
//!
//! Why: the chain's corrections are relative to the tables the OBC actually used (the
//! adjustment keeps the OBC's own two-tracker frame), so calibrating a run that flew uploaded
//! tables against the boot tables would be wrong without any error. One rule for `calibrate`
//! and `diagnose`: `--tables DIR` if given, else the run's uploads that were activated and
//! accepted (`metadata.json` `uploads`, docs/icd.md §5), else the boot tables (`None` here).

use std::path::Path;

use fsw_core::tables::{AlignmentTable, FilterTable, IruTable, StarCatalogTable};

use super::calibrate::{decode_table_image, read_table_image};
use crate::run_check::InputError;

/// The effects every GRO analyst's model includes when `metadata.json` does not list
/// `declared_effects`: the list `sim-harness` declares by default (one definition).
pub use sim_harness::scenario::DEFAULT_DECLARED_EFFECTS;

/// `metadata.json` as JSON (`Null` when absent or unreadable: every field has a default).
#[must_use]
pub fn metadata_json(run_dir: &Path) -> serde_json::Value {
    std::fs::read_to_string(run_dir.join("metadata.json"))
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or(serde_json::Value::Null)
}

/// The image files of the activated, accepted uploads of `table` ("alignment", "iru",
/// "filter", "star_catalog"), in upload order.
///
/// # Errors
/// [`InputError`] when a listed upload's file is missing: the flown table cannot be known
/// (reading it as "the boot table was flown" would calibrate against the wrong table).
fn activated_uploads(
    run_dir: &Path,
    meta: &serde_json::Value,
    table: &str,
) -> Result<Vec<std::path::PathBuf>, InputError> {
    let mut out = Vec::new();
    for (i, u) in meta["uploads"].as_array().into_iter().flatten().enumerate() {
        if u["activated_at_s"].is_null()
            || u["accepted"].as_bool() == Some(false)
            || u["table"].as_str() != Some(table)
        {
            continue;
        }
        let Some(f) = u["file"].as_str() else {
            continue;
        };
        let p = run_dir.join(f);
        if !p.is_file() {
            return Err(InputError::msg(format!(
                "{}: uploads[{i}] lists {} ({table} table, activated at t = {} s) but the file is missing: the table the OBC flew cannot be known. Restore the file, or give the flown tables with --tables DIR",
                run_dir.join("metadata.json").display(),
                p.display(),
                u["activated_at_s"]
            )));
        }
        out.push(p);
    }
    Ok(out)
}

/// The last flown image of `table`: the one `tables/manifest.json` lists when `tables` is
/// given (only that folder counts then), else the run's last activated upload; `None` = the
/// boot table.
fn flown<T: serde::de::DeserializeOwned + serde::Serialize>(
    run_dir: &Path,
    meta: &serde_json::Value,
    tables: Option<&Path>,
    table: &str,
) -> anyhow::Result<Option<T>> {
    match tables {
        Some(dir) => {
            let (listed, _) = sim_harness::manifest::read(dir)?;
            listed
                .iter()
                .rev()
                .find(|(_, t, _)| t == table)
                .map(|(p, _, bytes)| {
                    decode_table_image(bytes, p).map_err(|e| {
                        InputError(e.context(format!("the flown {table} table, given with --tables")))
                    })
                })
                .transpose()
                .map_err(Into::into)
        }
        None => activated_uploads(run_dir, meta, table)?
            .last()
            .map(|p| {
                read_table_image(p).map_err(|e| {
                    InputError(e.context(format!(
                        "the flown {table} table: the last activated upload of metadata.json `uploads`; pass --tables DIR to use other tables"
                    )))
                })
            })
            .transpose()
            .map_err(Into::into),
    }
}

/// Alignment, IRU and filter tables flown (`None` = boot).
///
/// # Errors
/// A table image that does not parse (the message names the file).
pub fn flown_tables(
    run_dir: &Path,
    meta: &serde_json::Value,
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

/// The onboard star catalog flown: the catalog `--tables DIR/manifest.json` lists, else the
/// run's last activated catalog upload (`None` when neither exists).
///
/// # Errors
/// As [`flown_tables`].
pub fn flown_catalog(
    run_dir: &Path,
    meta: &serde_json::Value,
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
    use crate::pipeline::calibrate::{filter_update, Metadata};

    #[test]
    fn absent_declared_effects_are_the_gro_defaults_an_empty_list_is_none() {
        let meta =
            |v: serde_json::Value| -> Metadata { serde_json::from_value(v).unwrap_or_default() };
        let absent = meta(serde_json::json!({})).declared();
        assert_eq!(absent, DEFAULT_DECLARED_EFFECTS.map(str::to_owned).to_vec());
        let empty = meta(serde_json::json!({ "declared_effects": [] })).declared();
        assert!(empty.is_empty());
        let m: Metadata = serde_json::from_value(serde_json::json!({})).unwrap_or_default();
        assert!(m.declares("aberration"));
        let m: Metadata =
            serde_json::from_value(serde_json::json!({ "declared_effects": ["sun_parallax"] }))
                .unwrap_or_default();
        assert!(!m.declares("aberration") && m.declares("sun_parallax"));
    }

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
        let meta = serde_json::json!({ "uploads": [
            { "table": "alignment", "file": "uploads/01_alignment.tbl", "activated_at_s": 0.0, "accepted": true },
            { "table": "alignment", "file": "uploads/02_alignment.tbl", "activated_at_s": null, "accepted": true },
        ]});
        let (a, i, f) = flown_tables(&dir, &meta, None).unwrap_or((None, None, None));
        assert_eq!(a, Some(moved));
        assert!(i.is_none() && f.is_none());
        let (a, _, _) =
            flown_tables(&dir, &serde_json::json!({}), None).unwrap_or((None, None, None));
        assert!(a.is_none(), "no uploads: the boot table");
        // --tables that does not exist: refused, not read as "the boot tables".
        let r = flown_tables(&dir, &meta, Some(&dir.join("none")));
        assert!(matches!(&r, Err(e) if sim_harness::is_input_error(e)));
        // --tables with a manifest that lists no alignment: only that folder counts.
        let _ = std::fs::create_dir_all(dir.join("t"));
        assert!(crate::pipeline::calibrate::write_table(
            &dir.join("t/iru.tbl"),
            fsw_core::tables::TableId::Iru,
            &IruTable::prelaunch(),
            0.0
        )
        .is_ok());
        assert!(sim_harness::manifest::write(&dir.join("t"), &["iru.tbl".into()], "test").is_ok());
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
            if sim_harness::is_input_error(e) && format!("{e:#}").contains("missing")));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
