"""The weather at a point, as a CIGI host's Environmental Conditions Request gets it: in cloud
only inside the clouds the frames draw, and never above or below every cloud layer."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from wxsky.scene.camera import Camera
from wxsky.scene.clouds import layer_keys
from wxsky.scene.conditions import (
    CLEAR_AIR_MAX_HUMIDITY_PCT,
    FOG_VISIBILITY_M,
    _drifted,
    _placed_block,
    conditions_at,
    conditions_many,
)
from wxsky.scene.formation import layer_block
from wxsky.scene.gather import Drift, NearRing, zero_drift
from wxsky.scene.in_cloud import INSIDE_FRAC
from wxsky.scene.layout import FrameScene, SceneSettings, build_frame
from wxsky.scene.sky import sky_params
from wxsky.settings.presets import list_presets, load_preset
from wxsky.weather.state import CloudLayer, CloudType, WeatherState

PRESETS = sorted(p.name for p in list_presets())
# The drift a while into a windy day: the answers hold wherever the wind has taken the clouds.
DRIFT_M = (1234.5, -678.9)


def preset_state(name: str) -> tuple[WeatherState, Drift]:
    state = WeatherState().apply(load_preset(name))
    return state, tuple(DRIFT_M for _ in state.layers)


def outside_heights(state: WeatherState) -> list[float]:
    """Heights above or below every cloud layer: just beyond each base and top, and between."""
    spans = [(layer.base_m, layer.top_m) for layer in state.layers]
    candidates = [state.observer.alt_m + 2.0]
    for base, top in spans:
        candidates += [base - 0.5, base - 10.0, base - 100.0, top + 0.5, top + 10.0, top + 100.0]
    return [h for h in candidates if not any(b <= h <= t for b, t in spans)]


def test_every_shipped_preset_is_checked() -> None:
    assert {"overcast-stratus", "thunderstorm", "broken-stratocumulus"} <= set(PRESETS)


@pytest.mark.parametrize("name", PRESETS)
def test_a_point_above_or_below_every_layer_is_never_in_cloud(name: str) -> None:
    state, drift = preset_state(name)
    rng = np.random.default_rng(39)
    heights = outside_heights(state)
    places = rng.uniform(-6000.0, 6000.0, size=(40, 2))
    for k, (east, north) in enumerate(places):
        for alt in heights:
            point = (float(east), float(north), alt)
            got = conditions_at(state, drift, point)
            where = f"{name}: ({east:.0f}, {north:.0f}, {alt:.1f} m)"
            assert not got.in_cloud, where
            assert got.visibility_m == state.visibility_m, where
            assert all(w == 0.0 for w in got.cloud_water_gpm3), where
            if state.visibility_m >= FOG_VISIBILITY_M:
                assert got.humidity_pct <= CLEAR_AIR_MAX_HUMIDITY_PCT, where
            if k < 3:  # and the frames' camera there is not in cloud, nor veiled
                seen = _frame(state, drift, point)
                assert not seen.in_cloud.inside and seen.veil_rgba[3] == 0.0, where


def test_the_reported_point_above_a_stratus_deck_is_clear() -> None:
    # Issue 39: 100 m above a 600-900 m overcast stratus deck came back as in cloud, humidity
    # 100 %, visibility 383-594 m. The deck's sprites are about 1 km wide: a sphere round
    # each reaches 350 m, far above the deck's top.
    deck = CloudLayer(8.0, 600.0, 900.0, CloudType.STRATUS)
    state = dataclasses.replace(WeatherState(), layers=(deck,), visibility_m=20_000.0)
    rng = np.random.default_rng(7)
    for east, north in rng.uniform(-4000.0, 4000.0, size=(60, 2)):
        above = conditions_at(state, zero_drift(state), (float(east), float(north), 1000.0))
        assert not above.in_cloud and above.humidity_pct < 100.0
        assert above.visibility_m == 20_000.0 and above.cloud_water_gpm3 == (0.0,)
        # The middle of an overcast deck is cloud wherever the point is.
        inside = conditions_at(state, zero_drift(state), (float(east), float(north), 750.0))
        assert inside.in_cloud and inside.humidity_pct == 100.0
        assert inside.visibility_m < 600.0 and inside.cloud_water_gpm3[0] > 0.0


def _frame(state: WeatherState, drift: Drift, eye: tuple[float, float, float]) -> FrameScene:
    # The ring round the eye, wider than a sprite reaches from its block (SPRITE_REACH_M):
    # the near layer holds every sprite the eye can be in.
    rings = (NearRing(eye, drift, 1.0),)
    settings = SceneSettings(ring_radius_m=2000.0)
    return build_frame(
        state, drift, Camera(position_m=eye), rings, sky_params(state), settings, lod=False
    )


@pytest.mark.parametrize("name", ["overcast-stratus", "thunderstorm", "broken-stratocumulus"])
def test_a_point_in_a_drawn_cloud_is_in_cloud_and_agrees_with_the_frame(name: str) -> None:
    """Points at drawn sprites and round them, across their layers' bases and tops: the
    answer is the frame's own in-cloud test for a camera there, to the metre of visibility."""
    state, drift = preset_state(name)
    drawn = _frame(state, drift, (0.0, 0.0, state.layers[0].base_m)).near.sprites
    rng = np.random.default_rng(3)
    # Opaque sprites near the middle of the scene, a few per layer.
    near = np.flatnonzero(
        (np.hypot(drawn.centre_m[:, 0], drawn.centre_m[:, 1]) < 1500.0) & (drawn.opacity > 0.9)
    )
    assert near.size > 0
    picks = rng.choice(near, size=min(6, near.size), replace=False)
    inside = 0
    for i in picks:
        centre = drawn.centre_m[i]
        reach = INSIDE_FRAC * float(drawn.size_m[i])
        for dz in (0.0, 0.5 * reach, -0.5 * reach, 0.95 * reach, -0.95 * reach):
            point = (float(centre[0]), float(centre[1]), float(centre[2] + dz))
            got = conditions_at(state, drift, point)
            seen = _frame(state, drift, point).in_cloud
            assert got.in_cloud == seen.inside, (name, point)
            if seen.visibility_m is not None:
                assert got.visibility_m == pytest.approx(seen.visibility_m, abs=1.0)
            inside += got.in_cloud
            if dz == 0.0:
                # A drawn sprite's centre is inside its cloud.
                assert got.in_cloud and got.humidity_pct == 100.0, (name, point)
                assert max(got.cloud_water_gpm3) > 0.0
    assert inside >= len(picks)


