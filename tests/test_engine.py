"""The engine's stage order: simulation clock, drift, and when the impostor ring is rebuilt."""

from __future__ import annotations

import dataclasses
import itertools
from datetime import UTC, datetime, timedelta

import numpy as np
import pytest

from wxsky.engine.stages import SkyEngine, enu_from_geodetic
from wxsky.scene import sky as sky_module
from wxsky.scene.camera import Camera
from wxsky.scene.layout import SceneSettings
from wxsky.weather.state import (
    CloudLayer,
    CloudType,
    Observer,
    Source,
    WeatherPatch,
    WeatherState,
    WindLayer,
)

T0 = datetime(2026, 6, 21, 13, 0, tzinfo=UTC)
SETTINGS = SceneSettings(ring_radius_m=8000.0, max_range_m=16_000.0, ring_texture_px=64)
CU = CloudLayer(3, 1900.0, 2700.0, CloudType.CUMULUS)


def _camera(x: float = 0.0, y: float = 0.0, z: float = 600.0) -> Camera:
    return Camera((x, y, z), heading_deg=200.0, pitch_deg=10.0, width_px=64, height_px=36)


def _engine(rate: float = 1.0, wind_mps: float = 0.0, **kw: object) -> SkyEngine:
    wind = (WindLayer(500.0, 270.0, wind_mps),) if wind_mps else ()
    args: dict = {"time_utc": T0, "layers": (CU,), "wind": wind, "seed": 5, **kw}
    return SkyEngine(WeatherState(**args), _camera(), SETTINGS, clock_rate=rate)


# -- clock --------------------------------------------------------------------------------


@pytest.mark.parametrize(("rate", "dt", "expected_s"), [(1.0, 0.5, 0.5), (60.0, 2.0, 120.0)])
def test_clock_advances_time_by_rate_times_dt(rate: float, dt: float, expected_s: float) -> None:
    engine = _engine(rate=rate)
    plan = engine.advance(dt)
    assert plan.state.time_utc == T0 + timedelta(seconds=expected_s)
    plan = engine.advance(dt)
    assert plan.state.time_utc == T0 + timedelta(seconds=2 * expected_s)
    assert engine.state.time_utc == plan.state.time_utc


def test_rate_zero_freezes_time_and_clouds() -> None:
    engine = _engine(rate=0.0, wind_mps=20.0)
    first = engine.advance(0.0)
    for _ in range(3):
        plan = engine.advance(10.0)
    assert plan.state.time_utc == T0
    assert plan.ring is first.ring and not plan.ring_changed
    np.testing.assert_array_equal(
        plan.frame.near.sprites.centre_m, first.frame.near.sprites.centre_m
    )


def test_negative_dt_does_not_run_the_clock_backwards() -> None:
    engine = _engine(rate=1.0)
    engine.advance(5.0)
    assert engine.advance(-100.0).state.time_utc == T0 + timedelta(seconds=5)


def test_set_time_jumps_and_changes_rate() -> None:
    engine = _engine(rate=1.0)
    engine.advance(1.0)
    t = datetime(2026, 6, 22, 6, 0, tzinfo=UTC)
    engine.set_time(t, rate=10.0)
    assert engine.clock_rate == 10.0
    plan = engine.advance(3.0)
    assert plan.state.time_utc == t + timedelta(seconds=30)
    assert plan.ring_changed  # the sun is somewhere else entirely


def test_drift_is_a_function_of_the_time_not_of_the_frames() -> None:
    # 10 m/s from the west. One engine runs 90 frames of a second then has its clock set; the
    # other has it set at once: both put the clouds where that time has them, as a one-shot
    # picture of that time does (wind x time since the weather was set).
    ran, fresh = _engine(rate=1.0, wind_mps=10.0), _engine(rate=1.0, wind_mps=10.0)
    for _ in range(90):
        ran.advance(1.0)
    np.testing.assert_allclose(ran.drift, [(900.0, 0.0)], atol=1e-6)
    t = T0 + timedelta(minutes=30)
    ran.set_time(t)
    fresh.set_time(t)
    np.testing.assert_allclose(ran.drift, [(18_000.0, 0.0)], atol=1e-6)
    assert ran.drift == fresh.drift
    # Earlier than the weather: the clouds stand upwind; back to it: where they began.
    ran.set_time(T0 - timedelta(seconds=60))
    np.testing.assert_allclose(ran.drift, [(-600.0, 0.0)], atol=1e-6)
    ran.set_time(T0)
    np.testing.assert_allclose(ran.drift, [(0.0, 0.0)], atol=1e-9)


