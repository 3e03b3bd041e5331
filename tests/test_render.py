"""GL rendering: the sky pass, sprites, ring impostors, the compositor, and the shader loader.

Small exact scenes whose expected pixels follow from the camera maths and the shader formulas:
odd viewports so the centre pixel's ray is exactly the camera's forward vector.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from sprite_helpers import sprite_batch

from wxsky.app.snapshot import LAYER_NAMES, take_snapshot
from wxsky.errors import RenderError
from wxsky.host.compositor import Layers, composite, layers_from_images, sample_ring, stretch
from wxsky.render import renderer as renderer_module
from wxsky.render import shaders as shaders_mod
from wxsky.render import sky_textures
from wxsky.render.profile import PassProfiler
from wxsky.render.renderer import (
    BASE_FEATHER_FROM_M,
    BASE_FEATHER_M,
    BASE_FEATHER_TO_M,
    IMPOSTOR_MIN_ROWS,
    NEAR_SCALE,
    Renderer,
    _variant_runs,
    impostor_rows,
    near_layer_size,
    turning_round,
)
from wxsky.render.shaders import ShaderLibrary, shader_source
from wxsky.scene.camera import Camera
from wxsky.scene.clouds import SpriteBatch
from wxsky.scene.layout import FrameScene, RingScene, SceneSettings, SpriteDraw
from wxsky.scene.ring import RING_SIZE, RingGeometry, bin_far_sprites
from wxsky.scene.sky import SkyParams, sky_params
from wxsky.scene.texture_slots import TEX_FLAT_BOTTOM, TEX_FOG
from wxsky.weather.state import CloudLayer, CloudType, WeatherState

W, H = 161, 91  # odd: the centre pixel (45, 80) looks exactly along the camera axis
CR, CC = H // 2, W // 2
FOV = 60.0
ZURICH_AFTERNOON = datetime(2026, 6, 21, 14, 0, tzinfo=UTC)
ZURICH_EVENING = datetime(2026, 6, 21, 17, 30, tzinfo=UTC)
EMPTY = SpriteDraw(SpriteBatch.empty(), np.zeros((0, 4), np.float32))


def _sky(t: datetime = ZURICH_AFTERNOON, **kw: object) -> SkyParams:
    return sky_params(WeatherState(time_utc=t, **kw))  # type: ignore[arg-type]


def _camera(**kw: object) -> Camera:
    args: dict = {
        "position_m": (0.0, 0.0, 1000.0),
        "fov_deg": FOV,
        "width_px": W,
        "height_px": H,
        **kw,
    }
    return Camera(**args)


def _sprites(
    centres: list, sizes: list, texture: int = TEX_FOG[0], rotation: float = 0.0
) -> SpriteBatch:
    return sprite_batch(centres, sizes, texture=texture, rotation=rotation)


def _draw(batch: SpriteBatch, rgba: tuple = (1.0, 1.0, 1.0, 1.0)) -> SpriteDraw:
    return SpriteDraw(batch, np.tile(np.float32(rgba), (len(batch), 1)))


def _u8(rgb: tuple[float, ...]) -> np.ndarray:
    return np.round(np.clip(np.asarray(rgb), 0.0, 1.0) * 255.0)


def _bbox(alpha: np.ndarray) -> tuple[int, int, int, int]:
    rows, cols = np.nonzero(alpha)
    assert len(rows), "nothing drawn"
    return int(rows.min()), int(rows.max()), int(cols.min()), int(cols.max())


@contextlib.contextmanager
def _near_scale(r: Renderer, scale: float) -> Iterator[Renderer]:
    old = r.near_scale
    r.near_scale = scale
    try:
        yield r
    finally:
        r.near_scale = old


# Near sprites at full resolution land within a pixel of the exact footprint; drawn at
# NEAR_SCALE and upscaled bilinearly, within one reduced pixel more.
SCALES = [(1.0, 1.0), (NEAR_SCALE, 1.0 + 1.0 / NEAR_SCALE)]


def _near_seen(r: Renderer, width: int = W, height: int = H) -> np.ndarray:
    """The near layer as a host shows it: stretched over the viewport (it is drawn at
    near_scale of it), bilinearly, as 8-bit RGBA."""
    seen = stretch(r.read("near"), width, height)
    return np.round(seen * 255.0).astype(np.uint8)


def _render_sky(r: Renderer, cam: Camera, sky: SkyParams) -> np.ndarray:
    r.render_frame(FrameScene(cam, sky, EMPTY))
    img = r.read("sky")
    assert img.shape == (cam.height_px, cam.width_px, 4)
    assert np.all(img[..., 3] == 255)
    return img.astype(int)


# -- sky pass -----------------------------------------------------------------------------


def test_sun_disc_at_the_centre_when_looking_at_the_sun(renderer: Renderer) -> None:
    sky = _sky()
    assert sky.sun.elevation_deg > 40.0
    cam = _camera(heading_deg=sky.sun.azimuth_deg, pitch_deg=sky.sun.elevation_deg)
    img = _render_sky(renderer, cam, sky)
    assert tuple(img[CR, CC]) == (255, 255, 255, 255)
    # The disc is 0.27° in radius, a pixel here 0.37°: three pixels out is sky with glow.
    for r, c in ((CR, CC + 3), (CR, CC - 3), (CR + 3, CC), (CR - 3, CC)):
        assert img[r, c, 0] < 230, (r, c, img[r, c])
        assert img[r, c, 2] > img[r, c, 0]  # still blue


def test_no_sun_disc_at_night(renderer: Renderer) -> None:
    sky = _sky(datetime(2026, 6, 21, 23, 30, tzinfo=UTC))
    assert sky.sun.elevation_deg < -10.0 and sky.sun_rgb == (0.0, 0.0, 0.0)
    cam = _camera(heading_deg=sky.sun.azimuth_deg, pitch_deg=sky.sun.elevation_deg)
    img = _render_sky(renderer, cam, sky)
    assert img[CR, CC, :3].max() < 40
    np.testing.assert_allclose(img[CR, CC], img[CR, CC + 3], atol=1)


def test_zenith_colour_when_pitched_straight_up(renderer: Renderer) -> None:
    sky = _sky(ZURICH_EVENING)
    # A low sun: its glow at the zenith is below half a level (0.08 * sin(el)^6).
    assert 5.0 < sky.sun.elevation_deg < 25.0
    img = _render_sky(renderer, _camera(pitch_deg=90.0), sky)
    np.testing.assert_allclose(img[CR, CC, :3], _u8(sky.zenith_rgb), atol=1)


def _lit_ground(sky: SkyParams) -> np.ndarray:
    """The ground's own colour in the light on it (sky.glsl `ground_band`), unhazed."""
    return _u8(tuple(np.asarray(sky.ground_rgb) * np.asarray(sky_textures.ground_tint(sky))))


