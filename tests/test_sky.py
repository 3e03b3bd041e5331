"""Sun position against an independent reference, and the sky parameters derived from it.

The reference is the NOAA Solar Calculator spreadsheet's algorithm (Meeus' low-precision
sun through the equation of time, no refraction), written out below independently of
`wxsky.scene.ephemeris`, which goes through right ascension and sidereal time. Without
refraction the two agree to 0.015°; `sky.sun_position` is refracted, which lifts a sun on the
horizon by about 0.6°. PyEphem comparisons for sun and moon are in tests/test_ephemeris.py.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
from datetime import UTC, datetime, timedelta, timezone

import numpy as np
import pytest

from wxsky.scene import ephemeris
from wxsky.scene.sky import (
    DISTANT_CLOUD_M,
    MIN_HAZE_M,
    DomeControls,
    MoonPosition,
    SunPosition,
    sky_params,
    sun_position,
)
from wxsky.weather.state import CloudLayer, CloudType, Observer, WeatherState, WindLayer

ZURICH = (47.4647, 8.5492)
SYDNEY = (-33.87, 151.21)
# Hand-worked values below are rounded to about 0.1°; the spreadsheet comparisons are tight.
TOL_DEG = 0.15
REF_TOL_DEG = 0.02


def airless_sun(t: datetime, lat: float, lon: float) -> SunPosition:
    return ephemeris.sun_position(t, lat, lon, refract=False)


def noaa_spreadsheet(t: datetime, lat: float, lon: float) -> tuple[float, float]:
    """(elevation, azimuth) in degrees from the NOAA Solar Calculator spreadsheet formulas."""
    jd = t.timestamp() / 86400.0 + 2440587.5
    jc = (jd - 2451545.0) / 36525.0
    l0 = (280.46646 + jc * (36000.76983 + jc * 0.0003032)) % 360.0
    m = math.radians(357.52911 + jc * (35999.05029 - 0.0001537 * jc))
    e = 0.016708634 - jc * (0.000042037 + 0.0000001267 * jc)
    c = (
        math.sin(m) * (1.914602 - jc * (0.004817 + 0.000014 * jc))
        + math.sin(2 * m) * (0.019993 - 0.000101 * jc)
        + math.sin(3 * m) * 0.000289
    )
    omega = math.radians(125.04 - 1934.136 * jc)
    app_long = math.radians(l0 + c - 0.00569 - 0.00478 * math.sin(omega))
    obliq = 23.0 + (26.0 + (21.448 - jc * (46.815 + jc * (0.00059 - jc * 0.001813))) / 60) / 60
    obliq = math.radians(obliq + 0.00256 * math.cos(omega))
    decl = math.asin(math.sin(obliq) * math.sin(app_long))
    y = math.tan(obliq / 2.0) ** 2
    l0r = math.radians(l0)
    eq_time_min = 4.0 * math.degrees(
        y * math.sin(2 * l0r)
        - 2 * e * math.sin(m)
        + 4 * e * y * math.sin(m) * math.cos(2 * l0r)
        - 0.5 * y * y * math.sin(4 * l0r)
        - 1.25 * e * e * math.sin(2 * m)
    )
    minutes = t.hour * 60 + t.minute + t.second / 60.0
    true_solar = (minutes + eq_time_min + 4.0 * lon) % 1440.0
    hour_angle = true_solar / 4.0 - 180.0
    latr, har = math.radians(lat), math.radians(hour_angle)
    cos_zen = math.sin(latr) * math.sin(decl) + math.cos(latr) * math.cos(decl) * math.cos(har)
    zen = math.acos(max(-1.0, min(1.0, cos_zen)))
    cos_az = (math.sin(latr) * math.cos(zen) - math.sin(decl)) / (math.cos(latr) * math.sin(zen))
    a = math.degrees(math.acos(max(-1.0, min(1.0, cos_az))))
    azimuth = (a + 180.0) % 360.0 if hour_angle > 0 else (540.0 - a) % 360.0
    return 90.0 - math.degrees(zen), azimuth


def _separation_deg(a: SunPosition, b: SunPosition) -> float:
    cos = float(np.dot(a.direction_enu, b.direction_enu))
    return math.degrees(math.acos(max(-1.0, min(1.0, cos))))


def _az_diff(a: float, b: float) -> float:
    return abs((a - b + 180.0) % 360.0 - 180.0)


def _at(*args: int) -> datetime:
    return datetime(*args, tzinfo=UTC)


# -- sun position -------------------------------------------------------------------------


def test_zurich_solar_noon_midsummer() -> None:
    # NOAA: solar noon 11:27:40 UTC, elevation 65.97°, azimuth 180.2°.
    # Noon elevation by hand: 90 - 47.4647 + 23.44 = 65.98.
    sun = airless_sun(_at(2026, 6, 21, 11, 28), *ZURICH)
    assert sun.elevation_deg == pytest.approx(65.97, abs=TOL_DEG)
    # Refraction at 66° is under an arcminute.
    refracted = sun_position(_at(2026, 6, 21, 11, 28), *ZURICH)
    assert 0.0 < refracted.elevation_deg - sun.elevation_deg < 0.01
    assert _az_diff(sun.azimuth_deg, 180.21) <= TOL_DEG


def test_zurich_midnight_is_below_the_horizon_to_the_north() -> None:
    sun = sun_position(_at(2026, 6, 21, 0, 0), *ZURICH)
    # No refraction this far below the horizon.
    assert sun == airless_sun(_at(2026, 6, 21, 0, 0), *ZURICH)
    assert sun.elevation_deg == pytest.approx(-18.72, abs=TOL_DEG)
    assert _az_diff(sun.azimuth_deg, 7.86) <= 1.0
    assert sun.direction_enu[2] < 0.0


def test_equator_equinox_noon_is_overhead() -> None:
    # Equinox 2026-03-20 14:46 UTC; solar noon at 0°E that day is 12:07 UTC.
    sun = airless_sun(_at(2026, 3, 20, 12, 7), 0.0, 0.0)
    assert sun.elevation_deg == pytest.approx(90.0, abs=1.0)
    np.testing.assert_allclose(sun.direction_enu, (0, 0, 1), atol=math.radians(1.0))


def test_equator_equinox_morning_sun_is_due_east() -> None:
    # At the equator on the equinox the sun climbs straight up the east-west great circle.
    sun = airless_sun(_at(2026, 3, 20, 9, 0), 0.0, 0.0)
    assert _az_diff(sun.azimuth_deg, 90.0) <= 1.0
    # 3h07 before noon, less the equinox's 0.4° declination's effect: 43.1°.
    assert sun.elevation_deg == pytest.approx(43.13, abs=TOL_DEG)
    east, north, _ = sun.direction_enu
    assert east > 0.7 and abs(north) < 0.02


def test_southern_hemisphere_winter_noon_sun_is_north() -> None:
    # Sydney, June solstice, solar noon about 01:53 UTC: elevation 90 - 33.87 - 23.44.
    sun = airless_sun(_at(2026, 6, 21, 1, 53), *SYDNEY)
    assert sun.elevation_deg == pytest.approx(32.68, abs=TOL_DEG)
    assert _az_diff(sun.azimuth_deg, 1.06) <= TOL_DEG
    assert sun.direction_enu[1] > 0.8


def test_zurich_morning_sun_is_east_north_east() -> None:
    sun = airless_sun(_at(2026, 6, 21, 5, 0), *ZURICH)
    assert sun.elevation_deg == pytest.approx(12.63, abs=TOL_DEG)
    assert _az_diff(sun.azimuth_deg, 68.98) <= TOL_DEG


@pytest.mark.parametrize(
    ("when", "lat", "lon"),
    [
        ((2026, 6, 21, 14, 0), *ZURICH),
        ((2026, 12, 21, 17, 0), -33.9, 18.4),  # Cape Town, summer evening
        ((2026, 12, 21, 10, 0), *SYDNEY),  # night
        ((2026, 1, 15, 16, 0), 40.64, -73.78),  # New York, winter
        ((2024, 2, 29, 15, 30), 60.0, 25.0),  # leap day, low sun
        ((2026, 7, 1, 12, 0, 30), 78.2, 15.6),  # Svalbard midnight-sun season
    ],
)
def test_sun_position_matches_noaa_spreadsheet(when: tuple, lat: float, lon: float) -> None:
    t = _at(*when)
    el, az = noaa_spreadsheet(t, lat, lon)
    sun = airless_sun(t, lat, lon)
    assert sun.elevation_deg == pytest.approx(el, abs=REF_TOL_DEG)
    assert _az_diff(sun.azimuth_deg, az) <= REF_TOL_DEG / max(math.cos(math.radians(el)), 0.2)
    # sky.sun_position is the same sun, refracted.
    refracted = sun_position(t, lat, lon)
    assert refracted.azimuth_deg == sun.azimuth_deg
    expected = sun.elevation_deg + float(ephemeris.refraction_deg(sun.elevation_deg))
    assert refracted.elevation_deg == pytest.approx(expected, abs=1e-9)


def test_sun_position_sweep_within_two_hundredths_of_a_degree() -> None:
    """Over 2024-2030 and five latitudes the airless sun direction stays within 0.02° of the
    reference (measured 0.015°: the spreadsheet's equation-of-time series)."""
    worst = 0.0
    t = _at(2024, 1, 1)
    while t.year < 2031:
        for lat, lon in [ZURICH, (0.0, 0.0), SYDNEY, (65.0, -20.0), (-60.0, -70.0)]:
            ref = SunPosition(*noaa_spreadsheet(t, lat, lon))
            worst = max(worst, _separation_deg(ref, airless_sun(t, lat, lon)))
        t += timedelta(hours=29, minutes=17)
    assert worst <= REF_TOL_DEG


def test_refraction_lifts_the_setting_sun_by_about_half_a_degree() -> None:
    # Saemundsson: 29' at the true horizon (the sun's whole disc is still visible when its
    # centre is geometrically 0.8° down), under 0.1' at the zenith, none far below.
    assert float(ephemeris.refraction_deg(0.0)) * 60 == pytest.approx(28.9, abs=0.3)
    assert float(ephemeris.refraction_deg(45.0)) * 60 == pytest.approx(1.0, abs=0.05)
    assert float(ephemeris.refraction_deg(90.0)) * 60 == pytest.approx(0.0, abs=0.01)
    assert float(ephemeris.refraction_deg(-5.0)) == 0.0
    # Apparent elevation never decreases as the true one grows: no folds in the sky.
    true_el = np.linspace(-6.0, 90.0, 4000)
    assert np.all(np.diff(true_el + ephemeris.refraction_deg(true_el)) > 0.0)


def test_sun_position_accepts_non_utc_aware_times() -> None:
    cet = timezone(timedelta(hours=2))
    a = sun_position(datetime(2026, 6, 21, 13, 28, tzinfo=cet), *ZURICH)
    b = sun_position(_at(2026, 6, 21, 11, 28), *ZURICH)
    assert a == b


def test_direction_enu_is_a_unit_vector_matching_the_angles() -> None:
    d = SunPosition(elevation_deg=30.0, azimuth_deg=90.0).direction_enu
    np.testing.assert_allclose(d, (math.sqrt(3) / 2, 0.0, 0.5), atol=1e-12)
    d = SunPosition(elevation_deg=0.0, azimuth_deg=225.0).direction_enu
    np.testing.assert_allclose(d, (-math.sqrt(0.5), -math.sqrt(0.5), 0.0), atol=1e-12)


# -- sky parameters -----------------------------------------------------------------------


def _state(t: datetime, **kwargs: object) -> WeatherState:
    return WeatherState(observer=Observer(*ZURICH, 432.0), time_utc=t, **kwargs)  # type: ignore[arg-type]


def _lum(rgb: tuple[float, float, float]) -> float:
    return 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]


