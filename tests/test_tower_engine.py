"""The engine's side of the towers (engine/stages.py, engine/tower_work.py; issue 17): each
layer's epoch, a picture later than its weather showing the towers older, clearing air cutting
their supply, lit steps made at once for a snapshot or on a thread for the daemon, and the
budget's trace events."""

from __future__ import annotations

import dataclasses
import time

import pytest

from wxsky.engine.stages import SkyEngine
from wxsky.engine.tower_work import TowerWork
from wxsky.scene.camera import Camera
from wxsky.scene.layout import SceneSettings
from wxsky.scene.sky import sky_params
from wxsky.settings.presets import load_preset
from wxsky.towers.volume import STEP_S
from wxsky.weather.state import CloudType, Source, WeatherPatch, WeatherState


def _tc() -> WeatherState:
    return WeatherState().apply(load_preset("towering-cumulus"))


def _camera(state: WeatherState) -> Camera:
    return Camera((0.0, 0.0, state.observer.alt_m + 2.0), heading_deg=104.0, pitch_deg=12.0)


def test_a_later_picture_shows_the_same_towers_older() -> None:
    state = _tc()
    settings = SceneSettings(max_towers=4)
    with SkyEngine(state, _camera(state), settings, clock_rate=0.0) as now:
        first = now.advance(0.0).frame
    with SkyEngine(state, _camera(state), settings, clock_rate=0.0) as later:
        later.drift_for(120.0)
        second = later.advance(0.0).frame
    assert first.towers and second.towers
    ages = {t.spec: t.age_s for t in first.towers}
    common = [t for t in second.towers if t.spec in ages]
    assert common  # drifted by the wind, the nearest cells may be partly others
    for t in common:
        assert t.age_s == pytest.approx(ages[t.spec] + 120.0)
    # A snapshot's engine makes the lit steps at once: the two around each tower's age.
    for t in second.towers:
        assert [v.step for v in t.volumes] == [t.step, t.step + 1]
        assert t.frac == pytest.approx(t.age_s / STEP_S - t.step)


def test_the_clock_ages_the_towers_and_a_new_layer_starts_at_zero() -> None:
    state = _tc()
    with SkyEngine(state, _camera(state), SceneSettings(max_towers=4), clock_rate=1.0) as e:
        before = {t.spec: t.age_s for t in e.advance(0.0).frame.towers}
        after = {t.spec: t.age_s for t in e.advance(30.0).frame.towers}
        for spec in set(before) & set(after):
            assert after[spec] == pytest.approx(before[spec] + 30.0)
        # A cumulonimbus layer added now: its cells are timed from now.
        layers = (
            *state.layers,
            dataclasses.replace(
                state.layers[0], base_m=900.0, top_m=11_000.0, type=CloudType.CUMULONIMBUS
            ),
        )
        e.apply(WeatherPatch(source=Source.CONTROL, layers=layers))
        clock = e.advance(0.0).state.time_utc
        epochs = dict(e._epochs)
    assert len(epochs) == 2
    new = [ep for ep in epochs.values() if ep.set_utc == clock]
    assert len(new) == 1


def test_clearing_air_cuts_the_supply_once_and_a_return_restores_it() -> None:
    state = _tc()
    with SkyEngine(state, _camera(state), SceneSettings(max_towers=2), clock_rate=1.0) as e:
        e.advance(0.0)
        (key,) = e._epochs
        assert e._epochs[key].cut_utc is None
        thin = dataclasses.replace(state.layers[0], cover_oktas=1)
        e.apply(WeatherPatch(source=Source.CONTROL, layers=(thin,)))
        e.advance(5.0)
        # Instant rates: the applied cover dropped at once; the cut is when the target thinned.
        cut = e._epochs[key].cut_utc
        assert cut is not None
        e.advance(5.0)
        assert e._epochs[key].cut_utc == cut
        e.release(Source.CONTROL)
        e.advance(5.0)
        assert e._epochs[key].cut_utc is None


def test_a_display_channel_shows_the_masters_towers_at_the_masters_ages() -> None:
    state = _tc()
    settings = SceneSettings(max_towers=3)
    with (
        SkyEngine(state, _camera(state), settings, clock_rate=0.0) as master,
        SkyEngine(state, _camera(state), settings, clock_rate=0.0) as channel,
    ):
        master.drift_for(300.0)  # its towers five minutes older than the channel's own
        channel.follow(master.shared())
        mine = {t.spec: t.age_s for t in master.advance(0.0).frame.towers}
        theirs = {t.spec: t.age_s for t in channel.advance(0.0).frame.towers}
    assert mine and mine == theirs


def test_more_cells_than_the_budget_is_a_trace_event_not_a_collapse() -> None:
    state = _tc()
    with SkyEngine(state, _camera(state), SceneSettings(max_towers=2), clock_rate=0.0) as e:
        plan = e.advance(0.0)
    assert len(plan.frame.towers) <= 2
    assert plan.frame.towers_left_out > 0
    (event,) = [ev for ev in plan.events if ev.event == "tower_cap_start"]
    assert event.fields["left_out"] == plan.frame.towers_left_out


def test_async_work_shows_nothing_until_a_step_is_lit_then_keeps_up() -> None:
    state = _tc()
    with SkyEngine(state, _camera(state), SceneSettings(max_towers=2), clock_rate=0.0) as e:
        towers = e.advance(0.0).frame.towers
    sky = sky_params(state)
    bare = tuple(dataclasses.replace(t, volumes=(), frac=0.0) for t in towers)
    with TowerWork("async") as work:
        first = work.fill(bare, sky)
        assert all(not t.ready for t in first)
        deadline = time.monotonic() + 60.0
        while work.pending and time.monotonic() < deadline:
            time.sleep(0.05)
        ready = work.fill(bare, sky)
        assert all([v.step for v in t.volumes] == [t.step, t.step + 1] for t in ready)
        # Ten seconds on, the next step was made ahead: no wait at the step.
        older = tuple(dataclasses.replace(t, age_s=t.age_s + STEP_S) for t in bare)
        deadline = time.monotonic() + 60.0
        while work.pending and time.monotonic() < deadline:
            time.sleep(0.05)
        moved = work.fill(older, sky)
        assert all([v.step for v in t.volumes] == [t.step, t.step + 1] for t in moved)
    work.close()  # idempotent


def test_tower_work_checks_its_mode() -> None:
    with pytest.raises(ValueError, match="tower work mode"):
        TowerWork("sometimes")
