//! # The closed loop: truth → sensors → flight software → wheels → truth
//!
//! Why: the flight software (`fsw_core::executive::FlightCore`) must fly against a truth it
//! cannot see, and every cycle's raw frame, flight output and truth must be recorded for the
//! ground and for scoring.
//!
//! # Cycle k (t_k = k·step)
//! 1. Orbit to t_k; Sun (cached ephemeris); truth snapshot (attitude, rate, apparent Sun from
//!    the spacecraft, umbra).
//! 2. Thermal nodes; FHST1/2 and FSS1/2 sample the truth at t_k; the IRU sample is the one
//!    that closed the interval [t_{k−1}, t_k] (initial counters at k = 0).
//!    With `[magnetics] enabled`, TAM1/2 and the CSSs ([`crate::magnetics`]) are sampled
//!    into the raw frame and the record (their own random streams), the TAMs with the
//!    torquer bars' field for the dipole the bars delivered over [t_{k−1}, t_k].
//! 3. The commands due at t_k (at most `MAX_COMMANDS_PER_CYCLE`, the rest wait a cycle) and
//!    `FlightCore::step(frame, commands)`.
//! 4. The FSW's IRU rate-mode request goes to the IRU (it applies from the next interval,
//!    as the hardware does); its wheel torque command is held over [t_k, t_{k+1}], and so is
//!    its torquer-bar dipole command (`momentum_unloading = "bars"`,
//!    [`crate::truth::torquer`]; clamped per bar, `torquer_stuck_on` faults applied).
//! 5. Dynamics over [t_k, t_{k+1}] (external torques at the t_k position and field: gravity
//!    gradient, the bars' `m × B`); the IRU closes the interval with `∫ω dt`.
//!
//! # Start-up uplinks (t = 0, in this order, before the scenario's own t = 0 commands)
//! Onboard star catalog ([`crate::onboard`]), the filter table of `filter_table` and
//! `[onboard_orbit]`, the true-alignment table if `fly_true_alignments`, the orbit tables of
//! `[onboard_orbit]` (at their own times), every `--tables` image (load + activate each), then
//! `FilterInitialize(Rot(error) · A_true)` (scenario `[initial_estimate]`).
//!
//! # Scoring per cycle
//! `δθ` with `A_true = Rot(δθ) Â` (fsw_core convention) and the NEES `δθᵀ P_θθ⁻¹ δθ` from the
//! filter's full covariance (3 for a consistent filter).
//!
//! The per-cycle path allocates nothing.

use anyhow::Context;
use nalgebra::{Matrix3, Vector3};

use crate::faults::{Fault, FaultKind, FaultState};
use crate::onboard;
use crate::paper::PaperFacts;
use crate::scenario::{body_axis_from_name, table_id_from_name, CommandKind, Scenario};
use crate::sensors::fhst::Fhst;
use crate::sensors::fss::Fss;
use crate::sensors::iru::Iru;
use crate::sensors::tachometer::Tachometers;
use crate::sensors::thermal::ThermalNode;
use crate::sensors::TruthSnapshot;
use crate::truth::dynamics::{AttitudeState, MomentumUnloading, RigidBody};
use crate::truth::orbit::Orbit;
use crate::truth::sky::Sky;
use crate::truth::sun::SunEphemeris;
use crate::truth::time::{epoch_from_iso, SimClock};
use crate::truth::torquer::{magnetic_torque_nm, TorquerBars, TESLA_PER_NT};
use crate::InputError;
use fsw_core::attitude::{attitude_error_rad, Quat};
use fsw_core::executive::{Command, CycleOutput, FlightCore, MAX_COMMANDS_PER_CYCLE};
use fsw_core::iru::IruConfiguration;
use fsw_core::raw::{IruSample, RawSensorFrame, TEMPERATURE_SENSORS};
use fsw_core::tables::TableId;

/// What one cycle produced, for recording and scoring.
#[derive(Clone, Debug)]
pub struct CycleRecord {
    /// Cycle index.
    pub cycle: u64,
    /// The truth at the sample instant.
    pub truth: TruthSnapshot,
    /// The raw frame the flight software read.
    pub frame: RawSensorFrame,
    /// The flight software's output.
    pub output: CycleOutput,
    /// Estimation error `A_true = Rot(δθ) Â` (rad, ACS); zero before the filter has an attitude.
    pub attitude_error_acs_rad: Vector3<f64>,
    /// `δθᵀ P_θθ⁻¹ δθ`; `None` before initialisation or with a singular `P_θθ`.
    pub nees: Option<f64>,
    /// Number of commands sent to the OBC this cycle.
    pub commands_sent: usize,
    /// The field, TAM and CSS samples of this cycle ([`crate::magnetics`]; the flight
    /// software does not see them yet).
    pub magnetics: crate::magnetics::MagneticsRecord,
    /// The OBC's coarse attitude against the truth (`None` before its first fix).
    pub coarse: Option<CoarseCheck>,
    /// The dipole each torquer bar delivers over the step after this cycle (A·m²; zero
    /// without bars): the OBC's command, clamped, or a stuck bar's dipole.
    pub torquer_dipole_am2: [f64; 3],
}

