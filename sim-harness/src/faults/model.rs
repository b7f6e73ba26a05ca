//! # The fault model: what each `[[faults]]` kind is and how the harness applies it
//!
//! The kinds and their fields are tabled in the [`super`] module doc. This module holds the
//! scenario-side definition ([`Fault`], validated with the scenario) and the per-cycle state
//! that applies the faults to the truth sensors, the clock and the uplink ([`FaultState`],
//! used by `closed_loop`). Why apart from the campaign ([`super::campaign`]): the scenario and
//! the closed loop need the model, and the campaign flies scenarios through the closed loop;
//! in one file the two made the scenario, the closed loop and the run import each other.

use anyhow::bail;
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use fsw_core::attitude::rot;
use fsw_core::raw::{
    CssSample, FhstSample, FssSample, TamSample, TimeTag, FHST_FLAG_NEW_STAR, FHST_FLAG_VALID,
    FSS_FLAG_SUN_ALPHA, IRU_CHANNEL_NAMES,
};
use fsw_core::tables::types::{matrix_from_rows, rows_from_matrix};
use fsw_core::tables::{AlignmentTable, TableId};
use fsw_core::units::{ARCSEC_PER_RAD, RAD_PER_DEG};

/// Kinds of fault.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FaultKind {
    /// No FHST data.
    FhstDropout,
    /// A tracker reports a star where it is not (or another star as the tracked one).
    FhstWrongStar,
    /// An FSS reports a displaced Sun.
    FssGlint,
    /// A gyro channel fails.
    IruChannelFailure,
    /// The spacecraft clock jumps.
    TimeTagJump,
    /// An alignment table upload, possibly damaged.
    TableUpload,
    /// An unexpected filter reset.
    FilterReset,
    /// The gyro counters are preset to wrap at a given time.
    IruCounterWrap,
    /// A magnetometer fails: it reads zero (dead electronics) with its valid flag still set,
    /// or, with `offset_milligauss`, its reading jumps by that much (a bias shift).
    TamFailure,
    /// A coarse Sun sensor eye reads `counts` more than it should (a reflection).
    CssGlint,
    /// A magnetic torquer bar delivers a fixed dipole whatever the OBC commands (a driver
    /// stuck on).
    TorquerStuckOn,
    /// A reaction wheel's tachometer stops reporting (its valid bit cleared): the OBC falls
    /// back to counting its torque commands (event 0x0A03).
    TachometerFailed,
}

/// Damage of a `table_upload`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Corruption {
    /// A valid image.
    None,
    /// Bits flipped after the CRC was computed.
    BitFlip,
    /// The end of the image lost.
    Truncate,
    /// A valid image of a rotated alignment.
    Rotate,
    /// A valid image with a NaN matrix element.
    Nan,
}

