//! MEKF on synthetic FHST + IRU data with known truth.
//!
//! * Truth: a slow body rotation (5e-5 rad/s plus a 1e-5 rad/s limit cycle), integrated at
//!   10 Hz with the exact rotation per sub-step; in the second test also 30° slews at
//!   0.08°/s.
//! * IRU: the DRIRU II primary channels see `G⁻¹(ω + b + η_v)`, with the truth bias a random
//!   walk (σ_u) from a GRO-like start (~0.5″/s per axis), angle random walk σ_v, and integer
//!   pulses (0.05″ low rate, 0.8″ high rate during slews, the fraction carried across a
//!   switch) in 16-bit wrapping counters → [`IruIntegrator`].
//! * FHST1 and FHST2 (prelaunch alignments, boresights 90° apart) each track one star: placed
//!   at a random (H, V) at acquisition, tracked until it leaves ±3.8° or for 1–5 min, then a new
//!   one after one cycle of search. Each second: noise σ(m) for a random magnitude 2–5.7
//!   (8–24″), 7.78″ quantization, raw counts → [`fhst::measure`] →
//!   [`Mekf::update_focal_plane`] with σ from [`fhst::measurement_sigma_rad`].
//! * Filter: 1° initial attitude error, zero initial bias, table noise values, 1 Hz.

mod est_support;

use est_support::filter_truth::{
    attitude_nees, fhst_sample, in_field, new_track, prelaunch_trackers, propagate, start, wobble,
    TruthIru,
};
use est_support::Rng;
use fsw_core::attitude::{attitude_error_rad, Quat};
use fsw_core::fhst;
use fsw_core::tables::{FilterTable, IruTable};
use fsw_core::units::ARCSEC_PER_RAD;
use nalgebra::Vector3;

/// A slew of the truth: start time, axis (ACS), angle.
#[derive(Clone, Copy)]
struct Slew {
    start_s: f64,
    axis: Vector3<f64>,
    angle_rad: f64,
}

const SLEW_RATE: f64 = 0.08 * std::f64::consts::PI / 180.0;
const SLEW_RAMP_S: f64 = 60.0;

impl Slew {
    fn duration_s(&self) -> f64 {
        self.angle_rad / SLEW_RATE + SLEW_RAMP_S
    }
    /// Trapezoidal rate profile (ramps of SLEW_RAMP_S).
    fn rate(&self, t: f64) -> Vector3<f64> {
        let tau = t - self.start_s;
        let d = self.duration_s();
        if tau <= 0.0 || tau >= d {
            return Vector3::zeros();
        }
        let s = (tau / SLEW_RAMP_S).min(1.0).min((d - tau) / SLEW_RAMP_S);
        self.axis * (SLEW_RATE * s)
    }
    fn high_rate(&self, t: f64) -> bool {
        let tau = t - self.start_s;
        tau > -10.0 && tau < self.duration_s() + 10.0
    }
}

struct Stats {
    converged_at: Option<u32>,
    max_err_after_rad: f64,
    containment: [f64; 3],
    nees_mean: f64,
    final_sigma_rad: Vector3<f64>,
    bias_err: Vector3<f64>,
    bias_sigma: Vector3<f64>,
    bias_truth: Vector3<f64>,
    accepted: u32,
    gated: u32,
    other_rejections: u32,
    worst_nis: f64,
    high_rate_cycles: u32,
}

