"""The building blocks of the CIGI 3.3 packet table (`cigi_packets.PACKETS`): a packet's
fields with their wire types, ranges and conditions, the checks a table entry must pass, and
how a field's accepted values read in docs and problem messages.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from datetime import date
from functools import cached_property
from types import MappingProxyType
from typing import Literal

from wxsky.weather.state import CLOCK_YEARS, year_in_range

Kind = Literal["u8", "s8", "u16", "u32", "f32", "f64", "bits"]
Direction = Literal["host_to_ig", "ig_to_host"]

KIND_SIZES: Mapping[str, int] = MappingProxyType(
    {"u8": 1, "s8": 1, "u16": 2, "u32": 4, "f32": 4, "f64": 8, "bits": 1}
)
STRUCT_CODES: Mapping[str, str] = MappingProxyType(
    {"u8": "B", "s8": "b", "u16": "H", "u32": "I", "f32": "f", "f64": "d", "bits": "B"}
)
INT_LIMITS: Mapping[str, tuple[int, int]] = MappingProxyType(
    {"u8": (0, 0xFF), "s8": (-0x80, 0x7F), "u16": (0, 0xFFFF), "u32": (0, 0xFFFF_FFFF)}
)
HEADER_SIZE = 2  # u8 packet id, u8 packet size
MAJOR_VERSION = 3
MINOR_VERSION = 3
BYTE_SWAP_MAGIC = 0x8000
# A wrapped angle may arrive anywhere in this band (CCL's Weather Control sends the wind
# direction as -180..180 where the ICD says 0..360; a host with CCL's range checks off, or
# built without CCL, may wrap any angle either way); it is kept normalised into [lo, hi).
WRAP_ACCEPT_DEG = 360.0
DIRECTION_TEXT: Mapping[str, str] = MappingProxyType(
    {"host_to_ig": "host → IG", "ig_to_host": "IG → host"}
)


@dataclass(frozen=True)
class Field:
    """One field of a packet. `bits` fields are `width` bits from bit `bit` (0 = least
    significant) of the byte at `offset`; several share a byte."""

    name: str  # with its unit: coverage_pct, base_elevation_m
    offset: int
    kind: Kind
    lo: float | None = None
    hi: float | None = None
    bit: int = 0
    width: int = 0
    wrap: bool = False  # an angle: accepted in ±WRAP_ACCEPT_DEG, kept in [lo, hi)
    fixed: int | None = None  # a constant the packet must carry; not a value of the packet
    default: int | float = 0
    when: tuple[str, int] | None = None  # lo/hi/rule apply only while that field is this
    rule: Callable[[int], str] | None = None  # a further check: "" or why the value is bad
    rule_text: str = ""  # what `rule` accepts, for the docs
    note: str = ""

    @property
    def is_float(self) -> bool:
        return self.kind in ("f32", "f64")

    def int_limits(self) -> tuple[int, int]:
        """What the wire type itself can hold (integers and bit fields)."""
        if self.kind == "bits":
            return 0, (1 << self.width) - 1
        return INT_LIMITS[self.kind]


@dataclass(frozen=True)
class PacketSpec:
    opcode: int
    key: str  # snake case, for `cigi.make`: "weather_control"
    name: str  # as in the standard and in problem messages: "Weather Control"
    size: int
    direction: Direction
    fields: tuple[Field, ...]
    source: str
    starts_message: bool = False  # IG Control / Start of Frame: first, once, with the magic

    @cached_property
    def value_fields(self) -> tuple[Field, ...]:
        """The fields a decoded packet carries, in table order (constants left out)."""
        return tuple(f for f in self.fields if f.fixed is None)

    @cached_property
    def index(self) -> Mapping[str, int]:
        return MappingProxyType({f.name: i for i, f in enumerate(self.value_fields)})


def _number(kind: Kind) -> Callable[..., Field]:
    def field(
        name: str,
        offset: int,
        lo: float | None = None,
        hi: float | None = None,
        *,
        fixed: int | None = None,
        when: tuple[str, int] | None = None,
        rule: Callable[[int], str] | None = None,
        rule_text: str = "",
        note: str = "",
    ) -> Field:
        return Field(
            name,
            offset,
            kind,
            lo,
            hi,
            fixed=fixed,
            when=when,
            rule=rule,
            rule_text=rule_text,
            note=note,
        )

    return field


u8, s8, u16, u32, f32, f64 = (_number(k) for k in ("u8", "s8", "u16", "u32", "f32", "f64"))


def bits(name: str, offset: int, bit: int, width: int, hi: int, note: str = "") -> Field:
    return Field(name, offset, "bits", 0, hi, bit=bit, width=width, note=note)


def flag(name: str, offset: int, bit: int, note: str = "") -> Field:
    return Field(name, offset, "bits", bit=bit, width=1, note=note)


def angle(name: str, offset: int, lo: float, note: str = "") -> Field:
    return Field(name, offset, "f32", lo, lo + 360.0, wrap=True, note=note)


def calendar_mmddyyyy(value: int) -> str:
    """ "" for a CIGI date (MM·1 000 000 + DD·10 000 + YYYY) that is a day, else why not."""
    month, day, year = value // 1_000_000, value // 10_000 % 100, value % 10_000
    try:
        date(year, month, day)
    except ValueError:
        return f"{value} is not a calendar date (month {month}, day {day}, year {year})"
    if not year_in_range(year):  # the clock's range, wxsky.weather.state
        return f"{value}: year {year} is outside the clock's years {CLOCK_YEARS}"
    return ""


def version(note: str) -> Field:
    return u8("major_version", 2, fixed=MAJOR_VERSION, note=note)


def magic() -> Field:
    return u16("byte_swap_magic", 6, fixed=BYTE_SWAP_MAGIC, note="decides the byte order")


def minor_version(offset: int) -> Field:
    return Field("minor_version", offset, "bits", bit=4, width=4, default=MINOR_VERSION)


def table_problems(spec: PacketSpec) -> list[str]:
    """What is wrong with a packet's table entry: overlaps, gaps past its size, misaligned
    numbers, bad bit fields, dangling conditions. Empty for a sound entry."""
    found: list[str] = []
    names = [f.name for f in spec.fields]
    if len(set(names)) != len(names):
        found.append("duplicate field names")
    if spec.size % 8 or not HEADER_SIZE < spec.size <= 0xFF:
        found.append(f"size {spec.size} is not a multiple of 8 in 8..248")
    used: dict[int, int] = {}  # byte -> bits taken (0xFF for a whole-byte field)
    for f in spec.fields:
        width = KIND_SIZES[f.kind]
        if f.offset < HEADER_SIZE or f.offset + width > spec.size:
            found.append(f"{f.name} at byte {f.offset} is outside the packet")
        if f.offset % width:
            found.append(f"{f.name} at byte {f.offset} is not aligned to {width}")
        if f.kind == "bits" and not (f.width >= 1 and f.bit >= 0 and f.bit + f.width <= 8):
            found.append(f"{f.name}: bits {f.bit}+{f.width} do not fit a byte")
        masks = [((1 << f.width) - 1) << f.bit] if f.kind == "bits" else [0xFF] * width
        for byte, mask in enumerate(masks, f.offset):
            if used.get(byte, 0) & mask or (mask == 0xFF and byte in used):
                found.append(f"{f.name} overlaps byte {byte}")
            used[byte] = used.get(byte, 0) | mask
        if f.when is not None and f.when[0] not in names:
            found.append(f"{f.name} depends on missing field {f.when[0]}")
        if f.wrap and (f.kind != "f32" or f.lo is None or f.hi != f.lo + 360.0):
            found.append(f"{f.name}: a wrapped angle is an f32 over 360 degrees")
    if spec.starts_message:
        fixed = {(f.name, f.offset) for f in spec.fields if f.fixed is not None}
        if fixed != {("major_version", 2), ("byte_swap_magic", 6)}:
            found.append("a first packet carries the version at byte 2 and the magic at 6")
    return found


def _num(x: float) -> str:
    return f"{x:.10g}"


def range_text(f: Field) -> str:
    """The values a field accepts, as the docs and problem messages say it."""
    if f.fixed is not None:
        return f"= 0x{f.fixed:04X}" if f.fixed > 0xFF else f"= {f.fixed}"
    if f.wrap and f.lo is not None and f.hi is not None:
        text = (
            f"{_num(-WRAP_ACCEPT_DEG)}..{_num(WRAP_ACCEPT_DEG)}, "
            f"kept as {_num(f.lo)}..<{_num(f.hi)}"
        )
    elif f.lo is not None and f.hi is not None:
        text = f"{_num(f.lo)}..{_num(f.hi)}"
    elif f.lo is not None:
        text = f"≥ {_num(f.lo)}"
    elif f.hi is not None:
        text = f"≤ {_num(f.hi)}"
    else:
        text = "finite" if f.is_float else ""
    if f.rule_text:
        text = f"{text}, {f.rule_text}" if text else f.rule_text
    if f.when is not None and text:
        text += f" when `{f.when[0]}` = {f.when[1]}"
    return text or "-"


def type_text(f: Field) -> str:
    if f.kind != "bits":
        return f.kind
    last = f.bit + f.width - 1
    return f"bit {f.bit}" if f.width == 1 else f"bits {f.bit}–{last}"
