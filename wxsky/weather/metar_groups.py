"""METAR groups: one recogniser per group kind, each turning body tokens into a typed value.

`parse_group` is the only entry point the decoder (`wxsky.weather.metar`) needs. It tries the
recognisers in `_RECOGNISERS` in order and returns the typed group plus how many tokens it used,
or None when no recogniser claims the token. A recogniser that claims a token whose value is
impossible (wind 300 kt, QNH 99 hPa, ...) raises `GroupValueError`; the decoder turns that into a
warning. Adding a group kind means adding a dataclass, a recogniser and a case in the decoder.

All values leave this module in SI units; heights are above ground level (AGL).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from wxsky.units import FT_TO_M, INHG_TO_HPA, KMH_TO_MPS, KT_TO_MPS, STATUTE_MILE_TO_M, mps_to_kt

MAX_WIND_KT = 250.0
MAX_VISIBILITY_M = 1_000_000.0  # the weather state's limit; METAR never comes close
# The longest real body group is about 20 characters; longer tokens skip the regexes entirely.
MAX_GROUP_CHARS = 40
TEMPERATURE_RANGE_C = (-90.0, 60.0)
QNH_RANGE_HPA = (850.0, 1100.0)
# ICAO's 9999 means "10 km or more"; we report the floor, as CAVOK does.
TEN_KM = 10_000.0


class GroupValueError(ValueError):
    """A token has the shape of a known group but an impossible value; the message says which."""


@dataclass(frozen=True)
class MetarWind:
    """Surface wind. dir_from_deg is None for VRB (variable=True) or an unreported direction."""

    dir_from_deg: float | None
    variable: bool
    speed_mps: float
    gust_mps: float | None = None
    variable_from_deg: float | None = None  # from a dddVddd sector group
    variable_to_deg: float | None = None

    @property
    def calm(self) -> bool:
        return self.speed_mps == 0.0 and not self.gust_mps


@dataclass(frozen=True)
class MetarSkyGroup:
    """One cloud group. cover is FEW/SCT/BKN/OVC, VV (obscured) or /// (cover not observed)."""

    cover: str
    base_m: float | None  # AGL; None when the height was reported as ///
    cb: bool = False
    tcu: bool = False


# --- group values the decoder consumes -------------------------------------------------------


@dataclass(frozen=True)
class Flag:
    name: str  # AUTO, COR, NIL or RTD


@dataclass(frozen=True)
class UnitlessWind:
    """A wind group without its unit (`04014`); only trusted where the wind group belongs."""

    wind: MetarWind


@dataclass(frozen=True)
class WindSector:
    from_deg: float
    to_deg: float


@dataclass(frozen=True)
class Visibility:
    metres: float | None  # None: reported missing (////)
    cavok: bool = False
    directional: bool = False  # carries a direction: a second one is the sector minimum


@dataclass(frozen=True)
class RunwayVisualRange:
    text: str


@dataclass(frozen=True)
class Weather:
    code: str


@dataclass(frozen=True)
class SkyClear:
    code: str  # CLR, SKC, NSC or NCD


@dataclass(frozen=True)
class DetachedCloudType:
    """`CB` or `TCU` standing alone after a cloud group (a common typing slip)."""

    code: str


@dataclass(frozen=True)
class Temperatures:
    temperature_c: float | None
    dewpoint_c: float | None


@dataclass(frozen=True)
class Pressure:
    hpa: float | None  # None: reported missing
    kind: str  # "Q" (hPa) or "A" (inHg)


@dataclass(frozen=True)
class Ignored:
    """A recognised group that carries nothing the weather state uses (runway or sea state...)."""

    what: str


Group = (
    Flag
    | MetarWind
    | UnitlessWind
    | WindSector
    | Visibility
    | RunwayVisualRange
    | Weather
    | SkyClear
    | MetarSkyGroup
    | DetachedCloudType
    | Temperatures
    | Pressure
    | Ignored
)
Recogniser = Callable[[Sequence[str], int], "tuple[Group, int] | None"]

# --- header and structure ---------------------------------------------------------------------

