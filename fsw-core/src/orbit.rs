//! # The onboard orbit: an uplinked state vector propagated with J2, fixed-step RK4
//!
//! Why: the orbital part of the velocity aberration (≤ 5.2″) needs the spacecraft's
//! velocity, and the Sun seen from the spacecraft (parallax ≤ 9.5″) its position
//! (algorithms.md §3.3). The ground determines the orbit from tracking and uplinks a state
//! vector at an epoch (the orbit table, `docs/tables.md` Table 5); the OBC propagates it.
//!
//! ## Model
//! Point mass plus J2, J2000/GCRS axes, the J2 axis taken as the J2000 pole, no drag: the
//! simulator's truth orbit (`sim-harness/src/truth/orbit.rs`) with the same constants, each
//! cited below (EGM96 / WGS 84, the SI speed of light, the IAU 2012 astronomical unit).
//! What the velocity aberration needs is lax: 1 m/s of velocity error is 0.0007″ of
//! aberration, 1 km of position error 0.0014″ of Sun parallax. A real orbit has drag and
//! higher harmonics the model leaves out (kilometres per day at GRO's 450 km): the ground
//! uplinks a fresh state at least every [`MAX_STATE_AGE_S`].
//!
//! ## Integration (project choice)
//! Classical RK4 on a fixed grid `epoch + k·`[`STEP_S`] (10 s, the truth's largest step):
//! the grid state does not depend on when the cycles fall, so two OBCs fed the same table
//! and times agree bit for bit. The state at the cycle time `t` (between two grid points)
//! is one more RK4 step of length `t − t_k < STEP_S` from the grid state, not stored.
//! Accuracy against the truth orbit (test `est_orbit`): velocity error well under the
//! 1 m/s-per-day requirement (the measured figures are in `docs/obc_filter.md` §7).
//!
//! ## Bounded work, catching up, invalid states
//! Per cycle at most [`MAX_STEPS_PER_CYCLE`] grid steps plus the interpolating step (36
//! evaluations of the gravity model). When the cycle time is further from the grid state
//! than that covers — a table whose epoch is hours away, a forward time jump — the
//! propagator catches up over several cycles ([`MAX_STEPS_PER_CYCLE`] × [`STEP_S`] = 80 s of
//! orbit per cycle, 80× real time at 1 Hz) and reports [`OrbitStatus::CatchingUp`]: the
//! orbit is not yet valid and the OBC does not use it. A table epoch after the cycle time is
//! caught up backwards the same way. The orbit becomes [`OrbitStatus::Invalid`], until a
//! new table is loaded, when the time goes backwards (the grid would be run back over a
//! time it already passed: a clock fault, not an orbit), when the cycle time is more than
//! [`MAX_CATCH_UP_S`] from the state (at 80 s per cycle that would take more than 4.5 min
//! of cycles without the correction; the ground should uplink a fresher state), when the
//! state is older than [`MAX_STATE_AGE_S`], or when the state leaves the physical range
//! of the table's validation (a numerical failure). Errors are enums; no heap, no panic.

use crate::tables::OrbitTable;
use nalgebra::Vector3;

/// Earth gravitational parameter, km³/s²: EGM96 / WGS 84 (398 600.4418), the value of the
/// simulator's truth orbit (`sim-harness/src/truth/orbit.rs`).
/// Project choice (not in the paper): the same constant as the truth, EGM96.
pub const MU_EARTH_KM3_PER_S2: f64 = 398_600.441_8;

/// Earth J2 (EGM96 unnormalised C20 = −1.08262668e-3, sign flipped), the truth's value.
/// Project choice (not in the paper): EGM96, as `sim-harness/src/truth/orbit.rs`.
pub const J2_EARTH: f64 = 1.082_626_68e-3;

/// Earth equatorial radius, km (WGS 84 semi-major axis), the truth's J2 reference radius.
/// Project choice (not in the paper): WGS 84, as `sim-harness/src/truth/sun.rs`.
pub const EARTH_EQUATORIAL_RADIUS_KM: f64 = 6_378.137;

