"""CIGI 3.3 packets (wxsky/protocols/cigi*.py): reference bytes assembled here with `struct`,
independently of the packet table, in both byte orders; round trips of every packet; the
decoder's rules for bad input; and docs/cigi.md against the table."""

from __future__ import annotations

import math
import random
import struct
from pathlib import Path

import pytest

from wxsky.protocols.cigi import (
    MAX_PROBLEMS,
    REASONS,
    ByteOrder,
    CigiDatagram,
    Packet,
    decode_datagram,
    encode_datagram,
    encode_packet,
    make,
    reasons_markdown,
)
from wxsky.protocols.cigi_examples import examples, messages
from wxsky.protocols.cigi_fields import PacketSpec, f32, table_problems, u8, u16
from wxsky.protocols.cigi_packets import BY_OPCODE, PACKETS, table_markdown

DOC = Path(__file__).resolve().parents[1] / "docs" / "cigi.md"
ORDERS = (">", "<")
NAME: dict[str, ByteOrder] = {">": "big", "<": "little"}
MAGIC = 0x8000
EX = examples()


def _f32(x: float) -> float:
    return float(struct.unpack("f", struct.pack("f", x))[0])


def ig_control_bytes(o: str, *, version: int = 3, size: int = 24, mode: int = 1) -> bytes:
    # database 5, mode, timestamp valid, smoothing, minor version 3; frames 1000 and 999
    bits = mode | 1 << 2 | 1 << 3 | 3 << 4
    return struct.pack(f"{o}BBBbBBHIII4x", 1, size, version, 5, bits, 0, MAGIC, 1000, 123456, 999)


def sof_bytes(o: str) -> bytes:
    # database -2, status 7, mode 3 (offline), timestamp valid, WGS 84, minor version 3
    bits = 3 | 1 << 2 | 3 << 4
    return struct.pack(f"{o}BBBbBBHIII4x", 101, 24, 3, -2, 7, bits, MAGIC, 77, 2_000_000, 41)


def weather_bytes(o: str, *, coverage: float = 62.5, base: float = 1500.0) -> bytes:
    # layer 2, humidity 80 %, weather on, random lightning on, cumulus (7); regional, severity 4
    return struct.pack(
        f"{o}BBHBBBB12f",
        12,
        56,
        9,
        2,
        80,
        1 | 1 << 3 | 7 << 4,
        1 | 4 << 2,
        15.0,
        9999.0,
        5.0,
        coverage,
        base,
        800.0,
        100.0,
        12.5,
        -1.5,
        -90.0,  # CCL's ±180 wind direction: kept as 270
        1013.25,
        0.125,
    )


def atmosphere_bytes(o: str) -> bytes:
    return struct.pack(f"{o}BBBB6f4x", 10, 32, 1, 40, -5.0, 3000.0, 7.5, 0.0, 350.0, 990.0)


def test_ig_control_reference_bytes() -> None:
    for o in ORDERS:
        data = ig_control_bytes(o)
        d = decode_datagram(data)
        assert (d.byte_order, d.direction, dict(d.counts)) == (NAME[o], "host_to_ig", {})
        assert d.packets[0].as_dict() == {
            "database_number": 5,
            "ig_mode": 1,
            "timestamp_valid": 1,
            "smoothing_enable": 1,
            "minor_version": 3,
            "host_frame_number": 1000,
            "timestamp_10us": 123456,
            "last_ig_frame_number": 999,
        }
        assert encode_datagram(d.packets, NAME[o]) == data


def test_the_byte_order_comes_from_the_magic_alone() -> None:
    big, little = ig_control_bytes(">"), ig_control_bytes("<")
    assert big[6:8] == b"\x80\x00" and little[6:8] == b"\x00\x80"
    assert big[8:12] == (1000).to_bytes(4, "big") and little[8:12] == (1000).to_bytes(4, "little")
    assert decode_datagram(big).packets == decode_datagram(little).packets


def test_start_of_frame_reference_bytes() -> None:
    for o in ORDERS:
        d = decode_datagram(sof_bytes(o))
        assert (d.byte_order, d.direction) == (NAME[o], "ig_to_host")
        assert d.packets[0].as_dict() == {
            "database_number": -2,
            "ig_status": 7,
            "ig_mode": 3,
            "timestamp_valid": 1,
            "earth_reference_model": 0,
            "minor_version": 3,
            "ig_frame_number": 77,
            "timestamp_10us": 2_000_000,
            "last_host_frame_number": 41,
        }
        assert encode_packet(d.packets[0], NAME[o]) == sof_bytes(o)


