#!/usr/bin/env python3
"""Independent telemetry writer, from docs/icd.md alone (Python 3, standard library only).

Writes a run folder (telemetry.bin + metadata.json + truth_icd.json) for a simple,
physically consistent scenario: a circular orbit, inertial holds with the Sun in the FSS
fields and slews about single body axes between them, real Hipparcos stars from
data/hipparcos_mag6p5.csv (proper motion, parallax, annual + orbital aberration), the Sun
and the Earth's velocity interpolated in data/sun_reference.csv (JPL DE421, 1991; outside
it Meeus' low-precision formula, Astronomical Algorithms ch. 25, precessed to J2000) with
parallax and aberration, and FHST / FSS / IRU counts computed with the ICD's conventions.

Optional undeclared effects (--time-tag, --orbit-align, --fhst-radial, --fss-transfer,
--gyro-asym, --gyro-ramp, --gyro-bias-transient, --gyro-bias-step, --align-step, and outside
diagnose's library --gyro-rate2, --gyro-rate3, --gyro-mode-bias, --gyro-scale-step, --ringing) are recorded in
truth_icd.json "effects" with the library's parameter names; --plan long is the calibration
day tests/icd/diagnose_cases.py flies them on, --days D repeats its slews for D days.

The gyro: each triad (primary X2, Y1, Z1; backup X1, Y2, Z2) has a true δM and bias
(--iru-delta-m, --iru-delta-m-backup, --backup-bias), so that Δθ_acs = (I + δM) G w ΔN with
G the prelaunch G the ground flies; truth_icd.json "iru" holds both, the bias model and a
bias history. --backup-halfway has the OBC select the backup triad halfway (event 0x0202,
housekeeping byte 106). --downlink-every N writes raw frames and housekeeping every N cycles
while the counters accumulate every cycle (refused when they could alias); the gyro noise
has its own random generator, so such a run's counters are the 1-s run's at the same
cycles. tests/icd/check_writer.py decodes these options back (tests/icd/read_run.py) and
checks them; tests/icd/gyro_cases.py runs issue 16's gyro cases through the ground tool.

It is deliberately written without the simulator's or the flight software's encoders: every
byte comes from the tables of docs/icd.md (and the conventions it cites: docs/conventions.md,
docs/tables.md, data/gro_paper.toml for the boot tables). Flags add the variations of
docs/icd-conformance.md (missing packets, gaps, duplicates, reordering, wrap-around, a dead
sensor, extreme values, ...).

    python3 tests/icd/write_run.py --out /tmp/run            # the nominal run
    python3 tests/icd/write_run.py --out /tmp/r2 --no-hk --eph-period 300
    python3 tests/icd/write_run.py --out /tmp/r3 --tam    # + APID 0x013 (TAM1/TAM2, CSS)

--tam writes the magnetics frame (docs/icd.md §3.5) after every raw frame from the writer's
own TAM and CSS model (tests/icd/tam_model.py: IGRF through PyPI ppigrf when installed, else
its own synthesis of data/igrf_dgrf_1990_1995.csv; TAM1 bias --tam-bias, default the paper's
[0, 0, -4] mG); truth_icd.json "tam" holds the injected TAM errors.

truth_icd.json holds what was injected (alignment rotations, bias, noise), for the tests;
the ground tool never reads it.
"""

import argparse
import json
import math
import os
import bisect
import random
import struct
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.normpath(os.path.join(HERE, "..", ".."))
CATALOG = os.path.join(ROOT, "data", "hipparcos_mag6p5.csv")

RAD_PER_DEG = math.pi / 180.0
RAD_PER_ARCSEC = RAD_PER_DEG / 3600.0
AU_KM = 149597870.7
C_KM_PER_S = 299792.458
MU_EARTH = 398600.4418
R_EARTH_KM = 6378.137

# ICD §3.1 resolutions.
FHST_ARCSEC_PER_COUNT = 7.78
FSS_DEG_PER_COUNT = 0.004
IRU_LOW_ARCSEC_PER_PULSE = 0.05
IRU_HIGH_ARCSEC_PER_PULSE = 0.8

APID_RAW, APID_HK, APID_EVENT, APID_EPH = 0x010, 0x011, 0x012, 0x020
APID_MAG = 0x013

# The writer's TAMs (its own numbers; TAM1's bias is --tam-bias).
TAM2_MODEL = {"bias_mG": [0.6, -0.4, 0.3], "scale_ppm": [-400.0, 700.0, 300.0],
              "misalignment_acs_arcsec": [-250.0, 400.0, 150.0], "noise_mG": 0.2}
TAM1_SCALE_PPM = [600.0, -500.0, 800.0]
TAM1_MISALIGNMENT_ACS_ARCSEC = [300.0, -450.0, 200.0]

# Boot tables (docs/tables.md: the paper's Table 1 and prelaunch G; data/gro_paper.toml).
M_PRELAUNCH = {
    "FHST1": [[-0.707293868, 0.000641730, -0.706919372],
              [-0.706919611, -0.000965840, 0.707293212],
              [-0.000228880, 0.999999344, 0.001136780]],
    "FHST2": [[-0.706911922, -0.000668710, -0.707301319],
              [0.707300782, 0.000884930, -0.706912220],
              [0.001098630, -0.999999404, -0.000152590]],
    "FSS1": [[0.003753100, -0.865531862, 0.500839829],
             [0.999986291, 0.001422380, -0.005035412],
             [0.003645920, 0.500851870, 0.865525305]],
    "FSS2": [[0.000871080, 0.034161031, 0.999415934],
             [0.999991417, -0.004071418, -0.000732420],
             [0.004044019, 0.999408066, -0.034164291]],
}
G_PRELAUNCH = [[1.00000, 0.00108, 0.00079],
               [-0.00100, 1.00000, -0.00156],
               [-0.00056, 0.00128, 1.00000]]

# The writer's backup triad (X1, Y2, Z2): its own δM and bias (the paper's Fig. 4 / Table 3
# backup biases are of this size: X1 −0.84e-4, Y2 1.22e-4, Z2 0.81e-4 °/s).
DELTA_M_BACKUP_DEFAULT_PPM = [[420.0, -310.0, 180.0],
                              [260.0, -380.0, 150.0],
                              [-230.0, 340.0, 510.0]]
BACKUP_BIAS_DEFAULT = [-0.30, 0.44, 0.29]  # arcsec/s, ACS
# The paper's published primary δM (data/gro_paper.toml [iru_calibration_published]).
DELTA_M_PAPER = [[0.000167, 0.000374, 0.000167],
                 [-0.000511, -0.000265, -0.000048],
                 [-0.000547, 0.000365, 0.000037]]

# TAI - UTC (s) from each date on (IERS Bulletin C), enough for 1972..2035.
LEAP = [(1972, 1, 1, 10), (1972, 7, 1, 11), (1973, 1, 1, 12), (1974, 1, 1, 13),
        (1975, 1, 1, 14), (1976, 1, 1, 15), (1977, 1, 1, 16), (1978, 1, 1, 17),
        (1979, 1, 1, 18), (1980, 1, 1, 19), (1981, 7, 1, 20), (1982, 7, 1, 21),
        (1983, 7, 1, 22), (1985, 7, 1, 23), (1988, 1, 1, 24), (1990, 1, 1, 25),
        (1991, 1, 1, 26), (1992, 7, 1, 27), (1993, 7, 1, 28), (1994, 7, 1, 29),
        (1996, 1, 1, 30), (1997, 7, 1, 31), (1999, 1, 1, 32), (2006, 1, 1, 33),
        (2009, 1, 1, 34), (2012, 7, 1, 35), (2015, 7, 1, 36), (2017, 1, 1, 37)]


# ----------------------------------------------------------------------------- small math
def add(a, b):
    return [a[0] + b[0], a[1] + b[1], a[2] + b[2]]


def sub(a, b):
    return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]


def scale(a, s):
    return [a[0] * s, a[1] * s, a[2] * s]


def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def norm(a):
    return math.sqrt(dot(a, a))


def unit(a):
    n = norm(a)
    return [a[0] / n, a[1] / n, a[2] / n]


def mv(m, v):
    return [dot(m[0], v), dot(m[1], v), dot(m[2], v)]


def mt(m):
    return [[m[j][i] for j in range(3)] for i in range(3)]


def mm(a, b):
    bt = mt(b)
    return [[dot(a[i], bt[j]) for j in range(3)] for i in range(3)]


def inv3(m):
    a, b, c = m[0]
    d, e, f = m[1]
    g, h, i = m[2]
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    return [[(e * i - f * h) / det, (c * h - b * i) / det, (b * f - c * e) / det],
            [(f * g - d * i) / det, (a * i - c * g) / det, (c * d - a * f) / det],
            [(d * h - e * g) / det, (b * g - a * h) / det, (a * e - b * d) / det]]


def rot(theta):
    """docs/conventions.md: Rot(θ) = exp(−[θ×]) = cos θ I + (1 − cos θ) e eᵀ − sin θ [e×]."""
    ang = norm(theta)
    if ang < 1e-15:
        return [[1.0, theta[2], -theta[1]], [-theta[2], 1.0, theta[0]], [theta[1], -theta[0], 1.0]]
    e = scale(theta, 1.0 / ang)
    c, s = math.cos(ang), math.sin(ang)
    m = [[c * (i == j) + (1 - c) * e[i] * e[j] for j in range(3)] for i in range(3)]
    # − sin θ [e×]; [e×] = [[0,−e3,e2],[e3,0,−e1],[−e2,e1,0]]
    m[0][1] += s * e[2]
    m[0][2] -= s * e[1]
    m[1][0] -= s * e[2]
    m[1][2] += s * e[0]
    m[2][0] += s * e[1]
    m[2][1] -= s * e[0]
    return m


