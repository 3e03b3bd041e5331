"""METAR group shapes and values: the tokenizer that `wxsky.weather.metar` runs on.

A body token is classified in at most two steps: tokens that are always the same text (`CAVOK`,
`NSC`, `AUTO`, `////`...) are looked up in `FIXED_GROUPS`; every other shape is one alternative
of the single compiled expression `BODY_GROUP`, whose top-level named groups (`GROUP_PATTERNS`,
tried in order) say what the token is through `match.lastgroup` (mapped back to a kind name by
`KIND_OF_GROUP`). Matching a token once instead of once per group kind is what keeps the
decoder faster than python-metar (see docs/metar-decoder.md); the decoder has one handler per
kind name.

The value functions turn a match into SI values. A token that has the shape of a group but an
impossible value (wind 300 kt, QNH 99 hPa) raises `GroupValueError`, which the decoder turns into
an error line naming the group; that is the only exception a value function raises on purpose,
and the decoder treats any other as a defect of its own. Heights are above ground level (AGL).

Every pattern spells digits as `[0-9]` and letters as `[A-Z]`: `\\d` would accept other scripts'
digits, which `int()` then reads, so a report in Arabic-Indic digits could decode.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import MINYEAR, UTC, datetime, timedelta

from wxsky.units import FT_TO_M, INHG_TO_HPA, KMH_TO_MPS, KT_TO_MPS, STATUTE_MILE_TO_M, mps_to_kt

MAX_WIND_KT = 250.0
MAX_DIRECTION_DEG = 360.0
MAX_VISIBILITY_M = 1_000_000.0  # the weather state's limit; METAR never comes close
# The longest real body group is about 20 characters; longer tokens skip the regex entirely.
MAX_GROUP_CHARS = 40
TEMPERATURE_RANGE_C = (-70.0, 70.0)
ALTIMETER_RANGE_HPA = (850.0, 1100.0)
# ICAO's 9999 means "10 km or more"; we report the floor, as CAVOK does.
TEN_KM = 10_000.0


class GroupValueError(ValueError):
    """A token has the shape of a known group but an impossible value; the message says which."""


@dataclass(frozen=True, slots=True)
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


@dataclass(frozen=True, slots=True)
class MetarSkyGroup:
    """One cloud group. cover is FEW/SCT/BKN/OVC, VV (obscured) or /// (cover not observed)."""

    cover: str
    base_m: float | None  # AGL; None when the height was reported as ///
    cb: bool = False
    tcu: bool = False


# --- header -----------------------------------------------------------------------------------

STATION = re.compile(r"[A-Z][A-Z0-9]{3}")
# The Z is optional: right after the station, six digits can only be the time.
TIME = re.compile(r"([0-9]{2})([0-9]{2})([0-9]{2})Z?")
REPORT_TYPES = frozenset({"METAR", "SPECI"})
_FLAG_WORD = r"(?:AUTO|CORR?|CC[A-G]) "
# The header as nearly every report writes it, matched on the space-joined tokens in one go;
# anything else (missing station, odd time group) takes the token-by-token path.
COMMON_HEADER = re.compile(
    rf"(?P<header>(?:(?P<type>METAR|SPECI) )?(?P<flags>(?:{_FLAG_WORD})*)"
    rf"(?P<station>[A-Z][A-Z0-9]{{3}}) (?P<flags2>(?:{_FLAG_WORD})*)"
    r"(?P<day>[0-9]{2})(?P<hour>[0-9]{2})(?P<minute>[0-9]{2})Z)(?: |$)"
)


def parse_time(token: str) -> tuple[int, int, int] | None:
    """(day, hour, minute) of a token shaped like a ddhhmmZ group, as written, or None.

    The values are not checked: `time_problem` says whether they name a time at all, and
    `time_in_month` or `latest_time` date them.
    """
    m = TIME.fullmatch(token)
    if m is None:
        return None
    return int(m[1]), int(m[2]), int(m[3])


def time_problem(day: int, hour: int, minute: int) -> str | None:
    """Why a ddhhmm value names no time in any month, or None.

    Hour 24 and minute 60 are not problems here: real stations send them for the next day's
    00 hours and the next hour's 00 minutes, and `time_in_month` reads them so (`rolls_over`).
    """
    if not 1 <= day <= 31:
        return f"day {day:02d} is not a day of any month"
    if hour > 24 or minute > 60:
        return f"{hour:02d}:{minute:02d} is not a UTC time"
    return None