# 2 m above the ground: the ground 17° down is 7 m off, its own colour (no haze to speak of).
GROUND_EYE_M = (0.0, 0.0, WeatherState().observer.alt_m + 2.0)


def test_horizon_and_ground_colours_looking_level_away_from_the_sun(renderer: Renderer) -> None:
    sky = _sky()
    cam = _camera(heading_deg=sky.sun.azimuth_deg + 180.0, pitch_deg=0.0, position_m=GROUND_EYE_M)
    img = _render_sky(renderer, cam, sky)
    horizon, zenith, ground = _u8(sky.horizon_rgb), _u8(sky.zenith_rgb), _lit_ground(sky)
    # The centre row looks exactly level: the horizon colour, no glow facing away.
    np.testing.assert_allclose(img[CR, CC, :3], horizon, atol=1)
    # The bottom row looks 17° down at the ground 7 m off: its own colour in the light on it.
    np.testing.assert_allclose(img[H - 1, CC, :3], ground, atol=1)
    # Above the horizon the colour runs monotonically from the horizon towards the zenith.
    column = img[: CR + 1, CC, :3][::-1]  # from the horizon row up to the top row
    lo, hi = np.minimum(horizon, zenith) - 1, np.maximum(horizon, zenith) + 1
    assert np.all((column >= lo) & (column <= hi))
    steps = np.diff(column, axis=0) * np.sign(zenith - horizon)
    assert np.all(steps >= -1)
    assert np.abs(column[-1] - horizon).sum() > 20  # and actually gets somewhere


def test_a_steady_view_keeps_its_sky_layer_until_what_it_shows_moves(
    renderer: Renderer,
) -> None:
    profiler = renderer.start_profile()
    try:
        _check_sky_reuse(renderer, profiler)
    finally:
        renderer.stop_profile()


def _check_sky_reuse(renderer: Renderer, profiler: PassProfiler) -> None:
    cam = _camera(heading_deg=200.0, pitch_deg=10.0)
    t0 = ZURICH_AFTERNOON

    def sky_draws(cam: Camera, t: datetime) -> int:
        before = len(profiler.passes["sky"].seconds) if "sky" in profiler.passes else 0
        renderer.render_frame(FrameScene(cam, _sky(t), EMPTY))
        return len(profiler.passes["sky"].seconds) - before

    sky_draws(cam, t0 - timedelta(minutes=5))  # whatever the layer held before
    assert sky_draws(cam, t0) == 1
    kept = renderer.read("sky")
    # A frame later the sun has moved 2.4e-6 rad: the layer stays as it is.
    assert sky_draws(cam, t0 + timedelta(seconds=1 / 30)) == 0
    # Five seconds later (3.6e-4 rad, past SKY_CATCH_UP tolerances) it is redrawn whole, and
    # differs by no more than rounding from what was kept.
    assert sky_draws(cam, t0 + timedelta(seconds=5)) == 1
    assert np.abs(renderer.read("sky").astype(int) - kept.astype(int)).max() <= 1
    # Any turn of the camera redraws at once.
    turned = dataclasses.replace(cam, heading_deg=200.01)
    assert sky_draws(turned, t0 + timedelta(seconds=5)) == 1
    assert sky_draws(turned, t0 + timedelta(seconds=5)) == 0


def test_sky_follows_roll(renderer: Renderer) -> None:
    # Rolled 90° right wing down, the image's up points to the world's right and its right
    # points down: the horizon runs vertically through the centre, the ground on the right.
    sky = _sky()
    cam = _camera(
        heading_deg=sky.sun.azimuth_deg + 180.0,
        roll_deg=90.0,
        height_px=W,
        width_px=H,
        position_m=GROUND_EYE_M,
    )
    img = _render_sky(renderer, cam, sky)
    mid_r, mid_c = W // 2, H // 2
    np.testing.assert_allclose(img[mid_r, mid_c, :3], _u8(sky.horizon_rgb), atol=1)
    np.testing.assert_allclose(img[mid_r, H - 1, :3], _lit_ground(sky), atol=1)
    assert abs(img[mid_r, 0, :3] - _lit_ground(sky)).sum() > 60


