"""Decode one METAR/SPECI report into SI values: `decode(report, year=, month=) -> Metar`.

Grammar: the text is cut at the first `=` (the WMO end-of-report mark) and split on whitespace.
An optional `METAR`/`SPECI` word, the station (4 characters, a letter first) and the `ddhhmmZ`
time group form the header; `COR`, `CCx` and `AUTO` may stand anywhere before the remarks. The
body runs up to `RMK` (the rest is `remarks`) or the first trend group (`NOSIG`, `BECMG`,
`TEMPO`, `INTER`, `FMhhmm`, `PROBnn`, or a military colour state such as `YLO`); the trend is
kept verbatim in `trend` and never decoded into body fields. Body groups are recognised by shape,
in any order (`metar_groups`); the first group of a kind wins, so a stray group later in the
report can never overwrite a value.

Error policy: `decode` never raises on any text. Whatever cannot be decoded becomes one line in
`errors` (naming the group: `group 5 'FEW02': malformed cloud group`) and `partial` is true:

* no station group (`station` None; the body is still decoded: VATSIM-style text can lack it);
* no time group (`time_group` and `time_utc` None; nothing after the header is decoded, because
  without the time the text is most likely not a report at all: `PART 1 OF 2`, bulletin junk);
* a time group whose time is impossible: day 0 or above 31, hour above 24, minute above 60, or a
  day the month does not have (`time_utc` None, `time_group` kept, the body decoded);
* a time group with hour 24 or minute 60, which real stations send: it rolls over (`262400Z` is
  27th 00:00, `261560Z` is 26th 16:00) and the error line says how it was read;
* an unknown or garbled body group (skipped), a duplicate group (the first wins);
* an out-of-range value, field by field: wind above 250 kt (the wind), gust above 250 kt (the
  gust), direction above 360° (the direction), temperature or dewpoint outside ±70 °C (that
  value), altimeter outside 850..1100 hPa, a negative cloud base (that group);
* a second report glued onto the first (the rest is ignored).

Callers that need a report to act on call `Metar.require_usable()`, which raises `MetarError`
when the station or time is missing or the report is NIL.

A defect of the decoder itself (any exception but the `GroupValueError` a value function raises
on purpose for an impossible value) is never turned into an error line: it propagates as
`MetarInternalError`, naming the group and the report, with the original exception as its
cause. Otherwise a crashing group handler would look like one more garbled group, and the fuzz
and corpus tests, which check that decoding never raises, could not catch it.

Dates: the report names only the day. With `year` and `month` (from the feed, or the simulated
time) the report is in that month, and a day that month lacks leaves the time unknown. Without
them the report is in the latest month that puts its whole timestamp (day, hour and minute) at
or before `now_utc` (the clock by default), never in the future: at 2026-12-01 00:10 UTC,
`302350Z` is 2026-11-30 23:50, `312350Z` 2026-10-31 23:50 (November has no 31st), and
`012350Z` 2026-11-01 23:50 (1 December 23:50 has not happened yet). With only one of `year` and
`month`, the other is chosen by the same rule.

Value conventions: `9999` and CAVOK mean 10 km; `M` (less than) and `P` (more than) visibility
and wind prefixes give the bound itself; a wind group without a unit (`04014`) is read as knots,
wherever the station is; cloud bases are above ground level (AGL). A North American
`Tsttt[sddd]` remark refines temperature and dewpoint to tenths where it agrees with the body
group to within 1 °C (as AWC's own decode does); no other remark is decoded.
"""

from __future__ import annotations

import calendar
import dataclasses
import re
from collections.abc import Callable
from dataclasses import dataclass
from datetime import MAXYEAR, MINYEAR, UTC, datetime
from typing import Any, Literal

from wxsky.errors import MetarError
from wxsky.units import FT_TO_M, mps_to_kt
from wxsky.weather import metar_groups as g
from wxsky.weather.metar_groups import MetarSkyGroup, MetarWind

__all__ = ["Metar", "MetarInternalError", "MetarSkyGroup", "MetarWind", "decode"]

