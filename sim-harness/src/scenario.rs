//! # Scenario files (TOML)
//!
//! One file describes a run: epoch, duration, step, initial state, every truth and sensor
//! error parameter, and a timeline of ground commands. Every table uses
//! `deny_unknown_fields`, so a misspelt key is an error that names it (toml reports the key,
//! the line and the expected names); every parameter has a default (the GRO values or our
//! documented choices), so `name` and `duration_s` are all a minimal file needs.
//!
//! ```toml
//! name = "inertial hold"
//! duration_s = 3600
//! [initial]
//! q_acs_from_eci = [0.0, 0.0, 0.0, 1.0]
//! [orbit]
//! raan_deg = 120.0
//! [fhst1.effects]
//! radial_distortion_arcsec_at_4deg = 15.0
//! [[commands]]
//! at_s = 600
//! kind = "slew_to"          # rotate +60° about body X from the current target
//! axis = "x"
//! angle_deg = 60.0
//! [[commands]]
//! at_s = 3000
//! kind = "table_load"       # an uplink image, path relative to this file
//! file = "tables/alignment.tbl"
//! [[commands]]
//! at_s = 3000
//! kind = "table_activate"
//! table = "alignment"
//! ```
//!
//! # What the harness does at t = 0 by itself (before the timeline)
//! 1. Uplinks the onboard star catalog ([`crate::onboard`]) with `TableLoad` + `TableActivate`
//!    (unless `uplink_catalog = false`);
//! 2. with `fly_true_alignments = true`, uplinks an alignment table equal to the truth;
//! 3. loads and activates the images `--tables DIR/manifest.json` lists, in its order
//!    ([`crate::manifest`]);
//! 4. initialises the filter with `FilterInitialize(Rot(error) · A_true)`, `error` =
//!    `[initial_estimate]` (default 0.1° about (1, 1, 1)/√3), which also starts the inertial
//!    hold (unless `initial_estimate.enabled = false`).
//!
//! At most 8 commands go to the OBC per cycle (`MAX_COMMANDS_PER_CYCLE`); the rest wait for
//! the next cycle in order.
//!
//! # Timeline command kinds
//! | kind | fields | what the OBC gets |
//! |---|---|---|
//! | `slew_to` | `q_acs_from_eci`, or `axis` ("x", "y", "z") + `angle_deg` | `SlewTo(q)`; the relative form is `q = Rot(angle · axis) ⊗ current target` (a rotation of the body about its own axis) |
//! | `hold` | — | `Hold` (the current estimate becomes the target) |
//! | `select_iru_config` | `config` = "primary" / "backup" | `SelectIruConfig` |
//! | `table_load` | `file` (relative to the scenario file), or `filter_table` = { fields } (a filter-table image built from the boot values, the scenario's `filter_table` and these: e.g. a new slew rate limit) | `TableLoad(image)` |
//! | `table_activate`, `table_abort` | `table` = "alignment", "iru", "filter", "star_catalog" | `TableActivate(id)`, `TableAbort(id)` |
//! | `filter_initialize` | optional `q_acs_from_eci` (default: truth rotated by `[initial_estimate]`) | `FilterInitialize(q)` |
//! | `filter_reset` | — | `FilterReset` |
//! | `sun_acquire` | `sun_axis_acs` = [x, y, z] (unit, ACS) | `SunAcquire(axis)`: the axis turned to the Sun from the Sun sensors and gyros alone, then held there |
//!
//! # Faults (`[[faults]]`)
//! Injected by the harness into the sensor words, the clock or the uplink at given times
//! (kinds, fields and effects: [`crate::faults`]; examples: `scenarios/faults/`):
//! `fhst_dropout`, `fhst_wrong_star`, `fss_glint`, `iru_channel_failure`, `time_tag_jump`,
//! `table_upload` (damaged or valid alignment images), `filter_reset`.
//!
//! # Magnetometers and coarse Sun sensors
//! `[tam1]` (primary; default bias = the paper's [0, 0, −4] mG), `[tam2]`
//! ([`crate::sensors::tam::TamParams`], units in the key names: `bias_milligauss`,
//! `scale_ppm`, `misalignment_arcsec`, ...), `[css]` ([`crate::sensors::css::CssParams`]) and
//! `[magnetics] enabled` (sample them into the record and the raw frame, and downlink them as
//! APID 0x013; default off, on in `gro-early-mission` and `normal-ops`: [`crate::magnetics`],
//! `docs/magnetics.md`).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::sensors::css::CssParams;
use crate::sensors::fhst::FhstParams;
use crate::sensors::fss::FssParams;
use crate::sensors::iru::IruParams;
use crate::sensors::tam::TamParams;
use crate::sensors::thermal::ThermalParams;
use crate::truth::dynamics::DynamicsParams;
use crate::truth::orbit::OrbitParams;
use crate::truth::sky::SkyParams;
use fsw_core::attitude::Quat;

fn default_seed() -> u64 {
    1
}
fn default_epoch() -> String {
    "1991-04-07T22:37:00Z".to_owned()
}
fn default_step() -> f64 {
    1.0
}
fn default_sun_refresh() -> f64 {
    600.0
}
fn default_ephemeris_period() -> f64 {
    10.0
}
fn default_one() -> u32 {
    1
}
fn default_true() -> bool {
    true
}
fn default_bias_period() -> f64 {
    60.0
}

/// The filter initialisation the harness sends at t = 0 (scenario `[initial_estimate]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct InitialEstimate {
    /// Send `FilterInitialize` at t = 0.
    pub enabled: bool,
    /// Size of the initial attitude error (deg): the estimate is `Rot(error) · A_true`.
    pub error_deg: f64,
    /// Axis of the error rotation in ACS (normalised).
    pub axis_acs: [f64; 3],
}

