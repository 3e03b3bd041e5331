"""The ring's rebuild schedule (`wxsky.engine.ring_schedule`): when a rebuild starts and why, one
impostor per frame over 8 frames into the other texture set, the cross-fade, and the near
layer's share of each ring while the two fade."""

from __future__ import annotations

import dataclasses
import itertools
import math
import os
import threading
from datetime import timedelta
from typing import Any

import numpy as np
import pytest
from sprite_helpers import sprite_batch

from wxsky.engine.ring_schedule import (
    FIRST_SECONDS_PER_UNIT,
    MAX_SLICES,
    RETRY_AFTER_S,
    RING_WEATHER_GAP_S,
    Builder,
    RingPolicy,
    RingSchedule,
)
from wxsky.scene.camera import Camera
from wxsky.scene.gather import Drift, NearRing, gather_near, zero_drift
from wxsky.scene.layout import RingScene, SpriteDraw, empty_ring
from wxsky.scene.ring import RING_SIZE, WINDOW_FILL_COST, RingGeometry, impostor_costs
from wxsky.scene.sky import SkyParams, sky_params
from wxsky.weather.state import CloudLayer, CloudType, WeatherState, WindLayer

R = 8000.0
DT = 1.0 / 30.0
STATE = WeatherState(layers=(CloudLayer(4.0, 1500.0, 2200.0, CloudType.CUMULUS),), wind=())
SKY = sky_params(STATE)
DRIFT = zero_drift(STATE)


def quick_build(state: WeatherState, drift: Drift, centre: tuple, sky: SkyParams) -> RingScene:
    return empty_ring(centre, R, drift)


def cam(x: float = 0.0, z: float = 1500.0) -> Camera:
    return Camera(position_m=(x, 0.0, z))


def events(frame: object) -> list[str]:
    return [e.event for e in frame.events]  # type: ignore[attr-defined]


def test_a_rebuild_renders_one_impostor_per_frame_then_fades() -> None:
    s = RingSchedule(quick_build, R, mode="sync", fade_s=0.2)
    frames = [s.step(STATE, DRIFT, cam(), SKY, DT) for _ in range(20)]
    assert events(frames[0]) == ["ring_rebuild_start", "impostor_rendered"]
    assert frames[0].events[0].fields["reason"] == "initial"
    for k in range(RING_SIZE):
        assert frames[k].render == (k,) and frames[k].render_set == 1
        assert frames[k].current is None and frames[k].fade == 0.0
    assert events(frames[7])[-1] == "ring_rebuild_done"
    assert events(frames[8]) == ["crossfade_start"]
    assert all(len(f.render) <= 1 for f in frames)
    fades = [f.fade for f in frames[8:]]
    # 0.2 s at 30 fps: six steps of 1/6, the sixth completing the fade and swapping sets.
    np.testing.assert_allclose(fades[:5], np.arange(1, 6) / 6.0)
    assert events(frames[13]) == ["crossfade_done"]
    assert frames[13].current is not None and frames[13].current_set == 1
    assert frames[13].fade == 0.0 and frames[13].incoming is None
    assert all(not f.events for f in frames[14:])
    versions = [f.version for f in frames]
    assert versions == sorted(versions) and versions[13] > versions[7]


def sprite_build(n: int) -> Builder:
    """A ring whose every impostor holds n equal sprites 20 km out, in its own direction."""

    def build(state: WeatherState, drift: Drift, centre: tuple, sky: SkyParams) -> RingScene:
        ring = empty_ring(centre, R, drift)
        draws = []
        for i in range(RING_SIZE):
            _right, _up, fwd = ring.geometry.axes(i)
            centres = np.asarray(centre) + fwd * np.linspace(20_000.0, 19_000.0, n)[:, None]
            draws.append(SpriteDraw(sprite_batch(centres, 200.0), np.ones((n, 4), np.float32)))
        return dataclasses.replace(ring, impostors=tuple(draws))

    return build


