//! # Truth sensor models: FHST, FSS, DRIRU II, temperatures, TAMs, CSSs and wheel tachometers
//!
//! Each model turns a [`TruthSnapshot`] into the integer words of
//! [`fsw_core::raw::RawSensorFrame`] (the TAMs and CSSs into their own readings,
//! [`tam::TamReading`] and [`css::CssReading`], until the raw frame carries them). Every error parameter is a serde field with a default
//! (scenario TOML); "undeclared" effects the ground is meant to discover default to off.
//! Randomness comes from one `ChaCha8Rng` per model, seeded from the scenario seed and a
//! fixed stream number ([`model_rng`]), so adding a model never changes another's draws.

pub mod css;
pub mod fhst;
pub mod fss;
pub mod iru;
pub mod tachometer;
pub mod tam;
pub mod thermal;

use nalgebra::{Matrix3, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use fsw_core::attitude::{rot, Quat};

/// Stream numbers of the per-model random generators.
pub mod stream {
    /// FHST1 (FHST2 is `FHST1 + 1`).
    pub const FHST1: u64 = 1;
    /// FSS1 (FSS2 is `FSS1 + 1`).
    pub const FSS1: u64 = 3;
    /// The IRU.
    pub const IRU: u64 = 5;
    /// FSS1's drawn transfer function (FSS2 is `FSS1_TRANSFER + 1`).
    pub const FSS1_TRANSFER: u64 = 6;
    /// TAM1, the primary magnetometer (TAM2 is `TAM1 + 1`).
    pub const TAM1: u64 = 8;
    /// The coarse Sun sensor set.
    pub const CSS: u64 = 10;
    /// The wheel tachometers.
    pub const TACHOMETERS: u64 = 11;
}

/// A deterministic generator for model `stream` of scenario `seed`.
#[must_use]
pub fn model_rng(seed: u64, stream: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(stream);
    rng
}

/// Everything true at one sample instant that a sensor may look at. Built once per cycle by
/// the driver; J2000 axes, km, km/s, rad.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TruthSnapshot {
    /// Seconds since the scenario epoch.
    pub t_s: f64,
    /// Seconds since J2000 TT.
    pub j2000_tt_s: f64,
    /// True attitude `A`.
    pub q_acs_from_eci: Quat,
    /// True attitude matrix `A` (same as the quaternion).
    pub m_acs_from_eci: Matrix3<f64>,
    /// True body rate (rad/s).
    pub rate_acs_rad_per_s: Vector3<f64>,
    /// Spacecraft position, geocentric (km).
    pub pos_eci_km: Vector3<f64>,
    /// Spacecraft velocity, geocentric (km/s).
    pub vel_eci_km_per_s: Vector3<f64>,
    /// Geocentre position relative to the solar-system barycentre (km).
    pub earth_pos_bary_eci_km: Vector3<f64>,
    /// Geocentre velocity relative to the solar-system barycentre (km/s).
    pub earth_vel_bary_eci_km_per_s: Vector3<f64>,
    /// Apparent Sun direction from the spacecraft (parallax, light time, annual + orbital
    /// aberration).
    pub sun_dir_app_eci: Vector3<f64>,
    /// The spacecraft is in the Earth's umbra.
    pub in_umbra: bool,
}

impl TruthSnapshot {
    /// A snapshot at rest at the origin of time, for tests: identity attitude, zero rate, the
    /// spacecraft at 6833 km on +x, Sun along +y, no aberration.
    #[must_use]
    pub fn at_rest(q_acs_from_eci: Quat) -> Self {
        Self {
            t_s: 0.0,
            j2000_tt_s: -2.74e8,
            q_acs_from_eci,
            m_acs_from_eci: q_acs_from_eci.to_dcm(),
            rate_acs_rad_per_s: Vector3::zeros(),
            pos_eci_km: Vector3::new(6833.0, 0.0, 0.0),
            vel_eci_km_per_s: Vector3::zeros(),
            earth_pos_bary_eci_km: Vector3::zeros(),
            earth_vel_bary_eci_km_per_s: Vector3::zeros(),
            sun_dir_app_eci: Vector3::new(0.0, 1.0, 0.0),
            in_umbra: false,
        }
    }

