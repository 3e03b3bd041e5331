"""The channel bus's messages (wxsky/share/messages.py) and wire packing of single values:
what a master sends decodes to what it sent, and what a channel must not take (garbage,
truncation, out-of-range values, another site or version, a weather the weather state
refuses) is refused with one line naming the field."""

from __future__ import annotations

import dataclasses
from datetime import UTC, datetime, timedelta
from typing import Any

import pytest

from wxsky.output.wire import WireError, pack_data, unpack_data
from wxsky.scene.camera import Camera
from wxsky.scene.tower_field import LayerEpoch
from wxsky.settings.presets import load_preset
from wxsky.share.messages import (
    ClockTick,
    Health,
    ShareError,
    SkyState,
    decode_health,
    decode_pong,
    decode_state,
    decode_tick,
    encode_health,
    encode_pong,
    encode_state,
    encode_tick,
    sky_id,
    time_from_us,
    time_to_us,
)
from wxsky.weather.state import EARLIEST_UTC, LATEST_UTC, WeatherState

MASTER = "0123456789abcdef"
_END_US = time_to_us(LATEST_UTC) - 1  # the last microsecond of the clock's range
_BEFORE_US = time_to_us(EARLIEST_UTC) - 1
_Y9999_US = time_to_us(datetime(9999, 12, 31, 23, 59, 58, tzinfo=UTC))
WHEN = datetime(2026, 6, 21, 13, 0, 0, 123456, tzinfo=UTC)


def _state(preset: str = "thunderstorm", **changes: Any) -> SkyState:
    weather = dataclasses.replace(WeatherState().apply(load_preset(preset)), time_utc=WHEN)
    drift = tuple((0.1 + i / 3.0, -7.25 * i) for i in range(len(weather.layers)))
    # The storm's stratus and stratocumulus make no towers; its cumulonimbus was set 25
    # minutes ago and has been clearing for 2.
    epochs = (
        None,
        None,
        LayerEpoch(WHEN - timedelta(minutes=25), 52.5, WHEN - timedelta(minutes=2), 6.0),
    )
    base = SkyState("default", MASTER, 12, 5, weather, weather, WHEN, drift, 1.0, epochs)
    return dataclasses.replace(base, **changes)


def _tick(**changes: Any) -> ClockTick:
    cam = Camera((10.0, -20.0, 1500.0), 90.0, 5.0, -3.0, 60.0, 320, 180)
    base = ClockTick("default", MASTER, 1234.5, WHEN, 1.0, 12, cam, (1.0, 2.0, 3.0))
    return dataclasses.replace(base, **changes)


def _over_the_wire(message: dict[str, Any]) -> object:
    return unpack_data(pack_data(message))


def test_a_state_decodes_to_what_the_master_sent_to_the_microsecond() -> None:
    sent = _state(anchor_utc=WHEN - timedelta(minutes=7, microseconds=3))
    got = decode_state(_over_the_wire(encode_state(sent)), "default")
    assert got == sent
    assert got.applied.time_utc == WHEN and got.anchor_utc == sent.anchor_utc
    assert sky_id(got) == sky_id(sent)


def test_a_state_from_a_master_without_towers_keeps_the_channels_own_epochs() -> None:
    message = encode_state(_state())
    assert len(message["tower_epochs"]) == 3 and message["tower_epochs"][0] is None
    del message["tower_epochs"]
    assert decode_state(_over_the_wire(message), "default").tower_epochs == ()


def test_the_sky_id_names_what_makes_the_cloud_field() -> None:
    base = _state()
    same = [
        dataclasses.replace(base, sequence=99),  # a repeat
        dataclasses.replace(
            base, applied=dataclasses.replace(base.applied, time_utc=WHEN + timedelta(hours=1))
        ),  # the clock: the same field, later
    ]
    assert all(sky_id(s) == sky_id(base) for s in same)
    differ = [
        dataclasses.replace(base, applied=dataclasses.replace(base.applied, seed=1)),
        dataclasses.replace(base, anchor_drift=((0.0, 0.0),) * len(base.anchor_drift)),
        dataclasses.replace(base, master_id="fedcba9876543210"),
        dataclasses.replace(base, weather_version=6),
        _state("fair-cumulus"),
    ]
    ids = {sky_id(s) for s in differ}
    assert len(ids) == len(differ) and sky_id(base) not in ids


def test_ticks_pongs_and_health_decode_to_what_was_sent() -> None:
    for tick in (_tick(), _tick(camera=None, aircraft_m=None, rate=0.0)):
        assert decode_tick(_over_the_wire(encode_tick(tick)), "default") == tick
    assert decode_pong(_over_the_wire(encode_pong("default", MASTER, 5.5)), "default") == (
        MASTER,
        5.5,
    )
    health = Health("default", "left", "channel", 29.5, 12.0, 100)
    assert decode_health(_over_the_wire(encode_health(health)), "default") == health


def _with(message: dict[str, Any], path: tuple[Any, ...], value: object) -> dict[str, Any]:
    out = _over_the_wire(message)
    assert isinstance(out, dict)
    node: Any = out
    for key in path[:-1]:
        node = node[key]
    if value is KeyError:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    return out


