//! # What the ground uplinks before the first cycle: the onboard star catalog and tables
//!
//! # The onboard star catalog (prelaunch ground system product)
//! The OBC boots with an empty catalog (docs/tables.md, table 4). Before launch the ground
//! system prepared the FHST catalog from the star catalogue; the harness plays that role at
//! t = 0 and uplinks it with `TableLoad` + `TableActivate`. Construction:
//! * source: the same Hipparcos file as the truth sky (the **catalogue** proper motions,
//!   never the truth's perturbed ones: `[sky] proper_motion_error_*` makes the truth differ
//!   from this catalog, which is the point of that effect);
//! * magnitude: the instrument magnitude of the truth FHST (`[sky] magnitude_system`,
//!   `colour_term`, default Hipparcos Hp), so catalog and tracker agree on the system;
//! * window: the FHST window `[fhst1] magnitude_min ..= magnitude_max` (2.0–5.7);
//! * direction: catalogue position at J1991.25 moved by its proper motion to the scenario
//!   epoch (linear space motion, no parallax, no aberration: the OBC applies aberration
//!   itself if its filter table says so), normalised, stored as `f32`;
//! * at most [`MAX_CATALOG_STARS`]: if more stars qualify, the brightest are kept; order is
//!   the catalogue (HIP) order, so the image is deterministic;
//! * catalog epoch = scenario epoch in Julian years since J2000.0 TT.
//!
//! # The filter table's rate random walk for the flight's epoch
//! [`filter_rrw_for_epoch_rad_per_s_sqrt_s`]: the boot table's derivation (docs/obc_filter.md
//! §2) evaluated at the time since gyro release at which a flight starts: the least σ_u the
//! gyro model allows then (weeks after release, its K; at release, the boot value sized for
//! the transient). A test checks that no shipped scenario uplinks less.
//!
//! # True alignment table (`fly_true_alignments = true`)
//! The alignment table whose four `M_AS` equal the truth's (without thermal drift), no
//! corrections: what a perfect calibration would uplink.

pub use crate::uplink::{filter_table_with, image, image_table_id};
use anyhow::Context;
use nalgebra::Matrix3;

use crate::data::{CsvTable, HIPPARCOS_CSV};
use crate::scenario::{OnboardOrbitUplink, Scenario};
use crate::truth::orbit::Orbit;
use crate::truth::sky::{Sky, SkyParams, HIPPARCOS_EPOCH_J2000_TT_S};
use crate::truth::time::SimClock;
use crate::truth::time::S_PER_JULIAN_YEAR;
use fsw_core::tables::types::rows_from_matrix;
use fsw_core::tables::{
    AlignmentTable, CatalogStar, MagneticsTable, OrbitTable, SensorCorrections, StarCatalogTable,
    MAX_CATALOG_STARS,
};

/// The DRIRU II rate random walk K, 0.0012″/s in 6 h (rad/s^1.5; docs/obc_filter.md §2; the
/// simulated gyro's, `IruParams::default()`, checked in a test).
pub const DRIRU_RRW_RAD_PER_S_SQRT_S: f64 = 3.958e-11;
/// The early bias transient's largest drift rate, at release: 0.108″/s over τ = 1.5 d
/// (rad/s²; docs/obc_filter.md §2).
pub const TRANSIENT_DRIFT_AT_RELEASE_RAD_PER_S2: f64 = 4.04e-12;
/// The transient's time constant τ (s): 1.5 days.
pub const TRANSIENT_TIME_CONSTANT_S: f64 = 129_600.0;
/// The longest interval in which the filter cannot re-estimate the bias on an axis (s): one
/// orbit, the roll about a single tracker's boresight (docs/obc_filter.md §2).
pub const BIAS_UNOBSERVED_INTERVAL_S: f64 = 5_760.0;

