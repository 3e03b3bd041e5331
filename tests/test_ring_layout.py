"""The impostor ring's geometry and binning, and the layout stage (blocks, drift, sorting)."""

from __future__ import annotations

import math
from datetime import UTC, datetime

import numpy as np
import pytest
from sprite_helpers import sprite_batch

from wxsky.scene.camera import Camera
from wxsky.scene.clouds import BLOCK_SIZE_M, SpriteBatch
from wxsky.scene.gather import NearRing, advance_drift, gather_blocks, zero_drift
from wxsky.scene.layout import (
    SceneSettings,
    build_frame,
    build_ring,
    fade_by_range,
    in_view,
    shade_for_eye,
    sort_back_to_front,
)
from wxsky.scene.ring import RING_SIZE, RingGeometry, bin_far_sprites
from wxsky.scene.sky import sky_params
from wxsky.weather.state import CloudLayer, CloudType, WeatherState, WindLayer

R = 8000.0
TAN = math.tan(math.radians(22.5))


def _sprites(centres: np.ndarray, sizes: np.ndarray, rotations: np.ndarray | None = None):
    rot = 0.0 if rotations is None else rotations
    return sprite_batch(centres, np.asarray(sizes).reshape(-1), texture=4, rotation=rot)


def _polar(centre: tuple, az_deg: float, dist: float, dz: float) -> list[float]:
    a = math.radians(az_deg)
    return [centre[0] + dist * math.sin(a), centre[1] + dist * math.cos(a), centre[2] + dz]


def _keys(batch: SpriteBatch) -> set[bytes]:
    return {row.tobytes() for row in np.ascontiguousarray(batch.centre_m)}


def _state(**kw: object) -> WeatherState:
    layers = (
        CloudLayer(4, 1500.0, 2600.0, CloudType.CUMULUS),
        CloudLayer(6, 4000.0, 4600.0, CloudType.ALTOCUMULUS),
    )
    args: dict = {"layers": layers, "seed": 42, **kw}
    return WeatherState(**args)


# -- ring geometry ------------------------------------------------------------------------


def _geometry() -> RingGeometry:
    bottoms = tuple(-300.0 - 50 * i for i in range(RING_SIZE))
    tops = tuple(900.0 + 100 * i for i in range(RING_SIZE))
    return RingGeometry(
        centre_m=(1000.0, -2000.0, 1500.0), radius_m=R, bottom_m=bottoms, top_m=tops
    )


def test_ring_quads_sit_on_the_ring_facing_their_headings() -> None:
    geo = _geometry()
    c = np.asarray(geo.centre_m)
    quads = geo.corners_m()
    assert quads.shape == (8, 4, 3)
    for i in range(RING_SIZE):
        tl, tr, br, bl = quads[i]
        h = math.radians(45.0 * i)
        mid = (tl + tr) / 2.0 - c
        np.testing.assert_allclose(mid[:2], (R * math.sin(h), R * math.cos(h)), atol=1e-6)
        np.testing.assert_allclose(np.linalg.norm(tr - tl), 2.0 * R * TAN, rtol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(br - bl), 2.0 * R * TAN, rtol=1e-12)
        # Vertical quads spanning the window.
        np.testing.assert_allclose(tl[:2], bl[:2], atol=1e-9)
        np.testing.assert_allclose(tr[:2], br[:2], atol=1e-9)
        assert tl[2] == pytest.approx(c[2] + geo.top_m[i])
        assert bl[2] == pytest.approx(c[2] + geo.bottom_m[i])
        # Seen from the centre looking along heading i, tl is on the left.
        right = np.array([math.cos(h), -math.sin(h)])
        assert (tr - tl)[:2] @ right > 0.0
        # The corners are at R / cos(22.5°) from the centre, 22.5° either side.
        for corner, sign in ((tl, -1.0), (tr, 1.0)):
            rel = corner[:2] - c[:2]
            assert np.hypot(*rel) == pytest.approx(R / math.cos(math.radians(22.5)))
            az = math.degrees(math.atan2(rel[0], rel[1])) % 360.0
            assert (az - (45.0 * i + sign * 22.5) + 180.0) % 360.0 - 180.0 == pytest.approx(0.0)


