//! Closed-loop tests with the real FlightCore: determinism, the ICD byte layout (read back
//! with a decoder written here from docs/icd.md, not fsw-core's), the normal-ops smoke run,
//! the early-mission maneuvers with prelaunch tables, and bad inputs.

use std::path::Path;

use sim_harness::closed_loop::{CycleRecord, Simulation};
use sim_harness::run::{run, RunOptions, Summary};
use sim_harness::scenario::{self, Scenario};

fn scenario(name: &str, duration_s: f64) -> Scenario {
    let mut s = scenario::resolve(name).unwrap();
    s.duration_s = duration_s;
    s
}

fn run_to(s: Scenario, dir: &Path) -> Summary {
    run(
        s,
        &RunOptions {
            out_dir: Some(dir.to_path_buf()),
            ..RunOptions::default()
        },
    )
    .unwrap()
}

/// Same scenario and seed ⇒ byte-identical telemetry.bin (and truth.json); another seed
/// changes it.
#[test]
fn determinism_same_seed_same_bytes() {
    let tmp = tempfile::tempdir().unwrap();
    let (a, b, c) = (
        tmp.path().join("a"),
        tmp.path().join("b"),
        tmp.path().join("c"),
    );
    run_to(scenario("gro-early-mission", 400.0), &a);
    run_to(scenario("gro-early-mission", 400.0), &b);
    let mut other = scenario("gro-early-mission", 400.0);
    other.seed = 2;
    run_to(other, &c);
    let ta = std::fs::read(a.join("telemetry.bin")).unwrap();
    let tb = std::fs::read(b.join("telemetry.bin")).unwrap();
    let tc = std::fs::read(c.join("telemetry.bin")).unwrap();
    assert!(ta.len() > 100_000);
    assert!(ta == tb, "same seed, different telemetry");
    assert!(ta != tc, "different seeds, same telemetry");
    assert_eq!(
        std::fs::read(a.join("truth.json")).unwrap(),
        std::fs::read(b.join("truth.json")).unwrap()
    );
    for f in [
        "metadata.json",
        "truth.json",
        "summary.json",
        "uploads/00_star_catalog.tbl",
    ] {
        assert!(a.join(f).exists(), "{f}");
    }
    assert!(
        !std::fs::read_dir(&a).unwrap().any(|e| e
            .unwrap()
            .path()
            .to_string_lossy()
            .ends_with(".partial")),
        "no .partial file left"
    );
}

// ------------------------------------------------------------------------------------------
// An independent reader of docs/icd.md (no fsw-core decoders).
// ------------------------------------------------------------------------------------------

struct Packet<'a> {
    offset: usize,
    version: u8,
    tm: bool,
    sec_header: bool,
    apid: u16,
    seq_flags: u8,
    seq: u16,
    coarse: u32,
    fine: u16,
    user: &'a [u8],
}

fn be16(b: &[u8], at: usize) -> u16 {
    u16::from_be_bytes([b[at], b[at + 1]])
}
fn be32(b: &[u8], at: usize) -> u32 {
    u32::from_be_bytes(b[at..at + 4].try_into().unwrap())
}
fn bef64(b: &[u8], at: usize) -> f64 {
    f64::from_be_bytes(b[at..at + 8].try_into().unwrap())
}
fn bef32(b: &[u8], at: usize) -> f32 {
    f32::from_be_bytes(b[at..at + 4].try_into().unwrap())
}

fn parse(file: &[u8]) -> Vec<Packet<'_>> {
    let mut out = Vec::new();
    let mut at = 0;
    while at < file.len() {
        assert!(at + 12 <= file.len(), "truncated header at {at}");
        let w0 = be16(file, at);
        let w1 = be16(file, at + 2);
        let len = usize::from(be16(file, at + 4)) + 1;
        let end = at + 6 + len;
        assert!(end <= file.len(), "truncated packet at {at}");
        out.push(Packet {
            offset: at,
            version: (w0 >> 13) as u8,
            tm: (w0 >> 12) & 1 == 0,
            sec_header: (w0 >> 11) & 1 == 1,
            apid: w0 & 0x7ff,
            seq_flags: (w1 >> 14) as u8,
            seq: w1 & 0x3fff,
            coarse: be32(file, at + 6),
            fine: be16(file, at + 10),
            user: &file[at + 12..end],
        });
        at = end;
    }
    out
}

