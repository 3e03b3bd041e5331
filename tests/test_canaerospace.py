"""CANaerospace: the decoder, the encoder, the id table, the DBC file built from it, and the
profile table in docs/canaerospace.md."""

from __future__ import annotations

import math
import random
import struct
import subprocess
import sys
import uuid
from datetime import UTC, date, datetime, timedelta, timezone
from pathlib import Path

import can
import cantools
import pytest

from wxsky.protocols.canaerospace import (
    BY_ID,
    DATA_TYPE_SIZES,
    IDS,
    CanasDecoder,
    DataType,
    decode_header,
    encode_date,
    encode_float,
    encode_layer,
    encode_long,
    encode_raw,
    encode_short2,
    encode_time,
    encode_utc,
    encode_wind,
    frames_for_update,
    table_markdown,
)
from wxsky.protocols.canaerospace_dbc import dbc_text
from wxsky.protocols.result import Decoded
from wxsky.weather.cockpit import (
    QNH,
    RANGES,
    TEMPERATURE,
    VISIBILITY,
    WIND_DIR,
    WIND_SPEED,
    CockpitUpdate,
    checked,
    layer_key,
)

ROOT = Path(__file__).resolve().parents[1]
DBC_PATH = ROOT / "configs" / "wxsky-canaerospace.dbc"
NUMERIC_IDS = [e.can_id for e in IDS if e.char4 is None]
LAYERED_IDS = [e.can_id for e in IDS if e.layered]

DECODER = CanasDecoder()


def _value(can_id: int, data: bytes, decoder: CanasDecoder = DECODER) -> tuple[str, float]:
    """The one value a numeric frame sets, failing the test if it set anything else."""
    result = decoder.decode(can_id, data)
    assert result.update is not None, result
    assert result.update.time_of_day_s is None and result.update.date_utc is None
    ((key, value),) = result.update.values.items()
    assert isinstance(value, float)
    return key, value


def _error(can_id: int, data: bytes, **flags: bool) -> str:
    result = DECODER.decode(can_id, data, **flags)
    assert result.update is None and not result.ignored, result
    assert result.error and "\n" not in result.error
    return result.error


def _ignored(can_id: int, data: bytes, decoder: CanasDecoder = DECODER, **flags: bool) -> str:
    result = decoder.decode(can_id, data, **flags)
    assert result.update is None and not result.error, result
    assert result.ignored
    return result.ignored


# -- the table --------------------------------------------------------------------------


def test_data_type_sizes_cover_the_standard_table() -> None:
    assert sorted(DATA_TYPE_SIZES) == list(range(32))
    assert DATA_TYPE_SIZES[DataType.FLOAT] == 4
    assert DATA_TYPE_SIZES[DataType.SHORT2] == 4
    assert DATA_TYPE_SIZES[DataType.CHAR4] == 4
    assert DATA_TYPE_SIZES[DataType.USHORT] == 2
    assert DATA_TYPE_SIZES[DataType.CHAR3] == 3
    assert DATA_TYPE_SIZES[DataType.NODATA] == 0
    assert (DataType.FLOAT, DataType.LONG, DataType.SHORT2, DataType.CHAR4) == (2, 3, 12, 15)


def test_the_table_holds_exactly_the_profile() -> None:
    assert [e.can_id for e in IDS] == [319, 333, 334, 335, 1200, 1206, 1500, 1501, 1502, 1503]
    assert LAYERED_IDS == [1500, 1501, 1502]
    assert BY_ID[1503].service_code == "0"
    assert BY_ID[1200].data_types == (DataType.CHAR4,) and BY_ID[1200].key is None
    assert BY_ID[1206].data_types == (DataType.CHAR4,) and BY_ID[1206].key is None
    for can_id in NUMERIC_IDS:
        assert BY_ID[can_id].data_types == (DataType.FLOAT, DataType.SHORT2, DataType.LONG)
    assert BY_ID[335].to_si(288.15) == pytest.approx(15.0)
    assert BY_ID[335].from_si(15.0) == pytest.approx(288.15)


