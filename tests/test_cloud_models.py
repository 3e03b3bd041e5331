"""Cloud models as data: the shipped files, subtype choice, Wang-like counts, and errors that
name the file and the key."""

from __future__ import annotations

import dataclasses
import tomllib
from pathlib import Path

import numpy as np
import pytest

from wxsky.errors import ConfigError
from wxsky.scene.cloud_model_files import (
    BOX_TABLE,
    MODEL_TABLE,
    TEXTURE_NAMES,
    builtin_cloud_dirs,
    default_models,
    load_cloud_model,
    load_cloud_models,
)
from wxsky.scene.clouds import BLOCK_SIZE_M, UNDER_BASE_MAX_M, SpriteBatch, block_clouds
from wxsky.scene.formation import layer_block
from wxsky.scene.texture_slots import CATEGORIES
from wxsky.weather.metar_clouds import CLOUD_TABLE
from wxsky.weather.state import CloudLayer, CloudType

REPO = Path(__file__).resolve().parents[1]
SHIPPED = REPO / "wxsky" / "scene" / "clouds"
ALL_MODELS = [m for models in default_models().by_type.values() for m in models]
# Stratiform layers at METAR-like depths: closed at 8/8.
SLABS = {
    "stratus": CloudLayer(8, 830.0, 1350.0, CloudType.STRATUS),
    "nimbostratus": CloudLayer(8, 1000.0, 3000.0, CloudType.NIMBOSTRATUS),
    "altostratus": CloudLayer(8, 3000.0, 4500.0, CloudType.ALTOSTRATUS),
    "stratocumulus": CloudLayer(8, 1100.0, 1700.0, CloudType.STRATOCUMULUS),
    "cirrostratus": CloudLayer(8, 8000.0, 9000.0, CloudType.CIRROSTRATUS),
}

MINIMAL = """\
type = "cumulus"
cell_m = 1000.0
width_frac = [0.5, 0.8]
height_frac = [0.5, 1.0]
cull_frac = 0.3

[[box]]
centre = [0.0, 0.0, 0.5]
width = [0.5, 0.7]
depth = [0.5, 0.7]
height = [0.3, 0.5]
sprites = 10
sprite_size = [0.3, 0.4]
textures = ["puffy"]
"""


def test_shipped_models_come_from_the_checkout_and_cover_every_type() -> None:
    assert builtin_cloud_dirs()[0] == SHIPPED
    models = default_models()
    assert models.source == str(SHIPPED)
    assert set(models.by_type) == {t for t in CloudType if t is not CloudType.NONE}
    assert len(ALL_MODELS) == len(list(SHIPPED.glob("*.toml"))) == 12
    assert {m.name for m in ALL_MODELS} >= {
        "cumulus-humilis",
        "cumulus-mediocris",
        "cumulus-congestus",
        "cumulonimbus",
        "stratus",
        "nimbostratus",
        "cirrus",
    }


@pytest.mark.parametrize(
    ("thickness_m", "name"),
    [
        (300.0, "cumulus-humilis"),
        (770.0, "cumulus-humilis"),  # fair-cumulus preset
        (999.0, "cumulus-humilis"),
        (1000.0, "cumulus-mediocris"),
        (1640.0, "cumulus-mediocris"),  # scattered-cumulus preset
        (2499.0, "cumulus-mediocris"),
        (2500.0, "cumulus-congestus"),
        (8000.0, "cumulus-congestus"),
    ],
)
def test_cumulus_subtype_follows_the_layer_thickness(thickness_m: float, name: str) -> None:
    assert default_models().for_layer(CloudType.CUMULUS, thickness_m).name == name


def test_metar_towering_cumulus_gets_congestus() -> None:
    tcu = next(r for r in CLOUD_TABLE if r.form == "TCU")
    model = default_models().for_layer(tcu.cloud_type, tcu.thickness_m)
    assert model.name == "cumulus-congestus"


