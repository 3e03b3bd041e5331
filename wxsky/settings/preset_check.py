"""Check preset files: the parser behind `load_preset_file` and `wxsky preset validate`.

The parser does not stop at the first problem: it collects every one with the key path it is
about, e.g. `("layers", 1, "cover_oktas")`, and `key_line` maps that path back to a line of the
source (tomllib gives no positions for values), so each problem reads `FILE:LINE: key: what`.
"""

from __future__ import annotations

import difflib
import json
import math
import re
import tomllib
from dataclasses import dataclass
from datetime import UTC, date, datetime, time
from pathlib import Path
from typing import Any

from wxsky.weather.state import (
    MAX_LAYERS,
    CloudLayer,
    CloudType,
    Observer,
    Source,
    WeatherPatch,
    WeatherState,
    WindLayer,
    parse_time_utc,
)

KeyPath = tuple[str | int, ...]

TOP_KEYS = (
    "description",
    "time_utc",
    "seed",
    "visibility_m",
    "temperature_c",
    "dewpoint_c",
    "qnh_hpa",
    "present_weather",
    "observer",
    "layers",
    "wind",
)
OBSERVER_KEYS = ("lat_deg", "lon_deg", "alt_m")
LAYER_KEYS = ("type", "cover_oktas", "base_m", "top_m")
WIND_KEYS = ("alt_m", "dir_deg", "speed_mps", "gust_mps", "variable")

# A METAR weather group such as "-RA", "+TSRA", "VCSH", "BR"; decoding them is the METAR
# module's business, this only keeps obvious junk out of the state.
_WEATHER_GROUP = re.compile(r"(?:[+-]|VC)?[A-Z]{2,12}")


@dataclass(frozen=True)
class Problem:
    """One thing wrong with a preset. `at` is where to point when that differs from `path`
    (too many layers: the key is `layers`, the line is the first layer too many)."""

    path: KeyPath
    message: str
    at: KeyPath | None = None

    @property
    def key(self) -> str:
        return format_key(self.path)


@dataclass(frozen=True)
class LocatedProblem:
    line: int | None  # None only where the file could not be read at all
    key: str  # "" for problems of the whole file (syntax, encoding)
    message: str

    def __str__(self) -> str:
        parts = [str(self.line)] if self.line is not None else []
        if self.key:
            parts.append(self.key)
        parts.append(self.message)
        return ": ".join(parts)


@dataclass(frozen=True)
class PresetCheck:
    """The outcome of checking one file: the patch is None unless there are no problems."""

    path: Path
    description: str
    patch: WeatherPatch | None
    problems: tuple[LocatedProblem, ...]

    def lines(self) -> list[str]:
        """Every problem as `FILE:LINE: key: problem`, in file order."""
        return [
            f"{self.path}:{p}" if p.line is not None else f"{self.path}: {p}" for p in self.problems
        ]

    def error_message(self) -> str:
        """The first problem, on one line, with a count of the others."""
        first = self.lines()[0]
        more = len(self.problems) - 1
        if more:
            first += f" (and {more} more problem{'s' if more > 1 else ''})"
        return first


def format_key(path: KeyPath) -> str:
    """("layers", 1, "cover_oktas") -> "layers[1].cover_oktas"; odd keys are quoted."""
    out = ""
    for part in path:
        if isinstance(part, int):
            out += f"[{part}]"
            continue
        text = part if re.fullmatch(r"[A-Za-z0-9_-]+", part) else json.dumps(part)
        out += f".{text}" if out else text
    return out


def check_preset_file(path: Path) -> PresetCheck:
    """Read, parse and check one preset file; never raises for a bad file."""
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        return _unreadable(path, "no such file")
    except IsADirectoryError:
        return _unreadable(path, "is a directory, not a file")
    except OSError as exc:
        return _unreadable(path, f"cannot read: {exc.strerror or exc}")
    return check_preset_bytes(path, raw)


def check_preset_bytes(path: Path, raw: bytes) -> PresetCheck:
    """Check a preset's bytes; `path` names it in messages and gives the preset its name."""
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        return PresetCheck(path, "", None, (LocatedProblem(line, "", "not UTF-8 text"),))
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        message = str(exc)
        m = re.search(r"\(at line (\d+), column \d+\)", message)
        # tomllib gives no line for errors at the end of the input, the usual symptom of a
        # truncated file; the last line is where the reader should look.
        line = int(m.group(1)) if m else text.rstrip("\n").count("\n") + 1
        problem = LocatedProblem(line, "", f"invalid TOML: {message}")
        return PresetCheck(path, "", None, (problem,))
    description, patch, problems = parse_preset_data(data)
    lines = key_lines(text)
    located = sorted(
        (LocatedProblem(_line_of(lines, p.at or p.path), p.key, p.message) for p in problems),
        key=lambda p: p.line or 0,
    )
    return PresetCheck(path, description, None if located else patch, tuple(located))