fn run(seed: u64, duration_s: u32, settle_s: u32, slews: &[Slew]) -> Stats {
    let filter_table = FilterTable::default_boot();
    let iru_table = IruTable::prelaunch();
    let (rows, ms) = prelaunch_trackers();
    let mut rng = Rng::new(seed);

    let substeps = 10;
    let dt = 1.0 / f64::from(substeps);
    let sigma_v = filter_table.arw_rad_per_sqrt_s;
    let sigma_u = filter_table.rrw_rad_per_s_sqrt_s;

    // Truth.
    let mut q_true = rng.quaternion();
    let mut bias = Vector3::new(2.9e-6, 1.7e-6, 2.5e-6);
    let omega0 = Vector3::new(0.3, -0.5, 0.8).normalize() * 5e-5;
    let mut gyro = TruthIru::primary(&iru_table, Vector3::new(1.0e-3, -2.0e-3, 0.5e-3));

    // Filter: 1° initial error about a skew axis.
    let err0 = Vector3::new(1.0, -1.0, 0.5).normalize() * 1.0_f64.to_radians();
    let (mut filter, mut iru) = start(&q_true, &err0, &mut gyro, &filter_table, &iru_table);
    let mut tracks = [0, 1].map(|i| new_track(&mut rng, &q_true.to_dcm(), &ms[i], 0));

    let mut inside = [0u32; 3];
    let mut samples = 0u32;
    let mut nees_sum = 0.0;
    let mut st = Stats {
        converged_at: None,
        max_err_after_rad: 0.0,
        containment: [0.0; 3],
        nees_mean: 0.0,
        final_sigma_rad: Vector3::zeros(),
        bias_err: Vector3::zeros(),
        bias_sigma: Vector3::zeros(),
        bias_truth: Vector3::zeros(),
        accepted: 0,
        gated: 0,
        other_rejections: 0,
        worst_nis: 0.0,
        high_rate_cycles: 0,
    };
    for k in 1..=duration_s {
        let t = f64::from(k);
        // Truth over one second.
        for j in 0..substeps {
            let ts = t - 1.0 + (f64::from(j) + 0.5) * dt;
            let w = omega0 + wobble(ts) + slews.iter().map(|s| s.rate(ts)).sum::<Vector3<f64>>();
            q_true = Quat::from_rotation_vector(&(w * dt))
                .compose(&q_true)
                .normalized();
            let noise = rng.gauss3() * (sigma_v / dt.sqrt());
            gyro.angle_rad += gyro.ginv * (w + bias + noise) * dt;
            bias += rng.gauss3() * (sigma_u * dt.sqrt());
        }

        // OBC cycle: IRU, propagation, two FHST updates.
        let high = slews.iter().any(|s| s.high_rate(t - 0.5));
        st.high_rate_cycles += u32::from(high);
        propagate(
            &mut filter,
            &mut iru,
            &mut gyro,
            high,
            &filter_table,
            &iru_table,
        );
        let a_true = q_true.to_dcm();
        for i in 0..2 {
            let m = &ms[i];
            let s = m.transpose() * (a_true * tracks[i].r_eci);
            let Some((h, v)) = in_field(&s) else {
                tracks[i] = new_track(&mut rng, &a_true, m, k);
                continue; // lost: the tracker searches for one cycle
            };
            if k >= tracks[i].ends_at_s {
                tracks[i] = new_track(&mut rng, &a_true, m, k);
                continue;
            }
            let sigma = filter_table.fhst_sigma_rad(tracks[i].magnitude);
            let sample = fhst_sample(&mut rng, &mut tracks[i], h, v, sigma);
            let meas = fhst::measure(&sample, &rows[i], &[0.0; 3]).unwrap();
            let sig = fhst::measurement_sigma_rad(meas.magnitude, &filter_table);
            let o = filter.update_focal_plane(
                meas.h_rad,
                meas.v_rad,
                &tracks[i].r_eci,
                m,
                sig,
                filter_table.gate_chi2,
            );
            if k > settle_s {
                st.worst_nis = st.worst_nis.max(o.nis);
            }
        }

        // Statistics.
        let e = attitude_error_rad(&q_true, &filter.q_acs_from_eci);
        let sig = filter.attitude_sigma_rad();
        if e.norm() * ARCSEC_PER_RAD > 30.0 {
            st.converged_at = None;
        } else if st.converged_at.is_none() {
            st.converged_at = Some(k);
        }
        if k > settle_s {
            samples += 1;
            for ax in 0..3 {
                if e[ax].abs() <= 3.0 * sig[ax] {
                    inside[ax] += 1;
                }
            }
            nees_sum += attitude_nees(&filter, &e);
            st.max_err_after_rad = st.max_err_after_rad.max(e.norm());
        }
    }
    st.containment = inside.map(|n| f64::from(n) / f64::from(samples));
    st.nees_mean = nees_sum / f64::from(samples);
    st.final_sigma_rad = filter.attitude_sigma_rad();
    st.bias_err = filter.bias_rad_per_s - bias;
    st.bias_sigma = filter.bias_sigma_rad_per_s();
    st.bias_truth = bias;
    st.accepted = filter.counters.accepted;
    st.gated = filter.counters.gated;
    st.other_rejections = filter.counters.other_rejections;
    let p = filter.covariance;
    assert!((p - p.transpose()).norm() == 0.0 && p.cholesky().is_some());
    st
}

