//! Record a deterministic replay fixture for the Cortex-M4 firmware (`firmware/`).
//!
//! ```text
//! cargo run -p fsw-core --example replay_record -- [INPUTS.bin [EXPECTED.bin]]
//! cargo run -p fsw-core --example replay_record -- --show CYCLE [INPUTS.bin [EXPECTED.bin]]
//! ```
//! Defaults: `firmware/fixtures/replay.bin` and, next to INPUTS, `<stem>.expected.bin`.
//!
//! The scenario is built in pure fsw-core terms (no sim-harness): a rigid spacecraft with the
//! filter table's inertia, closed loop with [`FlightCore`]'s wheel torque command; 600 one-second
//! cycles:
//!
//! * cycle 0: load a 43-star catalog image, a filter-table image and a corrupted copy of it;
//! * cycle 1: activate the catalog, load the corrupted image (rejected), load and activate the
//!   filter table;
//! * cycle 2: a slew before the filter is initialised (rejected);
//! * cycle 3: `FilterInitialize` 0.2° away from the truth → star identification, fine mode;
//! * cycle 240: `SlewTo` a target 0.6° away (gyro-only propagation, IRU high rate);
//! * cycles 360–365: FHST2 loses track, reacquires with the new-star flag;
//! * cycle 400: switch to the backup IRU channels (other biases) and reset the filter
//!   covariance;
//! * cycle 470: FHST1 acquires another star (identification after the slew);
//! * cycle 5: load and activate an orbit table and a magnetics table (a degree-10 field
//!   model); from then on TAM1/TAM2 words (the truth attitude, the model's field at the
//!   orbit's position, 0.2 mG noise) let the coarse attitude fix every 10th cycle (issue 20):
//!   the field synthesis, Earth orientation and TRIAD run on the target too.
//!
//! Raw counts come from fsw-core's inverse sensor functions ([`fhst::hv_from_dir`],
//! [`fss::angles_from_dir`], IRU pulses through the table's `G`) with deterministic noise
//! (a fixed-seed SplitMix64, Irwin–Hall normals: no platform math, so the fixture is the same
//! on every host).
//!
//! The frames and commands are written with postcard (`firmware/src/fixture.rs`, shared with
//! the firmware through `include!`). The expected outputs come from replaying the *written
//! file* on the host through a fresh [`FlightCore`], exactly as the firmware does, and are
//! checked against the closed-loop run: per cycle the CRC-32 of the cycle record (CUC time
//! code, ICD housekeeping user data, events) and, every 100 cycles and for the last one, the
//! full record.
#![allow(
    clippy::cast_possible_truncation,
    clippy::cast_precision_loss,
    clippy::cast_sign_loss,
    clippy::cast_possible_wrap,
    clippy::manual_is_multiple_of, // rust-version 1.85 predates is_multiple_of
    missing_docs
)]

#[allow(dead_code, clippy::all)]
mod fixture {
    include!("../../firmware/src/fixture.rs");
}

use fixture::{
    check_cycle, file_crc, CycleCheck, CycleRecord, ExpectedCycle, ExpectedHeader, ExpectedReader,
    InputHeader, InputReader, RecordedCommand, RecordedCycle, EXPECTED_MAGIC, FIXTURE_VERSION,
    INPUT_MAGIC,
};
use fsw_core::attitude::Quat;
use fsw_core::executive::{CycleOutput, FlightCore};
use fsw_core::fhst::{self, FHST_HALF_FIELD_RAD, FHST_RAD_PER_COUNT};
use fsw_core::fss::{self, FSS_HALF_FIELD_RAD, FSS_RAD_PER_COUNT};
use fsw_core::raw::{
    FhstSample, FssSample, IruSample, RawSensorFrame, TamSample, TimeTag, FHST_FLAG_NEW_STAR,
    FHST_FLAG_TRACKING, FHST_FLAG_VALID, FSS_FLAG_SUN_ALPHA, FSS_FLAG_SUN_BETA, TAM_FLAG_VALID,
};
use fsw_core::sun_ephemeris;
use fsw_core::tables::image::encode_image;
use fsw_core::tables::types::matrix_from_rows;
use fsw_core::tables::{
    AlignmentTable, CatalogStar, FilterTable, IruTable, MagneticsTable, OrbitTable,
    StarCatalogTable, TableId,
};
use fsw_core::telemetry::{decode_event, decode_housekeeping, decode_time_code, TIME_CODE_LEN};
use fsw_core::units::{RAD_PER_ARCSEC, RAD_PER_DEG};
use nalgebra::{Matrix3, Vector3};
use std::path::{Path, PathBuf};