/// APID 0x010 (docs/icd.md §3.1) against the frame the simulation produced.
fn check_raw_frame(p: &Packet<'_>, r: &CycleRecord) {
    assert_eq!(
        (p.coarse, p.fine),
        (r.frame.time.coarse_s, r.frame.time.fine)
    );
    for ch in 0..6 {
        assert_eq!(be16(p.user, 2 * ch), r.frame.iru.counts[ch]);
    }
    assert_eq!(p.user[12], r.frame.iru.channel_failed);
    assert_eq!(p.user[13], u8::from(r.frame.iru.high_rate));
    for k in 0..2 {
        let o = 14 + 7 * k;
        let f = &r.frame.fhst[k];
        assert_eq!(be16(p.user, o) as i16, f.h_counts);
        assert_eq!(be16(p.user, o + 2) as i16, f.v_counts);
        assert_eq!(be16(p.user, o + 4) as i16, f.magnitude_centimag);
        assert_eq!(p.user[o + 6], f.flags);
        let o = 28 + 5 * k;
        let f = &r.frame.fss[k];
        assert_eq!(be16(p.user, o) as i16, f.alpha_counts);
        assert_eq!(be16(p.user, o + 2) as i16, f.beta_counts);
        assert_eq!(p.user[o + 4], f.flags);
    }
    for i in 0..5 {
        assert_eq!(
            be16(p.user, 38 + 2 * i) as i16,
            r.frame.temperatures_centi_c[i]
        );
    }
}

/// APID 0x013 (docs/icd.md §3.5) against the frame's TAM and CSS words.
fn check_magnetics_frame(p: &Packet<'_>, r: &CycleRecord) {
    for k in 0..2 {
        let o = 7 * k;
        let t = &r.frame.tam[k];
        for i in 0..3 {
            assert_eq!(be16(p.user, o + 2 * i) as i16, t.field_counts[i]);
        }
        assert_eq!(p.user[o + 6], t.flags);
        assert_eq!(t.flags & 1, 1, "TAM{} valid in 1991", k + 1);
    }
    for i in 0..6 {
        assert_eq!(be16(p.user, 14 + 2 * i), r.frame.css.counts[i]);
    }
    assert_eq!(p.user[26], r.frame.css.flags);
}

/// APID 0x014 (docs/icd.md §3.6) against the frame's tachometer and monitor words.
fn check_wheel_frame(p: &Packet<'_>, r: &CycleRecord) {
    let w = &r.frame.wheels;
    for i in 0..4 {
        assert_eq!(be16(p.user, 2 * i) as i16, w.speed_counts[i]);
    }
    assert_eq!(p.user[8], w.speed_valid);
    assert_eq!(w.speed_valid, 0x0F, "four tachometers");
    for k in 0..3 {
        assert_eq!(be16(p.user, 9 + 2 * k) as i16, w.dipole_counts[k]);
    }
    assert_eq!(p.user[15], w.dipole_valid);
    assert_eq!(w.dipole_valid, 0x07, "three bar monitors");
}

