"""FlightGear's pose lines and wxsky's weather as FlightGear's properties (issue 18, the pure
part: wxsky/protocols/flightgear.py, plugins/flightgear/Protocol/wxsky.xml). Lines FlightGear
writes while it resets (nan, -9999 ft), garbage, truncation and out-of-range values are
dropped with one line saying what; the mapping is checked row by row."""

from __future__ import annotations

import dataclasses
import random
import xml.etree.ElementTree as ET
from datetime import UTC, datetime
from pathlib import Path

import pytest

from wxsky.protocols.flightgear import (
    MAX_LAYERS,
    POSE_FIELDS,
    TAKE_OVER,
    coverage_name,
    parse_pose,
    weather_properties,
)
from wxsky.settings.presets import load_preset
from wxsky.units import FT_TO_M
from wxsky.weather.state import CloudLayer, CloudType, WeatherState, WindLayer

PROTOCOL = Path(__file__).resolve().parents[1] / "plugins" / "flightgear" / "Protocol" / "wxsky.xml"
GOOD = (
    "21.3245000,-157.9251000,1500.00,90.000,2.500,-1.000,90.000,-5.000,55.00,12.0,"
    "21.3245000,-157.9251000,1504.00,1,2026-07-15T13:30:00"
)
# The same aircraft seen from a chase camera 100 m south of it and 100 ft lower.
CHASE = GOOD.replace("21.3245000,-157.9251000,1504.00,1,", "21.3235954,-157.9251000,1400.00,0,")


def test_the_protocol_file_writes_the_fields_the_parser_reads_in_its_order() -> None:
    root = ET.parse(PROTOCOL).getroot()
    output = root.find("generic/output")
    assert output is not None
    assert output.findtext("binary_mode") == "false"
    assert output.findtext("var_separator") == ","
    names = [chunk.findtext("name") for chunk in output.findall("chunk")]
    assert tuple(names) == POSE_FIELDS
    nodes = [chunk.findtext("node") for chunk in output.findall("chunk")]
    assert nodes[0] == "/position/latitude-deg" and nodes[-1] == "/sim/time/gmt"


def test_a_pose_line_is_the_aircraft_the_view_and_the_time() -> None:
    got = parse_pose(GOOD)
    assert got.error == "" and got.pose is not None
    p = got.pose
    assert (p.lat_deg, p.lon_deg) == (21.3245, -157.9251)
    assert p.alt_m == pytest.approx(1500.0 * FT_TO_M)
    assert (p.heading_deg, p.pitch_deg, p.roll_deg, p.fov_deg) == (90.0, 2.5, -1.0, 55.0)
    assert p.ground_m == pytest.approx(12.0 * FT_TO_M)
    # The view turned 90 degrees left of an eastbound aircraft looks north, 5 degrees down
    # from the aircraft's 2.5 up.
    assert p.view_heading_deg == pytest.approx(0.0)
    assert p.view_pitch_deg == pytest.approx(-2.5)
    assert p.view_roll_deg == -1.0  # from inside, the view rolls with the aircraft
    assert p.internal and p.viewer_alt_m == pytest.approx(1504.0 * FT_TO_M)
    assert p.time_utc == datetime(2026, 7, 15, 13, 30, tzinfo=UTC)
    assert parse_pose(GOOD.encode() + b"\r\n").pose == p  # bytes, a CR LF end


def test_a_view_from_outside_looks_at_the_aircraft_level() -> None:
    p = parse_pose(CHASE).pose
    assert p is not None and not p.internal
    # From 100 m south and 100 ft (30.48 m) below: north, up by atan(30.48 / 100); the
    # aircraft's heading and the view's offsets no longer say where the eye looks.
    assert p.view_heading_deg == pytest.approx(0.0, abs=0.01)
    assert p.view_pitch_deg == pytest.approx(16.95, abs=0.05)
    assert p.view_roll_deg == 0.0
    # An outside eye at the aircraft itself (a view being switched) looks where it heads.
    at = parse_pose(
        CHASE.replace("21.3235954,-157.9251000,1400.00", "21.3245000,-157.9251000,1500.00")
    )
    assert at.pose is not None and at.pose.view_heading_deg == pytest.approx(0.0)
    assert at.pose.view_pitch_deg == pytest.approx(-2.5)


