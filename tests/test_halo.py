"""A cirrostratus veil and its 22° halo (issue 42 item 6): the sky pass draws the veil as a
milky film, more even than cirrus of the same cover, and a ring 22° from the sun over it, red
on its sharp inner edge, the veil inside it darker; nothing of the kind without cirrostratus.
Pictures: `wxsky snapshot`'s own path, facing the sun."""

from __future__ import annotations

import dataclasses
import math
from datetime import UTC, datetime

import numpy as np
import numpy.typing as npt
import pytest

from tools.gallery.light_sheet import sun_time
from wxsky.app.snapshot import take_snapshot
from wxsky.scene.camera import Camera
from wxsky.scene.sky import sky_params
from wxsky.settings.config import load_config
from wxsky.settings.presets import load_preset
from wxsky.weather.state import CloudLayer, CloudType, WeatherState

pytestmark = pytest.mark.gl

SIZE = (480, 300)
FOV_DEG = 100.0
SUN_DEG = 30.0


# A night over the preset's field with the moon 34° up, three quarters lit, the sun 14° down.
MOON_NIGHT = datetime(2026, 5, 25, 21, 0, tzinfo=UTC)


def _picture(
    layer: CloudLayer | None, moon: bool = False
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """(picture 0..1 RGB, each pixel's angle from the sun in degrees), looking at the sun
    (`moon`: at the moon on MOON_NIGHT, the angles from it)."""
    state = WeatherState().apply(load_preset("high-cirrus"))
    obs = state.observer
    if moon:
        state = dataclasses.replace(state, time_utc=MOON_NIGHT)
        body = sky_params(state).moon
        azimuth, elevation = body.azimuth_deg, body.elevation_deg
    else:
        sun = sun_time(state.time_utc, obs.lat_deg, obs.lon_deg, SUN_DEG)
        state = dataclasses.replace(state, time_utc=sun.time_utc)
        azimuth, elevation = sun.azimuth_deg, sun.elevation_deg
    state = dataclasses.replace(state, layers=() if layer is None else (layer,))
    camera = Camera(
        position_m=(0.0, 0.0, obs.alt_m + 2.0),
        heading_deg=azimuth,
        pitch_deg=elevation,
        fov_deg=FOV_DEG,
        width_px=SIZE[0],
        height_px=SIZE[1],
    )
    image = take_snapshot(state, camera, load_config(None).scene_settings()).image
    tan_x = math.tan(math.radians(FOV_DEG) / 2.0)
    tan_y = tan_x * SIZE[1] / SIZE[0]
    x = ((np.arange(SIZE[0]) + 0.5) / SIZE[0] * 2.0 - 1.0)[None, :] * tan_x
    y = ((np.arange(SIZE[1]) + 0.5) / SIZE[1] * 2.0 - 1.0)[:, None] * tan_y
    angle = np.degrees(np.arctan(np.hypot(x, y)))
    return image[..., :3].astype(np.float64) / 255.0, angle


def _ring(
    rgb: npt.NDArray[np.float64], angle: npt.NDArray[np.float64], lo: float, hi: float
) -> npt.NDArray[np.float64]:
    """Mean colour of the annulus lo..hi degrees from the sun, above the picture's middle row
    (the sky, not the ground)."""
    upper = np.zeros(angle.shape, bool)
    upper[: SIZE[1] // 2] = True
    inside = (angle >= lo) & (angle < hi) & upper
    out: npt.NDArray[np.float64] = rgb[inside].mean(axis=0)
    return out


def test_a_cirrostratus_veil_shows_the_22_degree_halo() -> None:
    veil = CloudLayer(8, 9900.0, 10600.0, CloudType.CIRROSTRATUS)
    rgb, angle = _picture(veil)
    ring = _ring(rgb, angle, 21.6, 23.0)
    inside = _ring(rgb, angle, 18.0, 20.0)
    outside = _ring(rgb, angle, 27.0, 29.0)
    ring_l, inside_l = (
        float(ring @ [0.2126, 0.7152, 0.0722]),
        float(inside @ [0.2126, 0.7152, 0.0722]),
    )
    outside_l = float(outside @ [0.2126, 0.7152, 0.0722])
    assert ring_l > inside_l + 0.02 and ring_l > outside_l + 0.01, (inside_l, ring_l, outside_l)
    # Red bends least: the ring's inner edge is redder than its outer side.
    inner_edge = _ring(rgb, angle, 21.2, 21.9)
    outer_side = _ring(rgb, angle, 23.0, 24.5)
    assert inner_edge[0] / inner_edge[2] > outer_side[0] / outer_side[2] + 0.01


def test_no_halo_without_cirrostratus() -> None:
    streaks = CloudLayer(8, 8500.0, 9600.0, CloudType.CIRRUS)
    rgb, angle = _picture(streaks)
    ring = _ring(rgb, angle, 21.6, 23.0) @ [0.2126, 0.7152, 0.0722]
    between = 0.5 * (
        _ring(rgb, angle, 18.0, 20.0) @ [0.2126, 0.7152, 0.0722]
        + _ring(rgb, angle, 27.0, 29.0) @ [0.2126, 0.7152, 0.0722]
    )
    assert abs(float(ring) - float(between)) < 0.015, (ring, between)


def _local_detail(layer: CloudLayer) -> float:
    """Spread of the luma less its 21x21 box mean, over the sky more than 30° from the sun."""
    rgb, angle = _picture(layer)
    luma = rgb @ np.array([0.2126, 0.7152, 0.0722])
    k = np.ones(21) / 21.0
    mean = np.apply_along_axis(lambda v: np.convolve(v, k, "same"), 0, luma)
    mean = np.apply_along_axis(lambda v: np.convolve(v, k, "same"), 1, mean)
    sky = (angle > 30.0) & (np.arange(SIZE[1])[:, None] < SIZE[1] // 2)
    sky[:12] = False
    sky[:, :12] = False
    sky[:, -12:] = False
    return float((luma - mean)[sky].std())


def test_a_cirrostratus_veil_is_more_even_than_cirrus() -> None:
    veil = _local_detail(CloudLayer(8, 9900.0, 10600.0, CloudType.CIRROSTRATUS))
    streaks = _local_detail(CloudLayer(8, 8500.0, 9600.0, CloudType.CIRRUS))
    # Before the veil was a film of its own, it was patchier than cirrus (0.022 against 0.015).
    assert veil < 0.9 * streaks, (veil, streaks)


def test_the_moon_has_its_halo_over_the_veil_at_night() -> None:
    """The same ring 22° from the moon (three quarters lit, 34° up, the sun 14° down): over
    cirrostratus it stands out of the dark veil; over cirrus there is none."""
    lum = np.array([0.2126, 0.7152, 0.0722])
    rgb, angle = _picture(CloudLayer(8, 9900.0, 10600.0, CloudType.CIRROSTRATUS), moon=True)
    ring = float(_ring(rgb, angle, 21.6, 23.0) @ lum)
    inside = float(_ring(rgb, angle, 18.0, 20.0) @ lum)
    outside = float(_ring(rgb, angle, 27.0, 29.0) @ lum)
    assert ring > inside + 0.01 and ring > outside + 0.01, (inside, ring, outside)
    rgb, angle = _picture(CloudLayer(8, 8500.0, 9600.0, CloudType.CIRRUS), moon=True)
    ring = float(_ring(rgb, angle, 21.6, 23.0) @ lum)
    between = 0.5 * float((_ring(rgb, angle, 18.0, 20.0) + _ring(rgb, angle, 27.0, 29.0)) @ lum)
    assert abs(ring - between) < 0.005, (ring, between)


def test_the_halo_is_drawn_only_where_it_can_show() -> None:
    """The halo is its own part of the sky pass (`sky_textures.halo_rect_ndc`), drawn over
    the pixels within 32° of the sun: a view of the veil facing the sun holds its rectangle,
    with the sun inside it; a view facing away holds none (the dome then runs without the
    halo's code), and without a veil there is none anywhere."""
    from wxsky.render import sky_textures

    state = WeatherState().apply(load_preset("high-cirrus"))
    sky = sky_params(state)
    assert sky.dome.veil > 0.0
    sun = sky.sun
    # Facing the sun the ring's 32° holds the whole picture; with the sun some 38° to the
    # right of the view's middle, the right part of it only.
    toward = Camera((0.0, 0.0, 500.0), sun.azimuth_deg, sun.elevation_deg - 10.0)
    assert sky_textures.halo_rect_ndc(toward, sky) == sky_textures.FULL_RECT
    aside = Camera((0.0, 0.0, 500.0), sun.azimuth_deg - 70.0, sun.elevation_deg)
    rect = sky_textures.halo_rect_ndc(aside, sky)
    assert rect is not None and rect[2] == 1.0 and -1.0 < rect[0] < 0.5
    assert sky_textures.features(aside, sky).halo
    away = Camera((0.0, 0.0, 500.0), sun.azimuth_deg + 180.0, 0.0)
    assert sky_textures.halo_rect_ndc(away, sky) is None
    assert not sky_textures.features(away, sky).halo
    cirrus_only = dataclasses.replace(
        state, layers=tuple(lay for lay in state.layers if lay.type is CloudType.CIRRUS)
    )
    assert sky_textures.halo_rect_ndc(toward, sky_params(cirrus_only)) is None