def test_adjacent_quads_share_their_vertical_edges() -> None:
    quads = _geometry().corners_m()
    for i in range(RING_SIZE):
        j = (i + 1) % RING_SIZE
        np.testing.assert_allclose(quads[i, 1, :2], quads[j, 0, :2], atol=1e-6)  # tr == next tl
        np.testing.assert_allclose(quads[i, 2, :2], quads[j, 3, :2], atol=1e-6)  # br == next bl


def test_ring_projection_maps_the_quad_corners_to_the_image_corners() -> None:
    geo = _geometry()
    quads = geo.corners_m()
    for i in (0, 3, 6):
        vp = geo.projection_matrix(i) @ geo.view_matrix(i)
        ndc = []
        for corner in quads[i]:
            clip = vp @ np.append(corner, 1.0)
            ndc.append(clip[:2] / clip[3])
        # tl, tr, br, bl -> NDC (-1,-1), (1,-1), (1,1), (-1,1): y flipped, row 0 = top edge.
        np.testing.assert_allclose(ndc, [(-1, -1), (1, -1), (1, 1), (-1, 1)], atol=1e-9)


@pytest.mark.parametrize(
    ("offset", "expected"),
    [
        ((1199.0, 0.0, 0.0), False),
        ((1201.0, 0.0, 0.0), True),
        ((0.0, -1201.0, 0.0), True),
        ((848.0, 848.0, 0.0), False),  # 1199.3 m
        ((849.0, 849.0, 0.0), True),  # 1200.7 m
        ((0.0, 0.0, 159.0), False),
        ((0.0, 0.0, 161.0), True),
        ((0.0, 0.0, -161.0), True),
        ((1100.0, 0.0, -150.0), False),
    ],
)
def test_needs_regeneration_thresholds(offset: tuple, expected: bool) -> None:
    # 15 % of 8000 m horizontally = 1200 m, 2 % vertically = 160 m.
    geo = RingGeometry((500.0, 700.0, 2000.0), R, (-1.0,) * 8, (1.0,) * 8)
    eye = (500.0 + offset[0], 700.0 + offset[1], 2000.0 + offset[2])
    assert geo.needs_regeneration(eye) is expected


# -- binning ------------------------------------------------------------------------------

CENTRE = (300.0, -400.0, 1200.0)


def _bins_of(az_deg: float, size: float = 300.0, dist: float = 20_000.0) -> list[int]:
    batch = _sprites(np.array([_polar(CENTRE, az_deg, dist, 800.0)]), np.array([size]))
    _, bins = bin_far_sprites(batch, CENTRE, R)
    return [i for i in range(RING_SIZE) if len(bins[i])]


def test_binning_by_wedge() -> None:
    assert _bins_of(0.0) == [0]
    assert _bins_of(45.0) == [1]
    assert _bins_of(350.0) == [0]
    assert _bins_of(190.0) == [4]
    # On a wedge boundary: both neighbours.
    assert _bins_of(22.5) == [0, 1]
    assert _bins_of(337.5) == [0, 7]
    assert _bins_of(202.5) == [4, 5]
    # A sprite whose half-width reaches over the boundary goes into both too.
    assert _bins_of(21.0, size=1500.0) == [0, 1]
    assert _bins_of(21.0, size=100.0) == [0]


def _random_far(rng: np.random.Generator, n: int) -> SpriteBatch:
    az = rng.uniform(0.0, 360.0, n)
    dist = rng.uniform(R, 40_000.0, n)
    dz = rng.uniform(-1500.0, 4000.0, n)
    centres = np.array([_polar(CENTRE, a, d, z) for a, d, z in zip(az, dist, dz, strict=True)])
    return _sprites(centres, rng.uniform(150.0, 1600.0, n), rng.uniform(0.0, 2 * np.pi, n))


