//! End-to-end support: the calibration loop's before/after scoring ([`loop_report`]), used by
//! the `calibration-loop` binary and by the tests in `tests/tests/`; the calibration Monte
//! Carlo's shards, merge and summary ([`mc_campaign`]); the evaluation of `ground-tool
//! diagnose` against the simulator's truth ([`diagnose`]: scoring, synthetic frames,
//! injected effects), which the ground tool must not carry; the workspace's structure rules
//! ([`structure`]: function length, import cycles) checked by `structure-check`.

pub mod diagnose;
pub mod loop_report;
pub mod mc_campaign;
pub mod structure;
