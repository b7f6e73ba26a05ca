//! Scenario design aid: brute-force roll search with the closed loop. Args: epoch raan
//! fss(0=FSS1,1=FSS2) alpha_deg beta_deg duration_s [t0_s] [extra TOML]. For each of 24 rolls
//! about the Sun line, flies the attitude and prints rms/max error, NEES, fine-mode fraction.
use fsw_core::attitude::{rot, Quat};
use nalgebra::Vector3;
use sim_harness::closed_loop::Simulation;
use sim_harness::paper::PaperFacts;
use sim_harness::scenario::Scenario;
use sim_harness::truth::sun::sun_state;
use sim_harness::truth::time::{epoch_from_iso, SimClock};
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let epoch = &a[1];
    let raan: f64 = a[2].parse().unwrap();
    let fss: usize = a[3].parse().unwrap();
    let al: f64 = a[4].parse().unwrap();
    let be: f64 = a[5].parse().unwrap();
    let dur: f64 = a[6].parse().unwrap();
    let t0: f64 = a.get(7).map_or(0.0, |x| x.parse().unwrap());
    let extra = a.get(8).cloned().unwrap_or_default();
    let paper = PaperFacts::load().unwrap();
    let clock = SimClock::new(epoch_from_iso(epoch).unwrap());
    let sun = sun_state(clock.j2000_tt_s(t0))
        .apparent_dir_geocentric_eci()
        .normalize();
    let s_b = (paper.prelaunch(2 + fss)
        * Vector3::new(al.to_radians().tan(), be.to_radians().tan(), 1.0).normalize())
    .normalize();
    let axis = sun.cross(&s_b).normalize();
    let ang = sun.dot(&s_b).clamp(-1.0, 1.0).acos();
    let c = rot(&(-axis * ang));
    let a0 = if (c * sun - s_b).norm() < 1e-6 {
        c
    } else {
        rot(&(axis * ang))
    };
    for roll in (0..360).step_by(15) {
        let m = a0 * rot(&(sun * (roll as f64).to_radians()));
        let q = Quat::from_dcm(&m).canonical();
        let mut worst_sun: f64 = 180.0;
        for k in 0..2 {
            let b = m.transpose() * paper.prelaunch(k).column(2);
            worst_sun = worst_sun.min(b.dot(&sun).acos().to_degrees());
        }
        let text = format!("name=\"s\"\nepoch_utc=\"{epoch}\"\nduration_s={dur}\n{extra}\n[initial]\nq_acs_from_eci=[{},{},{},{}]\n[orbit]\nraan_deg={raan}\n", q.x, q.y, q.z, q.w);
        let s = Scenario::from_toml_str(&text, "s").unwrap();
        let mut sim = Simulation::new(s, None).unwrap();
        let (mut n, mut ss, mut mx, mut nees, mut fine) = (0.0, [0.0; 3], 0.0f64, 0.0, 0.0);
        while let Some(r) = sim.step() {
            if r.truth.t_s < 600.0 {
                continue;
            }
            let e = r.attitude_error_acs_rad * 206264.8;
            n += 1.0;
            for i in 0..3 {
                ss[i] += e[i] * e[i];
            }
            mx = mx.max(e.norm());
            nees += r.nees.unwrap_or(0.0);
            if r.output.housekeeping.filter_mode == 2 {
                fine += 1.0;
            }
        }
        println!("roll {roll:3} sun-fhst {worst_sun:5.1} rms [{:5.1} {:5.1} {:5.1}] max {mx:6.1} nees {:6.1} fine {:.2} q [{:.6}, {:.6}, {:.6}, {:.6}]", (ss[0]/n).sqrt(), (ss[1]/n).sqrt(), (ss[2]/n).sqrt(), nees / n, fine / n, q.x, q.y, q.z, q.w);
    }
}
