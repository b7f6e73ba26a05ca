//! # The whole chain: TP → DA/FADS → FFCAL → adjustment → IRUCAL → tables
//!
//! `ground-tool calibrate RUN_DIR --out DIR` runs this. It needs only `telemetry.bin` (and
//! optionally `metadata.json`) from the run folder, never the simulator's truth.
//!
//! Steps (paper §3.3 and §4):
//! 1. **TP** decodes the telemetry, reporting damage.
//! 2. **DA/FADS** converts counts with the tables flown (the boot tables unless `--tables`
//!    says otherwise), identifies stars against the full catalog and computes apparent
//!    references ([`super::observations`]).
//! 3. **FFCAL** in two stages: (1) FHST2 relative to FHST1 from every identified star, tied
//!    by the gyro in batches of holds and slews ([`super::star_batches`],
//!    [`crate::calibration::fhst_relative`]; `FhstStage::StarPairs` = Shuster's simultaneous
//!    star pairs instead), fused with the flown alignments as the prior; (2) every frame with
//!    two or more referenced vectors is an epoch of Shuster's attitude-independent alignment
//!    estimation of the FSSs with the FHSTs held (`ffcal_staged`).
//! 4. **Adjustment** (paper appendix): the common rotation that would move the OBC's
//!    two-tracker attitude frame `M_AN` is removed, giving the uplinked `M_AS''`.
//! 5. **IRUCAL**: maneuvers are found in the telemetry as runs of high-rate frames; each end
//!    attitude is a FHST-only fine attitude centred in a 10-min batch in the holds before and
//!    after (the paper's recommendation); holds give bias intervals and the bias history.
//! 6. **Tables**: binary images written with `fsw-core`'s own types.

use super::alignment_heldout::{
    validate_aberration_switch, validate_alignment_heldout, AberrationSwitchValidation,
    AlignmentValidation,
};
use super::ffcal_stages::{alignment_data, fss_cell, AlignmentFit, AlignmentSetup, FfcalStaging};
pub use super::ffcal_stages::{FhstStage, SENSOR_NAMES};
use super::fss_systematic::{estimate_fss_systematic, FssSystematicEstimate};
pub use super::gyro_chain::IruReport;
use super::gyro_chain::{build_gyro_chain, irucal_stage, IruStage};
use super::iru_fixes::{frame_index_at, FixFloors, BATCH_HALF_S};
use super::maneuvers::high_rate_runs;
pub use super::maneuvers::{CoarseAttitude, ManeuverReport};
use super::observations::{
    build_observations, fhst_attitude, fine_attitude, AttitudeSensors, FrameObservations,
    IdentifyOptions, RateSwitch,
};
use crate::calibration::adjust::{preserve_obc_attitude, Adjustment, BoresightFrame};
use crate::calibration::alignment::{
    cramer_rao_covariance, AlignmentData, FfcalConfig, FfcalSolution, SensorSpec, Weighting,
};
use crate::calibration::fhst_relative::{FhstRelativeAlignment, RelativeAlignmentError};
use crate::calibration::iru::{GyroNoise, IrucalSolution};
use crate::calibration::iru_chain::{Chain, ChainConfig};
use crate::tp::{self, Telemetry, TpReport};
use anyhow::{bail, Context};
use fsw_core::attitude::{rotvec_from_rot, Quat};
use fsw_core::tables::image::encode_image;
use fsw_core::tables::types::{matrix_from_rows, rows_from_matrix};
use fsw_core::tables::{AlignmentTable, FilterTable, IruTable, TableId};
use fsw_core::units::ARCSEC_PER_RAD;
use gro_reference::sky::{Sky, SkyParams};
use nalgebra::{Matrix3, Vector3};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Largest per-axis σ of a coarse attitude reported (deg).
const COARSE_MAX_SIGMA_DEG: f64 = 2.0;

/// Prior 1σ of the flown alignments per axis (arcsec): FHSTs, FSSs. The paper's FSS1 moved by
/// 733 arcsec, so the FSS prior must not constrain a change of that size.
const PRIOR_SIGMA_ARCSEC: [f64; 4] = [60.0, 60.0, 1800.0, 1800.0];

/// What the operator declares about a run (`metadata.json`): the one definition, shared with
/// the simulator that writes it (`gro_reference::run_folder`, docs/icd.md §5).
pub use gro_reference::run_folder::Metadata;

/// Options of the chain.
#[derive(Clone, Debug)]
pub struct CalibrateOptions {
    /// Tables flown (alignment and IRU); `None` = the boot tables.
    pub flown_alignment: Option<AlignmentTable>,
    /// IRU table flown; `None` = boot.
    pub flown_iru: Option<IruTable>,
    /// Filter table flown; `None` = boot.
    pub flown_filter: Option<FilterTable>,
    /// Magnetics table flown (`Ok(None)` = boot, no field model); `Err` = the run lists one
    /// whose file is missing, said in `report.json` `tam.table` (the table is optional: a new
    /// one is then built from the boot table).
    pub flown_magnetics: Result<Option<fsw_core::tables::MagneticsTable>, String>,
    /// FFCAL weighting.
    pub weighting: Weighting,
    /// Identification options (aberration on by default).
    pub identify: IdentifyOptions,
    /// FFCAL in two stages (FHSTs from star pairs, then the FSSs relative to them; default)
    /// instead of one joint fit of all four sensors.
    pub staged_ffcal: bool,
    /// How the staged FFCAL's first stage gets the FHST1–FHST2 relative alignment.
    pub fhst_stage: FhstStage,
    /// IRU calibration maneuvers given by the user as (start, end) in seconds since the first
    /// raw frame; `None` = found in the telemetry as runs of high-rate frames.
    pub maneuvers_s: Option<Vec<(f64, f64)>>,
}

impl CalibrateOptions {
    /// The stages of FFCAL these options ask for.
    pub(crate) fn ffcal_staging(&self) -> FfcalStaging {
        FfcalStaging {
            staged_ffcal: self.staged_ffcal,
            fhst_stage: self.fhst_stage,
        }
    }
}

impl Default for CalibrateOptions {
    fn default() -> Self {
        Self {
            flown_alignment: None,
            flown_iru: None,
            flown_filter: None,
            flown_magnetics: Ok(None),
            weighting: Weighting::Optimal1990,
            identify: IdentifyOptions::default(),
            staged_ffcal: true,
            fhst_stage: FhstStage::GyroBatches,
            maneuvers_s: None,
        }
    }
}

/// The OBC's filter bias (ACS, rad/s) at the first housekeeping packet at or after `t_s` (the
/// last one after the end); zero without housekeeping.
#[must_use]
pub fn obc_bias_at(tm: &Telemetry, t_s: f64) -> Vector3<f64> {
    let i = tm.housekeeping.partition_point(|h| h.time.seconds() < t_s);
    tm.housekeeping
        .get(i.min(tm.housekeeping.len().saturating_sub(1)))
        .map_or(Vector3::zeros(), |h| Vector3::from(h.bias_acs_rad_per_s))
}

/// One sensor's alignment result for the report.
#[derive(Clone, Debug, Serialize)]
pub struct AlignmentReport {
    /// `M_AS` (row-major).
    pub m_acs_from_sensor: [[f64; 3]; 3],
    /// 1σ of the rotation vector per ACS axis, arcsec.
    pub sigma_arcsec: [f64; 3],
    /// Rotation vector from the flown alignment, ACS, arcsec.
    pub theta_acs_arcsec: [f64; 3],
}