def test_doc_embeds_the_generated_profile_table() -> None:
    doc = (ROOT / "docs" / "canaerospace.md").read_text(encoding="utf-8")
    table = table_markdown()
    assert table in doc, "docs/canaerospace.md is stale: paste table_markdown() into it"
    for e in IDS:
        assert f"| {e.can_id} | 0x{e.can_id:03X} | {e.name} |" in table


# -- decoding good frames -----------------------------------------------------------------


def test_reference_frame_wind_speed() -> None:
    data = bytes.fromhex("2a02000741480000")
    header = decode_header(data)
    assert (header.node_id, header.data_type, header.service_code, header.message_code) == (
        42,
        DataType.FLOAT,
        0,
        7,
    )
    assert _value(333, data) == (WIND_SPEED, 12.5)
    assert encode_float(333, 12.5, node_id=42, message_code=7) == data


def test_short2_value_is_raw_over_full_scale() -> None:
    data = encode_raw(333, DataType.SHORT2, struct.pack(">hh", 16384, 100))
    assert _value(333, data)[1] == pytest.approx(16384 / (32767 / 100))
    data = encode_raw(1503, DataType.SHORT2, struct.pack(">hh", -32767, -20000))
    assert _value(1503, data)[1] == pytest.approx(20000.0)
    assert _value(333, encode_short2(333, 12.5, 100))[1] == pytest.approx(12.5, abs=100 / 32767)
    assert encode_short2(333, 12.5, 100)[4:] == struct.pack(">hh", 4096, 100)


def test_long_is_a_signed_integer_value() -> None:
    assert _value(1503, encode_long(1503, 8000)) == (VISIBILITY, 8000.0)
    assert _value(334, encode_long(334, -90)) == (WIND_DIR, 270.0)
    assert encode_long(1501, -300, service_code=2)[4:] == bytes.fromhex("fffffed4")
    assert _value(1501, encode_long(1501, -300, service_code=2)) == (
        layer_key(2, "base_m"),
        -300.0,
    )


@pytest.mark.parametrize(
    ("wire_deg", "dir_from_deg"), [(-90.0, 270.0), (-180.0, 180.0), (180.0, 180.0), (0.0, 0.0)]
)
def test_wind_direction_plus_minus_180_is_normalised(wire_deg: float, dir_from_deg: float) -> None:
    assert _value(334, encode_float(334, wire_deg)) == (WIND_DIR, dir_from_deg)


def test_outside_air_temperature_kelvin_to_celsius() -> None:
    key, value = _value(335, encode_float(335, 288.15))
    assert key == TEMPERATURE
    assert value == pytest.approx(15.0, abs=1e-4)  # 288.15 is not exact in a float32
    assert _value(335, encode_float(335, 253.15))[1] == pytest.approx(-20.0, abs=1e-4)


def test_baro_correction_is_qnh() -> None:
    assert _value(319, encode_float(319, 1013.25)) == (QNH, 1013.25)


def test_utc_frame_is_time_of_day() -> None:
    data = encode_raw(1200, DataType.CHAR4, bytes([13, 43, 22, 0]))
    assert data == encode_time(13, 43, 22)
    update = DECODER.decode(1200, data).update
    assert update == CockpitUpdate(time_of_day_s=49402.0, time_resolution_s=1.0)
    assert DECODER.decode(1200, encode_time(23, 59, 59)).update == CockpitUpdate(
        time_of_day_s=86399.0, time_resolution_s=1.0
    )


def test_date_frame_is_binary_not_bcd() -> None:
    data = encode_raw(1206, DataType.CHAR4, bytes([12, 6, 19, 87]))
    assert data == encode_date(date(1987, 6, 12))
    assert DECODER.decode(1206, data).update == CockpitUpdate(date_utc=date(1987, 6, 12))
    leap = DECODER.decode(1206, encode_date(date(2024, 2, 29))).update
    assert leap is not None and leap.date_utc == date(2024, 2, 29)


@pytest.mark.parametrize("layer", [1, 2, 3])
@pytest.mark.parametrize(
    ("can_id", "part", "wire"),
    [(1500, "cover_oktas", 6.0), (1501, "base_m", 1850.0), (1502, "thickness_m", 450.0)],
)
def test_cloud_layer_ids_take_the_layer_from_the_service_code(
    layer: int, can_id: int, part: str, wire: float
) -> None:
    data = encode_float(can_id, wire, service_code=layer)
    assert _value(can_id, data) == (layer_key(layer, part), wire)


