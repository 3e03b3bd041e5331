"""Both shading models on a generated cumulus from noon to night, Wang's tables, Harris's
lights and cache, the ring's whole-cloud lighting, and the `[scene] shading` key."""

from __future__ import annotations

import dataclasses
from datetime import UTC, datetime, timedelta

import numpy as np
import pytest

from wxsky.scene import shading_harris
from wxsky.scene.cloud_model_files import default_models
from wxsky.scene.clouds import SpriteBatch, block_clouds, layer_keys
from wxsky.scene.layout import SceneSettings, shade_for_eye
from wxsky.scene.shading import (
    DEFAULT_SHADING,
    SHADING_MODELS,
    prepare_lighting,
    sprite_colours,
)
from wxsky.scene.shading_harris import particle_light, scene_lights
from wxsky.scene.shading_wang import (
    AMBIENT_BY_SUN_EL,
    LEVEL_HEIGHTS,
    LEVEL_RGB,
    sunset_tint,
    wang_colours,
)
from wxsky.scene.sky import SkyParams, SunPosition, sky_params
from wxsky.settings.config import SceneSection
from wxsky.weather.state import CloudLayer, CloudType, WeatherState

LUMA = np.array([0.2126, 0.7152, 0.0722])
LAYER = CloudLayer(8.0, 1500.0, 3000.0, CloudType.CUMULUS)  # 1500 m: cumulus mediocris
EYE = (0.0, -6000.0, 500.0)  # 6 km south of the cloud, near the ground
NOON = datetime(2026, 6, 21, 11, 30, tzinfo=UTC)
NIGHT = datetime(2026, 6, 21, 23, 30, tzinfo=UTC)  # sun -19°, moon just set


def _cumulus() -> SpriteBatch:
    """The largest cloud of a generated cumulus block, its axis over the origin, z MSL."""
    model = default_models().for_layer(LAYER.type, LAYER.thickness_m)
    block = block_clouds(0, 0, layer_keys((LAYER,))[0], model, LAYER.thickness_m, 7)
    ids, counts = np.unique(block.sprites.cloud_id, return_counts=True)
    one = block.sprites.take(np.flatnonzero(block.sprites.cloud_id == ids[np.argmax(counts)]))
    centre = one.centre_m.mean(axis=0)
    return one.shifted((-centre[0], -centre[1], LAYER.base_m))


def _sky(t: datetime) -> SkyParams:
    return sky_params(WeatherState(time_utc=t))


def _dusk() -> SkyParams:
    """Zurich's sky on the evening of 21 June with the sun 2° up (19:08 UTC)."""
    start = datetime(2026, 6, 21, 18, 30, tzinfo=UTC)
    times = [start + timedelta(minutes=m) for m in range(80)]
    sky = min((_sky(t) for t in times), key=lambda s: abs(s.sun.elevation_deg - 2.0))
    assert sky.sun.elevation_deg == pytest.approx(2.0, abs=0.1)
    return sky


def _with_sun(sky: SkyParams, elevation_deg: float, azimuth_deg: float) -> SkyParams:
    return dataclasses.replace(sky, sun=SunPosition(elevation_deg, azimuth_deg))


def _luma(rgba: np.ndarray) -> np.ndarray:
    return rgba[:, :3] @ LUMA


def _redness(rgba: np.ndarray) -> float:
    return float(rgba[:, 0].mean() / rgba[:, 2].mean())


def test_harris_lower_third_darker_than_upper_third_with_the_sun_overhead() -> None:
    # Measured: lower third 0.56, upper third 0.86 (light reaching them 0.09 and 0.63).
    cloud = _cumulus()
    sky = _with_sun(_sky(NOON), 90.0, 0.0)
    lum = _luma(sprite_colours(cloud, sky, EYE, "harris"))
    low, top = cloud.height_frac < 1 / 3, cloud.height_frac > 2 / 3
    assert low.sum() >= 10 and top.sum() >= 10
    assert lum[low].mean() < lum[top].mean() - 0.15
    # And the light itself: the precompute darkens the base, not just Wang-like levels.
    incident = particle_light(cloud, scene_lights(sky)).lookup(cloud)
    assert incident is not None
    assert incident[low, 0].mean() < 0.5 * incident[top, 0].mean()


