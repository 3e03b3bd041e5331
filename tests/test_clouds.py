"""Per-block cloud generation: determinism, the cover-free cache, Wang's cull, geometry bounds,
and SpriteBatch helpers. Hole-free overcast slabs are in test_cloud_models.py."""

from __future__ import annotations

import dataclasses
import hashlib
import pickle
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from wxsky.scene import sprite_cull
from wxsky.scene.cloud_model_files import default_models
from wxsky.scene.clouds import (
    BLOCK_CACHE,
    BLOCK_SIZE_M,
    SpriteBatch,
    block_clouds,
    generate_block_clouds,
)
from wxsky.scene.formation import layer_block
from wxsky.scene.texture_slots import TEX_FLAT_BOTTOM
from wxsky.weather.state import CloudLayer, CloudType

# The undecorated generator, so determinism is not just the lru_cache handing back one object.
_generate = generate_block_clouds

FIELDS = tuple(f.name for f in dataclasses.fields(SpriteBatch))

# One layer per type at METAR-like thicknesses; cumulus at each of its three subtypes.
LAYERS = {
    "cumulus-humilis": (CloudType.CUMULUS, 1930.0, 2700.0),
    "cumulus-mediocris": (CloudType.CUMULUS, 1560.0, 3200.0),
    "cumulus-congestus": (CloudType.CUMULUS, 1500.0, 5500.0),
    "cumulonimbus": (CloudType.CUMULONIMBUS, 1000.0, 10_000.0),
    "altocumulus": (CloudType.ALTOCUMULUS, 4000.0, 4500.0),
    "cirrocumulus": (CloudType.CIRROCUMULUS, 7000.0, 7500.0),
    "stratocumulus": (CloudType.STRATOCUMULUS, 1100.0, 1700.0),
    "stratus": (CloudType.STRATUS, 830.0, 1350.0),
    "nimbostratus": (CloudType.NIMBOSTRATUS, 1000.0, 3000.0),
    "altostratus": (CloudType.ALTOSTRATUS, 3000.0, 4500.0),
    "cirrus": (CloudType.CIRRUS, 9000.0, 10_000.0),
    "cirrostratus": (CloudType.CIRROSTRATUS, 8000.0, 9000.0),
}


def _layer(name: str, oktas: float) -> CloudLayer:
    kind, base, top = LAYERS[name]
    return CloudLayer(oktas, base, top, kind)


def _model_args(name: str) -> tuple:
    layer = _layer(name, 8)
    return default_models().for_layer(layer.type, layer.thickness_m), layer.thickness_m


def _digest(batch: SpriteBatch) -> str:
    h = hashlib.sha256()
    for name in FIELDS:
        arr = np.ascontiguousarray(getattr(batch, name))
        h.update(f"{name}:{arr.dtype.str}:{arr.shape}".encode())
        h.update(arr.tobytes())
    return h.hexdigest()


def _assert_same(a: SpriteBatch, b: SpriteBatch) -> None:
    for name in FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.shape == y.shape, name
        np.testing.assert_array_equal(x, y, err_msg=name)


# -- determinism --------------------------------------------------------------------------

BLOCK_ARGS = [
    (0, 0, 0, "cumulus-humilis", 7),
    (-3, 5, 1, "stratus", 2**40 + 3),
    (12, -9, 2, "cirrus", 1),
    (2, 2, 3, "cumulonimbus", 99),
]


def _args(bx: int, by: int, key: int, name: str, seed: int) -> tuple:
    model, thickness = _model_args(name)
    return (bx, by, key, model, thickness, seed)


def test_same_arguments_give_identical_arrays() -> None:
    for spec in BLOCK_ARGS:
        args = _args(*spec)
        _assert_same(_generate(*args).sprites, _generate(*args).sprites)
        _assert_same(_generate(*args).sprites, block_clouds(*args).sprites)


