"""The ground below the horizon under the physical sky: lit by the atmosphere's sun and sky
through the cloud cover, so it darkens with the light as the sky and the clouds do."""

from __future__ import annotations

import dataclasses
from datetime import UTC, datetime

import numpy as np

from wxsky.render.sky_textures import physical_ground_tint
from wxsky.scene import atmosphere as atm
from wxsky.scene.ephemeris import SunPosition
from wxsky.scene.sky import sky_params
from wxsky.weather.state import WeatherState

LUMA = np.array([0.2126, 0.7152, 0.0722])


def _ground(sun_elevation_deg: float, cover: float) -> float:
    """The ground's shown luminance (display values) with the sun this high, under `cover`."""
    state = WeatherState(time_utc=datetime(2026, 6, 21, 12, 0, tzinfo=UTC))
    base = sky_params(state)
    sun = SunPosition(sun_elevation_deg, 90.0)
    luts = atm.build_luts(atm.atmosphere_key(sun_elevation_deg, 30_000.0, 50.0, 0.0))
    sky = dataclasses.replace(base, sun=sun, cover=cover).with_atmosphere(luts)
    tint = np.asarray(physical_ground_tint(sky))
    assert np.all(np.isfinite(tint)) and np.all(tint >= 0.0)
    return float((np.asarray(sky.ground_rgb) * tint) @ LUMA)


def test_the_ground_darkens_with_the_sun_and_under_a_deck() -> None:
    noon, low, dusk = _ground(60.0, 0.0), _ground(5.0, 0.0), _ground(-4.0, 0.0)
    assert noon > low > dusk
    # An overcast lets a third of the light through; the exposure adapts to the dimmer scene
    # (scene.sky.scene_exposure, by the square root as to the evening), so the ground shows
    # darker, though not three times.
    assert _ground(60.0, 1.0) < 0.85 * noon
