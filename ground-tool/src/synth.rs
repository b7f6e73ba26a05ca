//! Deterministic synthetic data for tests, Monte Carlo runs and the `bench` subcommand.
//!
//! Why our own generator: tests must be reproducible bit-for-bit across machines and crate
//! upgrades, and we only need uniform and Gaussian draws. The generator is xoshiro256**
//! seeded through splitmix64; Gaussians use the Box–Muller transform.

use nalgebra::{Matrix3, Vector3};

use fsw_core::attitude::Quat;
use fsw_core::sensor::SensorId;

/// Small deterministic random number generator (xoshiro256**).
#[derive(Clone, Debug)]
pub struct Rng {
    s: [u64; 4],
    spare_normal: Option<f64>,
}

impl Rng {
    /// Seeded generator; equal seeds give equal streams.
    #[must_use]
    pub fn new(seed: u64) -> Self {
        // The state from SplitMix64, as the xoshiro authors recommend.
        let mut sm = gro_reference::splitmix::SplitMix64::new(seed);
        Self {
            s: [sm.next_u64(), sm.next_u64(), sm.next_u64(), sm.next_u64()],
            spare_normal: None,
        }
    }

    /// Next raw 64-bit value.
    pub fn next_u64(&mut self) -> u64 {
        let result = self.s[1].wrapping_mul(5).rotate_left(7).wrapping_mul(9);
        let t = self.s[1] << 17;
        self.s[2] ^= self.s[0];
        self.s[3] ^= self.s[1];
        self.s[1] ^= self.s[2];
        self.s[0] ^= self.s[3];
        self.s[2] ^= t;
        self.s[3] = self.s[3].rotate_left(45);
        result
    }

