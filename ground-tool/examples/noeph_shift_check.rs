//! Developer check: why removing the ephemeris packets moves the FHST1–FHST2 gyro-batch
//! estimate. Takes two runs with identical raw frames (with and without APID 0x020), builds
//! the gyro-batch star samples of both, and prints the estimate of each, the shift each batch
//! alone causes (the other batches from the first run) and the orbital aberration change per
//! batch and tracker.
//!
//! ```text
//! cargo run --release -p ground-tool --example noeph_shift_check -- RUN_WITH_EPH RUN_WITHOUT
//! ```
use fsw_core::tables::types::{AlignmentTable, IruTable};
use fsw_core::units::ARCSEC_PER_RAD;
use ground_tool::calibration::fhst_relative::{
    estimate_relative_alignment, BatchStarSample, FhstRelativeAlignment,
};
use ground_tool::pipeline::calibrate::{load_catalog, read_run, CalibrateOptions};
use ground_tool::pipeline::observations::{build_observations, FrameObservations};
use ground_tool::pipeline::star_batches::{star_batch_samples, star_batches};
use nalgebra::Vector3;
use std::path::Path;

/// The run's frames, gyro-batch samples and batch count, and its batch spans.
type RunSamples = (
    Vec<FrameObservations>,
    Vec<BatchStarSample>,
    usize,
    Vec<(usize, usize)>,
);

fn samples(dir: &Path) -> anyhow::Result<RunSamples> {
    let (tm, md) = read_run(dir)?;
    let sky = load_catalog()?;
    let o = CalibrateOptions::default();
    let frames = build_observations(
        &tm,
        &AlignmentTable::prelaunch(),
        &IruTable::prelaunch(),
        &md.sensors,
        &sky,
        &o.identify,
    );
    let bias_at = |t_s: f64| ground_tool::pipeline::calibrate::obc_bias_at(&tm, t_s);
    let (s, n) = star_batch_samples(&frames, &bias_at);
    let spans = star_batches(&frames, &bias_at)
        .into_iter()
        .map(|(lo, hi, _)| (lo, hi))
        .collect();
    Ok((frames, s, n, spans))
}

/// The gyro-batch estimate of `samples` over `n` batches.
fn estimate(samples: &[BatchStarSample], n: usize) -> anyhow::Result<FhstRelativeAlignment> {
    estimate_relative_alignment(samples, n, 1).map_err(|e| anyhow::anyhow!("{e}"))
}

/// The two runs' frames and samples, and their estimates.
struct Runs {
    /// The first run's frames.
    fa: Vec<FrameObservations>,
    /// Samples of the first and the second run.
    sa: Vec<BatchStarSample>,
    sb: Vec<BatchStarSample>,
    /// Batches (the same in both).
    na: usize,
    /// Estimates of the first and the second run.
    ta: Vector3<f64>,
    eb: FhstRelativeAlignment,
    /// The first run's batch spans with identified stars (the samples' batch indices).
    with_samples: Vec<(usize, usize)>,
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let (fa, sa, na, spans) = samples(Path::new(&args[1]))?;
    let (_fb, sb, nb, _) = samples(Path::new(&args[2]))?;
    println!("samples {} / {}, batches {na} / {nb}", sa.len(), sb.len());
    assert_eq!(sa.len(), sb.len());
    assert_eq!(na, nb);
    let same = sa
        .iter()
        .zip(sb.iter())
        .all(|(a, b)| a.tracker == b.tracker && a.batch == b.batch && a.meas_acs == b.meas_acs);
    println!("same samples (tracker, batch, measurement): {same}");
    let ea = estimate(&sa, na)?;
    let eb = estimate(&sb, nb)?;
    let ta = ea.theta_acs_arcsec;
    let tb = eb.theta_acs_arcsec;
    println!("with eph    θ = [{:.1}, {:.1}, {:.1}]", ta.x, ta.y, ta.z);
    println!("without eph θ = [{:.1}, {:.1}, {:.1}]", tb.x, tb.y, tb.z);
    // The spans with identified stars: the batch indices of the samples count only these.
    let with_samples: Vec<(usize, usize)> = spans
        .iter()
        .copied()
        .filter(|(lo, hi)| {
            fa[*lo..*hi]
                .iter()
                .any(|f| f.stars.iter().flatten().any(|s| s.identified.is_some()))
        })
        .collect();
    let tb = eb.theta_acs_arcsec;
    let r = Runs {
        fa,
        sa,
        sb,
        na,
        ta,
        eb,
        with_samples,
    };
    batch_shifts(&r)?;
    predicted_shift(&r)?;
    consider_sigma(&r, tb)?;
    star_segments(&r, args.get(3).map(String::as_str))
}

