//! e2e: fault injection in the closed loop (issue 7, "Must have 1").
//!
//! One test per `scenarios/faults/*.toml`; each checks the OBC behaviour written at the top of
//! its scenario: no panic (the run completes), the events and counters an operator would see,
//! the attitude error (truth vs OBC estimate) bounded during the fault and back inside the
//! fine requirement after it, and the active tables unchanged unless a valid table was
//! activated. `sim_harness::faults::assess` flies each scenario twice, with and without its
//! faults (same seed), so "bounded" is stated against the fault-free run.
//!
//! Requirement used: every axis of `δθ` (`A_true = Rot(δθ) Â`) inside 0.024° = 86.4″ at every
//! cycle (the paper's 0.024° 3σ fine requirement applied to the instantaneous error, which is
//! stricter than 3σ). Recovery = the first time after the fault end from which every later
//! cycle of the run meets it.
//!
//! Durations: the dropout test flies a 1800 s dropout (the scenario file has the full 5700 s
//! orbit, measured by `sim-harness faults`); the others fly their scenario files unchanged.

use fsw_core::events::EventId;
use fsw_core::tables::TableId;
use fsw_core::telemetry::MeasurementStatus;
use sim_harness::closed_loop::{CycleRecord, Simulation};
use sim_harness::faults::{assess, FaultKind, FaultReport, FINE_REQUIREMENT_ARCSEC};
use sim_harness::scenario::Scenario;

fn load(name: &str) -> Scenario {
    let path = sim_harness::scenario::scenarios_dir()
        .join("faults")
        .join(format!("{name}.toml"));
    Scenario::load(&path).unwrap_or_else(|e| panic!("{}: {e:#}", path.display()))
}

/// Every cycle of a run (the events, housekeeping and error are all we look at).
fn fly(s: &Scenario) -> (Vec<CycleRecord>, Simulation) {
    let mut sim = Simulation::new(s.clone(), None).unwrap();
    let mut out = Vec::new();
    while let Some(r) = sim.step() {
        out.push(r);
    }
    (out, sim)
}

fn events_of(recs: &[CycleRecord], id: EventId) -> Vec<(f64, u32, u32)> {
    recs.iter()
        .flat_map(|r| {
            r.output
                .events
                .iter()
                .filter(move |e| e.id == id)
                .map(move |e| (r.truth.t_s, e.p1, e.p2))
        })
        .collect()
}

fn axis_arcsec(r: &CycleRecord) -> f64 {
    r.attitude_error_acs_rad.amax() * fsw_core::units::ARCSEC_PER_RAD
}

/// Common checks: recovered, inside the requirement after the recovery, the tables'
/// dumps unchanged (unless `tables_may_change`).
fn common(r: &FaultReport, tables_may_change: bool) {
    println!("{r:#?}");
    let at = r
        .recovery
        .recovered_at_s
        .unwrap_or_else(|| panic!("{}: never back inside 86.4″/axis", r.scenario));
    assert!(at >= r.fault_end_s);
    assert!(
        r.after_recovery_worst_axis_error_arcsec < FINE_REQUIREMENT_ARCSEC,
        "{}",
        r.scenario
    );
    if !tables_may_change {
        assert!(r.tables.tables_unchanged, "{}: tables changed", r.scenario);
        assert_eq!(r.tables.table_crc_before, r.tables.table_crc_after);
        assert_eq!(r.tables.tables_activated, 0);
    }
}

/// The scenario `name` of `scenarios/faults/` assessed (flown with and without its faults) and
/// the common checks applied.
fn assessed(name: &str, tables_may_change: bool) -> (Scenario, FaultReport) {
    let s = load(name);
    let r = assess(&s).unwrap();
    common(&r, tables_may_change);
    (s, r)
}

/// Every cycle of the same scenario flown without its faults.
fn fly_without_faults(s: &Scenario) -> Vec<CycleRecord> {
    let mut clean = s.clone();
    clean.faults.clear();
    fly(&clean).0
}

/// The attitude error bit-identical at every cycle of `a` and `b` before `until_s`.
fn assert_same_attitude(a: &[CycleRecord], b: &[CycleRecord], until_s: f64) {
    for (a, b) in a.iter().zip(b).take_while(|(a, _)| a.truth.t_s < until_s) {
        assert_eq!(
            a.attitude_error_acs_rad, b.attitude_error_acs_rad,
            "t = {}",
            a.truth.t_s
        );
    }
}