_STATION = re.compile(r"[A-Z][A-Z0-9]{3}")
_TIME = re.compile(r"(\d\d)(\d\d)(\d\d)Z")
_TIME_WITHOUT_Z = re.compile(r"(\d\d)(\d\d)(\d\d)")
_TREND = re.compile(r"NOSIG|N0SIG|BECMG|TEMPO|INTER|FM\d{4}(?:\d\d)?|PROB[34]0")
_FLAGS = {"AUTO": "AUTO", "COR": "COR", "CORR": "COR", "NIL": "NIL", "RTD": "RTD"}
_CORRECTION = re.compile(r"CC[A-G]")


def is_station(token: str) -> bool:
    return _STATION.fullmatch(token) is not None


def is_time_group(token: str) -> bool:
    return _TIME.fullmatch(token) is not None


def parse_time(token: str) -> tuple[int, int, int] | None:
    """(day, hour, minute) of a ddhhmmZ group, or None. Raises GroupValueError if impossible.

    The Z is optional here: right after the station six digits can only be the time.
    """
    m = _TIME.fullmatch(token) or _TIME_WITHOUT_Z.fullmatch(token)
    if m is None:
        return None
    day, hour, minute = (int(g) for g in m.groups())
    if not 1 <= day <= 31 or hour > 23 or minute > 59:
        raise GroupValueError(f"day {day}, {hour:02d}:{minute:02d} is not a valid day and UTC time")
    return day, hour, minute


def flag_name(token: str) -> str | None:
    """AUTO/COR/NIL/RTD for a report modifier token (CCA..CCG count as COR)."""
    if _CORRECTION.fullmatch(token):
        return "COR"
    return _FLAGS.get(token)


def is_trend_start(token: str) -> bool:
    return _TREND.fullmatch(token) is not None


# --- recognisers ------------------------------------------------------------------------------

_WIND = re.compile(
    r"(?P<dir>\d{3}|VRB|///)(?P<speed>P?\d{2,3}|//)(?:G(?P<gust>P?\d{2,3}|//))?"
    r"(?P<unit>KT|MPS|KMH)"
)
_UNITLESS_WIND = re.compile(r"(?P<dir>\d{3})(?P<speed>\d{2})(?:G(?P<gust>\d{2}))?")
_WIND_UNIT_MPS = {"KT": KT_TO_MPS, "MPS": 1.0, "KMH": KMH_TO_MPS}
_SECTOR = re.compile(r"(\d{3})V(\d{3})")


def _wind_speed(text: str, unit: str, what: str) -> float:
    speed = float(text.lstrip("P")) * _WIND_UNIT_MPS[unit]
    if mps_to_kt(speed) > MAX_WIND_KT:
        raise GroupValueError(f"{what} {mps_to_kt(speed):.0f} kt is above {MAX_WIND_KT:.0f} kt")
    return speed


def _make_wind(direction: str, speed: str, gust: str | None, unit: str) -> MetarWind:
    dir_deg: float | None = None
    if direction.isdigit():
        dir_deg = float(direction)
        if dir_deg > 360.0:
            raise GroupValueError(f"wind direction {direction}° is above 360°")
    gust_mps = None if gust is None or gust == "//" else _wind_speed(gust, unit, "gust")
    return MetarWind(
        dir_from_deg=dir_deg,
        variable=direction == "VRB",
        speed_mps=_wind_speed(speed, unit, "wind speed"),
        gust_mps=gust_mps,
    )


def _wind(tokens: Sequence[str], i: int) -> tuple[Group, int] | None:
    m = _WIND.fullmatch(tokens[i])
    if m is None:
        return None
    if m["speed"] == "//":
        return Ignored("wind not reported"), 1
    return _make_wind(m["dir"], m["speed"], m["gust"], m["unit"]), 1


def _unitless_wind(tokens: Sequence[str], i: int) -> tuple[Group, int] | None:
    m = _UNITLESS_WIND.fullmatch(tokens[i])
    if m is None:
        return None
    # Knots: the few real reports seen (HSPN 04014, HSDN 36020) match AWC's knot decode.
    return UnitlessWind(_make_wind(m["dir"], m["speed"], m["gust"], "KT")), 1


