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
//! takes the difference of two runs (N and 2N cycles) so set-up cost cancels. With
//! `STEP_COST_HOOKS=1` the alignment and IRU tables carry every sensor correction (distortion,
//! magnitude bias, thermal drift on all four sensors, the FSS transfer function with its cubic
//! and cyclic terms, gyro scale asymmetry; small values), activated before the measured cycles.
//! With `STEP_COST_ORBIT=1` an orbit table (GRO's orbit, epoch at the first frame) and the
//! filter table with `orbital_aberration_correction` on are activated first: every cycle then
//! propagates the onboard orbit and applies the orbital aberration (issue 19).
//! With `STEP_COST_COARSE=1` the orbit table (aberration correction on, as above), a magnetics
//! table with a full degree-10 field model and TAM words consistent with it (the truth
//! attitude, the field at the orbit's position) and wheel tachometer words are added: the
//! coarse attitude is carried every cycle and fixed every 10th, and the unloading reads the
//! wheel momentum from the tachometers (issue 20).

// Host measurement tooling, not flight code: the flight-code lints are relaxed here.
#![allow(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::field_reassign_with_default,
    missing_docs
)]

include!("synthetic/mod.rs");

use fsw_core::executive::{Command, CycleOutput, FlightCore};
use fsw_core::raw::{RawSensorFrame, TimeTag};
use fsw_core::tables::image::encode_image;
use fsw_core::tables::TableId;

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
    let mut scenario = synthetic::build(cycles + 2);
    let coarse = std::env::var_os("STEP_COST_COARSE").is_some_and(|v| !v.is_empty());
    if coarse {
        add_tam_words(&mut scenario);
    }
    let mut core = synthetic::boot(&scenario);
    if coarse || std::env::var_os("STEP_COST_ORBIT").is_some_and(|v| !v.is_empty()) {
        activate_orbit(&mut core, &scenario.frames[0]);
    }
    if coarse {
        let table = magnetics_table(&scenario.frames[0]);
        let out = load_and_activate(
            &mut core,
            &scenario.frames[0],
            &[image(TableId::Magnetics, &table)],
        );
        assert_eq!(core.tables().magnetics(), &table, "{:?}", out.events);
    }
    if std::env::var_os("STEP_COST_HOOKS").is_some_and(|v| !v.is_empty()) {
        activate_hooks(&mut core, &scenario.frames[1]);
    } else {
        let _ = core.step(&scenario.frames[1], &[]);
    }
    let accepted = run_cycles(&mut core, &scenario.frames[2..]);
    eprintln!(
        "filter mode {:?}, measurements accepted {accepted}, size_of::<FlightCore>() = {} B, \
         coarse fixes {} (last refusal {:?})",
        core.filter_mode(),
        std::mem::size_of::<FlightCore>(),
        core.coarse().fixes,
        core.coarse().last_unavailable
    );
    println!("{cycles}");
}

/// The table `id` and the image of `t` (a default time tag).
fn image<T: serde::Serialize>(id: TableId, t: &T) -> (TableId, Vec<u8>) {
    let mut buf = vec![0u8; 8192];
    let n = encode_image(id, TimeTag::default(), t, &mut buf).expect("fits");
    buf.truncate(n);
    (id, buf)
}

/// One cycle at `frame` that loads and activates each image of `images` in turn.
fn load_and_activate(
    core: &mut FlightCore,
    frame: &RawSensorFrame,
    images: &[(TableId, Vec<u8>)],
) -> CycleOutput {
    let commands: Vec<Command<'_>> = images
        .iter()
        .flat_map(|(id, image)| [Command::TableLoad(image), Command::TableActivate(*id)])
        .collect();
    core.step(frame, &commands)
}

/// Load and activate alignment and IRU tables with every correction switched on.
fn activate_hooks(core: &mut FlightCore, frame: &RawSensorFrame) {
    use fsw_core::tables::{AlignmentTable, IruTable};
    let r = fsw_core::units::RAD_PER_ARCSEC;
    let mut al = AlignmentTable::prelaunch();
    let c = &mut al.corrections;
    c.fhst_distortion = [[0.1, 1e-3, -1e-3]; 2];
    c.fss_transfer = [[1e-4, 1e-4, 0.0, -1e-4, 1e-4, 0.0]; 2];
    c.fhst_magnitude_bias_rad_per_mag = [[2.0 * r, -r]; 2];
    c.thermal_alignment_rad_per_c = [[0.5 * r, -r, 2.0 * r]; 4];
    c.thermal_reference_c = [18.0, 17.0, 22.0, 21.0];
    c.fss_cubic = [[5e-4, -5e-4]; 2];
    c.fss_cyclic = [[0.0349, 6.0 * r, r, 5.0 * r, -r]; 2];
    let mut iru = IruTable::prelaunch();
    iru.scale_asymmetry_primary = [4e-4, -3e-4, 2e-4];
    let out = load_and_activate(
        core,
        frame,
        &[image(TableId::Alignment, &al), image(TableId::Iru, &iru)],
    );
    assert_eq!(core.tables().alignment(), &al, "{:?}", out.events);
    assert_eq!(core.tables().iru(), &iru);
}