impl Default for InitialEstimate {
    fn default() -> Self {
        Self {
            enabled: true,
            error_deg: 0.1,
            axis_acs: [1.0, 1.0, 1.0],
        }
    }
}

impl InitialEstimate {
    /// The error rotation vector (rad, ACS).
    #[must_use]
    pub fn error_rad(&self) -> Vector3<f64> {
        let a = Vector3::from(self.axis_acs);
        let n = a.norm();
        if n > 0.0 {
            a * (self.error_deg * fsw_core::units::RAD_PER_DEG / n)
        } else {
            Vector3::zeros()
        }
    }
}

/// Initial true state.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct InitialState {
    /// True attitude `q_acs_from_eci`, scalar last `[x, y, z, w]` (normalised on load).
    pub q_acs_from_eci: [f64; 4],
    /// True body rate (deg/s, ACS).
    pub rate_acs_deg_per_s: [f64; 3],
}

impl Default for InitialState {
    fn default() -> Self {
        Self {
            q_acs_from_eci: [0.0, 0.0, 0.0, 1.0],
            rate_acs_deg_per_s: [0.0; 3],
        }
    }
}

impl InitialState {
    /// The attitude as a quaternion.
    #[must_use]
    pub fn quat(&self) -> Quat {
        let [x, y, z, w] = self.q_acs_from_eci;
        Quat::new(x, y, z, w).normalized()
    }

    /// The rate in rad/s.
    #[must_use]
    pub fn rate_acs_rad_per_s(&self) -> Vector3<f64> {
        Vector3::from(self.rate_acs_deg_per_s) * fsw_core::units::RAD_PER_DEG
    }
}

/// Temperatures of the five raw-frame slots.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThermalSet {
    /// FHST1 node.
    #[serde(default = "thermal_0")]
    pub fhst1: ThermalParams,
    /// FHST2 node.
    #[serde(default = "thermal_1")]
    pub fhst2: ThermalParams,
    /// FSS1 node.
    #[serde(default = "thermal_2")]
    pub fss1: ThermalParams,
    /// FSS2 node.
    #[serde(default = "thermal_3")]
    pub fss2: ThermalParams,
    /// IRU baseplate node.
    #[serde(default = "thermal_4")]
    pub iru: ThermalParams,
}
fn thermal_0() -> ThermalParams {
    ThermalParams::default_for_slot(0)
}
fn thermal_1() -> ThermalParams {
    ThermalParams::default_for_slot(1)
}
fn thermal_2() -> ThermalParams {
    ThermalParams::default_for_slot(2)
}
fn thermal_3() -> ThermalParams {
    ThermalParams::default_for_slot(3)
}
fn thermal_4() -> ThermalParams {
    ThermalParams::default_for_slot(4)
}

impl Default for ThermalSet {
    fn default() -> Self {
        Self {
            fhst1: thermal_0(),
            fhst2: thermal_1(),
            fss1: thermal_2(),
            fss2: thermal_3(),
            iru: thermal_4(),
        }
    }
}

impl ThermalSet {
    /// In raw-frame slot order.
    #[must_use]
    pub fn slots(&self) -> [ThermalParams; 5] {
        [self.fhst1, self.fhst2, self.fss1, self.fss2, self.iru]
    }
}

/// Kinds of timeline command.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CommandKind {
    /// Slew to `q_acs_from_eci` and hold.
    SlewTo,
    /// Hold the current estimate.
    Hold,
    /// Select the IRU triad `config` ("primary" or "backup").
    SelectIruConfig,
    /// Initialise the filter at `q_acs_from_eci`, or at the true attitude rotated by the
    /// `[initial_estimate]` error if absent.
    FilterInitialize,
    /// Reopen the filter covariance.
    FilterReset,
    /// Load the table image `file` (path relative to the scenario file).
    TableLoad,
    /// Activate the pending image of `table`.
    TableActivate,
    /// Clear the pending image of `table`.
    TableAbort,
    /// Turn the body axis `sun_axis_acs` to the Sun from the Sun sensors and gyros alone and
    /// hold it there (fsw-core `sun_acquisition`; no attitude estimate needed).
    SunAcquire,
}

/// A table name of a timeline command (`table = "alignment"`, ...).
///
/// # Errors
/// An unknown name.
pub fn table_id_from_name(name: &str) -> anyhow::Result<fsw_core::tables::TableId> {
    use fsw_core::tables::TableId;
    TableId::ALL
        .into_iter()
        .find(|id| id.name() == name)
        .ok_or_else(|| {
            anyhow::anyhow!("unknown table {name:?} (alignment, iru, filter, star_catalog)")
        })
}

/// A body axis of a relative slew (`axis = "x"`, "y", "z", optionally signed "-y").
///
/// # Errors
/// An unknown name.
pub fn body_axis_from_name(name: &str) -> anyhow::Result<Vector3<f64>> {
    let (sign, rest) = match name.strip_prefix('-') {
        Some(r) => (-1.0, r),
        None => (1.0, name.strip_prefix('+').unwrap_or(name)),
    };
    let v = match rest.to_ascii_lowercase().as_str() {
        "x" => Vector3::x(),
        "y" => Vector3::y(),
        "z" => Vector3::z(),
        _ => bail!("unknown axis {name:?} (\"x\", \"y\", \"z\", optionally signed)"),
    };
    Ok(v * sign)
}

