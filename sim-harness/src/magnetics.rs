//! # The magnetometers and coarse Sun sensors in the closed loop (issue 20, first layers)
//!
//! Why: the coarse attitude, Sun acquisition and the ground's TAM calibration need TAM and
//! CSS samples taken with the truth of every cycle. They go into the simulation's own record
//! ([`crate::closed_loop::CycleRecord`] `magnetics`, with the true field they were taken
//! from), into the raw frame the OBC reads (`tam`, `css`), and into the downlink as APID
//! 0x013 right after each raw frame (`docs/icd.md` §3.5, format version 2; `run.rs`).
//!
//! Per cycle (when `[magnetics] enabled = true`; off by default, so that scenarios written
//! before it fly and downlink as before; on in `gro-early-mission` and `normal-ops`, at about
//! a quarter more simulator cost per cycle, `docs/magnetics.md` §3): the field at the truth position
//! ([`crate::truth::field`]), TAM1 and TAM2 ([`crate::sensors::tam`], with the torquer bars'
//! field for the dipole they delivered while the TAMs sampled: [`crate::truth::torquer`])
//! and the CSS set ([`crate::sensors::css`]). Each model
//! draws from its own random stream, so the FHST, FSS and IRU draws and therefore every
//! packet of `telemetry.bin` but the 0x013 ones do not change.
//! `docs/magnetics.md` has the measured numbers.

use nalgebra::Vector3;

pub use crate::scenario::MagneticsParams;
use crate::scenario::Scenario;
use crate::sensors::css::{Css, CssReading};
use crate::sensors::tam::{Tam, TamReading};
use crate::sensors::TruthSnapshot;
use crate::truth::field::TruthField;
use crate::truth::time::SimClock;

/// One cycle's magnetics: the truth field and the readings.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct MagneticsRecord {
    /// The true geomagnetic field at the spacecraft (nT, `eci` axes); `None` outside the field
    /// model's span or with magnetics disabled.
    pub field_eci_nt: Option<Vector3<f64>>,
    /// TAM1 (primary) and TAM2 readings.
    pub tam: [TamReading; 2],
    /// The CSS set's reading.
    pub css: CssReading,
}

/// The field model and the sensors of the loop.
#[derive(Clone, Debug)]
pub struct Magnetics {
    field: TruthField,
    tam: [Tam; 2],
    css: Css,
}

impl Magnetics {
    /// The models of scenario `s` (its seed), `None` when `[magnetics] enabled = false`.
    ///
    /// # Errors
    /// A malformed embedded field model (a build defect).
    pub fn of_scenario(s: &Scenario) -> anyhow::Result<Option<Self>> {
        if !s.magnetics.enabled {
            return Ok(None);
        }
        Ok(Some(Self {
            field: TruthField::new()?,
            tam: [
                Tam::new(0, s.tam1.clone(), s.seed),
                Tam::new(1, s.tam2.clone(), s.seed),
            ],
            css: Css::new(s.css.clone(), s.seed),
        }))
    }

    /// The TAMs.
    #[must_use]
    pub fn tam(&self) -> &[Tam; 2] {
        &self.tam
    }

    /// The CSS set.
    #[must_use]
    pub fn css(&self) -> &Css {
        &self.css
    }

    /// Sample everything at the truth of this cycle, the torquer bars delivering
    /// `dipole_acs_am2` (ACS, A·m²; zero while they are off). Allocates nothing.
    pub fn sample(
        &mut self,
        clock: &SimClock,
        truth: &TruthSnapshot,
        dipole_acs_am2: &Vector3<f64>,
    ) -> MagneticsRecord {
        let field_eci_nt = self.field.field_eci_nt(clock, truth.t_s, &truth.pos_eci_km);
        MagneticsRecord {
            field_eci_nt,
            tam: [
                self.tam[0].sample(truth, field_eci_nt.as_ref(), dipole_acs_am2),
                self.tam[1].sample(truth, field_eci_nt.as_ref(), dipole_acs_am2),
            ],
            css: self.css.sample(truth),
        }
    }
}

/// The hardware words the OBC reads from a TAM reading (`docs/icd.md` §3.5).
#[must_use]
pub fn flight_tam_sample(r: TamReading) -> fsw_core::raw::TamSample {
    fsw_core::raw::TamSample {
        field_counts: r.field_counts,
        flags: if r.valid {
            fsw_core::raw::TAM_FLAG_VALID
        } else {
            0
        },
    }
}

/// The hardware words the OBC reads from the CSS set: the first
/// [`fsw_core::raw::CSS_EYES`] eyes (`docs/icd.md` §3.5); no data when the set has none.
#[must_use]
pub fn flight_css_sample(r: &CssReading) -> fsw_core::raw::CssSample {
    let mut counts = [0u16; fsw_core::raw::CSS_EYES];
    for (dst, src) in counts
        .iter_mut()
        .zip(r.counts.iter().take(usize::from(r.eyes)))
    {
        *dst = *src;
    }
    fsw_core::raw::CssSample {
        counts,
        flags: if r.eyes > 0 {
            fsw_core::raw::CSS_FLAG_VALID
        } else {
            0
        },
    }
}
