"""The cloud model files: `wxsky/scene/clouds/*.toml` read into `cloud_models` dataclasses.

The shipped files are package data (`wxsky/scene/clouds/`, found through
`importlib.resources` wherever the package is installed). They are read once per process
(`default_models` is cached). Unknown keys, wrong types and out-of-range values are errors
naming the file and the dotted key (`box[2].sprites`). Every channel of a multi-channel setup
must run the same files: the models decide the clouds as much as the seed does.
"""

from __future__ import annotations

import difflib
import functools
import itertools
import math
import tomllib
from pathlib import Path
from typing import Any

from wxsky.errors import ConfigError
from wxsky.scene.cloud_models import BoxTemplate, CloudModel, CloudModels
from wxsky.scene.texture_slots import CATEGORIES
from wxsky.settings.package_data import package_data_dir
from wxsky.weather.state import CloudType

MAX_SPRITES_PER_BOX = 100  # Wang: "between 1 to 100, depending on the density"
MAX_GRID_SIDE = 16
MAX_SHADING_GROUP = 31
# Wang's categories, plus the two halves of the wispy one as the sheet paints them: fine
# streaks (cirrus) and ragged blobs (scud, fringes). Derived, so they follow the slots.
TEXTURE_NAMES: dict[str, tuple[int, ...]] = {
    **CATEGORIES,
    "streaks": CATEGORIES["wispy"][:3],
    "ragged": CATEGORIES["wispy"][3:],
}

# Every key a model file may hold, with its kind: a Python type, or "range" ([lo, hi] numbers),
# "vec3" (three numbers), "grid" ([nx, ny] integers), "names" (texture names).
MODEL_KEYS = {
    "description": str,
    "type": str,
    "min_thickness_m": float,
    "cell_m": float,
    "width_frac": "range",
    "height_frac": "range",
    "jitter_frac": float,
    "cull_frac": float,
    "opacity": float,
    "darkness": float,
    "flat": bool,
    "slab": bool,
    "grows_up": bool,
    "formation_spread_oktas": float,
    "box": list,
}
MODEL_DEFAULTS: dict[str, Any] = {
    "description": "",
    "min_thickness_m": 0.0,
    "jitter_frac": 0.0,
    "opacity": 1.0,
    "darkness": 0.0,
    "flat": False,
    "slab": False,
    "grows_up": False,
    "formation_spread_oktas": 1.5,
}
BOX_KEYS = {
    "centre": "vec3",
    "width": "range",
    "depth": "range",
    "height": "range",
    "sprites": int,
    "grid": "grid",
    "grid_jitter": float,
    "sprite_size": "range",
    "rotation_deg": "range",
    "textures": "names",
    "shading_group": int,
}
BOX_DEFAULTS: dict[str, Any] = {
    "sprites": 0,
    "grid": (0, 0),
    "grid_jitter": 0.0,
    "rotation_deg": (0.0, 360.0),
    "shading_group": 0,
}


def builtin_cloud_dirs() -> tuple[Path, ...]:
    """Where the shipped models are looked for, in order: the package data folder."""
    return (package_data_dir("clouds"),)


@functools.lru_cache(maxsize=1)
def default_models() -> CloudModels:
    """The shipped models, read once."""
    for d in builtin_cloud_dirs():
        if d.is_dir() and any(d.glob("*.toml")):
            return load_cloud_models(d)
    searched = ", ".join(str(d) for d in builtin_cloud_dirs())
    raise ConfigError(f"no cloud models found (looked in {searched})")


def load_cloud_models(directory: Path) -> CloudModels:
    """Every `*.toml` in `directory`; each cloud type needs a model for any thickness."""
    by_type: dict[CloudType, list[CloudModel]] = {}
    for path in sorted(Path(directory).glob("*.toml")):
        model = load_cloud_model(path)
        by_type.setdefault(model.type, []).append(model)
    out: dict[CloudType, tuple[CloudModel, ...]] = {}
    for kind in CloudType:
        if kind is CloudType.NONE:
            continue
        models = sorted(by_type.get(kind, []), key=lambda m: m.min_thickness_m)
        if not models or models[0].min_thickness_m > 0.0:
            raise ConfigError(f"{directory}: no model for {kind.wire_name} layers of any thickness")
        for a, b in itertools.pairwise(models):
            if a.min_thickness_m == b.min_thickness_m:
                raise ConfigError(f"{directory}: {a.name} and {b.name} serve the same layers")
        out[kind] = tuple(models)
    return CloudModels(out, str(directory))


