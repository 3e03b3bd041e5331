from __future__ import annotations

import dataclasses
import struct

import numpy as np
import pytest

from wxsky.errors import ProtocolError
from wxsky.output.frame_meta import (
    RECORD_SIZE,
    RECORD_SIZE_V2,
    FrameMeta,
    RadarPlacement,
    ShadowPlacement,
)
from wxsky.scene.camera import Camera


def _meta() -> FrameMeta:
    quads = np.arange(96, dtype=np.float64).reshape(8, 4, 3) * 1.5
    return FrameMeta(
        frame_number=123456789012,
        ring_version=7,
        time_utc_unix_s=1_781_000_000.25,
        camera=Camera((1.0, -2.0, 434.5), 271.0, -12.5, 3.0, 75.0, 640, 360),
        sun_direction_enu=(0.1, -0.2, 0.97),
        ring_centre_m=(5.0, 6.0, 7.0),
        ring_radius_m=8000.0,
        ring_quads_m=quads,
    )


def test_round_trip_is_exact() -> None:
    meta = _meta()
    data = meta.pack()
    assert len(data) == RECORD_SIZE == 1800
    back = FrameMeta.unpack(data)
    assert back.camera == meta.camera
    assert back.frame_number == meta.frame_number
    assert back.sun_direction_enu == meta.sun_direction_enu
    np.testing.assert_array_equal(back.ring_quads_m, meta.ring_quads_m)


def test_field_offsets_match_the_protocol_doc() -> None:
    data = _meta().pack()
    assert struct.unpack_from("<I", data, 0)[0] == 3
    assert struct.unpack_from("<Q", data, 8)[0] == 123456789012
    assert struct.unpack_from("<Q", data, 16)[0] == 7
    assert struct.unpack_from("<d", data, 56)[0] == 271.0  # heading_deg
    assert struct.unpack_from("<II", data, 88) == (640, 360)
    assert struct.unpack_from("<d", data, 144)[0] == 8000.0  # ring radius
    assert struct.unpack_from("<d", data, 152 + 8 * 5)[0] == 5 * 1.5  # quads[0][1][2]


@pytest.mark.parametrize("cut", [0, 1, 100, RECORD_SIZE - 1])
def test_truncated_record_is_a_protocol_error(cut: int) -> None:
    with pytest.raises(ProtocolError, match="bytes, expected"):
        FrameMeta.unpack(_meta().pack()[:cut])


def test_unknown_version_is_refused() -> None:
    data = bytearray(_meta().pack())
    data[0] = 9
    with pytest.raises(ProtocolError, match="version 9"):
        FrameMeta.unpack(bytes(data))


def test_garbage_record_is_a_protocol_error() -> None:
    rng = np.random.default_rng(3)
    data = bytearray(rng.integers(0, 256, RECORD_SIZE, dtype=np.uint8).tobytes())
    data[0:4] = struct.pack("<I", 1)
    with pytest.raises(ProtocolError, match="frame record"):
        FrameMeta.unpack(bytes(data))


def test_a_fade_round_trips_and_sits_where_the_doc_says() -> None:
    quads = np.arange(96, dtype=np.float64).reshape(8, 4, 3) * -2.0
    meta = dataclasses.replace(
        _meta(),
        ring_set=1,
        ring_fade=0.375,
        incoming_centre_m=(900.0, -50.0, 1500.0),
        incoming_radius_m=8000.0,
        incoming_quads_m=quads,
    )
    data = meta.pack()
    back = FrameMeta.unpack(data)
    assert back.fading and back.ring_set == 1 and back.ring_fade == 0.375
    assert back.incoming_centre_m == (900.0, -50.0, 1500.0)
    np.testing.assert_array_equal(back.incoming_quads_m, quads)
    assert struct.unpack_from("<IId", data, 920) == (1, 1, 0.375)
    assert struct.unpack_from("<3dd", data, 936) == (900.0, -50.0, 1500.0, 8000.0)
    assert struct.unpack_from("<d", data, 968 + 8 * 5)[0] == 5 * -2.0