def sliced_schedule(n: int, **kw: Any) -> RingSchedule:
    """A sliced schedule past its first ring (sliced like any other), the camera just far
    enough away for the next frame to start a rebuild."""
    s = RingSchedule(sprite_build(n), R, mode="sync", fade_s=0.0, slice_ms=2.0, **kw)
    frames = [s.step(STATE, DRIFT, cam(), SKY, DT) for _ in range(8 * MAX_SLICES + 2)]
    assert events(frames[0])[0] == "ring_rebuild_start"
    # No frame draws more than one impostor's slice, the first ring's included.
    assert all(len(f.render) <= 1 for f in frames)
    assert sum(events(f).count("impostor_rendered") for f in frames) == RING_SIZE
    assert frames[-1].current is not None  # complete, and faded in at once
    return s


def test_sliced_impostors_cover_every_sprite_once_in_order_within_the_budget() -> None:
    n = 3000
    s = sliced_schedule(n)
    costs = impostor_costs(s_geometry(), 0, sprite_build(n)(STATE, DRIFT, (0, 0, 1500), SKY)
                           .impostors[0].sprites)  # fmt: skip
    away = cam(0.2 * R)
    frames = [s.step(STATE, DRIFT, away, SKY, DT) for _ in range(200)]
    assert events(frames[0])[0] == "ring_rebuild_start"
    pieces = [f.render_slice for f in frames if f.render_slice is not None]
    # Before any slice was timed: FIRST_SECONDS_PER_UNIT, so 2 ms holds this many units.
    per_slice = 2e-3 / FIRST_SECONDS_PER_UNIT
    expected_slices = math.ceil(costs.sum() / per_slice)
    assert 1 < expected_slices <= MAX_SLICES
    for i in range(RING_SIZE):
        mine = [p for p in pieces if p.index == i]
        assert len(mine) == expected_slices
        # Consecutive, back to front, every sprite once; the last one completes it.
        assert mine[0].start == 0 and mine[-1].stop == n
        assert all(a.stop == b.start for a, b in itertools.pairwise(mine))
        assert [p.last for p in mine] == [False] * (len(mine) - 1) + [True]
        assert all(p.units <= per_slice + costs.max() for p in mine)
    # One impostor a frame, in order; each done when its last slice is drawn.
    indices = [p.index for p in pieces]
    assert indices == sorted(indices)
    done = [(k, e.fields) for k, f in enumerate(frames) for e in f.events
            if e.event == "impostor_rendered"]  # fmt: skip
    assert [d["index"] for _, d in done] == list(range(RING_SIZE))
    assert all(d["slices"] == expected_slices for _, d in done)
    assert events(frames[8 * expected_slices - 1])[-2:] == [
        "impostor_rendered",
        "ring_rebuild_done",
    ]


def test_slices_follow_what_drawing_them_took() -> None:
    s = sliced_schedule(3000)
    away = cam(0.2 * R)
    first = s.step(STATE, DRIFT, away, SKY, DT).render_slice
    assert first is not None and not first.last
    # That slice took ten times longer than assumed: the next ones shrink toward a tenth.
    s.note_render(first.units, 10 * first.units * FIRST_SECONDS_PER_UNIT)
    second = s.step(STATE, DRIFT, away, SKY, DT).render_slice
    assert second is not None and second.start == first.stop
    assert second.units < 0.25 * first.units
    # A fast machine (a GPU) takes the whole impostor in one slice.
    fast = sliced_schedule(3000)
    piece = fast.step(STATE, DRIFT, away, SKY, DT).render_slice
    assert piece is not None
    for _ in range(20):
        fast.note_render(piece.units, 1e-9)
    for _ in range(2 * MAX_SLICES):
        piece = fast.step(STATE, DRIFT, away, SKY, DT).render_slice
        assert piece is not None
        if piece.index == 1:
            break
    assert (piece.start, piece.last) == (0, True)


