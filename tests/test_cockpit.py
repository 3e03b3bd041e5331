"""Cockpit values over the weather: range checks, the layer and wind overlay, the clock, and
their place in the precedence stack and the engine."""

from __future__ import annotations

import dataclasses
import math
from datetime import UTC, date, datetime, timedelta

import pytest

from wxsky.engine.stages import REORIGIN_M, SkyEngine
from wxsky.scene.camera import Camera
from wxsky.scene.layout import SceneSettings
from wxsky.weather.cockpit import (
    DEFAULT_LAYER_BASE_AGL_M,
    QNH,
    TEMPERATURE,
    WIND_DIR,
    WIND_SPEED,
    CockpitUpdate,
    check_groups,
    checked,
    clock_target,
    layer_key,
    overlay,
)
from wxsky.weather.precedence import SourceStack
from wxsky.weather.state import (
    CloudLayer,
    CloudType,
    Observer,
    Source,
    WeatherPatch,
    WeatherState,
    WindLayer,
)

FIELD_M = 400.0
BELOW = WeatherState(
    observer=Observer(47.0, 8.0, FIELD_M),
    layers=(
        CloudLayer(2.0, 1400.0, 2600.0, CloudType.CUMULUS),
        CloudLayer(6.0, 4000.0, 4500.0, CloudType.ALTOCUMULUS),
    ),
    wind=(
        WindLayer(410.0, 270.0, 5.0, gust_mps=9.0),
        WindLayer(3000.0, 290.0, 15.0),
    ),
)
SKY = datetime(2026, 6, 21, 12, 0, 0, tzinfo=UTC)


# -- checked ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("key", "value", "expected"),
    [
        (WIND_DIR, -90.0, 270.0),
        (WIND_DIR, -180.0, 180.0),
        (WIND_DIR, 360.0, 0.0),
        (WIND_DIR, -1e-300, 0.0),
        (WIND_SPEED, 150.0, 150.0),
        (layer_key(2, "cover_oktas"), 8.0, 8.0),
        (QNH, 1013.25, 1013.25),
    ],
)
def test_checked_accepts_and_normalises(key: str, value: float, expected: float) -> None:
    assert checked(key, value) == expected


@pytest.mark.parametrize(
    ("key", "value", "fragment"),
    [
        (WIND_SPEED, 999.0, "wind.speed_mps 999 out of range 0..150"),
        (WIND_SPEED, -1.0, "out of range"),
        (WIND_SPEED, math.nan, "not a finite number"),
        (WIND_DIR, math.inf, "not a finite number"),
        (WIND_DIR, 361.0, "out of range -180..360"),
        (layer_key(1, "cover_oktas"), 9.0, "layer1.cover_oktas 9 out of range 0..8"),
        (layer_key(1, "thickness_m"), 0.0, "out of range 0..25000 and more than 0"),
        (TEMPERATURE, 80.0, "out of range -90..60"),
        ("layer9.base_m", 1000.0, "unknown cockpit value"),
    ],
)
def test_checked_rejects(key: str, value: float, fragment: str) -> None:
    with pytest.raises(ValueError, match=fragment):
        checked(key, value)


def test_layer_key_range() -> None:
    assert layer_key(3, "base_m") == "layer3.base_m"
    with pytest.raises(ValueError, match=r"out of range 1\.\.3"):
        layer_key(7, "base_m")


def test_groups_restrict_an_update() -> None:
    update = CockpitUpdate(
        values={WIND_SPEED: 4.0, QNH: 1000.0, layer_key(1, "cover_oktas"): 3.0},
        time_of_day_s=100.0,
        position_deg=(1.0, 2.0),
    )
    only_wind = update.restricted(("wind",))
    assert dict(only_wind.values) == {WIND_SPEED: 4.0}
    assert only_wind.time_of_day_s is None and only_wind.position_deg is None
    assert update.restricted(("time",)).time_of_day_s == 100.0
    assert update.restricted(()).empty
    with pytest.raises(ValueError, match="unknown field group 'rain'"):
        check_groups(["wind", "rain"])


# -- the overlay --------------------------------------------------------------------------


def test_nothing_from_the_cockpit_leaves_the_weather() -> None:
    assert overlay(BELOW, {}) is BELOW


def test_layer_one_is_the_lowest_layer_below() -> None:
    out = overlay(BELOW, {layer_key(1, "cover_oktas"): 8.0})
    low = out.layers[0]
    assert (low.cover_oktas, low.base_m, low.top_m, low.type) == (
        8.0,
        1400.0,
        2600.0,
        CloudType.CUMULUS,
    )
    assert out.layers[1] == BELOW.layers[1]
    assert out.sources.layers is Source.COCKPIT
    assert out.sources.wind is Source.DEFAULT


def test_zero_cover_clears_a_layer() -> None:
    out = overlay(BELOW, {layer_key(2, "cover_oktas"): 0.0})
    assert out.layers == (BELOW.layers[0],)


