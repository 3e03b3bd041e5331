"""Sun and moon: apparent topocentric azimuth and elevation, and the moon's phase.

After Meeus, *Astronomical Algorithms* (2nd ed., 1998):

- time: Julian day from UTC, taken as UT1 (they differ by under 0.9 s, 0.004° of sky
  rotation); dynamical time TT = UT + ΔT from Espenak & Meeus' polynomials (NASA, 2006).
- sun: chapter 25, through the true longitude with the full short nutation and the annual
  aberration (about 0.01°).
- moon: chapter 47 with all 60 + 60 terms of tables 47.A and 47.B (kept, as data, in
  `wxsky.scene.ephemeris_tables`) and the additive terms (10" in longitude, 4" in latitude).
- nutation and obliquity: chapter 22 (the short series, 0.5" in Δψ and 0.1" in Δε; mean
  obliquity 22.2); sidereal time: chapter 12, made apparent by the equation of the equinoxes.
- topocentric parallax: the observer's geocentric position on the WGS-84 ellipsoid
  (chapter 11) subtracted from the body's geocentric vector, which is chapter 40 in vector
  form. For the moon this moves it by up to about 1° (its horizontal parallax, 0.9-1.0°); for
  the sun by under 9".
- refraction: Saemundsson's formula (16.4) for the true altitude, scaled by pressure and
  temperature (default 1010 hPa and 10 °C, the formula's own atmosphere). It is applied
  above a true elevation of -1°, where it bends the horizon up by about 0.6°; below that it
  tapers linearly to zero at -3°, because the formula diverges further down and an object that
  far below the horizon is not seen through the air anyway.
- phase: the illuminated fraction from the phase angle (48.1, 48.3) and the position angle of
  the bright limb (48.5), both from the geocentric positions.

Checked in tests/test_ephemeris.py against PyEphem (random observers 1950-2050) and against
Meeus' worked examples 25.a, 47.a and 48.a.

Everything works on numpy arrays (broadcasting Julian days against latitudes and longitudes);
`sun_position` and `moon_position` are the scalar front doors taking a `datetime`.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import UTC, datetime

import numpy as np
import numpy.typing as npt

from wxsky.scene.ephemeris_tables import MOON_B, MOON_LR

FloatArray = npt.NDArray[np.float64]
ArrayLikeFloat = float | Sequence[float] | FloatArray
Matrix3 = tuple[tuple[float, float, float], tuple[float, float, float], tuple[float, float, float]]

J2000_JD = 2451545.0
J2000_UTC = datetime(2000, 1, 1, 12, 0, 0, tzinfo=UTC)
DAYS_PER_CENTURY = 36525.0
AU_KM = 149_597_870.7
EARTH_EQUATORIAL_RADIUS_KM = 6378.137
EARTH_POLAR_OVER_EQUATORIAL = 1.0 - 1.0 / 298.257223563  # WGS-84
MOON_RADIUS_KM = 1737.4
STANDARD_PRESSURE_HPA = 1010.0
STANDARD_TEMPERATURE_C = 10.0
# Refraction is used as the formula gives it down to this true elevation, then tapered off.
REFRACTION_FULL_DOWN_TO_DEG = -1.0
REFRACTION_ZERO_AT_DEG = -3.0

_D2R = math.pi / 180.0


@dataclass(frozen=True)
class SunPosition:
    elevation_deg: float  # apparent: refracted unless asked otherwise
    azimuth_deg: float  # from true north, clockwise

    @property
    def direction_enu(self) -> tuple[float, float, float]:
        """Unit vector from the observer towards the sun (east, north, up)."""
        return _enu(self.elevation_deg, self.azimuth_deg)


@dataclass(frozen=True)
class MoonPosition:
    elevation_deg: float  # apparent topocentric: parallax applied, refracted unless asked not
    azimuth_deg: float  # from true north, clockwise
    illuminated_fraction: float  # 0 new .. 1 full
    # Position angle of the midpoint of the bright limb, measured on the sky from the
    # direction to the north celestial pole towards the east (Meeus' χ): 270 means the lit
    # side faces west, as in the evening after new moon.
    bright_limb_angle_deg: float
    # The same angle measured from the direction towards the zenith (χ minus the parallactic
    # angle): the tilt of the lit side as an observer sees it, 90 = lit side to the left.
    bright_limb_from_zenith_deg: float
    distance_km: float  # topocentric

    @property
    def direction_enu(self) -> tuple[float, float, float]:
        """Unit vector from the observer towards the moon's centre (east, north, up)."""
        return _enu(self.elevation_deg, self.azimuth_deg)

    @property
    def angular_radius_deg(self) -> float:
        """Apparent semi-diameter: 0.245° at apogee to 0.28° at perigee high in the sky."""
        return math.degrees(math.asin(MOON_RADIUS_KM / self.distance_km))

    def to_dict(self) -> dict[str, object]:
        return {
            "elevation_deg": self.elevation_deg,
            "azimuth_deg": self.azimuth_deg,
            "illuminated_fraction": self.illuminated_fraction,
            "bright_limb_angle_deg": self.bright_limb_angle_deg,
            "bright_limb_from_zenith_deg": self.bright_limb_from_zenith_deg,
            "distance_km": self.distance_km,
            "direction_enu": list(self.direction_enu),
        }