/// The fine filter's error `A_true = Rot(δθ) Â` (rad, ACS) and NEES against `q_true`; zero and
/// `None` before the filter has an attitude (`filter_mode` 0).
fn fine_check(fsw: &FlightCore, q_true: &Quat, filter_mode: u8) -> (Vector3<f64>, Option<f64>) {
    if filter_mode == 0 {
        return (Vector3::zeros(), None);
    }
    let filter = fsw.filter();
    let err = attitude_error_rad(q_true, &filter.q_acs_from_eci);
    let p: Matrix3<f64> = filter.covariance.fixed_view::<3, 3>(0, 0).into_owned();
    let nees = p.cholesky().map(|c| err.dot(&c.solve(&err)));
    (err, nees)
}

/// The OBC's coarse attitude (`fsw_core::coarse`) against the truth, one cycle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoarseCheck {
    /// `A_true = Rot(δθ) Â_coarse` (rad, ACS).
    pub error_acs_rad: Vector3<f64>,
    /// The OBC's 1σ per ACS axis, rad (√ of the covariance diagonal).
    pub sigma_acs_rad: Vector3<f64>,
    /// `δθᵀ P⁻¹ δθ`; `None` with a singular covariance.
    pub nees: Option<f64>,
    /// Seconds since the solution's last fix.
    pub age_s: f64,
    /// The last fix's vectors (`fsw_core::coarse::CoarseSource`: 1 FSS + TAM, 2 CSS + TAM).
    pub source: u8,
}

impl CoarseCheck {
    /// The check of `fsw`'s coarse attitude against `q_true`, `None` before its first fix.
    #[must_use]
    pub fn of(fsw: &FlightCore, q_true: &Quat) -> Option<Self> {
        let c = fsw.coarse();
        if !c.valid {
            return None;
        }
        let e = attitude_error_rad(q_true, &c.q_acs_from_eci);
        let p = c.covariance_rad2;
        Some(Self {
            error_acs_rad: e,
            sigma_acs_rad: p.diagonal().map(|v| v.max(0.0).sqrt()),
            nees: p.cholesky().map(|ch| e.dot(&ch.solve(&e))),
            age_s: c.age_s,
            source: c.source as u8,
        })
    }
}

/// One scheduled action.
#[derive(Clone, Debug)]
enum Action {
    Slew(Quat),
    SlewRelative(Vector3<f64>),
    Hold,
    SelectIru(IruConfiguration),
    Load(usize),
    Activate(TableId),
    Abort(TableId),
    FilterInit(Option<Quat>),
    FilterReset,
    SunAcquire([f64; 3]),
}

/// A table image uplinked during the run.
#[derive(Clone, Debug)]
pub struct Upload {
    /// Where it came from ("onboard catalog", a file path, ...).
    pub source: String,
    /// Short file name used in the run folder.
    pub name: String,
    /// The image.
    pub image: Vec<u8>,
    /// Load time (s).
    pub at_s: f64,
}

/// The simulator state.
pub struct Simulation {
    scenario: Scenario,
    clock: SimClock,
    orbit: Orbit,
    body: RigidBody,
    sun: SunEphemeris,
    sky: Sky,
    fhst: [Fhst; 2],
    fss: [Fss; 2],
    iru: Iru,
    thermal: [ThermalNode; TEMPERATURE_SENSORS],
    fsw: FlightCore,
    cycle: u64,
    cycle_count: u64,
    pending_iru: IruSample,
    timeline: Vec<(f64, Action)>,
    next_action: usize,
    uploads: Vec<Upload>,
    current_target: Quat,
    error_rotation: Quat,
    faults: Vec<Fault>,
    fault_state: FaultState,
    magnetics: Option<crate::magnetics::Magnetics>,
    /// The magnetic torquer bars (`[dynamics] momentum_unloading = "bars"`).
    torquers: Option<TorquerBars>,
    /// The wheel tachometers and bar current monitors (`[wheel_tachometers] enabled`).
    tachometers: Option<Tachometers>,
}

/// The torquer bars of a scenario flown with `[dynamics] momentum_unloading = "bars"`.
fn torquers_of(s: &Scenario) -> Option<TorquerBars> {
    (s.dynamics.momentum_unloading == MomentumUnloading::Bars)
        .then(|| TorquerBars::new(&s.torquers))
}

/// Cycles of a run of `duration_s` at `step_s` (both ends included).
#[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
fn cycle_count_of(duration_s: f64, step_s: f64) -> u64 {
    (duration_s / step_s + 1e-9).floor() as u64 + 1
}

fn quat_from_array([x, y, z, w]: [f64; 4]) -> Quat {
    Quat::new(x, y, z, w).normalized()
}