/// APID 0x011 (docs/icd.md §3.2) against the cycle's housekeeping (a sample of its fields).
fn check_housekeeping(p: &Packet<'_>, h: &fsw_core::telemetry::ObcHousekeeping) {
    let q = [
        bef64(p.user, 0),
        bef64(p.user, 8),
        bef64(p.user, 16),
        bef64(p.user, 24),
    ];
    assert_eq!(
        q,
        [
            h.q_acs_from_eci.x,
            h.q_acs_from_eci.y,
            h.q_acs_from_eci.z,
            h.q_acs_from_eci.w
        ]
    );
    for i in 0..3 {
        assert_eq!(bef64(p.user, 32 + 8 * i), h.bias_acs_rad_per_s[i]);
    }
    for i in 0..6 {
        assert_eq!(bef64(p.user, 56 + 8 * i), h.covariance_diag[i]);
    }
    assert_eq!(
        [p.user[104], p.user[105], p.user[106], p.user[107]],
        [
            h.filter_mode,
            h.control_mode,
            h.iru_config,
            h.iru_high_rate_cmd
        ]
    );
    assert_eq!(bef32(p.user, 108), h.wheel_torque_cmd_nm[0]);
    for k in 0..4 {
        let o = 120 + 13 * k;
        assert_eq!(p.user[o], h.residuals[k].status as u8);
        assert_eq!(bef32(p.user, o + 1), h.residuals[k].innovation_arcsec[0]);
        assert_eq!(be32(p.user, o + 9), h.residuals[k].star_id);
    }
    assert_eq!(be32(p.user, 173), h.counters.cycles);
    assert_eq!(be32(p.user, 173 + 16), h.counters.stars_identified);
    assert_eq!(be32(p.user, 213 + 12), h.table_crc[3]);
}

/// `r`, after checking that packet `p` carries its raw frame's time code (APIDs 0x013 and
/// 0x014 are written with the raw frame of their cycle).
fn with_raw_frame_time<'a>(p: &Packet<'_>, r: &'a CycleRecord) -> &'a CycleRecord {
    assert_eq!(
        (p.coarse, p.fine),
        (r.frame.time.coarse_s, r.frame.time.fine),
        "APID {:#x} at {} with its raw frame's time code",
        p.apid,
        p.offset
    );
    r
}

