"""`wxsky snapshot --transition-to PRESET --elapsed-s S`: pictures of a weather change in
progress, from the same transition stages as the daemon."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from wxsky.app.snapshot import Snapshot, Transition, take_snapshot
from wxsky.render.renderer import Renderer
from wxsky.scene.camera import Camera
from wxsky.settings.config import DaemonConfig
from wxsky.settings.presets import load_preset
from wxsky.weather.state import WeatherState

pytestmark = pytest.mark.gl

CONFIG = DaemonConfig()
W, H = 320, 180


def shot_after(renderer: Renderer, first: str, second: str, elapsed_s: float) -> Snapshot:
    state = WeatherState().apply(load_preset(first, ()))
    camera = Camera(
        position_m=(0.0, 0.0, state.observer.alt_m + 2.0),
        pitch_deg=12.0,
        width_px=W,
        height_px=H,
    )
    transition = Transition(
        to=load_preset(second, ()),
        elapsed_s=elapsed_s,
        rates=CONFIG.transition.rates(),
        step_s=CONFIG.transition.step_s,
    )
    return take_snapshot(state, camera, CONFIG.scene.settings(), renderer, transition)


def cloud_alpha(shot: Snapshot) -> float:
    """Total cloud opacity over the near layer and the ring impostors, 0..1 per pixel."""
    return float(
        sum(
            img[..., 3].astype(np.float64).mean()
            for name, img in shot.layers.items()
            if name not in ("sky", "shadow")  # the shadow map is opaque data, not cloud
        )
        / 255.0
    )


def test_formation_grows_with_elapsed_time(renderer: Renderer) -> None:
    steps = [0.0, 30.0, 60.0, 90.0, 120.0, 240.0]
    shots = [shot_after(renderer, "clear", "scattered-cumulus", t) for t in steps]
    covers = [sum(lay.cover_oktas for lay in s.state.layers) for s in shots]
    alpha = [cloud_alpha(s) for s in shots]
    assert covers[0] == 0.0 and alpha[0] == 0.0
    assert all(b >= a for a, b in itertools.pairwise(covers)), covers
    assert all(b >= a - 1e-6 for a, b in itertools.pairwise(alpha)), alpha
    assert alpha[-1] > alpha[1] > 0.0


def test_dissipation_shrinks_with_elapsed_time(renderer: Renderer) -> None:
    steps = [0.0, 60.0, 120.0, 300.0]
    alpha = [cloud_alpha(shot_after(renderer, "scattered-cumulus", "clear", t)) for t in steps]
    assert all(b <= a + 1e-6 for a, b in itertools.pairwise(alpha)), alpha
    assert alpha[0] > 0.0 and alpha[-1] == 0.0


def test_settled_transition_keeps_the_first_sky_and_takes_the_second_weather(
    renderer: Renderer,
) -> None:
    shot = shot_after(renderer, "clear", "scattered-cumulus", 3600.0)
    clear = WeatherState().apply(load_preset("clear", ()))
    target = WeatherState().apply(load_preset("scattered-cumulus", ()))
    assert shot.state.layers == target.layers
    assert (shot.state.seed, shot.state.time_utc, shot.state.observer) == (
        clear.seed,
        clear.time_utc,
        clear.observer,
    )


def test_no_elapsed_time_is_the_first_preset(renderer: Renderer) -> None:
    state = WeatherState().apply(load_preset("fair-cumulus", ()))
    camera = Camera(
        position_m=(0.0, 0.0, state.observer.alt_m + 2.0), pitch_deg=12.0, width_px=W, height_px=H
    )
    plain = take_snapshot(state, camera, CONFIG.scene.settings(), renderer)
    changing = shot_after(renderer, "fair-cumulus", "clear", 0.0)
    assert np.array_equal(changing.image, plain.image)
