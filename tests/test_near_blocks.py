"""The near layer's blocks, kept from frame to frame (`gather.near_blocks`) with Harris's light
on them (`layout.near_scattered_light`): every frame must hold exactly the sprites, shares and
colours that gathering and shading them anew gives, whatever the drift, the rings and their
weights in a cross-fade."""

from __future__ import annotations

import dataclasses
from datetime import timedelta

import numpy as np
import pytest

from wxsky.app.camera_path import straight_and_level
from wxsky.engine.stages import SkyEngine
from wxsky.scene import gather as gather_module
from wxsky.scene import near_sets as near_sets_module
from wxsky.scene.camera import Camera
from wxsky.scene.clouds import BLOCK_SIZE_M
from wxsky.scene.gather import (
    NearBlocks,
    NearRing,
    _gather_near,
    advance_drift,
    clear_near_blocks,
    gather_blocks,
    gather_near,
    gather_near_blocks,
    near_blocks,
    zero_drift,
)
from wxsky.scene.layout import (
    SceneSettings,
    SpriteDraw,
    empty_ring,
    in_view,
    shade_for_eye,
    sort_order,
)
from wxsky.scene.near_sets import near_scattered_light, prepare_near
from wxsky.scene.shading_harris import LIGHT_REUSE_DEG, Scattered, scene_lights
from wxsky.scene.sky import sky_params
from wxsky.scene.sprites import SpriteBatch
from wxsky.settings.presets import load_preset
from wxsky.weather.state import CloudLayer, CloudType, WeatherState, WindLayer

PRESETS = (
    "fair-cumulus",
    "broken-stratocumulus",
    "overcast-stratus",
    "thunderstorm",
    "high-cirrus",
)


def _same_batch(a: SpriteBatch, b: SpriteBatch) -> None:
    for f in dataclasses.fields(SpriteBatch):
        x, y = getattr(a, f.name), getattr(b, f.name)
        assert x.dtype == y.dtype and x.shape == y.shape, f.name
        assert x.tobytes() == y.tobytes(), f.name


def _state(preset: str) -> WeatherState:
    return WeatherState().apply(load_preset(preset, ()))


@pytest.mark.parametrize("preset", PRESETS)
def test_kept_blocks_give_what_gathering_anew_gives(preset: str) -> None:
    state = _state(preset)
    drift0 = advance_drift(state, zero_drift(state), 600.0)
    old = NearRing((0.0, 0.0, 1500.0), drift0, 1.0)
    new = NearRing((1300.0, -250.0, 1500.0), advance_drift(state, drift0, 10.0), 1.0)
    cases = [
        (old,),
        (old._replace(weight=0.7), new._replace(weight=0.3)),
        (old._replace(weight=1e-9), new._replace(weight=1.0 - 1e-9)),
        (old._replace(weight=0.0), new._replace(weight=1.0)),  # a block left out: gathered anew
        (new,),
    ]
    for rings in cases:
        for seconds in (0.0, 1.0 / 30.0, 7.3):  # the set is reused as the layers drift on
            drift = advance_drift(state, drift0, seconds)
            for max_range_m in (None, 40_000.0):
                near, share = gather_near(state, drift, rings, 8000.0, max_range_m)
                want, want_share = _gather_near(state, drift, rings, 8000.0, max_range_m)
                _same_batch(near, want)
                assert share.dtype == want_share.dtype
                assert share.tobytes() == want_share.tobytes()


def test_one_set_of_blocks_serves_every_frame_until_the_rings_change() -> None:
    state = _state("fair-cumulus")
    drift = zero_drift(state)
    ring = (NearRing((0.0, 0.0, 1500.0), drift, 1.0),)
    _, _, first = gather_near_blocks(state, drift, ring, 8000.0, 40_000.0)
    _, _, again = gather_near_blocks(
        state, advance_drift(state, drift, 3.0), ring, 8000.0, 40_000.0
    )
    assert first is not None and again is first
    moved = (NearRing((5000.0, 0.0, 1500.0), drift, 1.0),)
    _, _, other = gather_near_blocks(state, drift, moved, 8000.0, 40_000.0)
    assert other is not None and other is not first