def test_shipped_files_ship_and_every_key_is_documented() -> None:
    project = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))
    package_data = project["tool"]["setuptools"]["package-data"]
    assert "clouds/*.toml" in package_data["wxsky.scene"]
    readme = (SHIPPED / "README.md").read_text(encoding="utf-8")
    for key in [*MODEL_TABLE.fields, *BOX_TABLE.fields]:
        shown = "[[box]]" if key == "box" else f"`{key}`"
        assert shown in readme, key


def test_texture_names_are_wangs_categories_and_the_halves_of_wispy() -> None:
    assert {k: TEXTURE_NAMES[k] for k in CATEGORIES} == CATEGORIES
    assert TEXTURE_NAMES["streaks"] + TEXTURE_NAMES["ragged"] == CATEGORIES["wispy"]


# -- counts as Wang's artists built them ----------------------------------------------------


@pytest.mark.parametrize("model", ALL_MODELS, ids=lambda m: m.name)
def test_box_and_sprite_counts_are_plausible(model) -> None:  # type: ignore[no-untyped-def]
    thickness = max(model.min_thickness_m, 1000.0) * 1.2
    block = block_clouds(0, 0, 0, model, thickness, 5)
    per_side = max(1, round(BLOCK_SIZE_M / model.cell_m))
    assert block.n_clouds == per_side * per_side
    boxes_per_block = block.n_clouds * len(model.boxes)
    per_cloud = len(block.sprites) / block.n_clouds
    # Wang: 1..100 sprites per box, 5..400 per cloud, 20..200 boxes per 16 km^2 (a lone
    # storm cell has fewer). Flat cirrus quads are few and large.
    assert all(1 <= box.count <= 100 for box in model.boxes)
    if model.flat:
        assert 1 <= per_cloud <= 20
        assert 4 <= boxes_per_block <= 200
    else:
        assert 5 <= per_cloud <= 400
        assert 10 <= boxes_per_block <= 200
    # Culling removes overlaps, not whole boxes.
    placed = block.n_clouds * sum(box.count for box in model.boxes)
    assert 0.5 * placed <= len(block.sprites) <= placed


def test_heaped_models_grow_up_and_slabs_do_not() -> None:
    grows = {m.name for m in ALL_MODELS if m.grows_up}
    assert grows == {
        "cumulus-humilis",
        "cumulus-mediocris",
        "cumulus-congestus",
        "cumulonimbus",
        "altocumulus",
    }
    flat = {m.type for m in ALL_MODELS if m.flat}
    assert flat == {CloudType.CIRRUS, CloudType.CIRROSTRATUS, CloudType.CIRROCUMULUS}


def test_slabs_lead_with_a_lattice() -> None:
    for m in ALL_MODELS:
        if m.type in (CloudType.STRATUS, CloudType.NIMBOSTRATUS, CloudType.ALTOSTRATUS):
            assert m.boxes[0].grid != (0, 0) and m.jitter_frac == 0.0, m.name


# -- overcast slabs have no holes ---------------------------------------------------------


def _covered(batch: SpriteBatch, eye: np.ndarray, points: np.ndarray, margin: float) -> np.ndarray:
    """(P,) whether the ray from the eye through each point crosses some sprite within
    `margin` of its radius: camera-facing sprites as discs facing the eye, flat ones as
    horizontal discs (the circle inscribed in the quad)."""
    rays = points - eye
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)  # (P, 3)
    to_c = batch.centre_m - eye  # (N, 3)
    radius = margin * 0.5 * batch.size_m.astype(np.float64)
    out = np.zeros(len(points), bool)
    for lo in range(0, len(points), 128):
        d = rays[lo : lo + 128, None, :]  # (p, 1, 3)
        facing = np.sum(d * to_c[None], axis=2)  # (p, N): d . (c - e)
        along = np.where(
            batch.flat[None, :],
            to_c[None, :, 2] / d[:, :, 2],
            np.sum(to_c**2, axis=1)[None, :] / np.where(facing > 0, facing, np.inf),
        )
        hit = d * along[:, :, None] - to_c[None]  # (p, N, 3) hit point minus centre
        ok = (along > 0) & (np.linalg.norm(hit, axis=2) < radius[None, :])
        out[lo : lo + 128] = ok.any(axis=1)
    return out


