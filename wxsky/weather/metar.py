"""Decode one METAR/SPECI report into SI values, and turn it into a `WeatherPatch`.

Grammar: the text is split on whitespace and cut at the first `=` (the WMO end-of-report mark).
An optional `METAR`/`SPECI` word, the station (4 characters, a letter first) and the
`ddhhmmZ` time group form the header; `COR`, `CCx` and `AUTO` may stand on either side of the
station. The body runs up to `RMK` (the rest is `remarks`) or the first trend group (`NOSIG`,
`BECMG`, `TEMPO`, `INTER`, `FMhhmm`, `PROBnn`; kept verbatim in `trend`, never decoded into body
fields). Body groups are recognised by shape, in any order (`metar_groups`); the first group of a
kind wins.

Error policy:

* `MetarError` (one line: what, and which group) when there is no report to speak of: empty
  text, a character outside printable ASCII, no station group, or no valid time group after it.
* Everything else is a warning and the report still decodes: an unknown or garbled body group,
  a duplicate group, and a known group with an out-of-range value (wind above 250 kt,
  temperature or dewpoint outside -90..60 °C, QNH outside 850..1100 hPa, wind direction above
  360°). Such a group is skipped, its field stays None and `warnings` names the group. Negative
  visibility cannot be written in METAR syntax, so it only ever appears as an unknown group.
  Blending reports from several stations can make up for one missing field; it cannot make up
  for a whole report rejected because of one typo.
* A second report glued onto the first (a new station + time, or `METAR`/`SPECI`) ends the body
  with a warning.

Value conventions: `9999` and CAVOK mean 10 km; `M` (less than) and `P` (more than) visibility
and wind prefixes give the bound itself; cloud bases are above ground level (AGL). A North
American `Tsttt[sddd]` remark refines temperature and dewpoint to tenths where it agrees with the
body group to within 1 °C (as AWC's own decode does); no other remark is decoded.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any, Literal

from wxsky.errors import MetarError
from wxsky.units import FT_TO_M, mps_to_kt
from wxsky.weather import metar_groups as g
from wxsky.weather.metar_groups import MetarSkyGroup, MetarWind
from wxsky.weather.state import MAX_LAYERS, CloudLayer, CloudType, Source, WeatherPatch, WindLayer

__all__ = ["MetarReport", "MetarSkyGroup", "MetarWind", "decode_metar"]

# Oktas for each cover: the standard ranges are FEW 1-2, SCT 3-4, BKN 5-7, OVC 8; the midpoints
# 1.5 and 3.5 round up so that thin cover still shows on screen.
COVER_OKTAS = {"FEW": 2, "SCT": 4, "BKN": 6, "OVC": 8, "VV": 8}

LOW_CLOUD_MAX_M = 2000.0
MID_CLOUD_MAX_M = 6000.0
WIND_HEIGHT_M = 10.0  # anemometer height above the field

# Typical layer depth by cloud type, so that each layer gets a plausible top.
THICKNESS_M = {
    CloudType.CUMULONIMBUS: 9000.0,
    CloudType.CUMULUS: 1200.0,
    CloudType.STRATOCUMULUS: 600.0,
    CloudType.STRATUS: 400.0,
    CloudType.ALTOCUMULUS: 500.0,
    CloudType.ALTOSTRATUS: 1500.0,
    CloudType.CIRRUS: 1000.0,
    CloudType.CIRROSTRATUS: 800.0,
}
TOWERING_CUMULUS_THICKNESS_M = 4000.0
MAX_CLOUD_TOP_M = 25_000.0  # CloudLayer's limit


@dataclass(frozen=True)
class MetarReport:
    """One decoded report. Values are SI; None means the report did not give the value."""

    station: str
    kind: Literal["METAR", "SPECI"]
    day: int  # day of month; the month and year come from the feed
    hour: int  # UTC
    minute: int
    auto: bool = False
    cor: bool = False
    nil: bool = False  # "NIL": the station sent no observation
    wind: MetarWind | None = None
    visibility_m: float | None = None
    cavok: bool = False
    weather: tuple[str, ...] = ()
    sky: tuple[MetarSkyGroup, ...] = ()
    sky_clear: str | None = None  # CLR, SKC, NSC or NCD
    temperature_c: float | None = None
    dewpoint_c: float | None = None
    qnh_hpa: float | None = None
    rvr: tuple[str, ...] = ()  # runway visual range groups, verbatim
    trend: str = ""
    remarks: str = ""
    warnings: tuple[str, ...] = ()
    raw: str = field(default="", compare=False)

    @property
    def issued_ddhhmm(self) -> tuple[int, int, int]:
        return (self.day, self.hour, self.minute)

    def issued_at(self, year: int, month: int) -> datetime:
        """The observation time, given the year and month the feed says it belongs to."""
        try:
            return datetime(year, month, self.day, self.hour, self.minute, tzinfo=UTC)
        except ValueError:
            raise MetarError(
                f"METAR {self.station}: day {self.day} does not exist in {year}-{month:02d}"
            ) from None

    def to_patch(self, field_elevation_m: float = 0.0) -> WeatherPatch:
        """The weather this report states, with cloud bases and wind moved to MSL.

        Clouds: `COVER_OKTAS`; CB -> cumulonimbus, TCU -> (towering) cumulus, VV -> 8/8 stratus
        at the vertical visibility; otherwise by base AGL: below 2000 m cumulus (FEW/SCT),
        stratocumulus (BKN), stratus (OVC); up to 6000 m altocumulus (FEW/SCT/BKN) or altostratus
        (OVC); above that cirrus or cirrostratus. Groups without a base or cover are dropped;
        the lowest MAX_LAYERS are kept. CAVOK and CLR/SKC/NSC/NCD give no layers. Wind: one
        layer 10 m above the field; VRB and unknown directions give dir 0, variable=True. A
        report without weather groups says "no weather" (an empty tuple), except a NIL report.
        """
        if not -500.0 <= field_elevation_m <= 9000.0:
            raise ValueError(f"field_elevation_m {field_elevation_m} outside -500..9000")
        if self.nil:
            return WeatherPatch(source=Source.METAR)
        return WeatherPatch(
            source=Source.METAR,
            layers=self._layers(field_elevation_m),
            wind=self._wind_layers(field_elevation_m),
            visibility_m=self.visibility_m,
            temperature_c=self.temperature_c,
            dewpoint_c=self.dewpoint_c,
            qnh_hpa=self.qnh_hpa,
            present_weather=self.weather,
        )

    def _layers(self, field_elevation_m: float) -> tuple[CloudLayer, ...] | None:
        if self.cavok or self.sky_clear is not None:
            return ()
        if not self.sky:
            return None
        layers = []
        for group in sorted(
            (s for s in self.sky if s.base_m is not None and s.cover in COVER_OKTAS),
            key=lambda s: s.base_m or 0.0,
        ):
            layer = _cloud_layer(group, field_elevation_m)
            if layer is not None:
                layers.append(layer)
        return tuple(layers[:MAX_LAYERS])

    def _wind_layers(self, field_elevation_m: float) -> tuple[WindLayer, ...] | None:
        w = self.wind
        if w is None:
            return None
        return (
            WindLayer(
                alt_m=field_elevation_m + WIND_HEIGHT_M,
                dir_from_deg=0.0 if w.dir_from_deg is None else w.dir_from_deg,
                speed_mps=w.speed_mps,
                gust_mps=w.gust_mps or 0.0,
                variable=w.dir_from_deg is None,
            ),
        )

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-serialisable data (lists, not tuples), field names as on the dataclass."""
        wind = None
        if self.wind is not None:
            wind = {
                "dir_from_deg": self.wind.dir_from_deg,
                "variable": self.wind.variable,
                "speed_mps": self.wind.speed_mps,
                "gust_mps": self.wind.gust_mps,
                "variable_from_deg": self.wind.variable_from_deg,
                "variable_to_deg": self.wind.variable_to_deg,
            }
        return {
            "station": self.station,
            "kind": self.kind,
            "day": self.day,
            "hour": self.hour,
            "minute": self.minute,
            "auto": self.auto,
            "cor": self.cor,
            "nil": self.nil,
            "wind": wind,
            "visibility_m": self.visibility_m,
            "cavok": self.cavok,
            "weather": list(self.weather),
            "sky": [
                {"cover": s.cover, "base_m": s.base_m, "cb": s.cb, "tcu": s.tcu} for s in self.sky
            ],
            "sky_clear": self.sky_clear,
            "temperature_c": self.temperature_c,
            "dewpoint_c": self.dewpoint_c,
            "qnh_hpa": self.qnh_hpa,
            "rvr": list(self.rvr),
            "trend": self.trend,
            "remarks": self.remarks,
            "warnings": list(self.warnings),
            "raw": self.raw,
        }

    def describe(self) -> str:
        """A few human-readable lines for the CLI."""
        flags = " ".join(f for f, on in (("AUTO", self.auto), ("COR", self.cor)) if on)
        head = f"{self.kind} {self.station} day {self.day} {self.hour:02d}:{self.minute:02d}Z"
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
                f"  QNH         {_opt(self.qnh_hpa, 'hPa', 1)}",
            ]
        if self.trend:
            lines.append(f"  trend       {self.trend}")
        if self.remarks:
            lines.append(f"  remarks     {self.remarks}")
        lines += [f"  warning: {w}" for w in self.warnings]
        return "\n".join(lines)


