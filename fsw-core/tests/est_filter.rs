//! MEKF on synthetic FHST + IRU data with known truth.
//!
//! * Truth: a slow body rotation (5e-5 rad/s plus a 1e-5 rad/s limit cycle), integrated at
//!   10 Hz with the exact rotation per sub-step.
//! * IRU: the DRIRU II primary channels see `G⁻¹(ω + b + η_v)`, with the truth bias a random
//!   walk (σ_u) from a GRO-like start (~0.5″/s per axis), angle random walk σ_v, and integer
//!   low-rate pulses (0.05″) in 16-bit wrapping counters → [`IruIntegrator`].
//! * FHST1 and FHST2 (prelaunch alignments, boresights 90° apart) each track one star: placed
//!   at a random (H, V) at acquisition, tracked until it leaves ±3.8° or for 1–5 min, then a new
//!   one. Each second: noise σ(m) for a random magnitude 2–5.7 (8–24″), 7.78″ quantization,
//!   raw counts → [`fhst::measure`] → [`Mekf::update_focal_plane`].
//! * Filter: 1° initial attitude error, zero initial bias, table noise values; 4 h at 1 Hz.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects
)]

mod est_support;

use est_support::Rng;
use fsw_core::attitude::{attitude_error_rad, Quat};
use fsw_core::fhst::{self, FHST_RAD_PER_COUNT};
use fsw_core::iru::{pulse_weight_rad, IruConfiguration, IruIntegrator};
use fsw_core::mekf::Mekf;
use fsw_core::raw::{
    FhstSample, IruSample, FHST_FLAG_NEW_STAR, FHST_FLAG_TRACKING, FHST_FLAG_VALID,
};
use fsw_core::tables::types::matrix_from_rows;
use fsw_core::tables::{AlignmentTable, FilterTable, IruTable};
use fsw_core::units::ARCSEC_PER_RAD;
use nalgebra::{Matrix3, Vector3};

/// Truth gyro: channel angles and pulse counters of the primary configuration.
struct TruthIru {
    ginv: Matrix3<f64>,
    angle_rad: Vector3<f64>,
    pulses: [i64; 3],
    weight_rad: f64,
}

impl TruthIru {
    fn sample(&mut self) -> IruSample {
        let mut counts = [0u16; 6];
        let ch = IruConfiguration::Primary.channels();
        for axis in 0..3 {
            let n = (self.angle_rad[axis] / self.weight_rad).floor() as i64;
            self.pulses[axis] = n;
            counts[ch[axis]] = n as u16; // wraps: the register is 16 bits
        }
        // Unused backup channels count too (not stuck), with arbitrary values.
        for (i, c) in [0usize, 3, 5].into_iter().enumerate() {
            counts[c] = (self.pulses[i] / 3) as u16;
        }
        IruSample {
            counts,
            channel_failed: 0,
            high_rate: false,
        }
    }
}

struct Track {
    r_eci: Vector3<f64>,
    magnitude: f64,
    ends_at_s: u32,
    new: bool,
}

fn new_track(rng: &mut Rng, a_true: &Matrix3<f64>, m: &Matrix3<f64>, now: u32) -> Track {
    let lim = 3.5_f64.to_radians();
    let s = fhst::dir_from_hv(rng.range(-lim, lim), rng.range(-lim, lim));
    Track {
        r_eci: a_true.transpose() * (m * s),
        magnitude: rng.range(2.0, 5.7),
        ends_at_s: now + 60 + (rng.next_u64() % 240) as u32,
        new: true,
    }
}

