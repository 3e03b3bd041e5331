"""Weather presets: named TOML files that become a `WeatherPatch` with `source=Source.PRESET`.

A preset `<name>.toml` is looked up in the config's `presets.dirs`, then in the user folder
(`$XDG_CONFIG_HOME/wxsky/presets`, by default `~/.config/wxsky/presets`, where
`wxsky preset save` writes), then the built-in presets shipped as package data
(`wxsky/settings/presets/`, found through `importlib.resources` wherever the package is
installed); the first file of a name wins, so a user preset overrides a built-in one. Every
key but `description` is optional and the patch sets only what the file gives, so a preset
that should clear the sky must say `layers = []`.

Parsing and checking live in `wxsky.settings.preset_check` (every problem, with its line),
writing and comparing in `wxsky.settings.preset_write`.
"""

from __future__ import annotations

import contextlib
import os
import re
import tempfile
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wxsky.errors import PresetError
from wxsky.schema.toml_file import package_folder
from wxsky.settings.config import PRESET_NAME_PATTERN
from wxsky.settings.preset_check import PresetCheck, check_preset_file, parse_preset_data
from wxsky.settings.preset_write import preset_diff, preset_to_toml
from wxsky.weather.state import WeatherPatch

__all__ = [
    "PresetCheck",
    "PresetInfo",
    "builtin_preset_dirs",
    "check_preset_file",
    "find_preset",
    "list_presets",
    "load_preset",
    "load_preset_file",
    "patch_from_weather_dict",
    "preset_diff",
    "preset_search_path",
    "preset_to_toml",
    "resolve_preset",
    "user_preset_dir",
    "write_user_preset",
]

ORIGIN_BUILTIN = "builtin"
ORIGIN_USER = "user"


@dataclass(frozen=True)
class PresetInfo:
    name: str
    description: str
    path: Path
    origin: str = ""  # "builtin", "user", or the directory it came from
    overrides: tuple[str, ...] = ()  # origins of same-named presets this one hides


def user_preset_dir() -> Path:
    """The user's preset folder, `$XDG_CONFIG_HOME/wxsky/presets` (a relative XDG_CONFIG_HOME
    is ignored, as the XDG spec says), else `~/.config/wxsky/presets`. It need not exist."""
    xdg = os.environ.get("XDG_CONFIG_HOME", "")
    if xdg and Path(xdg).is_absolute():
        return Path(xdg) / "wxsky" / "presets"
    try:
        home = Path.home()
    except RuntimeError:
        raise PresetError(
            "cannot find the user preset folder: set HOME or XDG_CONFIG_HOME"
        ) from None
    return home / ".config" / "wxsky" / "presets"


def builtin_preset_dirs() -> tuple[Path, ...]:
    """The built-in preset directories, in search order: the package data folder."""
    return (package_folder("wxsky.settings", "presets"),)


def preset_search_path(extra_dirs: Iterable[Path | str] = ()) -> tuple[Path, ...]:
    """Every directory searched for presets, in order. An extra directory that does not exist is
    a PresetError: it was asked for by name, so a typo in it should not pass unnoticed."""
    return tuple(d for d, _ in _search_dirs(extra_dirs))


def list_presets(extra_dirs: Iterable[Path | str] = ()) -> list[PresetInfo]:
    """Every preset found, sorted by name. Each is parsed, so a malformed one is a PresetError
    here rather than a surprise when a host switches to it."""
    found = _find_presets(extra_dirs)
    infos = []
    for name in sorted(found):
        (path, origin), *hidden = found[name]
        info = load_preset_file(path)[0]
        overrides = tuple(dict.fromkeys(o for _, o in hidden if o != origin))
        infos.append(PresetInfo(name, info.description, path, origin, overrides))
    return infos


def find_preset(name: str, extra_dirs: Iterable[Path | str] = ()) -> tuple[Path, str]:
    """The file a preset name resolves to and its origin. Raises PresetError for a bad or
    unknown name, listing the known ones."""
    _check_name(name)
    dirs = tuple(extra_dirs)
    found = _find_presets(dirs)
    if name not in found:
        if found:
            raise PresetError(f"unknown preset {name!r} (known: {', '.join(sorted(found))})")
        searched = ", ".join(str(d) for d in preset_search_path(dirs))
        raise PresetError(f"unknown preset {name!r}: no presets found in {searched}")
    return found[name][0]


def load_preset(name: str, extra_dirs: Iterable[Path | str] = ()) -> WeatherPatch:
    """The named preset as a patch. Raises PresetError for a bad or unknown name (listing the
    known ones) or a malformed file (`FILE:LINE: key: problem`)."""
    return load_preset_file(find_preset(name, extra_dirs)[0])[1]


