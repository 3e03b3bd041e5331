"""MessagePack-RPC framing: encode/decode, streaming, and the errors a broken peer gets."""

from __future__ import annotations

import gc
import struct
import tracemalloc
from typing import Any

import numpy as np
import pytest

from wxsky.errors import ProtocolError, WxskyError
from wxsky.output.wire import (
    MAX_REQUEST_SIZE,
    MSGID_MAX,
    MessageDecoder,
    Notification,
    Request,
    Response,
    WireError,
    encode,
)


def pack(obj: Any) -> bytes:
    """A deliberately independent msgpack encoder for the subset the tests need, written from
    the msgpack spec, so malformed messages can be built without going through wire.encode (and
    so encode's output is checked against the spec, not against itself)."""
    if obj is None:
        return b"\xc0"
    if obj is True:
        return b"\xc3"
    if obj is False:
        return b"\xc2"
    if isinstance(obj, int):
        if 0 <= obj <= 0x7F:
            return bytes([obj])
        if -32 <= obj < 0:
            return struct.pack("b", obj)
        if obj > 0:
            for code, fmt, top in (
                (0xCC, ">B", 0xFF),
                (0xCD, ">H", 0xFFFF),
                (0xCE, ">I", 2**32 - 1),
            ):
                if obj <= top:
                    return bytes([code]) + struct.pack(fmt, obj)
            return b"\xcf" + struct.pack(">Q", obj)
        for code, fmt, bottom in (
            (0xD0, ">b", -(2**7)),
            (0xD1, ">h", -(2**15)),
            (0xD2, ">i", -(2**31)),
        ):
            if obj >= bottom:
                return bytes([code]) + struct.pack(fmt, obj)
        return b"\xd3" + struct.pack(">q", obj)
    if isinstance(obj, float):
        return b"\xcb" + struct.pack(">d", obj)
    if isinstance(obj, str):
        raw = obj.encode()
        if len(raw) < 32:
            return bytes([0xA0 | len(raw)]) + raw
        return b"\xd9" + bytes([len(raw)]) + raw
    if isinstance(obj, bytes):
        return b"\xc4" + bytes([len(obj)]) + obj
    if isinstance(obj, list):
        assert len(obj) < 16
        return bytes([0x90 | len(obj)]) + b"".join(pack(v) for v in obj)
    if isinstance(obj, dict):
        assert len(obj) < 16
        return bytes([0x80 | len(obj)]) + b"".join(pack(k) + pack(v) for k, v in obj.items())
    raise TypeError(obj)


MESSAGES: list[Request | Response | Notification] = [
    Request(0, "ping", {}),
    Request(MSGID_MAX, "set_weather", {"preset": "cavok", "visibility_m": 9999.5, "ok": True}),
    Response(1, None, {"frame": 12, "layers": ["clouds", "haze"], "blob": b"\x00\xff"}),
    Response(2, "unknown preset 'x'", None),
    Response(None, "control message 1: expected an array [type, ...], got int", None),
    Notification("weather", {"wind": [270, -3, 2**64 - 1, -(2**63)], "note": "ünïcødé", "n": None}),
]


@pytest.mark.parametrize("message", MESSAGES, ids=lambda m: type(m).__name__)
def test_round_trip(message: Request | Response | Notification) -> None:
    assert MessageDecoder().feed(encode(message)) == [message]


def test_encoding_matches_the_spec_arrays() -> None:
    params = {"a": 1, "b": [None, True, 1.5, "x", b"y"]}
    assert encode(Request(7, "m", params)) == pack([0, 7, "m", params])
    assert encode(Response(7, None, -5)) == pack([1, 7, None, -5])
    assert encode(Response(None, "bad", None)) == pack([1, None, "bad", None])
    assert encode(Notification("frame", {"n": 300})) == pack([2, "frame", {"n": 300}])