def test_same_clouds_in_another_process() -> None:
    code = textwrap.dedent(
        """
        import hashlib
        import numpy as np
        from wxsky.scene.cloud_model_files import default_models
        from wxsky.scene.clouds import block_clouds
        from wxsky.weather.state import CloudType
        for bx, by, key, kind, thickness, seed in %r:
            model = default_models().for_layer(CloudType(kind), thickness)
            b = block_clouds(bx, by, key, model, thickness, seed).sprites
            h = hashlib.sha256()
            for name in %r:
                arr = np.ascontiguousarray(getattr(b, name))
                h.update(f"{name}:{arr.dtype.str}:{arr.shape}".encode())
                h.update(arr.tobytes())
            print(h.hexdigest())
        """
    ) % (
        [(bx, by, k, int(LAYERS[n][0]), _model_args(n)[1], s) for bx, by, k, n, s in BLOCK_ARGS],
        FIELDS,
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=60
    )
    assert out.stdout.split() == [_digest(_generate(*_args(*a)).sprites) for a in BLOCK_ARGS]


@pytest.mark.parametrize(
    "changed",
    [(1, 0, 0, 7), (0, -1, 0, 7), (0, 0, 1, 7), (0, 0, 0, 8), (0, 0, 0, 7 + 2**32)],
    ids=["block-x", "block-y", "layer-key", "seed", "seed-high-word"],
)
def test_different_block_layer_or_seed_gives_different_clouds(changed: tuple) -> None:
    base = _generate(*_args(0, 0, 0, "cumulus-humilis", 7)).sprites
    bx, by, key, seed = changed
    other = _generate(*_args(bx, by, key, "cumulus-humilis", seed)).sprites
    rel_base = np.sort(base.centre_m[:, 0] % BLOCK_SIZE_M)
    rel_other = np.sort(other.centre_m[:, 0] % BLOCK_SIZE_M)
    assert len(base) != len(other) or not np.allclose(rel_base, rel_other)


# -- the cache does not see the cover -----------------------------------------------------


def test_cover_and_base_changes_reuse_the_cached_generation() -> None:
    BLOCK_CACHE.clear()
    layer = _layer("cumulus-mediocris", 2.0)
    first = layer_block(4, -1, 0, layer, 31)
    misses = BLOCK_CACHE.info().misses
    model, thickness = _model_args("cumulus-mediocris")
    generated = block_clouds(4, -1, 0, model, thickness, 31)
    for cover in np.linspace(0.1, 8.0, 40):
        layer_block(4, -1, 0, dataclasses.replace(layer, cover_oktas=float(cover)), 31)
    moved = CloudLayer(5.0, layer.base_m + 300.0, layer.top_m + 300.0, layer.type)
    shifted = layer_block(4, -1, 0, moved, 31)
    info = BLOCK_CACHE.info()
    assert info.misses == misses  # 41 more calls, not one generation
    assert info.hits >= 42
    assert block_clouds(4, -1, 0, model, thickness, 31) is generated
    # The same sprites at any cover, lifted with the base.
    keys = {tuple(r) for r in np.round(first.centre_m + np.array([0.0, 0.0, 300.0]), 6)}
    assert keys <= {tuple(r) for r in np.round(shifted.centre_m, 6)}


# -- Wang's cull --------------------------------------------------------------------------


@pytest.mark.parametrize("name", list(LAYERS))
def test_no_two_sprites_of_a_cloud_closer_than_the_cull_distance(name: str) -> None:
    model, thickness = _model_args(name)
    sprites = block_clouds(-2, 6, 5, model, thickness, 404).sprites
    assert len(sprites) > 0
    checked = 0
    for cid in np.unique(sprites.cloud_id):
        one = sprites.take(sprites.cloud_id == cid)
        d = np.linalg.norm(one.centre_m[:, None, :] - one.centre_m[None, :, :], axis=2)
        size = one.size_m.astype(np.float64)
        reach = model.cull_frac * np.maximum(size[:, None], size[None, :])
        np.fill_diagonal(d, np.inf)
        assert np.all(d >= reach * (1 - 1e-9)), f"{name}: cloud {cid}"
        checked += len(one)
    assert checked == len(sprites)