def _wind_sector(tokens: Sequence[str], i: int) -> tuple[Group, int] | None:
    m = _SECTOR.fullmatch(tokens[i])
    if m is None:
        return None
    lo, hi = float(m[1]), float(m[2])
    if lo > 360.0 or hi > 360.0:
        raise GroupValueError("variable wind sector beyond 360°")
    return WindSector(lo, hi), 1


_VIS_METRES = re.compile(r"[MP]?(\d{4})(NDV|N|NE|E|SE|S|SW|W|NW)?")
_VIS_SM = re.compile(r"[MP]?(?:(?P<num>\d{1,2})/(?P<den>\d{1,2})|(?P<whole>\d{1,3}))SM")
_VIS_FRACTION_SM = re.compile(r"(\d)/(\d{1,2})SM")
_VIS_KM = re.compile(r"(\d{1,3})KM")
_VIS_MISSING = frozenset({"////", "////SM", "////NDV", "////KM"})


def _statute_miles(m: re.Match[str]) -> float:
    if m["whole"] is not None:
        return float(m["whole"])
    num, den = int(m["num"]), int(m["den"])
    if den == 0:
        raise GroupValueError("visibility fraction with a zero denominator")
    if num > den and num >= 10:
        # "11/2SM" is a mixed number typed without its space (1 1/2), never 5.5 miles.
        return num // 10 + (num % 10) / den
    return num / den


def _checked_visibility(metres: float) -> float:
    if metres > MAX_VISIBILITY_M:
        raise GroupValueError(f"visibility {metres / 1000.0:.0f} km is above 1000 km")
    return metres


def _visibility(tokens: Sequence[str], i: int) -> tuple[Group, int] | None:
    tok = tokens[i]
    if tok == "CAVOK":
        return Visibility(TEN_KM, cavok=True), 1
    if tok in _VIS_MISSING:
        return Visibility(None), 1
    if m := _VIS_METRES.fullmatch(tok):
        metres = TEN_KM if m[1] == "9999" else float(m[1])
        return Visibility(metres, directional=m[2] not in (None, "NDV")), 1
    if m := _VIS_SM.fullmatch(tok):
        return Visibility(_checked_visibility(_statute_miles(m) * STATUTE_MILE_TO_M)), 1
    if m := _VIS_KM.fullmatch(tok):
        return Visibility(_checked_visibility(float(m[1]) * 1000.0)), 1
    if tok.isdigit() and len(tok) <= 2 and i + 1 < len(tokens):
        frac = _VIS_FRACTION_SM.fullmatch(tokens[i + 1])
        if frac is not None:
            den = int(frac[2])
            if den == 0:
                raise GroupValueError("visibility fraction with a zero denominator")
            miles = int(tok) + int(frac[1]) / den
            return Visibility(miles * STATUTE_MILE_TO_M), 2
    return None


_RVR = re.compile(r"R\d\d[LCR]?/[PM]?\d{4}(?:V[PM]?\d{4})?(?:FT)?(?:/?[UDN])?/?")
# Current (R24/290050, R99/CLRD//, R15//////) and pre-2013 (88290595, 88CLRD95) runway state.
_RUNWAY_STATE = re.compile(
    r"R\d\d[LCR]?/(?:[\d/]{4,6}|CLRD[\d/]{2}|SNOCLO|\d\d[UDN]?)|R/[\d/]{6,8}|R/SNOCLO|SNOCLO"
    r"|R\d\d[LCR]?/{5,6}|\d\d(?:[\d/]{6}|CLRD[\d/]{2})"
)


def _runway(tokens: Sequence[str], i: int) -> tuple[Group, int] | None:
    tok = tokens[i]
    if _RVR.fullmatch(tok):
        return RunwayVisualRange(tok), 1
    if _RUNWAY_STATE.fullmatch(tok):
        return Ignored("runway state"), 1
    return None


_WEATHER = re.compile(
    r"(?:[-+]|VC)?(?P<desc>MI|PR|BC|DR|BL|SH|TS|FZ)?"
    r"(?P<phen>(?:DZ|RA|SN|SG|IC|PL|GR|GS|UP|BR|FG|FU|VA|DU|SA|HZ|PY|PO|SQ|FC|SS|DS)*)"
)
_RECENT = re.compile(r"RE(?://|[A-Z]{2,8})")


