//! # The executive: one fixed-period cycle of the OBC attitude software
//!
//! [`FlightCore::step`] takes one cycle of raw sensor words and ground commands and returns
//! the housekeeping record and the events of that cycle (their packet order is
//! `docs/icd.md` §4). The phase order is fixed (documented here) and every phase is bounded:
//!
//! 1. **Time**: check the frame time is after the previous one and within 10 periods
//!    (otherwise count, raise `TimeTagAnomaly`, and use the nominal period).
//! 2. **Commands** in the order given (at most [`MAX_COMMANDS_PER_CYCLE`]): table
//!    load/activate/abort (activation therefore always happens at a cycle boundary, before
//!    any table is used in the cycle; an activated orbit table restarts the onboard orbit),
//!    IRU configuration, filter init/reset, slew/hold, Sun acquisition.
//! 3. **Orbit** (only once an orbit table was activated): the onboard orbit propagated to the
//!    frame time ([`crate::orbit`], at most 9 RK4 steps). With the filter table's
//!    `orbital_aberration_correction` on, a valid orbit gives this cycle's star and Sun
//!    references the orbital aberration and the Sun parallax; an orbit that is not valid
//!    leaves them annual-only, said once by event 0x0801 (0x0802 when applied again).
//! 4. **IRU**: pulse integration (paper `G`; algorithms.md §5); a failed selected channel
//!    switches to the backup configuration automatically. Any configuration change
//!    (automatic or commanded) reopens the filter's bias covariance: the new channels have
//!    their own biases.
//! 5. **Propagation** of the MEKF with the exact rotation-vector update.
//! 6. **FHST1, FHST2** (not during slews or a Sun acquisition's turn: gyro-only propagation, as
//!    on GRO, but the trackers'
//!    new-star and lost flags are followed): counts → unit vector in ACS; star identification
//!    on a new acquisition in a window from the attitude covariance; sequential focal-plane
//!    update with χ² gating and the systematic floor (filter table
//!    `fhst_uncorrected_systematic_arcsec`).
//! 7. **FSS1, FSS2**: counts → Sun vector in ACS; onboard Sun ephemeris (seen from the
//!    spacecraft when the orbital correction applies); update in coarse mode only (fine mode
//!    is FHST-only, as on GRO); the α/β innovation is always reported.
//!
//!    Then phase 7b, the **coarse attitude** (every mode, alongside the fine filter;
//!    [`crate::coarse`]): carried on the gyro increments every cycle, fixed every
//!    `coarse_fix_every_n_cycles` from the Sun (FSS, else CSS) and the TAM field against the
//!    onboard field model at the onboard orbit (magnetics table, Table 6), after a magnitude
//!    check and a χ² gate; events 0x0901–0x0903.
//!
//!    Then phase 7c, **momentum unloading** ([`crate::unloading`], Table 6 fields 19–23):
//!    the previous cycle's wheel torque command is counted into the OBC's wheel momentum;
//!    on a frame taken with every torquer bar off, the cross-product law's dipole is
//!    recomputed from the TAM field (else the model's) and the bars-off check runs (event
//!    0x0A01); the dipole is held for the following cycles and the bars are commanded off
//!    for the cycle before each coarse fix (blanking: the fix's TAM sample sees no bar
//!    field); event 0x0A02 at the dead band's edges. The command is
//!    [`FlightCore::torquer_dipole_command_am2`].
//! 8. **Control**: inertial hold or rate-limited eigen-axis slew → wheel torque; IRU rate
//!    mode request (high for slews). In Sun acquisition ([`crate::sun_acquisition`]) the
//!    same law turns a commanded body axis to the Sun of the cycle's best Sun sensor (FSS1,
//!    FSS2, the CSS eyes) with the gyro rate alone, no attitude needed; events 0x0603–0x0605.
//! 9. **Housekeeping** (the onboard orbit is not in it: the 230-octet record of
//!    `docs/icd.md` §3.2 has no room without changing its length for outside decoders).
//!
//! Worst case per cycle: one star identification per tracker (a linear scan of at most
//! `MAX_CATALOG_STARS` stars, only on a new acquisition), four 2-component filter updates,
//! nine RK4 steps of the orbit, one coarse fix (a degree-10 field synthesis and a TRIAD) and
//! on the same cycle the unloading's bars-off check (a second degree-10 synthesis).

use crate::attitude::{rot, Quat};
use crate::coarse::{sun_candidates_acs, CoarseAttitude, CoarseUnavailable};
use crate::control::{ControlError, Controller};
use crate::events::{raise, Counters, Event, EventId, MAX_EVENTS_PER_CYCLE};
use crate::fhst;
use crate::fss;
use crate::iru::{IruConfiguration, IruIntegrator};
use crate::mekf::Mekf;
use crate::orbit::{OnboardOrbit, OrbitState, OrbitStatus, C_KM_PER_S};
use crate::raw::{
    FhstSample, RawSensorFrame, TimeTag, FHST_FLAG_NEW_STAR, FHST_FLAG_TRACKING, FHST_FLAG_VALID,
};
use crate::sensor::SensorId;
use crate::star_id::{self, StarIdError, StarMatch};
use crate::sun_acquisition::SunAcquisition;
use crate::sun_ephemeris;
use crate::tables::types::{matrix_from_rows, Mat3Rows, ORBITAL_ABERRATION_RMS_PER_AXIS_ARCSEC};
use crate::tables::{TableId, TableSet};
use crate::telemetry::{MeasurementStatus, ObcHousekeeping, SensorResidual};
use crate::units::{ARCSEC_PER_RAD, RAD_PER_ARCSEC};
use crate::unloading::{FieldSample, MomentumUnloading, TAM_PLAUSIBLE_MILLIGAUSS};
use nalgebra::{Matrix3, Vector3};

/// Largest number of commands processed in one cycle (further ones are refused).
/// Project choice (not in the paper): bounds the work of one cycle.
pub const MAX_COMMANDS_PER_CYCLE: usize = 8;

/// Cycles without an accepted FHST measurement after which fine mode drops to coarse.
const FINE_MODE_TIMEOUT_CYCLES: u32 = 900;

/// Largest age of the cached onboard Sun direction, s.
const SUN_REFRESH_S: f64 = 10.0;

/// A frame more than this many nominal periods after the previous one is a time-tag jump.
const MAX_GAP_PERIODS: f64 = 10.0;

/// White (sample-to-sample independent) FSS error per axis, rad: the 0.5-count electronic
/// noise and the 0.004° quantization, `0.004° · √(0.5² + 1/12)` = 8.3″. The table's
/// `fss_sigma_arcsec` is then the systematic part (alignment residual and transfer-function
/// error at one Sun position), which does not average down: it is the floor of
/// [`Mekf::update_vector_with_floor`]. Paper: resolution 0.004°, noise half a count.
/// docs/obc_filter.md §3.
pub const FSS_WHITE_SIGMA_RAD: f64 = 0.004 * 0.577_350_269_189_625_8 * crate::units::RAD_PER_DEG;

/// Systematic FHST error per axis the OBC models but does not correct without the orbital
/// correction, rad: the orbital velocity aberration. `β = 7.5 km/s / c` = 5.16″ displaces a
/// star by the part of `β` perpendicular to it; along a focal-plane axis `e` that is `β·e`,
/// and with `β` turning once per orbit in the orbit plane (normal `n`),
/// `E[(β·e)²] = β² (1 − (e·n)²)/2 ≤ β²/2`: at most `β/√2` = 3.65″ RMS on any axis, whatever
/// the tracker's geometry. It changes over an orbit, slower than the filter, so it does not
/// average down within a star track: the σ of the FHSTs' consider states in
/// [`Mekf::update_focal_plane_consider`] (Gauss–Markov over a quarter orbit).
/// The boot value of the filter table's `fhst_uncorrected_systematic_arcsec`, which the OBC
/// uses (docs/tables.md field 22). algorithms.md §3.3; docs/obc_filter.md §3.
pub const FHST_UNCORRECTED_SYSTEMATIC_RAD: f64 =
    ORBITAL_ABERRATION_RMS_PER_AXIS_ARCSEC * crate::units::RAD_PER_ARCSEC;

/// Milligauss per nanotesla (1 mG = 100 nT).
/// SI definition of the gauss.
const NT_TO_MILLIGAUSS: f64 = 0.01;

/// Filter mode, telemetry code in brackets.
/// Paper requirements: coarse attitude (FSS + TAM + IRU, 2° 3σ), fine (FHST + IRU, 0.024° 3σ).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum FilterMode {
    /// No attitude yet (0).
    /// docs/icd.md §3.2 (filter mode 0).
    Uninitialized = 0,
    /// Attitude from propagation and FSS only (1).
    /// Paper: coarse attitude from FSS + IRU (the TAM is not modelled; project choice).
    Coarse = 1,
    /// FHST stars identified and used (2).
    /// Paper: fine attitude from FHST + IRU, 0.024° 3σ per axis.
    Fine = 2,
}

