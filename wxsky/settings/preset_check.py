"""Check preset files: the parser behind `load_preset_file` and `wxsky preset validate`.

The preset's keys and limits are a `wxsky.schema` table built from the weather state's own
limits (`wxsky.weather.state`), so a preset that passes here is a state that exists. Every
problem is collected with the key path it is about and reported as `FILE:LINE: key: what`.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, date, datetime, time
from pathlib import Path
from typing import Any

from wxsky.schema import (
    REQUIRED,
    Bool,
    Custom,
    Field,
    Items,
    KeyPath,
    Problem,
    Rule,
    Table,
    Tables,
    Text,
    fmt_number,
    format_key,
)
from wxsky.schema.toml_file import (
    FileCheck,
    LocatedProblem,
    key_line,
    key_lines,
    locate,
    parse_toml,
    read_toml,
)
from wxsky.weather.state import (
    ALT_M,
    FOG_DEPTH_M,
    FOG_VISIBILITY_M,
    GUST_MPS,
    LAT_DEG,
    LAYER_HEIGHT_M,
    LON_DEG,
    MAX_LAYERS,
    MAX_RVR,
    NO_FOG,
    QNH_HPA,
    RUNWAY_PATTERN,
    RVR_M,
    SEED,
    TEMPERATURE_C,
    VISIBILITY_M,
    WHOLE_OKTAS,
    WIND_DIR_DEG,
    WIND_SPEED_MPS,
    CloudLayer,
    CloudType,
    Fog,
    Observer,
    RunwayRvr,
    Source,
    WeatherPatch,
    WeatherState,
    WindLayer,
    check_time_range,
    parse_time_utc,
)

__all__ = [
    "PRESET_TABLE",
    "TOP_KEYS",
    "KeyPath",
    "LocatedProblem",
    "PresetCheck",
    "check_preset_bytes",
    "check_preset_file",
    "format_key",
    "key_line",
    "key_lines",
    "parse_preset_data",
]

# A METAR weather group such as "-RA", "+TSRA", "VCSH", "BR"; decoding them is the METAR
# module's business, this only keeps obvious junk out of the state.
_WEATHER_GROUP = r"(?:[+-]|VC)?[A-Z]{2,12}"


def _time_utc(value: Any) -> datetime:
    # TOML has a native date-time type; accept it as well as a quoted ISO 8601 string.
    if isinstance(value, datetime):
        if value.tzinfo is None:
            return check_time_range("time", value.replace(tzinfo=UTC))
        try:
            return check_time_range("time", value.astimezone(UTC))
        except OverflowError:  # 0001-01-01T00:00+01:00 is in year 0 in UTC
            raise ValueError(f"{value.isoformat()} is outside the years 1..9999 in UTC") from None
    if isinstance(value, str):
        return parse_time_utc(value)
    kind = "a date without a time" if isinstance(value, date) else repr(value)
    if isinstance(value, time):
        kind = "a time without a date"
    raise ValueError(f"must be an ISO 8601 date-time, got {kind}")


def _cloud_type(value: Any) -> CloudType:
    if not isinstance(value, str) or value.strip().lower() == "none":
        raise ValueError(f"must be a cloud type name, got {value!r}")
    return CloudType.from_name(value)


def _top_above_base(v: dict[str, Any], path: KeyPath, problems: list[Problem]) -> None:
    if v["top_m"] <= v["base_m"]:
        problems.append(
            Problem(
                (*path, "top_m"),
                f"{fmt_number(v['top_m'])} must be above base_m {fmt_number(v['base_m'])}",
            )
        )


def _gust_or_none(v: dict[str, Any], path: KeyPath, problems: list[Problem]) -> None:
    if 0.0 < v["gust_mps"] < v["speed_mps"]:
        problems.append(
            Problem(
                (*path, "gust_mps"),
                f"{fmt_number(v['gust_mps'])} must be 0 (no gusts) or at least speed_mps "
                f"{fmt_number(v['speed_mps'])}",
            )
        )


def _distinct_wind_levels(v: dict[str, Any], path: KeyPath, problems: list[Problem]) -> None:
    seen: dict[float, int] = {}
    for i, wind in enumerate(v.get("wind") or ()):
        alt = wind["alt_m"]
        if alt in seen:
            problems.append(
                Problem(("wind", i, "alt_m"), f"{fmt_number(alt)} repeats wind[{seen[alt]}].alt_m")
            )
        seen.setdefault(alt, i)


def _dewpoint_not_above_temperature(
    v: dict[str, Any], path: KeyPath, problems: list[Problem]
) -> None:
    t, d = v.get("temperature_c"), v.get("dewpoint_c")
    if t is not None and d is not None and d > t:
        problems.append(
            Problem(("dewpoint_c",), f"{fmt_number(d)} is above temperature_c {fmt_number(t)}")
        )


OBSERVER_TABLE = Table(
    {
        "lat_deg": Field(LAT_DEG, REQUIRED),
        "lon_deg": Field(LON_DEG, REQUIRED),
        "alt_m": Field(ALT_M, REQUIRED),
    },
    what="a table ([observer])",
)
LAYER_TABLE = Table(
    {
        "type": Field(Custom(_cloud_type, "a cloud type name"), REQUIRED),
        "cover_oktas": Field(WHOLE_OKTAS, REQUIRED),
        "base_m": Field(LAYER_HEIGHT_M, REQUIRED),
        "top_m": Field(LAYER_HEIGHT_M, REQUIRED),
    },
    rules=(Rule(("base_m", "top_m"), _top_above_base),),
)
WIND_TABLE = Table(
    {
        "alt_m": Field(ALT_M, REQUIRED),
        "dir_deg": Field(WIND_DIR_DEG, REQUIRED),
        "speed_mps": Field(WIND_SPEED_MPS, REQUIRED),
        "gust_mps": Field(GUST_MPS, 0.0),
        "variable": Field(Bool(), False),
    },
    rules=(Rule(("speed_mps", "gust_mps"), _gust_or_none),),
)


def _distinct_runways(v: dict[str, Any], path: KeyPath, problems: list[Problem]) -> None:
    seen: dict[str, int] = {}
    for i, item in enumerate(v.get("rvr") or ()):
        name = item["runway"]
        if name in seen:
            problems.append(
                Problem((*path, "rvr", i, "runway"), f"{name!r} repeats rvr[{seen[name]}].runway")
            )
        seen.setdefault(name, i)


RVR_TABLE = Table(
    {
        "runway": Field(
            Text(pattern=RUNWAY_PATTERN, pattern_desc="a runway designator like '14' or '32L'"),
            REQUIRED,
        ),
        "rvr_m": Field(RVR_M, REQUIRED),
    },
)
# Fog over the ground (docs/fog.md): visibility_m inside it (left out: only the RVRs' fog),
# its top over the ground, banks or a sheet, and the runway visual ranges it gives.
FOG_TABLE = Table(
    {
        "visibility_m": Field(FOG_VISIBILITY_M),
        "depth_m": Field(FOG_DEPTH_M, 100.0),
        "patchy": Field(Bool(), False),
        "rvr": Field(Tables(RVR_TABLE, "fog.rvr", max_items=MAX_RVR, noun="runways"), ()),
    },
    rules=(Rule(("rvr",), _distinct_runways),),
    what="a table ([fog])",
)
PRESET_TABLE = Table(
    {
        "description": Field(Text(non_empty=True), REQUIRED),
        "time_utc": Field(Custom(_time_utc, "an ISO 8601 date-time")),
        "seed": Field(SEED),
        "visibility_m": Field(VISIBILITY_M),
        "temperature_c": Field(TEMPERATURE_C),
        "dewpoint_c": Field(TEMPERATURE_C),
        "qnh_hpa": Field(QNH_HPA),
        "present_weather": Field(
            Items(
                Text(
                    pattern=_WEATHER_GROUP,
                    pattern_desc="a METAR weather group like '-RA' or 'TSRA'",
                ),
                what="a list of METAR groups",
            )
        ),
        "observer": Field(OBSERVER_TABLE),
        "layers": Field(Tables(LAYER_TABLE, "layers", max_items=MAX_LAYERS, noun="cloud layers")),
        "wind": Field(Tables(WIND_TABLE, "wind")),
        "fog": Field(FOG_TABLE),
    },
    rules=(
        Rule(("temperature_c", "dewpoint_c"), _dewpoint_not_above_temperature),
        Rule(("wind",), _distinct_wind_levels),
    ),
)
TOP_KEYS = tuple(PRESET_TABLE.fields)


@dataclass(frozen=True)
class PresetCheck:
    """The outcome of checking one file: the patch is None unless there are no problems."""

    path: Path
    description: str
    patch: WeatherPatch | None
    problems: tuple[LocatedProblem, ...]

    def lines(self) -> list[str]:
        """Every problem as `FILE:LINE: key: problem`, in file order."""
        return FileCheck(self.path, None, self.problems).lines()

    def error_message(self) -> str:
        """The first problem, on one line, with a count of the others."""
        first = self.lines()[0]
        more = len(self.problems) - 1
        if more:
            first += f" (and {more} more problem{'s' if more > 1 else ''})"
        return first


def check_preset_file(path: Path) -> PresetCheck:
    """Read, parse and check one preset file; never raises for a bad file."""
    read = read_toml(path)
    if isinstance(read, LocatedProblem):
        return PresetCheck(Path(path), "", None, (read,))
    return _check_text(Path(path), *read)


def check_preset_bytes(path: Path, raw: bytes) -> PresetCheck:
    """Check a preset's bytes; `path` names it in messages and gives the preset its name."""
    parsed = parse_toml(raw)
    if isinstance(parsed, LocatedProblem):
        return PresetCheck(Path(path), "", None, (parsed,))
    return _check_text(Path(path), *parsed)