def test_streaming_split_at_every_byte_boundary() -> None:
    stream = b"".join(encode(m) for m in MESSAGES)
    for cut in range(len(stream) + 1):
        decoder = MessageDecoder()
        got = decoder.feed(stream[:cut]) + decoder.feed(stream[cut:])
        assert got == MESSAGES, cut


def test_byte_at_a_time() -> None:
    stream = b"".join(encode(m) for m in MESSAGES)
    decoder = MessageDecoder()
    got = [m for i in range(len(stream)) for m in decoder.feed(stream[i : i + 1])]
    assert got == MESSAGES
    assert decoder.messages_decoded == len(MESSAGES)


def test_a_long_stream_in_small_pieces_keeps_its_place() -> None:
    # Beyond the decoder's first 16 KiB piece, with messages straddling every piece: a
    # decoder that swapped its msgpack buffer while a message was half parsed lost its place
    # ("expected an array [type, ...], got int") at 100- and 1000-byte reads.
    sent = [Response(i, None, {"s": "a" * 700, "n": list(range(i))}) for i in range(100)]
    stream = b"".join(encode(m) for m in sent)
    for step in (1, 100, 1000, 4096, 20_000):
        decoder = MessageDecoder()
        got = [
            m for pos in range(0, len(stream), step) for m in decoder.feed(stream[pos : pos + step])
        ]
        assert got == sent, step


def test_truncated_input_yields_nothing_until_complete() -> None:
    data = encode(Notification("scene", {"pad": b"z" * 200}))
    decoder = MessageDecoder()
    assert decoder.feed(data[:-1]) == []
    assert decoder.feed(b"") == []
    assert decoder.feed(data[-1:]) == [Notification("scene", {"pad": b"z" * 200})]


def test_bytes_that_are_not_msgpack_break_the_stream() -> None:
    decoder = MessageDecoder()
    with pytest.raises(WireError, match=r"^control message 1: not valid msgpack") as info:
        decoder.feed(b"\xc1\x00\x00")  # 0xc1 is the one byte msgpack never uses
    assert not info.value.recoverable
    assert info.value.msgid is None
    assert isinstance(info.value, ProtocolError)
    assert isinstance(info.value, WxskyError)
    with pytest.raises(WireError, match="unusable after an earlier error"):
        decoder.feed(encode(Request(1, "ping", {})))


def test_text_garbage_is_named_by_its_shape() -> None:
    # Most bytes are valid msgpack (b"G" is the int 71), so text shows up as wrong shapes.
    decoder = MessageDecoder()
    with pytest.raises(WireError) as info:
        decoder.feed(b"GET / HTTP/1.1\r\n")
    assert str(info.value) == "control message 1: expected an array [type, ...], got int"
    assert info.value.msgid is None


def test_messages_before_a_bad_one_are_kept_and_decoding_continues() -> None:
    good: list[Request | Response | Notification] = [Request(1, "a", {}), Notification("b", {})]
    bad = pack([0, 3, 5, {}])
    after = Request(4, "c", {"x": 1})
    decoder = MessageDecoder()
    with pytest.raises(WireError) as info:
        decoder.feed(b"".join(encode(m) for m in good) + bad + encode(after))
    err = info.value
    assert str(err) == (
        "control message 3: expected [0, msgid, method, params], got int method (must be a string)"
    )
    assert err.decoded == good
    assert err.recoverable
    assert err.msgid == 3
    assert decoder.feed(b"") == [after]