/// The whole result.
#[derive(Clone, Debug, Serialize)]
pub struct CalibrationReport {
    /// TP findings.
    pub telemetry: TpReport,
    /// Frames, identified stars, Sun observations.
    pub data: DataSummary,
    /// Calibrated alignments (before adjustment).
    pub alignments: std::collections::BTreeMap<String, AlignmentReport>,
    /// Adjusted alignments (uplinked).
    pub alignments_adjusted: std::collections::BTreeMap<String, AlignmentReport>,
    /// The common rotation removed by the adjustment, arcsec.
    pub adjustment_theta_acs_arcsec: [f64; 3],
    /// Residual RMS per sensor (dot-product residuals of FFCAL), arcsec.
    pub residual_rms_arcsec: BeforeAfter,
    /// FFCAL details.
    pub ffcal: FfcalSummary,
    /// IRU calibration (absent when the telemetry has too few maneuvers).
    pub iru: Option<IruReport>,
    /// Why the IRU calibration was not done, if so.
    pub iru_skipped: Option<String>,
    /// Maneuvers found.
    pub maneuvers: Vec<ManeuverReport>,
    /// Bias history from inertial holds.
    pub bias_history: Vec<BiasHistoryPoint>,
    /// Table images written.
    pub tables: std::collections::BTreeMap<String, String>,
    /// Filter-table settings changed, with why; a last line "not written: …" when the change
    /// failed its validation (`filter_validation`). Empty = no change proposed.
    pub filter_changes: Vec<String>,
    /// Held-out validation of the alignment table (`super::alignment_heldout`): the new
    /// alignments are written only if it passed; otherwise the flown table is written again.
    pub alignment_validation: AlignmentValidation,
    /// Validation of the filter-table change, when there is one (the flown filter table is
    /// kept when it fails).
    pub filter_validation: Option<AberrationSwitchValidation>,
    /// The filter table's noise terms derived from the flight (gyro and FHST) and the
    /// decision on each, written or not, with why (`super::filter_tuning`).
    pub filter_tuning: Vec<super::filter_tuning::TermDecision>,
    /// The FHST systematic floor derived for the alignments that fly
    /// ([`super::filter_floor`]); `None` before `calibrate_run` decides which alignments fly.
    pub fhst_floor: Option<super::filter_floor::FhstFloor>,
    /// The TAM calibration against the FHST fine attitude and the FSS/TAM attitude check
    /// (`pipeline::tam`, issue 20); says why when the telemetry has no TAM data.
    pub tam: super::tam::TamReport,
    /// The wheel frames (APID 0x014): wheel momentum, bar dipoles and the bar monitors
    /// against the TAM bars-on bits (`pipeline::wheels`); `None` without wheel frames.
    pub wheels: Option<super::wheels::WheelSummary>,
}

/// Data counts.
#[derive(Clone, Debug, Default, Serialize)]
pub struct DataSummary {
    /// Raw frames.
    pub frames: usize,
    /// FHST samples identified against the catalog, per tracker.
    pub stars_identified: [usize; 2],
    /// FHST samples not identified (unique match failed), per tracker.
    pub stars_unidentified: [usize; 2],
    /// FSS samples with the Sun, per sensor.
    pub sun_samples: [usize; 2],
    /// FFCAL epochs (frames with ≥ 2 referenced vectors).
    pub ffcal_epochs: usize,
    /// Epochs of the FHST stage (both trackers on identified stars); 0 = one joint fit.
    pub ffcal_fhst_stage_epochs: usize,
    /// Sensors never observed together with another one: left out of FFCAL, their flown
    /// alignment is kept.
    pub not_observed: Vec<String>,
    /// Frame intervals holding an IRU rate-mode switch whose pulses were split at the switch.
    pub rate_switch_frames_split: usize,
    /// Frame intervals holding a rate-mode switch that could not be split (step dropped).
    pub rate_switch_frames_dropped: usize,
}

/// Per-sensor before/after.
#[derive(Clone, Debug, Default, Serialize)]
pub struct BeforeAfter {
    /// Before calibration.
    pub before: std::collections::BTreeMap<String, f64>,
    /// After.
    pub after: std::collections::BTreeMap<String, f64>,
}

/// FFCAL summary.
#[derive(Clone, Debug, Serialize)]
pub struct FfcalSummary {
    /// Weighting used.
    pub weighting: Weighting,
    /// Gauss–Newton passes.
    pub iterations: usize,
    /// Epochs.
    pub epochs: usize,
    /// Normal-matrix eigenvalues (ascending), arcsec⁻².
    pub eigenvalues: Vec<f64>,
    /// Relative alignment FHST2 w.r.t. FHST1, 1σ per axis, arcsec.
    pub sigma_fhst2_rel_fhst1_arcsec: [f64; 3],
    /// Covariance of each sensor's alignment relative to FHST1 (`θ_k − θ_FHST1`, ACS,
    /// arcsec², rows), the quantity that the data determine (the common rotation rests on
    /// the priors); absent for FHST1 and for sensors not observed.
    pub relative_covariance_to_fhst1_arcsec2: std::collections::BTreeMap<String, [[f64; 3]; 3]>,
    /// Cramér–Rao bound of the same quantity from every FFCAL epoch (all sensors, FSS samples
    /// weighted as FFCAL weights them), 1σ per axis, arcsec.
    pub crb_sigma_fhst2_rel_fhst1_all_sensors_arcsec: [f64; 3],
    /// The bound from the simultaneous FHST star pairs alone (the star-pair stage's data),
    /// arcsec.
    pub crb_sigma_fhst2_rel_fhst1_fhst_only_arcsec: [f64; 3],
    /// Data of the FHST stage (`gyro_batches`, `star_pairs`; absent for one joint fit).
    pub fhst_stage: Option<FhstStage>,
    /// The gyro-batch estimate of FHST2 relative to FHST1 (computed whenever the data allow,
    /// used by the `gyro_batches` stage).
    pub gyro_batches: Option<BatchAlignmentSummary>,
    /// FSS1, FSS2: the error level left in the calibrated residuals per field cell, beside
    /// the declared level the FSS weights use (absent without FSS data).
    pub fss_systematic: Option<[FssSystematicEstimate; 2]>,
    /// How the FSS covariance was formed: `consider` (the declared transfer-function spreads
    /// as consider parameters plus the noise bound, `pipeline::fss_consider`) or `cells` (the
    /// per-cell weights' formal covariance with the declared systematic level).
    pub fss_covariance: &'static str,
}

/// The gyro-batch relative FHST alignment (`calibration::fhst_relative`) for the report.
#[derive(Clone, Debug, Serialize)]
pub struct BatchAlignmentSummary {
    /// θ of FHST2 relative to FHST1 from the flown alignments, ACS, arcsec.
    pub theta_fhst2_rel_fhst1_arcsec: [f64; 3],
    /// 1σ per axis, arcsec (the bound scaled by χ²/dof, plus the uncorrected aberration).
    pub sigma_arcsec: [f64; 3],
    /// Cramér–Rao bound of the batch data with the declared noise, 1σ per axis, arcsec.
    pub crb_sigma_arcsec: [f64; 3],
    /// Part of `sigma_arcsec` from orbital aberration left uncorrected (frames without a
    /// definitive orbit), 1σ per axis, arcsec; 0 with a full ephemeris.
    pub aberration_consider_sigma_arcsec: [f64; 3],
    /// Part of the variance behind `sigma_arcsec` from the flown gyro's δM, estimated with the
    /// alignment from the slew batches (`pipeline::star_batches`), as 1σ per axis, arcsec.
    pub gyro_scale_sigma_arcsec: [f64; 3],
    /// χ²/dof of the fit.
    pub variance_factor: f64,
    /// Batches with stars in both trackers.
    pub batches: usize,
    /// Samples used per tracker.
    pub samples: [usize; 2],
    /// Samples rejected as outliers.
    pub rejected: usize,
    /// Residual RMS per tracker, arcsec per axis.
    pub residual_rms_arcsec: [f64; 2],
}

/// One bias-history point.
#[derive(Clone, Debug, Serialize)]
pub struct BiasHistoryPoint {
    /// Mid time, s since the first frame.
    pub t_s: f64,
    /// Bias in ACS, rad/s.
    pub bias_rad_per_s: [f64; 3],
    /// 1σ, rad/s.
    pub sigma_rad_per_s: [f64; 3],
    /// The gyro triad active at this time, whose bias this is (`Primary`, `Backup`).
    pub triad: crate::calibration::iru_chain::Triad,
    /// The OBC filter's bias at the same time, rad/s (from housekeeping).
    pub obc_bias_rad_per_s: Option<[f64; 3]>,
}

/// Output of the chain besides the report: the new tables.
#[derive(Clone, Debug)]
pub struct CalibrationOutput {
    /// The report.
    pub report: CalibrationReport,
    /// New alignment table (adjusted).
    pub alignment: AlignmentTable,
    /// New IRU table (G updated only when significant).
    pub iru: IruTable,
    /// New filter table, only when a setting should change ([`filter_update`]).
    pub filter: Option<FilterTable>,
    /// The frames (for plots and residual analysis).
    pub frames: Vec<FrameObservations>,
    /// FFCAL solution.
    pub ffcal: FfcalSolution,
    /// IRUCAL solution.
    pub irucal: Option<IrucalSolution>,
    /// The gyro chain IRUCAL used (attitude fixes and gyro links).
    pub gyro_chain: Chain,
}

fn rows(m: &Matrix3<f64>) -> [[f64; 3]; 3] {
    rows_from_matrix(m)
}

/// The Hipparcos catalog shipped with the project (provenance in `data/README.md`).
///
/// # Errors
/// Parse errors of the embedded CSV (a build defect).
pub fn load_catalog() -> anyhow::Result<Sky> {
    let table = gro_reference::data::CsvTable::parse(
        gro_reference::data::HIPPARCOS_CSV,
        "data/hipparcos_mag6p5.csv",
    )?;
    Sky::from_csv(&table, &SkyParams::default())
}