def test_without_a_slice_budget_an_impostor_is_drawn_whole() -> None:
    s = RingSchedule(sprite_build(3000), R, mode="sync", fade_s=0.0)
    frames = [s.step(STATE, DRIFT, cam(), SKY, DT) for _ in range(8)]
    assert [f.render for f in frames] == [(k,) for k in range(RING_SIZE)]
    assert all(f.render_slice is None for f in frames)


def s_geometry() -> RingGeometry:
    return sprite_build(1)(STATE, DRIFT, (0.0, 0.0, 1500.0), SKY).geometry


def test_impostor_costs_count_each_sprite_and_its_share_of_the_window() -> None:
    geo = s_geometry()
    _right, _up, fwd = geo.axes(2)
    centre = np.asarray(geo.centre_m)
    # One tiny sprite, one covering a quarter of the window's height at the ring radius, one
    # far larger than the window: 1, 1 + its share x WINDOW_FILL_COST, and 1 + the cap.
    height = geo.top_m[2] - geo.bottom_m[2]
    width = 2 * geo.half_width_m
    sizes = [1.0, 0.25 * height, 10 * max(height, width)]
    batch = sprite_batch([centre + fwd * R] * 3, sizes)
    costs = impostor_costs(geo, 2, batch)
    np.testing.assert_allclose(
        costs,
        [1.0 + WINDOW_FILL_COST / (width * height), 1 + WINDOW_FILL_COST * (0.25 * height) ** 2
         / (width * height), 1 + WINDOW_FILL_COST],
        rtol=1e-6,
    )  # fmt: skip
    assert impostor_costs(geo, 2, batch.take(np.arange(0))).shape == (0,)


def _run(s: RingSchedule, xs: list[float], z: float = 1500.0) -> list[tuple[int, str, dict]]:
    out = []
    for i, x in enumerate(xs):
        f = s.step(STATE, DRIFT, cam(x, z), SKY, DT)
        out += [(i, e.event, e.fields) for e in f.events]
    return out


def test_rebuilds_start_exactly_when_the_camera_passes_fifteen_percent() -> None:
    s = RingSchedule(quick_build, R, mode="sync", fade_s=0.5)
    xs = [4.0 * i for i in range(1000)]  # 120 m/s at 30 fps
    starts = [(i, f) for i, e, f in _run(s, xs) if e == "ring_rebuild_start"]
    reasons = [f["reason"] for _, f in starts]
    assert reasons == ["initial"] + ["moved_horizontal"] * 3  # 4 km flown, every 1.2 km
    centre = 0.0
    for i, fields in starts[1:]:
        # The first frame beyond 0.15 R (1200 m) from where the previous ring was built.
        assert xs[i] - centre > 0.15 * R >= xs[i - 1] - centre
        assert fields["centre_m"][0] == xs[i]
        centre = xs[i]


def test_a_climb_of_two_percent_rebuilds() -> None:
    s = RingSchedule(quick_build, R, mode="sync", fade_s=0.0)
    out = []
    for i in range(200):
        f = s.step(STATE, DRIFT, cam(0.0, 1500.0 + 2.0 * i), SKY, DT)
        out += [(i, e.fields.get("reason")) for e in f.events if e.event == "ring_rebuild_start"]
    assert out[1][1] == "moved_vertical"
    assert 2.0 * out[1][0] > 0.02 * R >= 2.0 * (out[1][0] - 1)


def test_a_need_that_arises_mid_cycle_waits_for_the_cycle_to_end() -> None:
    s = RingSchedule(quick_build, R, mode="sync", fade_s=0.1)
    s.step(STATE, DRIFT, cam(), SKY, DT)  # starts the first rebuild
    log = _run(s, [5000.0] * 20)  # far beyond the threshold from the very next frame
    starts = [i for i, e, _ in log if e == "ring_rebuild_start"]
    done = [i for i, e, _ in log if e == "crossfade_done"]
    assert starts == [done[0]]  # in the frame the first cycle ends, not before