impl Simulation {
    /// Build every model from a validated scenario, boot the flight software and schedule
    /// the start-up uplinks and the scenario timeline. `tables_dir`: the images its
    /// `manifest.json` lists ([`crate::manifest`]) are loaded and activated at t = 0.
    ///
    /// # Errors
    /// [`InputError`] for unreadable/invalid table files or parameters (naming the field);
    /// other errors for internal failures.
    pub fn new(scenario: Scenario, tables_dir: Option<&std::path::Path>) -> anyhow::Result<Self> {
        let paper = PaperFacts::load()?;
        let epoch = epoch_from_iso(&scenario.epoch_utc)
            .context("epoch_utc")
            .map_err(InputError::from)?;
        let clock = SimClock::new(epoch);
        let catalogue = onboard::catalogue_table(&scenario).map_err(InputError::from)?;
        let sky = Sky::from_csv(&catalogue, &scenario.sky)
            .context("sky catalogue")
            .map_err(InputError::from)?;
        let body = RigidBody::new(
            &scenario.dynamics,
            scenario.initial.quat(),
            scenario.initial.rate_acs_rad_per_s(),
        )
        .map_err(InputError::from)?;
        let seed = scenario.seed;
        let iru = iru_of(&scenario, &paper)?;
        let pending_iru = IruSample {
            counts: iru.counts(),
            channel_failed: 0,
            high_rate: scenario.iru.initial_high_rate,
        };
        let fhst = [
            Fhst::new(0, scenario.fhst1.clone(), &paper, seed),
            Fhst::new(1, scenario.fhst2.clone(), &paper, seed),
        ];
        let fss = [
            Fss::new(0, scenario.fss1.clone(), &paper, seed),
            Fss::new(1, scenario.fss2.clone(), &paper, seed),
        ];
        let true_alignments = true_alignment_table(&fhst, &fss);
        let mut schedule = Schedule::default();
        schedule.startup_uplinks(&scenario, &clock, &catalogue, &true_alignments, tables_dir)?;
        schedule.scenario_commands(&scenario, &clock)?;
        schedule.uplink_faults(&scenario, &clock, &true_alignments)?;
        // Start-up entries are at 0 and come first; the scenario's are sorted: keep stable.
        schedule.timeline.sort_by(|a, b| a.0.total_cmp(&b.0));

        let cycle_count = cycle_count_of(scenario.duration_s, scenario.step_s);
        let error_rotation = Quat::from_rotation_vector(&scenario.initial_estimate.error_rad());
        Ok(Self {
            clock,
            orbit: Orbit::new(&scenario.orbit),
            sun: SunEphemeris::new(clock.j2000_tt_s(0.0), scenario.sun_refresh_s),
            current_target: scenario.initial.quat(),
            body,
            sky,
            fhst,
            fss,
            iru,
            thermal: scenario.thermal.slots().map(ThermalNode::new),
            fsw: FlightCore::new(),
            cycle: 0,
            cycle_count,
            pending_iru,
            timeline: schedule.timeline,
            next_action: 0,
            uploads: schedule.uploads,
            error_rotation,
            faults: scenario.faults.clone(),
            fault_state: FaultState::new(&scenario.faults),
            magnetics: crate::magnetics::Magnetics::of_scenario(&scenario)?,
            torquers: torquers_of(&scenario),
            tachometers: scenario.wheel_tachometers.enabled.then(|| {
                Tachometers::new(
                    &scenario.wheel_tachometers,
                    crate::sensors::model_rng(seed, crate::sensors::stream::TACHOMETERS),
                )
            }),
            scenario,
        })
    }

    /// This cycle's field, TAM and CSS samples (all invalid without magnetics) and the words
    /// the OBC reads from them, with the `tam_failure` and `css_glint` faults applied.
    fn sample_magnetics(
        &mut self,
        truth: &TruthSnapshot,
    ) -> (
        crate::magnetics::MagneticsRecord,
        [fsw_core::raw::TamSample; 2],
        fsw_core::raw::CssSample,
    ) {
        let Some(m) = self.magnetics.as_mut() else {
            return Default::default();
        };
        let dipole_acs_am2 = self
            .torquers
            .as_ref()
            .map_or_else(Vector3::zeros, TorquerBars::dipole_acs_am2);
        let record = m.sample(&self.clock, truth, &dipole_acs_am2);
        let t = truth.t_s;
        let mut tam = record.tam.map(crate::magnetics::flight_tam_sample);
        // The bar drive's current monitor: a bar carried current while the TAMs sampled.
        if dipole_acs_am2.iter().any(|m| *m != 0.0) {
            for s in tam.iter_mut().filter(|s| s.flags != 0) {
                s.flags |= fsw_core::raw::TAM_FLAG_TORQUERS_ON;
            }
        }
        for (unit, sample) in tam.iter_mut().enumerate() {
            let resolution = m.tam()[unit].params().resolution_milligauss_per_count;
            *sample = FaultState::apply_tam(&self.faults, unit, t, *sample, resolution);
        }
        let css = FaultState::apply_css(
            &self.faults,
            t,
            crate::magnetics::flight_css_sample(&record.css),
        );
        (record, tam, css)
    }

    /// The FHST and FSS faults of `t` applied to this cycle's samples ([`crate::faults`]);
    /// returns the time-tag offset of a `time_tag_jump` (s).
    fn apply_sensor_faults(
        &mut self,
        t: f64,
        truth: &TruthSnapshot,
        fhst: &mut [fsw_core::raw::FhstSample; 2],
        fss: &mut [fsw_core::raw::FssSample; 2],
    ) -> f64 {
        if self.faults.is_empty() {
            return 0.0;
        }
        for (unit, sample) in fhst.iter_mut().enumerate() {
            let tracker = &self.fhst[unit];
            let sky = &self.sky;
            let other = || {
                crate::faults::other_star_offset(
                    tracker.m_acs_from_fhst_true(),
                    tracker.last_truth().hv_rad,
                    truth,
                    sky,
                    tracker.params().fov_half_width_deg * fsw_core::units::RAD_PER_DEG,
                    (
                        tracker.params().magnitude_min,
                        tracker.params().magnitude_max,
                    ),
                )
            };
            *sample = self.fault_state.apply_fhst(
                &self.faults,
                unit,
                t,
                *sample,
                tracker.params().resolution_arcsec_per_count,
                other,
            );
        }
        for (unit, sample) in fss.iter_mut().enumerate() {
            *sample = FaultState::apply_fss(
                &self.faults,
                unit,
                t,
                *sample,
                self.fss[unit].params().resolution_deg_per_count,
            );
        }
        FaultState::time_offset_s(&self.faults, t)
    }