def test_harris_silver_lining_toward_the_sun() -> None:
    # Edge sprites (core_frac > 0.7) seen level from 6 km, sun 10° up behind the cloud
    # versus behind the eye. Measured: 0.95 against 0.73.
    cloud = _cumulus()
    eye = (0.0, -6000.0, 0.5 * (LAYER.base_m + LAYER.top_m))
    edge = cloud.core_frac > 0.7
    assert edge.sum() >= 10
    behind_cloud = _with_sun(_sky(NOON), 10.0, 0.0)
    behind_eye = _with_sun(_sky(NOON), 10.0, 180.0)
    rim = _luma(sprite_colours(cloud, behind_cloud, eye, "harris"))[edge].mean()
    lit_face = _luma(sprite_colours(cloud, behind_eye, eye, "harris"))[edge].mean()
    assert rim > lit_face + 0.1
    # Wang's shading groups under the same light have the rim too (measured 0.34 against
    # 0.20); his artist model has no halo (his words): within a few percent either way.
    wang_rim = _luma(sprite_colours(cloud, behind_cloud, eye, "wang"))[edge].mean()
    wang_face = _luma(sprite_colours(cloud, behind_eye, eye, "wang"))[edge].mean()
    assert wang_rim > wang_face + 0.1
    artist_rim = _luma(sprite_colours(cloud, behind_cloud, eye, "wang-artist"))[edge].mean()
    artist_face = _luma(sprite_colours(cloud, behind_eye, eye, "wang-artist"))[edge].mean()
    assert abs(artist_rim - artist_face) < 0.1


@pytest.mark.parametrize("model", SHADING_MODELS)
def test_dusk_is_redder_than_noon(model: str) -> None:
    # Mean R / mean B. Measured: Wang 0.96 -> 2.27 (2.4x), Harris 0.86 -> 1.85 (2.1x).
    cloud = _cumulus()
    noon = _redness(sprite_colours(cloud, _sky(NOON), EYE, model))
    dusk = _redness(sprite_colours(cloud, _dusk(), EYE, model))
    assert dusk >= 1.3 * noon


@pytest.mark.parametrize("model", SHADING_MODELS)
def test_night_clouds_are_dark_but_not_black(model: str) -> None:
    # Mean luma. Measured: Wang 0.075 (noon 0.80), Harris 0.091 (noon 0.59).
    cloud = _cumulus()
    sky = _sky(NIGHT)
    assert sky.sun.elevation_deg < -18.0 and sky.moon_rgb == (0.0, 0.0, 0.0)
    night = _luma(sprite_colours(cloud, sky, EYE, model))
    noon = _luma(sprite_colours(cloud, _sky(NOON), EYE, model))
    assert 0.02 < night.mean() < 0.2 * noon.mean()
    assert night.min() > 0.01