/// Control mode, telemetry code in brackets.
/// docs/icd.md §3.2 (control mode, offset 105).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum ControlMode {
    /// No attitude, no control (0).
    /// docs/icd.md §3.2 (control mode 0).
    Idle = 0,
    /// Inertial hold (1).
    /// Paper: inertial pointing (low-rate IRU); docs/icd.md §3.2.
    Hold = 1,
    /// Slew to a target (2).
    /// Paper: maneuvers (high-rate IRU); docs/icd.md §3.2.
    Slew = 2,
    /// Sun acquisition: a body axis turned to the Sun from the Sun sensors and the gyros
    /// alone, then held on it (3).
    /// Project choice (not in the paper): [`crate::sun_acquisition`]; docs/icd.md §3.2.
    SunAcquisition = 3,
}

/// Event 0x0607 p1 when control mode 3 has no Sun-acquisition state (cannot be entered).
/// docs/icd.md §3.3.
const CONTROL_FAULT_NO_SUN_ACQUISITION: u32 = 4;

/// Event 0x0607 p1 for a control-law error: 1 invalid target, 2 invalid estimate (a
/// non-finite attitude, rate or torque), 3 unusable table values. docs/icd.md §3.3.
fn control_fault_code(e: ControlError) -> u32 {
    match e {
        ControlError::InvalidTarget => 1,
        ControlError::InvalidEstimate => 2,
        ControlError::InvalidTable => 3,
    }
}

/// A ground command for this cycle.
/// Project choice (not in the paper): the ground commands the emulation needs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Command<'a> {
    /// Slew to the target attitude `q_acs_from_eci`, then hold it.
    /// Paper: calibration maneuvers between inertial attitudes.
    SlewTo(Quat),
    /// Hold the current estimated attitude.
    /// Paper: inertial pointing.
    Hold,
    /// Select the IRU configuration.
    /// Paper: primary X2, Y1, Z1 or backup X1, Y2, Z2.
    SelectIruConfig(IruConfiguration),
    /// Load a table image into its inactive buffer.
    /// docs/tables.md ("Lifecycle", cFE Table Services style).
    TableLoad(&'a [u8]),
    /// Activate the validated inactive buffer of a table.
    /// docs/tables.md ("Lifecycle", cFE Table Services style).
    TableActivate(TableId),
    /// Clear the inactive buffer of a table.
    /// docs/tables.md ("Lifecycle", cFE Table Services style).
    TableAbort(TableId),
    /// Initialise the filter at this attitude with the table's initial covariance.
    /// algorithms.md §2 (reference state and initial `P`).
    FilterInitialize(Quat),
    /// Reset the filter: keep the estimate, reopen the covariance to its initial values.
    /// docs/icd.md §3.3 (event 0x0302).
    FilterReset,
    /// Turn this body axis (ACS, unit) to the Sun and hold it there, with no attitude needed.
    /// Project choice (not in the paper): [`crate::sun_acquisition`]; docs/icd.md §3.3.
    SunAcquire([f64; 3]),
}

impl Command<'_> {
    /// Command code used in `CommandRejected` events.
    /// docs/icd.md §3.3 (event 0x0701, p1).
    #[must_use]
    pub fn code(&self) -> u32 {
        match self {
            Self::SlewTo(_) => 1,
            Self::Hold => 2,
            Self::SelectIruConfig(_) => 3,
            Self::TableLoad(_) => 4,
            Self::TableActivate(_) => 5,
            Self::TableAbort(_) => 6,
            Self::FilterInitialize(_) => 7,
            Self::FilterReset => 8,
            Self::SunAcquire(_) => 9,
        }
    }
}

/// Everything a cycle produces (postcard-serializable: fixed field order, no maps).
/// docs/icd.md §3.2 and §3.3.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CycleOutput {
    /// The housekeeping record (downlinked every cycle).
    /// APID 0x011, docs/icd.md §3.2.
    pub housekeeping: ObcHousekeeping,
    /// Events raised in this cycle.
    /// APID 0x012, docs/icd.md §3.3.
    pub events: heapless::Vec<Event, MAX_EVENTS_PER_CYCLE>,
}

/// Identification state of one tracker.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct TrackerState {
    /// The star identified for the current track, if any.
    star: Option<StarMatch>,
    /// Identification was tried for this track and failed (do not retry until a new star).
    failed: bool,
    /// Samples of the identified star offered to the filter so far (saturating at
    /// [`TRACK_CONFIRM_SAMPLES`]).
    offered: u8,
    /// How many of those the χ² gate refused.
    gated: u8,
}

/// A tracker's corrections from the active alignment table (see
/// `FlightCore::fhst_corrections`).
struct FhstCorrections {
    /// The tracker's alignment rows at its temperature.
    rows: Mat3Rows,
    /// Focal-plane distortion coefficients.
    distortion: [f64; 3],
    /// Magnitude-dependent bias, rad/mag.
    magnitude_bias: [f64; 2],
    /// Time-tag offset, s.
    offset_s: f64,
}

/// A newly identified star is confirmed by its first this many samples.
/// Project choice (not in the paper): docs/obc_filter.md §4.
const TRACK_CONFIRM_SAMPLES: u8 = 5;

/// A newly identified star whose first [`TRACK_CONFIRM_SAMPLES`] samples include this many
/// gated ones is refused for the rest of its track (a displaced or misidentified star): a
/// right star is gated with probability 0.27 % per sample (χ²₂ at 11.83), so two in five
/// happen with probability 7e-5, while a star displaced by ~4σ passes the gate on one sample
/// in several and, with the honest covariance, those few pull the attitude (issue 19: 34″ at
/// a 0.03° offset). docs/obc_filter.md §4.
const TRACK_REFUSE_GATED: u8 = 2;

/// Event code (p2 of `StarIdFailed`) of a star refused after its first samples were gated.
const STAR_REFUSED_AFTER_GATING: u32 = 5;

/// The OBC attitude software state. No heap; `size_of::<FlightCore>()` is reported in
/// `docs/performance.md` (the star catalog table dominates it).
#[derive(Clone, Debug)]
pub struct FlightCore {
    tables: TableSet,
    iru: IruIntegrator,
    iru_config: IruConfiguration,
    filter: Mekf,
    filter_mode: FilterMode,
    controller: Controller,
    control_mode: ControlMode,
    /// The Sun acquisition while `control_mode` is `SunAcquisition`.
    sun_acquisition: Option<SunAcquisition>,
    /// The control step's failure, as event 0x0607's code (`None`: working).
    control_fault: Option<u32>,
    last_time: Option<TimeTag>,
    trackers: [TrackerState; 2],
    counters: Counters,
    cycles_since_star: u32,
    gated_run: [bool; 4],
    rejected_run: [bool; 5],
    iru_high_rate_cmd: bool,
    slew_count: u32,
    last_rate_acs_rad_per_s: Vector3<f64>,
    wheel_torque_cmd_nm: Vector3<f64>,
    sun_cache: Option<(f64, sun_ephemeris::SunState)>,
    slew_angle_rad: f64,
    /// Angle turned about each ACS axis since the slew began (`|Δθ_j|` summed), rad.
    slew_angle_acs_rad: Vector3<f64>,
    /// The onboard orbit (phase 3).
    orbit: OnboardOrbit,
    /// This cycle's orbit state when the orbital correction applies (flag on, orbit valid).
    orbital_fix: Option<OrbitState>,
    /// The last orbital-correction event raised (0x0801 with its status and reason, or
    /// 0x0802), so that each is raised once per run; `None` with the flag off.
    orbital_reported: Option<(EventId, u32, u32)>,
    /// The coarse attitude (phase 7b).
    coarse: CoarseAttitude,
    /// The last coarse-fix reason reported (0 = fixed), for events on change only.
    coarse_reported: Option<u32>,
    /// The last coarse vector rejection reported (0 none).
    coarse_rejection_reported: u8,
    /// Time since the last gyro data (a coast), s.
    coast_s: f64,
    /// Momentum unloading with the torquer bars (phase 7c).
    unloading: MomentumUnloading,
}

impl Default for FlightCore {
    fn default() -> Self {
        Self::new()
    }
}