def _saturation(rgb: tuple[float, float, float]) -> float:
    return (max(rgb) - min(rgb)) / max(rgb)


def test_night_is_darker_than_day() -> None:
    day = sky_params(_state(_at(2026, 6, 21, 11, 30)))
    night = sky_params(_state(_at(2026, 6, 21, 23, 30)))
    assert day.sun.elevation_deg > 60.0 and night.sun.elevation_deg < -15.0
    assert _lum(night.zenith_rgb) < 0.2 * _lum(day.zenith_rgb)
    assert _lum(night.horizon_rgb) < 0.2 * _lum(day.horizon_rgb)
    assert _lum(night.ground_rgb) < _lum(day.ground_rgb)
    assert night.ambient < 0.2 < 0.9 < day.ambient
    assert night.sun_rgb == (0.0, 0.0, 0.0)
    assert min(day.sun_rgb) > 0.8
    # A clear day sky is blue, bluest at the zenith.
    assert day.zenith_rgb[2] > day.zenith_rgb[1] > day.zenith_rgb[0]
    assert day.horizon_rgb[0] > day.zenith_rgb[0]


def test_sunset_tint_only_in_the_horizon_elevation_band() -> None:
    """Sample a whole midsummer day every 10 minutes: the sunset control is zero whenever the
    sun is well up or well down, peaks near the horizon, and reddens the horizon there."""
    noon = sky_params(_state(_at(2026, 6, 21, 11, 30)))
    peak = 0.0
    peak_horizon = noon.horizon_rgb
    for k in range(144):
        sky = sky_params(_state(_at(2026, 6, 21) + timedelta(minutes=10 * k)))
        el = sky.sun.elevation_deg
        assert 0.0 <= sky.sunset <= 1.0
        if el >= 18.0 or el <= -8.0:
            assert sky.sunset == 0.0, f"sunset tint {sky.sunset} at elevation {el:.1f}°"
        if -5.0 <= el <= 3.0:
            assert sky.sunset > 0.3, f"no sunset tint at elevation {el:.1f}°"
        if sky.sunset > peak:
            peak, peak_horizon = sky.sunset, sky.horizon_rgb
    assert peak > 0.8
    # At its peak the horizon is orange: red above blue, unlike the blue-white noon horizon.
    assert peak_horizon[0] > peak_horizon[2]
    assert noon.horizon_rgb[0] < noon.horizon_rgb[2]
    # And the light on the clouds turns warm.
    evening = sky_params(_state(_at(2026, 6, 21, 18, 50)))
    assert evening.sunset > 0.2
    assert evening.sun_rgb[0] > evening.sun_rgb[2] + 0.1


