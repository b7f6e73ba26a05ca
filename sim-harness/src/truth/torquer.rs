//! # Magnetic torquer bars (MTBs): the truth of GRO's momentum unloading actuators
//!
//! Why: the wheels absorb the secular gravity-gradient torque of an inertial hold (≈ 0.05 N·m
//! for this spacecraft's estimated inertia in `normal-ops`), so without an external torque
//! they saturate within hours. GRO dumped that momentum with magnetic torquer bars commanded
//! by the onboard software (issue 20); the simulator used to apply an ideal external torque
//! instead (`[dynamics] momentum_unloading = "ideal"`, still available for scenarios without
//! the magnetics models). With `momentum_unloading = "bars"` the flight core's dipole command
//! ([`fsw_core::executive::FlightCore::torquer_dipole_command_am2`]) drives these bars.
//!
//! # Model
//! * Three bars, bar `k` along `bar_axes_acs[k]` (default the ACS axes, the axes the flight
//!   core commands on). Each bar's dipole is the commanded one clamped to
//!   ±`dipole_limit_am2` (the drive electronics' current limit), held over the step (no coil
//!   time constant: the bars' L/R, a fraction of a second, is far below the 1-s cycle).
//! * Torque on the body `τ = m × B` (N·m), `m` the total dipole in ACS (A·m²), `B` the truth
//!   geomagnetic field in ACS (tesla, [`crate::truth::field`]) at the step start, held over the
//!   step like the gravity gradient (the field turns ≈ 0.07°/s in the orbit: 0.07° per step).
//! * The bars' own field at each TAM: the TAM model's `torquer_coupling_milligauss_per_am2`
//!   (`[tam1]`, `[tam2]`: column `k` is the field at that TAM, ACS axes, per A·m² of dipole
//!   along ACS axis `k`, i.e. per bar with the default axes), with the dipole in effect while
//!   the TAM sampled (the previous cycle's command).
//! * Fault `torquer_stuck_on` ([`crate::faults`]): a bar delivers a fixed dipole whatever is
//!   commanded, clamped like a command to the drive's current limit.
//!
//! # The dipole limit (`dipole_limit_am2`, default 4,000 A·m²)
//! **Assumed**: we found no published dipole for GRO's bars. The value is sized from the
//! simulator itself: the secular gravity-gradient torque of the `normal-ops` hold is about
//! 0.05 N·m (a day of it with the ideal 600-s unloading kept 31 N·m·s in the wheels, i.e.
//! 31/600 ≈ 0.05 N·m), and a dipole perpendicular to a 25–45 μT field gives at most
//! `m |B|`: 4,000 A·m² × 30 μT = 0.12 N·m per bar, about twice the secular torque once the
//! geometry (only the part of `h` perpendicular to `B` can be dumped) is counted. A few
//! hundred A·m² (a small LEO satellite's bars) would leave the wheels to saturate with this
//! inertia: `docs/magnetics.md` §7 has the measurement.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Number of torquer bars.
pub const BARS: usize = 3;

/// Tesla per nanotesla.
pub const TESLA_PER_NT: f64 = 1.0e-9;

/// The torquer bars' parameters (scenario `[torquers]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TorquerParams {
    /// Bar axes in ACS (normalised on use), bar 1, 2, 3.
    pub bar_axes_acs: [[f64; 3]; BARS],
    /// Largest dipole per bar (A·m²), either sign (module doc: assumed).
    pub dipole_limit_am2: f64,
}

impl Default for TorquerParams {
    fn default() -> Self {
        Self {
            bar_axes_acs: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            dipole_limit_am2: 4_000.0,
        }
    }
}

impl TorquerParams {
    /// Axes not zero and finite, limit positive.
    ///
    /// # Errors
    /// The first offending field, by its TOML path.
    pub fn validate(&self) -> anyhow::Result<()> {
        for (k, a) in self.bar_axes_acs.iter().enumerate() {
            let n = Vector3::from(*a).norm();
            if !(n.is_finite() && n > 1e-9) {
                anyhow::bail!("torquers.bar_axes_acs[{k}] must be a non-zero finite vector");
            }
        }
        if !(self.dipole_limit_am2.is_finite() && self.dipole_limit_am2 > 0.0) {
            anyhow::bail!(
                "torquers.dipole_limit_am2 must be > 0, got {}",
                self.dipole_limit_am2
            );
        }
        Ok(())
    }
}

/// The three bars and the dipole each delivers now.
#[derive(Clone, Debug, PartialEq)]
pub struct TorquerBars {
    axes_acs: [Vector3<f64>; BARS],
    limit_am2: f64,
    /// Dipole each bar delivers (A·m², along its axis).
    dipole_am2: [f64; BARS],
}