@pytest.mark.parametrize("model", SHADING_MODELS)
def test_every_time_of_day_and_random_batches_give_finite_colours_in_range(model: str) -> None:
    rng = np.random.default_rng(11)
    n = 400
    light_dir = rng.normal(size=(n, 3))
    light_dir /= np.linalg.norm(light_dir, axis=1, keepdims=True)
    light_dir[:20] = 0.0  # a shading group centred on its cloud's centre
    batch = SpriteBatch(
        centre_m=rng.uniform(-3000.0, 3000.0, size=(n, 3)) + np.array([0.0, 0.0, 2000.0]),
        size_m=rng.uniform(1.0, 900.0, n).astype(np.float32),
        rotation_rad=rng.uniform(0.0, 6.3, n).astype(np.float32),
        texture=rng.integers(0, 16, n).astype(np.int32),
        height_frac=rng.uniform(0.0, 1.0, n).astype(np.float32),
        light_dir=light_dir.astype(np.float32),
        opacity=rng.uniform(0.0, 1.0, n).astype(np.float32),
        darkness=rng.uniform(0.0, 1.0, n).astype(np.float32),
        cloud_id=rng.integers(0, 12, n).astype(np.int64),
        core_frac=rng.uniform(0.0, 1.0, n).astype(np.float32),
    )
    eyes = [(0.0, 0.0, 0.0), tuple(batch.centre_m[0]), (5.0e4, -2.0e4, 9000.0)]
    for hour in range(0, 24, 3):
        sky = _sky(datetime(2026, 3, 20, hour, 17, tzinfo=UTC))
        for eye in eyes:
            rgba = sprite_colours(batch, sky, eye, model)  # type: ignore[arg-type]
            assert rgba.shape == (n, 4) and rgba.dtype == np.float32
            assert np.all(np.isfinite(rgba)) and rgba.min() >= 0.0 and rgba.max() <= 1.0
            np.testing.assert_array_equal(rgba[:, 3], batch.opacity)
    empty = sprite_colours(SpriteBatch.empty(), _sky(NOON), EYE, model)
    assert empty.shape == (0, 4)


def test_wang_levels_and_time_of_day_table() -> None:
    cloud = _cumulus()
    noon, night = _sky(NOON), _sky(NIGHT)
    flat = dataclasses.replace(
        cloud,
        light_dir=np.zeros_like(cloud.light_dir),
        darkness=np.zeros_like(cloud.darkness),
    )
    rgb = wang_colours(flat, night)[:, :3]
    base, top = flat.height_frac.argmin(), flat.height_frac.argmax()
    # At night only the ambient levels show, scaled by the table's night percentage.
    night_share = AMBIENT_BY_SUN_EL[0][1]
    level = np.stack(
        [np.interp(flat.height_frac, LEVEL_HEIGHTS, LEVEL_RGB[:, c]) for c in range(3)],
        axis=1,
    )
    np.testing.assert_allclose(rgb, level * night_share, atol=1e-6)
    assert rgb[base].sum() < rgb[top].sum()
    # By day the side facing the sun is brighter than the side away from it.
    sun = np.asarray(noon.sun.direction_enu, np.float32)
    towards = dataclasses.replace(flat, light_dir=np.tile(sun, (len(flat), 1)))
    away = dataclasses.replace(flat, light_dir=np.tile(-sun, (len(flat), 1)))
    low = _sky(datetime(2026, 6, 21, 17, 0, tzinfo=UTC))  # 18° up: nothing clips at 1
    assert _luma(wang_colours(towards, low)).mean() > _luma(wang_colours(away, low)).mean() + 0.05
    np.testing.assert_allclose(sunset_tint(noon), 1.0)
    tint = sunset_tint(_dusk())
    assert tint[0] == pytest.approx(1.0) and tint[2] < 0.7


def test_harris_key_light_hands_over_from_sun_to_moon_without_a_jump() -> None:
    noon, dusk = _sky(NOON), _dusk()
    lights = scene_lights(noon)
    assert lights.directions.shape == (5, 3) and lights.rgb.shape == (5, 3)
    np.testing.assert_allclose(lights.directions[0], noon.sun.direction_enu, atol=1e-3)
    np.testing.assert_allclose(lights.rgb[0], noon.sun_rgb)
    np.testing.assert_allclose(np.linalg.norm(lights.directions, axis=1), 1.0)
    moon_up = _sky(datetime(2026, 6, 21, 22, 0, tzinfo=UTC))  # sun -16°, half moon 11° up
    moonlit = scene_lights(moon_up)
    np.testing.assert_allclose(moonlit.directions[0], moon_up.moon.direction_enu, atol=1e-3)
    assert 0.0 < moonlit.rgb[0].max() < 0.1
    # The minutes either side of the hand-over (sun at -3°): neither light is on.
    start = datetime(2026, 6, 21, 19, 20, tzinfo=UTC)
    skies = [_sky(start + timedelta(minutes=m)) for m in range(40)]
    k = next(i for i, s in enumerate(skies) if s.sun.elevation_deg < -3.0)
    before, after = scene_lights(skies[k - 1]), scene_lights(skies[k])
    np.testing.assert_allclose(before.directions[0], skies[k - 1].sun.direction_enu, atol=1e-3)
    np.testing.assert_allclose(after.directions[0], skies[k].moon.direction_enu, atol=1e-3)
    assert before.rgb[0].max() < 0.01 and after.rgb[0].max() < 0.01
    assert scene_lights(dusk).rgb[0].max() > 0.5


