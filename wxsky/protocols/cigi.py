"""CIGI 3.3 datagrams decoded into packets and packets encoded into datagrams, both driven by
the table in `cigi_packets`.

A datagram (one UDP payload) is a run of packets, each `u8 opcode, u8 size, ...`. Its first
packet must be IG Control (host → IG) or Start of Frame (IG → host), major version 3, carrying
the magic 0x8000 at bytes 6-7: read as 80 00 the sender is big-endian, as 00 80 little-endian,
and that order holds for the whole datagram. A datagram whose first packet fails this is
refused. After it, each packet stands alone: one that is malformed, not finite or out of range
is dropped and counted by reason, and decoding goes on with the next by the size byte; an
unknown opcode is skipped the same way. Only a size byte that cannot advance (0 or 1) or one
running past the end stops the datagram. `decode_datagram` never raises.

Every `Packet` holds values the table accepts, normalised (angles wrapped, f32 fields at f32
precision), so `decode_datagram(encode_datagram(p)).packets == p` in either byte order.
Pure: the UDP socket lives in `wxsky.inputs`.
"""

from __future__ import annotations

import math
import struct
from collections import Counter
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Literal, NamedTuple

from wxsky.protocols.cigi_fields import (
    BYTE_SWAP_MAGIC,
    DIRECTION_TEXT,
    HEADER_SIZE,
    MAJOR_VERSION,
    STRUCT_CODES,
    WRAP_ACCEPT_DEG,
    Direction,
    Field,
    PacketSpec,
    range_text,
)
from wxsky.protocols.cigi_packets import BY_KEY, BY_OPCODE, PACKETS, START_PACKETS

ByteOrder = Literal["big", "little"]
Value = int | float

F32_MAX = struct.unpack(">f", b"\x7f\x7f\xff\xff")[0]
TICKS_PER_S = 100_000  # CIGI timestamps count 10 µs
MAX_PROBLEMS = 16  # messages kept per datagram; the counts cover every problem

# Reason name -> what happens to the bytes. The names are status counters: keep them stable.
REASONS: Mapping[str, str] = MappingProxyType(
    {
        "truncated": "fewer bytes than a packet's size byte claims: stops the datagram "
        "(refuses it when the first packet is short)",
        "bad_first_packet": "the first packet is not IG Control or Start of Frame: refused",
        "wrong_version": "the first packet's major version is not 3: refused",
        "bad_magic": "the first packet's bytes 6-7 are neither 80 00 nor 00 80: refused",
        "size_mismatch": "a known opcode with another size byte: skipped by the size byte "
        "(refuses the datagram when the first packet is not 24 bytes, e.g. CIGI 3.0/3.1)",
        "zero_size": "a size byte of 0 or 1 cannot advance: stops the datagram",
        "unknown_opcode": "a packet wxsky does not read: skipped by its size byte",
        "misplaced": "IG Control or Start of Frame after the first packet: dropped",
        "wrong_direction": "an IG→host packet in a host→IG datagram or the reverse: dropped",
        "not_finite": "a NaN or infinite float: the packet is dropped",
        "out_of_range": "a value outside the table's range: the packet is dropped",
    }
)


class _Bad(Exception):
    """Internal: why one field's value cannot stand (caught, never escapes the module)."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(detail)
        self.reason = reason
        self.detail = detail


def _f32(x: float) -> float:
    return float(struct.unpack("<f", struct.pack("<f", x))[0])


def _wrapped(f: Field, x: float) -> float:
    lo = f.lo if f.lo is not None else 0.0
    if not -WRAP_ACCEPT_DEG <= x <= WRAP_ACCEPT_DEG:
        raise _Bad("out_of_range", f"{f.name} {x:g} is outside ±{WRAP_ACCEPT_DEG:g}")
    w = _f32(lo + (x - lo) % 360.0)
    # Rounding to f32 can land on the excluded end of [lo, lo + 360).
    return lo if w >= lo + 360.0 else w


def _converted(f: Field, raw: object) -> Value:
    """A field's value in its stored form: typed, finite, f32 precision, angles wrapped."""
    if f.is_float:
        if not isinstance(raw, int | float) or isinstance(raw, bool):
            raise _Bad("out_of_range", f"{f.name} is {type(raw).__name__}, not a number")
        x = float(raw)
        if not math.isfinite(x):
            raise _Bad("not_finite", f"{f.name} is {x}")
        if f.wrap:
            return _wrapped(f, x)
        if f.kind == "f32":
            if abs(x) > F32_MAX:
                raise _Bad("out_of_range", f"{f.name} {x:g} does not fit an f32")
            return _f32(x)
        return x
    if not isinstance(raw, int):
        raise _Bad("out_of_range", f"{f.name} is {type(raw).__name__}, not an integer")
    lo, hi = f.int_limits()
    if not lo <= raw <= hi:
        raise _Bad("out_of_range", f"{f.name} {raw} does not fit {f.kind} ({lo}..{hi})")
    return int(raw)