    /// This cycle's tachometer and bar-monitor words (all invalid without
    /// `[wheel_tachometers] enabled`), with the `tachometer_failed` faults applied. The bars
    /// still hold the previous cycle's dipole: the one over the interval that ended now.
    fn sample_wheels(&mut self, t_s: f64) -> fsw_core::raw::WheelSample {
        let Some(tach) = self.tachometers.as_mut() else {
            return fsw_core::raw::WheelSample::default();
        };
        let failed = FaultState::failed_tachometers(&self.faults, t_s);
        let dipoles = self.torquers.as_ref().map(TorquerBars::dipole_am2);
        tach.sample(self.body.wheel_momenta_nms(), &failed, dipoles)
    }

    /// The magnetometers and coarse Sun sensors, `None` with `[magnetics] enabled = false`.
    #[must_use]
    pub fn magnetics(&self) -> Option<&crate::magnetics::Magnetics> {
        self.magnetics.as_ref()
    }

    /// The scenario.
    #[must_use]
    pub fn scenario(&self) -> &Scenario {
        &self.scenario
    }

    /// The clock.
    #[must_use]
    pub fn clock(&self) -> &SimClock {
        &self.clock
    }

    /// The flight software.
    #[must_use]
    pub fn fsw(&self) -> &FlightCore {
        &self.fsw
    }

    /// True attitude state.
    #[must_use]
    pub fn true_attitude(&self) -> &AttitudeState {
        self.body.state()
    }

    /// The truth's wheel momentum in ACS now (N·m·s): what the next frame's tachometers
    /// measure.
    #[must_use]
    pub fn true_wheel_momentum_acs_nms(&self) -> Vector3<f64> {
        self.body.wheel_momentum_acs_nms()
    }

    /// The truth orbit (position/velocity at the last sampled cycle).
    #[must_use]
    pub fn orbit(&self) -> &Orbit {
        &self.orbit
    }

    /// FHST truth models.
    #[must_use]
    pub fn fhst(&self) -> &[Fhst; 2] {
        &self.fhst
    }

    /// FSS truth models.
    #[must_use]
    pub fn fss(&self) -> &[Fss; 2] {
        &self.fss
    }

    /// The IRU truth model.
    #[must_use]
    pub fn iru(&self) -> &Iru {
        &self.iru
    }

    /// Thermal node of raw-frame slot `i` (4 = IRU baseplate).
    #[must_use]
    pub fn thermal(&self, i: usize) -> Option<&ThermalNode> {
        self.thermal.get(i)
    }

    /// True alignments `M_AS` of FHST1, FHST2, FSS1, FSS2 (without thermal drift).
    #[must_use]
    pub fn true_alignments(&self) -> [Matrix3<f64>; 4] {
        [
            *self.fhst[0].m_acs_from_fhst_true(),
            *self.fhst[1].m_acs_from_fhst_true(),
            *self.fss[0].m_acs_from_fss_true(),
            *self.fss[1].m_acs_from_fss_true(),
        ]
    }

    /// HIP number of the star tracker `unit` (0 = FHST1) followed in its last sample, if any:
    /// the truth an onboard identification is scored against (wrong-star rate).
    #[must_use]
    pub fn tracked_star_id(&self, unit: usize) -> Option<u32> {
        let hip = self.fhst.get(unit)?.last_truth().hip;
        (hip != 0).then_some(hip)
    }

    /// Table images uplinked (or scheduled) in this run.
    #[must_use]
    pub fn uploads(&self) -> &[Upload] {
        &self.uploads
    }

    /// Number of cycles in the run (`duration_s / step_s`, rounded down, plus one for t = 0).
    #[must_use]
    pub fn cycle_count(&self) -> u64 {
        self.cycle_count
    }

    /// Shorten or lengthen the run (`--duration`).
    pub fn set_duration_s(&mut self, duration_s: f64) {
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let n = (duration_s.max(0.0) / self.scenario.step_s + 1e-9).floor() as u64;
        self.scenario.duration_s = duration_s;
        self.cycle_count = n + 1;
    }

    /// Time of the next cycle (s).
    #[must_use]
    pub fn t_s(&self) -> f64 {
        self.cycle as f64 * self.scenario.step_s
    }

    fn snapshot(&mut self, t_s: f64) -> TruthSnapshot {
        self.orbit.advance_to(t_s);
        let orbit = *self.orbit.state();
        let j2000_tt_s = self.clock.j2000_tt_s(t_s);
        let sun = self.sun.state(j2000_tt_s);
        let att = self.body.state();
        TruthSnapshot {
            t_s,
            j2000_tt_s,
            q_acs_from_eci: att.q_acs_from_eci,
            m_acs_from_eci: att.q_acs_from_eci.to_dcm(),
            rate_acs_rad_per_s: att.rate_acs_rad_per_s,
            pos_eci_km: orbit.pos_eci_km,
            vel_eci_km_per_s: orbit.vel_eci_km_per_s,
            earth_pos_bary_eci_km: sun.earth_pos_bary_eci_km,
            earth_vel_bary_eci_km_per_s: sun.earth_vel_bary_eci_km_per_s,
            sun_dir_app_eci: sun
                .apparent_dir_from_sc_eci(&orbit.pos_eci_km, &orbit.vel_eci_km_per_s),
            in_umbra: sun.in_umbra(&orbit.pos_eci_km),
        }
    }