/// Read `metadata.json` if present (defaults otherwise).
///
/// # Errors
/// A present but malformed file ([`crate::run_check::InputError`], naming the file).
pub fn read_metadata(run_dir: &Path) -> anyhow::Result<Metadata> {
    Metadata::read(run_dir)
}

/// 1σ per axis (arcsec) of the FHST2-relative-to-FHST1 alignment from the Cramér–Rao bound
/// of `data` at the solution's alignments; NaN when the bound cannot be formed.
fn crb_relative_sigma(
    sensors: &[SensorSpec],
    data: &AlignmentData,
    solution: &FfcalSolution,
) -> [f64; 3] {
    let m: Vec<Matrix3<f64>> = solution
        .sensors
        .iter()
        .take(sensors.len())
        .map(|s| s.m_acs_from_sensor_calibrated)
        .collect();
    match cramer_rao_covariance(sensors, data, &m) {
        Ok(c) if c.nrows() >= 6 => {
            let blk = |a: usize, b: usize| -> Matrix3<f64> {
                c.fixed_view::<3, 3>(3 * a, 3 * b).into_owned()
            };
            let r = blk(1, 1) + blk(0, 0) - blk(0, 1) - blk(1, 0);
            [0, 1, 2].map(|i| r[(i, i)].max(0.0).sqrt())
        }
        _ => [f64::NAN; 3],
    }
}

/// The coarse attitude at the end `e` of the maneuver `s..=e`: FSS vectors over the maneuver
/// carried to its end by the gyro. Why: the OBC's coarse mode (FSS + TAM + IRU) must be
/// within 2° for star identification; on the ground it checks the FSS alignments and the
/// gyro independently of the trackers.
fn coarse_attitude(
    frames: &[FrameObservations],
    s: usize,
    e: usize,
    bias: &Vector3<f64>,
    t0: f64,
) -> Option<CoarseAttitude> {
    let sol = fine_attitude(
        frames,
        s..e + 1,
        e,
        bias,
        &Matrix3::zeros(),
        AttitudeSensors::FssOnly,
    )
    .ok()?;
    let sigma_deg = [0, 1, 2].map(|i| sol.cov_acs_rad2[(i, i)].max(0.0).sqrt().to_degrees());
    // Undetermined about the Sun line when the Sun hardly moved in the body.
    if sigma_deg.iter().any(|x| !(*x <= COARSE_MAX_SIGMA_DEG)) {
        return None;
    }
    let hi = frame_index_at(frames, frames[e].time.seconds() + 2.0 * BATCH_HALF_S);
    let fine = fhst_attitude(frames, e..hi.max(e + 1), e, bias).ok();
    let q = sol.q_acs_from_eci;
    Some(CoarseAttitude {
        t_s: frames[e].time.seconds() - t0,
        q_acs_from_eci: [q.x, q.y, q.z, q.w],
        sigma_deg,
        difference_to_fine_deg: fine.map(|f| {
            rotvec_from_rot(&(f.m_acs_from_eci * sol.m_acs_from_eci.transpose()))
                .norm()
                .to_degrees()
        }),
    })
}

/// User-given maneuvers (seconds since the first frame) as frame index pairs, in time order.
///
/// # Errors
/// A span outside the telemetry, or spans that overlap.
fn user_maneuvers(
    frames: &[FrameObservations],
    spans_s: &[(f64, f64)],
) -> anyhow::Result<Vec<(usize, usize)>> {
    let (Some(first), Some(last)) = (frames.first(), frames.last()) else {
        bail!("no frames for the given maneuvers");
    };
    let t0 = first.time.seconds();
    let span_s = last.time.seconds() - t0;
    let mut sorted = spans_s.to_vec();
    sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut out: Vec<(usize, usize)> = Vec::new();
    for &(a, b) in &sorted {
        if !(a >= 0.0 && b > a && b <= span_s) {
            bail!(
                "maneuver {a}:{b} s is outside the telemetry (0 to {span_s:.0} s after the first raw frame)"
            );
        }
        let ia = frame_index_at(frames, t0 + a);
        let ib = frame_index_at(frames, t0 + b);
        if out.last().is_some_and(|&(_, e)| ia <= e) {
            bail!("maneuver {a}:{b} s overlaps the previous one: give disjoint spans");
        }
        out.push((ia, ib));
    }
    Ok(out)
}

/// The least rotation, deg, of a maneuver given with `--maneuver`: the scale factors and
/// misalignments show only in a rotation (100 ppm of 1° is 0.4″, below one star's noise).
pub const MIN_USER_MANEUVER_DEG: f64 = 1.0;

/// A `--maneuver` span in which the body hardly turned carries no scale information, and its
/// link would be taken for one: refused, naming the span and the rotation the gyro measured
/// along it (the path, Σ ‖Δθ‖ of its frames after the first: an out-and-back slew turns far
/// though it ends where it began), or that it holds no gyro data.
fn refuse_still_user_maneuvers(
    frames: &[FrameObservations],
    maneuvers: &[(usize, usize)],
    t0: f64,
) -> anyhow::Result<()> {
    for &(s, e) in maneuvers {
        let steps: Vec<f64> = frames
            .get(s + 1..=e)
            .unwrap_or_default()
            .iter()
            .filter_map(|f| f.gyro.map(|g| g.dtheta_acs_rad.norm()))
            .collect();
        let turned_deg = steps.iter().sum::<f64>().to_degrees();
        if steps.is_empty() || turned_deg < MIN_USER_MANEUVER_DEG {
            let span = format!(
                "--maneuver {:.0}:{:.0}",
                frames[s].time.seconds() - t0,
                frames[e].time.seconds() - t0
            );
            let why = if steps.is_empty() {
                "holds no gyro data".to_owned()
            } else {
                format!("the gyro turned only {turned_deg:.3}° along it")
            };
            return Err(crate::run_check::InputError::msg(format!(
                "{span}: {why} (at least {MIN_USER_MANEUVER_DEG}° is needed: the scale factors show only in a rotation); give spans that hold the slews"
            ))
            .into());
        }
    }
    Ok(())
}

/// The OBC's bias from the housekeeping record at or before `t_s` (absolute time, s).
fn obc_bias_sample(tm: &Telemetry, t_s: f64) -> Option<[f64; 3]> {
    let k = tm.housekeeping.partition_point(|h| h.time.seconds() <= t_s);
    tm.housekeeping
        .get(k.checked_sub(1)?)
        .map(|h| h.bias_acs_rad_per_s)
}

/// What every stage of [`calibrate_telemetry`] reads and none writes: the run (telemetry and
/// declarations), the operator's options, the tables flown and the catalog.
struct ChainContext<'a> {
    /// The decoded telemetry.
    tm: &'a Telemetry,
    /// What the operator declares about the run.
    metadata: &'a Metadata,
    /// The operator's options.
    options: &'a CalibrateOptions,
    /// The alignment table flown (the boot table unless the options name one).
    flown_alignment: AlignmentTable,
    /// The IRU table flown (the boot table unless the options name one).
    flown_iru: IruTable,
    /// The star catalog.
    sky: Sky,
}

impl<'a> ChainContext<'a> {
    /// The context of a run (module doc, step 1).
    ///
    /// # Errors
    /// Too few raw frames for a calibration (said before the catalog is loaded), or the
    /// catalog cannot be loaded.
    fn new(
        tm: &'a Telemetry,
        metadata: &'a Metadata,
        options: &'a CalibrateOptions,
    ) -> anyhow::Result<Self> {
        if tm.raw.len() < 10 {
            bail!(
                "only {} raw sensor frames (APID 0x010) in the telemetry: calibration needs hours of data with both FHSTs tracking and the Sun in an FSS (docs/icd.md)",
                tm.raw.len()
            );
        }
        Ok(Self {
            tm,
            metadata,
            options,
            flown_alignment: options
                .flown_alignment
                .unwrap_or_else(AlignmentTable::prelaunch),
            flown_iru: options.flown_iru.unwrap_or_else(IruTable::prelaunch),
            sky: load_catalog()?,
        })
    }

    /// DA/FADS (module doc, step 2): every frame's observations, converted with `alignment`
    /// and the flown IRU table, stars identified against the catalog.
    fn identify(&self, alignment: &AlignmentTable) -> Vec<FrameObservations> {
        build_observations(
            self.tm,
            alignment,
            &self.flown_iru,
            &self.metadata.sensors,
            &self.sky,
            &self.options.identify,
        )
    }
}

