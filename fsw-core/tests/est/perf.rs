//! The estimation work of one OBC cycle, isolated for instruction counting:
//! IRU pulse integration + MEKF propagation + 2 FHST conversions and focal-plane updates +
//! 1 FSS conversion and vector update (+ the Sun ephemeris, separately).
//!
//! ```text
//! cargo test --release -p fsw-core --test est --no-run
//! valgrind --tool=callgrind --toggle-collect='est::perf::estimation_cycle' <binary> --exact perf::estimation_cycle_runs
//! ```
//! and divide the collected instructions by [`CYCLES`].

use fsw_core::attitude::Quat;
use fsw_core::fhst;
use fsw_core::fss;
use fsw_core::iru::{IruConfiguration, IruIntegrator};
use fsw_core::mekf::Mekf;
use fsw_core::raw::{
    FhstSample, FssSample, IruSample, FHST_FLAG_TRACKING, FHST_FLAG_VALID, FSS_FLAG_SUN_ALPHA,
    FSS_FLAG_SUN_BETA,
};
use fsw_core::sun_ephemeris;
use fsw_core::tables::{AlignmentTable, FilterTable, IruTable};
use nalgebra::Vector3;
use std::hint::black_box;

/// Cycles per run.
const CYCLES: u32 = 1000;

struct Inputs {
    iru: IruSample,
    fhst: [FhstSample; 2],
    fss: FssSample,
    star_eci: [Vector3<f64>; 2],
    sun_eci: Vector3<f64>,
}

#[inline(never)]
fn estimation_cycle(
    integ: &mut IruIntegrator,
    filter: &mut Mekf,
    inputs: &Inputs,
    al: &AlignmentTable,
    it: &IruTable,
    ft: &FilterTable,
) -> u32 {
    let mut accepted = 0;
    let out = integ.process(&inputs.iru, IruConfiguration::Primary, it);
    if let Some(d) = out.delta_theta_acs_rad {
        let _ = filter.propagate(&d, ft.cycle_period_s, ft);
    }
    for (i, (sample, m)) in inputs
        .fhst
        .iter()
        .zip([&al.m_acs_from_fhst1, &al.m_acs_from_fhst2])
        .enumerate()
    {
        let d = al.corrections.fhst_distortion[i];
        if let Ok(meas) = fhst::measure(sample, m, &d) {
            let sigma = fhst::measurement_sigma_rad(meas.magnitude, ft);
            let mm = fsw_core::tables::types::matrix_from_rows(m);
            let o = filter.update_focal_plane(
                meas.h_rad,
                meas.v_rad,
                &inputs.star_eci[i],
                &mm,
                sigma,
                ft.gate_chi2,
            );
            accepted += u32::from(o.accepted);
        }
    }
    if let Ok(meas) = fss::measure(
        &inputs.fss,
        &al.m_acs_from_fss1,
        &al.corrections.fss_transfer[0],
    ) {
        let sigma = ft.fss_sigma_arcsec / fsw_core::units::ARCSEC_PER_RAD;
        let o = filter.update_vector(&meas.dir_acs, &inputs.sun_eci, sigma, ft.gate_chi2);
        accepted += u32::from(o.accepted);
    }
    accepted
}

#[inline(never)]
fn sun_cycle(t: f64) -> Vector3<f64> {
    sun_ephemeris::sun_dir_eci(t).unwrap_or_else(|_| Vector3::zeros())
}

#[test]
fn estimation_cycle_runs() {
    let al = AlignmentTable::prelaunch();
    let it = IruTable::prelaunch();
    let ft = FilterTable::default_boot();
    let q = Quat::from_rotation_vector(&Vector3::new(0.3, -0.4, 1.2));
    let a = q.to_dcm();
    let star_s = [
        fhst::dir_from_hv(0.01, -0.02),
        fhst::dir_from_hv(-0.03, 0.015),
    ];
    let star_eci = [0, 1].map(|i| {
        let m = if i == 0 {
            &al.m_acs_from_fhst1
        } else {
            &al.m_acs_from_fhst2
        };
        a.transpose() * (fsw_core::tables::types::matrix_from_rows(m) * star_s[i])
    });
    let sun_s = fss::dir_from_angles(0.1, -0.2);
    let sun_eci =
        a.transpose() * (fsw_core::tables::types::matrix_from_rows(&al.m_acs_from_fss1) * sun_s);
    let hv = |s: &Vector3<f64>| {
        let (h, v) = fhst::hv_from_dir(s).unwrap();
        (
            (h / fhst::FHST_RAD_PER_COUNT).round() as i16,
            (v / fhst::FHST_RAD_PER_COUNT).round() as i16,
        )
    };
    let (h0, v0) = hv(&star_s[0]);
    let (h1, v1) = hv(&star_s[1]);
    let flags = FHST_FLAG_VALID | FHST_FLAG_TRACKING;
    let mut inputs = Inputs {
        iru: IruSample::default(),
        fhst: [
            FhstSample {
                h_counts: h0,
                v_counts: v0,
                magnitude_centimag: 400,
                flags,
            },
            FhstSample {
                h_counts: h1,
                v_counts: v1,
                magnitude_centimag: 500,
                flags,
            },
        ],
        fss: FssSample {
            alpha_counts: (0.1_f64.to_degrees() / 0.004).round() as i16,
            beta_counts: (-0.2_f64.to_degrees() / 0.004).round() as i16,
            flags: FSS_FLAG_SUN_ALPHA | FSS_FLAG_SUN_BETA,
        },
        star_eci,
        sun_eci,
    };
    let mut integ = IruIntegrator::new();
    let mut filter = Mekf::new();
    filter.initialize(&q, &ft).unwrap();
    let mut accepted = 0;
    for k in 0..CYCLES {
        // Gyro counting the bias only (about 12 pulses per second per channel).
        inputs.iru.counts = [k as u16 * 12; 6];
        accepted += estimation_cycle(&mut integ, &mut filter, black_box(&inputs), &al, &it, &ft);
        black_box(sun_cycle(black_box(-2.7e8 + f64::from(k))));
    }
    assert!(accepted > 2 * CYCLES, "{accepted}");
}