/// Channel Y1 excluded at 900 s for `reasons` (`fsw_core::iru::EXCLUDED_*`), the switch to
/// the backup triad in the same cycle, and no more unusable IRU cycles than without the fault.
fn assert_y1_excluded_and_backup(recs: &[CycleRecord], r: &FaultReport, reasons: u32) {
    assert_eq!(
        events_of(recs, EventId::IruChannelExcluded),
        vec![(900.0, 2, reasons)]
    );
    assert_eq!(
        events_of(recs, EventId::IruConfigSwitched),
        vec![(900.0, 1, 1)]
    );
    assert_unusable_cycles_unchanged(r);
}

fn assert_unusable_cycles_unchanged(r: &FaultReport) {
    assert_eq!(
        r.counters.iru_unusable_cycles,
        r.baseline_counters.iru_unusable_cycles
    );
}

/// Both FHSTs dark for 2400 s (scenario: 5700 s): coarse mode after 900 cycles, fine again at
/// the first star after the dropout (trackers back at
/// 3600 s, when the fault-free run has stars), the error inside the requirement throughout.
#[test]
fn e2e_fault_fhst_dropout() {
    let mut s = load("fhst-dropout-orbit");
    s.faults[0].duration_s = Some(2400.0);
    s.duration_s = 4800.0;
    let r = assess(&s).unwrap();
    common(&r, false);
    let modes: Vec<(f64, u32)> = r
        .trace
        .windows(2)
        .filter(|w| w[0].2 != w[1].2)
        .map(|w| (w[1].0, u32::from(w[1].2)))
        .collect();
    // Coarse 900 cycles after the last star before the dropout, fine at most 60 s after it.
    let coarse = modes.iter().find(|(t, m)| *m == 1 && *t >= 1200.0).unwrap();
    assert!(coarse.0 >= 2000.0 && coarse.0 <= 2101.0, "{modes:?}");
    let fine = modes
        .iter()
        .find(|(t, m)| *m == 2 && *t > coarse.0)
        .unwrap();
    assert!(fine.0 >= 3600.0 && fine.0 <= 3660.0, "{modes:?}");
    assert!(r
        .events
        .iter()
        .any(|(n, a, _)| n == "FilterModeChanged" && *a >= 2));
    // Gyro + FSS: bounded well inside the requirement (measured 39″ for an
    // orbit).
    assert!(r.worst_axis_error_arcsec < FINE_REQUIREMENT_ARCSEC);
    assert!(r.worst_axis_error_arcsec > r.baseline_worst_axis_error_arcsec); // the fault did bite
    assert_eq!(r.recovery.recovery_s, Some(0.0));
}

/// FHST1 silently reports another catalogue star: gated, attitude held by FHST2.
#[test]
fn e2e_fault_fhst_wrong_star() {
    let (s, r) = assessed("fhst-wrong-star", false);
    let (recs, _) = fly(&s);
    let (t0, t1) = (s.faults[0].at_s, s.faults[0].end_s());
    let gated_events = events_of(&recs, EventId::MeasurementGated);
    assert!(
        gated_events
            .iter()
            .any(|(t, p1, _)| *p1 == 0 && (t0..=t1).contains(t)),
        "{gated_events:?}"
    );
    let gated_fhst1 = recs
        .iter()
        .filter(|r| (t0..t1).contains(&r.truth.t_s))
        .filter(|r| r.output.housekeeping.residuals[0].status == MeasurementStatus::Gated)
        .count();
    // Every sample of the window but the first few (the tracker's own gaps) is gated.
    assert!(gated_fhst1 >= 200, "{gated_fhst1}");
    // The gated counter counts them. (Compared with the total, not with the excess over the
    // fault-free run: that run's own few gated samples, 3 with the covariance of issue 19,
    // need not recur after the fault has changed the trajectory: 239 < 240.)
    let gated_total = r.counters.gated_measurements;
    assert!(
        gated_total as usize >= gated_fhst1,
        "{gated_total} < {gated_fhst1}"
    );
    // The wrong star moves the attitude by less than 3″ more than the fault-free run does.
    assert!(
        r.worst_axis_error_arcsec <= r.baseline_worst_axis_error_arcsec + 3.0,
        "{} vs {}",
        r.worst_axis_error_arcsec,
        r.baseline_worst_axis_error_arcsec
    );
    assert_eq!(r.recovery.recovery_s, Some(0.0));
}