@dataclass(frozen=True)
class Equatorial:
    """Apparent geocentric right ascension and declination, equinox of date."""

    ra_deg: FloatArray
    dec_deg: FloatArray
    distance_km: FloatArray

    def position_km(self) -> FloatArray:
        """(..., 3) geocentric position, x towards the equinox, z towards the pole."""
        ra, dec = self.ra_deg * _D2R, self.dec_deg * _D2R
        unit = np.stack([np.cos(dec) * np.cos(ra), np.cos(dec) * np.sin(ra), np.sin(dec)], -1)
        out: FloatArray = unit * self.distance_km[..., None]
        return out


@dataclass(frozen=True)
class Horizontal:
    azimuth_deg: FloatArray  # from true north, clockwise
    elevation_deg: FloatArray
    distance_km: FloatArray  # topocentric
    parallactic_deg: FloatArray  # angle at the body from the celestial pole to the zenith


@dataclass(frozen=True)
class Phase:
    illuminated_fraction: FloatArray
    bright_limb_angle_deg: FloatArray  # Meeus' χ, from celestial north towards east


# -- time -------------------------------------------------------------------------------


def julian_day_ut(time_utc: datetime | Sequence[datetime]) -> FloatArray:
    """Julian day (UT) of aware datetimes; a naive datetime is an error."""
    times = [time_utc] if isinstance(time_utc, datetime) else list(time_utc)
    for t in times:
        if t.tzinfo is None:
            raise ValueError(f"time {t.isoformat()} has no time zone; give UTC")
    days = np.asarray([(t - J2000_UTC).total_seconds() / 86400.0 for t in times])
    jd: FloatArray = J2000_JD + (days[0] if isinstance(time_utc, datetime) else days)
    return np.asarray(jd, dtype=np.float64)