def _weather(tokens: Sequence[str], i: int) -> tuple[Group, int] | None:
    tok = tokens[i]
    if tok == "//":
        return Ignored("present weather not observed"), 1
    if tok == "NSW":
        return Ignored("no significant weather"), 1
    m = _WEATHER.fullmatch(tok)
    if m is not None and (m["desc"] or m["phen"]):
        return Weather(tok), 1
    if _RECENT.fullmatch(tok) and (tok == "RE//" or _WEATHER.fullmatch(tok[2:])):
        return Ignored("recent weather"), 1
    return None


_SKY = re.compile(r"(?P<cover>FEW|SCT|BKN|OVC|///)(?P<height>\d{3}|///)(?P<type>CB|TCU|///)?")
_VERTICAL_VIS = re.compile(r"VV(\d{3}|///)")
_SKY_CLEAR = frozenset({"CLR", "SKC", "NSC", "NCD"})


def _hundreds_ft(text: str) -> float | None:
    return None if text == "///" else int(text) * 100.0 * FT_TO_M


def _sky(tokens: Sequence[str], i: int) -> tuple[Group, int] | None:
    tok = tokens[i]
    if tok in _SKY_CLEAR:
        return SkyClear(tok), 1
    if tok in ("CB", "TCU"):
        return DetachedCloudType(tok), 1
    if tok in ("///CB", "///TCU"):
        # French AUTO stations: a CB or TCU seen by radar, cover and height unknown.
        return MetarSkyGroup("///", None, cb=tok == "///CB", tcu=tok == "///TCU"), 1
    if m := _VERTICAL_VIS.fullmatch(tok):
        return MetarSkyGroup("VV", _hundreds_ft(m[1])), 1
    m = _SKY.fullmatch(tok)
    if m is None:
        return None
    if m["cover"] == "///" and m["height"] == "///" and m["type"] in (None, "///"):
        return Ignored("cloud not observed"), 1
    kind = m["type"]
    return MetarSkyGroup(m["cover"], _hundreds_ft(m["height"]), kind == "CB", kind == "TCU"), 1


_TEMP_VALUE = r"[M-]?\d{1,2}|//|XX|MM|M"  # M alone: US "missing"
_TEMPERATURES = re.compile(rf"(?P<t>{_TEMP_VALUE})/(?P<d>{_TEMP_VALUE})?")


def _celsius(text: str | None, what: str) -> float | None:
    if text is None or not text[-1].isdigit():
        return None
    # "+ 0.0" turns the -0.0 of "M00" into 0.0, so JSON and describe() never show "-0".
    value = (-float(text[1:]) if text[0] in "M-" else float(text)) + 0.0
    lo, hi = TEMPERATURE_RANGE_C
    if not lo <= value <= hi:
        raise GroupValueError(f"{what} {value:g} °C outside {lo:g}..{hi:g}")
    return value


def _temperatures(tokens: Sequence[str], i: int) -> tuple[Group, int] | None:
    m = _TEMPERATURES.fullmatch(tokens[i])
    if m is None:
        return None
    return Temperatures(_celsius(m["t"], "temperature"), _celsius(m["d"], "dewpoint")), 1


_QNH = re.compile(r"Q(?:NH)?(\d{4}|\d{3,4}\.\d)")
_ALTIMETER = re.compile(r"A(\d{4})")


def _checked_hpa(hpa: float) -> float:
    lo, hi = QNH_RANGE_HPA
    if not lo <= hpa <= hi:
        raise GroupValueError(f"QNH {hpa:.1f} hPa outside {lo:g}..{hi:g}")
    return hpa


def _pressure(tokens: Sequence[str], i: int) -> tuple[Group, int] | None:
    tok = tokens[i]
    if tok in ("Q////", "A////"):
        return Pressure(None, tok[0]), 1
    if m := _QNH.fullmatch(tok):
        return Pressure(_checked_hpa(float(m[1])), "Q"), 1
    if m := _ALTIMETER.fullmatch(tok):
        return Pressure(_checked_hpa(int(m[1]) / 100.0 * INHG_TO_HPA), "A"), 1
    return None


