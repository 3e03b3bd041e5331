"""Issue 42's flat bases: cumulus of a layer share one flat base at the condensation level,
seen in profile as a line their lowest pixels sit on (`tools/bench/flat_bases.py`, drawn
through the real renderer)."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from tools.bench import flat_bases
from wxsky.render.renderer import Renderer
from wxsky.scene.layout import SceneSettings
from wxsky.settings.presets import load_preset
from wxsky.weather.state import WeatherState


@pytest.fixture(scope="module")
def renderer() -> Iterator[Renderer]:
    with Renderer(256, near_scale=1.0) as r:
        yield r


def test_cumulus_lowest_pixels_sit_on_the_base_line_and_would_not_without_the_cut(
    renderer: Renderer,
) -> None:
    state = WeatherState().apply(load_preset("fair-cumulus", ()))
    settings = SceneSettings()
    cut, picture = flat_bases.measure_case(renderer, state, 0.0, 500.0, settings)
    assert len(cut) >= 20  # clouds 10-20 km away in a 60 degree view of 3/8 cover
    assert picture.shape == (flat_bases.SIZE[1], flat_bases.SIZE[0], 4)
    assert np.mean([b.flat for b in cut]) >= flat_bases.BAR
    # The same clouds without the cut at the base: the base's puffs hang below the line.
    uncut, _ = flat_bases.measure_case(renderer, state, 0.0, 500.0, settings, cut=False)
    assert np.mean([b.flat for b in uncut]) < 0.5
    assert np.median([b.error_deg for b in uncut]) < -flat_bases.TOLERANCE_DEG