/// One `[[faults]]` entry (module doc).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Fault {
    /// What.
    pub kind: FaultKind,
    /// Start (s from the epoch).
    pub at_s: f64,
    /// Length of the fault window (s); absent = instantaneous or permanent (per kind).
    #[serde(default)]
    pub duration_s: Option<f64>,
    /// "fhst1", "fhst2", "both" (dropout), "fss1", "fss2".
    #[serde(default)]
    pub sensor: Option<String>,
    /// Focal-plane or Sun-angle displacement (deg).
    #[serde(default)]
    pub offset_deg: Option<[f64; 2]>,
    /// `fhst_wrong_star`: flag the first faulty sample as a new acquisition.
    #[serde(default)]
    pub new_star_flag: bool,
    /// `iru_channel_failure`: channel name.
    #[serde(default)]
    pub channel: Option<String>,
    /// `iru_channel_failure`: the built-in-test bit reports the failure.
    #[serde(default)]
    pub bit: Option<bool>,
    /// `time_tag_jump`: the jump (s).
    #[serde(default)]
    pub offset_s: Option<f64>,
    /// `table_upload`: damage.
    #[serde(default)]
    pub corruption: Option<Corruption>,
    /// `table_upload`: activate after loading.
    #[serde(default)]
    pub activate: Option<bool>,
    /// `table_upload` rotate: angle (deg).
    #[serde(default)]
    pub rotation_deg: Option<f64>,
    /// `table_upload` rotate: "fhst1", "fhst2", "fss1", "fss2".
    #[serde(default)]
    pub rotation_sensor: Option<String>,
    /// `table_upload` bit_flip: number of bits.
    #[serde(default)]
    pub bits: Option<u32>,
    /// `table_upload` truncate: octets removed.
    #[serde(default)]
    pub octets: Option<usize>,
    /// `iru_counter_wrap`: pulses left before the wrap at `at_s` (default 40).
    #[serde(default)]
    pub margin_pulses: Option<u16>,
    /// `tam_failure`: the jump of the reading (mG, sensor axes); absent = reads zero.
    #[serde(default)]
    pub offset_milligauss: Option<[f64; 3]>,
    /// `css_glint`: the eye (0..5: +X, −X, +Y, −Y, +Z, −Z).
    #[serde(default)]
    pub eye: Option<usize>,
    /// `css_glint`: the counts added (default 800).
    #[serde(default)]
    pub counts: Option<f64>,
    /// `torquer_stuck_on`: the dipole the bar delivers (A·m², along its axis).
    #[serde(default)]
    pub dipole_am2: Option<f64>,
}

fn sensor_index(name: &str) -> Option<usize> {
    ["fhst1", "fhst2", "fss1", "fss2"]
        .iter()
        .position(|n| *n == name)
}

impl Fault {
    /// End of the fault window (s): `at_s + duration_s`, or `at_s` for instantaneous and
    /// permanent faults.
    #[must_use]
    pub fn end_s(&self) -> f64 {
        self.at_s + self.duration_s.unwrap_or(0.0)
    }

    /// Whether a windowed fault is active at `t_s` (`[at_s, at_s + duration_s)`; without a
    /// duration, from `at_s` on).
    #[must_use]
    pub fn active(&self, t_s: f64) -> bool {
        t_s + 1e-9 >= self.at_s && self.duration_s.is_none_or(|d| t_s + 1e-9 < self.at_s + d)
    }

    /// Which FHSTs (bit 0 = FHST1, bit 1 = FHST2) or FSSs (same bits) the fault addresses.
    pub(super) fn unit_mask(&self) -> u8 {
        match self.sensor.as_deref() {
            Some("fhst1" | "fss1" | "tam1") => 1,
            Some("fhst2" | "fss2" | "tam2") => 2,
            Some("both") => 3,
            _ => 0,
        }
    }

    /// The IRU channel index of an `iru_channel_failure`.
    #[must_use]
    pub fn channel_index(&self) -> Option<usize> {
        let name = self.channel.as_deref()?;
        IRU_CHANNEL_NAMES.iter().position(|n| *n == name)
    }