/// The sensors FFCAL calibrates (those seen together with another one: an FSS the Sun never
/// visited is left out and keeps its flown alignment, reported as not observed).
struct FfcalSensors {
    /// Table index (FHST1, FHST2, FSS1, FSS2) → index in `specs`, `None` = unobserved.
    map: [Option<usize>; 4],
    /// The observed table indices.
    observed: Vec<usize>,
    /// The flown `M_AS` of all four sensors, in table order.
    flown: Vec<Matrix3<f64>>,
    /// The observed sensors with their flown alignments and priors.
    specs: Vec<SensorSpec>,
}

impl FfcalSensors {
    /// The observed sensors of the frames (counted into `summary.not_observed`).
    ///
    /// # Errors
    /// A FHST never observed with another sensor.
    fn observed(
        ctx: &ChainContext<'_>,
        frames: &[FrameObservations],
        summary: &mut DataSummary,
    ) -> anyhow::Result<Self> {
        let declared_fss_sys = ctx.metadata.sensors.fss_systematic_or_paper_arcsec();
        let (map, observed) = observed_sensors(frames, declared_fss_sys, summary)?;
        let flown = ctx
            .flown_alignment
            .matrices()
            .map(matrix_from_rows)
            .to_vec();
        let specs = observed
            .iter()
            .map(|&k| SensorSpec::new(SENSOR_NAMES[k], flown[k], PRIOR_SIGMA_ARCSEC[k]))
            .collect();
        Ok(Self {
            map,
            observed,
            flown,
            specs,
        })
    }

    /// The FFCAL set-up of these sensors: the same for the full fit, its held-out folds and
    /// the aberration switch's validation.
    fn setup<'s>(
        &'s self,
        ctx: &ChainContext<'_>,
        obc_bias_at: &'s dyn Fn(f64) -> Vector3<f64>,
        summary: &DataSummary,
    ) -> AlignmentSetup<'s> {
        AlignmentSetup {
            sensors: &self.specs,
            map: self.map,
            fss_systematic_arcsec: ctx.metadata.sensors.fss_systematic_or_paper_arcsec(),
            staging: ctx.options.ffcal_staging(),
            cfg: FfcalConfig {
                weighting: ctx.options.weighting,
                ..FfcalConfig::default()
            },
            obc_bias_at,
            data_note: format!(
                "stars identified per FHST: {:?}; Sun samples per FSS: {:?}",
                summary.stars_identified, summary.sun_samples
            ),
        }
    }

    /// All four alignments: the flown ones with the observed replaced by `solution`'s.
    fn with_solution(&self, solution: &FfcalSolution) -> Vec<Matrix3<f64>> {
        let mut m_acs = self.flown.clone();
        for (j, &k) in self.observed.iter().enumerate() {
            m_acs[k] = solution.sensors[j].m_acs_from_sensor_calibrated;
        }
        m_acs
    }
}

/// What FFCAL and the adjustment (module doc, steps 3–4) hand on.
struct FfcalStage {
    /// The alignments and their covariance.
    solution: FfcalSolution,
    /// The report's FFCAL section.
    summary: FfcalSummary,
    /// The adjustment that keeps the OBC's attitude frame.
    adjustment: Adjustment,
    /// Per observed sensor, as calibrated.
    alignments: std::collections::BTreeMap<String, AlignmentReport>,
    /// Per observed sensor, as adjusted (uplinked).
    alignments_adjusted: std::collections::BTreeMap<String, AlignmentReport>,
    /// Residual RMS per sensor before and after.
    residual: BeforeAfter,
    /// The gyro-batch FHST stage against the star pairs: `None` when that stage was not
    /// used, `Some(None)` when it was but the check could not be made.
    fhst_stage_agreement: Option<Option<super::ffcal_stages::FhstStageAgreement>>,
}

/// FFCAL over the first pass's frames (module doc, step 3), the FSS error level left in its
/// residuals, and the adjustment (step 4). The fit's data are freed on return, before the
/// held-out folds build theirs (six months: 2 × 134 MB).
///
/// # Errors
/// A stage of the fit that cannot be solved, or an adjustment that fails.
fn ffcal_stage(
    ctx: &ChainContext<'_>,
    frames: &[FrameObservations],
    sensors: &FfcalSensors,
    setup: &AlignmentSetup<'_>,
    summary: &mut DataSummary,
) -> anyhow::Result<FfcalStage> {
    crate::progress::step("FFCAL: the alignments");
    let consider = ctx.metadata.fss_transfer_function_sigma.as_ref();
    let fit = setup.fit(&[frames], consider)?;
    if let (Some((FhstStage::StarPairs, _)), FhstStage::GyroBatches, Err(e)) =
        (&fit.fhst_stage, ctx.options.fhst_stage, &fit.batch_rel)
    {
        crate::note!("warning: FHST stage from the simultaneous star pairs: {e}");
    }
    let AlignmentFit {
        data,
        fhst_data,
        fhst_stage,
        batch_rel,
        solution,
    } = fit;
    summary.ffcal_epochs = data.epoch_count();
    let fhst_stage_agreement = match (&fhst_stage, &batch_rel) {
        (Some((FhstStage::GyroBatches, _)), Ok(rel)) => Some(
            super::ffcal_stages::fhst_stage_agreement(setup.sensors, &fhst_data, &setup.cfg, rel),
        ),
        (Some((FhstStage::GyroBatches, _)), Err(_)) => Some(None),
        _ => None,
    };
    // The FSS error level left in the calibrated residuals (the paper's "inherent" 0.022°),
    // reported beside the declared level the FSS weights use (`pipeline::fss_systematic`).
    let calibrated = sensors.with_solution(&solution);
    let fss_systematic = sensors.observed.iter().any(|&k| k >= 2).then(|| {
        let m_acs = [calibrated[0], calibrated[1], calibrated[2], calibrated[3]];
        estimate_fss_systematic(frames, &m_acs, setup.fss_systematic_arcsec, fss_cell)
    });
    summary.ffcal_fhst_stage_epochs = match &fhst_stage {
        Some((FhstStage::StarPairs, _)) => fhst_data.epoch_count(),
        _ => 0,
    };
    // Adjustment (over all four sensors; the unobserved keep their flown alignment).
    let adjustment =
        preserve_obc_attitude(&sensors.flown, &calibrated, 0, 1, BoresightFrame::Bisector)?;
    let (alignments, alignments_adjusted, residual) = alignment_reports(
        &solution,
        &sensors.observed,
        &sensors.flown,
        &adjustment.m_acs_from_sensor_adjusted,
    );
    let summary = FfcalSummary::new(
        &solution,
        &sensors.observed,
        &sensors.specs,
        (&data, &fhst_data),
        fhst_stage.as_ref().map(|(k, _)| *k),
        &batch_rel,
        fss_systematic,
        consider.is_some(),
    );
    Ok(FfcalStage {
        solution,
        summary,
        adjustment,
        alignments,
        alignments_adjusted,
        residual,
        fhst_stage_agreement,
    })
}

/// The alignment table to uplink (module doc, step 4): the flown table with the adjusted
/// alignments, each orthonormalised.
///
/// # Errors
/// The table fails the OBC's validation.
fn adjusted_alignment_table(
    flown: AlignmentTable,
    adjustment: &Adjustment,
) -> anyhow::Result<AlignmentTable> {
    let ortho = |m: &Matrix3<f64>| rows(&Quat::from_dcm(m).to_dcm());
    let adjusted = &adjustment.m_acs_from_sensor_adjusted;
    let mut table = flown;
    table.m_acs_from_fhst1 = ortho(&adjusted[0]);
    table.m_acs_from_fhst2 = ortho(&adjusted[1]);
    table.m_acs_from_fss1 = ortho(&adjusted[2]);
    table.m_acs_from_fss2 = ortho(&adjusted[3]);
    table
        .validate()
        .map_err(|e| anyhow::anyhow!("calibrated alignment table invalid: {e:?}"))?;
    Ok(table)
}

/// What IRUCAL (module doc, step 5) hands on.
struct GyroStage {
    /// The IRU table to write, the report's IRU section, the primary triad's solution and
    /// why IRUCAL gave no answer.
    iru: IruStage,
    /// One report per maneuver.
    maneuvers: Vec<ManeuverReport>,
    /// The smoothed bias at every fix beside the OBC's.
    bias_history: Vec<BiasHistoryPoint>,
    /// The gyro chain IRUCAL used.
    chain: Chain,
}