/// Temperature (°C) of `sensor` in the raw frame (its slot in table order; the IRU's is the
/// fifth).
/// docs/icd.md §3.1 (offset 38, 0.01 °C).
fn frame_temperature_c(frame: &RawSensorFrame, sensor: SensorId) -> f64 {
    frame
        .temperatures_centi_c
        .get(sensor.index())
        .map_or(f64::NAN, |t| f64::from(*t) * 0.01)
}

fn to_u32(v: usize) -> u32 {
    u32::try_from(v).unwrap_or(u32::MAX)
}

impl FlightCore {
    /// Boot with the built-in tables (paper Table 1 alignments, prelaunch IRU G).
    #[must_use]
    pub fn new() -> Self {
        Self::with_tables(TableSet::boot())
    }

    /// Boot with a given table set.
    /// docs/tables.md (boot tables and validation).
    #[must_use]
    pub fn with_tables(tables: TableSet) -> Self {
        Self {
            tables,
            iru: IruIntegrator::new(),
            iru_config: IruConfiguration::Primary,
            filter: Mekf::new(),
            filter_mode: FilterMode::Uninitialized,
            controller: Controller::new(),
            sun_acquisition: None,
            control_fault: None,
            control_mode: ControlMode::Idle,
            last_time: None,
            trackers: [TrackerState::default(); 2],
            counters: Counters::default(),
            cycles_since_star: u32::MAX,
            gated_run: [false; 4],
            rejected_run: [false; 5],
            iru_high_rate_cmd: false,
            slew_count: 0,
            last_rate_acs_rad_per_s: Vector3::zeros(),
            wheel_torque_cmd_nm: Vector3::zeros(),
            sun_cache: None,
            slew_angle_rad: 0.0,
            slew_angle_acs_rad: Vector3::zeros(),
            orbit: OnboardOrbit::new(),
            orbital_fix: None,
            orbital_reported: None,
            coarse: CoarseAttitude::new(),
            // The boot magnetics table holds no field model: the coarse attitude is off by
            // design, not unavailable, and says nothing until a table makes it possible.
            coarse_reported: Some(CoarseUnavailable::NoFieldModel.code()),
            coarse_rejection_reported: 0,
            coast_s: 0.0,
            unloading: MomentumUnloading::new(),
        }
    }

    /// The tables (active copies and status).
    /// docs/tables.md ("Lifecycle").
    #[must_use]
    pub fn tables(&self) -> &TableSet {
        &self.tables
    }

    /// Current filter mode.
    /// docs/icd.md §3.2 (filter mode).
    #[must_use]
    pub fn filter_mode(&self) -> FilterMode {
        self.filter_mode
    }

    /// Current attitude estimate `q_acs_from_eci`.
    /// docs/icd.md §3.2 (offset 0); convention algorithms.md §1.
    #[must_use]
    pub fn attitude(&self) -> Quat {
        self.filter.q_acs_from_eci
    }

    /// The attitude filter (estimate and full covariance), read-only: for test harnesses
    /// that score consistency (NEES needs the off-diagonal `P_θθ`).
    /// Project choice (not in the paper): test access; NEES per algorithms.md §2.
    #[must_use]
    pub fn filter(&self) -> &Mekf {
        &self.filter
    }