def test_entity_control_reference_bytes_and_angles() -> None:
    for o in ORDERS:
        # active, attached = 0, collision on, conformal clamp (2); playing, looping
        body = struct.pack(
            f"{o}BBHBBBxHHfffddd",
            2,
            48,
            4,
            1 | 1 << 3 | 2 << 5,
            1 << 1 | 2 << 2,
            200,
            1001,
            0,
            190.0,  # roll past 180: kept as -170
            -45.5,
            -90.0,  # yaw of a ±180 host: kept as 270
            -33.8675,
            151.2070,
            1234.5,
        )
        d = decode_datagram(ig_control_bytes(o) + body)
        assert dict(d.counts) == {}
        e = d.packets[1]
        assert (e["entity_id"], e["entity_state"], e["attach_state"]) == (4, 1, 0)
        assert (e["collision_detection_enable"], e["ground_clamp"]) == (1, 2)
        assert (e["animation_loop_mode"], e["animation_state"], e["alpha"]) == (1, 2, 200)
        assert (e["entity_type"], e["parent_id"]) == (1001, 0)
        assert (e["roll_deg"], e["pitch_deg"], e["yaw_deg"]) == (-170.0, -45.5, 270.0)
        assert (e["lat_deg"], e["lon_deg"], e["alt_m"]) == (-33.8675, 151.2070, 1234.5)


def test_weather_control_reference_bytes() -> None:
    for o in ORDERS:
        d = decode_datagram(ig_control_bytes(o) + weather_bytes(o))
        w = d.packets[1]
        assert w.as_dict() == {
            "entity_or_region_id": 9,
            "layer_id": 2,
            "humidity_pct": 80,
            "weather_enable": 1,
            "scud_enable": 0,
            "random_winds_enable": 0,
            "random_lightning_enable": 1,
            "cloud_type": 7,
            "scope": 1,
            "severity": 4,
            "temperature_c": 15.0,
            "visibility_m": 9999.0,
            "scud_frequency_pct": 5.0,
            "coverage_pct": 62.5,
            "base_elevation_m": 1500.0,
            "thickness_m": 800.0,
            "transition_band_m": 100.0,
            "wind_speed_mps": 12.5,
            "vertical_wind_speed_mps": -1.5,
            "wind_dir_deg": 270.0,
            "pressure_hpa": 1013.25,
            "aerosol_concentration_gpm3": 0.125,
        }
        # The encoder sends the normalised direction: 270, not the host's -90.
        sent = encode_packet(w, NAME[o])
        assert struct.unpack_from(f"{o}f", sent, 44)[0] == 270.0
        assert sent[:44] == weather_bytes(o)[:44] and sent[48:] == weather_bytes(o)[48:]


def test_celestial_sphere_control_reference_bytes() -> None:
    for o in ORDERS:
        date = 6 * 1_000_000 + 12 * 10_000 + 1987  # 06121987: 12 June 1987
        body = struct.pack(f"{o}BBBBB3xIf", 9, 16, 13, 43, 0b11111, date, 80.0)
        d = decode_datagram(ig_control_bytes(o) + body)
        c = d.packets[1]
        assert (c["hour"], c["minute"], c["date_mmddyyyy"]) == (13, 43, 6121987)
        assert [c[k] for k in ("ephemeris_enable", "sun_enable", "moon_enable")] == [1, 1, 1]
        assert (c["star_field_enable"], c["date_time_valid"]) == (1, 1)
        assert c["star_field_intensity_pct"] == 80.0
        assert encode_packet(c, NAME[o]) == body


def test_environmental_conditions_request_and_responses_reference_bytes() -> None:
    for o in ORDERS:
        request = struct.pack(f"{o}BBBB4xddd", 28, 32, 4 | 8, 42, 47.45, -122.31, 3048.0)
        d = decode_datagram(ig_control_bytes(o) + request)
        r = d.packets[1]
        assert [r[f"request_{k}"] for k in ("maritime", "terrestrial", "weather", "aerosol")] == [
            0,
            0,
            1,
            1,
        ]
        assert (r["request_id"], r["lat_deg"], r["lon_deg"], r["alt_m"]) == (
            42,
            47.45,
            -122.31,
            3048.0,
        )
        assert encode_packet(r, NAME[o]) == request

        weather = struct.pack(
            f"{o}BBBB6f4x", 109, 32, 42, 71, -4.5, 8000.0, 15.25, 0.5, -10.0, 700.0
        )
        aerosol = struct.pack(f"{o}BBBBf", 110, 8, 42, 3, 0.375)
        d = decode_datagram(sof_bytes(o) + weather + aerosol)
        assert dict(d.counts) == {}
        w, a = d.packets[1:]
        assert w.as_dict() == {
            "request_id": 42,
            "humidity_pct": 71,
            "temperature_c": -4.5,
            "visibility_m": 8000.0,
            "wind_speed_mps": 15.25,
            "vertical_wind_speed_mps": 0.5,
            "wind_dir_deg": 350.0,
            "pressure_hpa": 700.0,
        }
        assert a.as_dict() == {"request_id": 42, "layer_id": 3, "aerosol_concentration_gpm3": 0.375}
        assert encode_packet(a, NAME[o]) == aerosol