def _outside(f: Field, low: bool) -> str:
    if f.lo is not None and f.hi is not None:
        return f"is outside {range_text(f)}"
    return f"is below {f.lo:g}" if low else f"is above {f.hi:g}"


def _checked(spec: PacketSpec, raw: Mapping[str, object]) -> tuple[Value, ...]:
    """The packet's stored values from raw ones, or `_Bad` naming the first field wrong."""
    return _ranged(spec, {f.name: _converted(f, raw[f.name]) for f in spec.value_fields})


def _ranged(spec: PacketSpec, values: Mapping[str, Value]) -> tuple[Value, ...]:
    """`values` (already typed and rounded) as a tuple once each is within its field's range
    and rule, or `_Bad` naming the first that is not."""
    for f in spec.value_fields:
        if f.when is not None and values[f.when[0]] != f.when[1]:
            continue
        v = values[f.name]
        low = f.lo is not None and v < f.lo
        high = f.hi is not None and (v >= f.hi if f.wrap else v > f.hi)
        if low or high:
            raise _Bad("out_of_range", f"{f.name} {v:g} {_outside(f, low)}")
        if f.rule is not None and (why := f.rule(int(v))):
            raise _Bad("out_of_range", f"{f.name} {why}")
    return tuple(values.values())


@dataclass(frozen=True, repr=False)
class Packet:
    """One packet: its opcode and its values in the order of its table entry's value fields
    (constants such as the version and the magic are not values). Always valid: build one
    with `make` or get it from `decode_datagram`; constructing it checks the values."""

    opcode: int
    values: tuple[Value, ...]

    def __post_init__(self) -> None:
        spec = BY_OPCODE.get(self.opcode)
        if spec is None:
            raise ValueError(f"CIGI opcode {self.opcode} is not in the packet table")
        if len(self.values) != len(spec.value_fields):
            raise ValueError(f"{spec.name} has {len(spec.value_fields)} values")
        try:
            normal = _checked(spec, dict(zip(spec.index, self.values, strict=True)))
        except _Bad as bad:
            raise ValueError(f"{spec.name}: {bad.detail}") from None
        if normal != self.values or any(
            type(a) is not type(b) for a, b in zip(normal, self.values, strict=True)
        ):
            raise ValueError(f"{spec.name}: values not normalised; build it with cigi.make")

    @property
    def spec(self) -> PacketSpec:
        return BY_OPCODE[self.opcode]

    @property
    def key(self) -> str:
        return self.spec.key

    def __getitem__(self, name: str) -> Value:
        return self.values[self.spec.index[name]]

    def as_dict(self) -> dict[str, Value]:
        return dict(zip(self.spec.index, self.values, strict=True))

    def __repr__(self) -> str:
        fields = ", ".join(f"{k}={v!r}" for k, v in self.as_dict().items())
        return f"Packet({self.key}, {fields})"


def timestamp_10us(seconds: float) -> int:
    """A CIGI timestamp (IG Control, Start of Frame): 10 µs ticks, wrapping at 2**32."""
    return int(seconds * TICKS_PER_S) & 0xFFFF_FFFF