def rolls_over(hour: int, minute: int) -> bool:
    """True for the out-of-range but readable times: hour 24, minute 60."""
    return hour == 24 or minute == 60


def time_in_month(year: int, month: int, day: int, hour: int, minute: int) -> datetime | None:
    """The UTC time of a ddhhmm value (checked by `time_problem`) in one month; None when that
    month has no such day or is not a calendar month. Hour 24 and minute 60 roll over."""
    try:
        if hour < 24 and minute < 60:  # the usual case, without the timedelta
            return datetime(year, month, day, hour, minute, tzinfo=UTC)
        return datetime(year, month, day, tzinfo=UTC) + timedelta(hours=hour, minutes=minute)
    except (ValueError, OverflowError):
        return None


# Enough months to find any day: 29 February can be eight years from the last one (2096, 2104).
_LOOKBACK_MONTHS = 12 * 9


def latest_time(
    day: int,
    hour: int,
    minute: int,
    now_utc: datetime,
    *,
    year: int | None = None,
    month: int | None = None,
) -> datetime | None:
    """The latest time of a ddhhmm value (checked by `time_problem`) that is not after `now_utc`,
    in the given year and/or month where one is given; None when there is none.

    The whole timestamp decides, not the day alone: at 2026-12-01 00:10, `012350Z` is
    2026-11-01 23:50, `302400Z` is 2026-12-01 00:00, and `310000Z` is 2026-10-31 00:00.
    """
    y, m = now_utc.year, now_utc.month
    for _ in range(_LOOKBACK_MONTHS):
        if year is not None and y < year:
            break
        if (year is None or y == year) and (month is None or m == month):
            time = time_in_month(y, m, day, hour, minute)
            if time is not None and time <= now_utc:
                return time
        y, m = (y, m - 1) if m > 1 else (y - 1, 12)
        if y < MINYEAR:
            break
    return None


def looks_like_time(token: str) -> bool:
    return TIME.fullmatch(token) is not None


def starts_report(token: str, next_token: str) -> bool:
    """A station followed by a time group with its Z: a report glued onto the one before."""
    # Cheap length checks first: this runs for every 4-character body token.
    return (
        len(next_token) == 7
        and next_token[-1] == "Z"
        and STATION.fullmatch(token) is not None
        and TIME.fullmatch(next_token) is not None
    )


# --- body groups ------------------------------------------------------------------------------

# Tokens that are always spelled the same, and the kind the decoder dispatches on.
FIXED_GROUPS: dict[str, str] = {
    "METAR": "report_type",  # in the body: a second report glued on
    "SPECI": "report_type",
    "CAVOK": "cavok",
    **dict.fromkeys(("CLR", "SKC", "NSC", "NCD"), "sky_clear"),
    "AUTO": "auto",
    **dict.fromkeys(("COR", "CORR", "CCA", "CCB", "CCC", "CCD", "CCE", "CCF", "CCG"), "cor"),
    "NIL": "nil",
    "RTD": "ignored",  # a late report: nothing about the weather changes
    # Not observed / nothing significant: recognised so they are not errors; they carry nothing.
    **dict.fromkeys(("NSW", "//", "///", "M", "SNOCLO", "R/SNOCLO"), "ignored"),
    **dict.fromkeys(("////", "////SM", "////NDV", "////KM"), "visibility_missing"),
    **dict.fromkeys(("Q////", "A////"), "pressure_missing"),
    **dict.fromkeys(("CB", "TCU"), "detached_cloud_type"),
    # French AUTO stations: a CB or TCU seen by radar, cover and height unknown.
    **dict.fromkeys(("///CB", "///TCU"), "unknown_cover_type"),
    "WS": "wind_shear",
    "QFE": "qfe_word",
    "RMK": "remarks",
    **dict.fromkeys(("NOSIG", "N0SIG", "BECMG", "TEMPO", "INTER"), "trend"),
}

_WEATHER_DESCRIPTOR = "MI|PR|BC|DR|BL|SH|TS|FZ"
_WEATHER_PHENOMENON = "DZ|RA|SN|SG|IC|PL|GR|GS|UP|BR|FG|FU|VA|DU|SA|HZ|PY|PO|SQ|FC|SS|DS"