def test_a_new_layer_takes_defaults_and_a_derived_type() -> None:
    out = overlay(BELOW, {layer_key(3, "cover_oktas"): 8.0})
    new = out.layers[2]
    assert new.base_m == FIELD_M + DEFAULT_LAYER_BASE_AGL_M[2]
    # 7 km above the field is the high étage; overcast there is cirrostratus in the table.
    assert new.type is CloudType.CIRROSTRATUS
    assert new.thickness_m == pytest.approx(800.0)


def test_a_base_without_cover_makes_no_layer() -> None:
    out = overlay(BELOW, {layer_key(3, "base_m"): 9000.0})
    assert out.layers == BELOW.layers


def test_given_parts_win_and_none_type_is_derived() -> None:
    values = {
        layer_key(2, "cover_oktas"): 8.0,
        layer_key(2, "base_m"): 5000.0,
        layer_key(2, "thickness_m"): 1200.0,
        layer_key(2, "type"): CloudType.NONE,
    }
    out = overlay(BELOW, values)
    mid = out.layers[1]
    assert (mid.base_m, mid.top_m) == (5000.0, 6200.0)
    assert mid.type is CloudType.ALTOSTRATUS  # middle étage, overcast
    named = overlay(BELOW, {**values, layer_key(2, "type"): CloudType.NIMBOSTRATUS})
    assert named.layers[1].type is CloudType.NIMBOSTRATUS


def test_a_top_past_the_ceiling_is_clipped() -> None:
    values = {
        layer_key(1, "cover_oktas"): 4.0,
        layer_key(1, "base_m"): 24_800.0,
        layer_key(1, "thickness_m"): 2000.0,
    }
    top = overlay(BELOW, values).layers[-1]
    assert (top.base_m, top.top_m) == (24_800.0, 25_000.0)


def test_surface_wind_replaced_and_aloft_turns_with_it() -> None:
    out = overlay(BELOW, {WIND_DIR: 180.0, WIND_SPEED: 10.0})
    surface, aloft = out.wind
    assert (surface.dir_from_deg, surface.speed_mps, surface.gust_mps) == (180.0, 10.0, 0.0)
    assert aloft.dir_from_deg == pytest.approx(200.0)  # turned by the same -90°
    assert aloft.speed_mps == pytest.approx(30.0)  # scaled by the same 2x
    assert out.sources.wind is Source.COCKPIT


def test_direction_alone_keeps_the_speed_and_gust() -> None:
    surface = overlay(BELOW, {WIND_DIR: 90.0}).wind[0]
    assert (surface.dir_from_deg, surface.speed_mps, surface.gust_mps) == (90.0, 5.0, 9.0)


def test_wind_into_a_calm_sky() -> None:
    calm = WeatherState(observer=Observer(0.0, 0.0, 100.0), wind=())
    (only,) = overlay(calm, {WIND_SPEED: 7.0}).wind
    assert (only.alt_m, only.dir_from_deg, only.speed_mps) == (100.0, 0.0, 7.0)


def test_scalars() -> None:
    out = overlay(BELOW, {QNH: 990.0, TEMPERATURE: -5.0})
    assert (out.qnh_hpa, out.temperature_c) == (990.0, -5.0)
    assert out.sources.qnh_hpa is Source.COCKPIT and out.sources.visibility_m is Source.DEFAULT


# -- the clock ----------------------------------------------------------------------------


def test_full_time_sets_the_clock() -> None:
    then = datetime(1987, 6, 12, 13, 43, 22, tzinfo=UTC)
    assert clock_target(SKY, CockpitUpdate(time_utc=then)) == then


def test_time_of_day_lands_on_the_nearest_day() -> None:
    late = datetime(2026, 6, 21, 23, 59, 58, tzinfo=UTC)
    after_midnight = clock_target(late, CockpitUpdate(time_of_day_s=2.0, time_resolution_s=1.0))
    assert after_midnight == datetime(2026, 6, 22, 0, 0, 2, tzinfo=UTC)
    early = datetime(2026, 6, 22, 0, 0, 5, tzinfo=UTC)
    before = clock_target(early, CockpitUpdate(time_of_day_s=86_399.0, time_resolution_s=1.0))
    assert before == datetime(2026, 6, 21, 23, 59, 59, tzinfo=UTC)


def test_whole_seconds_do_not_pull_the_clock_back() -> None:
    sky = SKY + timedelta(seconds=0.9)
    assert (
        clock_target(sky, CockpitUpdate(time_of_day_s=12 * 3600.0, time_resolution_s=1.0)) is None
    )
    # ...but a clock two seconds off is set.
    sky = SKY + timedelta(seconds=2.0)
    assert clock_target(sky, CockpitUpdate(time_of_day_s=12 * 3600.0, time_resolution_s=1.0)) == SKY


def test_date_alone_keeps_the_time_of_day() -> None:
    moved = clock_target(SKY, CockpitUpdate(date_utc=date(1987, 6, 12)))
    assert moved == datetime(1987, 6, 12, 12, 0, tzinfo=UTC)
    assert clock_target(SKY, CockpitUpdate(date_utc=SKY.date())) is None


