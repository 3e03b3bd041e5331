"""The NMEA 0183 sentences wxsky reads, each turned from its fields into weather values.

An interpreter gets the fields after the address (field 1 first, numbered as NMEA's field
tables number them) and returns a `CockpitUpdate`, or None for a
sentence that only feeds later ones (a heading for MWV). It raises `SentenceError` for a
malformed or out-of-range field and `SentenceIgnored` for a well-formed sentence wxsky cannot
use. Fields an interpreter does not use are not looked at, so a device's odd magnetic or
humidity field does not cost the values beside it. Reading one field into a checked value is
`nmea_fields`' job; framing and checksums are `nmea`'s.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import date, datetime
from types import MappingProxyType
from typing import TYPE_CHECKING

from wxsky.protocols.nmea_fields import (
    DDMMYY,
    SentenceError,
    SentenceIgnored,
    TimeOfDay,
    angle,
    calendar_date,
    coordinate,
    full_year,
    measure,
    number,
    text,
    time_of_day,
    whole,
)
from wxsky.protocols.result import Decoded
from wxsky.units import FT_TO_M, INHG_TO_HPA, KMH_TO_MPS, KT_TO_MPS, STATUTE_MILE_TO_M
from wxsky.weather.cockpit import (
    COCKPIT_LAYERS,
    DEWPOINT,
    LAYER_BASE,
    LAYER_COVER,
    LAYER_THICKNESS,
    LAYER_TYPE,
    QNH,
    RANGES,
    TEMPERATURE,
    WIND_DIR,
    WIND_SPEED,
    CockpitUpdate,
    checked,
    layer_key,
)
from wxsky.weather.state import CloudType

if TYPE_CHECKING:
    from wxsky.protocols.nmea import NmeaSettings

# A heading older than this no longer says where a (possibly turning) sensor points.
HEADING_MAX_AGE_S = 10.0

# MWV speed units -> (m/s per unit, how the unit is written in a reason).
_MWV_UNITS: Mapping[str, tuple[float, str]] = MappingProxyType(
    {
        "K": (KMH_TO_MPS, "km/h"),
        "M": (1.0, "m/s"),
        "N": (KT_TO_MPS, "kn"),
        "S": (STATUTE_MILE_TO_M / 3600.0, "mph"),  # not in the standard; some devices send it
    }
)


@dataclass
class LinkState:
    """What earlier sentences on the same input said that later ones depend on."""

    # heading source ("hdt" / "hdg") -> (true heading in degrees, now_s it arrived)
    headings: dict[str, tuple[float, float]] = field(default_factory=dict)
    geographic_wind_at_s: float | None = None  # when MWD/MDA last gave wind


@dataclass(frozen=True)
class Context:
    settings: NmeaSettings
    state: LinkState
    now_s: float
    reference_year: int


Interpreter = Callable[[Sequence[str], Context], CockpitUpdate | None]


def interpret(name: str, fields: Sequence[str], ctx: Context) -> Decoded:
    """The sentence `name` (`MWV`, `PWXCL`) with `fields` after its address, decoded."""
    entry = SENTENCES.get(name)
    if entry is None:
        return Decoded.ignore(f"{name}: sentence not used by wxsky")
    min_fields, interpreter = entry
    if len(fields) < min_fields:
        return Decoded.reject(f"{name}: {len(fields)} fields, expected at least {min_fields}")
    try:
        update = interpreter(fields, ctx)
    except SentenceError as exc:
        return Decoded.reject(f"{name}: {exc}")
    except SentenceIgnored as exc:
        return Decoded.ignore(f"{name}: {exc}")
    if update is None:
        return Decoded()
    if update.empty:
        return Decoded.ignore(f"{name}: no values (the fields wxsky reads are empty)")
    return Decoded(update=update)


# -- fields -----------------------------------------------------------------------------


def _weather(key: str, value: float, what: str, unit: str, given: str = "") -> float:
    """`checked(key, value)`, refusing with a reason that names the quantity as the sentence
    gave it (`given`, e.g. "300 kn") and in the unit wxsky keeps it in."""
    try:
        return checked(key, value)
    except ValueError as exc:
        shown = f"{given} ({value:g} {unit})" if given else f"{value:g} {unit}"
        lo, hi = RANGES[key].bounds
        if key.endswith(LAYER_THICKNESS) and lo <= value <= hi:
            raise SentenceError(f"{what} {shown} must be more than 0 {unit}") from None
        if lo <= value <= hi:  # refused for a reason checked() has and this function lacks
            raise SentenceError(f"{what} {shown} refused: {exc}") from None
        raise SentenceError(f"{what} {shown} out of range {lo:g}..{hi:g} {unit}") from None


def _wind_dir(dir_from_deg: float) -> float:
    return checked(WIND_DIR, dir_from_deg % 360.0)


def _speed_mps(fields: Sequence[str], mps_n: int, kn_n: int) -> float | None:
    """Wind speed from the m/s field, else the knots one (MWD, MDA)."""
    mps = measure(fields, mps_n, "wind speed m/s", "M")
    if mps is not None:
        return _weather(WIND_SPEED, mps, "wind speed", "m/s")
    kn = measure(fields, kn_n, "wind speed knots", "N")
    if kn is not None:
        return _weather(WIND_SPEED, kn * KT_TO_MPS, "wind speed", "m/s", f"{kn:g} kn")
    return None


def _status(fields: Sequence[str], n: int, invalid: str) -> None:
    status = text(fields, n)
    if status == "V":
        raise SentenceIgnored(f"status V ({invalid})")
    if status != "A":
        raise SentenceError(f"field {n} (status) {status!r}, expected A or V")


# -- wind -------------------------------------------------------------------------------


def _heading_deg(ctx: Context) -> float:
    source = ctx.settings.heading_source
    if source == "fixed":
        return ctx.settings.sensor_heading_deg
    got = ctx.state.headings.get(source)
    if got is None:
        raise SentenceIgnored(f"no {source.upper()} heading received yet (heading_source)")
    heading_deg, at_s = got
    age_s = ctx.now_s - at_s
    if age_s > HEADING_MAX_AGE_S:
        raise SentenceIgnored(
            f"last {source.upper()} heading is {age_s:.1f} s old (limit {HEADING_MAX_AGE_S:g} s)"
        )
    return heading_deg


def _mwv(f: Sequence[str], ctx: Context) -> CockpitUpdate:
    _status(f, 5, "sensor reports the data invalid")
    reference = f[1]
    if reference == "R":
        if not ctx.settings.accept_relative_wind:
            raise SentenceIgnored("relative (apparent) wind, and accept_relative_wind is off")
    elif reference != "T":
        raise SentenceError(f"field 2 (reference) {reference!r}, expected T or R")
    held_at_s = ctx.state.geographic_wind_at_s
    if held_at_s is not None and ctx.now_s - held_at_s < ctx.settings.geographic_wind_hold_s:
        # MWD/MDA are already geographic; an MWV beside them is the same wind, less certain.
        raise SentenceIgnored(
            f"MWD/MDA gave wind {ctx.now_s - held_at_s:.1f} s ago, within geographic_wind_hold_s"
        )
    values: dict[str, float | CloudType] = {}
    speed = number(f, 3, "wind speed")
    if speed is not None:
        unit = _MWV_UNITS.get(f[3])
        if unit is None:
            raise SentenceError(f"field 4 (speed unit) {f[3]!r}, expected K, M, N or S")
        per_unit_mps, unit_name = unit
        given = "" if unit_name == "m/s" else f"{speed:g} {unit_name}"
        values[WIND_SPEED] = _weather(WIND_SPEED, speed * per_unit_mps, "wind speed", "m/s", given)
    angle_deg = angle(number(f, 1, "wind angle"), 1, "wind angle")
    if angle_deg is not None:
        values[WIND_DIR] = _wind_dir(angle_deg + _heading_deg(ctx))
    return CockpitUpdate(values=values)


def _mwd(f: Sequence[str], ctx: Context) -> CockpitUpdate:
    values: dict[str, float | CloudType] = {}
    # Only the true direction: magnetic needs a variation this sentence does not carry.
    dir_deg = angle(measure(f, 1, "wind direction true", "T"), 1, "wind direction true")
    if dir_deg is not None:
        values[WIND_DIR] = _wind_dir(dir_deg)
    speed_mps = _speed_mps(f, 7, 5)
    if speed_mps is not None:
        values[WIND_SPEED] = speed_mps
    if values:
        ctx.state.geographic_wind_at_s = ctx.now_s
    return CockpitUpdate(values=values)


def _mda(f: Sequence[str], ctx: Context) -> CockpitUpdate:
    values: dict[str, float | CloudType] = {}
    bar = measure(f, 3, "pressure bar", "B")
    inhg = measure(f, 1, "pressure inHg", "I") if bar is None else None
    if bar is not None:
        values[QNH] = _weather(QNH, bar * 1000.0, "pressure", "hPa", f"{bar:g} bar")
    elif inhg is not None:
        values[QNH] = _weather(QNH, inhg * INHG_TO_HPA, "pressure", "hPa", f"{inhg:g} inHg")
    air_c = measure(f, 5, "air temperature", "C")
    if air_c is not None:
        values[TEMPERATURE] = _weather(TEMPERATURE, air_c, "air temperature", "°C")
    dew_c = measure(f, 11, "dew point", "C")
    if dew_c is not None:
        values[DEWPOINT] = _weather(DEWPOINT, dew_c, "dew point", "°C")
    wind: dict[str, float | CloudType] = {}
    dir_deg = angle(measure(f, 13, "wind direction true", "T"), 13, "wind direction true")
    if dir_deg is not None:
        wind[WIND_DIR] = _wind_dir(dir_deg)
    speed_mps = _speed_mps(f, 19, 17)
    if speed_mps is not None:
        wind[WIND_SPEED] = speed_mps
    if wind:
        ctx.state.geographic_wind_at_s = ctx.now_s
    return CockpitUpdate(values={**values, **wind})


# -- heading ----------------------------------------------------------------------------


def _hdt(f: Sequence[str], ctx: Context) -> None:
    heading_deg = angle(measure(f, 1, "heading true", "T"), 1, "heading true")
    if heading_deg is None:
        raise SentenceIgnored("no heading (field 1 empty)")
    ctx.state.headings["hdt"] = (heading_deg % 360.0, ctx.now_s)


def _east_positive(f: Sequence[str], n: int, what: str) -> float:
    """A deviation or variation with its E/W letter in field n+1; missing counts as 0."""
    value = number(f, n, what)
    if value is None or value == 0.0:
        return 0.0
    if abs(value) > 180.0:
        raise SentenceError(f"field {n} ({what}) {value:g}° out of range 0..180")
    side = text(f, n + 1)
    if side not in ("E", "W"):
        raise SentenceError(f"field {n + 1} ({what} direction) {side!r}, expected E or W")
    return value if side == "E" else -value


def _hdg(f: Sequence[str], ctx: Context) -> None:
    heading_deg = angle(number(f, 1, "heading magnetic"), 1, "heading magnetic")
    if heading_deg is None:
        raise SentenceIgnored("no heading (field 1 empty)")
    true_deg = heading_deg + _east_positive(f, 2, "deviation") + _east_positive(f, 4, "variation")
    ctx.state.headings["hdg"] = (true_deg % 360.0, ctx.now_s)


# -- time and position ------------------------------------------------------------------


def _time_update(
    tod: TimeOfDay | None, day: date | None, position_deg: tuple[float, float] | None = None
) -> CockpitUpdate:
    if tod is not None and day is not None:
        return CockpitUpdate(
            time_utc=datetime.combine(day, tod.clock),
            time_resolution_s=tod.resolution_s,
            position_deg=position_deg,
        )
    if tod is not None:
        return CockpitUpdate(
            time_of_day_s=tod.seconds,
            time_resolution_s=tod.resolution_s,
            position_deg=position_deg,
        )
    return CockpitUpdate(date_utc=day, position_deg=position_deg)


def _zda(f: Sequence[str], ctx: Context) -> CockpitUpdate:
    tod = time_of_day(f, 1)
    day, month, year = whole(f, 2, "day"), whole(f, 3, "month"), whole(f, 4, "year")
    parts = (day, month, year)
    when: date | None = None
    if day is not None and month is not None and year is not None:
        digits = len(f[3])
        if digits not in (2, 4):
            raise SentenceError(f"field 4 (year) {f[3]!r} is not 2 or 4 digits")
        when = calendar_date(day, month, full_year(year, digits, ctx.reference_year), "fields 2-4")
    elif any(p is not None for p in parts):
        raise SentenceError("fields 2-4 (day, month, year) are partly empty")
    return _time_update(tod, when)


def _rmc(f: Sequence[str], ctx: Context) -> CockpitUpdate:
    _status(f, 2, "receiver has no valid fix")
    tod = time_of_day(f, 1)
    when: date | None = None
    date_text = f[8]
    if date_text:
        m = DDMMYY.fullmatch(date_text)
        if m is None:
            raise SentenceError(f"field 9 (date) {date_text!r} is not ddmmyy")
        year = full_year(int(m[3]), 2, ctx.reference_year)
        when = calendar_date(int(m[1]), int(m[2]), year, "field 9")
    lat_deg = coordinate(f, 3, "latitude", 90.0, "NS")
    lon_deg = coordinate(f, 5, "longitude", 180.0, "EW")
    if (lat_deg is None) != (lon_deg is None):
        raise SentenceError("fields 3 and 5 (latitude, longitude): one is empty")
    position = (lat_deg, lon_deg) if lat_deg is not None and lon_deg is not None else None
    return _time_update(tod, when, position)


# -- clouds -----------------------------------------------------------------------------


def _pwxcl(f: Sequence[str], ctx: Context) -> CockpitUpdate:
    if len(f) > 5:
        raise SentenceError(f"{len(f)} fields, expected 4 or 5")
    layer = whole(f, 1, "layer")
    if layer is None:
        raise SentenceError("field 1 (layer) is empty; the layer is required")
    if not 1 <= layer <= COCKPIT_LAYERS:
        raise SentenceError(f"layer {layer} out of range 1..{COCKPIT_LAYERS}")
    values: dict[str, float | CloudType] = {}
    oktas = number(f, 2, "oktas")
    if oktas is not None:
        key = layer_key(layer, LAYER_COVER)
        values[key] = _weather(key, oktas, f"layer {layer} cover", "oktas")
    for n, part, what in ((3, LAYER_BASE, "base"), (4, LAYER_THICKNESS, "thickness")):
        ft = number(f, n, f"{what} ft")
        if ft is not None:
            key = layer_key(layer, part)
            values[key] = _weather(key, ft * FT_TO_M, f"layer {layer} {what}", "m", f"{ft:g} ft")
    type_name = text(f, 5).strip()
    cloud_type = CloudType.NONE  # empty or absent: the weather derives the type
    if type_name:
        if type_name.upper() == CloudType.NONE.name:
            raise SentenceError("field 5 (cloud type) NONE: leave it empty to derive the type")
        try:
            cloud_type = CloudType.from_name(type_name)
        except ValueError as exc:
            raise SentenceError(f"field 5 (cloud type): {exc}") from None
    values[layer_key(layer, LAYER_TYPE)] = cloud_type
    return CockpitUpdate(values=values)


# name -> (fewest fields it must have, interpreter). Fewest is the fields the table defines,
# except where devices and NMEA versions differ in what trails (RMC's variation and mode, ZDA's
# zone, HDG's deviation and variation), which count as empty when absent.
SENTENCES: Mapping[str, tuple[int, Interpreter]] = MappingProxyType(
    {
        "MWV": (5, _mwv),
        "MWD": (8, _mwd),
        "MDA": (20, _mda),
        "HDT": (1, _hdt),
        "HDG": (1, _hdg),
        "ZDA": (4, _zda),
        "RMC": (9, _rmc),
        "PWXCL": (4, _pwxcl),
    }
)