def make(key: str, **values: Value) -> Packet:
    """A packet from its table key and the values it sets; the rest take their defaults
    (0, and minor version 3). Raises ValueError naming the field for a bad value."""
    spec = BY_KEY.get(key)
    if spec is None:
        raise ValueError(f"no CIGI packet {key!r}; known: {', '.join(BY_KEY)}")
    unknown = set(values) - set(spec.index)
    if unknown:
        raise ValueError(f"{spec.name} has no field {', '.join(sorted(unknown))}")
    raw = {f.name: values.get(f.name, f.default) for f in spec.value_fields}
    try:
        checked = _checked(spec, raw)
    except _Bad as bad:
        raise ValueError(f"{spec.name}: {bad.detail}") from None
    return _trusted(spec.opcode, checked)


def _trusted(opcode: int, checked: tuple[Value, ...]) -> Packet:
    """A packet of values `_checked` just made: `__post_init__`'s second check skipped (a
    third of an answer's cost, half a datagram's decoding: issue 40)."""
    packet = object.__new__(Packet)
    object.__setattr__(packet, "opcode", opcode)
    object.__setattr__(packet, "values", checked)
    return packet


# --- layout: one struct per packet and byte order, from the table -----------------------------


@dataclass(frozen=True)
class _Layout:
    structs: Mapping[str, struct.Struct]  # byte order -> header and slots, reserved as pad
    slot_of: tuple[int, ...]  # per spec field, its slot (bit fields of one byte share one)
    slot_count: int  # slots 0 and 1 are the header
    reads: tuple[_Read, ...]  # how to read each value field from the slots, in order


class _Read(NamedTuple):
    """One value field as decoding reads it: its slot, its bits, and what wire values need
    checking (a struct's integers always fit their type; its f32s are already f32)."""

    name: str
    slot: int
    bit: int
    mask: int | None  # bit fields: the width's mask
    is_float: bool
    wrap: Field | None  # angles: the field, to wrap into its range


_LAYOUTS: dict[int, _Layout] = {}


def _layout(spec: PacketSpec) -> _Layout:
    # Keyed by opcode, not by the spec: hashing a frozen spec hashes every field, a fifth
    # of a 64 KB datagram's decoding (issue 40).
    layout = _LAYOUTS.get(spec.opcode)
    if layout is None:
        layout = _LAYOUTS[spec.opcode] = _make_layout(spec)
    return layout


def _make_layout(spec: PacketSpec) -> _Layout:
    slots: dict[int, str] = {0: "B", 1: "B"}  # the header
    for f in spec.fields:
        slots[f.offset] = STRUCT_CODES[f.kind]
    fmt, at = "", 0
    for offset in sorted(slots):
        fmt += "x" * (offset - at) + slots[offset]
        at = offset + struct.calcsize("<" + slots[offset])
    fmt += "x" * (spec.size - at)
    order = sorted(slots)
    reads = tuple(
        _Read(
            f.name,
            order.index(f.offset),
            f.bit,
            (1 << f.width) - 1 if f.kind == "bits" else None,
            f.is_float,
            f if f.wrap else None,
        )
        for f in spec.fields
        if f.fixed is None
    )
    return _Layout(
        MappingProxyType({"big": struct.Struct(">" + fmt), "little": struct.Struct("<" + fmt)}),
        tuple(order.index(f.offset) for f in spec.fields),
        len(order),
        reads,
    )


def encode_packet(packet: Packet, byte_order: ByteOrder = "big") -> bytes:
    """One packet's bytes, reserved bytes zero. No message rules: see `encode_datagram`."""
    spec = packet.spec
    layout = _layout(spec)
    slots: list[Value] = [0] * layout.slot_count
    slots[0], slots[1] = spec.opcode, spec.size
    values = packet.as_dict()
    for f, slot in zip(spec.fields, layout.slot_of, strict=True):
        v = f.fixed if f.fixed is not None else values[f.name]
        if f.kind == "bits":
            slots[slot] = int(slots[slot]) | (int(v) << f.bit)
        else:
            slots[slot] = v
    return layout.structs[byte_order].pack(*slots)