def test_the_table_has_the_packets_and_sizes_of_cigi_3_3() -> None:
    sizes = {p.opcode: p.size for p in PACKETS}
    assert sizes == {
        1: 24,
        2: 48,
        9: 16,
        10: 32,
        11: 48,
        12: 56,
        16: 32,
        21: 32,
        28: 32,
        101: 24,
        109: 32,
        110: 8,
    }
    for spec in PACKETS:
        assert len(encode_packet(EX[spec.key])) == spec.size
        assert table_problems(spec) == []


def test_the_table_check_finds_overlaps_misalignment_and_overruns() -> None:
    bad = PacketSpec(
        200,
        "bad",
        "Bad",
        16,
        "host_to_ig",
        (u8("a", 2), u16("b", 3), f32("c", 14), u8("a", 4)),
        "a test",
    )
    found = table_problems(bad)
    assert "duplicate field names" in found
    assert "b at byte 3 is not aligned to 2" in found
    assert "b overlaps byte 4" in found or "a overlaps byte 4" in found
    assert "c at byte 14 is outside the packet" in found


@pytest.mark.parametrize("order", ["big", "little"])
@pytest.mark.parametrize("message", messages(), ids=lambda m: "+".join(p.key for p in m))
def test_every_message_round_trips(order: ByteOrder, message: list[Packet]) -> None:
    data = encode_datagram(message, order)
    d = decode_datagram(data)
    assert (d.byte_order, d.packets, dict(d.counts), d.problems) == (order, tuple(message), {}, ())


def test_every_packet_type_is_in_the_round_trips() -> None:
    keys = {p.key for m in messages() for p in m}
    assert keys == {spec.key for spec in PACKETS}


def test_make_normalises_like_the_decoder() -> None:
    w = make("weather_control", wind_dir_deg=-180.0, base_elevation_m=1219.2)
    assert w["wind_dir_deg"] == 180.0
    assert w["base_elevation_m"] == _f32(1219.2) != 1219.2
    assert make("atmosphere_control", wind_dir_deg=360.0)["wind_dir_deg"] == 0.0
    assert make("entity_control", roll_deg=180.0)["roll_deg"] == -180.0
    # Rounding to f32 would land on 360, the excluded end: it is 0 instead.
    assert make("atmosphere_control", wind_dir_deg=-1e-9)["wind_dir_deg"] == 0.0
    assert make("ig_control")["minor_version"] == 3


@pytest.mark.parametrize(
    ("key", "values", "message"),
    [
        ("weather_control", {"coverage_pct": 100.5}, "coverage_pct 100.5 is outside 0..100"),
        ("weather_control", {"nope_m": 1.0}, "has no field nope_m"),
        ("weather_control", {"humidity_pct": 300}, "humidity_pct 300 does not fit u8"),
        ("weather_control", {"humidity_pct": 1.5}, "humidity_pct is float, not an integer"),
        ("weather_control", {"visibility_m": math.inf}, "visibility_m is inf"),
        ("weather_control", {"thickness_m": 1e39}, "does not fit an f32"),
        ("entity_control", {"yaw_deg": 361.0}, "yaw_deg 361 is outside ±360"),
        ("celestial_sphere_control", {"date_time_valid": 1}, "0 is not a calendar date"),
        ("ig_control", {"ig_mode": 3}, "ig_mode 3 is outside 0..2"),
        ("no_such_packet", {}, "no CIGI packet 'no_such_packet'"),
    ],
)
def test_make_refuses_what_the_decoder_would_drop(
    key: str, values: dict[str, float], message: str
) -> None:
    with pytest.raises(ValueError, match=message.replace(".", r"\.")):
        make(key, **values)