def test_overcast_greys_the_sky() -> None:
    t = _at(2026, 6, 21, 11, 30)
    clear = sky_params(_state(t))
    overcast = sky_params(_state(t, layers=(CloudLayer(8, 800.0, 1300.0, CloudType.STRATUS),)))
    assert overcast.cover == 1.0 and clear.cover == 0.0
    assert _saturation(overcast.zenith_rgb) < 0.5 * _saturation(clear.zenith_rgb)
    assert _saturation(overcast.horizon_rgb) < 0.7 * _saturation(clear.horizon_rgb)
    assert _lum(overcast.zenith_rgb) < _lum(clear.horizon_rgb)
    # Scattered cloud leaves the sky colour alone; layers overlap at random.
    few = sky_params(_state(t, layers=(CloudLayer(2, 1500.0, 2200.0, CloudType.CUMULUS),)))
    assert few.zenith_rgb == clear.zenith_rgb and few.cover == 0.25
    two = (
        CloudLayer(6, 1500.0, 2200.0, CloudType.CUMULUS),
        CloudLayer(7, 5000.0, 5500.0, CloudType.ALTOSTRATUS),
    )
    # 1 - (2/8)(1/8): the gaps of one layer are mostly covered by the other.
    assert sky_params(_state(t, layers=two)).cover == pytest.approx(1.0 - 2 / 64)
    half = (
        CloudLayer(4, 1500.0, 2200.0, CloudType.CUMULUS),
        CloudLayer(4, 5000.0, 5500.0, CloudType.ALTOCUMULUS),
    )
    assert sky_params(_state(t, layers=half)).cover == pytest.approx(0.75)