/// Speed of light, km/s (exact by the SI definition of the metre).
/// algorithms.md §3.3 (`β = v/c`); SI (BIPM), as `sim-harness/src/truth/aberration.rs`.
pub const C_KM_PER_S: f64 = 299_792.458;

/// Astronomical unit, km (IAU 2012 Resolution B2, exact).
/// IAU 2012 B2; as `sim-harness/src/truth/sun.rs` (`AU_KM`).
pub const AU_KM: f64 = 149_597_870.7;

/// Smallest orbit radius (and perigee radius) accepted, km: 100 km above the equator.
/// docs/tables.md (Table 5 ranges); project choice: below it the orbit is not an orbit.
pub const MIN_RADIUS_KM: f64 = EARTH_EQUATORIAL_RADIUS_KM + 100.0;

/// Largest orbit radius accepted, km (above geostationary, 42 164 km).
/// docs/tables.md (Table 5 ranges); project choice: the RK4 step is sized for Earth orbits.
pub const MAX_RADIUS_KM: f64 = 50_000.0;

/// RK4 grid step, s: the truth orbit's largest step (its energy drift ~1e-11 per day).
/// Project choice (module docs); the accuracy is tested in `est_orbit`.
pub const STEP_S: f64 = 10.0;

/// Largest number of grid steps per cycle while catching up (module docs).
/// Project choice: bounds the cycle's work to 9 RK4 steps (36 gravity evaluations).
pub const MAX_STEPS_PER_CYCLE: u32 = 8;

/// Largest distance between the cycle time and the state the propagator catches up, s
/// (6 h: at most 270 cycles at 80 s per cycle). Further: [`OrbitInvalid::GapTooLarge`].
/// Project choice (module docs).
pub const MAX_CATCH_UP_S: f64 = 21_600.0;

/// Largest age of the state (cycle time minus table epoch), s: 2 days, twice the day over
/// which the accuracy is tested; a real orbit drifts from the J2 model by drag.
/// Project choice (module docs).
pub const MAX_STATE_AGE_S: f64 = 172_800.0;

/// Position and velocity, J2000/GCRS axes.
/// docs/tables.md (Table 5 fields 1–2); algorithms.md §3.3.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OrbitState {
    /// Position, km.
    /// docs/tables.md (Table 5 field 1).
    pub pos_eci_km: Vector3<f64>,
    /// Velocity, km/s.
    /// docs/tables.md (Table 5 field 2).
    pub vel_eci_km_per_s: Vector3<f64>,
}

/// Why the onboard orbit is invalid (until a new table is loaded). Codes in brackets are
/// p2 of event 0x0801.
/// docs/icd.md §3.3 (event 0x0801); module docs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum OrbitInvalid {
    /// The cycle time went backwards (1).
    /// Project choice (module docs): a clock fault, not an orbit.
    TimeWentBackwards,
    /// The cycle time is more than [`MAX_CATCH_UP_S`] from the state, or not finite (2).
    /// Project choice (module docs).
    GapTooLarge,
    /// The state is older than [`MAX_STATE_AGE_S`] (3).
    /// Project choice (module docs).
    StateTooOld,
    /// The propagated state left the table's physical range (4).
    /// docs/tables.md (Table 5 ranges).
    Diverged,
}

impl OrbitInvalid {
    /// Reason code (event 0x0801 p2).
    /// docs/icd.md §3.3.
    #[must_use]
    pub fn code(self) -> u32 {
        match self {
            Self::TimeWentBackwards => 1,
            Self::GapTooLarge => 2,
            Self::StateTooOld => 3,
            Self::Diverged => 4,
        }
    }
}

/// State of the onboard orbit. Codes in brackets are p1 of event 0x0801.
/// docs/icd.md §3.3 (event 0x0801); module docs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum OrbitStatus {
    /// No orbit table loaded since boot (0).
    /// docs/tables.md (Table 5: "boot: none").
    NoTable,
    /// Propagating towards the cycle time, not there yet (1).
    /// Project choice (module docs): bounded work per cycle.
    CatchingUp,
    /// The state at the cycle time is available (2).
    /// Project choice (module docs).
    Valid,
    /// Not usable until a new table is loaded (3).
    /// Project choice (module docs).
    Invalid(OrbitInvalid),
}