# (kind, pattern): one alternative of BODY_GROUP each. Inner group names are unique across the
# table because they all live in one expression. Order matters only where shapes overlap:
# `//////` must be a cloud group before the temperature pattern sees it, and the trend and
# colour words must be recognised before the weather pattern tries them.
GROUP_PATTERNS: tuple[tuple[str, str], ...] = (
    (
        "wind",
        r"(?P<wind_dir>[0-9]{3}|VRB|///)(?P<wind_speed>P?[0-9]{2,3}|//)"
        r"(?:G(?P<wind_gust>P?[0-9]{2,3}|//))?(?P<wind_unit>KTS?|MPS|KMH)",
    ),
    ("wind_sector", r"(?P<sector_from>[0-9]{3})V(?P<sector_to>[0-9]{3})"),
    # "4000M": some stations spell out the metres.
    ("visibility_m", r"[MP]?(?P<vis_m>[0-9]{4})M?(?P<vis_dir>NDV|NE|NW|SE|SW|N|E|S|W)?"),
    (
        "visibility_sm",
        r"[MP]?(?:(?P<sm_num>[0-9]{1,2})/(?P<sm_den>[0-9]{1,2})|(?P<sm_whole>[0-9]{1,3}))SM",
    ),
    ("visibility_km", r"(?P<vis_km>[0-9]{1,3})KM"),
    ("whole_number", r"[0-9]{1,2}"),  # "1" of "1 1/2SM"
    ("rvr", r"R[0-9]{2}[LCR]?/[PM]?[0-9]{4}(?:V[PM]?[0-9]{4})?(?:FT)?(?:/?[UDN])?/?"),
    # Current (R24/290050, R99/CLRD//, R15//////) and pre-2013 (88290595, 88CLRD95) runway state.
    (
        "runway_state",
        r"R[0-9]{2}[LCR]?/(?:[0-9/]{4,6}|CLRD[0-9/]{2}|SNOCLO|[0-9]{2}[UDN]?)|R/[0-9/]{6,8}"
        r"|R[0-9]{2}[LCR]?/{5,6}|[0-9]{2}(?:[0-9/]{6}|CLRD[0-9/]{2})",
    ),
    (
        "sky",
        r"(?P<sky_cover>FEW|SCT|BKN|OVC|///)(?P<sky_height>[0-9]{3}|///|-[0-9]{1,3})"
        r"(?P<sky_type>CB|TCU|///)?",
    ),
    ("vertical_visibility", r"VV(?P<vv_height>[0-9]{3}|///)"),
    ("trend", r"FM[0-9]{4}(?:[0-9]{2})?|PROB[34]0"),
    # Dutch and UK military colour states (BLU, WHT, GRN, YLO1/2, AMB, RED, BLACK prefix) close
    # the body: what follows them is the colour forecast, never body weather.
    ("trend", r"(?:(?:BLACK)?(?:BLU|WHT|GRN|YLO[12]?|AMB|RED)\+?)+"),
    (
        "recent_weather",
        rf"RE(?://|(?:{_WEATHER_DESCRIPTOR})?(?:{_WEATHER_PHENOMENON})+|(?:{_WEATHER_DESCRIPTOR}))",
    ),
    (
        "weather",
        rf"(?:[-+]|VC)?(?P<wx_descriptor>{_WEATHER_DESCRIPTOR})?"
        rf"(?P<wx_phenomena>(?:{_WEATHER_PHENOMENON})*)",
    ),
    (
        "temperatures",
        r"(?P<temp>[M-]?[0-9]{1,2}|//|XX|MM|M)/(?P<dew>[M-]?[0-9]{1,2}|//|XX|MM|M)?",
    ),
    ("qnh", r"Q(?:NH)?(?P<qnh>[0-9]{4}|[0-9]{3,4}\.[0-9])"),
    ("altimeter", r"A(?P<altimeter>[0-9]{4})"),
    ("ignored", r"W(?:M?[0-9]{1,2}|//)/(?:S[0-9/]|H[0-9/]{1,3})"),  # sea state
    ("ignored", r"RF[0-9/.]+/[0-9/.]+|RH[0-9]{2,3}"),  # Australian rainfall, humidity
    ("ignored", r"QFE[0-9]{3,4}(?:\.[0-9])?(?:/[0-9]{1,4})?"),
    # Central American cloud location (CB/NE/E, TCU/N/W, CB/PCPN/SMC): where, not what.
    ("ignored", r"(?:CB|TCU)(?:/[A-Z0-9]+)+/?"),
    (
        "unitless_wind",
        r"(?P<uwind_dir>[0-9]{3})(?P<uwind_speed>[0-9]{2})(?:G(?P<uwind_gust>[0-9]{2}))?",
    ),
)