    /// Run one cycle; `None` when the run is over.
    pub fn step(&mut self) -> Option<CycleRecord> {
        if self.cycle >= self.cycle_count {
            return None;
        }
        let dt = self.scenario.step_s;
        let t = self.t_s();
        let truth = self.snapshot(t);
        let mut temps = [0_i16; TEMPERATURE_SENSORS];
        let mut dev = [0.0; TEMPERATURE_SENSORS];
        for (i, node) in self.thermal.iter_mut().enumerate() {
            node.update(
                dt,
                &truth.pos_eci_km,
                &truth.sun_dir_app_eci,
                truth.in_umbra,
            );
            temps[i] = node.centi_c();
            dev[i] = node.deviation_c();
        }
        let mut fhst = [
            self.fhst[0].sample(&truth, &self.sky, dev[0]),
            self.fhst[1].sample(&truth, &self.sky, dev[1]),
        ];
        let mut fss = [
            self.fss[0].sample(&truth, dev[2]),
            self.fss[1].sample(&truth, dev[3]),
        ];
        let time_offset_s = self.apply_sensor_faults(t, &truth, &mut fhst, &mut fss);
        let (magnetics, tam, css) = self.sample_magnetics(&truth);
        let frame = RawSensorFrame {
            time: self.clock.time_tag(t + time_offset_s).unwrap_or_default(),
            iru: self.pending_iru,
            fhst,
            fss,
            temperatures_centi_c: temps,
            tam,
            css,
            wheels: self.sample_wheels(t),
        };

        // Commands due now (borrowing the images; at most MAX_COMMANDS_PER_CYCLE).
        let mut commands = [Command::Hold; MAX_COMMANDS_PER_CYCLE];
        let mut n = 0;
        while let Some((at, action)) = self.timeline.get(self.next_action) {
            if *at > t + 1e-9 || n >= MAX_COMMANDS_PER_CYCLE {
                break;
            }
            self.next_action += 1;
            let cmd = match action {
                Action::Slew(q) => {
                    self.current_target = *q;
                    Command::SlewTo(*q)
                }
                Action::SlewRelative(theta) => {
                    self.current_target = Quat::from_rotation_vector(theta)
                        .compose(&self.current_target)
                        .normalized();
                    Command::SlewTo(self.current_target)
                }
                Action::Hold => {
                    self.current_target = self.fsw.attitude();
                    Command::Hold
                }
                Action::SelectIru(c) => Command::SelectIruConfig(*c),
                Action::Load(i) => match self.uploads.get(*i) {
                    Some(up) => Command::TableLoad(&up.image),
                    None => continue,
                },
                Action::Activate(id) => Command::TableActivate(*id),
                Action::Abort(id) => Command::TableAbort(*id),
                Action::FilterInit(q) => {
                    let q = q.unwrap_or_else(|| {
                        self.error_rotation
                            .compose(&truth.q_acs_from_eci)
                            .normalized()
                    });
                    self.current_target = q;
                    Command::FilterInitialize(q)
                }
                Action::FilterReset => Command::FilterReset,
                Action::SunAcquire(axis) => Command::SunAcquire(*axis),
            };
            if let Some(slot) = commands.get_mut(n) {
                *slot = cmd;
                n += 1;
            }
        }
        let output = self.fsw.step(&frame, &commands[..n]);

        let (attitude_error_acs_rad, nees) = fine_check(
            &self.fsw,
            &truth.q_acs_from_eci,
            output.housekeeping.filter_mode,
        );
        self.advance_truth(dt, &truth, &magnetics, dev[4]);
        let record = CycleRecord {
            cycle: self.cycle,
            truth,
            frame,
            output,
            attitude_error_acs_rad,
            nees,
            commands_sent: n,
            magnetics,
            coarse: CoarseCheck::of(&self.fsw, &truth.q_acs_from_eci),
            torquer_dipole_am2: self
                .torquers
                .as_ref()
                .map_or([0.0; 3], TorquerBars::dipole_am2),
        };
        self.cycle += 1;
        Some(record)
    }

    /// Steps 4–5 of the module doc: the OBC's IRU rate mode to the IRU, its wheel torque and
    /// torquer-bar commands held over [t, t + dt] through the dynamics, and the IRU sample that
    /// closes the interval (`iru_deviation_c`: the IRU's thermal deviation).
    fn advance_truth(
        &mut self,
        dt: f64,
        truth: &TruthSnapshot,
        magnetics: &crate::magnetics::MagneticsRecord,
        iru_deviation_c: f64,
    ) {
        let t = truth.t_s;
        self.iru.command_high_rate(self.fsw.iru_high_rate_command());
        let torque = self.fsw.wheel_torque_command_nm();
        let magnetic_torque_acs_nm = self.drive_torquers(t, truth, magnetics);
        let report = self.body.step_with_external_torque(
            dt,
            &torque,
            &truth.pos_eci_km,
            &magnetic_torque_acs_nm,
        );
        self.pending_iru =
            self.iru
                .sample(&report.rate_integral_acs_rad, dt, t + dt, iru_deviation_c);
    }