def test_visibility_needs_service_code_0() -> None:
    assert _value(1503, encode_float(1503, 9999.0)) == (VISIBILITY, 9999.0)
    assert _error(1503, encode_float(1503, 9999.0, service_code=5)) == (
        "CAN 1503 visibility: service code 5, expected 0"
    )


def test_standard_ids_do_not_read_the_service_code() -> None:
    assert _value(333, encode_float(333, 5.0, service_code=77)) == (WIND_SPEED, 5.0)


# -- bad input ----------------------------------------------------------------------------


def test_unknown_ids_are_ignored_whatever_their_data() -> None:
    assert _ignored(0x123, b"") == "CAN id 0x123 not used by wxsky"
    assert _ignored(0x123, b"\x01\x02\x03") == "CAN id 0x123 not used by wxsky"
    assert _ignored(1504, encode_float(1504, 1.0)) == "CAN id 0x5e0 not used by wxsky"


def test_extended_remote_and_error_frames() -> None:
    frame = encode_float(333, 10.0)
    assert "extended" in _ignored(333, frame, is_extended=True)
    assert _ignored(333, b"", is_remote=True) == "CAN 333 wind speed: remote frame"
    assert _error(333, frame, is_error=True) == "CAN error frame"
    assert "11-bit" in _error(0x800, frame)
    assert "11-bit" in _error(-1, frame)


@pytest.mark.parametrize("length", [0, 1, 3])
def test_frames_shorter_than_the_header(length: int) -> None:
    assert _error(333, bytes(length)) == (
        f"CAN 333 wind speed: DLC {length}, shorter than the 4-byte header"
    )


def test_dlc_must_be_header_plus_the_data_type_size() -> None:
    frame = encode_float(333, 10.0)
    assert _error(333, frame[:7]) == "CAN 333 wind speed: DLC 7, expected 8 for FLOAT"
    assert "DLC 9" in _error(333, frame + b"\x00")
    assert "DLC 4" in _error(333, frame[:4])
    assert "DLC 6" in _error(1200, encode_time(1, 2, 3)[:6])


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
@pytest.mark.parametrize("can_id", NUMERIC_IDS)
def test_non_finite_floats_are_rejected(can_id: int, bad: float) -> None:
    service_code = 1 if can_id in LAYERED_IDS else 0
    error = _error(can_id, encode_float(can_id, bad, service_code=service_code))
    assert error.startswith(f"CAN {can_id} {BY_ID[can_id].name}: ")
    assert "not a finite number" in error


@pytest.mark.parametrize(
    ("can_id", "data", "reason"),
    [
        (333, encode_float(333, 999.0), "CAN 333 wind speed: 999 m/s out of range 0..150"),
        (333, encode_float(333, -1.0), "CAN 333 wind speed: -1 m/s out of range 0..150"),
        (334, encode_float(334, -181.0), "CAN 334 wind direction: -181 deg out of range -180..360"),
        (
            335,
            encode_float(335, 100.0),
            "CAN 335 outside air temperature: 100 K out of range 183.15..333.15",
        ),
        (319, encode_long(319, 2000), "CAN 319 baro correction: 2000 hPa out of range 850..1100"),
        (
            1500,
            encode_float(1500, 9.0, service_code=1),
            "CAN 1500 cloud cover: 9 oktas out of range 0..8",
        ),
        (
            1500,
            encode_float(1500, 4.0, service_code=7),
            "CAN 1500 cloud cover: layer 7 out of range 1..3",
        ),
        (
            1501,
            encode_float(1501, 900.0, service_code=0),
            "CAN 1501 cloud base: layer 0 out of range 1..3",
        ),
        (
            1502,
            encode_float(1502, -10.0, service_code=2),
            "CAN 1502 cloud thickness: -10 m out of range 0..25000",
        ),
        (1200, encode_time(25, 0, 0), "CAN 1200 UTC: hour 25 out of range 0..23"),
        (1200, encode_time(12, 60, 0), "CAN 1200 UTC: minute 60 out of range 0..59"),
        (1200, encode_time(12, 0, -1), "CAN 1200 UTC: second -1 out of range 0..59"),
        (
            1206,
            encode_raw(1206, DataType.CHAR4, bytes([29, 2, 20, 23])),
            "CAN 1206 date: 2023-02-29 is not a calendar date",
        ),
        (
            1206,
            encode_raw(1206, DataType.CHAR4, bytes([1, 13, 20, 23])),
            "CAN 1206 date: month 13 out of range 1..12",
        ),
    ],
)
def test_out_of_range_values_are_rejected_with_one_line_naming_the_id(
    can_id: int, data: bytes, reason: str
) -> None:
    assert _error(can_id, data) == reason