def test_a_packet_cannot_be_built_around_the_checks() -> None:
    good = EX["weather_control"]
    with pytest.raises(ValueError, match="coverage_pct"):
        Packet(12, tuple(150.0 if i == 13 else v for i, v in enumerate(good.values)))
    with pytest.raises(ValueError, match="not normalised"):
        Packet(12, tuple(-100.0 if i == 19 else v for i, v in enumerate(good.values)))
    with pytest.raises(ValueError, match="opcode 99"):
        Packet(99, ())


def test_encode_datagram_refuses_a_message_a_receiver_would_cut() -> None:
    host, sof = EX["ig_control"], EX["start_of_frame"]
    with pytest.raises(ValueError, match="starts with"):
        encode_datagram([EX["weather_control"]])
    with pytest.raises(ValueError, match="packet 1, Start of Frame"):
        encode_datagram([host, sof])
    with pytest.raises(ValueError, match="packet 1, Weather Conditions Response"):
        encode_datagram([host, EX["weather_conditions_response"]])


# --- bad input -----------------------------------------------------------------------------


def _refused(d: CigiDatagram, reason: str) -> str:
    assert d.refused and d.packets == () and dict(d.counts) == {reason: 1}, d
    return d.problems[0].message


def test_garbage_is_refused_with_a_reason() -> None:
    assert "no CIGI packet header" in _refused(decode_datagram(b""), "truncated")
    assert "opcode 255 (unknown) at byte 0" in _refused(
        decode_datagram(b"\xff" * 40), "bad_first_packet"
    )
    message = _refused(decode_datagram(weather_bytes(">")), "bad_first_packet")
    assert message.startswith("datagram: first packet opcode 12 (Weather Control) at byte 0")


def test_a_wrong_version_is_refused() -> None:
    msg = _refused(decode_datagram(ig_control_bytes(">", version=2, size=16)), "wrong_version")
    assert msg == "IG Control at byte 0: CIGI major version 2, wxsky reads 3"
    v4 = struct.pack(">HHBbBBIIII", 24, 0, 4, 0, 0, 0x31, 1, 0, 0, 0)
    assert "CIGI 4" in _refused(decode_datagram(v4), "wrong_version")
    assert "CIGI 4" in _refused(
        decode_datagram(struct.pack("<HH20x", 24, 0xFFFF)[:4] + v4[4:]), "wrong_version"
    )


def test_a_cigi_3_0_first_packet_and_a_bad_magic_are_refused() -> None:
    short = ig_control_bytes(">", size=16)[:16]
    assert "size byte 16, CIGI 3.3 sends 24" in _refused(decode_datagram(short), "size_mismatch")
    data = bytearray(ig_control_bytes("<"))
    data[6:8] = b"\x12\x34"
    assert "magic 12 34" in _refused(decode_datagram(bytes(data)), "bad_magic")


def test_truncation_at_every_length() -> None:
    for o in ORDERS:
        message = [EX["ig_control"], EX["weather_control"], EX["atmosphere_control"]]
        data = encode_datagram(message, NAME[o])
        ends = [24, 80, 112]  # where each packet ends
        for n in range(len(data)):
            d = decode_datagram(data[:n])
            if n < 24:
                _refused(d, "truncated")
                continue
            whole = sum(1 for end in ends if end <= n)
            assert d.packets == tuple(message[:whole]), n
            assert dict(d.counts) == ({} if n in ends else {"truncated": 1}), n
            if n not in ends:
                start = ends[whole - 1]
                assert d.problems[0].offset == start
                assert f"at byte {start}" in d.problems[0].message


def test_a_size_byte_that_disagrees_drops_only_that_packet() -> None:
    for o in ORDERS:
        wrong = bytearray(weather_bytes(o) + bytes(8))
        wrong[1] = 64  # 56 sent, the size byte says 64: skipped by 64
        d = decode_datagram(ig_control_bytes(o) + bytes(wrong) + atmosphere_bytes(o))
        assert [p.key for p in d.packets] == ["ig_control", "atmosphere_control"]
        assert dict(d.counts) == {"size_mismatch": 1}
        assert d.problems[0].message == (
            "Weather Control at byte 24: size byte 64, CIGI 3.3 sends 56; 64 bytes skipped"
        )
        assert d.packets[1]["wind_dir_deg"] == 350.0