/// Write packets with the harness, read them back by hand (docs/icd.md §2–4) and compare
/// against the records the simulation produced.
#[test]
fn icd_round_trip_independent_decoder() {
    let tmp = tempfile::tempdir().unwrap();
    let s = scenario("gro-early-mission", 120.0);
    run_to(s.clone(), tmp.path());
    // The same run, cycle by cycle, for the reference values.
    let mut sim = Simulation::new(s, None).unwrap();
    let mut recs: Vec<CycleRecord> = Vec::new();
    while let Some(r) = sim.step() {
        recs.push(r);
    }
    let file = std::fs::read(tmp.path().join("telemetry.bin")).unwrap();
    let packets = parse(&file);
    let lengths = [
        (0x010, 48),
        (0x011, 230),
        (0x012, 10),
        (0x013, 27),
        (0x014, 16),
        (0x020, 48),
    ];
    let mut seq = std::collections::HashMap::new();
    let mut cycle = 0usize;
    let mut last_time = 0.0;
    // Order within a cycle: raw, magnetics (format version 2, `[magnetics] enabled`), wheels
    // (version 4, `[wheel_tachometers] enabled`), [ephemeris], housekeeping, events.
    let mut expect = 0x010;
    let mut magnetics = 0usize;
    let mut wheels = 0usize;
    let mut ephemeris_times = Vec::new();
    for p in &packets {
        assert_eq!(p.version, 0, "at {}", p.offset);
        assert!(p.tm && p.sec_header, "at {}", p.offset);
        assert_eq!(p.seq_flags, 0b11, "unsegmented at {}", p.offset);
        let want_len = lengths.iter().find(|(a, _)| *a == p.apid).unwrap().1;
        assert_eq!(p.user.len(), want_len, "APID {:#x} at {}", p.apid, p.offset);
        let n = seq.entry(p.apid).or_insert(0u16);
        assert_eq!(p.seq, *n, "APID {:#x} sequence at {}", p.apid, p.offset);
        *n = (*n + 1) & 0x3fff;
        let t = f64::from(p.coarse) + f64::from(p.fine) / 65536.0;
        assert!(t >= last_time, "time decreases at {}", p.offset);
        last_time = t;
        match p.apid {
            0x010 => {
                assert!(
                    expect == 0x010 || expect == 0x012,
                    "raw out of order at {}",
                    p.offset
                );
                let r = &recs[cycle];
                cycle += 1;
                check_raw_frame(p, r);
                expect = 0x020;
            }
            0x013 => {
                assert_eq!(expect, 0x020, "magnetics out of order at {}", p.offset);
                expect = 0x013;
                let r = with_raw_frame_time(p, &recs[cycle - 1]);
                check_magnetics_frame(p, r);
                magnetics += 1;
            }
            0x014 => {
                assert!(
                    expect == 0x020 || expect == 0x013,
                    "wheel frame out of order at {}",
                    p.offset
                );
                expect = 0x014;
                let r = with_raw_frame_time(p, &recs[cycle - 1]);
                check_wheel_frame(p, r);
                wheels += 1;
            }
            0x020 => {
                assert!(
                    [0x020, 0x013, 0x014].contains(&expect),
                    "ephemeris out of order at {}",
                    p.offset
                );
                let r = &recs[cycle - 1];
                let pos = [bef64(p.user, 0), bef64(p.user, 8), bef64(p.user, 16)];
                let vel = [bef64(p.user, 24), bef64(p.user, 32), bef64(p.user, 40)];
                assert_eq!(pos, <[f64; 3]>::from(r.truth.pos_eci_km));
                assert_eq!(vel, <[f64; 3]>::from(r.truth.vel_eci_km_per_s));
                let rn = pos.iter().map(|x| x * x).sum::<f64>().sqrt();
                assert!((rn - 6833.0).abs() < 30.0, "{rn}");
                ephemeris_times.push(r.truth.t_s);
                expect = 0x011;
            }
            0x011 => {
                assert!(
                    [0x020, 0x013, 0x014, 0x011].contains(&expect),
                    "hk out of order at {}",
                    p.offset
                );
                check_housekeeping(p, &recs[cycle - 1].output.housekeeping);
                expect = 0x012;
            }
            0x012 => {
                assert_eq!(expect, 0x012, "event out of order at {}", p.offset);
                let r = &recs[cycle - 1];
                let code = be16(p.user, 0);
                assert!(
                    r.output.events.iter().any(|e| e.id.code() == code
                        && e.p1 == be32(p.user, 2)
                        && e.p2 == be32(p.user, 6)),
                    "event {code:#x} not in cycle {}",
                    cycle - 1
                );
            }
            other => panic!("unknown APID {other:#x}"),
        }
    }
    assert_eq!(cycle, recs.len(), "one raw frame per cycle");
    assert_eq!(magnetics, recs.len(), "one magnetics frame per raw frame");
    assert_eq!(wheels, recs.len(), "one wheel frame per raw frame");
    assert_eq!(seq[&0x011], recs.len() as u16);
    // Ephemeris every 10 s of sim time; the catalog is activated at t = 0 (CRC in housekeeping).
    assert_eq!(
        ephemeris_times,
        (0..13).map(|k| f64::from(k) * 10.0).collect::<Vec<_>>()
    );
    assert_ne!(recs[0].output.housekeeping.table_crc[3], 0);
}