    /// Run one cycle.
    /// Phase order of the module docs (docs/icd.md §4 packet order).
    pub fn step(&mut self, frame: &RawSensorFrame, commands: &[Command<'_>]) -> CycleOutput {
        let mut events = heapless::Vec::new();
        let mut residuals = [SensorResidual::default(); 4];
        self.counters.cycles = self.counters.cycles.saturating_add(1);

        // 1. Time.
        let dt_s = self.check_time(frame.time, &mut events);

        // 2. Commands.
        for (i, cmd) in commands.iter().enumerate() {
            if i >= MAX_COMMANDS_PER_CYCLE {
                raise(
                    &mut events,
                    &mut self.counters,
                    EventId::CommandRejected,
                    cmd.code(),
                    1,
                );
                continue;
            }
            self.execute(cmd, &mut events);
        }

        // 3. Orbit.
        self.advance_orbit(frame.time, &mut events);

        // 4–5. IRU and propagation.
        let increment = self.integrate_iru(frame, &mut events);
        let initialized = self.filter_mode != FilterMode::Uninitialized;
        // Without gyro data for a cycle, propagate with the last known body rate (a coast),
        // not with zero rate.
        let delta_theta = match increment {
            Some(d) => {
                self.coast_s = 0.0;
                d
            }
            None => (self.last_rate_acs_rad_per_s + self.filter.bias_rad_per_s) * dt_s,
        };
        if dt_s > 0.0 {
            self.last_rate_acs_rad_per_s = delta_theta / dt_s - self.filter.bias_rad_per_s;
        }
        let maneuvering = self.maneuvering();
        if initialized && maneuvering {
            self.inflate_for_gyro_calibration(&delta_theta);
        } else {
            self.slew_angle_rad = 0.0;
            self.slew_angle_acs_rad = Vector3::zeros();
        }
        if initialized
            && self
                .filter
                .propagate(&delta_theta, dt_s, self.tables.filter())
                .is_err()
        {
            // Out-of-range increment or step: the estimate is left untouched and counted.
            self.counters.iru_unusable_cycles = self.counters.iru_unusable_cycles.saturating_add(1);
        }
        if initialized && increment.is_none() && self.iru.is_initialized() {
            self.add_coast_noise(dt_s);
        }

        // 6–7. Measurements. During a slew the OBC propagates on the gyros alone, as GRO
        // did: the post-maneuver error then measures the gyro calibration, and star
        // identification after the slew is what the 0.5° requirement protects.
        if initialized && maneuvering {
            // No updates, but the trackers' track bookkeeping goes on: a star acquired
            // during the slew is a new star, not the one identified before it.
            self.follow_tracks(frame);
        }
        if initialized && !maneuvering {
            for tracker in 0..2usize {
                let r = self.process_fhst(frame, tracker, &mut events);
                if let Some(slot) = residuals.get_mut(tracker) {
                    *slot = r;
                }
            }
            for sensor in 0..2usize {
                let r = self.process_fss(frame, sensor, &mut events);
                if let Some(slot) = residuals.get_mut(sensor.saturating_add(2)) {
                    *slot = r;
                }
            }
        }
        self.update_filter_mode(&residuals, &mut events);

        // 7b. Coarse attitude (Sun, field, gyros), alongside the fine solution.
        self.coarse_attitude(frame, &delta_theta, dt_s, &mut events);

        // 7c. Momentum unloading (torquer bars), with the previous cycle's wheel command.
        self.momentum_unloading(frame, dt_s, &mut events);

        // 8. Control.
        self.control(frame, &mut events);

        // 9. Housekeeping.
        let housekeeping = self.housekeeping(frame.time, residuals);
        CycleOutput {
            housekeeping,
            events,
        }
    }

    /// Phase 7b: carry the coarse attitude on the gyros and, when due, fix it from the Sun and
    /// the field (`crate::coarse`, docs/magnetics.md §5). Events on a change of reason only.
    fn coarse_attitude(
        &mut self,
        frame: &RawSensorFrame,
        delta_theta_acs_rad: &Vector3<f64>,
        dt_s: f64,
        events: &mut heapless::Vec<Event, MAX_EVENTS_PER_CYCLE>,
    ) {
        let p_bb: Matrix3<f64> = self.filter.covariance.fixed_view::<3, 3>(3, 3).into_owned();
        self.coarse.propagate(
            delta_theta_acs_rad,
            &self.filter.bias_rad_per_s,
            &p_bb,
            self.tables.filter().arw_rad_per_sqrt_s,
            dt_s,
        );
        let table = self.tables.magnetics();
        if !self.coarse.fix_due(table) {
            return;
        }
        let orbit = match (self.tables.has_orbit(), self.orbit.state()) {
            (true, Ok(state)) if self.orbit.status() == OrbitStatus::Valid => {
                Some(state.pos_eci_km)
            }
            _ => None,
        };
        let t_s = frame.time.seconds_since_j2000_tt();
        let rejections_before = self.coarse.rejections;
        let result =
            self.coarse
                .try_fix(frame, self.tables.alignment(), table, orbit.as_ref(), t_s);
        // 0x0903 when the kind of rejection changes; an attempt without one re-arms it, so
        // that a sensor failing again later is reported again.
        if self.coarse.rejections == rejections_before {
            self.coarse_rejection_reported = 0;
        } else if self.coarse_rejection_reported != self.coarse.last_rejection {
            let rejection = self.coarse.last_rejection;
            self.coarse_rejection_reported = rejection;
            let total = self.coarse.rejections;
            let id = EventId::CoarseVectorRejected;
            raise(events, &mut self.counters, id, u32::from(rejection), total);
        }
        let reason = match result {
            Ok(()) => 0,
            Err(why) => why.code(),
        };
        if self.coarse_reported != Some(reason) {
            let previous = self.coarse_reported.unwrap_or(0);
            self.coarse_reported = Some(reason);
            if reason == 0 {
                let source = u32::from(self.coarse.source as u8);
                raise(
                    events,
                    &mut self.counters,
                    EventId::CoarseFixResumed,
                    source,
                    previous,
                );
            } else {
                let fixes = self.coarse.fixes;
                raise(
                    events,
                    &mut self.counters,
                    EventId::CoarseFixUnavailable,
                    reason,
                    fixes,
                );
            }
        }
    }

    /// Phase 7c: momentum unloading with the torquer bars (`crate::unloading`,
    /// docs/magnetics.md §7). Events 0x0A01 (bars-off check), 0x0A02 (dead band) and 0x0A03
    /// (wheel momentum source).
    fn momentum_unloading(
        &mut self,
        frame: &RawSensorFrame,
        dt_s: f64,
        events: &mut heapless::Vec<Event, MAX_EVENTS_PER_CYCLE>,
    ) {
        let changed = self.unloading.update_wheel_momentum(
            &frame.wheels,
            &self.wheel_torque_cmd_nm,
            dt_s,
            self.tables.magnetics(),
        );
        if let Some(source) = changed {
            let id = EventId::WheelMomentumSourceChanged;
            let p1 = source.code();
            let p2 = u32::from(frame.wheels.speed_valid);
            raise(events, &mut self.counters, id, p1, p2);
        }
        let table = self.tables.magnetics();
        if !table.unloading_enabled() || self.control_mode == ControlMode::Idle {
            self.unloading.switch_off();
            return;
        }
        // A blanked frame: its TAMs saw no bar field (every bar off over the interval).
        let sample = self
            .unloading
            .sample_due()
            .then(|| self.field_sample(frame));
        let [jx, jy, jz] = self.tables.filter().inertia_kg_m2;
        let w = self.last_rate_acs_rad_per_s;
        let h_system =
            Vector3::new(jx * w.x, jy * w.y, jz * w.z) + self.unloading.wheel_momentum_acs_nms();
        let table = self.tables.magnetics();
        let blank_next = self.coarse.fix_due_next_cycle(table);
        let report = self
            .unloading
            .update(sample.as_ref(), &h_system, table, blank_next);
        if let Some((mask, tenths_mg)) = report.unexpected_field {
            let id = EventId::TorquerFieldUnexpected;
            raise(events, &mut self.counters, id, mask, tenths_mg);
        }
        if let Some(on) = report.state_changed {
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let h = libm::round(self.unloading.last_momentum_nms()).clamp(0.0, 1.0e9) as u32;
            let id = EventId::UnloadingStateChanged;
            raise(events, &mut self.counters, id, u32::from(on), h);
        }
    }

    /// The field of this frame for the unloading: the TAMs (Table 6 calibration, plausible
    /// magnitude) and, with a field model, a valid onboard orbit and an initialised filter,
    /// the model field turned to ACS with the fine attitude (mG).
    fn field_sample(&self, frame: &RawSensorFrame) -> FieldSample {
        let table = self.tables.magnetics();
        let (lo, hi) = TAM_PLAUSIBLE_MILLIGAUSS;
        let mut out = FieldSample::default();
        for (unit, (slot, tam)) in out
            .tam_acs_milligauss
            .iter_mut()
            .zip(frame.tam.iter())
            .enumerate()
        {
            *slot = crate::coarse::tam_field_acs_milligauss(tam, unit, table)
                .filter(|b| (lo..=hi).contains(&b.norm()));
        }
        let orbit_valid = self.tables.has_orbit() && self.orbit.status() == OrbitStatus::Valid;
        if table.has_field_model() && orbit_valid && self.filter_mode != FilterMode::Uninitialized {
            if let Ok(state) = self.orbit.state() {
                // The coarse fix of this cycle (phase 7b) computed the same field unless it
                // stopped earlier (Earth's shadow, no Sun): synthesise it only then.
                let t_s = frame.time.seconds_since_j2000_tt();
                let b_eci_nt = self.coarse.reference_field_eci_nt(t_s).or_else(|| {
                    crate::field_model::field_eci_nt(table, &state.pos_eci_km, t_s).ok()
                });
                out.model_acs_milligauss =
                    b_eci_nt.map(|b| self.filter.q_acs_from_eci.to_dcm() * b * NT_TO_MILLIGAUSS);
                // The attitude block is the first three diagonal elements (rad²).
                let var_max = self
                    .filter
                    .covariance
                    .diagonal()
                    .iter()
                    .take(3)
                    .fold(0.0_f64, |m, v| m.max(*v));
                out.model_sigma_milligauss = out
                    .model_acs_milligauss
                    .map_or(0.0, |b| b.norm() * libm::sqrt(var_max));
            }
        }
        out
    }

    /// The torquer-bar dipole command for the coming interval, per bar on the ACS x, y, z
    /// axes, A·m² (zero while the bars are off). docs/magnetics.md §7.
    #[must_use]
    pub fn torquer_dipole_command_am2(&self) -> [f64; 3] {
        self.unloading.command_acs_am2()
    }

    /// The momentum unloading's state (docs/magnetics.md §7).
    #[must_use]
    pub fn unloading(&self) -> &MomentumUnloading {
        &self.unloading
    }

    /// The coarse attitude (Sun, field and gyros; docs/magnetics.md §5).
    #[must_use]
    pub fn coarse(&self) -> &CoarseAttitude {
        &self.coarse
    }

    fn check_time(
        &mut self,
        now: TimeTag,
        events: &mut heapless::Vec<Event, MAX_EVENTS_PER_CYCLE>,
    ) -> f64 {
        let period = self.tables.filter().cycle_period_s;
        let dt = match self.last_time {
            Some(prev) => {
                let dt = now.seconds() - prev.seconds();
                if dt > 0.0 && dt <= MAX_GAP_PERIODS * period {
                    dt
                } else {
                    self.counters.time_tag_anomalies =
                        self.counters.time_tag_anomalies.saturating_add(1);
                    raise(
                        events,
                        &mut self.counters,
                        EventId::TimeTagAnomaly,
                        prev.coarse_s,
                        now.coarse_s,
                    );
                    period
                }
            }
            None => period,
        };
        self.last_time = Some(now);
        dt
    }

    fn execute(
        &mut self,
        cmd: &Command<'_>,
        events: &mut heapless::Vec<Event, MAX_EVENTS_PER_CYCLE>,
    ) {
        let counters = &mut self.counters;
        match *cmd {
            Command::TableLoad(image) => match self.tables.load(image) {
                Ok(id) => raise(
                    events,
                    counters,
                    EventId::TableLoaded,
                    u32::from(id as u8),
                    0,
                ),
                Err((id, e)) => raise(
                    events,
                    counters,
                    EventId::TableRejected,
                    id.map_or(0, |i| u32::from(i as u8)),
                    u32::from(e.code()),
                ),
            },
            Command::TableActivate(id) => match self.tables.activate(id) {
                Ok(()) => {
                    let crc = self
                        .tables
                        .status()
                        .get(id.index())
                        .map_or(0, |s| s.active_crc);
                    raise(
                        events,
                        counters,
                        EventId::TableActivated,
                        u32::from(id as u8),
                        crc,
                    );
                    if id == TableId::StarCatalog || id == TableId::Alignment {
                        // Stars identified with the old catalog/alignment are re-identified.
                        self.trackers = [TrackerState::default(); 2];
                    }
                    if id == TableId::Orbit {
                        // A new state vector: the propagation restarts from its epoch.
                        self.orbit.load(self.tables.orbit());
                    }
                }
                Err(reason) => raise(
                    events,
                    counters,
                    EventId::TableActivateFailed,
                    u32::from(id as u8),
                    reason.map_or(0, |e| u32::from(e.code())),
                ),
            },
            Command::TableAbort(id) => {
                let pending = self.tables.abort(id);
                raise(
                    events,
                    counters,
                    EventId::TableAborted,
                    u32::from(id as u8),
                    u32::from(pending),
                );
            }
            Command::SelectIruConfig(config) => {
                if config != self.iru_config {
                    self.iru_config = config;
                    // Other channels, other biases: see `Mekf::reopen_bias_covariance`.
                    if self.filter_mode != FilterMode::Uninitialized
                        && self
                            .filter
                            .reopen_bias_covariance(self.tables.filter())
                            .is_err()
                    {
                        raise(events, counters, EventId::CommandRejected, cmd.code(), 2);
                    }
                    raise(
                        events,
                        counters,
                        EventId::IruConfigSwitched,
                        config.code(),
                        0,
                    );
                }
            }
            Command::FilterInitialize(q) => {
                let q = q.normalized();
                if self.filter.initialize(&q, self.tables.filter()).is_ok() {
                    self.filter_mode = FilterMode::Coarse;
                    self.trackers = [TrackerState::default(); 2];
                    raise(events, counters, EventId::FilterInitialized, 1, 0);
                    if self.control_mode == ControlMode::Idle && self.controller.hold(&q).is_ok() {
                        self.control_mode = ControlMode::Hold;
                    }
                } else {
                    raise(events, counters, EventId::CommandRejected, cmd.code(), 2);
                }
            }
            Command::FilterReset => {
                if self.filter.reset_covariance(self.tables.filter()).is_ok() {
                    self.trackers = [TrackerState::default(); 2];
                    raise(events, counters, EventId::FilterReset, 0, 0);
                } else {
                    raise(events, counters, EventId::CommandRejected, cmd.code(), 2);
                }
            }
            Command::SlewTo(target) => {
                if self.filter_mode != FilterMode::Uninitialized
                    && self.controller.slew_to(&target).is_ok()
                {
                    self.control_mode = ControlMode::Slew;
                    self.sun_acquisition = None;
                    self.slew_count = self.slew_count.saturating_add(1);
                    raise(events, counters, EventId::SlewStarted, self.slew_count, 0);
                } else {
                    raise(events, counters, EventId::CommandRejected, cmd.code(), 2);
                }
            }
            Command::Hold => {
                if self.filter_mode != FilterMode::Uninitialized
                    && self.controller.hold(&self.filter.q_acs_from_eci).is_ok()
                {
                    self.control_mode = ControlMode::Hold;
                    self.sun_acquisition = None;
                } else {
                    raise(events, counters, EventId::CommandRejected, cmd.code(), 3);
                }
            }
            Command::SunAcquire(axis) => match SunAcquisition::new(axis) {
                Ok(acq) => {
                    self.sun_acquisition = Some(acq);
                    self.control_mode = ControlMode::SunAcquisition;
                    raise(events, counters, EventId::SunAcquisitionStarted, 0, 0);
                }
                Err(_) => raise(events, counters, EventId::CommandRejected, cmd.code(), 4),
            },
        }
    }

    fn integrate_iru(
        &mut self,
        frame: &RawSensorFrame,
        events: &mut heapless::Vec<Event, MAX_EVENTS_PER_CYCLE>,
    ) -> Option<Vector3<f64>> {
        let table = *self.tables.iru();
        let excluded_before = self.iru.excluded_mask();
        let mut out = self.iru.process(&frame.iru, self.iru_config, &table);
        let newly = self.iru.excluded_mask() & !excluded_before;
        for ch in 0..6u8 {
            if newly & (1u8 << ch) != 0 {
                let reason = self.iru.exclusion_reason(usize::from(ch));
                raise(
                    events,
                    &mut self.counters,
                    EventId::IruChannelExcluded,
                    u32::from(ch),
                    reason,
                );
            }
        }
        if !out.selected_usable && self.iru_config == IruConfiguration::Primary {
            // Automatic switch to the backup channels (their counters were tracked too).
            self.iru_config = IruConfiguration::Backup;
            raise(events, &mut self.counters, EventId::IruConfigSwitched, 1, 1);
            // The backup channels have their own biases: the estimate of the primary ones
            // must not be trusted (`Mekf::reopen_bias_covariance`). The table σ was validated
            // on load, so this cannot fail; if it did the old covariance would be kept.
            if self.filter_mode != FilterMode::Uninitialized {
                let _ = self.filter.reopen_bias_covariance(self.tables.filter());
            }
            out = self.iru.reprocess(self.iru_config, &table);
        }
        if out.delta_theta_acs_rad.is_none() && self.iru.is_initialized() {
            self.counters.iru_unusable_cycles = self.counters.iru_unusable_cycles.saturating_add(1);
            if !self.rejected_run[4] {
                raise(
                    events,
                    &mut self.counters,
                    EventId::IruDataUnusable,
                    u32::from(self.iru.excluded_mask()),
                    0,
                );
            }
            self.rejected_run[4] = true;
        } else {
            self.rejected_run[4] = false;
        }
        out.delta_theta_acs_rad
    }

    /// Rotate a measured body vector from its sample time (frame time − τ) to the frame time.
    fn time_align(&self, dir_acs: Vector3<f64>, offset_s: f64) -> Vector3<f64> {
        if offset_s == 0.0 {
            return dir_acs;
        }
        // A fixed inertial direction seen from a body turning at ω: b(t) = Rot(ω τ) b(t − τ).
        rot(&(self.last_rate_acs_rad_per_s * offset_s)) * dir_acs
    }

    /// Phase 3: the onboard orbit to the frame time (once an orbit table was activated) and,
    /// with the filter table's orbital correction on, this cycle's orbit state for the
    /// references, or the fallback to annual aberration said by event 0x0801 (once per status
    /// while it lasts; 0x0802 when the correction applies again).
    fn advance_orbit(
        &mut self,
        time: TimeTag,
        events: &mut heapless::Vec<Event, MAX_EVENTS_PER_CYCLE>,
    ) {
        self.orbital_fix = None;
        let t_s = time.seconds_since_j2000_tt();
        let status = if self.tables.has_orbit() {
            self.orbit.advance_to(t_s)
        } else {
            OrbitStatus::NoTable
        };
        if !self.tables.filter().orbital_aberration_correction {
            self.orbital_reported = None;
            return;
        }
        let (report, p1) = match (status, self.orbit.state()) {
            (OrbitStatus::Valid, Ok(state)) => {
                self.orbital_fix = Some(state);
                // Saturating float-to-integer cast; a state epoch after now reads 0.
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                let age_s = (t_s - self.orbit.epoch_s_since_j2000_tt()) as u32;
                ((EventId::OrbitalCorrectionApplied, 0, 0), age_s)
            }
            (status, _) => {
                let reason = match status {
                    OrbitStatus::Invalid(why) => why.code(),
                    _ => 0,
                };
                let key = (EventId::OrbitalCorrectionUnavailable, status.code(), reason);
                (key, status.code())
            }
        };
        if self.orbital_reported != Some(report) {
            self.orbital_reported = Some(report);
            let (id, _, p2) = report;
            raise(events, &mut self.counters, id, p1, p2);
        }
    }

    /// The FHST systematic floor, rad: the filter table's `fhst_uncorrected_systematic_arcsec`
    /// (what the table's corrections leave), with the orbital aberration's
    /// [`ORBITAL_ABERRATION_RMS_PER_AXIS_ARCSEC`] added in quadrature while the orbital
    /// correction is asked for but not applied (no valid orbit).
    fn fhst_floor_rad(&self) -> f64 {
        let table = self.tables.filter();
        let floor = table.fhst_uncorrected_systematic_arcsec;
        let arcsec = if table.orbital_aberration_correction && self.orbital_fix.is_none() {
            libm::hypot(floor, ORBITAL_ABERRATION_RMS_PER_AXIS_ARCSEC)
        } else {
            floor
        };
        arcsec * RAD_PER_ARCSEC
    }

    /// The catalog star's reference direction: aberrated by the Earth's velocity (annual,
    /// filter table `aberration_correction`) plus the spacecraft's (orbital, when it applies
    /// this cycle), algorithms.md §3.3.
    fn reference_star(&self, star: &StarMatch, time: TimeTag) -> Vector3<f64> {
        let orbital = self
            .orbital_fix
            .map(|fix| fix.vel_eci_km_per_s / C_KM_PER_S);
        sun_ephemeris::star_reference_dir(
            &star.star.dir(),
            time.seconds_since_j2000_tt(),
            self.tables.filter().aberration_correction,
            orbital.as_ref(),
        )
    }

    fn note_rejected(
        &mut self,
        sensor: usize,
        reason: u32,
        events: &mut heapless::Vec<Event, MAX_EVENTS_PER_CYCLE>,
    ) {
        self.counters.rejected_inputs = self.counters.rejected_inputs.saturating_add(1);
        if let Some(run) = self.rejected_run.get_mut(sensor) {
            if !*run {
                raise(
                    events,
                    &mut self.counters,
                    EventId::InputRejected,
                    to_u32(sensor),
                    reason,
                );
            }
            *run = true;
        }
    }

    fn note_outcome(
        &mut self,
        sensor: usize,
        accepted: bool,
        events: &mut heapless::Vec<Event, MAX_EVENTS_PER_CYCLE>,
    ) -> MeasurementStatus {
        let run = self.gated_run.get(sensor).copied().unwrap_or(false);
        if accepted {
            self.counters.accepted_measurements =
                self.counters.accepted_measurements.saturating_add(1);
            if let Some(r) = self.gated_run.get_mut(sensor) {
                *r = false;
            }
            MeasurementStatus::Accepted
        } else {
            self.counters.gated_measurements = self.counters.gated_measurements.saturating_add(1);
            if !run {
                raise(
                    events,
                    &mut self.counters,
                    EventId::MeasurementGated,
                    to_u32(sensor),
                    0,
                );
            }
            if let Some(r) = self.gated_run.get_mut(sensor) {
                *r = true;
            }
            MeasurementStatus::Gated
        }
    }

    /// Count a newly identified star's first samples and refuse the track when
    /// [`TRACK_REFUSE_GATED`] of its first [`TRACK_CONFIRM_SAMPLES`] were gated.
    fn confirm_track(
        &mut self,
        tracker: usize,
        outcome: &crate::mekf::UpdateOutcome,
        events: &mut heapless::Vec<Event, MAX_EVENTS_PER_CYCLE>,
    ) {
        let Some(state) = self.trackers.get_mut(tracker) else {
            return;
        };
        if state.star.is_none() || state.offered >= TRACK_CONFIRM_SAMPLES {
            return;
        }
        state.offered = state.offered.saturating_add(1);
        if outcome.rejection == Some(crate::mekf::UpdateRejection::Gated) {
            state.gated = state.gated.saturating_add(1);
        }
        if state.gated >= TRACK_REFUSE_GATED {
            state.star = None;
            state.failed = true;
            raise(
                events,
                &mut self.counters,
                EventId::StarIdFailed,
                to_u32(tracker),
                STAR_REFUSED_AFTER_GATING,
            );
        }
    }

    /// Forget a tracker's identified star when it reports a new acquisition or no valid
    /// star (the same rules as [`Self::process_fhst`], without a measurement): used while
    /// the measurements are not processed (slews). Without it a star acquired during a slew,
    /// whose new-star flag is seen only in its first sample, would be taken after the slew
    /// for the star identified before it (issue 19: 15° innovations gated for minutes after
    /// a slew of the main job).
    fn follow_tracks(&mut self, frame: &RawSensorFrame) {
        for (state, sample) in self.trackers.iter_mut().zip(frame.fhst.iter()) {
            let tracking =
                sample.flags & FHST_FLAG_VALID != 0 && sample.flags & FHST_FLAG_TRACKING != 0;
            if !tracking || sample.flags & FHST_FLAG_NEW_STAR != 0 {
                *state = TrackerState::default();
            }
        }
    }

    /// A tracker's corrections from the active alignment table: its alignment at its
    /// temperature (thermal drift; none = the stored rows), distortion, magnitude bias and
    /// time offset.
    fn fhst_corrections(&self, frame: &RawSensorFrame, tracker: usize) -> FhstCorrections {
        let alignment = self.tables.alignment();
        let id = if tracker == 0 {
            SensorId::Fhst1
        } else {
            SensorId::Fhst2
        };
        let rows = alignment
            .drifted_rows_at(id, frame_temperature_c(frame, id))
            .unwrap_or_else(|| *alignment.rows(id));
        let c = &alignment.corrections;
        FhstCorrections {
            rows,
            distortion: c.fhst_distortion.get(tracker).copied().unwrap_or([0.0; 3]),
            magnitude_bias: c
                .fhst_magnitude_bias_rad_per_mag
                .get(tracker)
                .copied()
                .unwrap_or([0.0; 2]),
            offset_s: c.time_offset_s.get(tracker).copied().unwrap_or(0.0),
        }
    }

    /// The corrected measurement of a tracker's sample; a refused sample is noted (no data
    /// also forgets the track) and its residual returned instead.
    fn measure_fhst(
        &mut self,
        sample: &FhstSample,
        tracker: usize,
        corr: &FhstCorrections,
        events: &mut heapless::Vec<Event, MAX_EVENTS_PER_CYCLE>,
    ) -> Result<fhst::FhstMeasurement, SensorResidual> {
        match fhst::measure_corrected(sample, &corr.rows, &corr.distortion, &corr.magnitude_bias) {
            Ok(m) => {
                if let Some(r) = self.rejected_run.get_mut(tracker) {
                    *r = false;
                }
                Ok(m)
            }
            Err(reject) => {
                if reject.is_no_data() {
                    if let Some(t) = self.trackers.get_mut(tracker) {
                        *t = TrackerState::default();
                    }
                    return Err(SensorResidual::default());
                }
                self.note_rejected(tracker, u32::from(reject.code()), events);
                Err(SensorResidual {
                    status: MeasurementStatus::Rejected,
                    ..SensorResidual::default()
                })
            }
        }
    }

    /// The tracker's track after this sample: a new acquisition forgets the star; a track
    /// not yet identified (and not failed) is identified in the window the attitude
    /// covariance allows, with its event and counters.
    fn identify_track(
        &mut self,
        tracker: usize,
        new_star: bool,
        dir_acs: &Vector3<f64>,
        magnitude: f64,
        events: &mut heapless::Vec<Event, MAX_EVENTS_PER_CYCLE>,
    ) -> TrackerState {
        let mut state = self.trackers.get(tracker).copied().unwrap_or_default();
        if new_star {
            state = TrackerState::default();
        }
        if state.star.is_none() && !state.failed {
            let filter_table = self.tables.filter();
            let result = if self.tables.catalog().stars.is_empty() {
                Err(StarIdError::NoCatalog)
            } else {
                // The window from the attitude covariance (issue 19), at most the table's.
                let p = &self.filter.covariance;
                let window = star_id::StarIdWindow::from_covariance(
                    filter_table,
                    p.m11 + p.m22 + p.m33,
                    fhst::measurement_sigma_rad(magnitude, filter_table),
                    self.fhst_floor_rad(),
                );
                star_id::identify_in_window(
                    dir_acs,
                    magnitude,
                    &self.filter.q_acs_from_eci,
                    self.tables.catalog(),
                    &window,
                )
            };
            match result {
                Ok(star) => {
                    state.star = Some(star);
                    self.counters.stars_identified =
                        self.counters.stars_identified.saturating_add(1);
                    raise(
                        events,
                        &mut self.counters,
                        EventId::StarIdentified,
                        to_u32(tracker),
                        star.star.id,
                    );
                }
                Err(e) => {
                    state.failed = true;
                    self.note_star_id_failed(tracker, e, events);
                }
            }
        }
        state
    }

    /// Counts a failed identification by its kind and raises its event.
    fn note_star_id_failed(
        &mut self,
        tracker: usize,
        e: StarIdError,
        events: &mut heapless::Vec<Event, MAX_EVENTS_PER_CYCLE>,
    ) {
        let code = match e {
            StarIdError::NoMatch => {
                self.counters.star_id_unmatched = self.counters.star_id_unmatched.saturating_add(1);
                1
            }
            StarIdError::Ambiguous { .. } => {
                self.counters.star_id_ambiguous = self.counters.star_id_ambiguous.saturating_add(1);
                2
            }
            StarIdError::NoCatalog | StarIdError::InvalidInput => u32::from(e.code()),
        };
        raise(
            events,
            &mut self.counters,
            EventId::StarIdFailed,
            to_u32(tracker),
            code,
        );
    }

    /// One FHST sample: (1) the tracker's corrections, (2) the corrected measurement,
    /// time-aligned, (3) the track identified, (4) the focal-plane update against the
    /// identified star, its outcome noted and the track confirmed.
    fn process_fhst(
        &mut self,
        frame: &RawSensorFrame,
        tracker: usize,
        events: &mut heapless::Vec<Event, MAX_EVENTS_PER_CYCLE>,
    ) -> SensorResidual {
        let Some(sample) = frame.fhst.get(tracker) else {
            return SensorResidual::default();
        };
        // 1. Corrections.
        let corr = self.fhst_corrections(frame, tracker);
        let m_acs_from_fhst = matrix_from_rows(&corr.rows);
        // 2. The measurement.
        let meas = match self.measure_fhst(sample, tracker, &corr, events) {
            Ok(m) => m,
            Err(residual) => return residual,
        };
        let dir_acs = self.time_align(meas.dir_acs, corr.offset_s);
        // 3. Identify on a new acquisition (or if not yet identified for this track).
        let new_star = sample.flags & FHST_FLAG_NEW_STAR != 0;
        let state = self.identify_track(tracker, new_star, &dir_acs, meas.magnitude, events);
        if let Some(t) = self.trackers.get_mut(tracker) {
            *t = state;
        }
        let Some(star) = state.star else {
            return SensorResidual {
                status: MeasurementStatus::Unidentified,
                ..SensorResidual::default()
            };
        };
        // 4. Focal-plane update (H, V): the measurement space of the tracker.
        let ref_eci = self.reference_star(&star, frame.time);
        let filter_table = self.tables.filter();
        let sigma = fhst::measurement_sigma_rad(meas.magnitude, filter_table);
        let gate = filter_table.gate_chi2;
        let floor = self.fhst_floor_rad();
        let (h_rad, v_rad) = if corr.offset_s == 0.0 {
            (meas.h_rad, meas.v_rad)
        } else {
            fhst::hv_from_dir(&(m_acs_from_fhst.transpose() * dir_acs))
                .unwrap_or((meas.h_rad, meas.v_rad))
        };
        let outcome = self.filter.update_focal_plane_consider(
            h_rad,
            v_rad,
            &ref_eci,
            &m_acs_from_fhst,
            sigma,
            floor,
            tracker,
            gate,
        );
        let status = self.note_outcome(tracker, outcome.accepted, events);
        if outcome.accepted {
            self.cycles_since_star = 0;
        }
        self.confirm_track(tracker, &outcome, events);
        #[allow(clippy::cast_possible_truncation)]
        SensorResidual {
            status,
            innovation_arcsec: [
                (outcome.innovation_rad[0] * ARCSEC_PER_RAD) as f32,
                (outcome.innovation_rad[1] * ARCSEC_PER_RAD) as f32,
            ],
            star_id: star.star.id,
        }
    }

    fn process_fss(
        &mut self,
        frame: &RawSensorFrame,
        sensor: usize,
        events: &mut heapless::Vec<Event, MAX_EVENTS_PER_CYCLE>,
    ) -> SensorResidual {
        let Some(sample) = frame.fss.get(sensor) else {
            return SensorResidual::default();
        };
        let index = sensor.saturating_add(2);
        let sensor_id = if sensor == 0 {
            SensorId::Fss1
        } else {
            SensorId::Fss2
        };
        let alignment = self.tables.alignment();
        // The sensor's alignment at its temperature (thermal drift; none = the stored rows).
        let drifted = alignment.drifted_rows_at(sensor_id, frame_temperature_c(frame, sensor_id));
        let m_acs_from_fss_rows = match &drifted {
            Some(rows) => rows,
            None => alignment.rows(sensor_id),
        };
        let m_acs_from_fss = matrix_from_rows(m_acs_from_fss_rows);
        let id = if sensor == 0 {
            fss::FssId::Fss1
        } else {
            fss::FssId::Fss2
        };
        let transfer = id.transfer_terms(&alignment.corrections);
        let offset_s = alignment
            .corrections
            .time_offset_s
            .get(index)
            .copied()
            .unwrap_or(0.0);
        let meas = match fss::measure_corrected(sample, m_acs_from_fss_rows, &transfer) {
            Ok(m) => {
                if let Some(r) = self.rejected_run.get_mut(index) {
                    *r = false;
                }
                m
            }
            Err(reject) => {
                if reject.is_no_data() {
                    return SensorResidual::default();
                }
                self.note_rejected(index, u32::from(reject.code()), events);
                return SensorResidual {
                    status: MeasurementStatus::Rejected,
                    ..SensorResidual::default()
                };
            }
        };
        let dir_acs = self.time_align(meas.dir_acs, offset_s);
        let Some(sun_eci) = self.sun_direction(frame.time) else {
            return SensorResidual {
                status: MeasurementStatus::NotUsed,
                ..SensorResidual::default()
            };
        };
        // Innovation in the sensor's own axes (α, β), reported whether or not it is used.
        let predicted = fss::angles_from_dir(
            &(m_acs_from_fss.transpose() * (self.filter.q_acs_from_eci.to_dcm() * sun_eci)),
        );
        let measured = fss::angles_from_dir(&(m_acs_from_fss.transpose() * dir_acs));
        let innovation_rad = match (measured, predicted) {
            (Some((a_m, b_m)), Some((a_p, b_p))) => [a_m - a_p, b_m - b_p],
            _ => [0.0; 2],
        };
        #[allow(clippy::cast_possible_truncation)]
        let innovation_arcsec = [
            (innovation_rad[0] * ARCSEC_PER_RAD) as f32,
            (innovation_rad[1] * ARCSEC_PER_RAD) as f32,
        ];
        // Fine mode uses the FHSTs only; the FSSs serve coarse mode (paper §2: FSS + IRU
        // coarse attitude, FHST + IRU fine attitude). An uncalibrated FSS would otherwise pull
        // the fine attitude by its misalignment.
        if self.filter_mode == FilterMode::Fine {
            return SensorResidual {
                status: MeasurementStatus::NotUsed,
                innovation_arcsec,
                star_id: 0,
            };
        }
        let filter_table = self.tables.filter();
        let floor = filter_table.fss_sigma_arcsec / ARCSEC_PER_RAD;
        let gate = filter_table.gate_chi2;
        let outcome = self.filter.update_vector_with_floor(
            &dir_acs,
            &sun_eci,
            FSS_WHITE_SIGMA_RAD,
            floor,
            gate,
        );
        let status = self.note_outcome(index, outcome.accepted, events);
        SensorResidual {
            status,
            innovation_arcsec,
            star_id: 0,
        }
    }

    /// Process noise of a coast (no gyro data: the increment is the last rate times `dt`).
    /// The rate is then wrong by what the body's angular acceleration changed since the last
    /// gyro data, at most `α = torque_limit / min(inertia)` (filter table): after a coast of
    /// `t` the attitude error is at most `α t²/2`. That bound is taken as 1σ, so each coast
    /// cycle adds `(α/2)² (t⁴ − (t − dt)⁴)` per axis (docs/obc_filter.md §4).
    fn add_coast_noise(&mut self, dt_s: f64) {
        let table = self.tables.filter();
        let inertia_min = table
            .inertia_kg_m2
            .iter()
            .fold(f64::INFINITY, |a, b| a.min(*b));
        let alpha = table.torque_limit_nm / inertia_min;
        let before = self.coast_s;
        let after = before + dt_s;
        let (a2, b2) = (after * after, before * before);
        let var = 0.25 * alpha * alpha * (a2 * a2 - b2 * b2);
        if self.filter.add_attitude_variance(var).is_ok() {
            self.coast_s = after;
        }
    }

    /// Gyro scale-factor/misalignment uncertainty during a slew: the attitude error it causes
    /// is coherent (∝ angle turned), so the standard deviation grows linearly with the angle:
    /// `var += k² ((θ + |Δθ|)² − θ²)` per axis, `k` = `gyro_scale_uncertainty`.
    fn inflate_for_gyro_calibration(&mut self, delta_theta: &Vector3<f64>) {
        let filter = self.tables.filter();
        let k = filter.gyro_scale_uncertainty;
        let per_element = filter.gyro_calibration_sigma;
        let step = delta_theta.norm();
        if !(step.is_finite() && k.is_finite() && delta_theta.iter().all(|x| x.is_finite())) {
            return;
        }
        let before = self.slew_angle_rad;
        let after = before + step;
        self.slew_angle_rad = after;
        let before_axes = self.slew_angle_acs_rad;
        let after_axes = before_axes + delta_theta.abs();
        self.slew_angle_acs_rad = after_axes;
        let grow = if per_element.iter().flatten().any(|e| *e != 0.0) {
            // `var_i += Σ_j E_ij² (a_j'² − a_j²)`.
            let turned =
                after_axes.component_mul(&after_axes) - before_axes.component_mul(&before_axes);
            let e2 = matrix_from_rows(&per_element).map(|e| e * e);
            Matrix3::from_diagonal(&(e2 * turned))
        } else {
            Matrix3::identity() * (k * k * (after * after - before * before))
        };
        let mut block = self.filter.covariance.fixed_view_mut::<3, 3>(0, 0);
        block += grow;
        // The coarse solution is carried on the same gyros through the slew.
        self.coarse.add_covariance(&grow);
    }

    /// Onboard Sun direction, the ephemeris re-evaluated at most every [`SUN_REFRESH_S`]
    /// (the Sun moves 0.04″/s, so a 10 s old direction is 0.4″ off: far below the FSS
    /// noise). Apparent from the geocentre (annual aberration), or from the spacecraft when
    /// the orbital correction applies this cycle: the Sun's geocentric position minus the
    /// spacecraft's (parallax ≤ 9.5″), aberrated by the Earth's plus the spacecraft's
    /// velocity (algorithms.md §3.3, "Sun vector").
    fn sun_direction(&mut self, time: TimeTag) -> Option<Vector3<f64>> {
        let t = time.seconds_since_j2000_tt();
        let fresh =
            matches!(&self.sun_cache, Some((t_cached, _)) if (t - t_cached).abs() <= SUN_REFRESH_S);
        if !fresh {
            self.sun_cache = Some((t, sun_ephemeris::sun_state(t).ok()?));
        }
        let (_, sun) = self.sun_cache.as_ref()?;
        Some(match &self.orbital_fix {
            None => sun.dir_eci,
            Some(fix) => sun_ephemeris::apparent_sun_from(
                sun,
                &fix.pos_eci_km,
                &(fix.vel_eci_km_per_s / C_KM_PER_S),
            ),
        })
    }

    fn update_filter_mode(
        &mut self,
        residuals: &[SensorResidual; 4],
        events: &mut heapless::Vec<Event, MAX_EVENTS_PER_CYCLE>,
    ) {
        let star_used = residuals
            .iter()
            .take(2)
            .any(|r| r.status == MeasurementStatus::Accepted);
        if !star_used {
            self.cycles_since_star = self.cycles_since_star.saturating_add(1);
        }
        let new_mode = match self.filter_mode {
            FilterMode::Uninitialized => FilterMode::Uninitialized,
            _ if self.cycles_since_star < FINE_MODE_TIMEOUT_CYCLES => FilterMode::Fine,
            _ => FilterMode::Coarse,
        };
        if new_mode != self.filter_mode {
            self.filter_mode = new_mode;
            raise(
                events,
                &mut self.counters,
                EventId::FilterModeChanged,
                u32::from(new_mode as u8),
                0,
            );
        }
    }

    fn control(
        &mut self,
        frame: &RawSensorFrame,
        events: &mut heapless::Vec<Event, MAX_EVENTS_PER_CYCLE>,
    ) {
        if self.control_mode == ControlMode::Idle {
            self.wheel_torque_cmd_nm = Vector3::zeros();
            return;
        }
        if self.control_mode == ControlMode::SunAcquisition {
            self.sun_acquisition_cycle(frame, events);
            return;
        }
        let out = self.controller.update(
            &self.filter.q_acs_from_eci,
            &self.last_rate_acs_rad_per_s,
            self.tables.filter(),
        );
        self.wheel_torque_cmd_nm = out.torque_acs_nm;
        self.note_control_fault(out.fault.map(control_fault_code), events);
        if self.control_mode == ControlMode::Slew && out.slew_complete {
            self.control_mode = ControlMode::Hold;
            raise(
                events,
                &mut self.counters,
                EventId::SlewCompleted,
                self.slew_count,
                0,
            );
        }
        self.command_iru_rate(out.high_rate_iru, events);
    }

    /// A maneuver: a slew, or a Sun acquisition still turning (not yet acquired). The filter
    /// then propagates on the gyros alone and grows its covariance by the gyro calibration's
    /// uncertainty over the angle turned, as in a slew.
    fn maneuvering(&self) -> bool {
        match self.control_mode {
            ControlMode::Slew => true,
            ControlMode::SunAcquisition => {
                self.sun_acquisition.as_ref().is_some_and(|a| !a.acquired())
            }
            ControlMode::Idle | ControlMode::Hold => false,
        }
    }

    /// Phase 8 in Sun acquisition: the best Sun sensor of the cycle (FSS1, FSS2, the CSS eyes)
    /// and the gyro rate drive the eigen-axis law ([`crate::sun_acquisition`]); events 0x0603
    /// (acquired) and 0x0604 (no Sun seen); the IRU in high rate.
    fn sun_acquisition_cycle(
        &mut self,
        frame: &RawSensorFrame,
        events: &mut heapless::Vec<Event, MAX_EVENTS_PER_CYCLE>,
    ) {
        let candidates =
            sun_candidates_acs(frame, self.tables.alignment(), self.tables.magnetics());
        let sun = candidates.iter().flatten().map(|(v, _, _)| *v).next();
        let Some(acq) = self.sun_acquisition.as_mut() else {
            // Mode 3 without its state cannot be entered (command 9 sets both); said, not
            // hidden, if it ever is.
            self.wheel_torque_cmd_nm = Vector3::zeros();
            self.note_control_fault(Some(CONTROL_FAULT_NO_SUN_ACQUISITION), events);
            return;
        };
        let result = acq.update(
            sun.as_ref(),
            &self.last_rate_acs_rad_per_s,
            self.tables.filter(),
        );
        let turning = !acq.acquired();
        match result {
            Ok(out) => {
                self.wheel_torque_cmd_nm = out.law.torque_acs_nm;
                self.note_control_fault(None, events);
                if out.acquired_now {
                    let centideg = out
                        .sun_angle_rad
                        .map_or(0.0, |a| a / crate::units::RAD_PER_DEG * 100.0);
                    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                    let p1 = centideg.clamp(0.0, f64::from(u32::MAX)) as u32;
                    raise(events, &mut self.counters, EventId::SunAcquired, p1, 0);
                }
                if out.acquisition_lost_now {
                    raise(
                        events,
                        &mut self.counters,
                        EventId::SunAcquisitionLost,
                        0,
                        0,
                    );
                }
                if out.sun_lost_now {
                    let at_entry = u32::from(out.first_cycle);
                    raise(events, &mut self.counters, EventId::SunNotSeen, at_entry, 0);
                }
            }
            Err(e) => {
                self.wheel_torque_cmd_nm = Vector3::zeros();
                self.note_control_fault(Some(control_fault_code(e)), events);
            }
        }
        // High rate while turning, low rate in the Sun hold (as slews and inertial holds).
        self.command_iru_rate(turning, events);
    }

    /// Command the IRU rate mode; event 0x0203 on a change.
    fn command_iru_rate(
        &mut self,
        high: bool,
        events: &mut heapless::Vec<Event, MAX_EVENTS_PER_CYCLE>,
    ) {
        if high != self.iru_high_rate_cmd {
            self.iru_high_rate_cmd = high;
            raise(
                events,
                &mut self.counters,
                EventId::IruRateModeChanged,
                u32::from(high),
                0,
            );
        }
    }

    /// Event 0x0607 when the control step starts failing (or fails differently); the torque
    /// is then zero. `None`: the step worked.
    fn note_control_fault(
        &mut self,
        fault: Option<u32>,
        events: &mut heapless::Vec<Event, MAX_EVENTS_PER_CYCLE>,
    ) {
        if let Some(code) = fault {
            if self.control_fault != Some(code) {
                raise(
                    events,
                    &mut self.counters,
                    EventId::ControlFault,
                    code,
                    u32::from(self.control_mode as u8),
                );
            }
        }
        self.control_fault = fault;
    }

    fn housekeeping(&self, time: TimeTag, residuals: [SensorResidual; 4]) -> ObcHousekeeping {
        let status = self.tables.status();
        let mut table_crc = [0u32; 4];
        let mut table_pending_mask = 0u8;
        for (i, (crc, s)) in table_crc.iter_mut().zip(status.iter()).enumerate() {
            *crc = s.active_crc;
            if s.pending {
                table_pending_mask |= 1u8 << (i & 7);
            }
        }
        let b = self.filter.bias_rad_per_s;
        let mut covariance_diag = [0.0; 6];
        for (dst, src) in covariance_diag
            .iter_mut()
            .zip(self.filter.covariance.diagonal().iter())
        {
            *dst = *src;
        }
        #[allow(clippy::cast_possible_truncation)]
        ObcHousekeeping {
            time,
            q_acs_from_eci: self.filter.q_acs_from_eci,
            bias_acs_rad_per_s: [b.x, b.y, b.z],
            covariance_diag,
            filter_mode: self.filter_mode as u8,
            control_mode: self.control_mode as u8,
            iru_config: self.iru_config.code() as u8,
            iru_high_rate_cmd: u8::from(self.iru_high_rate_cmd),
            wheel_torque_cmd_nm: [
                self.wheel_torque_cmd_nm.x as f32,
                self.wheel_torque_cmd_nm.y as f32,
                self.wheel_torque_cmd_nm.z as f32,
            ],
            residuals,
            iru_excluded_mask: self.iru.excluded_mask(),
            counters: self.counters,
            table_crc,
            table_pending_mask,
        }
    }

    /// The IRU high-rate command the hardware should apply from the next interval.
    /// Paper: IRU high rate for maneuvers, low rate inertial; docs/icd.md §3.2 (offset 107).
    #[must_use]
    pub fn iru_high_rate_command(&self) -> bool {
        self.iru_high_rate_cmd
    }

    /// The wheel torque command of the last cycle in ACS, N m.
    /// docs/icd.md §3.2 (offset 108).
    #[must_use]
    pub fn wheel_torque_command_nm(&self) -> Vector3<f64> {
        self.wheel_torque_cmd_nm
    }
}