def _cloud_layer(group: MetarSkyGroup, field_elevation_m: float) -> CloudLayer | None:
    assert group.base_m is not None
    cloud_type = _cloud_type(group)
    thickness = THICKNESS_M[cloud_type]
    if group.tcu:
        thickness = TOWERING_CUMULUS_THICKNESS_M
    base = field_elevation_m + group.base_m
    top = min(base + thickness, MAX_CLOUD_TOP_M)
    if top <= base:
        return None
    return CloudLayer(COVER_OKTAS[group.cover], base, top, cloud_type)


def _cloud_type(group: MetarSkyGroup) -> CloudType:
    if group.cb:
        return CloudType.CUMULONIMBUS
    if group.tcu:
        return CloudType.CUMULUS
    if group.cover == "VV":
        return CloudType.STRATUS
    base = group.base_m or 0.0
    if base < LOW_CLOUD_MAX_M:
        if group.cover == "OVC":
            return CloudType.STRATUS
        return CloudType.STRATOCUMULUS if group.cover == "BKN" else CloudType.CUMULUS
    if base < MID_CLOUD_MAX_M:
        return CloudType.ALTOSTRATUS if group.cover == "OVC" else CloudType.ALTOCUMULUS
    return CloudType.CIRROSTRATUS if group.cover == "OVC" else CloudType.CIRRUS


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


