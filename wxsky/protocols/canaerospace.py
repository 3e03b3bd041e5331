"""CANaerospace (v1.7) frames from cockpit hardware decoded into weather values, and the
encoder emulators use to make them.

A frame's data field is a 4-byte header -- node id, data type, service code, message code --
then the big-endian value, so its length must be 4 + the size of the data type. Numeric ids
take FLOAT, SHORT2 or LONG; time (1200) and date (1206) take CHAR4. The ids and their units
are in `canaerospace_ids.IDS`.

Ignored (counted, not an error): ids wxsky does not use -- a bus carries other avionics --
extended ids, remote frames, and frames from nodes outside the decoder's filter. Rejected:
everything malformed or out of range; the reason is one line naming the id. Pure: the link
in `wxsky.inputs` owns the bus.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from datetime import UTC, date, datetime
from types import MappingProxyType

from wxsky.protocols.canaerospace_ids import (
    BY_ID,
    BY_KEY,
    DATA_TYPE_SIZES,
    DATE_CHAR4,
    IDS,
    MAX_STANDARD_ID,
    SERVICE_LAYER,
    SERVICE_ZERO,
    UTC_CHAR4,
    CanasId,
    Char4,
    Char4Field,
    DataType,
    table_markdown,
)
from wxsky.protocols.result import Decoded
from wxsky.weather.cockpit import COCKPIT_LAYERS, WIND_DIR, CockpitUpdate, checked

__all__ = [
    "BY_ID",
    "DATA_TYPE_SIZES",
    "HEADER_SIZE",
    "IDS",
    "CanasDecoder",
    "CanasHeader",
    "CanasId",
    "Char4",
    "Char4Field",
    "DataType",
    "decode_header",
    "encode_date",
    "encode_float",
    "encode_layer",
    "encode_long",
    "encode_raw",
    "encode_short2",
    "encode_time",
    "encode_utc",
    "encode_wind",
    "frames_for_update",
    "table_markdown",
]

HEADER_SIZE = 4
UTC_ID = 1200
DATE_ID = 1206
SHORT2_FULL_SCALE_RAW = 32767  # value = raw / (32767 / scale), §5

Bytes = bytes | bytearray | memoryview  # python-can hands over a bytearray


@dataclass(frozen=True)
class CanasHeader:
    node_id: int
    data_type: int
    service_code: int
    message_code: int


def decode_header(data: Bytes) -> CanasHeader:
    """The header of a frame's data field; raises ValueError when it is shorter than 4 bytes."""
    if len(data) < HEADER_SIZE:
        raise ValueError(f"DLC {len(data)}, shorter than the {HEADER_SIZE}-byte header")
    node_id, data_type, service_code, message_code = bytes(data[:HEADER_SIZE])
    return CanasHeader(node_id, data_type, service_code, message_code)


class _Rejected(Exception):
    """A frame for one of wxsky's ids that must not reach the weather; args[0] is why."""


def _short2(payload: bytes) -> float:
    raw, scale = struct.unpack(">hh", payload)
    if scale == 0:
        raise _Rejected(f"SHORT2 scale 0 (raw {raw})")
    return float(raw / (SHORT2_FULL_SCALE_RAW / scale))


# The wire value of each numeric data type; each payload has been checked for its size.
_NUMBER_READERS: Mapping[int, Callable[[bytes], float]] = MappingProxyType(
    {
        DataType.FLOAT: lambda payload: float(struct.unpack(">f", payload)[0]),
        DataType.SHORT2: _short2,
        DataType.LONG: lambda payload: float(struct.unpack(">i", payload)[0]),
    }
)


def _type_name(code: int) -> str:
    try:
        return f"{DataType(code).name} ({code})"
    except ValueError:
        return f"{code}"