def test_zero_thickness_is_rejected() -> None:
    error = _error(1502, encode_float(1502, 0.0, service_code=1))
    assert error.startswith("CAN 1502 cloud thickness: ")
    assert "more than 0" in error


@pytest.mark.parametrize(
    ("can_id", "data_type", "payload", "named"),
    [
        (333, DataType.USHORT, b"\x00\x05", "USHORT (7)"),
        (333, DataType.DOUBLEH, bytes(4), "DOUBLEH (30)"),
        (333, DataType.CHAR4, bytes(4), "CHAR4 (15)"),
        (1501, DataType.ULONG, bytes(4), "ULONG (4)"),
        (1200, DataType.FLOAT, struct.pack(">f", 12.0), "FLOAT (2)"),
        (1206, DataType.LONG, bytes(4), "LONG (3)"),
        (335, 40, bytes(4), "data type 40 not"),
        (335, 200, bytes(4), "data type 200 not"),
    ],
)
def test_data_types_the_id_does_not_take_are_rejected(
    can_id: int, data_type: int, payload: bytes, named: str
) -> None:
    error = _error(can_id, encode_raw(can_id, data_type, payload, service_code=1))
    assert error.startswith(f"CAN {can_id} {BY_ID[can_id].name}: data type ")
    assert named in error and "not allowed" in error


def test_short2_scale_zero_is_rejected() -> None:
    data = encode_raw(333, DataType.SHORT2, struct.pack(">hh", 100, 0))
    assert _error(333, data) == "CAN 333 wind speed: SHORT2 scale 0 (raw 100)"
    with pytest.raises(ValueError, match="scale"):
        encode_short2(333, 1.0, 0)


def _check_update(update: CockpitUpdate) -> None:
    """Everything in a decoded update may reach the weather."""
    for key, value in update.values.items():
        assert isinstance(value, float)
        lo, hi = RANGES[key].bounds
        assert lo <= value <= hi, (key, value)
        if key == WIND_DIR:
            assert checked(key, value) == value % 360.0
        else:
            assert checked(key, value) == value
    if update.time_of_day_s is not None:
        assert 0.0 <= update.time_of_day_s < 86_400.0
        assert update.time_of_day_s == int(update.time_of_day_s)
        assert update.time_resolution_s == 1.0
    if update.date_utc is not None:
        assert isinstance(update.date_utc, date)
    assert not update.empty


def test_random_frames_never_raise_nor_pass_bad_values() -> None:
    rng = random.Random(20240611)
    ids = [e.can_id for e in IDS]
    outcomes = {"update": 0, "ignored": 0, "error": 0}
    for i in range(20_000):
        can_id = rng.randrange(-5, 0x900) if i % 4 == 0 else rng.choice(ids)
        length = rng.choice([rng.randrange(0, 13), 8, 8, 8])
        data = bytearray(rng.randbytes(length))
        if length >= 4 and can_id in BY_ID and rng.random() < 0.8:
            # A header a real node could send, so that many frames get past it to the value.
            data[1] = rng.choice(BY_ID[can_id].data_types)
            data[2] = rng.choice([0, 1, 2, 3, rng.randrange(256)])
        result = DECODER.decode(
            can_id,
            data,
            is_extended=rng.random() < 0.02,
            is_remote=rng.random() < 0.02,
            is_error=rng.random() < 0.01,
        )
        assert isinstance(result, Decoded)
        assert [result.update is not None, bool(result.ignored), bool(result.error)].count(
            True
        ) == 1, result
        if result.update is not None:
            outcomes["update"] += 1
            _check_update(result.update)
        elif result.ignored:
            outcomes["ignored"] += 1
        else:
            outcomes["error"] += 1
            assert "\n" not in result.error
    # The sweep reached the value checks often enough to mean something.
    assert outcomes["update"] > 300, outcomes
    assert outcomes["error"] > 5000, outcomes
    assert outcomes["ignored"] > 1000, outcomes