def test_haze_is_koschmieders_for_the_visibility() -> None:
    t = _at(2026, 6, 21, 11, 30)
    vis = [0.0, 200.0, 700.0, 1000.0, 3000.0, 10_000.0, 50_000.0, 200_000.0]
    haze = [sky_params(_state(t, visibility_m=v)).haze_m for v in vis]
    assert all(h >= MIN_HAZE_M for h in haze)  # never 0: the fade divides by it
    assert all(a < b for a, b in itertools.pairwise(haze))
    # A cloud at the visibility distance keeps 2 % of its contrast, as a dark object does.
    for v, h in zip(vis[2:], haze[2:], strict=True):
        assert math.exp(-v / h) == pytest.approx(0.02, rel=1e-3)


def test_sky_params_to_dict_is_plain_data() -> None:
    sky = sky_params(_state(_at(2026, 6, 21, 11, 30)))
    d = sky.to_dict()
    assert d["sun_elevation_deg"] == sky.sun.elevation_deg
    assert d["sun_direction_enu"] == list(sky.sun.direction_enu)
    assert d["zenith_rgb"] == list(sky.zenith_rgb)
    assert set(d) >= {"ambient", "sunset", "cover", "haze_m", "sun_rgb", "ground_rgb"}
    assert d["moon_elevation_deg"] == sky.moon.elevation_deg
    assert d["moon_azimuth_deg"] == sky.moon.azimuth_deg
    assert d["moon_illuminated_fraction"] == sky.moon.illuminated_fraction
    assert d["moon_direction_enu"] == list(sky.moon.direction_enu)
    assert d["dome"] == sky.dome.to_dict()
    assert set(sky.dome.to_dict()) >= {"cover", "height", "density", "sunset", "speed", "time"}
    assert json.loads(json.dumps(d)) == d