@pytest.mark.parametrize(
    ("line", "reason"),
    [
        ("", "has 1 fields, expected 15"),
        (GOOD.rsplit(",", 1)[0], "has 14 fields"),
        (GOOD + ",1", "has 16 fields"),
        (GOOD.replace("21.3245000,-157.9251000,1504.00,1,", ""), "(an older Protocol/wxsky.xml?)"),
        (GOOD.replace(",1,2026", ",2,2026"), "view-internal = 2 is outside 0..1"),
        (GOOD.replace("1504.00", "nan"), "viewer-elev-ft is nan"),
        (GOOD.replace(",12.0,", ",-9999.0,"), "ground-elev-ft = -9999 is outside"),
        (GOOD.replace("21.3245000", "nan"), "latitude-deg is nan (FlightGear resetting?)"),
        (GOOD.replace("1500.00", "-9999.00"), "altitude-ft = -9999 is outside"),
        (GOOD.replace("1500.00", "inf"), "altitude-ft is inf"),
        (GOOD.replace("21.3245000", "91"), "latitude-deg = 91 is outside"),
        (GOOD.replace("-157.9251000", "-181"), "longitude-deg = -181 is outside"),
        (GOOD.replace("55.00", "0.5"), "field-of-view = 0.5 is outside"),
        (GOOD.replace("2.500", "95"), "pitch-deg = 95 is outside"),
        (GOOD.replace("90.000,2.500", "east,2.500"), "heading-deg is not a number: 'east'"),
        (GOOD.replace("2026-07-15T13:30:00", "13:30"), "gmt is not a time: '13:30'"),
        (GOOD.replace("2026-07-15T13:30:00", "2026-02-30T13:30:00"), "gmt is not a time"),
        ("x" * 600, "pose line of 600 characters"),
    ],
)
def test_bad_lines_are_dropped_with_one_line_saying_what(line: str, reason: str) -> None:
    got = parse_pose(line)
    assert got.pose is None
    assert reason in got.error and "\n" not in got.error


def test_non_ascii_and_every_truncation_are_dropped_never_raised() -> None:
    assert parse_pose("21.3\u00b0".encode()).error == "pose line is not ASCII"
    for n in range(len(GOOD)):
        got = parse_pose(GOOD[:n])
        assert got.pose is None and got.error


def test_fuzzed_lines_never_raise() -> None:
    rng = random.Random(18)
    alphabet = "0123456789.,-+eEnaifT:x \t"
    for _ in range(3000):
        line = "".join(rng.choice(alphabet) for _ in range(rng.randrange(0, 140)))
        got = parse_pose(line)
        assert (got.pose is None) != (got.error == "")
    for _ in range(500):
        raw = bytes(rng.randrange(256) for _ in range(rng.randrange(0, 200)))
        got = parse_pose(raw)
        assert (got.pose is None) != (got.error == "")


@pytest.mark.parametrize(
    ("type_", "oktas", "name"),
    [
        (CloudType.CUMULUS, 0.0, "clear"),
        (CloudType.CUMULUS, 1.0, "few"),
        (CloudType.CUMULUS, 2.0, "few"),
        (CloudType.CUMULUS, 3.0, "scattered"),
        (CloudType.STRATOCUMULUS, 4.0, "scattered"),
        (CloudType.STRATOCUMULUS, 5.0, "broken"),
        (CloudType.CUMULONIMBUS, 7.0, "broken"),
        (CloudType.STRATUS, 8.0, "overcast"),
        (CloudType.CIRRUS, 3.0, "cirrus"),
        (CloudType.CIRROSTRATUS, 7.0, "cirrus"),
        (CloudType.CIRROSTRATUS, 8.0, "overcast"),
    ],
)
def test_cover_maps_to_flightgears_coverage_names(
    type_: CloudType, oktas: float, name: str
) -> None:
    assert coverage_name(CloudLayer(oktas, 1000.0, 2000.0, type_)) == name


