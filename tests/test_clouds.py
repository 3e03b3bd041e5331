"""Per-block cloud generation: determinism, cover, geometry bounds, and SpriteBatch helpers."""

from __future__ import annotations

import hashlib
import itertools
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from wxsky.scene.clouds import (
    BLOCK_SIZE_M,
    TEMPLATES,
    SpriteBatch,
    block_clouds,
    template_for,
)
from wxsky.scene.texture_slots import TEX_FLAT_BOTTOM
from wxsky.weather.state import CloudLayer, CloudType

# The undecorated generator, so determinism is not just the lru_cache handing back one object.
_generate = block_clouds.__wrapped__  # type: ignore[attr-defined]

CU = CloudLayer(4, 1500.0, 2700.0, CloudType.CUMULUS)
ST = CloudLayer(8, 830.0, 1350.0, CloudType.STRATUS)

FIELDS = (
    "centre_m",
    "size_m",
    "rotation_rad",
    "texture",
    "height_frac",
    "light_dir",
    "opacity",
    "darkness",
)

# One layer per type, thick enough for the sprite margins to fit (METAR-like thicknesses).
LAYERS = {
    CloudType.CUMULUS: (1500.0, 2700.0),
    CloudType.CUMULONIMBUS: (1000.0, 10_000.0),
    CloudType.ALTOCUMULUS: (4000.0, 4500.0),
    CloudType.CIRROCUMULUS: (7000.0, 7500.0),
    CloudType.STRATOCUMULUS: (1000.0, 1600.0),
    CloudType.STRATUS: (800.0, 1300.0),
    CloudType.NIMBOSTRATUS: (1000.0, 3000.0),
    CloudType.ALTOSTRATUS: (3000.0, 4500.0),
    CloudType.CIRRUS: (9000.0, 10_000.0),
    CloudType.CIRROSTRATUS: (8000.0, 9000.0),
}
ALL_TYPES = list(LAYERS)


def _kind_id(kind: CloudType) -> str:
    return kind.name.lower()


def _layer(kind: CloudType, oktas: int) -> CloudLayer:
    base, top = LAYERS[kind]
    return CloudLayer(oktas, base, top, kind)


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