/// σ_u for a flight that starts `time_since_release_s` after gyro release (rad/s^1.5):
/// `√(K² + ṙ(t₀)² T)` with `ṙ(t) = ṙ₀ e^{−t/τ}` the transient's drift rate, largest at the
/// flight's start (docs/obc_filter.md §2). At release it is the boot table's 3.1e-10; 55 days
/// later (normal-ops) the transient has decayed by e^{−37} and σ_u is the gyro's K.
#[must_use]
pub fn filter_rrw_for_epoch_rad_per_s_sqrt_s(time_since_release_s: f64) -> f64 {
    let drift_rad_per_s2 = TRANSIENT_DRIFT_AT_RELEASE_RAD_PER_S2
        * (-time_since_release_s.max(0.0) / TRANSIENT_TIME_CONSTANT_S).exp();
    (DRIRU_RRW_RAD_PER_S_SQRT_S.powi(2) + drift_rad_per_s2.powi(2) * BIAS_UNOBSERVED_INTERVAL_S)
        .sqrt()
}

/// Read the scenario's catalogue file (or the embedded one).
///
/// # Errors
/// I/O or format errors, with the path.
pub fn catalogue_table(scenario: &Scenario) -> anyhow::Result<CsvTable> {
    match &scenario.catalog_path {
        Some(p) => CsvTable::read(&scenario.resolve_file(p)).context("catalog_path"),
        None => CsvTable::parse(HIPPARCOS_CSV, "data/hipparcos_mag6p5.csv (embedded)"),
    }
}

/// The onboard catalog for a scenario whose epoch is `j2000_tt_s` (module doc).
///
/// # Errors
/// Catalogue format errors.
pub fn build_star_catalog(
    catalogue: &CsvTable,
    scenario: &Scenario,
    j2000_tt_s: f64,
) -> anyhow::Result<StarCatalogTable> {
    let params = SkyParams {
        apply_parallax: false,
        proper_motion_scale: 1.0,
        proper_motion_error_sigma_mas_per_yr: 0.0,
        ..scenario.sky.clone()
    };
    let sky = Sky::from_csv(catalogue, &params)?;
    let (lo, hi) = (scenario.fhst1.magnitude_min, scenario.fhst1.magnitude_max);
    let mut picked: Vec<_> = sky
        .stars()
        .iter()
        .filter(|s| (lo..=hi).contains(&s.magnitude))
        .collect();
    if picked.len() > MAX_CATALOG_STARS {
        picked.sort_by(|a, b| a.magnitude.total_cmp(&b.magnitude).then(a.hip.cmp(&b.hip)));
        picked.truncate(MAX_CATALOG_STARS);
    }
    picked.sort_by_key(|s| s.hip);
    let years = (j2000_tt_s - HIPPARCOS_EPOCH_J2000_TT_S) / S_PER_JULIAN_YEAR;
    let mut table = StarCatalogTable {
        epoch_years_since_j2000: j2000_tt_s / S_PER_JULIAN_YEAR,
        stars: heapless::Vec::new(),
    };
    for s in picked {
        let d = (s.dir_cat_eci + s.pm_eci_rad_per_yr * years).normalize();
        #[allow(clippy::cast_possible_truncation)]
        let star = CatalogStar {
            id: s.hip,
            dir_eci: [d.x as f32, d.y as f32, d.z as f32],
            magnitude_centimag: (s.magnitude * 100.0).round().clamp(-200.0, 900.0) as i16,
        };
        table
            .stars
            .push(star)
            .map_err(|_| anyhow::anyhow!("onboard catalog over capacity"))?;
    }
    table
        .validate()
        .map_err(|e| anyhow::anyhow!("onboard catalog invalid: {e:?}"))?;
    Ok(table)
}

