"""Clouds of one 4 km block: Wang's sprite clouds built from a cloud model's artist boxes.

A block's clouds depend only on (block x, block y, layer key, model, layer thickness, weather
seed), so the same weather gives the same sky in any process on any machine (numpy's PCG64 is
portable). Every cell of the block holds a cloud here, whatever the cover: cover only decides
which of them show and how far they have formed (`formation.py`), so a cover that changes
every second never regenerates a block and a cloud keeps its shape while it forms.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from wxsky.scene.block_cache import BlockCache
from wxsky.scene.cloud_models import BoxTemplate, CloudModel
from wxsky.scene.sprite_cull import cull_mask_clouds
from wxsky.scene.sprites import F32, F64, I32, I64, SpriteBatch
from wxsky.scene.texture_slots import TEX_FLAT_BOTTOM
from wxsky.weather.state import CloudLayer, CloudType

__all__ = [
    "BLOCK_CACHE",
    "BLOCK_SIZE_M",
    "BlockClouds",
    "SpriteBatch",
    "block_clouds",
    "block_seed",
    "generate_block_clouds",
    "layer_keys",
]

BLOCK_SIZE_M = 4000.0
# A box that hangs under its layer's base (`BoxTemplate.under_base`: scud, fractus) reaches at
# most this far down: scud forms in the moist air just under a rain layer, a few hundred
# metres (a model file cannot put it on the ground).
UNDER_BASE_MAX_M = 600.0
# Shading groups 1..31 come from the model; sprites of group 0 boxes are grouped by their
# octant around the cloud's centre, as keys 32..39.
_OCTANT_GROUP = 32
_GROUP_KEYS = 40


@dataclass(frozen=True)
class BlockClouds:
    """Every cloud a block can hold, fully formed, in the layer's drifting frame with z above
    the layer's base. Cloud k forms k-th as cover rises (`formation.visible_sprites`)."""

    sprites: SpriteBatch  # (N,) opacity is the model's
    cloud_rank: I32  # (N,) the sprite's cloud's place in the block's formation order
    n_clouds: int
    rank_offset: float  # 0..1, this block's share of a rank: spreads coarse models over blocks
    spread_oktas: float  # cover change over which one cloud forms


def layer_keys(layers: tuple[CloudLayer, ...]) -> tuple[int, ...]:
    """A stable identity per layer: its cloud type and its rank among the layers of that type.
    Seeding blocks by it (not by the position in the list) keeps a layer's clouds when another
    layer forms or dissipates below it, or when its base or cover changes."""
    seen: dict[CloudType, int] = {}
    keys = []
    for layer in layers:
        rank = seen.get(layer.type, 0)
        seen[layer.type] = rank + 1
        keys.append(int(layer.type) * 16 + rank)
    return tuple(keys)


def block_seed(seed: int, layer_key: int, block_x: int, block_y: int) -> np.random.SeedSequence:
    # SeedSequence wants non-negative words: split the 63-bit seed, offset signed block indices.
    return np.random.SeedSequence(
        [seed & 0xFFFFFFFF, seed >> 32, layer_key, block_x + 2**31, block_y + 2**31]
    )


def _block_bytes(block: BlockClouds) -> int:
    arrays = [getattr(block.sprites, f.name) for f in dataclasses.fields(block.sprites)]
    return block.cloud_rank.nbytes + sum(a.nbytes for a in arrays if isinstance(a, np.ndarray))


# Every block made in this process, for the next ring build (`block_cache.py`: bounded by
# bytes, sized to the scene); `status` reports it.
BLOCK_CACHE: BlockCache[BlockClouds] = BlockCache(_block_bytes)


def block_clouds(
    block_x: int, block_y: int, layer_key: int, model: CloudModel, thickness_m: float, seed: int
) -> BlockClouds:
    """All clouds of one block (made once, then read from `BLOCK_CACHE`); layer_key comes
    from `layer_keys`, the model from `CloudModels.for_layer`. Not the cover nor the base:
    the cache stays hot while they move."""
    key = (block_x, block_y, layer_key, model, thickness_m, seed)
    return BLOCK_CACHE.get(
        key, lambda: generate_block_clouds(block_x, block_y, layer_key, model, thickness_m, seed)
    )


@dataclass(frozen=True)
class BlockLayout:
    """Where a block's clouds stand, before any sprite: what the radar (`scene/radar.py`)
    reads of the very clouds that are drawn, at a small part of a block's cost."""

    axis_m: F64  # (n, 2) each cloud's axis in the layer's drifting frame
    width_m: F64  # (n,)
    height_m: F64  # (n,)
    rank: I32  # (n,) each cloud's place in the block's formation order
    rank_offset: float
    cloud_id: I64  # (n,)


def block_layout(
    block_x: int, block_y: int, layer_key: int, model: CloudModel, thickness_m: float, seed: int
) -> BlockLayout:
    """The layout `generate_block_clouds` draws first, from the same stream."""
    rng = np.random.default_rng(block_seed(seed, layer_key, block_x, block_y))
    return _layout(rng, block_x, block_y, model, thickness_m)