    /// Check the fields of this kind; `here` names the entry.
    ///
    /// # Errors
    /// A missing, unknown or out-of-range field, named.
    pub fn validate(&self, here: &str) -> anyhow::Result<()> {
        if !(self.at_s.is_finite() && self.at_s >= 0.0) {
            bail!("{here}.at_s must be ≥ 0, got {}", self.at_s);
        }
        if let Some(d) = self.duration_s {
            if !(d.is_finite() && d > 0.0) {
                bail!("{here}.duration_s must be > 0, got {d}");
            }
        }
        let need_duration = || -> anyhow::Result<()> {
            if self.duration_s.is_none() {
                bail!("{here}: kind {:?} needs duration_s", self.kind);
            }
            Ok(())
        };
        let sensor = self.sensor.as_deref();
        match self.kind {
            FaultKind::FhstDropout => {
                need_duration()?;
                if !matches!(sensor, Some("fhst1" | "fhst2" | "both")) {
                    bail!("{here}.sensor must be \"fhst1\", \"fhst2\" or \"both\"");
                }
            }
            FaultKind::FhstWrongStar => {
                need_duration()?;
                if !matches!(sensor, Some("fhst1" | "fhst2")) {
                    bail!("{here}.sensor must be \"fhst1\" or \"fhst2\"");
                }
            }
            FaultKind::FssGlint => {
                need_duration()?;
                if !matches!(sensor, Some("fss1" | "fss2")) {
                    bail!("{here}.sensor must be \"fss1\" or \"fss2\"");
                }
                if self.offset_deg.is_none() {
                    bail!("{here}: kind fss_glint needs offset_deg = [alpha, beta]");
                }
            }
            FaultKind::IruChannelFailure => {
                if self.channel_index().is_none() {
                    bail!("{here}.channel must be one of X1, X2, Y1, Y2, Z1, Z2");
                }
            }
            FaultKind::TimeTagJump => match self.offset_s {
                Some(o) if o.is_finite() && o.abs() <= 1.0e6 => {}
                _ => bail!("{here}.offset_s must be a number of seconds within ±1e6"),
            },
            FaultKind::TableUpload => {
                let Some(c) = self.corruption else {
                    bail!("{here}: kind table_upload needs corruption = \"none\" | \"bit_flip\" | \"truncate\" | \"rotate\" | \"nan\"");
                };
                if c == Corruption::Rotate {
                    match self.rotation_deg {
                        Some(a) if a.is_finite() && a.abs() <= 180.0 => {}
                        _ => bail!("{here}.rotation_deg must be in [-180, 180]"),
                    }
                    if self
                        .rotation_sensor
                        .as_deref()
                        .and_then(sensor_index)
                        .is_none()
                    {
                        bail!("{here}.rotation_sensor must be fhst1, fhst2, fss1 or fss2");
                    }
                }
                if self.bits == Some(0) {
                    bail!("{here}.bits must be ≥ 1");
                }
            }
            FaultKind::FilterReset => {}
            FaultKind::IruCounterWrap => {
                if self.margin_pulses.is_some_and(|m| m > 30_000) {
                    bail!("{here}.margin_pulses must be ≤ 30000");
                }
            }
            FaultKind::TamFailure => {
                if !matches!(sensor, Some("tam1" | "tam2")) {
                    bail!("{here}.sensor must be \"tam1\" or \"tam2\"");
                }
                if let Some(o) = self.offset_milligauss {
                    if !o.iter().all(|x| x.is_finite() && x.abs() <= 1_000.0) {
                        bail!("{here}.offset_milligauss must be within ±1000 mG");
                    }
                }
            }
            FaultKind::TorquerStuckOn => {
                if !matches!(sensor, Some("mtb1" | "mtb2" | "mtb3")) {
                    bail!("{here}.sensor must be \"mtb1\", \"mtb2\" or \"mtb3\"");
                }
                if !self
                    .dipole_am2
                    .is_some_and(|d| d.is_finite() && d.abs() <= 100_000.0)
                {
                    bail!("{here}.dipole_am2 must be given, within ±100000 A·m²");
                }
            }
            FaultKind::TachometerFailed => {
                need_duration()?;
                if !matches!(sensor, Some("rwa1" | "rwa2" | "rwa3" | "rwa4")) {
                    bail!("{here}.sensor must be \"rwa1\", \"rwa2\", \"rwa3\" or \"rwa4\"");
                }
            }
            FaultKind::CssGlint => {
                need_duration()?;
                if self.eye.is_none_or(|e| e >= fsw_core::raw::CSS_EYES) {
                    bail!("{here}.eye must be 0..5 (+X, -X, +Y, -Y, +Z, -Z)");
                }
                if let Some(c) = self.counts {
                    if !(c.is_finite() && (0.0..=65_535.0).contains(&c)) {
                        bail!("{here}.counts must be within 0..65535");
                    }
                }
            }
        }
        if let Some(o) = self.offset_deg {
            if !o.iter().all(|x| x.is_finite() && x.abs() <= 60.0) {
                bail!("{here}.offset_deg must be within ±60°");
            }
        }
        Ok(())
    }