def _walk(centre_m: np.ndarray, reach_m: np.ndarray) -> np.ndarray:
    """Wang's cull as he states it: in order, keep a sprite unless one kept before is closer
    than the larger reach of the two."""
    kept: list[int] = []
    for j in range(len(reach_m)):
        if all(
            np.sum((centre_m[i] - centre_m[j]) ** 2) >= max(reach_m[i], reach_m[j]) ** 2
            for i in kept
        ):
            kept.append(j)
    mask = np.zeros(len(reach_m), np.bool_)
    mask[kept] = True
    return mask


@pytest.mark.parametrize("dense", [True, False])
@pytest.mark.parametrize(("n", "k"), [(16, 48), (3, 1), (1, 120), (0, 4), (5, 0)])
def test_cloud_by_cloud_cull_keeps_what_the_in_order_walk_keeps(
    n: int, k: int, dense: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    if not dense:  # the voxel-grid form it falls back to for big clouds
        monkeypatch.setattr(sprite_cull, "DENSE_PAIRS_MAX", 0)
    rng = np.random.default_rng(n * 100 + k)
    # Crowded: most sprites have a neighbour within reach, some chains are long.
    centre_m = rng.uniform(0.0, 300.0, size=(n, k, 3))
    reach_m = rng.uniform(10.0, 80.0, size=(n, k))
    keep = sprite_cull.cull_mask_clouds(centre_m, reach_m)
    assert keep.shape == (n, k)
    for c in range(n):
        np.testing.assert_array_equal(keep[c], _walk(centre_m[c], reach_m[c]))
    if n and k > 1:
        assert 0 < keep.sum() < n * k


def test_cull_removes_sprites_only_where_boxes_crowd() -> None:
    model, thickness = _model_args("cumulus-mediocris")
    block = block_clouds(0, 0, 0, model, thickness, 3)
    placed = block.n_clouds * sum(b.count for b in model.boxes)
    assert 0.5 * placed < len(block.sprites) < placed


# -- geometry -----------------------------------------------------------------------------


@pytest.mark.parametrize("name", list(LAYERS))
def test_sprites_stay_inside_layer_and_near_their_block(name: str) -> None:
    layer = _layer(name, 8)
    model = default_models().for_layer(layer.type, layer.thickness_m)
    batch = layer_block(3, -4, 2, layer, 12345)
    assert len(batch) > 0
    z = batch.centre_m[:, 2]
    size = batch.size_m.astype(np.float64)
    slack = 1e-3 * size
    margin = np.minimum(0.3 * size, 0.5 * layer.thickness_m)
    # A flat-based cloud's sprites may hang below its base, which cuts them (`base_m`).
    floor = 0.0 if model.flat_base else margin
    inside = z >= layer.base_m + floor - slack
    # Scud boxes (`under_base`) hang under the base, no lower than their boxes reach.
    reaches = [
        (b.centre[2] - 0.5 * b.height[1]) * model.height_frac[1] * layer.thickness_m
        for b in model.boxes
        if b.under_base
    ]
    if reaches:
        assert np.all(z[~inside] >= layer.base_m + min(reaches) - 1.0)
        assert inside.mean() > 0.5
    else:
        assert inside.all()
    assert np.all(z <= layer.top_m - margin + slack)
    # Horizontally within the block, give or take the widest box of the widest cloud.
    reach = (
        max((abs(b.centre[0]) + 0.5 * b.width[1]) * model.width_frac[1] for b in model.boxes)
        * BLOCK_SIZE_M
        / max(1, round(BLOCK_SIZE_M / model.cell_m))
    )
    x, y = batch.centre_m[:, 0], batch.centre_m[:, 1]
    assert np.all((x >= 3 * BLOCK_SIZE_M - reach) & (x <= 4 * BLOCK_SIZE_M + reach))
    assert np.all((y >= -4 * BLOCK_SIZE_M - reach) & (y <= -3 * BLOCK_SIZE_M + reach))


def test_sprites_in_a_thin_layer_sit_at_its_middle() -> None:
    thin = CloudLayer(8, 830.0, 930.0, CloudType.STRATUS)
    z = layer_block(0, 0, 0, thin, 23).centre_m[:, 2]
    # Every sprite is far larger than the 100 m layer: the margins meet in the middle.
    np.testing.assert_allclose(z, 880.0, atol=1e-6)


@pytest.mark.parametrize("name", list(LAYERS))
def test_attributes_are_finite_and_in_range(name: str) -> None:
    layer = _layer(name, 8)
    model = default_models().for_layer(layer.type, layer.thickness_m)
    batch = layer_block(5, 5, 1, layer, 77)
    n = len(batch)
    assert n > 0
    for f in FIELDS:
        arr = getattr(batch, f)
        assert arr.shape[0] == n, f
        if f == "slab_m":  # NaN marks sprites shaded as particles
            assert np.all(np.isnan(arr) != model.slab), f
        elif f == "base_m":  # NaN marks sprites not cut at a flat base
            assert np.all(np.isnan(arr) != model.flat_base), f
            assert np.all(arr[~np.isnan(arr)] == np.float32(layer.base_m)), f
        elif arr.dtype != np.bool_:
            assert np.all(np.isfinite(arr)), f"{f} has NaN/inf"
    assert batch.centre_m.dtype == np.float64 and batch.texture.dtype == np.int32
    slots = {s for box in model.boxes for s in box.textures}
    assert set(np.unique(batch.texture)) <= slots
    assert np.all(batch.size_m > 0.0)
    assert np.all((batch.rotation_rad >= 0.0) & (batch.rotation_rad <= 2 * np.pi))
    for f in ("height_frac", "core_frac", "darkness"):
        assert np.all((getattr(batch, f) >= 0.0) & (getattr(batch, f) <= 1.0)), f
    np.testing.assert_allclose(batch.opacity, model.opacity, rtol=1e-6)  # 8/8: whole
    norms = np.linalg.norm(batch.light_dir, axis=1)
    assert np.all((np.abs(norms - 1.0) < 1e-5) | (norms == 0.0))
    assert np.all(batch.flat == model.flat)
    assert (
        len(np.unique(batch.cloud_id))
        == block_clouds(5, 5, 1, model, layer.thickness_m, 77).n_clouds
    )


def test_only_the_cirrus_family_lies_flat() -> None:
    flat = {n for n in LAYERS if _model_args(n)[0].flat}
    assert flat == {"cirrus", "cirrostratus", "cirrocumulus"}


@pytest.mark.parametrize("name", ["cumulus-humilis", "cumulus-mediocris", "cumulus-congestus"])
def test_cumulus_share_the_layers_flat_base_and_fill_it(name: str) -> None:
    """Every sprite of a cumulus layer is cut at the layer's base (one condensation level for
    every cloud), and the base's sprites reach below it, so the cut is a dense straight
    edge rather than the round bottoms of puffs kept above it."""
    layer = _layer(name, 6)
    batch = layer_block(0, 0, 0, layer, 9)
    assert np.all(batch.base_m == np.float32(layer.base_m))
    bottom = batch.centre_m[:, 2] - 0.5 * batch.size_m
    for cloud in np.unique(batch.cloud_id):
        mine = batch.cloud_id == cloud
        assert (bottom[mine] < layer.base_m).sum() >= 3, cloud
    # No flat-bottomed texture: it paints a little cloud with its own base (a shelf).
    assert not np.any(batch.texture == TEX_FLAT_BOTTOM[0])


def test_shading_groups_point_base_down_and_tops_up() -> None:
    batch = layer_block(0, 0, 0, _layer("cumulus-mediocris", 8), 9)
    assert batch.light_dir[batch.height_frac < 0.05, 2].mean() < -0.3
    assert batch.light_dir[batch.height_frac > 0.8, 2].mean() > 0.3


# -- SpriteBatch helpers ------------------------------------------------------------------


def _batch(n: int, offset: float = 0.0) -> SpriteBatch:
    i = np.arange(n, dtype=np.float64) + offset
    return SpriteBatch(
        centre_m=np.stack([i, 2 * i, 3 * i], axis=1),
        size_m=(i + 100).astype(np.float32),
        rotation_rad=(i * 0.1).astype(np.float32),
        texture=(np.arange(n) % 16).astype(np.int32),
        height_frac=np.full(n, 0.5, np.float32),
        light_dir=np.tile(np.array([0, 0, 1], np.float32), (n, 1)),
        opacity=np.ones(n, np.float32),
        darkness=(i / 100).astype(np.float32),
        cloud_id=np.arange(n, dtype=np.int64),
        core_frac=np.full(n, 0.5, np.float32),
        flat=np.arange(n) % 2 == 1,
    )


def test_take_selects_rows_of_every_field() -> None:
    b = _batch(6)
    t = b.take(np.array([4, 1]))
    assert len(t) == 2
    np.testing.assert_array_equal(t.centre_m, [[4, 8, 12], [1, 2, 3]])
    np.testing.assert_array_equal(t.size_m, [104, 101])
    np.testing.assert_array_equal(t.texture, [4, 1])
    np.testing.assert_array_equal(t.flat, [False, True])
    np.testing.assert_array_equal(t.darkness, np.float32([0.04, 0.01]))
    m = b.take(np.array([True, False, False, False, False, True]))
    np.testing.assert_array_equal(m.centre_m[:, 0], [0, 5])
    assert len(b.take(np.array([], dtype=np.intp))) == 0


def test_a_take_cuts_each_field_when_first_read_as_an_eager_cut_would() -> None:
    """`take` cuts a field when it is read: what it reads is what cutting every field at
    once gives, a take of a take reads the first batch's rows, and a pickled take (a ring
    built in the worker process) carries its own rows, not the batch it was cut from."""
    b = _batch(40)
    first = np.array([30, 2, 17, 5, 9, 33, 0])
    t = b.take(first)
    assert "darkness" not in t.__dict__  # nothing read yet
    np.testing.assert_array_equal(t.darkness, b.darkness[first])
    assert "darkness" in t.__dict__ and "cloud_id" not in t.__dict__
    second = np.array([True, False, True, True, False, False, True])
    tt = t.take(second)
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(tt, name), getattr(b, name)[first[second]])
    with pytest.raises(AttributeError):
        _ = t.not_a_field  # type: ignore[attr-defined]
    whole = pickle.dumps(b)
    packed = pickle.dumps(t)
    assert len(packed) < len(whole) / 2
    back = pickle.loads(packed)
    assert "_taken" not in back.__dict__
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(back, name), getattr(b, name)[first])