#[test]
fn mekf_converges_is_consistent_and_estimates_the_bias() {
    let filter_table = FilterTable::default_boot();
    let iru_table = IruTable::prelaunch();
    let al = AlignmentTable::prelaunch();
    let rows = [al.m_acs_from_fhst1, al.m_acs_from_fhst2];
    let ms = rows.map(|r| matrix_from_rows(&r));
    let mut rng = Rng::new(0xF117_E125);

    let duration_s: u32 = 4 * 3600;
    let substeps = 10;
    let dt = 1.0 / f64::from(substeps);
    let sigma_v = filter_table.arw_rad_per_sqrt_s;
    let sigma_u = filter_table.rrw_rad_per_s_sqrt_s;

    // Truth.
    let mut q_true = rng.quaternion();
    let mut bias = Vector3::new(2.9e-6, 1.7e-6, 2.5e-6);
    let omega0 = Vector3::new(0.3, -0.5, 0.8).normalize() * 5e-5;
    let mut gyro = TruthIru {
        ginv: IruConfiguration::Primary
            .g(&iru_table)
            .try_inverse()
            .unwrap(),
        angle_rad: Vector3::new(1.0e-3, -2.0e-3, 0.5e-3),
        pulses: [0; 3],
        weight_rad: pulse_weight_rad(false, &iru_table),
    };

    // Filter: 1° initial error about a skew axis.
    let err0 = Vector3::new(1.0, -1.0, 0.5).normalize() * 1.0_f64.to_radians();
    let mut filter = Mekf::new();
    filter
        .initialize(
            &Quat::from_rotation_vector(&(-err0)).compose(&q_true),
            &filter_table,
        )
        .unwrap();
    let mut iru = IruIntegrator::new();
    iru.process(&gyro.sample(), IruConfiguration::Primary, &iru_table);
    let mut tracks = [0, 1].map(|i| new_track(&mut rng, &q_true.to_dcm(), &ms[i], 0));

    let settle_s = 1800;
    let mut inside = [0u32; 3];
    let mut samples = 0u32;
    let mut nees_sum = 0.0;
    let mut max_err_after = 0.0_f64;
    let mut converged_at: Option<u32> = None;
    let mut worst_nis = 0.0_f64;
    let mut updates = 0u32;
    for k in 1..=duration_s {
        let t = f64::from(k);
        // Truth over one second.
        for j in 0..substeps {
            let ts = t - 1.0 + (f64::from(j) + 0.5) * dt;
            let wobble = Vector3::new(
                (ts / 97.0).sin(),
                (ts / 151.0 + 1.0).sin(),
                (ts / 263.0 + 2.0).cos(),
            ) * 1e-5;
            let w = omega0 + wobble;
            q_true = Quat::from_rotation_vector(&(w * dt))
                .compose(&q_true)
                .normalized();
            let noise = rng.gauss3() * (sigma_v / dt.sqrt());
            gyro.angle_rad += gyro.ginv * (w + bias + noise) * dt;
            bias += rng.gauss3() * (sigma_u * dt.sqrt());
        }

        // OBC cycle: IRU, propagation, two FHST updates.
        let out = iru.process(&gyro.sample(), IruConfiguration::Primary, &iru_table);
        let d = out.delta_theta_acs_rad.expect("healthy IRU");
        filter.propagate(&d, 1.0, &filter_table).unwrap();
        let a_true = q_true.to_dcm();
        for i in 0..2 {
            let m = &ms[i];
            let s = m.transpose() * (a_true * tracks[i].r_eci);
            let (h, v) = fhst::hv_from_dir(&s).unwrap();
            let lim = 3.8_f64.to_radians();
            if k >= tracks[i].ends_at_s || h.abs() > lim || v.abs() > lim {
                tracks[i] = new_track(&mut rng, &a_true, m, k);
                continue; // the tracker searches for one cycle
            }
            let sigma = filter_table.fhst_sigma_rad(tracks[i].magnitude);
            let nh = ((h + sigma * rng.gauss()) / FHST_RAD_PER_COUNT).round();
            let nv = ((v + sigma * rng.gauss()) / FHST_RAD_PER_COUNT).round();
            let mut flags = FHST_FLAG_VALID | FHST_FLAG_TRACKING;
            if tracks[i].new {
                flags |= FHST_FLAG_NEW_STAR;
                tracks[i].new = false;
            }
            let sample = FhstSample {
                h_counts: nh as i16,
                v_counts: nv as i16,
                magnitude_centimag: (tracks[i].magnitude * 100.0).round() as i16,
                flags,
            };
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
                worst_nis = worst_nis.max(o.nis);
                updates += 1;
            }
        }

        // Statistics.
        let e = attitude_error_rad(&q_true, &filter.q_acs_from_eci);
        let sig = filter.attitude_sigma_rad();
        if e.norm() * ARCSEC_PER_RAD > 30.0 {
            converged_at = None;
        } else if converged_at.is_none() {
            converged_at = Some(k);
        }
        if k > settle_s {
            samples += 1;
            for ax in 0..3 {
                if e[ax].abs() <= 3.0 * sig[ax] {
                    inside[ax] += 1;
                }
            }
            let p11 = filter.covariance.fixed_view::<3, 3>(0, 0).into_owned();
            nees_sum += (e.transpose() * p11.try_inverse().unwrap() * e).x;
            max_err_after = max_err_after.max(e.norm());
        }
    }

    let frac = inside.map(|n| f64::from(n) / f64::from(samples));
    let b_err = filter.bias_rad_per_s - bias;
    let b_sig = filter.bias_sigma_rad_per_s();
    let sig = filter.attitude_sigma_rad();
    let c = filter.counters;
    println!("MEKF, 4 h at 1 Hz, 1 deg initial error, statistics after {settle_s} s:");
    println!(
        "  converged below 30\" (total) at t = {} s; max error after settling {:.2}\"",
        converged_at.unwrap(),
        max_err_after * ARCSEC_PER_RAD
    );
    println!(
        "  3-sigma containment per ACS axis: {:.2} % {:.2} % {:.2} %; mean NEES (3 dof) {:.2}",
        100.0 * frac[0],
        100.0 * frac[1],
        100.0 * frac[2],
        nees_sum / f64::from(samples)
    );
    println!(
        "  final attitude sigma {:.2}\" {:.2}\" {:.2}\"",
        sig.x * ARCSEC_PER_RAD,
        sig.y * ARCSEC_PER_RAD,
        sig.z * ARCSEC_PER_RAD
    );
    println!(
        "  bias truth {:.4} {:.4} {:.4} \"/s; error {:.2e} {:.2e} {:.2e} rad/s = {:.5} {:.5} {:.5} \"/s; filter sigma {:.2e} {:.2e} {:.2e} rad/s",
        bias.x * ARCSEC_PER_RAD,
        bias.y * ARCSEC_PER_RAD,
        bias.z * ARCSEC_PER_RAD,
        b_err.x,
        b_err.y,
        b_err.z,
        b_err.x * ARCSEC_PER_RAD,
        b_err.y * ARCSEC_PER_RAD,
        b_err.z * ARCSEC_PER_RAD,
        b_sig.x,
        b_sig.y,
        b_sig.z
    );
    println!(
        "  updates: accepted {}, gated {}, other rejections {}; worst NIS after settling {:.1} over {} updates",
        c.accepted, c.gated, c.other_rejections, worst_nis, updates
    );

    assert!(
        converged_at.unwrap() < 600,
        "did not converge within 10 min"
    );
    for (ax, f) in frac.iter().enumerate() {
        assert!(
            *f >= 0.97,
            "axis {ax}: only {:.2} % inside 3 sigma",
            100.0 * f
        );
    }
    // Bias: within 3σ of the filter and within 1.5e-8 rad/s (0.003″/s, 0.5 % of the bias).
    for ax in 0..3 {
        assert!(
            b_err[ax].abs() <= 3.0 * b_sig[ax],
            "bias axis {ax} outside 3 sigma"
        );
        assert!(
            b_err[ax].abs() <= 1.5e-8,
            "bias axis {ax} error {:e}",
            b_err[ax]
        );
    }
    assert_eq!(c.other_rejections, 0);
    assert!(f64::from(c.gated) < 0.01 * f64::from(c.accepted));
    let p = filter.covariance;
    assert!((p - p.transpose()).norm() == 0.0 && p.cholesky().is_some());
}
