"""What keeps the near layer's fill rate down without changing its look: sprites drawn as
the convex polygon around their texture's support, the far band at the impostors' texel
density, and (as an option) Wang's single-sprite LOD for far near clouds."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from sprite_helpers import sprite_batch

from wxsky.render.renderer import Renderer
from wxsky.render.sprite_sheet import (
    CELL_PX,
    MIP_LEVELS,
    SUPPORT_LEVELS,
    load_sheet,
    polygon_area,
    polygon_corners,
    support_polygons,
    support_radii,
)
from wxsky.scene.camera import Camera
from wxsky.scene.cloud_lod import collapse_far_clouds
from wxsky.scene.layout import FrameScene, SpriteDraw
from wxsky.scene.sky import sky_params
from wxsky.scene.sprites import SpriteBatch
from wxsky.scene.texture_slots import SHEET_CELLS, TEX_FLAT_BOTTOM, TEX_FOG, TEX_PUFFY, TEX_WISPY
from wxsky.weather.state import WeatherState

SKY = sky_params(WeatherState())


def _batch(centres: list, sizes: list, cloud: list, texture: int = TEX_PUFFY[0], rot=0.0):
    return sprite_batch(centres, sizes, texture=texture, rotation=rot, cloud_id=cloud)


def test_support_radius_holds_every_visible_texel() -> None:
    level = load_sheet()[0]
    radii = support_radii()
    yy, xx = np.mgrid[0:CELL_PX, 0:CELL_PX]
    centre = (CELL_PX - 1) / 2.0
    radius = np.hypot(xx - centre, yy - centre) / (CELL_PX / 2.0)
    for slot in range(SHEET_CELLS * SHEET_CELLS):
        row, col = divmod(slot, SHEET_CELLS)
        alpha = level[row * CELL_PX : (row + 1) * CELL_PX, col * CELL_PX : (col + 1) * CELL_PX, 3]
        assert radius[alpha > 0].max() < radii[slot] <= math.sqrt(2.0)
        assert radii[slot] < 1.0  # every shipped texture saves fill: none reaches the corners


TURNING = (TEX_FLAT_BOTTOM[0], TEX_FOG[0])


def _cell(level: np.ndarray, slot: int) -> np.ndarray:
    cell = level.shape[0] // SHEET_CELLS
    row, col = divmod(slot, SHEET_CELLS)
    return level[row * cell : (row + 1) * cell, col * cell : (col + 1) * cell]


@pytest.mark.parametrize("depth", [SUPPORT_LEVELS, MIP_LEVELS])
def test_a_support_polygon_holds_every_texel_a_sprite_can_read(depth: int) -> None:
    # Every corner of every shown texel's square on the levels read, with the bilinear
    # filter's half texel beyond it, lies within the polygon, but where the octagon the
    # sprites used to be drawn as (around the support disc of the full-size level) or the cell
    # cuts it: the polygon is never larger than those.
    levels = load_sheet()
    polygons = support_polygons(levels, TURNING, depth)
    slots = SHEET_CELLS * SHEET_CELLS
    assert polygons.shape == (slots + 1, 8, 2)
    radii = [*support_radii(levels), max(support_radii(levels)[s] for s in TURNING)]
    angles = np.radians(45.0 * np.arange(8))
    normals = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    along_axis = np.arange(8) % 2 == 0
    for k, strip in enumerate(polygons):
        ring = polygon_corners(strip)
        assert polygon_area(ring) > 0.0, k  # counter-clockwise, and not empty
        reach = (ring @ normals.T).max(axis=0)  # how far the polygon goes each way
        cap = np.where(along_axis, min(radii[k], 1.0), radii[k])
        assert np.all(reach <= cap + 1e-5), k
        for level in levels[:depth]:
            cell = level.shape[0] // SHEET_CELLS
            if k < slots:
                shown = _cell(level, k)[..., 3] > 0
            else:
                shown = (_cell(level, TURNING[0])[..., 3] > 0) | (
                    _cell(level, TURNING[1])[..., 3] > 0
                )
            yy, xx = np.nonzero(shown)
            texel = 2.0 / cell
            centres = np.stack([(xx + 0.5) * texel - 1.0, 1.0 - (yy + 0.5) * texel], axis=1)
            for corner in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                along = (centres + np.asarray(corner) * texel) @ normals.T
                inside = (along <= reach + 1e-5) | (along > cap - 1e-5)
                assert inside.all(), (k, level.shape, np.argwhere(~inside)[:3])


def test_support_polygons_save_fill_where_a_texture_is_not_round() -> None:
    polygons = support_polygons(None, TURNING)
    radii = support_radii()
    octagon = [8.0 * math.tan(math.radians(22.5)) * r * r for r in radii]
    areas = [polygon_area(polygon_corners(p)) for p in polygons]
    share = [a / o for a, o in zip(areas[:-1], octagon, strict=True)]
    assert share[TEX_FLAT_BOTTOM[0]] < 0.75  # the flat base's empty half
    assert max(share[s] for s in TEX_WISPY) < 0.65
    assert np.mean([share[s] for s in TEX_PUFFY]) < 0.85
    assert all(s <= 1.0 + 1e-6 for s in share)
    # The turning sprite's polygon holds both of its textures'.
    assert areas[-1] >= max(areas[s] for s in TURNING) - 1e-6


def _drawn_alpha(renderer: Renderer, cam: Camera, draw: SpriteDraw) -> float:
    old = renderer.near_scale
    renderer.near_scale = 1.0
    try:
        renderer.render_frame(FrameScene(cam, SKY, draw))
        return float(renderer.read("near")[..., 3].astype(np.float64).sum())
    finally:
        renderer.near_scale = old


def _texture_alpha(slot: int) -> float:
    return float(_cell(load_sheet()[0], slot)[..., 3].astype(np.float64).sum())


@pytest.mark.gl
@pytest.mark.parametrize(
    "slot", [TEX_FLAT_BOTTOM[0], TEX_FOG[0], TEX_PUFFY[2], TEX_PUFFY[4], 12, TEX_WISPY[3]]
)
@pytest.mark.parametrize("rotation", [0.0, 0.7])
def test_a_polygon_sprite_loses_none_of_its_texture(
    renderer: Renderer, slot: int, rotation: float
) -> None:
    # A sprite one texel per pixel: its drawn alpha adds up to its texture's.
    cam = Camera((0.0, 0.0, 0.0), 0.0, 0.0, fov_deg=90.0, width_px=257, height_px=257)
    size_m = 1000.0 * CELL_PX / 128.5  # 128 px across at 1000 m with a 90° view of 257 px
    draw = SpriteDraw(
        _batch([(0, 1000, 0)], [size_m], [1], slot, rotation), np.ones((1, 4), np.float32)
    )
    assert _drawn_alpha(renderer, cam, draw) == pytest.approx(_texture_alpha(slot), rel=0.02)


@pytest.mark.gl
@pytest.mark.parametrize("slot", [TEX_FLAT_BOTTOM[0], TEX_FOG[1], TEX_PUFFY[2], TEX_WISPY[3]])
@pytest.mark.parametrize("rotation", [0.0, 0.7])
def test_a_quad_sprite_wide_enough_for_the_fine_box_loses_none_of_its_texture(
    renderer: Renderer, slot: int, rotation: float
) -> None:
    # The far band's and impostors' quads take the bounding box of the polygon set the
    # sprite's size picks, as polygons do: at one texel per pixel, the fine set's.
    cam = Camera((0.0, 0.0, 0.0), 0.0, 0.0, fov_deg=90.0, width_px=257, height_px=257)
    size_m = 1000.0 * CELL_PX / 128.5
    draw = SpriteDraw(
        _batch([(0, 1000, 0)], [size_m], [1], slot, rotation), np.ones((1, 4), np.float32)
    )
    target = renderer._target("quad_probe", 257, 257)
    view, proj = cam.view_matrix(), cam.projection_matrix()
    renderer._draw_sprites(target, draw, cam.position_m, view, proj, shape="quad")
    drawn = float(renderer.read("quad_probe")[..., 3].astype(np.float64).sum())
    assert drawn == pytest.approx(_texture_alpha(slot), rel=0.02)


@pytest.mark.gl
@pytest.mark.parametrize("rotation", [0.0, 0.7])
def test_a_flat_bottomed_sprite_turning_round_loses_neither_texture(
    renderer: Renderer, rotation: float
) -> None:
    # Seen 36.87° up (sine 0.6), half-way through its turn (ROUND_FROM 0.45, ROUND_TO 0.75):
    # it shows half of each texture, from the union of their polygons.
    cam = Camera((0.0, 0.0, 0.0), 0.0, math.degrees(math.asin(0.6)), 0.0, 90.0, 257, 257)
    size_m = 1000.0 * CELL_PX / 128.5
    draw = SpriteDraw(
        _batch([(0, 800, 600)], [size_m], [1], TEX_FLAT_BOTTOM[0], rotation),
        np.ones((1, 4), np.float32),
    )
    both = 0.5 * (_texture_alpha(TURNING[0]) + _texture_alpha(TURNING[1]))
    assert _drawn_alpha(renderer, cam, draw) == pytest.approx(both, rel=0.02)


@pytest.mark.gl
def test_the_far_band_at_impostor_density_looks_the_same(renderer: Renderer) -> None:
    rng = np.random.default_rng(5)
    n = 400
    centres = np.column_stack(
        [rng.uniform(-6000, 6000, n), rng.uniform(2000, 9000, n), rng.uniform(1200, 2000, n)]
    )
    eye = (0.0, 0.0, 1000.0)
    order = np.argsort(-np.linalg.norm(centres - eye, axis=1))
    batch = _batch(centres[order].tolist(), [600.0] * n, list(range(n)))
    rgba = np.tile(np.float32([0.9, 0.9, 0.95, 0.8]), (n, 1))
    rgba[:, :3] *= rng.uniform(0.6, 1.0, (n, 1)).astype(np.float32)
    draw = SpriteDraw(batch, rgba)
    cam = Camera(eye, 0.0, 8.0, fov_deg=60.0, width_px=1280, height_px=720)
    far = int(np.count_nonzero(np.linalg.norm(batch.centre_m - eye, axis=1) >= 3000.0))
    assert 0 < far < n

    def over_grey(frame: FrameScene) -> np.ndarray:
        renderer.render_frame(frame)
        near = renderer.read("near").astype(np.float64)
        return near[..., :3] + (255.0 - near[..., 3:4]) * 0.5  # premultiplied over mid-grey

    whole = over_grey(FrameScene(cam, SKY, draw))
    banded = over_grey(FrameScene(cam, SKY, draw, near_far_count=far))
    assert renderer.layer_size("near_far")[0] < renderer.layer_size("near")[0]
    diff = np.abs(whole - banded)
    assert diff.mean() < 1.0 and np.percentile(diff, 99) < 16, (
        diff.mean(),
        np.percentile(diff, 99),
    )


def test_lod_collapses_far_clouds_to_one_sprite_of_their_colour() -> None:
    # Two clouds of 3 sprites: one 2 km away, one 9 km away.
    centres = [(0, 2000, 0), (100, 2000, 50), (-100, 2000, 0)]
    centres += [(0, 9000, 0), (150, 9000, 60), (-150, 9000, 0)]
    batch = _batch(centres, [300.0] * 6, [1, 1, 1, 2, 2, 2])
    rgba = np.array(
        [[1, 0, 0, 1], [1, 0, 0, 1], [1, 0, 0, 1], [0.2, 0.4, 0.6, 1], [0.4, 0.4, 0.6, 1],
         [0.6, 0.4, 0.6, 0.5]], np.float32,
    )  # fmt: skip
    out = collapse_far_clouds(batch, rgba, (0.0, 0.0, 0.0), 4000.0, 1000.0)
    assert out.lod_clouds == 1 and len(out.sprites) == 4
    near = out.sprites.cloud_id == 1
    np.testing.assert_array_equal(out.rgba[near], rgba[:3])
    one = ~near
    assert out.sprites.centre_m[one][0, 1] == pytest.approx(9000.0)
    weights = np.array([1.0, 1.0, 0.5])
    np.testing.assert_allclose(
        out.rgba[one][0, :3], (weights @ rgba[3:, :3]) / weights.sum(), atol=1e-6
    )
    assert out.rgba[one][0, 3] == 1.0 and out.sprites.size_m[one][0] > 300.0


def test_lod_cross_fades_in_its_band_and_leaves_flat_clouds_alone() -> None:
    batch = _batch([(0, 4500, 0), (50, 4500, 0)], [300.0, 300.0], [3, 3])
    rgba = np.ones((2, 4), np.float32)
    out = collapse_far_clouds(batch, rgba, (0.0, 0.0, 0.0), 4000.0, 1000.0)
    assert len(out.sprites) == 3  # both sprites and the one, mid-fade
    parts, one = out.rgba[:2, 3], out.rgba[2, 3]
    assert 0.0 < one < 1.0 and np.allclose(parts, 1.0 - one)
    flat = dataclasses.replace(batch, flat=np.ones(2, np.bool_))
    kept = collapse_far_clouds(flat, rgba, (0.0, 0.0, 0.0), 1000.0, 100.0)
    assert kept.lod_clouds == 0 and len(kept.sprites) == 2


def test_impostor_lod_puts_one_sprite_per_far_cloud_into_the_ring() -> None:
    from wxsky.scene.gather import zero_drift
    from wxsky.scene.layout import SceneSettings, build_ring
    from wxsky.settings.presets import load_preset

    state = WeatherState().apply(load_preset("fair-cumulus", ()))
    centre = (0.0, 0.0, state.observer.alt_m + 2.0)
    settings = SceneSettings(max_range_m=30_000.0)

    def far_part(lod_m: float) -> tuple[SpriteBatch, SpriteBatch]:
        # One impostor (a cloud on a wedge's edge is in both neighbours).
        ring = build_ring(
            state,
            zero_drift(state),
            centre,
            sky_params(state),
            dataclasses.replace(settings, impostor_lod_m=lod_m),
        )
        batch = ring.impostors[3].sprites
        dist = np.linalg.norm(batch.centre_m - np.asarray(centre), axis=1)
        return batch.take(dist > 18_000.0), batch.take(dist < 15_000.0)

    (far_lod, near_lod), (far_all, near_all) = far_part(16_000.0), far_part(0.0)
    assert len(far_lod) and len(np.unique(far_lod.cloud_id)) == len(far_lod)  # one a cloud
    assert 10 * len(far_lod) < len(far_all)
    np.testing.assert_array_equal(near_lod.centre_m, near_all.centre_m)  # nearer: untouched