impl TorquerBars {
    /// Bars of `p`, all off.
    #[must_use]
    pub fn new(p: &TorquerParams) -> Self {
        let axes_acs = p.bar_axes_acs.map(|a| {
            let v = Vector3::from(a);
            let n = v.norm();
            if n > 0.0 {
                v / n
            } else {
                v
            }
        });
        Self {
            axes_acs,
            limit_am2: p.dipole_limit_am2.abs(),
            dipole_am2: [0.0; BARS],
        }
    }

    /// Drive the bars with the flight core's command (A·m² per bar); a bar with
    /// `stuck[k] = Some(d)` delivers `d` whatever is commanded. Either way the drive's
    /// current limit clamps the dipole: a stuck driver cannot exceed it either.
    pub fn command(&mut self, cmd_am2: &[f64; BARS], stuck: &[Option<f64>; BARS]) {
        for k in 0..BARS {
            let wanted = stuck[k].unwrap_or(cmd_am2[k]);
            self.dipole_am2[k] = if wanted.is_finite() {
                wanted.clamp(-self.limit_am2, self.limit_am2)
            } else {
                0.0
            };
        }
    }

    /// Dipole each bar delivers (A·m²).
    #[must_use]
    pub fn dipole_am2(&self) -> [f64; BARS] {
        self.dipole_am2
    }

    /// Total dipole in ACS (A·m²).
    #[must_use]
    pub fn dipole_acs_am2(&self) -> Vector3<f64> {
        (0..BARS).fold(Vector3::zeros(), |acc, k| {
            acc + self.axes_acs[k] * self.dipole_am2[k]
        })
    }
}

/// Torque of a dipole in a field: `τ = m × B` (N·m; `m` A·m², `B` tesla, same axes).
#[must_use]
pub fn magnetic_torque_nm(dipole_am2: &Vector3<f64>, field_tesla: &Vector3<f64>) -> Vector3<f64> {
    dipole_am2.cross(field_tesla)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// τ = m × B: perpendicular to both, |τ| = |m||B| sin θ, and the textbook case
    /// x̂ × ŷ = ẑ (1000 A·m² in 30 μT: 0.03 N·m).
    #[test]
    fn torque_is_m_cross_b() {
        let t = magnetic_torque_nm(
            &Vector3::new(1000.0, 0.0, 0.0),
            &Vector3::new(0.0, 30e-6, 0.0),
        );
        assert!((t - Vector3::new(0.0, 0.0, 0.03)).norm() < 1e-15, "{t}");
        let m = Vector3::new(1200.0, -300.0, 2500.0);
        let b = Vector3::new(-12e-6, 25e-6, 7e-6);
        let t = magnetic_torque_nm(&m, &b);
        assert!(t.dot(&m).abs() < 1e-12 * m.norm() * t.norm());
        assert!(t.dot(&b).abs() < 1e-12 * b.norm() * t.norm());
        let sin = m.normalize().cross(&b.normalize()).norm();
        assert!((t.norm() - m.norm() * b.norm() * sin).abs() < 1e-15);
    }

    /// Commands are clamped per bar, a stuck bar ignores its command (within the limit), and
    /// the total dipole follows the bar axes.
    #[test]
    fn bars_clamp_stick_and_sum_along_their_axes() {
        let p = TorquerParams {
            bar_axes_acs: [[2.0, 0.0, 0.0], [0.0, 1.0, 1.0], [0.0, 0.0, 1.0]],
            dipole_limit_am2: 500.0,
        };
        let mut bars = TorquerBars::new(&p);
        bars.command(&[800.0, -100.0, f64::NAN], &[None, None, None]);
        assert_eq!(bars.dipole_am2(), [500.0, -100.0, 0.0]);
        let s = std::f64::consts::FRAC_1_SQRT_2;
        let expect = Vector3::new(500.0, -100.0 * s, -100.0 * s);
        assert!((bars.dipole_acs_am2() - expect).norm() < 1e-9);
        bars.command(&[0.0, 0.0, 0.0], &[None, None, Some(350.0)]);
        assert_eq!(bars.dipole_am2(), [0.0, 0.0, 350.0]);
        // A driver stuck beyond the current limit still delivers at most the limit.
        bars.command(&[0.0, 0.0, 0.0], &[Some(-9_000.0), None, None]);
        assert_eq!(bars.dipole_am2(), [-500.0, 0.0, 0.0]);
        assert!(p.validate().is_ok());
        let bad = TorquerParams {
            dipole_limit_am2: 0.0,
            ..TorquerParams::default()
        };
        assert!(bad.validate().is_err());
    }
}