/// Cycles in the scenario.
const CYCLES: u32 = 600;
/// A full cycle record is stored every this many cycles (and for the last cycle).
const FULL_EVERY: u32 = 100;
/// 1991-05-14T00:00:00 TAI in seconds since 1958-01-01 TAI (12 186 days).
const T0_COARSE_S: u32 = 12_186 * 86_400;
/// Fraction of the second of every frame (the OBC does not sample on the second).
const T0_FINE: u16 = 0x2000;
/// Truth integration sub-steps per cycle.
const SUBSTEPS: u32 = 10;

const CYCLE_SLEW: u32 = 240;
const CYCLE_BACKUP: u32 = 400;
const FHST2_LOST: std::ops::Range<u32> = 360..366;
const CYCLE_FHST1_SWITCH: u32 = 470;
const CYCLE_MAGNETICS: u32 = 5;
/// TAM count size, mG.
const TAM_MILLIGAUSS_PER_COUNT: f64 = 0.3;

// ------------------------------------------------------------------------------------------
// Deterministic noise
// ------------------------------------------------------------------------------------------

// SplitMix64, the workspace's one definition (fsw-core cannot depend on gro-reference).
#[path = "../../gro-reference/src/splitmix.rs"]
mod splitmix;

struct Rng(splitmix::SplitMix64);

impl Rng {
    fn new(seed: u64) -> Self {
        Self(splitmix::SplitMix64::new(seed))
    }
    /// Uniform in [0, 1).
    fn uniform(&mut self) -> f64 {
        self.0.unit()
    }
    /// Approximately standard normal (Irwin–Hall, 12 uniforms): no transcendental functions.
    fn normal(&mut self) -> f64 {
        (0..12).map(|_| self.uniform()).sum::<f64>() - 6.0
    }
}

// ------------------------------------------------------------------------------------------
// Scenario geometry
// ------------------------------------------------------------------------------------------

fn time_tag(cycle: u32) -> TimeTag {
    TimeTag {
        coarse_s: T0_COARSE_S + cycle,
        fine: T0_FINE,
    }
}

fn dcm_quat(m: &Matrix3<f64>) -> Quat {
    Quat::from_dcm(m).normalized()
}

/// Initial true attitude: the Sun at (α, β) = (5°, −3°) in FSS1, the ECI pole in the ACS
/// y–z half-plane (TRIAD).
fn initial_attitude(al: &AlignmentTable) -> Quat {
    let t = time_tag(0).seconds_since_j2000_tt();
    let sun_eci = sun_ephemeris::sun_dir_eci(t).unwrap();
    let sun_b = matrix_from_rows(&al.m_acs_from_fss1)
        * fss::dir_from_angles(5.0 * RAD_PER_DEG, -3.0 * RAD_PER_DEG);
    let pole = Vector3::z();
    let b1 = sun_b.normalize();
    let b2 = b1.cross(&Vector3::new(0.0, 1.0, 0.2)).normalize();
    let b3 = b1.cross(&b2);
    let r1 = sun_eci.normalize();
    let r2 = r1.cross(&pole).normalize();
    let r3 = r1.cross(&r2);
    let mb = Matrix3::from_columns(&[b1, b2, b3]);
    let mr = Matrix3::from_columns(&[r1, r2, r3]);
    dcm_quat(&(mb * mr.transpose()))
}

/// A catalog star at focal-plane angles (h, v) of a tracker at attitude `q`.
fn star_at(
    id: u32,
    q: &Quat,
    m_acs_from_fhst: &[[f64; 3]; 3],
    h_deg: f64,
    v_deg: f64,
    mag: f64,
) -> CatalogStar {
    let s = fhst::dir_from_hv(h_deg * RAD_PER_DEG, v_deg * RAD_PER_DEG);
    let r = q.to_dcm().transpose() * (matrix_from_rows(m_acs_from_fhst) * s);
    let r = r.normalize();
    CatalogStar {
        id,
        dir_eci: [r.x as f32, r.y as f32, r.z as f32],
        magnitude_centimag: (mag * 100.0).round() as i16,
    }
}

struct Scenario {
    q0: Quat,
    q_target: Quat,
    catalog: StarCatalogTable,
    /// FHST1 tracks A, then B; FHST2 tracks C.
    star_a: CatalogStar,
    star_b: CatalogStar,
    star_c: CatalogStar,
}

