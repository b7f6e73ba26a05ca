//! # Uplinkable tables (paper §3.3: alignments and IRU calibration uplinked to the OBC)
//!
//! [`image`] is the binary format, [`types`] the four tables and their validation,
//! [`manager`] the load/validate/activate services.

pub mod image;
pub mod manager;
pub mod types;

pub use image::{TableError, TableId};
pub use manager::{TableSet, TableStatus};
pub use types::{
    AlignmentTable, CatalogStar, FilterTable, IruTable, SensorCorrections, StarCatalogTable,
    MAX_CATALOG_STARS,
};