def encode_datagram(packets: Iterable[Packet], byte_order: ByteOrder = "big") -> bytes:
    """A message: IG Control or Start of Frame first, then packets of the same direction.
    Raises ValueError for a message a receiver would refuse or drop parts of."""
    items = list(packets)
    if not items or not items[0].spec.starts_message:
        raise ValueError("a CIGI message starts with IG Control or Start of Frame")
    direction = items[0].spec.direction
    for i, p in enumerate(items[1:], 1):
        if p.spec.starts_message or p.spec.direction != direction:
            raise ValueError(f"packet {i}, {p.spec.name}, does not belong in this message")
    return b"".join(encode_packet(p, byte_order) for p in items)


# --- decoding ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Problem:
    reason: str  # a key of REASONS
    offset: int  # byte offset in the datagram of the packet (or byte) at fault
    message: str  # one line: what and where


@dataclass(frozen=True)
class CigiDatagram:
    """What one datagram came to: `byte_order` None when it was refused whole."""

    byte_order: ByteOrder | None
    direction: Direction | None
    packets: tuple[Packet, ...]
    counts: Mapping[str, int]  # reason -> how many times, every problem
    problems: tuple[Problem, ...]  # the first MAX_PROBLEMS, in datagram order

    @property
    def refused(self) -> bool:
        return self.byte_order is None


class _Collector:
    def __init__(self) -> None:
        self.counts: Counter[str] = Counter()
        self.problems: list[Problem] = []

    def add(self, reason: str, offset: int, message: str) -> None:
        self.counts[reason] += 1
        if len(self.problems) < MAX_PROBLEMS:
            self.problems.append(Problem(reason, offset, message))

    def result(
        self,
        order: ByteOrder | None,
        direction: Direction | None,
        packets: Iterable[Packet] = (),
    ) -> CigiDatagram:
        return CigiDatagram(
            order,
            direction,
            tuple(packets),
            MappingProxyType(dict(self.counts)),
            tuple(self.problems),
        )


_STARTS = " or ".join(f"{p.name} ({p.opcode})" for p in START_PACKETS.values())


def _looks_like_v4(data: bytes) -> bool:
    # v4 leads with u16 size 24 and u16 id 0x0000 (IG Control) or 0xFFFF (Start of Frame),
    # in either byte order, then the major version.
    return len(data) >= 5 and data[:2] in (b"\x00\x18", b"\x18\x00") and data[4] == 4


def _start(data: bytes, out: _Collector) -> tuple[ByteOrder, PacketSpec] | None:
    """The byte order and first packet of a datagram, or None with the refusal recorded."""
    if len(data) < 3:
        out.add("truncated", 0, f"datagram of {len(data)} bytes: no CIGI packet header")
        return None
    if _looks_like_v4(data):
        out.add("wrong_version", 0, "datagram: CIGI 4 framing (u16 size, u16 id), wxsky reads 3.3")
        return None
    spec = BY_OPCODE.get(data[0])
    if spec is None or not spec.starts_message:
        name = spec.name if spec is not None else "unknown"
        out.add(
            "bad_first_packet",
            0,
            f"datagram: first packet opcode {data[0]} ({name}) at byte 0, not {_STARTS}",
        )
        return None
    if data[2] != MAJOR_VERSION:
        out.add(
            "wrong_version",
            2,
            f"{spec.name} at byte 0: CIGI major version {data[2]}, wxsky reads {MAJOR_VERSION}",
        )
        return None
    if data[1] != spec.size:
        out.add(
            "size_mismatch",
            1,
            f"{spec.name} at byte 0: size byte {data[1]}, CIGI 3.3 sends {spec.size}",
        )
        return None
    if len(data) < spec.size:
        out.add("truncated", 0, f"{spec.name} at byte 0 claims {spec.size} bytes, {len(data)} sent")
        return None
    magic = data[6:8]
    if magic == BYTE_SWAP_MAGIC.to_bytes(2, "big"):
        return "big", spec
    if magic == BYTE_SWAP_MAGIC.to_bytes(2, "little"):
        return "little", spec
    out.add("bad_magic", 6, f"{spec.name} at byte 0: byte-swap magic {magic.hex(' ')}")
    return None


