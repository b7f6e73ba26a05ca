//! In-flight calibration (paper §4 alignment, §5 IRU; `docs/algorithms.md` §6–§8, §10).
//!
//! - [`alignment`]: FFCAL, relative sensor alignments from attitude-independent dot products.
//! - [`fhst_relative`]: FHST2 relative to FHST1 from every star, batch attitudes tied by the
//!   gyro and eliminated (the FFCAL FHST stage).
//! - [`allan`]: gyro noise (ARW, bias instability, RRW) by Allan deviation of inertial holds.
//! - [`adjust`]: the appendix adjustment that preserves the OBC's FHST attitude.
//! - [`iru`]: IRUCAL, gyro misalignment/scale and bias; bias from inertial holds; plan study.
//! - [`iru_chain`]: IRUCAL over a whole timeline (calibration filter + RTS smoother, bias as a
//!   random walk, held-out validation).

pub mod adjust;
pub mod alignment;
pub mod allan;
pub mod fhst_relative;
pub mod iru;
pub mod iru_chain;