@pytest.mark.parametrize(
    ("obj", "expected"),
    [
        (5, "expected an array [type, ...], got int"),
        ({"type": 0}, "expected an array [type, ...], got dict"),
        ([], "unknown message type None"),
        ([3, 1, "m", {}], "unknown message type 3"),
        ([True, 1, "m", {}], "unknown message type True"),
        ([0, 1, "m"], "expected [0, msgid, method, params], got an array of 3"),
        ([0, 1, "m", {}, 5], "expected [0, msgid, method, params], got an array of 5"),
        ([0, "1", "m", {}], "got msgid '1' (must be an int in 0..4294967295)"),
        ([0, -1, "m", {}], "got msgid -1"),
        ([0, 2**32, "m", {}], "got msgid 4294967296"),
        ([0, 1, b"m", {}], "got bytes method (must be a string)"),
        ([0, 1, "m", [1, 2]], "got list params (must be a map)"),
        ([0, 1, "m", None], "got nil params (must be a map)"),
        ([1, "x", None, None], "expected [1, msgid, error, result], got msgid 'x'"),
        ([1, 1, 42, None], "got int error (must be a string or nil)"),
        ([2, "m"], "expected [2, method, params], got an array of 2"),
        ([2, 7, {}], "got int method"),
        ([2, "m", "p"], "got str params (must be a map)"),
    ],
)
def test_wrong_shapes(obj: Any, expected: str) -> None:
    with pytest.raises(WireError) as info:
        MessageDecoder().feed(pack(obj))
    message = str(info.value)
    assert message.startswith("control message 1: ")
    assert expected in message
    assert "\n" not in message
    assert info.value.recoverable


def test_wrong_shape_request_reports_its_msgid() -> None:
    with pytest.raises(WireError) as info:
        MessageDecoder().feed(pack([0, 42, "m", [1]]))
    assert info.value.msgid == 42


def test_int_map_keys_are_refused() -> None:
    with pytest.raises(WireError, match="map keys must be strings") as info:
        MessageDecoder().feed(pack([2, "m", {1: 2}]))
    assert not info.value.recoverable


def test_extension_types_are_refused() -> None:
    fixext1 = b"\xd4\x03a"  # ext type 3, one byte of data
    data = b"\x93" + pack(2) + pack("m") + b"\x81" + pack("t") + fixext1
    with pytest.raises(WireError, match=r"message\[2\]\['t'\] is a msgpack extension type"):
        MessageDecoder().feed(data)


def test_oversized_message_is_refused_naming_the_decoders_own_limit() -> None:
    decoder = MessageDecoder(max_message_size=1024)
    with pytest.raises(WireError, match="larger than") as info:
        decoder.feed(encode(Notification("big", {"b": b"x" * 2000})))
    assert not info.value.recoverable
    assert str(info.value) == "control message 1: larger than 1024 bytes"


def test_message_limit_is_exact_however_the_bytes_are_split() -> None:
    # msgpack's own buffer limit counts buffered bytes, not messages: the decoder checks each
    # message's size as it completes, so the limit is the same in one read or many.
    limit = 40_000
    at_limit = _request_of_size(limit)
    over = _request_of_size(limit + 1)
    for split in (1, 1000, 16_384, 65_536, len(over)):
        decoder = MessageDecoder(max_message_size=limit)
        got = [
            m for i in range(0, len(at_limit), split) for m in decoder.feed(at_limit[i : i + split])
        ]
        assert len(got) == 1, split
        decoder = MessageDecoder(max_message_size=limit)
        with pytest.raises(WireError, match=f"^control message 1: larger than {limit} bytes$"):
            for i in range(0, len(over), split):
                decoder.feed(over[i : i + split])


def test_many_small_messages_in_one_read_are_not_too_large() -> None:
    stream = encode(Request(1, "status", {})) * 20_000  # 220 kB: far over the request limit
    got = MessageDecoder(max_message_size=MAX_REQUEST_SIZE).feed(stream)
    assert len(got) == 20_000


def test_a_message_announced_larger_than_the_limit_is_refused_long_before_it_is_all_in() -> None:
    decoder = MessageDecoder(max_message_size=MAX_REQUEST_SIZE)
    header = b"\x94\x00\x01\xa6status\x81\xa1r\xdb" + struct.pack(">I", 8 * 1024 * 1024)
    assert decoder.feed(header) == []
    with pytest.raises(WireError, match=f"larger than {MAX_REQUEST_SIZE} bytes"):
        for _ in range(4):  # 64 KiB of the 8 MiB announced
            decoder.feed(b"x" * 16_384)