# -- sprites ------------------------------------------------------------------------------


def test_empty_scene_clears_to_transparent(renderer: Renderer) -> None:
    cam = _camera()
    # Draw something first so the clear is what empties the layer.
    renderer.render_frame(FrameScene(cam, _sky(), _draw(_sprites([(0, 2000, 1000)], [400]))))
    assert renderer.read("near")[..., 3].any()
    renderer.render_frame(FrameScene(cam, _sky(), EMPTY))
    near = renderer.read("near")
    w, h = near_layer_size(cam, renderer.near_scale)
    assert near.shape == (h, w, 4) and (w, h) == (round(W * NEAR_SCALE), round(H * NEAR_SCALE))
    assert not near.any()


@pytest.mark.parametrize(("scale", "margin"), SCALES)
@pytest.mark.parametrize(("distance", "size"), [(2000.0, 400.0), (5000.0, 2000.0)])
def test_single_sprite_straight_ahead_is_centred_with_its_projected_size(
    renderer: Renderer, distance: float, size: float, scale: float, margin: float
) -> None:
    cam = _camera()
    batch = _sprites([(0.0, distance, 1000.0)], [size], texture=TEX_FOG[0])  # round fog texture
    with _near_scale(renderer, scale):
        renderer.render_frame(FrameScene(cam, _sky(), _draw(batch)))
    alpha = _near_seen(renderer)[..., 3]
    # Half the sprite's edge, in pixels: (size/2) / distance over tan(fov/2), times W/2.
    half_px = (size / 2.0) / distance / math.tan(math.radians(FOV / 2.0)) * (W / 2.0)
    r0, r1, c0, c1 = _bbox(alpha)
    assert c0 >= CC - half_px - margin and c1 <= CC + half_px + margin
    assert r0 >= CR - half_px - margin and r1 <= CR + half_px + margin
    # The fog texture fills ~90 % of its cell's radius, centred.
    assert c1 - c0 >= 1.6 * half_px and r1 - r0 >= 1.6 * half_px
    assert abs((c0 + c1) / 2 - CC) <= margin and abs((r0 + r1) / 2 - CR) <= margin
    assert alpha.max() > 120


@pytest.mark.parametrize(("scale", "margin"), SCALES)
def test_sprite_textures_are_upright(renderer: Renderer, scale: float, margin: float) -> None:
    # The flat-bottomed cumulus base is cut off just below the middle of the sprite.
    cam = _camera()
    batch = _sprites([(0.0, 2000.0, 1000.0)], [400.0], texture=TEX_FLAT_BOTTOM[0])
    with _near_scale(renderer, scale):
        renderer.render_frame(FrameScene(cam, _sky(), _draw(batch)))
    r0, r1, _, _ = _bbox(renderer.read("near")[..., 3] > 2)
    half_px = 0.1 / math.tan(math.radians(FOV / 2.0)) * (W / 2.0)
    assert r1 <= CR + 0.3 * half_px + margin
    assert r0 <= CR - 0.8 * half_px


def _base_ramp_m(renderer: Renderer, distance_m: float) -> tuple[float, float]:
    """A flat-based sprite seen edge-on (its base at the eye's height), `distance_m` away with
    a view about 6 m a pixel there: (metres above the base where its cut lets a tenth of the
    sprite through, metres over which it goes from a tenth to nine tenths), down the middle
    column, against the same sprite uncut."""
    px_m = 6.0
    fov = math.degrees(2.0 * math.atan(px_m * (W / 2.0) / distance_m))
    cam = _camera(fov_deg=fov)
    size = 400.0
    batch = _sprites([(0.0, distance_m, 1000.0 + 0.25 * size)], [size])

    def alpha(b: SpriteBatch) -> np.ndarray:
        with _near_scale(renderer, 1.0):
            renderer.render_frame(FrameScene(cam, _sky(), _draw(b)))
        return renderer.read("near")[:, CC, 3].astype(float)

    uncut = alpha(batch)
    cut = alpha(dataclasses.replace(batch, base_m=np.float32([1000.0])))
    rows = np.arange(H)
    # Row r's centre is (CR - r) pixels above the eye's level (the base).
    above_m = (CR - rows) * distance_m * math.tan(math.radians(fov / 2.0)) / (W / 2.0)
    seen = uncut > 40.0
    share = np.where(seen, cut / np.maximum(uncut, 1.0), np.nan)
    lit = above_m[seen & (share >= 0.1)].min()
    full = above_m[seen & (share >= 0.9)].min()
    return float(lit), float(full - lit)


def test_a_far_cloud_base_fades_in_over_its_lowest_metres_and_a_near_one_is_sharp(
    renderer: Renderer,
) -> None:
    # Far, the ragged base's lowest metres average into a ramp (BASE_FEATHER_M); near, the
    # cut stays a pixel sharp. Both start on the base's line.
    near_lit, near_ramp = _base_ramp_m(renderer, 0.5 * BASE_FEATHER_FROM_M)
    far_lit, far_ramp = _base_ramp_m(renderer, 1.5 * BASE_FEATHER_TO_M)
    assert near_ramp <= 2 * 6.0
    assert 0.6 * BASE_FEATHER_M <= far_ramp <= 1.0 * BASE_FEATHER_M
    assert abs(near_lit) <= 6.0 and 0.0 <= far_lit <= 0.2 * BASE_FEATHER_M