def parse_preset_data(data: dict[str, Any]) -> tuple[str, WeatherPatch, list[Problem]]:
    """A parsed TOML preset as (description, patch, problems). The patch is only meaningful
    when there are no problems: a field with a problem is left out of it."""
    p = _Problems()
    p.check_keys(data, TOP_KEYS, ())
    description = data.get("description")
    if description is None:
        p.add(("description",), "missing key")
        description = ""
    elif not isinstance(description, str) or not description.strip():
        p.add(("description",), f"must be a non-empty string, got {description!r}")
        description = ""

    temperature_c = p.number(data, (), "temperature_c", -90.0, 60.0)
    dewpoint_c = p.number(data, (), "dewpoint_c", -90.0, 60.0)
    if temperature_c is not None and dewpoint_c is not None and dewpoint_c > temperature_c:
        p.add(("dewpoint_c",), f"{_fmt(dewpoint_c)} is above temperature_c {_fmt(temperature_c)}")

    patch = WeatherPatch(
        source=Source.PRESET,
        observer=_observer(p, data["observer"]) if "observer" in data else None,
        time_utc=_time_utc(p, data["time_utc"]) if "time_utc" in data else None,
        layers=_layers(p, data["layers"]) if "layers" in data else None,
        wind=_winds(p, data["wind"]) if "wind" in data else None,
        visibility_m=p.number(data, (), "visibility_m", 0.0, 1_000_000.0),
        temperature_c=temperature_c,
        dewpoint_c=dewpoint_c,
        qnh_hpa=p.number(data, (), "qnh_hpa", 850.0, 1100.0),
        present_weather=(
            _present_weather(p, data["present_weather"]) if "present_weather" in data else None
        ),
        seed=_seed(p, data["seed"]) if "seed" in data else None,
    )
    if not p.problems:
        # The state's own checks (layer count, ranges) are the final word on validity.
        try:
            WeatherState().apply(patch)
        except ValueError as exc:
            p.add((), str(exc))
    return description.strip(), patch, p.problems


class _Problems:
    def __init__(self) -> None:
        self.problems: list[Problem] = []

    def add(self, path: KeyPath, message: str, at: KeyPath | None = None) -> None:
        self.problems.append(Problem(path, message, at))

    def check_keys(self, table: dict[str, Any], known: tuple[str, ...], prefix: KeyPath) -> None:
        for key in table:
            if key not in known:
                close = difflib.get_close_matches(key, list(known), n=1)
                hint = f" (did you mean {close[0]!r}?)" if close else ""
                self.add((*prefix, key), f"unknown key{hint}")

    def number(
        self, table: dict[str, Any], prefix: KeyPath, key: str, lo: float, hi: float
    ) -> float | None:
        """The value if present and valid; None (with a problem if present) otherwise."""
        if key not in table:
            return None
        value = table[key]
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        if not ok or not math.isfinite(value) or not lo <= value <= hi:
            self.add((*prefix, key), f"must be a number in {_fmt(lo)}..{_fmt(hi)}, got {value!r}")
            return None
        return float(value)

    def required(
        self, table: dict[str, Any], prefix: KeyPath, key: str, lo: float, hi: float
    ) -> float | None:
        if key not in table:
            self.add((*prefix, key), "missing key")
            return None
        return self.number(table, prefix, key, lo, hi)

    def array_of_tables(self, value: Any, key: str) -> list[dict[str, Any]] | None:
        if not isinstance(value, list) or not all(isinstance(t, dict) for t in value):
            self.add((key,), f"must be an array of tables ([[{key}]]), got {value!r}")
            return None
        return value


def _observer(p: _Problems, value: Any) -> Observer | None:
    if not isinstance(value, dict):
        p.add(("observer",), f"must be a table ([observer]), got {value!r}")
        return None
    before = len(p.problems)
    path: KeyPath = ("observer",)
    p.check_keys(value, OBSERVER_KEYS, path)
    lat = p.required(value, path, "lat_deg", -90.0, 90.0)
    lon = p.required(value, path, "lon_deg", -180.0, 180.0)
    alt = p.required(value, path, "alt_m", -500.0, 30_000.0)
    if len(p.problems) > before or lat is None or lon is None or alt is None:
        return None
    try:
        return Observer(lat_deg=lat, lon_deg=lon, alt_m=alt)
    except ValueError as exc:
        p.add(path, str(exc))
        return None