def delta_t_s(jd_ut: ArrayLikeFloat) -> FloatArray:
    """TT - UT in seconds: Espenak & Meeus' polynomials from 1900 to 2150, their long-term
    parabola outside (about 1 s in the 1950-2020 observations, 5 s by 2025)."""
    year = 2000.0 + (np.asarray(jd_ut, dtype=np.float64) - J2000_JD) / 365.25
    u = (year - 1820.0) / 100.0
    out = -20.0 + 32.0 * u * u
    t = year - 1900.0
    out = np.where(
        (year >= 1900) & (year < 1920),
        -2.79 + t * (1.494119 + t * (-0.0598939 + t * (0.0061966 - 0.000197 * t))),
        out,
    )
    t = year - 1920.0
    out = np.where(
        (year >= 1920) & (year < 1941),
        21.20 + t * (0.84493 + t * (-0.076100 + 0.0020936 * t)),
        out,
    )
    t = year - 1950.0
    out = np.where(
        (year >= 1941) & (year < 1961), 29.07 + t * (0.407 + t * (-1 / 233 + t / 2547)), out
    )
    t = year - 1975.0
    out = np.where(
        (year >= 1961) & (year < 1986), 45.45 + t * (1.067 + t * (-1 / 260 - t / 718)), out
    )
    t = year - 2000.0
    out = np.where(
        (year >= 1986) & (year < 2005),
        63.86
        + t * (0.3345 + t * (-0.060374 + t * (0.0017275 + t * (0.000651814 + t * 0.00002373599)))),
        out,
    )
    out = np.where((year >= 2005) & (year < 2050), 62.92 + t * (0.32217 + t * 0.005589), out)
    out = np.where(
        (year >= 2050) & (year < 2150), -20.0 + 32.0 * u * u - 0.5628 * (2150.0 - year), out
    )
    result: FloatArray = out
    return result


def _centuries_tt(jd_ut: ArrayLikeFloat) -> FloatArray:
    jd = np.asarray(jd_ut, dtype=np.float64)
    t: FloatArray = (jd - J2000_JD + delta_t_s(jd) / 86400.0) / DAYS_PER_CENTURY
    return t


# -- nutation, obliquity, sidereal time --------------------------------------------------