fn scenario(al: &AlignmentTable) -> Scenario {
    let q0 = initial_attitude(al);
    let q_target = Quat::from_rotation_vector(
        &(Vector3::new(0.3, -0.5, 0.81).normalize() * (0.6 * RAD_PER_DEG)),
    )
    .compose(&q0)
    .normalized();
    let star_a = star_at(24_436, &q0, &al.m_acs_from_fhst1, 1.0, -0.5, 3.2);
    let star_b = star_at(27_989, &q0, &al.m_acs_from_fhst1, -2.0, 1.5, 4.5);
    let star_c = star_at(32_349, &q0, &al.m_acs_from_fhst2, 0.3, 2.0, 2.7);
    let mut stars: heapless::Vec<CatalogStar, { fsw_core::tables::MAX_CATALOG_STARS }> =
        heapless::Vec::new();
    for s in [star_a, star_b, star_c] {
        stars.push(s).unwrap();
    }
    // Distractors uniform on the sky, none within 2° of a tracked star.
    let mut rng = Rng::new(0x6752_4F20_1991_0514);
    let mut id = 100_000;
    while stars.len() < 43 {
        let z = 2.0 * rng.uniform() - 1.0;
        let lon = 2.0 * std::f64::consts::PI * rng.uniform();
        let rho = (1.0 - z * z).sqrt();
        let r = Vector3::new(rho * libm::cos(lon), rho * libm::sin(lon), z);
        let mag = 2.0 + 3.7 * rng.uniform();
        let clear = [star_a, star_b, star_c]
            .iter()
            .all(|s| s.dir().dot(&r) < libm::cos(2.0 * RAD_PER_DEG));
        if clear {
            stars
                .push(CatalogStar {
                    id,
                    dir_eci: [r.x as f32, r.y as f32, r.z as f32],
                    magnitude_centimag: (mag * 100.0).round() as i16,
                })
                .unwrap();
            id += 7;
        }
    }
    let catalog = StarCatalogTable {
        epoch_years_since_j2000: -8.63,
        stars,
    };
    catalog.validate().unwrap();
    Scenario {
        q0,
        q_target,
        catalog,
        star_a,
        star_b,
        star_c,
    }
}

// ------------------------------------------------------------------------------------------
// Truth and raw sensors
// ------------------------------------------------------------------------------------------

struct Truth {
    q: Quat,
    omega: Vector3<f64>,
    inertia: Vector3<f64>,
    /// Per channel (X1, X2, Y1, Y2, Z1, Z2): angle not yet pulsed, rad.
    unpulsed_rad: [f64; 6],
    counters: [u16; 6],
    /// Channel bias, rad/s.
    bias_rad_per_s: [f64; 6],
    /// Rate mode of the interval in progress.
    high_rate: bool,
    g_inv: Matrix3<f64>,
    rng: Rng,
    fhst_track: [Option<CatalogStar>; 2],
}

impl Truth {
    fn new(q: Quat, filter: &FilterTable, iru: &IruTable) -> Self {
        let arcsec = RAD_PER_ARCSEC;
        Self {
            q,
            omega: Vector3::new(2.0e-6, -1.0e-6, 0.5e-6),
            inertia: Vector3::from(filter.inertia_kg_m2),
            unpulsed_rad: [0.0; 6],
            counters: [1_000, 65_500, 30_000, 12_345, 54_321, 7],
            bias_rad_per_s: [
                0.6 * arcsec,
                0.45 * arcsec,
                -0.5 * arcsec,
                -0.35 * arcsec,
                0.7 * arcsec,
                0.55 * arcsec,
            ],
            high_rate: false,
            g_inv: matrix_from_rows(&iru.g_primary).try_inverse().unwrap(),
            rng: Rng::new(0x4452_4952_5520_4949),
            fhst_track: [None, None],
        }
    }