def test_a_wind_change_carries_on_from_where_the_clouds_are() -> None:
    engine = _engine(rate=1.0, wind_mps=10.0)
    engine.advance(0.0)
    engine.advance(100.0)  # 1000 m east
    south = (WindLayer(500.0, 180.0, 5.0),)  # now from the south at 5 m/s
    engine.apply(WeatherPatch(source=Source.CONTROL, wind=south))
    np.testing.assert_allclose(engine.drift, [(1000.0, 0.0)], atol=1e-6)  # no jump
    engine.advance(40.0)
    np.testing.assert_allclose(engine.drift, [(1000.0, 200.0)], atol=1e-6)
    engine.set_time(engine.state.time_utc + timedelta(seconds=60))
    np.testing.assert_allclose(engine.drift, [(1000.0, 500.0)], atol=1e-6)


def test_drift_for_moves_the_clouds_and_later_times_carry_on_from_there() -> None:
    engine = _engine(rate=1.0, wind_mps=10.0)
    engine.drift_for(50.0)
    np.testing.assert_allclose(engine.drift, [(500.0, 0.0)], atol=1e-6)
    engine.advance(0.0)
    engine.advance(10.0)
    np.testing.assert_allclose(engine.drift, [(600.0, 0.0)], atol=1e-6)


@pytest.mark.parametrize(("jump_s", "rebuilt"), [(0.5, False), (-0.9, False), (2.0, True)])
def test_setting_the_clock_rebuilds_the_ring_for_the_new_time(jump_s: float, rebuilt: bool) -> None:
    # Two seconds moves neither the sun a degree nor the clouds 3 % of the radius, yet the
    # ring is rebuilt for the new time, so the frames after a set_time are the sky of that
    # time; a set within a second of the running clock (a cockpit keeping it in step) is not.
    engine = _engine(rate=0.0, wind_mps=10.0)
    first = engine.advance(0.0)
    engine.set_time(T0 + timedelta(seconds=jump_s))
    plan = engine.advance(0.0)
    assert plan.ring_changed is rebuilt
    starts = [e.fields.get("reason") for e in plan.events if e.event == "ring_rebuild_start"]
    assert starts == (["time_set"] if rebuilt else [])
    if rebuilt:
        np.testing.assert_allclose(plan.ring.drift, [(10.0 * jump_s, 0.0)], atol=1e-9)
    else:
        assert plan.ring is first.ring
    assert not engine.advance(0.0).ring_changed  # once, not on every frame after


# -- ring rebuilds ------------------------------------------------------------------------


def test_first_frame_builds_the_ring_at_the_camera() -> None:
    engine = _engine()
    assert engine.ring is None
    plan = engine.advance(0.0)
    assert plan.ring_changed and plan.ring_version == 1
    assert plan.ring.geometry.centre_m == _camera().position_m
    assert engine.ring is plan.ring


def test_same_ring_object_when_nothing_changed() -> None:
    engine = _engine(rate=1.0)
    first = engine.advance(0.0)
    for _ in range(3):
        plan = engine.advance(1.0 / 60.0)
        assert plan.ring is first.ring
        assert not plan.ring_changed and plan.ring_version == first.ring_version


@pytest.mark.parametrize(
    ("move", "rebuilt"),
    [
        ((1000.0, 0.0, 0.0), False),  # under 15 % of the 8 km radius
        ((0.0, -1190.0, 0.0), False),
        ((1300.0, 0.0, 0.0), True),
        ((900.0, 900.0, 0.0), True),  # 1273 m diagonally
        ((0.0, 0.0, 150.0), False),  # under 2 % = 160 m
        ((0.0, 0.0, -170.0), True),
    ],
)
def test_ring_rebuilt_when_the_camera_moves_past_the_threshold(
    move: tuple[float, float, float], rebuilt: bool
) -> None:
    engine = _engine(rate=0.0)
    first = engine.advance(0.0)
    engine.set_camera(_camera(*move[:2], 600.0 + move[2]))
    plan = engine.advance(0.0)
    assert plan.ring_changed is rebuilt
    assert (plan.ring is not first.ring) is rebuilt
    assert plan.ring_version == first.ring_version + int(rebuilt)
    expected_centre = (move[0], move[1], 600.0 + move[2]) if rebuilt else (0.0, 0.0, 600.0)
    assert plan.ring.geometry.centre_m == expected_centre
    # The frame follows the camera either way.
    assert plan.frame.camera.position_m == (move[0], move[1], 600.0 + move[2])


