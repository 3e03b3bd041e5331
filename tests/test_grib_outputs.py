"""The model's column reaches the outputs (issue 45): CIGI's layer winds, as the CIGI decoder
reads them back, and FlightGear's winds aloft are the column's wind at each height, not one
wind for the whole sky."""

from __future__ import annotations

import dataclasses
import math

import pytest
from grib_fixture import GFS, LONDON, VALID, needs_gfs

from wxsky.inputs.grib_decode import Window, decode
from wxsky.protocols.cigi import decode_datagram, encode_datagram
from wxsky.protocols.cigi_source import SourceFrame, cloud_packets, host_message
from wxsky.protocols.flightgear import weather_properties
from wxsky.units import KT_TO_MPS
from wxsky.weather.model_clouds import model_layers
from wxsky.weather.model_fields import merge_steps
from wxsky.weather.model_profile import ModelProfile, profile_at
from wxsky.weather.state import CloudLayer, CloudType, Observer, WeatherState

pytestmark = needs_gfs


@pytest.fixture(scope="module")
def column() -> ModelProfile:
    steps = merge_steps(decode(GFS.read_bytes(), "gfs", Window(*LONDON)), ("gfs",))
    p = profile_at(steps, *LONDON, VALID)
    assert p is not None
    return p


@pytest.fixture(scope="module")
def state(column: ModelProfile) -> WeatherState:
    """The weather the daemon makes of the column: its wind by height and its clouds."""
    layers = model_layers(column)
    assert len(layers) >= 2
    return dataclasses.replace(
        WeatherState(),
        observer=Observer(*LONDON, 25.0),
        wind=column.winds(),
        layers=layers,
        time_utc=VALID,
    )


def _wind_at(column: ModelProfile, alt_m: float) -> tuple[float, float]:
    """(speed m/s, from degrees) of the column at a height, straight from the profile."""
    at = column.at_height(alt_m)
    assert at is not None
    return at.speed_mps, at.dir_deg


def test_cigi_layers_carry_the_wind_at_their_own_heights(
    state: WeatherState, column: ModelProfile
) -> None:
    datagram = encode_datagram(host_message(state, SourceFrame()))
    got = [p.as_dict() for p in decode_datagram(datagram).packets if p.key == "weather_control"]
    on = [g for g in got if g["weather_enable"]]
    assert len(on) >= 2
    winds = []
    for g in on:
        mid = float(g["base_elevation_m"]) + float(g["thickness_m"]) / 2.0  # type: ignore[arg-type]
        speed, direction = _wind_at(column, mid)
        assert float(g["wind_speed_mps"]) == pytest.approx(speed, abs=0.05)  # type: ignore[arg-type]
        turn = (float(g["wind_dir_deg"]) - direction + 180.0) % 360.0 - 180.0  # type: ignore[arg-type]
        assert abs(turn) < 0.5
        winds.append(speed)
    assert max(winds) - min(winds) > 5.0  # the layers' winds differ by height


def test_flightgears_winds_aloft_are_the_columns(state: WeatherState, column: ModelProfile) -> None:
    props = dict(weather_properties(state))
    speeds = []
    for i in range(3):
        entry = f"/environment/config/aloft/entry[{i}]"
        alt_m = float(props[f"{entry}/elevation-ft"]) * 0.3048
        speed, direction = _wind_at(column, alt_m)
        assert float(props[f"{entry}/wind-speed-kt"]) == pytest.approx(speed / KT_TO_MPS, abs=0.02)
        turn = (float(props[f"{entry}/wind-from-heading-deg"]) - direction + 180.0) % 360.0
        assert abs(turn - 180.0) < 0.05 or math.isclose(speed, 0.0)
        speeds.append(speed)
    assert len(set(round(s, 1) for s in speeds)) == 3
    assert not any(p.endswith("temperature-degc") and "aloft" in p for p in props)
    # with the model's temperatures (as the daemon offers them), each entry has its own
    aloft = tuple((lev.height_m, lev.t_k - 273.15) for lev in column.levels)
    warm = dict(weather_properties(state, aloft))
    for i in range(3):
        entry = f"/environment/config/aloft/entry[{i}]"
        at = column.at_height(float(warm[f"{entry}/elevation-ft"]) * 0.3048)
        assert at is not None
        assert float(warm[f"{entry}/temperature-degc"]) == pytest.approx(at.t_k - 273.15, abs=0.02)


def test_a_layer_the_model_gives_no_wind_for_falls_back_to_the_nearest_level(
    state: WeatherState, column: ModelProfile
) -> None:
    """Above the column's top level the wind holds the top level's (no extrapolation)."""
    high = dataclasses.replace(
        state, layers=(CloudLayer(2.0, 20_000.0, 21_000.0, CloudType.CIRRUS),)
    )
    (packet, *_) = cloud_packets(high, high.layers)
    top = column.levels[-1]
    assert float(packet["wind_speed_mps"]) == pytest.approx(top.speed_mps, abs=0.05)  # type: ignore[arg-type]