def quat_from_dcm(a):
    """Scalar-last q with A(q) = (w² − |v|²) I + 2 v vᵀ − 2 w [v×] (docs/conventions.md)."""
    tr = a[0][0] + a[1][1] + a[2][2]
    # 4w² = 1 + tr; −2w[v×] off-diagonals: A01 − A10 = 4 w v2, A12 − A21 = 4 w v0, A20 − A02 = 4 w v1
    cands = [1 + tr, 1 + 2 * a[0][0] - tr, 1 + 2 * a[1][1] - tr, 1 + 2 * a[2][2] - tr]
    k = max(range(4), key=lambda i: cands[i])
    if k == 0:
        w = 0.5 * math.sqrt(cands[0])
        x = (a[1][2] - a[2][1]) / (4 * w)
        y = (a[2][0] - a[0][2]) / (4 * w)
        z = (a[0][1] - a[1][0]) / (4 * w)
    elif k == 1:
        x = 0.5 * math.sqrt(cands[1])
        w = (a[1][2] - a[2][1]) / (4 * x)
        y = (a[0][1] + a[1][0]) / (4 * x)
        z = (a[0][2] + a[2][0]) / (4 * x)
    elif k == 2:
        y = 0.5 * math.sqrt(cands[2])
        w = (a[2][0] - a[0][2]) / (4 * y)
        x = (a[0][1] + a[1][0]) / (4 * y)
        z = (a[1][2] + a[2][1]) / (4 * y)
    else:
        z = 0.5 * math.sqrt(cands[3])
        w = (a[0][1] - a[1][0]) / (4 * z)
        x = (a[0][2] + a[2][0]) / (4 * z)
        y = (a[1][2] + a[2][1]) / (4 * z)
    if w < 0:
        x, y, z, w = -x, -y, -z, -w
    return [x, y, z, w]


def dcm_from_quat(q):
    x, y, z, w = q
    v = [x, y, z]
    s = w * w - dot(v, v)
    m = [[s * (i == j) + 2 * v[i] * v[j] for j in range(3)] for i in range(3)]
    m[0][1] += 2 * w * z
    m[0][2] -= 2 * w * y
    m[1][0] -= 2 * w * z
    m[1][2] += 2 * w * x
    m[2][0] += 2 * w * y
    m[2][1] -= 2 * w * x
    return m


def triad(b1, r1, b2, r2):
    def frame(v1, v2):
        e1 = unit(v1)
        e2 = unit(cross(e1, v2))
        e3 = cross(e1, e2)
        return [[e1[i], e2[i], e3[i]] for i in range(3)]  # columns e1 e2 e3
    return mm(frame(b1, b2), mt(frame(r1, r2)))


def aberrate(u, v_km_per_s):
    """First-order stellar aberration: u' = normalize(u + v/c − u (u·v/c))."""
    b = scale(v_km_per_s, 1.0 / C_KM_PER_S)
    return unit(add(u, sub(b, scale(u, dot(u, b)))))


# ----------------------------------------------------------------------------- time
def days_from_civil(y, m, d):
    y -= m <= 2
    era = (y if y >= 0 else y - 399) // 400
    yoe = y - era * 400
    doy = (153 * (m + (-3 if m > 2 else 9)) + 2) // 5 + d - 1
    doe = yoe * 365 + yoe // 4 - yoe // 100 + doy
    return era * 146097 + doe - 719468  # days since 1970-01-01


def tai_minus_utc(y, m, d):
    off = 10
    for (ly, lm, ld, val) in LEAP:
        if (y, m, d) >= (ly, lm, ld):
            off = val
    return off


def parse_epoch_utc(s):
    """'YYYY-MM-DDTHH:MM:SSZ' -> TAI seconds since 1958-01-01T00:00:00 TAI (ICD §2)."""
    s = s.rstrip("Z")
    date, clock = s.split("T")
    y, mo, d = (int(x) for x in date.split("-"))
    hh, mi, ss = clock.split(":")
    days = days_from_civil(y, mo, d) - days_from_civil(1958, 1, 1)
    return days * 86400 + int(hh) * 3600 + int(mi) * 60 + float(ss) + tai_minus_utc(y, mo, d)


# J2000.0 = 2000-01-01T12:00:00 TT = 11:59:27.816 TAI.
J2000_TAI1958 = (days_from_civil(2000, 1, 1) - days_from_civil(1958, 1, 1)) * 86400 + 43200 - 32.184


def sun_geocentric_km(tai1958):
    """Meeus ch. 25 (low accuracy, 0.01°): geometric Sun, mean equinox of date, then precessed
    to J2000 by −50.29″/yr in ecliptic longitude. Returns the J2000 position, km."""
    t_tt = tai1958 - J2000_TAI1958
    T = t_tt / (86400.0 * 36525.0)
    L0 = 280.46646 + 36000.76983 * T + 0.0003032 * T * T
    M = 357.52911 + 35999.05029 * T - 0.0001537 * T * T
    e = 0.016708634 - 0.000042037 * T - 0.0000001267 * T * T
    Mr = M * RAD_PER_DEG
    C = ((1.914602 - 0.004817 * T - 0.000014 * T * T) * math.sin(Mr)
         + (0.019993 - 0.000101 * T) * math.sin(2 * Mr) + 0.000289 * math.sin(3 * Mr))
    lon = L0 + C
    nu = (M + C) * RAD_PER_DEG
    R_au = 1.000001018 * (1 - e * e) / (1 + e * math.cos(nu))
    lon_j2000 = (lon - 0.01397 * T * 100.0) * RAD_PER_DEG
    eps = 23.4392911 * RAD_PER_DEG
    x = math.cos(lon_j2000)
    y = math.sin(lon_j2000) * math.cos(eps)
    z = math.sin(lon_j2000) * math.sin(eps)
    return scale([x, y, z], R_au * AU_KM)


def earth_velocity_km_per_s(tai1958):
    """Heliocentric Earth velocity (≈ barycentric), by differencing the Sun formula."""
    h = 60.0
    a = sun_geocentric_km(tai1958 - h)
    b = sun_geocentric_km(tai1958 + h)
    return scale(sub(a, b), 1.0 / (2 * h))  # Earth = −Sun


# A JPL ephemeris where one is at hand: data/sun_reference.csv (DE421 via Skyfield, every
# 33 h of 1991; data/README.md) interpolated with 4-point Lagrange polynomials (error
# < 0.01″ at this spacing). Meeus' low-precision Sun is ≈ 3–18″ off in 1991: a real writer
# flies a real ephemeris, and an inertial Sun error of that size moves through the FSS field
# with every slew, which the ground rightly sees as a structure. Outside the table: Meeus.
SUN_TABLE = os.path.join(ROOT, "data", "sun_reference.csv")
_SUN_ROWS = None


def _csv_columns(path):
    """The data rows of a CSV file whose first non-comment line names the columns (lines
    starting with `#` skipped): for each row, a function from a column name to its text. One
    reader for the Sun table and the star catalog, which share that layout."""
    with open(path) as f:
        header = None
        for line in f:
            if line.startswith("#"):
                continue
            cols = line.strip().split(",")
            if header is None:
                header = {c: i for i, c in enumerate(cols)}
                continue
            yield lambda k, cols=cols, header=header: cols[header[k]]


def _sun_rows():
    global _SUN_ROWS
    if _SUN_ROWS is None:
        _SUN_ROWS = []
        if os.path.exists(SUN_TABLE):
            for col in _csv_columns(SUN_TABLE):
                g = lambda k: float(col(k))
                tai = (g("jd_tt") - 2451545.0) * 86400.0 + J2000_TAI1958
                d = g("sun_dist_au") * AU_KM
                _SUN_ROWS.append((tai, [g("geo_x") * d, g("geo_y") * d, g("geo_z") * d],
                                  [g("earth_vx_kms"), g("earth_vy_kms"), g("earth_vz_kms")]))
    return _SUN_ROWS


def _lagrange(tai1958, which):
    rows = _sun_rows()
    if len(rows) < 4 or not (rows[1][0] <= tai1958 <= rows[-2][0]):
        return None
    j = max(1, min(len(rows) - 3, next(i for i in range(len(rows)) if rows[i][0] > tai1958) - 1))
    pts = rows[j - 1:j + 3]
    out = [0.0, 0.0, 0.0]
    for a, (ta, *va) in enumerate(pts):
        w = 1.0
        for b, (tb, *_vb) in enumerate(pts):
            if a != b:
                w *= (tai1958 - tb) / (ta - tb)
        out = add(out, scale(va[which], w))
    return out


def sun_geocentric(tai1958):
    """Geometric geocentric Sun (J2000/ICRS axes, km): DE421 table, else Meeus."""
    v = _lagrange(tai1958, 0)
    return v if v is not None else sun_geocentric_km(tai1958)


def earth_velocity(tai1958):
    """Earth's barycentric velocity (km/s): DE421 table, else differenced Meeus."""
    v = _lagrange(tai1958, 1)
    return v if v is not None else earth_velocity_km_per_s(tai1958)


# ----------------------------------------------------------------------------- orbit
class Orbit:
    def __init__(self, a_km=6833.0, inc_deg=28.48, raan_deg=40.0, u0_deg=0.0):
        self.a = a_km
        self.n = math.sqrt(MU_EARTH / a_km ** 3)
        i, o = inc_deg * RAD_PER_DEG, raan_deg * RAD_PER_DEG
        self.P = [math.cos(o), math.sin(o), 0.0]
        self.Q = [-math.cos(i) * math.sin(o), math.cos(i) * math.cos(o), math.sin(i)]
        self.u0 = u0_deg * RAD_PER_DEG

    def state(self, t):
        u = self.u0 + self.n * t
        pos = add(scale(self.P, self.a * math.cos(u)), scale(self.Q, self.a * math.sin(u)))
        vel = add(scale(self.P, -self.a * self.n * math.sin(u)),
                  scale(self.Q, self.a * self.n * math.cos(u)))
        return pos, vel