def test_the_weather_becomes_flightgears_properties_row_by_row() -> None:
    state = WeatherState().apply(load_preset("thunderstorm"))
    props = dict(weather_properties(state))
    # Lowest layer first, bases and thicknesses in feet; the two unused layers cleared.
    assert props["/environment/clouds/layer[0]/coverage"] == "scattered"  # stratus 3/8
    assert float(props["/environment/clouds/layer[0]/elevation-ft"]) == pytest.approx(
        800.0 / FT_TO_M, abs=0.01
    )
    assert float(props["/environment/clouds/layer[0]/thickness-ft"]) == pytest.approx(
        250.0 / FT_TO_M, abs=0.01
    )
    assert props["/environment/clouds/layer[2]/coverage"] == "broken"  # cumulonimbus 6/8
    assert float(props["/environment/clouds/layer[2]/thickness-ft"]) == pytest.approx(
        10_000.0 / FT_TO_M, abs=0.01
    )
    for i in range(3, MAX_LAYERS):
        assert props[f"/environment/clouds/layer[{i}]/coverage"] == "clear"
        assert f"/environment/clouds/layer[{i}]/elevation-ft" not in props
    assert props["/environment/visibility-m"] == "3000"
    # The surface wind (280 at 9 m/s = 17.49 kt), temperatures and QNH (1013 hPa = 29.91 inHg).
    b = "/environment/config/boundary/entry[0]"
    assert props[f"{b}/wind-from-heading-deg"] == "280"
    assert props[f"{b}/wind-speed-kt"] == "17.49"
    assert props["/environment/wind-speed-kt"] == "17.49"
    assert props[f"{b}/temperature-degc"] == "19" and props[f"{b}/dewpoint-degc"] == "17"
    assert props[f"{b}/pressure-sea-level-inhg"] == "29.91"
    # Aloft, 3,000 ft above the field (1,346 m): between the surface wind and 1,500 m's 260.
    a = "/environment/config/aloft/entry[0]"
    assert float(props[f"{a}/elevation-ft"]) == pytest.approx(432.0 / FT_TO_M + 3000.0, abs=0.01)
    assert 260.0 < float(props[f"{a}/wind-from-heading-deg"]) < 280.0
    # 9,000 ft up is above the highest reported wind: 250 at 18 m/s.
    assert props["/environment/config/aloft/entry[1]/wind-from-heading-deg"] == "250"
    assert all("e" not in v.lower() or v.isalpha() for v in props.values())  # no exponents


def test_calm_air_unknown_temperatures_and_more_layers_than_flightgear_has() -> None:
    layers = tuple(
        CloudLayer(2.0, 500.0 + 1000.0 * i, 800.0 + 1000.0 * i, CloudType.CUMULUS) for i in range(6)
    )
    state = dataclasses.replace(
        WeatherState(),
        layers=layers,
        wind=(),
        temperature_c=None,
        dewpoint_c=None,
    )
    props = weather_properties(state)
    names = [k for k, _ in props]
    assert len(names) == len(set(names))
    got = dict(props)
    # The five lowest of six layers; calm air is 0 kt from 000.
    assert float(got[f"/environment/clouds/layer[{MAX_LAYERS - 1}]/elevation-ft"]) == (
        pytest.approx(4500.0 / FT_TO_M, abs=0.01)
    )
    assert got["/environment/wind-speed-kt"] == "0"
    assert got["/environment/wind-from-heading-deg"] == "0"
    assert not any("temperature" in k or "dewpoint" in k for k in names)
    # A wind layer alone sets every level to it.
    windy = dataclasses.replace(state, wind=(WindLayer(0.0, 90.0, 10.0),))
    assert dict(weather_properties(windy))["/environment/wind-from-heading-deg"] == "90"


def test_taking_over_flightgears_weather_turns_its_own_updates_off() -> None:
    assert dict(TAKE_OVER) == {
        "/environment/params/metar-updates-environment": "0",
        "/environment/config/enabled": "0",
    }