    /// Advance one cycle under a constant body torque; the IRU counts in the rate mode
    /// `high_rate` for the whole interval.
    fn advance(&mut self, torque: &Vector3<f64>, dt: f64, high_rate: bool, iru: &IruTable) {
        self.high_rate = high_rate;
        let h = dt / f64::from(SUBSTEPS);
        let mut theta_acs = Vector3::zeros();
        for _ in 0..SUBSTEPS {
            let j_omega = self.inertia.component_mul(&self.omega);
            let omega_dot = (torque - self.omega.cross(&j_omega)).component_div(&self.inertia);
            let omega_mid = self.omega + omega_dot * (0.5 * h);
            let step = omega_mid * h;
            // A(t+h) = Rot(ω h) A(t)  ⇔  q(t+h) = q(ω h) ⊗ q(t).
            self.q = Quat::from_rotation_vector(&step)
                .compose(&self.q)
                .normalized();
            theta_acs += step;
            self.omega += omega_dot * h;
        }
        // Channel angles: the table's G is the truth (φ_xyz = G⁻¹ θ_acs) for both channels
        // of an axis, plus bias and angle random walk.
        let phi = self.g_inv * theta_acs;
        let weight_arcsec = if high_rate {
            iru.high_rate_arcsec_per_pulse
        } else {
            iru.low_rate_arcsec_per_pulse
        };
        let weight = weight_arcsec * RAD_PER_ARCSEC;
        for ch in 0..6 {
            let axis = ch / 2;
            let arw = 1.5e-7 * dt.sqrt() * self.rng.normal();
            self.unpulsed_rad[ch] += phi[axis] + self.bias_rad_per_s[ch] * dt + arw;
            let pulses = (self.unpulsed_rad[ch] / weight).trunc();
            self.unpulsed_rad[ch] -= pulses * weight;
            self.counters[ch] = self.counters[ch].wrapping_add(pulses as i64 as u16);
        }
    }

    fn iru_sample(&self) -> IruSample {
        IruSample {
            counts: self.counters,
            channel_failed: 0,
            high_rate: self.high_rate,
        }
    }

    fn fhst_sample(
        &mut self,
        tracker: usize,
        wanted: Option<CatalogStar>,
        al: &AlignmentTable,
    ) -> FhstSample {
        let m = if tracker == 0 {
            &al.m_acs_from_fhst1
        } else {
            &al.m_acs_from_fhst2
        };
        let seen = wanted.and_then(|star| {
            let s = matrix_from_rows(m).transpose() * (self.q.to_dcm() * star.dir());
            let (h, v) = fhst::hv_from_dir(&s)?;
            let limit = FHST_HALF_FIELD_RAD - 0.1 * RAD_PER_DEG;
            (h.abs() < limit && v.abs() < limit).then_some((star, h, v))
        });
        let Some((star, h, v)) = seen else {
            self.fhst_track[tracker] = None;
            return FhstSample::default();
        };
        let new_star = self.fhst_track[tracker].map(|s| s.id) != Some(star.id);
        self.fhst_track[tracker] = Some(star);
        let noise = 3.0 * RAD_PER_ARCSEC;
        let h_m = h + noise * self.rng.normal();
        let v_m = v + noise * self.rng.normal();
        let mag = f64::from(star.magnitude_centimag) + 4.0 * self.rng.normal();
        let mut flags = FHST_FLAG_VALID | FHST_FLAG_TRACKING;
        if new_star {
            flags |= FHST_FLAG_NEW_STAR;
        }
        FhstSample {
            h_counts: (h_m / FHST_RAD_PER_COUNT).round() as i16,
            v_counts: (v_m / FHST_RAD_PER_COUNT).round() as i16,
            magnitude_centimag: mag.round() as i16,
            flags,
        }
    }

    fn fss_sample(&mut self, sensor: usize, time: TimeTag, al: &AlignmentTable) -> FssSample {
        let m = if sensor == 0 {
            &al.m_acs_from_fss1
        } else {
            &al.m_acs_from_fss2
        };
        let sun_eci = sun_ephemeris::sun_dir_eci(time.seconds_since_j2000_tt()).unwrap();
        let s = matrix_from_rows(m).transpose() * (self.q.to_dcm() * sun_eci);
        let Some((alpha, beta)) = fss::angles_from_dir(&s) else {
            return FssSample::default();
        };
        if !(alpha.abs() < FSS_HALF_FIELD_RAD && beta.abs() < FSS_HALF_FIELD_RAD) {
            return FssSample::default();
        }
        let noise = 20.0 * RAD_PER_ARCSEC;
        let a_m = alpha + noise * self.rng.normal();
        let b_m = beta + noise * self.rng.normal();
        FssSample {
            alpha_counts: (a_m / FSS_RAD_PER_COUNT).round() as i16,
            beta_counts: (b_m / FSS_RAD_PER_COUNT).round() as i16,
            flags: FSS_FLAG_SUN_ALPHA | FSS_FLAG_SUN_BETA,
        }
    }
}

/// Cycles without wheel 4's tachometer word: the OBC counts its commands, then returns to the
/// tachometers (event 0x0A03 both ways).
const WHEEL4_TACH_LOST: std::ops::Range<u32> = 420..430;