/// IRUCAL over the second pass's frames (module doc, step 5): the maneuvers (the user's or
/// found), the chain of attitude fixes and gyro links, the solution and the bias history.
///
/// # Errors
/// A user maneuver outside the frames.
fn gyro_stage(
    ctx: &ChainContext<'_>,
    frames: &[FrameObservations],
    ffcal: &FfcalStage,
    obc_bias_at: &dyn Fn(f64) -> Vector3<f64>,
    summary: &mut DataSummary,
) -> anyhow::Result<GyroStage> {
    let t0 = frames.first().map_or(0.0, |f| f.time.seconds());
    let noise = GyroNoise {
        sigma_v_rad_per_sqrt_s: ctx.metadata.sensors.iru_arw_rad_per_sqrt_s,
        sigma_u_rad_per_s_1p5: ctx.metadata.sensors.iru_rrw_rad_per_s_sqrt_s,
    };
    let maneuvers = match &ctx.options.maneuvers_s {
        Some(spans) => user_maneuvers(frames, spans)?,
        None => high_rate_runs(frames.iter().map(|f| f.high_rate), true),
    };
    let fhst_floor = FixFloors::from_ffcal(&ffcal.summary, &ffcal.solution, ctx.metadata);
    summary.count_rate_switches(frames);
    crate::progress::step("IRUCAL: attitude fixes and the gyro chain");
    let gyro_chain = build_gyro_chain(frames, &maneuvers, obc_bias_at, &fhst_floor, t0);
    let mut maneuver_reports = maneuver_reports(frames, &maneuvers, &gyro_chain, obc_bias_at, t0);
    if ctx.options.maneuvers_s.is_some() {
        refuse_still_user_maneuvers(frames, &maneuvers, t0)?;
    }
    let chain_cfg = ChainConfig {
        noise,
        ..ChainConfig::default()
    };
    let mut iru = irucal_stage(
        &gyro_chain.chain,
        &chain_cfg,
        &ctx.flown_iru,
        &mut maneuver_reports,
    );
    if let Some(r) = iru.report.as_mut() {
        r.misfit_fixes.clone_from(&gyro_chain.misfit_fixes);
    }
    let bias_history = iru
        .chain_solution
        .as_ref()
        .map(|sol| bias_history(sol, ctx.tm, t0))
        .unwrap_or_default();
    Ok(GyroStage {
        iru,
        maneuvers: maneuver_reports,
        bias_history,
        chain: gyro_chain.chain,
    })
}

/// The flown Table 6 (its rotor inertia for the wheel frames), else the boot table, with
/// where it came from (said in the report: a boot inertia is an assumption).
fn flown_magnetics_or_boot(
    options: &CalibrateOptions,
) -> (fsw_core::tables::MagneticsTable, String) {
    match &options.flown_magnetics {
        Ok(Some(t)) => (*t, "the flown Table 6".to_owned()),
        Ok(None) => (
            fsw_core::tables::MagneticsTable::boot(),
            "the boot Table 6 (no magnetics table was uplinked)".to_owned(),
        ),
        Err(why) => (
            fsw_core::tables::MagneticsTable::boot(),
            format!("the boot Table 6 (the flown one is unknown: {why})"),
        ),
    }
}

/// Run the chain on decoded telemetry, stage by stage as the module doc numbers them.
///
/// # Errors
/// Too little data for FFCAL (with what is missing), or an internal numerical failure.
pub fn calibrate_telemetry(
    tm: &Telemetry,
    metadata: &Metadata,
    options: &CalibrateOptions,
) -> anyhow::Result<CalibrationOutput> {
    // 1. The run, the tables flown and the catalog.
    let ctx = ChainContext::new(tm, metadata, options)?;
    // The batches that give the interval end attitudes (and the FHST gyro batches) carry their
    // vectors with the OBC's bias, so the bias is not smeared into them.
    let obc_bias_at = |t_s: f64| obc_bias_at(tm, t_s);

    // 2. DA/FADS with the flown alignments.
    crate::progress::step("identifying stars against the catalog (flown alignments)");
    let frames = ctx.identify(&ctx.flown_alignment);
    let mut summary = DataSummary::of_frames(&frames);
    if tm.ephemeris.is_empty() {
        crate::note!("warning: no ephemeris packets (APID 0x020): orbital aberration and Sun parallax are not corrected");
    }

    // 3–4. FFCAL and the adjustment, the alignments' held-out validation, the new table.
    let sensors = FfcalSensors::observed(&ctx, &frames, &mut summary)?;
    let setup = sensors.setup(&ctx, &obc_bias_at, &summary);
    let ffcal = ffcal_stage(&ctx, &frames, &sensors, &setup, &mut summary)?;
    crate::progress::step("held-out validation of the alignments");
    let mut alignment_validation = validate_alignment_heldout(&frames, &setup);
    alignment_validation.check_fhst_stage(ffcal.fhst_stage_agreement.clone());
    let new_alignment = adjusted_alignment_table(ctx.flown_alignment, &ffcal.adjustment)?;

    // 5. IRUCAL: re-derive observations with the calibrated alignments so that end attitudes
    // use the best alignments. The first pass's frames are not needed any more: free them
    // before the second pass (six months of 30-s frames are ~0.5 GB each).
    drop(frames);
    crate::progress::step("identifying stars again with the calibrated alignments");
    let frames_cal = ctx.identify(&new_alignment);
    let gyro = gyro_stage(&ctx, &frames_cal, &ffcal, &obc_bias_at, &mut summary)?;

    // 6. The filter table.
    crate::progress::step("filter table: validation of the proposed change");
    let filter = filter_stage(
        options,
        metadata,
        &frames_cal,
        &setup,
        (gyro.iru.report.as_ref(), gyro.iru.skipped.as_deref()),
        (tm, &ctx.flown_iru),
    )?;

    // 7. The TAM and the report.
    let report = CalibrationReport {
        telemetry: tm.report.clone(),
        data: summary,
        alignments: ffcal.alignments,
        alignments_adjusted: ffcal.alignments_adjusted,
        adjustment_theta_acs_arcsec: ffcal.adjustment.theta_adjust_acs_arcsec.into(),
        residual_rms_arcsec: ffcal.residual,
        ffcal: ffcal.summary,
        iru: gyro.iru.report,
        iru_skipped: gyro.iru.skipped,
        maneuvers: gyro.maneuvers,
        bias_history: gyro.bias_history,
        tables: std::collections::BTreeMap::new(),
        filter_changes: filter.changes,
        alignment_validation,
        filter_validation: filter.aberration_validation,
        filter_tuning: filter.terms,
        fhst_floor: None,
        tam: super::tam::tam_stage(tm, &frames_cal, &obc_bias_at),
        wheels: {
            let (table, source) = flown_magnetics_or_boot(options);
            super::wheels::summarize(tm, &table, &source)
        },
    };
    Ok(CalibrationOutput {
        report,
        alignment: new_alignment,
        iru: gyro.iru.table,
        filter: filter.table,
        frames: frames_cal,
        ffcal: ffcal.solution,
        irucal: gyro.iru.solution,
        gyro_chain: gyro.chain,
    })
}

impl DataSummary {
    /// The frames split at, and dropped for, a rate-mode switch.
    fn count_rate_switches(&mut self, frames: &[FrameObservations]) {
        let count = |kind: RateSwitch| frames.iter().filter(|f| f.rate_switch == kind).count();
        self.rate_switch_frames_split = count(RateSwitch::Split);
        self.rate_switch_frames_dropped = count(RateSwitch::Dropped);
    }

    /// Frame, star and Sun counts of the frames (the rest is filled in by the stages).
    fn of_frames(frames: &[FrameObservations]) -> Self {
        let mut summary = DataSummary {
            frames: frames.len(),
            ..DataSummary::default()
        };
        for f in frames {
            for (i, s) in f.stars.iter().enumerate() {
                if let Some(s) = s {
                    if s.identified.is_some() {
                        summary.stars_identified[i] += 1;
                    } else {
                        summary.stars_unidentified[i] += 1;
                    }
                }
            }
            for (i, s) in f.suns.iter().enumerate() {
                if s.is_some() {
                    summary.sun_samples[i] += 1;
                }
            }
        }
        summary
    }
}

/// The sensors FFCAL can calibrate: those seen together with another one (an FSS the Sun
/// never visited is left out, keeps its flown alignment and is reported as not observed).
/// Returns the table index → sensor index map and the observed table indices.
///
/// # Errors
/// A FHST never observed with another sensor.
fn observed_sensors(
    frames: &[FrameObservations],
    fss_systematic_arcsec: f64,
    summary: &mut DataSummary,
) -> anyhow::Result<([Option<usize>; 4], Vec<usize>)> {
    let all: [Option<usize>; 4] = [Some(0), Some(1), Some(2), Some(3)];
    let mut seen = [0usize; 4];
    for epoch in alignment_data(frames, &all, [fss_systematic_arcsec; 2]).epochs() {
        for o in epoch {
            seen[o.sensor] += 1;
        }
    }
    if seen[0] == 0 || seen[1] == 0 {
        bail!(
            "FFCAL needs both FHSTs observing with another sensor at the same time; epochs per sensor FHST1/FHST2/FSS1/FSS2: {seen:?} (stars identified per FHST: {:?})",
            summary.stars_identified
        );
    }
    let mut map = [None; 4];
    let mut observed = Vec::new();
    for k in 0..4 {
        if seen[k] > 0 {
            map[k] = Some(observed.len());
            observed.push(k);
        }
    }
    summary.not_observed = (0..4)
        .filter(|k| seen[*k] == 0)
        .map(|k| SENSOR_NAMES[k].to_string())
        .collect();
    Ok((map, observed))
}

