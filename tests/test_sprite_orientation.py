"""Sprites with their own orientation (flat cirrus sheets, in-cloud locked sprites): drawn in
the plane across their normal, faded as the eye sees them edge-on."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import numpy as np
import pytest

from wxsky.render.renderer import Renderer
from wxsky.scene.camera import Camera
from wxsky.scene.clouds import SpriteBatch
from wxsky.scene.layout import FrameScene, SpriteDraw
from wxsky.scene.sky import sky_params
from wxsky.scene.texture_slots import TEX_FOG
from wxsky.weather.state import WeatherState

pytestmark = pytest.mark.gl

W, H = 161, 91
SKY = sky_params(WeatherState())


@contextlib.contextmanager
def full_scale(renderer: Renderer) -> Iterator[None]:
    old, renderer.near_scale = renderer.near_scale, 1.0
    try:
        yield
    finally:
        renderer.near_scale = old


def one_sprite(normal: tuple[float, float, float] | None, size_m: float = 400.0) -> SpriteDraw:
    batch = SpriteBatch(
        centre_m=np.array([[0.0, 2000.0, 1000.0]]),
        size_m=np.float32([size_m]),
        rotation_rad=np.float32([0.0]),
        texture=np.int32([TEX_FOG[0]]),
        height_frac=np.float32([0.5]),
        light_dir=np.float32([[0, 0, 1]]),
        opacity=np.float32([1.0]),
        darkness=np.float32([0.0]),
        cloud_id=np.int64([1]),
        core_frac=np.float32([0.0]),
    )
    normals = None if normal is None else np.float32([normal])
    return SpriteDraw(batch, np.float32([[1.0, 1.0, 1.0, 1.0]]), normals)


def near_alpha(renderer: Renderer, draw: SpriteDraw) -> np.ndarray:
    camera = Camera(position_m=(0.0, 0.0, 1000.0), width_px=W, height_px=H)
    with full_scale(renderer):
        renderer.render_frame(FrameScene(camera, SKY, draw))
        return renderer.read("near")[..., 3].astype(np.float64)


def test_a_normal_toward_the_eye_draws_like_a_facing_sprite(renderer: Renderer) -> None:
    facing = near_alpha(renderer, one_sprite(None))
    fixed = near_alpha(renderer, one_sprite((0.0, -1.0, 0.0)))
    assert facing.sum() > 0
    assert np.abs(facing - fixed).max() <= 2.0
    assert renderer.ctx.error == "GL_NO_ERROR"


def test_a_quad_seen_edge_on_vanishes(renderer: Renderer) -> None:
    assert near_alpha(renderer, one_sprite((0.0, 0.0, 1.0))).max() <= 2.0  # level with the eye
    assert near_alpha(renderer, one_sprite((1.0, 0.0, 0.0))).max() <= 2.0


def test_a_tilted_quad_is_foreshortened_and_fainter(renderer: Renderer) -> None:
    facing = near_alpha(renderer, one_sprite(None))
    c45 = float(np.sqrt(0.5))
    tilted = near_alpha(renderer, one_sprite((0.0, -c45, c45)))
    rows = lambda a: np.flatnonzero(a.max(axis=1) > 2.0)  # noqa: E731
    cols = lambda a: np.flatnonzero(a.max(axis=0) > 2.0)  # noqa: E731
    # Tipped back about the horizontal axis: as wide as before, about 0.71 as tall.
    assert len(cols(tilted)) == pytest.approx(len(cols(facing)), abs=2)
    assert len(rows(tilted)) == pytest.approx(c45 * len(rows(facing)), abs=3)
    # ...and fainter by the cosine of the angle to the eye.
    assert tilted.max() == pytest.approx(c45 * facing.max(), rel=0.1)
