"""The silver lining (issue 41, item 3): a sprite's thin outer texels show the light its centre
is shaded without, the key light's forward beam that the cloud in front of the centre takes
off (`shading_harris.harris_radiance_and_rim`). Under the physical sky the draw carries each
sprite's rim colour (SpriteDraw.rgba, columns 4-6) through every stage that keeps, merges,
drops or fogs sprites, and the sprite shader mixes it in by how thin a texel is."""

from __future__ import annotations

import dataclasses
from datetime import UTC, datetime

import numpy as np
import pytest
from sprite_helpers import sprite_batch

from tests.test_shading import _cumulus
from wxsky.render.renderer import Renderer
from wxsky.scene.atmosphere import atmosphere_key, build_luts
from wxsky.scene.camera import Camera
from wxsky.scene.cloud_lod import collapse_far_clouds
from wxsky.scene.exposure import display_inverse
from wxsky.scene.in_cloud import InCloud, in_cloud_fog
from wxsky.scene.layout import FrameScene, SpriteDraw, shade_for_eye
from wxsky.scene.shading import display_colours, display_colours_and_rim
from wxsky.scene.shading_harris import batch_balls, view_depth_and_limb, view_rays
from wxsky.scene.sky import SkyParams, SunPosition, deck_share, deck_sun_share, sky_params
from wxsky.scene.sprite_budget import cap_sprites
from wxsky.scene.sprites import SpriteBatch
from wxsky.scene.texture_slots import TEX_FOG
from wxsky.settings.presets import load_preset
from wxsky.weather.state import WeatherState

LUMA = np.array([0.2126, 0.7152, 0.0722])
NOON = datetime(2026, 6, 21, 11, 30, tzinfo=UTC)
EYE = (0.0, -6000.0, 2250.0)  # 6 km south of the cloud, level with its middle


def _sky(elevation_deg: float, azimuth_deg: float, physical: bool = True) -> SkyParams:
    sky = dataclasses.replace(
        sky_params(WeatherState(time_utc=NOON)), sun=SunPosition(elevation_deg, azimuth_deg)
    )
    if not physical:
        return sky
    return sky.with_atmosphere(build_luts(atmosphere_key(elevation_deg, 30_000.0, 60.0, 2.0)))


def test_a_cloud_before_a_low_sun_has_rims_brighter_than_its_body() -> None:
    cloud = _cumulus()
    behind_cloud = _sky(5.0, 0.0)  # the sun due north, the eye south of the cloud
    body, rim = display_colours_and_rim(cloud, behind_cloud, EYE, "harris")
    assert rim is not None and rim.shape == body.shape == (3, len(cloud))
    assert np.isfinite(rim).all() and (rim >= 0.0).all() and (rim <= 1.0).all()
    # The rim keeps what the cloud before the centre takes: never darker, and for the
    # sprites behind others toward the eye (most of a cloud) far brighter. In radiance: the
    # tone map keeps hue (max-RGB), so adding orange light can lower a display's green.
    rim_l = display_inverse(rim.T, 1.0) @ LUMA
    body_l = display_inverse(body.T, 1.0) @ LUMA
    # (Where the body is already past the curve's white its display says nothing more.)
    unclipped = body.max(axis=0) < 0.999
    assert unclipped.sum() > len(cloud) // 2
    assert (rim_l >= body_l - 1e-6)[unclipped].all()
    gain = rim_l / np.maximum(body_l, 1e-6)
    assert np.median(gain) > 1.5, np.median(gain)
    # The body is what display_colours gives.
    assert np.array_equal(body, display_colours(cloud, behind_cloud, EYE, "harris"))
    # With the sun behind the eye the droplets scatter less toward it: the rim is nearer
    # the body (the forward peak is what makes a silver lining).
    behind_eye = _sky(5.0, 180.0)
    body_away, rim_away = display_colours_and_rim(cloud, behind_eye, EYE, "harris")
    assert rim_away is not None
    away_gain = (display_inverse(rim_away.T, 1.0) @ LUMA) / np.maximum(
        display_inverse(body_away.T, 1.0) @ LUMA, 1e-6
    )
    # Measured: a median gain of 1.23 with the sun behind the eye, 2.4 before it (over 3
    # before the cumulus hung their base's puffs down to the cut at the flat base, issue 42).
    assert np.median(gain) > 1.6 * np.median(away_gain), (away_gain, gain)


