"""The independent writer's magnetometer (TAM) and coarse Sun sensor (CSS) model (issue 20).

Written from docs/icd.md §3.5 and docs/magnetics.md, without the simulator's or the ground
tool's code: the geomagnetic field is the IGRF (DGRF 1990/1995 of data/igrf_dgrf_1990_1995.csv,
linear in time between 1990-01-01 and 1995-01-01 UTC), synthesised by PyPI `ppigrf`
(`ppigrf.igrf_gc`, geocentric) when it is installed, else by this file's own Schmidt
semi-normalised synthesis of the same coefficients (Wertz 1978, app. H; degree 10). The
GCRS -> ITRS rotation is this file's own: IAU 1976 precession (Lieske 1977), the four largest
nutation terms (Meeus, Astronomical Algorithms ch. 22: <= 0.5" left out), GAST from the IAU 1982
GMST, UT1 = UTC (<= 0.9 s: <= 14" about the pole, <= 0.03 mG of a 400-mG field), no polar
motion. A leap second inside the run is ignored (TAI - UTC of the start date).

TAM model (docs/magnetics.md §2, the writer's own numbers):
    B_tam = (I + diag(scale_ppm) 1e-6) Rot(theta)^T (A B_eci) + bias + noise,
rounded to 0.3 mG per count, clamped at +-600 mG; A the true attitude (m_acs_from_eci),
B_eci in mG (1 mG = 100 nT). CSS: six cosine-law eyes on +-X, +-Y, +-Z of ACS,
1000 counts at normal incidence, no albedo, 0 in the Earth's umbra (cylindrical shadow).
"""
import math
import os

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.normpath(os.path.join(HERE, "..", ".."))
COEFFS = os.path.join(ROOT, "data", "igrf_dgrf_1990_1995.csv")
A_REF_KM = 6371.2
ARCSEC = math.pi / 180.0 / 3600.0
MILLIGAUSS_PER_COUNT = 0.3
RANGE_MG = 600.0

try:  # optional: the reference synthesis of data/igrf_reference.csv
    import ppigrf  # noqa: F401
    import numpy
    import datetime
    HAVE_PPIGRF = True
except ImportError:  # pragma: no cover
    HAVE_PPIGRF = False


def _load():
    rows = []
    with open(COEFFS) as f:
        for line in f:
            if line.startswith("#") or line.startswith("n,"):
                continue
            n, m, g0, h0, g1, h1 = (float(x) for x in line.strip().split(","))
            rows.append((int(n), int(m), g0, h0, g1, h1))
    return rows


_ROWS = _load()


def coefficients(utc_s_since_1990):
    """(g, h) dicts keyed (n, m), nT, linear between 1990-01-01 and 1995-01-01 UTC."""
    span = (365 * 5 + 1) * 86400.0  # 1990-01-01 .. 1995-01-01 (1992 is a leap year)
    f = utc_s_since_1990 / span
    if not 0.0 <= f <= 1.0:
        raise ValueError("outside DGRF 1990-1995")
    g = {(n, m): g0 + f * (g1 - g0) for (n, m, g0, _h0, g1, _h1) in _ROWS}
    h = {(n, m): h0 + f * (h1 - h0) for (n, m, _g0, h0, _g1, h1) in _ROWS}
    return g, h


def field_spherical_nt(g, h, r_km, colat, lon):
    """(B_r, B_theta, B_phi), nT: B = -grad V with Schmidt semi-normalised P_n^m."""
    nmax = 10
    ct, st = math.cos(colat), math.sin(colat)
    # Schmidt semi-normalised P and dP/dtheta by the standard recursion (Wertz app. H).
    p = {(0, 0): 1.0}
    dp = {(0, 0): 0.0}
    for n in range(1, nmax + 1):
        for m in range(0, n + 1):
            if n == m:
                k = math.sqrt(1.0 - 1.0 / (2 * n)) if n > 1 else 1.0
                p[(n, m)] = k * st * p[(n - 1, m - 1)]
                dp[(n, m)] = k * (st * dp[(n - 1, m - 1)] + ct * p[(n - 1, m - 1)])
            else:
                k1 = (2 * n - 1) / math.sqrt(n * n - m * m)
                k2 = math.sqrt(((n - 1) ** 2 - m * m) / (n * n - m * m)) if n - 2 >= m else 0.0
                p2 = p.get((n - 2, m), 0.0)
                dp2 = dp.get((n - 2, m), 0.0)
                p[(n, m)] = k1 * ct * p[(n - 1, m)] - k2 * p2
                dp[(n, m)] = k1 * (ct * dp[(n - 1, m)] - st * p[(n - 1, m)]) - k2 * dp2
    br = bt = bp = 0.0
    for n in range(1, nmax + 1):
        ar = (A_REF_KM / r_km) ** (n + 2)
        for m in range(0, n + 1):
            c, s = math.cos(m * lon), math.sin(m * lon)
            gh = g[(n, m)] * c + h[(n, m)] * s
            br += (n + 1) * ar * gh * p[(n, m)]
            bt -= ar * gh * dp[(n, m)]
            bp += ar * m * (g[(n, m)] * s - h[(n, m)] * c) * p[(n, m)] / max(st, 1e-12)
    return br, bt, bp


def _r1(a):
    c, s = math.cos(a), math.sin(a)
    return [[1, 0, 0], [0, c, s], [0, -s, c]]


def _r2(a):
    c, s = math.cos(a), math.sin(a)
    return [[c, 0, -s], [0, 1, 0], [s, 0, c]]


