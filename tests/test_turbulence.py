"""Turbulence for a host's flight model (scene/turbulence.py): the gust field has the Dryden
spectra's variance and correlation, is the sky's seed's own, and grows rough where the weather
says (in cloud, near storms, near the ground in wind, in shear); icing in supercooled cloud."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest

from wxsky.scene.turbulence import (
    CLEAR_AIR_MPS,
    HIGH_L_M,
    gust_mps,
    icing,
    roughness,
    scale_lengths_m,
    sigma_ratio,
)
from wxsky.weather.state import CloudLayer, CloudType, Observer, WeatherState, WindLayer


def test_each_component_has_the_asked_variance_aloft() -> None:
    xs = np.linspace(0.0, 600_000.0, 6000)
    g = np.array([gust_mps(7, x, 2.0, 3000.0) for x in xs])
    assert np.abs(g.mean(axis=0)).max() < 0.3
    assert g.std(axis=0) == pytest.approx([2.0, 2.0, 2.0], rel=0.2)


def test_the_gusts_decorrelate_over_drydens_scale_length() -> None:
    """The longitudinal Dryden spectrum is the transform of exp(-r/L): at a lag of L the
    correlation is about 1/e; far beyond it, nothing."""
    step = HIGH_L_M / 8.0
    xs = np.arange(0.0, 4000 * step, step)
    samples = np.array([gust_mps(11, x, 1.0, 3000.0)[0] for x in xs])
    samples -= samples.mean()

    def corr(lag: int) -> float:
        return float(np.mean(samples[:-lag] * samples[lag:]) / np.mean(samples * samples))

    assert corr(8) == pytest.approx(math.exp(-1.0), abs=0.12)
    assert abs(corr(8 * 20)) < 0.2


def test_the_same_sky_gives_the_same_gusts() -> None:
    p = 1234.5
    assert gust_mps(42, p, 1.5, 800.0) == gust_mps(42, p, 1.5, 800.0)
    assert gust_mps(42, p, 1.5, 800.0) != gust_mps(43, p, 1.5, 800.0)
    assert gust_mps(42, p, 0.0, 800.0) == (0.0, 0.0, 0.0)


def test_near_the_ground_the_scales_shrink_and_horizontal_gusts_dominate() -> None:
    assert scale_lengths_m(1000.0) == (HIGH_L_M, HIGH_L_M)
    lu, lw = scale_lengths_m(30.0)
    assert lw == pytest.approx(30.0) and lw < lu < HIGH_L_M
    assert sigma_ratio(1000.0) == 1.0 and sigma_ratio(30.0) > 1.5


def _state(**fields: Any) -> WeatherState:
    return dataclasses.replace(WeatherState(observer=Observer(47.0, 8.0, 400.0)), **fields)


def test_the_air_is_rough_where_the_weather_says() -> None:
    calm = _state(wind=(WindLayer(400.0, 0.0, 0.0), WindLayer(5000.0, 0.0, 0.0)))
    smooth = roughness(calm, 3000.0, 400.0, None)
    assert smooth.sigma_w_mps == pytest.approx(CLEAR_AIR_MPS) and smooth.category == "none"
    assert roughness(calm, 3000.0, 400.0, CloudType.STRATUS).category in ("none", "light")
    assert roughness(calm, 3000.0, 400.0, CloudType.CUMULUS).category == "moderate"
    assert roughness(calm, 3000.0, 400.0, CloudType.CUMULONIMBUS).category == "severe"
    windy = _state(wind=(WindLayer(400.0, 270.0, 20.0), WindLayer(5000.0, 270.0, 20.0)))
    low = roughness(windy, 450.0, 400.0, None)
    assert low.causes["low_altitude"] > 1.0 and low.sigma_w_mps > smooth.sigma_w_mps
    sheared = _state(wind=(WindLayer(400.0, 270.0, 5.0), WindLayer(1400.0, 90.0, 15.0)))
    shear = roughness(sheared, 900.0, 400.0, None)
    # from 5 m/s one way to 15 the other over 1000 m: 20 m/s per km
    assert shear.causes["shear"] == pytest.approx(30.0 * 20.0 / 1000.0, rel=0.05)
    storm = _state(layers=(CloudLayer(6.0, 1500.0, 11000.0, CloudType.CUMULONIMBUS),))
    beside = roughness(storm, 3000.0, 400.0, None)  # at the layer's heights, out of cloud
    assert beside.causes["near_cumulonimbus"] == pytest.approx(3.0 * 6.0 / 8.0)
    assert "near_cumulonimbus" not in roughness(storm, 14000.0, 400.0, None).causes


def test_icing_in_supercooled_cloud_only() -> None:
    assert icing(True, -10.0) and icing(True, 0.0) and icing(True, -20.0)
    assert not icing(False, -10.0) and not icing(True, 2.0) and not icing(True, -25.0)