def load_preset_file(path: Path) -> tuple[PresetInfo, WeatherPatch]:
    """One preset file, whatever its directory; the name is the file's stem. Raises PresetError
    with the first problem (file, line, key) and how many more there are."""
    check = check_preset_file(Path(path))
    if check.patch is None:
        raise PresetError(check.error_message())
    return PresetInfo(check.path.stem, check.description, check.path), check.patch


def resolve_preset(
    name_or_path: str, extra_dirs: Iterable[Path | str] = ()
) -> tuple[PresetInfo, WeatherPatch]:
    """A preset given as a name (looked up) or as a file path (anything with a `/` or ending
    in `.toml`)."""
    if "/" in name_or_path or name_or_path.endswith(".toml") or os.sep in name_or_path:
        info, patch = load_preset_file(Path(name_or_path))
        return PresetInfo(info.name, info.description, info.path, "file"), patch
    path, origin = find_preset(name_or_path, extra_dirs)
    info, patch = load_preset_file(path)
    return PresetInfo(info.name, info.description, path, origin), patch


def patch_from_weather_dict(weather: Mapping[str, Any]) -> WeatherPatch:
    """A preset patch from the `weather` map of the daemon's `status` (`weather_to_dict`'s
    shape). `sources` and `precipitation` (presets do not hold it yet) are dropped, an unknown
    temperature left unset, and a fractional cloud cover (the weather in the middle of a
    transition) rounded to whole oktas. Raises PresetError naming the key if the map is not
    weather."""
    data: dict[str, Any] = {"description": "from the daemon"}
    for key, value in weather.items():
        if key not in ("sources", "precipitation") and value is not None:
            data[key] = value
    layers = data.get("layers")
    if isinstance(layers, list):
        data["layers"] = [_whole_oktas(layer) for layer in layers]
    fog = data.get("fog")
    if isinstance(fog, dict):  # a fog of only the RVRs' has no visibility_m
        data["fog"] = {k: v for k, v in fog.items() if v is not None}
    _, patch, problems = parse_preset_data(data)
    if problems:
        first = problems[0]
        where = f"{first.key}: " if first.path else ""
        raise PresetError(f"the daemon's weather is not a valid preset: {where}{first.message}")
    return patch


def write_user_preset(name: str, text: str, force: bool = False) -> Path:
    """Write `text` as the user preset `name` and return its path. Refuses to replace an
    existing file unless `force`; the file appears whole or not at all."""
    _check_name(name)
    folder = user_preset_dir()
    path = folder / f"{name}.toml"
    if path.exists() and not force:
        raise PresetError(f"{path} already exists (use --force to replace it)")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{name}.", suffix=".tmp", dir=folder)
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(text)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
    except OSError as exc:
        raise PresetError(f"cannot write {path}: {exc.strerror or exc}") from None
    return path


def _check_name(name: str) -> None:
    if not isinstance(name, str) or not re.fullmatch(PRESET_NAME_PATTERN, name):
        shown = name if not isinstance(name, str) or len(name) <= 40 else name[:40] + "…"
        raise PresetError(
            f"invalid preset name {shown!r}: names are 1 to 64 lowercase letters, digits and '-'"
        )


def _search_dirs(extra_dirs: Iterable[Path | str]) -> list[tuple[Path, str]]:
    dirs: list[tuple[Path, str]] = []
    for d in extra_dirs:
        path = Path(d).expanduser()
        if not path.is_dir():
            raise PresetError(f"preset directory {str(path)!r} does not exist")
        dirs.append((path, str(path)))
    # No home to find the user folder in: the other directories still work.
    with contextlib.suppress(PresetError):
        dirs.append((user_preset_dir(), ORIGIN_USER))
    dirs += [(d, ORIGIN_BUILTIN) for d in builtin_preset_dirs()]
    return dirs


def _find_presets(extra_dirs: Iterable[Path | str]) -> dict[str, list[tuple[Path, str]]]:
    """Each name with every file of that name, first (the one used) first."""
    found: dict[str, list[tuple[Path, str]]] = {}
    for d, origin in _search_dirs(extra_dirs):
        if not d.is_dir():
            continue
        for path in sorted(d.glob("*.toml")):
            if re.fullmatch(PRESET_NAME_PATTERN, path.stem) and path.is_file():
                found.setdefault(path.stem, []).append((path, origin))
    return found


def _whole_oktas(layer: Any) -> Any:
    if not isinstance(layer, dict):
        return layer
    cover = layer.get("cover_oktas")
    if isinstance(cover, float) and 0.0 <= cover <= 8.0:
        return {**layer, "cover_oktas": int(cover + 0.5)}
    return layer