def _r3(a):
    c, s = math.cos(a), math.sin(a)
    return [[c, s, 0], [-s, c, 0], [0, 0, 1]]


def _mm(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def _mv(m, v):
    return [sum(m[i][k] * v[k] for k in range(3)) for i in range(3)]


def m_itrs_from_gcrs(jd_tt, jd_ut1):
    """IAU 1976 precession, 4-term nutation, GAST (IAU 1982 GMST + equation of equinoxes)."""
    t = (jd_tt - 2451545.0) / 36525.0
    zeta = (2306.2181 * t + 0.30188 * t * t + 0.017998 * t ** 3) * ARCSEC
    z = (2306.2181 * t + 1.09468 * t * t + 0.018203 * t ** 3) * ARCSEC
    theta = (2004.3109 * t - 0.42665 * t * t - 0.041833 * t ** 3) * ARCSEC
    prec = _mm(_r3(-z), _mm(_r2(theta), _r3(-zeta)))
    om = math.radians(125.04452 - 1934.136261 * t)
    lsun = math.radians(280.4665 + 36000.7698 * t)
    lmoon = math.radians(218.3165 + 481267.8813 * t)
    dpsi = (-17.20 * math.sin(om) - 1.32 * math.sin(2 * lsun) - 0.23 * math.sin(2 * lmoon)
            + 0.21 * math.sin(2 * om)) * ARCSEC
    deps = (9.20 * math.cos(om) + 0.57 * math.cos(2 * lsun) + 0.10 * math.cos(2 * lmoon)
            - 0.09 * math.cos(2 * om)) * ARCSEC
    eps = (84381.448 - 46.8150 * t) * ARCSEC
    nut = _mm(_r1(-(eps + deps)), _mm(_r3(-dpsi), _r1(eps)))
    tu = (jd_ut1 - 2451545.0) / 36525.0
    gmst_s = (67310.54841 + (876600.0 * 3600.0 + 8640184.812866) * tu + 0.093104 * tu * tu
              - 6.2e-6 * tu ** 3)
    gast = math.radians((gmst_s % 86400.0) / 240.0) + dpsi * math.cos(eps)
    return _mm(_r3(gast), _mm(nut, prec))


def field_eci_mg(tai1958, tai_minus_utc_s, pos_eci_km):
    """IGRF field on GCRS (= the writer's J2000) axes at pos, mG."""
    utc = tai1958 - tai_minus_utc_s
    # 1958-01-01 -> 1990-01-01: 11688 days; JD of 1958-01-01T00:00 is 2436204.5.
    jd_utc = 2436204.5 + utc / 86400.0
    jd_tt = 2436204.5 + (tai1958 + 32.184) / 86400.0
    m = m_itrs_from_gcrs(jd_tt, jd_utc)
    x = _mv(m, pos_eci_km)
    r = math.sqrt(sum(c * c for c in x))
    colat = math.acos(x[2] / r)
    lon = math.atan2(x[1], x[0])
    if HAVE_PPIGRF:
        when = datetime.datetime(1958, 1, 1) + datetime.timedelta(seconds=utc)
        br, bt, bp = (float(numpy.ravel(v)[0])
                      for v in ppigrf.igrf_gc(r, math.degrees(colat), math.degrees(lon), when))
    else:
        g, h = coefficients(utc - 11688 * 86400.0)
        br, bt, bp = field_spherical_nt(g, h, r, colat, lon)
    ct, st, cp, sp = math.cos(colat), math.sin(colat), math.cos(lon), math.sin(lon)
    # (r, theta, phi) unit vectors in ITRS.
    e_r = [st * cp, st * sp, ct]
    e_t = [ct * cp, ct * sp, -st]
    e_p = [-sp, cp, 0.0]
    b_itrs = [br * e_r[i] + bt * e_t[i] + bp * e_p[i] for i in range(3)]
    b_gcrs = [sum(m[k][i] * b_itrs[k] for k in range(3)) for i in range(3)]
    return [v * 0.01 for v in b_gcrs]


def tam_counts(rng, a_acs_from_eci, b_eci_mg, unit):
    """One TAM's three counts (i16) from its model `unit` (bias_mG, scale_ppm, misalignment_acs_arcsec,
    noise_mG)."""
    b_acs = _mv(a_acs_from_eci, b_eci_mg)
    th = [x * ARCSEC for x in unit["misalignment_acs_arcsec"]]
    # Rot(theta)^T v ~ v + theta x v (first order is enough for arcminute misalignments: the
    # second-order term is 4e-6 of the field, < 0.002 mG).
    mt_v = [b_acs[0] + th[1] * b_acs[2] - th[2] * b_acs[1],
            b_acs[1] + th[2] * b_acs[0] - th[0] * b_acs[2],
            b_acs[2] + th[0] * b_acs[1] - th[1] * b_acs[0]]
    out = []
    for i in range(3):
        v = (1.0 + unit["scale_ppm"][i] * 1e-6) * mt_v[i] + unit["bias_mG"][i] + rng.gauss(0.0, unit["noise_mG"])
        v = max(-RANGE_MG, min(RANGE_MG, v))
        out.append(int(round(v / MILLIGAUSS_PER_COUNT)))
    return out


def css_counts(a_acs_from_eci, sun_eci_unit, in_shadow):
    """Six cosine-law eyes (+X, -X, +Y, -Y, +Z, -Z of ACS), 1000 counts at normal incidence."""
    s = _mv(a_acs_from_eci, sun_eci_unit)
    if in_shadow:
        return [0] * 6
    return [int(round(1000.0 * max(0.0, sign * s[axis]))) for axis in range(3) for sign in (1.0, -1.0)]
