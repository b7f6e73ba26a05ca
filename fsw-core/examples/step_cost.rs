//! Instructions per cycle of `FlightCore::step`: runs a fixed synthetic scenario (gyro
//! propagation, two FHST star updates and the FSS processing each cycle) for a fixed number
//! of cycles and prints that number last, so that
//!
//! ```sh
//! cargo build --release -p fsw-core --example step_cost
//! valgrind --tool=callgrind --callgrind-out-file=/tmp/cg.out target/release/examples/step_cost 20000
//! ```
//!
//! gives instructions per cycle as (total of `run_cycles`) / cycles; `docs/performance.md`
//! takes the difference of two runs (N and 2N cycles) so set-up cost cancels.

// Host measurement tooling, not flight code: the flight-code lints are relaxed here.
#![allow(
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::field_reassign_with_default,
    missing_docs
)]

include!("synthetic/mod.rs");

use fsw_core::executive::FlightCore;
use fsw_core::raw::RawSensorFrame;

#[inline(never)]
fn run_cycles(core: &mut FlightCore, frames: &[RawSensorFrame]) -> u32 {
    let mut accepted = 0;
    for f in frames {
        let out = core.step(f, &[]);
        accepted = out.housekeeping.counters.accepted_measurements;
    }
    accepted
}

fn main() {
    let cycles: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(10_000);
    let scenario = synthetic::build(cycles + 1);
    let mut core = synthetic::boot(&scenario);
    let accepted = run_cycles(&mut core, &scenario.frames[1..]);
    eprintln!(
        "filter mode {:?}, measurements accepted {accepted}, size_of::<FlightCore>() = {} B",
        core.filter_mode(),
        std::mem::size_of::<FlightCore>()
    );
    println!("{cycles}");
}
