//! # Evaluation of `ground-tool diagnose` against the simulator's truth
//!
//! Moved out of the ground tool (issue 18: the ground does not carry the simulator):
//! [`scoring`] (the scorer against `truth.json`, plugged into `diagnose` through
//! `ground_tool::diagnose::scoring::Scorer`), [`synthetic`] (frames with known effects, the
//! FSS transfer function from the simulator's own model) and [`inject`] (effects outside the
//! library added to a real run folder, re-encoded with the simulator's packet writer).

pub mod inject;
pub mod scoring;
pub mod synthetic;