def test_date_straddling_midnight_is_left_to_the_time() -> None:
    late = datetime(2026, 6, 21, 23, 59, 59, tzinfo=UTC)
    assert clock_target(late, CockpitUpdate(date_utc=date(2026, 6, 22))) is None
    # Far from midnight the same one-day difference is a real change.
    assert clock_target(SKY, CockpitUpdate(date_utc=date(2026, 6, 22))) == SKY + timedelta(days=1)


# -- the stack and the engine -------------------------------------------------------------


def test_cockpit_values_beat_control_and_expire_one_by_one() -> None:
    stack = SourceStack(base=BELOW, cockpit_hold_s=30.0)
    stack = stack.with_patch(WeatherPatch(Source.CONTROL, visibility_m=800.0), 0.0)
    stack = stack.with_cockpit_values({WIND_SPEED: 12.0}, 0.0)
    stack = stack.with_cockpit_values({layer_key(1, "cover_oktas"): 7.0}, 20.0)
    target = stack.target()
    assert target.wind[0].speed_mps == 12.0 and target.layers[0].cover_oktas == 7.0
    assert target.visibility_m == 800.0
    stack, gone = stack.expired(40.0)
    assert gone == (WIND_SPEED,)
    target = stack.target()
    assert target.wind[0].speed_mps == 5.0 and target.layers[0].cover_oktas == 7.0
    stack, fields = stack.released(Source.COCKPIT)
    assert fields == ("layer1.cover_oktas",)
    assert stack.target().layers == BELOW.layers


def engine(state: WeatherState = BELOW) -> SkyEngine:
    camera = Camera(position_m=(0.0, 0.0, state.observer.alt_m + 2.0))
    return SkyEngine(state, camera, SceneSettings())


def test_engine_applies_cockpit_weather_time_and_position() -> None:
    eng = engine()
    before = eng.weather_version, eng.target_version
    eng.apply_cockpit(
        CockpitUpdate(
            values={WIND_DIR: 90.0, layer_key(1, "cover_oktas"): 5.0},
            time_utc=datetime(2026, 12, 1, 6, 30, tzinfo=UTC),
            position_deg=(47.01, 8.0),
        )
    )
    assert eng.target.wind[0].dir_from_deg == 90.0
    assert eng.state.layers[0].cover_oktas == 5.0  # instant rates settle at once
    assert eng.state.time_utc == datetime(2026, 12, 1, 6, 30, tzinfo=UTC)
    assert eng.state.sources.time_utc is Source.COCKPIT
    east, north, _ = eng.camera.position_m
    assert east == pytest.approx(0.0, abs=1e-6)
    assert north == pytest.approx(1105.4, rel=1e-3)
    assert eng.weather_version > before[0] and eng.target_version > before[1]
    assert "layer1.cover_oktas" in eng.sources.holds(eng.wall_s)


def test_a_far_position_is_a_new_site() -> None:
    eng = engine()
    eng.apply_cockpit(CockpitUpdate(position_deg=(51.47, -0.46)))
    assert (eng.state.observer.lat_deg, eng.state.observer.lon_deg) == (51.47, -0.46)
    assert eng.camera.position_m[:2] == (0.0, 0.0)
    assert REORIGIN_M < 1_000_000.0


def test_a_time_that_moves_the_clock_takes_the_date_sent_just_before() -> None:
    sky = datetime(2027, 1, 1, 0, 0, 5, tzinfo=UTC)
    # The date alone is ambiguous this near midnight...
    assert clock_target(sky, CockpitUpdate(date_utc=date(2027, 1, 2))) is None
    # ...but the time that follows it moves the clock five hours: it goes on that date.
    moved = clock_target(sky, CockpitUpdate(time_of_day_s=5 * 3600.0), date(2027, 1, 2))
    assert moved == datetime(2027, 1, 2, 5, 0, tzinfo=UTC)


def test_a_stale_date_does_not_undo_a_midnight_rollover() -> None:
    sky = datetime(2027, 1, 1, 23, 59, 59, 900_000, tzinfo=UTC)
    # The time frame of the new day comes before the new date; the old date is still recent.
    moved = clock_target(
        sky, CockpitUpdate(time_of_day_s=0.0, time_resolution_s=1.0), date(2027, 1, 1)
    )
    assert moved is None or moved == datetime(2027, 1, 2, 0, 0, tzinfo=UTC)


def test_engine_pairs_a_cockpit_date_with_the_next_time() -> None:
    eng = engine(dataclasses.replace(BELOW, time_utc=datetime(2027, 1, 1, 0, 0, 5, tzinfo=UTC)))
    eng.apply_cockpit(CockpitUpdate(date_utc=date(2027, 1, 2)))
    eng.apply_cockpit(CockpitUpdate(time_of_day_s=5 * 3600.0, time_resolution_s=1.0))
    assert eng.state.time_utc == datetime(2027, 1, 2, 5, 0, tzinfo=UTC)