@pytest.mark.parametrize("name", list(SLABS))
@pytest.mark.parametrize("seed", [17, 2**33 + 5])
def test_overcast_slab_is_hole_free_from_below_and_above(name: str, seed: int) -> None:
    layer = SLABS[name]
    bx, by = 2, -3
    batch = SpriteBatch.concat(
        [layer_block(bx + i, by + j, 0, layer, seed) for i in (-1, 0, 1) for j in (-1, 0, 1)]
    )
    g = (np.arange(40) + 0.5) / 40 * BLOCK_SIZE_M
    gx, gy = np.meshgrid(g + bx * BLOCK_SIZE_M, g + by * BLOCK_SIZE_M)
    mid = 0.5 * (layer.base_m + layer.top_m)
    points = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, mid)], axis=1)
    centre = np.array([(bx + 0.5) * BLOCK_SIZE_M, (by + 0.5) * BLOCK_SIZE_M])
    for eye_z in (layer.base_m - 1500.0, layer.top_m + 2000.0):
        for dx, dy in ((0.0, 0.0), (1500.0, -900.0)):
            eye = np.array([centre[0] + dx, centre[1] + dy, eye_z])
            covered = _covered(batch, eye, points.copy(), margin=0.75)
            assert covered.all(), f"{name} from z={eye_z:g}: {np.sum(~covered)} holes"


@pytest.mark.parametrize("name", list(SLABS))
def test_broken_slab_shows_gaps(name: str) -> None:
    """The same slab at 5/8 is not closed: missing cells leave holes straight overhead."""
    layer = dataclasses.replace(SLABS[name], cover_oktas=5.0)
    batch = SpriteBatch.concat(
        [layer_block(i, j, 0, layer, 17) for i in (-1, 0, 1) for j in (-1, 0, 1)]
    )
    g = (np.arange(40) + 0.5) / 40 * BLOCK_SIZE_M
    gx, gy = np.meshgrid(g, g)
    points = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, layer.base_m)], axis=1)
    hidden = _covered(batch, np.array([2000.0, 2000.0, layer.base_m - 1e5]), points, 0.75)
    assert 0.3 < hidden.mean() < 0.95


# -- errors name the file and the key --------------------------------------------------------


def _write(tmp_path: Path, text: str, name: str = "model.toml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_a_minimal_model_loads_with_defaults(tmp_path: Path) -> None:
    model = load_cloud_model(_write(tmp_path, MINIMAL))
    assert model.name == "model" and model.type is CloudType.CUMULUS
    assert model.boxes[0].textures == CATEGORIES["puffy"]
    assert model.boxes[0].rotation_deg == (0.0, 360.0) and model.boxes[0].shading_group == 0
    assert not model.flat and not model.grows_up and model.formation_spread_oktas == 1.5


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (("cell_m = 1000.0", "cel_m = 1000.0"), "cel_m: unknown key (did you mean 'cell_m'?)"),
        (
            ("sprite_size = [0.3, 0.4]", "sprite_sise = [0.3, 0.4]"),
            "box[0].sprite_sise: unknown key (did you mean 'sprite_size'?)",
        ),
        (('"puffy"]', '"puffy", "lumpy"]'), "box[0].textures[1]: unknown category 'lumpy'"),
        (
            ("cell_m = 1000.0", 'cell_m = "big"'),
            "cell_m: must be a number in 0..16000 and more than 0",
        ),
        (("cull_frac = 0.3", "cull_frac = 1.5"), "cull_frac: must be a number in 0..1, got 1.5"),
        (
            ("width = [0.5, 0.7]", "width = [0.7, 0.5]"),
            "box[0].width: must be [lo, hi] with",
        ),
        (("sprites = 10", "sprites = 10\ngrid = [2, 2]"), "box[0]: give either sprites"),
        (
            ("sprites = 10", "sprites = 101"),
            "box[0].sprites: must be an integer in 0..100",
        ),
        (("height_frac = [0.5, 1.0]\n", ""), "height_frac: missing key"),
        (('type = "cumulus"', 'type = "cumulous"'), "type: unknown cloud type 'cumulous'"),
        (
            ("sprites = 10", "grid = [5, 5]"),
            "box[0].grid: lattice spacing 0.1 cloud widths is inside the cull distance 0.12",
        ),
        (
            ('textures = ["puffy"]', 'textures = ["puffy"]\nunder_base = "yes"'),
            "box[0].under_base: must be true or false, got 'yes'",
        ),
    ],
)
def test_bad_models_are_errors_naming_file_and_key(
    tmp_path: Path, change: tuple[str, str], message: str
) -> None:
    old, new = change
    assert old in MINIMAL
    path = _write(tmp_path, MINIMAL.replace(old, new, 1))
    with pytest.raises(ConfigError) as err:
        load_cloud_model(path)
    assert str(err.value).startswith(f"{path}:")
    assert message in str(err.value)