@pytest.mark.parametrize("preset", PRESETS)
def test_kept_light_shades_exactly_as_shading_anew(preset: str) -> None:
    state = _state(preset)
    sky = sky_params(state)
    drift = zero_drift(state)
    rings = (NearRing((0.0, 0.0, 1500.0), drift, 1.0),)
    eye = (150.0, -40.0, 1500.0)
    for seconds in (0.0, 2.0, 9.0):
        moved = advance_drift(state, drift, seconds)
        near, share, blocks = gather_near_blocks(state, moved, rings, 8000.0, 40_000.0)
        assert blocks is not None
        scattered = near_scattered_light(blocks, near, sky)
        order = sort_order(near, eye)
        kept = shade_for_eye(near, eye, sky, 40_000.0, "harris", None, share, order, scattered)
        anew = shade_for_eye(near, eye, sky, 40_000.0, "harris", None, share, order)
        _same_batch(kept.sprites, anew.sprites)
        assert kept.rgba.tobytes() == anew.rgba.tobytes()


def test_frames_along_a_flight_through_rebuilds_match_a_fresh_gather_and_shade() -> None:
    """The engine's near layer, frame by frame across ring rebuilds and cross-fades, against
    the straightforward gather and shading of the same rings."""
    layers = (
        CloudLayer(5.0, 1900.0, 2500.0, CloudType.CUMULUS),
        CloudLayer(6.0, 2600.0, 3000.0, CloudType.STRATOCUMULUS),
    )
    state = WeatherState(layers=layers, wind=(WindLayer(0.0, 250.0, 12.0),))
    settings = SceneSettings(max_near_sprites=0, far_band_m=0.0, shadow_map_px=0)
    path = straight_and_level(speed_mps=900.0, alt_m=1500.0)
    seen_fade = False
    worst = 0.0
    with SkyEngine(state, Camera((0.0, 0.0, 1500.0)), settings, ring_build="sync") as engine:
        for k in range(70):
            pose = path.at(k / 30.0)
            engine.set_camera(Camera(pose.position_m, pose.heading_deg, pose.pitch_deg))
            plan = engine.advance(1.0 / 30.0 if k else 0.0)
            rings = plan.rings.near_rings(plan.frame.camera, engine.drift)
            seen_fade |= len(rings) == 2
            eye = plan.frame.camera.position_m
            near, share = _gather_near(plan.state, engine.drift, rings, 8000.0, 40_000.0)
            sky = plan.frame.sky
            want = shade_for_eye(near, eye, sky, 40_000.0, settings.shading, share=share)
            seen = np.flatnonzero(in_view(want.sprites, plan.frame.camera))  # the rest: culled
            want = SpriteDraw(want.sprites.take(seen), want.rgba[seen])
            got = plan.frame.near
            _same_batch(got.sprites, want.sprites)
            # The kept light is the light of lights within LIGHT_REUSE_DEG of this sky's
            # (the sun moves on as the frames go): the colours it gives are those of light
            # made anew to within a fraction of a display level, and exact where it was made
            # for this very sky.
            worst = max(worst, float(np.abs(got.rgba - want.rgba).max()))
            assert np.abs(got.rgba - want.rgba).max() <= 0.5 / 255.0
    assert seen_fade
    print(f"largest difference from light made anew: {worst * 255:.3f}/255")


