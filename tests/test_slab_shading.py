"""Bouthors' slab shading for stratiform layers (`wxsky.scene.shading_slab`): the 1D model's
energies against hand-computed values from the paper's Appendix B, conservation, the angular
and thickness behaviour a deck must show, and the sky a pilot sees above and below one."""

from __future__ import annotations

import dataclasses
import math
from datetime import UTC, datetime

import numpy as np
import pytest

from wxsky.scene.clouds import SpriteBatch
from wxsky.scene.formation import layer_block
from wxsky.scene.shading import prepare_lighting, sprite_colours
from wxsky.scene.shading_slab import (
    BETA,
    G_S,
    KAPPA_S_PER_M,
    SCUD_TRANSMITTANCE,
    limb,
    slab_energy,
    slab_radiance,
    slab_view_radiance,
)
from wxsky.scene.sky import sky_params
from wxsky.settings.presets import load_preset
from wxsky.weather.state import WeatherState

OVERCAST = WeatherState().apply(load_preset("overcast-stratus", ()))
JUNE_NOON = datetime(2026, 6, 21, 11, 30, tzinfo=UTC)


def test_modified_mie_constants_follow_from_the_droplets() -> None:
    # N0 = 300 cm^-3, r_e = 7 um: kappa = pi r^2 N0 = 0.0462 /m, half of it kept.
    assert pytest.approx(0.49 * math.pi * 49e-12 * 3e8, rel=1e-12) == KAPPA_S_PER_M
    assert pytest.approx(0.02263, abs=1e-5) == KAPPA_S_PER_M
    assert pytest.approx(0.35 / 0.49) == G_S


def test_thick_slab_transmittance_is_the_papers_formula() -> None:
    # Where e^{-cH} is gone: T_ms = b beta / (H - (H - 1) beta), b from Appendix B's row.
    e = slab_energy(np.array([1000.0, 2000.0]), 0.0)
    expected = [1.1796 * BETA / (h - (h - 1.0) * BETA) for h in (1000.0, 2000.0)]
    np.testing.assert_allclose(e["t_ms"], expected, rtol=1e-3)
    assert e["t_ms"][0] == pytest.approx(0.2400, abs=5e-4)
    # Between two table rows the parameters are interpolated: 35° is halfway 30° - 40°.
    mid = slab_energy(np.array([3000.0]), 35.0)["t_ms"][0]
    b = 0.5 * (1.0953 + 0.9808)
    assert mid == pytest.approx(b * BETA / (3000.0 - 2999.0 * BETA), rel=2e-3)


def test_energy_is_conserved_and_split_into_orders() -> None:
    h = np.array([20.0, 100.0, 300.0, 800.0, 3000.0])
    for angle in (0.0, 25.0, 55.0, 80.0, 89.0):
        e = slab_energy(h, angle)
        np.testing.assert_allclose(e["t_ms"] + e["r_ms"], 1.0)
        for name, v in e.items():
            assert np.all((v >= 0.0) & (v <= 1.0)), (name, angle, v)
        thick = h >= 300.0
        # Thick slabs: the orders add up to the total (nothing is clipped away).
        np.testing.assert_allclose(
            (e["t_0"] + e["t_1"] + e["t_2"] + e["t_3"])[thick], e["t_ms"][thick], rtol=1e-9
        )
        np.testing.assert_allclose((e["r_1"] + e["r_2"] + e["r_3"])[thick], e["r_ms"][thick])
        assert np.all(np.diff(e["t_ms"]) < 0.0), "a thicker slab lets less light through"


def test_thin_slabs_are_mostly_unscattered_and_forward_scattered() -> None:
    e = slab_energy(np.array([30.0]), 0.0)
    assert e["t_0"][0] == pytest.approx(math.exp(-KAPPA_S_PER_M * 30.0))
    assert e["t_0"][0] + e["t_1"][0] + e["t_2"][0] > e["t_3"][0]
    assert slab_energy(np.array([600.0]), 0.0)["t_0"][0] < 1e-5


