"""Issue 42's decks: an overcast stratus base seen from below has darker and lighter patches
(`tools/bench/deck_structure.py`'s measure), drawn by the deck shader variant, fixed to the
deck so they drift with it."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tools.bench import deck_structure
from tools.gallery import light_sheet as sheet
from wxsky.render import renderer as renderer_module
from wxsky.render.renderer import Renderer
from wxsky.settings.presets import load_preset
from wxsky.weather.state import WeatherState

pytestmark = pytest.mark.gl


def _noon_deck() -> tuple[WeatherState, float]:
    base = WeatherState().apply(load_preset("overcast-stratus", ()))
    obs = base.observer
    sun = sheet.sun_time(base.time_utc, obs.lat_deg, obs.lon_deg, None)
    return dataclasses.replace(base, time_utc=sun.time_utc), sun.azimuth_deg


def test_an_overcast_base_has_structure_and_a_plain_deck_would_not(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    state, azimuth = _noon_deck()
    with Renderer(256) as r:
        relief, _ = deck_structure.structure(deck_structure.picture(r, state, azimuth))
    assert relief >= deck_structure.BAR
    # The same deck with no relief: the even grey the issue found (0.1-0.2).
    monkeypatch.setattr(renderer_module, "DECK_RELIEF", (0.0, 0.0, 0.0))
    with Renderer(256) as r:
        plain, _ = deck_structure.structure(deck_structure.picture(r, state, azimuth))
    assert plain < 0.5 < relief


def test_the_band_pass_ignores_even_gradients_and_keeps_patches() -> None:
    y, x = np.mgrid[0:200, 0:300].astype(np.float64)
    ramp = np.dstack([x * 0.5 + y * 0.3] * 3).astype(np.uint8)
    assert deck_structure.structure(ramp)[0] < 0.3
    patches = 100.0 + 6.0 * np.sin(x / 5.0) * np.sin(y / 5.0)  # about 30 px across
    assert deck_structure.structure(np.dstack([patches] * 3).astype(np.uint8))[0] > 1.5