def test_a_new_rings_worker_prepares_the_near_sets_and_light_its_frames_ask_for() -> None:
    """`prepare_near`, run with a new ring: the set the ring's frames gather (alone, and in the
    cross-fade from the ring on show) and Harris's light on it are made already, and are the
    ones the frames then use."""
    state = _state("fair-cumulus")
    settings = SceneSettings(max_range_m=16_000.0)
    sky = sky_params(state)
    drift0 = zero_drift(state)
    drift1 = advance_drift(state, drift0, 30.0)
    shown = empty_ring((0.0, 0.0, 1500.0), settings.ring_radius_m, drift0)
    ring = empty_ring((1300.0, -250.0, 1500.0), settings.ring_radius_m, drift1)
    clear_near_blocks()
    alone = (NearRing(ring.geometry.centre_m, ring.drift, 1.0),)
    fading = (
        NearRing(shown.geometry.centre_m, shown.drift, 0.6),
        NearRing(ring.geometry.centre_m, ring.drift, 0.4),
    )
    with pytest.MonkeyPatch.context() as mp:
        made: list[object] = []
        real = gather_module._make_near_blocks
        mp.setattr(gather_module, "_make_near_blocks", lambda *a: made.append(a) or real(*a))
        shown_near = NearRing(shown.geometry.centre_m, shown.drift, 1.0)
        prepared = prepare_near(state, ring, shown_near, sky, settings)
        assert len(made) == 2  # the ring's own set, and the fade's
        assert [p.light is not None for p in prepared] == [True, True]
        lights = {}
        for rings in (alone, fading):
            blocks = near_blocks(state, drift1, rings, settings.ring_radius_m, 16_000.0)
            assert blocks is not None
            kept = near_sets_module._near_light.get(blocks)
            assert kept is not None  # its light is there before any frame
            lights[rings] = kept[0]
        # A frame of the fade, a little later, finds both: nothing is made in it.
        later = advance_drift(state, drift1, 2.0)
        for rings in (alone, fading):
            near, _, blocks = gather_near_blocks(
                state, later, rings, settings.ring_radius_m, 16_000.0
            )
            assert blocks is not None
            assert near_scattered_light(blocks, near, sky) is lights[rings]
        assert len(made) == 2


def _fair_cumulus_lit() -> tuple[
    WeatherState, SpriteBatch, np.ndarray, NearBlocks, Scattered | None
]:
    """fair-cumulus's near set around 1,500 m over the origin, and its light for the sky."""
    state = _state("fair-cumulus")
    drift = zero_drift(state)
    rings = (NearRing((0.0, 0.0, 1500.0), drift, 1.0),)
    near, share, blocks = gather_near_blocks(state, drift, rings, 8000.0, 40_000.0)
    assert blocks is not None
    return state, near, share, blocks, near_scattered_light(blocks, near, sky_params(state))


def test_kept_light_serves_a_sun_that_moved_less_than_the_reuse_angle() -> None:
    """A frame keeps the near layer's light while every light is within LIGHT_REUSE_DEG of
    the sky's; past that it makes it again. What the kept light gives stays close to light
    made anew."""
    state, near, share, blocks, made = _fair_cumulus_lit()
    eye = (150.0, -40.0, 1500.0)
    order = sort_order(near, eye)
    moved_deg = []
    for minutes in (0.5, 1.0, 20.0):
        later = dataclasses.replace(state, time_utc=state.time_utc + timedelta(minutes=minutes))
        sky = sky_params(later)
        lights = scene_lights(sky)
        assert made is not None
        cos = np.sum(lights.directions * made.directions, axis=1).clip(-1.0, 1.0)
        moved = float(np.degrees(np.arccos(cos)).max())
        moved_deg.append(moved)
        kept = near_scattered_light(blocks, near, sky, LIGHT_REUSE_DEG)
        assert kept is not None
        # Kept: the same rows, handed out under this sky's directions (shading then sees at
        # once that they are for its lights).
        assert (kept.rows is made.rows) == (moved < LIGHT_REUSE_DEG)
        assert kept.directions is lights.directions
        if kept.rows is made.rows:
            got = shade_for_eye(near, eye, sky, 40_000.0, "harris", None, share, order, kept)
            want = shade_for_eye(near, eye, sky, 40_000.0, "harris", None, share, order)
            assert np.abs(got.rgba - want.rgba).mean() < 0.25 / 255.0
            assert np.abs(got.rgba - want.rgba).max() < 4.0 / 255.0
    # The cases cover both sides of the angle.
    assert min(moved_deg) < LIGHT_REUSE_DEG < max(moved_deg)


def test_a_light_kept_for_some_lights_is_not_taken_where_exact_light_is_asked() -> None:
    """The frames of a sky step take the kept light without comparing its directions again;
    that shortcut holds only for as close as was asked: the ring's worker, asking for light
    made for exactly these lights, still gets it made."""
    state, near, _, blocks, made = _fair_cumulus_lit()
    later = dataclasses.replace(state, time_utc=state.time_utc + timedelta(minutes=0.5))
    sky = sky_params(later)
    assert made is not None
    assert not np.array_equal(scene_lights(sky).directions, made.directions)
    kept = near_scattered_light(blocks, near, sky, LIGHT_REUSE_DEG)
    assert kept is not None and kept.rows is made.rows
    for _ in range(3):  # the step's frames: the one light kept for the step's lights
        assert near_scattered_light(blocks, near, sky, LIGHT_REUSE_DEG) is kept
    exact = near_scattered_light(blocks, near, sky)
    assert exact is not None and exact.rows is not made.rows
    np.testing.assert_array_equal(exact.directions, scene_lights(sky).directions)