    /// The damaged alignment image of a `table_upload` built from `base`.
    ///
    /// # Errors
    /// Encoding failures (none for an alignment table).
    pub fn upload_image(&self, base: &AlignmentTable, created: TimeTag) -> anyhow::Result<Vec<u8>> {
        let mut table = *base;
        let corruption = self.corruption.unwrap_or(Corruption::None);
        match corruption {
            Corruption::Rotate => {
                let angle = self.rotation_deg.unwrap_or(0.0) * RAD_PER_DEG;
                let r = rot(&Vector3::new(angle, 0.0, 0.0));
                let m = match self.rotation_sensor.as_deref().and_then(sensor_index) {
                    Some(0) => &mut table.m_acs_from_fhst1,
                    Some(1) => &mut table.m_acs_from_fhst2,
                    Some(2) => &mut table.m_acs_from_fss1,
                    _ => &mut table.m_acs_from_fss2,
                };
                *m = rows_from_matrix(&(r * matrix_from_rows(m)));
            }
            Corruption::Nan => table.m_acs_from_fhst2[1][1] = f64::NAN,
            Corruption::None | Corruption::BitFlip | Corruption::Truncate => {}
        }
        let mut image = crate::uplink::image(TableId::Alignment, created, &table)?;
        match corruption {
            Corruption::BitFlip => {
                // Payload octets only (after the 20-octet header), spread over the image.
                let bits = self.bits.unwrap_or(1) as usize;
                let payload = image.len().saturating_sub(24);
                for k in 0..bits {
                    let octet = 20 + (k * 37 + 11) % payload.max(1);
                    if let Some(b) = image.get_mut(octet) {
                        *b ^= 1 << (k % 8);
                    }
                }
            }
            Corruption::Truncate => {
                let n = self.octets.unwrap_or(16).min(image.len());
                image.truncate(image.len() - n);
            }
            _ => {}
        }
        Ok(image)
    }
}

/// Validate every `[[faults]]` entry.
///
/// # Errors
/// The first bad entry, named `faults[i]`.
pub fn validate_all(faults: &[Fault]) -> anyhow::Result<()> {
    for (i, f) in faults.iter().enumerate() {
        f.validate(&format!("faults[{i}]"))?;
    }
    Ok(())
}

/// Per-run state of the sensor faults (what the harness needs between cycles).
#[derive(Clone, Debug, Default)]
pub struct FaultState {
    /// Offset (rad, H and V) of each `fhst_wrong_star` fault, fixed at its first cycle.
    wrong_star_offset_rad: Vec<Option<[f64; 2]>>,
}

impl FaultState {
    /// State for `faults`.
    #[must_use]
    pub fn new(faults: &[Fault]) -> Self {
        Self {
            wrong_star_offset_rad: vec![None; faults.len()],
        }
    }

    /// Apply the FHST faults active at `t_s` to tracker `unit`'s sample. `other_star` gives,
    /// on demand, the (H, V) offset (rad) from the tracked star to the nearest other star.
    pub fn apply_fhst(
        &mut self,
        faults: &[Fault],
        unit: usize,
        t_s: f64,
        sample: FhstSample,
        resolution_arcsec_per_count: f64,
        other_star: impl Fn() -> Option<[f64; 2]>,
    ) -> FhstSample {
        let mut out = sample;
        let bit = 1u8 << unit.min(1);
        for (i, f) in faults.iter().enumerate() {
            if f.unit_mask() & bit == 0 || !f.active(t_s) {
                continue;
            }
            match f.kind {
                FaultKind::FhstDropout => out = FhstSample::default(),
                FaultKind::FhstWrongStar => {
                    if out.flags & FHST_FLAG_VALID == 0 {
                        continue;
                    }
                    let first = self
                        .wrong_star_offset_rad
                        .get(i)
                        .is_some_and(Option::is_none);
                    if first {
                        let off = match f.offset_deg {
                            Some([h, v]) => Some([h * RAD_PER_DEG, v * RAD_PER_DEG]),
                            None => other_star(),
                        };
                        if let Some(slot) = self.wrong_star_offset_rad.get_mut(i) {
                            *slot = Some(off.unwrap_or([0.0; 2]));
                        }
                        if f.new_star_flag {
                            out.flags |= FHST_FLAG_NEW_STAR;
                        }
                    }
                    let [dh, dv] = self
                        .wrong_star_offset_rad
                        .get(i)
                        .copied()
                        .flatten()
                        .unwrap_or([0.0; 2]);
                    let q = resolution_arcsec_per_count;
                    out.h_counts = shift_counts(out.h_counts, dh * ARCSEC_PER_RAD / q);
                    out.v_counts = shift_counts(out.v_counts, dv * ARCSEC_PER_RAD / q);
                }
                _ => {}
            }
        }
        out
    }