def test_random_values_in_valid_frames_are_checked() -> None:
    rng = random.Random(7)
    for _ in range(5000):
        entry = rng.choice([e for e in IDS if e.char4 is None])
        wire = rng.uniform(-2e6, 2e6) if rng.random() < 0.5 else rng.uniform(-400, 400)
        layer = rng.randrange(1, 4) if entry.layered else 0
        result = DECODER.decode(entry.can_id, encode_float(entry.can_id, wire, service_code=layer))
        lo, hi = entry.wire_limits()
        if result.update is not None:
            _check_update(result.update)
            assert lo <= wire <= hi
        else:
            assert result.error.startswith(f"CAN {entry.can_id} {entry.name}: ")


# -- node filter --------------------------------------------------------------------------


def test_node_filter() -> None:
    decoder = CanasDecoder(node_ids=frozenset({1, 2}))
    assert _value(333, encode_float(333, 7.0, node_id=2), decoder) == (WIND_SPEED, 7.0)
    assert _ignored(333, encode_float(333, 7.0, node_id=42), decoder) == (
        "CAN 333 wind speed from node 42, not one of 1, 2"
    )
    # The filter comes before the value: another node's bad frame is none of wxsky's business.
    assert _ignored(333, encode_float(333, 999.0, node_id=42), decoder)
    assert _ignored(0x123, b"", decoder) == "CAN id 0x123 not used by wxsky"
    assert _value(333, encode_float(333, 7.0, node_id=42)) == (WIND_SPEED, 7.0)
    with pytest.raises(ValueError, match=r"0\.\.255"):
        CanasDecoder(node_ids=frozenset({300}))


# -- encoders -----------------------------------------------------------------------------


def test_encode_wind_sends_the_direction_as_plus_minus_180() -> None:
    (speed_id, speed), (dir_id, direction) = encode_wind(12.5, 270.0, node_id=3)
    assert (speed_id, dir_id) == (333, 334)
    assert struct.unpack(">f", direction[4:])[0] == -90.0
    assert direction[0] == 3
    assert _value(334, direction) == (WIND_DIR, 270.0)
    assert _value(333, speed) == (WIND_SPEED, 12.5)


def test_encode_layer_sends_only_the_given_parts() -> None:
    frames = encode_layer(3, cover_oktas=5.0, thickness_m=600.0)
    assert [(can_id, data[2]) for can_id, data in frames] == [(1500, 3), (1502, 3)]
    with pytest.raises(ValueError, match="layer 4"):
        encode_layer(4, cover_oktas=1.0)


def test_encode_utc_sends_time_and_date_in_utc() -> None:
    # 19:30:15.9 on New Year's Eve in New York is the next day in UTC.
    new_york = datetime(2025, 12, 31, 19, 30, 15, 900_000, tzinfo=timezone(timedelta(hours=-5)))
    frames = dict(encode_utc(new_york))
    assert frames[1200][4:] == bytes([0, 30, 15, 0])
    assert frames[1206][4:] == bytes([1, 1, 20, 26])
    with pytest.raises(ValueError, match="timezone"):
        encode_utc(datetime(2026, 1, 1))


def test_encoders_refuse_what_does_not_fit() -> None:
    with pytest.raises(ValueError):
        encode_float(333, 1e39)
    with pytest.raises(ValueError):
        encode_float(0x800, 1.0)
    with pytest.raises(ValueError):
        encode_float(333, 1.0, node_id=256)
    with pytest.raises(ValueError):
        encode_short2(333, 200.0, 100)
    with pytest.raises(ValueError):
        encode_long(333, 2**31)
    with pytest.raises(ValueError):
        encode_time(200, 0, 0)