def test_a_batch_of_points_gets_each_points_own_answer() -> None:
    """Issue 40: a batch looks each drifted block up once; the answers are the points' own."""
    state, drift = preset_state("thunderstorm")
    rng = np.random.default_rng(40)
    points = [
        (float(e), float(n), float(a))
        for e, n, a in zip(
            rng.uniform(-9000.0, 9000.0, 30),
            rng.uniform(-9000.0, 9000.0, 30),
            rng.uniform(0.0, 9000.0, 30),
            strict=True,
        )
    ]
    assert conditions_many(state, drift, points) == [conditions_at(state, drift, p) for p in points]


def test_a_block_kept_at_its_height_and_drifted_is_the_frames_own() -> None:
    """Issue 40: the answers keep each layer's blocks across frames and add the drift after;
    the sprites are the very ones `layer_block` places with the drift."""
    state, _ = preset_state("thunderstorm")
    for layer, key in zip(state.layers, layer_keys(state.layers), strict=True):
        for bx, by in ((0, 0), (-1, 2), (3, -4)):
            want = layer_block(bx, by, key, layer, state.seed, DRIFT_M)
            got = _drifted(_placed_block(bx, by, key, layer, state.seed), DRIFT_M)
            assert np.array_equal(got.centre_m, want.centre_m)
            assert np.array_equal(got.slab_m, want.slab_m, equal_nan=True)
            assert np.array_equal(got.opacity, want.opacity)