def _body_expression(patterns: Sequence[tuple[str, str]]) -> re.Pattern[str]:
    # A kind may have several rows; the regex needs unique names, so later rows get a suffix
    # that KIND_OF_GROUP maps back.
    parts = []
    for index, (kind, pattern) in enumerate(patterns):
        parts.append(f"(?P<{kind}__{index}>{pattern})")
    return re.compile("|".join(parts))


BODY_GROUP = _body_expression(GROUP_PATTERNS)
KIND_OF_GROUP: dict[str, str] = {
    f"{kind}__{index}": kind for index, (kind, _) in enumerate(GROUP_PATTERNS)
}

# "KTS" is a common manual-station spelling of KT.
_WIND_UNIT_MPS = {"KT": KT_TO_MPS, "KTS": KT_TO_MPS, "MPS": 1.0, "KMH": KMH_TO_MPS}
_WIND_SHEAR_RUNWAY = re.compile(r"R[0-9]{2}[LCR]?|RWY[0-9]{2}[LCR]?")
_QFE_VALUE = re.compile(r"[0-9]{3,4}(?:\.[0-9])?")
_REMARK_TEMPERATURES = re.compile(r"T([01])([0-9]{3})(?:([01])([0-9]{3})|////)?")


# --- values -----------------------------------------------------------------------------------


def _wind_speed_mps(text: str, unit: str, what: str) -> float:
    speed_mps = float(text.lstrip("P")) * _WIND_UNIT_MPS[unit]
    speed_kt = mps_to_kt(speed_mps)
    if speed_kt > MAX_WIND_KT:
        raise GroupValueError(f"{what} {speed_kt:.0f} kt is above {MAX_WIND_KT:.0f} kt")
    return speed_mps


def wind(
    direction: str, speed: str, gust: str | None, unit: str
) -> tuple[MetarWind | None, list[str]]:
    """The wind of one group and the problems found in it, field by field.

    Raises GroupValueError when the speed itself is impossible: without a speed there is no wind.
    Returns None for a group whose speed was not observed (`/////KT`).
    """
    if speed == "//":
        return None, []
    problems = []
    dir_deg: float | None = None
    if direction.isdigit():
        dir_deg = float(direction)
        if dir_deg > MAX_DIRECTION_DEG:
            problems.append(f"wind direction {direction}° is above 360°; direction left out")
            dir_deg = None
    speed_mps = _wind_speed_mps(speed, unit, "wind speed")
    gust_mps = None
    if gust is not None and gust != "//":
        try:
            gust_mps = _wind_speed_mps(gust, unit, "gust")
        except GroupValueError as e:
            problems.append(f"{e}; gust left out")
    wind_value = MetarWind(dir_deg, direction == "VRB", speed_mps, gust_mps)
    return wind_value, problems


def wind_sector(m: re.Match[str]) -> tuple[float, float]:
    lo, hi = float(m["sector_from"]), float(m["sector_to"])
    if lo > MAX_DIRECTION_DEG or hi > MAX_DIRECTION_DEG:
        raise GroupValueError("variable wind sector beyond 360°")
    return lo, hi


def visibility_metres(m: re.Match[str]) -> float:
    digits = m["vis_m"]
    return TEN_KM if digits == "9999" else float(digits)


def _checked_visibility(metres: float) -> float:
    if metres > MAX_VISIBILITY_M:
        raise GroupValueError(f"visibility {metres / 1000.0:.0f} km is above 1000 km")
    return metres


def _fraction(num: str, den: str) -> float:
    n, d = int(num), int(den)
    if d == 0:
        raise GroupValueError("visibility fraction with a zero denominator")
    if n > d and n >= 10:
        # "11/2SM" is a mixed number typed without its space (1 1/2), never 5.5 miles.
        return n // 10 + (n % 10) / d
    return n / d


def visibility_statute_miles(m: re.Match[str]) -> float:
    """Metres of an SM group; an M (less than) or P (more than) prefix gives the bound itself."""
    whole = m["sm_whole"]
    miles = float(whole) if whole is not None else _fraction(m["sm_num"], m["sm_den"])
    return _checked_visibility(miles * STATUTE_MILE_TO_M)


def visibility_kilometres(m: re.Match[str]) -> float:
    return _checked_visibility(float(m["vis_km"]) * 1000.0)