def test_after_a_clock_set_the_near_layer_shows_the_clouds_around_the_eye() -> None:
    """A clock set moves the clouds by months of wind (about 1e8 m); until a ring for the new
    time arrives, the near layer complements the old one. Its blocks are then chosen as the
    clouds stand now: chosen as they stood, they would be placed 1e8 m off and none shown."""
    state = _state("fair-cumulus")
    radius_m = SceneSettings().ring_radius_m
    centre = (0.0, 0.0, 1500.0)
    old = zero_drift(state)
    now = advance_drift(state, old, 150 * 86_400.0)  # five months of a 4 m/s wind
    moved_m = float(np.hypot(*np.subtract(now[0], old[0])))
    assert moved_m > 1e7
    near, share, _ = gather_near_blocks(state, now, (NearRing(centre, old, 1.0),), radius_m)
    dist = np.hypot(near.centre_m[:, 0] - centre[0], near.centre_m[:, 1] - centre[1])
    assert len(near) > 1000 and (share == 1.0).all()
    assert dist.max() < radius_m + BLOCK_SIZE_M * 2**0.5  # blocks reaching into the radius
    # The same as a ring built at the new time would have it complement.
    fresh, _, _ = gather_near_blocks(state, now, (NearRing(centre, now, 1.0),), radius_m)
    _same_batch(near, fresh)
    # A drift within the radius still chooses the blocks as they stood (no block both in the
    # ring and the near layer, nor in neither).
    nudged = advance_drift(state, old, 60.0)
    kept, _, _ = gather_near_blocks(state, nudged, (NearRing(centre, old, 1.0),), radius_m)
    _same_batch(kept, gather_blocks(state, nudged, centre, 0.0, radius_m, select_drift=old))


def test_a_set_key_made_in_another_process_finds_the_set_made_here() -> None:
    """A ring's worker process hands back near sets under their keys: a key's hash is kept
    for the frames' lookups, but not across processes, where strings hash otherwise."""
    import os
    import pickle
    import subprocess
    import sys

    state = _state("thunderstorm")
    drift = zero_drift(state)
    rings = (NearRing((0.0, 0.0, 1500.0), drift, 1.0),)
    keyed = gather_module.near_blocks_keyed(state, drift, rings, 8000.0, 40_000.0)
    assert keyed is not None
    key, blocks = keyed
    again = gather_module.near_blocks_keyed(
        state, advance_drift(state, drift, 1.0), rings, 8000.0, 40_000.0
    )
    assert again is not None and again[0] is key and again[1] is blocks  # the kept key
    code = (
        "import pickle, sys\n"
        "from wxsky.scene.gather import NearRing, near_blocks_keyed, zero_drift\n"
        "from wxsky.settings.presets import load_preset\n"
        "from wxsky.weather.state import WeatherState\n"
        "state = WeatherState().apply(load_preset('thunderstorm', ()))\n"
        "drift = zero_drift(state)\n"
        "keyed = near_blocks_keyed(state, drift, (NearRing((0.0, 0.0, 1500.0), drift, 1.0),),"
        " 8000.0, 40_000.0)\n"
        "from wxsky.scene.gather import SetKey\n"
        "sys.stdout.buffer.write(pickle.dumps((keyed[0], SetKey(('stratus', 1.5)))))\n"
    )
    env = {**os.environ, "PYTHONHASHSEED": "12345"}
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, check=True)
    theirs, named = pickle.loads(done.stdout)
    assert theirs == key and hash(theirs) == hash(key)
    # Strings hash otherwise in each process: a key holding one is equal here only if its
    # hash is worked out here.
    assert named == gather_module.SetKey(("stratus", 1.5))
    with gather_module._near_lock:
        assert gather_module._near_sets.get(theirs) is blocks