def test_shifted_moves_the_centres_and_the_drift_they_carry() -> None:
    b = _batch(3)
    s = b.shifted((10.0, -20.0, 0.5))
    np.testing.assert_array_equal(s.centre_m - b.centre_m, np.tile([10.0, -20.0, 0.5], (3, 1)))
    # What is fixed to the layer's frame (a deck's relief) goes across with it.
    np.testing.assert_array_equal(s.drift_m - b.drift_m, np.tile([10.0, -20.0], (3, 1)))
    for name in FIELDS[1:]:
        if name != "drift_m":  # (slab_m and base_m are NaN here: no deck, no flat base)
            np.testing.assert_array_equal(getattr(s, name), getattr(b, name))
    np.testing.assert_array_equal(b.centre_m[1], [1, 2, 3])  # original untouched


def test_with_centres_moves_the_sprites_and_keeps_every_other_field() -> None:
    b = _batch(3)
    b = dataclasses.replace(b, slab_m=np.float32([[100, 200], [np.nan, np.nan], [300, 400]]))
    assert b.slab.tolist() == [True, False, True]
    moved = b.with_centres(b.centre_m + 5.0)
    np.testing.assert_array_equal(moved.centre_m, b.centre_m + 5.0)
    for name in FIELDS[1:]:
        assert getattr(moved, name) is getattr(b, name)
    assert moved.slab is b.slab  # kept with the batch, and read-only
    assert not moved.slab.flags.writeable
    with pytest.raises(ValueError, match="2 centres for 3 sprites"):
        b.with_centres(b.centre_m[:2])
    # Rows taken carry the kept mask, cut alike.
    taken = moved.take(np.array([2, 1]))
    assert "slab" in taken.__dict__ and taken.slab.tolist() == [True, False]
    assert not taken.slab.flags.writeable