    /// Drive the torquer bars with the OBC's dipole command (and the `torquer_stuck_on`
    /// faults) for the coming step and return their torque `m × B` on the body (ACS, N·m)
    /// in the truth field of this cycle; zero without bars or outside the field model.
    fn drive_torquers(
        &mut self,
        t_s: f64,
        truth: &TruthSnapshot,
        magnetics: &crate::magnetics::MagneticsRecord,
    ) -> Vector3<f64> {
        let Some(bars) = self.torquers.as_mut() else {
            return Vector3::zeros();
        };
        let stuck = FaultState::stuck_torquers(&self.faults, t_s);
        bars.command(&self.fsw.torquer_dipole_command_am2(), &stuck);
        magnetics
            .field_eci_nt
            .map_or_else(Vector3::zeros, |b_eci_nt| {
                let b_acs_tesla = truth.m_acs_from_eci * b_eci_nt * TESLA_PER_NT;
                magnetic_torque_nm(&bars.dipole_acs_am2(), &b_acs_tesla)
            })
    }

    /// The torquer bars (`None` unless `[dynamics] momentum_unloading = "bars"`).
    #[must_use]
    pub fn torquers(&self) -> Option<&TorquerBars> {
        self.torquers.as_ref()
    }
}

/// The IRU of a scenario with its `iru_channel_failure` and `iru_counter_wrap` faults.
fn iru_of(scenario: &Scenario, paper: &PaperFacts) -> anyhow::Result<Iru> {
    let mut iru = Iru::new(scenario.iru.clone(), paper, scenario.seed).map_err(InputError::from)?;
    for f in &scenario.faults {
        if let (FaultKind::IruChannelFailure, Some(ch)) = (f.kind, f.channel_index()) {
            iru.add_failure(ch, f.at_s, f.bit.unwrap_or(true));
        }
        if f.kind == FaultKind::IruCounterWrap {
            iru.preset_counters_to_wrap(f.at_s, f.margin_pulses.unwrap_or(40));
        }
    }
    Ok(iru)
}

/// The alignment table of the sensors' true alignments (`fly_true_alignments`, and the base
/// of a damaged `table_upload` then).
fn true_alignment_table(fhst: &[Fhst; 2], fss: &[Fss; 2]) -> fsw_core::tables::AlignmentTable {
    onboard::true_alignment_table(&[
        *fhst[0].m_acs_from_fhst_true(),
        *fhst[1].m_acs_from_fhst_true(),
        *fss[0].m_acs_from_fss_true(),
        *fss[1].m_acs_from_fss_true(),
    ])
}

/// The uplinks and the command timeline of a run, built in [`Simulation::new`]'s stages.
#[derive(Default)]
struct Schedule {
    uploads: Vec<Upload>,
    timeline: Vec<(f64, Action)>,
}

impl Schedule {
    /// Load the image at its time, and activate it when it names a table.
    fn push_upload(&mut self, up: Upload) {
        let id = onboard::image_table_id(&up.image);
        self.timeline
            .push((up.at_s, Action::Load(self.uploads.len())));
        if let Some(id) = id {
            self.timeline.push((up.at_s, Action::Activate(id)));
        }
        self.uploads.push(up);
    }

    /// Start-up uplinks: the star catalog, the scenario's filter table, the true alignments,
    /// the `--tables` folder, the orbit tables and magnetics table, and the filter
    /// initialisation.
    fn startup_uplinks(
        &mut self,
        scenario: &Scenario,
        clock: &SimClock,
        catalogue: &crate::data::CsvTable,
        true_alignments: &fsw_core::tables::AlignmentTable,
        tables_dir: Option<&std::path::Path>,
    ) -> anyhow::Result<()> {
        let created = clock.time_tag(0.0).unwrap_or_default();
        if scenario.uplink_catalog {
            let cat = onboard::build_star_catalog(catalogue, scenario, clock.j2000_tt_s(0.0))?;
            self.push_upload(Upload {
                source: format!(
                    "prelaunch ground system: Hipparcos {}-{} mag ({:?}), proper motion to the epoch, {} stars",
                    scenario.fhst1.magnitude_min,
                    scenario.fhst1.magnitude_max,
                    scenario.sky.magnitude_system,
                    cat.stars.len()
                ),
                name: "star_catalog.tbl".into(),
                image: onboard::image(TableId::StarCatalog, created, &cat)?,
                at_s: 0.0,
            });
        }
        if let Some(overrides) = &scenario.startup_filter_table() {
            let table = onboard::filter_table_with(overrides).map_err(InputError::from)?;
            self.push_upload(Upload {
                source: format!(
                    "scenario filter_table (boot values except {:?})",
                    overrides.keys().collect::<Vec<_>>()
                ),
                name: "filter.tbl".into(),
                image: onboard::image(TableId::Filter, created, &table)?,
                at_s: 0.0,
            });
        }
        if scenario.fly_true_alignments {
            self.push_upload(Upload {
                source: "true alignments (fly_true_alignments = true)".into(),
                name: "true_alignment.tbl".into(),
                image: onboard::image(TableId::Alignment, created, true_alignments)?,
                at_s: 0.0,
            });
        }
        if let Some(dir) = tables_dir {
            // The images the folder's manifest lists, checked (crate::manifest).
            let (tables, unlisted) = crate::manifest::read(dir)?;
            for f in &unlisted {
                eprintln!(
                    "warning: {} is not listed in {}: not loaded",
                    f.display(),
                    dir.join(crate::manifest::MANIFEST).display()
                );
            }
            for (f, _, image) in tables {
                self.push_upload(Upload {
                    source: f.display().to_string(),
                    name: f
                        .file_name()
                        .map_or_else(|| "table.tbl".into(), |n| n.to_string_lossy().into()),
                    image,
                    at_s: 0.0,
                });
            }
        }
        for up in ephemeris_uploads(scenario, clock, tables_dir)? {
            self.push_upload(up);
        }
        if scenario.initial_estimate.enabled {
            self.timeline.push((0.0, Action::FilterInit(None)));
        }
        Ok(())
    }