# A megabyte of garbage would otherwise give a megabyte of error lines.
MAX_ERRORS = 40
# Q and A groups in one report that differ by more than this are reported as inconsistent.
PRESSURE_AGREEMENT_HPA = 2.0
# Digits of the knot values in to_dict: enough to give back the reported integer exactly.
KT_DIGITS = 6


class MetarInternalError(RuntimeError):
    """A defect in the decoder, never a property of the report: see the module docstring.

    Not a WxskyError or ValueError on purpose, so that no caller reports it as bad input.
    """


@dataclass(frozen=True)
class Metar:
    """One decoded report. Values are SI; None means the report did not give the value."""

    raw: str  # the report text up to '=', whitespace collapsed
    station: str | None = None
    time_utc: datetime | None = None
    type: Literal["METAR", "SPECI"] = "METAR"
    auto: bool = False
    cor: bool = False
    nil: bool = False  # "NIL": the station sent no observation
    errors: tuple[str, ...] = ()
    wind: MetarWind | None = None
    visibility_m: float | None = None
    # The directional minimum (`9999 4000SE`): the lowest visibility in one sector, never the
    # prevailing value. Direction None when the group gave none.
    min_visibility_m: float | None = None
    min_visibility_dir: str | None = None
    cavok: bool = False
    rvr: tuple[str, ...] = ()  # runway visual range groups, verbatim
    weather: tuple[str, ...] = ()
    sky: tuple[MetarSkyGroup, ...] = ()
    sky_clear: str | None = None  # CLR, SKC, NSC or NCD; None also when there is no sky group
    temperature_c: float | None = None
    dewpoint_c: float | None = None
    altimeter_hpa: float | None = None
    trend: str = ""
    remarks: str = ""
    # The ddhhmmZ group as written, also when its time is impossible (then time_utc is None):
    # it tells a report with a broken time from text that is no report at all.
    time_group: str | None = None

    @property
    def partial(self) -> bool:
        """True when some group could not be decoded; `errors` says which."""
        return bool(self.errors)

    @property
    def observes_nothing(self) -> bool:
        """True when no group after the header gave a value: a report cut off after its time
        (`LSZH 011731Z` from a file caught half-written) or only `AUTO`, `COR`, a trend or
        remarks. Applied, it would say "no clouds, no wind", which the station never said."""
        return not (
            self.wind
            or self.visibility_m is not None
            or self.min_visibility_m is not None
            or self.cavok
            or self.rvr
            or self.weather
            or self.sky
            or self.sky_clear
            or self.temperature_c is not None
            or self.dewpoint_c is not None
            or self.altimeter_hpa is not None
        )

    def require_usable(self) -> Metar:
        """This report, or MetarError (one line) when it names no station or time, or is NIL."""
        where = f"METAR {self.station}" if self.station else "METAR report"
        detail = f" ({self.errors[0]})" if self.errors else ""
        if self.station is None:
            raise MetarError(f"{where}: no station group{detail}")
        if self.time_utc is None:
            raise MetarError(f"{where}: no valid observation time{detail}")
        if self.nil:
            raise MetarError(f"{where}: NIL report, the station sent no observation")
        return self

    def to_dict(self) -> dict[str, Any]:
        """The report as JSON-ready data, in aviation units (kt, ft) as the report gives them."""
        wind = None
        if self.wind is not None:
            w = self.wind
            wind = {
                "dir_deg": w.dir_from_deg,
                "speed_kt": _kt(w.speed_mps),
                "gust_kt": None if w.gust_mps is None else _kt(w.gust_mps),
                "var_from_deg": w.variable_from_deg,
                "var_to_deg": w.variable_to_deg,
                "variable": w.variable,
            }
        return {
            "raw": self.raw,
            "station": self.station,
            "time_utc": None
            if self.time_utc is None
            else f"{_day(self.time_utc)}T{self.time_utc:%H:%M}:00Z",
            "time_group": self.time_group,
            "type": self.type,
            "auto": self.auto,
            "cor": self.cor,
            "nil": self.nil,
            "partial": self.partial,
            "errors": list(self.errors),
            "wind": wind,
            "visibility_m": self.visibility_m,
            "min_visibility_m": self.min_visibility_m,
            "min_visibility_dir": self.min_visibility_dir,
            "cavok": self.cavok,
            "rvr": list(self.rvr),
            "weather": list(self.weather),
            "clouds": [
                {
                    "cover": s.cover,
                    "base_ft_agl": None if s.base_m is None else round(s.base_m / FT_TO_M),
                    "type": "CB" if s.cb else "TCU" if s.tcu else None,
                }
                for s in self.sky
            ],
            "sky_clear": self.sky_clear,
            "temperature_c": self.temperature_c,
            "dewpoint_c": self.dewpoint_c,
            "altimeter_hpa": self.altimeter_hpa,
            "trend": self.trend,
            "remarks": self.remarks,
        }

    def describe(self) -> str:
        """A few human-readable lines for the CLI."""
        flags = " ".join(f for f, on in (("AUTO", self.auto), ("COR", self.cor)) if on)
        when = (
            "time n/a" if self.time_utc is None else f"{_day(self.time_utc)} {self.time_utc:%H:%MZ}"
        )
        head = f"{self.type} {self.station or '(no station)'} {when}"
        lines = [f"{head} {flags}".rstrip()]
        if self.nil:
            lines.append("  no observation (NIL)")
        else:
            lines += [
                f"  wind        {_describe_wind(self.wind)}",
                f"  visibility  {_describe_visibility(self)}",
                f"  weather     {' '.join(self.weather) or 'none'}",
                f"  sky         {_describe_sky(self)}",
                f"  temp/dew    {_opt(self.temperature_c, '°C')} / {_opt(self.dewpoint_c, '°C')}",
                f"  altimeter   {_opt(self.altimeter_hpa, 'hPa', 1)}",
            ]
        if self.trend:
            lines.append(f"  trend       {self.trend}")
        if self.remarks:
            lines.append(f"  remarks     {self.remarks}")
        lines += [f"  error: {e}" for e in self.errors]
        return "\n".join(lines)