def _view_extent(batch: SpriteBatch, i: int) -> tuple[np.ndarray, ...]:
    """Impostor i's view of each sprite from the centre: (x, y, depth, half extent)."""
    h = math.radians(45.0 * i)
    rel = batch.centre_m - np.asarray(CENTRE)
    x = rel[:, 0] * math.cos(h) - rel[:, 1] * math.sin(h)
    depth = rel[:, 0] * math.sin(h) + rel[:, 1] * math.cos(h)
    rot = batch.rotation_rad.astype(np.float64)
    half = 0.5 * batch.size_m * (np.abs(np.cos(rot)) + np.abs(np.sin(rot)))
    return x, rel[:, 2], depth, half


def test_fitted_windows_contain_every_binned_sprite() -> None:
    far = _random_far(np.random.default_rng(3), 400)
    geo, bins = bin_far_sprites(far, CENTRE, R)
    assert sum(len(b) for b in bins) >= len(far)
    for i in range(RING_SIZE):
        assert len(bins[i]) > 0
        _, y, depth, half = _view_extent(bins[i], i)
        assert np.all(depth > 0.0)
        scale = R / depth
        assert geo.bottom_m[i] <= np.min((y - half) * scale) + 1e-6
        assert geo.top_m[i] >= np.max((y + half) * scale) - 1e-6
        # Fitted, not merely huge: no more than 0.8 sprite of margin.
        reach = 0.8 * bins[i].size_m
        assert geo.top_m[i] <= np.max((y + reach) * scale)
        assert geo.bottom_m[i] >= np.min((y - reach) * scale)


def test_every_sprite_overlapping_a_quad_is_in_its_bin() -> None:
    far = _random_far(np.random.default_rng(4), 400)
    _, bins = bin_far_sprites(far, CENTRE, R)
    for i in range(RING_SIZE):
        x, _, depth, half = _view_extent(far, i)
        w = R * TAN
        visible = (depth > 0.0) & ((x - half) * R / depth <= w) & ((x + half) * R / depth >= -w)
        assert visible.sum() > 10
        assert _keys(far.take(np.nonzero(visible)[0])) <= _keys(bins[i])


def test_empty_bins_get_a_square_default_window() -> None:
    batch = _sprites(np.array([_polar(CENTRE, 0.0, 20_000.0, 500.0)]), np.array([200.0]))
    geo, _ = bin_far_sprites(batch, CENTRE, R)
    for i in range(1, RING_SIZE):
        assert geo.bottom_m[i] == pytest.approx(-R * TAN)
        assert geo.top_m[i] == pytest.approx(R * TAN)
    assert geo.centre_m == CENTRE and geo.radius_m == R


# -- blocks, drift, sorting ---------------------------------------------------------------


def test_near_and_far_partition_the_full_range() -> None:
    state = _state()
    drift = ((130.0, -2210.0), (5000.0, 75.0))
    centre = (1234.0, -567.0, 1000.0)
    near = gather_blocks(state, drift, centre, 0.0, R)
    far = gather_blocks(state, drift, centre, R, 20_000.0)
    full = gather_blocks(state, drift, centre, 0.0, 20_000.0)
    kn, kf, kfull = _keys(near), _keys(far), _keys(full)
    assert len(kn) == len(near) and len(kf) == len(far)  # no duplicates
    assert len(near) > 0 and len(far) > len(near)
    assert not kn & kf
    assert kn | kf == kfull
    assert len(near) + len(far) == len(full)
    # Near blocks reach at most one block diagonal (plus a cloud radius) past the ring.
    d_near = np.hypot(*(near.centre_m[:, :2] - centre[:2]).T)
    assert d_near.max() < R + math.sqrt(2) * BLOCK_SIZE_M + 1000.0
    d_far = np.hypot(*(far.centre_m[:, :2] - centre[:2]).T)
    assert d_far.min() > R - 1000.0