/// Per batch: its span, rate, samples per tracker, the largest reference change, and the
/// shift of the estimate when only this batch comes from the second run.
fn batch_shifts(r: &Runs) -> anyhow::Result<()> {
    let Runs {
        fa,
        sa,
        sb,
        na,
        ta,
        with_samples,
        ..
    } = r;
    let na = *na;
    println!("batch  t0(s)  len(s)  rate  n1  n2  |Δref| max FHST1/FHST2 (″)  shift alone (″)");
    for b in 0..na {
        let mixed: Vec<BatchStarSample> = sa
            .iter()
            .zip(sb.iter())
            .map(|(a, bb)| if a.batch == b { bb.clone() } else { a.clone() })
            .collect();
        let em = estimate(&mixed, na)?;
        let d = em.theta_acs_arcsec - ta;
        let mut dmax = [0.0f64; 2];
        let mut cnt = [0usize; 2];
        for (a, bb) in sa.iter().zip(sb.iter()).filter(|(a, _)| a.batch == b) {
            let dd = (a.ref_acs - bb.ref_acs).norm() * ARCSEC_PER_RAD;
            dmax[a.tracker.index()] = dmax[a.tracker.index()].max(dd);
            cnt[a.tracker.index()] += 1;
        }
        // Batch index b counts only batches with samples.
        let (lo, hi) = with_samples.get(b).copied().unwrap_or((0, 1));
        println!(
            "{b:5} {:7.0} {:6.0} {:5} {:4} {:4}  {:6.1} {:6.1}  [{:6.1}, {:6.1}, {:6.1}]",
            fa[lo].time.seconds() - fa[0].time.seconds(),
            fa[hi - 1].time.seconds() - fa[lo].time.seconds(),
            if fa[lo].high_rate { "high" } else { "low" },
            cnt[0],
            cnt[1],
            dmax[0],
            dmax[1],
            d.x,
            d.y,
            d.z
        );
    }
    Ok(())
}

/// The first-order change of a direction `a` by the aberration of the velocity `w_acs`
/// (km/s, same axes).
fn aberrate(a: &Vector3<f64>, w_acs: &Vector3<f64>) -> Vector3<f64> {
    const C_KM_PER_S: f64 = 299_792.458;
    (w_acs - a * w_acs.dot(a)) / C_KM_PER_S
}

/// The shift predicted by the orbital aberration alone.
fn predicted_shift(r: &Runs) -> anyhow::Result<()> {
    let Runs { fa, sa, na, ta, .. } = r;
    let na = *na;
    // The first run's references
    // without the orbital velocity's aberration (first order, the OBC attitude of the frame),
    // and a consider covariance: each batch's orbital velocity unknown, isotropic, |v| = V.
    let mut frame_of = Vec::with_capacity(sa.len());
    for &(lo, hi) in &r.with_samples {
        for (k, f) in fa.iter().enumerate().take(hi).skip(lo) {
            for s in f.stars.iter().flatten() {
                if s.identified.is_some() {
                    frame_of.push(k);
                }
            }
        }
    }
    assert_eq!(frame_of.len(), sa.len());
    let mut predicted = sa.clone();
    let mut ok = true;
    for (s, &k) in predicted.iter_mut().zip(&frame_of) {
        let f = &fa[k];
        match (f.orbit, f.obc_q_acs_from_eci) {
            (Some((_, v)), Some(q)) => {
                let w = q.to_dcm() * v;
                s.ref_acs = (s.ref_acs - aberrate(&s.ref_acs, &w)).normalize();
            }
            _ => ok = false,
        }
    }
    if ok {
        let ep = estimate(&predicted, na)?;
        let d = ep.theta_acs_arcsec - ta;
        println!(
            "orbital aberration removed from the first run's references: shift [{:.1}, {:.1}, {:.1}]″",
            d.x, d.y, d.z
        );
    } else {
        println!("(no orbit or OBC attitude in some frames: predicted shift not computed)");
    }
    Ok(())
}