def _time_utc(p: _Problems, value: Any) -> datetime | None:
    # TOML has a native date-time type; accept it as well as a quoted ISO 8601 string.
    if isinstance(value, datetime):
        return value.replace(tzinfo=UTC) if value.tzinfo is None else value.astimezone(UTC)
    if isinstance(value, str):
        try:
            return parse_time_utc(value)
        except ValueError as exc:
            p.add(("time_utc",), str(exc))
            return None
    kind = "a date without a time" if isinstance(value, date) else repr(value)
    if isinstance(value, time):
        kind = "a time without a date"
    p.add(("time_utc",), f"must be an ISO 8601 date-time, got {kind}")
    return None


def _layers(p: _Problems, value: Any) -> tuple[CloudLayer, ...] | None:
    tables = p.array_of_tables(value, "layers")
    if tables is None:
        return None
    before = len(p.problems)
    layers = []
    for i, table in enumerate(tables):
        path: KeyPath = ("layers", i)
        p.check_keys(table, LAYER_KEYS, path)
        cloud_type = _cloud_type(p, table, path)
        cover = _oktas(p, table, path)
        base_m = p.required(table, path, "base_m", -500.0, 25_000.0)
        top_m = p.required(table, path, "top_m", -500.0, 25_000.0)
        if base_m is None or top_m is None:
            continue
        if top_m <= base_m:
            p.add((*path, "top_m"), f"{_fmt(top_m)} must be above base_m {_fmt(base_m)}")
        elif cloud_type is not None and cover is not None:
            try:
                layers.append(CloudLayer(cover, base_m, top_m, cloud_type))
            except ValueError as exc:
                p.add(path, str(exc))
    if len(tables) > MAX_LAYERS:
        p.add(
            ("layers",),
            f"at most {MAX_LAYERS} cloud layers, got {len(tables)}",
            at=("layers", MAX_LAYERS),
        )
    return None if len(p.problems) > before else tuple(layers)


def _cloud_type(p: _Problems, table: dict[str, Any], path: KeyPath) -> CloudType | None:
    type_name = table.get("type")
    if type_name is None:
        p.add((*path, "type"), "missing key")
        return None
    if not isinstance(type_name, str) or type_name.strip().lower() == "none":
        p.add((*path, "type"), f"must be a cloud type name, got {type_name!r}")
        return None
    try:
        return CloudType.from_name(type_name)
    except ValueError as exc:
        p.add((*path, "type"), str(exc))
        return None


def _oktas(p: _Problems, table: dict[str, Any], path: KeyPath) -> int | None:
    if "cover_oktas" not in table:
        p.add((*path, "cover_oktas"), "missing key")
        return None
    cover = table["cover_oktas"]
    if not isinstance(cover, int) or isinstance(cover, bool) or not 0 <= cover <= 8:
        p.add((*path, "cover_oktas"), f"must be an integer in 0..8, got {cover!r}")
        return None
    return cover


def _winds(p: _Problems, value: Any) -> tuple[WindLayer, ...] | None:
    tables = p.array_of_tables(value, "wind")
    if tables is None:
        return None
    before = len(p.problems)
    winds = []
    seen_alts: dict[float, int] = {}
    for i, table in enumerate(tables):
        path: KeyPath = ("wind", i)
        p.check_keys(table, WIND_KEYS, path)
        alt_m = p.required(table, path, "alt_m", -500.0, 30_000.0)
        if alt_m is not None:
            if alt_m in seen_alts:
                p.add((*path, "alt_m"), f"{_fmt(alt_m)} repeats wind[{seen_alts[alt_m]}].alt_m")
            seen_alts.setdefault(alt_m, i)
        dir_deg = p.required(table, path, "dir_deg", 0.0, 360.0)
        speed_mps = p.required(table, path, "speed_mps", 0.0, 150.0)
        gust_mps = p.number(table, path, "gust_mps", 0.0, 200.0)
        if "gust_mps" not in table:
            gust_mps = 0.0
        if speed_mps is not None and gust_mps is not None and 0.0 < gust_mps < speed_mps:
            p.add(
                (*path, "gust_mps"),
                f"{_fmt(gust_mps)} must be 0 (no gusts) or at least speed_mps {_fmt(speed_mps)}",
            )
        variable = table.get("variable", False)
        if not isinstance(variable, bool):
            p.add((*path, "variable"), f"must be true or false, got {variable!r}")
            continue
        if alt_m is None or dir_deg is None or speed_mps is None or gust_mps is None:
            continue
        try:
            winds.append(WindLayer(alt_m, dir_deg, speed_mps, gust_mps, variable))
        except ValueError as exc:
            p.add(path, str(exc))
    return None if len(p.problems) > before else tuple(winds)


