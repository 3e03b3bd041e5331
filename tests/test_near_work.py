"""Issue 39: the daemon's frames never make a near set (`engine.near_work`). While a set is
made off the frame path (here held back with the engine's work gate), the frames keep coming,
drawn from the last near layer; once it is made, the frames are exactly those an engine that
makes everything at once draws."""

from __future__ import annotations

import dataclasses
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from wxsky.engine.stages import FramePlan, SkyEngine
from wxsky.scene.camera import Camera
from wxsky.scene.layout import SceneSettings, build_frame
from wxsky.settings.presets import load_preset
from wxsky.weather.state import Source, WeatherState

HANG_S = 120.0  # only catches a hang: nothing here waits for time to pass
# The gradient sky: with the physical one a live engine lights a new site's clouds with the
# last atmosphere tables until the new site's are made (by design, test_atmosphere), and an
# engine that makes everything at once does not, which is not what these tests compare.
SETTINGS = SceneSettings(
    ring_radius_m=8000.0, max_range_m=16_000.0, shadow_map_px=32, sky="roden-parberry"
)
DT_S = 1.0 / 30.0


def _off_thread(work: Callable[[], Any]) -> Any:
    """Run `work` on a thread of its own and return what it gave: a frame that waited on the
    held work would never return, and the join catches that as a hang, not a slow frame."""
    out: list[Any] = []
    errors: list[BaseException] = []

    def run() -> None:
        try:
            out.append(work())
        except BaseException as exc:
            errors.append(exc)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(HANG_S)
    assert not thread.is_alive(), "a frame waited on the work held back"
    if errors:
        raise errors[0]
    return out[0]


def _engine(preset: str, worker: str) -> SkyEngine:
    state = WeatherState().apply(load_preset(preset, ()))
    camera = Camera((0.0, 0.0, 1500.0), heading_deg=250.0, pitch_deg=5.0, width_px=64, height_px=36)
    return SkyEngine(
        state, camera, SETTINGS, ring_build="async", ring_worker=worker, clock_rate=0.0
    )


def _settle(engine: SkyEngine) -> FramePlan:
    """Frames until no work is left (a ring on show, nothing pending)."""
    deadline = time.monotonic() + HANG_S
    while True:
        plan = engine.advance(DT_S)
        idle = not engine.ring_busy and not engine.near_pending and engine.ring is not None
        if idle and engine.towers_pending == 0:
            return plan
        assert time.monotonic() < deadline, "the work never finished: a hang"
        time.sleep(0.01)


@pytest.mark.parametrize("worker", ["thread", "process"])
def test_frames_keep_coming_from_the_last_near_layer_while_a_new_site_is_made(
    worker: str,
) -> None:
    engine = _engine("fair-cumulus", worker)
    try:
        engine.warm_up()
        before = _settle(engine)
        assert len(before.frame.near) > 0
        shown_near = before.frame.near.sprites.centre_m
        gate = threading.Event()
        engine.work_gate = gate  # held: nothing off the frame path may run
        obs = engine.state.observer
        engine.move_observer(obs.lat_deg + 4.5, obs.lon_deg)  # 500 km: a new site
        assert engine.state.observer != obs
        held_from = engine.near_waits

        def frames() -> list[FramePlan]:
            return [engine.advance(DT_S) for _ in range(20)]

        plans = _off_thread(frames)
        assert engine.near_pending and engine.ring_busy
        assert engine.near_waits - held_from == 20
        for plan in plans:
            # The frame is this frame's weather and site, drawn from the last near layer:
            # the same clouds where they stood.
            assert plan.state.observer == engine.state.observer
            centres = plan.frame.near.sprites.centre_m
            assert {tuple(c) for c in centres} <= {tuple(c) for c in shown_near}
        names = [e.event for plan in plans for e in plan.events]
        assert names.count("near_wait_start") == 1 and "near_wait_end" not in names

        gate.set()
        after = _off_thread(lambda: _settle(engine))
        assert not engine.near_pending
        # The new site's clouds are drawn as an engine that makes everything at once draws
        # them for the same weather, rings and camera.
        same = _immediate_frame(engine, after)
        np.testing.assert_array_equal(after.frame.near.sprites.centre_m, same.near.sprites.centre_m)
        np.testing.assert_array_equal(after.frame.near.rgba, same.near.rgba)
        # The same seed makes the same cloud field at the new site, but its light is the new
        # site's sun, which the held frames did not have yet.
        assert not np.array_equal(after.frame.near.rgba, plans[-1].frame.near.rgba)
    finally:
        engine.close(1.0)


