//! Property tests of the DRIRU II pulse integration.

use fsw_core::attitude::{attitude_error_rad, Quat};
use fsw_core::iru::{
    pulse_weight_rad, IruConfiguration, IruIntegrator, AXIS_PAIRS, PAIR_STUCK_ARCSEC,
};
use fsw_core::raw::IruSample;
use fsw_core::tables::IruTable;
use nalgebra::{Matrix3, Vector3};
use proptest::prelude::*;

fn table() -> IruTable {
    let mut t = IruTable::prelaunch();
    t.g_backup = [
        [0.9995, -0.0021, 0.0011],
        [0.0017, 1.0004, 0.0009],
        [-0.0012, 0.0006, 0.9990],
    ];
    t.scale_factor_primary = [1.0003, 0.9998, 1.0001];
    t.scale_factor_backup = [0.9996, 1.0002, 1.0004];
    t.stuck_cycles = 10_000;
    t
}

fn config(backup: bool) -> IruConfiguration {
    if backup {
        IruConfiguration::Backup
    } else {
        IruConfiguration::Primary
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Any 16-bit previous value and any change up to the saturation threshold is recovered
    /// exactly across the wrap, and converted with G diag(k) w.
    #[test]
    fn wrap_is_transparent(
        prev in any::<[u16; 6]>(),
        delta in proptest::array::uniform6(-30_000i32..=30_000),
        high in any::<bool>(),
        backup in any::<bool>(),
    ) {
        let t = table();
        let cfg = config(backup);
        let mut integ = IruIntegrator::new();
        integ.process(&IruSample { counts: prev, channel_failed: 0, high_rate: high }, cfg, &t);
        let mut now = prev;
        for (n, d) in now.iter_mut().zip(delta) {
            *n = n.wrapping_add(d as i16 as u16);
        }
        let out = integ.process(&IruSample { counts: now, channel_failed: 0, high_rate: high }, cfg, &t);
        for (got, want) in out.delta_counts.iter().zip(delta) {
            prop_assert_eq!(i32::from(*got), want);
        }
        prop_assert_eq!(integ.totals_pulses().map(|x| x as i32), delta);
        let [ix, iy, iz] = cfg.channels();
        let k = cfg.scale_factors(&t);
        let phi = Vector3::new(
            f64::from(delta[ix]) * k[0],
            f64::from(delta[iy]) * k[1],
            f64::from(delta[iz]) * k[2],
        ) * pulse_weight_rad(high, &t);
        let expect = cfg.g(&t) * phi;
        // A selected channel that did not move while its partner on the same axis turned
        // PAIR_STUCK_ARCSEC or more is stuck by the pair cross-check: no rotation this cycle.
        let weight_arcsec = if high { t.high_rate_arcsec_per_pulse } else { t.low_rate_arcsec_per_pulse };
        let pair_stuck = [ix, iy, iz].iter().any(|&c| {
            AXIS_PAIRS.iter().any(|&(a, b)| {
                let partner = if c == a { b } else if c == b { a } else { return false };
                delta[c] == 0 && f64::from(delta[partner].unsigned_abs()) * weight_arcsec >= PAIR_STUCK_ARCSEC
            })
        });
        match out.delta_theta_acs_rad {
            Some(got) => {
                prop_assert!(!pair_stuck, "a pair-stuck selected channel was used");
                prop_assert!((got - expect).norm() <= 1e-15 * expect.norm().max(1e-9));
            }
            None => prop_assert!(pair_stuck, "no rotation without a stuck selected channel"),
        }
    }

    /// A constant rate about any axis, any start counters, any mode schedule: the integrated
    /// rotation angle is exact to one pulse of the final mode (per channel), and the cross-axis
    /// error stays bounded by the lag swing of the largest pulse used.
    #[test]
    fn constant_rate_integrates_to_the_exact_angle(
        axis in (-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0),
        rate_frac in 0.05f64..1.0,
        start in any::<[u16; 6]>(),
        schedule in any::<u64>(),
        backup in any::<bool>(),
        cycles in 50u32..400,
    ) {
        let e = Vector3::new(axis.0, axis.1, axis.2);
        prop_assume!(e.norm() > 0.1);
        let e = e.normalize();
        let t = table();
        let cfg = config(backup);
        // Keep below the low-rate wrap limit (0.45 deg/s) so every schedule is valid.
        let rate = e * (rate_frac * 0.4_f64.to_radians());
        let gk = cfg.g(&t) * Matrix3::from_diagonal(&Vector3::from(cfg.scale_factors(&t)));
        let ginv = gk.try_inverse().unwrap();
        let ch = cfg.channels();
        let mut pulsed = [0.0f64; 3];
        let mut counts = start;
        let mut integ = IruIntegrator::new();
        integ.process(&IruSample { counts, channel_failed: 0, high_rate: false }, cfg, &t);
        let mut q = Quat::IDENTITY;
        let (mut w_final, mut w_max) = (0.0, 0.0f64);
        for k in 1..=cycles {
            // Mode of this interval: from the schedule bits, switching at most every 8 cycles.
            let high = (schedule >> ((k / 8) % 64)) & 1 == 1;
            let w = pulse_weight_rad(high, &t);
            let phi = ginv * (rate * f64::from(k));
            for a in 0..3 {
                let n = ((phi[a] - pulsed[a]) / w).floor();
                pulsed[a] += n * w;
                counts[ch[a]] = counts[ch[a]].wrapping_add(n as i64 as u16);
            }
            let out = integ.process(&IruSample { counts, channel_failed: 0, high_rate: high }, cfg, &t);
            q = Quat::from_rotation_vector(&out.delta_theta_acs_rad.unwrap()).compose(&q).normalized();
            w_final = w;
            w_max = w_max.max(w);
        }
        let truth = Quat::from_rotation_vector(&(rate * f64::from(cycles)));
        let err = attitude_error_rad(&truth, &q);
        let along = e.dot(&err);
        let along_bound = (gk.transpose() * e).abs().sum() * w_final * (1.0 + 1e-9) + 1e-15;
        let perp_bound = 2.0 * 3f64.sqrt() * gk.norm() * w_max;
        prop_assert!(along.abs() <= along_bound, "along {} > {}", along, along_bound);
        prop_assert!((err - e * along).norm() <= perp_bound);
    }
}
