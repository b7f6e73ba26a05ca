//! # sim-harness: the closed-loop simulator of the Compton GRO attitude emulation
//!
//! Design principles:
//! 1. One convention: attitudes, alignments and rotation vectors are [`fsw_core::attitude`]'s
//!    (`A = m_acs_from_eci`, `M_AS = m_acs_from_<sensor>`, paper `Rot(θ)`).
//! 2. Sensor models produce exactly [`fsw_core::raw::RawSensorFrame`]: counts and flags.
//! 3. Deterministic: every random draw comes from a seeded `ChaCha8Rng`, one stream per model;
//!    the same scenario and seed give a byte-identical `telemetry.bin`.
//! 4. The per-cycle path does not allocate.
//! 5. Every error parameter is a serde field with a default; undeclared effects default off.
//!
//! Modules: [`truth`] and [`sensors`] (phase 1), [`scenario`] (TOML), [`onboard`] (what the
//! ground uplinks at t = 0), [`closed_loop`] (truth → FlightCore → wheels), [`telemetry`]
//! (CCSDS packets), [`run`] (run folder, scores, bench), [`campaign`] (Monte Carlo, merge),
//! [`faults`] (fault injection, `[[faults]]`), [`magnetics`] (field, TAMs and CSSs sampled into
//! the record).
/// The reference data reader, the tables manifest and the output folders are shared with the
/// ground (`gro-reference`), re-exported under their old paths.
pub use gro_reference::{data, manifest, outdir};
pub mod campaign;
pub mod closed_loop;
pub mod faults;
pub mod magnetics;
pub mod onboard;
pub mod paper;
pub mod provenance;
pub mod run;
pub mod scenario;
pub mod sensors;
pub mod telemetry;
pub mod truth;
pub mod uplink;

/// Exit codes and the bad-input error, one definition for every binary of the workspace
/// (`gro_reference::exit`).
pub use gro_reference::exit;
pub use gro_reference::{exit_code, is_input_error, InputError};