def _immediate_frame(engine: SkyEngine, plan: FramePlan) -> Any:
    """The frame `plan` shows, its near layer gathered, lit and its cells found at once."""
    from wxsky.scene.tower_field import TowerClock

    state, camera = plan.state, plan.frame.camera
    sky = engine.sky(camera.position_m[2])
    near = plan.rings.near_rings(camera, engine.drift)
    epochs = engine.shared().tower_epochs
    return build_frame(
        state,
        engine.drift,
        camera,
        near,
        sky,
        SETTINGS,
        towers=TowerClock(epochs, state.time_utc),
    )


def test_a_change_of_layers_is_drawn_from_the_last_layer_until_its_set_is_made() -> None:
    """New layers (a preset switched in at once, or a transition's step) are a new near set:
    frames go on from the last one until it comes, then show exactly the new one."""
    engine = _engine("scattered-cumulus", "thread")
    try:
        engine.warm_up()
        before = _settle(engine)
        gate = threading.Event()
        engine.work_gate = gate
        thicker = load_preset("broken-stratocumulus", ())
        engine.apply(dataclasses.replace(thicker, source=Source.CONTROL, observer=None, seed=None))
        engine.settle()
        assert engine.state.layers != before.state.layers
        plans = _off_thread(lambda: [engine.advance(DT_S) for _ in range(10)])
        assert engine.near_pending
        for plan in plans:
            assert plan.state.layers == engine.state.layers  # the frame's weather is the new
            np.testing.assert_array_equal(  # but its near clouds are the last ones drawn
                plan.frame.near.sprites.centre_m, before.frame.near.sprites.centre_m
            )
        gate.set()
        after = _off_thread(lambda: _settle(engine))
        same = _immediate_frame(engine, after)
        np.testing.assert_array_equal(after.frame.near.sprites.centre_m, same.near.sprites.centre_m)
        assert len(after.frame.near) != len(before.frame.near)
    finally:
        engine.close(1.0)


def test_a_tower_not_lit_yet_stays_the_sprite_cloud_it_grows_from() -> None:
    """A convective cell whose volume is not made yet is drawn as its sprite cloud, not left
    out: the sky shows a cumulus where the tower will be, never a hole."""
    engine = _engine("towering-cumulus", "thread")
    try:
        gate = threading.Event()
        engine.work_gate = gate  # no tower step is lit until the gate opens
        engine.drift_for(1800.0)  # half an hour on: the cells have grown
        engine.warm_up()
        held = _off_thread(lambda: [engine.advance(DT_S) for _ in range(5)])[-1]
        assert engine.towers_pending > 0 and held.frame.towers == ()
        # Every cloud is drawn as sprites, as with no towers at all.
        state, camera = held.state, held.frame.camera
        plain = build_frame(
            state,
            engine.drift,
            camera,
            held.rings.near_rings(camera, engine.drift),
            engine.sky(camera.position_m[2]),
            dataclasses.replace(SETTINGS, max_towers=0),
        )
        np.testing.assert_array_equal(held.frame.near.sprites.centre_m, plain.near.sprites.centre_m)
        gate.set()
        lit = _off_thread(lambda: _settle(engine))
        assert lit.frame.towers, "the cells grow as volumes once lit"
        lit_ids = set(lit.frame.near.sprites.cloud_id.tolist())
        assert not {t.cloud_id for t in lit.frame.towers} & lit_ids  # now drawn as volumes
    finally:
        engine.close(1.0)


@pytest.mark.parametrize("preset", ["fair-cumulus", "overcast-stratus"])
def test_the_first_frames_show_clouds_while_their_own_set_is_made(preset: str) -> None:
    """The first ring's blocks are picked with the first frame's drift, which the warm-up
    cannot know: until that set is made, the first frames show the warm-up's, not an empty
    sky; and an engine never warmed up makes its first set at once."""
    engine = _engine(preset, "thread")
    try:
        gate = threading.Event()
        engine.work_gate = gate
        warm = engine.warm_up()
        assert warm is not None and len(warm.near) > 0
        plans = _off_thread(lambda: [engine.advance(DT_S) for _ in range(3)])
        assert all(len(p.frame.near) > 0 for p in plans)
    finally:
        engine.close(1.0)
    cold = _engine(preset, "thread")
    try:
        cold.work_gate = threading.Event()  # held: only the frame itself can make it
        plan = _off_thread(lambda: cold.advance(DT_S))
        assert len(plan.frame.near) > 0
    finally:
        cold.close(1.0)