def test_a_deck_is_brighter_toward_the_zenith_from_below() -> None:
    mu_v = np.array([0.05, 0.3, 0.6, 1.0])
    key, sky = slab_radiance(np.full(4, 500.0), 0.8, mu_v, np.zeros(4), np.zeros(4, bool))
    assert np.all(np.diff(key) > 0.0) and np.all(np.diff(sky) > 0.0)
    assert key[-1] / key[0] == pytest.approx(
        limb(np.array([1.0]))[0] / limb(np.array([0.05]))[0], rel=0.05
    )


def test_thicker_decks_are_darker_beneath_and_brighter_on_top() -> None:
    h = np.array([150.0, 500.0, 1500.0, 4000.0])
    below, _ = slab_radiance(h, 0.9, np.full(4, 0.9), np.zeros(4), np.zeros(4, bool))
    above, _ = slab_radiance(h, 0.9, np.full(4, 0.9), np.zeros(4), np.ones(4, bool))
    assert np.all(np.diff(below) < 0.0)
    assert np.all(np.diff(above) > 0.0)
    assert np.all(above[1:] > below[1:])


def test_no_key_light_when_the_light_is_below_the_slab() -> None:
    key, sky = slab_radiance(np.array([500.0]), 0.0, np.array([0.7]), np.zeros(1), np.ones(1, bool))
    assert key[0] == 0.0 and sky[0] > 0.0


def test_view_along_the_light_path_is_continuous() -> None:
    # Single-scattered transmission divides by (mu_v - mu_l): the limit is used where they meet.
    mu_l = 0.5
    mu_v = np.array([0.5 - 1e-3, 0.5 - 1e-5, 0.5, 0.5 + 1e-5, 0.5 + 1e-3])
    key, _ = slab_radiance(np.full(5, 60.0), mu_l, mu_v, np.full(5, 0.9), np.zeros(5, bool))
    assert np.all(np.isfinite(key))
    # Across the limit the curve is as straight as beside it.
    assert abs(key[2] - 0.5 * (key[1] + key[3])) < 1e-9
    assert np.all(np.diff(key) > 0.0)


def test_nan_thickness_stays_in_its_own_entry() -> None:
    key, sky = slab_radiance(
        np.array([np.nan, 500.0]), 0.8, np.array([0.5, 0.5]), np.zeros(2), np.zeros(2, bool)
    )
    assert np.isnan(key[0]) and np.isfinite(key[1]) and np.isfinite(sky[1])


def _deck() -> SpriteBatch:
    layer = OVERCAST.layers[0]
    parts = [layer_block(bx, by, 1, layer, OVERCAST.seed) for bx in (-1, 0) for by in (-1, 0)]
    return SpriteBatch.concat(parts)


def test_deck_sprites_are_slab_sprites_with_the_layers_bounds() -> None:
    deck = _deck()
    layer = OVERCAST.layers[0]
    assert deck.slab.all()
    np.testing.assert_allclose(deck.slab_m[:, 0], layer.base_m)
    np.testing.assert_allclose(deck.slab_m[:, 1], layer.top_m)
    moved = deck.shifted((10.0, 20.0, 30.0))
    np.testing.assert_allclose(moved.slab_m[:, 1], layer.top_m + 30.0)
    # Heaped clouds are shaded as particles.
    cumulus = WeatherState().apply(load_preset("fair-cumulus", ()))
    assert not layer_block(0, 0, 1, cumulus.layers[0], cumulus.seed).slab.any()