def test_weather_and_sun_changes_rebuild_with_their_reason() -> None:
    s = RingSchedule(quick_build, R, mode="sync", fade_s=0.0)
    for _ in range(12):
        s.step(STATE, DRIFT, cam(), SKY, DT)
    assert not s.busy
    thicker = dataclasses.replace(
        STATE, layers=(dataclasses.replace(STATE.layers[0], cover_oktas=5.0),)
    )
    f = s.step(thicker, DRIFT, cam(), SKY, DT)
    assert f.events[0].event == "ring_rebuild_start" and f.events[0].fields["reason"] == "weather"
    for _ in range(12):
        s.step(thicker, DRIFT, cam(), SKY, DT)
    later = dataclasses.replace(thicker, time_utc=thicker.time_utc + timedelta(minutes=10))
    f = s.step(later, DRIFT, cam(), sky_params(later), DT)
    assert f.events[0].fields["reason"] == "sun"
    # The clock alone (seconds, the sun barely moving) rebuilds nothing.
    for _ in range(12):
        s.step(later, DRIFT, cam(), sky_params(later), DT)
    soon = dataclasses.replace(later, time_utc=later.time_utc + timedelta(seconds=20))
    assert not s.step(soon, DRIFT, cam(), sky_params(soon), DT).events


def test_what_the_ring_does_not_show_rebuilds_nothing() -> None:
    s = RingSchedule(quick_build, R, mode="sync", fade_s=0.0)
    for _ in range(12):
        s.step(STATE, DRIFT, cam(), SKY, DT)
    assert not s.busy
    # A cockpit stepping temperature, pressure and wind (its effect is the drift test's).
    knobs = dataclasses.replace(
        STATE,
        temperature_c=-5.0,
        dewpoint_c=-9.0,
        qnh_hpa=990.0,
        present_weather=("-RA",),
        wind=(WindLayer(0.0, 270.0, 12.0),),
    )
    assert not s.step(knobs, DRIFT, cam(), sky_params(knobs), DT).events
    hazier = dataclasses.replace(knobs, visibility_m=3000.0)
    f = s.step(hazier, DRIFT, cam(), sky_params(hazier), DT)
    assert f.events[0].fields["reason"] == "weather"


NO_GAP = RingPolicy(weather_gap_s=0.0)  # the allowances alone


def test_a_visibility_transition_rebuilds_once_per_five_percent_not_every_step() -> None:
    s = RingSchedule(quick_build, R, mode="sync", fade_s=0.0, policy=NO_GAP)
    for _ in range(12):
        s.step(STATE, DRIFT, cam(), SKY, DT)
    reasons = []
    # 10 km closing in at 100 m a step, as a transition does at its default rate over 1 s.
    for k in range(1, 21):
        hazier = dataclasses.replace(STATE, visibility_m=10_000.0 - 100.0 * k)
        for _ in range(RING_SIZE + 1):  # let each rebuild finish before the next step
            f = s.step(hazier, DRIFT, cam(), sky_params(hazier), DT)
            reasons += [
                (k, e.fields["reason"]) for e in f.events if e.event == "ring_rebuild_start"
            ]
    # Built at 10,000 m: 9,500 is 5.3 % below it (rebuilt), then 9,000 is 5.6 % below 9,500;
    # 8,500 and 8,000 follow: each the first step more than 5 % from the ring's visibility.
    assert reasons == [(5, "weather"), (10, "weather"), (15, "weather"), (20, "weather")]


def _rebuilds(s: RingSchedule, state: WeatherState, frames: int) -> list[str]:
    out = []
    for _ in range(frames):
        f = s.step(state, DRIFT, cam(), sky_params(state), DT)
        out += [e.fields["reason"] for e in f.events if e.event == "ring_rebuild_start"]
    return out


