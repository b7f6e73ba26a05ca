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
//! ([`crate::truth::field`]), TAM1 and TAM2 ([`crate::sensors::tam`]; the torquer bars'
//! dipole is zero: there are none yet) and the CSS set ([`crate::sensors::css`]). Each model
//! draws from its own random stream, so the FHST, FSS and IRU draws and therefore every
//! packet of `telemetry.bin` but the 0x013 ones do not change.
//! `docs/magnetics.md` has the measured numbers.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::scenario::Scenario;
use crate::sensors::css::{Css, CssReading};
use crate::sensors::tam::{Tam, TamReading};
use crate::sensors::TruthSnapshot;
use crate::truth::field::TruthField;
use crate::truth::time::SimClock;

/// Scenario `[magnetics]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MagneticsParams {
    /// Sample the field, the TAMs and the CSSs every cycle into the record and the raw frame
    /// (default off).
    pub enabled: bool,
    /// With `enabled`: uplink the OBC's magnetics table (Table 6: the field model at the
    /// epoch and the TAM knowledge below) at `onboard_table_at_s` (default on, at 2 s: the
    /// catalog, filter, alignment and orbit uplinks fill the first two cycles' events).
    pub onboard_table: bool,
    /// When the magnetics table is uplinked (s from the epoch).
    pub onboard_table_at_s: f64,
    /// The TAM1, TAM2 biases the OBC's table subtracts (mG, sensor axes): zero is prelaunch
    /// knowledge; the ground's determined bias is the "after" case of issue 20.
    pub onboard_tam_bias_milligauss: [[f64; 3]; 2],
    /// The table's `field_sigma_milligauss` (1σ per axis of what is left in a corrected TAM
    /// field); `None`: the OBC's boot value (4 mG, an undetermined bias).
    pub onboard_field_sigma_milligauss: Option<f64>,
}

impl Default for MagneticsParams {
    fn default() -> Self {
        Self {
            enabled: false,
            onboard_table: true,
            onboard_table_at_s: 2.0,
            onboard_tam_bias_milligauss: [[0.0; 3]; 2],
            onboard_field_sigma_milligauss: None,
        }
    }
}

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

    /// Sample everything at the truth of this cycle. Allocates nothing.
    pub fn sample(&mut self, clock: &SimClock, truth: &TruthSnapshot) -> MagneticsRecord {
        let field_eci_nt = self.field.field_eci_nt(clock, truth.t_s, &truth.pos_eci_km);
        let no_dipole = Vector3::zeros();
        MagneticsRecord {
            field_eci_nt,
            tam: [
                self.tam[0].sample(truth, field_eci_nt.as_ref(), &no_dipole),
                self.tam[1].sample(truth, field_eci_nt.as_ref(), &no_dipole),
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