/// 30 min of normal-ops (true alignments, onboard annual aberration correction): the filter
/// reaches fine mode and the attitude error 3σ per axis is ≤ 15″ (requirement 86″).
///
/// NEES: the upper end (6) catches an optimistic filter (σ understated by √2 or more), the
/// lower end (0.75) one whose σ is overstated by 2× or more. Why not issue 19's [1.5, 6] here:
/// the error of these 30 min is mostly the stars' orbital aberration (≤ 5.2″, not corrected
/// without an onboard orbit), which the OBC carries as the FHSTs' consider states with a
/// correlation time of 24 min (docs/obc_filter.md §10): 30 min hold about one draw of it, so
/// the mean NEES is about one draw's (measured 1.01 on seed 1). The band [1.5, 6] needs many
/// correlation times: it is asserted on the 4-h mismatched filter test (three seeds,
/// `fsw-core/tests/est_filter_mismatched.rs`) and measured on one day and two weeks of
/// `normal-ops` (docs/obc_filter.md §10). Before the consider states the floored update gave
/// 2.35 here, partly from the frozen noise of each star's first samples (§9).
#[test]
fn e2e_normal_ops_smoke_fine_attitude() {
    let s = scenario("normal-ops", 1800.0);
    let start = std::time::Instant::now();
    let sum = run(s, &RunOptions::default()).unwrap();
    let e = &sum.attitude_error_arcsec;
    eprintln!(
        "normal-ops 30 min: {:.2} s wall; rms {:?}″, 3σ {:?}″, max {:.1}″, NEES {:?}, fine {:.2}",
        start.elapsed().as_secs_f64(),
        e.rms,
        e.three_sigma,
        e.max,
        sum.filter_nees_mean,
        sum.fine_mode_fraction
    );
    assert!(e.cycles > 1000);
    for k in 0..3 {
        assert!(
            e.three_sigma[k] <= 15.0,
            "3σ axis {k}: {}″",
            e.three_sigma[k]
        );
        assert!(e.rms[k] <= 8.0, "rms axis {k}: {}″", e.rms[k]);
    }
    assert!(sum.fine_mode_fraction > 0.9);
    let nees = sum.filter_nees_mean.unwrap();
    assert!((0.75..=6.0).contains(&nees), "NEES {nees}");
    // The start-up uplinks at 0 s; the orbit (1 s) and the magnetics table (2 s) after them
    // (issue 20: the coarse attitude needs both).
    let when: Vec<_> = sum
        .tables_loaded
        .iter()
        .map(|t| (t.table.as_str(), t.accepted, t.activated_at_s))
        .collect();
    assert_eq!(
        when,
        [
            ("star_catalog", true, Some(0.0)),
            ("filter", true, Some(0.0)),
            ("alignment", true, Some(0.0)),
            ("orbit", true, Some(1.0)),
            ("magnetics", true, Some(2.0)),
        ],
        "catalog, filter table, true alignments, orbit, magnetics"
    );
    // The coarse attitude ran alongside and met the 2° (3σ) requirement.
    let coarse = sum.coarse_attitude_error_3sigma_deg.unwrap();
    assert!(coarse.iter().all(|x| *x <= 2.0), "{coarse:?}");
}

/// The same 30 min without the onboard orbit and without the orbital aberration: the floor
/// the OBC keeps for the uncorrected aberration (docs/obc_filter.md §3) is then an error the
/// truth does not have, so the filter must be conservative (NEES below the consistent band),
/// not inconsistent. Before the floor the same run gave 1.4 with the table's tenfold gyro ARW,
/// and the band was [1, 6]. The FSS transfer-function errors are removed too (the FSSs serve
/// coarse mode only; the run stays in fine mode).
#[test]
fn normal_ops_filter_is_conservative_without_orbital_aberration() {
    let mut s = scenario("normal-ops", 1800.0);
    s.onboard_orbit = None;
    s.sky.orbital_aberration = false;
    for f in [&mut s.fss1, &mut s.fss2] {
        for h in [&mut f.alpha, &mut f.beta] {
            h.scale_ppm = 0.0;
            h.cyclic_arcsec = 0.0;
            h.cross_arcsec_at_corner = 0.0;
            h.cubic_arcsec_at_edge = 0.0;
        }
    }
    let sum = run(s, &RunOptions::default()).unwrap();
    let nees = sum.filter_nees_mean.unwrap();
    eprintln!(
        "normal-ops without orbital aberration: NEES {nees:.2}, rms {:?}″",
        sum.attitude_error_arcsec.rms
    );
    assert!((0.05..1.5).contains(&nees), "NEES {nees}");
}

/// gro-early-mission with the prelaunch tables through the first calibration maneuver
/// (X +60°): every slew ends with an estimation error below the paper's 0.5°.
#[test]
fn e2e_early_mission_post_maneuver_error_below_half_degree() {
    let s = scenario("gro-early-mission", 12_200.0);
    let sum = run(s, &RunOptions::default()).unwrap();
    eprintln!(
        "post-maneuver errors (deg): {:?}",
        sum.post_maneuver_error_deg
    );
    assert!(sum.slews.len() >= 6, "{} slews", sum.slews.len());
    for (k, e) in sum.post_maneuver_error_deg.iter().enumerate() {
        assert!(*e < 0.5, "slew {k}: {e}°");
    }
    // The X +60° maneuver was flown in high-rate mode about body X.
    let last = sum.slews.last().unwrap();
    assert!(last.end_s - last.start_s > 600.0);
    assert_eq!(sum.iru_counter_aliasing_frames, 0);
}

