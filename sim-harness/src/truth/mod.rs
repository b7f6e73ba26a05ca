//! # Truth models: time, orbit, Sun, sky, rigid-body dynamics, geomagnetic field, torquer bars
//!
//! Everything the sensors see is computed here, in J2000/ICRS axes (`eci`), km, km/s, rad.
//! The reference physics the ground uses as well (time scales, Sun ephemeris, sky,
//! aberration) lives in `gro-reference` and is re-exported here under its old paths; the
//! orbit and the rigid body are the simulator's own.
pub use gro_reference::{aberration, sky, sun, time};
pub mod dynamics;
pub mod field;
pub mod orbit;
pub mod torquer;
