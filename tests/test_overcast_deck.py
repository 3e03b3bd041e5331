"""`overcast-stratus` is one deck: from below it covers every bit of sky above 10° elevation,
from above the layer it is continuous. Measured on the composited picture, as a host sees it."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from wxsky.app.snapshot import take_snapshot
from wxsky.host.compositor import Layers, composite, layers_from_images
from wxsky.render.renderer import Renderer
from wxsky.scene.camera import Camera
from wxsky.settings.config import DaemonConfig
from wxsky.settings.presets import load_preset
from wxsky.weather.state import WeatherState

pytestmark = pytest.mark.gl

STATE = WeatherState().apply(load_preset("overcast-stratus", ()))
W, H = 320, 240


def coverage(renderer: Renderer, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) cloud coverage 0..1 of the composited picture, and each pixel's elevation in
    degrees: the clouds are composited white over a black sky, so a pixel's value is how much
    cloud covers it."""
    shot = take_snapshot(STATE, camera, DaemonConfig().scene.settings(), renderer)
    images = {}
    for name, image in shot.layers.items():
        alpha = image[..., 3:4]
        if name == "sky":
            images[name] = np.concatenate([np.zeros_like(image[..., :3]), alpha], axis=-1)
        else:  # premultiplied white: colour equals alpha
            images[name] = np.concatenate([np.repeat(alpha, 3, axis=-1), alpha], axis=-1)
    layers: Layers = layers_from_images(images, shot.ring_quads_m)
    cover = composite(layers, camera)[..., 0].astype(np.float64) / 255.0
    elevation = np.degrees(np.arcsin(np.clip(camera.pixel_rays()[..., 2], -1.0, 1.0)))
    return cover, elevation


@pytest.mark.parametrize("heading_deg", [0.0, 135.0, 250.0])
def test_from_below_no_sky_shows_above_ten_degrees(renderer: Renderer, heading_deg: float) -> None:
    camera = Camera(
        position_m=(0.0, 0.0, STATE.observer.alt_m + 2.0),
        heading_deg=heading_deg,
        pitch_deg=45.0,
        fov_deg=100.0,
        width_px=W,
        height_px=H,
    )
    cover, elevation = coverage(renderer, camera)
    above = elevation > 10.0
    assert above.sum() > 0.5 * above.size
    assert cover[above].min() >= 0.98, f"least covered pixel {cover[above].min():.3f}"


def test_from_above_the_deck_is_continuous(renderer: Renderer) -> None:
    top_m = max(layer.top_m for layer in STATE.layers)
    camera = Camera(
        position_m=(0.0, 0.0, top_m + 600.0),
        pitch_deg=-50.0,
        fov_deg=90.0,
        width_px=W,
        height_px=H,
    )
    cover, elevation = coverage(renderer, camera)
    below = elevation < -10.0
    assert below.sum() > 0.5 * below.size
    assert cover[below].min() >= 0.98, f"least covered pixel {cover[below].min():.3f}"


def test_the_measure_sees_holes_when_there_are_some(renderer: Renderer) -> None:
    # Guard for the two tests above: the same measure at 5/8 finds open sky.
    broken = dataclasses.replace(
        STATE, layers=tuple(dataclasses.replace(lay, cover_oktas=5.0) for lay in STATE.layers)
    )
    camera = Camera(
        position_m=(0.0, 0.0, broken.observer.alt_m + 2.0),
        pitch_deg=45.0,
        fov_deg=100.0,
        width_px=W,
        height_px=H,
    )
    shot_state = STATE
    try:
        globals()["STATE"] = broken
        cover, elevation = coverage(renderer, camera)
    finally:
        globals()["STATE"] = shot_state
    assert cover[elevation > 10.0].min() < 0.5