impl OrbitStatus {
    /// Status code (event 0x0801 p1).
    /// docs/icd.md §3.3.
    #[must_use]
    pub fn code(self) -> u32 {
        match self {
            Self::NoTable => 0,
            Self::CatchingUp => 1,
            Self::Valid => 2,
            Self::Invalid(_) => 3,
        }
    }
}

/// Why [`OnboardOrbit::state`] has no state to give.
/// Module docs; project choice: errors as enums.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum OrbitError {
    /// The orbit is not valid at the last cycle time; the status says why.
    /// Project choice (module docs).
    NotValid {
        /// The status at the last cycle.
        /// Project choice (module docs).
        status: OrbitStatus,
    },
}

/// Grid state: `t = epoch + k · STEP_S`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct GridState {
    k: i32,
    state: OrbitState,
}

/// The onboard orbit propagator (module docs).
/// algorithms.md §3.3; docs/tables.md (Table 5).
#[derive(Clone, Debug, PartialEq)]
pub struct OnboardOrbit {
    epoch_s: f64,
    grid: Option<GridState>,
    last_time_s: Option<f64>,
    status: OrbitStatus,
    now: Option<OrbitState>,
}

impl Default for OnboardOrbit {
    fn default() -> Self {
        Self::new()
    }
}

/// Gravitational acceleration, km/s²: point mass plus J2 (axis = J2000 pole).
/// Project choice: the truth orbit's model (`sim-harness/src/truth/orbit.rs`); EGM96 J2.
#[must_use]
pub fn gravity_accel_km_per_s2(pos_eci_km: &Vector3<f64>) -> Vector3<f64> {
    let r2 = pos_eci_km.norm_squared();
    let r = libm::sqrt(r2);
    let z2_over_r2 = pos_eci_km.z * pos_eci_km.z / r2;
    let k = -1.5
        * J2_EARTH
        * MU_EARTH_KM3_PER_S2
        * EARTH_EQUATORIAL_RADIUS_KM
        * EARTH_EQUATORIAL_RADIUS_KM
        / (r2 * r2 * r);
    let point = -pos_eci_km * (MU_EARTH_KM3_PER_S2 / (r2 * r));
    point
        + Vector3::new(
            pos_eci_km.x * (1.0 - 5.0 * z2_over_r2),
            pos_eci_km.y * (1.0 - 5.0 * z2_over_r2),
            pos_eci_km.z * (3.0 - 5.0 * z2_over_r2),
        ) * k
}

/// Perigee radius (km) of the two-body orbit through `pos`, `vel`; `None` if the orbit is not
/// bound (speed at or above escape) or the inputs are degenerate.
/// docs/tables.md (Table 5 field 2: "a bound orbit, perigee ≥ 6478 km"); two-body relations.
#[must_use]
pub fn perigee_radius_km(
    pos_eci_km: &Vector3<f64>,
    vel_eci_km_per_s: &Vector3<f64>,
) -> Option<f64> {
    let r = pos_eci_km.norm();
    let v2 = vel_eci_km_per_s.norm_squared();
    let energy = 0.5 * v2 - MU_EARTH_KM3_PER_S2 / r;
    if !(energy < 0.0 && r > 0.0) {
        return None;
    }
    let a = -MU_EARTH_KM3_PER_S2 / (2.0 * energy);
    let h2 = pos_eci_km.cross(vel_eci_km_per_s).norm_squared();
    let e2 = 1.0 + 2.0 * energy * h2 / (MU_EARTH_KM3_PER_S2 * MU_EARTH_KM3_PER_S2);
    let e = libm::sqrt(e2.max(0.0));
    let rp = a * (1.0 - e);
    rp.is_finite().then_some(rp)
}

