//! # Table images as the simulated ground uplinks them
//!
//! The image encoding (fsw-core's format), the table id of an image, and the boot filter
//! table with a scenario's `filter_table` fields laid over it. Why a module of their own:
//! the scenario (its `filter_table` check), the fault model (damaged uploads), the closed
//! loop and the run all build or read images; here they depend on nothing of the harness,
//! so none of them imports the prelaunch products of `onboard` (which read the scenario).

use anyhow::Context;
use fsw_core::raw::TimeTag;
use fsw_core::tables::image::encode_image;
use fsw_core::tables::{FilterTable, TableId, MAX_CATALOG_STARS};

/// Room for the largest image (catalog: ≤ 4096 × 21 octets + header).
const IMAGE_CAPACITY: usize = 20 + 10 + MAX_CATALOG_STARS * 24 + 4;

/// The boot filter table with the scenario's `filter_table` fields laid over it, validated.
///
/// # Errors
/// An unknown field, a wrong type or a value `FilterTable::validate` refuses (named).
pub fn filter_table_with(overrides: &toml::Table) -> anyhow::Result<FilterTable> {
    let boot = FilterTable::default_boot();
    let mut value = toml::Table::try_from(boot).context("filter_table")?;
    for (k, v) in overrides {
        if !value.contains_key(k) {
            anyhow::bail!(
                "filter_table.{k}: unknown field (fields of FilterTable: {})",
                value.keys().cloned().collect::<Vec<_>>().join(", ")
            );
        }
        value.insert(k.clone(), v.clone());
    }
    let table: FilterTable = toml::Value::Table(value)
        .try_into()
        .map_err(|e| anyhow::anyhow!("filter_table: {e}"))?;
    table
        .validate()
        .map_err(|e| anyhow::anyhow!("filter_table: refused by FilterTable::validate: {e:?}"))?;
    Ok(table)
}

/// Encode a table as an uplink image (fsw-core's format).
///
/// # Errors
/// The table does not fit (cannot happen for the four table types).
pub fn image<T: serde::Serialize>(
    id: TableId,
    created: TimeTag,
    table: &T,
) -> anyhow::Result<Vec<u8>> {
    let mut buf = vec![0_u8; IMAGE_CAPACITY];
    let n = encode_image(id, created, table, &mut buf)
        .map_err(|e| anyhow::anyhow!("encoding the {} table image: {e:?}", id.name()))?;
    buf.truncate(n);
    Ok(buf)
}

/// The table id of an image (octet 4), if valid.
#[must_use]
pub fn image_table_id(image: &[u8]) -> Option<TableId> {
    image.get(4).copied().and_then(TableId::from_u8)
}