/// Load and activate an orbit table (circular, a = 6833 km, i = 28.48°, epoch at `frame`) and
/// the active filter table with the orbital aberration correction on.
fn activate_orbit(core: &mut FlightCore, frame: &RawSensorFrame) {
    use fsw_core::tables::OrbitTable;
    let v = (fsw_core::orbit::MU_EARTH_KM3_PER_S2 / 6833.0).sqrt();
    let i = 28.48_f64.to_radians();
    let orbit = OrbitTable {
        epoch_s_since_j2000_tt: frame.time.seconds_since_j2000_tt(),
        pos_eci_km: [0.0, -6833.0 * i.cos(), -6833.0 * i.sin()],
        vel_eci_km_per_s: [v, 0.0, 0.0],
    };
    let mut filter = *core.tables().filter();
    filter.orbital_aberration_correction = true;
    filter.fhst_uncorrected_systematic_arcsec = 0.02;
    let out = load_and_activate(
        core,
        frame,
        &[
            image(TableId::Orbit, &orbit),
            image(TableId::Filter, &filter),
        ],
    );
    assert_eq!(core.tables().orbit(), &orbit, "{:?}", out.events);
    assert!(core.tables().filter().orbital_aberration_correction);
}

/// A magnetics table with every coefficient of degree ≤ 10 non-zero (the full synthesis cost),
/// dominated by a dipole, its epoch at `frame`.
fn magnetics_table(frame: &RawSensorFrame) -> fsw_core::tables::MagneticsTable {
    let mut t = fsw_core::tables::MagneticsTable::boot();
    t.field_degree = 10;
    t.field_epoch_s_since_j2000_tt = frame.time.seconds_since_j2000_tt();
    for n in 1..=10 {
        for m in 0..=n {
            t.g_nt[n][m] = 100.0 / n as f64;
            if m > 0 {
                t.h_nt[n][m] = -50.0 / n as f64;
            }
        }
    }
    t.g_nt[1][0] = -29_775.0;
    t
}

/// TAM words of the truth attitude at the orbit of `activate_orbit`, in every frame.
fn add_tam_words(s: &mut synthetic::Scenario) {
    let first = s.frames[0];
    let table = magnetics_table(&first);
    let mut orbit = fsw_core::orbit::OnboardOrbit::new();
    let v = (fsw_core::orbit::MU_EARTH_KM3_PER_S2 / 6833.0).sqrt();
    let i = 28.48_f64.to_radians();
    orbit.load(&fsw_core::tables::OrbitTable {
        epoch_s_since_j2000_tt: first.time.seconds_since_j2000_tt(),
        pos_eci_km: [0.0, -6833.0 * i.cos(), -6833.0 * i.sin()],
        vel_eci_km_per_s: [v, 0.0, 0.0],
    });
    let a = s.q_true.to_dcm();
    for f in &mut s.frames {
        let t_s = f.time.seconds_since_j2000_tt();
        let _ = orbit.advance_to(t_s);
        let Ok(state) = orbit.state() else { continue };
        let Ok(b) = fsw_core::field_model::field_eci_nt(&table, &state.pos_eci_km, t_s) else {
            continue;
        };
        let counts = a * b / 100.0 / 0.3;
        let tam = fsw_core::raw::TamSample {
            field_counts: [counts.x, counts.y, counts.z].map(|c| c.round() as i16),
            flags: fsw_core::raw::TAM_FLAG_VALID,
        };
        f.tam = [tam, tam];
        // The wheel tachometers (ICD v4): wheels at a few hundred rpm, every word valid, so
        // the OBC takes the wheel momentum from them every cycle.
        f.wheels = fsw_core::raw::WheelSample {
            speed_counts: [1_200, -800, 450, 2_000],
            speed_valid: 0x0F,
            ..Default::default()
        };
    }
}