_VIS_FRACTION_SM = re.compile(r"([0-9])/([0-9]{1,2})SM")


def mixed_statute_miles(whole: str, next_token: str) -> float | None:
    """Metres of `1 1/2SM` split over two tokens, or None when the next token is no fraction."""
    frac = _VIS_FRACTION_SM.fullmatch(next_token)
    if frac is None:
        return None
    return _checked_visibility((int(whole) + _fraction(frac[1], frac[2])) * STATUTE_MILE_TO_M)


def sky_group(m: re.Match[str]) -> MetarSkyGroup | None:
    """The cloud group, or None for `//////` (cover and height both unobserved)."""
    cover, height, kind = m["sky_cover"], m["sky_height"], m["sky_type"]
    if cover == "///" and height == "///" and kind in (None, "///"):
        return None
    return MetarSkyGroup(cover, hundreds_of_feet_m(height), kind == "CB", kind == "TCU")


def hundreds_of_feet_m(text: str) -> float | None:
    if text == "///":
        return None
    hundreds = int(text)
    if hundreds < 0:
        raise GroupValueError(f"cloud base {hundreds * 100} ft is below the ground")
    return hundreds * 100.0 * FT_TO_M


def celsius(text: str | None, what: str) -> float | None:
    """A temperature value (`M05`, `23`), None when missing. Raises when out of range."""
    if text is None or not text[-1].isdigit():
        return None
    # "+ 0.0" turns the -0.0 of "M00" into 0.0, so JSON and describe() never show "-0".
    value = (-float(text[1:]) if text[0] in "M-" else float(text)) + 0.0
    lo, hi = TEMPERATURE_RANGE_C
    if not lo <= value <= hi:
        raise GroupValueError(f"{what} {value:g} °C outside {lo:g}..{hi:g}")
    return value


def _checked_hpa(hpa: float) -> float:
    lo, hi = ALTIMETER_RANGE_HPA
    if not lo <= hpa <= hi:
        raise GroupValueError(f"altimeter {hpa:.1f} hPa outside {lo:g}..{hi:g}")
    return hpa


def qnh_hpa(m: re.Match[str]) -> float:
    return _checked_hpa(float(m["qnh"]))


def altimeter_hpa(m: re.Match[str]) -> float:
    return _checked_hpa(int(m["altimeter"]) / 100.0 * INHG_TO_HPA)


def wind_shear_tokens(tokens: Sequence[str], i: int) -> int:
    """How many tokens a `WS` group spans: `WS R27`, `WS ALL RWY` or a bare `WS`."""
    if tokens[i + 1 : i + 3] == ["ALL", "RWY"]:
        return 3
    if i + 1 < len(tokens) and _WIND_SHEAR_RUNWAY.fullmatch(tokens[i + 1]):
        return 2
    return 1


def qfe_tokens(tokens: Sequence[str], i: int) -> int:
    """`QFE 871.6` written as two tokens: 2, else 0 (a bare QFE is not a group)."""
    if i + 1 < len(tokens) and _QFE_VALUE.fullmatch(tokens[i + 1]):
        return 2
    return 0


def unknown_reason(token: str) -> str:
    """A short guess at what a token that matched no group was meant to be."""
    if not (token.isascii() and token.isprintable()):
        return "non-ASCII or control character; group skipped"
    if token.endswith(("KT", "KTS", "MPS", "KMH")):
        return "malformed wind group"
    if token.endswith("SM"):
        return "malformed visibility group"
    if token.startswith(("FEW", "SCT", "BKN", "OVC", "VV")):
        return "malformed cloud group"
    if len(token) > 1 and token[0] in "QA" and token[1].isdigit():
        return "malformed pressure group"
    if "/" in token and not token.strip("M0123456789/"):
        return "malformed temperature group"
    return "unrecognised group"


def remark_temperatures(remarks: Sequence[str]) -> tuple[float | None, float | None] | None:
    """Temperature and dewpoint in tenths from a North American `T01830117` remark, if any."""
    for token in remarks:
        if token[:1] != "T":
            continue
        m = _REMARK_TEMPERATURES.fullmatch(token)
        if m is not None:
            t = _signed_tenths(m[1], m[2])
            return t, None if m[3] is None else _signed_tenths(m[3], m[4])
    return None


def _signed_tenths(sign: str, digits: str) -> float:
    return (-1.0 if sign == "1" else 1.0) * int(digits) / 10.0 + 0.0
