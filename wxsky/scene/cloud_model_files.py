"""The cloud model files: `wxsky/scene/clouds/*.toml` read into `cloud_models` dataclasses.

The shipped files are package data (`wxsky/scene/clouds/`, found through
`importlib.resources` wherever the package is installed). They are read once per process
(`default_models` is cached). Unknown keys, wrong types and out-of-range values are errors
naming the file and the dotted key (`box[2].sprites`). Every channel of a multi-channel setup
must run the same files: the models decide the clouds as much as the seed does.
"""

from __future__ import annotations

import functools
import itertools
from pathlib import Path
from typing import Any

from wxsky.errors import ConfigError
from wxsky.scene.cloud_models import BoxTemplate, CloudModel, CloudModels
from wxsky.scene.clouds import BLOCK_SIZE_M
from wxsky.scene.texture_slots import CATEGORIES
from wxsky.schema import (
    REQUIRED,
    Bool,
    Custom,
    Field,
    Items,
    KeyPath,
    Number,
    Problem,
    Rule,
    Table,
    Tables,
    Text,
)
from wxsky.schema.toml_file import check_toml_file, package_folder
from wxsky.weather.state import LAYER_THICKNESS_M, CloudType

MAX_SPRITES_PER_BOX = 100  # Wang: "between 1 to 100, depending on the density"
MAX_GRID_SIDE = 16
MAX_SHADING_GROUP = 31
# A block's clouds are generated all at once, so a tiny cell_m (2 m: four million clouds)
# would take the daemon's memory: clouds per block times sprites per cloud stays under this,
# 13 times the densest shipped model (cumulus humilis, 16 clouds of 48 sprites).
MAX_SPRITES_PER_BLOCK = 10_000
# Wang's categories, plus the two halves of the wispy one as the sheet paints them: fine
# streaks (cirrus) and ragged blobs (scud, fringes). Derived, so they follow the slots.
TEXTURE_NAMES: dict[str, tuple[int, ...]] = {
    **CATEGORIES,
    "streaks": CATEGORIES["wispy"][:3],
    "ragged": CATEGORIES["wispy"][3:],
}


def _cloud_type(value: Any) -> CloudType:
    if not isinstance(value, str):
        raise ValueError(f"must be a cloud type name, got {value!r}")
    kind = CloudType.from_name(value)
    if kind is CloudType.NONE:
        raise ValueError("'none' has no clouds to model")
    return kind


def _texture(value: Any) -> str:
    if not isinstance(value, str) or value not in TEXTURE_NAMES:
        raise ValueError(f"unknown category {value!r} (known: {', '.join(TEXTURE_NAMES)})")
    return value


def _span(lo: float, hi: float) -> Items:
    """A [lo, hi] pair of cloud-relative sizes within lo..hi."""
    return Items(Number(lo, hi), length=2, ordered=True, what=f"[lo, hi] within {lo:g}..{hi:g}")


def _box_rules(v: dict[str, Any], path: KeyPath, problems: list[Problem]) -> None:
    if (v["sprites"] > 0) == (v["grid"] != (0, 0)):
        problems.append(Problem(path, "give either sprites (random fill) or grid (a lattice)"))
    for key in ("width", "depth", "height", "sprite_size"):
        if v[key][1] <= 0.0:
            problems.append(Problem((*path, key), f"must reach above 0, got {list(v[key])}"))


def _lattices_keep_their_sprites(v: dict[str, Any], path: KeyPath, problems: list[Problem]) -> None:
    for i, box in enumerate(v["box"]):
        if box["grid"] == (0, 0):
            continue
        nx, ny = box["grid"]
        # Lattice sprites are the slab: none may cull a neighbour, or the slab gets holes.
        spacing = min(box["width"][0] / nx, box["depth"][0] / ny) * (1.0 - 2.0 * box["grid_jitter"])
        cull = v["cull_frac"] * box["sprite_size"][1]
        if spacing <= cull:
            problems.append(
                Problem(
                    ("box", i, "grid"),
                    f"lattice spacing {spacing:.3g} cloud widths is inside the cull distance "
                    f"{cull:.3g}; the lattice would cull itself",
                )
            )


def _bounded_block(v: dict[str, Any], path: KeyPath, problems: list[Problem]) -> None:
    clouds = max(1, round(BLOCK_SIZE_M / v["cell_m"])) ** 2  # as clouds.block_clouds cuts it
    per_cloud = sum(box["sprites"] + box["grid"][0] * box["grid"][1] for box in v["box"])
    if clouds * per_cloud > MAX_SPRITES_PER_BLOCK:
        problems.append(
            Problem(
                (*path, "cell_m"),
                f"{clouds} clouds of {per_cloud} sprites make {clouds * per_cloud} sprites a "
                f"{BLOCK_SIZE_M / 1000:g} km block, more than {MAX_SPRITES_PER_BLOCK}: "
                "a larger cell_m or fewer sprites",
            )
        )


