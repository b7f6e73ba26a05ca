//! # sim-harness: truth and sensor models for the Compton GRO attitude emulation
//!
//! Design principles:
//! 1. One convention: attitudes, alignments and rotation vectors are [`fsw_core::attitude`]'s
//!    (`A = m_acs_from_eci`, `M_AS = m_acs_from_<sensor>`, paper `Rot(θ)`).
//! 2. Sensor models produce exactly [`fsw_core::raw::RawSensorFrame`]: counts and flags.
//! 3. Deterministic: every random draw comes from a seeded `ChaCha8Rng`, one stream per model.
//! 4. The per-cycle path does not allocate.
//! 5. Every error parameter is a serde field with a default; undeclared effects default off.
/// The closed-loop driver needs `fsw_core::executive` (`FlightCore`), which is written but
/// not yet exported by fsw-core; build it with `--features closed-loop` once it is.
#[cfg(feature = "closed-loop")]
pub mod closed_loop;
pub mod data;
pub mod paper;
pub mod scenario;
pub mod sensors;
pub mod truth;