class CanasDecoder:
    """Decodes one frame at a time; keeps no state beyond the node filter."""

    def __init__(self, node_ids: frozenset[int] = frozenset()) -> None:
        bad = sorted(n for n in node_ids if not 0 <= n <= 255)
        if bad:
            raise ValueError(f"CANaerospace node ids are 0..255, got {bad}")
        self.node_ids = node_ids  # empty: every node

    def decode(
        self,
        can_id: int,
        data: Bytes,
        *,
        is_extended: bool = False,
        is_remote: bool = False,
        is_error: bool = False,
    ) -> Decoded:
        if is_error:
            return Decoded.reject("CAN error frame")
        if is_extended:
            return Decoded.ignore(f"extended CAN id 0x{can_id:08x} not used by wxsky")
        if not 0 <= can_id <= MAX_STANDARD_ID:
            return Decoded.reject(f"CAN id {can_id:#x} is not an 11-bit identifier")
        entry = BY_ID.get(can_id)
        if entry is None:
            return Decoded.ignore(f"CAN id 0x{can_id:03x} not used by wxsky")
        if is_remote:
            return Decoded.ignore(f"CAN {can_id} {entry.name}: remote frame")
        try:
            header = decode_header(data)
        except ValueError as exc:
            return Decoded.reject(f"CAN {can_id} {entry.name}: {exc}")
        if self.node_ids and header.node_id not in self.node_ids:
            wanted = ", ".join(str(n) for n in sorted(self.node_ids))
            return Decoded.ignore(
                f"CAN {can_id} {entry.name} from node {header.node_id}, not one of {wanted}"
            )
        try:
            return Decoded(update=_update(entry, header, bytes(data[HEADER_SIZE:])))
        except _Rejected as exc:
            return Decoded.reject(f"CAN {can_id} {entry.name}: {exc.args[0]}")


def _update(entry: CanasId, header: CanasHeader, payload: bytes) -> CockpitUpdate:
    if header.data_type not in entry.data_types:
        *others, last = (t.name for t in entry.data_types)
        allowed = f"{', '.join(others)} or {last}" if others else last
        raise _Rejected(f"data type {_type_name(header.data_type)} not allowed, expected {allowed}")
    size = DATA_TYPE_SIZES[header.data_type]
    if len(payload) != size:
        raise _Rejected(
            f"DLC {HEADER_SIZE + len(payload)}, expected {HEADER_SIZE + size} "
            f"for {DataType(header.data_type).name}"
        )
    if entry.char4 is not None:
        return _char4_update(entry.char4, payload)
    layer = _layer(entry, header.service_code)
    wire = _NUMBER_READERS[header.data_type](payload)
    return CockpitUpdate(values={entry.cockpit_key(layer): _checked_wire(entry, layer, wire)})


def _layer(entry: CanasId, service_code: int) -> int:
    if entry.layered:
        if not 1 <= service_code <= COCKPIT_LAYERS:
            raise _Rejected(f"layer {service_code} out of range 1..{COCKPIT_LAYERS}")
        return service_code
    if entry.service_code == SERVICE_ZERO and service_code != 0:
        raise _Rejected(f"service code {service_code}, expected 0")
    return 1


def _checked_wire(entry: CanasId, layer: int, wire: float) -> float:
    if not math.isfinite(wire):
        raise _Rejected(f"{wire} is not a finite number")
    try:
        return checked(entry.cockpit_key(layer), entry.to_si(wire))
    except ValueError as exc:
        lo, hi = entry.wire_limits()
        if not lo <= wire <= hi:
            raise _Rejected(f"{wire:.7g} {entry.unit} out of range {lo:.10g}..{hi:.10g}") from None
        raise _Rejected(str(exc)) from None  # in range yet refused: a thickness of 0


def _char4_update(spec: Char4, payload: bytes) -> CockpitUpdate:
    values = struct.unpack(">4b", payload)
    for field, value in zip(spec.fields, values, strict=True):
        if not field.lo <= value <= field.hi:
            raise _Rejected(f"{field.name} {value} out of range {field.lo}..{field.hi}")
    try:
        return spec.read(*values)
    except ValueError as exc:
        raise _Rejected(str(exc)) from None


# -- encoding (emulators, tests) ----------------------------------------------------------


