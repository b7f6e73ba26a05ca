//! Print the per-cycle attitude error of a fault scenario (with and without its faults)
//! every N seconds: `cargo run --release -p sim-harness --example fault_trace -- FILE [N]`.
use sim_harness::closed_loop::Simulation;
use sim_harness::scenario::resolve;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let s = resolve(args.get(1).map_or("normal-ops", String::as_str))?;
    let every: u64 = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(100);
    let mut clean = s.clone();
    clean.faults.clear();
    let mut a = Simulation::new(s, None)?;
    let mut b = Simulation::new(clean, None)?;
    while let (Some(ra), Some(rb)) = (a.step(), b.step()) {
        for e in &ra.output.events {
            println!("{:>7.0} event {:?} {} {}", ra.truth.t_s, e.id, e.p1, e.p2);
        }
        if ra.cycle % every == 0 {
            let ea = ra.attitude_error_acs_rad * fsw_core::units::ARCSEC_PER_RAD;
            let eb = rb.attitude_error_acs_rad * fsw_core::units::ARCSEC_PER_RAD;
            let hk = &ra.output.housekeeping;
            println!(
                "{:>7.0} fault [{:7.1} {:7.1} {:7.1}] mode {} ctl {} res {:?} | clean [{:7.1} {:7.1} {:7.1}] mode {}",
                ra.truth.t_s, ea.x, ea.y, ea.z, hk.filter_mode, hk.control_mode,
                hk.residuals.iter().map(|r| r.status as u8).collect::<Vec<_>>(),
                eb.x, eb.y, eb.z, rb.output.housekeeping.filter_mode
            );
        }
    }
    Ok(())
}