def test_ring_rebuilt_on_weather_change_only() -> None:
    engine = _engine(rate=0.0)
    first = engine.advance(0.0)
    engine.apply(WeatherPatch(source=Source.CONTROL, visibility_m=3000.0))
    second = engine.advance(0.0)
    assert second.ring_changed and second.ring is not first.ring
    assert second.state.visibility_m == 3000.0
    # Saying the same thing again (even from another source) is not a change.
    engine.apply(WeatherPatch(source=Source.METAR, visibility_m=3000.0))
    third = engine.advance(0.0)
    assert not third.ring_changed and third.ring is second.ring
    # New clouds are.
    layers = (CloudLayer(6, 1900.0, 2700.0, CloudType.CUMULUS),)
    engine.apply(WeatherPatch(source=Source.CONTROL, layers=layers))
    fourth = engine.advance(0.0)
    assert fourth.ring_changed and fourth.ring_version == third.ring_version + 1
    assert sum(len(d) for d in fourth.ring.impostors) > sum(len(d) for d in third.ring.impostors)


def test_ring_rebuilt_when_the_sun_moves_a_degree() -> None:
    # The sun moves about 15° an hour: 2 minutes is ~0.5°, 5 minutes ~1.25°.
    engine = _engine(rate=1.0)
    first = engine.advance(0.0)
    assert not engine.advance(120.0).ring_changed
    plan = engine.advance(180.0)
    assert plan.ring_changed and plan.ring is not first.ring


def test_ring_rebuilt_when_the_clouds_drift_too_far() -> None:
    # 10 m/s from the west; the limit is 3 % of 8 km = 240 m.
    engine = _engine(rate=1.0, wind_mps=10.0)
    first = engine.advance(0.0)
    assert first.ring.drift == ((0.0, 0.0),)
    plan = engine.advance(20.0)
    assert not plan.ring_changed and plan.ring is first.ring
    # Near sprites drift every frame even while the ring stays: 200 m east after 20 s.
    moved = {tuple(p) for p in np.round(plan.frame.near.sprites.centre_m, 3)}
    east = np.array([200.0, 0.0, 0.0])
    still = {tuple(p) for p in np.round(first.frame.near.sprites.centre_m + east, 3)}
    assert len(still) > 100
    assert len(moved & still) > 0.9 * len(still)
    plan = engine.advance(5.0)
    assert plan.ring_changed
    np.testing.assert_allclose(plan.ring.drift, [(250.0, 0.0)], atol=1e-9)


def test_a_new_layer_starts_undrifted_and_moves_no_other() -> None:
    engine = _engine(rate=1.0, wind_mps=10.0)
    engine.advance(0.0)
    engine.advance(10.0)
    two = (CU, CloudLayer(5, 4000.0, 4500.0, CloudType.ALTOCUMULUS))
    engine.apply(WeatherPatch(source=Source.CONTROL, layers=two))
    plan = engine.advance(0.0)
    assert plan.ring_changed
    np.testing.assert_allclose(plan.ring.drift, [(100.0, 0.0), (0.0, 0.0)], atol=1e-9)
    # And when it dissipates again, the cumulus layer still keeps its place.
    engine.apply(WeatherPatch(source=Source.CONTROL, layers=(CU,)))
    plan = engine.advance(0.0)
    np.testing.assert_allclose(plan.ring.drift, [(100.0, 0.0)], atol=1e-9)


def test_weather_version_counts_changes() -> None:
    engine = _engine()
    assert engine.weather_version == 0
    engine.apply(WeatherPatch(source=Source.CONTROL))  # says nothing
    assert engine.weather_version == 0
    engine.apply(WeatherPatch(source=Source.CONTROL, seed=9))
    assert engine.weather_version > 0 and engine.state.seed == 9


