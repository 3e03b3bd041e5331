"""The night sky, the moon and the cloud dome, drawn with real GL through the snapshot path.

Stars are found as local maxima that stand out from the median of their 5 x 5 neighbourhood
(a star lights about 3 x 3 pixels), so a smooth gradient has none.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta

import numpy as np
import numpy.typing as npt
import pytest

from wxsky.app.snapshot import take_snapshot
from wxsky.render import sky_layer, sky_texture_gen, sky_textures
from wxsky.render.renderer import Renderer
from wxsky.scene import ephemeris
from wxsky.scene.atmosphere import atmosphere_key, build_luts
from wxsky.scene.camera import Camera
from wxsky.scene.clouds import SpriteBatch
from wxsky.scene.layout import FrameScene, SceneSettings, SpriteDraw
from wxsky.scene.sky import DOME_MAX_WIND_MPS, DOME_TOP_M, SkyParams, sky_params
from wxsky.settings.presets import load_preset
from wxsky.weather.state import WeatherState

W, H = 640, 360
ZURICH = (47.4647, 8.5492)
# New moon week: at 19:50 UTC the sun is 20° down and the moon below the horizon.
NIGHT = datetime(2026, 9, 10, 19, 50, 0, tzinfo=UTC)
NOON = datetime(2026, 9, 10, 11, 30, 0, tzinfo=UTC)
# Waxing gibbous moon in the south-south-west, sun 35° down.
MOON_NIGHT = datetime(2026, 9, 21, 21, 0, 0, tzinfo=UTC)
STAR_CONTRAST = 12  # levels above the local median that make a star
SETTINGS = SceneSettings(max_range_m=16_000.0)

U8 = npt.NDArray[np.uint8]
NO_SPRITES = SpriteDraw(SpriteBatch.empty(), np.zeros((0, 4), np.float32))


def _state(preset: str, when: datetime) -> WeatherState:
    return dataclasses.replace(WeatherState().apply(load_preset(preset)), time_utc=when)


def _camera(
    state: WeatherState, heading_deg: float, pitch_deg: float, fov_deg: float = 60.0
) -> Camera:
    return Camera(
        position_m=(0.0, 0.0, state.observer.alt_m + 2.0),
        heading_deg=heading_deg,
        pitch_deg=pitch_deg,
        fov_deg=fov_deg,
        width_px=W,
        height_px=H,
    )


def _shot(renderer: Renderer, state: WeatherState, cam: Camera) -> U8:
    return take_snapshot(state, cam, SETTINGS, renderer).image


def _luma(img: U8) -> npt.NDArray[np.int32]:
    return img[..., :3].max(axis=2).astype(np.int32)


def local_contrast(img: U8) -> npt.NDArray[np.float64]:
    """How far each pixel stands above the median of its 5 x 5 neighbourhood."""
    lum = _luma(img)
    h, w = lum.shape
    windows = np.lib.stride_tricks.sliding_window_view(np.pad(lum, 2, mode="edge"), (5, 5))
    out: npt.NDArray[np.float64] = lum - np.median(windows.reshape(h, w, 25), axis=2)
    return out


def star_peaks(img: U8, contrast: int = STAR_CONTRAST) -> npt.NDArray[np.bool_]:
    """(H, W) True on each star's brightest pixel. Ties go to the first pixel in raster
    order, so a star centred between two pixels counts once."""
    lum = _luma(img)
    h, w = lum.shape
    padded = np.pad(lum, 1, constant_values=-1)
    peak = np.ones((h, w), bool)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dy == dx == 0:
                continue
            other = padded[1 + dy : h + 1 + dy, 1 + dx : w + 1 + dx]
            earlier = dy < 0 or (dy == 0 and dx < 0)
            peak &= lum > other if earlier else lum >= other
    return peak & (local_contrast(img) >= contrast)


def _project(cam: Camera, direction: tuple[float, float, float]) -> tuple[float, float]:
    """(column, row) in pixel units (centres at +0.5) of a direction from the eye."""
    eye = np.asarray(cam.position_m)
    clip = cam.view_projection() @ np.append(eye + 1.0e4 * np.asarray(direction), 1.0)
    ndc = clip[:3] / clip[3]
    return ((ndc[0] + 1.0) / 2.0 * cam.width_px, (ndc[1] + 1.0) / 2.0 * cam.height_px)


# -- stars ----------------------------------------------------------------------------------


def test_clear_night_shows_hundreds_of_stars(renderer: Renderer) -> None:
    state = _state("clear", NIGHT)
    sky = sky_params(state)
    assert sky.sun.elevation_deg == pytest.approx(-20.0, abs=0.5)
    assert sky.moon.elevation_deg < 0.0 and sky.stars == 1.0
    img = _shot(renderer, state, _camera(state, heading_deg=180.0, pitch_deg=60.0))
    peaks = star_peaks(img)
    assert peaks.sum() >= 200, peaks.sum()  # measured 709 on llvmpipe
    # Points, not blobs: nearly every star pixel is part of a small spot.
    bright = _luma(img) >= int(np.median(_luma(img))) + STAR_CONTRAST
    assert bright.sum() < 12 * peaks.sum()
    # Spread over the whole picture, not a pattern in one corner.
    rows, cols = np.nonzero(peaks)
    for half in (rows < H // 2, rows >= H // 2, cols < W // 2, cols >= W // 2):
        assert half.sum() > 0.2 * len(rows)


def _isolated(peaks: npt.NDArray[np.bool_], radius: int = 3) -> npt.NDArray[np.bool_]:
    """Peaks with no other peak within `radius` pixels (pairs of stars can swap their
    brightest pixel as they flicker)."""
    count = np.zeros(peaks.shape, int)
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            count += np.roll(np.roll(peaks, dy, 0), dx, 1)
    return peaks & (count == 1)


def _centroids(img: U8, peaks: npt.NDArray[np.bool_]) -> npt.NDArray[np.float64]:
    """(N, 2) light-weighted (row, column) centre of each star over its 3 x 3 pixels, above
    the local median."""
    lum = _luma(img).astype(float)
    rows, cols = np.nonzero(peaks)
    out = np.empty((len(rows), 2))
    for k, (r, c) in enumerate(zip(rows, cols, strict=True)):
        patch = lum[r - 1 : r + 2, c - 1 : c + 2]
        patch = np.clip(patch - np.median(lum[r - 3 : r + 4, c - 3 : c + 4]), 0.0, None)
        dy, dx = np.mgrid[-1:2, -1:2]
        out[k] = (r + (dy * patch).sum() / patch.sum(), c + (dx * patch).sum() / patch.sum())
    return out


def test_stars_flicker_in_place(renderer: Renderer) -> None:
    """Half a second later every star is where it was, and many have changed brightness."""
    state = _state("clear", NIGHT)
    cam = _camera(state, heading_deg=180.0, pitch_deg=60.0)
    first = _shot(renderer, state, cam)
    later_state = dataclasses.replace(state, time_utc=NIGHT + timedelta(milliseconds=500))
    second = _shot(renderer, later_state, cam)
    peaks_a = star_peaks(first)
    # The second picture's threshold is lower, so that flicker cannot drop a star from it.
    peaks_b = star_peaks(second, contrast=STAR_CONTRAST // 2)
    lum_a, lum_b = _luma(first), _luma(second)
    stars = _isolated(peaks_a) & (local_contrast(first) >= 2 * STAR_CONTRAST)
    stars[:4], stars[-4:], stars[:, :4], stars[:, -4:] = False, False, False, False
    assert stars.sum() >= 200
    # Same peak pixels. A star centred on a pixel edge lights two pixels almost alike, and
    # 8-bit rounding or a fainter star next to it, flickering on its own, picks which one is
    # the peak: allowed only where the two differ by 2 levels or 5 %.
    same = stars & peaks_b
    assert same.sum() >= 0.97 * stars.sum()  # measured 258 of 261
    for r, c in zip(*np.nonzero(stars & ~peaks_b), strict=True):
        nb = peaks_b[r - 1 : r + 2, c - 1 : c + 2]
        assert nb.sum() == 1, (r, c)
        dr, dc = (int(v[0]) - 1 for v in np.nonzero(nb))
        assert lum_a[r, c] - lum_a[r + dr, c + dc] <= max(2, 0.05 * lum_a[r, c]), (r, c)
    # And the same light-weighted centres, to a tenth of a pixel.
    np.testing.assert_allclose(_centroids(second, stars), _centroids(first, stars), atol=0.1)
    changed = np.abs(lum_a[stars] - lum_b[stars]) >= 3
    assert changed.mean() >= 0.2, changed.mean()  # measured 0.83
    # Only stars change, faint ones included: away from them the sky is the same.
    any_star = star_peaks(first, contrast=3) | star_peaks(second, contrast=3)
    star_area = np.zeros_like(any_star)
    for dy in (-2, -1, 0, 1, 2):
        for dx in (-2, -1, 0, 1, 2):
            star_area |= np.roll(np.roll(any_star, dy, 0), dx, 1)
    diff = np.abs(first.astype(int) - second.astype(int)).max(axis=2)[~star_area]
    assert (diff > 1).mean() < 0.001 and diff.max() <= 4  # the faintest stars hide in noise


def test_no_stars_by_day(renderer: Renderer) -> None:
    state = _state("clear", NOON)
    sky = sky_params(state)
    assert sky.sun.elevation_deg > 30.0 and sky.stars == 0.0
    img = _shot(renderer, state, _camera(state, heading_deg=0.0, pitch_deg=60.0))
    assert star_peaks(img, contrast=3).sum() == 0


def test_twilight_shows_fewer_stars_than_night(renderer: Renderer) -> None:
    night = _state("clear", NIGHT)
    dusk = _state("clear", NIGHT - timedelta(minutes=55))  # sun ~12° down
    assert 0.0 < sky_params(dusk).stars < 0.8
    cam = _camera(night, heading_deg=180.0, pitch_deg=60.0)
    n_night = star_peaks(_shot(renderer, night, cam)).sum()
    n_dusk = star_peaks(_shot(renderer, dusk, cam)).sum()
    assert 0 < n_dusk < 0.7 * n_night


def test_cloud_cover_dims_the_stars(renderer: Renderer) -> None:
    clear = _state("clear", NIGHT)
    cloudy = _state("broken-stratocumulus", NIGHT)
    assert 0.0 < sky_params(cloudy).stars < 0.7
    cam = _camera(clear, heading_deg=180.0, pitch_deg=60.0)
    # The sky layer alone: the sprites hide stars as well, but the sky must dim them itself.
    renderer_sky = take_snapshot(cloudy, cam, SETTINGS, renderer).layers["sky"]
    n_cloudy = star_peaks(renderer_sky).sum()
    n_clear = star_peaks(_shot(renderer, clear, cam)).sum()
    assert n_cloudy < 0.8 * n_clear


# -- moon -----------------------------------------------------------------------------------


def _moon_view(
    renderer: Renderer, when: datetime, fov_deg: float = 8.0
) -> tuple[U8, Camera, ephemeris.MoonPosition, tuple[float, float, float]]:
    state = _state("clear", when)
    sky = sky_params(state)
    moon = sky.moon
    # The moon off-centre, so that a wrong projection cannot pass by luck.
    cam = _camera(state, moon.azimuth_deg - 1.5, moon.elevation_deg + 1.0, fov_deg)
    return _shot(renderer, state, cam), cam, moon, sky.sun.direction_enu


def test_moon_disc_is_where_the_ephemeris_puts_it(renderer: Renderer) -> None:
    img, cam, moon, _sun = _moon_view(renderer, MOON_NIGHT)
    assert moon.elevation_deg > 10.0 and 0.6 < moon.illuminated_fraction < 0.95
    col, row = _project(cam, moon.direction_enu)
    radius_px = math.tan(math.radians(moon.angular_radius_deg)) / cam.tan_half_fov_x * W / 2
    lum = _luma(img)
    sky_level = float(np.median(lum))
    # Everything bright within two moon radii of where the ephemeris puts the moon.
    ring = np.hypot(*np.meshgrid(np.arange(W) + 0.5 - col, np.arange(H) + 0.5 - row))
    lit = (lum > sky_level + 60) & (ring < 2.0 * radius_px)
    rows, cols = np.nonzero(lit)
    assert len(rows) > 0.5 * math.pi * radius_px**2 * moon.illuminated_fraction
    assert len(rows) < 1.15 * math.pi * (radius_px + 1) ** 2 * moon.illuminated_fraction
    dist = np.hypot(cols + 0.5 - col, rows + 0.5 - row)
    assert dist.max() <= radius_px + 1.5
    assert lum.max() > 200  # bright at night
    # Outside the disc it is night sky (stars allowed).
    assert np.median(lum[(ring > 2 * radius_px) & (ring < 4 * radius_px)]) < sky_level + 5


def test_moon_lit_side_faces_the_sun(renderer: Renderer) -> None:
    for when in (MOON_NIGHT, datetime(2026, 9, 17, 19, 0, tzinfo=UTC)):  # gibbous, crescent
        img, cam, moon, sun = _moon_view(renderer, when)
        col, row = _project(cam, moon.direction_enu)
        lum = _luma(img).astype(float)
        ring = np.hypot(*np.meshgrid(np.arange(W) + 0.5 - col, np.arange(H) + 0.5 - row))
        radius_px = math.tan(math.radians(moon.angular_radius_deg)) / cam.tan_half_fov_x * W / 2
        lit = (lum > np.median(lum) + 60) & (ring < 1.5 * radius_px)
        rows, cols = np.nonzero(lit)
        weights = lum[lit]
        offset = (
            np.array([(cols + 0.5 - col) @ weights, (rows + 0.5 - row) @ weights]) / weights.sum()
        )
        # Towards the sun along the great circle through moon and sun, as the screen shows it.
        m, s = np.asarray(moon.direction_enu), np.asarray(sun)
        step = s - m * (m @ s)
        towards = np.asarray(_project(cam, tuple(m + 1e-3 * step / np.linalg.norm(step))))
        towards -= (col, row)
        cos = offset @ towards / (np.linalg.norm(offset) * np.linalg.norm(towards))
        assert cos > math.cos(math.radians(15.0)), (when, offset, towards)


def test_moon_is_faint_by_day(renderer: Renderer) -> None:
    day = datetime(2026, 6, 21, 14, 0, tzinfo=UTC)
    img, cam, moon, _sun = _moon_view(renderer, day)
    assert moon.elevation_deg > 10.0
    col, row = _project(cam, moon.direction_enu)
    # In red, where the blue sky is darkest: the moon lifts it visibly but well short of the
    # night moon's contrast.
    red = img[..., 0].astype(int)
    near = red[int(row) - 4 : int(row) + 5, int(col) - 4 : int(col) + 5]
    contrast = near.max() - np.median(red)
    night_img, _, _, _ = _moon_view(renderer, MOON_NIGHT)
    night_red = night_img[..., 0].astype(int)
    assert 20 < contrast < 0.5 * (night_red.max() - np.median(night_red))


# -- cloud dome -----------------------------------------------------------------------------


def test_cloud_dome_shows_high_cirrus_and_not_a_clear_sky(renderer: Renderer) -> None:
    when = datetime(2026, 5, 20, 10, 0, tzinfo=UTC)
    cirrus = _state("high-cirrus", when)
    clear = _state("clear", when)
    cam = _camera(cirrus, heading_deg=200.0, pitch_deg=40.0)
    sky_cirrus = take_snapshot(cirrus, cam, SETTINGS, renderer).layers["sky"].astype(int)
    sky_clear = take_snapshot(clear, cam, SETTINGS, renderer).layers["sky"].astype(int)
    whiter = (sky_cirrus[..., 0] - sky_clear[..., 0]) > 12  # cloud is whiter than blue sky
    # About the cover's share of the picture, not all of it: a thin, broken veil.
    cover = sky_params(cirrus).dome.high_cover
    assert 0.3 * cover < whiter.mean() < 1.5 * cover
    # The clear sky is the plain gradient: no cloud texture anywhere.
    assert np.abs(np.diff(sky_clear, axis=1)).max() <= 2


def test_cloud_dome_drifts_with_the_wind_aloft(renderer: Renderer) -> None:
    when = datetime(2026, 5, 20, 10, 0, tzinfo=UTC)
    state = _state("high-cirrus", when)
    # Facing south-south-west, east is to the left; the jet blows from 250°, towards ENE.
    cam = _camera(state, heading_deg=200.0, pitch_deg=60.0)
    # The gradient's sky, the same behind both presets (the physical sky follows each
    # preset's visibility and humidity, and would not subtract out).
    settings = dataclasses.replace(SETTINGS, sky="roden-parberry")
    clear = take_snapshot(_state("clear", when), cam, settings, renderer).layers["sky"]
    background = clear[..., 0].astype(float)  # the gradient, which does not move
    a = take_snapshot(state, cam, settings, renderer).layers["sky"][..., 0] - background
    later = dataclasses.replace(state, time_utc=when + timedelta(seconds=5))
    b = take_snapshot(later, cam, settings, renderer).layers["sky"][..., 0] - background
    assert np.abs(a - b).mean() > 0.5
    # The pattern has moved, not been replaced: some shift of the old picture's centre
    # matches the new one far better than none.
    r0, c0, half = H // 2 - 40, W // 2 - 40, 80
    old_centre = a[r0 : r0 + half, c0 : c0 + half]

    def mismatch(sy: int, sx: int) -> float:
        moved = b[r0 + sy : r0 + sy + half, c0 + sx : c0 + sx + half]
        return float(np.abs(moved - old_centre).mean())

    _, dy, dx = min((mismatch(sy, sx), sy, sx) for sy in range(-15, 16) for sx in range(-25, 26))
    assert mismatch(dy, dx) < 0.6 * mismatch(0, 0), (dy, dx)
    # Where the air over the centre of the picture has gone in those 5 s, on the dome plane.
    dome = sky_params(state).dome
    height_m = dome.height * DOME_TOP_M - cam.position_m[2]
    fwd = cam.basis()[2]
    here = fwd * height_m / fwd[2]
    toward = math.radians(dome.drift_toward_deg)
    wind = dome.speed * DOME_MAX_WIND_MPS * np.array([math.sin(toward), math.cos(toward), 0.0])
    col0, row0 = _project(cam, tuple(here))
    col1, row1 = _project(cam, tuple(here + 5.0 * wind))
    assert col1 - col0 < -5.0  # leftwards, towards the east
    assert abs(dx - (col1 - col0)) <= 3.0 and abs(dy - (row1 - row0)) <= 3.0


# -- the textures ---------------------------------------------------------------------------


def test_star_texture_channels_follow_roden_and_parberry() -> None:
    tex = sky_textures.star_texture()
    n = sky_texture_gen.STAR_FACE_PX
    assert tex.shape == (6 * n, n, 4) and tex.dtype == np.uint8
    stars = tex[tex[..., 0] > 0]
    # Mostly empty: a few percent of the cells hold a star.
    assert 0.04 < len(stars) / (6 * n * n) < 0.12
    mean, rate, variance, phase = (stars[:, k].astype(int) for k in range(4))
    assert np.all(variance <= mean)  # brightness R + B·sin never goes below zero
    assert rate.min() > 0 and np.ptp(rate) > 150  # every star flickers, at many rates
    assert np.ptp(phase) > 240  # in no common rhythm
    # Many faint stars and few bright ones.
    assert (mean > 128).sum() < 0.05 * len(mean) < (mean < 32).sum()
    # Deterministic: the same texture in every process.
    assert sky_textures.star_texture.__wrapped__().tobytes() == tex.tobytes()  # type: ignore[attr-defined]


def test_flicker_clock_wraps_without_changing_any_star() -> None:
    # G = k/255 flickers at k/100 Hz: after the 100 s period every phase is whole again.
    k = np.arange(256)
    rate_hz = k / 255.0 * sky_textures.STAR_RATE_SCALE_HZ
    cycles = rate_hz * sky_textures.STAR_CLOCK_PERIOD_S
    np.testing.assert_allclose(cycles, np.round(cycles), atol=1e-9)
    assert sky_textures.flicker_clock_s(1234.25) == pytest.approx(34.25)


def test_cube_cells_cover_the_sphere_evenly() -> None:
    dirs = sky_texture_gen.cube_cell_directions(64)
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=-1), 1.0, atol=1e-12)
    # Neighbouring cell centres are 90°/64 apart within 30 % everywhere (equi-angular; a
    # plain cube map is 1.7 times denser at the face corners than at their centres).
    step = np.degrees(np.arccos(np.clip((dirs[:, :, 1:] * dirs[:, :, :-1]).sum(-1), -1, 1)))
    assert step.min() > 0.7 * 90 / 64 and step.max() < 1.3 * 90 / 64


def test_each_frame_compiles_in_only_the_features_it_shows() -> None:
    """A CPU renderer pays for shader code it branches around, so the sky pass picks a
    variant: stars at night, the moon only when it is in view, the dome only with cover."""
    night = _state("clear", MOON_NIGHT)
    sky = sky_params(night)
    towards = _camera(night, sky.moon.azimuth_deg + 20.0, sky.moon.elevation_deg)
    away = _camera(night, sky.moon.azimuth_deg + 180.0, 30.0)
    assert sky_textures.features(towards, sky) == sky_textures.SkyFeatures(True, True, False)
    assert sky_textures.features(away, sky) == sky_textures.SkyFeatures(True, False, False)
    noon = sky_params(_state("clear", NOON))
    assert sky_textures.features(away, noon) == sky_textures.SkyFeatures(False, False, False)
    cirrus = _state("high-cirrus", NOON)
    assert sky_textures.features(away, sky_params(cirrus)).dome
    # Above the cirrus deck the dome is not drawn: the sprites are the clouds there.
    high = dataclasses.replace(away, position_m=(0.0, 0.0, 11_000.0))
    assert not sky_textures.features(high, sky_params(cirrus)).dome
    # Uniforms only for what is drawn (GL would have optimised the others away): with no
    # feature, the ground band's, which every variant draws.
    names = set(
        sky_textures.frame_uniforms(away, noon, sky_textures.SkyFeatures(False, False, False))
    )
    assert names == set(sky_textures.ground_uniforms(away, noon))
    assert names == {"u_pixel_rad", "u_ground_air", "u_horizon_air", "u_ground_tint"}


# -- split passes ---------------------------------------------------------------------------


@pytest.fixture
def one_pass_renderer(renderer: Renderer) -> Iterator[Renderer]:
    # In the session's context: GL calls go to the context current on the thread.
    with Renderer(ring_texture_px=renderer.ring_px, ctx=renderer.ctx, split_sky=False) as r:
        yield r


@pytest.mark.parametrize(
    ("preset", "when", "where"),
    [
        ("clear", MOON_NIGHT, "moon-at-edge"),  # stars, and the moon cut by the picture's side
        ("clear", datetime(2026, 6, 21, 14, 0, tzinfo=UTC), "moon-centre"),  # a day moon
        ("fair-cumulus", datetime(2026, 6, 21, 13, 0, tzinfo=UTC), "rolled"),  # distant band
        ("high-cirrus", datetime(2026, 5, 20, 10, 0, tzinfo=UTC), "moon-centre"),  # high cover
        ("high-cirrus", datetime(2026, 5, 20, 10, 0, tzinfo=UTC), "down"),
        # The sun's part (the physical sky per pixel round the sun, the baked table beyond).
        ("clear", datetime(2026, 6, 21, 9, 0, tzinfo=UTC), "sun-centre"),
        ("fair-cumulus", datetime(2026, 6, 21, 19, 30, tzinfo=UTC), "sun-centre"),  # low sun
    ],
)
def test_sky_drawn_in_parts_equals_one_pass(
    renderer: Renderer,
    one_pass_renderer: Renderer,
    preset: str,
    when: datetime,
    where: str,
) -> None:
    """The sky without moon and dome over the picture, then each over its own rectangle, is
    the picture that one pass with every feature makes: the rectangles miss no pixel."""
    state = _state(preset, when)
    sky = sky_params(state)
    moon = sky.moon
    if where == "moon-at-edge":  # the disc across the right edge of a 20° view
        turn_deg = math.degrees(
            math.atan(math.tan(math.radians(10.0)) / math.cos(math.radians(moon.elevation_deg)))
        )
        cam = _camera(state, moon.azimuth_deg - turn_deg, moon.elevation_deg, fov_deg=20.0)
    elif where == "moon-centre":
        cam = _camera(state, moon.azimuth_deg, moon.elevation_deg, fov_deg=30.0)
    elif where == "sun-centre":
        cam = _camera(state, sky.sun.azimuth_deg + 3.0, max(sky.sun.elevation_deg, 2.0))
    elif where == "rolled":
        cam = dataclasses.replace(_camera(state, 120.0, 2.0), roll_deg=25.0)
    else:
        cam = _camera(state, 200.0, -60.0)
    feats = sky_textures.features(cam, sky)
    assert feats.moon or not where.startswith("moon")
    assert feats.dome == (preset != "clear")
    if where.startswith("sun"):  # the snapshot's sky is the physical one: its sun part
        luts = build_luts(atmosphere_key(sky.sun.elevation_deg, state.visibility_m, 60.0, 2.0))
        physical = dataclasses.replace(sky, atmosphere=luts)
        assert sky_textures.features(cam, physical).sun
        assert sky_textures.sun_rect_ndc(cam, physical) not in (None, sky_textures.FULL_RECT)
    split = take_snapshot(state, cam, SETTINGS, renderer).layers["sky"].astype(int)
    whole = take_snapshot(state, cam, SETTINGS, one_pass_renderer).layers["sky"].astype(int)
    assert np.abs(split - whole).max() == 0
    if where == "moon-at-edge":
        rect = sky_textures.moon_rect_ndc(cam, sky)
        assert rect is not None and rect[2] == 1.0 and rect[0] > 0.5  # only the edge


def _sky_draws(renderer: Renderer, cam: Camera, sky: SkyParams) -> tuple[dict[str, int], int]:
    """Draw the sky layer for cam and sky: the calls of each sky pass it took, and the
    pixels they wrote."""
    profiler = renderer.start_profile()
    try:
        renderer.render_frame(FrameScene(cam, sky, NO_SPRITES))
    finally:
        renderer.stop_profile()
    sky_passes = {n: p for n, p in profiler.passes.items() if n.startswith("sky")}
    return {n: len(p.seconds) for n, p in sky_passes.items()}, sum(
        sum(p.samples) for p in sky_passes.values()
    )


def _sky_passes(renderer: Renderer, cam: Camera, sky: SkyParams) -> dict[str, int]:
    return _sky_draws(renderer, cam, sky)[0]


def _fresh_sky(renderer: Renderer, cam: Camera, sky: SkyParams) -> npt.NDArray[np.int64]:
    renderer._sky_drawn.clear()  # forget what the layer holds: everything is drawn
    renderer.render_frame(FrameScene(cam, sky, NO_SPRITES))
    return renderer.read("sky").astype(np.int64)


def test_a_steady_view_refreshes_its_sky_a_strip_at_a_time_and_stays_the_fresh_sky(
    renderer: Renderer, one_pass_renderer: Renderer
) -> None:
    """While the sun, moon and dome drift, a steady view draws its sky layer again a few
    strips at a time (every part clipped to them), never the whole picture, and the kept
    layer stays within a level of the sky drawn afresh in one pass; a turn draws everything
    at once. High cirrus overhead drifts a few pixels a second: a few strips a frame."""
    state = _state("high-cirrus", datetime(2026, 5, 20, 10, 0, tzinfo=UTC))
    sky0 = sky_params(state)
    moon = sky0.moon
    cam = _camera(state, moon.azimuth_deg, moon.elevation_deg)
    feats = sky_textures.features(cam, sky0)
    assert feats.dome and feats.moon
    renderer._sky_drawn.clear()
    passes, whole = _sky_draws(renderer, cam, sky0)
    # The sun is 35 degrees from the moon: its halo's part (over the veil) is drawn too.
    assert feats.halo
    assert set(passes) == {"sky", "sky dome", "sky halo", "sky moon"}
    assert _sky_passes(renderer, cam, sky0) == {}  # nothing moved: nothing drawn
    first = renderer.read("sky").astype(np.int64)
    drawn: list[int] = []
    skies = []
    for k in range(1, 91):  # 3 s at 30 fps
        moment = state.time_utc + timedelta(seconds=k / 30.0)
        sky = sky_params(dataclasses.replace(state, time_utc=moment))
        skies.append(sky)
        assert sky_textures.moon_rect_ndc(cam, sky) == sky_textures.moon_rect_ndc(cam, sky0)
        passes, samples = _sky_draws(renderer, cam, sky)
        assert samples < 0.75 * whole, (k, passes)  # never the whole picture
        drawn.append(samples)
    assert 0.05 * whole < np.mean(drawn) < 0.5 * whole
    kept = renderer.read("sky").astype(np.int64)
    assert np.abs(kept - first).max() > 2  # the dome moved, and the layer with it
    # Each pixel is, to the bit, the sky of one of the last few frames (the strip it lies in
    # was last drawn then, or the moon's disc over it later): a strip is redrawn once its
    # numbers drift SKY_CATCH_UP - 1 tolerances at most, which the sun's 0.1 of a tolerance a
    # frame takes 20 frames to do.
    recent = [_fresh_sky(one_pass_renderer, cam, s) for s in skies[-24:]]
    bands = renderer.layer_bands("sky")
    assert bands is not None and len(bands) >= sky_layer.SKY_STRIPS
    seen = np.zeros(kept.shape[:2], np.bool_)
    for fresh in recent:
        seen |= np.all(kept == fresh, axis=-1)
    assert seen.all(), f"{np.count_nonzero(~seen)} pixels of no recent frame"
    # And the layer is within a fraction of a level of the latest sky on average.
    assert np.abs(kept - recent[-1]).mean() < 0.05
    # A turn is drawn whole at once: every pixel, the plain sky only where the dome's band
    # leaves it showing (here none: the band is the picture).
    turned = dataclasses.replace(cam, heading_deg=cam.heading_deg + 0.05)
    passes, samples = _sky_draws(renderer, turned, sky)
    assert {"sky dome", "sky moon"} <= set(passes) and samples >= W * H


def test_dome_rectangle_is_the_band_above_the_horizon() -> None:
    """Without high cover the dome shows only in a band a few degrees above the horizon: a
    level camera redraws that strip, not the picture."""
    state = _state("fair-cumulus", datetime(2026, 6, 21, 13, 0, tzinfo=UTC))
    sky = sky_params(state)
    cam = dataclasses.replace(_camera(state, 90.0, 0.0), position_m=(0.0, 0.0, 1500.0))
    rect = sky_textures.dome_rect_ndc(cam, sky)
    assert rect is not None
    x0, y0, x1, y1 = rect
    assert (x0, x1) == (-1.0, 1.0)
    # NDC y runs down the picture: the horizon is the middle row, the band just above it,
    # reaching highest at the picture's sides (where z = h at y = -h·√(1 + tx²) / (ty·√(1 - h²))).
    h = sky_textures.dome_band(sky)[1]
    band_top = (
        -h * math.hypot(1.0, cam.tan_half_fov_x) / (cam.tan_half_fov_y * math.sqrt(1 - h * h))
    )
    margin = 2.0 * 2.0 / (cam.height_px / 10.0)  # two grid cells
    assert band_top - margin <= y0 <= band_top
    assert 0.0 <= y1 <= margin
    # Looking down from above the band's reach shows none of it.
    down = dataclasses.replace(cam, pitch_deg=-60.0)
    assert sky_textures.dome_rect_ndc(down, sky) is None