def test_sky_params_follow_the_observer() -> None:
    t = _at(2026, 6, 21, 11, 30)
    zurich = sky_params(_state(t))
    sydney = sky_params(dataclasses.replace(_state(t), observer=Observer(*SYDNEY, 10.0)))
    assert zurich.sun.elevation_deg > 0.0 > sydney.sun.elevation_deg


# -- moon, stars and the cloud dome ---------------------------------------------------------


def test_sky_params_carry_the_ephemeris_moon() -> None:
    t = _at(2026, 6, 21, 22, 0)
    sky = sky_params(_state(t))
    moon = ephemeris.moon_position(t, *ZURICH, 432.0)
    assert isinstance(sky.moon, MoonPosition)
    assert sky.moon == moon
    assert moon.elevation_deg > 5.0  # a first-quarter moon in the south-west
    assert 0.4 < moon.illuminated_fraction < 0.6
    np.testing.assert_allclose(np.linalg.norm(moon.direction_enu), 1.0, atol=1e-12)


def test_stars_come_out_through_twilight_and_hide_behind_cloud() -> None:
    """Sampled every 10 minutes through a winter day: no stars while the sun is up or in
    civil twilight, all of them once it is 15° down, more as it sinks."""
    last_el, last_stars = None, None
    for k in range(144):
        sky = sky_params(_state(_at(2026, 12, 21) + timedelta(minutes=10 * k)))
        el = sky.sun.elevation_deg
        if el > -4.0:
            assert sky.stars == 0.0, (el, sky.stars)
        if el < -15.0:
            assert sky.stars == 1.0, (el, sky.stars)
        if last_el is not None and last_stars is not None and el < last_el:
            assert sky.stars >= last_stars
        last_el, last_stars = el, sky.stars
    night = _at(2026, 12, 21, 22, 0)
    overcast = sky_params(_state(night, layers=(CloudLayer(8, 800.0, 1300.0, CloudType.STRATUS),)))
    broken = sky_params(_state(night, layers=(CloudLayer(6, 1500.0, 2200.0, CloudType.CUMULUS),)))
    assert overcast.stars == 0.0 < broken.stars < 0.6


def test_moon_is_faint_by_day_bright_by_night_and_gone_below_the_horizon() -> None:
    def lum_of(sky: object) -> float:
        return _lum(sky.moon_rgb)  # type: ignore[attr-defined]

    # 2026-06-21: moon up in the afternoon (waxing), and late evening.
    day = sky_params(_state(_at(2026, 6, 21, 14, 0)))
    night = sky_params(_state(_at(2026, 6, 21, 22, 30)))
    assert day.moon.elevation_deg > 10.0 and night.moon.elevation_deg > 5.0
    assert 0.1 < lum_of(day) < 0.5 * lum_of(night)
    below = sky_params(_state(_at(2026, 6, 22, 4, 0)))
    assert below.moon.elevation_deg < -1.0 and below.moon_rgb == (0.0, 0.0, 0.0)