def test_plan_state_carries_the_frame_time() -> None:
    engine = _engine(rate=2.0)
    plan = engine.advance(1.5)
    assert plan.state is engine.state
    assert plan.state.time_utc == T0 + timedelta(seconds=3)
    assert dataclasses.replace(plan.state, time_utc=T0) == _engine().state
    assert plan.frame.sky.sun.elevation_deg > 40.0  # Zurich early afternoon in June


def _count_ephemeris(monkeypatch: pytest.MonkeyPatch) -> list[datetime]:
    """The times the sky asks the ephemeris for, from now on (its smoothed form, which works
    the exact one out every 2 s and interpolates between)."""
    calls: list[datetime] = []
    real = sky_module.sun_and_moon_smooth

    def counted(time_utc: datetime, *args: float, **kw: bool) -> object:
        calls.append(time_utc)
        return real(time_utc, *args, **kw)

    monkeypatch.setattr(sky_module, "sun_and_moon_smooth", counted)
    return calls


def test_one_ephemeris_per_frame_shared_with_the_scene_sky(monkeypatch: pytest.MonkeyPatch) -> None:
    engine = _engine(rate=1.0)
    calls = _count_ephemeris(monkeypatch)
    plan = engine.advance(0.5)
    # What the daemon reports as the scene after the frame is of the same moment.
    scene_sky = engine.sky()
    assert calls == [plan.state.time_utc]
    assert scene_sky.sun == plan.frame.sky.sun and scene_sky.moon == plan.frame.sky.moon
    # Only the eye differs: the scene's sky is the observer's, the frame's the camera's.
    assert scene_sky == sky_module.sky_params(plan.state)
    calls.clear()
    later = engine.advance(0.5)
    assert calls == [later.state.time_utc]


def test_a_stopped_clock_needs_no_new_ephemeris(monkeypatch: pytest.MonkeyPatch) -> None:
    engine = _engine(rate=0.0)
    calls = _count_ephemeris(monkeypatch)
    for _ in range(3):
        engine.advance(1.0)
    assert calls == [T0]
    # A new site is another sky at the same moment.
    engine.apply(WeatherPatch(source=Source.PRESET, observer=Observer(10.0, 20.0, 0.0)))
    plan = engine.advance(1.0)
    assert calls == [T0, T0]
    assert plan.frame.sky.sun == sky_module.sky_params(plan.state).sun


def test_enu_from_geodetic() -> None:
    # One degree north is ~110.5 km, one degree east at 60° N is half of ~111.3 km.
    e, n, u = enu_from_geodetic(60.0, 10.0, 61.0, 11.0, 1234.0)
    assert n == pytest.approx(110_540.0)
    assert e == pytest.approx(111_320.0 * 0.5, rel=1e-9)
    assert u == 1234.0
    assert enu_from_geodetic(47.0, 8.0, 47.0, 8.0, 0.0) == (0.0, 0.0, 0.0)


def test_near_and_ring_partition_the_clouds_while_they_drift() -> None:
    """Between ring rebuilds the near layer keeps the ring's choice of blocks: a drifting
    block is never drawn both as sprites and in an impostor, nor dropped from both."""
    from wxsky.scene.gather import gather_blocks
    from wxsky.scene.layout import in_view

    eng = _engine(rate=1.0, wind_mps=20.0)
    first = eng.advance(0.0)
    plan = eng.advance(10.0)  # 200 m of drift: below the 3 % rebuild threshold
    assert not plan.ring_changed
    ring = plan.ring
    drift_now = eng._drift  # the drift the frame was placed with
    offset = np.asarray(drift_now[0]) - np.asarray(ring.drift[0])
    far = np.unique(np.concatenate([i.sprites.centre_m for i in ring.impostors]), axis=0)
    far_now = far + np.array([offset[0], offset[1], 0.0])
    near = plan.frame.near.sprites.centre_m
    near_set = {tuple(np.round(p, 3)) for p in near}
    far_set = {tuple(np.round(p, 3)) for p in far_now}
    assert near_set and far_set
    assert not near_set & far_set
    settings = eng.settings
    everything = gather_blocks(
        plan.state,
        drift_now,
        ring.geometry.centre_m,
        0.0,
        settings.max_range_m,
        select_drift=ring.drift,
    )
    every_key = [tuple(np.round(p, 3)) for p in everything.centre_m]
    assert far_set <= set(every_key)
    # The near layer is the rest, less what is out of view (culled, never drawn).
    rest = everything.take(np.array([k not in far_set for k in every_key]))
    seen = rest.take(in_view(rest, plan.frame.camera))
    assert 0 < len(seen) < len(rest)
    assert near_set == {tuple(np.round(p, 3)) for p in seen.centre_m}
    assert first.ring is ring