def test_the_buffer_of_a_large_message_is_given_back() -> None:
    decoder = MessageDecoder()  # the 8 MiB protocol limit
    data = _request_of_size(4_000_000)
    tracemalloc.start()
    try:
        held_before = tracemalloc.get_traced_memory()[0]
        for i in range(0, len(data), 65_536):
            decoder.feed(data[i : i + 65_536])
        gc.collect()
        held = tracemalloc.get_traced_memory()[0] - held_before
    finally:
        tracemalloc.stop()
    assert held < 200_000, f"the decoder still holds {held} bytes after a 4 MB message"
    assert decoder.feed(encode(Request(2, "status", {}))) == [Request(2, "status", {})]


def test_a_wrong_shaped_message_in_a_long_read_loses_nothing_after_it() -> None:
    after = [Request(i, "status", {}) for i in range(5000)]  # 55 kB after the bad one
    decoder = MessageDecoder()
    with pytest.raises(WireError) as info:
        decoder.feed(pack([0, 3, 5, {}]) + b"".join(encode(m) for m in after))
    assert info.value.recoverable
    assert decoder.feed(b"") == after


def _request_of_size(size: int) -> bytes:
    """An encoded request exactly `size` bytes long."""
    base = len(encode(Request(1, "apply_metar", {"report": ""})))
    for pad in range(size - base, size - base - 6, -1):
        data = encode(Request(1, "apply_metar", {"report": "x" * pad}))
        if len(data) == size:
            return data
    raise AssertionError(f"no request of {size} bytes")


class Custom:
    pass


@pytest.mark.parametrize(
    ("params", "expected"),
    [
        ({"s": {1, 2}}, "params['s'] has type set"),
        ({"o": Custom()}, "params['o'] has type test_wire.Custom"),
        ({"n": np.int64(3)}, "params['n'] has type numpy.int64"),
        ({"deep": [1, {"x": [object()]}]}, "params['deep'][1]['x'][0] has type object"),
        ({"k": {1: "one"}}, "params['k'] has key 1 of type int; map keys must be str"),
        ({"big": 2**64}, "does not fit in 64 bits"),
        ({"small": -(2**63) - 1}, "does not fit in 64 bits"),
    ],
)
def test_encode_rejects_what_is_not_plain_data(params: dict[str, Any], expected: str) -> None:
    with pytest.raises(ProtocolError) as info:
        encode(Notification("m", params))
    assert expected in str(info.value)
    assert str(info.value).startswith("cannot encode notification: ")


def test_encode_rejects_bad_envelopes() -> None:
    with pytest.raises(ProtocolError, match="msgid"):
        encode(Request(-1, "m", {}))
    with pytest.raises(ProtocolError, match="msgid"):
        encode(Request(2**32, "m", {}))
    with pytest.raises(ProtocolError, match="params must be a dict"):
        encode(Request(1, "m", [1]))  # type: ignore[arg-type]
    with pytest.raises(ProtocolError, match="method must be a str"):
        encode(Notification(5, {}))  # type: ignore[arg-type]
    with pytest.raises(ProtocolError, match="cannot encode type str"):
        encode("hello")  # type: ignore[arg-type]
    with pytest.raises(ProtocolError, match="cannot encode response"):
        encode(Response(1, None, {"r": Custom()}))


def test_tuples_travel_as_arrays_and_deep_nesting_is_fine() -> None:
    nested: Any = "leaf"
    for _ in range(400):
        nested = [nested]
    message = Notification("m", {"t": (1, 2), "deep": nested})
    (decoded,) = MessageDecoder().feed(encode(message))
    assert isinstance(decoded, Notification)
    assert decoded.params["t"] == [1, 2]
    assert decoded.params["deep"] == nested