def _present_weather(p: _Problems, value: Any) -> tuple[str, ...] | None:
    if not isinstance(value, list):
        p.add(("present_weather",), f"must be a list of METAR groups, got {value!r}")
        return None
    ok = True
    for i, group in enumerate(value):
        if not isinstance(group, str) or not _WEATHER_GROUP.fullmatch(group):
            p.add(
                ("present_weather", i),
                f"must be a METAR weather group like '-RA' or 'TSRA', got {group!r}",
            )
            ok = False
    return tuple(value) if ok else None


def _seed(p: _Problems, value: Any) -> int | None:
    if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value < 2**63:
        p.add(("seed",), f"must be an integer in 0..2**63-1, got {value!r}")
        return None
    return value


def _fmt(x: float) -> str:
    """A bound or value as a person writes it: 1000000, 0.5, -90."""
    return str(int(x)) if float(x).is_integer() else str(x)


def _unreadable(path: Path, why: str) -> PresetCheck:
    return PresetCheck(path, "", None, (LocatedProblem(None, "", why),))


# -- key paths back to source lines ---------------------------------------------------------

_SEGMENT = r"""(?:[A-Za-z0-9_-]+|"(?:[^"\\]|\\.)*"|'[^']*')"""
_DOTTED = rf"{_SEGMENT}(?:\s*\.\s*{_SEGMENT})*"
_HEADER_RE = re.compile(rf"\s*(\[\[?)\s*({_DOTTED})\s*\]\]?\s*(?:#.*)?$")
_KEY_RE = re.compile(rf"\s*({_DOTTED})\s*=")
_SEGMENT_RE = re.compile(_SEGMENT)


def key_line(text: str, path: KeyPath) -> int | None:
    """The 1-based line where `path` is given in the TOML source `text`, e.g.
    ("layers", 1, "cover_oktas") -> the `cover_oktas = ...` line after the second `[[layers]]`.
    A path the source does not spell out (a missing key, an entry of an inline array) gives the
    line of its nearest enclosing key or table; None if not even the first part is there."""
    return _find(key_lines(text), path)


def key_lines(text: str) -> dict[KeyPath, int]:
    """Every key path and table header the source spells out, with the line it first appears
    on. Array-of-tables headers count up: the second `[[layers]]` is ("layers", 1)."""
    found: dict[KeyPath, int] = {}
    counters: dict[KeyPath, int] = {}
    table: KeyPath = ()
    in_string: str | None = None
    for number, line in enumerate(text.splitlines(), start=1):
        if in_string is not None:
            if in_string in line:
                in_string = None
            continue
        header = _HEADER_RE.match(line)
        if header:
            table = _concrete(_segments(header.group(2)), counters, header.group(1) == "[[")
            _record(found, table, number)
            continue
        key = _KEY_RE.match(line)
        if key:
            _record(found, (*table, *_segments(key.group(1))), number)
            value = line[key.end() :]
            for quote in ('"""', "'''"):
                if value.count(quote) % 2 == 1:
                    in_string = quote
    return found


def _find(lines: dict[KeyPath, int], path: KeyPath) -> int | None:
    for n in range(len(path), 0, -1):
        if path[:n] in lines:
            return lines[path[:n]]
    return None


def _line_of(lines: dict[KeyPath, int], path: KeyPath) -> int:
    return _find(lines, path) or 1


def _segments(dotted: str) -> list[str]:
    out = []
    for seg in _SEGMENT_RE.findall(dotted):
        if seg.startswith('"'):
            out.append(json.loads(seg))
        elif seg.startswith("'"):
            out.append(seg[1:-1])
        else:
            out.append(seg)
    return out


def _concrete(segments: list[str], counters: dict[KeyPath, int], new_entry: bool) -> KeyPath:
    """A header's key path with array indices filled in: the latest entry of each array of
    tables on the way, a new one for the last segment of a `[[...]]` header."""
    path: KeyPath = ()
    for i, seg in enumerate(segments):
        path = (*path, seg)
        if new_entry and i == len(segments) - 1:
            n = counters.get(path, 0)
            counters[path] = n + 1
            path = (*path, n)
        elif path in counters:
            path = (*path, counters[path] - 1)
    return path


def _record(found: dict[KeyPath, int], path: KeyPath, line: int) -> None:
    for n in range(1, len(path) + 1):
        found.setdefault(path[:n], line)
