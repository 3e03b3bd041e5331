"""Clouds lit by where the sun is (issue 41, item 3), measured on the composited picture as a
pilot sees it: fair cumulus with the sun 5 degrees up, facing it (dark cores, bright silver
rims) and facing away (lit faces brighter than the sky), and at noon (sunlit tops at least
twice as bright as the bases). Luminance is scene-linear radiance, relative
(`cloud_light_helpers.picture_luminance`: the one tone map inverted).
"""

from __future__ import annotations

import dataclasses
from datetime import datetime
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

from tests.cloud_light_helpers import (
    cloud_regions,
    noon_time,
    picture_luminance,
    time_for_sun_elevation,
)
from wxsky.app.snapshot import take_snapshot
from wxsky.errors import ConfigError
from wxsky.host.compositor import clouds_alpha
from wxsky.render.renderer import Renderer
from wxsky.scene.camera import Camera
from wxsky.scene.layout import SceneSettings
from wxsky.settings.config import load_config
from wxsky.settings.presets import load_preset
from wxsky.weather.state import WeatherState

pytestmark = pytest.mark.gl

SETTINGS = SceneSettings(ring_texture_px=128)
SIZE_PX = (480, 270)
# Facing a low sun, the eye is just under the fair cumulus's base (1930 m MSL), so that the
# clouds within 20 degrees of a sun 5 degrees up are a few kilometres off; those seen lower
# than BAND_DEG above the horizon are left out: beyond 3 km, where a 30 km visibility's haze
# (aerial perspective, another part of issue 41) hides most of what the light does.
EYE_ALT_M = 1500.0
BAND_DEG = 8.0


def shot(
    renderer: Renderer,
    preset: str,
    when: datetime,
    heading_deg: float,
    pitch_deg: float,
    alt_m: float | None = None,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], Camera]:
    """(H, W) luminance of the composited picture, (H, W) the clouds' alpha in it, and the
    camera (at alt_m MSL; None: 2 m above the preset's observer)."""
    patch = dataclasses.replace(load_preset(preset), time_utc=when)
    state = WeatherState().apply(patch)
    camera = Camera(
        position_m=(0.0, 0.0, state.observer.alt_m + 2.0 if alt_m is None else alt_m),
        heading_deg=heading_deg,
        pitch_deg=pitch_deg,
        fov_deg=60.0,
        width_px=SIZE_PX[0],
        height_px=SIZE_PX[1],
    )
    taken = take_snapshot(state, camera, SETTINGS, renderer)

    alpha = clouds_alpha(taken.layers, taken.ring_quads_m, camera)
    return picture_luminance(taken.image), alpha, camera


def low_sun(preset: str, elevation_deg: float = 5.0) -> tuple[datetime, float, float, float]:
    """The evening time on the preset's day with the sun elevation_deg up at its site: time,
    azimuth, and the site."""
    patch = load_preset(preset)
    assert patch.observer is not None and patch.time_utc is not None
    lat, lon = patch.observer.lat_deg, patch.observer.lon_deg
    when, az = time_for_sun_elevation(patch.time_utc, lat, lon, elevation_deg)
    return when, az, lat, lon


def test_backlit_cumulus_dark_core_bright_rim(renderer: Renderer) -> None:
    when, az, _, _ = low_sun("fair-cumulus")
    lum, alpha, camera = shot(renderer, "fair-cumulus", when, az, 10.0, EYE_ALT_M)
    el = np.radians(5.0)
    sun = np.array([np.sin(np.radians(az)) * np.cos(el), np.cos(np.radians(az)) * np.cos(el)])
    sun = np.append(sun, np.sin(el))
    rays = camera.pixel_rays()
    up_deg = np.degrees(np.arcsin(rays[..., 2]))
    near_sun = (rays @ sun > np.cos(np.radians(20.0))) & (up_deg > BAND_DEG + 1.0)
    # The band's clouds cut off below BAND_DEG: what is left above it are separate clouds.
    cut = np.where(up_deg > BAND_DEG, alpha, 0.0)
    regions = cloud_regions(lum, cut, within=near_sun, whole=False)
    assert regions, "no whole cloud within 20 degrees of the sun in the picture"
    cloud = regions[0]
    # A dark body: the issue asks for a core darker than the sky beside it; before issue 41
    # the orange-lit core was barely so (0.96 of the sky; now about half), so the margin.
    assert cloud["core"] < 0.7 * cloud["sky"], f"the core is not a dark body: {cloud}"
    # The rim: the fringe on the silhouette in the sun's undimmed beam through the droplets'
    # forward peak (`shading_harris.view_depth_and_limb`); before it, 0.58 of the sky. Since
    # issue 42 the clouds near this sun (below them) show it their flat bases, their thick
    # bodies cut straight and dark, no fringe: the rim's mean is 0.59 of the sky, its silver
    # lining the thin edges, its brightest tenth (measured 1.7 times the sky; 3.8 when every
    # base was a row of little flat-bottomed clouds, each with its own lit fringe).
    assert cloud["rim_bright"] > 1.5 * cloud["sky"], f"no silver lining: {cloud}"
    assert cloud["rim"] > 1.5 * cloud["core"], f"the rim is not brighter than the core: {cloud}"


def test_front_lit_cumulus_brighter_than_sky(renderer: Renderer) -> None:
    when, az, _, _ = low_sun("fair-cumulus")
    lum, alpha, _ = shot(renderer, "fair-cumulus", when, (az + 180.0) % 360.0, 10.0)
    regions = cloud_regions(lum, alpha)
    assert regions, "no whole cloud in the picture"
    for cloud in regions[:3]:
        assert cloud["bright_half"] > cloud["sky"], f"lit faces not brighter than sky: {cloud}"


def test_noon_cumulus_tops_twice_their_bases(renderer: Renderer) -> None:
    patch = load_preset("fair-cumulus")
    assert patch.observer is not None and patch.time_utc is not None
    when, _, az = noon_time(patch.time_utc, patch.observer.lat_deg, patch.observer.lon_deg)
    # Facing away from the sun (60 degrees to the side of straight away, where this seed's
    # cumulus leave a whole one in the picture), from 700 m under the clouds' base, looking up
    # at them: a cloud a few kilometres off, not in the haze that hides the clouds low down.
    lum, alpha, _ = shot(renderer, "fair-cumulus", when, (az + 240.0) % 360.0, 30.0, 1200.0)
    regions = cloud_regions(lum, alpha, min_radius_px=6)
    assert regions, "no whole cloud in the picture"
    cloud = regions[0]
    assert cloud["top_third"] >= 2.0 * cloud["bottom_tenth"], f"top not twice base: {cloud}"


def test_wang_artist_colours_are_a_setting(tmp_path: Path) -> None:
    cfg = tmp_path / "wxsky.toml"
    cfg.write_text('[scene]\nshading = "wang-artist"\n', encoding="utf-8")
    assert load_config(cfg).scene.settings().shading == "wang-artist"
    cfg.write_text('[scene]\nshading = "artist"\n', encoding="utf-8")
    with pytest.raises(ConfigError, match="shading"):
        load_config(cfg)
