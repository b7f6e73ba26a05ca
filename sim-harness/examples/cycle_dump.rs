//! Per-cycle dump for filter debugging: args SCENARIO TABLES_DIR T0 T1 [EVERY] [--seed N];
//! prints t, filter and control modes, each sensor's residual status and innovation (″), the
//! error and σ (″). The seed must be the one the tables were calibrated on (the truth's
//! misalignments and noise draws follow it).
use sim_harness::closed_loop::Simulation;
use sim_harness::scenario;
fn main() {
    let mut a: Vec<String> = std::env::args().collect();
    let seed = a.iter().position(|x| x == "--seed").map(|i| {
        let n: u64 = a[i + 1].parse().expect("--seed N");
        a.drain(i..=i + 1);
        n
    });
    let mut s = scenario::resolve(&a[1]).unwrap();
    if let Some(seed) = seed {
        s.seed = seed;
    }
    let tables = Some(a[2].as_str())
        .filter(|x| !x.is_empty())
        .map(std::path::PathBuf::from);
    let t0: f64 = a[3].parse().unwrap();
    let t1: f64 = a[4].parse().unwrap();
    let every: u64 = a.get(5).map_or(1, |x| x.parse().unwrap());
    let mut sim = Simulation::new(s, tables.as_deref()).unwrap();
    while let Some(r) = sim.step() {
        let t = r.truth.t_s;
        if t < t0 || r.cycle % every != 0 {
            continue;
        }
        if t > t1 {
            break;
        }
        let hk = &r.output.housekeeping;
        let e = r.attitude_error_acs_rad * 206_264.8;
        let sig: Vec<f64> = (0..3)
            .map(|i| hk.covariance_diag[i].sqrt() * 206_264.8)
            .collect();
        let res: Vec<String> = hk
            .residuals
            .iter()
            .map(|x| {
                format!(
                    "{:?}({:.0},{:.0})",
                    x.status, x.innovation_arcsec[0], x.innovation_arcsec[1]
                )
            })
            .collect();
        let ev: Vec<String> = r
            .output
            .events
            .iter()
            .map(|e| format!("{:?}:{}:{}", e.id, e.p1, e.p2))
            .collect();
        println!(
            "t={t:.0} fm={} cm={} err=[{:.1} {:.1} {:.1}] sig=[{:.1} {:.1} {:.1}] nees={:.1} {} {}",
            hk.filter_mode,
            hk.control_mode,
            e.x,
            e.y,
            e.z,
            sig[0],
            sig[1],
            sig[2],
            r.nees.unwrap_or(f64::NAN),
            res.join(" "),
            ev.join(" ")
        );
    }
}
