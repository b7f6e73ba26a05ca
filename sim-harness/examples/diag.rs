//! Diagnostic trace of a closed-loop run: args SCENARIO [duration_s] [every_n_cycles]; prints
//! events and, every n cycles, filter/control modes, δθ, filter σ, NEES and residuals.
use sim_harness::closed_loop::Simulation;
use sim_harness::scenario;
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let mut s = scenario::resolve(&args[1]).unwrap();
    if let Some(d) = args.get(2) {
        s.duration_s = d.parse().unwrap();
    }
    let every: u64 = args.get(3).map_or(30, |x| x.parse().unwrap());
    let mut sim = Simulation::new(s, None).unwrap();
    while let Some(r) = sim.step() {
        let hk = &r.output.housekeeping;
        for e in &r.output.events {
            println!("  t={} event {:?} {} {}", r.truth.t_s, e.id, e.p1, e.p2);
        }
        if r.cycle % every != 0 {
            continue;
        }
        let e = r.attitude_error_acs_rad * 206264.8;
        let p = hk.covariance_diag;
        let st: Vec<String> = hk
            .residuals
            .iter()
            .map(|x| {
                format!(
                    "{}:{:.0},{:.0}",
                    x.status as u8, x.innovation_arcsec[0], x.innovation_arcsec[1]
                )
            })
            .collect();
        println!("t={:6} fm={} cm={} err=[{:7.1} {:7.1} {:7.1}] sig=[{:5.1} {:5.1} {:5.1}] nees={:7.1} {} fhst flags {} {} fss {} {}", r.truth.t_s, hk.filter_mode, hk.control_mode, e.x, e.y, e.z,
            p[0].sqrt()*206264.8, p[1].sqrt()*206264.8, p[2].sqrt()*206264.8, r.nees.unwrap_or(0.0), st.join(" "), r.frame.fhst[0].flags, r.frame.fhst[1].flags, r.frame.fss[0].flags, r.frame.fss[1].flags);
    }
}