/// The alignment table of the true alignments (FHST1, FHST2, FSS1, FSS2), no corrections.
#[must_use]
pub fn true_alignment_table(m_acs_from_sensor_true: &[Matrix3<f64>; 4]) -> AlignmentTable {
    AlignmentTable {
        m_acs_from_fhst1: rows_from_matrix(&m_acs_from_sensor_true[0]),
        m_acs_from_fhst2: rows_from_matrix(&m_acs_from_sensor_true[1]),
        m_acs_from_fss1: rows_from_matrix(&m_acs_from_sensor_true[2]),
        m_acs_from_fss2: rows_from_matrix(&m_acs_from_sensor_true[3]),
        corrections: SensorCorrections::default(),
    }
}

/// The orbit table the ground would uplink for the state at `epoch_t_s` (s from the
/// scenario epoch): the truth orbit sampled as the closed loop samples it (one cycle at a
/// time from t = 0), plus the `[onboard_orbit]` errors, validated by the OBC's rules.
///
/// # Errors
/// A state the OBC's `OrbitTable::validate` refuses (named).
pub fn truth_orbit_table(
    scenario: &Scenario,
    clock: &SimClock,
    epoch_t_s: f64,
    uplink: &OnboardOrbitUplink,
) -> anyhow::Result<OrbitTable> {
    let mut orbit = Orbit::new(&scenario.orbit);
    if epoch_t_s > 0.0 {
        let mut k = 1_u64;
        #[allow(clippy::cast_precision_loss)]
        while (k as f64) * scenario.step_s < epoch_t_s {
            orbit.advance_to((k as f64) * scenario.step_s);
            k += 1;
        }
    }
    orbit.advance_to(epoch_t_s);
    let s = orbit.state();
    let table = OrbitTable {
        epoch_s_since_j2000_tt: clock.j2000_tt_s(epoch_t_s),
        pos_eci_km: (s.pos_eci_km + nalgebra::Vector3::from(uplink.pos_error_km)).into(),
        vel_eci_km_per_s: (s.vel_eci_km_per_s + nalgebra::Vector3::from(uplink.vel_error_km_per_s))
            .into(),
    };
    table.validate().map_err(|e| {
        anyhow::anyhow!("onboard_orbit: the OBC would refuse the state at t = {epoch_t_s} s: {e}")
    })?;
    Ok(table)
}

/// The magnetics table (Table 6) the ground uplinks at the start: the DGRF field model at the
/// scenario epoch (`gro_reference::field::onboard_field_table`), the TAMs' nominal axes and
/// count size, the TAM biases and field σ the scenario tells the OBC
/// (`[magnetics] onboard_*`) and the torquer bars' dipole limit (`[torquers]`); `None` without magnetics or with `onboard_table = false`.
///
/// # Errors
/// An epoch outside the field model (1990–1995), or a table the OBC would refuse (named).
/// Table 6 field 24 for the scenario's wheels (`[dynamics] wheel_axes_acs`, normalised as the
/// truth does; absent wheels zero), or `default` itself when they are its wheels to 1e-12 (so
/// that the boot geometry's bits stay those of the table).
fn wheel_axes_for_table(
    scenario: &Scenario,
    default: &[[f64; 3]; fsw_core::raw::WHEELS],
) -> [[f64; 3]; fsw_core::raw::WHEELS] {
    let mut axes = [[0.0; 3]; fsw_core::raw::WHEELS];
    for (slot, a) in axes.iter_mut().zip(&scenario.dynamics.wheel_axes_acs) {
        let v = nalgebra::Vector3::from(*a);
        let n = v.norm();
        if n > 0.0 {
            *slot = (v / n).into();
        }
    }
    let same = axes
        .iter()
        .flatten()
        .zip(default.iter().flatten())
        .all(|(a, b)| (a - b).abs() < 1e-12);
    if same {
        *default
    } else {
        axes
    }
}

