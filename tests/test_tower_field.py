"""Which convective cells a frame draws as volumes, how old they are, and where they go among
the near sprites (scene/tower_field.py; issue 17, items 2 and 4)."""

from __future__ import annotations

import dataclasses
import math
from datetime import timedelta

import numpy as np
import pytest

from wxsky.scene.camera import Camera
from wxsky.scene.gather import NearRing, near_blocks
from wxsky.scene.layout import SceneSettings, build_frame
from wxsky.scene.sky import sky_params
from wxsky.scene.tower_field import (
    DENSITY_CHANNEL,
    TOWER_FADE_S,
    LayerEpoch,
    TowerClock,
    candidates,
    insert_points,
    lit_volume,
    occupied_part,
    place_towers,
)
from wxsky.settings.presets import load_preset
from wxsky.towers.volume import TowerSpec, TowerVolume
from wxsky.weather.state import WeatherState


def _state(preset: str) -> WeatherState:
    return WeatherState().apply(load_preset(preset))


def _set_at(state: WeatherState, minutes_ago: float = 0.0) -> TowerClock:
    epoch = LayerEpoch(state.time_utc - timedelta(minutes=minutes_ago), 50.0)
    return TowerClock(tuple(epoch for _ in state.layers), state.time_utc)


def _near(state: WeatherState):
    drift = tuple((0.0, 0.0) for _ in state.layers)
    blocks = near_blocks(state, drift, (NearRing((0.0, 0.0, 0.0), drift, 1.0),), 8000.0)
    assert blocks is not None
    return drift, blocks


def test_congestus_layers_make_cells_and_fair_cumulus_does_not() -> None:
    tc = _state("towering-cumulus")
    _, blocks = _near(tc)
    found = candidates(blocks, tc, _set_at(tc).epochs)
    ids = set(np.unique(blocks.batch.cloud_id).tolist())
    assert len(found) >= 10
    assert {c.cloud_id for c in found} <= ids
    # Every candidate hangs under its own cloud: its base at the layer's, its axis on the
    # cloud's sprites.
    for c in found[:5]:
        rows = blocks.batch.cloud_id == c.cloud_id
        assert c.spec.base_m == tc.layers[0].base_m
        xy = blocks.batch.centre_m[rows, :2].mean(axis=0)
        assert math.dist(xy, c.spec.axis_m) < 0.5 * c.spec.width_m
    fair = _state("fair-cumulus")
    _, fair_blocks = _near(fair)
    assert candidates(fair_blocks, fair, _set_at(fair).epochs) == ()
    # A layer without an epoch makes none.
    assert candidates(blocks, tc, (None,)) == ()


def test_a_cut_supply_stops_at_the_cut_and_cells_born_after_it_never_grow() -> None:
    tc = _state("towering-cumulus")
    _, blocks = _near(tc)
    set_utc = tc.time_utc
    cut = LayerEpoch(set_utc, 50.0, cut_utc=set_utc + timedelta(minutes=5))
    found = candidates(blocks, tc, (cut,))
    free = {c.cloud_id: c for c in candidates(blocks, tc, (LayerEpoch(set_utc, 50.0),))}
    assert 0 < len(found) < len(free)  # those born after the cut are gone
    for c in found:
        assert c.spec.born_s < 300.0
        assert c.spec.supplied_s == pytest.approx(300.0 - c.spec.born_s)
        assert math.isinf(free[c.cloud_id].spec.supplied_s)