@pytest.mark.parametrize("model", ["wang", "wang-artist"])
def test_models_without_a_rim_and_the_gradient_sky_give_four_columns(model: str) -> None:
    cloud = _cumulus()
    _, rim = display_colours_and_rim(cloud, _sky(5.0, 0.0), EYE, model)
    assert rim is None
    gradient = _sky(5.0, 0.0, physical=False)
    _, rim = display_colours_and_rim(cloud, gradient, EYE, "harris")
    assert rim is None
    draw = shade_for_eye(cloud, EYE, gradient, 100_000.0, "harris")
    assert draw.rgba.shape == (len(cloud), 4)
    draw = shade_for_eye(cloud, EYE, _sky(5.0, 0.0), 100_000.0, "harris")
    assert draw.rgba.shape == (len(cloud), 7)
    # Hazed alike: a sprite with no forward beam hidden (none before it) has rim = body.
    assert np.isfinite(draw.rgba).all()


def _seven(n: int, seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    rgba = rng.uniform(0.1, 0.6, (n, 7)).astype(np.float32)
    rgba[:, 4:7] = rgba[:, :3] + 0.3  # rims brighter than bodies, told apart below
    return rgba


def test_rims_survive_the_stages_that_merge_drop_and_fog_sprites() -> None:
    cloud = _cumulus()
    n = len(cloud)
    rgba = _seven(n)
    far = cloud.shifted((0.0, 40_000.0, 0.0))
    # One sprite for a far cloud: its rim is the coverage-weighted mean of its sprites'.
    collapsed = collapse_far_clouds(far, rgba, (0.0, 0.0, 0.0), 10_000.0, 1_000.0)
    assert collapsed.lod_clouds == 1 and collapsed.rgba.shape[1] == 7
    one = collapsed.rgba[-1]
    assert (one[4:7] > one[:3]).all()
    assert one[4:7] == pytest.approx(one[:3] + 0.3, abs=1e-4)
    # A budget keeps rows whole.
    capped = cap_sprites(cloud, rgba, EYE, n // 2)
    assert capped.rgba.shape[1] == 7
    assert np.allclose(capped.rgba[:, 4:7] - capped.rgba[:, :3], 0.3, atol=1e-6)
    # In cloud, the rims fog as the bodies do, toward the same fog colour.
    inside = InCloud(inside=True, visibility_m=40.0)  # the core of a cloud
    eye = tuple(float(v) for v in cloud.centre_m.mean(axis=0))
    fogged, veil = in_cloud_fog(cloud, rgba, eye, inside)  # type: ignore[arg-type]
    assert veil[3] > 0.0
    assert fogged.shape == rgba.shape
    diff_before = rgba[:, 4:7] - rgba[:, :3]
    diff_after = fogged[:, 4:7] - fogged[:, :3]
    assert (np.abs(diff_after) <= np.abs(diff_before) + 1e-6).all()
    assert np.abs(diff_after).sum() < np.abs(diff_before).sum()


@pytest.mark.gl
def test_the_shader_shows_the_rim_in_thin_texels_and_the_body_in_thick_ones(
    renderer: Renderer,
) -> None:
    sky = sky_params(WeatherState(time_utc=NOON))
    cam = Camera(position_m=(0.0, 0.0, 1000.0), fov_deg=60.0, width_px=161, height_px=91)
    batch = sprite_batch([(0, 2000, 1000)], [900], texture=TEX_FOG[0])
    body = np.float32([[0.2, 0.2, 0.2, 1.0]])

    def near(rgba: np.ndarray) -> np.ndarray:
        renderer.render_frame(FrameScene(cam, sky, SpriteDraw(batch, rgba)))
        return renderer.read("near").astype(np.float64)

    plain = near(body)
    same = near(np.concatenate([body, body[:, :3]], axis=1))
    bright = near(np.concatenate([body, np.float32([[1.0, 1.0, 1.0]])], axis=1))
    alpha = plain[..., 3] / 255.0
    # The fog texture is soft: its densest texels give about 0.85.
    assert (alpha > 0.8).any() and ((alpha > 0.02) & (alpha < 0.3)).any()
    # Alpha is the sprite's whatever its rim.
    assert np.array_equal(plain[..., 3], bright[..., 3])
    thin = (alpha > 0.02) & (alpha < 0.3)
    thick = alpha > 0.8

    # Premultiplied: straight colour = rgb / alpha.
    def straight(img: np.ndarray, where: np.ndarray) -> float:
        return float((img[..., :3].mean(axis=2)[where] / img[..., 3][where]).mean())

    assert straight(bright, thin) > straight(plain, thin) + 0.3
    assert straight(bright, thick) < straight(plain, thick) + 0.15
    # A rim of the body's own colour keeps the thin texels near that colour (the texture's
    # shade is left out there), and no rim at all draws exactly what it always did.
    assert abs(straight(same, thin) - straight(plain, thin)) < 0.15


def _limb(cloud: SpriteBatch, toward_light: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """(limb share, the sprites' offset across the view from their cloud's centre, as a
    share of its radius) for the cloud seen from EYE."""
    view = view_rays(cloud.centre_m, EYE)
    balls = batch_balls(cloud)
    _, limb = view_depth_and_limb(cloud, view, balls, toward_light)
    rel = balls[:, :3].astype(np.float64)
    along = np.einsum("ij,ji->i", rel, view)
    across = np.sqrt(np.maximum(np.einsum("ij,ij->i", rel, rel) - along**2, 0.0))
    return limb, across / balls[:, 3]


def _unit(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    el, az = np.radians(elevation_deg), np.radians(azimuth_deg)
    return np.array([np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), np.sin(el)])


def test_a_fringe_on_the_silhouette_is_in_the_beam_only_where_the_beam_misses_the_body() -> None:
    cloud = _cumulus()
    # Without a light: the sprites whose edge reaches the silhouette, and none deep inside.
    bare, across = _limb(cloud, None)
    assert (bare[across < 0.3] == 0.0).all()
    assert (bare > 0.5).any() and (bare <= 1.0).all() and (bare >= 0.0).all()
    # A sun 5 degrees up right behind the cloud (due north, the eye south of it): a ray from
    # the limb toward it crosses a thin slice of the ball, so the fringe keeps much of it.
    behind, _ = _limb(cloud, _unit(5.0, 0.0))
    assert (behind <= bare + 1e-12).all()
    rim = bare > 0.5
    assert np.median(behind[rim] / bare[rim]) > 0.3
    # A sun overhead: the fringe under the cloud (its offset below the centre) would see it
    # through the whole cloud; the fringe over it sees it straight.
    overhead, _ = _limb(cloud, _unit(85.0, 0.0))
    # Under the cloud: its lower part (a sprite on its side just below the centre sees an
    # overhead sun past the body, as one just above it does).
    balls = batch_balls(cloud)
    below = balls[:, 2] < -0.25 * balls[:, 3]
    assert overhead[rim & below].max() < 0.06  # measured 0.050
    assert np.median(overhead[rim & ~below] / bare[rim & ~below]) > 0.5


def test_a_deck_stands_in_the_way_of_a_low_sun_not_of_a_high_one() -> None:
    base = sky_params(WeatherState().apply(load_preset("broken-stratocumulus")))
    eye = base.ground_m + 2.0  # at the ground, under the deck
    shares = [
        deck_sun_share(dataclasses.replace(base, sun=SunPosition(el, 0.0)), eye)
        for el in (0.0, 5.0, 30.0, 90.0)
    ]
    assert deck_share(base, eye) == 1.0
    assert shares[0] == pytest.approx(1.0 - base.cover)
    assert shares == sorted(shares) and shares[-1] == pytest.approx(1.0)
    # Over the deck, and under scattered cloud, nothing stands in the way.
    assert deck_sun_share(base, 10_000.0) == 1.0
    scattered = sky_params(WeatherState().apply(load_preset("scattered-cumulus")))
    assert deck_sun_share(dataclasses.replace(scattered, sun=SunPosition(2.0, 0.0)), 0.0) == 1.0