@pytest.mark.parametrize(
    ("path", "value", "reason"),
    [
        (("v",), 2, "version 2"),
        (("kind",), "clock", "kind 'clock'"),
        (("site",), "other", "from site 'other'"),
        (("sequence",), -1, "sequence = -1 is outside"),
        (("sequence",), 1.5, "sequence must be an integer"),
        (("master_id",), "not hex", "master_id is not a valid value"),
        (("clock_rate",), float("nan"), "clock_rate = nan is outside"),
        (("clock_rate",), 1e9, "clock_rate = 1000000000.0 is outside"),
        (("anchor_us",), 2**62, "anchor_us"),
        (("anchor_drift",), [[0.0, 1.0]], "anchor_drift has 1 entries for 3 layers"),
        (("anchor_drift", 0), [0.0, float("inf")], "anchor_drift[0] must be finite"),
        (("anchor_drift", 0), "east", "anchor_drift[0] must be [east_m, north_m]"),
        (("applied",), KeyError, "applied is not a map"),
        (("applied", "layers", 0, "cover_oktas"), 12.0, "applied"),
        (("applied", "visibility_m"), -5.0, "applied"),
        (("applied", "observer"), KeyError, "applied: missing 'observer'"),
        (("target", "layers", 0, "type"), "kumulus", "target"),
        (("tower_epochs",), [None], "tower_epochs has 1 entries for 3 layers"),
        (("tower_epochs", 2), [1, 2], "tower_epochs[2] must be [set_us"),
        (("tower_epochs", 2, 0), _BEFORE_US, f"tower_epochs[2]: set_us = {_BEFORE_US} is outside"),
        # The clock's range, years 1900-2199 (weather.state; issue 40): its ends and beyond.
        (("applied_time_us",), _END_US + 1, "applied_time_us"),
        (("target_time_us",), _BEFORE_US, "target_time_us"),
        (("anchor_us",), _Y9999_US, "anchor_us"),
        (("tower_epochs", 2, 2), _END_US + 1, "cut_us"),
        (("tower_epochs", 2, 1), 95.0, "sun_elevation_deg = 95.0 is outside"),
        (("tower_epochs", 2, 2), "soon", "cut_us must be an integer"),
        (("tower_epochs", 2, 3), float("nan"), "cover_oktas = nan is outside"),
        (("tower_epochs",), "all", "tower_epochs must be a list"),
        (("applied", "seed"), "seven", "applied"),
    ],
)
def test_a_bad_state_is_refused_with_one_line_naming_the_field(
    path: tuple[Any, ...], value: object, reason: str
) -> None:
    bad = _with(encode_state(_state()), path, value)
    with pytest.raises(ShareError, match=reason.replace("[", r"\[").replace("(", r"\(")) as err:
        decode_state(bad, "default")
    assert "\n" not in str(err.value)


@pytest.mark.parametrize(
    ("path", "value", "reason"),
    [
        (("camera", "fov_deg"), 0.5, "fov_deg = 0.5 is outside"),
        (("camera", "width"), 10**6, "width = 1000000 is outside"),
        (("camera", "position_m"), [0.0, 1.0], "camera.position_m must be"),
        (("camera",), [1, 2], "camera is not a map"),
        (("aircraft_m",), [0.0, float("nan"), 1.0], "aircraft_m must hold three finite"),
        (("master_mono_s",), -1.0, "master_mono_s = -1.0 is outside"),
        (("master_mono_s",), 1e12, "master_mono_s = 1000000000000.0 is outside"),
        (("time_us",), _Y9999_US, "time_us"),
        (("time_us",), _END_US + 1, "time_us"),
        (("time_us",), _BEFORE_US, "time_us"),
        (("rate",), True, "rate must be a number"),
    ],
)
def test_a_bad_tick_is_refused_with_one_line_naming_the_field(
    path: tuple[Any, ...], value: object, reason: str
) -> None:
    bad = _with(encode_tick(_tick()), path, value)
    with pytest.raises(ShareError, match=reason.replace("[", r"\[")):
        decode_tick(bad, "default")


def test_garbage_and_truncation_never_get_past_the_wire_or_the_checks() -> None:
    good = pack_data(encode_state(_state()))
    for cut in range(0, len(good), max(1, len(good) // 97)):
        with pytest.raises(WireError):
            unpack_data(good[:cut])
    with pytest.raises(WireError, match="trailing bytes"):
        unpack_data(good + b"\x00")
    with pytest.raises(WireError, match="exceed"):
        unpack_data(b"\x00" * 2_000_000)
    with pytest.raises(WireError):
        unpack_data(b"\xd4\x01\x00")  # an extension type
    for value in (None, 3, "state", [1, 2], {"v": 1}, {"v": 1, "kind": "state"}):
        with pytest.raises(ShareError):
            decode_state(value, "default")
        with pytest.raises(ShareError):
            decode_tick(value, "default")
    with pytest.raises(WireError, match="map keys must be str"):
        pack_data({1: 2})


def test_microseconds_round_trip_across_the_years() -> None:
    for t in (
        datetime(1970, 1, 1, tzinfo=UTC),
        WHEN,
        datetime(9999, 12, 31, 23, 59, 59, 999999, tzinfo=UTC),
    ):
        assert time_from_us(time_to_us(t)) == t


def test_the_ends_of_the_clocks_range_pass() -> None:
    for us in (time_to_us(EARLIEST_UTC), _END_US):
        tick = decode_tick(
            {**encode_tick(_tick()), "time_us": us, "master_mono_s": 3.0e9}, "default"
        )
        assert tick.time_utc == time_from_us(us)
        state = decode_state({**encode_state(_state()), "anchor_us": us}, "default")
        assert state.anchor_utc == time_from_us(us)