def test_a_second_box_is_named_by_its_number(tmp_path: Path) -> None:
    second = MINIMAL.split("[[box]]")[1].replace("sprites = 10", "sprites = 0")
    path = _write(tmp_path, MINIMAL + "\n[[box]]" + second)
    with pytest.raises(ConfigError, match=r"box\[1\]: give either sprites"):
        load_cloud_model(path)


def test_broken_toml_names_the_file(tmp_path: Path) -> None:
    path = _write(tmp_path, MINIMAL + "\nopacity = \n")
    with pytest.raises(ConfigError, match=f"^{path}:[0-9]+: invalid TOML"):
        load_cloud_model(path)


def test_a_directory_must_model_every_type(tmp_path: Path) -> None:
    _write(tmp_path, MINIMAL, "cumulus.toml")
    with pytest.raises(ConfigError, match="no model for altocumulus layers of any thickness"):
        load_cloud_models(tmp_path)


def test_two_models_for_the_same_layers_are_an_error(tmp_path: Path) -> None:
    for path in SHIPPED.glob("*.toml"):
        _write(tmp_path, path.read_text(encoding="utf-8"), path.name)
    _write(tmp_path, MINIMAL, "cumulus-twin.toml")
    with pytest.raises(ConfigError, match="serve the same layers"):
        load_cloud_models(tmp_path)


def test_nimbostratus_scud_hangs_under_the_base_and_the_rest_stays_in_the_layer() -> None:
    layer = SLABS["nimbostratus"]
    (model,) = [m for m in ALL_MODELS if m.name == "nimbostratus"]
    assert any(box.under_base for box in model.boxes)
    thickness = layer.top_m - layer.base_m
    batch = block_clouds(0, 0, 7, model, thickness, 11).sprites
    z = batch.centre_m[:, 2]  # above the layer's base
    under = z < 0.0
    assert 10 <= under.sum() < 0.5 * len(z)
    # A few hundred metres down: scud, not a second layer near the ground.
    assert z[under].min() > -400.0 and z[under].max() < -20.0
    # The rest keep inside the layer, as before.
    assert (z[~under] >= 0.0).all() and (z <= thickness).all()


def test_a_scud_box_reaches_no_farther_than_under_base_max_under_the_base(tmp_path: Path) -> None:
    deep = MINIMAL.replace("centre = [0.0, 0.0, 0.5]", "centre = [0.0, 0.0, -1.9]").replace(
        'textures = ["puffy"]', 'textures = ["puffy"]\nunder_base = true'
    )
    model = load_cloud_model(_write(tmp_path, deep))
    z = block_clouds(0, 0, 3, model, 2000.0, 5).sprites.centre_m[:, 2]
    assert len(z) and z.min() >= -UNDER_BASE_MAX_M and (z < -0.5 * UNDER_BASE_MAX_M).any()