/// One timeline entry.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimedCommand {
    /// When to send it (s from the epoch; sent with the first cycle at or after).
    pub at_s: f64,
    /// What.
    pub kind: CommandKind,
    /// Target or initial attitude (`slew_to`, `filter_initialize`), `[x, y, z, w]`.
    #[serde(default)]
    pub q_acs_from_eci: Option<[f64; 4]>,
    /// IRU configuration (`select_iru_config`): "primary" or "backup".
    #[serde(default)]
    pub config: Option<String>,
    /// Body axis of a relative `slew_to`: "x", "y" or "z".
    #[serde(default)]
    pub axis: Option<String>,
    /// Angle of a relative `slew_to` (deg, right-handed about `axis`).
    #[serde(default)]
    pub angle_deg: Option<f64>,
    /// Table image file of `table_load`, relative to the scenario file.
    #[serde(default)]
    pub file: Option<String>,
    /// Table name of `table_activate` / `table_abort`.
    #[serde(default)]
    pub table: Option<String>,
    /// A `table_load` without `file`: a filter-table image the harness builds from the boot
    /// values, the scenario's `filter_table` fields and these (e.g.
    /// `filter_table = { slew_rate_limit_rad_per_s = 2.7925e-3 }` for 0.16°/s slews).
    #[serde(default)]
    pub filter_table: Option<toml::Table>,
    /// Body axis (ACS, unit) of `sun_acquire`: where the Sun is brought, e.g. an FSS
    /// boresight.
    #[serde(default)]
    pub sun_axis_acs: Option<[f64; 3]>,
}

impl TimedCommand {
    /// The filter table of a `table_load` with `filter_table`: boot values, then the
    /// scenario's `filter_table` fields, then the command's, validated.
    ///
    /// # Errors
    /// An unknown field or a value the table refuses.
    pub fn filter_table_image_fields(
        &self,
        scenario: &Scenario,
    ) -> anyhow::Result<Option<fsw_core::tables::types::FilterTable>> {
        let Some(own) = &self.filter_table else {
            return Ok(None);
        };
        let mut fields = scenario.startup_filter_table().unwrap_or_default();
        for (k, v) in own {
            fields.insert(k.clone(), v.clone());
        }
        crate::uplink::filter_table_with(&fields).map(Some)
    }
}

/// `[onboard_orbit]`: the ground uplinks the onboard orbit (fsw-core's orbit table,
/// docs/tables.md Table 5) built from the truth orbit, as orbit determination from tracking
/// would give it, and turns on the filter table's orbital aberration correction.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OnboardOrbitUplink {
    /// First uplink (s from the epoch; load + activate). Default 1 s: at t = 0 the catalog,
    /// filter and alignment loads and activations already fill the OBC's eight events of the
    /// cycle (`fsw_core::events::MAX_EVENTS_PER_CYCLE`), and the orbit's would be dropped.
    pub at_s: f64,
    /// Uplink a fresh state every this many seconds after the first (0 = once). The OBC
    /// refuses a state older than 2 days (`fsw_core::orbit::MAX_STATE_AGE_S`).
    pub every_s: f64,
    /// Age of the state at each uplink (s): its epoch is the uplink time minus this (a state
    /// determined before the uplink; the OBC catches it up at 80 s of orbit per cycle).
    pub state_age_s: f64,
    /// Error added to the truth position (km, J2000), to test robustness.
    pub pos_error_km: [f64; 3],
    /// Error added to the truth velocity (km/s, J2000), to test robustness.
    pub vel_error_km_per_s: [f64; 3],
    /// Filter-table fields laid over the scenario's `filter_table` (and the boot values):
    /// by default `orbital_aberration_correction = true` and
    /// `fhst_uncorrected_systematic_arcsec` = [`ORBIT_ON_FHST_FLOOR_ARCSEC`]
    /// (docs/obc_filter.md §3). The scenario's own `filter_table` keys win over these.
    pub filter_table: toml::Table,
}

/// The FHST systematic floor recommended with the orbital correction on (arcsec): what the
/// onboard ephemerides leave of the aberration (docs/obc_filter.md §3).
pub const ORBIT_ON_FHST_FLOOR_ARCSEC: f64 = 0.02;

impl Default for OnboardOrbitUplink {
    fn default() -> Self {
        let mut filter_table = toml::Table::new();
        filter_table.insert(
            "orbital_aberration_correction".into(),
            toml::Value::Boolean(true),
        );
        filter_table.insert(
            "fhst_uncorrected_systematic_arcsec".into(),
            toml::Value::Float(ORBIT_ON_FHST_FLOOR_ARCSEC),
        );
        Self {
            at_s: 1.0,
            every_s: 0.0,
            state_age_s: 0.0,
            pos_error_km: [0.0; 3],
            vel_error_km_per_s: [0.0; 3],
            filter_table,
        }
    }
}

impl OnboardOrbitUplink {
    /// The uplink times within `[0, duration_s]`.
    #[must_use]
    pub fn uplink_times_s(&self, duration_s: f64) -> Vec<f64> {
        let mut out = vec![self.at_s];
        if self.every_s > 0.0 {
            let mut t = self.at_s + self.every_s;
            while t <= duration_s {
                out.push(t);
                t += self.every_s;
            }
        }
        out
    }
}

/// Scenario `[magnetics]` ([`crate::magnetics`]: the field, TAM and CSS models of the loop).
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
    /// The table's `field_sigma_milligauss` for both TAMs (1σ per axis of what is left in a corrected TAM
    /// field); `None`: the OBC's boot value (2.5 mG, an undetermined bias).
    pub onboard_field_sigma_milligauss: Option<f64>,
    /// A magnetics table image the ground wrote (`ground-tool calibrate` `tables/
    /// magnetics.tbl`), relative to the scenario's folder, uplinked at `onboard_table_at_s`
    /// instead of the one built from the `onboard_*` fields above: a flight after the ground
    /// calibrated its TAMs (`normal-ops`). `None`: the built table (prelaunch knowledge).
    pub onboard_table_file: Option<String>,
}

