//! Developer check: what the truth's FSS transfer-function error does to FFCAL's FSS2
//! alignment. For every FSS2 Sun sample of a run it evaluates the scenario's transfer-function
//! error at the Sun position, groups the samples by FFCAL's 1° cells, and solves the FSS2
//! rotation those errors alone produce through FFCAL's Sun–star dot products with the
//! per-cell deweighting (n = all samples of the cell, as `alignment_data` does, and n = the
//! samples at epochs with an identified star, which are the ones used).
//!
//! ```text
//! cargo run --release -p tests --example fss2_tf_check -- RUN_DIR SCENARIO
//! ```
use fsw_core::tables::types::{AlignmentTable, IruTable};
use fsw_core::units::ARCSEC_PER_RAD;
use ground_tool::pipeline::calibrate::{load_catalog, read_run, CalibrateOptions};
use ground_tool::pipeline::observations::build_observations;
use nalgebra::{Matrix3, Vector3};
use std::collections::BTreeMap;
use std::path::Path;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let (tm, md) = read_run(Path::new(&args[1]))?;
    let scenario = sim_harness::scenario::resolve(&args[2])?;
    let p = scenario.fss2.clone();
    let sky = load_catalog()?;
    let table = AlignmentTable::prelaunch();
    let frames = build_observations(
        &tm,
        &table,
        &IruTable::prelaunch(),
        &md.sensors,
        &sky,
        &CalibrateOptions::default().identify,
    );
    let m2 = fsw_core::tables::types::matrix_from_rows(table.matrices()[3]);
    let dir = |a: f64, b: f64| Vector3::new(a.tan(), b.tan(), 1.0).normalize();
    let cell = |d: &Vector3<f64>| {
        (
            (d.x.atan2(d.z).to_degrees()).floor() as i64,
            (d.y.atan2(d.z).to_degrees()).floor() as i64,
        )
    };
    // per cell: n_all, n_used, Σ e (″, α β), first time
    let mut cells: BTreeMap<(i64, i64), (usize, usize, [f64; 2], f64)> = BTreeMap::new();
    struct Row {
        c: (i64, i64),
        g: Vector3<f64>,
        y: f64,
        star_var: f64,
    }
    let mut rows = Vec::new();
    let t0 = frames[0].time.seconds();
    for f in &frames {
        let Some(sun) = f.suns[1].as_deref() else {
            continue;
        };
        let s = sun.meas.dir_sensor;
        let (am, bm) = (s.x.atan2(s.z), s.y.atan2(s.z));
        let (at, bt) = (
            am - (p.alpha.apply(am, bm) - am),
            bm - (p.beta.apply(bm, am) - bm),
        );
        let e = s - dir(at, bt);
        let c = cell(&s);
        let stars: Vec<_> = f
            .stars
            .iter()
            .flatten()
            .filter(|st| st.identified.is_some())
            .collect();
        let entry = cells
            .entry(c)
            .or_insert((0, 0, [0.0; 2], f.time.seconds() - t0));
        entry.0 += 1;
        if !stars.is_empty() {
            entry.1 += 1;
            entry.2[0] += (am - at) * ARCSEC_PER_RAD;
            entry.2[1] += (bm - bt) * ARCSEC_PER_RAD;
        }
        let b = m2 * s;
        for st in stars {
            let a = st.meas.dir_acs;
            rows.push(Row {
                c,
                g: b.cross(&a),
                y: -(m2 * e).dot(&a) * ARCSEC_PER_RAD,
                star_var: (st.sigma_rad * ARCSEC_PER_RAD).powi(2),
            });
        }
    }
    println!("FSS2 cell (α, β °)  first t (s)  samples all / with a star  mean TF error α β (″)");
    for (c, (n, m, e, t)) in &cells {
        let mf = (*m).max(1) as f64;
        println!(
            "  ({:3}, {:3})  {:8.0}  {:6} / {:6}  {:6.1} {:6.1}",
            c.0,
            c.1,
            t,
            n,
            m,
            e[0] / mf,
            e[1] / mf
        );
    }
    let sys2 = md.sensors.fss_systematic_or_paper_arcsec().powi(2);
    let sig2 = md.sensors.fss_sigma_arcsec.powi(2);
    for (label, used_only, holds_only) in [
        (
            "n = all samples in the cell (as alignment_data)",
            false,
            false,
        ),
        ("n = samples at epochs with a star", true, false),
        ("hold cells only (≥ 200 samples)", false, true),
        ("slew cells only (< 200 samples)", false, false),
    ] {
        let slews_only = label.starts_with("slew");
        let mut n = Matrix3::zeros();
        let mut v = Vector3::zeros();
        for r in &rows {
            let big = cells[&r.c].0 >= 200;
            if (holds_only && !big) || (slews_only && big) {
                continue;
            }
            let (na, nu, _, _) = cells[&r.c];
            let nn = if used_only { nu } else { na } as f64;
            let w = 1.0 / (sig2 + nn * sys2 + r.star_var);
            n += r.g * r.g.transpose() * w;
            v += r.g * r.y * w;
        }
        let phi = n.try_inverse().unwrap_or_else(Matrix3::zeros) * v;
        let sd = n
            .try_inverse()
            .unwrap_or_else(Matrix3::zeros)
            .diagonal()
            .map(f64::sqrt);
        println!(
            "TF alone, {label}: [{:.1}, {:.1}, {:.1}]″ (σ if the cells were independent [{:.0}, {:.0}, {:.0}]″)",
            phi.x, phi.y, phi.z, sd.x, sd.y, sd.z
        );
    }
    Ok(())
}