@pytest.mark.parametrize("model", ["harris", "wang"])
def test_a_deck_seen_from_above_has_one_colour_per_direction(model: str) -> None:
    # The lattice's sprites sit at different heights in the deck; as one slab they still take
    # the slab's colour for their view ray, so no sprite stands out from its neighbours.
    deck = _deck()
    state = dataclasses.replace(OVERCAST, time_utc=JUNE_NOON)
    eye = (0.0, 0.0, 3500.0)
    sky = sky_params(state, eye[2])
    rgba = sprite_colours(deck, sky, eye, model, prepare_lighting(deck, sky, model))
    ray = deck.centre_m - np.asarray(eye)
    down = -ray[:, 2] / np.linalg.norm(ray, axis=1)
    band = (down > 0.45) & (down < 0.5)
    assert band.sum() > 20
    # (Measured 0.034: the clouds' exposure curve is steeper near white since its toe, issue
    # 41, so the band's spread of view angles shows a little more; 0.024 before.)
    assert np.ptp(rgba[band, :3], axis=0).max() < 0.04
    # A deck top in the June noon sun is white, not a blue or grey field.
    rgb = rgba[band, :3].mean(axis=0)
    assert rgb.min() > 0.8 and rgb[2] / rgb[0] < 1.12


def test_dawn_under_a_deck_is_grey_not_orange() -> None:
    deck = _deck()
    layer = OVERCAST.layers[0]
    eye = (0.0, 0.0, OVERCAST.observer.alt_m + 2.0)
    for hour in (7.1, 15.6):  # November at Zurich: the sun 2-4° up, east then west
        when = datetime(2026, 11, 18, int(hour), int(hour % 1 * 60), tzinfo=UTC)
        sky = sky_params(dataclasses.replace(OVERCAST, time_utc=when), eye[2])
        assert 0.0 < sky.sun.elevation_deg < 6.0
        rgba = sprite_colours(deck, sky, eye, "harris")
        overhead = deck.centre_m[:, 2] < layer.base_m + 200.0
        rgb = rgba[overhead, :3].mean(axis=0)
        assert rgb[0] / rgb[2] < 1.1, f"underside R/B {rgb[0] / rgb[2]:.2f}"
        # ... and lit from above: its top, seen from above, is redder than its base.
        top = sprite_colours(deck, sky, (0.0, 0.0, layer.top_m + 800.0), "harris")
        assert top[overhead, 0].mean() / top[overhead, 2].mean() > rgb[0] / rgb[2]


def test_the_sky_above_a_deck_is_clear() -> None:
    state = dataclasses.replace(OVERCAST, time_utc=JUNE_NOON)
    layer = state.layers[0]
    heights = [state.observer.alt_m, layer.base_m, 0.5 * (layer.base_m + layer.top_m), layer.top_m]
    covers = [sky_params(state, h).cover for h in heights]
    assert covers[0] == pytest.approx(1.0) and covers[-1] == pytest.approx(0.0)
    assert covers == sorted(covers, reverse=True)
    below, above = sky_params(state, heights[0]), sky_params(state, layer.top_m + 500.0)
    assert above.zenith_rgb[2] > 3.0 * above.zenith_rgb[0]  # blue
    assert below.zenith_rgb[2] < 1.4 * below.zenith_rgb[0]  # grey
    # The surface mist stays under the deck: an eye above it sees far.
    assert above.haze_m >= 5.0 * below.haze_m
    assert sky_params(state).cover == covers[0]  # the default eye is the observer's


def test_scud_under_the_base_is_darker_than_the_base_behind_it() -> None:
    # Two sprites of one deck seen from under it along the same ray: one in the deck's base,
    # one of its scud 150 m under it. The scud is the base's light through its own thickness.
    state = WeatherState().apply(load_preset("overcast-stratus"))
    sky = sky_params(state)
    slab = np.array([[1000.0, 2500.0]] * 2, np.float32)
    view = np.array([[0.0, 0.0], [0.6, 0.6], [0.8, 0.8]])
    out = slab_view_radiance(np.array([1010.0, 850.0]), slab, view, sky, 2.0)
    assert out[:, 0].min() > 0.0
    np.testing.assert_allclose(out[:, 1], SCUD_TRANSMITTANCE * out[:, 0], rtol=1e-9)
    assert 0.4 <= SCUD_TRANSMITTANCE <= 0.8