def load_cloud_model(path: Path) -> CloudModel:
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read cloud model: {exc}") from None
    try:
        return parse_cloud_model(data, path.stem)
    except ValueError as exc:
        raise ConfigError(f"{path}: {exc}") from None


def parse_cloud_model(data: dict[str, Any], name: str) -> CloudModel:
    """A model from a file's table; ValueError names the dotted key (`box[2].sprites`)."""
    top = _read_table(data, "", MODEL_KEYS, MODEL_DEFAULTS)
    try:
        kind = CloudType.from_name(top["type"])
    except ValueError as exc:
        raise ValueError(f"type: {exc}") from None
    if kind is CloudType.NONE:
        raise ValueError("type: 'none' has no clouds to model")
    _positive("cell_m", top["cell_m"], hi=16_000.0)
    _fraction_range("width_frac", top["width_frac"], 0.05, 3.0)
    _fraction_range("height_frac", top["height_frac"], 0.05, 1.0)
    for key, lo, hi in (
        ("min_thickness_m", 0.0, 25_000.0),
        ("jitter_frac", 0.0, 0.5),
        ("cull_frac", 0.0, 1.0),
        ("opacity", 0.01, 1.0),
        ("darkness", 0.0, 1.0),
        ("formation_spread_oktas", 0.1, 4.0),
    ):
        if not lo <= top[key] <= hi:
            raise ValueError(f"{key}: must be in {lo:g}..{hi:g}, got {top[key]!r}")
    tables = top["box"]
    if not tables or not all(isinstance(t, dict) for t in tables):
        raise ValueError("box: needs at least one [[box]] table")
    boxes = tuple(_box(t, f"box[{i}]", top["cull_frac"]) for i, t in enumerate(tables, 1))
    return CloudModel(
        name=name,
        type=kind,
        min_thickness_m=top["min_thickness_m"],
        cell_m=top["cell_m"],
        width_frac=top["width_frac"],
        height_frac=top["height_frac"],
        jitter_frac=top["jitter_frac"],
        cull_frac=top["cull_frac"],
        opacity=top["opacity"],
        darkness=top["darkness"],
        flat=top["flat"],
        slab=top["slab"],
        grows_up=top["grows_up"],
        formation_spread_oktas=top["formation_spread_oktas"],
        boxes=boxes,
    )