_SEA_STATE = re.compile(r"W(?:M?\d{1,2}|//)/(?:S[\d/]|H[\d/]{1,3})")
_RAINFALL = re.compile(r"RF[\d/.]+/[\d/.]+")
_COLOUR = re.compile(r"(?:(?:BLACK)?(?:BLU|WHT|GRN|YLO[12]?|AMB|RED)\+?)+")
_QFE = re.compile(r"QFE\d{3,4}(?:\.\d)?(?:/\d{3,4})?")
_WIND_SHEAR_RUNWAY = re.compile(r"R\d\d[LCR]?|RWY\d\d[LCR]?")


def _supplementary(tokens: Sequence[str], i: int) -> tuple[Group, int] | None:
    """Regional and supplementary groups we recognise but do not use."""
    tok = tokens[i]
    if tok == "M":
        return Ignored("missing value"), 1
    if tok == "///":
        return Ignored("group not observed"), 1
    if _SEA_STATE.fullmatch(tok):
        return Ignored("sea state"), 1
    if _RAINFALL.fullmatch(tok) or re.fullmatch(r"RH\d{2,3}", tok):
        return Ignored("regional supplementary group"), 1
    if _COLOUR.fullmatch(tok):
        return Ignored("aerodrome colour state"), 1
    if _QFE.fullmatch(tok):
        return Ignored("QFE"), 1
    if tok == "QFE" and i + 1 < len(tokens) and re.fullmatch(r"\d{3,4}(?:\.\d)?", tokens[i + 1]):
        return Ignored("QFE"), 2
    if tok == "WS":
        # WS R27 / WS ALL RWY: swallow the runway designator so it is not an unknown group.
        n = 1
        if tokens[i + 1 : i + 3] == ["ALL", "RWY"]:
            n = 3
        elif i + 1 < len(tokens) and _WIND_SHEAR_RUNWAY.fullmatch(tokens[i + 1]):
            n = 2
        return Ignored("wind shear"), n
    return None


def _flag(tokens: Sequence[str], i: int) -> tuple[Group, int] | None:
    name = flag_name(tokens[i])
    return None if name is None else (Flag(name), 1)


# Order matters only where shapes overlap: `////` is visibility before it could be anything
# else, and bare `///` must not reach the temperature pattern (it would read as "//" + "/").
_RECOGNISERS: tuple[Recogniser, ...] = (
    _flag,
    _wind,
    _wind_sector,
    _visibility,
    _runway,
    _sky,
    _supplementary,
    _weather,
    _temperatures,
    _pressure,
    _unitless_wind,
)


def parse_group(tokens: Sequence[str], i: int) -> tuple[Group, int] | None:
    """The group starting at tokens[i] and the number of tokens it spans, or None if unknown.

    Raises GroupValueError when the token is a known group with an impossible value.
    """
    if len(tokens[i]) > MAX_GROUP_CHARS:
        return None
    for recognise in _RECOGNISERS:
        found = recognise(tokens, i)
        if found is not None:
            return found
    return None


def unknown_reason(token: str) -> str:
    """A short guess at what a token that no recogniser took was meant to be."""
    if re.search(r"(KT|MPS|KMH)$", token):
        return "malformed wind group"
    if token.endswith("SM"):
        return "malformed visibility group"
    if re.match(r"(FEW|SCT|BKN|OVC|VV)", token):
        return "malformed cloud group"
    if re.match(r"[QA]\d", token):
        return "malformed pressure group"
    if "/" in token and re.fullmatch(r"[M\d/]+", token):
        return "malformed temperature group"
    return "unrecognised group"


_REMARK_TEMPERATURES = re.compile(r"T([01])(\d{3})(?:([01])(\d{3})|////)?")


def remark_temperatures(remarks: Sequence[str]) -> tuple[float | None, float | None] | None:
    """Temperature and dewpoint in tenths from a North American `T01830117` remark, if any."""
    for token in remarks:
        m = _REMARK_TEMPERATURES.fullmatch(token)
        if m is not None:
            t = _signed_tenths(m[1], m[2])
            return t, None if m[3] is None else _signed_tenths(m[3], m[4])
    return None


def _signed_tenths(sign: str, digits: str) -> float:
    return (-1.0 if sign == "1" else 1.0) * int(digits) / 10.0 + 0.0
