"""Weather presets: named TOML files that become a `WeatherPatch` with `source=Source.PRESET`.

A preset `<name>.toml` is looked up in the config's `presets.dirs`, then in `configs/presets/` of
the checkout this package lives in, then in `<sys.prefix>/share/wxsky/presets`; the first file
of a name wins, so a user directory can override a built-in preset. Every key but
`description` is optional and the patch sets only what the file gives, so a preset that should
clear the sky must say `layers = []`.
"""

from __future__ import annotations

import math
import re
import sys
from collections.abc import Iterable
from dataclasses import dataclass
from datetime import UTC, date, datetime, time
from pathlib import Path
from typing import Any

from wxsky.config import PRESET_NAME_PATTERN, read_toml_file, unknown_key_message
from wxsky.errors import PresetError
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

_TOP_KEYS = (
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
_OBSERVER_KEYS = ("lat_deg", "lon_deg", "alt_m")
_LAYER_KEYS = ("type", "cover_oktas", "base_m", "top_m")
_WIND_KEYS = ("alt_m", "dir_deg", "speed_mps", "gust_mps", "variable")

# A METAR weather group such as "-RA", "+TSRA", "VCSH", "BR"; decoding them is the METAR
# module's business, this only keeps obvious junk out of the state.
_WEATHER_GROUP = re.compile(r"(?:[+-]|VC)?[A-Z]{2,12}")


@dataclass(frozen=True)
class PresetInfo:
    name: str
    description: str
    path: Path


def builtin_preset_dirs() -> tuple[Path, ...]:
    """The built-in preset directories, in search order; they need not exist."""
    # This module's own path rather than wxsky.__file__: the two name the same checkout, but a
    # stale editable install can make `wxsky` a namespace package whose __file__ is None.
    checkout = Path(__file__).resolve().parents[1] / "configs" / "presets"
    installed = Path(sys.prefix) / "share" / "wxsky" / "presets"
    return (checkout, installed)


def preset_search_path(extra_dirs: Iterable[Path | str] = ()) -> tuple[Path, ...]:
    """Every directory searched for presets, in order. An extra directory that does not exist is
    a PresetError: it was asked for by name, so a typo in it should not pass unnoticed."""
    extra = tuple(Path(d).expanduser() for d in extra_dirs)
    for d in extra:
        if not d.is_dir():
            raise PresetError(f"preset directory {str(d)!r} does not exist")
    return extra + builtin_preset_dirs()


def list_presets(extra_dirs: Iterable[Path | str] = ()) -> list[PresetInfo]:
    """Every preset found, sorted by name. Each is parsed, so a malformed one is a PresetError
    here rather than a surprise when a host switches to it."""
    return [load_preset_file(path)[0] for _, path in sorted(_find_presets(extra_dirs).items())]


def load_preset(name: str, extra_dirs: Iterable[Path | str] = ()) -> WeatherPatch:
    """The named preset as a patch. Raises PresetError for a bad or unknown name (listing the
    known ones) or a malformed file (naming the file and key)."""
    if not isinstance(name, str) or not re.fullmatch(PRESET_NAME_PATTERN, name):
        raise PresetError(
            f"invalid preset name {name!r}: names are lowercase letters, digits and '-'"
        )
    dirs = tuple(extra_dirs)
    found = _find_presets(dirs)
    if name not in found:
        if found:
            raise PresetError(f"unknown preset {name!r} (known: {', '.join(sorted(found))})")
        searched = ", ".join(str(d) for d in preset_search_path(dirs))
        raise PresetError(f"unknown preset {name!r}: no presets found in {searched}")
    return load_preset_file(found[name])[1]


def load_preset_file(path: Path) -> tuple[PresetInfo, WeatherPatch]:
    """One preset file, whatever its directory; the name is the file's stem."""
    data = read_toml_file(path, PresetError)
    try:
        description, patch = _parse_preset(data)
        # The state's own checks (layer count, ranges) are the final word on validity.
        WeatherState().apply(patch)
    except ValueError as exc:
        raise PresetError(f"{path}: {exc}") from None
    return PresetInfo(path.stem, description, path), patch


def _find_presets(extra_dirs: Iterable[Path | str]) -> dict[str, Path]:
    found: dict[str, Path] = {}
    for d in preset_search_path(extra_dirs):
        if not d.is_dir():
            continue
        for path in sorted(d.glob("*.toml")):
            if re.fullmatch(PRESET_NAME_PATTERN, path.stem) and path.is_file():
                found.setdefault(path.stem, path)
    return found


def _parse_preset(data: dict[str, Any]) -> tuple[str, WeatherPatch]:
    _check_keys(data, _TOP_KEYS, "")
    description = data.get("description")
    if description is None:
        raise ValueError("missing key 'description'")
    if not isinstance(description, str) or not description.strip():
        raise ValueError(f"description must be a non-empty string, got {description!r}")

    temperature_c = _number(data, "temperature_c", -90.0, 60.0)
    dewpoint_c = _number(data, "dewpoint_c", -90.0, 60.0)
    if temperature_c is not None and dewpoint_c is not None and dewpoint_c > temperature_c:
        raise ValueError(
            f"dewpoint_c {_fmt(dewpoint_c)} is above temperature_c {_fmt(temperature_c)}"
        )

    patch = WeatherPatch(
        source=Source.PRESET,
        observer=_observer(data["observer"]) if "observer" in data else None,
        time_utc=_time_utc(data["time_utc"]) if "time_utc" in data else None,
        layers=_layers(data["layers"]) if "layers" in data else None,
        wind=_winds(data["wind"]) if "wind" in data else None,
        visibility_m=_number(data, "visibility_m", 0.0, 1_000_000.0),
        temperature_c=temperature_c,
        dewpoint_c=dewpoint_c,
        qnh_hpa=_number(data, "qnh_hpa", 850.0, 1100.0),
        present_weather=(
            _present_weather(data["present_weather"]) if "present_weather" in data else None
        ),
        seed=_seed(data["seed"]) if "seed" in data else None,
    )
    return description.strip(), patch


def _observer(value: Any) -> Observer:
    table = _table(value, "observer")
    _check_keys(table, _OBSERVER_KEYS, "observer.")
    return Observer(
        lat_deg=_required_number(table, "lat_deg", -90.0, 90.0, "observer."),
        lon_deg=_required_number(table, "lon_deg", -180.0, 180.0, "observer."),
        alt_m=_required_number(table, "alt_m", -500.0, 30_000.0, "observer."),
    )


def _time_utc(value: Any) -> datetime:
    # TOML has a native date-time type; accept it as well as a quoted ISO 8601 string.
    if isinstance(value, datetime):
        return value.replace(tzinfo=UTC) if value.tzinfo is None else value.astimezone(UTC)
    if isinstance(value, str):
        try:
            return parse_time_utc(value)
        except ValueError as exc:
            raise ValueError(f"time_utc: {exc}") from None
    kind = "a date without a time" if isinstance(value, date) else repr(value)
    if isinstance(value, time):
        kind = "a time without a date"
    raise ValueError(f"time_utc must be an ISO 8601 date-time, got {kind}")


def _layers(value: Any) -> tuple[CloudLayer, ...]:
    tables = _array_of_tables(value, "layers")
    if len(tables) > MAX_LAYERS:
        raise ValueError(f"layers: at most {MAX_LAYERS} cloud layers, got {len(tables)}")
    layers = []
    for i, table in enumerate(tables):
        prefix = f"layers[{i}]."
        _check_keys(table, _LAYER_KEYS, prefix)
        type_name = table.get("type")
        if type_name is None:
            raise ValueError(f"missing key '{prefix}type'")
        if not isinstance(type_name, str) or type_name.strip().lower() == "none":
            raise ValueError(f"{prefix}type must be a cloud type name, got {type_name!r}")
        try:
            cloud_type = CloudType.from_name(type_name)
        except ValueError as exc:
            raise ValueError(f"{prefix}type: {exc}") from None
        if "cover_oktas" not in table:
            raise ValueError(f"missing key '{prefix}cover_oktas'")
        cover = table["cover_oktas"]
        if not isinstance(cover, int) or isinstance(cover, bool) or not 0 <= cover <= 8:
            raise ValueError(f"{prefix}cover_oktas must be an integer in 0..8, got {cover!r}")
        base_m = _required_number(table, "base_m", -500.0, 25_000.0, prefix)
        top_m = _required_number(table, "top_m", -500.0, 25_000.0, prefix)
        if top_m <= base_m:
            raise ValueError(f"{prefix}top_m {_fmt(top_m)} must be above base_m {_fmt(base_m)}")
        layers.append(CloudLayer(cover, base_m, top_m, cloud_type))
    return tuple(layers)


def _winds(value: Any) -> tuple[WindLayer, ...]:
    winds = []
    seen_alts: dict[float, int] = {}
    for i, table in enumerate(_array_of_tables(value, "wind")):
        prefix = f"wind[{i}]."
        _check_keys(table, _WIND_KEYS, prefix)
        alt_m = _required_number(table, "alt_m", -500.0, 30_000.0, prefix)
        if alt_m in seen_alts:
            raise ValueError(f"{prefix}alt_m {_fmt(alt_m)} repeats wind[{seen_alts[alt_m]}].alt_m")
        seen_alts[alt_m] = i
        speed_mps = _required_number(table, "speed_mps", 0.0, 150.0, prefix)
        gust_mps = _number(table, "gust_mps", 0.0, 200.0, prefix) or 0.0
        if 0.0 < gust_mps < speed_mps:
            raise ValueError(
                f"{prefix}gust_mps {_fmt(gust_mps)} must be 0 (no gusts) or at least "
                f"speed_mps {_fmt(speed_mps)}"
            )
        variable = table.get("variable", False)
        if not isinstance(variable, bool):
            raise ValueError(f"{prefix}variable must be true or false, got {variable!r}")
        winds.append(
            WindLayer(
                alt_m=alt_m,
                dir_from_deg=_required_number(table, "dir_deg", 0.0, 360.0, prefix),
                speed_mps=speed_mps,
                gust_mps=gust_mps,
                variable=variable,
            )
        )
    return tuple(winds)


def _present_weather(value: Any) -> tuple[str, ...]:
    if not isinstance(value, list):
        raise ValueError(f"present_weather must be a list of METAR groups, got {value!r}")
    for group in value:
        if not isinstance(group, str) or not _WEATHER_GROUP.fullmatch(group):
            raise ValueError(
                f"present_weather entries must be METAR weather groups like '-RA' or 'TSRA', "
                f"got {group!r}"
            )
    return tuple(value)


def _seed(value: Any) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value < 2**63:
        raise ValueError(f"seed must be an integer in 0..2**63-1, got {value!r}")
    return value


def _check_keys(table: dict[str, Any], known: tuple[str, ...], prefix: str) -> None:
    for key in table:
        if key not in known:
            raise ValueError(unknown_key_message(f"{prefix}{key}", known))


def _table(value: Any, key: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise ValueError(f"{key} must be a table ([{key}]), got {value!r}")
    return value


def _array_of_tables(value: Any, key: str) -> list[dict[str, Any]]:
    if not isinstance(value, list) or not all(isinstance(t, dict) for t in value):
        raise ValueError(f"{key} must be an array of tables ([[{key}]]), got {value!r}")
    return value


def _required_number(
    table: dict[str, Any], key: str, lo: float, hi: float, prefix: str = ""
) -> float:
    value = _number(table, key, lo, hi, prefix)
    if value is None:
        raise ValueError(f"missing key '{prefix}{key}'")
    return value


def _number(
    table: dict[str, Any], key: str, lo: float, hi: float, prefix: str = ""
) -> float | None:
    if key not in table:
        return None
    value = table[key]
    ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    if not ok or not math.isfinite(value) or not lo <= value <= hi:
        raise ValueError(f"{prefix}{key} must be a number in {_fmt(lo)}..{_fmt(hi)}, got {value!r}")
    return float(value)


def _fmt(x: float) -> str:
    """A bound or value as a person writes it: 1000000, 0.5, -90."""
    return str(int(x)) if float(x).is_integer() else str(x)
