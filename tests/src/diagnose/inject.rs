//! # Effects the library does not have, injected into a real run folder
//!
//! `sim-harness` has hooks only for the library's effects. To show that something outside the
//! library ends up as *unexplained* structure (issue 5) on real harness telemetry, this module
//! copies a run folder and adds an effect to the raw FHST counts, re-encoding every packet in
//! ICD order (raw frame, ephemeris, housekeeping, events per cycle):
//!
//! * [`Injected::TemperatureSquared`]: an FHST focal-plane shift `ΔH = k (T − T̄)²` of the
//!   tracker's own temperature (a thermo-elastic term beyond the linear one);
//! * [`Injected::MagneticTwicePerOrbit`]: a line-of-sight shift `ΔH = A cos 2u` following
//!   the geomagnetic field strength (twice per orbit; the library's orbit-periodic term is
//!   once per orbit);
//! * [`Injected::PostSlewOscillation`]: a decaying structural oscillation of the tracker's
//!   line of sight after every slew, `ΔH = A e^{−t/τ} sin(2π t/P)` (algorithms.md §9 row 16).
//!
//! `truth.json` gets the injected effect appended to `present_effects` and
//! `undeclared_effects`; `metadata.json` is copied unchanged (the operator does not know).

use anyhow::Context;
use fsw_core::sensor::SensorId;
use gro_reference::run_folder::{Truth, TRUTH_FILE};
use ground_tool::tp;
use sim_harness::telemetry::PacketWriter;
use std::path::Path;

/// An effect outside the library.
#[derive(Clone, Copy, Debug)]
pub enum Injected {
    /// `ΔH = k (T − T̄)²` on FHST `tracker`, k in arcsec/°C².
    TemperatureSquared {
        /// Tracker (FHST1 or FHST2).
        tracker: SensorId,
        /// Coefficient (arcsec/°C²).
        k_arcsec_per_c2: f64,
    },
    /// `ΔH = A cos(2u)`, u the argument of latitude: a sensitivity to the geomagnetic field
    /// strength, which varies twice per orbit (algorithms.md §9 row 18).
    MagneticTwicePerOrbit {
        /// Tracker (FHST1 or FHST2).
        tracker: SensorId,
        /// Amplitude (arcsec).
        amplitude_arcsec: f64,
    },
    /// `ΔH = A e^{−t/τ} sin(2π t/P)` after the end of every slew (high-rate run).
    PostSlewOscillation {
        /// Tracker (FHST1 or FHST2).
        tracker: SensorId,
        /// Amplitude (arcsec).
        amplitude_arcsec: f64,
        /// Period (s).
        period_s: f64,
        /// Decay time (s).
        decay_s: f64,
    },
}

/// The out-of-library effects the tests inject into a clean run, each on FHST2: (short name,
/// effect, the regressor its residual structure follows) — `ΔH = 2″/°C² (T − T̄)²`, a
/// post-slew ringing of 20″ (60 s period, 200 s decay) and a twice-per-orbit shift of 6″.
pub const NON_LIBRARY: [(&str, Injected, &str); 3] = [
    (
        "t2",
        Injected::TemperatureSquared {
            tracker: SensorId::Fhst2,
            k_arcsec_per_c2: 2.0,
        },
        "temperature_c",
    ),
    (
        "osc",
        Injected::PostSlewOscillation {
            tracker: SensorId::Fhst2,
            amplitude_arcsec: 20.0,
            period_s: 60.0,
            decay_s: 200.0,
        },
        "time_since_slew_s",
    ),
    (
        "mag",
        Injected::MagneticTwicePerOrbit {
            tracker: SensorId::Fhst2,
            amplitude_arcsec: 6.0,
        },
        "orbit_phase_rad",
    ),
];

impl Injected {
    /// Name recorded in truth.json.
    #[must_use]
    pub fn name(&self) -> String {
        match self {
            Self::TemperatureSquared { tracker, .. } => {
                format!(
                    "{}.temperature_squared_shift",
                    tracker.name().to_lowercase()
                )
            }
            Self::PostSlewOscillation { tracker, .. } => {
                format!("{}.post_slew_oscillation", tracker.name().to_lowercase())
            }
            Self::MagneticTwicePerOrbit { tracker, .. } => {
                format!("{}.magnetic_sensitivity", tracker.name().to_lowercase())
            }
        }
    }
}