def _kt(speed_mps: float) -> float:
    return round(mps_to_kt(speed_mps), KT_DIGITS)


def _opt(value: float | None, unit: str, digits: int = 0) -> str:
    return "n/a" if value is None else f"{value:.{digits}f} {unit}"


def _describe_wind(w: MetarWind | None) -> str:
    if w is None:
        return "n/a"
    if w.calm:
        return "calm"
    if w.dir_from_deg is not None:
        direction = f"{w.dir_from_deg:03.0f}°"
    else:
        direction = "variable" if w.variable else "direction unknown"
    text = f"{direction} {w.speed_mps:.1f} m/s ({mps_to_kt(w.speed_mps):.0f} kt)"
    if w.gust_mps is not None:
        text += f" gusting {w.gust_mps:.1f} m/s"
    if w.variable_from_deg is not None and w.variable_to_deg is not None:
        text += f", varying {w.variable_from_deg:03.0f}°-{w.variable_to_deg:03.0f}°"
    return text


def _describe_visibility(r: Metar) -> str:
    if r.cavok:
        return "CAVOK (10 km or more, no cloud below 1500 m, no CB)"
    text = _opt(r.visibility_m, "m")
    if r.min_visibility_m is not None:
        text += f", minimum {r.min_visibility_m:.0f} m {r.min_visibility_dir or ''}".rstrip()
    return text


def _describe_sky(r: Metar) -> str:
    if r.cavok:
        return "CAVOK"
    parts = [_describe_sky_group(s) for s in r.sky]
    if r.sky_clear:
        parts.append(r.sky_clear)
    return ", ".join(parts) or "n/a"


def _describe_sky_group(s: MetarSkyGroup) -> str:
    base = "base n/a" if s.base_m is None else f"{s.base_m:.0f} m ({s.base_m / FT_TO_M:.0f} ft)"
    kind = " CB" if s.cb else " TCU" if s.tcu else ""
    return f"{s.cover} {base}{kind}"


# --- decoding ---------------------------------------------------------------------------------


def _day(t: datetime) -> str:
    # The year padded by hand: strftime writes year 857 as `857`, which is not ISO 8601.
    return f"{t.year:04d}-{t:%m-%d}"