# -- sources and transitions ----------------------------------------------------------------


def _live_engine() -> SkyEngine:
    from wxsky.weather.transition import TransitionRates

    state = WeatherState(time_utc=T0, layers=(CU,), seed=5)
    return SkyEngine(
        state,
        _camera(),
        SETTINGS,
        clock_rate=1.0,
        rates=TransitionRates(cover_oktas_per_min=3.0, base_m_per_min=600.0),
        transition_step_s=1.0,
        cockpit_hold_s=5.0,
    )


def test_a_metar_moves_the_applied_weather_step_by_step() -> None:
    engine = _live_engine()
    ovc = CloudLayer(8, 1900.0, 2700.0, CloudType.CUMULUS)
    engine.apply(WeatherPatch(source=Source.METAR, layers=(ovc,)))
    assert engine.target.layers == (ovc,) and engine.target.sources.layers is Source.METAR
    assert engine.state.layers == (CU,) and not engine.settled
    covers = []
    for _ in range(30):  # quarter-second frames: a step each second
        for _ in range(4):
            engine.advance(0.25)
        covers.append(engine.state.layers[0].cover_oktas)
    # 3 oktas/min: 0.05 per one-second step, never more; 5 oktas in 100 s.
    assert covers[0] == pytest.approx(3.05, abs=0.02)
    assert max(b - a for a, b in itertools.pairwise(covers)) <= 0.05 + 1e-9
    assert covers[-1] == pytest.approx(3.0 + 30 * 0.05, abs=0.05)
    assert engine.state.time_utc == T0 + timedelta(seconds=30)


def test_control_override_beats_a_later_metar_until_released() -> None:
    engine = _live_engine()
    ovc = (CloudLayer(8, 800.0, 1200.0, CloudType.STRATUS),)
    engine.apply(WeatherPatch(source=Source.CONTROL, layers=ovc))
    engine.apply(WeatherPatch(source=Source.METAR, layers=(CU,), visibility_m=3000.0))
    assert engine.target.layers == ovc and engine.target.visibility_m == 3000.0
    assert engine.release(Source.CONTROL) == ("layers",)
    assert engine.target.layers == (CU,) and engine.target.sources.layers is Source.METAR


def test_cockpit_hold_expires_with_wall_time_not_sim_time() -> None:
    engine = _live_engine()
    engine.clock_rate = 1000.0
    engine.apply(WeatherPatch(source=Source.COCKPIT, visibility_m=800.0))
    engine.advance(4.0)
    assert engine.target.visibility_m == 800.0
    engine.advance(1.5)
    assert engine.target.visibility_m == WeatherState().visibility_m
    assert engine.target.sources.visibility_m is Source.DEFAULT


def test_a_new_site_is_applied_at_once() -> None:
    from wxsky.weather.state import Observer

    engine = _live_engine()
    engine.apply(
        WeatherPatch(source=Source.CONTROL, observer=Observer(40.0, -105.0, 1600.0), layers=())
    )
    assert engine.settled and engine.state.layers == ()


def test_geodetic_round_trip() -> None:
    from wxsky.engine.stages import geodetic_from_enu

    east, north, _ = enu_from_geodetic(47.0, 8.0, 47.1, 8.2, 500.0)
    lat, lon = geodetic_from_enu(47.0, 8.0, east, north)
    assert lat == pytest.approx(47.1, abs=1e-9) and lon == pytest.approx(8.2, abs=1e-9)


def test_the_state_summary_writes_early_years_with_four_digits() -> None:
    state = WeatherState(time_utc=datetime(857, 3, 4, 5, 6, tzinfo=UTC), layers=(CU,))
    assert state.summary().startswith("0857-03-04T05:06Z wind calm vis ")