# ----------------------------------------------------------------------------- catalog
def load_catalog(epoch_year):
    stars = []
    for col in _csv_columns(CATALOG):
        hp = float(col("hp_mag"))
        if not (2.0 <= hp <= 5.7):
            continue
        ra = float(col("ra_deg")) * RAD_PER_DEG
        de = float(col("dec_deg")) * RAD_PER_DEG
        pmra = float(col("pmra_mas_yr")) * RAD_PER_ARCSEC / 1000.0
        pmde = float(col("pmdec_mas_yr")) * RAD_PER_ARCSEC / 1000.0
        plx = max(float(col("parallax_mas")), 0.0) * RAD_PER_ARCSEC / 1000.0
        u = [math.cos(de) * math.cos(ra), math.cos(de) * math.sin(ra), math.sin(de)]
        e_ra = [-math.sin(ra), math.cos(ra), 0.0]
        e_de = [-math.sin(de) * math.cos(ra), -math.sin(de) * math.sin(ra), math.cos(de)]
        dt = epoch_year - 1991.25  # catalog epoch J1991.25
        u = unit(add(u, add(scale(e_ra, pmra * dt), scale(e_de, pmde * dt))))
        stars.append((int(col("hip")), u, hp, plx))
    return stars


# ----------------------------------------------------------------------------- packets
class Packets:
    def __init__(self, seq_start=0, time_offset_s=0.0, stream_to=None):
        self.time_offset_s = time_offset_s
        self.seq = {APID_RAW: seq_start, APID_HK: seq_start, APID_EVENT: seq_start,
                    APID_EPH: seq_start, APID_MAG: seq_start}
        self.out = []  # (time, apid, bytes)
        # Streamed straight to the file unless packets are to be reordered or duplicated
        # (a multi-day 1-s run would otherwise hold every packet in memory).
        self.f = open(stream_to, "wb") if stream_to else None
        self.n = 0

    def add(self, apid, tai1958, user):
        tai1958 += self.time_offset_s
        coarse = int(math.floor(tai1958))
        fine = int(round((tai1958 - coarse) * 65536.0))
        if fine == 65536:
            coarse, fine = coarse + 1, 0
        data = struct.pack(">IH", coarse, fine) + user
        seq = self.seq[apid] % 16384
        self.seq[apid] += 1
        hdr = struct.pack(">HHH", (1 << 11) | apid, (3 << 14) | seq, len(data) - 1)
        self.n += 1
        if self.f is not None:
            self.f.write(hdr + data)
        else:
            self.out.append((tai1958, apid, hdr + data))


def i16(x):
    return max(-32768, min(32767, int(round(x))))


# ----------------------------------------------------------------------------- scenario
def build_timeline(args):
    """List of segments: ('hold', duration_s) or ('slew', axis_index, angle_deg, rate_deg_s).

    Slew rates: --slew-rates cycled over the slews in order (default: --slew-rate-deg-s)."""
    hold = args.hold_s
    if args.no_slews:
        return [("hold", args.duration or 4 * hold)]
    if args.plan == "long" or args.days:
        # A calibration day: out-and-back slews about every body axis in both directions,
        # twice, between holds (≈ 5.7 h, ≈ 3.6 orbits): the signatures of time tags (rate),
        # the gyro scale asymmetry (± slews), orbit-periodic and drift terms (time) all occur.
        # --days D: that block of 12 slews repeated until D days are covered (the run is
        # cut at D days); slews in high rate, holds in low rate, as every plan.
        segs = [("hold", hold)]
        block = []
        for axis, ang in ((0, 30.0), (1, 30.0), (2, 25.0)):
            block += [("slew", axis, ang), ("hold", hold), ("slew", axis, -ang), ("hold", hold)]
        if not args.days:
            segs += block + block
        else:
            t = hold
            while t < args.days * 86400.0:
                for seg in block:
                    segs.append(seg)
                    t += hold if seg[0] == "hold" else abs(seg[2]) / args.slew_rate_deg_s
    else:
        segs = [("hold", hold), ("slew", 0, 30.0), ("hold", hold), ("slew", 1, -45.0),
                ("hold", hold), ("slew", 2, 20.0), ("hold", hold)]
    rates = ([float(x) for x in args.slew_rates.split(",")] if args.slew_rates
             else [args.slew_rate_deg_s])
    out, j = [], 0
    for seg in segs:
        if seg[0] == "slew":
            seg = seg + (rates[j % len(rates)],)
            j += 1
        out.append(seg)
    return out