/// FHST1 reports a spurious new star 0.3° off: refused by the identification (the window from
/// the covariance, issue 19) or identified and then gated or refused after its first gated
/// samples; no displaced sample is used.
#[test]
fn e2e_fault_fhst_offset_star() {
    let (s, r) = assessed("fhst-offset-star", false);
    let (recs, _) = fly(&s);
    let id_at_900 = recs
        .iter()
        .find(|r| (r.truth.t_s - 900.0).abs() < 0.5)
        .unwrap()
        .output
        .events
        .iter()
        .any(|e| e.p1 == 0 && matches!(e.id, EventId::StarIdentified | EventId::StarIdFailed));
    assert!(
        id_at_900,
        "the spurious acquisition was not (re-)identified"
    );
    let refused = |id| {
        events_of(&recs, id)
            .iter()
            .any(|(t, p1, _)| *p1 == 0 && (900.0..=1140.0).contains(t))
    };
    assert!(refused(EventId::MeasurementGated) || refused(EventId::StarIdFailed));
    let used = recs
        .iter()
        .filter(|r| (901.0..1140.0).contains(&r.truth.t_s))
        .filter(|r| r.output.housekeeping.residuals[0].status == MeasurementStatus::Accepted)
        .count();
    assert_eq!(used, 0, "a displaced FHST1 sample was accepted");
    assert!(r.worst_axis_error_arcsec <= r.baseline_worst_axis_error_arcsec + 3.0);
    assert_eq!(r.recovery.recovery_s, Some(0.0));
}

/// The spurious star over offsets from 18″ to 2°: the attitude stays inside the requirement
/// whatever the offset. Small offsets (2–3σ of the FHST noise) pass the χ² gate and pull the
/// attitude (measured worst 12.8″ at 0.01°; 30″ at 0.02° before the track confirmation of
/// issue 19, now 4.9″); from 0.02° the track is refused after its first gated samples, from
/// ~0.03° the identification (window from the covariance, ≥ 120″) fails, beyond the field
/// edge the input is rejected.
#[test]
fn e2e_fault_fhst_offset_sweep() {
    let base = load("fhst-offset-star");
    for off_deg in [0.005, 0.01, 0.02, 0.025, 0.03, 0.1, 0.6, 1.0, 2.0] {
        let mut s = base.clone();
        s.faults[0].offset_deg = Some([off_deg, 0.0]);
        let r = assess(&s).unwrap();
        println!(
            "offset {off_deg}°: worst {:.1}″ (fault-free {:.1}″), events {:?}",
            r.worst_axis_error_arcsec, r.baseline_worst_axis_error_arcsec, r.fault_events
        );
        assert!(
            r.worst_axis_error_arcsec < 0.5 * FINE_REQUIREMENT_ARCSEC,
            "offset {off_deg}°: {}″",
            r.worst_axis_error_arcsec
        );
        assert_eq!(r.recovery.recovery_s, Some(0.0));
        assert!(r.tables.tables_unchanged);
        if off_deg >= 0.03 {
            // Gated, rejected or unidentified: never pulls the attitude by more than 3″.
            assert!(r.worst_axis_error_arcsec <= r.baseline_worst_axis_error_arcsec + 3.0);
            assert!(!r.fault_events.is_empty(), "offset {off_deg}°: no event");
        }
    }
}