def test_harris_precompute_is_reused_and_independent_of_order_drift_and_eye() -> None:
    cloud = _cumulus()
    sky = _sky(NOON)
    shading_harris._CACHE.clear()
    first = sprite_colours(cloud, sky, EYE, "harris")
    assert len(shading_harris._CACHE) == 1
    perm = np.random.default_rng(2).permutation(len(cloud))
    moved = cloud.take(perm).shifted((812.5, -33.25, 0.0))
    again = sprite_colours(moved, sky, (EYE[0] + 812.5, EYE[1] - 33.25, EYE[2]), "harris")
    assert len(shading_harris._CACHE) == 1  # a hit: same clouds, drifted and reordered
    np.testing.assert_allclose(again, first[perm], atol=1e-6)
    # Formation changes a cloud's opacity, so its light: a new entry.
    thin = dataclasses.replace(cloud, opacity=(cloud.opacity * 0.5).astype(np.float32))
    sprite_colours(thin, sky, EYE, "harris")
    assert len(shading_harris._CACHE) == 2


def test_ring_bins_read_the_light_of_their_whole_cloud() -> None:
    cloud = _cumulus()
    # Clear air: the haze 6 km off (the default state's 10 km visibility leaves 10 % of a
    # cloud's contrast) is not what this test looks at.
    sky = dataclasses.replace(_with_sun(_sky(NOON), 30.0, 90.0), haze_m=1e12)
    half = cloud.take(np.flatnonzero(cloud.centre_m[:, 0] < 0.0))  # the half away from the sun
    light = prepare_lighting(cloud, sky, "harris")
    assert light is not None and prepare_lighting(cloud, sky, "wang") is None
    from_whole = shade_for_eye(half, EYE, sky, 40_000.0, "harris", light)
    own = shade_for_eye(half, EYE, sky, 40_000.0, "harris")
    whole = shade_for_eye(cloud, EYE, sky, 40_000.0, "harris")
    # Cut off from the sunward half, the half would be lit as if nothing shaded it.
    assert _luma(from_whole.rgba).mean() < _luma(own.rgba).mean() - 0.03
    by_key = dict(
        zip(shading_harris.particle_keys(whole.sprites).tolist(), whole.rgba.tolist(), strict=True)
    )
    expected = [by_key[k] for k in shading_harris.particle_keys(from_whole.sprites).tolist()]
    np.testing.assert_allclose(from_whole.rgba, expected, atol=1e-6)
    # A precompute for other sprites is not used by mistake.
    other = prepare_lighting(cloud.shifted((0.0, 0.0, 0.0)).take(np.arange(3)), sky, "harris")
    np.testing.assert_allclose(shade_for_eye(half, EYE, sky, 4e4, "harris", other).rgba, own.rgba)


def test_shading_setting_and_config_key() -> None:
    assert SceneSettings().shading == DEFAULT_SHADING == SceneSection().shading == "harris"
    assert SceneSection(shading="Wang").settings().shading == "wang"
    with pytest.raises(ValueError, match=r"scene\.shading: must be one of wang, harris"):
        SceneSection(shading="phong")
    with pytest.raises(ValueError, match="shading must be one of"):
        sprite_colours(_cumulus(), _sky(NOON), EYE, "phong")


