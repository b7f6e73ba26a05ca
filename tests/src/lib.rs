//! End-to-end support: the calibration loop's before/after scoring ([`loop_report`]), used by
//! the `calibration-loop` binary and by the tests in `tests/tests/`.

pub mod loop_report;
