//! # ground-tool: the flight-dynamics side of the emulated Compton GRO
//!
//! The ground system computes what the onboard computer (OBC, emulated by `fsw-core`) cannot:
//! sensor alignments and gyro calibration from downlinked data, and the tables that carry
//! them back up. This crate follows the 1991 in-flight calibration of CGRO (Davis et al.,
//! `data/gro_paper.toml`) and the algorithm notes in `docs/algorithms.md` (shared docs).
//!
//! Design principles:
//! 1. **One attitude convention**: everything uses `fsw_core::attitude` (`A = m_acs_from_eci`,
//!    `M_AS = m_acs_from_<sensor>`, the paper's `Rot(θ) = exp(−[θ×])`, left body-frame error
//!    states `A_true = Rot(δθ) Â`). No second convention is written here.
//! 2. **Radians inside, arcsec / ppm at the normal equations and at I/O**, with the unit in
//!    every name.
//! 3. **Streaming normal equations**: calibration batches accumulate `HᵀWH` epoch by epoch and
//!    never build a stacked `H`.
//! 4. **No silent wrong answers**: an unobservable or under-determined problem is an error that
//!    says what is missing, never a number.
//!
//! Module map:
//! - [`attitude::quest`]: optimal attitude from weighted vector pairs (SVD solution of
//!   Wahba's problem) with the QUEST covariance.
//! - [`calibration::alignment`]: FFCAL, Shuster's attitude-independent alignment estimation
//!   (1982 scalar weights with sandwich covariance, or the 1990 optimal weights), plus the
//!   Cramér–Rao bound of the same data.
//! - [`calibration::adjust`]: the paper's appendix adjustment that keeps the OBC's
//!   two-tracker attitude unchanged.
//! - [`calibration::iru`]: IRUCAL, the Davenport/Keat 12-parameter gyro calibration, bias from
//!   inertial holds, and the covariance study of a maneuver plan.
//! - [`paper`]: reproduction of the paper's tables and numbers (`ground-tool paper`).
//! - [`tp`]: TP, telemetry processing of `telemetry.bin` (`docs/icd.md`), robust to damage.
//! - [`bench`]: FFCAL throughput check (`ground-tool bench`).
//! - [`table`]: uplink table images (inspect, diff, write) in `fsw_core::tables` format.
//! - [`synth`]: deterministic synthetic data (tests, benchmarks).
//! - [`report`]: `report.md` and the PNG plots of a calibration; [`progress`]: the long
//!   steps named on stderr.

pub mod attitude;
pub mod bench;
pub mod calibration;
pub mod diagnose;
pub mod icd_export;
pub mod linalg;
pub mod paper;
pub mod pipeline;
pub mod progress;
pub mod report;
pub mod run_check;
pub mod synth;
pub mod table;
pub mod tp;

pub use fsw_core::units::{ARCSEC_PER_RAD, DEG_PER_RAD, RAD_PER_ARCSEC, RAD_PER_DEG};