def nutation_deg(t_tt: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(Δψ, Δε, ε): nutation in longitude and obliquity, and the true obliquity, degrees."""
    omega = (125.04452 + t_tt * (-1934.136261 + t_tt * (0.0020708 + t_tt / 450000.0))) * _D2R
    l_sun = (280.4665 + 36000.7698 * t_tt) * _D2R
    l_moon = (218.3165 + 481267.8813 * t_tt) * _D2R
    dpsi = (
        -17.20 * np.sin(omega)
        - 1.32 * np.sin(2 * l_sun)
        - 0.23 * np.sin(2 * l_moon)
        + 0.21 * np.sin(2 * omega)
    ) / 3600.0
    deps = (
        9.20 * np.cos(omega)
        + 0.57 * np.cos(2 * l_sun)
        + 0.10 * np.cos(2 * l_moon)
        - 0.09 * np.cos(2 * omega)
    ) / 3600.0
    eps0_arcsec = 21.448 - t_tt * (46.8150 + t_tt * (0.00059 - t_tt * 0.001813))
    eps0 = 23.0 + 26.0 / 60.0 + eps0_arcsec / 3600.0
    return dpsi, deps, eps0 + deps


def apparent_sidereal_deg(jd_ut: ArrayLikeFloat, lon_deg: ArrayLikeFloat = 0.0) -> FloatArray:
    """Local apparent sidereal time in degrees (Greenwich when lon_deg is 0), 0..360."""
    jd = np.asarray(jd_ut, dtype=np.float64)
    days = jd - J2000_JD
    t = days / DAYS_PER_CENTURY
    # Whole days advance the mean sidereal time by 0.98564736629° each, the fraction by a
    # full turn more: split so the large product keeps its precision.
    whole = np.floor(days)
    frac = days - whole
    gmst = (
        280.46061837
        + (0.98564736629 * whole) % 360.0
        + 360.98564736629 * frac
        + t * t * (0.000387933 - t / 38710000.0)
    )
    dpsi, _deps, eps = nutation_deg(_centuries_tt(jd))
    out: FloatArray = (gmst + dpsi * np.cos(eps * _D2R) + np.asarray(lon_deg)) % 360.0
    return out


# -- the sun (chapter 25) ----------------------------------------------------------------


def sun_equatorial(jd_ut: ArrayLikeFloat) -> Equatorial:
    """Apparent geocentric place of the sun."""
    t = _centuries_tt(jd_ut)
    l0 = 280.46646 + t * (36000.76983 + t * 0.0003032)
    m = (357.52911 + t * (35999.05029 - t * 0.0001537)) * _D2R
    e = 0.016708634 - t * (0.000042037 + t * 0.0000001267)
    c = (
        (1.914602 - t * (0.004817 + t * 0.000014)) * np.sin(m)
        + (0.019993 - t * 0.000101) * np.sin(2 * m)
        + 0.000289 * np.sin(3 * m)
    )
    true_anomaly = m + c * _D2R
    r_au = 1.000001018 * (1.0 - e * e) / (1.0 + e * np.cos(true_anomaly))
    dpsi, _deps, eps = nutation_deg(t)
    lam = (l0 + c + dpsi - 20.4898 / 3600.0 / r_au) * _D2R
    eps_r = eps * _D2R
    ra = np.degrees(np.arctan2(np.cos(eps_r) * np.sin(lam), np.cos(lam))) % 360.0
    dec = np.degrees(np.arcsin(np.sin(eps_r) * np.sin(lam)))
    return Equatorial(ra, dec, r_au * AU_KM)


# -- the moon (chapter 47) ---------------------------------------------------------------


def moon_ecliptic(t_tt: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Geocentric (λ, β, Δ) of the moon, mean equinox of date: degrees, degrees, km."""
    t = np.asarray(t_tt, dtype=np.float64)
    lp = 218.3164477 + t * (481267.88123421 + t * (-0.0015786 + t * (1 / 538841 - t / 65194000)))
    d = 297.8501921 + t * (445267.1114034 + t * (-0.0018819 + t * (1 / 545868 - t / 113065000)))
    m = 357.5291092 + t * (35999.0502909 + t * (-0.0001536 + t / 24490000))
    mp = 134.9633964 + t * (477198.8675055 + t * (0.0087414 + t * (1 / 69699 - t / 14712000)))
    f = 93.2720950 + t * (483202.0175233 + t * (-0.0036539 + t * (-1 / 3526000 + t / 863310000)))
    a1 = (119.75 + 131.849 * t) * _D2R
    a2 = (53.09 + 479264.290 * t) * _D2R
    a3 = (313.45 + 481266.484 * t) * _D2R
    # The eccentricity of the earth's orbit shrinks; terms in M carry it once per multiple.
    e = 1.0 - t * (0.002516 + t * 0.0000074)
    args = np.stack([d, m, mp, f], -1) * _D2R  # (..., 4)

    def series(table: FloatArray) -> tuple[FloatArray, FloatArray]:
        phase = args @ table[:, :4].T  # (..., n)
        e_factor = e[..., None] ** np.abs(table[:, 1])
        return np.sin(phase) * e_factor, np.cos(phase) * e_factor

    sin_lr, cos_lr = series(MOON_LR)
    sin_b, _ = series(MOON_B)
    lpr, fr, mpr = lp * _D2R, f * _D2R, mp * _D2R
    sum_l = sin_lr @ MOON_LR[:, 4] + 3958 * np.sin(a1) + 1962 * np.sin(lpr - fr) + 318 * np.sin(a2)
    sum_r = cos_lr @ MOON_LR[:, 5]
    sum_b = (
        sin_b @ MOON_B[:, 4]
        - 2235 * np.sin(lpr)
        + 382 * np.sin(a3)
        + 175 * np.sin(a1 - fr)
        + 175 * np.sin(a1 + fr)
        + 127 * np.sin(lpr - mpr)
        - 115 * np.sin(lpr + mpr)
    )
    lam = (lp + sum_l / 1e6) % 360.0
    beta = sum_b / 1e6
    dist = 385000.56 + sum_r / 1000.0
    return lam, beta, dist


def moon_equatorial(jd_ut: ArrayLikeFloat) -> Equatorial:
    """Apparent geocentric place of the moon."""
    t = _centuries_tt(jd_ut)
    lam, beta, dist = moon_ecliptic(t)
    dpsi, _deps, eps = nutation_deg(t)
    lam_r, beta_r, eps_r = (lam + dpsi) * _D2R, beta * _D2R, eps * _D2R
    ra = np.arctan2(np.sin(lam_r) * np.cos(eps_r) - np.tan(beta_r) * np.sin(eps_r), np.cos(lam_r))
    dec = np.arcsin(np.sin(beta_r) * np.cos(eps_r) + np.cos(beta_r) * np.sin(eps_r) * np.sin(lam_r))
    return Equatorial(np.degrees(ra) % 360.0, np.degrees(dec), dist)


def moon_phase(sun: Equatorial, moon: Equatorial) -> Phase:
    """Illuminated fraction (48.1 with the exact phase angle, 48.3) and the position angle of
    the bright limb (48.5), from geocentric places."""
    a0, d0 = sun.ra_deg * _D2R, sun.dec_deg * _D2R
    a, d = moon.ra_deg * _D2R, moon.dec_deg * _D2R
    cos_psi = np.sin(d0) * np.sin(d) + np.cos(d0) * np.cos(d) * np.cos(a0 - a)
    psi = np.arccos(np.clip(cos_psi, -1.0, 1.0))
    r_sun, r_moon = sun.distance_km, moon.distance_km
    phase_angle = np.arctan2(r_sun * np.sin(psi), r_moon - r_sun * cos_psi)
    chi = np.arctan2(
        np.cos(d0) * np.sin(a0 - a),
        np.sin(d0) * np.cos(d) - np.cos(d0) * np.sin(d) * np.cos(a0 - a),
    )
    return Phase((1.0 + np.cos(phase_angle)) / 2.0, np.degrees(chi) % 360.0)


# -- observer, parallax, refraction ------------------------------------------------------


def observer_geocentric_km(
    lat_deg: ArrayLikeFloat, sidereal_deg: ArrayLikeFloat, height_m: ArrayLikeFloat = 0.0
) -> FloatArray:
    """(..., 3) geocentric equatorial position of an observer on the WGS-84 ellipsoid at the
    local sidereal time, km (Meeus chapter 11)."""
    phi = np.asarray(lat_deg, dtype=np.float64) * _D2R
    theta = np.asarray(sidereal_deg, dtype=np.float64) * _D2R
    h = np.asarray(height_m, dtype=np.float64) / 1000.0 / EARTH_EQUATORIAL_RADIUS_KM
    u = np.arctan(EARTH_POLAR_OVER_EQUATORIAL * np.tan(phi))
    rho_sin = EARTH_POLAR_OVER_EQUATORIAL * np.sin(u) + h * np.sin(phi)
    rho_cos = np.cos(u) + h * np.cos(phi)
    rho_cos, rho_sin, theta = np.broadcast_arrays(rho_cos, rho_sin, theta)
    out: FloatArray = EARTH_EQUATORIAL_RADIUS_KM * np.stack(
        [rho_cos * np.cos(theta), rho_cos * np.sin(theta), rho_sin], -1
    )
    return out


def equatorial_from_enu_matrix(lat_deg: ArrayLikeFloat, sidereal_deg: ArrayLikeFloat) -> FloatArray:
    """(..., 3, 3) rotation taking an east-north-up vector to the equatorial frame of date
    (x towards the equinox, z towards the celestial pole); its transpose goes back."""
    phi = np.asarray(lat_deg, dtype=np.float64) * _D2R
    theta = np.asarray(sidereal_deg, dtype=np.float64) * _D2R
    phi, theta = np.broadcast_arrays(phi, theta)
    sp, cp, st, ct = np.sin(phi), np.cos(phi), np.sin(theta), np.cos(theta)
    zero = np.zeros_like(phi)
    east = np.stack([-st, ct, zero], -1)
    north = np.stack([-sp * ct, -sp * st, cp], -1)
    up = np.stack([cp * ct, cp * st, sp], -1)
    out: FloatArray = np.stack([east, north, up], -1)  # columns
    return out


def refraction_deg(
    true_elevation_deg: ArrayLikeFloat,
    pressure_hpa: float = STANDARD_PRESSURE_HPA,
    temperature_c: float = STANDARD_TEMPERATURE_C,
) -> FloatArray:
    """How far the air lifts an object at a true (airless) elevation: Saemundsson's formula
    with Meeus' zenith offset, tapered to zero below the horizon (see the module notes)."""
    h = np.asarray(true_elevation_deg, dtype=np.float64)
    h_used = np.maximum(h, REFRACTION_FULL_DOWN_TO_DEG)
    r_arcmin = 1.02 / np.tan((h_used + 10.3 / (h_used + 5.11)) * _D2R) + 0.0019279
    r_arcmin = r_arcmin * (pressure_hpa / 1010.0) * (283.0 / (273.0 + temperature_c))
    taper = np.clip(
        (h - REFRACTION_ZERO_AT_DEG) / (REFRACTION_FULL_DOWN_TO_DEG - REFRACTION_ZERO_AT_DEG),
        0.0,
        1.0,
    )
    out: FloatArray = np.maximum(r_arcmin, 0.0) / 60.0 * taper
    return out


def horizontal(
    body: Equatorial,
    jd_ut: ArrayLikeFloat,
    lat_deg: ArrayLikeFloat,
    lon_deg: ArrayLikeFloat,
    height_m: ArrayLikeFloat = 0.0,
    *,
    refract: bool = True,
    parallax: bool = True,
    pressure_hpa: float = STANDARD_PRESSURE_HPA,
    temperature_c: float = STANDARD_TEMPERATURE_C,
) -> Horizontal:
    """Topocentric azimuth and elevation of a body's geocentric place for observers
    (geocentric, as from the earth's centre, with `parallax=False`)."""
    theta = apparent_sidereal_deg(jd_ut, lon_deg)
    topo = body.position_km()
    if parallax:
        topo = topo - observer_geocentric_km(lat_deg, theta, height_m)
    dist = np.linalg.norm(topo, axis=-1)
    rot = equatorial_from_enu_matrix(lat_deg, theta)
    enu = np.einsum("...ji,...j->...i", rot, topo / dist[..., None])
    el = np.degrees(np.arcsin(np.clip(enu[..., 2], -1.0, 1.0)))
    az = np.degrees(np.arctan2(enu[..., 0], enu[..., 1])) % 360.0
    if refract:
        el = el + refraction_deg(el, pressure_hpa, temperature_c)
    # Parallactic angle q (14.1), from the topocentric hour angle and declination.
    ra = np.arctan2(topo[..., 1], topo[..., 0])
    dec = np.arcsin(np.clip(topo[..., 2] / dist, -1.0, 1.0))
    hour = theta * _D2R - ra
    phi = np.asarray(lat_deg, dtype=np.float64) * _D2R
    q = np.arctan2(np.sin(hour), np.tan(phi) * np.cos(dec) - np.sin(dec) * np.cos(hour))
    return Horizontal(az, el, dist, np.degrees(q))


# -- front doors ---------------------------------------------------------------------------


def sun_and_moon(
    time_utc: datetime,
    lat_deg: float,
    lon_deg: float,
    height_m: float = 0.0,
    *,
    refract: bool = True,
) -> tuple[SunPosition, MoonPosition]:
    """Both bodies at once, sharing the time arguments and the sun's place (the phase needs it)."""
    jd = julian_day_ut(time_utc)
    sun_eq, moon_eq = sun_equatorial(jd), moon_equatorial(jd)
    both = Equatorial(
        np.stack([sun_eq.ra_deg, moon_eq.ra_deg]),
        np.stack([sun_eq.dec_deg, moon_eq.dec_deg]),
        np.stack([sun_eq.distance_km, moon_eq.distance_km]),
    )
    h = horizontal(both, jd, lat_deg, lon_deg, height_m, refract=refract)
    phase = moon_phase(sun_eq, moon_eq)
    chi = float(phase.bright_limb_angle_deg)
    sun = SunPosition(elevation_deg=float(h.elevation_deg[0]), azimuth_deg=float(h.azimuth_deg[0]))
    moon = MoonPosition(
        elevation_deg=float(h.elevation_deg[1]),
        azimuth_deg=float(h.azimuth_deg[1]),
        illuminated_fraction=float(phase.illuminated_fraction),
        bright_limb_angle_deg=chi,
        bright_limb_from_zenith_deg=(chi - float(h.parallactic_deg[1])) % 360.0,
        distance_km=float(h.distance_km[1]),
    )
    return sun, moon


# The sun and moon a frame sees: exact every SMOOTH_STEP_S of time, linear in between. Over two
# seconds the sun moves 0.008 degrees and the moon no faster; the straight line between two
# exact places misses the true path by under a millionth of a degree, where working the
# ephemeris out each frame cost 0.5 ms of a 2 ms frame budget.
SMOOTH_STEP_S = 2.0
# The Unix times the two exact places must lie between: datetime's years, a second inside
# either end so that a float's rounding cannot carry a moment out of them.
_FIRST_S = datetime(1, 1, 1, 0, 0, 1, tzinfo=UTC).timestamp()
_LAST_S = datetime(9999, 12, 31, 23, 59, 58, tzinfo=UTC).timestamp()


def sun_and_moon_smooth(
    time_utc: datetime,
    lat_deg: float,
    lon_deg: float,
    height_m: float = 0.0,
    step_s: float = SMOOTH_STEP_S,
) -> tuple[SunPosition, MoonPosition]:
    """`sun_and_moon` exactly at every multiple of step_s since the Unix epoch and interpolated
    between them: directions along the great circle between the two (no wrap of the azimuth,
    no jump near the zenith), the phase and the limb angles linearly. Continuous in time; the
    two exact places it interpolates are cached, so a frame pays for an ephemeris once per
    step_s."""
    ts = time_utc.timestamp()
    t0 = math.floor(ts / step_s) * step_s
    frac = (ts - t0) / step_s
    if t0 < _FIRST_S or t0 + step_s > _LAST_S:
        # The step's ends would leave datetime's years (a clock at 9999-12-31T23:59:58
        # looked 2 s ahead into year 10000): work this moment out exactly instead.
        return sun_and_moon(time_utc, lat_deg, lon_deg, height_m)
    if frac == 0.0:
        return _exact_bodies(t0, lat_deg, lon_deg, height_m)
    (sun_a, moon_a) = _exact_bodies(t0, lat_deg, lon_deg, height_m)
    (sun_b, moon_b) = _exact_bodies(t0 + step_s, lat_deg, lon_deg, height_m)
    s_el, s_az = _slerp_el_az(sun_a, sun_b, frac)
    m_el, m_az = _slerp_el_az(moon_a, moon_b, frac)
    sun = SunPosition(elevation_deg=s_el, azimuth_deg=s_az)
    moon = MoonPosition(
        elevation_deg=m_el,
        azimuth_deg=m_az,
        illuminated_fraction=_lerp(moon_a.illuminated_fraction, moon_b.illuminated_fraction, frac),
        bright_limb_angle_deg=_lerp_deg(
            moon_a.bright_limb_angle_deg, moon_b.bright_limb_angle_deg, frac
        ),
        bright_limb_from_zenith_deg=_lerp_deg(
            moon_a.bright_limb_from_zenith_deg, moon_b.bright_limb_from_zenith_deg, frac
        ),
        distance_km=_lerp(moon_a.distance_km, moon_b.distance_km, frac),
    )
    return sun, moon


_exact_cache: dict[tuple[float, float, float, float], tuple[SunPosition, MoonPosition]] = {}
_EXACT_CACHE_SIZE = 8  # two per site a frame asks for, a few sites (channels, reports)


def _exact_bodies(
    t_s: float, lat_deg: float, lon_deg: float, height_m: float
) -> tuple[SunPosition, MoonPosition]:
    key = (t_s, lat_deg, lon_deg, height_m)
    hit = _exact_cache.get(key)  # a dict's get and set are atomic: threads may share it
    if hit is None:
        hit = sun_and_moon(datetime.fromtimestamp(t_s, UTC), lat_deg, lon_deg, height_m)
        if len(_exact_cache) >= _EXACT_CACHE_SIZE:
            _exact_cache.clear()
        _exact_cache[key] = hit
    return hit


def _slerp_el_az(
    a: SunPosition | MoonPosition, b: SunPosition | MoonPosition, frac: float
) -> tuple[float, float]:
    # On plain floats: on (3,) arrays the numpy calls were most of a frame's 0.1 ms here.
    ua, ub = a.direction_enu, b.direction_enu
    dot = ua[0] * ub[0] + ua[1] * ub[1] + ua[2] * ub[2]
    angle = math.acos(min(1.0, max(-1.0, dot)))
    if angle < 1e-12:
        v = ua
    else:
        wa, wb, s = math.sin((1.0 - frac) * angle), math.sin(frac * angle), math.sin(angle)
        v = (
            (wa * ua[0] + wb * ub[0]) / s,
            (wa * ua[1] + wb * ub[1]) / s,
            (wa * ua[2] + wb * ub[2]) / s,
        )
    el = math.degrees(math.asin(min(1.0, max(-1.0, v[2]))))
    az = math.degrees(math.atan2(v[0], v[1])) % 360.0
    return el, az


def _lerp(a: float, b: float, frac: float) -> float:
    return a + (b - a) * frac


def _lerp_deg(a: float, b: float, frac: float) -> float:
    return (a + ((b - a + 180.0) % 360.0 - 180.0) * frac) % 360.0


def sun_position(
    time_utc: datetime,
    lat_deg: float,
    lon_deg: float,
    height_m: float = 0.0,
    *,
    refract: bool = True,
) -> SunPosition:
    """Where an observer sees the sun."""
    jd = julian_day_ut(time_utc)
    h = horizontal(sun_equatorial(jd), jd, lat_deg, lon_deg, height_m, refract=refract)
    return SunPosition(elevation_deg=float(h.elevation_deg), azimuth_deg=float(h.azimuth_deg))


def moon_position(
    time_utc: datetime,
    lat_deg: float,
    lon_deg: float,
    height_m: float = 0.0,
    *,
    refract: bool = True,
) -> MoonPosition:
    """Where an observer sees the moon, and how it is lit."""
    return sun_and_moon(time_utc, lat_deg, lon_deg, height_m, refract=refract)[1]


@functools.lru_cache(maxsize=8)
def celestial_from_enu(time_utc: datetime, lat_deg: float, lon_deg: float) -> Matrix3:
    """The rotation taking east-north-up vectors to the equatorial frame of date at a time and
    place, as row tuples: what turns the star field with the sky. Kept for the last few: the
    sky asks for it every frame at the whole second."""
    theta = apparent_sidereal_deg(julian_day_ut(time_utc), lon_deg)
    m = equatorial_from_enu_matrix(lat_deg, theta)
    r0, r1, r2 = (tuple(float(v) for v in row) for row in m)
    return ((r0[0], r0[1], r0[2]), (r1[0], r1[1], r1[2]), (r2[0], r2[1], r2[2]))


def _enu(elevation_deg: float, azimuth_deg: float) -> tuple[float, float, float]:
    el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
    return (math.cos(el) * math.sin(az), math.cos(el) * math.cos(az), math.sin(el))