/// FSS2 glint in fine mode (no effect, visible in the innovation) and in coarse mode (gated).
#[test]
fn e2e_fault_fss_glint() {
    let (s, r) = assessed("fss-glint", false);
    let (recs, _) = fly(&s);
    // Glint 1, fine mode: the attitude is bit-identical to a run without any fault until the
    // dropout starts, and the FSS2 innovation shows the 0.5°/−0.3° outlier (2000″ class).
    assert_same_attitude(&recs, &fly_without_faults(&s), 1300.0);
    let glint1 = recs
        .iter()
        .find(|r| (r.truth.t_s - 1205.0).abs() < 0.5)
        .unwrap();
    let nu = glint1.output.housekeeping.residuals[3].innovation_arcsec;
    assert!(nu[0].abs() > 1500.0 && nu[1].abs() > 800.0, "{nu:?}");
    // Glint 2, coarse mode: gated every cycle, never accepted, MeasurementGated(3).
    let window: Vec<_> = recs
        .iter()
        .filter(|r| (3000.0..3020.0).contains(&r.truth.t_s))
        .collect();
    assert!(window
        .iter()
        .all(|r| r.output.housekeeping.filter_mode == 1));
    let gated = window
        .iter()
        .filter(|r| r.output.housekeeping.residuals[3].status == MeasurementStatus::Gated)
        .count();
    assert_eq!(gated, window.len());
    assert!(events_of(&recs, EventId::MeasurementGated)
        .iter()
        .any(|(t, p1, _)| *p1 == 3 && (3000.0..3020.0).contains(t)));
    // Not pulled: within 3″ of the same run without the glints.
    let mut dropout_only = s.clone();
    dropout_only
        .faults
        .retain(|f| f.kind == FaultKind::FhstDropout);
    let (ref_recs, _) = fly(&dropout_only);
    let worst = |v: &[CycleRecord]| {
        v.iter()
            .filter(|r| (3000.0..3100.0).contains(&r.truth.t_s))
            .map(axis_arcsec)
            .fold(0.0, f64::max)
    };
    assert!(worst(&recs) <= worst(&ref_recs) + 3.0);
    assert!(r.worst_axis_error_arcsec < FINE_REQUIREMENT_ARCSEC);
}

/// The coarse attitude's inputs fail (issue 20): a dead TAM1 is refused on its magnitude and
/// a TAM1 bias jump by the gate, TAM2 takes over each time, and a CSS glint while the FSSs see
/// the Sun changes nothing; the fine attitude is bit-identical to the fault-free run.
#[test]
fn e2e_fault_magnetics() {
    let (s, _) = assessed("magnetics", false);
    let (recs, _) = fly(&s);
    let clean_recs = fly_without_faults(&s);
    assert_same_attitude(&recs, &clean_recs, f64::INFINITY);
    let rejected = events_of(&recs, EventId::CoarseVectorRejected);
    println!("{rejected:?}");
    assert!(rejected
        .iter()
        .any(|(t, p1, _)| *p1 == 1 && (1500.0..2700.0).contains(t)));
    assert!(rejected
        .iter()
        .any(|(t, p1, _)| *p1 == 3 && (3000.0..3600.0).contains(t)));
    assert!(!rejected.iter().any(|(_, p1, _)| *p1 == 4));
    assert!(events_of(&clean_recs, EventId::CoarseVectorRejected).is_empty());
    // The unloading's bars-off check sees TAM1's jump against the model on TAM1 alone (a TAM
    // fault, not a bar: p1 = 1); the dead TAM1 is refused before it (implausible magnitude).
    let unexpected = events_of(&recs, EventId::TorquerFieldUnexpected);
    println!("0x0A01: {unexpected:?}");
    assert!(unexpected.iter().all(|(_, p1, _)| *p1 == 1));
    assert!(events_of(&clean_recs, EventId::TorquerFieldUnexpected).is_empty());
    // During the faults the coarse attitude keeps the 2° (3σ) requirement per axis and stays
    // within 3σ of its own covariance at every cycle.
    assert_coarse_holds(&recs, 1500.0..3600.0);
}

/// In the window the coarse attitude keeps the 2° (3σ) requirement per axis (3×RMS) and every
/// cycle stays within 3σ of its own covariance.
fn assert_coarse_holds(recs: &[CycleRecord], window: std::ops::Range<f64>) {
    let during: Vec<_> = recs
        .iter()
        .filter(|r| window.contains(&r.truth.t_s))
        .filter_map(|r| r.coarse)
        .collect();
    assert!(during.len() > 1000, "{}", during.len());
    for axis in 0..3 {
        let ms = during
            .iter()
            .map(|c| c.error_acs_rad[axis].powi(2))
            .sum::<f64>()
            / during.len() as f64;
        let three_rms_deg = 3.0 * ms.sqrt().to_degrees();
        println!("axis {axis}: 3×RMS {three_rms_deg:.3}°");
        assert!(three_rms_deg <= 2.0, "axis {axis}: {three_rms_deg}°");
    }
    let outside = during
        .iter()
        .filter(|c| (0..3).any(|i| c.error_acs_rad[i].abs() > 3.0 * c.sigma_acs_rad[i]))
        .count();
    assert_eq!(outside, 0);
}

