//! # The regressors of the residual analysis and the tests run against each
//!
//! Why a module of their own: the effect library ([`super::effects`]) names each effect's
//! signature by its regressors, and the structure tests ([`super::structure`]) run on them;
//! the tests also need the fit's residuals ([`super::fit`]), which need the library. With the
//! regressors here, the library depends on neither the tests nor the fit, and the three
//! import in one direction: structure → fit → effects → regressor.

use super::measurements::Measurement;
use fsw_core::units::DEG_PER_RAD;
use serde::Serialize;

/// A regressor of the residual analysis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Regressor {
    /// Time since the first frame (s).
    Time,
    /// Argument of latitude (rad).
    OrbitPhase,
    /// Sun angle to the boresight (deg).
    SunAngle,
    /// FOV position H or α (deg).
    FovH,
    /// FOV position V or β (deg).
    FovV,
    /// FOV radius (deg).
    FovRadius,
    /// Catalog magnitude.
    Magnitude,
    /// Body rate about the sensor x axis (deg/s).
    RateX,
    /// About y.
    RateY,
    /// About z (boresight).
    RateZ,
    /// IRU rate mode (0 low, 1 high).
    RateMode,
    /// Barycentric velocity direction, sensor x component.
    VelocityX,
    /// Sensor y component.
    VelocityY,
    /// The sensor's temperature deviation (°C).
    Temperature,
    /// IRU baseplate temperature deviation (°C).
    IruTemperature,
    /// Star id (grouping).
    StarId,
    /// Time since the end of the last slew (s).
    SinceSlew,
}

impl Regressor {
    /// All regressors.
    pub const ALL: [Regressor; 17] = [
        Self::Time,
        Self::OrbitPhase,
        Self::SunAngle,
        Self::FovH,
        Self::FovV,
        Self::FovRadius,
        Self::Magnitude,
        Self::RateX,
        Self::RateY,
        Self::RateZ,
        Self::RateMode,
        Self::VelocityX,
        Self::VelocityY,
        Self::Temperature,
        Self::IruTemperature,
        Self::StarId,
        Self::SinceSlew,
    ];

    /// Report name.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Time => "time_s",
            Self::OrbitPhase => "orbit_phase_rad",
            Self::SunAngle => "sun_angle_deg",
            Self::FovH => "fov_h_deg",
            Self::FovV => "fov_v_deg",
            Self::FovRadius => "fov_radius_deg",
            Self::Magnitude => "magnitude",
            Self::RateX => "rate_sensor_x_deg_per_s",
            Self::RateY => "rate_sensor_y_deg_per_s",
            Self::RateZ => "rate_sensor_z_deg_per_s",
            Self::RateMode => "rate_mode",
            Self::VelocityX => "velocity_dir_sensor_x",
            Self::VelocityY => "velocity_dir_sensor_y",
            Self::Temperature => "temperature_c",
            Self::IruTemperature => "iru_temperature_c",
            Self::StarId => "star_id",
            Self::SinceSlew => "time_since_slew_s",
        }
    }

    /// Value for a measurement (NaN: not applicable).
    #[must_use]
    pub fn value(self, m: &Measurement) -> f64 {
        match self {
            Self::Time => m.t_s,
            Self::OrbitPhase => m.orbit_phase,
            Self::SunAngle => m.sun_angle_deg,
            Self::FovH => m.ang[0] * DEG_PER_RAD,
            Self::FovV => m.ang[1] * DEG_PER_RAD,
            Self::FovRadius => (m.ang[0].powi(2) + m.ang[1].powi(2)).sqrt() * DEG_PER_RAD,
            Self::Magnitude => m.magnitude,
            Self::RateX => m.rate_sensor.x * DEG_PER_RAD,
            Self::RateY => m.rate_sensor.y * DEG_PER_RAD,
            Self::RateZ => m.rate_sensor.z * DEG_PER_RAD,
            Self::RateMode => f64::from(u8::from(m.high_rate)),
            Self::VelocityX => m.vel_sensor.x,
            Self::VelocityY => m.vel_sensor.y,
            Self::Temperature => m.dtemp[m.sensor],
            Self::IruTemperature => m.dtemp[4],
            Self::StarId => {
                if m.star == 0 {
                    f64::NAN
                } else {
                    f64::from(m.star)
                }
            }
            Self::SinceSlew => m.since_slew_s,
        }
    }

    /// The tests run against this regressor.
    pub(super) fn methods(self) -> &'static [Method] {
        match self {
            Self::OrbitPhase => &[Method::Harmonics],
            Self::StarId | Self::RateMode => &[Method::Groups],
            Self::SinceSlew => &[
                Method::Binned,
                Method::Cubic,
                Method::FineBinned,
                Method::Ringing,
            ],
            _ => &[Method::Binned, Method::Cubic],
        }
    }
}

/// Test method.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// Binned means (ANOVA over quantile bins).
    Binned,
    /// Cubic fit against a constant.
    Cubic,
    /// Orbital harmonics 1–3.
    Harmonics,
    /// Grouping (star id, rate mode).
    Groups,
    /// Fixed 15-s bins over the first 900 s after a slew (oscillations after maneuvers).
    FineBinned,
    /// A decaying sinusoid `e^{−x/T} (a cos 2πx/P + b sin 2πx/P)` over the first 900 s after
    /// a slew, the best of a grid of periods P (5–300 s) and decay times T (60, 200, 600 s),
    /// its p-value Bonferroni-corrected over the grid ([`super::structure::RINGING_GRID`]): the matched test
    /// for structural ringing after maneuvers (algorithms.md §9 row 16), which the 60 bins of
    /// `FineBinned` dilute when the ringing lasts a few minutes.
    Ringing,
}