def _covered_fraction(batch: SpriteBatch, bx: int, by: int, n: int = 80) -> float:
    """Share of a block's area under at least one sprite's horizontal disc (radius size/2),
    on an n x n grid of sample points."""
    step = BLOCK_SIZE_M / n
    g = (np.arange(n) + 0.5) * step
    covered = np.zeros((n, n), bool)
    for (x, y, _), size in zip(batch.centre_m, batch.size_m, strict=True):
        r = 0.5 * float(size)
        # Only the grid rows and columns within the disc's bounding box.
        lx, ly = x - bx * BLOCK_SIZE_M, y - by * BLOCK_SIZE_M
        i0, i1 = max(0, int((lx - r) // step)), min(n, int((lx + r) // step) + 1)
        j0, j1 = max(0, int((ly - r) // step)), min(n, int((ly + r) // step) + 1)
        if i0 >= i1 or j0 >= j1:
            continue
        dx, dy = g[i0:i1] - lx, g[j0:j1] - ly
        covered[j0:j1, i0:i1] |= dy[:, None] ** 2 + dx[None, :] ** 2 <= r * r
    return float(covered.mean())


def _with_neighbours(layer: CloudLayer, bx: int, by: int, seed: int) -> SpriteBatch:
    return SpriteBatch.concat(
        [block_clouds(bx + i, by + j, 0, layer, seed) for i in (-1, 0, 1) for j in (-1, 0, 1)]
    )


# -- determinism --------------------------------------------------------------------------

BLOCK_ARGS = [
    (0, 0, 0, CU, 7),
    (-3, 5, 1, ST, 2**40 + 3),
    (12, -9, 2, _layer(CloudType.CIRRUS, 6), 1),
]


def test_same_arguments_give_identical_arrays() -> None:
    for args in BLOCK_ARGS:
        _assert_same(_generate(*args), _generate(*args))
        _assert_same(_generate(*args), block_clouds(*args))


def test_same_clouds_in_another_process() -> None:
    code = textwrap.dedent(
        """
        import hashlib, sys
        import numpy as np
        from wxsky.scene.clouds import block_clouds
        from wxsky.weather.state import CloudLayer, CloudType
        fields = %r
        for args in %s:
            b = block_clouds(*args)
            h = hashlib.sha256()
            for name in fields:
                arr = np.ascontiguousarray(getattr(b, name))
                h.update(f"{name}:{arr.dtype.str}:{arr.shape}".encode())
                h.update(arr.tobytes())
            print(h.hexdigest())
        """
    ) % (
        FIELDS,
        "[(0, 0, 0, CloudLayer(4, 1500.0, 2700.0, CloudType.CUMULUS), 7),"
        " (-3, 5, 1, CloudLayer(8, 830.0, 1350.0, CloudType.STRATUS), 2**40 + 3),"
        " (12, -9, 2, CloudLayer(6, 9000.0, 10000.0, CloudType.CIRRUS), 1)]",
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=60
    )
    assert out.stdout.split() == [_digest(_generate(*args)) for args in BLOCK_ARGS]


@pytest.mark.parametrize(
    "changed",
    [
        (1, 0, 0, CU, 7),  # another block x
        (0, -1, 0, CU, 7),  # another block y
        (0, 0, 1, CU, 7),  # another layer index
        (0, 0, 0, CU, 8),  # another seed
        (0, 0, 0, CU, 7 + 2**32),  # seed differing only in the high word
    ],
)
def test_different_block_layer_or_seed_gives_different_clouds(changed: tuple) -> None:
    base = _generate(0, 0, 0, CU, 7)
    other = _generate(*changed)
    assert len(base) and len(other)
    # Not merely shifted: positions within the block differ.
    rel_base = np.sort(base.centre_m[:, 0] % BLOCK_SIZE_M)
    rel_other = np.sort(other.centre_m[:, 0] % BLOCK_SIZE_M)
    assert len(base) != len(other) or not np.allclose(rel_base, rel_other)


# -- cover --------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ALL_TYPES, ids=_kind_id)
def test_zero_cover_gives_no_sprites(kind: CloudType) -> None:
    batch = block_clouds(2, 3, 0, _layer(kind, 0), 11)
    assert len(batch) == 0
    assert batch.centre_m.shape == (0, 3) and batch.light_dir.shape == (0, 3)


@pytest.mark.parametrize("kind", ALL_TYPES, ids=_kind_id)
def test_more_oktas_never_fewer_sprites_or_less_area(kind: CloudType) -> None:
    counts, areas = [], []
    for oktas in range(9):
        batch = block_clouds(1, -2, 0, _layer(kind, oktas), 5)
        counts.append(len(batch))
        areas.append(_covered_fraction(batch, 1, -2, n=50))
    assert counts[0] == 0 and counts[8] > 0
    assert all(a <= b for a, b in itertools.pairwise(counts)), counts
    assert all(a <= b + 1e-9 for a, b in itertools.pairwise(areas)), areas
    assert areas[8] > areas[1] + 0.5


@pytest.mark.parametrize(
    "kind", [CloudType.CUMULUS, CloudType.STRATUS, CloudType.ALTOCUMULUS], ids=_kind_id
)
@pytest.mark.parametrize(("bx", "by", "seed"), [(0, 0, 1), (3, -2, 4), (-7, 5, 99)])
def test_covered_area_grows_strictly_and_overcast_closes(
    kind: CloudType, bx: int, by: int, seed: int
) -> None:
    """Templates with a fine cell grid: every okta adds cloud; 8/8 covers the block."""
    areas = [
        _covered_fraction(_with_neighbours(_layer(kind, oktas), bx, by, seed), bx, by)
        for oktas in range(1, 9)
    ]
    assert all(a < b for a, b in itertools.pairwise(areas)), areas
    assert areas[0] > 0.0
    assert areas[-1] >= 0.95, areas
    counts = [len(block_clouds(bx, by, 0, _layer(kind, k), seed)) for k in range(1, 9)]
    assert all(a < b for a, b in itertools.pairwise(counts)), counts


@pytest.mark.parametrize("kind", ALL_TYPES, ids=_kind_id)
def test_overcast_covers_the_block(kind: CloudType) -> None:
    area = _covered_fraction(_with_neighbours(_layer(kind, 8), 2, 2, 17), 2, 2)
    assert area >= 0.95


@pytest.mark.parametrize("kind", [CloudType.CUMULONIMBUS, CloudType.CIRRUS], ids=_kind_id)
def test_any_nonzero_cover_produces_some_cloud(kind: CloudType) -> None:
    """A FEW or SCT layer must show some clouds somewhere in a 6 x 6 block (24 km) area."""
    for oktas in range(1, 5):
        layer = _layer(kind, oktas)
        total = sum(len(block_clouds(bx, by, 0, layer, 3)) for bx in range(6) for by in range(6))
        assert total > 0, f"{oktas}/8 {kind.name}: no sprites in 36 blocks"


# -- geometry -----------------------------------------------------------------------------


@pytest.mark.parametrize("oktas", [5, 8])
@pytest.mark.parametrize("kind", ALL_TYPES, ids=_kind_id)
def test_sprites_stay_inside_layer_and_block(kind: CloudType, oktas: int) -> None:
    layer = _layer(kind, oktas)
    # A coarse template (one cumulonimbus per block) leaves some blocks empty below 8/8:
    # take the first of a row of blocks that holds a cloud.
    candidates = [(bx, 9) for bx in range(-4, 2)]
    bx, by = next(
        ((x, y) for x, y in candidates if len(block_clouds(x, y, 2, layer, 12345))), (0, 0)
    )
    batch = block_clouds(bx, by, 2, layer, 12345)
    assert len(batch) > 0, f"no cloud in any of {candidates}"
    z = batch.centre_m[:, 2]
    size = batch.size_m.astype(np.float64)
    slack = 1e-3 * size  # sizes are stored as float32
    assert np.all((z >= layer.base_m) & (z <= layer.top_m))
    # Sprite discs kept inside the layer: centres at least 0.3 sprite above the base, and
    # 0.3 sprite below the top wherever the cloud is tall enough for both margins (a cloud
    # is at least height_frac[0] of the layer thick).
    tpl = template_for(kind)
    fits = 0.6 * size <= tpl.height_frac[0] * layer.thickness_m
    assert np.all(z[fits] >= layer.base_m + 0.3 * size[fits] - slack[fits])
    assert np.all(z[fits] <= layer.top_m - 0.3 * size[fits] + slack[fits])
    # Horizontally inside the block, give or take one cloud radius.
    cell = BLOCK_SIZE_M / max(1, round(BLOCK_SIZE_M / tpl.cell_m))
    radius = cell * max(tpl.radius_frac[1], 0.8)
    x, y = batch.centre_m[:, 0], batch.centre_m[:, 1]
    assert np.all(x >= bx * BLOCK_SIZE_M - radius) and np.all(x <= (bx + 1) * BLOCK_SIZE_M + radius)
    assert np.all(y >= by * BLOCK_SIZE_M - radius) and np.all(y <= (by + 1) * BLOCK_SIZE_M + radius)
    # Most of the cloud mass is in the block itself.
    inside = (x >= bx * BLOCK_SIZE_M) & (x < (bx + 1) * BLOCK_SIZE_M)
    assert inside.mean() > 0.7


def test_sprite_centres_stay_inside_a_thin_layer() -> None:
    thin = CloudLayer(8, 830.0, 930.0, CloudType.STRATUS)
    batch = block_clouds(0, 0, 0, thin, 23)
    assert len(batch)
    z = batch.centre_m[:, 2]
    assert np.all((z >= thin.base_m) & (z <= thin.top_m)), (z.min(), z.max())


def test_sprites_in_a_thin_layer_sit_at_its_middle() -> None:
    thin = CloudLayer(8, 830.0, 930.0, CloudType.STRATUS)
    batch = block_clouds(0, 0, 0, thin, 23)
    # Every sprite is far larger than the 100 m layer: the margins meet at each cloud's middle,
    # which lies in the lower half of the layer or at its centre.
    z = batch.centre_m[:, 2]
    assert np.all((z > thin.base_m) & (z <= 0.5 * (thin.base_m + thin.top_m) + 1e-6))


@pytest.mark.parametrize("kind", ALL_TYPES, ids=_kind_id)
def test_attributes_are_finite_and_in_range(kind: CloudType) -> None:
    batch = block_clouds(5, 5, 1, _layer(kind, 8), 77)
    n = len(batch)
    assert n > 0
    for name in FIELDS:
        arr = getattr(batch, name)
        assert arr.shape[0] == n, name
        assert np.all(np.isfinite(arr)), f"{name} has NaN/inf"
    assert batch.centre_m.dtype == np.float64 and batch.texture.dtype == np.int32
    assert set(np.unique(batch.texture)) <= set(range(16))
    assert set(np.unique(batch.texture)) <= set(template_for(kind).textures) | set(TEX_FLAT_BOTTOM)
    assert np.all(batch.size_m > 0.0)
    assert np.all((batch.rotation_rad >= 0.0) & (batch.rotation_rad <= 2 * np.pi))
    assert np.all((batch.height_frac >= 0.0) & (batch.height_frac <= 1.0))
    assert np.all((batch.opacity > 0.0) & (batch.opacity <= 1.0))
    assert np.all((batch.darkness >= 0.0) & (batch.darkness <= 1.0))
    norms = np.linalg.norm(batch.light_dir, axis=1)
    assert np.all((np.abs(norms - 1.0) < 1e-5) | (norms == 0.0))


def test_heaped_clouds_use_upright_flat_bottoms_low_down() -> None:
    batch = block_clouds(0, 0, 0, _layer(CloudType.CUMULUS, 5), 9)
    flat = batch.texture == TEX_FLAT_BOTTOM[0]
    assert flat.any() and (~flat).any()
    assert np.all(batch.rotation_rad[flat] == 0.0)
    assert batch.height_frac[flat].mean() < batch.height_frac[~flat].mean()


def test_every_template_uses_valid_texture_slots() -> None:
    for tpl in TEMPLATES.values():
        assert tpl.textures and all(0 <= t < 16 for t in tpl.textures)


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
    )


def test_take_selects_rows_of_every_field() -> None:
    b = _batch(6)
    t = b.take(np.array([4, 1]))
    assert len(t) == 2
    np.testing.assert_array_equal(t.centre_m, [[4, 8, 12], [1, 2, 3]])
    np.testing.assert_array_equal(t.size_m, [104, 101])
    np.testing.assert_array_equal(t.texture, [4, 1])
    np.testing.assert_array_equal(t.darkness, np.float32([0.04, 0.01]))
    m = b.take(np.array([True, False, False, False, False, True]))
    np.testing.assert_array_equal(m.centre_m[:, 0], [0, 5])
    assert len(b.take(np.array([], dtype=np.intp))) == 0


def test_shifted_moves_only_centres() -> None:
    b = _batch(3)
    s = b.shifted((10.0, -20.0, 0.5))
    np.testing.assert_array_equal(s.centre_m - b.centre_m, np.tile([10.0, -20.0, 0.5], (3, 1)))
    for name in FIELDS[1:]:
        np.testing.assert_array_equal(getattr(s, name), getattr(b, name))
    np.testing.assert_array_equal(b.centre_m[1], [1, 2, 3])  # original untouched


def test_concat_appends_in_order_and_skips_empties() -> None:
    a, b = _batch(2), _batch(3, offset=10.0)
    c = SpriteBatch.concat([SpriteBatch.empty(), a, SpriteBatch.empty(), b])
    assert len(c) == 5
    np.testing.assert_array_equal(c.centre_m[:, 0], [0, 1, 10, 11, 12])
    np.testing.assert_array_equal(c.texture, [0, 1, 0, 1, 2])
    for name in FIELDS:
        assert getattr(c, name).shape[0] == 5
    assert len(SpriteBatch.concat([])) == 0
    assert len(SpriteBatch.concat([SpriteBatch.empty()])) == 0
    only = SpriteBatch.concat([SpriteBatch.empty(), a])
    np.testing.assert_array_equal(only.centre_m, a.centre_m)


def test_empty_batch_has_consistent_shapes_and_dtypes() -> None:
    e = SpriteBatch.empty()
    assert len(e) == 0
    assert e.centre_m.shape == (0, 3) and e.light_dir.shape == (0, 3)
    assert e.texture.dtype == np.int32 and e.size_m.dtype == np.float32


def test_cached_blocks_are_read_only() -> None:
    b = block_clouds(0, 0, 0, CU, 7)
    with pytest.raises(ValueError):
        b.centre_m[0, 0] = 1.0
