"""Presets out: weather as preset-shaped plain data, as TOML text, and compared field by field.

The stdlib reads TOML but does not write it; presets need only a small subset (scalars, lists
of strings, one `[observer]` table and the `[[layers]]` / `[[wind]]` arrays of tables), so
`preset_to_toml` writes that subset itself. Loading its output gives back an equal patch.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import PurePath
from typing import Any

from wxsky.settings.preset_check import TOP_KEYS, KeyPath, format_key
from wxsky.weather.state import NO_FOG, Provenance, Source, WeatherPatch, WeatherState


@dataclass(frozen=True)
class Difference:
    """One field that two presets set differently; None where a preset leaves it unset."""

    key: str
    a: Any
    b: Any


def as_patch(weather: WeatherPatch | WeatherState) -> WeatherPatch:
    """A state as the patch that sets every field it has."""
    if isinstance(weather, WeatherPatch):
        return weather
    fields = {f.name: getattr(weather, f.name) for f in dataclasses.fields(Provenance)}
    return WeatherPatch(source=Source.PRESET, **fields)


def preset_dict(weather: WeatherPatch | WeatherState, *, sort: bool = False) -> dict[str, Any]:
    """The fields a patch (or state) sets, with the keys and units of a preset file; layers
    and wind in the patch's order, or by height with `sort` (the order the state keeps)."""
    patch = as_patch(weather)
    out: dict[str, Any] = {}
    if patch.time_utc is not None:
        out["time_utc"] = _time_text(patch.time_utc)
    for key in ("seed", "visibility_m", "temperature_c", "dewpoint_c", "qnh_hpa"):
        value = getattr(patch, key)
        if value is not None:
            out[key] = value
    if patch.present_weather is not None:
        out["present_weather"] = list(patch.present_weather)
    if patch.fog is not None and patch.fog != NO_FOG:
        # A preset has no way to say "no fog" but to leave the table out.
        out["fog"] = {k: v for k, v in patch.fog.to_dict().items() if v is not None}
    if patch.observer is not None:
        obs = patch.observer
        out["observer"] = {"lat_deg": obs.lat_deg, "lon_deg": obs.lon_deg, "alt_m": obs.alt_m}
    if patch.layers is not None:
        layers = sorted(patch.layers, key=lambda lay: lay.base_m) if sort else patch.layers
        out["layers"] = [
            {
                "type": lay.type.wire_name,
                "cover_oktas": _whole_oktas(lay.cover_oktas),
                "base_m": lay.base_m,
                "top_m": lay.top_m,
            }
            for lay in layers
        ]
    if patch.wind is not None:
        winds = sorted(patch.wind, key=lambda w: w.alt_m) if sort else patch.wind
        out["wind"] = [
            {
                "alt_m": w.alt_m,
                "dir_deg": w.dir_from_deg,
                "speed_mps": w.speed_mps,
                "gust_mps": w.gust_mps,
                **({"variable": True} if w.variable else {}),
            }
            for w in winds
        ]
    return out


def preset_to_toml(
    weather: WeatherPatch | WeatherState, description: str, comment: str = ""
) -> str:
    """A preset file that loads back to `weather` (as a patch with source preset). `comment`
    becomes `#` lines at the top. Raises ValueError for a fractional cloud cover (a state in
    the middle of a transition), which a preset cannot hold."""
    if not description.strip():
        raise ValueError("a preset needs a non-empty description")
    data = preset_dict(weather)
    lines = [f"# {line}".rstrip() for line in comment.splitlines()]
    lines.append(f"description = {toml_value(description.strip())}")
    tables: list[str] = []
    for key, value in data.items():
        if key == "observer":
            tables += ["", "[observer]", *_table_lines(value)]
        elif key in ("layers", "wind") and value:
            for entry in value:
                tables += ["", f"[[{key}]]", *_table_lines(entry)]
        else:
            # Scalars, lists of strings and empty arrays (`layers = []`: "no clouds") all go
            # before the first table header, where TOML puts top-level keys.
            lines.append(f"{key} = {toml_value(value)}")
    return "\n".join(lines + tables) + "\n"


def preset_diff(a: WeatherPatch | WeatherState, b: WeatherPatch | WeatherState) -> list[Difference]:
    """Field-by-field differences of the weather two presets make, in preset key order:
    `layers[0].cover_oktas`, `wind[1].speed_mps`, ...; a field or list entry only one side
    sets has None on the other. Layers and winds are compared by height order."""
    flat_a = _flatten(preset_dict(a, sort=True))
    flat_b = _flatten(preset_dict(b, sort=True))
    paths = sorted(set(flat_a) | set(flat_b), key=_rank)
    return [
        Difference(format_key(path), flat_a.get(path), flat_b.get(path))
        for path in paths
        if flat_a.get(path) != flat_b.get(path)
    ]


def format_value(value: Any) -> str:
    """A diff value as it would appear in a preset file; None is `(unset)`."""
    if value is None:
        return "(unset)"
    if isinstance(value, str):
        return value
    return toml_value(value)


def _flatten(data: dict[str, Any]) -> dict[KeyPath, Any]:
    out: dict[KeyPath, Any] = {}
    for key, value in data.items():
        if isinstance(value, dict):
            for sub, v in value.items():
                out[(key, sub)] = v
        elif isinstance(value, list) and value and isinstance(value[0], dict):
            for i, entry in enumerate(value):
                for sub, v in entry.items():
                    out[(key, i, sub)] = v
        else:
            out[(key,)] = value
    return out


_SUB_ORDER: tuple[str, ...] = (
    *("lat_deg", "lon_deg", "alt_m"),
    *("type", "cover_oktas", "base_m", "top_m"),
    *("dir_deg", "speed_mps", "gust_mps", "variable"),
)


def _rank(path: KeyPath) -> tuple[int, int, int]:
    top = TOP_KEYS.index(str(path[0])) if path[0] in TOP_KEYS else len(TOP_KEYS)
    index = path[1] if len(path) > 2 and isinstance(path[1], int) else -1
    sub = str(path[-1]) if len(path) > 1 else ""
    return (top, index, _SUB_ORDER.index(sub) if sub in _SUB_ORDER else -1)


def _table_lines(table: dict[str, Any]) -> list[str]:
    return [f"{key} = {toml_value(value)}" for key, value in table.items()]


def toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"a preset cannot hold {value!r}")
        return repr(value)  # shortest text that reads back as the same float
    if isinstance(value, str | PurePath):
        return toml_string(str(value))
    if isinstance(value, list | tuple):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    raise TypeError(f"no TOML form for {value!r}")


def toml_string(text: str) -> str:
    """A TOML basic string: quote, backslash and control characters escaped."""
    escapes = {'"': '\\"', "\\": "\\\\", "\b": "\\b", "\t": "\\t", "\n": "\\n", "\f": "\\f"}
    escapes["\r"] = "\\r"
    out = []
    for ch in text:
        if ch in escapes:
            out.append(escapes[ch])
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04X}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def _time_text(t: datetime) -> str:
    t = t.astimezone(UTC)
    # The year padded by hand: strftime writes year 857 as `857`, which TOML does not read.
    text = f"{t.year:04d}-{t:%m-%dT%H:%M:%S}"
    if t.microsecond:
        text += f".{t.microsecond:06d}"
    return text + "Z"


def _whole_oktas(cover: float) -> int:
    if not float(cover).is_integer():
        raise ValueError(
            f"cloud cover {cover} is not a whole number of oktas (the weather is changing)"
        )
    return int(cover)
