//! Filter consistency over time: args SCENARIO [tables_dir] [window_s]; per window, the mean
//! NEES, the RMS error and the mean filter σ per axis (arcsec), and the fraction of cycles
//! with stars in 0/1/2 trackers. Only steady cycles (t ≥ 600 s, not slewing, fine mode).
use sim_harness::closed_loop::Simulation;
use sim_harness::scenario;
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let s = scenario::resolve(&args[1]).unwrap();
    let tables = args
        .get(2)
        .filter(|a| !a.is_empty())
        .map(std::path::PathBuf::from);
    let window: f64 = args.get(3).map_or(600.0, |x| x.parse().unwrap());
    let mut sim = Simulation::new(s, tables.as_deref()).unwrap();
    let mut acc = (
        0.0,
        0usize,
        [0.0f64; 3],
        [0.0f64; 3],
        [0usize; 3],
        [0.0f64; 3],
    );
    let mut w_start = 0.0;
    let mut all_nees: Vec<f64> = Vec::new();
    while let Some(r) = sim.step() {
        let hk = &r.output.housekeeping;
        let t = r.truth.t_s;
        if t - w_start >= window {
            if acc.1 > 0 {
                let n = acc.1 as f64;
                println!(
                    "t={:6.0} n={:4} nees={:8.1} rms=[{:5.1} {:5.1} {:5.1}] sig=[{:5.1} {:5.1} {:5.1}] mean=[{:6.1} {:6.1} {:6.1}] trackers0/1/2={:.2}/{:.2}/{:.2}",
                    w_start, acc.1, acc.0 / n,
                    (acc.2[0] / n).sqrt(), (acc.2[1] / n).sqrt(), (acc.2[2] / n).sqrt(),
                    acc.3[0] / n, acc.3[1] / n, acc.3[2] / n,
                    acc.5[0] / n, acc.5[1] / n, acc.5[2] / n,
                    acc.4[0] as f64 / n, acc.4[1] as f64 / n, acc.4[2] as f64 / n
                );
            }
            acc = (0.0, 0, [0.0; 3], [0.0; 3], [0; 3], [0.0; 3]);
            w_start = t;
        }
        if t < 600.0 || hk.control_mode == 2 || hk.filter_mode != 2 {
            continue;
        }
        let Some(nees) = r.nees else { continue };
        all_nees.push(nees);
        let e = r.attitude_error_acs_rad * 206264.8;
        acc.0 += nees;
        acc.1 += 1;
        for i in 0..3 {
            acc.2[i] += e[i] * e[i];
            acc.3[i] += hk.covariance_diag[i].sqrt() * 206264.8;
            acc.5[i] += e[i];
        }
        let k = r.frame.fhst.iter().filter(|f| f.flags & 1 != 0).count();
        acc.4[k.min(2)] += 1;
    }
    all_nees.sort_by(|a, b| a.partial_cmp(b).unwrap());
    let q = |p: f64| all_nees[((all_nees.len() - 1) as f64 * p) as usize];
    println!(
        "NEES cycles {} mean {:.1} median {:.1} p90 {:.1} p99 {:.1}",
        all_nees.len(),
        all_nees.iter().sum::<f64>() / all_nees.len() as f64,
        q(0.5),
        q(0.9),
        q(0.99)
    );
}
