//! Unit conversion constants, named `<TO>_PER_<FROM>`: multiply by them
//! (`x_rad = x_arcsec * RAD_PER_ARCSEC`).
//! Values are exact by definition; see docs/conventions.md ("Units and names").

/// Radians per arcsecond.
/// Exact; docs/conventions.md ("Units and names": radians inside, arcsec at I/O).
pub const RAD_PER_ARCSEC: f64 = core::f64::consts::PI / (180.0 * 3600.0);
/// Arcseconds per radian.
/// Exact; docs/conventions.md ("Units and names").
pub const ARCSEC_PER_RAD: f64 = 180.0 * 3600.0 / core::f64::consts::PI;
/// Radians per degree.
/// Exact; docs/conventions.md ("Units and names").
pub const RAD_PER_DEG: f64 = core::f64::consts::PI / 180.0;
/// Degrees per radian.
/// Exact; docs/conventions.md ("Units and names").
pub const DEG_PER_RAD: f64 = 180.0 / core::f64::consts::PI;
/// Seconds per day.
/// The SI day of 86 400 s (TT and TAI days, as in docs/conventions.md time scales).
pub const S_PER_DAY: f64 = 86_400.0;