    /// Uniform in `[0, 1)`.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in `[lo, hi)`.
    pub fn uniform_in(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// Standard normal draw.
    pub fn normal(&mut self) -> f64 {
        if let Some(z) = self.spare_normal.take() {
            return z;
        }
        let u1 = loop {
            let u = self.uniform();
            if u > 0.0 {
                break u;
            }
        };
        let u2 = self.uniform();
        let r = (-2.0 * u1.ln()).sqrt();
        let phi = 2.0 * std::f64::consts::PI * u2;
        self.spare_normal = Some(r * phi.sin());
        r * phi.cos()
    }

    /// Vector of three independent standard normals.
    pub fn normal3(&mut self) -> Vector3<f64> {
        Vector3::new(self.normal(), self.normal(), self.normal())
    }

    /// Uniformly distributed unit vector.
    pub fn unit_vector(&mut self) -> Vector3<f64> {
        loop {
            let v = self.normal3();
            let n = v.norm();
            if n > 1e-6 {
                return v / n;
            }
        }
    }

    /// Uniformly distributed rotation matrix (from a uniformly distributed unit quaternion).
    pub fn rotation(&mut self) -> Matrix3<f64> {
        let q = Quat::new(self.normal(), self.normal(), self.normal(), self.normal());
        q.normalized().to_dcm()
    }
}

/// Perturb a unit vector by isotropic small-angle noise of `sigma_rad` per tangent axis
/// (the QUEST measurement model: error covariance `σ² (I − b bᵀ)`).
pub fn perturb_unit_vector(rng: &mut Rng, dir: &Vector3<f64>, sigma_rad: f64) -> Vector3<f64> {
    let n = rng.normal3() * sigma_rad;
    let tangent = n - dir * dir.dot(&n);
    (dir + tangent).normalize()
}

/// A unit vector in a sensor frame, uniformly spread over a square field of view of
/// half-width `half_fov_rad` about the +z boresight (gnomonic coordinates).
pub fn dir_in_square_fov(rng: &mut Rng, half_fov_rad: f64) -> Vector3<f64> {
    let t = half_fov_rad.tan();
    Vector3::new(rng.uniform_in(-t, t), rng.uniform_in(-t, t), 1.0).normalize()
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;

    #[test]
    fn normal_moments() {
        let mut rng = Rng::new(7);
        let n = 20_000;
        let xs: Vec<f64> = (0..n).map(|_| rng.normal()).collect();
        let mean = xs.iter().sum::<f64>() / n as f64;
        let var = xs.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / n as f64;
        assert!(mean.abs() < 0.03, "mean {mean}");
        assert!((var - 1.0).abs() < 0.04, "var {var}");
    }

    #[test]
    fn rotations_are_proper() {
        let mut rng = Rng::new(3);
        for _ in 0..20 {
            assert!(fsw_core::attitude::is_proper_rotation(
                &rng.rotation(),
                1e-12
            ));
        }
    }
}

/// A sensor of a synthetic alignment scenario.
#[derive(Clone, Debug, PartialEq)]
pub struct SyntheticSensor {
    /// Name.
    pub id: String,
    /// Alignment the ground believes (prelaunch), `M_AS`.
    pub m_acs_from_sensor_prelaunch: Matrix3<f64>,
    /// True correction: the true alignment is `Rot(θ) M_AS` (θ in ACS, rad).
    pub theta_true_acs_rad: Vector3<f64>,
    /// Half-width of the square field of view (rad).
    pub half_fov_rad: f64,
    /// 1σ measurement noise per tangent axis (rad).
    pub sigma_rad: f64,
}

impl SyntheticSensor {
    /// True alignment `Rot(θ_true) M_AS`.
    #[must_use]
    pub fn m_acs_from_sensor_true(&self) -> Matrix3<f64> {
        fsw_core::attitude::rot(&self.theta_true_acs_rad) * self.m_acs_from_sensor_prelaunch
    }
}

/// One synthetic epoch: a random attitude, each sensor sees an object at a random place in its
/// field of view, measured with noise. Returns `(sensor index, measured dir in sensor frame,
/// reference dir in ECI, σ)` per sensor.
pub fn alignment_epoch(
    rng: &mut Rng,
    sensors: &[SyntheticSensor],
) -> Vec<crate::calibration::alignment::SensorObservation> {
    let m_acs_from_eci = rng.rotation();
    sensors
        .iter()
        .enumerate()
        .map(|(sensor, s)| {
            let dir_true_sensor = dir_in_square_fov(rng, s.half_fov_rad);
            let dir_eci =
                m_acs_from_eci.transpose() * (s.m_acs_from_sensor_true() * dir_true_sensor);
            let dir_sensor = perturb_unit_vector(rng, &dir_true_sensor, s.sigma_rad);
            crate::calibration::alignment::SensorObservation {
                sensor,
                dir_sensor,
                dir_eci,
                sigma_rad: s.sigma_rad,
            }
        })
        .collect()
}

/// A data set of `epochs` synthetic epochs (see [`alignment_epoch`]).
#[must_use]
pub fn alignment_data(
    rng: &mut Rng,
    sensors: &[SyntheticSensor],
    epochs: usize,
) -> crate::calibration::alignment::AlignmentData {
    let mut data =
        crate::calibration::alignment::AlignmentData::with_capacity(epochs, sensors.len());
    for _ in 0..epochs {
        let obs = alignment_epoch(rng, sensors);
        // Synthetic epochs are valid by construction (≥ 2 sensors, unit vectors, σ > 0).
        if data.push_epoch(&obs).is_err() {
            break;
        }
    }
    data
}

/// The paper's four sensors with their Table 1 prelaunch alignments (2 FHSTs 90° apart, 2
/// FSSs), true corrections `theta_true_arcsec` (one per sensor, ACS), FHST σ 10″ in a ±4°
/// field, FSS σ 40″ in a ±32° field.
#[must_use]
pub fn gro_sensors(theta_true_arcsec: &[Vector3<f64>; 4]) -> Vec<SyntheticSensor> {
    let paper = crate::paper::PaperData::embedded();
    let specs = [
        ("FHST1", 4.0, 10.0),
        ("FHST2", 4.0, 10.0),
        ("FSS1", 32.0, 40.0),
        ("FSS2", 32.0, 40.0),
    ];
    specs
        .iter()
        .zip(theta_true_arcsec)
        .map(|(&(id, half_fov_deg, sigma_arcsec), th)| SyntheticSensor {
            id: id.to_owned(),
            m_acs_from_sensor_prelaunch: paper
                .as_ref()
                .ok()
                .and_then(|p| p.prelaunch(id))
                .unwrap_or_else(Matrix3::identity),
            theta_true_acs_rad: th * crate::RAD_PER_ARCSEC,
            half_fov_rad: half_fov_deg * crate::RAD_PER_DEG,
            sigma_rad: sigma_arcsec * crate::RAD_PER_ARCSEC,
        })
        .collect()
}

/// Gyro-batch star samples (`calibration::fhst_relative`): two trackers 90° apart (FHST1
/// along ACS +z, FHST2 along +x), `n_batches` batches, each with `stars_per_batch` stars at
/// random places of a ±4° field (alternating trackers) tracked for `samples_per_star` 1-s
/// samples with 10″ noise; each batch's reference attitude is off by up to 60″ and drifts
/// (a bias error). FHST2's true alignment is rotated by `theta_true_arcsec` (ACS).
#[must_use]
pub fn fhst_batch_samples(
    theta_true_arcsec: Vector3<f64>,
    n_batches: usize,
    stars_per_batch: usize,
    samples_per_star: usize,
    seed: u64,
) -> Vec<crate::calibration::fhst_relative::BatchStarSample> {
    use crate::RAD_PER_ARCSEC;
    use fsw_core::attitude::rot;
    let mut rng = Rng::new(seed);
    let m = [
        Matrix3::identity(),
        Matrix3::new(0.0, 0.0, 1.0, 0.0, 1.0, 0.0, -1.0, 0.0, 0.0),
    ];
    let m2_true = rot(&(theta_true_arcsec * RAD_PER_ARCSEC)) * m[1];
    let sigma = 10.0 * RAD_PER_ARCSEC;
    let half_s = (stars_per_batch * samples_per_star) as f64 / 2.0;
    let mut out = Vec::with_capacity(n_batches * stars_per_batch * samples_per_star);
    for batch in 0..n_batches {
        let d0 = Vector3::new(
            rng.uniform_in(-60.0, 60.0),
            rng.uniform_in(-60.0, 60.0),
            30.0,
        ) * RAD_PER_ARCSEC;
        let d1 = Vector3::new(0.02, -0.01, 0.03) * RAD_PER_ARCSEC;
        for star in 0..stars_per_batch {
            let tracker = if star % 2 == 0 {
                SensorId::Fhst1
            } else {
                SensorId::Fhst2
            };
            let h: f64 = rng.uniform_in(-0.07, 0.07);
            let v: f64 = rng.uniform_in(-0.07, 0.07);
            let s_true = Vector3::new(h.tan(), v.tan(), 1.0).normalize();
            let m_true = if tracker == SensorId::Fhst1 {
                m[0]
            } else {
                m2_true
            };
            for j in 0..samples_per_star {
                let t = (star * samples_per_star + j) as f64 - half_s;
                // The star in the true body frame, seen with the reference attitude
                // (`A_true = Rot(δ) A_ref`).
                let ref_acs = rot(&(d0 + d1 * t)).transpose() * (m_true * s_true);
                let noise = Vector3::new(rng.normal(), rng.normal(), 0.0) * sigma;
                out.push(crate::calibration::fhst_relative::BatchStarSample {
                    tracker,
                    batch,
                    dt_s: t,
                    ref_acs,
                    meas_acs: m[tracker.index()] * (s_true + noise).normalize(),
                    sigma_rad: sigma,
                    aberration_uncorrected: false,
                    gyro_scale_partial: None,
                });
            }
        }
    }
    out
}