def test_the_moon_shows_through_a_cirrostratus_veil_and_not_through_a_deck() -> None:
    """A whole sky of thin ice cloud leaves most of the moon's light (it is ringed by its halo
    there); a whole deck of water cloud hides most of it."""
    t = _at(2026, 6, 21, 22, 30)

    def moon_under(*layers: CloudLayer) -> float:
        return _lum(sky_params(_state(t, layers=layers)).moon_rgb)

    clear = moon_under()
    veil = moon_under(CloudLayer(8, 9900.0, 10600.0, CloudType.CIRROSTRATUS))
    deck = moon_under(CloudLayer(8, 800.0, 1300.0, CloudType.STRATUS))
    both = moon_under(
        CloudLayer(8, 9900.0, 10600.0, CloudType.CIRROSTRATUS),
        CloudLayer(8, 800.0, 1300.0, CloudType.STRATUS),
    )
    assert clear > 0.3
    assert 0.6 * clear <= veil < clear
    assert deck <= 0.2 * clear and both <= deck


def test_star_field_turns_with_sidereal_time_in_whole_seconds() -> None:
    t = _at(2026, 6, 21, 22, 0, 0)
    a = sky_params(_state(t))
    b = sky_params(_state(t + timedelta(milliseconds=500)))
    c = sky_params(_state(t + timedelta(hours=1)))
    assert a.celestial_from_enu == b.celestial_from_enu
    assert b.sky_time_s - a.sky_time_s == pytest.approx(0.5)
    m = np.asarray(a.celestial_from_enu)
    np.testing.assert_allclose(m @ m.T, np.eye(3), atol=1e-12)
    # The celestial pole stands due north at the observer's latitude.
    pole_enu = m.T @ np.array([0.0, 0.0, 1.0])
    lat = math.radians(ZURICH[0])
    np.testing.assert_allclose(pole_enu, [0.0, math.cos(lat), math.sin(lat)], atol=1e-12)
    # An hour later a star on the celestial equator has moved 15.04° (one sidereal hour).
    star = m @ np.array([0.0, 0.0, 1.0])  # the equatorial direction of the zenith at t
    zenith_later = np.asarray(c.celestial_from_enu) @ np.array([0.0, 0.0, 1.0])
    turned = math.degrees(
        math.atan2(zenith_later[1], zenith_later[0]) - math.atan2(star[1], star[0])
    )
    assert turned % 360.0 == pytest.approx(15.041, abs=0.002)


def test_dome_controls_from_the_weather() -> None:
    t = _at(2026, 5, 20, 10, 0)
    clear = sky_params(_state(t)).dome
    assert clear.cover == 0.0 and clear.high_cover == 0.0
    # Local mean solar time: 10:00 UTC at 8.55° E is 10:34.
    assert clear.time == pytest.approx((10.0 + 8.5492 / 15.0) / 24.0)
    cirrus = (
        CloudLayer(2, 8500.0, 9600.0, CloudType.CIRRUS),
        CloudLayer(1, 9900.0, 10600.0, CloudType.CIRROSTRATUS),
    )
    wind = (WindLayer(442.0, 220.0, 3.0), WindLayer(9000.0, 250.0, 38.0))
    high = sky_params(_state(t, layers=cirrus, wind=wind)).dome
    assert isinstance(high, DomeControls)
    assert high.high_cover == pytest.approx(high.cover) == pytest.approx(1 - (6 / 8) * (7 / 8))
    assert high.height == pytest.approx(9900.0 / 13_000.0)
    assert high.density < 0.2  # ice veils are thin
    assert high.speed == pytest.approx(38.0 / 60.0, abs=0.02)
    assert high.drift_toward_deg == pytest.approx(70.0, abs=1.0)  # blown from 250°
    low = sky_params(_state(t, layers=(CloudLayer(5, 1500.0, 2600.0, CloudType.CUMULUS),))).dome
    assert low.high_cover == 0.0 and low.cover == pytest.approx(5 / 8)
    assert low.density > high.density
    edge = math.degrees(math.atan2(1500.0 - 432.0, DISTANT_CLOUD_M))
    assert low.horizon_deg == pytest.approx(edge)
    for dome in (clear, high, low):
        for name in ("cover", "height", "density", "sunset", "speed", "time", "high_cover"):
            assert 0.0 <= getattr(dome, name) <= 1.0, name
    # The sunset control is the sky's.
    evening = sky_params(_state(_at(2026, 6, 21, 19, 20), layers=cirrus))
    assert evening.dome.sunset == evening.sunset > 0.3