def decode(
    report: str,
    *,
    year: int | None = None,
    month: int | None = None,
    now_utc: datetime | None = None,
) -> Metar:
    """Decode one report; never raises on any text (see the module docstring for the error
    policy), but a defect of the decoder raises MetarInternalError.

    year and month are those the feed says the report belongs to, where it says so: the report
    itself carries only the day. Without them the report is dated at the latest time not after
    now_utc (the clock when None); now_utc is ignored when both are given.
    """
    if not (isinstance(year, int | None) and isinstance(month, int | None)):
        # A caller's bug, not a report's fault: no error line for it.
        raise TypeError(f"decode: year and month must be int or None, got {year!r}, {month!r}")
    if not isinstance(report, str):
        return Metar(raw="", errors=(f"report is a {type(report).__name__}, not text",))
    now = None
    if year is None or month is None:
        now = _utc_now() if now_utc is None else _as_utc(now_utc)
    tokens = report.split("=", 1)[0].split()
    try:
        return _Decoder(tokens, year, month, now).run()
    except MetarInternalError:
        raise
    except Exception as exc:  # outside the group loop: the header or the remarks
        raise MetarInternalError(
            f"METAR decoder defect outside the group handlers ({type(exc).__name__}: {exc}) "
            f"on {' '.join(tokens)!r}"
        ) from exc


def _utc_now() -> datetime:
    return datetime.now(UTC)


def _as_utc(time: datetime) -> datetime:
    return time.replace(tzinfo=UTC) if time.tzinfo is None else time.astimezone(UTC)


def _group_message(index: int, token: str, reason: str) -> str:
    return f"group {index + 1} {token!r}: {reason}"


def _year_month(year: int, month: int) -> str:
    return f"{year:04d}-{month:02d}"


