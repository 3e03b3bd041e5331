"""The clouds' sunlight, skylight and haze from the physical atmosphere (issue 41, item 2): the
key light at a cloud's altitude is the sun's light transmitted there, the ambient the sky's and
the ground's irradiance there, and distant clouds fade into the physical sky behind them."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import numpy.typing as npt
import pytest

from tests.test_cloud_backlit import low_sun
from wxsky.app.snapshot import take_snapshot
from wxsky.host.compositor import composite, layers_from_images
from wxsky.render.renderer import Renderer
from wxsky.render.sky_textures import display_veil as render_veil
from wxsky.render.sky_textures import physical_uniforms
from wxsky.scene import shading_harris
from wxsky.scene.atmosphere import AtmosphereLuts, atmosphere_key, build_luts, display_exposure
from wxsky.scene.camera import Camera
from wxsky.scene.cloud_light import CloudLights, cloud_lights, cloud_units_per_klx, key_rgb_at
from wxsky.scene.exposure import display
from wxsky.scene.layout import SceneSettings
from wxsky.scene.sky import (
    SkyParams,
    SunPosition,
    aureole,
    display_veil,
    overcast_veil,
    sky_params,
)
from wxsky.settings.presets import load_preset
from wxsky.weather.state import WeatherState

F64 = npt.NDArray[np.float64]
GROUND_M = 432.0  # fair-cumulus's field, MSL


def physical_sky(
    sun_el_deg: float, visibility_m: float = 30_000.0, cover: float = 0.375
) -> SkyParams:
    state = WeatherState().apply(load_preset("fair-cumulus"))
    base = sky_params(state)
    assert base.ground_m == state.observer.alt_m == GROUND_M
    luts = build_luts(atmosphere_key(sun_el_deg, visibility_m, 60.0, 2.0))
    sky = dataclasses.replace(base, sun=SunPosition(sun_el_deg, 270.0), cover=cover)
    return sky.with_atmosphere(luts)


def red_over_blue(rgb: tuple[float, float, float] | F64) -> float:
    return float(rgb[0]) / max(float(rgb[2]), 1e-12)


def lights_at(sky: SkyParams, agl_m: float) -> CloudLights:
    return cloud_lights(sky, alt_m=GROUND_M + agl_m)


def test_low_sun_lights_a_deck_top_before_its_base() -> None:
    """Sun 2 degrees up: the light reaching a top at 3 km has crossed far less air than that
    reaching a base at 1 km, so the top is lit several times brighter; the base's sun, which
    has lost its blue on the longer path, is the redder and darker (on old main both got the
    gradient's one orange, whatever their height)."""
    sky = physical_sky(2.0)
    base, top = lights_at(sky, 1_000.0).key_rgb, lights_at(sky, 3_000.0).key_rgb
    assert top[0] > 3.0 * base[0], (base, top)
    assert red_over_blue(base) > red_over_blue(top) > 2.0, (base, top)
    # Per sprite, as the shading models take it: the same transmittance.
    per_sprite = key_rgb_at(sky, np.array([GROUND_M + 1_000.0, GROUND_M + 3_000.0]))
    assert per_sprite is not None
    assert np.allclose(per_sprite[0], base, rtol=0.02) and np.allclose(
        per_sprite[1], top, rtol=0.02
    )


def test_deck_top_sunlit_while_the_ground_is_in_twilight() -> None:
    """Sun half a degree below the ground's horizon (60 km visibility): no sunlight at the
    ground, a red sun still on a top at 4 km (its horizon dips 2 degrees)."""
    sky = physical_sky(-0.5, visibility_m=60_000.0)
    ground = lights_at(sky, 0.0).key_rgb
    top = lights_at(sky, 4_000.0).key_rgb
    assert max(ground) < 1e-4, ground
    assert top[0] > 0.02, top
    assert red_over_blue(top) > 2.0, top


def test_noon_sun_is_white_and_the_sky_above_blue() -> None:
    """Units (one factor from klx, `cloud_units_per_klx`: the sky's exposure over pi): the
    noon sun is about 1.4 in the clouds' units, past the tone map's mid-tones and short of
    its white (7.2); the sky's light on a cloud is blue-grey (B/R over 1, bluer
    than the sun's), and far weaker than the sun's, as the sky's irradiance is."""
    sky = physical_sky(60.0)
    cl = lights_at(sky, 1_500.0)
    assert 0.8 < cl.key_rgb[1] < 3.0, cl.key_rgb
    zenith_b_over_r = cl.sky_zenith_rgb[2] / cl.sky_zenith_rgb[0]
    assert zenith_b_over_r > 1.1, cl.sky_zenith_rgb
    assert zenith_b_over_r > cl.key_rgb[2] / cl.key_rgb[0] + 0.2, cl
    assert 0.05 < cl.sky_zenith_rgb[1] / cl.key_rgb[1] < 0.5, cl
    # The ground's light is its albedo's share of what falls on it: a small fraction.
    assert 0.0 < cl.ground_rgb[1] < 0.2 * cl.key_rgb[1], cl
    # The one factor: the sky pass's exposure over pi.
    luts = sky.atmosphere
    assert luts is not None
    assert cloud_units_per_klx(luts) == pytest.approx(display_exposure(luts) / math.pi)


def test_a_cloud_as_bright_as_the_sky_shows_as_the_sky_does() -> None:
    """One exposure and one tone map: a cloud whose radiance is the sky's (in the clouds'
    units, kcd/m^2 times the sky's exposure) shows, through the shading models' display
    curve under the physical sky (`shown_channels`), the value the sky pass gives that sky;
    a brighter cloud shows brighter and a darker one darker, for a grey and a blue sky, at
    noon, a low sun and in twilight."""
    for el in (60.0, 5.0, -3.0):
        sky = physical_sky(el)
        luts = sky.atmosphere
        assert luts is not None
        rows = luts.sky_view.shape[0]
        mean = (luts.sky_view[rows // 2 :].reshape(-1, 3) * 128.0).mean(axis=0)
        grey = np.full(3, float(mean @ np.array([0.2126, 0.7152, 0.0722])))
        for radiance in (grey, mean):
            sky_shown = display(radiance, display_exposure(luts))
            units = radiance * display_exposure(luts)
            cloud_shown = shading_harris.shown_channels(units[:, None], sky)[:, 0]
            assert np.allclose(cloud_shown, sky_shown, atol=1e-9), (el, cloud_shown, sky_shown)
            brighter = shading_harris.shown_channels(2.0 * units[:, None], sky)[:, 0]
            darker = shading_harris.shown_channels(0.5 * units[:, None], sky)[:, 0]
            assert np.all(darker < cloud_shown) and np.all(cloud_shown < brighter), el
    # The gradient sky keeps Harris's own curve (the goldens' look).
    gradient = dataclasses.replace(physical_sky(60.0), atmosphere=None)
    units = np.array([[0.5], [0.4], [0.3]])
    assert np.array_equal(
        shading_harris.shown_channels(units, gradient), shading_harris.exposed_channels(units)
    )


def test_shading_lights_follow_the_cloud_altitude() -> None:
    """The shading models' lights (`scene_lights`) are taken at the altitude asked for."""
    sky = physical_sky(3.0)
    low = shading_harris.scene_lights(sky, alt_m=GROUND_M + 800.0)
    high = shading_harris.scene_lights(sky, alt_m=GROUND_M + 4_000.0)
    assert np.array_equal(low.directions, high.directions)
    assert high.rgb[0][1] > 2.0 * low.rgb[0][1], (low.rgb[0], high.rgb[0])


def test_gradient_sky_keeps_its_lights() -> None:
    """`sky = "roden-parberry"` (no tables): the gradient's sun colour, whatever the altitude."""
    state = WeatherState().apply(load_preset("fair-cumulus"))
    sky = sky_params(state)
    assert sky.atmosphere is None
    assert cloud_lights(sky, alt_m=5_000.0).key_rgb == sky.sun_rgb
    assert key_rgb_at(sky, np.array([1_000.0])) is None
    assert sky.haze_toward(np.ones((3, 2))).tolist() == [[c, c] for c in sky.haze_rgb]


def _display_sky(luts: AtmosphereLuts, sky: SkyParams, direction: F64) -> F64:
    """The exact sky: the table's radiance, the aureole, the veil, the tone map."""
    grey_share, dim = overcast_veil(sky.cover)
    sun = np.asarray(sky.sun.direction_enu)
    radiance = luts.radiance(direction, sun)
    # The aureole the sky pass adds round the sun.
    strength, g = aureole(luts)
    k = 1.0 + g * g - 2.0 * g * float(np.dot(direction, sun) / np.linalg.norm(direction))
    radiance = radiance + strength * (1.0 - g * g) / (4.0 * math.pi * k * math.sqrt(k))
    grey = radiance @ np.array([0.2126, 0.7152, 0.0722])
    veiled = (radiance + (grey[..., None] - radiance) * grey_share) * dim
    return display(veiled, display_exposure(luts))


def test_distant_clouds_fade_into_the_physical_sky_behind_them() -> None:
    """Sun 5 degrees up: a cloud 30 km toward the sun fades toward the sky behind it as the
    sky pass shows it (warm), one away from the sun toward the bluer sky there; the one haze
    colour (`haze_rgb`, the tower quads') is the horizon's average, not the gradient's."""
    sky = physical_sky(5.0)
    luts = sky.atmosphere
    assert luts is not None
    sun = np.asarray(sky.sun.direction_enu)
    flat = np.array([sun[0], sun[1], 0.0]) / np.linalg.norm(sun[:2])
    offsets = np.stack([flat * 30_000.0 + [0, 0, 1_500.0], -flat * 30_000.0 + [0, 0, 1_500.0]]).T
    toward, away = sky.haze_toward(offsets).T
    # The sky pass's baked table (display values per texel, filtered) is within a display
    # level or two of the exact sky beyond the sun's own part (scene.sky.SUN_EXACT_DEG).
    for got, offset in zip((toward, away), offsets.T, strict=True):
        assert np.allclose(got, _display_sky(luts, sky, offset), atol=2.0 / 255.0)
    assert red_over_blue(toward) > red_over_blue(away) + 0.1, (toward, away)
    gradient = dataclasses.replace(sky, atmosphere=None)
    assert not np.allclose(sky.haze_rgb, gradient.haze_rgb, atol=0.05)
    lo, hi = np.minimum(toward, away) - 0.05, np.maximum(toward, away) + 0.05
    assert np.all((lo <= sky.haze_rgb) & (np.asarray(sky.haze_rgb) <= hi)), sky.haze_rgb


def test_overcast_veil_and_aureole_are_the_sky_pass_own() -> None:
    for cover in (0.0, 0.5, 0.7, 0.9, 1.0):
        assert display_veil(cover) == render_veil(cover)
    for el in (60.0, 5.0):
        luts = build_luts(atmosphere_key(el, 30_000.0, 60.0, 2.0))
        strength, g = aureole(luts)
        assert physical_uniforms(luts)["u_aureole"] == pytest.approx((*strength, g))


# -- on a rendered picture -------------------------------------------------------------------


@pytest.mark.gl
def test_low_sun_away_lit_faces_warm_shaded_sides_blue_grey(renderer: Renderer) -> None:
    """Fair cumulus, sun 5 degrees up behind the eye: the clouds' brightest pixels (lit faces)
    are warm and their darkest (shaded sides, lit by the blue sky) blue-grey (B about R); on
    old main the gradient's one orange light made both orange."""
    when, az, _, _ = low_sun("fair-cumulus")
    patch = dataclasses.replace(load_preset("fair-cumulus"), time_utc=when)
    state = WeatherState().apply(patch)
    camera = Camera(
        position_m=(0.0, 0.0, 1_200.0),
        heading_deg=(az + 180.0) % 360.0,
        pitch_deg=20.0,
        fov_deg=60.0,
        width_px=320,
        height_px=180,
    )
    taken = take_snapshot(state, camera, SceneSettings(ring_texture_px=128), renderer)

    def over(level: int) -> F64:
        images = dict(taken.layers)
        images["sky"] = np.full_like(images["sky"], level)
        images["sky"][..., 3] = 255
        rgb = composite(layers_from_images(images, taken.ring_quads_m), camera)[..., :3]
        return rgb.astype(np.float64) / 255.0

    alpha = 1.0 - (over(255) - over(0)).mean(axis=2)
    rgb = taken.image[..., :3].astype(np.float64) / 255.0
    up = np.degrees(np.arcsin(camera.pixel_rays()[..., 2]))
    # Solid cloud well above the horizon haze.
    cloud = (alpha > 0.95) & (up > 8.0)
    assert np.count_nonzero(cloud) > 500, np.count_nonzero(cloud)
    luma = rgb @ np.array([0.2126, 0.7152, 0.0722])
    lit_cut, shade_cut = np.quantile(luma[cloud], [0.85, 0.15])
    lit = rgb[cloud & (luma >= lit_cut)].mean(axis=0)
    shaded = rgb[cloud & (luma <= shade_cut)].mean(axis=0)
    # Measured: lit R/B 1.34, shaded 1.12 (old main: 1.94 and 1.65, both orange).
    assert red_over_blue(lit) > 1.15, lit
    assert red_over_blue(shaded) < 1.2, (lit, shaded)
    assert red_over_blue(shaded) < 0.83 * red_over_blue(lit), (lit, shaded)
