"""The applied weather moves toward the target at the configured rates, never faster."""

from __future__ import annotations

import dataclasses
import itertools
import math

import pytest

from wxsky.weather.state import CloudLayer, CloudType, Source, WeatherPatch, WeatherState, WindLayer
from wxsky.weather.transition import INSTANT, TransitionRates, pair_layers, settled, step_toward

CU = CloudType.CUMULUS
ST = CloudType.STRATUS
RATES = TransitionRates(
    cover_oktas_per_min=2.0,
    base_m_per_min=300.0,
    wind_mps_per_s=1.0,
    visibility_m_per_s=100.0,
    temperature_c_per_min=2.0,
    qnh_hpa_per_min=2.0,
)


def _state(*layers: CloudLayer, **kw: object) -> WeatherState:
    return dataclasses.replace(WeatherState(), layers=layers, **kw)  # type: ignore[arg-type]


def _run(applied: WeatherState, target: WeatherState, seconds: int) -> list[WeatherState]:
    out = [applied]
    for _ in range(seconds):
        out.append(step_toward(out[-1], target, 1.0, RATES))
    return out


def test_cover_grows_at_the_rate_and_stops_at_the_target() -> None:
    start = _state(CloudLayer(2, 1000.0, 2000.0, CU))
    goal = _state(CloudLayer(6, 1000.0, 2000.0, CU))
    states = _run(start, goal, 150)
    covers = [s.layers[0].cover_oktas for s in states]
    steps = [b - a for a, b in itertools.pairwise(covers)]
    assert max(steps) == pytest.approx(2.0 / 60.0)
    assert min(steps) >= 0.0
    # 4 oktas at 2 oktas/min: two minutes, then it holds.
    assert covers[119] < 6.0 and covers[121] == 6.0 and covers[-1] == 6.0
    assert settled(states[-1], goal) and not settled(states[60], goal)


def test_base_creeps_and_top_follows() -> None:
    start = _state(CloudLayer(8, 500.0, 900.0, ST))
    goal = _state(CloudLayer(8, 800.0, 1100.0, ST))
    after_30s = step_toward(start, goal, 30.0, RATES)
    assert after_30s.layers[0].base_m == pytest.approx(650.0)
    assert after_30s.layers[0].top_m == pytest.approx(1050.0)
    assert step_toward(after_30s, goal, 60.0, RATES).layers == goal.layers


def test_a_new_type_dissipates_the_old_layer_and_forms_the_new_one() -> None:
    start = _state(CloudLayer(4, 1200.0, 2400.0, CU))
    goal = _state(CloudLayer(8, 400.0, 800.0, ST))
    mid = step_toward(start, goal, 60.0, RATES)
    by_type = {lay.type: lay.cover_oktas for lay in mid.layers}
    assert by_type == {ST: pytest.approx(2.0), CU: pytest.approx(2.0)}
    # The forming stratus sits at its own base from the start; it does not slide there.
    assert next(lay for lay in mid.layers if lay.type == ST).base_m == 400.0
    end = step_toward(mid, goal, 300.0, RATES)
    assert end.layers == goal.layers


def test_pairing_takes_the_nearest_layer_of_the_same_type() -> None:
    low, high = CloudLayer(3, 800.0, 1500.0, CU), CloudLayer(3, 3000.0, 4000.0, CU)
    goal = CloudLayer(5, 2800.0, 3900.0, CU)
    pairs = pair_layers((low, high), (goal,))
    assert pairs == [(high, goal), (low, None)]


def test_never_more_than_six_layers_while_changing() -> None:
    old = tuple(CloudLayer(3, 1000.0 + 1000 * i, 1500.0 + 1000 * i, CU) for i in range(6))
    new = tuple(CloudLayer(3, 1200.0 + 1000 * i, 1700.0 + 1000 * i, ST) for i in range(6))
    for state in _run(_state(*old), _state(*new), 200):
        assert len(state.layers) <= 6
    assert _run(_state(*old), _state(*new), 200)[-1].layers == new


def test_wind_turns_through_the_short_way_at_the_vector_rate() -> None:
    start = _state(wind=(WindLayer(10.0, 350.0, 10.0),))
    goal = _state(wind=(WindLayer(10.0, 10.0, 10.0),))
    states = _run(start, goal, 10)
    dirs = [s.wind[0].dir_from_deg for s in states]
    # The short way round is through north, never through south.
    assert all(d >= 349.0 or d <= 11.0 for d in dirs)
    assert dirs[-1] == 10.0
    # The vector difference is 2*10*sin(10°) = 3.47 m/s: four steps at 1 m/s.
    assert states[3].wind[0].dir_from_deg != 10.0 and states[4].wind[0].dir_from_deg == 10.0


def test_gusts_and_wind_profile_follow() -> None:
    start = _state(wind=(WindLayer(10.0, 270.0, 5.0),))
    goal = _state(wind=(WindLayer(10.0, 270.0, 5.0, gust_mps=12.0), WindLayer(3000.0, 270.0, 20.0)))
    one = step_toward(start, goal, 1.0, RATES)
    assert [w.alt_m for w in one.wind] == [10.0, 3000.0]
    assert one.wind[0].gust_mps == pytest.approx(1.0)
    assert one.wind[1].speed_mps == pytest.approx(6.0)  # from 5 m/s (the old profile) by 1


def test_scalars_move_at_their_rates_and_unknowns_switch() -> None:
    start = _state(visibility_m=10_000.0, temperature_c=20.0, qnh_hpa=1013.0, dewpoint_c=None)
    goal = _state(visibility_m=800.0, temperature_c=10.0, qnh_hpa=1000.0, dewpoint_c=8.0)
    one = step_toward(start, goal, 10.0, RATES)
    assert one.visibility_m == pytest.approx(9000.0)
    assert one.temperature_c == pytest.approx(20.0 - 2.0 / 6.0)
    assert one.qnh_hpa == pytest.approx(1013.0 - 2.0 / 6.0)
    assert one.dewpoint_c == 8.0  # nothing to move from


def test_instant_rates_and_zero_dt() -> None:
    start = _state(CloudLayer(2, 1000.0, 2000.0, CU))
    goal = _state(CloudLayer(8, 300.0, 700.0, ST), visibility_m=500.0)
    assert settled(step_toward(start, goal, 0.0, INSTANT), goal)
    frozen = step_toward(start, goal, 0.0, RATES)
    assert [(lay.type, lay.cover_oktas) for lay in frozen.layers] == [(ST, 0.0), (CU, 2.0)]


def test_observer_seed_and_sources_switch_at_once() -> None:
    start = WeatherState()
    goal = start.apply(WeatherPatch(source=Source.METAR, seed=77, present_weather=("-RA",)))
    one = step_toward(start, goal, 0.1, RATES)
    assert one.seed == 77 and one.present_weather == ("-RA",)
    assert one.sources.seed is Source.METAR


def test_rates_must_be_finite() -> None:
    with pytest.raises(ValueError, match="cover_oktas_per_min"):
        TransitionRates(cover_oktas_per_min=math.nan)