def test_clouds_forming_rebuild_past_an_allowance_and_exactly_once_they_hold_still() -> None:
    s = RingSchedule(quick_build, R, mode="sync", fade_s=0.0, policy=NO_GAP)
    _rebuilds(s, STATE, 12)
    (layer,) = STATE.layers

    def with_layer(**change: float) -> WeatherState:
        return dataclasses.replace(STATE, layers=(dataclasses.replace(layer, **change),))

    # Changing every frame, within 0.25 okta and 50 m of the ring's: nothing.
    creeping = [with_layer(cover_oktas=4.0 + 0.01 * k, base_m=1500.0 + 2.0 * k) for k in range(20)]
    assert [r for st in creeping for r in _rebuilds(s, st, 1)] == []
    # Past 0.25 okta (or 50 m of base or top, or another type): at once.
    assert _rebuilds(s, with_layer(cover_oktas=4.3), 1) == ["weather"]
    _rebuilds(s, with_layer(cover_oktas=4.3), RING_SIZE)
    assert _rebuilds(s, with_layer(cover_oktas=4.3, top_m=2260.0), 1) == ["weather"]
    _rebuilds(s, with_layer(cover_oktas=4.3, top_m=2260.0), RING_SIZE)
    cirrus = with_layer(cover_oktas=4.3, top_m=2260.0, type=CloudType.CIRRUS)
    assert _rebuilds(s, cirrus, 1) == ["weather"]
    _rebuilds(s, cirrus, RING_SIZE)
    # A small difference that then holds still for 1 s: rebuilt exactly, once.
    held = dataclasses.replace(
        cirrus, layers=(dataclasses.replace(cirrus.layers[0], base_m=1510.0),)
    )
    assert _rebuilds(s, held, 29) == []
    assert _rebuilds(s, held, 4) == ["weather"]  # 1 s in: 30 frames, give or take rounding
    assert _rebuilds(s, held, 60) == []


def test_weather_rebuilds_back_to_back_wait_a_gap_but_other_reasons_do_not() -> None:
    s = RingSchedule(quick_build, R, mode="sync", fade_s=0.0)
    _rebuilds(s, STATE, 12)
    hazy = [dataclasses.replace(STATE, visibility_m=v) for v in (8000.0, 6000.0, 4000.0)]
    # After a quiet spell: at once. Built and shown in 8 frames (no fade).
    assert _rebuilds(s, hazy[0], RING_SIZE + 1) == ["weather"]
    gap_frames = round(RING_WEATHER_GAP_S / DT)
    # The next weather change waits until the gap after that ring was shown ...
    assert _rebuilds(s, hazy[1], gap_frames - 2) == []
    assert _rebuilds(s, hazy[1], 3) == ["weather"]
    _rebuilds(s, hazy[1], RING_SIZE)
    # ... but a camera move does not, and builds the newest weather with it: once that ring
    # is shown, nothing is left to rebuild for the weather, gap or not.
    far = Camera(position_m=(0.2 * R, 0.0, 1500.0))
    reasons = []
    for _ in range(round(2 * RING_WEATHER_GAP_S / DT)):
        f = s.step(hazy[2], DRIFT, far, sky_params(hazy[2]), DT)
        reasons += [e.fields["reason"] for e in f.events if e.event == "ring_rebuild_start"]
    assert reasons == ["moved_horizontal"]


def test_async_builds_off_the_frame_and_renders_when_ready() -> None:
    gate = threading.Event()
    built: list[str] = []

    def slow_build(*args: object) -> RingScene:
        gate.wait(5.0)
        built.append(threading.current_thread().name)
        return quick_build(*args)  # type: ignore[arg-type]

    s = RingSchedule(slow_build, R, mode="async", fade_s=0.0)
    try:
        first = s.step(STATE, DRIFT, cam(), SKY, DT)
        assert events(first) == ["ring_rebuild_start"] and first.render == ()
        waiting = [s.step(STATE, DRIFT, cam(), SKY, DT) for _ in range(5)]
        assert all(not f.events and not f.render for f in waiting)  # frames go on meanwhile
        gate.set()
        for _ in range(100):
            f = s.step(STATE, DRIFT, cam(), SKY, DT)
            if f.render:
                break
            threading.Event().wait(0.01)
        assert f.render == (0,) and built and built[0].startswith("wxsky-ring")
    finally:
        s.close()
        s.close()  # idempotent