/// Alignment report per observed sensor: as calibrated, as adjusted (uplinked), and the
/// residual RMS before and after.
fn alignment_reports(
    solution: &FfcalSolution,
    observed: &[usize],
    flown: &[Matrix3<f64>],
    adjusted: &[Matrix3<f64>],
) -> (
    std::collections::BTreeMap<String, AlignmentReport>,
    std::collections::BTreeMap<String, AlignmentReport>,
    BeforeAfter,
) {
    let mut alignments = std::collections::BTreeMap::new();
    let mut alignments_adjusted = std::collections::BTreeMap::new();
    let mut residual = BeforeAfter::default();
    for (j, s) in solution.sensors.iter().enumerate() {
        let i = observed[j];
        let sigma = [
            s.sigma_acs_arcsec.x,
            s.sigma_acs_arcsec.y,
            s.sigma_acs_arcsec.z,
        ];
        alignments.insert(
            s.id.clone(),
            AlignmentReport {
                m_acs_from_sensor: rows(&s.m_acs_from_sensor_calibrated),
                sigma_arcsec: sigma,
                theta_acs_arcsec: s.theta_acs_arcsec.into(),
            },
        );
        let adj = adjusted[i];
        let theta = rotvec_from_rot(&(adj * flown[i].transpose())) * ARCSEC_PER_RAD;
        alignments_adjusted.insert(
            s.id.clone(),
            AlignmentReport {
                m_acs_from_sensor: rows(&adj),
                sigma_arcsec: sigma,
                theta_acs_arcsec: theta.into(),
            },
        );
        residual
            .before
            .insert(s.id.clone(), s.residual_rms_before_arcsec);
        residual
            .after
            .insert(s.id.clone(), s.residual_rms_after_arcsec);
    }
    (alignments, alignments_adjusted, residual)
}

/// One report per maneuver: span, angle, whether the calibration filter used it (and why
/// not), and its coarse attitude.
fn maneuver_reports(
    frames: &[FrameObservations],
    maneuvers: &[(usize, usize)],
    gyro_chain: &super::gyro_chain::GyroChain,
    obc_bias_at: &dyn Fn(f64) -> Vector3<f64>,
    t0: f64,
) -> Vec<ManeuverReport> {
    maneuvers
        .iter()
        .enumerate()
        .map(|(k, &(s, e))| {
            let t_end = frames[e].time.seconds();
            let angle: f64 = frames[s..=e]
                .iter()
                .filter_map(|f| f.gyro)
                .map(|g| g.dtheta_acs_rad)
                .sum::<Vector3<f64>>()
                .norm();
            let why_not_used = gyro_chain.why_not_used(frames, k, s, e);
            ManeuverReport {
                start_s: frames[s].time.seconds() - t0,
                end_s: t_end - t0,
                angle_deg: angle.to_degrees(),
                used: why_not_used.is_none(),
                why_not_used,
                coarse_attitude: coarse_attitude(frames, s, e, &obc_bias_at(t_end), t0),
            }
        })
        .collect()
}

/// The smoothed bias at every fix, beside the OBC's estimate at that time.
fn bias_history(
    sol: &crate::calibration::iru_chain::ChainSolution,
    tm: &Telemetry,
    t0: f64,
) -> Vec<BiasHistoryPoint> {
    sol.bias
        .iter()
        .map(|b| BiasHistoryPoint {
            t_s: b.t_s,
            bias_rad_per_s: b.bias_rad_per_s,
            sigma_rad_per_s: b.sigma_rad_per_s,
            triad: b.triad,
            obc_bias_rad_per_s: obc_bias_sample(tm, t0 + b.t_s),
        })
        .collect()
}

impl FfcalSummary {
    /// The FFCAL part of the report from the fit and its inputs.
    #[allow(clippy::too_many_arguments)]
    fn new(
        solution: &FfcalSolution,
        observed: &[usize],
        sensors: &[SensorSpec],
        (data, fhst_data): (&AlignmentData, &AlignmentData),
        fhst_stage: Option<FhstStage>,
        batch_rel: &Result<FhstRelativeAlignment, RelativeAlignmentError>,
        fss_systematic: Option<[FssSystematicEstimate; 2]>,
        consider_declared: bool,
    ) -> Self {
        let rel = solution.relative_covariance_arcsec2(1, 0);
        FfcalSummary {
            weighting: solution.weighting,
            iterations: solution.iterations,
            epochs: solution.epochs,
            eigenvalues: solution
                .observability
                .eigenvalues_with_prior_per_arcsec2
                .clone(),
            sigma_fhst2_rel_fhst1_arcsec: [
                rel[(0, 0)].sqrt(),
                rel[(1, 1)].sqrt(),
                rel[(2, 2)].sqrt(),
            ],
            relative_covariance_to_fhst1_arcsec2: match observed.iter().position(|&k| k == 0) {
                Some(j1) => observed
                    .iter()
                    .enumerate()
                    .filter(|&(j, _)| j != j1)
                    .map(|(j, &k)| {
                        (
                            SENSOR_NAMES[k].to_string(),
                            rows(&solution.relative_covariance_arcsec2(j, j1)),
                        )
                    })
                    .collect(),
                None => std::collections::BTreeMap::new(),
            },
            crb_sigma_fhst2_rel_fhst1_all_sensors_arcsec: crb_relative_sigma(
                sensors, data, solution,
            ),
            crb_sigma_fhst2_rel_fhst1_fhst_only_arcsec: crb_relative_sigma(
                sensors.get(..2).unwrap_or(sensors),
                fhst_data,
                solution,
            ),
            fhst_stage,
            gyro_batches: batch_rel.as_ref().ok().map(|h| {
                let sd = |c: &Matrix3<f64>| [0, 1, 2].map(|i| c[(i, i)].max(0.0).sqrt());
                BatchAlignmentSummary {
                    theta_fhst2_rel_fhst1_arcsec: h.theta_acs_arcsec.into(),
                    sigma_arcsec: sd(&h.covariance_arcsec2),
                    crb_sigma_arcsec: sd(&h.crb_covariance_arcsec2),
                    aberration_consider_sigma_arcsec: sd(&h.aberration_consider_arcsec2),
                    gyro_scale_sigma_arcsec: sd(&h.gyro_scale_arcsec2),
                    variance_factor: h.variance_factor,
                    batches: h.batches,
                    samples: h.samples,
                    rejected: h.rejected,
                    residual_rms_arcsec: h.residual_rms_arcsec,
                }
            }),
            fss_systematic,
            fss_covariance: if consider_declared && fhst_stage.is_some() {
                "consider"
            } else {
                "cells"
            },
        }
    }
}

impl FixFloors {
    /// The floors from FFCAL's result and the declared FSS error.
    fn from_ffcal(ffcal: &FfcalSummary, solution: &FfcalSolution, metadata: &Metadata) -> Self {
        // A FHST-only fix may follow either tracker's frame: a quarter of the FHST1–FHST2
        // relative alignment covariance (FFCAL, arcsec²) is added to it.
        // A fix that needed the Sun carries the FSS's own error and its calibrated alignment's
        // uncertainty (FFCAL, relative to FHST1): the larger FSS's largest axis σ.
        let fss_alignment_sigma = ["FSS1", "FSS2"]
            .iter()
            .filter_map(|n| ffcal.relative_covariance_to_fhst1_arcsec2.get(*n))
            .flat_map(|c| [c[0][0], c[1][1], c[2][2]])
            .fold(0.0_f64, f64::max)
            .sqrt();
        FixFloors {
            fhst_cov_rad2: solution.relative_covariance_arcsec2(1, 0)
                * (0.25 / ARCSEC_PER_RAD.powi(2)),
            fss_arcsec: metadata
                .sensors
                .fss_systematic_or_paper_arcsec()
                .hypot(fss_alignment_sigma),
        }
    }
}