def test_range_is_measured_to_the_nearest_point_of_each_block() -> None:
    state = _state(layers=(CloudLayer(8, 1500.0, 2600.0, CloudType.CUMULUS),))
    # Centre in the middle of block (0, 0): a range just under half a block only reaches it.
    centre = (2000.0, 2000.0, 0.0)
    only = gather_blocks(state, zero_drift(state), centre, 0.0, 1999.0)
    assert len(only) > 0
    x, y = only.centre_m[:, 0], only.centre_m[:, 1]
    assert x.mean() == pytest.approx(2000.0, abs=400.0)
    assert y.mean() == pytest.approx(2000.0, abs=400.0)
    # Just over half a block also takes the four edge neighbours.
    more = gather_blocks(state, zero_drift(state), centre, 0.0, 2001.0)
    assert len(more) > 4 * len(only)
    assert _keys(only) <= _keys(more)


def test_drift_moves_sprites_by_exactly_the_offset() -> None:
    state = _state()
    d = ((1234.5, -987.25), (-300.0, 4100.0))
    centre = (-2500.0, 800.0, 1000.0)
    # A layer that drifted by (dx, dy), seen from a centre that moved with it, is the still
    # layer seen from the old centre, every sprite moved by (dx, dy).
    for li, (dx, dy) in enumerate(d):
        layer_state = WeatherState(layers=(state.layers[li],), seed=state.seed)
        base = gather_blocks(layer_state, ((0.0, 0.0),), centre, 0.0, 12_000.0)
        moved_centre = (centre[0] + dx, centre[1] + dy, centre[2])
        moved = gather_blocks(layer_state, ((dx, dy),), moved_centre, 0.0, 12_000.0)
        assert len(moved) == len(base) > 0
        # Bit-exact: the same sprites, each moved by the offset.
        np.testing.assert_array_equal(moved.centre_m, base.centre_m + np.array([dx, dy, 0.0]))
        np.testing.assert_array_equal(moved.size_m, base.size_m)


def test_advance_drift_integrates_the_wind_at_mid_layer() -> None:
    state = _state(
        wind=(
            WindLayer(1050.0, 360.0, 10.0),  # from the north: air moves south
            WindLayer(3050.0, 90.0, 20.0),  # from the east: air moves west
            WindLayer(5550.0, 270.0, 8.0),  # from the west: air moves east
        )
    )
    # Cumulus 1500-2600 -> mid 2050, halfway between the first two levels: (-10, -5) m/s.
    # Altocumulus 4000-4600 -> mid 4300, halfway from (-20, 0) to (8, 0): (-6, 0) m/s.
    drift = advance_drift(state, zero_drift(state), 10.0)
    np.testing.assert_allclose(drift, [(-100.0, -50.0), (-60.0, 0.0)], atol=1e-9)
    drift = advance_drift(state, drift, 5.0)
    np.testing.assert_allclose(drift, [(-150.0, -75.0), (-90.0, 0.0)], atol=1e-9)
    # A drift for another layer count starts again from zero.
    np.testing.assert_allclose(
        advance_drift(state, ((1e6, 1e6),), 1.0), [(-10, -5), (-6, 0)], atol=1e-9
    )
    calm = _state()
    assert advance_drift(calm, zero_drift(calm), 100.0) == ((0.0, 0.0), (0.0, 0.0))


