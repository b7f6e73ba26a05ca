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
//! [`faults`] (fault injection, `[[faults]]`).
pub mod campaign;
pub mod closed_loop;
pub mod data;
pub mod faults;
pub mod manifest;
pub mod onboard;
pub mod outdir;
pub mod paper;
pub mod provenance;
pub mod run;
pub mod scenario;
pub mod sensors;
pub mod telemetry;
pub mod truth;

/// A bad input (scenario, table file, option): the CLI exits with code 2.
#[derive(Debug, thiserror::Error)]
#[error("{0:#}")]
pub struct InputError(pub anyhow::Error);

impl From<anyhow::Error> for InputError {
    fn from(e: anyhow::Error) -> Self {
        Self(e)
    }
}

impl InputError {
    /// An input error from a message.
    pub fn msg(m: impl std::fmt::Display) -> Self {
        Self(anyhow::anyhow!("{m}"))
    }
}

/// Exit code of every binary of the workspace (README "Exit codes", docs/reliability.md):
/// 0 success, 1 runtime failure, 2 bad or insufficient input.
pub mod exit {
    /// Success.
    pub const OK: u8 = 0;
    /// A runtime failure: I/O while writing, another writer busy, an internal error.
    pub const FAILURE: u8 = 1;
    /// Bad or insufficient input: the message names the file, field or option and the cause.
    pub const BAD_INPUT: u8 = 2;
}

/// The exit code for an error: [`exit::BAD_INPUT`] when it (or one of its causes) is an
/// [`InputError`], else [`exit::FAILURE`]. Chosen from the error's type, never its text.
#[must_use]
pub fn exit_code(e: &anyhow::Error) -> u8 {
    if is_input_error(e) {
        exit::BAD_INPUT
    } else {
        exit::FAILURE
    }
}

/// The error (or one of its causes) is an [`InputError`].
#[must_use]
pub fn is_input_error(e: &anyhow::Error) -> bool {
    e.downcast_ref::<InputError>().is_some()
        || e.chain().any(|c| c.downcast_ref::<InputError>().is_some())
}