impl MagneticsParams {
    /// A table file with nothing to fly it, or with the fields it replaces, is refused
    /// rather than ignored.
    ///
    /// # Errors
    /// `onboard_table_file` with `enabled` or `onboard_table` false, or with
    /// `onboard_tam_bias_milligauss` / `onboard_field_sigma_milligauss` set.
    pub fn validate(&self) -> anyhow::Result<()> {
        let Some(file) = &self.onboard_table_file else {
            return Ok(());
        };
        if !(self.enabled && self.onboard_table) {
            bail!(
                "[magnetics] onboard_table_file = {file:?} needs enabled = true and onboard_table = true (it would not be flown)"
            );
        }
        if self.onboard_tam_bias_milligauss != [[0.0; 3]; 2]
            || self.onboard_field_sigma_milligauss.is_some()
        {
            bail!(
                "[magnetics] onboard_table_file = {file:?} replaces the table built from onboard_tam_bias_milligauss and onboard_field_sigma_milligauss: give one or the other"
            );
        }
        Ok(())
    }
}

impl Default for MagneticsParams {
    fn default() -> Self {
        Self {
            enabled: false,
            onboard_table: true,
            onboard_table_at_s: 2.0,
            onboard_tam_bias_milligauss: [[0.0; 3]; 2],
            onboard_field_sigma_milligauss: None,
            onboard_table_file: None,
        }
    }
}

/// A whole scenario.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Short name (goes into metadata).
    pub name: String,
    /// Free text.
    #[serde(default)]
    pub description: String,
    /// Seed of every random stream.
    #[serde(default = "default_seed")]
    pub seed: u64,
    /// Start epoch, UTC (ISO 8601). Default: GRO release, 1991-04-07T22:37:00Z.
    #[serde(default = "default_epoch")]
    pub epoch_utc: String,
    /// Run length (s).
    pub duration_s: f64,
    /// Cycle period (s).
    #[serde(default = "default_step")]
    pub step_s: f64,
    /// Refresh interval of the cached Sun ephemeris (s).
    #[serde(default = "default_sun_refresh")]
    pub sun_refresh_s: f64,
    /// Period of the definitive-orbit telemetry records (s, ICD §3.4: ≤ 60). Default 10.
    #[serde(default = "default_ephemeris_period")]
    pub ephemeris_period_s: f64,
    /// Downlink the raw frame and the housekeeping every n-th cycle (events always; the
    /// ephemeris at the first downlinked cycle at or after it is due). The IRU counters must
    /// then still change by less than 2¹⁵ pulses between downlinked frames, or the ground
    /// cannot unwrap them: n · max rate / pulse weight < 32 768 (e.g. at the 0.08°/s slew
    /// rate in high-rate mode, 360 pulses/s, n < 91). The run counts violations
    /// (`summary.json` `iru_counter_aliasing_frames`).
    #[serde(default = "default_one")]
    pub telemetry_every_n_cycles: u32,
    /// Spacing of the true-bias samples in truth.json (s, ≥ 60).
    #[serde(default = "default_bias_period")]
    pub truth_bias_period_s: f64,
    /// Uplink the onboard star catalog at t = 0.
    #[serde(default = "default_true")]
    pub uplink_catalog: bool,
    /// Uplink, at t = 0, an alignment table equal to the true alignments (no calibration
    /// needed: the reference case for normal operations).
    #[serde(default)]
    pub fly_true_alignments: bool,
    /// Filter-table settings to uplink at t = 0: any fields of fsw-core's `FilterTable`
    /// (docs/tables.md, table 3), the others keep their boot values; absent = no upload.
    /// Example: `filter_table = { aberration_correction = true }`.
    #[serde(default)]
    pub filter_table: Option<toml::Table>,
    /// Uplink the onboard orbit from the truth and turn on the orbital aberration correction
    /// (`[onboard_orbit]`, [`OnboardOrbitUplink`]); absent = no orbit on board, as before.
    #[serde(default)]
    pub onboard_orbit: Option<OnboardOrbitUplink>,
    /// Effects the operator declares (metadata.json `declared_effects`); `None` = the
    /// physical ones every GRO analyst knows about ([`DEFAULT_DECLARED_EFFECTS`]).
    #[serde(default)]
    pub declared_effects: Option<Vec<String>>,
    /// The filter initialisation sent at t = 0.
    #[serde(default)]
    pub initial_estimate: InitialEstimate,
    /// Star catalogue CSV (default: the workspace data/hipparcos_mag6p5.csv).
    #[serde(default)]
    pub catalog_path: Option<String>,
    /// Initial true state.
    #[serde(default)]
    pub initial: InitialState,
    /// Orbit.
    #[serde(default)]
    pub orbit: OrbitParams,
    /// Rigid body and wheels.
    #[serde(default)]
    pub dynamics: DynamicsParams,
    /// Truth sky.
    #[serde(default)]
    pub sky: SkyParams,
    /// FHST1.
    #[serde(default)]
    pub fhst1: FhstParams,
    /// FHST2.
    #[serde(default)]
    pub fhst2: FhstParams,
    /// FSS1.
    #[serde(default)]
    pub fss1: FssParams,
    /// FSS2.
    #[serde(default)]
    pub fss2: FssParams,
    /// IRU.
    #[serde(default)]
    pub iru: IruParams,
    /// TAM1, the primary magnetometer ([`crate::sensors::tam`]); default: the paper's
    /// determined bias [0, 0, −4] mG.
    #[serde(default = "TamParams::primary_default")]
    pub tam1: TamParams,
    /// TAM2, the secondary magnetometer.
    #[serde(default)]
    pub tam2: TamParams,
    /// Coarse Sun sensors ([`crate::sensors::css`]).
    #[serde(default)]
    pub css: CssParams,
    /// Sample the field, TAMs and CSSs into the record and downlink them ([`crate::magnetics`]).
    #[serde(default)]
    pub magnetics: MagneticsParams,
    /// The magnetic torquer bars ([`crate::truth::torquer`]), flown with
    /// `[dynamics] momentum_unloading = "bars"`.
    #[serde(default)]
    pub torquers: crate::truth::torquer::TorquerParams,
    /// The wheel tachometers and torquer-bar current monitors
    /// ([`crate::sensors::tachometer`]; APID 0x014).
    #[serde(default)]
    pub wheel_tachometers: crate::sensors::tachometer::TachometerParams,
    /// Thermal nodes.
    #[serde(default)]
    pub thermal: ThermalSet,
    /// Command timeline.
    #[serde(default)]
    pub commands: Vec<TimedCommand>,
    /// Injected faults ([`crate::faults`], issue 7).
    #[serde(default)]
    pub faults: Vec<crate::faults::Fault>,
    /// Folder of the scenario file (table files are relative to it); not a TOML key.
    #[serde(skip)]
    pub base_dir: Option<PathBuf>,
}

