"""Sun position against an independent reference, and the sky parameters derived from it.

The reference is the NOAA Solar Calculator spreadsheet's algorithm (Meeus, Julian centuries,
no refraction), written out below independently of `wxsky.scene.sky`, which uses NOAA's
fractional-year Fourier series instead. The two agree to about half a degree.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from datetime import UTC, datetime, timedelta, timezone

import numpy as np
import pytest

from wxsky.scene.sky import SunPosition, sky_params, sun_position
from wxsky.weather.state import CloudLayer, CloudType, Observer, WeatherState

ZURICH = (47.4647, 8.5492)
SYDNEY = (-33.87, 151.21)
TOL_DEG = 0.5


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
    sun = sun_position(_at(2026, 6, 21, 11, 28), *ZURICH)
    assert sun.elevation_deg == pytest.approx(65.97, abs=TOL_DEG)
    assert _az_diff(sun.azimuth_deg, 180.21) <= TOL_DEG


def test_zurich_midnight_is_below_the_horizon_to_the_north() -> None:
    sun = sun_position(_at(2026, 6, 21, 0, 0), *ZURICH)
    assert sun.elevation_deg == pytest.approx(-18.72, abs=TOL_DEG)
    assert _az_diff(sun.azimuth_deg, 7.86) <= 1.0
    assert sun.direction_enu[2] < 0.0


def test_equator_equinox_noon_is_overhead() -> None:
    # Equinox 2026-03-20 14:46 UTC; solar noon at 0°E that day is 12:07 UTC.
    sun = sun_position(_at(2026, 3, 20, 12, 7), 0.0, 0.0)
    assert sun.elevation_deg == pytest.approx(90.0, abs=1.0)
    np.testing.assert_allclose(sun.direction_enu, (0, 0, 1), atol=math.radians(1.0))


def test_equator_equinox_morning_sun_is_due_east() -> None:
    # At the equator on the equinox the sun climbs straight up the east-west great circle.
    sun = sun_position(_at(2026, 3, 20, 9, 0), 0.0, 0.0)
    assert _az_diff(sun.azimuth_deg, 90.0) <= 1.0
    assert sun.elevation_deg == pytest.approx(43.13, abs=TOL_DEG)  # 3h07 before noon: ~46.9°
    east, north, _ = sun.direction_enu
    assert east > 0.7 and abs(north) < 0.02


def test_southern_hemisphere_winter_noon_sun_is_north() -> None:
    # Sydney, June solstice, solar noon about 01:53 UTC: elevation 90 - 33.87 - 23.44.
    sun = sun_position(_at(2026, 6, 21, 1, 53), *SYDNEY)
    assert sun.elevation_deg == pytest.approx(32.68, abs=TOL_DEG)
    assert _az_diff(sun.azimuth_deg, 1.06) <= TOL_DEG
    assert sun.direction_enu[1] > 0.8


def test_zurich_morning_sun_is_east_north_east() -> None:
    sun = sun_position(_at(2026, 6, 21, 5, 0), *ZURICH)
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
    sun = sun_position(t, lat, lon)
    assert sun.elevation_deg == pytest.approx(el, abs=TOL_DEG)
    assert _az_diff(sun.azimuth_deg, az) <= TOL_DEG / max(math.cos(math.radians(el)), 0.2)


def test_sun_position_sweep_within_six_tenths_of_a_degree() -> None:
    """Over 2024-2030 and five latitudes the sun direction stays within 0.6° of the reference
    (the fractional-year series drifts up to ~0.5° near the equinoxes)."""
    worst = 0.0
    t = _at(2024, 1, 1)
    while t.year < 2031:
        for lat, lon in [ZURICH, (0.0, 0.0), SYDNEY, (65.0, -20.0), (-60.0, -70.0)]:
            ref = SunPosition(*noaa_spreadsheet(t, lat, lon))
            worst = max(worst, _separation_deg(ref, sun_position(t, lat, lon)))
        t += timedelta(hours=29, minutes=17)
    assert worst <= 0.6


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


def test_haze_grows_with_visibility() -> None:
    t = _at(2026, 6, 21, 11, 30)
    vis = [0.0, 200.0, 700.0, 1000.0, 3000.0, 10_000.0, 50_000.0, 200_000.0]
    haze = [sky_params(_state(t, visibility_m=v)).haze_m for v in vis]
    assert all(h >= 2000.0 for h in haze)
    assert all(a <= b for a, b in itertools.pairwise(haze))
    assert haze[3] < haze[4] < haze[5] < haze[6] < haze[7]
    assert haze[5] >= 10_000.0  # clouds at the visibility distance are not yet faded out


def test_sky_params_to_dict_is_plain_data() -> None:
    sky = sky_params(_state(_at(2026, 6, 21, 11, 30)))
    d = sky.to_dict()
    assert d["sun_elevation_deg"] == sky.sun.elevation_deg
    assert d["sun_direction_enu"] == list(sky.sun.direction_enu)
    assert d["zenith_rgb"] == list(sky.zenith_rgb)
    assert set(d) >= {"ambient", "sunset", "cover", "haze_m", "sun_rgb", "ground_rgb"}


def test_sky_params_follow_the_observer() -> None:
    t = _at(2026, 6, 21, 11, 30)
    zurich = sky_params(_state(t))
    sydney = sky_params(dataclasses.replace(_state(t), observer=Observer(*SYDNEY, 10.0)))
    assert zurich.sun.elevation_deg > 0.0 > sydney.sun.elevation_deg