def test_the_nearest_cells_within_the_budget_are_towers_aged_by_their_epoch() -> None:
    tc = _state("towering-cumulus")
    drift, blocks = _near(tc)
    sky = sky_params(tc)
    found = candidates(blocks, tc, _set_at(tc, 40.0).epochs)
    share = np.ones(len(blocks.batch), np.float32)
    eye = (300.0, -200.0, tc.observer.alt_m + 2.0)
    placed = place_towers(found, drift, share, eye, _set_at(tc, 40.0), sky, 4, 40_000.0)
    dists = sorted(math.dist((*c.spec.axis_m, c.spec.box_centre_m[2]), eye) for c in found)
    # Forty minutes on, every cell is born: the four nearest are the towers.
    assert [round(t.distance_m, 3) for t in sorted(placed.shows, key=lambda t: t.distance_m)] == [
        round(d, 3) for d in dists[:4]
    ]
    assert placed.left_out == len(found) - 4
    # A picture (no frame before it): every tower whole, none part-way.
    assert set(placed.drop_ids.tolist()) == {t.cloud_id for t in placed.shows}
    assert len(placed.fade_ids) == 0 and all(t.alpha == 1.0 for t in placed.shows)
    for t in placed.shows:
        assert t.age_s == pytest.approx(2400.0 - t.spec.born_s)
        assert 0.0 < t.haze < 1.0
        # Hazed as a sprite at its middle is (`sky.haze_share`): by the boundary layer's haze
        # for the part of the way under its top, the clear air's above; never more than the
        # boundary layer's haze all the way, nor less than the clear air's.
        up = t.centre_m[2] - eye[2]
        assert t.haze == pytest.approx(float(sky.haze_of(t.distance_m, up, eye[2])))
        assert 1.0 - math.exp(-t.distance_m / 60_000.0) <= t.haze
        assert t.haze <= 1.0 - math.exp(-t.distance_m / sky.haze_m) + 1e-12
    # Just set: cells not born yet are clear air (their clouds' sprites still go) and are
    # not drawn.
    now = place_towers(found, drift, share, eye, _set_at(tc, 0.0), sky, 4, 40_000.0)
    born = {c.cloud_id for c in found if c.spec.born_s <= 0.0}
    assert len(now.drop_ids) == 4
    assert {t.cloud_id for t in now.shows} == set(now.drop_ids.tolist()) & born
    assert len(now.shows) < 4  # some of the four nearest are still to be born


def test_a_cell_entering_or_leaving_the_budget_cross_fades_with_its_sprite_cloud() -> None:
    # The eye flies 4 km east at 100 m/s, a frame every 0.2 s, each frame given the last
    # one's fades: cells enter and leave the four nearest, and each cell's tower share and its
    # sprites' share change a little a frame, never all at once; hovering after, every cell
    # settles to all tower or all sprites within TOWER_FADE_S (no ghost of both stays).
    tc = _state("towering-cumulus")
    drift, blocks = _near(tc)
    sky = sky_params(tc)
    clock = _set_at(tc, 40.0)
    found = candidates(blocks, tc, clock.epochs)
    share = np.ones(len(blocks.batch), np.float32)
    ids = [c.cloud_id for c in found]
    dt = 0.2
    tower, sprites = [], []
    fades = None
    path = [*np.arange(0.0, 4000.0, 20.0), *([4000.0] * int(TOWER_FADE_S / dt + 1))]
    for x in path:
        eye = (float(x), 0.0, tc.observer.alt_m + 2.0)
        placed = place_towers(found, drift, share, eye, clock, sky, 4, 40_000.0, fades, dt)
        fades = dict(placed.fades)
        alpha = {t.cloud_id: t.alpha for t in placed.shows}
        kept = dict(zip(placed.fade_ids.tolist(), placed.fade_keep.tolist(), strict=True))
        dropped = set(placed.drop_ids.tolist())
        tower.append([alpha.get(i, 0.0) for i in ids])
        sprites.append([0.0 if i in dropped else kept.get(i, 1.0) for i in ids])
    t, s = np.asarray(tower), np.asarray(sprites)
    assert ((t[0] > 0) != (t[-1] > 0)).sum() >= 2  # cells came in and went out
    assert ((t > 0.05) & (t < 0.95)).any()  # and were seen part-way
    step = min(1.5 * dt / TOWER_FADE_S, 0.25)  # the smoothstep's steepest; a fade one sees
    assert np.abs(np.diff(t, axis=0)).max() <= step + 1e-6
    assert np.abs(np.diff(s, axis=0)).max() <= step + 1e-6
    # Where a cell is part tower, its sprites carry the rest: the two add up to one.
    assert np.allclose(t + s, 1.0, atol=1e-6)
    assert set(np.unique(t[-1])) <= {0.0, 1.0}