    /// Apply the FSS faults active at `t_s` to sensor `unit`'s sample.
    #[must_use]
    pub fn apply_fss(
        faults: &[Fault],
        unit: usize,
        t_s: f64,
        sample: FssSample,
        resolution_deg_per_count: f64,
    ) -> FssSample {
        let mut out = sample;
        let bit = 1u8 << unit.min(1);
        for f in faults {
            if f.kind != FaultKind::FssGlint || f.unit_mask() & bit == 0 || !f.active(t_s) {
                continue;
            }
            if out.flags & FSS_FLAG_SUN_ALPHA == 0 {
                continue;
            }
            let [da, db] = f.offset_deg.unwrap_or([0.0; 2]);
            out.alpha_counts = shift_counts(out.alpha_counts, da / resolution_deg_per_count);
            out.beta_counts = shift_counts(out.beta_counts, db / resolution_deg_per_count);
        }
        out
    }

    /// Apply the `tam_failure` faults active at `t_s` to TAM `unit`'s words
    /// (`resolution_milligauss_per_count`: the TAM's count size).
    #[must_use]
    pub fn apply_tam(
        faults: &[Fault],
        unit: usize,
        t_s: f64,
        sample: TamSample,
        resolution_milligauss_per_count: f64,
    ) -> TamSample {
        let mut out = sample;
        let bit = 1u8 << unit.min(1);
        for f in faults {
            if f.kind != FaultKind::TamFailure || f.unit_mask() & bit == 0 || !f.active(t_s) {
                continue;
            }
            match f.offset_milligauss {
                Some(offset) => {
                    for (c, o) in out.field_counts.iter_mut().zip(offset) {
                        *c = shift_counts(*c, o / resolution_milligauss_per_count);
                    }
                }
                None => out.field_counts = [0; 3],
            }
        }
        out
    }