class _Decoder:
    """Walks the tokens once and collects the fields of a Metar."""

    def __init__(
        self, tokens: list[str], year: int | None, month: int | None, now: datetime | None
    ) -> None:
        self.tokens = tokens
        self.year = year
        self.month = month
        self.now = now  # set when year or month is None: the report is dated against it
        self.fields: dict[str, Any] = {}
        self.weather: list[str] = []
        self.sky: list[MetarSkyGroup] = []
        self.rvr: list[str] = []
        self.errors: list[str] = []
        self.sector: tuple[float, float] | None = None
        self.pressure_kind = ""
        self.last_kind = ""  # the kind of the previous body group
        self.discard_rest = False  # after NIL or a glued-on report: no trend, no remarks

    def error(self, index: int, reason: str) -> None:
        if len(self.errors) < MAX_ERRORS:
            self.errors.append(_group_message(index, self.tokens[index], reason))
        elif len(self.errors) == MAX_ERRORS:
            self.errors.append("more errors not listed")

    def run(self) -> Metar:
        tokens = self.tokens
        raw = " ".join(tokens)
        if not tokens:
            return Metar(raw=raw, errors=("empty report",))
        i = self._common_header(raw)
        if i < 0:
            i = self._header()
        end = len(tokens)
        if i < 0:  # no time group: what follows is not decoded
            i = end
        # The hot loop of the decoder: locals instead of attribute look-ups, one dict look-up or
        # one regex match per token, then a handler by kind (see metar_groups).
        fixed, match, kind_of = g.FIXED_GROUPS, g.BODY_GROUP.fullmatch, g.KIND_OF_GROUP
        while i < end:
            tok = tokens[i]
            if len(tok) == 4 and i + 1 < end and g.starts_report(tok, tokens[i + 1]):
                self.error(i, "a second report starts here; the rest is ignored")
                end = i
                break
            kind = fixed.get(tok)
            try:
                if kind is not None:
                    used = _FIXED_HANDLERS[kind](self, i)
                else:
                    m = match(tok) if len(tok) <= g.MAX_GROUP_CHARS else None
                    if m is None:
                        self.error(i, g.unknown_reason(tok))
                        self.last_kind = ""
                        i += 1
                        continue
                    kind = kind_of[m.lastgroup or ""]
                    used = _MATCH_HANDLERS[kind](self, i, m)
            except g.GroupValueError as e:
                self.error(i, f"{e}; group skipped")
                used = 1
            except Exception as exc:
                # Anything else is a bug in a handler: an error line would hide it as one
                # more garbled group (module docstring).
                raise MetarInternalError(
                    f"METAR decoder defect: the {kind or '(no kind)'} handler failed on group "
                    f"{i + 1} {tok!r} ({type(exc).__name__}: {exc}) of {raw!r}"
                ) from exc
            if used == 0:
                break  # a trend, the remarks, or after NIL: the body ends here
            self.last_kind = kind or ""
            i += used
        rest = [] if self.discard_rest else tokens[i:end]
        rmk = rest.index("RMK") if "RMK" in rest else len(rest)
        remarks = rest[rmk + 1 :]
        if remarks:
            self._refine_temperatures(remarks)
        wind = self.fields.pop("wind", None)
        if wind is not None and self.sector is not None:
            wind = dataclasses.replace(
                wind, variable_from_deg=self.sector[0], variable_to_deg=self.sector[1]
            )
        return Metar(
            raw=raw,
            **self.fields,
            errors=tuple(self.errors),
            wind=wind,
            rvr=tuple(self.rvr),
            weather=tuple(self.weather),
            sky=tuple(self.sky),
            trend=" ".join(rest[:rmk]),
            remarks=" ".join(remarks),
        )

    def _refine_temperatures(self, remarks: list[str]) -> None:
        # The T-group repeats the body temperatures in tenths; it refines them, but only where it
        # agrees with the body to within a degree, so a garbled remark cannot replace a value.
        tenths = g.remark_temperatures(remarks)
        if tenths is None:
            return
        for name, precise in zip(("temperature_c", "dewpoint_c"), tenths, strict=True):
            body = self.fields.get(name)
            if body is not None and precise is not None and abs(precise - body) <= 1.0:
                self.fields[name] = precise

    # --- header ---

    def _time(self, day: int, hour: int, minute: int) -> tuple[datetime | None, str | None]:
        """The time of the time group's values and what is wrong with them, if anything: why
        the time is None, or how an hour 24 or minute 60 was read (the time is then set)."""
        problem = g.time_problem(day, hour, minute)
        if problem is not None:
            return None, f"{problem}; observation time unknown"
        year, month = self.year, self.month
        if year is not None and month is not None:
            if not (MINYEAR <= year <= MAXYEAR and 1 <= month <= 12):
                return None, f"{_year_month(year, month)} is not a calendar month"
            time = g.time_in_month(year, month, day, hour, minute)
            if time is None:
                if day > calendar.monthrange(year, month)[1]:
                    return None, f"day {day} does not exist in {_year_month(year, month)}"
                when = f"{_year_month(year, month)}-{day:02d} {hour:02d}:{minute:02d}"
                return None, f"{when} is past the end of the calendar"
        else:
            assert self.now is not None  # decode sets it whenever year or month is missing
            time = g.latest_time(day, hour, minute, self.now, year=year, month=month)
            if time is None:
                months = "month" if month is None else f"month {month:02d}"
                of = "" if year is None else f" of {year}"
                return None, (
                    f"no {months}{of} has day {day} {hour:02d}:{minute:02d} at or before "
                    f"{self.now:%Y-%m-%d %H:%M}Z; observation time unknown"
                )
        if g.rolls_over(hour, minute):
            return time, f"{hour:02d}:{minute:02d} read as {time:%Y-%m-%d %H:%M}Z"
        return time, None

    def _common_header(self, raw: str) -> int:
        """The header in one match when it has the usual shape; -1 to take the general path."""
        m = g.COMMON_HEADER.match(raw)
        if m is None:
            return -1
        day, hour, minute = int(m["day"]), int(m["hour"]), int(m["minute"])
        year, month = self.year, self.month
        if year is None or month is None or not (1 <= day <= 31 and hour < 24 and minute < 60):
            time_utc, problem = self._time(day, hour, minute)
            if problem is not None:
                return -1  # the general path says what is wrong
        else:  # nearly every report: the feed's month and an ordinary time
            try:
                time_utc = datetime(year, month, day, hour, minute, tzinfo=UTC)
            except (ValueError, OverflowError):
                return -1
        used = m["header"].count(" ") + 1
        fields = self.fields
        fields["station"] = m["station"]
        fields["time_utc"] = time_utc
        fields["time_group"] = self.tokens[used - 1]
        if m["type"]:
            fields["type"] = m["type"]
        flags = m["flags"] + m["flags2"]
        if flags:
            if "AUTO" in flags:
                fields["auto"] = True
            if "C" in flags.replace("AUTO", ""):
                fields["cor"] = True
        return used

    def _header(self) -> int:
        """Reads type, station, flags and time; the index of the first body token, or -1 when
        there is no time group (then nothing after the header is worth decoding)."""
        tokens = self.tokens
        n = len(tokens)
        i = 0
        if tokens[0] in g.REPORT_TYPES:
            self.fields["type"] = tokens[0]
            i = 1
        i = self._flags(i)
        if i >= n:
            self.errors.append("no station group")
            return -1
        tok = tokens[i]
        if g.STATION.fullmatch(tok):
            self.fields["station"] = tok
            i = self._flags(i + 1)
        elif g.looks_like_time(tok):
            self.errors.append(f"no station group before group {i + 1} {tok!r}")
        elif i + 1 < n and g.looks_like_time(tokens[i + 1]):
            self.error(i, "expected a 4-character station identifier")
            i += 1
        else:
            self.error(i, "expected a 4-character station identifier; the rest is not decoded")
            return -1
        after = f" after station {self.fields['station']!r}" if "station" in self.fields else ""
        if i >= n:
            self.errors.append(f"no time group (ddhhmmZ){after}")
            return -1
        issued = g.parse_time(tokens[i])
        if issued is None:
            self.error(i, f"expected the time group (ddhhmmZ){after}; the rest is not decoded")
            return -1
        # The shape of a time group: a report, so its body is decoded even when the time is not.
        self.fields["time_group"] = tokens[i]
        time_utc, problem = self._time(*issued)
        if problem is not None:
            self.error(i, problem)
        if time_utc is not None:
            self.fields["time_utc"] = time_utc
        return i + 1

    def _flags(self, i: int) -> int:
        while i < len(self.tokens):
            kind = g.FIXED_GROUPS.get(self.tokens[i])
            if kind not in ("auto", "cor"):
                break
            self.fields[kind] = True
            i += 1
        return i

    # --- body: one handler per group kind; each returns the tokens it used, 0 to end the body

    def _set_first(self, i: int, name: str, value: object) -> None:
        # A group reported as missing (None) neither blocks a later real value nor is an error:
        # AUTO stations often send "/////" where a later group carries the actual value.
        if self.fields.get(name) is None:
            self.fields[name] = value
        elif value is not None:
            self.error(i, f"second {name.replace('_', ' ')} group ignored")

    def _on_end_of_body(self, i: int) -> int:
        return 0

    def _on_report_type(self, i: int) -> int:
        self.error(i, "a second report starts here; the rest is ignored")
        self.discard_rest = True
        return 0

    def _on_nil(self, i: int) -> int:
        self.fields["nil"] = True
        self.discard_rest = True  # nothing after NIL is an observation
        return 0

    def _on_flag(self, i: int) -> int:
        self.fields[g.FIXED_GROUPS[self.tokens[i]]] = True
        return 1

    def _on_ignored(self, i: int) -> int:
        return 1

    def _on_sky_clear(self, i: int) -> int:
        self._set_first(i, "sky_clear", self.tokens[i])
        return 1

    def _on_cavok(self, i: int) -> int:
        # CAVOK also says "no cloud below 5000 ft, no CB", which holds even when a station
        # wrote a visibility group before it ("9999 CAVOK").
        vis = self.fields.get("visibility_m")
        if vis is None:
            self.fields["visibility_m"] = g.TEN_KM
        elif vis < g.TEN_KM:
            self.error(i, f"CAVOK contradicts the visibility of {vis:.0f} m; visibility kept")
        self.fields["cavok"] = True
        return 1

    def _on_visibility_missing(self, i: int) -> int:
        self._set_first(i, "visibility_m", None)
        return 1

    def _on_pressure_missing(self, i: int) -> int:
        self.fields.setdefault("altimeter_hpa", None)
        return 1

    def _on_detached_cloud_type(self, i: int) -> int:
        tok = self.tokens[i]
        last = self.sky[-1] if self.sky else None
        if last is None or last.cb or last.tcu or self.last_kind != "sky":
            self.error(i, "cloud type without a cloud group")
        else:
            self.sky[-1] = MetarSkyGroup(last.cover, last.base_m, tok == "CB", tok == "TCU")
        return 1

    def _on_unknown_cover_type(self, i: int) -> int:
        tok = self.tokens[i]
        self.sky.append(MetarSkyGroup("///", None, tok == "///CB", tok == "///TCU"))
        return 1

    def _on_wind_shear(self, i: int) -> int:
        return g.wind_shear_tokens(self.tokens, i)

    def _on_qfe_word(self, i: int) -> int:
        used = g.qfe_tokens(self.tokens, i)
        if used == 0:
            self.error(i, "unrecognised group")
            return 1
        return used

    def _on_wind(self, i: int, m: re.Match[str]) -> int:
        self._wind(i, m["wind_dir"], m["wind_speed"], m["wind_gust"], m["wind_unit"])
        return 1

    def _on_unitless_wind(self, i: int, m: re.Match[str]) -> int:
        # Trusted only where the wind group belongs: before visibility and sky.
        if "wind" in self.fields or "visibility_m" in self.fields or self.sky:
            self.error(i, "unrecognised group")
        else:
            # Knots wherever the station is: the real reports seen (HSPN 04014, HSDN 36020)
            # match AWC's knot decode, where python-metar's m/s outside the US doubles them.
            self._wind(i, m["uwind_dir"], m["uwind_speed"], m["uwind_gust"], "KT")
        return 1

    def _on_wind_sector(self, i: int, m: re.Match[str]) -> int:
        sector = g.wind_sector(m)
        if self.sector is None:
            self.sector = sector
        else:
            self.error(i, "second variable wind sector ignored")
        return 1

    def _on_sky(self, i: int, m: re.Match[str]) -> int:
        group = g.sky_group(m)
        if group is not None:
            self.sky.append(group)
        return 1

    def _on_vertical_visibility(self, i: int, m: re.Match[str]) -> int:
        self.sky.append(MetarSkyGroup("VV", g.hundreds_of_feet_m(m["vv_height"])))
        return 1

    def _on_visibility_m(self, i: int, m: re.Match[str]) -> int:
        self._visibility(i, g.visibility_metres(m), m["vis_dir"])
        return 1

    def _on_visibility_sm(self, i: int, m: re.Match[str]) -> int:
        self._visibility(i, g.visibility_statute_miles(m), None)
        return 1

    def _on_visibility_km(self, i: int, m: re.Match[str]) -> int:
        self._visibility(i, g.visibility_kilometres(m), None)
        return 1

    def _on_whole_number(self, i: int, m: re.Match[str]) -> int:
        nxt = self.tokens[i + 1] if i + 1 < len(self.tokens) else ""
        metres = g.mixed_statute_miles(self.tokens[i], nxt)
        if metres is None:
            self.error(i, "unrecognised group")
            return 1
        self._visibility(i, metres, None)
        return 2

    def _on_rvr(self, i: int, m: re.Match[str]) -> int:
        self.rvr.append(self.tokens[i])
        return 1

    def _on_weather(self, i: int, m: re.Match[str]) -> int:
        if m["wx_descriptor"] or m["wx_phenomena"]:
            self.weather.append(self.tokens[i])
        else:
            self.error(i, "unrecognised group")  # "+" or "VC" on its own
        return 1

    def _on_temperatures(self, i: int, m: re.Match[str]) -> int:
        self._temperatures(i, m["temp"], m["dew"])
        return 1

    def _on_qnh(self, i: int, m: re.Match[str]) -> int:
        self._pressure(i, g.qnh_hpa(m), "Q")
        return 1

    def _on_altimeter(self, i: int, m: re.Match[str]) -> int:
        self._pressure(i, g.altimeter_hpa(m), "A")
        return 1

    def _on_matched_end_of_body(self, i: int, m: re.Match[str]) -> int:
        return 0

    def _on_matched_ignored(self, i: int, m: re.Match[str]) -> int:
        return 1

    def _wind(self, i: int, direction: str, speed: str, gust: str | None, unit: str) -> None:
        wind, problems = g.wind(direction, speed, gust, unit)
        for problem in problems:
            self.error(i, problem)
        self._set_first(i, "wind", wind)

    def _visibility(self, i: int, metres: float, direction: str | None) -> None:
        fields = self.fields
        if fields.get("visibility_m") is None:
            fields["visibility_m"] = metres
            return
        # A second visibility right after the first is the sector minimum (`9999 4000SE`, or
        # `4300 0900` without its direction); anywhere else it is a stray group.
        if (
            self.last_kind == "visibility_m"
            and fields.get("min_visibility_m") is None
            and metres < fields["visibility_m"]
            and direction != "NDV"
        ):
            fields["min_visibility_m"] = metres
            fields["min_visibility_dir"] = direction
            return
        self.error(i, "second visibility group ignored")

    def _temperatures(self, i: int, temp: str, dew: str | None) -> None:
        values: list[float | None] = []
        for text, what in ((temp, "temperature"), (dew, "dewpoint")):
            try:
                values.append(g.celsius(text, what))
            except g.GroupValueError as e:
                self.error(i, f"{e}; {what} left out")
                values.append(None)
        temperature, dewpoint = values
        fields = self.fields
        if fields.get("temperature_c") is not None or fields.get("dewpoint_c") is not None:
            if temperature is not None or dewpoint is not None:
                self.error(i, "second temperature group ignored")
            return
        fields["temperature_c"] = temperature
        fields["dewpoint_c"] = dewpoint

    def _pressure(self, i: int, hpa: float, kind: str) -> None:
        old = self.fields.get("altimeter_hpa")
        if old is None:
            self.fields["altimeter_hpa"], self.pressure_kind = hpa, kind
            return
        if kind == self.pressure_kind:
            self.error(i, "second altimeter group ignored")
            return
        # With both Q and A groups, Q wins: it is the hPa value itself, not a rounded conversion.
        if kind == "Q":
            self.fields["altimeter_hpa"], self.pressure_kind = hpa, kind
        if abs(old - hpa) > PRESSURE_AGREEMENT_HPA:
            self.error(i, f"disagrees with the other pressure group ({old:.1f} hPa)")