/// Tachometer words for wheels on the ACS axes carrying `h` (the skewed fourth at rest), with
/// Table 6's boot rotor inertia; wheel 4's word is dropped over [`WHEEL4_TACH_LOST`].
fn wheel_words(h_wheels_acs_nms: &Vector3<f64>, cycle: u32) -> fsw_core::raw::WheelSample {
    let nms_per_count = fsw_core::tables::MagneticsTable::boot().wheel_spin_inertia_kg_m2
        * fsw_core::raw::WHEEL_RPM_PER_COUNT
        * std::f64::consts::TAU
        / 60.0;
    let c = |h: f64| (h / nms_per_count).round() as i16;
    fsw_core::raw::WheelSample {
        speed_counts: [
            c(h_wheels_acs_nms.x),
            c(h_wheels_acs_nms.y),
            c(h_wheels_acs_nms.z),
            0,
        ],
        speed_valid: if WHEEL4_TACH_LOST.contains(&cycle) {
            0x07
        } else {
            0x0F
        },
        dipole_counts: [0; 3],
        dipole_valid: 0x07,
    }
}

fn temperatures(cycle: u32) -> [i16; 5] {
    let c = cycle as i16;
    [
        2_150 + c / 60,
        2_140 + c / 75,
        1_800,
        1_810,
        2_500 - c / 100,
    ]
}

// ------------------------------------------------------------------------------------------
// Recording
// ------------------------------------------------------------------------------------------

/// postcard into a `Vec` (fsw-core's postcard has no `alloc` feature).
fn to_vec<T: serde::Serialize>(value: &T) -> Result<Vec<u8>, postcard::Error> {
    let mut buf = vec![0u8; 1 << 20];
    let n = postcard::to_slice(value, &mut buf)?.len();
    buf.truncate(n);
    Ok(buf)
}

fn quat4(q: &Quat) -> [f64; 4] {
    [q.x, q.y, q.z, q.w]
}

fn commands_for(cycle: u32, sc: &Scenario, truth_q: &Quat) -> Vec<RecordedCommand> {
    let catalog = TableId::StarCatalog as u8;
    let filter = TableId::Filter as u8;
    match cycle {
        0 => vec![RecordedCommand::TableLoad(0)],
        1 => vec![
            RecordedCommand::TableActivate(catalog),
            RecordedCommand::TableLoad(2),
            RecordedCommand::TableLoad(1),
            RecordedCommand::TableActivate(filter),
        ],
        2 => vec![RecordedCommand::SlewTo(quat4(&sc.q_target))],
        3 => {
            let err = Vector3::new(0.12, -0.1, 0.12) * RAD_PER_DEG;
            let q = Quat::from_rotation_vector(&err)
                .compose(truth_q)
                .normalized();
            vec![RecordedCommand::FilterInitialize(quat4(&q))]
        }
        CYCLE_MAGNETICS => vec![
            RecordedCommand::TableLoad(3),
            RecordedCommand::TableActivate(TableId::Orbit as u8),
            RecordedCommand::TableLoad(4),
            RecordedCommand::TableActivate(TableId::Magnetics as u8),
        ],
        CYCLE_SLEW => vec![RecordedCommand::SlewTo(quat4(&sc.q_target))],
        CYCLE_BACKUP => vec![
            RecordedCommand::SelectIruConfig(1),
            RecordedCommand::FilterReset,
        ],
        _ => Vec::new(),
    }
}

fn table_images() -> (Vec<Vec<u8>>, StarCatalogTable) {
    let al = AlignmentTable::prelaunch();
    let sc = scenario(&al);
    let created = TimeTag {
        coarse_s: T0_COARSE_S - 86_400,
        fine: 0,
    };
    let mut buf = vec![0u8; 256 * 1024];
    let n = encode_image(TableId::StarCatalog, created, &sc.catalog, &mut buf).unwrap();
    let catalog_image = buf[..n].to_vec();
    let mut ft = FilterTable::default_boot();
    ft.fss_sigma_arcsec = 45.0;
    ft.validate().unwrap();
    let n = encode_image(TableId::Filter, created, &ft, &mut buf).unwrap();
    let filter_image = buf[..n].to_vec();
    let mut corrupt = filter_image.clone();
    corrupt[30] ^= 0x10;
    let n = encode_image(TableId::Orbit, created, &replay_orbit(), &mut buf).unwrap();
    let orbit_image = buf[..n].to_vec();
    let n = encode_image(TableId::Magnetics, created, &replay_magnetics(), &mut buf).unwrap();
    let magnetics_image = buf[..n].to_vec();
    (
        vec![
            catalog_image,
            filter_image,
            corrupt,
            orbit_image,
            magnetics_image,
        ],
        sc.catalog,
    )
}

