//! # Truth models: time, orbit, Sun, sky, rigid-body dynamics
//!
//! Everything the sensors see is computed here, in J2000/ICRS axes (`eci`), km, km/s, rad.
pub mod aberration;
pub mod dynamics;
pub mod orbit;
pub mod sky;
pub mod sun;
pub mod time;
mod vsop87_earth;