    /// The scenario's timeline (stable order for equal times).
    fn scenario_commands(&mut self, scenario: &Scenario, clock: &SimClock) -> anyhow::Result<()> {
        let created = clock.time_tag(0.0).unwrap_or_default();
        let mut order: Vec<usize> = (0..scenario.commands.len()).collect();
        order.sort_by(|&a, &b| {
            scenario.commands[a]
                .at_s
                .total_cmp(&scenario.commands[b].at_s)
                .then(a.cmp(&b))
        });
        for i in order {
            let c = &scenario.commands[i];
            let action = timeline_action(scenario, i, &mut self.uploads, created)?;
            self.timeline.push((c.at_s, action));
        }
        Ok(())
    }

    /// Faults that reach the OBC through the uplink ([`crate::faults`]).
    fn uplink_faults(
        &mut self,
        scenario: &Scenario,
        clock: &SimClock,
        true_alignments: &fsw_core::tables::AlignmentTable,
    ) -> anyhow::Result<()> {
        for (i, f) in scenario.faults.iter().enumerate() {
            match f.kind {
                FaultKind::TableUpload => {
                    let base = if scenario.fly_true_alignments {
                        *true_alignments
                    } else {
                        fsw_core::tables::AlignmentTable::prelaunch()
                    };
                    let created = clock.time_tag(f.at_s).unwrap_or_default();
                    let image = f.upload_image(&base, created)?;
                    let damage = f
                        .corruption
                        .map_or_else(|| "none".to_owned(), |c| format!("{c:?}").to_lowercase());
                    self.uploads.push(Upload {
                        source: format!("faults[{i}]: alignment image, damage {damage}"),
                        name: format!("fault{i}_{damage}_alignment.tbl"),
                        image,
                        at_s: f.at_s,
                    });
                    self.timeline
                        .push((f.at_s, Action::Load(self.uploads.len() - 1)));
                    if f.activate.unwrap_or(true) {
                        self.timeline
                            .push((f.at_s, Action::Activate(TableId::Alignment)));
                    }
                }
                FaultKind::FilterReset => self.timeline.push((f.at_s, Action::FilterReset)),
                _ => {}
            }
        }
        Ok(())
    }
}

/// The start-up uplinks of the tables the ground computes from ephemerides: the orbit table
/// (`[onboard_orbit]`, at its uplink times) and the magnetics table (`[magnetics]` with
/// `onboard_table`: the field model at the scenario epoch and the TAM knowledge the scenario
/// gives the OBC, `onboard::magnetics_table`) — unless the `--tables` folder holds a magnetics
/// table (the ground's, from its TAM calibration), which then flies instead. Pushed after the
/// `--tables` folder's uploads (at 0 s), so that the uploads are listed in load order (the
/// scorer and the ground match load events to them in order).
fn ephemeris_uploads(
    scenario: &Scenario,
    clock: &SimClock,
    tables_dir: Option<&std::path::Path>,
) -> anyhow::Result<Vec<Upload>> {
    let mut uploads = Vec::new();
    if let Some(uplink) = &scenario.onboard_orbit {
        for (k, at_s) in uplink
            .uplink_times_s(scenario.duration_s)
            .into_iter()
            .enumerate()
        {
            let epoch_t_s = at_s - uplink.state_age_s;
            let table = onboard::truth_orbit_table(scenario, clock, epoch_t_s, uplink)
                .map_err(InputError::from)?;
            uploads.push(Upload {
                source: format!(
                    "onboard orbit from the truth at t = {epoch_t_s} s (errors {:?} km, {:?} km/s)",
                    uplink.pos_error_km, uplink.vel_error_km_per_s
                ),
                name: format!("orbit_{k}.tbl"),
                image: onboard::image(
                    TableId::Orbit,
                    clock.time_tag(at_s).unwrap_or_default(),
                    &table,
                )?,
                at_s,
            });
        }
    }
    let folder_has_magnetics = match tables_dir {
        Some(dir) => crate::manifest::read(dir)?
            .0
            .iter()
            .any(|(_, _, image)| onboard::image_table_id(image) == Some(TableId::Magnetics)),
        None => false,
    };
    if folder_has_magnetics {
        if let Some(file) = &scenario.magnetics.onboard_table_file {
            eprintln!(
                "warning: the --tables folder holds a magnetics table: it flies instead of [magnetics] onboard_table_file = {file:?}"
            );
        }
        return Ok(uploads);
    }
    if let Some(file) = scenario
        .magnetics
        .onboard_table_file
        .as_deref()
        .filter(|_| scenario.magnetics.enabled && scenario.magnetics.onboard_table)
    {
        let path = scenario.resolve_file(file);
        let image = read_image(&path).map_err(InputError::from)?;
        if onboard::image_table_id(&image) != Some(TableId::Magnetics) {
            return Err(InputError::from(anyhow::anyhow!(
                "[magnetics] onboard_table_file {}: not a magnetics table image",
                path.display()
            ))
            .into());
        }
        uploads.push(Upload {
            source: format!("magnetics: the ground's table {}", path.display()),
            name: "magnetics.tbl".into(),
            image,
            at_s: scenario.magnetics.onboard_table_at_s,
        });
        return Ok(uploads);
    }
    if let Some((table, at_s)) = onboard::magnetics_table(scenario, clock)? {
        uploads.push(Upload {
            source: format!(
                "magnetics: DGRF 1990/1995 at the epoch, TAM bias {:?} mG (what the OBC is told)",
                table.tam_bias_milligauss
            ),
            name: "magnetics.tbl".into(),
            image: onboard::image(
                TableId::Magnetics,
                clock.time_tag(at_s).unwrap_or_default(),
                &table,
            )?,
            at_s,
        });
    }
    Ok(uploads)
}

