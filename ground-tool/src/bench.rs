//! FFCAL throughput benchmark (`ground-tool bench`): the requirement is 10⁶ dot-product pairs
//! in ≤ 2 s (release build), which the streaming normal equations of
//! [`crate::calibration::alignment`] meet without ever building a stacked `H`.

use std::time::Instant;

use nalgebra::Vector3;
use serde::Serialize;

use crate::calibration::alignment::{ffcal, AlignmentError, FfcalConfig, SensorSpec, Weighting};
use crate::synth::{alignment_data, gro_sensors, Rng};

/// Timing of one FFCAL run.
#[derive(Clone, Debug, Serialize)]
pub struct FfcalTiming {
    /// Weighting used.
    pub weighting: Weighting,
    /// Epochs (4 sensors each).
    pub epochs: usize,
    /// Dot products per Gauss–Newton pass.
    pub pairs_per_pass: usize,
    /// Gauss–Newton passes (each reads all the data; the last one only evaluates).
    pub passes: usize,
    /// Data generation time (s), not part of the requirement.
    pub generate_s: f64,
    /// FFCAL wall time (s), all passes, covariance and eigen-analysis included.
    pub ffcal_s: f64,
    /// FFCAL wall time per pass (s).
    pub per_pass_s: f64,
}

/// Generate ≥ `pairs` dot products over 4-sensor epochs (GRO sensors, paper-sized
/// misalignments) and time FFCAL.
///
/// # Errors
/// Any [`AlignmentError`] of the run.
pub fn ffcal_timing(
    pairs: usize,
    weighting: Weighting,
    seed: u64,
) -> Result<FfcalTiming, AlignmentError> {
    let per_epoch = match weighting {
        Weighting::Optimal1990 => 5,
        Weighting::Shuster1982 => 6,
    };
    let epochs = pairs.div_ceil(per_epoch).max(1);
    let truth = [
        Vector3::new(41.7, -41.7, -13.8),
        Vector3::new(56.4, 56.3, 13.7),
        Vector3::new(236.0, -407.0, -562.0),
        Vector3::new(-153.0, 2.0, 110.0),
    ];
    let syn = gro_sensors(&truth);
    let t0 = Instant::now();
    let mut rng = Rng::new(seed);
    let data = alignment_data(&mut rng, &syn, epochs);
    let generate_s = t0.elapsed().as_secs_f64();
    let specs: Vec<SensorSpec> = syn
        .iter()
        .map(|s| SensorSpec::new(&s.id, s.m_acs_from_sensor_prelaunch, 3600.0))
        .collect();
    let cfg = FfcalConfig {
        weighting,
        ..FfcalConfig::default()
    };
    let t1 = Instant::now();
    let sol = ffcal(&specs, &data, &cfg)?;
    let ffcal_s = t1.elapsed().as_secs_f64();
    let passes = sol.iterations + 1;
    Ok(FfcalTiming {
        weighting,
        epochs,
        pairs_per_pass: sol.pairs_per_pass,
        passes,
        generate_s,
        ffcal_s,
        per_pass_s: ffcal_s / passes as f64,
    })
}

/// Timing of the gyro-batch FHST relative alignment (`calibration::fhst_relative`).
#[derive(Clone, Debug, Serialize)]
pub struct FhstRelativeTiming {
    /// Star samples.
    pub samples: usize,
    /// Batches.
    pub batches: usize,
    /// Data generation time (s).
    pub generate_s: f64,
    /// Estimation wall time (s), outlier passes and covariance included.
    pub estimate_s: f64,
    /// Estimation time per 10⁶ samples (s).
    pub per_million_s: f64,
}

/// Generate ≈ `samples` star samples in 1,200-sample batches and time the estimator.
///
/// # Errors
/// The estimator's error (none on this data).
pub fn fhst_relative_timing(
    samples: usize,
    seed: u64,
) -> Result<FhstRelativeTiming, crate::calibration::fhst_relative::RelativeAlignmentError> {
    let per_batch = 6 * 200;
    let batches = samples.div_ceil(per_batch).max(3);
    let t0 = Instant::now();
    let data =
        crate::synth::fhst_batch_samples(Vector3::new(40.0, -25.0, 70.0), batches, 6, 200, seed);
    let generate_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let est = crate::calibration::fhst_relative::estimate_relative_alignment(&data, batches, 3)?;
    let estimate_s = t1.elapsed().as_secs_f64();
    std::hint::black_box(est);
    Ok(FhstRelativeTiming {
        samples: data.len(),
        batches,
        generate_s,
        estimate_s,
        per_million_s: estimate_s * 1e6 / data.len().max(1) as f64,
    })
}