/// Copy `src` to `dst` with the effect added to the raw FHST counts.
///
/// # Errors
/// Unreadable input, I/O.
pub fn inject_run(src: &Path, dst: &Path, effect: Injected) -> anyhow::Result<()> {
    let tm = tp::read_file(&src.join("telemetry.bin"))?;
    std::fs::create_dir_all(dst).with_context(|| format!("creating {}", dst.display()))?;
    let tracker = match effect {
        Injected::TemperatureSquared { tracker, .. }
        | Injected::PostSlewOscillation { tracker, .. }
        | Injected::MagneticTwicePerOrbit { tracker, .. } => tracker.index().min(1),
    };
    let n = tm.raw.len().max(1) as f64;
    let t_mean = tm
        .raw
        .iter()
        .map(|r| f64::from(r.temperatures_centi_c[tracker]) * 0.01)
        .sum::<f64>()
        / n;
    let counts_per_arcsec = 1.0 / 7.78;
    let mut last_slew_end: Option<f64> = None;
    let mut was_high = false;
    let file = std::fs::File::create(dst.join("telemetry.bin"))?;
    let mut w = PacketWriter::new(std::io::BufWriter::new(file));
    let (mut ie, mut ih, mut iv) = (0usize, 0usize, 0usize);
    for raw in &tm.raw {
        let mut f = *raw;
        let t = f.time.seconds();
        if was_high && !f.iru.high_rate {
            last_slew_end = Some(t);
        }
        was_high = f.iru.high_rate;
        let dh_arcsec = match effect {
            Injected::TemperatureSquared {
                k_arcsec_per_c2, ..
            } => {
                let dt = f64::from(f.temperatures_centi_c[tracker]) * 0.01 - t_mean;
                k_arcsec_per_c2 * dt * dt
            }
            Injected::MagneticTwicePerOrbit {
                amplitude_arcsec, ..
            } => match ground_tool::pipeline::observations::interpolate_orbit(&tm.ephemeris, t) {
                Some((p, v)) => {
                    let h = p.cross(&v);
                    let node = nalgebra::Vector3::z().cross(&h).normalize();
                    let y = h.normalize().cross(&node);
                    let u = p.dot(&y).atan2(p.dot(&node));
                    amplitude_arcsec * (2.0 * u).cos()
                }
                None => 0.0,
            },
            Injected::PostSlewOscillation {
                amplitude_arcsec,
                period_s,
                decay_s,
                ..
            } => match last_slew_end {
                Some(e) if !f.iru.high_rate => {
                    let s = t - e;
                    amplitude_arcsec
                        * (-s / decay_s).exp()
                        * (std::f64::consts::TAU * s / period_s).sin()
                }
                _ => 0.0,
            },
        };
        if let Some(sample) = f.fhst.get_mut(tracker) {
            if sample.flags & fsw_core::raw::FHST_FLAG_VALID != 0 {
                let c = f64::from(sample.h_counts) + dh_arcsec * counts_per_arcsec;
                #[allow(clippy::cast_possible_truncation)]
                {
                    sample.h_counts =
                        c.round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16;
                }
            }
        }
        w.raw(&f)?;
        while ie < tm.ephemeris.len() && tm.ephemeris[ie].time <= f.time {
            w.ephemeris(&tm.ephemeris[ie])?;
            ie += 1;
        }
        while ih < tm.housekeeping.len() && tm.housekeeping[ih].time <= f.time {
            w.housekeeping(&tm.housekeeping[ih])?;
            ih += 1;
        }
        while iv < tm.events.len() && tm.events[iv].0 <= f.time {
            w.event(tm.events[iv].0, &tm.events[iv].1)?;
            iv += 1;
        }
    }
    w.finish()?;
    for name in ["metadata.json", "summary.json"] {
        if src.join(name).exists() {
            std::fs::copy(src.join(name), dst.join(name))?;
        }
    }
    if src.join("uploads").is_dir() {
        std::fs::create_dir_all(dst.join("uploads"))?;
        for e in std::fs::read_dir(src.join("uploads"))? {
            let e = e?;
            std::fs::copy(e.path(), dst.join("uploads").join(e.file_name()))?;
        }
    }
    if let Some(mut truth) = Truth::read(src)? {
        truth.present_effects.push(effect.name());
        truth.undeclared_effects.push(effect.name());
        truth.injected_effect = Some(format!("{effect:?}"));
        std::fs::write(
            dst.join(TRUTH_FILE),
            serde_json::to_string_pretty(&truth.to_json_value()?)?,
        )?;
    }
    Ok(())
}