/// Gyro channel Y1 fails mid-slew: excluded, automatic switch to the backup triad, no gyro
/// cycle lost, and — with the bias covariance reopened at the switch — the filter re-learns
/// the backup biases after the slew instead of gating the stars.
#[test]
fn e2e_fault_iru_channel_failure_mid_slew() {
    let (s, r) = assessed("iru-channel-failure-mid-slew", false);
    let (recs, sim) = fly(&s);
    assert_y1_excluded_and_backup(
        &recs,
        &r,
        fsw_core::iru::EXCLUDED_FAILED | fsw_core::iru::EXCLUDED_STUCK,
    );
    let hk = &recs.last().unwrap().output.housekeeping;
    assert_eq!(hk.iru_config, 1);
    assert_ne!(hk.iru_excluded_mask & 0x04, 0);
    assert_eq!(
        sim.fsw().filter_mode(),
        fsw_core::executive::FilterMode::Fine
    );
    // The slew ends well inside the 0.5° identification window (measured 0.13°).
    assert_eq!(r.post_slew_error_arcsec.len(), 1);
    assert!(r.post_slew_error_arcsec[0] < 0.5 * 3600.0);
    // Back inside 86.4″/axis within 25 min of the failure (the slew itself takes 10 of them;
    // measured 1333 s; the fault-free run 601 s, one cycle after its slew). Without the bias
    // reopening it never came back (590″ at the end).
    let rec = r.recovery.recovery_s.unwrap();
    let base = r.recovery.baseline_recovery_s.unwrap();
    assert!(rec <= 1500.0, "{rec} (no fault: {base})");
    assert!(r
        .final_three_rms_arcsec
        .iter()
        .all(|x| *x < 3.0 * FINE_REQUIREMENT_ARCSEC));
}

/// Gyro channel Y1 sticks silently (no built-in-test bit) mid-slew: the pair cross-check
/// excludes it in the same cycle, and the rest is as for the reported failure.
#[test]
fn e2e_fault_iru_stuck_channel_mid_slew() {
    let (s, r) = assessed("iru-stuck-channel-mid-slew", false);
    let (recs, _) = fly(&s);
    // No BIT bit anywhere in the raw frames: the OBC found it by itself.
    assert!(recs.iter().all(|r| r.frame.iru.channel_failed == 0));
    assert_y1_excluded_and_backup(&recs, &r, fsw_core::iru::EXCLUDED_STUCK);
    // Identical figures to the reported failure (same cycle, same switch).
    let reported = assess(&load("iru-channel-failure-mid-slew")).unwrap();
    assert_eq!(r.worst_axis_error_arcsec, reported.worst_axis_error_arcsec);
    assert!(r.post_slew_error_arcsec[0] < 0.5 * 3600.0);
    assert!(r.recovery.recovery_s.unwrap() <= 1500.0);
}

/// The counters wrap at high rate: nothing for the OBC to notice, the attitude is identical
/// to the run whose counters do not wrap there.
#[test]
fn e2e_fault_iru_counter_wrap() {
    let (s, r) = assessed("iru-counter-wrap", false);
    let (recs, _) = fly(&s);
    // Wraps seen in the raw counters (a step whose u16 difference and i16 reading disagree
    // in sign); in the high-rate frames, the X channels wrap at least 4 times.
    let mut wraps = [0_u32; 6];
    let mut wraps_high = [0_u32; 6];
    for w in recs.windows(2) {
        for ch in 0..6 {
            let (a, b) = (w[0].frame.iru.counts[ch], w[1].frame.iru.counts[ch]);
            let d = b.wrapping_sub(a) as i16;
            let wrapped = (d > 0 && b < a) || (d < 0 && b > a);
            if wrapped {
                wraps[ch] += 1;
                if w[1].frame.iru.high_rate {
                    wraps_high[ch] += 1;
                }
            }
        }
    }
    println!("wraps {wraps:?}, at high rate {wraps_high:?}");
    assert!(wraps.iter().all(|w| *w >= 1), "{wraps:?}");
    assert!(wraps_high[0] >= 4 && wraps_high[1] >= 4, "{wraps_high:?}");
    for id in [EventId::IruChannelExcluded, EventId::IruDataUnusable] {
        assert!(
            events_of(&recs, id).iter().all(|(t, _, _)| *t == 0.0),
            "{id:?} after t = 0"
        );
    }
    assert_unusable_cycles_unchanged(&r);
    // Identical attitude history with and without the wraps (only differences are read).
    let clean_recs = fly_without_faults(&s);
    assert_eq!(recs.len(), clean_recs.len());
    assert_same_attitude(&recs, &clean_recs, f64::INFINITY);
    // Back inside the requirement within 25 min of the slew start (slew ~13 min).
    assert!(r.recovery.recovery_s.unwrap() <= 1500.0);
}