def encode_raw(
    can_id: int,
    data_type: int,
    payload: bytes,
    *,
    node_id: int = 1,
    service_code: int = 0,
    message_code: int = 0,
) -> bytes:
    """A frame's data field: header then `payload` as given. Neither the payload's size nor the
    data type is checked against the id, so an emulator can send what a faulty node would."""
    return _frame(can_id, data_type, payload, node_id, service_code, message_code)


def _frame(
    can_id: int,
    data_type: int,
    payload: bytes,
    node_id: int,
    service_code: int,
    message_code: int,
) -> bytes:
    if not 0 <= can_id <= MAX_STANDARD_ID:
        raise ValueError(f"CAN id {can_id} is not an 11-bit identifier")
    for name, byte in (
        ("node_id", node_id),
        ("data_type", data_type),
        ("service_code", service_code),
        ("message_code", message_code),
    ):
        if not 0 <= byte <= 255:
            raise ValueError(f"{name} {byte} does not fit in a byte")
    return bytes((node_id, data_type, service_code, message_code)) + bytes(payload)


def encode_float(
    can_id: int,
    value: float,
    *,
    node_id: int = 1,
    service_code: int = 0,
    message_code: int = 0,
) -> bytes:
    """A FLOAT frame for `value` in wire units (NaN and infinities pass, to test receivers)."""
    try:
        payload = struct.pack(">f", value)
    except (OverflowError, struct.error) as exc:
        raise ValueError(f"{value!r} does not fit a FLOAT: {exc}") from None
    return _frame(can_id, DataType.FLOAT, payload, node_id, service_code, message_code)


def encode_short2(
    can_id: int,
    value: float,
    scale: int,
    *,
    node_id: int = 1,
    service_code: int = 0,
    message_code: int = 0,
) -> bytes:
    """A SHORT2 frame: `value` as raw = value * 32767 / scale, rounded, with `scale` after it."""
    if scale == 0 or not -32768 <= scale <= 32767:
        raise ValueError(f"SHORT2 scale {scale} must be a non-zero 16-bit integer")
    if not math.isfinite(value):
        raise ValueError(f"SHORT2 cannot carry {value}")
    raw = round(value * SHORT2_FULL_SCALE_RAW / scale)
    if not -32768 <= raw <= 32767:
        raise ValueError(f"{value!r} is beyond SHORT2 full scale {scale}")
    return _frame(
        can_id, DataType.SHORT2, struct.pack(">hh", raw, scale), node_id, service_code, message_code
    )


def encode_long(
    can_id: int,
    value: int,
    *,
    node_id: int = 1,
    service_code: int = 0,
    message_code: int = 0,
) -> bytes:
    if not -(2**31) <= value < 2**31:
        raise ValueError(f"{value} does not fit a LONG")
    return _frame(
        can_id, DataType.LONG, struct.pack(">i", value), node_id, service_code, message_code
    )


def _encode_char4(
    can_id: int, values: tuple[int, int, int, int], node_id: int, message_code: int
) -> bytes:
    try:
        payload = struct.pack(">4b", *values)
    except struct.error:
        raise ValueError(f"CHAR4 bytes {values} are not all -128..127") from None
    return _frame(can_id, DataType.CHAR4, payload, node_id, 0, message_code)


def encode_time(
    hour: int, minute: int, second: int, *, node_id: int = 1, message_code: int = 0
) -> bytes:
    """A 1200 (UTC) frame. Values are not range-checked, so emulators can send bad times."""
    return _encode_char4(UTC_ID, (hour, minute, second, 0), node_id, message_code)


def encode_date(d: date, *, node_id: int = 1, message_code: int = 0) -> bytes:
    """A 1206 (date) frame: day, month, century, year."""
    century, year = divmod(d.year, 100)
    return _encode_char4(DATE_ID, (d.day, d.month, century, year), node_id, message_code)