def test_frames_for_update_decode_back_to_the_update() -> None:
    update = CockpitUpdate(
        values={
            WIND_SPEED: 12.5,
            WIND_DIR: 250.0,
            TEMPERATURE: 21.0,
            QNH: 1002.0,
            VISIBILITY: 4000.0,
            layer_key(1, "cover_oktas"): 3.0,
            layer_key(2, "base_m"): 2500.0,
            layer_key(3, "thickness_m"): 800.0,
        },
        time_of_day_s=3723.0,
        date_utc=date(2031, 12, 24),
    )
    frames = frames_for_update(update, node_id=9)
    assert len(frames) == 10
    merged = CockpitUpdate()
    for can_id, data in frames:
        result = DECODER.decode(can_id, data)
        assert result.update is not None, result
        merged = merged.merged(result.update)
    assert merged.values.keys() == update.values.keys()
    for key, value in update.values.items():
        assert merged.values[key] == pytest.approx(value, abs=1e-4), key
    assert merged.time_of_day_s == 3723.0 and merged.time_resolution_s == 1.0
    assert merged.date_utc == date(2031, 12, 24)
    with pytest.raises(ValueError, match="dewpoint"):
        frames_for_update(CockpitUpdate(values={"dewpoint_c": 5.0}))


# -- python-can ---------------------------------------------------------------------------


def test_round_trip_through_a_virtual_bus() -> None:
    channel = f"wxsky-canas-{uuid.uuid4().hex}"
    sent = [
        *encode_wind(8.0, 90.0, node_id=5),
        *encode_layer(2, cover_oktas=7.0, base_m=1200.0, thickness_m=300.0, node_id=5),
        (1503, encode_short2(1503, 5000.0, 10000, node_id=5)),
        (335, encode_long(335, 300, node_id=5)),
        *encode_utc(datetime(2026, 6, 21, 13, 43, 22, tzinfo=UTC), node_id=5),
    ]
    decoder = CanasDecoder(node_ids=frozenset({5}))
    merged = CockpitUpdate()
    with (
        can.Bus(interface="virtual", channel=channel) as tx,
        can.Bus(interface="virtual", channel=channel) as rx,
    ):
        for can_id, data in sent:
            tx.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))
        for can_id, data in sent:
            msg = rx.recv(timeout=2.0)
            assert msg is not None
            assert (msg.arbitration_id, bytes(msg.data)) == (can_id, data)
            result = decoder.decode(
                msg.arbitration_id,
                msg.data,
                is_extended=msg.is_extended_id,
                is_remote=msg.is_remote_frame,
                is_error=msg.is_error_frame,
            )
            assert result.update is not None, result
            merged = merged.merged(result.update)
        assert rx.recv(timeout=0.05) is None
    assert dict(merged.values) == {
        WIND_SPEED: 8.0,
        WIND_DIR: 90.0,
        layer_key(2, "cover_oktas"): 7.0,
        layer_key(2, "base_m"): 1200.0,
        layer_key(2, "thickness_m"): 300.0,
        VISIBILITY: pytest.approx(5000.0, abs=10000 / 32767),
        TEMPERATURE: pytest.approx(26.85),
    }
    assert merged.time_of_day_s == 49402.0
    assert merged.date_utc == date(2026, 6, 21)


# -- DBC ----------------------------------------------------------------------------------


def test_shipped_dbc_is_the_generated_one() -> None:
    assert DBC_PATH.read_bytes() == dbc_text().encode("ascii"), "run tools/generate/build_dbc.py"


def test_build_dbc_check(tmp_path: Path) -> None:
    out = tmp_path / "x.dbc"
    tool = [sys.executable, str(ROOT / "tools" / "generate" / "build_dbc.py"), "--out", str(out)]
    assert subprocess.run([*tool, "--check"], capture_output=True).returncode == 1  # missing
    assert subprocess.run(tool, capture_output=True).returncode == 0
    assert out.read_text(encoding="ascii") == dbc_text()
    assert subprocess.run([*tool, "--check"], capture_output=True).returncode == 0
    out.write_bytes(out.read_bytes().replace(b"\n", b"\r\n"))
    assert subprocess.run([*tool, "--check"], capture_output=True).returncode == 1


