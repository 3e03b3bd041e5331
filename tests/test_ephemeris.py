"""Sun and moon positions: Meeus' worked examples for the geocentric part, PyEphem for the
whole chain (parallax, sidereal time, refraction) at random observers, and `wxsky sun`.

Largest differences over the seeded sample below (400 observers and times, 1950-2050,
latitudes -80..80), measured: unrefracted elevation sun 0.0075°, moon 0.0028°; azimuth (more
than 1° from the zenith) sun 0.025°, moon 0.0066°; refracted elevation above 1° sun 0.0079°,
moon 0.0041°; illuminated fraction 0.003.
"""

from __future__ import annotations

import json
import math
from datetime import UTC, datetime, timedelta

import numpy as np
import pytest

from wxsky.cli import main
from wxsky.scene import ephemeris as eph

ephem = pytest.importorskip("ephem", reason="PyEphem is a dev dependency (pip install -e .[dev])")

ZURICH = (47.4647, 8.5492)
SAMPLE = 400
POSITION_TOL_DEG = 0.1
PHASE_TOL = 0.02


def _jd_ut_for_tt(jde: float) -> float:
    """The UT Julian day at which dynamical time reads `jde` (Meeus gives examples in TD)."""
    jd = jde
    for _ in range(3):
        jd = jde - float(eph.delta_t_s(jd)) / 86400.0
    return jd


def _az_diff(a: float, b: float) -> float:
    return abs((a - b + 180.0) % 360.0 - 180.0)


# -- Meeus' worked examples: the geocentric part ------------------------------------------


def test_example_25a_sun_apparent_place() -> None:
    # 1992 October 13.0 TD: α = 13h13m31.4s = 198.38083°, δ = -7°47'06" = -7.78507°,
    # R = 0.99766 AU. Meeus corrects the obliquity by 0.00256° cos Ω only; the full short
    # nutation used here moves α by 1".
    sun = eph.sun_equatorial(_jd_ut_for_tt(2448908.5))
    assert float(sun.ra_deg) == pytest.approx(198.38083, abs=0.0005)
    assert float(sun.dec_deg) == pytest.approx(-7.78507, abs=0.0002)
    assert float(sun.distance_km) / eph.AU_KM == pytest.approx(0.99766, abs=0.00001)


def test_example_47a_moon_geocentric_place() -> None:
    # 1992 April 12.0 TD: λ = 133.162655°, β = -3.229126°, Δ = 368409.7 km (mean equinox),
    # apparent α = 134.688470°, δ = 13.768368° (Meeus' with the full nutation; ours with the
    # short series differs by under 0.0001°).
    jde = 2448724.5
    t = np.asarray((jde - eph.J2000_JD) / eph.DAYS_PER_CENTURY)
    lam, beta, dist = eph.moon_ecliptic(t)
    assert float(lam) == pytest.approx(133.162655, abs=1e-6)
    assert float(beta) == pytest.approx(-3.229126, abs=1e-6)
    assert float(dist) == pytest.approx(368409.7, abs=0.1)
    moon = eph.moon_equatorial(_jd_ut_for_tt(jde))
    assert float(moon.ra_deg) == pytest.approx(134.688470, abs=0.0001)
    assert float(moon.dec_deg) == pytest.approx(13.768368, abs=0.0001)


def test_example_48a_moon_phase_and_bright_limb() -> None:
    # 1992 April 12.0 TD: k = 0.6786, χ = 285.0°.
    jd = _jd_ut_for_tt(2448724.5)
    phase = eph.moon_phase(eph.sun_equatorial(jd), eph.moon_equatorial(jd))
    assert float(phase.illuminated_fraction) == pytest.approx(0.6786, abs=0.0005)
    assert float(phase.bright_limb_angle_deg) == pytest.approx(285.0, abs=0.1)


def test_example_22a_nutation_and_obliquity() -> None:
    # 1987 April 10.0 TD: Δψ = -3.788", Δε = +9.443", ε = 23°26'36.850". The short series is
    # good to 0.5" and 0.1".
    t = np.asarray((2446895.5 - eph.J2000_JD) / eph.DAYS_PER_CENTURY)
    dpsi, deps, eps = eph.nutation_deg(t)
    assert float(dpsi) * 3600 == pytest.approx(-3.788, abs=0.5)
    assert float(deps) * 3600 == pytest.approx(9.443, abs=0.1)
    assert float(eps) == pytest.approx(23 + 26 / 60 + 36.850 / 3600, abs=0.1 / 3600)