/// The OBC command of timeline entry `i` (a table load also adds its image to `uploads`).
///
/// # Errors
/// A command the scenario's validation let through but that cannot be built (named).
fn timeline_action(
    scenario: &Scenario,
    i: usize,
    uploads: &mut Vec<Upload>,
    created: fsw_core::raw::TimeTag,
) -> anyhow::Result<Action> {
    let Some(c) = scenario.commands.get(i) else {
        anyhow::bail!("commands[{i}] does not exist");
    };
    let here = format!("commands[{i}]");
    let action = match c.kind {
        CommandKind::SlewTo => match (c.q_acs_from_eci, &c.axis, c.angle_deg) {
            (Some(q), _, _) => Action::Slew(quat_from_array(q)),
            (None, Some(axis), Some(angle)) => Action::SlewRelative(
                body_axis_from_name(axis)
                    .with_context(|| format!("{here}.axis"))
                    .map_err(InputError::from)?
                    * angle.to_radians(),
            ),
            _ => {
                return Err(InputError::msg(format!(
                    "{here}: slew_to needs q_acs_from_eci or axis + angle_deg"
                ))
                .into())
            }
        },
        CommandKind::Hold => Action::Hold,
        CommandKind::SelectIruConfig => {
            Action::SelectIru(if c.config.as_deref() == Some("backup") {
                IruConfiguration::Backup
            } else {
                IruConfiguration::Primary
            })
        }
        CommandKind::FilterInitialize => Action::FilterInit(c.q_acs_from_eci.map(quat_from_array)),
        CommandKind::FilterReset => Action::FilterReset,
        CommandKind::SunAcquire => {
            Action::SunAcquire(c.sun_axis_acs.ok_or_else(|| {
                InputError::msg(format!("{here}: sun_acquire needs sun_axis_acs"))
            })?)
        }
        CommandKind::TableLoad if c.filter_table.is_some() => {
            let table = c
                .filter_table_image_fields(scenario)
                .with_context(|| format!("{here}.filter_table"))
                .map_err(InputError::from)?
                .unwrap_or_else(fsw_core::tables::types::FilterTable::default_boot);
            let keys: Vec<&String> = c.filter_table.iter().flat_map(|t| t.keys()).collect();
            uploads.push(Upload {
                source: format!("scenario {here}.filter_table (fields {keys:?})"),
                name: "filter.tbl".into(),
                image: onboard::image(TableId::Filter, created, &table)?,
                at_s: c.at_s,
            });
            Action::Load(uploads.len() - 1)
        }
        CommandKind::TableLoad => {
            let name = c.file.as_deref().unwrap_or_default();
            let path = scenario.resolve_file(name);
            let image = read_image(&path)
                .with_context(|| format!("{here}.file"))
                .map_err(InputError::from)?;
            uploads.push(Upload {
                source: path.display().to_string(),
                name: path
                    .file_name()
                    .map_or_else(|| "table.tbl".into(), |n| n.to_string_lossy().into()),
                image,
                at_s: c.at_s,
            });
            Action::Load(uploads.len() - 1)
        }
        CommandKind::TableActivate | CommandKind::TableAbort => {
            let id = table_id_from_name(c.table.as_deref().unwrap_or_default())
                .with_context(|| format!("{here}.table"))
                .map_err(InputError::from)?;
            if c.kind == CommandKind::TableActivate {
                Action::Activate(id)
            } else {
                Action::Abort(id)
            }
        }
    };
    Ok(action)
}

/// Read a table image file, checking its header names a known table.
///
/// # Errors
/// I/O errors or a file that is not a table image.
pub fn read_image(path: &std::path::Path) -> anyhow::Result<Vec<u8>> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    fsw_core::tables::image::parse_image(&bytes)
        .map_err(|e| anyhow::anyhow!("{} is not a valid table image: {e}", path.display()))?;
    Ok(bytes)
}