@pytest.fixture(scope="module")
def db() -> cantools.database.can.Database:
    loaded = cantools.database.load_string(dbc_text(), database_format="dbc")
    assert isinstance(loaded, cantools.database.can.Database)
    return loaded


def test_dbc_describes_every_id_and_says_it_is_float_only(
    db: cantools.database.can.Database,
) -> None:
    assert sorted(m.frame_id for m in db.messages) == sorted(e.can_id for e in IDS)
    assert [n.name for n in db.nodes] == ["Cockpit", "Wxsky"]
    assert "cannot switch on the data-type byte" in dbc_text()
    for e in IDS:
        msg = db.get_message_by_frame_id(e.can_id)
        names = [s.name for s in msg.signals]
        assert names[:4] == [
            "NodeId",
            "DataType",
            "Layer" if e.layered else "ServiceCode",
            "MessageCode",
        ]
        assert msg.length == 8 and not msg.is_extended_frame
        if e.char4 is None:
            value = msg.get_signal_by_name(e.dbc_name)
            assert value.is_float and value.length == 32 and value.unit == e.unit
            assert (value.minimum, value.maximum) == pytest.approx(e.wire_limits())
        else:
            assert names[4:] == [f.dbc_name for f in e.char4.fields]
            assert all(s.is_signed and s.length == 8 for s in msg.signals[4:])


@pytest.mark.parametrize("can_id", NUMERIC_IDS)
def test_dbc_and_decoder_agree_on_float_frames(
    db: cantools.database.can.Database, can_id: int
) -> None:
    entry = BY_ID[can_id]
    lo, hi = entry.wire_limits()
    rng = random.Random(can_id)
    fractions = [0.001, 0.25, 0.5, 0.75, 0.999, *(rng.random() for _ in range(10))]
    for n, fraction in enumerate(fractions):
        wire = lo + (hi - lo) * fraction
        layer = 1 + n % 3 if entry.layered else 0
        data = encode_float(can_id, wire, node_id=n + 1, service_code=layer, message_code=n)
        signals = db.decode_message(can_id, data, decode_choices=False)
        key, value = _value(can_id, data)
        assert signals["NodeId"] == n + 1
        assert signals["DataType"] == DataType.FLOAT
        assert signals["Layer" if entry.layered else "ServiceCode"] == layer
        assert signals["MessageCode"] == n
        dbc_wire = signals[entry.dbc_name]
        assert isinstance(dbc_wire, float)
        assert dbc_wire == pytest.approx(wire, rel=1e-6)
        assert key == entry.cockpit_key(max(layer, 1))
        assert value == checked(key, entry.to_si(dbc_wire))


@pytest.mark.parametrize("can_id", [e.can_id for e in IDS if e.char4 is not None])
def test_dbc_and_decoder_agree_on_char4_frames(
    db: cantools.database.can.Database, can_id: int
) -> None:
    rng = random.Random(can_id)
    start = datetime(1987, 6, 12, tzinfo=UTC)
    for n in range(40):
        when = start + timedelta(seconds=rng.randrange(0, 120 * 365 * 86_400))
        (data,) = [d for i, d in encode_utc(when, node_id=7, message_code=n) if i == can_id]
        signals = db.decode_message(can_id, data, decode_choices=False)
        update = DECODER.decode(can_id, data).update
        assert update is not None
        assert (signals["NodeId"], signals["DataType"], signals["MessageCode"]) == (7, 15, n)
        if can_id == 1200:
            seconds = signals["Hours"] * 3600 + signals["Minutes"] * 60 + signals["Seconds"]
            assert update.time_of_day_s == seconds
            assert update.time_of_day_s == when.hour * 3600 + when.minute * 60 + when.second
        else:
            year = signals["Century"] * 100 + signals["Year"]
            assert update.date_utc == date(year, signals["Month"], signals["Day"])
            assert update.date_utc == when.date()
