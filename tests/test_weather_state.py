"""WeatherState's per-frame shortcuts: the clock's step and the wind profile, which must give
what the checked, uncached ways give."""

from __future__ import annotations

import dataclasses
from datetime import datetime, timedelta, timezone

import pytest

from wxsky.weather.state import CloudLayer, CloudType, WeatherState, WindLayer


def _state() -> WeatherState:
    return WeatherState(
        layers=(CloudLayer(cover_oktas=3.0, base_m=1200.0, top_m=2000.0, type=CloudType.CUMULUS),),
        wind=(WindLayer(0.0, 270.0, 5.0), WindLayer(3000.0, 300.0, 20.0)),
    )


def test_at_time_is_replace_with_the_time() -> None:
    state = _state()
    later = state.time_utc + timedelta(seconds=1.5)
    moved = state.at_time(later)
    assert moved == dataclasses.replace(state, time_utc=later)
    assert moved.time_utc == later and state.time_utc != later  # the original is untouched


@pytest.mark.parametrize(
    "when",
    [
        datetime(2026, 6, 21, 12, 0),
        datetime(2026, 6, 21, 12, 0, tzinfo=timezone(timedelta(hours=2))),
    ],
)
def test_at_time_refuses_a_time_that_is_not_utc(when: datetime) -> None:
    with pytest.raises(ValueError, match="UTC"):
        _state().at_time(when)


def test_the_wind_profile_follows_the_state_it_belongs_to() -> None:
    state = _state()
    assert state.wind_at(1500.0) == pytest.approx(
        [
            0.5 * (a + b)
            for a, b in zip(state.wind[0].velocity_mps(), state.wind[1].velocity_mps(), strict=True)
        ]
    )
    calmer = dataclasses.replace(state, wind=(WindLayer(0.0, 90.0, 2.0),))
    assert calmer.wind_at(1500.0) == pytest.approx(WindLayer(0.0, 90.0, 2.0).velocity_mps())
    assert state.at_time(state.time_utc + timedelta(hours=1)).wind_at(1500.0) == state.wind_at(
        1500.0
    )
    assert dataclasses.replace(state, wind=()).wind_at(1500.0) == (0.0, 0.0)


def test_the_layers_drift_winds_are_each_layers_mid_altitude_wind_of_its_own_state() -> None:
    state = _state()
    (layer,) = state.layers
    mid = 0.5 * (layer.base_m + layer.top_m)
    assert state.layer_winds_mps == (state.wind_at(mid),)
    assert state.at_time(state.time_utc + timedelta(hours=1)).layer_winds_mps == (
        state.wind_at(mid),
    )
    calm = dataclasses.replace(state, wind=())
    assert calm.layer_winds_mps == ((0.0, 0.0),)
    assert dataclasses.replace(state, layers=()).layer_winds_mps == ()


@pytest.mark.parametrize("bad", [3, "cumulus", None])
def test_a_cloud_layer_of_no_cloud_type_is_refused(bad: object) -> None:
    with pytest.raises(ValueError, match="cloud layer type must be one of CloudType"):
        CloudLayer(3.0, 1200.0, 2000.0, bad)  # type: ignore[arg-type]