/// The consider σ of the orbital aberration, each batch's velocity unknown.
fn consider_sigma(r: &Runs, tb: Vector3<f64>) -> anyhow::Result<()> {
    let Runs { fa, sb, na, eb, .. } = r;
    let na = *na;
    let v_orbit = fa
        .iter()
        .find_map(|f| f.orbit.map(|(_, v)| v.norm()))
        .unwrap_or(7.8);
    let mut consider = nalgebra::Matrix3::<f64>::zeros();
    for b in 0..na {
        let mut k_b = nalgebra::Matrix3::<f64>::zeros();
        for j in 0..3 {
            let w = Vector3::ith(j, v_orbit);
            let pert: Vec<BatchStarSample> = sb
                .iter()
                .map(|s| {
                    let mut s = s.clone();
                    if s.batch == b {
                        s.ref_acs = (s.ref_acs + aberrate(&s.ref_acs, &w)).normalize();
                    }
                    s
                })
                .collect();
            let e = estimate(&pert, na)?;
            k_b.set_column(j, &(e.theta_acs_arcsec - tb));
        }
        // E[w wᵀ] = V²/3 I for a direction uniform on the sphere; columns are per V.
        consider += k_b * k_b.transpose() / 3.0;
    }
    println!(
        "consider σ from orbital aberration (|v| = {v_orbit:.2} km/s, independent per batch): [{:.1}, {:.1}, {:.1}]″; stated σ [{:.1}, {:.1}, {:.1}]″",
        consider[(0, 0)].sqrt(),
        consider[(1, 1)].sqrt(),
        consider[(2, 2)].sqrt(),
        eb.covariance_arcsec2[(0, 0)].sqrt(),
        eb.covariance_arcsec2[(1, 1)].sqrt(),
        eb.covariance_arcsec2[(2, 2)].sqrt()
    );
    Ok(())
}

/// The star segments of the batches listed in `show` (comma-separated indices).
fn star_segments(r: &Runs, show: Option<&str>) -> anyhow::Result<()> {
    let Runs {
        fa,
        sa,
        sb,
        with_samples,
        ..
    } = r;
    // Star segments of the batches that move θ most: which stars, where in the field, and
    // the reference change (with − without ephemeris) in sensor axes.
    let m = AlignmentTable::prelaunch()
        .matrices()
        .map(fsw_core::tables::types::matrix_from_rows);
    let show: Vec<usize> = show.map_or(vec![], |s| {
        s.split(',').filter_map(|x| x.parse().ok()).collect()
    });
    let mut i = 0usize;
    for (b, (lo, hi)) in with_samples.iter().enumerate() {
        // segments: (tracker, hip) -> (t0, t1, n, sum h, sum v, sum Δ sensor)
        let mut segs: Vec<(usize, u32, f64, f64, usize, f64, f64, Vector3<f64>)> = Vec::new();
        for f in &fa[*lo..*hi] {
            for (k, s) in f.stars.iter().enumerate() {
                let Some(s) = s else { continue };
                let Some((hip, _)) = s.identified else {
                    continue;
                };
                let (a, bb) = (&sa[i], &sb[i]);
                i += 1;
                let d = m[k].transpose() * (a.ref_acs - bb.ref_acs) * ARCSEC_PER_RAD;
                let t = f.time.seconds() - fa[0].time.seconds();
                match segs.iter_mut().rev().find(|x| x.0 == k) {
                    Some(x) if x.1 == hip => {
                        x.3 = t;
                        x.4 += 1;
                        x.5 += s.meas.h_rad;
                        x.6 += s.meas.v_rad;
                        x.7 += d;
                    }
                    _ => segs.push((k, hip, t, t, 1, s.meas.h_rad, s.meas.v_rad, d)),
                }
            }
        }
        if !show.contains(&b) {
            continue;
        }
        println!("batch {b}: tracker hip t0 t1 n  H V (deg)  mean Δref sensor x y (″)");
        for (k, hip, t0, t1, n, h, v, d) in segs {
            let nf = n as f64;
            println!(
                "  FHST{} {hip:6} {t0:6.0} {t1:6.0} {n:4}  {:6.2} {:6.2}  {:5.2} {:5.2}",
                k + 1,
                h / nf * 57.29578,
                v / nf * 57.29578,
                d.x / nf,
                d.y / nf
            );
        }
    }
    Ok(())
}