@pytest.mark.skipif(not hasattr(os, "setpriority"), reason="no per-thread priority here")
def test_a_failed_build_keeps_the_old_ring_and_tries_again(
    caplog: pytest.LogCaptureFixture,
) -> None:
    calls = []

    def flaky(*args: object) -> RingScene:
        calls.append(1)
        if len(calls) == 2:
            raise RuntimeError("out of memory")
        return quick_build(*args)  # type: ignore[arg-type]

    s = RingSchedule(flaky, R, mode="sync", fade_s=0.0)
    for _ in range(10):
        s.step(STATE, DRIFT, cam(), SKY, DT)
    old = s.current
    failed = s.step(STATE, DRIFT, cam(3000.0), SKY, DT)
    assert "ring_rebuild_failed" in events(failed) and s.current is old
    assert "ring build failed: out of memory" in caplog.text
    # Not every frame: the next try comes RETRY_AFTER_S later.
    waits = 0
    while not (retry := s.step(STATE, DRIFT, cam(3000.0), SKY, DT)).events:
        waits += 1
    assert waits == round(RETRY_AFTER_S / DT) - 1
    assert events(retry)[:2] == ["ring_rebuild_start", "impostor_rendered"]


def test_immediate_mode_builds_and_renders_the_whole_ring_at_once() -> None:
    s = RingSchedule(quick_build, R, mode="immediate")
    f = s.step(STATE, DRIFT, cam(), SKY, DT)
    assert f.render == tuple(range(RING_SIZE)) and f.render_set == 0
    assert f.current is not None and f.current is f.render_ring and f.fade == 0.0
    assert not s.step(STATE, DRIFT, cam(), SKY, DT).render


def test_unknown_mode_is_refused() -> None:
    with pytest.raises(ValueError, match="async, sync, immediate"):
        RingSchedule(quick_build, R, mode="lazy")


def test_near_shares_of_the_two_rings_add_up_to_one_mid_fade() -> None:
    s = RingSchedule(quick_build, R, mode="sync", fade_s=0.3)
    for _ in range(30):
        s.step(STATE, DRIFT, cam(), SKY, DT)
    assert not s.busy
    for _ in range(8):  # a new ring built 3 km east, now fading in
        f = s.step(STATE, DRIFT, cam(3000.0), SKY, DT)
    f = s.step(STATE, DRIFT, cam(3000.0), SKY, DT)
    assert 0.0 < f.fade < 1.0
    old, new = f.near_rings(cam(3000.0), DRIFT)
    assert old.centre_m[0] == 0.0 and new.centre_m[0] == 3000.0
    assert old.weight + new.weight == pytest.approx(1.0) and new.weight == f.fade


def test_gather_near_weighs_each_block_by_the_rings_it_is_near_to() -> None:
    state = WeatherState(layers=(CloudLayer(8.0, 1000.0, 1500.0, CloudType.STRATUS),), wind=())
    drift = zero_drift(state)
    a = NearRing((0.0, 0.0, 1200.0), drift, 0.25)
    b = NearRing((9000.0, 0.0, 1200.0), drift, 0.75)
    batch, share = gather_near(state, drift, (a, b), 6000.0)
    x = batch.centre_m[:, 0]
    assert set(np.unique(share).round(6)) == {0.25, 0.75, 1.0}
    # Blocks only near the first centre show at its weight, only near the second at its.
    assert np.all(share[x < -2000.0] == np.float32(0.25))
    assert np.all(share[x > 12000.0] == np.float32(0.75))
    y = batch.centre_m[:, 1]
    both = (x > 4500.0) & (x < 7500.0) & (np.abs(y) < 3000.0)
    assert both.any() and np.all(share[both] == 1.0)
    # One ring at weight 1 is what gather_blocks gives, share 1 everywhere.
    single, ones = gather_near(state, drift, (a._replace(weight=1.0),), 6000.0)
    assert len(single) and np.all(ones == 1.0)