def test_an_unknown_opcode_is_skipped_and_the_next_packet_decoded() -> None:
    for o in ORDERS:
        unknown = bytes([200, 16]) + bytes(range(14))  # a user-defined packet
        rate_control = bytes([8, 32]) + bytes(30)  # a 3.3 packet wxsky does not read
        body = struct.pack(f"{o}BBBBB3xIf", 9, 16, 6, 5, 1, 0, 50.0)
        d = decode_datagram(ig_control_bytes(o) + unknown + rate_control + body)
        assert [p.key for p in d.packets] == ["ig_control", "celestial_sphere_control"]
        assert d.packets[1]["hour"] == 6
        assert dict(d.counts) == {"unknown_opcode": 2}
        assert [p.offset for p in d.problems] == [24, 40]
        assert d.problems[0].message == "opcode 200 at byte 24: not read by wxsky, 16 bytes skipped"


def test_a_size_byte_of_zero_stops_the_datagram() -> None:
    for size in (0, 1):
        d = decode_datagram(
            ig_control_bytes(">") + bytes([12, size]) + bytes(54) + atmosphere_bytes(">")
        )
        assert [p.key for p in d.packets] == ["ig_control"]
        assert dict(d.counts) == {"zero_size": 1}
        assert (
            d.problems[0].message
            == f"Weather Control at byte 24: size byte {size}; 88 bytes not read"
        )


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_nan_and_infinities_drop_the_packet(bad: float) -> None:
    for o in ORDERS:
        d = decode_datagram(
            ig_control_bytes(o) + weather_bytes(o, coverage=bad) + atmosphere_bytes(o)
        )
        assert [p.key for p in d.packets] == ["ig_control", "atmosphere_control"]
        assert dict(d.counts) == {"not_finite": 1}
        assert (
            d.problems[0].message == f"Weather Control at byte 24: coverage_pct (byte 44) is {bad}"
        )


def test_out_of_range_values_drop_the_packet_with_the_field_and_its_byte() -> None:
    for o in ORDERS:
        ig = ig_control_bytes(o)
        cases = [
            (weather_bytes(o, coverage=150.0), "coverage_pct (byte 44) 150 is outside 0..100"),
            (weather_bytes(o, base=-600.0), "base_elevation_m (byte 48) -600 is below -500"),
            (
                struct.pack(f"{o}BBHB3xdd5f4x", 11, 48, 1, 1, 91.0, 0.0, 1, 1, 0, 0, 0),
                "lat_deg (byte 32) 91 is outside -90..90",
            ),
            (
                struct.pack(f"{o}BBBB4xddd", 28, 32, 4, 1, 0.0, 181.0, 0.0),
                "lon_deg (byte 40) 181 is outside -180..180",
            ),
            (
                struct.pack(f"{o}BBBBB3xIf", 9, 16, 12, 0, 1 << 4, 13_01_2024, 0.0),
                "date_mmddyyyy (byte 32) 13012024 is not a calendar date (month 13",
            ),
            (
                struct.pack(f"{o}BBBBB3xIf", 9, 16, 24, 0, 0, 0, 0.0),
                "hour (byte 26) 24 is outside 0..23",
            ),
        ]
        for body, detail in cases:
            d = decode_datagram(ig + body + atmosphere_bytes(o))
            assert [p.key for p in d.packets] == ["ig_control", "atmosphere_control"], detail
            assert dict(d.counts) == {"out_of_range": 1}
            assert detail in d.problems[0].message
            assert d.problems[0].message.startswith(f"{BY_OPCODE[body[0]].name} at byte 24: ")


def test_a_bad_first_packet_value_drops_it_and_keeps_the_rest() -> None:
    d = decode_datagram(ig_control_bytes(">", mode=3) + atmosphere_bytes(">"))
    assert d.byte_order == "big" and [p.key for p in d.packets] == ["atmosphere_control"]
    assert d.problems[0].message == "IG Control at byte 0: ig_mode (byte 4) 3 is outside 0..2"


def test_conditional_ranges_apply_only_when_their_flag_says() -> None:
    # Attached: lat/lon are offsets in metres, any finite value.
    attached = struct.pack(
        ">BBHBBBxHHfffddd", 2, 48, 5, 1 | 1 << 2, 0, 255, 0, 4, 0, 0, 0, 250.0, -300.0, 2.0
    )
    d = decode_datagram(ig_control_bytes(">") + attached)
    assert dict(d.counts) == {} and d.packets[1]["lat_deg"] == 250.0
    # Date not valid: a host that leaves the date 0 still sets its sun and moon.
    undated = struct.pack(">BBBBB3xIf", 9, 16, 0, 0, 0b0110, 0, 0.0)
    d = decode_datagram(ig_control_bytes(">") + undated)
    assert dict(d.counts) == {} and d.packets[1]["sun_enable"] == 1