def test_the_frames_sun_and_moon_are_the_ephemeris_interpolated_without_steps() -> None:
    from wxsky.scene.ephemeris import SMOOTH_STEP_S, sun_and_moon, sun_and_moon_smooth

    def apart_deg(a: tuple[float, float, float], b: tuple[float, float, float]) -> float:
        return math.degrees(math.acos(min(1.0, float(np.dot(a, b)))))

    rng = np.random.default_rng(19)
    start = datetime(2026, 1, 1, tzinfo=UTC)
    # Sites from pole to pole, the sun near the zenith at the tropics among them.
    for _ in range(300):
        t = start + timedelta(seconds=float(rng.uniform(0.0, 3.15e7)))
        lat, lon = float(rng.uniform(-89.0, 89.0)), float(rng.uniform(-180.0, 180.0))
        (sun, moon), (s_sun, s_moon) = sun_and_moon(t, lat, lon), sun_and_moon_smooth(t, lat, lon)
        assert apart_deg(sun.direction_enu, s_sun.direction_enu) < 1e-5
        assert apart_deg(moon.direction_enu, s_moon.direction_enu) < 1e-5
        assert abs(moon.illuminated_fraction - s_moon.illuminated_fraction) < 1e-8
        limb = moon.bright_limb_from_zenith_deg - s_moon.bright_limb_from_zenith_deg
        assert abs((limb + 180.0) % 360.0 - 180.0) < 0.01
    # Exact on the grid; across a grid point the places run on without a step (a frame's
    # worth of motion, not a jump).
    grid = datetime.fromtimestamp(1_780_000_000.0 - 1_780_000_000.0 % SMOOTH_STEP_S, UTC)
    assert sun_and_moon_smooth(grid, 47.0, 8.0) == sun_and_moon(grid, 47.0, 8.0)
    tick = timedelta(milliseconds=1)
    before = sun_and_moon_smooth(grid - tick, 47.0, 8.0)
    after = sun_and_moon_smooth(grid + tick, 47.0, 8.0)
    frame_deg = 360.0 / 86400.0 * 0.002  # the sky turns this far in 2 ms
    for a, b in zip(before, after, strict=True):
        assert 0.0 < apart_deg(a.direction_enu, b.direction_enu) < 2.0 * frame_deg