_FIXED_HANDLERS: dict[str, Callable[[_Decoder, int], int]] = {
    "cavok": _Decoder._on_cavok,
    "sky_clear": _Decoder._on_sky_clear,
    "auto": _Decoder._on_flag,
    "cor": _Decoder._on_flag,
    "nil": _Decoder._on_nil,
    "report_type": _Decoder._on_report_type,
    "ignored": _Decoder._on_ignored,
    "visibility_missing": _Decoder._on_visibility_missing,
    "pressure_missing": _Decoder._on_pressure_missing,
    "detached_cloud_type": _Decoder._on_detached_cloud_type,
    "unknown_cover_type": _Decoder._on_unknown_cover_type,
    "wind_shear": _Decoder._on_wind_shear,
    "qfe_word": _Decoder._on_qfe_word,
    "remarks": _Decoder._on_end_of_body,
    "trend": _Decoder._on_end_of_body,
}
_MATCH_HANDLERS: dict[str, Callable[[_Decoder, int, re.Match[str]], int]] = {
    "wind": _Decoder._on_wind,
    "unitless_wind": _Decoder._on_unitless_wind,
    "wind_sector": _Decoder._on_wind_sector,
    "visibility_m": _Decoder._on_visibility_m,
    "visibility_sm": _Decoder._on_visibility_sm,
    "visibility_km": _Decoder._on_visibility_km,
    "whole_number": _Decoder._on_whole_number,
    "rvr": _Decoder._on_rvr,
    "runway_state": _Decoder._on_matched_ignored,
    "recent_weather": _Decoder._on_matched_ignored,
    "ignored": _Decoder._on_matched_ignored,
    "sky": _Decoder._on_sky,
    "vertical_visibility": _Decoder._on_vertical_visibility,
    "weather": _Decoder._on_weather,
    "temperatures": _Decoder._on_temperatures,
    "qnh": _Decoder._on_qnh,
    "altimeter": _Decoder._on_altimeter,
    "trend": _Decoder._on_matched_end_of_body,
}
