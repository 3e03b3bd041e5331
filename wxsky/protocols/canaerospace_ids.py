"""The CANaerospace identifiers wxsky reads, as one table.

`IDS` is the single source for the decoder, the encoder emulators use, the DBC file
(`canaerospace_dbc`) and the profile table in docs/canaerospace.md (`table_markdown`).
Standard ids follow CANaerospace v1.7 (§5.1, §5.9); 1500-1503 are wxsky's own profile in the
range the standard leaves to the user (1500-1799), since v1.7 has no ids for clouds or
visibility.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from datetime import date
from enum import IntEnum
from types import MappingProxyType

from wxsky.weather.cockpit import (
    COCKPIT_LAYERS,
    LAYER_BASE,
    LAYER_COVER,
    LAYER_THICKNESS,
    QNH,
    RANGES,
    TEMPERATURE,
    VISIBILITY,
    WIND_DIR,
    WIND_SPEED,
    CockpitUpdate,
    layer_key,
)
from wxsky.weather.state import CLOCK_YEARS, year_in_range

MAX_STANDARD_ID = 0x7FF  # CANaerospace runs on CAN 2.0A only
USER_RANGE = range(1500, 1800)  # "unassigned and may be used at the user's discretion" (§5)


class DataType(IntEnum):
    """CANaerospace v1.7 data-type codes (§2.2): byte 1 of every frame."""

    NODATA = 0
    ERROR = 1
    FLOAT = 2
    LONG = 3
    ULONG = 4
    BLONG = 5
    SHORT = 6
    USHORT = 7
    BSHORT = 8
    CHAR = 9
    UCHAR = 10
    BCHAR = 11
    SHORT2 = 12
    USHORT2 = 13
    BSHORT2 = 14
    CHAR4 = 15
    UCHAR4 = 16
    BCHAR4 = 17
    CHAR2 = 18
    UCHAR2 = 19
    BCHAR2 = 20
    MEMID = 21
    CHKSUM = 22
    ACHAR = 23
    ACHAR2 = 24
    ACHAR4 = 25
    CHAR3 = 26
    UCHAR3 = 27
    BCHAR3 = 28
    ACHAR3 = 29
    DOUBLEH = 30
    DOUBLEL = 31


# Payload bytes per data type, as the reference marshaller checks them (codes 32-99 are
# reserved and 100-255 user-defined with no fixed size, so a frame using them cannot be sized).
DATA_TYPE_SIZES: Mapping[int, int] = MappingProxyType(
    {
        DataType.NODATA: 0,
        DataType.ERROR: 4,
        DataType.FLOAT: 4,
        DataType.LONG: 4,
        DataType.ULONG: 4,
        DataType.BLONG: 4,
        DataType.SHORT: 2,
        DataType.USHORT: 2,
        DataType.BSHORT: 2,
        DataType.CHAR: 1,
        DataType.UCHAR: 1,
        DataType.BCHAR: 1,
        DataType.SHORT2: 4,
        DataType.USHORT2: 4,
        DataType.BSHORT2: 4,
        DataType.CHAR4: 4,
        DataType.UCHAR4: 4,
        DataType.BCHAR4: 4,
        DataType.CHAR2: 2,
        DataType.UCHAR2: 2,
        DataType.BCHAR2: 2,
        DataType.MEMID: 4,
        DataType.CHKSUM: 4,
        DataType.ACHAR: 1,
        DataType.ACHAR2: 2,
        DataType.ACHAR4: 4,
        DataType.CHAR3: 3,
        DataType.UCHAR3: 3,
        DataType.BCHAR3: 3,
        DataType.ACHAR3: 3,
        DataType.DOUBLEH: 4,
        DataType.DOUBLEL: 4,
    }
)

NUMERIC = (DataType.FLOAT, DataType.SHORT2, DataType.LONG)

# What the service code (byte 2) means for an id.
SERVICE_LAYER = "layer 1-3"  # the cockpit cloud layer, as the spec indexes tires
SERVICE_ZERO = "0"  # must be 0: reserved for later use of the profile
SERVICE_FREE = "-"  # standard NOD ids: free use by the sender, not read


@dataclass(frozen=True)
class Char4Field:
    """One signed byte of a CHAR4 time or date frame."""

    dbc_name: str
    name: str  # as in a rejection reason
    lo: int
    hi: int
    unit: str = ""


@dataclass(frozen=True)
class Char4:
    """How the four CHAR4 bytes of a time or date id read. Each byte is range-checked against
    its field before `read`, which may still refuse a combination (31 February)."""

    fields: tuple[Char4Field, Char4Field, Char4Field, Char4Field]
    target: str  # the CockpitUpdate field it sets
    read: Callable[[int, int, int, int], CockpitUpdate]  # raises ValueError with a reason


@dataclass(frozen=True)
class CanasId:
    """One identifier wxsky reads. Numeric ids carry `wire` units; wxsky's value is
    `wire * si_scale + si_offset` (linear, so the inverse gives encoders and limits)."""

    can_id: int
    name: str  # as in reasons and docs: "wind speed"
    unit: str  # on the wire
    data_types: tuple[DataType, ...]
    key: str | None  # cockpit key; for layered ids the layer part; None for time and date
    service_code: str  # SERVICE_LAYER, SERVICE_ZERO or SERVICE_FREE
    note: str = ""
    si_scale: float = 1.0
    si_offset: float = 0.0
    # Wire values accepted where they differ from the cockpit range converted to wire units.
    accepted_wire: tuple[float, float] | None = None
    char4: Char4 | None = None

    @property
    def dbc_name(self) -> str:
        """DBC message and value-signal name: "wind speed" -> WindSpeed."""
        return "".join(word.capitalize() for word in self.name.split())

    @property
    def layered(self) -> bool:
        return self.service_code == SERVICE_LAYER

    @property
    def standard(self) -> bool:
        return self.can_id not in USER_RANGE

    def cockpit_key(self, layer: int = 1) -> str:
        """The cockpit key a value of this id sets (`layer` only matters for layered ids)."""
        if self.key is None:
            raise ValueError(f"CAN {self.can_id} {self.name} sets no cockpit value")
        return layer_key(layer, self.key) if self.layered else self.key

    def to_si(self, wire: float) -> float:
        return wire * self.si_scale + self.si_offset

    def from_si(self, si: float) -> float:
        return (si - self.si_offset) / self.si_scale

    def wire_limits(self) -> tuple[float, float]:
        """The wire values `checked` lets through, for reasons, the DBC and the docs."""
        if self.accepted_wire is not None:
            return self.accepted_wire
        lo, hi = sorted(self.from_si(x) for x in RANGES[self.cockpit_key()].bounds)
        return lo, hi


def _utc(hour: int, minute: int, second: int, _reserved: int) -> CockpitUpdate:
    return CockpitUpdate(
        time_of_day_s=float(hour * 3600 + minute * 60 + second), time_resolution_s=1.0
    )


def _date(day: int, month: int, century: int, year: int) -> CockpitUpdate:
    full_year = century * 100 + year
    try:
        when = date(full_year, month, day)
    except ValueError:
        raise ValueError(f"{full_year:04d}-{month:02d}-{day:02d} is not a calendar date") from None
    if not year_in_range(full_year):
        raise ValueError(f"{when.isoformat()} is outside the clock's years {CLOCK_YEARS}")
    return CockpitUpdate(date_utc=when)


UTC_CHAR4 = Char4(
    fields=(
        Char4Field("Hours", "hour", 0, 23, "h"),
        Char4Field("Minutes", "minute", 0, 59, "min"),
        Char4Field("Seconds", "second", 0, 59, "s"),
        # The standard sends 0 here; a sender that uses it for more is still on time.
        Char4Field("Reserved", "reserved byte", -128, 127),
    ),
    target="time_of_day_s",
    read=_utc,
)
DATE_CHAR4 = Char4(
    fields=(
        Char4Field("Day", "day", 1, 31),
        Char4Field("Month", "month", 1, 12),
        Char4Field("Century", "century", 0, 99),
        Char4Field("Year", "year", 0, 99),
    ),
    target="date_utc",
    read=_date,
)

IDS: tuple[CanasId, ...] = (
    CanasId(319, "baro correction", "hPa", NUMERIC, QNH, SERVICE_FREE),
    CanasId(333, "wind speed", "m/s", NUMERIC, WIND_SPEED, SERVICE_FREE),
    CanasId(
        334,
        "wind direction",
        "deg",
        NUMERIC,
        WIND_DIR,
        SERVICE_FREE,
        note="true, from; the standard sends -180..180, wxsky keeps 0..360",
        accepted_wire=(-180.0, 360.0),
    ),
    CanasId(
        335,
        "outside air temperature",
        "K",
        NUMERIC,
        TEMPERATURE,
        SERVICE_FREE,
        note="kelvin on the wire; wxsky keeps deg C = K - 273.15",
        si_offset=-273.15,
    ),
    CanasId(
        1200,
        "UTC",
        "h min s",
        (DataType.CHAR4,),
        None,
        SERVICE_FREE,
        note="bytes hour, minute, second, 0 (binary, not BCD); 1 s resolution",
        char4=UTC_CHAR4,
    ),
    CanasId(
        1206,
        "date",
        "",
        (DataType.CHAR4,),
        None,
        SERVICE_FREE,
        note="bytes day, month, century, year (binary, not BCD)",
        char4=DATE_CHAR4,
    ),
    CanasId(1500, "cloud cover", "oktas", NUMERIC, LAYER_COVER, SERVICE_LAYER),
    CanasId(1501, "cloud base", "m", NUMERIC, LAYER_BASE, SERVICE_LAYER, note="MSL"),
    CanasId(
        1502,
        "cloud thickness",
        "m",
        NUMERIC,
        LAYER_THICKNESS,
        SERVICE_LAYER,
        note="more than 0",
    ),
    CanasId(1503, "visibility", "m", NUMERIC, VISIBILITY, SERVICE_ZERO),
)

BY_ID: Mapping[int, CanasId] = MappingProxyType({entry.can_id: entry for entry in IDS})
# Cockpit key (or layer part, for layered ids) -> the id that carries it.
BY_KEY: Mapping[str, CanasId] = MappingProxyType(
    {entry.key: entry for entry in IDS if entry.key is not None}
)
assert len(BY_ID) == len(IDS), "duplicate CAN id in IDS"
assert COCKPIT_LAYERS < 256, "the layer travels in the one-byte service code"


def _num(x: float) -> str:
    return f"{x:.10g}"


def _target(entry: CanasId) -> str:
    if entry.char4 is not None:
        return f"`{entry.char4.target}`"
    if entry.layered:
        return f"`layerN.{entry.key}`, N = service code"
    return f"`{entry.cockpit_key()}`"


def _accepts(entry: CanasId) -> str:
    if entry.char4 is not None:
        return ", ".join(
            f"{f.name} {f.lo}..{f.hi}" for f in entry.char4.fields if f.lo > -128 or f.hi < 127
        )
    lo, hi = entry.wire_limits()
    return f"{_num(lo)}..{_num(hi)}"


def table_markdown() -> str:
    """The profile table for docs/canaerospace.md, generated so the doc cannot drift."""
    rows = [
        "| CAN-ID | Hex | Parameter | Data types | Wire unit | Service code | Sets | Accepts |"
        " Defined by | Notes |",
        "|---:|---|---|---|---|---|---|---|---|---|",
    ]
    for e in IDS:
        rows.append(
            f"| {e.can_id} | 0x{e.can_id:03X} | {e.name} | "
            f"{', '.join(t.name for t in e.data_types)} | {e.unit or '-'} | {e.service_code} | "
            f"{_target(e)} | {_accepts(e)} | "
            f"{'CANaerospace v1.7' if e.standard else 'wxsky profile'} | {e.note or '-'} |"
        )
    return "\n".join(rows) + "\n"
