//! # fsw-core: the Compton GRO onboard attitude software, as a `no_std` Rust core
//!
//! See `docs/conventions.md` and [`attitude`] for the one attitude convention of the workspace.
#![no_std]
#![cfg_attr(
    test,
    allow(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::indexing_slicing,
        clippy::arithmetic_side_effects
    )
)]

pub mod attitude;
pub mod control;
pub mod events;
pub mod executive;
pub mod fhst;
pub mod fss;
pub mod iru;
pub mod mekf;
pub mod raw;
pub mod star_id;
pub mod sun_ephemeris;
pub mod tables;
pub mod telemetry;
pub mod units;