def encode_utc(
    when: datetime, *, node_id: int = 1, message_code: int = 0
) -> list[tuple[int, bytes]]:
    """The 1200 and 1206 frames for an aware datetime (whole seconds: 1200 carries no more)."""
    if when.tzinfo is None:
        raise ValueError("encode_utc needs a timezone-aware datetime")
    utc = when.astimezone(UTC)
    return [
        (
            UTC_ID,
            encode_time(
                utc.hour, utc.minute, utc.second, node_id=node_id, message_code=message_code
            ),
        ),
        (DATE_ID, encode_date(utc.date(), node_id=node_id, message_code=message_code)),
    ]


def _signed_deg(dir_deg: float) -> float:
    """A direction as the standard sends it, ±180."""
    return dir_deg - 360.0 if dir_deg > 180.0 else dir_deg


def _encode_si(
    entry: CanasId, si_value: float, layer: int, node_id: int, message_code: int
) -> tuple[int, bytes]:
    wire = entry.from_si(si_value)
    if entry.key == WIND_DIR:
        wire = _signed_deg(wire)
    service_code = layer if entry.service_code == SERVICE_LAYER else 0
    frame = encode_float(
        entry.can_id, wire, node_id=node_id, service_code=service_code, message_code=message_code
    )
    return entry.can_id, frame


def encode_wind(
    speed_mps: float, dir_from_deg: float, *, node_id: int = 1, message_code: int = 0
) -> list[tuple[int, bytes]]:
    """333 and 334 FLOAT frames; the direction goes out as ±180, as the standard has it."""
    return [
        _encode_si(BY_ID[333], speed_mps, 1, node_id, message_code),
        _encode_si(BY_ID[334], dir_from_deg, 1, node_id, message_code),
    ]


def encode_layer(
    layer: int,
    *,
    cover_oktas: float | None = None,
    base_m: float | None = None,
    thickness_m: float | None = None,
    node_id: int = 1,
    message_code: int = 0,
) -> list[tuple[int, bytes]]:
    """1500-1502 FLOAT frames for the parts of cockpit layer `layer` that are given."""
    if not 1 <= layer <= COCKPIT_LAYERS:
        raise ValueError(f"layer {layer} out of range 1..{COCKPIT_LAYERS}")
    parts = ((1500, cover_oktas), (1501, base_m), (1502, thickness_m))
    return [
        _encode_si(BY_ID[can_id], value, layer, node_id, message_code)
        for can_id, value in parts
        if value is not None
    ]


def frames_for_update(
    update: CockpitUpdate, *, node_id: int = 1, message_code: int = 0
) -> list[tuple[int, bytes]]:
    """(id, data) frames that decode back to `update` (values as FLOAT, time to the whole
    second). Raises ValueError for what no id carries: dewpoint, cloud type, position."""
    if update.position_deg is not None:
        raise ValueError("no CANaerospace id in wxsky's table carries a position")
    frames: list[tuple[int, bytes]] = []
    for key, value in update.values.items():
        layer, part = 1, key
        if key.startswith("layer"):  # layerN.part: the layer goes in the service code
            layer_s, _, part = key.partition(".")
            layer = int(layer_s.removeprefix("layer"))
        entry = BY_KEY.get(part)
        if entry is None:
            raise ValueError(f"no CANaerospace id in wxsky's table carries {key}")
        frames.append(_encode_si(entry, float(value), layer, node_id, message_code))
    if update.time_utc is not None:
        frames += encode_utc(update.time_utc, node_id=node_id, message_code=message_code)
    if update.time_of_day_s is not None:
        minutes, second = divmod(int(update.time_of_day_s), 60)
        hour, minute = divmod(minutes, 60)
        frames.append(
            (UTC_ID, encode_time(hour, minute, second, node_id=node_id, message_code=message_code))
        )
    if update.date_utc is not None:
        frames.append(
            (DATE_ID, encode_date(update.date_utc, node_id=node_id, message_code=message_code))
        )
    return frames


assert BY_ID[UTC_ID].char4 is UTC_CHAR4 and BY_ID[DATE_ID].char4 is DATE_CHAR4