def _check_text(path: Path, text: str, data: dict[str, Any]) -> PresetCheck:
    description, patch, problems = parse_preset_data(data)
    located = locate(text, problems)
    return PresetCheck(path, description, None if located else patch, located)


def parse_preset_data(data: dict[str, Any]) -> tuple[str, WeatherPatch, list[Problem]]:
    """A parsed TOML preset as (description, patch, problems). The patch is only meaningful
    when there are no problems."""
    problems: list[Problem] = []
    v = PRESET_TABLE.check(data, (), problems) or {}
    patch = _patch(v) if not problems else WeatherPatch(source=Source.PRESET)
    if not problems:
        # The state's own checks are the final word: a rule no table above states would show
        # here rather than when a host switches to the preset.
        try:
            WeatherState().apply(patch)
        except ValueError as exc:
            problems.append(Problem((), str(exc)))
    description = v.get("description") or ""
    return description.strip(), patch, problems


def _patch(v: dict[str, Any]) -> WeatherPatch:
    observer = v.get("observer")
    layers = v.get("layers")
    wind = v.get("wind")
    return WeatherPatch(
        source=Source.PRESET,
        observer=Observer(**observer) if observer is not None else None,
        time_utc=v.get("time_utc"),
        layers=(
            tuple(
                CloudLayer(lay["cover_oktas"], lay["base_m"], lay["top_m"], lay["type"])
                for lay in layers
            )
            if layers is not None
            else None
        ),
        wind=(
            tuple(
                WindLayer(w["alt_m"], w["dir_deg"], w["speed_mps"], w["gust_mps"], w["variable"])
                for w in wind
            )
            if wind is not None
            else None
        ),
        visibility_m=v.get("visibility_m"),
        temperature_c=v.get("temperature_c"),
        dewpoint_c=v.get("dewpoint_c"),
        qnh_hpa=v.get("qnh_hpa"),
        present_weather=v.get("present_weather"),
        # A preset without [fog] has none: switching presets never leaves another's fog.
        fog=_fog(v["fog"]) if v.get("fog") is not None else NO_FOG,
        seed=v.get("seed"),
    )


def _fog(f: dict[str, Any]) -> Fog:
    return Fog(
        visibility_m=f.get("visibility_m"),
        depth_m=f["depth_m"],
        patchy=f["patchy"],
        rvr=tuple(RunwayRvr(r["runway"], r["rvr_m"]) for r in f["rvr"]),
    )
