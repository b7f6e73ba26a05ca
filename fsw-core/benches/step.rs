//! Criterion bench of `FlightCore::step` (filled in with the synthetic scenario of
//! `examples/step_cost.rs`).
fn main() {}