def test_without_a_fade_the_incoming_ring_reads_back_as_absent() -> None:
    back = FrameMeta.unpack(_meta().pack())
    assert not back.fading and back.ring_fade == 0.0 and back.incoming_quads_m is None
    # ... even if a writer left a stale weight behind.
    stale = dataclasses.replace(_meta(), ring_fade=0.5).pack()
    assert FrameMeta.unpack(stale).ring_fade == 0.0


SHADOW = ShadowPlacement(
    version=12,
    centre_m=(-1500.5, 250.25, 432.0),
    size_m=16_000.0,
    sun_direction_enu=(0.6, 0.0, 0.8),
)


def test_the_shadow_placement_round_trips_and_sits_where_the_doc_says() -> None:
    data = dataclasses.replace(_meta(), shadow=SHADOW).pack()
    assert FrameMeta.unpack(data).shadow == SHADOW
    assert struct.unpack_from("<Q3dd3d", data, 1736) == (
        12,
        -1500.5,
        250.25,
        432.0,
        16_000.0,
        0.6,
        0.0,
        0.8,
    )
    # Without a map: version 0 and zeros, read back as None.
    plain = _meta().pack()
    assert plain[1736:] == bytes(64)
    assert FrameMeta.unpack(plain).shadow is None


def test_a_version_2_record_reads_without_a_shadow() -> None:
    v3 = dataclasses.replace(_meta(), shadow=SHADOW).pack()
    v2 = struct.pack("<I", 2) + v3[4:RECORD_SIZE_V2]
    back = FrameMeta.unpack(v2)
    assert back.shadow is None and back.camera == _meta().camera
    with pytest.raises(ProtocolError, match="1735 bytes, expected 1736"):
        FrameMeta.unpack(v2[:-1])
    # A version 3 record cut to version 2's length is short.
    with pytest.raises(ProtocolError, match="1736 bytes, expected 1800"):
        FrameMeta.unpack(v3[:RECORD_SIZE_V2])


@pytest.mark.parametrize("version", [1, 4])
def test_versions_before_2_and_after_3_are_refused(version: int) -> None:
    data = struct.pack("<I", version) + _meta().pack()[4:]
    with pytest.raises(ProtocolError, match=f"version {version}, this reader knows 2 and 3"):
        FrameMeta.unpack(data)


@pytest.mark.parametrize(
    ("offset", "value"),
    [(1768, 0.0), (1768, -5.0), (1744, float("nan")), (1784, float("inf"))],
    ids=["no-size", "negative-size", "nan-centre", "inf-sun"],
)
def test_an_impossible_shadow_placement_is_a_protocol_error(offset: int, value: float) -> None:
    data = bytearray(dataclasses.replace(_meta(), shadow=SHADOW).pack())
    struct.pack_into("<d", data, offset, value)
    with pytest.raises(ProtocolError, match="shadow placement"):
        FrameMeta.unpack(bytes(data))


def test_a_radar_placement_follows_the_version_3_record() -> None:
    """A slot with a radar picture (`[radar] layer`) has a longer version 3 record, whose
    bytes past 1800 readers of before ignore; one without has the record of before."""
    placed = RadarPlacement(7, (1.0, -2.0, 1500.0), 40.0, -2.5, 1_781_000_000.0)
    plain = _meta().pack()
    data = dataclasses.replace(_meta(), radar=placed).pack()
    assert len(data) == RECORD_SIZE + 56 and data[:RECORD_SIZE] == plain
    assert struct.unpack_from("<Q3dddd", data, 1800) == (7, 1.0, -2.0, 1500.0, 40.0, -2.5, 1.781e9)
    assert FrameMeta.unpack(data).radar == placed
    assert FrameMeta.unpack(plain).radar is None
    assert FrameMeta.unpack(data[:RECORD_SIZE]).radar is None
    bad = data[:1832] + struct.pack("<d", float("nan")) + data[1840:]
    with pytest.raises(ProtocolError, match="radar placement"):
        FrameMeta.unpack(bad)
