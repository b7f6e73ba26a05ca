//! Filter consistency over time.
//!
//! `nees_trace SCENARIO [TABLES_DIR] [WINDOW_S] [--seed N] [--duration-s S] [--quiet]`
//!
//! Per window (unless `--quiet`): the mean NEES, the RMS error, the mean filter σ and the mean
//! error per axis (arcsec, ACS), and the fraction of cycles with stars in 0/1/2 trackers.
//! Scored cycles are the steady ones of `summary.json` (t ≥ 600 s, not slewing, filter
//! initialised) in fine mode. The last line (`SUMMARY …`) gives over all scored cycles: the
//! NEES mean, median, p90, p99; the fraction of cycles whose error is within 3σ on each ACS
//! axis (`contain3`); the error 3×RMS per axis (`3rms`, arcsec); and the wrong-star count
//! (identifications whose catalog star is not the one the truth tracker follows).
use sim_harness::closed_loop::Simulation;
use sim_harness::scenario;

const ARCSEC_PER_RAD: f64 = 206_264.806_247_096_36;

#[derive(Default)]
struct Window {
    nees: f64,
    n: usize,
    sq: [f64; 3],
    sig: [f64; 3],
    trackers: [usize; 3],
    sum: [f64; 3],
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let mut positional = Vec::new();
    let mut seed: Option<u64> = None;
    let mut duration: Option<f64> = None;
    let mut quiet = false;
    let mut i = 1;
    while i < args.len() {
        match args[i].as_str() {
            "--seed" => {
                i += 1;
                seed = Some(args[i].parse().expect("--seed N"));
            }
            "--duration-s" => {
                i += 1;
                duration = Some(args[i].parse().expect("--duration-s S"));
            }
            "--quiet" => quiet = true,
            a => positional.push(a.to_owned()),
        }
        i += 1;
    }
    let mut s = scenario::resolve(&positional[0]).unwrap();
    if let Some(seed) = seed {
        s.seed = seed;
    }
    if let Some(d) = duration {
        s.duration_s = d;
    }
    let tables = positional
        .get(1)
        .filter(|a| !a.is_empty())
        .map(std::path::PathBuf::from);
    let window: f64 = positional.get(2).map_or(600.0, |x| x.parse().unwrap());
    let mut sim = Simulation::new(s, tables.as_deref()).unwrap();
    let mut w = Window::default();
    let mut w_start = 0.0;
    let mut all_nees: Vec<f64> = Vec::new();
    let mut inside = [0usize; 3];
    let mut sq_all = [0.0f64; 3];
    let mut identified = 0usize;
    let mut wrong = 0usize;
    let mut stale = 0usize;
    let mut last_counters = fsw_core::events::Counters::default();
    while let Some(r) = sim.step() {
        let hk = &r.output.housekeeping;
        last_counters = hk.counters;
        let t = r.truth.t_s;
        // Wrong-star rate: every identification event against the truth's tracked star.
        for e in &r.output.events {
            if e.id == fsw_core::events::EventId::StarIdentified {
                identified += 1;
                let tracker = e.p1 as usize;
                if let Some(true_id) = sim.tracked_star_id(tracker) {
                    if true_id != e.p2 {
                        wrong += 1;
                    }
                }
            }
        }
        // Updates with a star other than the one tracked (a stale association).
        for (k, res) in hk.residuals.iter().take(2).enumerate() {
            let used = matches!(
                res.status,
                fsw_core::telemetry::MeasurementStatus::Accepted
                    | fsw_core::telemetry::MeasurementStatus::Gated
            );
            if used && sim.tracked_star_id(k).is_some_and(|h| h != res.star_id) {
                stale += 1;
            }
        }
        if t - w_start >= window {
            if w.n > 0 && !quiet {
                let n = w.n as f64;
                println!(
                    "t={:6.0} n={:4} nees={:8.1} rms=[{:5.1} {:5.1} {:5.1}] sig=[{:5.1} {:5.1} {:5.1}] mean=[{:6.1} {:6.1} {:6.1}] trackers0/1/2={:.2}/{:.2}/{:.2}",
                    w_start, w.n, w.nees / n,
                    (w.sq[0] / n).sqrt(), (w.sq[1] / n).sqrt(), (w.sq[2] / n).sqrt(),
                    w.sig[0] / n, w.sig[1] / n, w.sig[2] / n,
                    w.sum[0] / n, w.sum[1] / n, w.sum[2] / n,
                    w.trackers[0] as f64 / n, w.trackers[1] as f64 / n, w.trackers[2] as f64 / n
                );
            }
            w = Window::default();
            w_start = t;
        }
        if t < 600.0 || hk.control_mode == 2 || hk.filter_mode != 2 {
            continue;
        }
        let Some(nees) = r.nees else { continue };
        all_nees.push(nees);
        let e = r.attitude_error_acs_rad * ARCSEC_PER_RAD;
        w.nees += nees;
        w.n += 1;
        for i in 0..3 {
            let sig = hk.covariance_diag[i].sqrt() * ARCSEC_PER_RAD;
            w.sq[i] += e[i] * e[i];
            w.sig[i] += sig;
            w.sum[i] += e[i];
            sq_all[i] += e[i] * e[i];
            if e[i].abs() <= 3.0 * sig {
                inside[i] += 1;
            }
        }
        let k = r.frame.fhst.iter().filter(|f| f.flags & 1 != 0).count();
        w.trackers[k.min(2)] += 1;
    }
    let counters = last_counters;
    let n = all_nees.len().max(1) as f64;
    all_nees.sort_by(|a, b| a.partial_cmp(b).unwrap());
    let q = |p: f64| {
        all_nees
            .get(((all_nees.len().max(1) - 1) as f64 * p) as usize)
            .copied()
            .unwrap_or(f64::NAN)
    };
    println!(
        "SUMMARY cycles {} nees_mean {:.2} median {:.2} p90 {:.2} p99 {:.2} contain3 {:.4} {:.4} {:.4} 3rms {:.1} {:.1} {:.1} stars_identified {} wrong_stars {} wrong_star_cycles {} unmatched {} ambiguous {}",
        all_nees.len(),
        all_nees.iter().sum::<f64>() / n,
        q(0.5),
        q(0.9),
        q(0.99),
        inside[0] as f64 / n,
        inside[1] as f64 / n,
        inside[2] as f64 / n,
        3.0 * (sq_all[0] / n).sqrt(),
        3.0 * (sq_all[1] / n).sqrt(),
        3.0 * (sq_all[2] / n).sqrt(),
        identified,
        wrong,
        stale,
        counters.star_id_unmatched,
        counters.star_id_ambiguous,
    );
}