/// The filter table to write, the changes with why, their validation, and the decisions on
/// the noise terms: the aberration switch [`filter_update`] makes is written only if the
/// telemetry shows it is needed (`alignment_heldout::validate_aberration_switch`); the slew
/// uncertainty only through the IRU table's held-out validation (`super::filter_tuning`).
///
/// # Errors
/// The new table fails the OBC's validation.
fn filter_stage(
    options: &CalibrateOptions,
    metadata: &Metadata,
    frames: &[FrameObservations],
    setup: &AlignmentSetup<'_>,
    (iru, iru_skipped): (Option<&IruReport>, Option<&str>),
    gyro_data: (&Telemetry, &IruTable),
) -> anyhow::Result<FilterStage> {
    let flown = options
        .flown_filter
        .unwrap_or_else(FilterTable::default_boot);
    let (new_filter, mut filter_changes) = filter_update(&flown, metadata)?;
    let filter_validation = new_filter
        .as_ref()
        .map(|_| validate_aberration_switch(frames, setup));
    let mut new_filter = match &filter_validation {
        Some(v) if !v.passed => {
            filter_changes.push(format!("not written: {}", v.reason));
            None
        }
        _ => new_filter,
    };
    let slew = super::filter_tuning::slew_uncertainty(
        flown.gyro_scale_uncertainty,
        iru.map(IruReport::tuning_evidence).as_ref(),
        iru_skipped,
    );
    let [arw, rrw] = super::filter_tuning::noise_terms(&flown, gyro_data.0, gyro_data.1);
    let [bright, faint] = super::filter_tuning::fhst_noise_terms(&flown, frames);
    let mut terms = vec![slew, arw, rrw, bright, faint];
    for term in terms.iter_mut().filter(|t| t.written) {
        let mut table = new_filter.unwrap_or(flown);
        if !term.apply(&mut table) {
            continue;
        }
        if let Err(e) = table.validate() {
            term.written = false;
            term.reason = format!(
                "not written: the table would not validate ({e:?}); {}",
                term.reason
            );
            continue;
        }
        filter_changes.push(format!("{}: {}", term.field.field(), term.reason));
        new_filter = Some(table);
    }
    Ok(FilterStage {
        table: new_filter,
        changes: filter_changes,
        aberration_validation: filter_validation,
        terms,
    })
}

/// What [`filter_stage`] decides.
struct FilterStage {
    /// The new filter table, when one is written.
    table: Option<FilterTable>,
    /// The changes written (or refused), with why.
    changes: Vec<String>,
    /// The aberration switch's validation, when proposed.
    aberration_validation: Option<AberrationSwitchValidation>,
    /// The decisions on the noise terms (`super::filter_tuning`), written or not.
    terms: Vec<super::filter_tuning::TermDecision>,
}

/// The filter table the OBC should fly, when it differs from the flown one, and why.
///
/// Why: the ground corrects every effect the operator's model declares; an effect the OBC
/// could correct but the flown table leaves off stays in the onboard attitude. Annual
/// aberration (≈ 20″, `aberration` declared, the GRO default) is the one such setting: with
/// it off, the OBC's attitude after calibration carries it as a bias its covariance does not
/// know (`docs/investigations.md`, "The OBC filter's NEES after calibration").
///
/// # Errors
/// The new table fails the OBC's own validation (cannot happen for a valid flown table).
pub fn filter_update(
    flown: &FilterTable,
    metadata: &Metadata,
) -> anyhow::Result<(Option<FilterTable>, Vec<String>)> {
    let mut new = *flown;
    let mut changes = Vec::new();
    if metadata.declares("aberration") && !flown.aberration_correction {
        new.aberration_correction = true;
        changes.push(
            "aberration_correction: false -> true (annual aberration is declared: the ground corrects it, the flown OBC table did not)"
                .to_owned(),
        );
    }
    if changes.is_empty() {
        return Ok((None, changes));
    }
    new.validate()
        .map_err(|e| anyhow::anyhow!("the new filter table does not validate ({e:?})"))?;
    Ok((Some(new), changes))
}

/// The FHST floor for the alignments that fly ([`super::filter_floor`]), recorded in the
/// report with a note saying why it is not written (the module's docs).
/// Why here and not in [`filter_stage`]: the floor depends on which alignment table flies,
/// which the held-out validation decides after the chain.
fn floor_stage(
    out: &mut CalibrationOutput,
    alignment_to_fly: &AlignmentTable,
    flown: &FilterTable,
) {
    use super::filter_floor::{fhst_floor, relative_alignment_change_arcsec, FloorInputs};
    let base = out.filter.unwrap_or(*flown);
    let floor = fhst_floor(&FloorInputs {
        filter: &base,
        alignment: alignment_to_fly,
        relative_covariance_arcsec2: out
            .report
            .ffcal
            .relative_covariance_to_fhst1_arcsec2
            .get("FHST2"),
        relative_error_arcsec: relative_alignment_change_arcsec(alignment_to_fly, &out.alignment),
    });
    let mut floor = floor;
    floor.flown_arcsec = base.fhst_uncorrected_systematic_arcsec;
    if floor.floor_arcsec > floor.flown_arcsec + 0.1 {
        floor.note = Some(format!(
            "not written: the OBC carries {:.2}″ per focal-plane axis, the ground derives {:.2}″ (orbital aberration ⊕ the FHST1-FHST2 relative alignment σ); written, it made the onboard NEES pessimistic on the main job (0.65-1.08 over seeds 1-5: FFCAL's σ overstates the realised relative error), so the flown value stays (docs/obc_filter.md §10)",
            floor.flown_arcsec, floor.floor_arcsec
        ));
    }
    out.report.fhst_floor = Some(floor);
}

/// The alignment table `calibrate` writes: the new one if it passed the held-out validation,
/// with every sensor the validation could not test flying as before ([`keep_flown`]); else
/// the flown one again.
#[must_use]
pub fn alignment_to_fly(
    new: AlignmentTable,
    flown: AlignmentTable,
    validation: &AlignmentValidation,
) -> AlignmentTable {
    match keep_flown(new, &flown, &validation.not_validated) {
        Some(table) if validation.passed => table,
        _ => flown,
    }
}

/// `new` with each sensor named in `sensors` (`SENSOR_NAMES`) flying as before relative to the
/// trackers: its flown alignment turned by the rotation the reference tracker's alignment
/// underwent (FHST1, or FHST2 when FHST1 is itself not validated), so that its alignment
/// relative to the reference is the flown one. Why: a sensor whose new alignment the held-out
/// validation could not test must not move relative to the sensors that fix the attitude;
/// keeping its flown matrix in the ACS frame while the trackers move would move it.
/// `None` when neither tracker was validated.
#[must_use]
pub fn keep_flown(
    new: AlignmentTable,
    flown: &AlignmentTable,
    sensors: &[String],
) -> Option<AlignmentTable> {
    if sensors.is_empty() {
        return Some(new);
    }
    let names = SENSOR_NAMES;
    let reference = ["FHST1", "FHST2"]
        .into_iter()
        .find(|r| !sensors.iter().any(|s| s == r))?;
    let k_ref = names.iter().position(|n| *n == reference)?;
    let m =
        |t: &AlignmentTable, k: usize| fsw_core::tables::types::matrix_from_rows(t.matrices()[k]);
    // R · M_ref_flown = M_ref_new.
    let r = m(&new, k_ref) * m(flown, k_ref).transpose();
    let mut out = new;
    for name in sensors {
        let Some(k) = names.iter().position(|n| n == name) else {
            continue;
        };
        *out.matrices_mut()[k] = fsw_core::tables::types::rows_from_matrix(&(r * m(flown, k)));
    }
    Some(out)
}

/// Write a table image to `path`.
///
/// # Errors
/// Encoding or I/O failure.
pub fn write_table<T: serde::Serialize>(
    path: &Path,
    id: TableId,
    table: &T,
    created_tai1958_s: f64,
) -> anyhow::Result<()> {
    let created = fsw_core::raw::TimeTag::from_seconds(created_tai1958_s).unwrap_or_default();
    let mut buf = vec![0u8; 256 * 1024];
    let n = encode_image(id, created, table, &mut buf)
        .map_err(|e| anyhow::anyhow!("encoding the {} table: {e}", id.name()))?;
    std::fs::write(path, &buf[..n]).with_context(|| format!("writing {}", path.display()))
}

/// A run folder's telemetry (decoded, damage reported) and declared metadata.
///
/// # Errors
/// No `telemetry.bin` (the message says how to make one), unreadable files, bad metadata.
pub fn read_run(run_dir: &Path) -> anyhow::Result<(Telemetry, Metadata)> {
    let telemetry_path = run_dir.join("telemetry.bin");
    if !telemetry_path.exists() {
        return Err(crate::run_check::InputError::msg(format!(
            "{} not found: a run folder needs telemetry.bin (docs/icd.md); run `sim-harness run SCENARIO --out {}` first",
            telemetry_path.display(),
            run_dir.display()
        ))
        .into());
    }
    let tm = tp::read_file(&telemetry_path).map_err(|e| crate::run_check::InputError(e.into()))?;
    let metadata = read_metadata(run_dir)?;
    crate::run_check::validate_metadata(&run_dir.join("metadata.json"), &metadata)?;
    Ok((tm, metadata))
}