/// One classical RK4 step of length `h_s` (negative: backwards).
/// Project choice (module docs): RK4, as the truth orbit.
#[must_use]
pub fn rk4_step(s: &OrbitState, h_s: f64) -> OrbitState {
    let (r0, v0) = (s.pos_eci_km, s.vel_eci_km_per_s);
    let a1 = gravity_accel_km_per_s2(&r0);
    let r1 = r0 + v0 * (0.5 * h_s);
    let v1 = v0 + a1 * (0.5 * h_s);
    let a2 = gravity_accel_km_per_s2(&r1);
    let r2 = r0 + v1 * (0.5 * h_s);
    let v2 = v0 + a2 * (0.5 * h_s);
    let a3 = gravity_accel_km_per_s2(&r2);
    let r3 = r0 + v2 * h_s;
    let v3 = v0 + a3 * h_s;
    let a4 = gravity_accel_km_per_s2(&r3);
    OrbitState {
        pos_eci_km: r0 + (v0 + v1 * 2.0 + v2 * 2.0 + v3) * (h_s / 6.0),
        vel_eci_km_per_s: v0 + (a1 + a2 * 2.0 + a3 * 2.0 + a4) * (h_s / 6.0),
    }
}

/// Whether a propagated state is still in the table's physical range.
fn in_range(s: &OrbitState) -> bool {
    let r = s.pos_eci_km.norm();
    (MIN_RADIUS_KM * 0.99..=MAX_RADIUS_KM).contains(&r) && s.vel_eci_km_per_s.norm().is_finite()
}

impl OnboardOrbit {
    /// No orbit (boot).
    /// docs/tables.md (Table 5: "boot: none").
    #[must_use]
    pub const fn new() -> Self {
        Self {
            epoch_s: 0.0,
            grid: None,
            last_time_s: None,
            status: OrbitStatus::NoTable,
            now: None,
        }
    }

    /// Start from a (validated) orbit table: the state at its epoch; the next
    /// [`Self::advance_to`] decides whether it is valid. Clears any invalid state.
    /// docs/tables.md (Table 5, "Lifecycle": on activation).
    pub fn load(&mut self, table: &OrbitTable) {
        self.epoch_s = table.epoch_s_since_j2000_tt;
        self.grid = Some(GridState {
            k: 0,
            state: OrbitState {
                pos_eci_km: Vector3::from(table.pos_eci_km),
                vel_eci_km_per_s: Vector3::from(table.vel_eci_km_per_s),
            },
        });
        self.last_time_s = None;
        self.status = OrbitStatus::CatchingUp;
        self.now = None;
    }

    /// The status at the last [`Self::advance_to`].
    /// Project choice (module docs).
    #[must_use]
    pub fn status(&self) -> OrbitStatus {
        self.status
    }

    /// Epoch of the loaded table, s since J2000 TT (0 without a table).
    /// docs/tables.md (Table 5 field 0).
    #[must_use]
    pub fn epoch_s_since_j2000_tt(&self) -> f64 {
        self.epoch_s
    }

    /// The state at the last cycle time.
    /// Project choice (module docs).
    ///
    /// # Errors
    /// [`OrbitError::NotValid`] with the status when the orbit is not valid.
    pub fn state(&self) -> Result<OrbitState, OrbitError> {
        match (self.status, self.now) {
            (OrbitStatus::Valid, Some(s)) => Ok(s),
            (status, _) => Err(OrbitError::NotValid { status }),
        }
    }

    fn invalidate(&mut self, why: OrbitInvalid) -> OrbitStatus {
        self.status = OrbitStatus::Invalid(why);
        self.now = None;
        self.status
    }

