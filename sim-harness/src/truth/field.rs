//! # The geomagnetic field along the truth orbit
//!
//! Why: the TAMs ([`crate::sensors::tam`]) measure it. The model is the reference one
//! ([`gro_reference::field`]: IGRF synthesis with DGRF 1990/1995, GCRS ↔ ITRS through
//! [`gro_reference::earth_orientation`]); the simulation's `eci` axes are J2000/ICRS, taken
//! as GCRS (the 23 mas frame bias is ignored, as everywhere in the simulator).
//!
//! The truth field *is* the model here: the crustal and external fields the model omits
//! (of order 100 nT at 450 km, algorithms.md §10a) are not simulated, so a ground or onboard
//! field model built from the same coefficients sees no model error unless a scenario adds
//! one later.
//!
//! Outside the model's span (before 1990-01-01 or after 1995-01-01 UTC) the field is unknown:
//! [`TruthField::field_eci_nt`] returns `None` and the TAMs report invalid readings; the run
//! goes on.

use nalgebra::Vector3;

use gro_reference::field::{FieldEvaluator, FieldModel};
use gro_reference::time::SimClock;

/// The field along the orbit, cached per [`FieldEvaluator::DEFAULT_REFRESH_S`].
#[derive(Clone, Debug)]
pub struct TruthField {
    evaluator: FieldEvaluator,
}

impl TruthField {
    /// DGRF 1990/1995 with the default cache lifetime.
    ///
    /// # Errors
    /// A malformed embedded coefficient table (a build defect).
    pub fn new() -> anyhow::Result<Self> {
        Ok(Self {
            evaluator: FieldEvaluator::new(
                FieldModel::dgrf_1990_1995()?,
                FieldEvaluator::DEFAULT_REFRESH_S,
            ),
        })
    }

    /// The field (nT, `eci` axes) at `pos_eci_km` at `t_s` of `clock`; `None` outside the
    /// model's span.
    pub fn field_eci_nt(
        &mut self,
        clock: &SimClock,
        t_s: f64,
        pos_eci_km: &Vector3<f64>,
    ) -> Option<Vector3<f64>> {
        self.evaluator
            .field_gcrs_nt(clock.epoch(t_s), pos_eci_km)
            .ok()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use gro_reference::time::epoch_from_iso;

    /// At GRO's altitude the field is 24 000 .. 43 000 nT (data/igrf_reference.csv
    /// `B_total_nT`); outside 1990–1995 it is unknown.
    #[test]
    fn field_magnitude_at_gro_altitude_and_span() {
        let mut f = TruthField::new().unwrap();
        let clock = SimClock::new(epoch_from_iso("1991-04-09T00:00:00Z").unwrap());
        for k in 0..50 {
            let u = f64::from(k) * 0.13;
            let pos = Vector3::new(u.cos(), 0.88 * u.sin(), 0.48 * u.sin()) * 6_833.0;
            let b = f.field_eci_nt(&clock, f64::from(k) * 60.0, &pos).unwrap();
            assert!((20_000.0..45_000.0).contains(&b.norm()), "{}", b.norm());
        }
        let late = SimClock::new(epoch_from_iso("2025-01-01T00:00:00Z").unwrap());
        assert!(f
            .field_eci_nt(&late, 0.0, &Vector3::new(6_833.0, 0.0, 0.0))
            .is_none());
    }
}