/// The clock jumps +1000 s, then one frame glitches back: three TimeTagAnomaly, nominal
/// period used, attitude undisturbed.
#[test]
fn e2e_fault_time_tag_jump() {
    let (s, r) = assessed("time-tag-jump", false);
    let (recs, _) = fly(&s);
    let ev: Vec<f64> = events_of(&recs, EventId::TimeTagAnomaly)
        .iter()
        .map(|e| e.0)
        .collect();
    assert_eq!(ev, vec![900.0, 1500.0, 1501.0]);
    assert_eq!(r.counters.time_tag_anomalies, 3);
    assert_eq!(r.baseline_counters.time_tag_anomalies, 0);
    assert!(r.worst_axis_error_arcsec <= r.baseline_worst_axis_error_arcsec + 1.0);
    assert_eq!(r.recovery.recovery_s, Some(0.0));
}

/// Damaged alignment uploads are refused for their reasons, activation then finds nothing,
/// the active tables do not change until a valid image is activated, which then is the dump.
#[test]
fn e2e_fault_table_uploads() {
    let (s, r) = assessed("table-uploads", true);
    let mut sim = Simulation::new(s.clone(), None).unwrap();
    let mut buf = vec![0_u8; 1 << 17];
    let dump = |sim: &Simulation, buf: &mut Vec<u8>| -> Vec<Vec<u8>> {
        TableId::ALL
            .iter()
            .map(|id| {
                let n = sim.fsw().tables().dump(*id, buf).unwrap();
                buf[..n].to_vec()
            })
            .collect()
    };
    let mut before = None;
    let mut rejected = Vec::new();
    let mut activate_failed = 0;
    let mut activated = Vec::new();
    while let Some(rec) = sim.step() {
        let t = rec.truth.t_s;
        if (t - 899.0).abs() < 0.5 {
            before = Some((dump(&sim, &mut buf), sim.fsw().tables().status()));
        }
        for e in &rec.output.events {
            match e.id {
                EventId::TableRejected if t > 0.0 => rejected.push((t, e.p1, e.p2)),
                EventId::TableActivateFailed => {
                    assert_eq!((e.p1, e.p2), (1, 0));
                    activate_failed += 1;
                }
                EventId::TableActivated if t > 0.0 => activated.push((t, e.p1, e.p2)),
                _ => {}
            }
        }
        if (900.0..2100.0).contains(&t) {
            let (d, st) = before.as_ref().unwrap();
            assert_eq!(&dump(&sim, &mut buf), d, "tables changed at {t}");
            for (now, then) in sim.fsw().tables().status().iter().zip(st) {
                assert_eq!(
                    (
                        now.active_crc,
                        now.active_created,
                        now.activations,
                        now.pending
                    ),
                    (
                        then.active_crc,
                        then.active_created,
                        then.activations,
                        false
                    ),
                    "active table status changed at {t}"
                );
            }
        }
    }
    assert_eq!(
        rejected,
        vec![
            (900.0, 1, 9),
            (1200.0, 1, 8),
            (1500.0, 1, 15),
            (1800.0, 1, 12)
        ]
    );
    assert_eq!(activate_failed, 4);
    let valid = sim.uploads().last().unwrap();
    let crc = stored_crc(&valid.image);
    assert_eq!(activated, vec![(2100.0, 1, crc)]);
    let after = dump(&sim, &mut buf);
    assert_eq!(
        after[0], valid.image,
        "alignment dump = the activated image"
    );
    let (d, _) = before.unwrap();
    assert_eq!(&after[1..], &d[1..], "other tables unchanged");
    assert_eq!(r.tables.tables_activated, 1);
    assert!(r.worst_axis_error_arcsec <= r.baseline_worst_axis_error_arcsec + 1.0);
    assert_eq!(r.recovery.recovery_s, Some(0.0));
}

/// The CRC-32 field of an image (its last 4 octets, big-endian; docs/tables.md), which the
/// OBC reports in `TableActivated` and in the housekeeping table status.
fn stored_crc(image: &[u8]) -> u32 {
    u32::from_be_bytes(image[image.len() - 4..].try_into().unwrap())
}