def test_a_frame_on_the_same_sky_step_keeps_the_sky_and_runs_its_clock() -> None:
    from wxsky.scene.sky import SKY_EPOCH_UTC, SKY_STEP_US, bodies_for, on_sky_step

    t = _at(2026, 6, 21, 18, 30) + timedelta(microseconds=SKY_STEP_US // 4)
    state = _state(t, layers=(CloudLayer(4.0, 1500.0, 2500.0, CloudType.CUMULUS),))
    frame = timedelta(seconds=1.0 / 30.0)
    later = state.at_time(t + frame)  # the same step: a quarter plus a 30th of an eighth
    assert (
        on_sky_step(later.time_utc)
        == on_sky_step(t)
        == t - timedelta(microseconds=SKY_STEP_US // 4)
    )
    first = sky_params(state, 1000.0)
    again = sky_params(later, 1000.0)
    # The sky's colours and bodies are the same objects (what is kept by them holds) ...
    assert again.sun is first.sun and again.zenith_rgb is first.zenith_rgb
    assert dataclasses.replace(again, sky_time_s=first.sky_time_s) == first
    # ... and its clock is the frame's own, to the microsecond.
    assert again.sky_time_s == (later.time_utc - SKY_EPOCH_UTC).total_seconds()
    assert again.sky_time_s - first.sky_time_s == pytest.approx(1.0 / 30.0, abs=1e-6)
    known = bodies_for(state)
    assert bodies_for(later, known) is known
    # The next step moves the sun, by what it moves in an eighth of a second.
    step = state.at_time(on_sky_step(t) + timedelta(microseconds=SKY_STEP_US))
    moved = sky_params(step, 1000.0).sun
    apart_deg = math.degrees(
        math.acos(min(1.0, float(np.dot(moved.direction_enu, first.sun.direction_enu))))
    )
    assert 0.0 < apart_deg < 360.0 / 86400.0 * SKY_STEP_US * 1e-6 * 1.01


def test_the_kept_sky_is_the_sky_worked_out_afresh() -> None:
    """Whatever changes between frames (the clock across steps and seconds, the eye's height
    through a layer and above the haze, the weather), the sky reused from the frame before is
    the one worked out with nothing kept."""
    from wxsky.scene import sky as sky_module

    stratus = CloudLayer(6.0, 800.0, 1400.0, CloudType.STRATUS)
    cirrus = CloudLayer(3.0, 8000.0, 8500.0, CloudType.CIRRUS)
    start = _at(2026, 6, 21, 19, 59, 59) + timedelta(microseconds=900_000)
    base = _state(start, layers=(stratus,), wind=(WindLayer(8000.0, 270.0, 30.0),))
    frames: list[tuple[WeatherState, float]] = []
    for i in range(40):  # a second and a third at 30 fps, across a step and a whole second
        frames.append((base.at_time(start + timedelta(seconds=i / 30.0)), 500.0))
    frames += [(base, 900.0), (base, 1100.0), (base, 1100.0), (base, 2600.0), (base, 9000.0)]
    frames += [
        (dataclasses.replace(base, visibility_m=3000.0), 500.0),
        (dataclasses.replace(base, layers=(stratus, cirrus)), 500.0),
        (dataclasses.replace(base, wind=(WindLayer(8000.0, 90.0, 50.0),)), 500.0),
        (
            dataclasses.replace(
                base, layers=(dataclasses.replace(stratus, type=CloudType.NIMBOSTRATUS),)
            ),
            500.0,
        ),
        (dataclasses.replace(base, observer=Observer(-33.87, 151.21, 50.0)), 500.0),
    ]
    reused = 0
    for state, eye_m in frames:
        kept = sky_params(state, eye_m)
        sky_module._last_sky = None
        fresh = sky_params(state, eye_m)
        assert kept == fresh, (state.time_utc, eye_m)
        reused += kept.zenith_rgb is not fresh.zenith_rgb
    # Most frames found the sky of the frame before: this was the reuse, not fresh skies.
    assert reused > len(frames) // 2


def test_haze_thins_above_the_hazy_layers_top() -> None:
    """Aerial perspective (issue 43: a storm's tower over the haze): the boundary layer's haze
    distance on the part of the path under the hazy layer's top, the clear air's above it."""
    from wxsky.scene.sky import CLEAR_AIR_HAZE_M, haze_share

    haze_m, eye_m, top_m = 3000.0, 400.0, 1400.0  # the top 1000 m over the eye
    d = np.array([20_000.0])
    # Wholly in the layer: Koschmieder's, as before.
    low = haze_share(d, np.array([500.0]), eye_m, haze_m, top_m)
    assert low[0] == pytest.approx(1.0 - math.exp(-20_000.0 / haze_m))
    # A point 3000 m up: a third of the way is under the top.
    high = haze_share(d, np.array([3000.0]), eye_m, haze_m, top_m)
    tau = 20_000.0 * (1.0 / 3.0 / haze_m + 2.0 / 3.0 / CLEAR_AIR_HAZE_M)
    assert high[0] == pytest.approx(1.0 - math.exp(-tau))
    assert high[0] < low[0]
    # From above the top, looking down at a point under it: the same split.
    down = haze_share(d, np.array([-3000.0]), 3400.0, haze_m, top_m)
    assert down[0] == pytest.approx(1.0 - math.exp(-tau))
    # No top (no layer capping it): everything in the haze.
    assert haze_share(d, np.array([3000.0]), eye_m, haze_m, math.inf)[0] == pytest.approx(low[0])
