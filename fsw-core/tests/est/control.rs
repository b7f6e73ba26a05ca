//! Attitude control on a rigid-body model: a 60° eigen-axis slew and the hold that follows.
//!
//! Plant: `J ω̇ = τ − ω × Jω` with the table inertia plus 1 % products of inertia the control
//! law does not know; wheels are ideal torquers (their momentum is not modelled); RK4 at
//! 10 Hz, torque held over the 1-s control cycle. The controller sees the true attitude and
//! rate (estimation errors are the filter test's subject).

use fsw_core::attitude::Quat;
use fsw_core::control::{ControlMode, Controller};
use fsw_core::tables::FilterTable;
use fsw_core::units::{ARCSEC_PER_RAD, DEG_PER_RAD};
use nalgebra::{Matrix3, Vector3};

fn omega_dot(
    j: &Matrix3<f64>,
    j_inv: &Matrix3<f64>,
    w: &Vector3<f64>,
    tau: &Vector3<f64>,
) -> Vector3<f64> {
    j_inv * (tau - w.cross(&(j * w)))
}

struct SlewResult {
    complete_at_s: Option<u32>,
    max_rate: f64,
    max_torque: f64,
    overshoot_rad: f64,
    max_cross_axis_rad: f64,
    final_error_rad: f64,
    hold_max_error_rad: f64,
    high_rate_cycles: u32,
}

fn slew(axis: Vector3<f64>, angle_deg: f64) -> SlewResult {
    let t = FilterTable::default_boot();
    let [jx, jy, jz] = t.inertia_kg_m2;
    let j = Matrix3::new(
        jx,
        0.01 * jx,
        -0.01 * jx,
        0.01 * jx,
        jy,
        0.005 * jy,
        -0.01 * jx,
        0.005 * jy,
        jz,
    );
    let j_inv = j.try_inverse().unwrap();
    let e = axis.normalize();
    let q0 = Quat::from_rotation_vector(&Vector3::new(0.2, -0.7, 1.1));
    let target = Quat::from_rotation_vector(&(e * angle_deg.to_radians())).compose(&q0);
    let mut c = Controller::new();
    c.hold(&q0).unwrap();
    c.slew_to(&target).unwrap();

    let (mut q, mut w) = (q0, Vector3::zeros());
    let mut r = SlewResult {
        complete_at_s: None,
        max_rate: 0.0,
        max_torque: 0.0,
        overshoot_rad: 0.0,
        max_cross_axis_rad: 0.0,
        final_error_rad: 0.0,
        hold_max_error_rad: 0.0,
        high_rate_cycles: 0,
    };
    let h = 0.1;
    for k in 0..5000u32 {
        let out = c.update(&q, &w, &t);
        assert!(out.fault.is_none());
        let tau = out.torque_acs_nm;
        r.max_torque = r.max_torque.max(tau.amax());
        if out.high_rate_iru {
            r.high_rate_cycles += 1;
        }
        if out.slew_complete {
            assert!(r.complete_at_s.is_none());
            r.complete_at_s = Some(k);
            assert_eq!(out.mode, ControlMode::Hold);
            assert!(!out.high_rate_iru);
        }
        // Error to the target relative to the slew axis.
        let err = out.attitude_error_rad;
        let along = err.dot(&e);
        r.overshoot_rad = r.overshoot_rad.max(-along);
        r.max_cross_axis_rad = r.max_cross_axis_rad.max((err - e * along).norm());
        if let Some(done) = r.complete_at_s {
            if k > done {
                r.hold_max_error_rad = r.hold_max_error_rad.max(err.norm());
            }
        }
        r.final_error_rad = err.norm();
        for _ in 0..10 {
            let k1 = omega_dot(&j, &j_inv, &w, &tau);
            let k2 = omega_dot(&j, &j_inv, &(w + k1 * (h / 2.0)), &tau);
            let k3 = omega_dot(&j, &j_inv, &(w + k2 * (h / 2.0)), &tau);
            let k4 = omega_dot(&j, &j_inv, &(w + k3 * h), &tau);
            let w_new = w + (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (h / 6.0);
            // Kinematics with the mean rate over the sub-step (A(t+h) = Rot(ω h) A(t)).
            q = Quat::from_rotation_vector(&((w + w_new) * (h / 2.0)))
                .compose(&q)
                .normalized();
            w = w_new;
            r.max_rate = r.max_rate.max(w.norm());
        }
    }
    r
}

#[test]
fn sixty_degree_slew_is_rate_limited_and_does_not_overshoot() {
    let t = FilterTable::default_boot();
    for axis in [
        Vector3::new(1.0, 0.0, 0.0),
        Vector3::new(0.0, 1.0, 0.0),
        Vector3::new(0.4, -0.6, 0.7),
    ] {
        let r = slew(axis, 60.0);
        println!(
            "60 deg slew about {:?}: complete at {:?} s ({} high-rate cycles), max rate {:.4} deg/s (limit {:.4}), \
             max torque {:.3} N m, overshoot {:.2}\", max cross-axis {:.1}\", final {:.2}\", hold max {:.2}\"",
            axis.normalize().as_slice(),
            r.complete_at_s,
            r.high_rate_cycles,
            r.max_rate * DEG_PER_RAD,
            t.slew_rate_limit_rad_per_s * DEG_PER_RAD,
            r.max_torque,
            r.overshoot_rad * ARCSEC_PER_RAD,
            r.max_cross_axis_rad * ARCSEC_PER_RAD,
            r.final_error_rad * ARCSEC_PER_RAD,
            r.hold_max_error_rad * ARCSEC_PER_RAD
        );
        let done = r.complete_at_s.expect("slew completes");
        assert!(done < 2400, "slow slew: {done} s");
        assert_eq!(r.high_rate_cycles, done);
        assert!(r.max_rate <= t.slew_rate_limit_rad_per_s * 1.01);
        assert!(r.max_torque <= t.torque_limit_nm * (1.0 + 1e-12));
        // Overshoot bound: 0.01° (36″), a fifth of the 0.05° completion threshold.
        assert!(
            r.overshoot_rad <= 0.01_f64.to_radians(),
            "overshoot {}",
            r.overshoot_rad
        );
        assert!(r.hold_max_error_rad < t.slew_complete_rad);
        assert!(r.final_error_rad < 1.0 / ARCSEC_PER_RAD);
    }
}
