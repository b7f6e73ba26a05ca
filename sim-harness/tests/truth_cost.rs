//! Cost of one cycle of the truth and sensor models (no flight software), and a smoke test
//! that the models run together over a slew: the FHSTs track stars, the FSSs see the Sun,
//! the IRU counts. The closed loop aims at ≥ 50 000× real time at a 1 s step, i.e. ≤ 20 µs
//! per cycle for everything; this prints the truth+sensor share.

use fsw_core::attitude::Quat;
use fsw_core::raw::{FHST_FLAG_NEW_STAR, FHST_FLAG_VALID, FSS_FLAG_SUN_ALPHA};
use nalgebra::Vector3;
use sim_harness::data::data_dir;
use sim_harness::paper::PaperFacts;
use sim_harness::sensors::fhst::{Fhst, FhstParams};
use sim_harness::sensors::fss::{Fss, FssParams};
use sim_harness::sensors::iru::{Iru, IruParams};
use sim_harness::sensors::thermal::{ThermalNode, ThermalParams};
use sim_harness::sensors::TruthSnapshot;
use sim_harness::truth::dynamics::{DynamicsParams, RigidBody};
use sim_harness::truth::orbit::{Orbit, OrbitParams};
use sim_harness::truth::sky::{Sky, SkyParams};
use sim_harness::truth::sun::SunEphemeris;
use sim_harness::truth::time::{epoch_from_iso, SimClock};

#[test]
fn regress_truth_and_sensor_cycle_cost() {
    let paper = PaperFacts::load().unwrap();
    let clock = SimClock::new(epoch_from_iso("1991-04-07T22:37:00Z").unwrap());
    let sky = Sky::load(
        &data_dir().join("hipparcos_mag6p5.csv"),
        &SkyParams::default(),
    )
    .unwrap();
    let mut orbit = Orbit::new(&OrbitParams {
        raan_deg: 120.0,
        ..OrbitParams::default()
    });
    let mut sun = SunEphemeris::new(clock.j2000_tt_s(0.0), 600.0);
    // A slow tumble so the trackers see many stars and the FSSs see the Sun sometimes.
    let mut body = RigidBody::new(
        &DynamicsParams::default(),
        Quat::IDENTITY,
        Vector3::new(0.002, -0.003, 0.001),
    )
    .unwrap();
    let mut fhst = [
        Fhst::new(0, FhstParams::default(), &paper, 1),
        Fhst::new(1, FhstParams::default(), &paper, 1),
    ];
    let mut fss = [
        Fss::new(0, FssParams::default(), &paper, 1),
        Fss::new(1, FssParams::default(), &paper, 1),
    ];
    let mut iru = Iru::new(IruParams::default(), &paper, 1).unwrap();
    let mut thermal: [ThermalNode; 5] =
        core::array::from_fn(|i| ThermalNode::new(ThermalParams::default_for_slot(i)));
    let n = 20_000_u32;
    let (mut valid, mut new_stars, mut sun_seen) = (0_u32, 0_u32, 0_u32);
    let start = std::time::Instant::now();
    for k in 0..n {
        let t = f64::from(k);
        orbit.advance_to(t);
        let o = *orbit.state();
        let j = clock.j2000_tt_s(t);
        let s = sun.state(j);
        let a = *body.state();
        let truth = TruthSnapshot {
            t_s: t,
            j2000_tt_s: j,
            q_acs_from_eci: a.q_acs_from_eci,
            m_acs_from_eci: a.q_acs_from_eci.to_dcm(),
            rate_acs_rad_per_s: a.rate_acs_rad_per_s,
            pos_eci_km: o.pos_eci_km,
            vel_eci_km_per_s: o.vel_eci_km_per_s,
            earth_pos_bary_eci_km: s.earth_pos_bary_eci_km,
            earth_vel_bary_eci_km_per_s: s.earth_vel_bary_eci_km_per_s,
            sun_dir_app_eci: s.apparent_dir_from_sc_eci(&o.pos_eci_km, &o.vel_eci_km_per_s),
            in_umbra: s.in_umbra(&o.pos_eci_km),
        };
        let mut dev = [0.0; 5];
        for (i, node) in thermal.iter_mut().enumerate() {
            node.update(
                1.0,
                &truth.pos_eci_km,
                &truth.sun_dir_app_eci,
                truth.in_umbra,
            );
            dev[i] = node.deviation_c();
        }
        for (i, f) in fhst.iter_mut().enumerate() {
            let out = f.sample(&truth, &sky, dev[i]);
            valid += u32::from(out.flags & FHST_FLAG_VALID != 0);
            new_stars += u32::from(out.flags & FHST_FLAG_NEW_STAR != 0);
        }
        for (i, f) in fss.iter_mut().enumerate() {
            sun_seen += u32::from(f.sample(&truth, dev[2 + i]).flags & FSS_FLAG_SUN_ALPHA != 0);
        }
        let report = body.step(1.0, &Vector3::zeros(), &o.pos_eci_km);
        iru.sample(&report.rate_integral_acs_rad, 1.0, t + 1.0, dev[4]);
    }
    let per_cycle_us = start.elapsed().as_secs_f64() / f64::from(n) * 1e6;
    eprintln!(
        "truth+sensors: {per_cycle_us:.2} µs/cycle (this profile), {valid} valid FHST samples, \
         {new_stars} acquisitions, {sun_seen} FSS Sun samples in {n} cycles"
    );
    assert!(new_stars > 20, "{new_stars}");
    assert!(valid > n / 4, "{valid}");
    assert!(sun_seen > 0);
    assert!(iru.total_pulses().iter().any(|p| p.abs() > 1000));
}