/// Effects declared when a scenario does not say (`declared_effects`): the metadata's own
/// default, defined with the run-folder contract (`gro_reference::run_folder`).
pub use gro_reference::run_folder::DEFAULT_DECLARED_EFFECTS;

/// Longest `duration_s` accepted (s): one year. Why: runs are simulated cycle by cycle
/// (≈ 0.01 ms each) and write ≈ 300 octets of telemetry per cycle; a longer value is a typo
/// (`1e30` used to saturate the cycle count and simulate nothing with exit code 0).
pub const MAX_DURATION_S: f64 = 366.0 * 86_400.0;

/// Longest `step_s` accepted (s): the OBC's filter table accepts cycle periods of 0.125–2 s.
pub const MAX_STEP_S: f64 = 2.0;

/// The TOML path and value of the first NaN or infinite float in `v`.
fn first_non_finite(v: &toml::Value, path: String) -> Option<(String, f64)> {
    match v {
        toml::Value::Float(x) if !x.is_finite() => Some((path, *x)),
        toml::Value::Array(a) => a
            .iter()
            .enumerate()
            .find_map(|(i, x)| first_non_finite(x, format!("{path}[{i}]"))),
        toml::Value::Table(t) => t.iter().find_map(|(k, x)| {
            let p = if path.is_empty() {
                k.clone()
            } else {
                format!("{path}.{k}")
            };
            first_non_finite(x, p)
        }),
        _ => None,
    }
}

/// Scenarios shipped in `scenarios/` and embedded in the binary: (name, TOML text).
pub const EMBEDDED_SCENARIOS: [(&str, &str); 5] = [
    (
        "gro-early-mission",
        include_str!("../../scenarios/gro-early-mission.toml"),
    ),
    (
        "gro-bias-history",
        include_str!("../../scenarios/gro-bias-history.toml"),
    ),
    (
        "normal-ops",
        include_str!("../../scenarios/normal-ops.toml"),
    ),
    (
        "inertial_hold",
        include_str!("../../scenarios/inertial_hold.toml"),
    ),
    (
        "undeclared_effects",
        include_str!("../../scenarios/undeclared_effects.toml"),
    ),
];

/// The workspace `scenarios/` folder (compile-time path).
#[must_use]
pub fn scenarios_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("scenarios")
}

/// Resolve a scenario argument: an existing path is read; a bare name (`gro-early-mission`)
/// is `scenarios/NAME.toml` of the workspace, or the embedded copy when that file is absent
/// (so the binary works from any directory).
///
/// # Errors
/// Unknown name, unreadable file, or an invalid scenario (naming the field).
pub fn resolve(arg: &str) -> anyhow::Result<Scenario> {
    let path = Path::new(arg);
    if path.exists() {
        return Scenario::load(path);
    }
    let bare = !arg.contains('/') && !arg.contains('\\');
    let name = arg.strip_suffix(".toml").unwrap_or(arg);
    if bare {
        let file = scenarios_dir().join(format!("{name}.toml"));
        if file.exists() {
            return Scenario::load(&file);
        }
        if let Some((_, text)) = EMBEDDED_SCENARIOS.iter().find(|(n, _)| *n == name) {
            let mut s = Scenario::from_toml_str(text, &format!("{name} (embedded)"))?;
            s.base_dir = Some(scenarios_dir());
            return Ok(s);
        }
        let known: Vec<&str> = EMBEDDED_SCENARIOS.iter().map(|(n, _)| *n).collect();
        bail!(
            "no scenario file {arg:?} and no built-in scenario of that name (built in: {})",
            known.join(", ")
        );
    }
    bail!("scenario file {} does not exist", path.display())
}

impl Scenario {
    /// Parse and validate TOML text; `source` names it in errors.
    ///
    /// # Errors
    /// TOML syntax, unknown or mistyped keys (named by toml), or a failed validation
    /// (named field and value).
    pub fn from_toml_str(text: &str, source: &str) -> anyhow::Result<Self> {
        let s: Self = toml::from_str(text).map_err(|e| anyhow::anyhow!("{source}: {e}"))?;
        s.validate()
            .with_context(|| format!("{source}: invalid scenario"))?;
        Ok(s)
    }

