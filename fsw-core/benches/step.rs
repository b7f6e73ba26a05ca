//! Criterion bench of `FlightCore::step` on the fixed synthetic scenario of
//! `examples/step_cost.rs` (inertial hold, two FHST stars, the Sun in FSS1).

// Host measurement tooling, not flight code: the flight-code lints are relaxed here.
#![allow(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::field_reassign_with_default,
    missing_docs
)]

include!("../examples/synthetic/mod.rs");

use criterion::{criterion_group, criterion_main, Criterion};

fn bench_step(c: &mut Criterion) {
    let scenario = synthetic::build(2_001);
    let mut core = synthetic::boot(&scenario);
    // Warm the filter into fine mode first.
    for f in &scenario.frames[1..1_001] {
        let _ = core.step(f, &[]);
    }
    let frames = &scenario.frames[1_001..];
    let mut i = 0usize;
    c.bench_function("FlightCore::step (fine mode, 2 FHST + FSS)", |b| {
        b.iter(|| {
            let f = &frames[i % frames.len()];
            i += 1;
            std::hint::black_box(core.step(std::hint::black_box(f), &[]))
        })
    });
}

criterion_group!(benches, bench_step);
criterion_main!(benches);