    /// Propagate towards `t_s` (seconds since J2000 TT, the cycle time): at most
    /// [`MAX_STEPS_PER_CYCLE`] grid steps and one interpolating step (module docs).
    /// Returns the new status; an invalid orbit stays invalid until [`Self::load`].
    /// Project choice (module docs: bounded work, catching up, invalid states).
    pub fn advance_to(&mut self, t_s: f64) -> OrbitStatus {
        let Some(mut grid) = self.grid else {
            self.status = OrbitStatus::NoTable;
            return self.status;
        };
        if let OrbitStatus::Invalid(_) = self.status {
            return self.status;
        }
        if let Some(last) = self.last_time_s {
            if t_s < last {
                return self.invalidate(OrbitInvalid::TimeWentBackwards);
            }
        }
        self.last_time_s = Some(t_s);
        if !(t_s - self.epoch_s <= MAX_STATE_AGE_S) {
            return if t_s.is_finite() {
                self.invalidate(OrbitInvalid::StateTooOld)
            } else {
                self.invalidate(OrbitInvalid::GapTooLarge)
            };
        }
        let grid_time = |g: &GridState| self.epoch_s + f64::from(g.k) * STEP_S;
        if !((t_s - grid_time(&grid)).abs() <= MAX_CATCH_UP_S + STEP_S) {
            return self.invalidate(OrbitInvalid::GapTooLarge);
        }
        for _ in 0..MAX_STEPS_PER_CYCLE {
            let span = t_s - grid_time(&grid);
            let (h, k) = if span >= STEP_S {
                (STEP_S, grid.k.checked_add(1))
            } else if span < 0.0 {
                (-STEP_S, grid.k.checked_sub(1))
            } else {
                break;
            };
            let Some(k) = k else {
                return self.invalidate(OrbitInvalid::StateTooOld);
            };
            grid = GridState {
                k,
                state: rk4_step(&grid.state, h),
            };
        }
        if !in_range(&grid.state) {
            return self.invalidate(OrbitInvalid::Diverged);
        }
        self.grid = Some(grid);
        let span = t_s - grid_time(&grid);
        if !(0.0..STEP_S).contains(&span) {
            self.status = OrbitStatus::CatchingUp;
            self.now = None;
            return self.status;
        }
        let now = if span > 0.0 {
            rk4_step(&grid.state, span)
        } else {
            grid.state
        };
        if !in_range(&now) {
            return self.invalidate(OrbitInvalid::Diverged);
        }
        self.now = Some(now);
        self.status = OrbitStatus::Valid;
        self.status
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A circular equatorial-ish orbit at GRO's radius.
    fn table(epoch_s: f64) -> OrbitTable {
        let r = 6833.0;
        let v = libm::sqrt(MU_EARTH_KM3_PER_S2 / r);
        let i = 28.48_f64.to_radians();
        OrbitTable {
            epoch_s_since_j2000_tt: epoch_s,
            pos_eci_km: [r, 0.0, 0.0],
            vel_eci_km_per_s: [0.0, v * libm::cos(i), v * libm::sin(i)],
        }
    }

    #[test]
    fn no_table_until_loaded() {
        let mut o = OnboardOrbit::new();
        assert_eq!(o.advance_to(1.0e8), OrbitStatus::NoTable);
        assert_eq!(
            o.state(),
            Err(OrbitError::NotValid {
                status: OrbitStatus::NoTable
            })
        );
    }

    #[test]
    fn valid_at_the_epoch_and_between_grid_points() {
        let mut o = OnboardOrbit::new();
        let t = table(-2.7e8);
        assert_eq!(t.validate(), Ok(()));
        o.load(&t);
        assert_eq!(o.advance_to(-2.7e8), OrbitStatus::Valid);
        assert_eq!(o.state().unwrap().pos_eci_km, Vector3::from(t.pos_eci_km));
        // 1-s cycles: valid every cycle, radius stays near 6833 km (J2 moves it by ~km).
        for k in 1..=100 {
            let s = o.advance_to(-2.7e8 + f64::from(k));
            assert_eq!(s, OrbitStatus::Valid);
            let r = o.state().unwrap().pos_eci_km.norm();
            assert!((r - 6833.0).abs() < 20.0, "{r}");
        }
    }

    #[test]
    fn catches_up_over_cycles_then_valid() {
        let mut o = OnboardOrbit::new();
        o.load(&table(0.0));
        // 1000 s after the epoch: 100 grid steps, 8 per cycle → 13 cycles.
        let mut cycles = 0;
        let mut t = 1000.0;
        while o.advance_to(t) == OrbitStatus::CatchingUp {
            cycles += 1;
            t += 1.0;
            assert!(cycles < 20);
        }
        assert_eq!(o.status(), OrbitStatus::Valid);
        assert_eq!(cycles, 12);
        // A table epoch in the future is caught up backwards the same way.
        // 500 s ahead: 50 steps back, 8 per cycle → valid at the 7th cycle.
        let mut o = OnboardOrbit::new();
        o.load(&table(500.0));
        for k in 0..6 {
            assert_eq!(o.advance_to(0.5 + f64::from(k)), OrbitStatus::CatchingUp);
        }
        assert_eq!(o.advance_to(6.5), OrbitStatus::Valid);
    }

    #[test]
    fn backwards_time_gap_and_age_invalidate_until_reload() {
        let mut o = OnboardOrbit::new();
        o.load(&table(0.0));
        assert_eq!(o.advance_to(5.0), OrbitStatus::Valid);
        assert_eq!(
            o.advance_to(4.0),
            OrbitStatus::Invalid(OrbitInvalid::TimeWentBackwards)
        );
        // Stays invalid even at a later, good time.
        assert_eq!(
            o.advance_to(6.0),
            OrbitStatus::Invalid(OrbitInvalid::TimeWentBackwards)
        );
        o.load(&table(0.0));
        assert_eq!(o.advance_to(6.0), OrbitStatus::Valid);
        assert_eq!(
            o.advance_to(6.0 + MAX_CATCH_UP_S + 2.0 * STEP_S),
            OrbitStatus::Invalid(OrbitInvalid::GapTooLarge)
        );
        o.load(&table(0.0));
        assert_eq!(
            o.advance_to(MAX_STATE_AGE_S + 1.0),
            OrbitStatus::Invalid(OrbitInvalid::StateTooOld)
        );
        o.load(&table(0.0));
        assert_eq!(
            o.advance_to(f64::NAN),
            OrbitStatus::Invalid(OrbitInvalid::GapTooLarge)
        );
    }

    #[test]
    fn two_body_circular_speed_conserved_and_j2_regresses_the_node() {
        // One orbit (5621 s) in 1-s cycles: the speed of a circular J2 orbit stays within a few
        // m/s of circular (J2 osculation), the polar angular momentum is conserved.
        let mut o = OnboardOrbit::new();
        let t = table(0.0);
        o.load(&t);
        let s0 = OrbitState {
            pos_eci_km: Vector3::from(t.pos_eci_km),
            vel_eci_km_per_s: Vector3::from(t.vel_eci_km_per_s),
        };
        let hz0 = s0.pos_eci_km.cross(&s0.vel_eci_km_per_s).z;
        for k in 1..=5621 {
            assert_eq!(o.advance_to(f64::from(k)), OrbitStatus::Valid);
        }
        let s = o.state().unwrap();
        let hz = s.pos_eci_km.cross(&s.vel_eci_km_per_s).z;
        assert!(((hz - hz0) / hz0).abs() < 1e-10, "{}", (hz - hz0) / hz0);
        let dv = (s.vel_eci_km_per_s.norm() - s0.vel_eci_km_per_s.norm()).abs();
        assert!(dv < 0.02, "{dv}");
    }

    #[test]
    fn perigee_and_bound_checks() {
        let t = table(0.0);
        let r = Vector3::from(t.pos_eci_km);
        let v = Vector3::from(t.vel_eci_km_per_s);
        assert!((perigee_radius_km(&r, &v).unwrap() - 6833.0).abs() < 1e-6);
        // Escape speed: not bound.
        assert_eq!(perigee_radius_km(&r, &(v * 1.5)), None);
        // Half the circular speed: perigee inside the Earth.
        assert!(perigee_radius_km(&r, &(v * 0.5)).unwrap() < MIN_RADIUS_KM);
    }
}