/// A circular 6833-km orbit through the sub-solar point at cycle 0 (its epoch), so that the
/// 600 cycles are sunlit: the OBC refuses a Sun read in the Earth's shadow, and the recorded
/// FSS words see the Sun throughout.
fn replay_orbit() -> OrbitTable {
    let t0 = time_tag(0).seconds_since_j2000_tt();
    let sun = sun_ephemeris::sun_dir_eci(t0).unwrap();
    let along = sun.cross(&Vector3::z()).normalize();
    let v = (fsw_core::orbit::MU_EARTH_KM3_PER_S2 / 6833.0).sqrt();
    let pos = sun * 6833.0;
    let vel = along * v;
    OrbitTable {
        epoch_s_since_j2000_tt: t0,
        pos_eci_km: [pos.x, pos.y, pos.z],
        vel_eci_km_per_s: [vel.x, vel.y, vel.z],
    }
}

/// A magnetics table with every coefficient of degree ≤ 10 non-zero, dominated by a dipole,
/// its epoch at cycle 0; TAMs on the ACS axes.
fn replay_magnetics() -> MagneticsTable {
    let mut t = MagneticsTable::boot();
    t.field_degree = 10;
    t.field_epoch_s_since_j2000_tt = time_tag(0).seconds_since_j2000_tt();
    for n in 1..=10 {
        for m in 0..=n {
            t.g_nt[n][m] = 100.0 / n as f64;
            t.g_nt_per_year[n][m] = 1.0;
            if m > 0 {
                t.h_nt[n][m] = -50.0 / n as f64;
            }
        }
    }
    t.g_nt[1][0] = -29_775.0;
    t.tam_milligauss_per_count = [[TAM_MILLIGAUSS_PER_COUNT; 3]; 2];
    t.validate().unwrap();
    t
}

/// TAM words of attitude `q` at `t_s`, with 0.2 mG noise from `rng`.
fn tam_words(
    orbit: &mut fsw_core::orbit::OnboardOrbit,
    table: &MagneticsTable,
    q: &Quat,
    t_s: f64,
    rng: &mut Rng,
) -> [TamSample; 2] {
    let _ = orbit.advance_to(t_s);
    let b_eci = fsw_core::field_model::field_eci_nt(table, &orbit.state().unwrap().pos_eci_km, t_s)
        .unwrap();
    let b_mg = q.to_dcm() * b_eci / 100.0;
    [0, 1].map(|_| TamSample {
        field_counts: [b_mg.x, b_mg.y, b_mg.z]
            .map(|b| ((b + 0.2 * rng.normal()) / TAM_MILLIGAUSS_PER_COUNT).round() as i16),
        flags: TAM_FLAG_VALID,
    })
}

struct Recording {
    inputs: Vec<u8>,
    records: Vec<CycleRecord>,
    outputs: Vec<CycleOutput>,
    truth_final: Quat,
    estimate_final: Quat,
    coarse_final: fsw_core::coarse::CoarseAttitude,
}