    /// Observer (spacecraft) position relative to the barycentre (km).
    #[must_use]
    pub fn observer_pos_bary_eci_km(&self) -> Vector3<f64> {
        self.earth_pos_bary_eci_km + self.pos_eci_km
    }

    /// Observer velocity relative to the barycentre (km/s): annual + orbital.
    #[must_use]
    pub fn observer_vel_bary_eci_km_per_s(&self) -> Vector3<f64> {
        self.earth_vel_bary_eci_km_per_s + self.vel_eci_km_per_s
    }

    /// The attitude `offset_s` earlier than the snapshot, `A(t − τ) = Rot(−ω τ) A(t)` (exact
    /// for a constant rate; τ is milliseconds).
    #[must_use]
    pub fn m_acs_from_eci_earlier(&self, offset_s: f64) -> Matrix3<f64> {
        if offset_s == 0.0 {
            self.m_acs_from_eci
        } else {
            rot(&(-self.rate_acs_rad_per_s * offset_s)) * self.m_acs_from_eci
        }
    }
}

/// A one-time alignment step of a sensor (its `effects.alignment_step_arcsec` from
/// `alignment_step_at_s` on): the rotation about the ACS axes at `t_s` (rad), zero before.
#[must_use]
pub fn alignment_step_rad(step_arcsec: [f64; 3], at_s: Option<f64>, t_s: f64) -> Vector3<f64> {
    if at_s.is_some_and(|at| t_s >= at) {
        Vector3::from(step_arcsec) * fsw_core::units::RAD_PER_ARCSEC
    } else {
        Vector3::zeros()
    }
}

/// Nearest integer count of `value / per_count`, saturated to `i16`.
#[must_use]
pub fn quantize_i16(value: f64, per_count: f64) -> i16 {
    let c = (value / per_count).round();
    if c.is_nan() {
        0
    } else {
        #[allow(clippy::cast_possible_truncation)]
        let out = c.clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16;
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantize_rounds_and_saturates() {
        assert_eq!(quantize_i16(7.78 * 3.49, 7.78), 3);
        assert_eq!(quantize_i16(-7.78 * 3.51, 7.78), -4);
        assert_eq!(quantize_i16(1e9, 1.0), i16::MAX);
        assert_eq!(quantize_i16(f64::NAN, 1.0), 0);
    }

    #[test]
    fn earlier_attitude_undoes_rate() {
        let mut t =
            TruthSnapshot::at_rest(Quat::from_rotation_vector(&Vector3::new(0.1, 0.2, 0.3)));
        t.rate_acs_rad_per_s = Vector3::new(0.0, 0.0, 0.01);
        let earlier = t.m_acs_from_eci_earlier(0.5);
        let forward = rot(&(t.rate_acs_rad_per_s * 0.5)) * earlier;
        assert!((forward - t.m_acs_from_eci).abs().max() < 1e-15);
    }

    #[test]
    fn rng_streams_are_deterministic_and_distinct() {
        use rand::Rng;
        let a: u64 = model_rng(7, stream::IRU).random();
        let b: u64 = model_rng(7, stream::IRU).random();
        let c: u64 = model_rng(7, stream::FSS1).random();
        assert_eq!(a, b);
        assert_ne!(a, c);
    }

    /// Every stream number is distinct (FHST1/2, FSS1/2, IRU, FSS1/2 transfer, TAM1/2, CSS),
    /// so a new model never shares (and shifts) another's draws.
    #[test]
    fn stream_numbers_are_distinct() {
        let all = [
            stream::FHST1,
            stream::FHST1 + 1,
            stream::FSS1,
            stream::FSS1 + 1,
            stream::IRU,
            stream::FSS1_TRANSFER,
            stream::FSS1_TRANSFER + 1,
            stream::TAM1,
            stream::TAM1 + 1,
            stream::CSS,
        ];
        let set: std::collections::BTreeSet<u64> = all.iter().copied().collect();
        assert_eq!(set.len(), all.len());
    }
}