    /// Read, parse and validate a scenario file.
    ///
    /// # Errors
    /// I/O, parse or validation errors, with the path.
    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let mut s = Self::from_toml_str(&text, &path.display().to_string())?;
        s.base_dir = Some(
            path.parent()
                .map_or_else(|| PathBuf::from("."), Path::to_path_buf),
        );
        Ok(s)
    }

    /// Path of a file named in the scenario (relative to the scenario's folder).
    #[must_use]
    pub fn resolve_file(&self, name: &str) -> PathBuf {
        let p = Path::new(name);
        if p.is_absolute() {
            p.to_path_buf()
        } else {
            self.base_dir
                .clone()
                .unwrap_or_else(|| PathBuf::from("."))
                .join(p)
        }
    }

    /// The declared effects (metadata.json): the list given, else the metadata's default.
    #[must_use]
    pub fn declared_effects(&self) -> Vec<String> {
        gro_reference::run_folder::declared_or_default(self.declared_effects.as_deref())
    }

    /// The filter-table fields uplinked at t = 0 over the boot values: the
    /// `[onboard_orbit]` ones (the orbital correction on), then the scenario's
    /// `filter_table`; `None` = no filter-table upload (also when both are empty: an orbit
    /// uplinked with `filter_table = {}` leaves the boot filter table flying).
    #[must_use]
    pub fn startup_filter_table(&self) -> Option<toml::Table> {
        let mut fields = match (&self.onboard_orbit, &self.filter_table) {
            (None, None) => return None,
            (Some(o), _) => o.filter_table.clone(),
            (None, Some(_)) => toml::Table::new(),
        };
        for (k, v) in self.filter_table.iter().flatten() {
            fields.insert(k.clone(), v.clone());
        }
        if fields.is_empty() && self.filter_table.is_none() {
            return None;
        }
        Some(fields)
    }

    /// Check values serde cannot: the numbers finite, then timing, initial state, orbit,
    /// sensors, commands and faults, each stage with the first error it finds.
    ///
    /// # Errors
    /// The first offending field, by its TOML path.
    pub fn validate(&self) -> anyhow::Result<()> {
        // Every number of the file, however deep, is finite (a NaN or an infinity in any
        // parameter would propagate into the truth and the telemetry as nulls or garbage).
        if let Ok(tree) = toml::Value::try_from(self) {
            if let Some((path, v)) = first_non_finite(&tree, String::new()) {
                bail!("{path} must be a finite number, got {v}");
            }
        }
        self.validate_timing()?;
        self.validate_initial()?;
        self.validate_orbit()?;
        self.validate_sensors()?;
        self.magnetics.validate()?;
        for (i, c) in self.commands.iter().enumerate() {
            c.validate(i, self)?;
        }
        crate::faults::validate_all(&self.faults)?;
        let bars =
            self.dynamics.momentum_unloading == crate::truth::dynamics::MomentumUnloading::Bars;
        if !bars
            && self
                .faults
                .iter()
                .any(|f| f.kind == crate::faults::FaultKind::TorquerStuckOn)
        {
            bail!(
                "a torquer_stuck_on fault needs the bars: [dynamics] momentum_unloading = \"bars\""
            );
        }
        let limit = self.torquers.dipole_limit_am2;
        if let Some((i, d)) = self.faults.iter().enumerate().find_map(|(i, f)| {
            (f.kind == crate::faults::FaultKind::TorquerStuckOn)
                .then_some(f.dipole_am2)
                .flatten()
                .filter(|d| d.abs() > limit)
                .map(|d| (i, d))
        }) {
            bail!("faults[{i}].dipole_am2 = {d} exceeds [torquers] dipole_limit_am2 = {limit}: the bar's drive cannot deliver it");
        }
        if !self.wheel_tachometers.enabled
            && self
                .faults
                .iter()
                .any(|f| f.kind == crate::faults::FaultKind::TachometerFailed)
        {
            bail!("a tachometer_failed fault needs the tachometers: [wheel_tachometers] enabled = true");
        }
        Ok(())
    }

    /// The step, the duration and the periods of the run and its telemetry.
    fn validate_timing(&self) -> anyhow::Result<()> {
        positive("step_s", self.step_s)?;
        if self.step_s > MAX_STEP_S {
            bail!(
                "step_s must be ≤ {MAX_STEP_S} s (the OBC's filter table accepts cycle periods of 0.125–2 s), got {}",
                self.step_s
            );
        }
        if !(self.duration_s.is_finite() && (0.0..=MAX_DURATION_S).contains(&self.duration_s)) {
            bail!(
                "duration_s must be in [0, {MAX_DURATION_S}] s (one year; the run is simulated cycle by cycle), got {}",
                self.duration_s
            );
        }
        if self.duration_s > 0.0 && self.duration_s < self.step_s {
            bail!(
                "duration_s ({}) is shorter than one cycle (step_s = {}): nothing would be simulated",
                self.duration_s,
                self.step_s
            );
        }
        positive("sun_refresh_s", self.sun_refresh_s)?;
        positive("ephemeris_period_s", self.ephemeris_period_s)?;
        if self.ephemeris_period_s > 60.0 {
            bail!(
                "ephemeris_period_s must be ≤ 60 (ICD §3.4), got {}",
                self.ephemeris_period_s
            );
        }
        if self.telemetry_every_n_cycles == 0 {
            bail!("telemetry_every_n_cycles must be ≥ 1, got 0");
        }
        if !(self.truth_bias_period_s.is_finite() && self.truth_bias_period_s >= 60.0) {
            bail!(
                "truth_bias_period_s must be ≥ 60, got {}",
                self.truth_bias_period_s
            );
        }
        Ok(())
    }

    /// The initial estimate and state, the epoch, the magnetometers and Sun sensors' models.
    fn validate_initial(&self) -> anyhow::Result<()> {
        let ie = &self.initial_estimate;
        if !(ie.error_deg.is_finite() && (0.0..=10.0).contains(&ie.error_deg)) {
            bail!(
                "initial_estimate.error_deg must be in [0, 10], got {}",
                ie.error_deg
            );
        }
        if ie.error_deg > 0.0 && Vector3::from(ie.axis_acs).norm() < 1e-9 {
            bail!("initial_estimate.axis_acs must not be zero");
        }
        crate::truth::time::epoch_from_iso(&self.epoch_utc).context("epoch_utc")?;
        self.tam1.validate("tam1")?;
        self.tam2.validate("tam2")?;
        self.torquers.validate()?;
        self.wheel_tachometers.validate()?;
        if self.dynamics.momentum_unloading == crate::truth::dynamics::MomentumUnloading::Bars
            && !self.magnetics.enabled
        {
            bail!("dynamics.momentum_unloading = \"bars\" needs the truth field and the TAMs: [magnetics] enabled = true");
        }
        self.css.validate()?;
        let q = self.initial.q_acs_from_eci;
        let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
        if !(n.is_finite() && (n - 1.0).abs() < 1e-3) {
            bail!("initial.q_acs_from_eci must be a unit quaternion [x, y, z, w], norm is {n}");
        }
        Ok(())
    }

    /// The truth orbit and the onboard orbit uplink.
    fn validate_orbit(&self) -> anyhow::Result<()> {
        positive(
            "orbit.semimajor_axis_km",
            self.orbit.semimajor_axis_km - 6378.137,
        )
        .context("orbit.semimajor_axis_km must exceed the Earth radius")?;
        if !(0.0..=180.0).contains(&self.orbit.inclination_deg) {
            bail!(
                "orbit.inclination_deg must be in [0, 180], got {}",
                self.orbit.inclination_deg
            );
        }
        for (name, v) in [
            ("orbit.raan_deg", self.orbit.raan_deg),
            ("orbit.arg_perigee_deg", self.orbit.arg_perigee_deg),
            ("orbit.arg_latitude_deg", self.orbit.arg_latitude_deg),
        ] {
            if !(-360.0..=360.0).contains(&v) {
                bail!("{name} must be in [-360, 360] deg, got {v}");
            }
        }
        positive("orbit.max_step_s", self.orbit.max_step_s)?;
        if let Some(o) = &self.onboard_orbit {
            if !(o.at_s >= 0.0 && o.at_s <= self.duration_s.max(0.0)) {
                bail!(
                    "onboard_orbit.at_s must be in [0, duration_s], got {}",
                    o.at_s
                );
            }
            if !(o.every_s == 0.0 || o.every_s >= 60.0) {
                bail!(
                    "onboard_orbit.every_s must be 0 (once) or ≥ 60 s, got {}",
                    o.every_s
                );
            }
            if !(o.at_s - o.state_age_s >= -86_400.0) {
                bail!(
                    "onboard_orbit.state_age_s ({}) puts the state more than a day before the epoch",
                    o.state_age_s
                );
            }
        }
        if !(0.0..1.0).contains(&self.orbit.eccentricity) {
            bail!(
                "orbit.eccentricity must be in [0, 1), got {}",
                self.orbit.eccentricity
            );
        }
        Ok(())
    }

    /// The FHST, FSS and IRU parameters.
    fn validate_sensors(&self) -> anyhow::Result<()> {
        for (name, f) in [("fhst1", &self.fhst1), ("fhst2", &self.fhst2)] {
            positives(
                name,
                &[
                    ("fov_half_width_deg", f.fov_half_width_deg),
                    ("resolution_arcsec_per_count", f.resolution_arcsec_per_count),
                    ("max_track_s", f.max_track_s),
                ],
            )?;
            if f.magnitude_min > f.magnitude_max {
                bail!(
                    "{name}.magnitude_min ({}) exceeds magnitude_max ({})",
                    f.magnitude_min,
                    f.magnitude_max
                );
            }
        }
        for (name, f) in [("fss1", &self.fss1), ("fss2", &self.fss2)] {
            positives(
                name,
                &[
                    ("fov_half_width_deg", f.fov_half_width_deg),
                    ("resolution_deg_per_count", f.resolution_deg_per_count),
                ],
            )?;
        }
        positives(
            "iru",
            &[
                (
                    "low_rate_arcsec_per_pulse",
                    self.iru.low_rate_arcsec_per_pulse,
                ),
                (
                    "high_rate_arcsec_per_pulse",
                    self.iru.high_rate_arcsec_per_pulse,
                ),
            ],
        )
    }
}