fn record() -> Recording {
    let al = AlignmentTable::prelaunch();
    let iru_table = IruTable::prelaunch();
    let filter_boot = FilterTable::default_boot();
    let sc = scenario(&al);
    let (images, _) = table_images();

    let mut inputs = to_vec(&InputHeader {
        magic: INPUT_MAGIC,
        version: FIXTURE_VERSION,
        images: images.len() as u8,
        cycles: CYCLES,
    })
    .unwrap();
    for image in &images {
        inputs.extend(to_vec(&image.as_slice()).unwrap());
    }
    let image_refs: Vec<&[u8]> = images.iter().map(Vec::as_slice).collect();

    let mut core = FlightCore::new();
    let mut truth = Truth::new(sc.q0, &filter_boot, &iru_table);
    let mut records = Vec::new();
    let mut outputs = Vec::new();
    let magnetics = replay_magnetics();
    let mut orbit = fsw_core::orbit::OnboardOrbit::new();
    orbit.load(&replay_orbit());
    let mut tam_rng = Rng::new(0x5441_4D31_1991_0405);
    // The wheels' momentum (ACS), from rest: they take −τ dt of each command.
    let mut h_wheels_acs_nms = Vector3::zeros();
    // One cycle of pulses before the first frame.
    truth.advance(&Vector3::zeros(), 1.0, false, &iru_table);
    for cycle in 0..CYCLES {
        let time = time_tag(cycle);
        let track1 = if cycle < CYCLE_FHST1_SWITCH {
            sc.star_a
        } else {
            sc.star_b
        };
        let track2 = (!FHST2_LOST.contains(&cycle)).then_some(sc.star_c);
        let frame = RawSensorFrame {
            time,
            iru: truth.iru_sample(),
            fhst: [
                truth.fhst_sample(0, Some(track1), &al),
                truth.fhst_sample(1, track2, &al),
            ],
            fss: [
                truth.fss_sample(0, time, &al),
                truth.fss_sample(1, time, &al),
            ],
            temperatures_centi_c: temperatures(cycle),
            tam: tam_words(
                &mut orbit,
                &magnetics,
                &truth.q,
                time.seconds_since_j2000_tt(),
                &mut tam_rng,
            ),
            css: Default::default(),
            wheels: wheel_words(&h_wheels_acs_nms, cycle),
        };
        let recorded = commands_for(cycle, &sc, &truth.q);
        let cycle_rec = RecordedCycle {
            frame,
            commands: recorded.iter().copied().collect(),
        };
        inputs.extend(to_vec(&cycle_rec).unwrap());
        let cmds: Vec<_> = recorded
            .iter()
            .map(|rc| fixture::to_command(rc, &image_refs).unwrap())
            .collect();
        let out = core.step(&frame, &cmds);
        records.push(CycleRecord::encode(&out).unwrap());
        outputs.push(out);
        let torque = core.wheel_torque_command_nm();
        h_wheels_acs_nms -= torque;
        truth.advance(&torque, 1.0, core.iru_high_rate_command(), &iru_table);
    }
    Recording {
        inputs,
        records,
        outputs,
        truth_final: truth.q,
        estimate_final: core.attitude(),
        coarse_final: *core.coarse(),
    }
}

/// Replay an input file through a fresh core exactly as the firmware does.
fn replay(inputs: &[u8]) -> Vec<CycleRecord> {
    let mut reader = InputReader::new(inputs).unwrap();
    let mut core = FlightCore::new();
    let mut out = Vec::new();
    while let Some(cycle) = reader.next_cycle() {
        let cycle = cycle.unwrap();
        let cmds = reader.commands(&cycle).unwrap();
        let o = core.step(&cycle.frame, &cmds);
        out.push(CycleRecord::encode(&o).unwrap());
    }
    out
}

fn expected_file(inputs: &[u8], records: &[CycleRecord]) -> Vec<u8> {
    let mut bytes = to_vec(&ExpectedHeader {
        magic: EXPECTED_MAGIC,
        version: FIXTURE_VERSION,
        cycles: records.len() as u32,
        inputs_crc: file_crc(inputs),
        full_every: FULL_EVERY,
    })
    .unwrap();
    for (i, r) in records.iter().enumerate() {
        let i = i as u32;
        let full = i % FULL_EVERY == 0 || i + 1 == records.len() as u32;
        let events = r.bytes()[TIME_CODE_LEN + fsw_core::telemetry::HOUSEKEEPING_LEN];
        bytes.extend(
            to_vec(&ExpectedCycle {
                digest: r.digest(),
                events,
                record: full.then_some(r.bytes()),
            })
            .unwrap(),
        );
    }
    bytes
}

fn print_record(bytes: &[u8]) {
    let time = decode_time_code(bytes).unwrap();
    let hk_end = TIME_CODE_LEN + fsw_core::telemetry::HOUSEKEEPING_LEN;
    let hk = decode_housekeeping(time, &bytes[TIME_CODE_LEN..hk_end]).unwrap();
    println!("{hk:#?}");
    let n = usize::from(bytes[hk_end]);
    for k in 0..n {
        let at = hk_end + 1 + 10 * k;
        println!("event {:?}", decode_event(&bytes[at..at + 10]).unwrap());
    }
}