def test_the_lights_are_kept_for_the_frames_of_one_sky_and_made_anew_for_another() -> None:
    sky = _sky(NOON)
    lights = scene_lights(sky)
    # A later frame of the same sky step: only its clock moved.
    assert scene_lights(sky.at_clock(sky.sky_time_s + 1.0 / 30.0)) is lights
    later = _sky(NOON + timedelta(minutes=30))
    other = scene_lights(later)
    assert other is not lights
    assert not np.array_equal(other.directions, lights.directions)
    # And the first sky's again are its own, not the last asked for.
    assert np.array_equal(scene_lights(sky).directions, lights.directions)


def test_a_mixed_batch_is_shaded_as_its_particles_and_its_slabs_apart() -> None:
    """Particle and slab sprites share one pass (view rays, exposure) and are put back in
    their places by index: each sprite's colour is what shading its kind alone gives."""
    from wxsky.scene.shading import display_colours

    cloud = _cumulus()
    deck = dataclasses.replace(
        cloud, slab_m=np.tile(np.float32([1500.0, 1900.0]), (len(cloud), 1))
    ).take(np.arange(0, len(cloud), 2))
    # Interleaved, so that neither kind's rows are a block of the batch.
    mixed = SpriteBatch.concat([cloud, deck])
    order = np.argsort(np.r_[np.arange(len(cloud)) * 2.0, np.arange(len(deck)) * 4.0 + 1.0])
    mixed = mixed.take(order)
    is_slab = order >= len(cloud)
    sky = _sky(NOON)
    for model in SHADING_MODELS:
        rgba = sprite_colours(mixed, sky, EYE, model)
        np.testing.assert_allclose(
            rgba[~is_slab], sprite_colours(cloud, sky, EYE, model)[order[~is_slab]], atol=1e-6
        )
        np.testing.assert_allclose(
            rgba[is_slab],
            sprite_colours(deck, sky, EYE, model)[order[is_slab] - len(cloud)],
            atol=1e-6,
        )
        rgb = display_colours(mixed, sky, EYE, model)
        assert rgb.shape == (3, len(mixed))
        np.testing.assert_array_equal(rgba[:, :3], rgb.T.astype(np.float32))


def test_wang_sprites_take_the_depth_toward_the_eye_of_their_whole_cloud() -> None:
    # Wang has no precompute over whole clouds; the frame's drawn sprites (here the half of
    # the cloud west of its centre) must still be shaded as parts of the whole cloud, or a
    # cloud half out of view would change its shade as the view turns.
    cloud = _cumulus()
    eye = (0.0, -6000.0, 0.5 * (LAYER.base_m + LAYER.top_m))
    sky = dataclasses.replace(_with_sun(_sky(NOON), 10.0, 0.0), haze_m=1e12)  # behind it
    whole = shade_for_eye(cloud, eye, sky, 40_000.0, "wang")
    west = np.flatnonzero(cloud.centre_m[:, 0] < 0.0)
    part = shade_for_eye(cloud, eye, sky, 40_000.0, "wang", order=west)
    by_key = dict(
        zip(shading_harris.particle_keys(whole.sprites).tolist(), whole.rgba.tolist(), strict=True)
    )
    expected = [by_key[k] for k in shading_harris.particle_keys(part.sprites).tolist()]
    np.testing.assert_allclose(part.rgba, expected, atol=1e-6)
    # What the whole cloud's depth changes: shaded as a cloud of their own, they differ.
    alone = shade_for_eye(cloud.take(west), eye, sky, 40_000.0, "wang")
    as_whole = [by_key[k] for k in shading_harris.particle_keys(alone.sprites).tolist()]
    assert np.abs(alone.rgba[:, :3] - np.asarray(as_whole)[:, :3]).max() > 0.01
