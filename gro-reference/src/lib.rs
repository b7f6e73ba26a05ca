//! # gro-reference: what the simulator and the ground share, and nothing else
//!
//! Why a crate of its own: `ground-tool` must not carry the simulator (a real ground system
//! does not, and code common to truth and ground hides its own errors), yet both sides need
//! the same reference physics and the same file contract. This crate holds exactly that:
//!
//! - reference physics, in J2000/ICRS axes (`eci`), km, km/s, rad: [`time`] (UTC/TAI/TT
//!   scales, the telemetry time code), [`sun`] (VSOP87 Earth, apparent Sun), [`sky`]
//!   (Hipparcos with proper motion, parallax, aberration, cone search), [`aberration`],
//!   [`field`] (IGRF synthesis, DGRF 1990/1995) and [`earth_orientation`] (GCRS ↔ ITRS);
//! - reference data: [`data`] (the `data/` CSV reader, the Hipparcos subset embedded once),
//!   [`paper`] (the paper's published facts, `data/gro_paper.toml`, parsed once);
//! - the run-folder contract: [`run_folder`] (`metadata.json` and the simulator's
//!   `truth.json`, with their JSON Schemas in `docs/schema/`), [`manifest`]
//!   (`tables/manifest.json`), [`outdir`] (whole-or-nothing output folders), [`exit`] (exit
//!   codes from the error's type).
//!
//! What may import it: `sim-harness` (which re-exports these modules under their old paths),
//! `ground-tool` and `tests`. It imports only `fsw-core` (units, time codes, table images).
//! `docs/architecture.md` has the picture.

pub mod aberration;
pub mod data;
pub mod earth_orientation;
pub mod exit;
pub mod field;
pub mod manifest;
pub mod outdir;
pub mod paper;
pub mod provenance;
pub mod run_folder;
pub mod sky;
pub mod splitmix;
pub mod sun;
pub mod time;
mod vsop87_earth;

pub use exit::{exit_code, is_input_error, InputError};
