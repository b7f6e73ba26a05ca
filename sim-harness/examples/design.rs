#![allow(clippy::needless_range_loop)]
//! Scenario design aid: for a Sun position in an FSS (args: t_s fss(0=FSS1,1=FSS2) alpha beta,
//! epoch from $EPOCH), sweep the roll about the Sun line and print FHST Sun angles, trackable
//! stars, Earth-limb clear fractions and the attitude quaternion.
use fsw_core::attitude::{rot, Quat};
use nalgebra::{Matrix3, Vector3};
use sim_harness::data::{CsvTable, HIPPARCOS_CSV};
use sim_harness::paper::PaperFacts;
use sim_harness::truth::orbit::{Orbit, OrbitParams};
use sim_harness::truth::sky::{ExclusionParams, Sky, SkyParams};
use sim_harness::truth::sun::sun_state;
use sim_harness::truth::time::{epoch_from_iso, SimClock};

fn sensor_dir(a: f64, b: f64) -> Vector3<f64> {
    Vector3::new(a.to_radians().tan(), b.to_radians().tan(), 1.0).normalize()
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let t_s: f64 = args.get(1).map_or(0.0, |s| s.parse().unwrap());
    let fss: usize = args.get(2).map_or(0, |s| s.parse().unwrap());
    let al: f64 = args.get(3).map_or(0.0, |s| s.parse().unwrap());
    let be: f64 = args.get(4).map_or(0.0, |s| s.parse().unwrap());
    let paper = PaperFacts::load().unwrap();
    let clock = SimClock::new(
        epoch_from_iso(&std::env::var("EPOCH").unwrap_or("1991-04-09T00:00:00Z".into())).unwrap(),
    );
    let sun = sun_state(clock.j2000_tt_s(t_s)).apparent_dir_geocentric_eci();
    let sky = Sky::from_csv(
        &CsvTable::parse(HIPPARCOS_CSV, "h").unwrap(),
        &SkyParams::default(),
    )
    .unwrap();
    let mut orbit = Orbit::new(&OrbitParams {
        raan_deg: 120.0,
        ..OrbitParams::default()
    });
    let m_fss = paper.prelaunch(2 + fss);
    let s_b = (m_fss * sensor_dir(al, be)).normalize();
    let sun = sun.normalize();
    // A0: maps sun -> s_b minimal rotation (as DCM with b = A r)
    let axis = sun.cross(&s_b);
    let ang = sun.dot(&s_b).clamp(-1.0, 1.0).acos();
    // Rot(θ) passive: b = Rot(θ) r ; for active rotation of the vector r onto s_b we need Rot(-θ e)
    let a0 = {
        let c = rot(&(-axis.normalize() * ang));
        if (c * sun - s_b).norm() < 1e-6 {
            c
        } else {
            rot(&(axis.normalize() * ang))
        }
    };
    assert!((a0 * sun - s_b).norm() < 1e-6);
    let fhst = [paper.prelaunch(0), paper.prelaunch(1)];
    let excl = ExclusionParams::default();
    for roll in (0..360).step_by(15) {
        let a = a0 * rot(&(sun * (roll as f64).to_radians()));
        let mut line = format!("roll {roll:3}: ");
        let mut ok = true;
        let mut clear = [[false; 96]; 2];
        for (k, m) in fhst.iter().enumerate() {
            let b = a.transpose() * m.column(2);
            let sang = b.dot(&sun).acos().to_degrees();
            let mut n = 0;
            let mfe = m.transpose() * a;
            sky.for_each_in_cone(&b.into_owned(), 6.0f64.to_radians(), |_, st| {
                if (2.0..=5.7).contains(&st.magnitude) {
                    let s = mfe * st.dir_cat_eci;
                    if s.z > 0.0
                        && (s.x / s.z).atan().abs() < 4f64.to_radians()
                        && (s.y / s.z).atan().abs() < 4f64.to_radians()
                    {
                        n += 1;
                    }
                }
            });
            for j in 0..96 {
                orbit.advance_to(t_s + j as f64 * 60.0);
                let pos = orbit.state().pos_eci_km;
                clear[k][j] = excl.is_clear(&b.into_owned(), &sun, &pos);
            }
            let frac = clear[k].iter().filter(|c| **c).count();
            line += &format!(
                "FHST{} sun {sang:5.1} stars {n:2} clear {frac:2}/96 | ",
                k + 1
            );
            ok &= sang > 50.0 && n >= 3;
        }
        let union = (0..96).filter(|j| clear[0][*j] || clear[1][*j]).count();
        // longest gap
        let mut gap = 0;
        let mut cur = 0;
        for j in 0..192 {
            if clear[0][j % 96] || clear[1][j % 96] {
                cur = 0
            } else {
                cur += 1;
                gap = gap.max(cur)
            }
        }
        line += &format!("union {union}/96 gap {gap} min");
        let q = Quat::from_dcm(&a).canonical();
        // sun in the other FSS
        let o = paper.prelaunch(3 - fss).transpose() * (a * sun);
        line += &format!(
            " | other FSS a/b {:6.1} {:6.1} | q [{:.6}, {:.6}, {:.6}, {:.6}] {}",
            o.x.atan2(o.z).to_degrees(),
            o.y.atan2(o.z).to_degrees(),
            q.x,
            q.y,
            q.z,
            q.w,
            if ok { "OK" } else { "" }
        );
        println!("{line}");
    }
    let _ = Matrix3::<f64>::identity();
}
