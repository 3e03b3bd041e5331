"""A tower volume lit as the sprite clouds are (wxsky/scene/tower_shading.py): bright on the
sun's side, darker behind and underneath, and a silver lining toward the sun."""

from __future__ import annotations

import dataclasses
from datetime import UTC, datetime

import numpy as np

from wxsky.scene.ephemeris import SunPosition
from wxsky.scene.sky import sky_params
from wxsky.scene.tower_shading import tower_colours
from wxsky.weather.state import WeatherState

LUMA = np.array([0.2126, 0.7152, 0.0722])
N = 32


def _ball() -> np.ndarray:
    z, y, x = np.mgrid[0:N, 0:N, 0:N].astype(np.float32)
    r = np.sqrt((x - N / 2) ** 2 + (y - N / 2) ** 2 + (z - N / 2) ** 2)
    return np.clip((0.4 * N - r) / 3.0, 0.0, 1.0).astype(np.float32)  # soft-edged ball


def _sky(elevation_deg: float, azimuth_deg: float):  # type: ignore[no-untyped-def]
    sky = sky_params(WeatherState(time_utc=datetime(2026, 6, 21, 12, 0, tzinfo=UTC)))
    return dataclasses.replace(sky, sun=SunPosition(elevation_deg, azimuth_deg))


def test_the_suns_side_is_bright_and_the_far_side_and_base_darker() -> None:
    ball = _ball()
    luma = tower_colours(ball, _sky(20.0, 90.0), (0.0, 1.0, 0.0)) @ LUMA  # sun in the east
    c = N // 2
    inside = ball > 0.5
    east, west = luma[c, c, c + 10], luma[c, c, c - 10]
    assert inside[c, c, c + 10] and inside[c, c, c - 10]
    assert east > west + 0.1
    high = tower_colours(ball, _sky(70.0, 90.0), (0.0, 1.0, 0.0)) @ LUMA
    assert high[c + 10, c, c] > high[c - 10, c, c] + 0.1  # the base is grey under a high sun
    assert np.all((luma >= 0.0) & (luma <= 1.0))


def test_a_silver_lining_looking_toward_the_sun() -> None:
    ball = _ball()
    sky = _sky(10.0, 0.0)  # low sun in the north
    rim = (ball > 0.05) & (ball < 0.5)
    toward = tower_colours(ball, sky, (0.0, 1.0, 0.0)) @ LUMA  # looking north, into the sun
    away = tower_colours(ball, sky, (0.0, -1.0, 0.0)) @ LUMA  # the sun behind the eye
    assert toward[rim].mean() > away[rim].mean() + 0.05