def test_first_packets_later_and_packets_of_the_other_direction_are_dropped() -> None:
    for o in ORDERS:
        ig, sof = ig_control_bytes(o), sof_bytes(o)
        aerosol = struct.pack(f"{o}BBBBf", 110, 8, 1, 1, 0.5)
        d = decode_datagram(ig + ig + sof + aerosol + atmosphere_bytes(o))
        assert [p.key for p in d.packets] == ["ig_control", "atmosphere_control"]
        assert dict(d.counts) == {"misplaced": 2, "wrong_direction": 1}
        assert d.problems[2].message == (
            "Aerosol Concentration Response at byte 72: IG → host packet in a host → IG message"
        )


def test_problem_messages_are_kept_to_a_bound_and_counted_in_full() -> None:
    d = decode_datagram(ig_control_bytes(">") + bytes([200, 8, 0, 0, 0, 0, 0, 0]) * 100)
    assert dict(d.counts) == {"unknown_opcode": 100} and len(d.problems) == MAX_PROBLEMS


def test_every_reason_is_documented_and_named_stably() -> None:
    assert set(REASONS) == {
        "truncated",
        "bad_first_packet",
        "wrong_version",
        "bad_magic",
        "size_mismatch",
        "zero_size",
        "unknown_opcode",
        "misplaced",
        "wrong_direction",
        "not_finite",
        "out_of_range",
    }


def _assert_in_range(p: Packet) -> None:
    """Independent of the decoder's checks: read the table's numbers directly."""
    for f in p.spec.value_fields:
        v = p[f.name]
        assert isinstance(v, float if f.is_float else int), (p, f.name)
        assert math.isfinite(v), (p, f.name)
        if f.when is not None and p[f.when[0]] != f.when[1]:
            continue
        if f.lo is not None:
            assert v >= f.lo, (p, f.name)
        if f.hi is not None:
            assert v < f.hi if f.wrap else v <= f.hi, (p, f.name)


def test_random_bytes_never_raise_and_decode_only_values_in_range() -> None:
    rng = random.Random(20261202)
    seeds = [encode_datagram(m, NAME[o]) for m in messages() for o in ORDERS]
    decoded = 0
    for i in range(3000):
        if i % 3 == 0:
            data = rng.randbytes(rng.randrange(0, 200))
        else:
            mutated = bytearray(rng.choice(seeds))
            for _ in range(rng.randrange(1, 8)):
                mutated[rng.randrange(len(mutated))] = rng.randrange(256)
            if i % 7 == 0:
                del mutated[rng.randrange(len(mutated)) :]
            data = bytes(mutated)
        d = decode_datagram(data)
        assert sum(d.counts.values()) >= len(d.problems)
        assert set(d.counts) <= set(REASONS)
        assert all("\n" not in p.message for p in d.problems)
        for p in d.packets:
            _assert_in_range(p)
            decoded += 1
    assert decoded > 2000  # most mutations got past the first packet


# --- docs -----------------------------------------------------------------------------------


def _generated(name: str) -> str:
    text = DOC.read_text(encoding="utf-8")
    begin = f"<!-- BEGIN generated: {name} -->\n"
    end = f"<!-- END generated: {name} -->"
    assert begin in text and end in text, f"docs/cigi.md has no block for {name}"
    return text.split(begin, 1)[1].split(end, 1)[0]


def test_the_doc_holds_the_packet_table() -> None:
    assert _generated("wxsky.protocols.cigi_packets.table_markdown()") == table_markdown(), (
        "docs/cigi.md is stale: paste table_markdown() into it"
    )


def test_the_doc_holds_the_reasons() -> None:
    assert _generated("wxsky.protocols.cigi.reasons_markdown()") == reasons_markdown()


def test_the_doc_table_names_every_field() -> None:
    table = table_markdown()
    for spec in PACKETS:
        assert f"### {spec.name} ({spec.opcode}, {spec.size} bytes" in table
        for f in spec.value_fields:
            assert f"`{f.name}`" in table
    assert "| 4 | bits 4–7 | `cloud_type` |" not in table  # cloud type is byte 6
    assert "| 6 | bits 4–7 | `cloud_type` | 0..15 |" in table
    assert "| 44 | f32 | `wind_dir_deg` | -360..360, kept as 0..<360 |" in table