def test_sort_back_to_front_and_stability() -> None:
    eye = (0.0, 0.0, 0.0)
    centres = np.array([[0, 100, 0], [0, 300, 0], [300, 0, 0], [0, 200, 0], [0, -300, 0]], float)
    batch = _sprites(centres, np.array([1.0, 2.0, 3.0, 4.0, 5.0]))
    out = sort_back_to_front(batch, eye)
    # The three at 300 m keep their original order, then 200 m, then 100 m.
    np.testing.assert_array_equal(out.size_m, [2.0, 3.0, 5.0, 4.0, 1.0])
    state = _state()
    sprites = gather_blocks(state, zero_drift(state), (0.0, 0.0, 1000.0), 0.0, 12_000.0)
    eye2 = (500.0, -300.0, 900.0)
    draw = shade_for_eye(sprites, eye2, sky_params(state), 40_000.0)
    d = np.linalg.norm(draw.sprites.centre_m - np.asarray(eye2), axis=1)
    assert len(draw) == len(sprites) and draw.rgba.shape == (len(sprites), 4)
    assert np.all(np.diff(d) <= 0.0)
    assert np.all(np.isfinite(draw.rgba)) and np.all((draw.rgba >= 0) & (draw.rgba <= 1))


def test_fade_by_range_hazes_and_fades_distant_sprites() -> None:
    state = _state(time_utc=datetime(2026, 6, 21, 11, 0, tzinfo=UTC), visibility_m=5000.0)
    sky = sky_params(state)
    dists = np.array([10.0, 10_000.0, 29_000.0, 35_000.0, 40_000.0, 45_000.0])
    batch = _sprites(np.stack([np.zeros(6), dists, np.zeros(6)], axis=1), np.full(6, 500.0))
    rgba = np.tile(np.float32([0.0, 0.0, 0.0, 1.0]), (6, 1))
    out = fade_by_range(rgba, batch, (0.0, 0.0, 0.0), sky, 40_000.0)
    # Alpha untouched out to 75 % of the range, zero from the range on, in between between.
    np.testing.assert_allclose(out[:3, 3], 1.0)
    assert 0.0 < out[3, 3] < 1.0
    np.testing.assert_allclose(out[4:, 3], 0.0)
    # Black sprites take the haze's colour with distance: 1 - exp(-d / haze), Koschmieder's
    # (at the visibility, 2 % of their contrast is left).
    haze = 1.0 - np.exp(-dists / sky.haze_m)
    np.testing.assert_allclose(out[:, :3], haze[:, None] * np.asarray(sky.haze_rgb), rtol=1e-5)
    assert np.exp(-5000.0 / sky.haze_m) == pytest.approx(0.02, rel=1e-3)
    # Under a part-clouded sky the haze is the horizon's colour; greyed as cover closes.
    assert sky.haze_rgb == sky.horizon_rgb or sky.cover > 0.6
    assert np.all(rgba[:, 3] == 1.0)  # input not modified


def test_build_ring_and_frame_use_the_ring_centre() -> None:
    state = _state()
    sky = sky_params(state)
    settings = SceneSettings(ring_radius_m=R, max_range_m=20_000.0)
    centre = (700.0, 900.0, 1000.0)
    drift = zero_drift(state)
    ring = build_ring(state, drift, centre, sky, settings)
    far = gather_blocks(state, drift, centre, R, settings.max_range_m)
    assert ring.geometry.centre_m == centre and ring.drift == drift
    assert len(ring.impostors) == RING_SIZE
    binned = set().union(*(_keys(d.sprites) for d in ring.impostors))
    assert binned == _keys(far)
    cam = Camera((1500.0, 400.0, 1100.0), heading_deg=30.0, width_px=32, height_px=18)
    frame = build_frame(state, drift, cam, (NearRing(centre, drift, 1.0),), sky, settings)
    near = gather_blocks(state, drift, centre, 0.0, R)
    # What is in view of the camera of what the ring's centre leaves to the near layer.
    in_sight = near.take(in_view(near, cam))
    assert 0 < len(in_sight) < len(near)
    assert _keys(frame.near.sprites) == _keys(in_sight)
    d = np.linalg.norm(frame.near.sprites.centre_m - np.asarray(cam.position_m), axis=1)
    assert np.all(np.diff(d) <= 0.0)  # sorted for the camera, not the ring centre
