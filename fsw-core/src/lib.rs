//! # fsw-core: the Compton GRO onboard attitude software, as a `no_std` Rust core
//!
//! See `docs/conventions.md` and [`attitude`] for the one attitude convention of the workspace.
//!
//! ## Where things come from
//!
//! Every public item cites its source (checked by `fsw-core/tests/doc_citations.rs`):
//! * **Paper**: Davis, Eudell, Kulp, Lindrose and Harman, "The Results of the In-Flight
//!   Attitude Sensor Calibration for the Arthur Holly Compton Gamma Ray Observatory"; its
//!   figures are transcribed in `data/gro_paper.toml`. Cited by table (Table 1
//!   prelaunch `M_AS`, Table 2 `M_SS''`, Table 3 adjusted `M_AS''`) or by the quantity's name
//!   ("Paper: FHST resolution 7.78″/count"), not by equation or section numbers, which that
//!   transcription does not give.
//! * **algorithms.md §n**: `docs/algorithms.md`, with its literature (Lefferts,
//!   Markley & Shuster 1982 MEKF; Farrenkopf 1978; Shuster 1982/1990 alignment; Davenport /
//!   Keat IRU calibration).
//! * **`docs/icd.md`, `docs/tables.md`, `docs/conventions.md`**: this repository's interface
//!   documents (CCSDS 133.0-B-2 packets, CCSDS 301.0-B-4 CUC time codes).
//! * **Project choice (not in the paper)**, with the reason, where neither applies.
#![no_std]
#![deny(missing_docs)]
// Flight code: no unwrap, expect, panic, indexing or unchecked arithmetic (the unit tests of
// `cfg(test)` are exempt; the crate's other targets are host tooling, see Cargo.toml).
#![cfg_attr(
    not(test),
    deny(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic,
        clippy::indexing_slicing,
        clippy::arithmetic_side_effects
    )
)]

pub mod attitude;
pub mod coarse;
pub mod control;
pub mod events;
pub mod executive;
pub mod fhst;
pub mod field_model;
pub mod fss;
pub mod iru;
pub mod mekf;
pub mod orbit;
pub mod raw;
pub mod sensor;
pub mod star_id;
pub mod sun_acquisition;
pub mod sun_ephemeris;
pub mod tables;
pub mod telemetry;
pub mod tm_layout;
pub mod units;
pub mod unloading;