def test_concat_appends_in_order_and_skips_empties() -> None:
    a, b = _batch(2), _batch(3, offset=10.0)
    c = SpriteBatch.concat([SpriteBatch.empty(), a, SpriteBatch.empty(), b])
    assert len(c) == 5
    np.testing.assert_array_equal(c.centre_m[:, 0], [0, 1, 10, 11, 12])
    np.testing.assert_array_equal(c.texture, [0, 1, 0, 1, 2])
    np.testing.assert_array_equal(c.flat, [False, True, False, True, False])
    for name in FIELDS:
        assert getattr(c, name).shape[0] == 5
    assert len(SpriteBatch.concat([])) == 0
    assert len(SpriteBatch.concat([SpriteBatch.empty()])) == 0


def test_flat_defaults_to_camera_facing_and_must_match_the_count() -> None:
    b = _batch(3)
    fields = {f: getattr(b, f) for f in FIELDS if f != "flat"}
    older = SpriteBatch(**fields)
    assert older.flat.dtype == np.bool_ and not older.flat.any() and len(older.flat) == 3
    with pytest.raises(ValueError, match="flat has 2 entries for 3 sprites"):
        SpriteBatch(**fields, flat=np.zeros(2, bool))


def test_empty_batch_has_consistent_shapes_and_dtypes() -> None:
    e = SpriteBatch.empty()
    assert len(e) == 0
    assert e.centre_m.shape == (0, 3) and e.light_dir.shape == (0, 3)
    assert e.texture.dtype == np.int32 and e.size_m.dtype == np.float32
    assert e.flat.dtype == np.bool_


