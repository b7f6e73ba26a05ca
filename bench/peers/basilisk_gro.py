#!/usr/bin/env python3
"""Basilisk peer of our Compton GRO closed-loop attitude simulation, for a speed comparison.

One closed loop at a fixed 1.0 s cycle (dynamics, sensors and flight software all at 1.0 s):

  truth   spacecraft (18 000 kg rigid hub, RK4 at 1.0 s), gravityEffector (Earth point mass + J2),
          GravityGradientEffector, reactionWheelStateEffector (3 orthogonal wheels)
  sensors imuSensor (gyro: constant bias + white rate noise), starTracker (attitude + white noise)
  FSW     stComm -> inertialUKF (fed by the star tracker and by a gyro packet buffer),
          inertial3D -> attTrackingError -> mrpFeedback -> rwMotorTorque -> wheels

The one piece that is not a stock Basilisk module is a tiny bridge of ours that packs the
imuSensor output into the AccDataMsg ring buffer that inertialUKF reads as its gyro input
(Basilisk 2.12 has no module that writes an AccDataMsg). By default it is a Basilisk
NumbaModel (compiled by numba at InitializeSimulation, called from the C++ scheduler without
the Python interpreter); `--gyro-buffer python` uses a plain Python SysModel instead (about
twice the per-step cost of the whole loop), `--gyro-buffer none` leaves it out (inertialUKF
then reads an empty gyro buffer, as Basilisk's own examples do).

Only the sim loop (ExecuteSimulation) is timed; building and InitializeSimulation (which
includes the numba compile, cached on disk after the first run) are not. Prints one JSON
object on stdout; `--repeats N` builds and runs N fresh simulations and reports the median
wall time (and the median process CPU time of the loop, less sensitive to a busy machine).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import statistics
import sys
import time

import numpy as np

from Basilisk import __version__ as BSK_VERSION
from Basilisk.architecture import messaging, sysModel
from Basilisk.fswAlgorithms import (
    attTrackingError,
    inertial3D,
    inertialUKF,
    mrpFeedback,
    rwMotorTorque,
    stComm,
)
from Basilisk.simulation import (
    GravityGradientEffector,
    gravityEffector,
    imuSensor,
    reactionWheelStateEffector,
    spacecraft,
    starTracker,
)
from Basilisk.utilities import (
    RigidBodyKinematics as rbk,
    SimulationBaseClass,
    macros,
    orbitalMotion,
    simIncludeGravBody,
    simIncludeRW,
)

# --- scenario constants (kept in one place; README.md quotes them) -------------------------
MASS_KG = 18000.0
INERTIA_DIAG = [1.2e5, 1.4e5, 0.9e5]  # kg m^2, principal axes = body axes
SMA_M = 6833.0e3  # circular
INC_DEG = 28.48
RAAN_DEG = 0.0
ARG_LAT_DEG = 0.0
J2_UNNORMALISED = 1.08262668e-3  # EGM96/GGM-like value; Basilisk wants the normalised C20
RW_U_MAX_NM = 0.4  # same per-wheel torque limit as sim-harness' dynamics default
RW_H_MAX_NMS = 250.0  # same per-wheel momentum limit as sim-harness' dynamics default
RW_OMEGA_MAX_RPM = 6000.0
GYRO_BIAS_RAD_S = [4.8e-7, -2.9e-7, 3.9e-7]  # ~0.1, -0.06, 0.08 deg/h
GYRO_NOISE_RAD_S = 1.0e-6  # 1-sigma white rate noise per 1 s sample
ST_NOISE_ARCSEC = 10.0  # 1-sigma per axis
SIGMA_BN_0 = [0.10, -0.05, 0.20]  # initial true attitude (MRP)
SLEW_DEG = 5.0  # the attitude-hold target is SLEW_DEG away from the initial attitude
SLEW_AXIS = [1.0, 2.0, -1.0]  # body axis of that offset (normalised below)
# mrpFeedback gains: closed-loop natural frequency ~0.02 rad/s, damping ~0.9 on the 1.4e5 axis
K_MRP = 240.0  # [N m] (MRP gain: ~K/4 N m per rad)
P_RATE = 5000.0  # [N m s]
KI = -1.0  # integral feedback off (mrpFeedback convention: negative disables)

MODULES = [
    "spacecraft.Spacecraft",
    "gravityEffector (simIncludeGravBody Earth, SphericalHarmonicsGravityModel degree 2 = point mass + J2)",
    "GravityGradientEffector.GravityGradientEffector",
    "reactionWheelStateEffector.ReactionWheelStateEffector (3 x simIncludeRW 'custom')",
    "imuSensor.ImuSensor",
    "starTracker.StarTracker",
    "stComm.stComm",
    "inertialUKF.inertialUKF",
    "inertial3D.inertial3D",
    "attTrackingError.attTrackingError",
    "mrpFeedback.mrpFeedback",
    "rwMotorTorque.rwMotorTorque",
]
GYRO_BUFFER_MODULE = {
    "numba": "ImuGyroBufferNumba (numbaModel.NumbaModel, ours: IMUSensorMsg -> AccDataMsg ring buffer)",
    "python": "ImuGyroBuffer (sysModel.SysModel in Python, ours: IMUSensorMsg -> AccDataMsg ring buffer)",
}


class ImuGyroBuffer(sysModel.SysModel):
    """Packs each imuSensor sample into the AccDataMsg ring buffer read by inertialUKF."""

    def __init__(self):
        super().__init__()
        self.imuInMsg = messaging.IMUSensorMsgReader()
        self.gyroBufferOutMsg = messaging.AccDataMsg()
        self.Reset(0)

    def Reset(self, CurrentSimNanos):
        self._buf = messaging.AccDataMsgPayload()
        # proxies into the payload's C array, fetched once (building them costs ~120 objects)
        self._pkts = self._buf.accPkts
        self._next = 0

    def UpdateState(self, CurrentSimNanos):
        imu = self.imuInMsg()
        pkt = self._pkts[self._next]
        pkt.measTime = CurrentSimNanos
        pkt.gyro_B = imu.AngVelPlatform  # platform frame == body frame here
        pkt.accel_B = imu.AccelPlatform
        self._next = (self._next + 1) % messaging.MAX_ACC_BUF_PKT
        self.gyroBufferOutMsg.write(self._buf, CurrentSimNanos, self.moduleID)


@contextlib.contextmanager
def stdout_to_stderr():
    """Send file descriptor 1 (C and Python stdout) to stderr for the duration."""
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        os.dup2(2, 1)
        yield
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)


def make_numba_gyro_buffer():
    """The same bridge as a Basilisk NumbaModel: UpdateStateImpl is compiled by numba (at
    InitializeSimulation) into a C function that the C++ scheduler calls without entering
    the Python interpreter. Returns None when numba is not installed."""
    try:
        from Basilisk.architecture import numbaModel
    except ImportError:
        return None

    class ImuGyroBufferNumba(numbaModel.NumbaModel):
        def __init__(self):
            super().__init__()
            self.imuInMsg = messaging.IMUSensorMsgReader()
            self.gyroBufferOutMsg = messaging.AccDataMsg()
            self.memory.next = np.int64(0)

        @staticmethod
        def UpdateStateImpl(CurrentSimNanos, imuInMsgPayload, gyroBufferOutMsgPayload, memory):
            i = memory.next
            pkt = gyroBufferOutMsgPayload.accPkts[i]
            pkt.measTime = CurrentSimNanos
            for k in range(3):
                pkt.gyro_B[k] = imuInMsgPayload.AngVelPlatform[k]
                pkt.accel_B[k] = imuInMsgPayload.AccelPlatform[k]
            memory.next = (i + 1) % 120  # MAX_ACC_BUF_PKT

    return ImuGyroBufferNumba()


def mrp_angle_deg(sigma_a, sigma_b):
    """Principal angle (deg) between two MRP attitudes."""
    dcm = np.array(rbk.MRP2C(sigma_a)) @ np.array(rbk.MRP2C(sigma_b)).T
    c = max(-1.0, min(1.0, (np.trace(dcm) - 1.0) / 2.0))
    return math.degrees(math.acos(c))


def build(args, seed):
    step_ns = macros.sec2nano(args.step)
    sim = SimulationBaseClass.SimBaseClass()
    dyn = sim.CreateNewProcess("dynamics", 20)  # runs first in each cycle
    fsw = sim.CreateNewProcess("fsw", 10)
    dyn.addTask(sim.CreateNewTask("dynTask", step_ns), 100)
    fsw.addTask(sim.CreateNewTask("fswTask", step_ns), 50)
    # star tracker sampling (default: every cycle); sensor in the dynamics process, its
    # interface (stComm) in the FSW process, both at the star-tracker period
    st_ns = macros.sec2nano(args.st_period)
    dyn.addTask(sim.CreateNewTask("stTask", st_ns), 50)
    fsw.addTask(sim.CreateNewTask("stCommTask", st_ns), 100)
    h = {"sim": sim}

    # --- truth: spacecraft, gravity (+J2), gravity gradient, wheels -----------------------
    sc = spacecraft.Spacecraft()
    sc.ModelTag = "gro"
    sc.hub.mHub = MASS_KG
    sc.hub.r_BcB_B = [[0.0], [0.0], [0.0]]
    sc.hub.IHubPntBc_B = np.diag(INERTIA_DIAG).tolist()

    grav = simIncludeGravBody.gravBodyFactory()
    earth = grav.createEarth()
    earth.isCentralBody = True
    if not args.point_mass:
        # Degree-2 spherical harmonics with only C20 set = point mass + J2. The coefficients are
        # set directly (no coefficient file, which Basilisk would otherwise fetch from the net).
        sh = gravityEffector.SphericalHarmonicsGravityModel()
        sh.muBody = earth.mu
        sh.radEquator = earth.radEquator
        c20 = -J2_UNNORMALISED / math.sqrt(5.0)
        sh.cBar = [[1.0], [0.0, 0.0], [c20, 0.0, 0.0]]
        sh.sBar = [[0.0], [0.0, 0.0], [0.0, 0.0, 0.0]]
        sh.maxDeg = 2
        earth.gravityModel = sh
    grav.addBodiesTo(sc)
    h["grav"] = grav
    h["mu"] = earth.mu

    oe = orbitalMotion.ClassicElements()
    oe.a = SMA_M
    oe.e = 0.0
    oe.i = math.radians(INC_DEG)
    oe.Omega = math.radians(RAAN_DEG)
    oe.omega = 0.0
    oe.f = math.radians(ARG_LAT_DEG)
    r0, v0 = orbitalMotion.elem2rv(earth.mu, oe)
    sc.hub.r_CN_NInit = np.array(r0).reshape(3, 1).tolist()
    sc.hub.v_CN_NInit = np.array(v0).reshape(3, 1).tolist()
    sc.hub.sigma_BNInit = [[s] for s in SIGMA_BN_0]
    sc.hub.omega_BN_BInit = [[1.0e-5], [-2.0e-5], [1.5e-5]]
    sim.AddModelToTask("dynTask", sc, 100)

    gg = GravityGradientEffector.GravityGradientEffector()
    gg.ModelTag = "gravityGradient"
    gg.addPlanetName(earth.planetName)
    sc.addDynamicEffector(gg)
    sim.AddModelToTask("dynTask", gg, 99)

    rwf = simIncludeRW.rwFactory()
    for axis in ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]):
        rwf.create(
            "custom",
            axis,
            Omega=0.0,
            Omega_max=RW_OMEGA_MAX_RPM,
            maxMomentum=RW_H_MAX_NMS,
            u_max=RW_U_MAX_NM,
            useMaxTorque=True,
            RWModel=messaging.BalancedWheels,
        )
    rw = reactionWheelStateEffector.ReactionWheelStateEffector()
    rw.ModelTag = "rwa"
    rwf.addToSpacecraft(rw.ModelTag, rw, sc)
    # before the spacecraft in each cycle: the wheels read the FSW command of the previous
    # cycle, which then acts over the step the spacecraft integrates now (1-cycle hold)
    sim.AddModelToTask("dynTask", rw, 110)
    h["rwf"] = rwf

    # --- sensors ----------------------------------------------------------------------------
    imu = imuSensor.ImuSensor()
    imu.ModelTag = "gyro"
    imu.RNGSeed = seed
    imu.senRotBias = GYRO_BIAS_RAD_S
    imu.PMatrixGyro = (np.eye(3) * GYRO_NOISE_RAD_S).tolist()
    imu.setAMatrixGyro(np.zeros((3, 3)))  # white noise (no random walk)
    imu.setErrorBoundsGyro([1e3 * GYRO_NOISE_RAD_S] * 3)
    imu.scStateInMsg.subscribeTo(sc.scStateOutMsg)
    sim.AddModelToTask("dynTask", imu, 50)

    st_mrp = math.tan(math.radians(ST_NOISE_ARCSEC / 3600.0) / 4.0)
    st = starTracker.StarTracker()
    st.ModelTag = "starTracker"
    st.RNGSeed = seed + 1
    st.PMatrix = (np.eye(3) * st_mrp).tolist()
    st.setAMatrix(np.zeros((3, 3)))
    st.setWalkBounds([1e3 * st_mrp] * 3)
    st.scStateInMsg.subscribeTo(sc.scStateOutMsg)
    sim.AddModelToTask("stTask", st)

    # --- flight software ---------------------------------------------------------------------
    vc = messaging.VehicleConfigMsgPayload()
    vc.ISCPntB_B = np.diag(INERTIA_DIAG).flatten().tolist()
    vc_msg = messaging.VehicleConfigMsg().write(vc)
    rw_params_msg = rwf.getConfigMessage()
    h["keep"] = [vc_msg, rw_params_msg]

    stc = stComm.stComm()
    stc.ModelTag = "stComm"
    stc.dcm_BP = np.eye(3).flatten().tolist()
    stc.stSensorInMsg.subscribeTo(st.sensorOutMsg)
    sim.AddModelToTask("stCommTask", stc)

    ukf = inertialUKF.inertialUKF()
    ukf.ModelTag = "inertialUKF"
    ukf.alpha = 0.02
    ukf.beta = 2.0
    ukf.kappa = 0.0
    ukf.switchMag = 1.2
    ukf.stateInit = list(SIGMA_BN_0) + [0.0, 0.0, 0.0]
    p0 = [(1e-3) ** 2] * 3 + [(1e-4) ** 2] * 3
    ukf.covarInit = np.diag(p0).flatten().tolist()
    q = [(1e-6) ** 2] * 3 + [(2e-6) ** 2] * 3
    ukf.qNoise = np.diag(q).flatten().tolist()
    st_msg_cfg = inertialUKF.STMessage()
    st_msg_cfg.noise = (np.eye(3) * st_mrp**2).flatten().tolist()
    st_msg_cfg.stInMsg.subscribeTo(stc.stAttOutMsg)
    ukf.STDatasStruct.STMessages = [st_msg_cfg]
    ukf.STDatasStruct.numST = 1
    lp = inertialUKF.LowPassFilterData()
    lp.hStep = args.step
    lp.omegCutoff = 15.0 / (2.0 * math.pi)
    ukf.gyroFilt = [lp, lp, lp]
    ukf.massPropsInMsg.subscribeTo(vc_msg)
    ukf.rwParamsInMsg.subscribeTo(rw_params_msg)
    ukf.rwSpeedsInMsg.subscribeTo(rw.rwSpeedOutMsg)
    if args.gyro_buffer != "none":
        bridge = make_numba_gyro_buffer() if args.gyro_buffer == "numba" else ImuGyroBuffer()
        if bridge is None:
            raise SystemExit("--gyro-buffer numba needs the numba package (pip install numba)")
        bridge.ModelTag = "imuGyroBuffer"
        bridge.imuInMsg.subscribeTo(imu.sensorOutMsg)
        sim.AddModelToTask("fswTask", bridge, 59)
        ukf.gyrBuffInMsg.subscribeTo(bridge.gyroBufferOutMsg)
        h["bridge"] = bridge
    else:
        empty = messaging.AccDataMsg().write(messaging.AccDataMsgPayload())
        ukf.gyrBuffInMsg.subscribeTo(empty)
        h["keep"].append(empty)
    sim.AddModelToTask("fswTask", ukf, 58)

    axis = np.array(SLEW_AXIS) / np.linalg.norm(SLEW_AXIS)
    sigma_offset = axis * math.tan(math.radians(SLEW_DEG) / 4.0)  # R relative to B(0)
    sigma_R0N = rbk.addMRP(np.array(SIGMA_BN_0), sigma_offset)
    ref = inertial3D.inertial3D()
    ref.ModelTag = "inertial3D"
    ref.sigma_R0N = list(sigma_R0N)
    sim.AddModelToTask("fswTask", ref, 57)
    h["sigma_R0N"] = list(sigma_R0N)

    err = attTrackingError.attTrackingError()
    err.ModelTag = "attTrackingError"
    err.attNavInMsg.subscribeTo(ukf.navStateOutMsg)
    err.attRefInMsg.subscribeTo(ref.attRefOutMsg)
    sim.AddModelToTask("fswTask", err, 56)

    ctl = mrpFeedback.mrpFeedback()
    ctl.ModelTag = "mrpFeedback"
    ctl.K = K_MRP
    ctl.P = P_RATE
    ctl.Ki = KI
    ctl.integralLimit = 0.0
    ctl.guidInMsg.subscribeTo(err.attGuidOutMsg)
    ctl.vehConfigInMsg.subscribeTo(vc_msg)
    ctl.rwParamsInMsg.subscribeTo(rw_params_msg)
    ctl.rwSpeedsInMsg.subscribeTo(rw.rwSpeedOutMsg)
    sim.AddModelToTask("fswTask", ctl, 55)

    alloc = rwMotorTorque.rwMotorTorque()
    alloc.ModelTag = "rwMotorTorque"
    alloc.controlAxes_B = [1, 0, 0, 0, 1, 0, 0, 0, 1]
    alloc.vehControlInMsg.subscribeTo(ctl.cmdTorqueOutMsg)
    alloc.rwParamsInMsg.subscribeTo(rw_params_msg)
    sim.AddModelToTask("fswTask", alloc, 54)
    rw.rwMotorCmdInMsg.subscribeTo(alloc.rwMotorTorqueOutMsg)

    h.update(sc=sc, imu=imu, st=st, ukf=ukf, rw=rw, err=err, ctl=ctl, gg=gg)
    return h


def run_once(args, seed):
    t_build = time.perf_counter()
    h = build(args, seed)
    sim = h["sim"]
    with stdout_to_stderr():
        # module Reset() methods print benign "read an unwritten message" notices on the C
        # stdout (inputs not yet written before the first cycle); keep stdout for the JSON
        sim.InitializeSimulation()
    # inertialUKF writes its first estimate once it has a star-tracker sample with a time tag
    # > 0, i.e. at t = step; until then the controller reads the filter's initial state (not a
    # zero message, which would command a spurious slew in the first cycle)
    nav0 = messaging.NavAttMsgPayload()
    nav0.sigma_BN = list(SIGMA_BN_0)
    h["ukf"].navStateOutMsg.write(nav0, 0, h["ukf"].moduleID)
    sim.ConfigureStopTime(macros.sec2nano(args.duration))
    setup_s = time.perf_counter() - t_build

    c0 = time.process_time()
    t0 = time.perf_counter()
    sim.ExecuteSimulation()  # the timed sim loop
    wall = time.perf_counter() - t0
    cpu = time.process_time() - c0

    # sanity figures of the closed loop (read once, after timing)
    state = h["sc"].scStateOutMsg.read()
    nav = h["ukf"].navStateOutMsg.read()
    sigma_true = list(state.sigma_BN)
    r = np.array(state.r_BN_N)
    v = np.array(state.v_BN_N)
    hvec = np.cross(r, v)
    raan = math.degrees(math.atan2(hvec[0], -hvec[1]))
    wheel = h["rw"].rwSpeedOutMsg.read()
    return {
        "wall_seconds": wall,
        "cpu_seconds": cpu,
        "setup_seconds": setup_s,
        "final_pointing_error_deg": mrp_angle_deg(sigma_true, h["sigma_R0N"]),
        "final_estimation_error_arcsec": 3600.0 * mrp_angle_deg(sigma_true, list(nav.sigma_BN)),
        "final_radius_km": float(np.linalg.norm(r) / 1e3),
        "final_raan_deg": raan,
        "ukf_gyro_packets_used_last_cycle": int(h["ukf"].numUsedGyros),
        "final_wheel_speeds_rpm": [w / macros.RPM for w in list(wheel.wheelSpeeds)[:3]],
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=3600.0, help="simulated seconds (default 3600)")
    ap.add_argument("--repeats", type=int, default=1, help="independent runs; the median is reported")
    ap.add_argument("--step", type=float, default=1.0, help="dynamics and FSW step in s (default 1.0)")
    ap.add_argument("--st-period", type=float, default=None,
                    help="star-tracker sample period in s (default: = --step, i.e. every cycle)")
    ap.add_argument("--seed", type=int, default=1991)
    ap.add_argument("--gyro-buffer", choices=["numba", "python", "none"], default="numba",
                    help="how imuSensor output reaches inertialUKF's AccDataMsg gyro buffer: a "
                         "NumbaModel (default), a plain Python SysModel, or not at all (empty buffer)")
    ap.add_argument("--point-mass", action="store_true", help="Earth point-mass gravity only (no J2)")
    ap.add_argument("--verbose", action="store_true", help="per-repeat lines on stderr")
    args = ap.parse_args(argv)
    if args.st_period is None:
        args.st_period = args.step
    if args.duration <= 0 or args.step <= 0 or args.st_period <= 0 or args.repeats < 1:
        ap.error("duration, step, st-period must be > 0 and repeats >= 1")

    load_before = os.getloadavg()[0]
    runs = []
    for k in range(args.repeats):
        res = run_once(args, args.seed + 10 * k)
        runs.append(res)
        if args.verbose:
            print(f"repeat {k + 1}/{args.repeats}: wall {res['wall_seconds']:.3f} s, "
                  f"RTF {args.duration / res['wall_seconds']:.1f}", file=sys.stderr)

    walls = [r["wall_seconds"] for r in runs]
    wall = statistics.median(walls)
    last = runs[-1]
    modules = list(MODULES)
    if args.gyro_buffer != "none":
        modules.append(GYRO_BUFFER_MODULE[args.gyro_buffer])
    out = {
        "peer": "basilisk",
        "bsk_version": BSK_VERSION,
        "sim_seconds": args.duration,
        "wall_seconds": wall,
        "real_time_factor": args.duration / wall,
        "step_s": args.step,
        "star_tracker_period_s": args.st_period,
        "integrator": f"svIntegratorRK4 (Basilisk default): one RK4 step of {args.step} s per cycle",
        "steps": int(round(args.duration / args.step)),
        "repeats": args.repeats,
        "wall_seconds_all": walls,
        "cpu_seconds": statistics.median(r["cpu_seconds"] for r in runs),
        "cpu_real_time_factor": args.duration / statistics.median(r["cpu_seconds"] for r in runs),
        "loadavg_1min_before": load_before,
        "setup_seconds_median": statistics.median(r["setup_seconds"] for r in runs),
        "gravity": "point mass" if args.point_mass else "point mass + J2",
        "gyro_buffer_bridge": args.gyro_buffer,
        "modules": modules,
        "check": {k: v for k, v in last.items() if k.startswith("final_")},
        "python": sys.version.split()[0],
    }
    print(json.dumps(out))


if __name__ == "__main__":
    main()
