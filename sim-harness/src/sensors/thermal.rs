//! # Orbit-periodic sensor temperatures
//!
//! Why: downstream residual analysis needs a temperature regressor (thermal alignment drift
//! and thermally driven gyro bias, algorithms.md §9 rows 2 and 11), and some effect hooks are
//! driven by it.
//!
//! Model: one thermal node per sensor, first order with time constant τ, driven toward
//! `T_eq = mean + orbit_amplitude · (r̂ · ŝ) + eclipse_step · [in umbra]` (r̂ the spacecraft's
//! zenith, ŝ the Sun). The drive is a sinusoid at the orbit period phased on orbit noon (its
//! amplitude shrinks with the β angle, as real sunlit heating does) and the eclipse term gives
//! the exponential steps at umbra entry and exit. Update: exact exponential of the
//! first-order lag with the drive held over the step. The node starts at equilibrium.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// One node's parameters (°C, s).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ThermalParams {
    /// Orbit-average temperature in sunlight (°C).
    pub mean_c: f64,
    /// Half peak-to-peak of the orbit-noon drive (°C).
    pub orbit_amplitude_c: f64,
    /// Drive change while in umbra (°C, negative = cooling).
    pub eclipse_step_c: f64,
    /// Node time constant (s).
    pub time_constant_s: f64,
}

impl Default for ThermalParams {
    fn default() -> Self {
        Self {
            mean_c: 20.0,
            orbit_amplitude_c: 1.5,
            eclipse_step_c: -2.0,
            time_constant_s: 1200.0,
        }
    }
}

impl ThermalParams {
    /// Defaults per raw-frame temperature slot (FHST1, FHST2, FSS1, FSS2, IRU baseplate):
    /// chosen values, not from the paper; the IRU baseplate is heater-controlled, so small.
    #[must_use]
    pub fn default_for_slot(slot: usize) -> Self {
        match slot {
            0 => Self {
                mean_c: 18.0,
                orbit_amplitude_c: 1.5,
                eclipse_step_c: -2.0,
                time_constant_s: 1500.0,
            },
            1 => Self {
                mean_c: 17.0,
                orbit_amplitude_c: 2.0,
                eclipse_step_c: -2.5,
                time_constant_s: 1300.0,
            },
            2 => Self {
                mean_c: 22.0,
                orbit_amplitude_c: 4.0,
                eclipse_step_c: -6.0,
                time_constant_s: 600.0,
            },
            3 => Self {
                mean_c: 21.0,
                orbit_amplitude_c: 4.0,
                eclipse_step_c: -6.0,
                time_constant_s: 700.0,
            },
            _ => Self {
                mean_c: 25.0,
                orbit_amplitude_c: 0.3,
                eclipse_step_c: -0.4,
                time_constant_s: 3000.0,
            },
        }
    }
}

/// One thermal node.
#[derive(Clone, Debug)]
pub struct ThermalNode {
    params: ThermalParams,
    temperature_c: f64,
    started: bool,
}

impl ThermalNode {
    /// A node that will start at its equilibrium on the first update.
    #[must_use]
    pub fn new(params: ThermalParams) -> Self {
        Self {
            params,
            temperature_c: params.mean_c,
            started: false,
        }
    }

    fn drive_c(
        &self,
        pos_eci_km: &Vector3<f64>,
        sun_dir_eci: &Vector3<f64>,
        in_umbra: bool,
    ) -> f64 {
        let noon = pos_eci_km.normalize().dot(sun_dir_eci);
        self.params.mean_c
            + self.params.orbit_amplitude_c * noon
            + if in_umbra {
                self.params.eclipse_step_c
            } else {
                0.0
            }
    }

    /// Advance by `dt_s` under the current geometry and return the temperature (°C).
    pub fn update(
        &mut self,
        dt_s: f64,
        pos_eci_km: &Vector3<f64>,
        sun_dir_eci: &Vector3<f64>,
        in_umbra: bool,
    ) -> f64 {
        let drive = self.drive_c(pos_eci_km, sun_dir_eci, in_umbra);
        if self.started {
            let tau = self.params.time_constant_s.max(1e-3);
            self.temperature_c += (drive - self.temperature_c) * (1.0 - (-dt_s / tau).exp());
        } else {
            self.temperature_c = drive;
            self.started = true;
        }
        self.temperature_c
    }

    /// Current temperature (°C).
    #[must_use]
    pub fn temperature_c(&self) -> f64 {
        self.temperature_c
    }

    /// Deviation from the node's mean (°C), the regressor of the thermal effect hooks.
    #[must_use]
    pub fn deviation_c(&self) -> f64 {
        self.temperature_c - self.params.mean_c
    }

    /// Temperature in the raw frame's 0.01 °C units.
    #[must_use]
    pub fn centi_c(&self) -> i16 {
        super::quantize_i16(self.temperature_c, 0.01)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Over a circular orbit in the Sun's plane, the node oscillates at the orbit period with
    /// an amplitude reduced by the lag, `A / √(1 + (ωτ)²)`, and drops in eclipse.
    #[test]
    fn periodic_response_and_eclipse_step() {
        let p = ThermalParams {
            eclipse_step_c: 0.0,
            ..ThermalParams::default()
        };
        let mut node = ThermalNode::new(p);
        let period = 5621.0;
        let w = 2.0 * std::f64::consts::PI / period;
        let sun = Vector3::new(1.0, 0.0, 0.0);
        let (mut lo, mut hi) = (f64::MAX, f64::MIN);
        for k in 0..(period as usize * 6) {
            let a = w * k as f64;
            let t = node.update(1.0, &Vector3::new(a.cos(), a.sin(), 0.0), &sun, false);
            if k > period as usize * 4 {
                lo = lo.min(t);
                hi = hi.max(t);
            }
        }
        let expect = p.orbit_amplitude_c / (1.0 + (w * p.time_constant_s).powi(2)).sqrt();
        assert!(
            ((hi - lo) / 2.0 - expect).abs() < 0.01,
            "{} vs {expect}",
            (hi - lo) / 2.0
        );
        let mut e = ThermalNode::new(ThermalParams::default());
        let pos = Vector3::new(0.0, 1.0, 0.0);
        e.update(1.0, &pos, &sun, false);
        for _ in 0..10_000 {
            e.update(1.0, &pos, &sun, true);
        }
        assert!((e.temperature_c() - (20.0 - 2.0)).abs() < 1e-3);
        assert_eq!(e.centi_c(), 1800);
    }
}
