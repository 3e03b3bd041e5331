"""The near layer's view cull (issue 19): sprites wholly outside the camera's view are neither
shaded, packed nor drawn. It must never drop a sprite any of whose quad shows."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wxsky.scene.camera import Camera, spheres_in_view
from wxsky.scene.gather import NearRing, zero_drift
from wxsky.scene.in_cloud import INSIDE_FRAC, UNLOCK_FRAC
from wxsky.scene.layout import VIEW_REACH, SceneSettings, build_frame, in_view, sort_order
from wxsky.scene.sky import sky_params
from wxsky.settings.presets import load_preset
from wxsky.weather.state import WeatherState

EAST = Camera((0.0, 0.0, 1000.0), heading_deg=90.0, fov_deg=60.0, width_px=160, height_px=90)


def test_spheres_against_the_view_of_a_camera_looking_east() -> None:
    tx = math.tan(math.radians(30.0))
    r = np.full(6, 10.0)
    centres = np.array(
        [
            [500.0, 0.0, 1000.0],  # straight ahead
            [-50.0, 0.0, 1000.0],  # behind, out of reach
            [-5.0, 0.0, 1000.0],  # behind, but reaching past the eye
            [500.0, -500.0 * tx - 11.0, 1000.0],  # beyond the right edge, within reach
            [500.0, -500.0 * tx - 30.0, 1000.0],  # beyond it, out of reach
            [500.0, 0.0, 1000.0 + 500.0 * tx * 90 / 160 + 30.0],  # above the top edge
        ]
    )
    got = spheres_in_view(EAST, centres, r)
    assert got.tolist() == [True, False, True, True, False, False]
    # Rolled 90 degrees, the picture's top is north: the sphere above the top edge is in.
    rolled = Camera(EAST.position_m, 90.0, 0.0, 90.0, 60.0, 160, 90)
    assert spheres_in_view(rolled, centres[5:], r[5:]).tolist() == [True]
    # Broadcast over no spheres.
    assert spheres_in_view(EAST, np.zeros((0, 3)), np.zeros(0)).shape == (0,)


def test_the_reach_holds_every_sprite_the_eye_is_in_or_locked_to() -> None:
    assert max(INSIDE_FRAC, UNLOCK_FRAC) <= VIEW_REACH
    assert 0.5 * math.sqrt(2.0) <= VIEW_REACH  # a corner of the quad's square


@pytest.mark.parametrize(
    ("preset", "pose"),
    [
        ("fair-cumulus", (1500.0, 90.0, 10.0, 0.0)),
        ("overcast-stratus", (1000.0, 200.0, -20.0, 25.0)),  # in the deck, rolled
        ("thunderstorm", (1600.0, 300.0, -60.0, 0.0)),
        ("high-cirrus", (2000.0, 10.0, 70.0, -40.0)),
    ],
)
def test_no_culled_sprite_has_a_corner_in_view(
    preset: str, pose: tuple[float, float, float, float]
) -> None:
    """Every sprite the cull leaves out has all four corners of its square (a facing sprite's,
    spanned as the shader spans it; a flat one's in its layer) outside one side of the view."""
    state = WeatherState().apply(load_preset(preset))
    alt, heading, pitch, roll = pose
    cam = Camera((0.0, 0.0, alt), heading, pitch, roll, 60.0, 320, 180)
    settings = SceneSettings()
    sky = sky_params(state, alt)
    rings = (NearRing((0.0, 0.0, alt), zero_drift(state), 1.0),)
    frame = build_frame(state, zero_drift(state), cam, rings, sky, settings)
    from wxsky.scene.gather import gather_near

    near, _ = gather_near(state, zero_drift(state), rings, settings.ring_radius_m)
    near = near.take(sort_order(near, cam.position_m))
    kept = in_view(near, cam)
    assert 0 < kept.sum() < len(near)
    assert len(frame.near) <= int(kept.sum())  # towers take some of the rest
    out = near.take(~kept)
    eye = np.asarray(cam.position_m)
    right, up, fwd = cam.basis()
    to_sprite = out.centre_m - eye
    n = np.where(out.flat[:, None], [0.0, 0.0, 1.0], -to_sprite)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    u = np.cross([0.0, 0.0, 1.0], n)
    across = np.linalg.norm(u, axis=1, keepdims=True)
    u = np.where(across > 1e-6, u / np.maximum(across, 1e-12), [1.0, 0.0, 0.0])
    v = np.cross(n, u)
    half = 0.5 * out.size_m.astype(np.float64)[:, None]
    corners = np.stack(
        [to_sprite + half * (a * u + b * v) for a in (-1, 1) for b in (-1, 1)], axis=1
    )  # (M, 4, 3)
    x, y, z = corners @ right, corners @ up, corners @ fwd
    tx, ty = cam.tan_half_fov_x, cam.tan_half_fov_y
    outside = (
        (z < 0.0).all(axis=1)
        | (x > z * tx).all(axis=1)
        | (-x > z * tx).all(axis=1)
        | (y > z * ty).all(axis=1)
        | (-y > z * ty).all(axis=1)
    )
    assert outside.all(), f"{int((~outside).sum())} culled sprites show a corner"


def test_the_planes_give_the_camera_axes_answer_for_any_sphere() -> None:
    """The cull as one product against five planes is the test along the camera's axes:
    in front of the eye within reach, and within reach of the four sides."""
    rng = np.random.default_rng(19)
    cam = Camera((100.0, -300.0, 1500.0), 37.0, -12.0, 25.0, 75.0, 320, 180)
    centres = np.asarray(cam.position_m) + rng.uniform(-8000.0, 8000.0, (20_000, 3))
    radius = rng.uniform(1.0, 1500.0, 20_000)
    right, up, fwd = cam.basis()
    rel = centres - np.asarray(cam.position_m)
    x, y, z = rel @ right, rel @ up, rel @ fwd
    tx, ty = cam.tan_half_fov_x, cam.tan_half_fov_y
    want = (
        (z > -radius)
        & (np.abs(x) - z * tx < radius * math.sqrt(1.0 + tx * tx))
        & (np.abs(y) - z * ty < radius * math.sqrt(1.0 + ty * ty))
    )
    got = spheres_in_view(cam, centres, radius)
    assert 0.05 < want.mean() < 0.95
    assert (got == want).mean() > 0.9999  # rounding may tip a sphere exactly at a plane