def slew_profile(angle_rad, rate, accel):
    """Trapezoid (or triangle) angle profile: returns (duration, f(t) -> angle)."""
    a = abs(angle_rad)
    sgn = 1.0 if angle_rad >= 0 else -1.0
    t_acc = rate / accel
    if accel * t_acc * t_acc >= a:  # triangle
        t_acc = math.sqrt(a / accel)
        rate = accel * t_acc
        t_cruise = 0.0
    else:
        t_cruise = (a - accel * t_acc * t_acc) / rate
    total = 2 * t_acc + t_cruise

    def f(t):
        t = min(max(t, 0.0), total)
        if t < t_acc:
            return sgn * 0.5 * accel * t * t
        if t < t_acc + t_cruise:
            return sgn * (0.5 * accel * t_acc * t_acc + rate * (t - t_acc))
        td = total - t
        return sgn * (a - 0.5 * accel * td * td)
    return total, f


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--epoch", default="1991-04-10T00:00:00Z", help="UTC start, ISO 8601 with Z")
    p.add_argument("--hold-s", type=float, default=900.0, help="duration of each inertial hold")
    p.add_argument("--duration", type=float, default=None, help="cut the run after this many s")
    p.add_argument("--cycle-s", type=float, default=1.0)
    p.add_argument("--slew-rate-deg-s", type=float, default=0.08)
    p.add_argument("--orbit-phase-deg", type=float, default=180.0, help="argument of latitude at t = 0")
    p.add_argument("--raan-deg", type=float, default=160.0)
    p.add_argument("--no-slews", action="store_true", help="one long inertial hold")
    p.add_argument("--plan", default="short", choices=["short", "long"],
                   help="short: 4 holds, 3 slews (1.4 h); long: 13 holds, 12 out-and-back slews "
                        "about every axis (use --hold-s 1200: 5.7 h)")
    p.add_argument("--temps", default="default", choices=["default", "flat"],
                   help="flat: every temperature constant (no thermal information in telemetry)")
    # ---- injected undeclared effects (recorded in truth_icd.json 'effects'; diagnose is
    # told nothing). Sensor names FHST1, FHST2, FSS1, FSS2; angles arcsec, ACS axes, and
    # alignment variations as M_AS(t) = Rot(θ(t)) M_AS (docs/conventions.md).
    # One table, one add_argument per kind: (flag, repeated, metavar, help); repeated options
    # collect a list (SENSOR:... per sensor), the others hold one value or None.
    injected = [
        ("--time-tag", True, "SENSOR:TAU_S",
         "the sensor samples TAU_S before its time code (FHST or FSS)"),
        ("--orbit-align", True, "SENSOR:c1x,c1y,c1z,s1x,s1y,s1z[,c2x,c2y,c2z,s2x,s2y,s2z]",
         "alignment rotation c1 cos u + s1 sin u (+ c2 cos 2u + s2 sin 2u), u = argument of latitude"),
        ("--fhst-radial", True, "SENSOR:ARCSEC_AT_4DEG[:HV_H:HV_V]",
         "FHST focal-plane distortion: ΔH = k ρ² H, ΔV = k ρ² V (k = size / (4°)³), plus H·V/(4°)² terms"),
        ("--fss-transfer", True, "SENSOR:name=v,...",
         "FSS transfer-function error per head: alpha_scale (ppm), alpha_cross (″ at the 32° corner, x y²), "
          "alpha_cubic (″ at the 32° edge, x³), beta_... the same with α and β exchanged"),
        ("--gyro-asym", False, "AX,AY,AZ",
         "gyro scale asymmetry per ACS axis, ppm: measured = Δθ + a |Δθ|"),
        ("--gyro-ramp", False, "RX,RY,RZ",
         "gyro bias ramp per ACS axis, arcsec/s per hour (bias(t) = b0 + r t)"),
        ("--gyro-rate2", False, "KX,KY,KZ",
         "(outside the library) gyro scale nonlinearity: measured = Δθ (1 + k (ω/1°/s)²), k in ppm"),
        ("--gyro-rate3", False, "KX,KY,KZ",
         "(outside the library) gyro scale nonlinearity: measured = Δθ (1 + k |ω/1°/s|³), k in ppm"),
        ("--gyro-scale-step", False, "T_S:KX,KY,KZ",
         "(outside the library) gyro scale factor change per ACS axis of K ppm from T_S s on: measured = Δθ (1 + k)"),
        ("--gyro-mode-bias", False, "BX,BY,BZ",
         "(outside the library) gyro bias added while the IRU is in high rate mode, arcsec/s (ACS), both triads"),
        ("--gyro-bias-step", True, "T_S:BX,BY,BZ",
         "gyro bias step (in diagnose's library: a step at an unknown time) of (BX, BY, BZ) arcsec/s (ACS) at T_S s from the start, "
          "both triads"),
        ("--gyro-bias-transient", False, "AX,AY,AZ:TAU_S",
         "gyro bias transient added from the start: a e^(−t/TAU_S), a in arcsec/s (ACS), both triads"),
        ("--iru-delta-m", False, "paper|9 ppm",
         "true primary-triad δM (Δθ_acs = (I + δM) G w ΔN, G = prelaunch): 'paper' (the published "
          "δM of data/gro_paper.toml) or 9 numbers row-major in ppm; default 0 (true G = prelaunch)"),
        ("--iru-delta-m-backup", False, "9 ppm",
         "true backup-triad (X1, Y2, Z2) δM, 9 numbers row-major in ppm; default " +
          ",".join(f"{x:g}" for row in DELTA_M_BACKUP_DEFAULT_PPM for x in row)),
        ("--backup-bias", False, "BX,BY,BZ",
         "backup-triad bias in ACS, arcsec/s; default " + ",".join(f"{x:g}" for x in BACKUP_BIAS_DEFAULT)),
    ]
    for flag, repeated, metavar, text in injected:
        if repeated:
            p.add_argument(flag, action="append", default=[], metavar=metavar, help=text)
        else:
            p.add_argument(flag, default=None, metavar=metavar, help=text)
    p.add_argument("--backup-halfway", action="store_true",
                   help="the OBC selects the backup triad (X1, Y2, Z2) at the first cycle at or after half the run that "
                        "is in a hold, in low rate, at least 60 s from any high-rate interval: event 0x0202 (p1 = 1, p2 = 0 commanded), housekeeping byte 106 = 1 from then on")
    p.add_argument("--ringing", action="append", default=[], metavar="SENSOR:AX,AY,AZ:PERIOD_S:DECAY_S",
                   help="(outside the library) mount ringing after every slew: θ = a e^(−t/T) sin(2π t/P), t since the slew ended")
    p.add_argument("--align-step", action="append", default=[], metavar="SENSOR:T_S:X,Y,Z",
                   help="one-time alignment step at T_S s from the start (in diagnose's library: a step at an unknown time)")
    p.add_argument("--downlink-every", type=int, default=1, metavar="N",
                   help="raw frames (0x010) and housekeeping (0x011) only every N cycles (cycles k with k %% N == 0); "
                        "the IRU counters accumulate every cycle, byte 13 is the mode of the last cycle's interval; "
                        "events every cycle, ephemeris at its own period. Refused when the counters could change by "
                        "more than 32767 pulses between two frames (16-bit aliasing)")
    p.add_argument("--rate-switch-at-frames", action="store_true",
                   help="with --downlink-every: widen every high-rate window to frame times, so that no frame "
                        "interval straddles a rate switch (a control case)")
    p.add_argument("--allow-alias", action="store_true",
                   help="write even if the IRU counters alias between frames (to test the ground's handling)")
    p.add_argument("--days", type=float, default=None, metavar="D",
                   help="D days (any --plan): the long plan's block of 12 out-and-back slews (high rate) and --hold-s holds "
                        "(low rate) repeated, cut at D days")
    p.add_argument("--slew-rates", default=None, metavar="R1,R2,...",
                   help="slew rates in deg/s, cycled over the slews in order (default: --slew-rate-deg-s for all)")
    p.add_argument("--no-hk", action="store_true", help="no housekeeping (APID 0x011)")
    p.add_argument("--tam", action="store_true",
                   help="write the magnetics frame (APID 0x013: TAM1, TAM2, CSS) after every raw frame")
    p.add_argument("--tam-bias", default="0,0,-4", metavar="BX,BY,BZ",
                   help="TAM1 (primary) bias, mG, TAM axes (default the paper's 0,0,-4)")
    p.add_argument("--hk-every", type=int, default=1, help="housekeeping with every Nth raw frame")
    p.add_argument("--no-eph", action="store_true", help="no ephemeris (APID 0x020)")
    p.add_argument("--eph-period", type=float, default=60.0, help="ephemeris period, s")
    p.add_argument("--no-events", action="store_true")
    p.add_argument("--missing", action="append", default=[],
                   help="sensor absent for the whole run: FHST1, FHST2, FSS1, FSS2")
    p.add_argument("--invalid", action="append", default=[],
                   help="SENSOR:START:LEN: data-valid flag clear (counts still written)")
    p.add_argument("--gap", action="append", default=[],
                   help="START:LEN seconds from the start: no packets at all")
    p.add_argument("--duplicate-every", type=int, default=0, help="repeat every Nth packet")
    p.add_argument("--reorder-every", type=int, default=0,
                   help="swap packet k and k+1 every N packets")
    p.add_argument("--seq-start", type=int, default=0, help="first CCSDS sequence count")
    p.add_argument("--iru-start", type=int, default=0, help="initial IRU counter value")
    p.add_argument("--extreme", action="store_true",
                   help="valid extremes: counters near wrap, 0.5°/s slews, temperatures −40/+70 °C, Sun at the FSS edge")
    p.add_argument("--time-code-offset-s", type=float, default=0.0,
                   help="add this to every time code without changing the physics (a writer error)")
    p.add_argument("--flip-time-bit", default=None, metavar="K:BIT",
                   help="flip bit BIT (0 = LSB of the 6-octet CUC time code, 16 = LSB of the coarse seconds) of the K-th raw frame's time code (a damaged time code)")
    p.add_argument("--time-shift-after", default=None, metavar="T_S:DELTA_S",
                   help="add DELTA_S to the time code of every packet at or after T_S s from the start, sequence counts unbroken (a clock or time-stamping error of a block)")
    p.add_argument("--low-rate-slews", action="store_true", help="keep the IRU in low rate during slews")
    p.add_argument("--no-annual-aberration", action="store_true",
                   help="(a mis-declared model) star and Sun directions without annual aberration, though "
                        "metadata.json still declares it: the ground must not switch the OBC's correction on")
    p.add_argument("--quiet-iru", action="store_true", help="no gyro bias and no noise")
    p.add_argument("--gyro-arw", type=float, default=2.0e-8, metavar="RAD_PER_SQRT_S",
                   help="angle random walk per body axis and triad (default 2.0e-8)")
    p.add_argument("--gyro-common-noise", type=float, default=0.0, metavar="F",
                   help="fraction (0-1) of the gyro noise variance common to both triads (the "
                        "channel difference of an axis cannot see it)")
    p.add_argument("--backup-channels-dead", action="store_true",
                   help="backup IRU channels X1, Y2, Z2 never move (only the primary is written)")
    p.add_argument("--hk-offset-s", type=float, default=0.0,
                   help="housekeeping time codes this far from the raw frame's (an ICD §4 violation)")
    p.add_argument("--metadata", default="full", choices=["full", "empty", "none"],
                   help="metadata.json with declared figures, '{}', or no file")
    p.add_argument("--misalign", default="default",
                   help="'default' (injected rotations below) or 'none' (true = prelaunch)")
    args = p.parse_args(argv)
    if args.downlink_every < 1:
        p.error("--downlink-every must be >= 1")

    rng = random.Random(args.seed)
    # The gyro's noise has its own generator: the counters of a run with --downlink-every N
    # are then exactly those of the 1-s run at the same cycles (the sensors draw only at frames).
    rng_iru = random.Random(f"iru-{args.seed}")
    # The TAMs draw from their own generator too: --tam changes no other byte of the file.
    rng_tam = random.Random(f"tam-{args.seed}")
    tam_units = None
    if args.tam:
        sys.path.insert(0, HERE)
        import tam_model
        tam_units = [{"bias_mG": [float(x) for x in args.tam_bias.split(",")],
                      "scale_ppm": TAM1_SCALE_PPM, "misalignment_acs_arcsec": TAM1_MISALIGNMENT_ACS_ARCSEC,
                      "noise_mG": 0.2}, TAM2_MODEL]
        tai_utc = tai_minus_utc(*(int(x) for x in args.epoch.split("T")[0].split("-")))
    os.makedirs(args.out, exist_ok=True)
    t0 = parse_epoch_utc(args.epoch)
    epoch_year = 2000.0 + (t0 - J2000_TAI1958) / (86400.0 * 365.25)
    stars = load_catalog(epoch_year)
    orbit = Orbit(raan_deg=args.raan_deg, u0_deg=args.orbit_phase_deg)

    if args.extreme:
        args.slew_rate_deg_s = max(args.slew_rate_deg_s, 0.5)
        if args.iru_start == 0:
            args.iru_start = 65530

    # ---- the truth: alignments = prelaunch rotated by known small rotations (ACS, arcsec).
    inject = {"FHST1": [0.0, 0.0, 0.0], "FHST2": [25.0, -35.0, 40.0],
              "FSS1": [300.0, -200.0, 150.0], "FSS2": [-120.0, 60.0, 90.0]}
    if args.misalign == "none":
        inject = {k: [0.0, 0.0, 0.0] for k in inject}
    m_true = {k: mm(rot(scale(inject[k], RAD_PER_ARCSEC)), M_PRELAUNCH[k]) for k in M_PRELAUNCH}
    # Noise (1σ per axis, before quantisation), arcsec; IRU bias rad/s, ARW rad/√s.
    fhst_sigma = [6.0, 18.0]  # mag 2.0 and 5.7, linear between
    fss_noise_counts = 0.5
    bias = [0.30 * RAD_PER_ARCSEC, -0.20 * RAD_PER_ARCSEC, 0.25 * RAD_PER_ARCSEC]
    arw = args.gyro_arw
    if not 0.0 <= args.gyro_common_noise <= 1.0:
        sys.exit("--gyro-common-noise must lie in [0, 1]")
    if args.quiet_iru:
        bias, arw = [0.0, 0.0, 0.0], 0.0

    # ---- injected undeclared effects, and their truth in the library's parameter names
    # (docs/diagnose.md; the out-of-library ones with the regressor they should follow).
    def floats(x):
        return [float(v) for v in x.split(",")]

    def sensor_of(spec, kinds=("FHST1", "FHST2", "FSS1", "FSS2")):
        name, rest = spec.split(":", 1)
        name = name.upper()
        if name not in kinds:
            p.error(f"{spec}: sensor must be one of {', '.join(kinds)}")
        return name, rest

    effects = []
    tt_off, orbit_align, radial, fss_tf, ringing, steps = {}, {}, {}, {}, {}, {}
    for spec in args.time_tag:
        n, r = sensor_of(spec)
        tt_off[n] = float(r)
        effects.append({"effect": "time_tag_offset", "sensor": n, "in_library": True,
                        "parameters": {"tau": float(r) * 1e3}})
    for spec in args.orbit_align:
        n, r = sensor_of(spec)
        c = floats(r)
        if len(c) not in (6, 12):
            p.error(f"{spec}: 6 or 12 numbers")
        c += [0.0] * (12 - len(c))
        orbit_align[n] = c
        heads = ("cos", "sin", "cos2u", "sin2u") if any(c[6:]) else ("cos", "sin")
        effects.append({"effect": "orbit_periodic_alignment", "sensor": n, "in_library": True,
                        "parameters": {f"{cs}_{ax}": c[3 * j + i] for j, cs in enumerate(heads)
                                       for i, ax in enumerate("xyz")}})
    for spec in args.fhst_radial:
        n, r = sensor_of(spec, ("FHST1", "FHST2"))
        v = [float(x) for x in r.split(":")] + [0.0, 0.0]
        radial[n] = v[:3]
        effects.append({"effect": "fhst_distortion", "sensor": n, "in_library": True,
                        "parameters": {"radial_at_4deg": v[0], "hv_h_at_corner": v[1],
                                       "hv_v_at_corner": v[2]}})
    for spec in args.fss_transfer:
        n, r = sensor_of(spec, ("FSS1", "FSS2"))
        tf = {f"{h}_{k}": 0.0 for h in ("alpha", "beta") for k in ("scale", "cross", "cubic")}
        for kv in r.split(","):
            k, v = kv.split("=")
            if k not in tf:
                p.error(f"{spec}: unknown term {k}")
            tf[k] = float(v)
        fss_tf[n] = tf
        names = {"scale": "scale", "cross": "cross_at_corner", "cubic": "cubic_at_edge"}
        effects.append({"effect": "fss_transfer_function", "sensor": n, "in_library": True,
                        "parameters": {f"{h}_{names[k]}": tf[f"{h}_{k}"] for h in ("alpha", "beta")
                                       for k in ("scale", "cross", "cubic")}})
    asym = floats(args.gyro_asym) if args.gyro_asym else [0.0, 0.0, 0.0]
    if args.gyro_asym:
        effects.append({"effect": "gyro_scale_asymmetry", "sensor": "IRU", "in_library": True,
                        "parameters": dict(zip("xyz", asym))})
    ramp = floats(args.gyro_ramp) if args.gyro_ramp else [0.0, 0.0, 0.0]
    if args.gyro_ramp:
        effects.append({"effect": "gyro_bias_ramp", "sensor": "IRU", "in_library": True,
                        "parameters": dict(zip("xyz", ramp))})
    rate2 = floats(args.gyro_rate2) if args.gyro_rate2 else [0.0, 0.0, 0.0]
    if args.gyro_rate2:
        effects.append({"effect": "gyro_rate_squared_scale", "sensor": "IRU", "in_library": False,
                        "parameters_ppm_at_1deg_s": dict(zip("xyz", rate2)),
                        "unexplained_should_follow": ["slew", "slew_rate"]})
    rate3 = floats(args.gyro_rate3) if args.gyro_rate3 else [0.0, 0.0, 0.0]
    if args.gyro_rate3:
        effects.append({"effect": "gyro_rate_cubed_scale", "sensor": "IRU", "in_library": False,
                        "parameters_ppm_at_1deg_s": dict(zip("xyz", rate3)),
                        "unexplained_should_follow": ["slew", "slew_rate"]})
    scale_step = (0.0, [0.0, 0.0, 0.0])
    if args.gyro_scale_step:
        ts, vec = args.gyro_scale_step.split(":")
        scale_step = (float(ts), floats(vec))
        effects.append({"effect": "gyro_scale_step", "sensor": "IRU", "in_library": False,
                        "t_s": float(ts), "scale_change_ppm": floats(vec),
                        "unexplained_should_follow": ["time_s"]})
    mode_bias = floats(args.gyro_mode_bias) if args.gyro_mode_bias else [0.0, 0.0, 0.0]
    if args.gyro_mode_bias:
        effects.append({"effect": "gyro_high_rate_mode_bias", "sensor": "IRU", "in_library": False,
                        "bias_acs_arcsec_per_s": mode_bias,
                        "unexplained_should_follow": ["rate_mode"]})
    bias_steps = []
    for spec in args.gyro_bias_step:
        ts, vec = spec.split(":")
        bias_steps.append((float(ts), floats(vec)))
        # In diagnose's library since 2026-11-26 (a step at an unknown time, scanned).
        effects.append({"effect": "gyro_bias_step", "sensor": "IRU", "in_library": True,
                        "t_s": float(ts), "step_acs_arcsec_per_s": floats(vec),
                        "parameters": dict(zip("xyz", floats(vec)))})
    transient = None
    if args.gyro_bias_transient:
        amp, tau = args.gyro_bias_transient.split(":")
        transient = (floats(amp), float(tau))
        if float(tau) <= 0:
            p.error("--gyro-bias-transient: TAU_S must be > 0")
        effects.append({"effect": "gyro_bias_transient", "sensor": "IRU", "in_library": True,
                        "parameters": {"x": transient[0][0], "y": transient[0][1], "z": transient[0][2],
                                       "tau_s": transient[1]}})

    def delta_m_of(spec, default):
        if spec is None:
            return [row[:] for row in default]
        if spec == "paper":
            return [row[:] for row in DELTA_M_PAPER]
        v = floats(spec)
        if len(v) != 9:
            p.error(f"{spec}: δM needs 9 numbers (row-major, ppm) or 'paper'")
        return [[v[3 * i + j] * 1e-6 for j in range(3)] for i in range(3)]
    delta_m = {0: delta_m_of(args.iru_delta_m, [[0.0] * 3 for _ in range(3)]),
               1: delta_m_of(args.iru_delta_m_backup,
                             [[x * 1e-6 for x in row] for row in DELTA_M_BACKUP_DEFAULT_PPM])}
    # ΔN = ((I + δM) G w)⁻¹ (Δθ + b Δt + noise) per triad: the ground's (I + δM) G w ΔN is then
    # the true turn plus the bias and noise (ICD §3.1 "IRU", the simulator's convention).
    g_inv_cfg = {c: inv3(mm([[(i == j) + delta_m[c][i][j] for j in range(3)] for i in range(3)], G_PRELAUNCH))
                 for c in (0, 1)}
    backup_bias = floats(args.backup_bias) if args.backup_bias else BACKUP_BIAS_DEFAULT[:]
    if args.quiet_iru:
        backup_bias = [0.0, 0.0, 0.0]
    bias_cfg = {0: bias, 1: [x * RAD_PER_ARCSEC for x in backup_bias]}

    def bias_at(cfg, tt):
        """True bias of a triad at tt (rad/s, ACS): constant + ramp + steps + transient."""
        b = [bias_cfg[cfg][i] + ramp[i] * RAD_PER_ARCSEC * tt / 3600.0 for i in range(3)]
        for (ts, vec) in bias_steps:
            if tt >= ts:
                b = [b[i] + vec[i] * RAD_PER_ARCSEC for i in range(3)]
        if transient is not None:
            f = math.exp(-tt / transient[1])
            b = [b[i] + transient[0][i] * f * RAD_PER_ARCSEC for i in range(3)]
        return b

    for spec in args.ringing:
        n, r = sensor_of(spec)
        amp, per, dec = r.split(":")
        ringing[n] = (floats(amp), float(per), float(dec))
        effects.append({"effect": "post_slew_ringing", "sensor": n, "in_library": False,
                        "amplitude_acs_arcsec": floats(amp), "period_s": float(per), "decay_s": float(dec),
                        "unexplained_should_follow": ["time_since_slew_s"]})
    for spec in args.align_step:
        n, r = sensor_of(spec)
        ts, vec = r.split(":")
        steps.setdefault(n, []).append((float(ts), floats(vec)))
        # In diagnose's library since 2026-11-26 (a step at an unknown time, scanned).
        effects.append({"effect": "alignment_step", "sensor": n, "in_library": True,
                        "t_s": float(ts), "rotation_acs_arcsec": floats(vec),
                        "parameters": dict(zip("xyz", floats(vec)))})

    # ---- the timeline and the attitude: A0 puts the Sun near the FSS1 boresight.
    t_start_sun = unit(sun_geocentric(t0))
    b_sun0 = mv(m_true["FSS1"], unit([math.tan(2.0 * RAD_PER_DEG), math.tan(-3.0 * RAD_PER_DEG), 1.0]))
    if args.extreme:  # Sun 31.5° off the FSS1 boresight in α (the field is ±32°)
        b_sun0 = mv(m_true["FSS1"], unit([math.tan(31.5 * RAD_PER_DEG), 0.0, 1.0]))
    north = [0.0, 0.0, 1.0]
    r2 = unit(cross(t_start_sun, north))
    a_hold = triad(b_sun0, t_start_sun, [0.0, 1.0, 0.0], r2)

    segments = []  # (t_begin, t_end, kind, A_begin, axis, profile)
    t = 0.0
    for seg in build_timeline(args):
        if seg[0] == "hold":
            segments.append((t, t + seg[1], "hold", a_hold, None, None))
            t += seg[1]
        else:
            axis = [0.0, 0.0, 0.0]
            axis[seg[1]] = 1.0
            rate = seg[3] * RAD_PER_DEG
            dur, prof = slew_profile(seg[2] * RAD_PER_DEG, rate, rate / 40.0)
            dur = math.ceil(dur / args.cycle_s) * args.cycle_s
            segments.append((t, t + dur, "slew", a_hold, axis, prof))
            a_hold = mm(rot(scale(axis, prof(dur))), a_hold)
            t += dur
    total = t if args.duration is None else min(t, args.duration)
    if args.days:
        total = min(total, args.days * 86400.0)
    seg_ends = [sg[1] for sg in segments]

    def attitude(tt):
        j = bisect.bisect_left(seg_ends, tt - 1e-9)  # the first segment with tt <= end + 1e-9
        if j < len(segments):
            b, e, kind, a0, axis, prof = segments[j]
            if kind == "hold":
                return a0, 0, None
            return mm(rot(scale(axis, prof(tt - b))), a0), 2, (b, e)
        b, e, kind, a0, axis, prof = segments[-1]
        return (a0 if kind == "hold" else mm(rot(scale(axis, prof(e - b))), a0)), 1, None

    slew_ends = [e for (b, e, kind, _a0, _ax, _p) in segments if kind == "slew"]

    def aligned(name, tt):
        """True M_AS at tt with the injected alignment variations."""
        th = [0.0, 0.0, 0.0]
        if name in orbit_align:
            c = orbit_align[name]
            u = orbit.u0 + orbit.n * tt
            for i in range(3):
                th[i] += (c[i] * math.cos(u) + c[3 + i] * math.sin(u)
                          + c[6 + i] * math.cos(2 * u) + c[9 + i] * math.sin(2 * u))
        if name in ringing:
            amp, per, dec = ringing[name]
            j = bisect.bisect_right(slew_ends, tt)
            if j:
                d = tt - slew_ends[j - 1]
                f = math.exp(-d / dec) * math.sin(2 * math.pi * d / per)
                th = add(th, scale(amp, f))
        for (ts, vec) in steps.get(name, []):
            if tt >= ts:
                th = add(th, vec)
        if th == [0.0, 0.0, 0.0]:
            return m_true[name]
        return mm(rot(scale(th, RAD_PER_ARCSEC)), m_true[name])

    def sensed_attitude(name, tt, a):
        """The attitude the sensor sees: TAU s before its time code when time-tagged late."""
        return attitude(tt - tt_off[name])[0] if name in tt_off else a

    def in_span(spans, tt):
        return any(s <= tt < s + n for (s, n) in spans)

    gaps = [tuple(float(x) for x in g.split(":")) for g in args.gap]
    invalid = {}
    for spec in args.invalid:
        name, s, n = spec.split(":")
        invalid.setdefault(name.upper(), []).append((float(s), float(n)))
    missing = {m.upper() for m in args.missing}

    tm_path = os.path.join(args.out, "telemetry.bin")
    stream = not (args.reorder_every or args.duplicate_every or args.time_shift_after or args.flip_time_bit)
    pk = Packets(args.seq_start, args.time_code_offset_s, tm_path if stream else None)

    def refuse(msg):
        if pk.f is not None:
            pk.f.close()
            os.remove(tm_path)
        sys.stderr.write(msg)
        return 2
    counters = [args.iru_start % 65536] * 6
    frac = [0.0] * 6
    prev_a = None
    tracked = [None, None]  # (hip) per tracker
    cand = [None, None]  # (boresight eci at refresh, list of stars)
    n_cycles = int(round(total / args.cycle_s)) + 1
    next_eph = 0.0
    stats = {"frames": 0, "fhst_samples": [0, 0], "fss_samples": [0, 0], "new_stars": [0, 0],
             "high_rate_frames": 0, "hips": [set(), set()], "per_segment": [],
             "frames_straddling_rate_switch": 0, "max_pulses_between_frames": 0,
             "aliased_frame_intervals": 0, "cycles": n_cycles}
    slew_no = 0
    was_slewing = False
    q_err = rot([4.0 * RAD_PER_ARCSEC, -3.0 * RAD_PER_ARCSEC, 5.0 * RAD_PER_ARCSEC])

    # Rate mode: high from 10 s before a slew to 10 s after it; high_at(tt) is the mode of
    # the interval that ENDS at tt (ICD §3.1 byte 13). A command given at cycle tt applies
    # from the next sample on (ICD §3.3, event 0x0203): the interval that ends at tt + 2
    # cycles; housekeeping byte 107 carries it, event 0x0203 marks its change.
    hi_win = [] if args.low_rate_slews else [(b - 10.0, e + 10.0) for (b, e, kind, *_r) in segments
                                             if kind == "slew"]
    if args.rate_switch_at_frames:  # widen each window to frame times: no frame straddles a switch
        fr = max(args.downlink_every, 1) * args.cycle_s
        hi_win = [(math.floor(s0 / fr) * fr, math.ceil(e0 / fr) * fr) for (s0, e0) in hi_win]
    hi_start = [w[0] for w in hi_win]

    def high_at(tt):
        j = bisect.bisect_left(hi_start, tt) - 1  # the last window with start < tt
        return j >= 0 and tt <= hi_win[j][1]

    # Downlink (raw frame + housekeeping) every N cycles; the counters must not alias.
    n_dl = args.downlink_every
    max_rate_deg_s = max([sg[3] for sg in build_timeline(args) if sg[0] == "slew"], default=0.0)
    w_slew = IRU_LOW_ARCSEC_PER_PULSE if args.low_rate_slews else IRU_HIGH_ARCSEC_PER_PULSE
    # Worst channel: the largest row of ((I + δM) G)⁻¹ times the rate, plus the bias, per frame.
    gmax = max(sum(abs(x) for x in row) for c in (0, 1) for row in g_inv_cfg[c])
    bmax = max(abs(x) for c in (0, 1) for x in bias_at(c, 0.0)) / RAD_PER_ARCSEC
    predicted = (gmax * max_rate_deg_s * 3600.0 / w_slew + bmax / IRU_LOW_ARCSEC_PER_PULSE) * n_dl * args.cycle_s
    alias_check = {"predicted_max_pulses_between_frames": predicted, "limit": 32767,
                   "ground_saturation_pulses": 30000}
    if predicted > 32767 and not args.allow_alias:
        n_ok = int(32767 / (predicted / n_dl))
        return refuse(f"write_run.py: refused: at {max_rate_deg_s:g}°/s in "
                      f"{'low' if args.low_rate_slews else 'high'} rate about {predicted:.0f} pulses pass "
                      f"between two frames {n_dl} cycles apart; the 16-bit counters alias beyond 32767 "
                      f"(ICD §3.1). Use --downlink-every <= {n_ok}, or --allow-alias.\n")
    if predicted > 30000:
        sys.stderr.write(f"write_run.py: warning: up to {predicted:.0f} pulses between frames: the ground "
                         f"excludes a channel above 30000 pulses in a cycle as saturated (ICD §3.1)\n")
    since_frame = [0] * 6  # whole pulses since the last downlinked frame (unwrapped)
    modes_since_frame = set()

    # Backup triad: selected at the first low-rate hold cycle at or after half the run.
    t_switch = None
    if args.backup_halfway:
        for kk in range(int(math.ceil(0.5 * total / args.cycle_s)), n_cycles):
            tk = kk * args.cycle_s
            if not any(high_at(tk + d) or attitude(tk + d)[1] == 2 for d in (-60.0, -30.0, 0.0, 30.0, 60.0)) \
                    and not (hi_start and any(s - 60.0 < tk < e + 60.0 for (s, e) in hi_win)):
                t_switch = tk
                break
        if t_switch is None:
            return refuse("write_run.py: --backup-halfway: no low-rate hold cycle ≥ 60 s from high rate "
                          "in the second half of the run\n")
    cfg_now = 0
    prev_high = False

    for k in range(n_cycles):
        tt = k * args.cycle_s
        tai = t0 + tt
        a, ctrl, slew_span = attitude(tt)
        pos, vel = orbit.state(tt)
        high = high_at(tt)
        high_next = high_at(tt + 2.0 * args.cycle_s)
        high_cmd_prev = high_at(tt + args.cycle_s) if k > 0 else False
        downlink = k % n_dl == 0
        events = []
        if t_switch is not None and cfg_now == 0 and tt >= t_switch - 1e-9:
            cfg_now = 1
            events.append((0x0202, 1, 0))
        if ctrl == 2 and not was_slewing:
            slew_no += 1
            events.append((0x0601, slew_no, 0))
        if ctrl != 2 and was_slewing:
            events.append((0x0602, slew_no, 0))
        was_slewing = ctrl == 2
        if high_next != high_cmd_prev:
            events.append((0x0203, 1 if high_next else 0, 0))
        # ---------------- IRU: Δθ with A_k = Rot(Δθ) A_{k−1}, plus bias and ARW, into pulses.
        w_arcsec = IRU_HIGH_ARCSEC_PER_PULSE if high else IRU_LOW_ARCSEC_PER_PULSE
        if prev_a is not None:
            modes_since_frame.add(high)
            r = mm(a, mt(prev_a))  # Rot(Δθ) = A_k A_{k−1}ᵀ; small angle: Δθ from the skew part
            dth = [0.5 * (r[1][2] - r[2][1]), 0.5 * (r[2][0] - r[0][2]), 0.5 * (r[0][1] - r[1][0])]
            sn = norm(dth)
            if sn > 1e-12:
                dth = scale(dth, math.asin(min(sn, 1.0)) / sn)
            t_mid = tt - 0.5 * args.cycle_s
            # Scale asymmetry (over-reads by a|Δθ| both ways) and the rate² and |rate|³
            # nonlinearities per ACS axis, then the bias (ramp, steps, transient) and the
            # angle random walk; every triad through its own (I + δM) G.
            dth = [dth[i] + asym[i] * 1e-6 * abs(dth[i])
                   + rate2[i] * 1e-6 * dth[i] * (dth[i] / args.cycle_s / RAD_PER_DEG) ** 2
                   + rate3[i] * 1e-6 * dth[i] * abs(dth[i] / args.cycle_s / RAD_PER_DEG) ** 3
                   + (scale_step[1][i] * 1e-6 * dth[i] if t_mid >= scale_step[0] and args.gyro_scale_step else 0.0)
                   for i in range(3)]
            # Noise common to both triads, drawn only when asked (the default stream unchanged).
            f_common = args.gyro_common_noise
            common = ([rng_iru.gauss(0.0, arw * math.sqrt(args.cycle_s)) for _ in range(3)]
                      if f_common > 0.0 else [0.0, 0.0, 0.0])
            for cfg, chans in ((0, (1, 2, 4)), (1, (0, 3, 5))):
                b_now = bias_at(cfg, t_mid)
                if high:
                    b_now = [b_now[i] + mode_bias[i] * RAD_PER_ARCSEC for i in range(3)]
                own = [rng_iru.gauss(0.0, arw * math.sqrt(args.cycle_s)) for _ in range(3)]
                meas = [dth[i] + b_now[i] * args.cycle_s
                        + (own[i] if f_common == 0.0
                           else math.sqrt(1.0 - f_common) * own[i] + math.sqrt(f_common) * common[i])
                        for i in range(3)]
                dn = scale(mv(g_inv_cfg[cfg], meas), 1.0 / (w_arcsec * RAD_PER_ARCSEC))
                if cfg == 1 and args.backup_channels_dead:
                    continue
                for ax, ch in enumerate(chans):
                    if high != prev_high:  # the angle not yet pulsed, in the new pulse weight
                        frac[ch] *= (IRU_HIGH_ARCSEC_PER_PULSE if prev_high else IRU_LOW_ARCSEC_PER_PULSE) / w_arcsec
                    frac[ch] += dn[ax]
                    whole = math.floor(frac[ch])
                    frac[ch] -= whole
                    counters[ch] = (counters[ch] + int(whole)) % 65536
                    since_frame[ch] += int(whole)
        prev_a = a
        prev_high = high
        if not downlink:
            # No raw frame, no housekeeping: only the ephemeris when due, then the events.
            if in_span(gaps, tt):
                continue
            if not args.no_eph and (tt + 1e-9 >= next_eph or k == n_cycles - 1):
                pk.add(APID_EPH, tai, struct.pack(">6d", *pos, *vel))
                while next_eph <= tt + 1e-9:
                    next_eph += args.eph_period
            if not args.no_events:
                for (code, p1, p2) in events:
                    pk.add(APID_EVENT, tai, struct.pack(">HII", code, p1, p2))
            continue
        worst = max(abs(x) for x in since_frame)
        stats["max_pulses_between_frames"] = max(stats["max_pulses_between_frames"], worst)
        if worst > 32767:
            stats["aliased_frame_intervals"] += 1
            if not args.allow_alias:
                return refuse(f"write_run.py: refused: {worst} pulses on one channel between the frames "
                              f"ending at {tt:g} s: the 16-bit counters alias (ICD §3.1); lower "
                              f"--downlink-every or give --allow-alias\n")
        stats["frames_straddling_rate_switch"] += len(modes_since_frame) > 1
        since_frame = [0] * 6
        modes_since_frame = set()
        sun_geo = sun_geocentric(tai)
        v_earth = earth_velocity(tai) if not args.no_annual_aberration else [0.0, 0.0, 0.0]
        v_obs = add(v_earth, vel)
        earth_helio_au = scale(sun_geo, -1.0 / AU_KM)
        observer_au = add(earth_helio_au, scale(pos, 1.0 / AU_KM))
        sun_dir = aberrate(unit(sub(sun_geo, pos)), v_obs)
        # ---------------- FHSTs
        fhst_bytes = b""
        for i, name in enumerate(("FHST1", "FHST2")):
            h = v = mag = 0
            flags = 0
            m_as = aligned(name, tt)
            a_s = sensed_attitude(name, tt, a)
            bore_eci = mv(mt(a_s), mv(m_as, [0.0, 0.0, 1.0]))
            nadir = scale(unit(pos), -1.0)
            earth_radius = math.asin(R_EARTH_KM / norm(pos))
            visible = (name not in missing
                       and math.acos(max(-1.0, min(1.0, dot(bore_eci, nadir)))) > earth_radius + 10 * RAD_PER_DEG
                       and math.acos(max(-1.0, min(1.0, dot(bore_eci, sun_dir)))) > 45 * RAD_PER_DEG)
            if visible:
                if cand[i] is None or dot(cand[i][0], bore_eci) < math.cos(3 * RAD_PER_DEG):
                    c10 = math.cos(10 * RAD_PER_DEG)
                    cand[i] = (bore_eci, [s for s in stars if dot(s[1], bore_eci) > c10])
                m_sens_from_eci = mm(mt(m_as), a_s)
                in_fov = []
                for (hip, u, hp, plx) in cand[i][1]:
                    app = aberrate(unit(sub(u, scale(observer_au, plx))), v_obs)
                    s = mv(m_sens_from_eci, app)
                    if s[2] <= 0:
                        continue
                    hh, vv = math.atan2(s[0], s[2]), math.atan2(s[1], s[2])
                    if abs(hh) < 4 * RAD_PER_DEG and abs(vv) < 4 * RAD_PER_DEG:
                        in_fov.append((hp, hip, hh, vv))
                chosen = None
                for c in in_fov:
                    if c[1] == tracked[i]:
                        chosen = c
                if chosen is None and in_fov:
                    chosen = min(in_fov)
                    flags |= 4
                    stats["new_stars"][i] += 1
                if chosen is not None:
                    hp, hip, hh, vv = chosen
                    if name in radial:
                        k3 = radial[name][0] * RAD_PER_ARCSEC / (4 * RAD_PER_DEG) ** 3
                        hv = hh * vv / (4 * RAD_PER_DEG) ** 2
                        rho2 = hh * hh + vv * vv
                        hh, vv = (hh + k3 * rho2 * hh + radial[name][1] * RAD_PER_ARCSEC * hv,
                                  vv + k3 * rho2 * vv + radial[name][2] * RAD_PER_ARCSEC * hv)
                    tracked[i] = hip
                    sig = fhst_sigma[0] + (min(max(hp, 2.0), 5.7) - 2.0) / 3.7 * (fhst_sigma[1] - fhst_sigma[0])
                    h = i16((hh / RAD_PER_ARCSEC + rng.gauss(0, sig)) / FHST_ARCSEC_PER_COUNT)
                    v = i16((vv / RAD_PER_ARCSEC + rng.gauss(0, sig)) / FHST_ARCSEC_PER_COUNT)
                    mag = i16(hp * 100 + rng.gauss(0, 5))
                    flags |= 3
                    stats["fhst_samples"][i] += 1
                    stats["hips"][i].add(hip)
                else:
                    tracked[i] = None
            else:
                tracked[i] = None
            if in_span(invalid.get(name, []), tt) and flags:
                flags &= ~1
            fhst_bytes += struct.pack(">hhhB", h, v, mag, flags)
        # ---------------- FSSs (shadow: cylindrical Earth shadow)
        in_shadow = dot(pos, unit(sun_geo)) < 0 and norm(cross(pos, unit(sun_geo))) < R_EARTH_KM
        fss_bytes = b""
        for i, name in enumerate(("FSS1", "FSS2")):
            al = be = 0
            flags = 0
            s = mv(mt(aligned(name, tt)), mv(sensed_attitude(name, tt, a), sun_dir))
            if name not in missing and not in_shadow and s[2] > 0:
                aa, bb = math.atan2(s[0], s[2]), math.atan2(s[1], s[2])
                if abs(aa) <= 32 * RAD_PER_DEG and abs(bb) <= 32 * RAD_PER_DEG and name in fss_tf:
                    tf = fss_tf[name]
                    edge = 32 * RAD_PER_DEG
                    x, y = aa / edge, bb / edge
                    aa, bb = (aa + tf["alpha_scale"] * 1e-6 * aa
                              + (tf["alpha_cross"] * x * y * y + tf["alpha_cubic"] * x ** 3) * RAD_PER_ARCSEC,
                              bb + tf["beta_scale"] * 1e-6 * bb
                              + (tf["beta_cross"] * y * x * x + tf["beta_cubic"] * y ** 3) * RAD_PER_ARCSEC)
                if abs(aa) <= 32 * RAD_PER_DEG and abs(bb) <= 32 * RAD_PER_DEG:
                    al = i16(aa / RAD_PER_DEG / FSS_DEG_PER_COUNT + rng.gauss(0, fss_noise_counts))
                    be = i16(bb / RAD_PER_DEG / FSS_DEG_PER_COUNT + rng.gauss(0, fss_noise_counts))
                    flags = 3
                    stats["fss_samples"][i] += 1
            if in_span(invalid.get(name, []), tt) and flags:
                flags = 0  # "Sun present" bits clear: the FSS's only validity flags
            fss_bytes += struct.pack(">hhB", al, be, flags)
        seg_i = min(bisect.bisect_left(seg_ends, tt - 1e-9), len(segments) - 1)
        while len(stats["per_segment"]) <= seg_i:
            sg = segments[len(stats["per_segment"])]
            stats["per_segment"].append({"kind": sg[2], "begin_s": sg[0], "end_s": sg[1],
                                         "fhst": [0, 0], "fss": [0, 0], "shadow": 0})
        ps = stats["per_segment"][seg_i]
        ps["shadow"] += in_shadow
        for j in range(2):
            ps["fhst"][j] += (fhst_bytes[7 * j + 6] & 1)
            ps["fss"][j] += (fss_bytes[5 * j + 4] & 1)
        if args.extreme:
            temps = [-4000, 7000, -4000, 7000, 3276] if k % 2 else [7000, -4000, 7000, -4000, -3276]
        elif args.temps == "flat":
            temps = [2000, 2100, 2500, 2450, 3000]
        else:
            temps = [2000 + int(50 * math.sin(tt / 900.0)), 2100, 2500, 2450, 3000]
        raw = (struct.pack(">6H", *counters) + struct.pack(">BB", 0, 1 if high else 0)
               + fhst_bytes + fss_bytes + struct.pack(">5h", *temps))
        assert len(raw) == 48
        stats["frames"] += 1
        stats["high_rate_frames"] += high
        if in_span(gaps, tt):
            continue
        pk.add(APID_RAW, tai, raw)
        if tam_units is not None:
            b_eci = tam_model.field_eci_mg(tai, tai_utc, pos)
            mag = b"".join(struct.pack(">3hB", *tam_model.tam_counts(rng_tam, a, b_eci, u), 1) for u in tam_units)
            mag += struct.pack(">6HB", *tam_model.css_counts(a, sun_dir, in_shadow), 1)
            assert len(mag) == 27
            pk.add(APID_MAG, tai, mag)
        if not args.no_eph and (tt + 1e-9 >= next_eph or k == n_cycles - 1):
            pk.add(APID_EPH, tai, struct.pack(">6d", *pos, *vel))
            while next_eph <= tt + 1e-9:
                next_eph += args.eph_period
        if not args.no_hk and (k // n_dl) % max(args.hk_every, 1) == 0:
            q = quat_from_dcm(mm(q_err, a))
            hk = struct.pack(">4d", *q)
            # The OBC's bias estimate: the active triad's true bias now (an ideal filter).
            hk += struct.pack(">3d", *bias_at(cfg_now, tt))
            hk += struct.pack(">6d", 1e-10, 1e-10, 1e-10, 1e-16, 1e-16, 1e-16)
            hk += struct.pack(">BBBB", 2, ctrl, cfg_now, 1 if high_next else 0)
            hk += struct.pack(">3f", 0.0, 0.0, 0.0)
            hk += struct.pack(">BffI", 0, 0.0, 0.0, 0) * 4
            hk += struct.pack(">B", 0)
            hk += struct.pack(">10I", k, 0, 0, 0, 0, 0, 0, 0, 0, 0)
            hk += struct.pack(">4I", 0, 0, 0, 0)
            hk += struct.pack(">B", 0)
            assert len(hk) == 230, len(hk)
            pk.add(APID_HK, tai + args.hk_offset_s, hk)
        if not args.no_events:
            for (code, p1, p2) in events:
                pk.add(APID_EVENT, tai, struct.pack(">HII", code, p1, p2))

    if pk.f is not None:
        pk.f.close()
        n_packets = pk.n
    else:
        packets = [b for (_t, _a, b) in pk.out]
        if args.time_shift_after:
            t_cut, delta = (float(x) for x in args.time_shift_after.split(":"))
            t_start = pk.out[0][0] if pk.out else 0.0
            for j, (t, _a, b) in enumerate(pk.out):
                if t - t_start >= t_cut:
                    coarse, fine = struct.unpack(">IH", b[6:12])
                    tc = coarse + fine / 65536.0 + delta
                    c2 = int(math.floor(tc))
                    f2 = int(round((tc - c2) * 65536.0)) % 65536
                    packets[j] = b[:6] + struct.pack(">IH", c2, f2) + b[12:]
        if args.flip_time_bit:
            k, bit = (int(x) for x in args.flip_time_bit.split(":"))
            raws = [j for j, (_t, a, _b) in enumerate(pk.out) if a == APID_RAW]
            j = raws[k]
            code = bytearray(packets[j][6:12])
            code[5 - bit // 8] ^= 1 << (bit % 8)
            packets[j] = packets[j][:6] + bytes(code) + packets[j][12:]
        if args.reorder_every:
            # Swap packet j with j + 2: with a raw frame and a housekeeping packet per cycle that
            # is the same APID one cycle later, so time goes backwards within an APID.
            for j in range(0, len(packets) - 2, args.reorder_every):
                packets[j], packets[j + 2] = packets[j + 2], packets[j]
        if args.duplicate_every:
            packets = [x for j, x in enumerate(packets) for _ in range(2 if j % args.duplicate_every == 0 else 1)]
        with open(tm_path, "wb") as f:
            for b in packets:
                f.write(b)
        n_packets = len(packets)

    meta = {
        "scenario": "icd-writer",
        "epoch_utc": args.epoch,
        "cycle_period_s": args.cycle_s,
        "sensors": {
            # Declared = injected noise with the quantisation (count²/12) added.
            "fhst_sigma_arcsec": [math.hypot(s, FHST_ARCSEC_PER_COUNT / math.sqrt(12)) for s in fhst_sigma],
            "fss_sigma_arcsec": 3600 * FSS_DEG_PER_COUNT * math.sqrt(fss_noise_counts ** 2 + 1 / 12) + 10.0,
            "fss_systematic_arcsec": 20.0,
            "fss_noise_counts": fss_noise_counts,
            "iru_arw_rad_per_sqrt_s": arw,
            "iru_rrw_rad_per_s_sqrt_s": 1e-11,
        },
        "declared_effects": ["aberration", "orbital_aberration", "sun_parallax"],
    }
    if args.metadata == "full":
        with open(os.path.join(args.out, "metadata.json"), "w") as f:
            json.dump(meta, f, indent=2)
    elif args.metadata == "empty":
        with open(os.path.join(args.out, "metadata.json"), "w") as f:
            f.write("{}")
    truth = {
        "writer": "tests/icd/write_run.py",
        "tam": None if tam_units is None else {
            "bias_mG": tam_units[0]["bias_mG"], "scale_ppm": tam_units[0]["scale_ppm"],
            "misalignment_acs_arcsec": tam_units[0]["misalignment_acs_arcsec"],
            "noise_mG_1sigma": tam_units[0]["noise_mG"], "tam2": tam_units[1],
            "field": "IGRF via ppigrf" if tam_model.HAVE_PPIGRF else "IGRF, tests/icd/tam_model.py's own synthesis",
            "model": "B_tam = (I + diag(scale_ppm) 1e-6) Rot(theta)^T (A B_eci) + bias + noise, 0.3 mG/count"},
        "effects": effects,
        "injected_rotation_acs_arcsec": inject,
        "bias_acs_rad_per_s": bias,
        "iru": {
            "primary": {"channels": ["X2", "Y1", "Z1"], "g": G_PRELAUNCH, "delta_m": delta_m[0],
                        "bias_acs_rad_per_s": bias_cfg[0]},
            "backup": {"channels": ["X1", "Y2", "Z2"], "g": G_PRELAUNCH, "delta_m": delta_m[1],
                       "bias_acs_rad_per_s": bias_cfg[1]},
            "convention": "Δθ_acs = (I + delta_m) g w ΔN (channels X, Y, Z of the triad); the ground's δM "
                          "against the flown (prelaunch) G is delta_m; bias(t) = bias + ramp t + steps + "
                          "transient, in ACS, added before (I + delta_m) g is inverted",
            "bias_ramp_arcsec_per_s_per_h": ramp,
            "bias_steps": [{"t_s": ts, "step_acs_arcsec_per_s": v} for (ts, v) in bias_steps],
            "bias_transient": (None if transient is None else
                               {"amplitude_acs_arcsec_per_s": transient[0], "tau_s": transient[1]}),
            "scale_asymmetry_ppm": asym,
            "rate2_ppm_at_1deg_s": rate2,
            "rate3_ppm_at_1deg_s": rate3,
            "high_rate_mode_bias_acs_arcsec_per_s": mode_bias,
            "scale_step": {"t_s": scale_step[0], "ppm": scale_step[1]} if args.gyro_scale_step else None,
            "backup_selected_at_s": t_switch,
            "bias_history": [{"t_s": tb, "primary_acs_arcsec_per_s": [x / RAD_PER_ARCSEC for x in bias_at(0, tb)],
                              "backup_acs_arcsec_per_s": [x / RAD_PER_ARCSEC for x in bias_at(1, tb)]}
                             for tb in [i * min(600.0, max(total, 1.0) / 20) for i in
                                        range(int(total / min(600.0, max(total, 1.0) / 20)) + 1)]],
        },
        "downlink": {"every_n_cycles": n_dl, "cycle_s": args.cycle_s,
                     "frames_straddling_rate_switch": stats["frames_straddling_rate_switch"],
                     "max_pulses_between_frames": stats["max_pulses_between_frames"],
                     "aliased_frame_intervals": stats["aliased_frame_intervals"],
                     **alias_check},
        "cycles": n_cycles,
        "fhst_sigma_arcsec_injected": fhst_sigma,
        "gyro_arw_rad_per_sqrt_s": arw,
        "gyro_common_noise_fraction": args.gyro_common_noise,
        "duration_s": total,
        "frames": stats["frames"],
        "fhst_samples": stats["fhst_samples"],
        "fhst_distinct_stars": [len(s) for s in stats["hips"]],
        "fss_samples": stats["fss_samples"],
        "high_rate_frames": stats["high_rate_frames"],
        "per_segment": stats["per_segment"],
        "packets": n_packets,
        "args": vars(args),
    }
    with open(os.path.join(args.out, "truth_icd.json"), "w") as f:
        json.dump(truth, f, indent=2)
    print(json.dumps({k: truth[k] for k in ("duration_s", "frames", "fhst_samples",
                                             "fhst_distinct_stars", "fss_samples",
                                             "high_rate_frames", "packets")}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