fn report(name: &str, settle_s: u32, st: &Stats) {
    let a = ARCSEC_PER_RAD;
    println!("{name} (statistics after {settle_s} s):");
    println!(
        "  converged below 30\" (total) at t = {:?} s; max error after settling {:.2}\"; high-rate cycles {}",
        st.converged_at,
        st.max_err_after_rad * a,
        st.high_rate_cycles
    );
    println!(
        "  3-sigma containment per ACS axis: {:.2} % {:.2} % {:.2} %; mean NEES (3 dof, expect 3) {:.2}",
        100.0 * st.containment[0],
        100.0 * st.containment[1],
        100.0 * st.containment[2],
        st.nees_mean
    );
    println!(
        "  final attitude sigma {:.2}\" {:.2}\" {:.2}\"",
        st.final_sigma_rad.x * a,
        st.final_sigma_rad.y * a,
        st.final_sigma_rad.z * a
    );
    println!(
        "  bias truth {:.4} {:.4} {:.4} \"/s; error {:.2e} {:.2e} {:.2e} rad/s ({:.5} {:.5} {:.5} \"/s); filter sigma {:.2e} {:.2e} {:.2e} rad/s",
        st.bias_truth.x * a,
        st.bias_truth.y * a,
        st.bias_truth.z * a,
        st.bias_err.x,
        st.bias_err.y,
        st.bias_err.z,
        st.bias_err.x * a,
        st.bias_err.y * a,
        st.bias_err.z * a,
        st.bias_sigma.x,
        st.bias_sigma.y,
        st.bias_sigma.z
    );
    println!(
        "  updates: accepted {}, gated {} ({:.2} %), other rejections {}; worst NIS after settling {:.1}",
        st.accepted,
        st.gated,
        100.0 * f64::from(st.gated) / f64::from(st.accepted + st.gated),
        st.other_rejections,
        st.worst_nis
    );
}

#[test]
fn mekf_converges_is_consistent_and_estimates_the_bias() {
    let settle_s = 1800;
    let st = run(0xF117_E125, 4 * 3600, settle_s, &[]);
    report(
        "MEKF, inertial hold, 4 h at 1 Hz, 1 deg initial error",
        settle_s,
        &st,
    );
    assert!(
        st.converged_at.unwrap() < 600,
        "did not converge within 10 min"
    );
    for (ax, f) in st.containment.iter().enumerate() {
        assert!(
            *f >= 0.97,
            "axis {ax}: only {:.2} % inside 3 sigma",
            100.0 * f
        );
    }
    // Bias: within 3σ of the filter and within 1.5e-8 rad/s (0.003″/s, 0.5 % of the bias).
    for ax in 0..3 {
        assert!(
            st.bias_err[ax].abs() <= 3.0 * st.bias_sigma[ax],
            "bias axis {ax} outside 3 sigma"
        );
        assert!(
            st.bias_err[ax].abs() <= 1.5e-8,
            "bias axis {ax} error {:e}",
            st.bias_err[ax]
        );
    }
    assert_eq!(st.other_rejections, 0);
    assert!(f64::from(st.gated) < 0.01 * f64::from(st.accepted));
}

#[test]
fn mekf_stays_consistent_through_slews_with_high_rate_iru() {
    // Four 30° slews about different axes, one every 40 min, IRU in high rate around each.
    let axes = [
        Vector3::new(1.0, 0.0, 0.0),
        Vector3::new(0.0, 1.0, 0.0),
        Vector3::new(0.0, 0.0, -1.0),
        Vector3::new(0.6, -0.48, 0.64),
    ];
    let slews: Vec<Slew> = axes
        .iter()
        .enumerate()
        .map(|(i, a)| Slew {
            start_s: 1200.0 + 2400.0 * i as f64,
            axis: a.normalize(),
            angle_rad: 30.0_f64.to_radians(),
        })
        .collect();
    // Three seeds, containment pooled: the error is correlated over minutes, so one 3-h run
    // holds a few tens of independent samples and its containment alone varies by ±2 %
    // (measured with the filter table's gyro noise at the simulated gyro's, issue 19: 96.7,
    // 99.8, 100 % on axis y for these seeds; with the former table ARW, ten times the truth,
    // the filter was conservative and one seed sufficed). The threshold stays at 97 %.
    let settle_s = 600;
    let mut pooled = [0.0; 3];
    let seeds = [0x51E3_0002_u64, 0x51E3_0003, 0x51E3_0004];
    for seed in seeds {
        let st = run(seed, 3 * 3600, settle_s, &slews);
        report("MEKF, four 30 deg slews at 0.08 deg/s, 3 h", settle_s, &st);
        for (p, f) in pooled.iter_mut().zip(st.containment.iter()) {
            *p += f / seeds.len() as f64;
        }
        for ax in 0..3 {
            assert!(
                st.bias_err[ax].abs() <= 3.0 * st.bias_sigma[ax],
                "seed {seed:#x}: bias axis {ax} outside 3 sigma"
            );
        }
        assert!(st.max_err_after_rad * ARCSEC_PER_RAD < 20.0);
        assert_eq!(st.other_rejections, 0);
        assert!(f64::from(st.gated) < 0.01 * f64::from(st.accepted));
    }
    for (ax, f) in pooled.iter().enumerate() {
        assert!(
            *f >= 0.97,
            "axis {ax}: only {:.2} % inside 3 sigma (pooled)",
            100.0 * f
        );
    }
}