def test_a_flat_bottomed_sprite_seen_from_below_turns_into_the_round_one(
    renderer: Renderer,
) -> None:
    # Straight overhead, a flat-bottomed base sprite would be a grey bar across the cloud: it
    # draws as the round fog texture there, and as itself a little above the horizon.
    def near(texture: int, pitch_deg: float) -> np.ndarray:
        cam = _camera(pitch_deg=pitch_deg)
        el = math.radians(pitch_deg)
        centre = (0.0, 2000.0 * math.cos(el), 1000.0 + 2000.0 * math.sin(el))
        batch = _sprites([centre], [400.0], texture=texture)
        with _near_scale(renderer, 1.0):
            renderer.render_frame(FrameScene(cam, _sky(), _draw(batch)))
        return renderer.read("near").astype(int)

    overhead = near(TEX_FLAT_BOTTOM[0], 85.0)
    assert np.abs(overhead - near(TEX_FOG[0], 85.0)).max() <= 1
    low_flat, low_fog = near(TEX_FLAT_BOTTOM[0], 10.0), near(TEX_FOG[0], 10.0)
    assert np.abs(low_flat - low_fog)[..., 3].max() > 100  # the flat bottom still shows
    # Between the two it is a blend of both, never a hole: as much cover as the lesser.
    mid = near(TEX_FLAT_BOTTOM[0], 36.0)[..., 3].sum()
    ends = near(TEX_FLAT_BOTTOM[0], 36.0 - 36.0)[..., 3].sum(), overhead[..., 3].sum()
    assert mid >= 0.95 * min(ends)


def test_only_flat_bottomed_sprites_part_way_round_need_the_second_read() -> None:
    eye = (0.0, 0.0, 1000.0)
    # Seen at sines of elevation 0.2 (none of the turn), 0.6 (part-way), 0.9 (complete).
    centres = [(0.0, 1000.0 * math.sqrt(1 - e * e), 1000.0 + 1000.0 * e) for e in (0.2, 0.6, 0.9)]
    flat = _draw(_sprites(centres, [300.0] * 3, texture=TEX_FLAT_BOTTOM[0]))
    assert turning_round(flat, eye).tolist() == [False, True, False]
    fog = _draw(_sprites(centres, [300.0] * 3, texture=TEX_FOG[0]))
    assert not turning_round(fog, eye).any()
    # A sprite with its own orientation never turns.
    fixed = SpriteDraw(flat.sprites, flat.rgba, np.tile(np.float32([0, -1, 0]), (3, 1)))
    assert not turning_round(fixed, eye).any()
    runs = _variant_runs(np.array([0, 1, 1, 0, 0, 3, 2], np.int8))
    assert runs == [(0, 1, 0), (1, 3, 1), (3, 5, 0), (5, 6, 3), (6, 7, 2)]
    assert _variant_runs(np.zeros(4, np.int8)) == [(0, 4, 0)]


