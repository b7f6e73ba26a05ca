//! # Uplinkable tables (paper: calibrated alignments uplinked to the OBC on 1991-05-14)
//!
//! [`image`] is the binary format, [`types`] the five tables and their validation,
//! [`manager`] the load/validate/activate services. Byte layout: `docs/tables.md`.

pub mod image;
pub mod manager;
pub mod types;

pub use image::{TableError, TableId};
pub use manager::{TableSet, TableStatus};
pub use types::{
    AlignmentTable, CatalogStar, FilterTable, IruTable, OrbitTable, SensorCorrections,
    StarCatalogTable, MAX_CATALOG_STARS,
};