def test_the_eye_inside_a_cell_leaves_it_to_the_sprites() -> None:
    tc = _state("towering-cumulus")
    drift, blocks = _near(tc)
    found = candidates(blocks, tc, _set_at(tc, 40.0).epochs)
    share = np.ones(len(blocks.batch), np.float32)
    inside = found[0].spec.box_centre_m
    placed = place_towers(found, drift, share, inside, _set_at(tc, 40.0), sky_params(tc), 64, 4e4)
    assert found[0].cloud_id not in set(placed.drop_ids.tolist())
    assert len(placed.shows) == len(found) - 1


def test_a_frame_draws_towers_between_the_sprites_at_their_distance() -> None:
    tc = _state("towering-cumulus")
    drift = tuple((0.0, 0.0) for _ in tc.layers)
    cam = Camera((0.0, 0.0, tc.observer.alt_m + 2.0), heading_deg=104.0, pitch_deg=12.0)
    ring = NearRing(cam.position_m, drift, 1.0)
    sky = sky_params(tc)
    settings = SceneSettings(max_towers=5)
    plain = build_frame(tc, drift, cam, (ring,), sky, settings)
    frame = build_frame(tc, drift, cam, (ring,), sky, settings, towers=_set_at(tc, 40.0))
    assert plain.towers == () and len(frame.towers) == 5
    tower_ids = {t.cloud_id for t in frame.towers}
    assert not np.isin(frame.near.sprites.cloud_id, list(tower_ids)).any()
    assert np.isin(plain.near.sprites.cloud_id, list(tower_ids)).any()
    dist = np.linalg.norm(frame.near.sprites.centre_m - np.asarray(cam.position_m), axis=1)
    previous = -1
    for t in frame.towers:  # back to front
        assert t.insert_at >= previous
        previous = t.insert_at
        assert (dist[: t.insert_at] >= t.distance_m).all()
        assert (dist[t.insert_at :] <= t.distance_m).all()


def test_insert_points_on_a_descending_list() -> None:
    assert insert_points(np.array([9.0, 7.0, 5.0, 3.0]), [10.0, 6.0, 5.0, 1.0]) == [0, 2, 2, 4]


def test_occupied_part_is_the_cloudy_cells_a_cell_wider() -> None:
    d = np.zeros((16, 8, 4), np.float32)  # z, y, x
    assert occupied_part(d) == ((0.5, 0.5, 0.5), (0.5, 0.5, 0.5))
    d[3:5, 2, 1] = 0.9
    lo, hi = occupied_part(d)
    assert lo == pytest.approx((0 / 4, 1 / 8, 2 / 16))
    assert hi == pytest.approx((3 / 4, 4 / 8, 6 / 16))


def test_a_lit_step_holds_the_density_and_light_in_bytes() -> None:
    spec = TowerSpec(weather_seed=5, block=(0, 0), cell=0, mature_s=300.0)
    volume = TowerVolume(spec)
    sky = sky_params(_state("towering-cumulus"))
    lit = lit_volume(volume, 30, sky)
    density = volume.density_of_step(30)
    assert lit.texels.shape == (2, 64, 64, 64, 4) and lit.texels.dtype == np.uint8
    got = lit.texels[DENSITY_CHANNEL // 4][..., DENSITY_CHANNEL % 4]
    assert np.abs(got / 255.0 - density).max() <= 0.5 / 255.0 + 1e-6
    assert lit.step == 30 and lit.key == (spec, 30, lit.key[2])
    # The same step lit again is byte-identical; another sky's light is a different key.
    again = lit_volume(TowerVolume(spec), 30, sky)
    assert again.key == lit.key and np.array_equal(again.texels, lit.texels)
    dusk = dataclasses.replace(sky, sun=dataclasses.replace(sky.sun, elevation_deg=5.0))
    assert lit_volume(volume, 30, dusk).key != lit.key