def test_example_12a_sidereal_time() -> None:
    # 1987 April 10, 0h UT: apparent sidereal time at Greenwich 13h10m46.1351s.
    theta = float(eph.apparent_sidereal_deg(2446895.5))
    assert theta == pytest.approx((13 + 10 / 60 + 46.1351 / 3600) * 15, abs=0.0002)


def test_delta_t_matches_observed_values() -> None:
    # Observed TT - UT: 1950 29.1 s, 1980 50.5 s, 2000 63.8 s, 2020 69.4 s; the polynomial
    # runs a few seconds ahead after 2015 (2.5" of moon motion at most).
    years = {1950: 29.1, 1980: 50.5, 2000: 63.8, 2020: 69.4}
    for year, observed in years.items():
        jd = float(eph.julian_day_ut(datetime(year, 1, 1, tzinfo=UTC)))
        assert float(eph.delta_t_s(jd)) == pytest.approx(observed, abs=2.5), year


def test_julian_day_of_the_j2000_epoch_and_naive_times() -> None:
    assert float(eph.julian_day_ut(datetime(2000, 1, 1, 12, tzinfo=UTC))) == 2451545.0
    assert float(eph.julian_day_ut(datetime(1957, 10, 4, 19, 26, 24, tzinfo=UTC))) == (
        pytest.approx(2436116.31, abs=1e-6)  # Meeus example 7.a
    )
    with pytest.raises(ValueError, match="time zone"):
        eph.julian_day_ut(datetime(2026, 1, 1))


# -- the topocentric chain against PyEphem -------------------------------------------------


def _sample() -> tuple[list[datetime], np.ndarray, np.ndarray]:
    rng = np.random.default_rng(20260621)
    start = datetime(1950, 1, 1, tzinfo=UTC)
    seconds = rng.uniform(0.0, 100 * 365.25 * 86400.0, SAMPLE)
    times = [start + timedelta(seconds=round(float(s))) for s in seconds]
    return times, rng.uniform(-80.0, 80.0, SAMPLE), rng.uniform(-180.0, 180.0, SAMPLE)


def _pyephem(
    t: datetime, lat: float, lon: float, pressure_hpa: float
) -> tuple[ephem.Sun, ephem.Moon]:
    obs = ephem.Observer()
    obs.lat, obs.lon = math.radians(lat), math.radians(lon)
    obs.elevation = 0.0
    obs.pressure = pressure_hpa  # 0: no refraction
    obs.temp = eph.STANDARD_TEMPERATURE_C
    obs.date = ephem.Date(t.replace(tzinfo=None))  # PyEphem dates are UTC
    obs.epoch = obs.date
    return ephem.Sun(obs), ephem.Moon(obs)


@pytest.fixture(scope="module")
def sample() -> dict[str, np.ndarray]:
    return compare_sample()


def compare_sample() -> dict[str, np.ndarray]:
    """Ours (vectorised over the whole sample) and PyEphem's, unrefracted and refracted."""
    times, lat, lon = _sample()
    jd = eph.julian_day_ut(times)
    sun_eq, moon_eq = eph.sun_equatorial(jd), eph.moon_equatorial(jd)
    out: dict[str, np.ndarray] = {"lat": lat, "lon": lon}
    for refract in (False, True):
        key = "app" if refract else "geo"
        for name, body in (("sun", sun_eq), ("moon", moon_eq)):
            h = eph.horizontal(body, jd, lat, lon, refract=refract)
            out[f"{name}_el_{key}"], out[f"{name}_az_{key}"] = h.elevation_deg, h.azimuth_deg
    out["k"] = eph.moon_phase(sun_eq, moon_eq).illuminated_fraction
    ref: dict[str, list[float]] = {}
    for t, la, lo in zip(times, lat, lon, strict=True):
        for key, pressure in (("geo", 0.0), ("app", eph.STANDARD_PRESSURE_HPA)):
            sun, moon = _pyephem(t, float(la), float(lo), pressure)
            for name, body in (("sun", sun), ("moon", moon)):
                ref.setdefault(f"ref_{name}_el_{key}", []).append(math.degrees(body.alt))
                ref.setdefault(f"ref_{name}_az_{key}", []).append(math.degrees(body.az))
            if key == "geo":
                ref.setdefault("ref_k", []).append(moon.moon_phase)
    out.update({k: np.asarray(v) for k, v in ref.items()})
    return out


