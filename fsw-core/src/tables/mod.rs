//! # Uplinkable tables (paper: calibrated alignments uplinked to the OBC on 1991-05-14)
//!
//! [`image`] is the binary format, [`types`] the five tables and their validation,
//! [`error`] the table ids and the reasons a table or an image is refused,
//! [`manager`] the load/validate/activate services. Byte layout: `docs/tables.md`.

pub mod error;
pub mod image;
pub mod magnetics;
pub mod manager;
pub mod types;

pub use error::{TableError, TableId};
pub use magnetics::MagneticsTable;
pub use manager::{TableSet, TableStatus};
pub use types::{
    AlignmentTable, CatalogStar, FilterTable, IruTable, OrbitTable, SensorCorrections,
    StarCatalogTable, MAX_CATALOG_STARS,
};
