//! Unit conversion constants, named `<TO>_PER_<FROM>`: multiply by them
//! (`x_rad = x_arcsec * RAD_PER_ARCSEC`).

/// Radians per arcsecond.
pub const RAD_PER_ARCSEC: f64 = core::f64::consts::PI / (180.0 * 3600.0);
/// Arcseconds per radian.
pub const ARCSEC_PER_RAD: f64 = 180.0 * 3600.0 / core::f64::consts::PI;
/// Radians per degree.
pub const RAD_PER_DEG: f64 = core::f64::consts::PI / 180.0;
/// Degrees per radian.
pub const DEG_PER_RAD: f64 = 180.0 / core::f64::consts::PI;
/// Seconds per day.
pub const S_PER_DAY: f64 = 86_400.0;