@pytest.mark.parametrize("body", ["sun", "moon"])
def test_unrefracted_positions_match_pyephem(sample: dict[str, np.ndarray], body: str) -> None:
    el, ref_el = sample[f"{body}_el_geo"], sample[f"ref_{body}_el_geo"]
    az, ref_az = sample[f"{body}_az_geo"], sample[f"ref_{body}_az_geo"]
    assert np.abs(el - ref_el).max() <= POSITION_TOL_DEG
    # Azimuth is undefined at the zenith and changes fast next to it.
    away = ref_el < 89.0
    assert away.sum() > 0.95 * SAMPLE
    az_err = np.abs((az - ref_az + 180.0) % 360.0 - 180.0)[away]
    assert az_err.max() <= POSITION_TOL_DEG
    # And much better than the requirement (measured: 0.01° or less).
    assert np.abs(el - ref_el).max() <= 0.02 and az_err.max() <= 0.05


@pytest.mark.parametrize("body", ["sun", "moon"])
def test_refracted_positions_match_pyephem(sample: dict[str, np.ndarray], body: str) -> None:
    """With the same pressure and temperature; near and below the horizon each library
    bends differently (PyEphem's refraction is its own fit), so above 1° only."""
    el, ref_el = sample[f"{body}_el_app"], sample[f"ref_{body}_el_app"]
    up = ref_el > 1.0
    assert up.sum() > 0.3 * SAMPLE
    assert np.abs(el - ref_el)[up].max() <= POSITION_TOL_DEG
    away = up & (ref_el < 89.0)
    az_err = np.abs((sample[f"{body}_az_app"] - sample[f"ref_{body}_az_app"] + 180) % 360 - 180)
    assert az_err[away].max() <= POSITION_TOL_DEG


def test_illuminated_fraction_matches_pyephem(sample: dict[str, np.ndarray]) -> None:
    assert np.abs(sample["k"] - sample["ref_k"]).max() <= PHASE_TOL
    assert sample["k"].min() < 0.05 and sample["k"].max() > 0.95  # the sample spans phases


def test_scalar_front_door_matches_the_vectorised_path() -> None:
    times, lat, lon = _sample()
    jd = eph.julian_day_ut(times[:20])
    moon_h = eph.horizontal(eph.moon_equatorial(jd), jd, lat[:20], lon[:20])
    sun_h = eph.horizontal(eph.sun_equatorial(jd), jd, lat[:20], lon[:20])
    for k in range(20):
        sun, moon = eph.sun_and_moon(times[k], float(lat[k]), float(lon[k]))
        assert sun.elevation_deg == pytest.approx(float(sun_h.elevation_deg[k]), abs=1e-9)
        assert moon.azimuth_deg == pytest.approx(float(moon_h.azimuth_deg[k]), abs=1e-9)
        assert eph.moon_position(times[k], float(lat[k]), float(lon[k])) == moon
        assert eph.sun_position(times[k], float(lat[k]), float(lon[k])) == sun


# -- parallax, phase geometry ---------------------------------------------------------------


def test_moon_parallax_lowers_it_by_up_to_a_degree() -> None:
    times, lat, lon = _sample()
    jd = eph.julian_day_ut(times)
    moon = eph.moon_equatorial(jd)
    topo = eph.horizontal(moon, jd, lat, lon, refract=False)
    geo = eph.horizontal(moon, jd, lat, lon, refract=False, parallax=False)
    drop = geo.elevation_deg - topo.elevation_deg
    # sin p = (ρ / Δ) cos h: the horizontal parallax (0.9-1.0°) times the cosine of the
    # elevation, for an observer on the ellipsoid (ρ 0.997-1.0 earth radii).
    expected = np.degrees(
        np.arcsin(
            eph.EARTH_EQUATORIAL_RADIUS_KM
            / moon.distance_km
            * np.cos(np.radians(geo.elevation_deg))
        )
    )
    # (The ellipsoid tilts the geocentre 0.2° off the local vertical: 0.02° at most here.)
    np.testing.assert_allclose(drop, expected, atol=0.02)
    low = np.abs(geo.elevation_deg) < 10.0
    assert drop[low].max() > 0.9