/// A relative slew rotates the target about the body axis: after `axis = "z"`,
/// `angle_deg = 20` the true attitude has turned 20° about body z.
#[test]
fn relative_slew_turns_about_the_body_axis() {
    let text = r#"
name = "rel"
duration_s = 1500
fly_true_alignments = true
[initial]
q_acs_from_eci = [0.778310, 0.625643, 0.052966, 0.0]
[[commands]]
at_s = 10
kind = "slew_to"
axis = "z"
angle_deg = 20.0
"#;
    let s = Scenario::from_toml_str(text, "t").unwrap();
    let q0 = s.initial.quat();
    let mut sim = Simulation::new(s, None).unwrap();
    let mut last = None;
    while let Some(r) = sim.step() {
        last = Some(r);
    }
    let q1 = last.unwrap().truth.q_acs_from_eci;
    let rel = q1.compose(&q0.conjugate()).rotation_vector_rad();
    assert!(
        (rel.norm().to_degrees() - 20.0).abs() < 0.15,
        "{}",
        rel.norm().to_degrees()
    );
    assert!(rel.normalize().z > 0.99, "{rel:?}");
}

/// Bad inputs: errors name the field, are `InputError`s (exit code 2), and the CLI exits 2.
#[test]
fn bad_inputs_name_the_field_and_exit_2() {
    for (toml, key) in [
        ("[fhst1]\nnoise_flor_arcsec = 1\n", "noise_flor_arcsec"),
        (
            "[[commands]]\nat_s = 1\nkind = \"slew_to\"\naxis = \"w\"\nangle_deg = 5\n",
            "commands[0].axis",
        ),
    ] {
        let text = format!("name = \"x\"\nduration_s = 10\n{toml}");
        let err = format!("{:#}", Scenario::from_toml_str(&text, "t").unwrap_err());
        assert!(err.contains(key), "{err}");
    }
    let err = Scenario::from_toml_str(
        "name = \"x\"\nduration_s = 10\nfilter_table = { gate_chi = 3 }\n",
        "t",
    )
    .map(|s| Simulation::new(s, None).map(|_| ()))
    .unwrap()
    .unwrap_err();
    assert!(
        format!("{err:#}").contains("filter_table.gate_chi"),
        "{err:#}"
    );
    assert!(sim_harness::is_input_error(&err));
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("bad.toml");
    std::fs::write(
        &path,
        "name = \"x\"\nduration_s = 10\n[[commands]]\nat_s = 1\nkind = \"table_load\"\nfile = \"missing.tbl\"\n",
    )
    .unwrap();
    let err = Simulation::new(Scenario::load(&path).unwrap(), None)
        .map(|_| ())
        .unwrap_err();
    assert!(format!("{err:#}").contains("commands[0].file"), "{err:#}");
    assert!(sim_harness::is_input_error(&err));
    std::fs::write(&path, "name = \"x\"\nduration_s = 10\nstep_s = 0\n").unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_sim-harness"))
        .args(["run", path.to_str().unwrap(), "--out"])
        .arg(tmp.path().join("o"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("step_s"));
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_sim-harness"))
        .args(["run", "no-such-scenario", "--out"])
        .arg(tmp.path().join("o"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
}

/// Monte Carlo with shards and merge gives the same aggregate as one campaign.
#[test]
fn monte_carlo_shards_merge_to_the_campaign() {
    use sim_harness::campaign::{merge, monte_carlo, CampaignOptions};
    let tmp = tempfile::tempdir().unwrap();
    let s = scenario("normal-ops", 120.0);
    let opts = |dir: &str, shard| CampaignOptions {
        runs: 3,
        seed: 10,
        out_dir: tmp.path().join(dir),
        shard,
        tables_dir: None,
        duration_s: None,
        force: false,
    };
    let (whole, _) = monte_carlo(&s, &opts("all", (0, 1)), &|| {}).unwrap();
    monte_carlo(&s, &opts("s0", (0, 2)), &|| {}).unwrap();
    monte_carlo(&s, &opts("s1", (1, 2)), &|| {}).unwrap();
    let (merged, path) = merge(&[tmp.path().join("s0"), tmp.path().join("s1")], None).unwrap();
    assert!(path.exists());
    assert_eq!(merged.seeds, vec![10, 11, 12]);
    assert_eq!(
        merged.attitude_error_rms_arcsec,
        whole.attitude_error_rms_arcsec
    );
    assert_eq!(
        merged.post_maneuver_error_deg,
        whole.post_maneuver_error_deg
    );
}

/// `normal-ops-orbit` (issue 19): the OBC says what it applies. With the orbital correction
/// on, 0x0801 "no orbit table" at t = 0, 0x0801 "catching up" when the one-hour-old state
/// arrives at 1 s, 0x0802 once it is caught up (46 cycles at 80 s of orbit per cycle), and
/// nothing more over 30 min; fine mode and the smoke test's 3σ bound (15″) as normal-ops.
/// A state 7 h old (beyond the 6-h catch-up) is refused on board: 0x0801 "invalid, gap too
/// large", never 0x0802, and the OBC flies on with annual aberration only.
#[test]
fn e2e_normal_ops_orbit_events_and_fallback() {
    use fsw_core::events::EventId;
    let events_of = |s: Scenario| {
        let mut sim = Simulation::new(s, None).unwrap();
        let mut out = Vec::new();
        let mut last = None;
        while let Some(r) = sim.step() {
            for e in &r.output.events {
                if matches!(
                    e.id,
                    EventId::OrbitalCorrectionUnavailable | EventId::OrbitalCorrectionApplied
                ) {
                    out.push((r.cycle, e.id, e.p1, e.p2));
                }
            }
            last = Some(r);
        }
        (out, last.unwrap())
    };
    let (events, last) = events_of(scenario("normal-ops-orbit", 1800.0));
    eprintln!("normal-ops-orbit events: {events:?}");
    assert_eq!(events.len(), 3, "{events:?}");
    assert_eq!(
        (events[0].0, events[0].1, events[0].2),
        (0, EventId::OrbitalCorrectionUnavailable, 0)
    );
    assert_eq!(
        (events[1].0, events[1].1, events[1].2),
        (1, EventId::OrbitalCorrectionUnavailable, 1)
    );
    assert_eq!(events[2].1, EventId::OrbitalCorrectionApplied);
    assert_eq!(events[2].0, 46);
    assert!((3600..3700).contains(&events[2].2), "age {} s", events[2].2);
    assert_eq!(last.output.housekeeping.filter_mode, 2);

    let sum = run(scenario("normal-ops-orbit", 1800.0), &RunOptions::default()).unwrap();
    for k in 0..3 {
        assert!(sum.attitude_error_arcsec.three_sigma[k] <= 15.0);
    }
    let orbit_tables: Vec<_> = sum
        .tables_loaded
        .iter()
        .filter(|t| t.table == "orbit")
        .collect();
    assert_eq!(orbit_tables.len(), 1);
    assert!(orbit_tables[0].accepted && orbit_tables[0].activated_at_s == Some(1.0));

    let mut stale = scenario("normal-ops-orbit", 600.0);
    if let Some(o) = stale.onboard_orbit.as_mut() {
        o.state_age_s = 7.0 * 3600.0;
    }
    let (events, last) = events_of(stale);
    eprintln!("7-h-old state: {events:?}");
    assert!(events
        .iter()
        .all(|e| e.1 == EventId::OrbitalCorrectionUnavailable));
    assert_eq!(events.last().map(|e| (e.2, e.3)), Some((3, 2)));
    assert_eq!(events.len(), 2, "{events:?}");
    assert_eq!(last.output.housekeeping.filter_mode, 2);
}

/// The OBC's wheel momentum against the truth's through the torque-limited slews of
/// `gro-early-mission` (its first three): with the tachometers it is the measured one (to the
/// 0.1-rpm words and their noise) after every cycle; with them off the OBC counts its own
/// commands, which the wheels do not deliver on a torque-limited slew, and the count drifts
/// (docs/magnetics.md §7). With one tachometer lost the others stay measured and the lost
/// wheel is carried on with its share of the commands. Each change of source is an event
/// 0x0A03.
#[test]
fn obc_wheel_momentum_follows_the_tachometers_through_slews() {
    use fsw_core::events::EventId;
    use fsw_core::unloading::MomentumSource;
    let fly = |tachometers: bool, fault: Option<&str>| {
        let mut s = scenario("gro-early-mission", 6_000.0);
        s.wheel_tachometers.enabled = tachometers;
        s.faults.extend(fault.map(|f| toml::from_str(f).unwrap()));
        let mut sim = Simulation::new(s, None).unwrap();
        let (mut worst, mut source_events) = (0.0_f64, Vec::new());
        loop {
            let truth = sim.true_wheel_momentum_acs_nms();
            let Some(rec) = sim.step() else { break };
            let obc = sim.fsw().unloading().wheel_momentum_acs_nms();
            worst = worst.max((obc - truth).norm());
            for e in &rec.output.events {
                if e.id == EventId::WheelMomentumSourceChanged {
                    source_events.push((rec.cycle, e.p1));
                }
            }
        }
        (worst, source_events, sim.fsw().unloading().source())
    };
    let (with, events_with, source) = fly(true, None);
    let (without, events_without, _) = fly(false, None);
    // Wheel 2's tachometer lost over the first slew (1,200 s): the count takes over from the
    // last measured value, then the tachometers again.
    let lost =
        "kind = \"tachometer_failed\"\nsensor = \"rwa2\"\nat_s = 1000.0\nduration_s = 2000.0";
    let (with_fault, events_fault, _) = fly(true, Some(lost));
    eprintln!(
        "gro-early-mission, 6,000 s (3 slews): largest |h_obc − h_true| {with:.4} N·m·s with the tachometers, {without:.2} counting commands, {with_fault:.2} with wheel 2's tachometer lost over the first slew"
    );
    assert!(with < 0.05, "{with}");
    assert!(
        without > 5.0,
        "the command count should drift on the slews: {without}"
    );
    assert_eq!(source, MomentumSource::Tachometers);
    assert_eq!(events_with, vec![(0, 1)], "one event at the first frame");
    assert!(events_without.is_empty(), "{events_without:?}");
    assert_eq!(events_fault, vec![(0, 1), (1000, 2), (3000, 1)]);
    // The lost wheel carried on with its share of the commands: it drifts only when that
    // wheel clips (measured 0.03 N·m·s; 18.6 when the whole count took over).
    assert!(with_fault < 1.0, "{with_fault}");
}

/// The torquer bars unload the wheels in the closed loop (issue 20): three hours of
/// `normal-ops` with the OBC's cross-product law keep every wheel below 100 N·m·s, where the
/// same hours without unloading drive one to its 250 N·m·s limit. A sign error anywhere
/// between the law, the OBC's wheel momentum (tachometers) and the truth's m × B fails here (the unit
/// tests check the law only against its own formula).
#[test]
fn torquer_bars_keep_the_wheels_bounded() {
    use sim_harness::truth::dynamics::MomentumUnloading;
    let bars = scenario("normal-ops", 10_800.0);
    assert_eq!(bars.dynamics.momentum_unloading, MomentumUnloading::Bars);
    let mut off = bars.clone();
    off.dynamics.momentum_unloading = MomentumUnloading::Off;
    let with = run(bars, &RunOptions::default())
        .unwrap()
        .max_wheel_momentum_nms;
    let without = run(off, &RunOptions::default())
        .unwrap()
        .max_wheel_momentum_nms;
    eprintln!("3 h of normal-ops: largest wheel momentum {with:.1} N·m·s with the bars, {without:.1} without unloading");
    assert!(with < 100.0, "{with}");
    assert!(without > 200.0, "{without}");
}
