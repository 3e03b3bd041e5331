"""MessagePack-RPC framing for the control/state channel: the only module that imports msgpack.

Messages are msgpack arrays written back to back on a byte stream, with no length prefix:

    Request       [0, msgid, method, params]
    Response      [1, msgid, error, result]     error is nil on success, else a one-line string
    Notification  [2, method, params]

Unlike the MessagePack-RPC spec (positional params), `params` is always a map with string keys.
`msgid` is an unsigned 32-bit integer; a Response's msgid is nil when the request it answers could
not be identified. Values are plain data only: nil, bool, int (signed or unsigned 64-bit), float,
str, bin (bytes), array and string-keyed map; extension types are rejected.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import msgpack

from wxsky.errors import ProtocolError

REQUEST = 0
RESPONSE = 1
NOTIFICATION = 2

MAX_MESSAGE_SIZE = 8 * 1024 * 1024
"""Largest encoded message a decoder accepts; bigger ones are a protocol error."""

MAX_REQUEST_SIZE = 32 * 1024
"""Largest message the daemon reads from a host (docs/protocol.md §2.2). The largest legal
request is an `apply_metar` with the longest report accepted (4096 characters: 16,456 bytes
with every other param, if each character took 4 bytes of UTF-8), or a `subscribe` with the
most topics (32 of up to 64 characters: 8,092 bytes); about as much again is left for params
added later. Anything bigger
is refused before it is buffered: one connection cannot make the daemon hold megabytes, nor
hold up the other clients while they are decoded."""

MSGID_MAX = 0xFFFF_FFFF
_INT_MIN = -(2**63)
_INT_MAX = 2**64 - 1

_SHAPES = {
    REQUEST: "[0, msgid, method, params]",
    RESPONSE: "[1, msgid, error, result]",
    NOTIFICATION: "[2, method, params]",
}


@dataclass(frozen=True)
class Request:
    msgid: int
    method: str
    params: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Response:
    msgid: int | None
    error: str | None
    result: Any = None


@dataclass(frozen=True)
class Notification:
    method: str
    params: dict[str, Any] = field(default_factory=dict)


Message = Request | Response | Notification


class WireError(ProtocolError):
    """A message that could not be decoded.

    `decoded` holds the messages completed before the bad one (from the same `feed` call), so a
    caller can still answer them. `recoverable` is True when the bad message was well-formed
    msgpack of the wrong shape: the stream is still in step, and `feed(b"")` continues with
    whatever follows it. `msgid` is the request's msgid when it could be read.
    """

    def __init__(self, message: str, *, recoverable: bool, msgid: int | None = None) -> None:
        super().__init__(message)
        self.recoverable = recoverable
        self.msgid = msgid
        self.decoded: list[Message] = []


def _type_name(value: object) -> str:
    if value is None:
        return "nil"
    cls = type(value)
    return cls.__name__ if cls.__module__ == "builtins" else f"{cls.__module__}.{cls.__qualname__}"


def _plain_data_problem(value: object, where: str) -> str | None:
    """Why `value` is not plain data (naming the first offending path), or None if it is.

    Iterative, because msgpack accepts nesting deeper than Python's recursion limit.
    """
    stack: list[tuple[object, str]] = [(value, where)]
    while stack:
        item, path = stack.pop()
        if item is None or isinstance(item, (bool, str, bytes, bytearray, memoryview)):
            continue
        if isinstance(item, (msgpack.ExtType, msgpack.Timestamp)):
            return f"{path} is a msgpack extension type, which this protocol does not use"
        if isinstance(item, int):
            if not _INT_MIN <= item <= _INT_MAX:
                return f"{path} = {item} does not fit in 64 bits"
            continue
        if isinstance(item, float):
            continue
        if isinstance(item, (list, tuple)):
            stack.extend((v, f"{path}[{i}]") for i, v in enumerate(item))
            continue
        if isinstance(item, Mapping):
            for key, v in item.items():
                if not isinstance(key, str):
                    return f"{path} has key {key!r} of type {_type_name(key)}; map keys must be str"
                stack.append((v, f"{path}[{key!r}]"))
            continue
        return (
            f"{path} has type {_type_name(item)}; only nil, bool, int, float, str, bytes, "
            "list and str-keyed dict can be sent"
        )
    return None


def _check_msgid(msgid: object, *, nullable: bool) -> None:
    if nullable and msgid is None:
        return
    if isinstance(msgid, bool) or not isinstance(msgid, int) or not 0 <= msgid <= MSGID_MAX:
        raise ProtocolError(f"msgid must be an int in 0..{MSGID_MAX}, got {msgid!r}")


def encode(message: Message) -> bytes:
    """The msgpack bytes of one message. Raises ProtocolError for values that are not plain data
    (nothing is ever pickled or converted behind the caller's back)."""
    if isinstance(message, Request):
        _check_msgid(message.msgid, nullable=False)
        array: list[Any] = [REQUEST, message.msgid, message.method, message.params]
        names: tuple[str, ...] = ("type", "msgid", "method", "params")
    elif isinstance(message, Response):
        _check_msgid(message.msgid, nullable=True)
        if message.error is not None and not isinstance(message.error, str):
            raise ProtocolError(
                f"response error must be a str or None, got {_type_name(message.error)}"
            )
        array = [RESPONSE, message.msgid, message.error, message.result]
        names = ("type", "msgid", "error", "result")
    elif isinstance(message, Notification):
        array = [NOTIFICATION, message.method, message.params]
        names = ("type", "method", "params")
    else:
        raise ProtocolError(f"cannot encode type {_type_name(message)}; expected a wire message")
    if not isinstance(message, Response):
        method = message.method
        if not isinstance(method, str):
            raise ProtocolError(f"method must be a str, got {_type_name(method)}")
        if not isinstance(message.params, dict):
            raise ProtocolError(
                f"{method}: params must be a dict, got {_type_name(message.params)}"
            )
    for name, value in zip(names[1:], array[1:], strict=True):
        problem = _plain_data_problem(value, name)
        if problem is not None:
            raise ProtocolError(f"cannot encode {type(message).__name__.lower()}: {problem}")
    try:
        data: bytes = msgpack.packb(array, use_bin_type=True, default=_refuse)
    except (ValueError, OverflowError, TypeError) as exc:  # e.g. nesting beyond msgpack's limit
        raise ProtocolError(f"cannot encode {type(message).__name__.lower()}: {exc}") from exc
    if len(data) > MAX_MESSAGE_SIZE:
        raise ProtocolError(
            f"encoded message is {len(data)} bytes; the limit is {MAX_MESSAGE_SIZE}"
        )
    return data


def _refuse(value: object) -> object:
    # Unreachable after the plain-data check; a second guard against msgpack ever falling back.
    raise ProtocolError(f"cannot encode type {_type_name(value)}")


_FEED_CHUNK = 16 * 1024  # bytes handed to msgpack at a time (its buffer's starting size)


class MessageDecoder:
    """Turns a byte stream into messages, however the bytes are split. One per connection.

    It holds at most `max_message_size` plus 16 KiB however the stream is split (bytes go to
    msgpack 16 KiB at a time, each complete message taken out before the next piece), and
    gives memory back after a large message: msgpack's buffer only ever grows, so once nothing
    is pending a grown buffer is dropped for a fresh one."""

    def __init__(self, max_message_size: int = MAX_MESSAGE_SIZE) -> None:
        self.max_message_size = max_message_size
        self._unpacker = self._new_unpacker()
        self._fed = 0  # bytes fed to this unpacker
        self._start = 0  # where the message being decoded begins, in those bytes
        self._rest = b""  # bytes of a feed that a wrong-shaped message interrupted
        self._count = 0
        self._broken: str | None = None

    def _new_unpacker(self) -> msgpack.Unpacker:
        limit = self.max_message_size
        return msgpack.Unpacker(
            # A partial message over the limit plus one piece does not fit: BufferFull says
            # the message is too large, never earlier (each message's exact size is checked
            # as it completes). Headers announcing more than the limit are refused at once.
            max_buffer_size=limit + _FEED_CHUNK,
            max_str_len=limit,
            max_bin_len=limit,
            max_array_len=limit,
            max_map_len=limit // 2,
            read_size=min(_FEED_CHUNK, limit + _FEED_CHUNK),
            raw=False,
            strict_map_key=True,
            use_list=True,
        )

    @property
    def messages_decoded(self) -> int:
        return self._count

    def feed(self, data: bytes) -> list[Message]:
        """Add bytes; return every message they complete (none while one is still partial).

        Raises WireError (a ProtocolError). After a non-recoverable one the decoder refuses
        further input, because a msgpack stream cannot be resynchronised.
        """
        if self._broken is not None:
            raise WireError(
                f"control stream is unusable after an earlier error ({self._broken})",
                recoverable=False,
            )
        decoded: list[Message] = []
        if self._rest:  # what followed a wrong-shaped message, not yet decoded
            data, self._rest = self._rest + bytes(data), b""
        view = memoryview(data)
        offset = 0
        try:
            self._drain(decoded)  # messages still buffered after a wrong-shaped one
            while offset < len(view):
                piece = view[offset : offset + _FEED_CHUNK]
                offset += len(piece)
                try:
                    self._unpacker.feed(piece)
                except msgpack.BufferFull:
                    raise self._fail(self._too_large(), decoded) from None
                self._fed += len(piece)
                self._drain(decoded)
        except WireError as exc:
            if exc.recoverable:
                self._rest = bytes(view[offset:])
            raise
        if self._fed > _FEED_CHUNK and self._start == self._fed:
            # Nothing pending: let a buffer grown by a large message go. Only the end of the
            # last complete message tells that: msgpack's tell() also counts the bytes of a
            # container it has half parsed, and a fresh unpacker would lose its place.
            self._unpacker, self._fed, self._start = self._new_unpacker(), 0, 0
        return decoded

    def _too_large(self) -> str:
        return f"control message {self._count + 1}: larger than {self.max_message_size} bytes"

    def _drain(self, decoded: list[Message]) -> None:
        while True:
            try:
                obj = next(self._unpacker)
            except StopIteration:
                return
            except (ValueError, TypeError, msgpack.UnpackException) as exc:
                reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
                if "exceeds max_" in reason:  # a header announcing more than the limit
                    raise self._fail(self._too_large(), decoded) from None
                if "map key" in reason:
                    reason = f"map keys must be strings: {reason}"
                raise self._fail(
                    f"control message {self._count + 1}: not valid msgpack ({reason})", decoded
                ) from None
            end = self._unpacker.tell()
            size, self._start = end - self._start, end
            if size > self.max_message_size:
                raise self._fail(self._too_large(), decoded)
            self._count += 1
            try:
                decoded.append(self._to_message(obj))
            except WireError as exc:
                exc.decoded = decoded
                raise

    def _fail(self, message: str, decoded: list[Message]) -> WireError:
        self._broken = message
        error = WireError(message, recoverable=False)
        error.decoded = decoded
        return error

    def _to_message(self, obj: object) -> Message:
        n = self._count
        if not isinstance(obj, list):
            raise WireError(
                f"control message {n}: expected an array [type, ...], got {_type_name(obj)}",
                recoverable=True,
            )
        kind = obj[0] if obj else None
        # An int check first: `in` hashes the value, and a list or map type is unhashable.
        if isinstance(kind, bool) or not isinstance(kind, int) or kind not in _SHAPES:
            raise WireError(
                f"control message {n}: unknown message type {kind!r} "
                "(0 request, 1 response, 2 notification)",
                recoverable=True,
            )
        msgid = obj[1] if kind == REQUEST and len(obj) > 1 else None
        if not isinstance(msgid, int) or isinstance(msgid, bool) or not 0 <= msgid <= MSGID_MAX:
            msgid = None

        def wrong(what: str) -> WireError:
            return WireError(
                f"control message {n}: expected {_SHAPES[kind]}, {what}",
                recoverable=True,
                msgid=msgid,
            )

        expected_length = 3 if kind == NOTIFICATION else 4
        if len(obj) != expected_length:
            raise wrong(f"got an array of {len(obj)}")
        problem = _plain_data_problem(obj, "message")
        if problem is not None:
            raise wrong(f"but {problem}")
        if kind == REQUEST:
            _, raw_id, method, params = obj
            if msgid is None:
                raise wrong(f"got msgid {raw_id!r} (must be an int in 0..{MSGID_MAX})")
            self._check_call(method, params, wrong)
            return Request(msgid, method, params)
        if kind == RESPONSE:
            _, raw_id, error, result = obj
            if raw_id is not None and (
                not isinstance(raw_id, int)
                or isinstance(raw_id, bool)
                or not 0 <= raw_id <= MSGID_MAX
            ):
                raise wrong(f"got msgid {raw_id!r}")
            if error is not None and not isinstance(error, str):
                raise wrong(f"got {_type_name(error)} error (must be a string or nil)")
            return Response(raw_id, error, result)
        _, method, params = obj
        self._check_call(method, params, wrong)
        return Notification(method, params)

    @staticmethod
    def _check_call(method: object, params: object, wrong: Callable[[str], WireError]) -> None:
        if not isinstance(method, str):
            raise wrong(f"got {_type_name(method)} method (must be a string)")
        if not isinstance(params, dict):
            raise wrong(f"got {_type_name(params)} params (must be a map)")


# -- single values (the channel bus: docs/channels.md) ------------------------------------

MAX_DATA_SIZE = 1024 * 1024
"""Largest single encoded value `unpack_data` accepts (a channel state message is 2-4 KB)."""


def pack_data(value: object) -> bytes:
    """One plain-data value (as the RPC's params: nil, bool, int, float, str, bytes, list,
    str-keyed map) as one msgpack object. Raises WireError naming what cannot be sent."""
    problem = _plain_data_problem(value, "value")
    if problem is not None:
        raise WireError(problem, recoverable=True)
    packed: bytes = msgpack.packb(value, use_bin_type=True, default=_refuse)
    return packed


def unpack_data(data: bytes, max_size: int = MAX_DATA_SIZE) -> object:
    """The one msgpack object that is all of `data`. Raises WireError (a one-line reason) for
    anything else: too large, not msgpack, truncated, trailing bytes, extension types or map
    keys that are not strings."""
    if len(data) > max_size:
        raise WireError(f"{len(data)} bytes exceed the {max_size}-byte limit", recoverable=True)
    try:
        value = msgpack.unpackb(
            data,
            raw=False,
            strict_map_key=True,
            use_list=True,
            max_str_len=max_size,
            max_bin_len=max_size,
            max_array_len=max_size,
            max_map_len=max_size // 2,
            ext_hook=lambda code, _data: _refuse(msgpack.ExtType(code, b"")),
        )
    except msgpack.ExtraData:
        raise WireError("trailing bytes after one msgpack value", recoverable=True) from None
    except (ValueError, TypeError, msgpack.UnpackException, ProtocolError) as exc:
        reason = str(exc) or type(exc).__name__
        raise WireError(f"not one msgpack value: {reason}", recoverable=True) from None
    problem = _plain_data_problem(value, "value")
    if problem is not None:
        raise WireError(problem, recoverable=True)
    return value