/// A table from its binary image file (header, CRC and canonical payload checked).
///
/// # Errors
/// Unreadable file, or an image that does not parse or decode (the message names the file).
pub fn read_table_image<T: serde::de::DeserializeOwned + serde::Serialize>(
    path: &Path,
) -> anyhow::Result<T> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    decode_table_image(&bytes, path)
}

/// A table from the octets of its image file `path` (header, CRC and canonical payload
/// checked).
///
/// # Errors
/// An image that does not parse or decode: a sentence naming the file and the cause.
pub fn decode_table_image<T: serde::de::DeserializeOwned + serde::Serialize>(
    bytes: &[u8],
    path: &Path,
) -> anyhow::Result<T> {
    use fsw_core::tables::image::{decode_payload, parse_image};
    let (_, payload) = parse_image(bytes)
        .map_err(|e| anyhow::anyhow!("{} is not a valid table image: {e}", path.display()))?;
    decode_payload(payload)
        .map_err(|e| anyhow::anyhow!("{} is not a valid table image: {e}", path.display()))
}

/// `ground-tool calibrate RUN_DIR --out DIR`: run the chain and write tables and reports.
///
/// # Errors
/// Unreadable inputs, too little data, I/O.
pub fn calibrate_run(
    run_dir: &Path,
    out_dir: &Path,
    options: &CalibrateOptions,
) -> anyhow::Result<CalibrationOutput> {
    crate::progress::step("reading the telemetry");
    let (tm, metadata) = read_run(run_dir)?;
    // The chain's refusals are about the data (too few frames, stars or Sun samples): exit 2.
    let mut out = calibrate_telemetry(&tm, &metadata, options).map_err(|e| {
        crate::run_check::InputError(e.context(format!(
            "{}: the telemetry does not support a calibration",
            run_dir.display()
        )))
    })?;
    let tables_dir = out_dir.join("tables");
    std::fs::create_dir_all(&tables_dir)
        .with_context(|| format!("creating {}", tables_dir.display()))?;
    let created = tm.raw.last().map_or(0.0, |r| r.time.seconds());
    // Names relative to OUT: the folder may be written under a temporary name and renamed.
    let alignment_path: PathBuf = tables_dir.join("alignment.tbl");
    // Only a table that passed the held-out validation is uplinked; else the flown one again
    // (so that OUT/tables stays the complete set to fly), and the report says why.
    // A sensor the held-out blocks never tested keeps its flown alignment.
    let flown_alignment = options
        .flown_alignment
        .unwrap_or_else(AlignmentTable::prelaunch);
    let alignment_to_fly = alignment_to_fly(
        out.alignment,
        flown_alignment,
        &out.report.alignment_validation,
    );
    write_table(
        &alignment_path,
        TableId::Alignment,
        &alignment_to_fly,
        created,
    )?;
    floor_stage(
        &mut out,
        &alignment_to_fly,
        &options
            .flown_filter
            .unwrap_or_else(FilterTable::default_boot),
    );
    out.report
        .tables
        .insert("alignment".into(), "tables/alignment.tbl".into());
    let iru_path = tables_dir.join("iru.tbl");
    write_table(&iru_path, TableId::Iru, &out.iru, created)?;
    out.report
        .tables
        .insert("iru".into(), "tables/iru.tbl".into());
    let mut files = vec!["alignment.tbl".to_owned(), "iru.tbl".to_owned()];
    if let Some(filter) = &out.filter {
        let filter_path = tables_dir.join("filter.tbl");
        write_table(&filter_path, TableId::Filter, filter, created)?;
        out.report
            .tables
            .insert("filter".into(), "tables/filter.tbl".into());
        files.push("filter.tbl".to_owned());
    }
    magnetics_stage(
        &mut out,
        &tm,
        options.flown_magnetics.clone(),
        &tables_dir,
        created,
        &mut files,
    )?;
    // The tables to fly, named (gro_reference::manifest): exactly those the report lists.
    gro_reference::manifest::write(&tables_dir, &files, "ground-tool calibrate")?;
    Ok(out)
}

/// Table 6 from the TAM calibration, through its held-out check (`super::magnetics_table`);
/// the decision goes into `report.json` `tam.table`.
fn magnetics_stage(
    out: &mut CalibrationOutput,
    tm: &Telemetry,
    flown: Result<Option<fsw_core::tables::MagneticsTable>, String>,
    tables_dir: &Path,
    created: f64,
    files: &mut Vec<String>,
) -> anyhow::Result<()> {
    use super::magnetics_table::magnetics_table;
    let Some(first) = tm.raw.first() else {
        return Ok(());
    };
    let fss = fss_sigma_after_arcsec(
        &out.report.alignment_validation,
        &out.report.ffcal.relative_covariance_to_fhst1_arcsec2,
        &out.report.residual_rms_arcsec.after,
    );
    let (flown, unknown) = match flown {
        Ok(t) => (t, None),
        Err(why) => (None, Some(why)),
    };
    let (table, mut decision) = magnetics_table(&out.report.tam, first.time, fss, flown.as_ref());
    if let Some(why) = unknown {
        decision.reason = format!(
            "{}; the flown magnetics table is unknown ({why}): built from the boot table",
            decision.reason
        );
    }
    out.report.tam.table = Some(decision);
    if let Some(t) = table {
        write_table(
            &tables_dir.join("magnetics.tbl"),
            TableId::Magnetics,
            &t,
            created,
        )?;
        out.report
            .tables
            .insert("magnetics".into(), "tables/magnetics.tbl".into());
        files.push("magnetics.tbl".to_owned());
    }
    Ok(())
}

/// The per-axis σ of an FSS Sun direction through the alignments that fly, when the
/// alignment table passed its held-out validation with both FSSs tested (`None` otherwise):
/// per FSS, the largest per-axis σ of its alignment relative to FHST1 (FFCAL's covariance,
/// in the frame the fine attitude defines) with its FFCAL residual RMS after calibration (the
/// transfer function and noise at one Sun position) added in quadrature; the larger of the
/// two FSSs. The held-out RMS used before carries each fold's extrapolation of the alignment
/// to Sun positions it did not see, and overstated the error 2–4× (docs/magnetics.md §5).
#[must_use]
fn fss_sigma_after_arcsec(
    validation: &AlignmentValidation,
    relative_covariance_arcsec2: &std::collections::BTreeMap<String, [[f64; 3]; 3]>,
    residual_rms_after_arcsec: &std::collections::BTreeMap<String, f64>,
) -> Option<f64> {
    if !validation.passed {
        return None;
    }
    let mut worst = None::<f64>;
    for name in ["FSS1", "FSS2"] {
        if validation.not_validated.iter().any(|n| n == name) {
            return None;
        }
        let cov = relative_covariance_arcsec2.get(name)?;
        let alignment_var = (0..3).map(|i| cov[i][i]).fold(0.0_f64, f64::max);
        let residual = *residual_rms_after_arcsec.get(name)?;
        let sigma = (alignment_var + residual * residual).sqrt();
        if !sigma.is_finite() {
            return None;
        }
        worst = Some(worst.map_or(sigma, |w| w.max(sigma)));
    }
    worst
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;

    /// Stage 1 refuses telemetry without the hours of frames a calibration needs, naming the
    /// count, before it loads the catalog.
    #[test]
    fn the_context_refuses_too_few_raw_frames() {
        let tm = Telemetry::default();
        let err = ChainContext::new(&tm, &Metadata::default(), &CalibrateOptions::default())
            .err()
            .expect("no frames");
        assert!(
            err.to_string().contains("only 0 raw sensor frames"),
            "{err}"
        );
    }

    /// Stage 4's table: an adjustment that moves nothing gives the flown alignments back
    /// (orthonormalised to rounding) and keeps the table valid.
    #[test]
    fn an_identity_adjustment_gives_the_flown_table() {
        let flown = AlignmentTable::prelaunch();
        let adjustment = Adjustment {
            construction: BoresightFrame::Bisector,
            m_adjust: Matrix3::identity(),
            theta_adjust_acs_arcsec: Vector3::zeros(),
            m_acs_from_sensor_adjusted: flown.matrices().map(matrix_from_rows).to_vec(),
        };
        let table = adjusted_alignment_table(flown, &adjustment).unwrap();
        for (a, b) in table.matrices().iter().zip(flown.matrices()) {
            let d = (matrix_from_rows(a) - matrix_from_rows(b)).amax();
            assert!(d < 1e-6, "moved by {d}");
        }
    }
}