def test_bright_limb_points_at_the_sun() -> None:
    """χ, turned into a direction on the sky, is where the sun lies from the moon."""
    for hours in range(0, 30 * 24, 37):
        t = datetime(2026, 9, 1, tzinfo=UTC) + timedelta(hours=hours)
        moon = eph.moon_position(t, *ZURICH, refract=False)
        if moon.illuminated_fraction > 0.97:  # the limb angle is ill-defined at full moon
            continue
        # χ is geocentric: so are the directions here (parallax would turn a thin crescent's
        # sunward direction by up to 1.5°).
        jd = eph.julian_day_ut(t)
        m, s = (
            np.asarray(_enu(eph.horizontal(body(jd), jd, *ZURICH, refract=False, parallax=False)))
            for body in (eph.moon_equatorial, eph.sun_equatorial)
        )
        lat = math.radians(ZURICH[0])
        pole = np.array([0.0, math.cos(lat), math.sin(lat)])  # celestial north pole in ENU
        east = np.cross(pole, m)
        east /= np.linalg.norm(east)
        north = np.cross(m, east)
        chi = math.radians(moon.bright_limb_angle_deg)
        limb = math.cos(chi) * north + math.sin(chi) * east
        to_sun = s - m * (m @ s)
        to_sun /= np.linalg.norm(to_sun)
        assert math.degrees(math.acos(np.clip(limb @ to_sun, -1, 1))) < 0.1, t
        # The zenith-relative angle is the same direction measured from "up".
        up = np.array([0.0, 0.0, 1.0]) - m * m[2]
        up /= np.linalg.norm(up)
        # A quarter turn from "up" in the same sense as north to east (n x m = e).
        left = np.cross(up, m)
        zeta = math.radians(moon.bright_limb_from_zenith_deg)
        np.testing.assert_allclose(math.cos(zeta) * up + math.sin(zeta) * left, limb, atol=0.02)


def _enu(h: eph.Horizontal) -> tuple[float, float, float]:
    return eph.SunPosition(float(h.elevation_deg), float(h.azimuth_deg)).direction_enu


def test_phase_cycle_new_to_full() -> None:
    # 2026: new moon Sep 11 03:27 UTC, full moon Sep 26 16:49 UTC.
    new = eph.moon_position(datetime(2026, 9, 11, 3, 27, tzinfo=UTC), *ZURICH)
    full = eph.moon_position(datetime(2026, 9, 26, 16, 49, tzinfo=UTC), *ZURICH)
    assert new.illuminated_fraction < 0.005 and full.illuminated_fraction > 0.995
    first_quarter = eph.moon_position(datetime(2026, 9, 18, 20, 44, tzinfo=UTC), *ZURICH)
    assert first_quarter.illuminated_fraction == pytest.approx(0.5, abs=0.02)
    # Waxing: lit side west of the moon (χ near 270°).
    assert 240.0 < first_quarter.bright_limb_angle_deg < 300.0
    assert 0.24 < full.angular_radius_deg < 0.29


# -- wxsky sun --------------------------------------------------------------------------------


def test_cli_sun_json(capsys: pytest.CaptureFixture[str]) -> None:
    rc = main(
        ["sun", "--lat", "47.4647", "--lon", "8.5492", "--time", "2026-09-10T19:50:00Z", "--json"]
    )
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    sun, moon = eph.sun_and_moon(datetime(2026, 9, 10, 19, 50, tzinfo=UTC), *ZURICH)
    assert out["sun"]["azimuth_deg"] == pytest.approx(sun.azimuth_deg)
    assert out["sun"]["elevation_deg"] == pytest.approx(sun.elevation_deg)
    assert out["moon"]["azimuth_deg"] == pytest.approx(moon.azimuth_deg)
    assert out["moon"]["elevation_deg"] == pytest.approx(moon.elevation_deg)
    assert out["moon"]["illuminated_fraction"] == pytest.approx(moon.illuminated_fraction)
    assert out["sun"]["elevation_deg"] == pytest.approx(-20.1, abs=0.1)


def test_cli_sun_text(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sun", "--lat", "-33.87", "--lon", "151.21", "--time", "2026-06-21T01:53"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[1].split()[:5] == [
        "sun",
        "azimuth_deg",
        lines[1].split()[2],
        "elevation_deg",
        lines[1].split()[4],
    ]
    assert float(lines[1].split()[4]) == pytest.approx(32.7, abs=0.1)  # Sydney's winter noon
    assert lines[2].startswith("moon") and "illuminated_fraction" in lines[2]


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--lat", "95", "--lon", "0", "--time", "2026-01-01T00:00Z"], "--lat 95 is outside"),
        (["--lat", "nan", "--lon", "0", "--time", "2026-01-01T00:00Z"], "--lat nan"),
        (["--lat", "10", "--lon", "400", "--time", "2026-01-01T00:00Z"], "--lon 400"),
        (["--lat", "10", "--lon", "0", "--time", "yesterday noon"], "not an ISO 8601 time"),
        (["--lat", "10", "--lon", "0", "--time", "2026-13-01"], "not an ISO 8601 time"),
    ],
)
def test_cli_sun_bad_input_is_one_line(
    capsys: pytest.CaptureFixture[str], args: list[str], needle: str
) -> None:
    assert main(["sun", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0], err