BOX_TABLE = Table(
    {
        "centre": Field(
            Items(Number(-2.0, 2.0), length=3, what="[x, y, z] within -2..2"), REQUIRED
        ),
        "width": Field(_span(0.0, 4.0), REQUIRED),
        "depth": Field(_span(0.0, 4.0), REQUIRED),
        "height": Field(_span(0.0, 4.0), REQUIRED),
        "sprites": Field(Number(0, MAX_SPRITES_PER_BOX, integer=True), 0),
        "grid": Field(
            Items(Number(1, MAX_GRID_SIDE, integer=True), length=2, what="[nx, ny]"), (0, 0)
        ),
        "grid_jitter": Field(Number(0.0, 0.25), 0.0),
        "sprite_size": Field(_span(0.0, 4.0), REQUIRED),
        "rotation_deg": Field(
            Items(Number(-360.0, 360.0), length=2, ordered=True, what="[lo, hi] within -360..360"),
            (0.0, 360.0),
        ),
        "textures": Field(Items(Custom(_texture, "a texture category"), min_len=1), REQUIRED),
        "shading_group": Field(Number(0, MAX_SHADING_GROUP, integer=True), 0),
        "under_base": Field(Bool(), False),
    },
    rules=(Rule(("sprites", "grid", "width", "depth", "height", "sprite_size"), _box_rules),),
)
MODEL_TABLE = Table(
    {
        "description": Field(Text(), ""),
        "type": Field(Custom(_cloud_type, "a cloud type name"), REQUIRED),
        "min_thickness_m": Field(Number(0.0, LAYER_THICKNESS_M.hi, unit="m"), 0.0),
        "cell_m": Field(Number(0.0, 16_000.0, unit="m", above_lo=True), REQUIRED),
        "width_frac": Field(_span(0.05, 3.0), REQUIRED),
        "height_frac": Field(_span(0.05, 1.0), REQUIRED),
        "jitter_frac": Field(Number(0.0, 0.5), 0.0),
        "cull_frac": Field(Number(0.0, 1.0), REQUIRED),
        "opacity": Field(Number(0.01, 1.0), 1.0),
        "darkness": Field(Number(0.0, 1.0), 0.0),
        "flat": Field(Bool(), False),
        "slab": Field(Bool(), False),
        "grows_up": Field(Bool(), False),
        "formation_spread_oktas": Field(Number(0.1, 4.0, unit="oktas"), 1.5),
        "flat_base": Field(Bool(), False),
        "box": Field(Tables(BOX_TABLE, "box"), REQUIRED),
    },
    rules=(
        Rule(("box", "cull_frac"), _lattices_keep_their_sprites),
        Rule(("box", "cell_m"), _bounded_block),
    ),
)


def builtin_cloud_dirs() -> tuple[Path, ...]:
    """Where the shipped models are looked for, in order: the package data folder."""
    return (package_folder("wxsky.scene", "clouds"),)


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
    """One model file; ConfigError lists every problem as `FILE:LINE: key: problem`."""
    checked = check_toml_file(path, MODEL_TABLE)
    if not checked.ok:
        raise ConfigError(checked.error_message())
    return model_from_values(checked.value, Path(path).stem)


def parse_cloud_model(data: dict[str, Any], name: str) -> CloudModel:
    """A model from a file's table; ValueError (an Invalid) names every bad key."""
    return model_from_values(MODEL_TABLE.values(data), name)


def model_from_values(v: dict[str, Any], name: str) -> CloudModel:
    if not v["box"]:
        raise ConfigError(f"{name}: box: needs at least one [[box]] table")
    boxes = tuple(_box(b) for b in v["box"])
    return CloudModel(
        name=name,
        type=v["type"],
        min_thickness_m=v["min_thickness_m"],
        cell_m=v["cell_m"],
        width_frac=v["width_frac"],
        height_frac=v["height_frac"],
        jitter_frac=v["jitter_frac"],
        cull_frac=v["cull_frac"],
        opacity=v["opacity"],
        darkness=v["darkness"],
        flat=v["flat"],
        slab=v["slab"],
        grows_up=v["grows_up"],
        formation_spread_oktas=v["formation_spread_oktas"],
        flat_base=v["flat_base"],
        boxes=boxes,
    )


def _box(v: dict[str, Any]) -> BoxTemplate:
    slots: list[int] = []
    for category in v["textures"]:
        slots += [s for s in TEXTURE_NAMES[category] if s not in slots]
    return BoxTemplate(
        centre=v["centre"],
        width=v["width"],
        depth=v["depth"],
        height=v["height"],
        sprites=v["sprites"],
        grid=tuple(v["grid"]),
        grid_jitter=v["grid_jitter"],
        sprite_size=v["sprite_size"],
        rotation_deg=tuple(v["rotation_deg"]),
        textures=tuple(slots),
        shading_group=v["shading_group"],
        under_base=v["under_base"],
    )