def test_before_the_first_ring_the_near_layer_is_the_one_the_ring_being_built_complements() -> None:
    """While the first ring builds, the near layer gathers the blocks around the ring's
    centre (as its drift picks them), not around the moving camera: the same set frame after
    frame, and the set the ring's own frames then use, so no frame makes a set and its light."""
    release = threading.Event()

    def build(state: WeatherState, drift: Drift, centre: tuple, sky: SkyParams) -> RingScene:
        release.wait(10.0)
        return quick_build(state, drift, centre, sky)

    s = RingSchedule(build, R, mode="async", fade_s=0.0)
    try:
        first = s.step(STATE, DRIFT, cam(), SKY, DT)
        assert first.current is None
        built_for = (NearRing(cam().position_m, DRIFT, 1.0),)
        for x in (50.0, 400.0):  # the camera flies on while the ring builds
            f = s.step(STATE, DRIFT, cam(x), SKY, DT)
            assert f.current is None and f.near_rings(cam(x), DRIFT) == built_for
        release.set()
        for _ in range(500):
            f = s.step(STATE, DRIFT, cam(450.0), SKY, DT)
            if f.current is not None:
                break
            threading.Event().wait(0.005)
        assert f.current is not None
        assert f.near_rings(cam(450.0), DRIFT) == built_for
    finally:
        s.close()
    # With no ring asked for yet, the camera is all there is.
    nothing = RingSchedule(quick_build, R, mode="async", fade_s=0.0)
    try:
        blank = nothing._frame((), None, 1, [])
        assert blank.near_rings(cam(10.0), DRIFT) == (NearRing(cam(10.0).position_m, DRIFT, 1.0),)
    finally:
        nothing.close()


def test_a_ring_lit_by_other_atmosphere_tables_is_built_again_once_the_right_ones_come() -> None:
    """The daemon makes the physical sky's tables off the frame path; a ring built meanwhile
    (after a time set, a new preset) is lit by the last tables made. It is built again when
    the frame's tables differ in visibility, humidity or a sun beyond RING_SUN_DEG, never
    for the eye's height alone, and never under the gradient sky."""
    from wxsky.engine.ring_schedule import RING_SUN_DEG, _lit_otherwise
    from wxsky.scene.atmosphere import atmosphere_key, build_luts

    noon = build_luts(atmosphere_key(60.0, 30_000.0, 60.0, 2.0))

    def lit(el: float, vis: float = 30_000.0, rh: float = 60.0, eye: float = 2.0) -> SkyParams:
        # The same arrays under another key: only the key is read here.
        return SKY.with_atmosphere(dataclasses.replace(noon, key=atmosphere_key(el, vis, rh, eye)))

    built = noon.key
    assert not _lit_otherwise(built, lit(60.0), RING_SUN_DEG)
    assert not _lit_otherwise(built, lit(60.0, eye=3_000.0), RING_SUN_DEG)
    assert not _lit_otherwise(built, lit(60.5), RING_SUN_DEG)  # the "sun" reason's business
    assert _lit_otherwise(built, lit(4.0), RING_SUN_DEG)  # the tables of noon at dusk
    assert _lit_otherwise(built, lit(60.0, vis=8_000.0), RING_SUN_DEG)
    assert _lit_otherwise(built, lit(60.0, rh=95.0), RING_SUN_DEG)
    assert not _lit_otherwise(None, lit(4.0), RING_SUN_DEG)  # built under the gradient sky
    assert not _lit_otherwise(built, SKY, RING_SUN_DEG)  # a gradient frame