def _describe_visibility(r: MetarReport) -> str:
    if r.cavok:
        return "CAVOK (10 km or more, no cloud below 1500 m, no CB)"
    return _opt(r.visibility_m, "m")


def _describe_sky(r: MetarReport) -> str:
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


def decode_metar(text: str) -> MetarReport:
    """Decode one report (see the module docstring for the grammar and the error policy)."""
    _check_characters(text)
    tokens = text.split("=", 1)[0].split()
    if not tokens:
        raise MetarError("empty METAR report")
    return _Decoder(tokens).run()


def _check_characters(text: str) -> None:
    for offset, ch in enumerate(text):
        if not (ch.isascii() and ch.isprintable()) and ch not in " \t\r\n\f\v":
            raise MetarError(
                f"METAR report has a non-ASCII or control character {ch!r} at offset {offset}"
            )


def _group_message(index: int, token: str, reason: str) -> str:
    return f"group {index + 1} {token!r}: {reason}"


class _Decoder:
    """Walks the tokens once and collects the fields of a MetarReport."""

    def __init__(self, tokens: list[str]) -> None:
        self.tokens = tokens
        self.fields: dict[str, Any] = {}
        self.weather: list[str] = []
        self.sky: list[MetarSkyGroup] = []
        self.rvr: list[str] = []
        self.warnings: list[str] = []
        self.sector: g.WindSector | None = None
        self.qnh_kind = ""

    def run(self) -> MetarReport:
        i = self._header()
        end = len(self.tokens)
        while i < end:
            tok = self.tokens[i]
            if tok == "RMK" or g.is_trend_start(tok) or self.fields.get("nil"):
                break
            if self._second_report_at(i):
                self.warnings.append(
                    _group_message(i, tok, "a second report starts here; the rest is ignored")
                )
                end = i
                break
            i += self._body_group(i)
        rest = self.tokens[i:end]
        rmk = rest.index("RMK") if "RMK" in rest else len(rest)
        self._refine_temperatures(rest[rmk + 1 :])
        wind = self.fields.pop("wind", None)
        if wind is not None and self.sector is not None:
            wind = dataclasses.replace(
                wind, variable_from_deg=self.sector.from_deg, variable_to_deg=self.sector.to_deg
            )
        return MetarReport(
            **self.fields,
            wind=wind,
            weather=tuple(self.weather),
            sky=tuple(self.sky),
            rvr=tuple(self.rvr),
            trend="" if self.fields.get("nil") else " ".join(rest[:rmk]),
            remarks=" ".join(rest[rmk + 1 :]),
            warnings=tuple(self.warnings),
            raw=" ".join(self.tokens),
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

    def _header(self) -> int:
        """Reads type, station, flags and time; returns the index of the first body token."""
        tokens = self.tokens
        i = 0
        self.fields["kind"] = "METAR"
        if tokens[0] in ("METAR", "SPECI"):
            self.fields["kind"] = tokens[0]
            i = 1
        i = self._flags(i)
        if i >= len(tokens):
            raise MetarError("METAR report has no station group")
        if not g.is_station(tokens[i]):
            raise MetarError(
                f"METAR group {i + 1} {tokens[i]!r}: expected a 4-character station identifier"
            )
        self.fields["station"] = tokens[i]
        i = self._flags(i + 1)
        where = f"after station {self.fields['station']!r}"
        if i >= len(tokens):
            raise MetarError(f"METAR report has no time group (ddhhmmZ) {where}")
        try:
            issued = g.parse_time(tokens[i])
        except g.GroupValueError as e:
            raise MetarError(f"METAR {_group_message(i, tokens[i], str(e))}") from None
        if issued is None:
            raise MetarError(
                f"METAR group {i + 1} {tokens[i]!r}: expected the time group (ddhhmmZ) {where}"
            )
        self.fields["day"], self.fields["hour"], self.fields["minute"] = issued
        if not tokens[i].endswith("Z"):
            self.warnings.append(_group_message(i, tokens[i], "time group without its Z"))
        return i + 1

    def _flags(self, i: int) -> int:
        while i < len(self.tokens) and (name := g.flag_name(self.tokens[i])) in ("COR", "AUTO"):
            self.fields[name.lower()] = True
            i += 1
        return i

    def _second_report_at(self, i: int) -> bool:
        tok = self.tokens[i]
        if tok in ("METAR", "SPECI"):
            return True
        nxt = self.tokens[i + 1] if i + 1 < len(self.tokens) else ""
        return g.is_station(tok) and g.is_time_group(nxt)

    def _body_group(self, i: int) -> int:
        """Applies the group at token i and returns how many tokens it used."""
        tok = self.tokens[i]
        try:
            found = g.parse_group(self.tokens, i)
        except g.GroupValueError as e:
            self.warnings.append(_group_message(i, tok, f"{e}; group skipped"))
            return 1
        if found is None:
            self.warnings.append(_group_message(i, tok, g.unknown_reason(tok)))
            return 1
        group, used = found
        problem = self._apply(group)
        if problem:
            self.warnings.append(_group_message(i, " ".join(self.tokens[i : i + used]), problem))
        return used

    def _set_first(self, name: str, value: object) -> str | None:
        # A group reported as missing (None) neither blocks a later real value nor warns: AUTO
        # stations often send "/////" where a later group carries the actual value.
        if self.fields.get(name) is None:
            self.fields[name] = value
            return None
        return None if value is None else f"second {name.replace('_', ' ')} group ignored"

    def _apply(self, group: g.Group) -> str | None:
        """Stores one group; returns a warning when it had to be ignored."""
        match group:
            case g.Flag(name):
                if name != "RTD":  # a late report: nothing about the weather changes
                    self.fields[name.lower()] = True
            case MetarWind():
                return self._set_first("wind", group)
            case g.UnitlessWind(wind):
                if "wind" in self.fields or "visibility_m" in self.fields or self.sky:
                    return "unrecognised group"
                self.fields["wind"] = wind
                return "wind group without a unit, read as knots"
            case g.WindSector():
                if self.sector is not None:
                    return "second variable wind sector ignored"
                self.sector = group
            case g.Visibility(metres, cavok, directional):
                if "visibility_m" in self.fields and directional:
                    return None  # the lowest visibility in one direction, not the prevailing one
                problem = self._set_first("visibility_m", metres)
                if problem is None and cavok:
                    self.fields["cavok"] = True
                return problem
            case g.RunwayVisualRange(text):
                self.rvr.append(text)
            case g.Weather(code):
                self.weather.append(code)
            case g.SkyClear(code):
                return self._set_first("sky_clear", code)
            case MetarSkyGroup():
                self.sky.append(group)
            case g.DetachedCloudType(code):
                if not self.sky or self.sky[-1].cb or self.sky[-1].tcu:
                    return "cloud type without a cloud group"
                last = self.sky[-1]
                self.sky[-1] = MetarSkyGroup(
                    last.cover, last.base_m, cb=code == "CB", tcu=code == "TCU"
                )
            case g.Temperatures(temperature, dewpoint):
                known = self.fields.get("temperature_c") is not None
                if known or self.fields.get("dewpoint_c") is not None:
                    missing = temperature is None and dewpoint is None
                    return None if missing else "second temperature group ignored"
                self.fields["temperature_c"] = temperature
                self.fields["dewpoint_c"] = dewpoint
            case g.Pressure(hpa, kind):
                return self._pressure(hpa, kind)
            case g.Ignored():
                pass
        return None

    def _pressure(self, hpa: float | None, kind: str) -> str | None:
        if "qnh_hpa" not in self.fields:
            self.fields["qnh_hpa"], self.qnh_kind = hpa, kind
            return None
        old = self.fields["qnh_hpa"]
        if hpa is None:
            return None
        # With both Q and A groups, Q wins: it is the hPa value itself, not a rounded conversion.
        if old is None or (kind == "Q" and self.qnh_kind == "A"):
            self.fields["qnh_hpa"], self.qnh_kind = hpa, kind
        if old is not None and abs(old - hpa) > 2.0:
            return f"disagrees with the other pressure group ({old:.1f} hPa)"
        return None
