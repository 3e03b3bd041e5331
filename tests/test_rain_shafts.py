"""Rain and snow shafts (wxsky/scene/rain.py): what the weather says falls, and the shafts it
hangs under cumulonimbus and nimbostratus, from the base to the ground, with the cloud."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from wxsky.scene.camera import Camera
from wxsky.scene.clouds import layer_keys
from wxsky.scene.formation import layer_block
from wxsky.scene.gather import NearRing, gather_near_blocks
from wxsky.scene.rain import MAX_SPRITES_PER_SHAFT, Rain, is_shaft, rain_of, shaft_sprites
from wxsky.settings.presets import load_preset
from wxsky.weather.state import (
    CloudLayer,
    CloudType,
    PrecipKind,
    PrecipLayer,
    WeatherState,
)

GROUND_M = 432.0
STORM = WeatherState().apply(load_preset("thunderstorm"))


def _state(present: tuple[str, ...] = (), precip: tuple[PrecipLayer, ...] = ()) -> WeatherState:
    return dataclasses.replace(STORM, present_weather=present, precipitation=precip)


@pytest.mark.parametrize(
    "groups, intensity, snow",
    [
        (("+TSRA",), 1.0, False),
        (("SHRA",), 0.65, False),
        (("-RA", "BR"), 0.35, False),
        (("-SN",), 0.35, True),
        (("+SHSN",), 1.0, True),
        (("RASN",), 0.65, False),  # rain and snow mixed: a rain shaft
        (("-RA", "+TSRA"), 1.0, False),  # the heaviest wins
        (("TSGR",), 0.65, False),  # hail
    ],
)
def test_what_falls_from_present_weather(
    groups: tuple[str, ...], intensity: float, snow: bool
) -> None:
    rain = rain_of(_state(groups))
    assert rain == Rain(intensity, snow, GROUND_M)


@pytest.mark.parametrize("groups", [(), ("TS",), ("-DZ",), ("BR", "FG"), ("VCSH",), ("",)])
def test_nothing_that_makes_a_shaft(groups: tuple[str, ...]) -> None:
    assert rain_of(_state(groups)) is None


def test_cigi_precipitation_layers_fall_too() -> None:
    snow = PrecipLayer(PrecipKind.SNOW, 0.0, 1500.0, 50.0, 5, 800.0)
    rain = PrecipLayer(PrecipKind.RAIN, 0.0, 1500.0, 50.0, 1, 5000.0)
    assert rain_of(_state(precip=(rain,))) == Rain(2 / 6, False, GROUND_M)
    assert rain_of(_state(("-RA",), (rain, snow))) == Rain(1.0, True, GROUND_M)


def _cb_block(rain: Rain | None, cover: float = 8.0) -> tuple[CloudLayer, np.ndarray, object]:
    cb = next(lay for lay in STORM.layers if lay.type == CloudType.CUMULONIMBUS)
    cb = dataclasses.replace(cb, cover_oktas=cover)
    key = layer_keys((cb,))[0]
    block = layer_block(3, -2, key, cb, STORM.seed, rain=rain)
    return cb, is_shaft(block), block


def test_a_shaft_hangs_from_the_base_to_the_ground_under_its_cloud() -> None:
    heavy = Rain(1.0, False, GROUND_M)
    cb, shaft, block = _cb_block(heavy)
    assert shaft.any() and shaft.sum() <= MAX_SPRITES_PER_SHAFT * len(np.unique(block.cloud_id))
    s = block
    bottom = s.centre_m[shaft, 2] - 0.5 * s.size_m[shaft]
    top = s.centre_m[shaft, 2] + 0.5 * s.size_m[shaft]
    assert bottom.min() == pytest.approx(GROUND_M, abs=1.0)  # it reaches the ground
    # Its sprites' centres stay under the base; the top ones reach a quarter of a sprite into
    # it, so the shaft hangs from the cloud rather than under a gap.
    assert s.centre_m[shaft, 2].max() < cb.base_m
    assert top.max() <= cb.base_m + 0.25 * s.size_m[shaft].max() + 1e-3
    for cid in np.unique(s.cloud_id[shaft]):
        mine = shaft & (s.cloud_id == cid)
        body = ~shaft & (s.cloud_id == cid)
        base = body & (s.centre_m[:, 2] < s.centre_m[body, 2].min() + 400.0)
        # Under the middle of its own cloud's base, narrower than the base.
        axis = s.centre_m[base, :2].mean(axis=0)
        assert np.allclose(s.centre_m[mine, :2].mean(axis=0), axis, atol=1.0)
        spread = np.hypot(*(s.centre_m[mine, :2] - axis).T).max()
        assert spread < np.hypot(*(s.centre_m[base, :2] - axis).T).max()
    # None without rain; none under other types.
    assert not _cb_block(None)[1].any()
    sc = next(lay for lay in STORM.layers if lay.type == CloudType.STRATOCUMULUS)
    other = layer_block(3, -2, layer_keys((sc,))[0], sc, STORM.seed, rain=heavy)
    assert not is_shaft(other).any()


def test_the_shafts_kept_for_a_batch_are_its_own() -> None:
    """is_shaft keeps the last batch's answer by its arrays: a moved copy of the batch (a
    frame's near set) gets it, any other batch its own."""
    _, shaft, block = _cb_block(Rain(1.0, False, GROUND_M))
    _, none, dry = _cb_block(None)
    assert shaft.any() and not none.any()
    moved = block.with_centres(block.centre_m + 100.0)
    for batch, want in ((moved, shaft), (dry, none), (block, shaft), (dry, none)):
        got = is_shaft(batch)
        np.testing.assert_array_equal(got, want)
        assert not got.flags.writeable
    assert is_shaft(moved) is is_shaft(block)
    # Rows taken from a batch are a batch of their own.
    rows = np.flatnonzero(shaft)[:3]
    assert is_shaft(block.take(rows)).all()