def test_cached_blocks_are_read_only() -> None:
    b = block_clouds(*_args(0, 0, 0, "cumulus-humilis", 7)).sprites
    with pytest.raises(ValueError):
        b.centre_m[0, 0] = 1.0
    with pytest.raises(ValueError):
        b.opacity[0] = 0.5


def test_drifted_sprites_carry_the_drift_that_moved_them() -> None:
    """What moves with a layer (a deck's relief, fixed to centre - drift) reads the drift
    off each sprite: the gather's drift is the one its centres moved by."""
    from wxsky.scene.conditions import _drifted

    batch = layer_block(0, 0, 0, _layer("stratus", 8), 3)
    assert np.all(batch.drift_m == 0.0)
    moved = _drifted(batch, (120.0, -40.0))
    np.testing.assert_array_equal(
        moved.drift_m, np.tile(np.float32([120.0, -40.0]), (len(batch), 1))
    )
    np.testing.assert_allclose(
        moved.centre_m[:, :2] - moved.drift_m, batch.centre_m[:, :2], atol=1e-3
    )
    # Cut and joined with others, each sprite keeps its own.
    both = SpriteBatch.concat([moved.take(np.arange(3)), batch.take(np.arange(2))])
    assert both.drift_m[:3, 0].tolist() == [120.0] * 3 and both.drift_m[3:, 0].tolist() == [0.0] * 2