def _box(table: dict[str, Any], label: str, cull_frac: float) -> BoxTemplate:
    v = _read_table(table, f"{label}.", BOX_KEYS, BOX_DEFAULTS)
    for key in ("width", "depth", "height", "sprite_size"):
        _fraction_range(f"{label}.{key}", v[key], 0.0, 4.0)
    if not all(-2.0 <= c <= 2.0 for c in v["centre"]):
        raise ValueError(f"{label}.centre: each of x, y, z must be in -2..2, got {v['centre']}")
    lo, hi = v["rotation_deg"]
    if not -360.0 <= lo <= hi <= 360.0:
        raise ValueError(f"{label}.rotation_deg: must be lo <= hi within -360..360")
    if (v["sprites"] > 0) == (v["grid"] != (0, 0)):
        raise ValueError(f"{label}: give either sprites (random fill) or grid (a lattice)")
    if not 0 <= v["sprites"] <= MAX_SPRITES_PER_BOX:
        raise ValueError(f"{label}.sprites: must be in 1..{MAX_SPRITES_PER_BOX}")
    if not 0.0 <= v["grid_jitter"] <= 0.25:
        raise ValueError(f"{label}.grid_jitter: must be in 0..0.25, got {v['grid_jitter']!r}")
    if v["grid"] != (0, 0):
        nx, ny = v["grid"]
        # Lattice sprites are the slab: none may cull a neighbour, or the slab gets holes.
        spacing = min(v["width"][0] / nx, v["depth"][0] / ny) * (1.0 - 2.0 * v["grid_jitter"])
        if spacing <= cull_frac * v["sprite_size"][1]:
            raise ValueError(
                f"{label}.grid: lattice spacing {spacing:.3g} cloud widths is inside the cull "
                f"distance {cull_frac * v['sprite_size'][1]:.3g}; the lattice would cull itself"
            )
    if not 0 <= v["shading_group"] <= MAX_SHADING_GROUP:
        raise ValueError(f"{label}.shading_group: must be in 0..{MAX_SHADING_GROUP}")
    slots: list[int] = []
    for category in v["textures"]:
        if category not in TEXTURE_NAMES:
            known = ", ".join(TEXTURE_NAMES)
            raise ValueError(f"{label}.textures: unknown category {category!r} (known: {known})")
        slots += [s for s in TEXTURE_NAMES[category] if s not in slots]
    return BoxTemplate(
        centre=v["centre"],
        width=v["width"],
        depth=v["depth"],
        height=v["height"],
        sprites=v["sprites"],
        grid=v["grid"],
        grid_jitter=v["grid_jitter"],
        sprite_size=v["sprite_size"],
        rotation_deg=v["rotation_deg"],
        textures=tuple(slots),
        shading_group=v["shading_group"],
    )


def _read_table(
    table: dict[str, Any], prefix: str, kinds: dict[str, Any], defaults: dict[str, Any]
) -> dict[str, Any]:
    for key in table:
        if key not in kinds:
            close = difflib.get_close_matches(key, list(kinds), n=1)
            hint = f" (did you mean {prefix + close[0]!r}?)" if close else ""
            raise ValueError(f"unknown key {prefix + key!r}{hint}")
    out: dict[str, Any] = {}
    for key, kind in kinds.items():
        if key not in table:
            if key not in defaults:
                raise ValueError(f"{prefix}{key}: missing")
            out[key] = defaults[key]
            continue
        out[key] = _value(f"{prefix}{key}", kind, table[key])
    return out


def _value(key: str, kind: Any, value: Any) -> Any:
    if kind is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"{key}: must be a number, got {value!r}")
        if not math.isfinite(value):
            raise ValueError(f"{key}: must be finite, got {value!r}")
        return float(value)
    if kind is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"{key}: must be an integer, got {value!r}")
        return value
    if kind is bool or kind is str or kind is list:
        if not isinstance(value, kind):
            raise ValueError(f"{key}: must be a {kind.__name__}, got {value!r}")
        return value
    if kind == "names":
        if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
            raise ValueError(f"{key}: must be a non-empty list of names, got {value!r}")
        return tuple(value)
    count, item = {"range": (2, float), "vec3": (3, float), "grid": (2, int)}[kind]
    if not isinstance(value, list) or len(value) != count:
        raise ValueError(f"{key}: must be a list of {count} numbers, got {value!r}")
    out = tuple(_value(key, item, v) for v in value)
    if kind == "range" and out[0] > out[1]:
        raise ValueError(f"{key}: must be [lo, hi] with lo <= hi, got {value!r}")
    if kind == "grid" and not all(1 <= n <= MAX_GRID_SIDE for n in out):
        raise ValueError(f"{key}: each side must be in 1..{MAX_GRID_SIDE}, got {value!r}")
    return out


def _positive(key: str, value: float, hi: float) -> None:
    if not 0.0 < value <= hi:
        raise ValueError(f"{key}: must be in 0..{hi:g} and above 0, got {value!r}")


def _fraction_range(key: str, value: tuple[float, float], lo: float, hi: float) -> None:
    if not (lo <= value[0] and value[1] <= hi and value[1] > 0.0):
        raise ValueError(f"{key}: must lie within {lo:g}..{hi:g}, got {list(value)}")