def test_a_shaft_is_densest_at_its_core_and_follows_the_intensity_and_formation() -> None:
    clouds = _cb_block(None)[2]
    heavy = shaft_sprites(clouds, 1500.0, Rain(1.0, False, GROUND_M))
    light = shaft_sprites(clouds, 1500.0, Rain(0.35, False, GROUND_M))
    assert np.allclose(light.opacity, 0.35 * heavy.opacity)
    one = heavy.take(heavy.cloud_id == heavy.cloud_id[0])
    axis = one.centre_m[:, :2].mean(axis=0)
    radius = np.hypot(*(one.centre_m[:, :2] - axis).T) + 0.5 * one.size_m

    def cover_at(offset: float) -> int:  # sprites whose square a vertical line there crosses
        x = axis[0] + offset
        return int(np.count_nonzero(np.abs(one.centre_m[:, 0] - x) < 0.5 * one.size_m))

    assert cover_at(0.0) > cover_at(0.9 * radius.max())
    # A half-formed cloud has a fainter shaft.
    fading = dataclasses.replace(clouds, opacity=(0.5 * clouds.opacity).astype(np.float32))
    half = shaft_sprites(fading, 1500.0, Rain(1.0, False, GROUND_M))
    assert np.allclose(half.opacity, 0.5 * heavy.opacity)
    # No shaft from a base at or below the ground.
    assert len(shaft_sprites(clouds, GROUND_M, Rain(1.0, False, GROUND_M))) == 0


def test_snow_falls_wider_and_paler_than_rain() -> None:
    clouds = _cb_block(None)[2]
    rain = shaft_sprites(clouds, 1500.0, Rain(1.0, False, GROUND_M))
    snow = shaft_sprites(clouds, 1500.0, Rain(1.0, True, GROUND_M))

    def width(b: object) -> float:
        s = b  # type: ignore[assignment]
        first = s.cloud_id == s.cloud_id[0]  # type: ignore[attr-defined]
        xy = s.centre_m[first, :2]  # type: ignore[attr-defined]
        return float(np.ptp(xy[:, 0]) + s.size_m[first].max())  # type: ignore[attr-defined]

    assert width(snow) > width(rain)
    assert snow.darkness.max() < rain.darkness.min()


def test_the_near_layer_of_a_thunderstorm_has_its_shafts_and_loses_them_when_it_stops() -> None:
    camera = Camera(position_m=(0.0, 0.0, 2500.0), heading_deg=0.0, pitch_deg=0.0)
    ring = (NearRing(camera.position_m, (), 1.0),)

    def shafts(state: WeatherState) -> int:
        batch = gather_near_blocks(state, (), ring, 20_000.0)[0]
        return int(np.count_nonzero(is_shaft(batch)))

    assert shafts(STORM) > 0
    # The same sky with the rain stopped: the near set is a different one, with no shafts.
    assert shafts(dataclasses.replace(STORM, present_weather=())) == 0
    assert shafts(STORM) > 0