/// A filter reset mid-slew: the estimate is kept, the covariance reopens, the stars after the
/// slew are accepted at once and the error comes back inside the requirement.
#[test]
fn e2e_fault_filter_reset_mid_slew() {
    let (s, r) = assessed("filter-reset-mid-slew", false);
    let (recs, _) = fly(&s);
    assert_eq!(
        events_of(&recs, EventId::FilterReset)
            .iter()
            .map(|e| e.0)
            .collect::<Vec<_>>(),
        vec![900.0]
    );
    let clean_recs = fly_without_faults(&s);
    let at = |v: &[CycleRecord], t: f64| {
        v.iter()
            .find(|r| (r.truth.t_s - t).abs() < 0.5)
            .unwrap()
            .clone()
    };
    // The reset keeps the estimate: the error at the reset cycle is the fault-free one.
    let (a, b) = (at(&recs, 900.0), at(&clean_recs, 900.0));
    assert!((a.attitude_error_acs_rad - b.attitude_error_acs_rad).amax() * 206_264.8 < 0.1);
    // ... and reopens the covariance to the table's 1° (telemetered diagonal).
    let p = a.output.housekeeping.covariance_diag[0].sqrt().to_degrees();
    assert!((0.9..1.1).contains(&p), "σ_θ after reset {p}°");
    // After the slew: stars identified and the error back inside 86.4″/axis within 25 min of
    // the reset (measured 1336 s; the fault-free run 601 s, one cycle after its slew).
    assert!(events_of(&recs, EventId::StarIdentified)
        .iter()
        .any(|e| e.0 > 1500.0));
    let rec = r.recovery.recovery_s.unwrap();
    let base = r.recovery.baseline_recovery_s.unwrap();
    assert!(rec <= 1500.0, "{rec} (no fault: {base})");
    assert!(r.post_slew_error_arcsec[0] < 0.5 * 3600.0);
}

/// A torquer bar stuck on (issue 20): the OBC's bars-off check sees the unexpected field at
/// both TAMs on its blanked samples and raises 0x0A01 once (p1 = 3: both TAMs), within 60 s;
/// nothing of the kind in the fault-free run; the fine attitude stays inside the requirement
/// and the wheels below their limit while the bar is stuck.
#[test]
fn e2e_fault_torquer_stuck_on() {
    let s = load("torquer-stuck-on");
    assert!(s.faults.iter().any(|f| f.kind == FaultKind::TorquerStuckOn));
    let r = assess(&s).unwrap();
    common(&r, false);
    let (recs, _) = fly(&s);
    let mut clean = s.clone();
    clean.faults.clear();
    let (clean_recs, _) = fly(&clean);
    let unexpected = events_of(&recs, EventId::TorquerFieldUnexpected);
    println!("0x0A01: {unexpected:?}");
    assert_eq!(unexpected.len(), 1, "{unexpected:?}");
    let (t, mask, tenths_mg) = unexpected[0];
    assert!((1200.0..1260.0).contains(&t), "{t}");
    assert_eq!(mask, 3);
    // ≈ 100 mG of bar field (1,000 A·m² × 0.1 mG per A·m²), well above the 20-mG threshold.
    assert!((500..2000).contains(&tenths_mg), "{tenths_mg}");
    assert!(events_of(&clean_recs, EventId::TorquerFieldUnexpected).is_empty());
    // The bar really was stuck, and the OBC kept commanding the others.
    let stuck: Vec<_> = recs
        .iter()
        .filter(|r| (1300.0..3000.0).contains(&r.truth.t_s))
        .collect();
    assert!(stuck.iter().all(|r| r.torquer_dipole_am2[1] == 1000.0));
    let worst = stuck.iter().map(|r| axis_arcsec(r)).fold(0.0, f64::max);
    println!("worst axis error while stuck: {worst:.1}″");
    assert!(worst < FINE_REQUIREMENT_ARCSEC, "{worst}");
    // The coarse fix refuses the TAM samples taken with the stuck bar driven (their flag says
    // so although the bars were blanked: 0x0903 p1 = 5 / 6) instead of fixing on a field
    // 100 mG off (15° of error, NEES 643, before that check), and the coarse attitude holds.
    let refused = events_of(&recs, EventId::CoarseVectorRejected);
    assert!(
        refused.iter().any(|(_, kind, _)| matches!(kind, 5 | 6)),
        "{refused:?}"
    );
    assert_coarse_holds(&recs, 1300.0..3000.0);
}