def _unpack(spec: PacketSpec, data: bytes, pos: int, order: ByteOrder) -> tuple[Value, ...]:
    """The packet's values from the wire: what `_checked` would make of them, without its
    type and width checks, which a struct's output always passes (a 64 KB datagram of
    conditions requests decodes in a third of the time: issue 40)."""
    layout = _layout(spec)
    slots = layout.structs[order].unpack_from(data, pos)
    values: dict[str, Value] = {}
    for r in layout.reads:
        v = slots[r.slot]
        if r.mask is not None:
            v = (v >> r.bit) & r.mask
        elif r.is_float:
            if not math.isfinite(v):
                raise _Bad("not_finite", f"{r.name} is {v}")
            if r.wrap is not None:
                v = _wrapped(r.wrap, v)
        values[r.name] = v
    return _ranged(spec, values)


def decode_datagram(data: bytes | bytearray | memoryview) -> CigiDatagram:
    """Every packet of one datagram that the table accepts, and why the rest were not."""
    buf = bytes(data)
    out = _Collector()
    start = _start(buf, out)
    if start is None:
        return out.result(None, None)
    order, first = start
    direction = first.direction
    packets: list[Packet] = []
    pos = 0
    while pos < len(buf):
        left = len(buf) - pos
        if left < HEADER_SIZE:
            out.add("truncated", pos, f"packet header at byte {pos}: 1 byte left, 2 needed")
            break
        opcode, size = buf[pos], buf[pos + 1]
        spec = BY_OPCODE.get(opcode)
        if (
            spec is not None
            and size == spec.size
            and size <= left
            and not (spec.starts_message and pos > 0)
            and spec.direction == direction
        ):  # the usual packet, before any problem text is made
            try:
                packets.append(_trusted(opcode, _unpack(spec, buf, pos, order)))
            except _Bad as bad:
                what = f"{spec.name} at byte {pos}"
                out.add(bad.reason, pos, f"{what}: {_at(spec, pos, bad.detail)}")
            pos += size
            continue
        what = f"{spec.name if spec else f'opcode {opcode}'} at byte {pos}"
        if size < HEADER_SIZE:
            out.add("zero_size", pos, f"{what}: size byte {size}; {left} bytes not read")
            break
        if size > left:
            out.add("truncated", pos, f"{what} claims {size} bytes, {left} left")
            break
        if spec is None:
            out.add("unknown_opcode", pos, f"{what}: not read by wxsky, {size} bytes skipped")
        elif size != spec.size:
            out.add(
                "size_mismatch",
                pos,
                f"{what}: size byte {size}, CIGI 3.3 sends {spec.size}; {size} bytes skipped",
            )
        elif spec.starts_message and pos > 0:
            out.add("misplaced", pos, f"{what}: only the first packet may be a {spec.name}")
        elif spec.direction != direction:
            out.add(
                "wrong_direction",
                pos,
                f"{what}: {DIRECTION_TEXT[spec.direction]} packet in a "
                f"{DIRECTION_TEXT[direction]} message",
            )
        else:
            try:
                packets.append(_trusted(opcode, _unpack(spec, buf, pos, order)))
            except _Bad as bad:
                out.add(bad.reason, pos, f"{what}: {_at(spec, pos, bad.detail)}")
        pos += size
    return out.result(order, direction, packets)


def _at(spec: PacketSpec, pos: int, detail: str) -> str:
    """`detail` with its field's byte offset in the datagram: "coverage_pct (byte 44) …"."""
    name = detail.split(" ", 1)[0]
    for f in spec.fields:
        if f.name == name:
            return f"{name} (byte {pos + f.offset}){detail[len(name) :]}"
    return detail


def reasons_markdown() -> str:
    """The reasons table for docs/cigi.md, generated so the doc cannot drift."""
    rows = ["| Reason | What it means, what happens |", "|---|---|"]
    rows += [f"| `{name}` | {text} |" for name, text in REASONS.items()]
    return "\n".join(rows) + "\n"


__all__ = [
    "MAX_PROBLEMS",
    "PACKETS",
    "REASONS",
    "ByteOrder",
    "CigiDatagram",
    "Packet",
    "Problem",
    "Value",
    "decode_datagram",
    "encode_datagram",
    "encode_packet",
    "make",
    "reasons_markdown",
    "timestamp_10us",
]
