//! Attitude determination on the ground.
//!
//! Only the single-frame optimal attitude lives here for now ([`quest`]); the convention is
//! `fsw_core::attitude` throughout.

pub mod quest;