fn expected_path_for(inputs: &Path) -> PathBuf {
    let stem = inputs
        .file_stem()
        .map_or_else(|| "replay".into(), |s| s.to_string_lossy().into_owned());
    inputs.with_file_name(format!("{stem}.expected.bin"))
}

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let mut show: Option<usize> = None;
    if let Some(pos) = args.iter().position(|a| a == "--show") {
        show = Some(args[pos + 1].parse().expect("--show CYCLE"));
        args.drain(pos..pos + 2);
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let inputs_path = args
        .first()
        .map_or_else(|| root.join("firmware/fixtures/replay.bin"), PathBuf::from);
    let expected_path = args
        .get(1)
        .map_or_else(|| expected_path_for(&inputs_path), PathBuf::from);

    println!(
        "size_of::<FlightCore>() = {} bytes (StarCatalogTable {} bytes, CycleOutput {} bytes)",
        core::mem::size_of::<FlightCore>(),
        core::mem::size_of::<StarCatalogTable>(),
        core::mem::size_of::<CycleOutput>()
    );

    let rec = record();
    let replayed = replay(&rec.inputs);
    assert_eq!(replayed.len(), rec.records.len());
    for (i, (a, b)) in replayed.iter().zip(&rec.records).enumerate() {
        assert_eq!(
            a.bytes(),
            b.bytes(),
            "host replay differs from the recording at cycle {i}"
        );
    }
    let expected = expected_file(&rec.inputs, &replayed);

    // Read the expected file back with the firmware's reader and check it.
    let mut reader = ExpectedReader::new(&expected).unwrap();
    let mut n = 0usize;
    while let Some(e) = reader.next_cycle() {
        let e = e.unwrap();
        assert_eq!(check_cycle(&replayed[n], &e), CycleCheck::Match);
        if show == Some(n) {
            println!("expected output of cycle {n}:");
            print_record(replayed[n].bytes());
        }
        n += 1;
    }
    assert_eq!(n, replayed.len());

    if let Some(dir) = inputs_path.parent() {
        std::fs::create_dir_all(dir).unwrap();
    }
    std::fs::write(&inputs_path, &rec.inputs).unwrap();
    std::fs::write(&expected_path, &expected).unwrap();

    // Scenario summary.
    let mut counts = std::collections::BTreeMap::<String, u32>::new();
    for (i, o) in rec.outputs.iter().enumerate() {
        for e in &o.events {
            *counts.entry(format!("{:?}", e.id)).or_default() += 1;
            if matches!(
                e.id,
                fsw_core::events::EventId::SlewStarted
                    | fsw_core::events::EventId::SlewCompleted
                    | fsw_core::events::EventId::FilterModeChanged
                    | fsw_core::events::EventId::StarIdentified
                    | fsw_core::events::EventId::StarIdFailed
                    | fsw_core::events::EventId::TableRejected
                    | fsw_core::events::EventId::CommandRejected
            ) {
                println!("cycle {i:3}: {:?} p1={} p2={}", e.id, e.p1, e.p2);
            }
        }
    }
    let last = &rec.outputs[rec.outputs.len() - 1].housekeeping;
    let err_arcsec = rec.truth_final.angle_to_rad(&rec.estimate_final) / RAD_PER_ARCSEC;
    let coarse_deg = rec
        .truth_final
        .angle_to_rad(&rec.coarse_final.q_acs_from_eci)
        / RAD_PER_DEG;
    println!(
        "coarse attitude: {} fixes, final error {coarse_deg:.3}° (source {:?})",
        rec.coarse_final.fixes, rec.coarse_final.source
    );
    assert!(
        rec.coarse_final.fixes >= 50,
        "the coarse path must run in the replay"
    );
    assert!(coarse_deg < 1.0);
    // The wheel momentum's source: the tachometers from the first frame, the command count
    // while wheel 4's word is missing, the tachometers again (event 0x0A03).
    let sources: Vec<(usize, u32)> = rec
        .outputs
        .iter()
        .enumerate()
        .flat_map(|(i, o)| {
            o.events
                .iter()
                .filter(|e| e.id == fsw_core::events::EventId::WheelMomentumSourceChanged)
                .map(move |e| (i, e.p1))
        })
        .collect();
    let lost = WHEEL4_TACH_LOST.start as usize;
    let back = WHEEL4_TACH_LOST.end as usize;
    assert_eq!(sources, vec![(0, 1), (lost, 2), (back, 1)]);
    println!("events: {counts:?}");
    println!(
        "final: filter mode {}, control mode {}, accepted {}, gated {}, estimate error {:.1} arcsec",
        last.filter_mode,
        last.control_mode,
        last.counters.accepted_measurements,
        last.counters.gated_measurements,
        err_arcsec
    );
    println!(
        "wrote {} ({} bytes, CRC-32 {:08x}) and {} ({} bytes); {} cycles, host replay of the file identical",
        inputs_path.display(),
        rec.inputs.len(),
        file_crc(&rec.inputs),
        expected_path.display(),
        expected.len(),
        replayed.len()
    );
}