def _layout(
    rng: np.random.Generator, block_x: int, block_y: int, model: CloudModel, thickness_m: float
) -> BlockLayout:
    per_side = max(1, round(BLOCK_SIZE_M / model.cell_m))
    cell_m = BLOCK_SIZE_M / per_side
    n = per_side * per_side
    rank = np.empty(n, np.int32)
    rank[rng.permutation(n)] = np.arange(n, dtype=np.int32)
    rank_offset = float(rng.uniform())
    jitter = rng.uniform(-1.0, 1.0, size=(n, 2)) * model.jitter_frac
    width_m = cell_m * _lerp(model.width_frac, rng.uniform(size=n))  # (n,)
    height_m = thickness_m * _lerp(model.height_frac, rng.uniform(size=n))  # (n,)
    cloud_id = rng.integers(0, 2**63 - 1, size=n, dtype=np.int64)
    cells = np.arange(n)
    axis_m = np.stack(  # (n, 2) each cloud's axis in the drifting frame
        [
            block_x * BLOCK_SIZE_M + (cells % per_side + 0.5 + jitter[:, 0]) * cell_m,
            block_y * BLOCK_SIZE_M + (cells // per_side + 0.5 + jitter[:, 1]) * cell_m,
        ],
        axis=1,
    )
    return BlockLayout(axis_m, width_m, height_m, rank, rank_offset, cloud_id)


def generate_block_clouds(
    block_x: int, block_y: int, layer_key: int, model: CloudModel, thickness_m: float, seed: int
) -> BlockClouds:
    """`block_clouds` without the cache."""
    rng = np.random.default_rng(block_seed(seed, layer_key, block_x, block_y))
    lay = _layout(rng, block_x, block_y, model, thickness_m)
    axis_m, width_m, height_m = lay.axis_m, lay.width_m, lay.height_m
    rank, rank_offset, cloud_id = lay.rank, lay.rank_offset, lay.cloud_id
    n = len(rank)
    cells = np.arange(n)
    parts = [_box_sprites(rng, box, axis_m, width_m, height_m) for box in model.boxes]
    # Cloud-major order, boxes in file order within a cloud: the order Wang's cull walks.
    per_cloud = sum(p.size.shape[1] for p in parts)
    pos: F64 = np.concatenate([p.pos for p in parts], axis=1).reshape(-1, 3)
    size: F64 = np.concatenate([p.size for p in parts], axis=1).reshape(-1)
    rot: F64 = np.concatenate([p.rot for p in parts], axis=1).reshape(-1)
    tex: I64 = np.concatenate([p.tex for p in parts], axis=1).reshape(-1)
    group: I64 = np.concatenate([p.group for p in parts], axis=1).reshape(-1)
    under = np.concatenate(
        [np.full(p.size.shape, box.under_base) for p, box in zip(parts, model.boxes, strict=True)],
        axis=1,
    ).reshape(-1)
    cloud: I64 = np.repeat(cells, per_cloud)
    # Keep sprite discs inside the layer: centres a third of a sprite from base and top, or
    # the middle of a layer too thin for that, never outside it.
    margin = np.minimum(0.3 * size, 0.5 * thickness_m)
    # A flat-based cloud's sprites may hang below its base: the cut there (`base_m`) makes the
    # straight, dense edge that sprites kept above it would leave rounded and thin.
    floor = np.zeros_like(margin) if model.flat_base else margin
    # Scud boxes hang under the base, at most UNDER_BASE_MAX_M (and out of the layer's top).
    floor = np.where(under, -UNDER_BASE_MAX_M, floor)
    pos[:, 2] = np.clip(pos[:, 2], floor, thickness_m - margin)
    # Sprites are cloud-major, per_cloud to a cloud, as the cull walks them.
    keep = cull_mask_clouds(
        pos.reshape(n, per_cloud, 3), (model.cull_frac * size).reshape(n, per_cloud)
    ).reshape(-1)
    pos, size, rot = pos[keep], size[keep], rot[keep]
    tex, group, cloud = tex[keep], group[keep], cloud[keep]
    # The flat-bottomed texture only works upright.
    rot = np.where(tex == TEX_FLAT_BOTTOM[0], 0.0, rot)
    radial = np.hypot(pos[:, 0] - axis_m[cloud, 0], pos[:, 1] - axis_m[cloud, 1])
    core = radial / np.maximum(0.5 * width_m[cloud], 1.0)
    if model.grows_up:
        # A heaped cloud's core is its low middle: it forms from the base up and dissipates
        # from the top down, so a half-formed tower is a shorter tower, not a thin column.
        core = np.maximum(core, pos[:, 2] / np.maximum(height_m[cloud], 1.0))
    count = len(size)
    sprites = SpriteBatch(
        centre_m=pos,
        size_m=size.astype(np.float32),
        rotation_rad=rot.astype(np.float32),
        texture=tex.astype(np.int32),
        height_frac=np.clip(pos[:, 2] / np.maximum(height_m[cloud], 1.0), 0.0, 1.0).astype(
            np.float32
        ),
        light_dir=_light_dirs(pos, group, cloud, n),
        opacity=np.full(count, model.opacity, np.float32),
        darkness=np.full(count, model.darkness, np.float32),
        cloud_id=cloud_id[cloud],
        core_frac=np.clip(core, 0.0, 1.0).astype(np.float32),
        flat=np.full(count, model.flat, np.bool_),
        # The slab is the whole layer, base (z = 0 here) to top, whatever each cloud's height.
        slab_m=np.tile(
            np.array([0.0, thickness_m] if model.slab else [np.nan, np.nan], np.float32),
            (count, 1),
        ),
        # Heaped clouds share the layer's base (z = 0 here): their sprites are cut there.
        base_m=np.full(count, 0.0 if model.flat_base else np.nan, np.float32),
    )
    for f in dataclasses.fields(sprites):
        getattr(sprites, f.name).flags.writeable = False
    return BlockClouds(sprites, rank[cloud], n, rank_offset, model.formation_spread_oktas)


class _BoxDraw(NamedTuple):
    """One box's sprites in every one of n clouds, k each."""

    pos: F64  # (n, k, 3) centres, z above the layer base
    size: F64  # (n, k)
    rot: F64  # (n, k)
    tex: I64  # (n, k) texture slots
    group: I64  # (n, k) the box's shading group


def _lerp(span: tuple[float, float], u: F64) -> F64:
    return span[0] + (span[1] - span[0]) * u


def _box_sprites(
    rng: np.random.Generator, box: BoxTemplate, axis_m: F64, width_m: F64, height_m: F64
) -> _BoxDraw:
    """Draws the same numbers whatever the cover, so a cloud's shape never depends on it."""
    n, k = int(axis_m.shape[0]), box.count
    scale = np.stack([width_m, width_m, height_m], axis=1)  # (n, 3) cloud units to metres
    extent = np.stack(
        [_lerp(span, rng.uniform(size=n)) for span in (box.width, box.depth, box.height)], axis=1
    )
    extent_m = extent * scale  # (n, 3)
    centre_m = np.asarray(box.centre) * scale
    centre_m[:, :2] += axis_m
    if box.sprites:
        unit = rng.uniform(-0.5, 0.5, size=(n, k, 3))
    else:
        nx, ny = box.grid
        gx, gy = np.meshgrid((np.arange(nx) + 0.5) / nx - 0.5, (np.arange(ny) + 0.5) / ny - 0.5)
        unit = np.zeros((n, k, 3))
        unit[:, :, 0] = gx.ravel()[None, :]
        unit[:, :, 1] = gy.ravel()[None, :]
        step = np.array([1.0 / nx, 1.0 / ny])
        unit[:, :, :2] += rng.uniform(-1.0, 1.0, size=(n, k, 2)) * box.grid_jitter * step
        unit[:, :, 2] = rng.uniform(-0.5, 0.5, size=(n, k))
    pos = centre_m[:, None, :] + unit * extent_m[:, None, :]
    size = width_m[:, None] * _lerp(box.sprite_size, rng.uniform(size=(n, k)))
    rot = np.mod(np.radians(_lerp(box.rotation_deg, rng.uniform(size=(n, k)))), 2.0 * math.pi)
    slots = np.asarray(box.textures, np.int64)
    tex = slots[rng.integers(0, len(slots), size=(n, k))]
    group = np.full((n, k), box.shading_group, np.int64)
    return _BoxDraw(pos, size, rot, tex, group)


def _light_dirs(pos: F64, group: I64, cloud: I64, n_clouds: int) -> F32:
    """(N, 3) unit vector from each sprite's cloud centre to its shading group's centre (Wang:
    sprites of a group shade as one clump); zero where the two coincide."""
    count = np.bincount(cloud, minlength=n_clouds).astype(np.float64)
    centroid = (
        np.stack(
            [np.bincount(cloud, weights=pos[:, a], minlength=n_clouds) for a in range(3)], axis=1
        )
        / np.maximum(count, 1.0)[:, None]
    )
    offs = pos - centroid[cloud]
    octant = (offs[:, 0] > 0) + 2 * (offs[:, 1] > 0) + 4 * (offs[:, 2] > 0)
    key = np.where(group > 0, group, _OCTANT_GROUP + octant) + cloud * _GROUP_KEYS
    _, inverse = np.unique(key, return_inverse=True)
    inverse = inverse.reshape(-1)
    sums = np.stack([np.bincount(inverse, weights=offs[:, a]) for a in range(3)], axis=1)
    norms = np.linalg.norm(sums, axis=1, keepdims=True)
    dirs = np.divide(sums, norms, out=np.zeros_like(sums), where=norms > 1e-9)
    out: F32 = dirs[inverse].astype(np.float32)
    return out