    /// The faults of `kind` active at `t_s`, each with the index of its unit in `units`
    /// (the `sensor` names, e.g. "rwa1".."rwa4"); faults naming no such unit are skipped.
    fn active_on_units<'a>(
        faults: &'a [Fault],
        kind: FaultKind,
        t_s: f64,
        units: &'a [&str],
    ) -> impl Iterator<Item = (usize, &'a Fault)> + 'a {
        faults
            .iter()
            .filter(move |f| f.kind == kind && f.active(t_s))
            .filter_map(move |f| {
                let unit = units.iter().position(|u| Some(*u) == f.sensor.as_deref())?;
                Some((unit, f))
            })
    }

    /// The wheels whose tachometer has failed (`tachometer_failed` faults active at `t_s`).
    #[must_use]
    pub fn failed_tachometers(faults: &[Fault], t_s: f64) -> [bool; fsw_core::raw::WHEELS] {
        let mut out = [false; fsw_core::raw::WHEELS];
        let units = ["rwa1", "rwa2", "rwa3", "rwa4"];
        for (wheel, _) in Self::active_on_units(faults, FaultKind::TachometerFailed, t_s, &units) {
            if let Some(slot) = out.get_mut(wheel) {
                *slot = true;
            }
        }
        out
    }

    /// The dipole each torquer bar is stuck at by the `torquer_stuck_on` faults active at
    /// `t_s` (`None`: the bar follows its command).
    #[must_use]
    pub fn stuck_torquers(faults: &[Fault], t_s: f64) -> [Option<f64>; 3] {
        let mut out = [None; 3];
        let units = ["mtb1", "mtb2", "mtb3"];
        for (bar, f) in Self::active_on_units(faults, FaultKind::TorquerStuckOn, t_s, &units) {
            if let Some(slot) = out.get_mut(bar) {
                *slot = f.dipole_am2;
            }
        }
        out
    }

    /// Apply the `css_glint` faults active at `t_s` to the CSS words.
    #[must_use]
    pub fn apply_css(faults: &[Fault], t_s: f64, sample: CssSample) -> CssSample {
        let mut out = sample;
        for f in faults {
            if f.kind != FaultKind::CssGlint || !f.active(t_s) || out.flags == 0 {
                continue;
            }
            if let Some(c) = f.eye.and_then(|e| out.counts.get_mut(e)) {
                let added = f.counts.unwrap_or(800.0);
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                let v = (f64::from(*c) + added).round().clamp(0.0, 65_535.0) as u16;
                *c = v;
            }
        }
        out
    }

    /// The clock offset (s) of the `time_tag_jump` faults active at `t_s`.
    #[must_use]
    pub fn time_offset_s(faults: &[Fault], t_s: f64) -> f64 {
        faults
            .iter()
            .filter(|f| f.kind == FaultKind::TimeTagJump && f.active(t_s))
            .map(|f| f.offset_s.unwrap_or(0.0))
            .sum()
    }
}

fn shift_counts(c: i16, delta_counts: f64) -> i16 {
    let v = (f64::from(c) + delta_counts).round();
    #[allow(clippy::cast_possible_truncation)]
    let out = v.clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16;
    out
}

/// The (H, V) offset (rad) from the star tracker `fhst` tracks now to the nearest other
/// catalogue star inside its field at the truth attitude, if any.
#[must_use]
pub fn other_star_offset(
    m_acs_from_fhst: &Matrix3<f64>,
    tracked_hv_rad: [f64; 2],
    truth: &crate::sensors::TruthSnapshot,
    sky: &crate::truth::sky::Sky,
    fov_half_width_rad: f64,
    magnitude_window: (f64, f64),
) -> Option<[f64; 2]> {
    let m_fhst_from_eci = m_acs_from_fhst.transpose() * truth.m_acs_from_eci;
    let boresight = m_fhst_from_eci.row(2).transpose();
    let obs_pos = truth.observer_pos_bary_eci_km();
    let obs_vel = truth.observer_vel_bary_eci_km_per_s();
    let mut best: Option<(f64, [f64; 2])> = None;
    sky.for_each_in_cone(&boresight, fov_half_width_rad * 1.5, |_, star| {
        if !(magnitude_window.0..=magnitude_window.1).contains(&star.magnitude) {
            return;
        }
        let s = m_fhst_from_eci * star.apparent_dir_eci(truth.j2000_tt_s, &obs_pos, &obs_vel);
        if s.z <= 0.0 {
            return;
        }
        let (h, v) = (s.x.atan2(s.z), s.y.atan2(s.z));
        if h.abs() > fov_half_width_rad || v.abs() > fov_half_width_rad {
            return;
        }
        let d = [h - tracked_hv_rad[0], v - tracked_hv_rad[1]];
        let dist = d[0].hypot(d[1]);
        // Not the tracked star itself (closer than 30″).
        if dist < 30.0 / ARCSEC_PER_RAD {
            return;
        }
        if best.is_none_or(|(b, _)| dist < b) {
            best = Some((dist, d));
        }
    });
    best.map(|(_, d)| d)
}