def test_sprites_drawn_in_runs_match_every_sprite_drawn_with_both_reads(
    renderer: Renderer, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Flat-bottomed sprites at every angle of the turn, and round ones, overlapping: drawn
    as runs with one read or two, the picture is the one the two-read shader alone makes."""
    rng = np.random.default_rng(5)
    n = 60
    elevation = rng.uniform(0.0, 1.4, n)
    azimuth = rng.uniform(-0.4, 0.4, n)
    dist = rng.uniform(800.0, 3000.0, n)
    centres = np.stack(
        [
            dist * np.cos(elevation) * np.sin(azimuth),
            dist * np.cos(elevation) * np.cos(azimuth),
            1000.0 + dist * np.sin(elevation),
        ],
        axis=1,
    )
    order = np.argsort(-dist)  # back to front
    textures = np.where(rng.random(n) < 0.7, TEX_FLAT_BOTTOM[0], TEX_FOG[0])
    batch = sprite_batch(centres[order].tolist(), rng.uniform(200.0, 600.0, n).tolist())
    batch = dataclasses.replace(batch, texture=textures[order].astype(np.int32))
    draw = SpriteDraw(batch, rng.uniform(0.3, 1.0, (n, 4)).astype(np.float32))
    cam = _camera(pitch_deg=40.0, fov_deg=120.0)
    turning = turning_round(draw, cam.position_m)
    assert 5 <= turning.sum() <= n - 5  # both kinds, in several runs
    with _near_scale(renderer, 1.0):
        renderer.render_frame(FrameScene(cam, _sky(), draw))
        runs = renderer.read("near").astype(int)
        monkeypatch.setattr(renderer_module, "_variant_runs", lambda t: [(0, len(t), 1)])
        renderer.render_frame(FrameScene(cam, _sky(), draw))
        both = renderer.read("near").astype(int)
    assert runs[..., 3].max() > 200
    assert np.abs(runs - both).max() <= 1


@pytest.mark.parametrize("scale", [1.0, NEAR_SCALE])
def test_the_in_cloud_veil_covers_the_near_layer_under_the_sprites(
    renderer: Renderer, scale: float
) -> None:
    veil = (0.2, 0.3, 0.4, 0.5)  # premultiplied
    batch = _sprites([(0.0, 2000.0, 1000.0)], [400.0])
    with _near_scale(renderer, scale):
        renderer.render_frame(FrameScene(_camera(), _sky(), _draw(batch), veil_rgba=veil))
    near = _near_seen(renderer).astype(int)
    expected = np.round(np.asarray(veil) * 255.0)
    assert np.abs(near[0, 0] - expected).max() <= 1  # a corner: no sprite, only the veil
    assert near[CR, CC, 3] > expected[3] + 50  # the sprite is drawn over it
    renderer.render_frame(FrameScene(_camera(), _sky(), _draw(batch)))
    assert renderer.read("near")[0, 0, 3] == 0  # and the next frame out of cloud is clear


def test_reduced_near_layer_matches_the_full_resolution_one(renderer: Renderer) -> None:
    cam = _camera(heading_deg=15.0, pitch_deg=5.0)
    centres = [(600.0 * k - 1200.0, 4000.0 + 300.0 * k, 1300.0 + 50.0 * k) for k in range(5)]
    draw = _draw(_sprites(centres, [700.0] * 5, texture=5), (0.8, 0.8, 0.85, 0.9))
    with _near_scale(renderer, 1.0):
        renderer.render_frame(FrameScene(cam, _sky(), draw))
    full = renderer.read("near").astype(int)
    renderer.render_frame(FrameScene(cam, _sky(), draw))  # default: reduced, host-stretched
    reduced = _near_seen(renderer).astype(int)
    assert renderer.near_scale < 1.0
    assert np.all(reduced[..., :3].max(axis=2) <= reduced[..., 3])
    diff = np.abs(full - reduced)
    assert diff.mean() < 1.5  # measured 0.8 on llvmpipe; shifting by 2 px gives 2.3
    assert np.abs(full[..., 3].sum() - reduced[..., 3].sum()) < 0.03 * full[..., 3].sum()

    def centroid(alpha: np.ndarray) -> np.ndarray:
        rows, cols = np.indices(alpha.shape)
        return np.array([(rows * alpha).sum(), (cols * alpha).sum()]) / alpha.sum()

    np.testing.assert_allclose(centroid(reduced[..., 3]), centroid(full[..., 3]), atol=0.5)


def test_sprite_off_axis_lands_where_the_camera_projects_it(renderer: Renderer) -> None:
    cam = _camera(heading_deg=30.0, pitch_deg=10.0, roll_deg=-12.0)
    centre = np.array([1500.0, 3000.0, 1400.0])
    renderer.render_frame(FrameScene(cam, _sky(), _draw(_sprites([centre], [150.0]))))
    alpha = _near_seen(renderer)[..., 3].astype(float)
    clip = cam.view_projection() @ np.append(centre, 1.0)
    ndc = clip[:3] / clip[3]
    col = (ndc[0] + 1) / 2 * W - 0.5
    row = (ndc[1] + 1) / 2 * H - 0.5
    r0, r1, c0, c1 = _bbox(alpha)
    assert abs((c0 + c1) / 2 - col) <= 1.0 and abs((r0 + r1) / 2 - row) <= 1.0


def test_output_is_premultiplied(renderer: Renderer) -> None:
    state = WeatherState(
        time_utc=ZURICH_AFTERNOON,
        layers=(
            CloudLayer(5, 1500.0, 2600.0, CloudType.CUMULUS),
            CloudLayer(8, 6000.0, 6500.0, CloudType.ALTOSTRATUS),
        ),
        seed=2,
    )
    cam = _camera(heading_deg=120.0, pitch_deg=20.0)
    snap = take_snapshot(state, cam, SceneSettings(max_range_m=16_000.0), renderer)
    assert set(snap.layers) == {*LAYER_NAMES, "shadow"}
    drawn = 0
    for name, img in snap.layers.items():
        if name == "sky":
            continue
        assert np.all(img[..., :3].max(axis=2) <= img[..., 3]), name
        if name != "shadow":  # opaque: a map, not a picture
            drawn += int((img[..., 3] > 0).sum())
    assert drawn > 1000
    assert np.all(snap.image[..., 3] == 255)


# -- ring impostors -----------------------------------------------------------------------

RING_CENTRE = (0.0, 0.0, 1000.0)
RING_R = 8000.0


def _from_ring_centre(east: float, north: float, up: float) -> np.ndarray:
    return np.asarray(RING_CENTRE) + np.array([east, north, up])


def _ring_scene(draw: SpriteDraw, bottom: float, top: float) -> RingScene:
    geo = RingGeometry(RING_CENTRE, RING_R, (bottom,) * RING_SIZE, (top,) * RING_SIZE)
    return RingScene(geometry=geo, impostors=(draw,) * RING_SIZE, drift=())


def test_ring_impostor_shows_the_sprite_through_its_off_axis_frustum(renderer: Renderer) -> None:
    p = renderer.ring_px
    rel = np.array([1500.0, 20_000.0, 2000.0])  # east, north (depth for impostor 0), up
    size = 3000.0
    draw = _draw(_sprites([np.asarray(RING_CENTRE) + rel], [size]))
    bottom, top = -1000.0, 3000.0
    renderer.render_ring(_ring_scene(draw, bottom, top))
    images = {i: renderer.read(f"ring_{i}") for i in range(RING_SIZE)}
    assert images[0].shape == (p, p, 4)
    # On the quad (8 km out, 2 * 8 km * tan 22.5° wide, bottom..top tall) the sprite's centre
    # projects to x = 1500 * 8/20, y = 2000 * 8/20, its half-size to 1500 * 8/20.
    k = RING_R / rel[1]
    half_w = RING_R * math.tan(math.radians(22.5))
    col = (rel[0] * k + half_w) / (2 * half_w) * p - 0.5
    row = (top - rel[2] * k) / (top - bottom) * p - 0.5
    half_c = size / 2 * k / (2 * half_w) * p
    half_r = size / 2 * k / (top - bottom) * p
    r0, r1, c0, c1 = _bbox(images[0][..., 3])
    assert c0 >= col - half_c - 1 and c1 <= col + half_c + 1
    assert r0 >= row - half_r - 1 and r1 <= row + half_r + 1
    assert abs((c0 + c1) / 2 - col) <= 1.0 and abs((r0 + r1) / 2 - row) <= 1.0
    assert c1 - c0 >= 1.6 * half_c and r1 - r0 >= 1.6 * half_r
    # Behind impostor 4's eye and outside every other wedge: nothing there.
    for i in range(1, RING_SIZE):
        assert not images[i][..., 3].any(), f"sprite leaked into ring_{i}"
        assert np.all(images[i][..., :3].max(axis=2) <= images[i][..., 3])


def test_impostor_rows_follow_the_window_shape() -> None:
    # A window a fifth as tall as wide: the square texels' rows, 256 / 5 (finer rows than
    # columns would blur the far clouds sideways only: streaks, docs/cloud-form.md).
    assert impostor_rows(256, 0.2 * 2 * 1000.0, 1000.0) == math.ceil(256 / 5)
    assert impostor_rows(256, 2 * 1000.0, 1000.0) == 256  # square or taller: all of them
    assert impostor_rows(256, 3 * 2 * 1000.0, 1000.0) == 256
    assert impostor_rows(256, 1.0, 1000.0) == IMPOSTOR_MIN_ROWS


def test_an_impostor_drawn_with_fewer_rows_is_the_same_picture_stretched(
    renderer: Renderer, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A wide, low window (a layer seen edge-on) is drawn with fewer rows and stretched to
    the square layer: the sprites land where the square drawing puts them, and only their
    vertical detail softens."""
    rng = np.random.default_rng(3)
    n = 40
    rel = np.stack(
        [rng.uniform(-5000, 5000, n), rng.uniform(14_000, 30_000, n), rng.uniform(-200, 900, n)],
        axis=1,
    )
    order = np.argsort(-rel[:, 1])
    draw = _draw(
        _sprites((np.asarray(RING_CENTRE) + rel[order]).tolist(), rng.uniform(300, 900, n)),
        (0.9, 0.9, 0.95, 0.8),
    )
    scene = _ring_scene(draw, -400.0, 700.0)  # 1.1 km of a 6.6 km wide window
    assert impostor_rows(renderer.ring_px, 1100.0, scene.geometry.half_width_m) < renderer.ring_px
    renderer.render_ring(scene, indices=[0])
    fewer = renderer.read("ring_0").astype(float)
    monkeypatch.setattr(renderer_module, "IMPOSTOR_TEXEL_ASPECT", 1e9)
    renderer.render_ring(scene, indices=[0])
    square = renderer.read("ring_0").astype(float)
    alpha_f, alpha_s = fewer[..., 3], square[..., 3]
    assert alpha_s.sum() > 0.05 * 255 * alpha_s.size  # a good part of the window is cloud
    assert abs(alpha_f.sum() / alpha_s.sum() - 1.0) < 0.02  # no cloud lost or made
    rows = np.arange(alpha_s.shape[0])
    centroid = [float(rows @ a.sum(axis=1) / a.sum()) for a in (alpha_f, alpha_s)]
    assert abs(centroid[0] - centroid[1]) < 0.5  # not shifted by the stretch
    assert np.abs(fewer - square).mean() < 1.5


@pytest.mark.parametrize("window", [(-400.0, 700.0), (-3000.0, 3000.0)])  # stretched, square
def test_an_impostor_drawn_in_slices_is_the_impostor_drawn_whole(
    renderer: Renderer, window: tuple[float, float]
) -> None:
    rng = np.random.default_rng(9)
    n = 50
    rel = np.stack(
        [rng.uniform(-5000, 5000, n), rng.uniform(14_000, 30_000, n), rng.uniform(-200, 600, n)],
        axis=1,
    )
    order = np.argsort(-rel[:, 1])
    draw = _draw(
        _sprites((np.asarray(RING_CENTRE) + rel[order]).tolist(), rng.uniform(300, 900, n)),
        (0.9, 0.85, 0.95, 0.7),
    )
    scene = _ring_scene(draw, *window)
    renderer.render_ring(scene, indices=[0], ring_set=1)
    whole = renderer.read("ring_b_0")
    # Another impostor drawn meanwhile into the other set must not disturb the slices.
    for start, stop in ((0, 7), (7, 30), (30, n)):
        renderer.render_impostor_slice(scene, 0, start, stop, ring_set=1)
        renderer.render_ring(scene, indices=[0], ring_set=0)
    sliced = renderer.read("ring_b_0")
    assert whole[..., 3].astype(int).sum() > 0
    np.testing.assert_array_equal(sliced, whole)


def test_ring_texture_row_zero_is_the_top_of_the_quad(renderer: Renderer) -> None:
    # A sprite near the window's top edge appears in the first rows of the texture.
    rel = np.array([0.0, 16_000.0, 5000.0])  # y on the quad: 2500 of -1000..3000
    draw = _draw(_sprites([np.asarray(RING_CENTRE) + rel], [600.0]))
    renderer.render_ring(_ring_scene(draw, -1000.0, 3000.0), indices=[0])
    _, r1, _, _ = _bbox(renderer.read("ring_0")[..., 3])
    assert r1 < renderer.ring_px // 4


def test_compositor_through_the_ring_matches_a_direct_render(renderer: Renderer) -> None:
    """From the ring centre, the impostor seen through its quad is the sprite itself: the
    composite of sky + ring must match sky + the sprite drawn directly as a near sprite."""
    sky = _sky()
    cam = _camera(position_m=RING_CENTRE, heading_deg=10.0, pitch_deg=4.0)
    centre = _from_ring_centre(2500.0, 18_000.0, 1500.0)
    batch = _sprites([centre], [2500.0], texture=TEX_FOG[0])
    geo, bins = bin_far_sprites(batch, RING_CENTRE, RING_R)
    ring = RingScene(geo, tuple(_draw(b) for b in bins), drift=())
    renderer.render_ring(ring)
    renderer.render_frame(FrameScene(cam, sky, EMPTY))
    images = {name: renderer.read(name) for name in LAYER_NAMES}
    assert not images["near"].any()
    via_ring = composite(layers_from_images(images, geo.corners_m()), cam).astype(int)
    layers = layers_from_images(images, geo.corners_m())
    ring_only = sample_ring(layers.ring, layers.ring_quads_m, cam)

    with _near_scale(renderer, 1.0):  # the reference: the sprite drawn at full resolution
        renderer.render_frame(FrameScene(cam, sky, _draw(batch)))
    direct_near = renderer.read("near")
    empty_ring = tuple(np.zeros_like(images["ring_0"]) for _ in range(RING_SIZE))
    direct_layers = Layers(images["sky"], direct_near, empty_ring, geo.corners_m())
    direct = composite(direct_layers, cam).astype(int)

    covered = ring_only[..., 3] > 0.02
    assert covered.sum() > 100
    # Same footprint, same place...
    np.testing.assert_allclose(_bbox(covered), _bbox(direct_near[..., 3] > 5), atol=2)
    clip = cam.view_projection() @ np.append(centre, 1.0)
    col = (clip[0] / clip[3] + 1) / 2 * W - 0.5
    row = (clip[1] / clip[3] + 1) / 2 * H - 0.5
    r0, r1, c0, c1 = _bbox(covered)
    assert abs((c0 + c1) / 2 - col) <= 1.5 and abs((r0 + r1) / 2 - row) <= 1.5
    # ...and nearly the same colours (a second bilinear resampling blurs a little; measured
    # 0.4 mean and 1 at the 95th percentile on llvmpipe).
    diff = np.abs(via_ring[..., :3] - direct[..., :3])
    assert diff[covered].mean() < 2.0
    assert np.percentile(diff[covered], 95) < 8
    # Outside the sprite both are the sky (to two levels: the impostor's bilinear lookup, of
    # a sprite read from its nearest mip level, spreads the faintest edge of the sprite a
    # texel beyond where the direct one stops).
    outside = ~covered & (direct_near[..., 3] == 0)
    assert np.abs(via_ring[outside] - images["sky"][outside].astype(int)).max() <= 2


def test_snapshot_of_an_empty_sky_is_the_sky_layer(renderer: Renderer) -> None:
    state = WeatherState(time_utc=ZURICH_AFTERNOON, layers=())
    cam = _camera(heading_deg=200.0, pitch_deg=15.0)
    snap = take_snapshot(state, cam, SceneSettings(max_range_m=12_000.0), renderer)
    for name in LAYER_NAMES[1:]:
        assert not snap.layers[name].any(), name
    np.testing.assert_array_equal(snap.image, snap.layers["sky"])
    assert snap.ring_quads_m.shape == (8, 4, 3)


def test_resizing_the_layer_drawn_last(renderer: Renderer) -> None:
    draw = _draw(_sprites([_from_ring_centre(0.0, 16_000.0, 2000.0)], [600.0]))
    ring = _ring_scene(draw, -1000.0, 3000.0)
    px = renderer.ring_px
    try:
        renderer.render_ring(ring, indices=[0])  # ring_0 is the bound framebuffer now
        renderer.ring_px = px // 2
        renderer.render_ring(ring, indices=[0])
        assert renderer.read("ring_0").shape == (px // 2, px // 2, 4)
    finally:
        # Leave the session renderer as other tests expect it, with a live framebuffer bound.
        renderer.ring_px = px
        renderer.render_frame(FrameScene(_camera(), _sky(), EMPTY))
        renderer.render_ring(ring, indices=[0])


# -- shader loader ------------------------------------------------------------------------


def test_include_is_expanded() -> None:
    text = shader_source("sky.glsl")
    assert "#include" not in text
    assert text.count("vec3 sky_colour(") == 1
    assert text.index("vec3 sky_colour(") < text.index("void main()")


def test_missing_shader_file_raises_render_error() -> None:
    with pytest.raises(RenderError, match=r"shaders/no-such-shader\.glsl"):
        shader_source("no-such-shader.glsl")


@pytest.fixture
def shader_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Point the loader's package resources at a temporary folder of shaders."""
    (tmp_path / "shaders").mkdir()
    monkeypatch.setattr(shaders_mod, "resources", SimpleNamespace(files=lambda _pkg: tmp_path))
    return tmp_path / "shaders"


def test_nested_includes_expand_in_place(shader_dir: Path) -> None:
    (shader_dir / "a.glsl").write_text('// a\n#include "b.glsl"\n// end a\n')
    (shader_dir / "b.glsl").write_text('// b\n  #include "c.glsl"  \n// #include "not-me.glsl"\n')
    (shader_dir / "c.glsl").write_text("// c\n")
    text = shader_source("a.glsl")
    lines = [line for line in text.splitlines() if line.strip()]
    assert lines == ["// a", "// b", "// c", '// #include "not-me.glsl"', "// end a"]


def test_missing_include_names_the_missing_file(shader_dir: Path) -> None:
    (shader_dir / "a.glsl").write_text('#include "gone.glsl"\n')
    with pytest.raises(RenderError, match=r"shaders/gone\.glsl"):
        shader_source("a.glsl")


def test_recursive_include_is_an_error(shader_dir: Path) -> None:
    (shader_dir / "loop.glsl").write_text('#include "loop.glsl"\n')
    with pytest.raises(RenderError, match="too deep"):
        shader_source("loop.glsl")


def test_compile_error_names_the_file(renderer: Renderer, shader_dir: Path) -> None:
    (shader_dir / "broken.glsl").write_text(
        "#if defined VERTEX_SHADER\nvoid main() { gl_Position = vec4(0.0); }\n#endif\n"
        "#if defined FRAGMENT_SHADER\nout vec4 c;\nvoid main() { c = undefined_thing; }\n#endif\n"
    )
    lib = ShaderLibrary(renderer.ctx)
    with pytest.raises(RenderError, match=r"shaders/broken\.glsl"):
        lib.program("broken.glsl")
    lib.release()


def test_missing_define_is_a_compile_error_naming_the_file(renderer: Renderer) -> None:
    lib = ShaderLibrary(renderer.ctx)
    with pytest.raises(RenderError, match=r"shaders/sprites\.glsl"):
        lib.program("sprites.glsl")  # needs SHEET_CELLS, the slots, the turn, the size, the base
    defines = {
        "SHEET_CELLS": "4",
        "FLAT_BOTTOM_SLOT": "0",
        "ROUND_SLOT": "1",
        "ROUND_FROM": "0.45",
        "ROUND_TO": "0.75",
        "ROUND_MIX": "1",
        "FINE_MIN_PX": "48.0",
        "DECK": "0",
        "FLAT_BASE": "1",
        "BASE_SOFT_FROM": "0.2",
        "BASE_SOFT_TO": "0.45",
        "BASE_FEATHER_M": "90.0",
        "BASE_FEATHER_FROM_M": "2000.0",
        "BASE_FEATHER_TO_M": "8000.0",
        "BASE_DIM": "0.55",
        "BASE_SHADE_DEPTH": "0.5",
        "BASE_DIM_FROM": "0.1",
        "BASE_DIM_TO": "0.3",
    }
    prog = lib.program("sprites.glsl", defines)
    assert lib.program("sprites.glsl", dict(defines)) is prog  # compiled once
    lib.release()


def test_interleaved_variants_drawn_as_one_match_each_drawn_as_its_own(
    renderer: Renderer, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Deck sprites seen from below, flat-based ones and plain ones, interleaved back to
    front: past MAX_VARIANT_RUNS they are drawn in one run of the variant holding every
    feature (each sprite's data switching off what it lacks), and the picture is the one
    drawing each run with its own variant makes."""
    rng = np.random.default_rng(9)
    n = 90
    elevation = rng.uniform(0.1, 0.9, n)
    azimuth = rng.uniform(-0.5, 0.5, n)
    dist = np.sort(rng.uniform(800.0, 4000.0, n))[::-1]  # back to front
    centres = np.stack(
        [
            dist * np.cos(elevation) * np.sin(azimuth),
            dist * np.cos(elevation) * np.cos(azimuth),
            1000.0 + dist * np.sin(elevation),
        ],
        axis=1,
    )
    kind = np.arange(n) % 3  # 0 plain, 1 a deck's, 2 flat-based: a new variant every sprite
    z = centres[:, 2]
    batch = sprite_batch(centres.tolist(), rng.uniform(200.0, 500.0, n).tolist())
    batch = dataclasses.replace(
        batch,
        slab_m=np.where(
            (kind == 1)[:, None], np.stack([z - 100.0, z + 200.0], axis=1), np.nan
        ).astype(np.float32),
        base_m=np.where(kind == 2, z - 50.0, np.nan).astype(np.float32),
    )
    draw = SpriteDraw(batch, rng.uniform(0.3, 1.0, (n, 4)).astype(np.float32))
    cam = _camera(pitch_deg=30.0, fov_deg=120.0)
    drawn: list[int] = []
    real_runs = renderer_module._variant_runs
    limit = renderer_module.MAX_VARIANT_RUNS

    def counted(codes: np.ndarray) -> list[tuple[int, int, int]]:
        runs = real_runs(codes)
        drawn.append(len(runs))
        return runs

    monkeypatch.setattr(renderer_module, "_variant_runs", counted)
    with _near_scale(renderer, 1.0):
        renderer.render_frame(FrameScene(cam, _sky(), draw))
        merged = renderer.read("near").astype(int)
        monkeypatch.setattr(renderer_module, "MAX_VARIANT_RUNS", 10**6)
        renderer.render_frame(FrameScene(cam, _sky(), draw))
        apart = renderer.read("near").astype(int)
    assert drawn[0] <= 2 and drawn[1] > limit
    assert merged[..., 3].max() > 200
    assert np.abs(merged - apart).max() <= 1