pub fn magnetics_table(
    scenario: &Scenario,
    clock: &SimClock,
) -> anyhow::Result<Option<(MagneticsTable, f64)>> {
    let m = &scenario.magnetics;
    if !(m.enabled && m.onboard_table) {
        return Ok(None);
    }
    let at_s = m.onboard_table_at_s;
    let model = gro_reference::field::FieldModel::dgrf_1990_1995()?;
    let mut base = MagneticsTable::boot();
    base.tam_milligauss_per_count = [
        [scenario.tam1.resolution_milligauss_per_count; 3],
        [scenario.tam2.resolution_milligauss_per_count; 3],
    ];
    base.tam_bias_milligauss = m.onboard_tam_bias_milligauss;
    // The bars' rating is known to the ground (Table 6 field 20), and so are the wheels'
    // geometry and rotor inertia (fields 24–25): the spacecraft's, not the boot defaults.
    base.torquer_dipole_limit_am2 = scenario.torquers.dipole_limit_am2;
    base.wheel_spin_axes_acs = wheel_axes_for_table(scenario, &base.wheel_spin_axes_acs);
    base.wheel_spin_inertia_kg_m2 = scenario.wheel_tachometers.spin_inertia_kg_m2;
    if let Some(sigma) = m.onboard_field_sigma_milligauss {
        base.field_sigma_milligauss = [sigma; 2];
    }
    let table = gro_reference::field::onboard_field_table(&model, clock.epoch(at_s), &base)
        .map_err(|e| anyhow::anyhow!("[magnetics] onboard_table: {e}"))?;
    table.validate().map_err(|e| {
        anyhow::anyhow!("[magnetics]: the OBC would refuse the magnetics table: {e}")
    })?;
    Ok(Some((table, at_s)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use fsw_core::raw::TimeTag;
    use fsw_core::tables::{TableId, TableSet};

    /// The scenario files of the workspace `scenarios/` folder (not its subfolders), loaded.
    fn shipped_scenarios() -> Vec<(std::path::PathBuf, Scenario)> {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios");
        let mut out = Vec::new();
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().and_then(|e| e.to_str()) == Some("toml") {
                let s = Scenario::load(&path).unwrap();
                out.push((path, s));
            }
        }
        out
    }

    /// The derivation's constants are the simulated DRIRU II's (`IruParams::default()`: K, the
    /// largest transient channel over its τ); the boot table's σ_u is the derivation at
    /// release; every shipped scenario that uplinks a σ_u uplinks at least the derivation at
    /// its start (never below the gyro model; the ground may raise it, `normal-ops`), and its
    /// `time_since_release_at_start_s` agrees with its `epoch_utc` within a day (the
    /// derivation reads the former: an epoch moved alone fails here).
    #[test]
    fn rrw_uplinks_follow_the_epoch_derivation() {
        use fsw_core::units::{RAD_PER_ARCSEC, RAD_PER_DEG};
        let iru = crate::sensors::iru::IruParams::default();
        let k = iru.bias_random_walk_arcsec_per_s15 * RAD_PER_ARCSEC;
        assert!((DRIRU_RRW_RAD_PER_S_SQRT_S / k - 1.0).abs() < 1e-3, "K {k}");
        let largest = iru
            .bias_transient_deg_per_s
            .iter()
            .fold(0.0_f64, |a, b| a.max(b.abs()));
        let drift = largest * RAD_PER_DEG / iru.bias_transient_time_constant_s;
        assert!(
            (TRANSIENT_DRIFT_AT_RELEASE_RAD_PER_S2 / drift - 1.0).abs() < 0.01,
            "ṙ₀ {drift}"
        );
        assert!(
            (TRANSIENT_TIME_CONSTANT_S / iru.bias_transient_time_constant_s - 1.0).abs() < 1e-9
        );
        let boot = fsw_core::tables::FilterTable::default_boot().rrw_rad_per_s_sqrt_s;
        let at_release = filter_rrw_for_epoch_rad_per_s_sqrt_s(0.0);
        assert!(
            (boot / at_release - 1.0).abs() < 0.01,
            "{boot} vs {at_release}"
        );
        let release = gro_reference::time::epoch_from_iso("1991-04-07T22:37:00Z").unwrap();
        let mut checked = 0;
        for (path, s) in shipped_scenarios() {
            let Some(rrw) = s
                .filter_table
                .as_ref()
                .and_then(|t| t.get("rrw_rad_per_s_sqrt_s"))
                .and_then(toml::Value::as_float)
            else {
                continue;
            };
            let t0 = s.iru.time_since_release_at_start_s;
            let derived = filter_rrw_for_epoch_rad_per_s_sqrt_s(t0);
            assert!(
                rrw >= derived * 0.99,
                "{}: uplinks σ_u {rrw}, below the gyro model's {derived} at its epoch",
                path.display()
            );
            let epoch = gro_reference::time::epoch_from_iso(&s.epoch_utc).unwrap();
            let since = (epoch - release).to_seconds();
            assert!(
                (since - t0).abs() < 86_400.0,
                "{}: epoch {} is {since} s after release, time_since_release_at_start_s {t0}",
                path.display(),
                s.epoch_utc
            );
            checked += 1;
        }
        assert!(checked >= 1, "no shipped scenario uplinks a σ_u");
    }

    /// Every table image a shipped scenario flies (`[magnetics] onboard_table_file`) passes the
    /// OBC's table services, and its TAM biases are the scenario's true ones within 0.5 mG
    /// per axis: a scenario whose true TAM biases change without a new calibration fails
    /// here (a change of the true TAM scale or misalignment does not: those are the
    /// defaults the table was calibrated on, `scenarios/tables/README.md`). A file with
    /// nothing to fly it is refused by the scenario's validation.
    #[test]
    fn shipped_table_images_load() {
        let mut checked = 0;
        for (path, s) in shipped_scenarios() {
            let Some(file) = s.magnetics.onboard_table_file.as_deref() else {
                continue;
            };
            let image = std::fs::read(s.resolve_file(file)).unwrap();
            let mut set = TableSet::boot();
            assert_eq!(set.load(&image), Ok(TableId::Magnetics), "{file}");
            set.activate(TableId::Magnetics).unwrap();
            let flown = set.magnetics().tam_bias_milligauss;
            for (k, truth) in [s.tam1.bias_milligauss, s.tam2.bias_milligauss]
                .iter()
                .enumerate()
            {
                for axis in 0..3 {
                    assert!(
                        (flown[k][axis] - truth[axis]).abs() < 0.5,
                        "{}: TAM{} bias {:?} mG flown against the true {truth:?}",
                        path.display(),
                        k + 1,
                        flown[k]
                    );
                }
            }
            checked += 1;
        }
        assert!(checked >= 1, "no shipped scenario flies a table image");
        let text = "name = \"x\"\nduration_s = 1\n[magnetics]\nonboard_table_file = \"t.tbl\"\n";
        let err = Scenario::from_toml_str(text, "t").unwrap_err();
        assert!(
            format!("{err:#}").contains("needs enabled = true"),
            "{err:#}"
        );
    }

    /// The catalog holds the Hp 2.0–5.7 stars (3231, below the 4096 capacity), is accepted by
    /// the OBC's table services, and a known star sits where the catalogue puts it.
    #[test]
    fn catalog_builds_loads_and_matches_hipparcos() {
        let s = Scenario::from_toml_str("name = \"x\"\nduration_s = 1\n", "t").unwrap();
        let j2000 = -2.74e8;
        let cat = build_star_catalog(&catalogue_table(&s).unwrap(), &s, j2000).unwrap();
        assert_eq!(cat.stars.len(), 3231);
        assert!(cat
            .stars
            .iter()
            .all(|s| (200..=570).contains(&s.magnitude_centimag)));
        let img = image(TableId::StarCatalog, TimeTag::default(), &cat).unwrap();
        let mut set = TableSet::boot();
        assert_eq!(set.load(&img), Ok(TableId::StarCatalog));
        set.activate(TableId::StarCatalog).unwrap();
        assert_eq!(set.catalog().stars.len(), 3231);
        assert_eq!(image_table_id(&img), Some(TableId::StarCatalog));
    }
}
