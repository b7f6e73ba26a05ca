//! The flight core's estimation and control tests, one test binary (one link instead of six):
//! attitude control on a rigid body (`control`), the DRIRU II pulse integration (`iru`), MEKF
//! robustness (`mekf_robust`), the estimation work of one cycle (`perf`), star identification
//! against Hipparcos (`star_id`) and the onboard Sun ephemeris against DE421 (`sun`). Run one
//! with `cargo test -p fsw-core --test est sun::`. The filter tests on synthetic data stay
//! their own binaries (`est_filter`, `est_filter_mismatched`), with the shared helpers of
//! `est_support`.

#[path = "../est_support/mod.rs"]
mod est_support;

mod control;
mod iru;
mod mekf_robust;
mod perf;
mod star_id;
mod sun;