/// Each of `fields` (key, value) of the section `section` must be a positive number
/// ([`positive`], in order).
fn positives(section: &str, fields: &[(&str, f64)]) -> anyhow::Result<()> {
    for (key, v) in fields {
        positive(&format!("{section}.{key}"), *v)?;
    }
    Ok(())
}

/// `name` must be a positive number.
fn positive(name: &str, v: f64) -> anyhow::Result<()> {
    if !(v.is_finite() && v > 0.0) {
        bail!("{name} must be a positive number, got {v}");
    }
    Ok(())
}

impl TimedCommand {
    /// Command `i` of `scenario`: its time, the fields its kind needs, its quaternion.
    fn validate(&self, i: usize, scenario: &Scenario) -> anyhow::Result<()> {
        let c = self;
        let here = format!("commands[{i}]");
        if !(c.at_s.is_finite() && c.at_s >= 0.0) {
            bail!("{here}.at_s must be ≥ 0, got {}", c.at_s);
        }
        match c.kind {
            CommandKind::SlewTo => {
                let relative = c.axis.is_some() || c.angle_deg.is_some();
                match (c.q_acs_from_eci.is_some(), relative) {
                    (false, false) => bail!(
                        "{here}: kind = \"slew_to\" needs q_acs_from_eci or axis + angle_deg"
                    ),
                    (true, true) => bail!(
                        "{here}: kind = \"slew_to\" takes q_acs_from_eci or axis + angle_deg, not both"
                    ),
                    (false, true) => {
                        let axis = c.axis.as_deref().ok_or_else(|| {
                            anyhow::anyhow!("{here}.axis missing (angle_deg given)")
                        })?;
                        body_axis_from_name(axis).with_context(|| format!("{here}.axis"))?;
                        match c.angle_deg {
                            Some(a) if a.is_finite() && a.abs() <= 180.0 => {}
                            Some(a) => bail!("{here}.angle_deg must be in [-180, 180], got {a}"),
                            None => bail!("{here}.angle_deg missing (axis given)"),
                        }
                    }
                    (true, false) => {}
                }
            }
            CommandKind::TableLoad => match (&c.file, &c.filter_table) {
                (None, None) => {
                    bail!("{here}: kind = \"table_load\" needs file or filter_table")
                }
                (Some(_), Some(_)) => {
                    bail!("{here}: kind = \"table_load\" takes file or filter_table, not both")
                }
                (None, Some(_)) => {
                    c.filter_table_image_fields(scenario)
                        .with_context(|| format!("{here}.filter_table"))?;
                }
                (Some(_), None) => {}
            },
            CommandKind::TableActivate | CommandKind::TableAbort => {
                let name = c.table.as_deref().ok_or_else(|| {
                    anyhow::anyhow!("{here}: this kind needs table = \"alignment\" | \"iru\" | \"filter\" | \"star_catalog\"")
                })?;
                table_id_from_name(name).with_context(|| format!("{here}.table"))?;
            }
            CommandKind::SunAcquire => {
                let a = c.sun_axis_acs.ok_or_else(|| {
                    anyhow::anyhow!("{here}: kind = \"sun_acquire\" needs sun_axis_acs = [x, y, z]")
                })?;
                let n = a.iter().map(|x| x * x).sum::<f64>().sqrt();
                if !(n.is_finite() && (n - 1.0).abs() < 1e-3) {
                    bail!("{here}.sun_axis_acs must be a unit vector, norm is {n}");
                }
            }
            CommandKind::SelectIruConfig
                if !matches!(c.config.as_deref(), Some("primary" | "backup")) =>
            {
                bail!(
                    "{here}: kind = \"select_iru_config\" needs config = \"primary\" or \"backup\""
                )
            }
            _ => {}
        }
        if let Some(q) = c.q_acs_from_eci {
            let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
            if !(n.is_finite() && (n - 1.0).abs() < 1e-3) {
                bail!("{here}.q_acs_from_eci must be a unit quaternion, norm is {n}");
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn minimal_scenario_takes_gro_defaults() {
        let s = Scenario::from_toml_str("name = \"x\"\nduration_s = 10\n", "t").unwrap();
        assert_eq!(s.epoch_utc, "1991-04-07T22:37:00Z");
        assert_eq!(s.step_s, 1.0);
        assert_eq!(s.orbit.semimajor_axis_km, 6833.0);
        assert_eq!(s.fhst1.resolution_arcsec_per_count, 7.78);
        assert_eq!(s.thermal.fss1, ThermalParams::default_for_slot(2));
    }

    #[test]
    fn unknown_field_error_names_the_key() {
        // The error with its causes, of a scenario `name = "x"`, 10 s long, and then `rest`.
        let error = |rest: &str| {
            let text = format!("name = \"x\"\nduration_s = 10\n{rest}");
            format!("{:#}", Scenario::from_toml_str(&text, "t").unwrap_err())
        };
        for (rest, key) in [
            ("[fhst1]\nmax_trak_s = 5\n", "max_trak_s"),
            ("[fhst1.effects]\nfoo = 1\n", "foo"),
            ("step_s = -1\n", "step_s"),
            (
                "[[commands]]\nat_s = 5\nkind = \"slew_to\"\n",
                "commands[0]",
            ),
        ] {
            let err = error(rest);
            assert!(err.contains(key), "{err}");
        }
    }

    #[test]
    fn full_featured_scenario_parses() {
        let text = r#"
name = "cal"
seed = 42
duration_s = 100
[initial]
q_acs_from_eci = [0.0, 0.0, 0.7071067811865476, 0.7071067811865476]
rate_acs_deg_per_s = [0.0, 0.01, 0.0]
[orbit]
raan_deg = 120
arg_latitude_deg = 30
[sky]
magnitude_system = "v"
[fhst2]
misalignment_true_arcsec = [10.0, -5.0, 3.0]
[fhst2.effects]
time_tag_offset_s = 0.05
[fss1.alpha]
cyclic_arcsec = 4.0
[iru]
failure = { channel = "Z1", at_s = 50.0 }
[thermal.iru]
mean_c = 30.0
[[commands]]
at_s = 0
kind = "filter_initialize"
[[commands]]
at_s = 10
kind = "select_iru_config"
config = "backup"
"#;
        let s = Scenario::from_toml_str(text, "t").unwrap();
        assert_eq!(s.seed, 42);
        assert_eq!(s.fhst2.effects.time_tag_offset_s, 0.05);
        assert_eq!(s.iru.failure.as_ref().unwrap().channel, "Z1");
        assert_eq!(s.thermal.iru.mean_c, 30.0);
        assert_eq!(s.thermal.fhst1, ThermalParams::default_for_slot(0));
        assert_eq!(s.commands.len(), 2);
        assert!((s.initial.quat().z - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-12);
    }
}

#[cfg(test)]
mod shipped_scenarios {
    use super::*;

    /// Every file in the workspace `scenarios/` folder parses and validates.
    #[test]
    fn all_shipped_scenarios_load() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios");
        let mut count = 0;
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "toml") {
                Scenario::load(&path).unwrap_or_else(|e| panic!("{}: {e:#}", path.display()));
                count += 1;
            }
        }
        assert!(count >= 2, "found {count} scenarios in {}", dir.display());
    }
}
