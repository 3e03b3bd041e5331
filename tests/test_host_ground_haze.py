"""The reference host's own ground in aerial perspective (issue 41 item 5): a host's flat ground
fades toward the colour distant clouds fade into by its distance, as wxsky's own ground band
and clouds do, with the haze distance and colour the `scene` message publishes."""

from __future__ import annotations

import dataclasses
import math
from datetime import UTC, datetime

import numpy as np
import pytest

from wxsky.host.compositor import Ground, ground_colour
from wxsky.scene.camera import Camera
from wxsky.scene.sky import sky_params
from wxsky.weather.state import WeatherState

GROUND_M = 432.0
NOON = datetime(2026, 6, 21, 11, 30, tzinfo=UTC)


def _camera() -> Camera:
    # 2 m up, looking 5° down, 0.1° a pixel: rows from 0.5° below level (the ground 230 m
    # off) to 9.5° below it (12 m off).
    return Camera(
        position_m=(0.0, 0.0, GROUND_M + 2.0),
        heading_deg=0.0,
        pitch_deg=-5.0,
        fov_deg=20.0,
        width_px=200,
        height_px=90,
    )


def _row_colour(colour: np.ndarray, camera: Camera, depression_deg: float) -> np.ndarray:
    up = camera.pixel_rays()[:, 100, 2]
    row = int(np.argmin(np.abs(np.degrees(np.arcsin(up)) + depression_deg)))
    return np.asarray(colour[row, 100, :3])


def test_a_hosts_ground_takes_the_published_haze() -> None:
    state = dataclasses.replace(WeatherState(time_utc=NOON), visibility_m=5_000.0)
    sky = sky_params(state).to_dict()
    ground = Ground(GROUND_M, tuple(sky["sun_direction_enu"])).in_air_of(sky)
    # The surface's haze distance (Koschmieder: visibility / 3.912) and the clouds' colour.
    assert ground.haze_m == pytest.approx(5_000.0 / 3.912)
    assert ground.air_rgb == pytest.approx(tuple(sky["haze_rgb"]))
    camera = _camera()
    t, hazed = ground_colour(ground, None, camera)
    _, plain = ground_colour(dataclasses.replace(ground, haze_m=math.inf), None, camera)
    assert np.isfinite(t).all()
    air = np.asarray(ground.air_rgb)
    near, far = _row_colour(hazed, camera, 9.0), _row_colour(hazed, camera, 0.6)
    lit = _row_colour(plain, camera, 9.0)
    # 13 m off the ground is nearly its lit colour; 190 m off it is a seventh of the way to
    # the air (1 - exp(-190 / 1278)), as the formula says.
    np.testing.assert_allclose(near, lit, atol=0.01)
    d = 2.0 / math.tan(math.radians(0.6))
    expected = lit + (1.0 - math.exp(-d / ground.haze_m)) * (air - lit)
    np.testing.assert_allclose(far, expected, atol=0.01)
    assert np.linalg.norm(far - air) < np.linalg.norm(near - air) - 0.02


def test_a_ground_without_haze_is_as_lit() -> None:
    camera = _camera()
    sun = (0.0, 0.5, math.sqrt(0.75))
    _, plain = ground_colour(Ground(GROUND_M, sun), None, camera)
    # The old formula: rgb * (ambient + (1 - ambient) * max(0, n.s)).
    expected = np.asarray((0.30, 0.38, 0.20)) * (0.35 + 0.65 * math.sqrt(0.75))
    np.testing.assert_allclose(plain[..., :3], np.broadcast_to(expected, plain[..., :3].shape))
