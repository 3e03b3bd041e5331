"""Clouds of one 4 km block: Wang's sprite clouds, generated from the block's own seed.

A block's clouds depend only on (block x, block y, layer key, layer, weather seed), so the
same weather gives the same sky in any process on any machine (numpy's PCG64 is portable).
Cover decides how many of the block's cells hold a cloud; the cloud type picks a template.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from wxsky.scene.texture_slots import TEX_FLAT_BOTTOM, TEX_FOG, TEX_PUFFY, TEX_WISPY
from wxsky.weather.state import CloudLayer, CloudType

BLOCK_SIZE_M = 4000.0

F32 = npt.NDArray[np.float32]
F64 = npt.NDArray[np.float64]
I32 = npt.NDArray[np.int32]
I64 = npt.NDArray[np.int64]

# Until the sheet has ragged textures of its own, the second half of the wispy ones stand in.
TEX_RAGGED = TEX_WISPY[3:]


@dataclass(frozen=True)
class SpriteBatch:
    """N cloud sprites as parallel arrays."""

    centre_m: F64  # (N, 3) ENU
    size_m: F32  # (N,) edge length of the square sprite
    rotation_rad: F32  # (N,)
    texture: I32  # (N,) slot on the texture sheet
    height_frac: F32  # (N,) 0 at the cloud's base .. 1 at its top: picks the colour level
    light_dir: F32  # (N, 3) unit vector from the cloud centre to the sprite's shading group
    opacity: F32  # (N,) 0..1: formation/dissipation and type transparency
    darkness: F32  # (N,) 0..1: how grey the cloud type's base is (stratus, Cb)
    cloud_id: I64  # (N,) the sprite's cloud, the same in every frame and process
    core_frac: F32  # (N,) horizontal distance from the cloud's axis over its radius: 0 core, 1 edge

    def __len__(self) -> int:
        return int(self.size_m.shape[0])

    def take(self, index: npt.NDArray[np.intp] | npt.NDArray[np.bool_]) -> SpriteBatch:
        return SpriteBatch(**{f.name: getattr(self, f.name)[index] for f in _FIELDS})

    def shifted(self, offset_m: tuple[float, float, float]) -> SpriteBatch:
        return dataclasses.replace(
            self, centre_m=self.centre_m + np.asarray(offset_m, dtype=np.float64)
        )

    @staticmethod
    def empty() -> SpriteBatch:
        return SpriteBatch(
            centre_m=np.zeros((0, 3)),
            size_m=np.zeros(0, np.float32),
            rotation_rad=np.zeros(0, np.float32),
            texture=np.zeros(0, np.int32),
            height_frac=np.zeros(0, np.float32),
            light_dir=np.zeros((0, 3), np.float32),
            opacity=np.zeros(0, np.float32),
            darkness=np.zeros(0, np.float32),
            cloud_id=np.zeros(0, np.int64),
            core_frac=np.zeros(0, np.float32),
        )

    @staticmethod
    def concat(batches: list[SpriteBatch]) -> SpriteBatch:
        batches = [b for b in batches if len(b)]
        if not batches:
            return SpriteBatch.empty()
        if len(batches) == 1:
            return batches[0]
        return SpriteBatch(
            **{f.name: np.concatenate([getattr(b, f.name) for b in batches]) for f in _FIELDS}
        )


_FIELDS = dataclasses.fields(SpriteBatch)


@dataclass(frozen=True)
class CloudTemplate:
    """How one cloud type fills a block: Wang's artist boxes, reduced to a few numbers."""

    cell_m: float  # one cloud per occupied cell
    radius_frac: tuple[float, float]  # cloud radius as a fraction of the cell
    height_frac: tuple[float, float]  # cloud height as a fraction of the layer thickness
    sprites_per_km2: float  # sprite density over the cloud's footprint
    min_sprites: int
    size_frac: tuple[float, float]  # sprite size as a fraction of the cloud radius
    textures: tuple[int, ...]
    dome: bool  # heaped (cumulus) rather than a slab (stratus)
    opacity: float
    darkness: float


_HEAPED = CloudTemplate(
    1000.0, (0.36, 0.52), (0.55, 1.0), 70.0, 10, (0.55, 0.85), TEX_PUFFY, True, 1.0, 0.35
)
_SLAB = CloudTemplate(
    1000.0, (0.62, 0.72), (0.7, 1.0), 5.0, 4, (0.85, 1.15), TEX_FOG + TEX_RAGGED, False, 0.9, 0.45
)

TEMPLATES: dict[CloudType, CloudTemplate] = {
    CloudType.CUMULUS: _HEAPED,
    CloudType.CUMULONIMBUS: CloudTemplate(
        4000.0,
        (0.35, 0.45),
        (0.9, 1.0),
        30.0,
        60,
        (0.3, 0.5),
        TEX_PUFFY + TEX_RAGGED,
        True,
        1.0,
        0.7,
    ),
    CloudType.ALTOCUMULUS: CloudTemplate(
        600.0, (0.35, 0.5), (0.6, 1.0), 60.0, 5, (0.6, 0.9), TEX_PUFFY + TEX_RAGGED, True, 0.9, 0.25
    ),
    CloudType.CIRROCUMULUS: CloudTemplate(
        500.0,
        (0.3, 0.45),
        (0.5, 1.0),
        50.0,
        4,
        (0.7, 1.0),
        TEX_WISPY + TEX_RAGGED,
        False,
        0.6,
        0.05,
    ),
    CloudType.STRATOCUMULUS: CloudTemplate(
        1000.0,
        (0.5, 0.68),
        (0.6, 1.0),
        22.0,
        6,
        (0.6, 0.9),
        TEX_RAGGED + TEX_PUFFY,
        True,
        0.95,
        0.45,
    ),
    CloudType.STRATUS: _SLAB,
    CloudType.NIMBOSTRATUS: CloudTemplate(
        1000.0,
        (0.65, 0.75),
        (0.8, 1.0),
        6.0,
        4,
        (0.85, 1.15),
        TEX_FOG + TEX_RAGGED,
        False,
        1.0,
        0.65,
    ),
    CloudType.ALTOSTRATUS: CloudTemplate(
        1000.0, (0.62, 0.72), (0.7, 1.0), 5.0, 4, (0.9, 1.2), TEX_FOG, False, 0.75, 0.3
    ),
    CloudType.CIRRUS: CloudTemplate(
        2000.0, (0.4, 0.6), (0.3, 1.0), 3.0, 4, (0.8, 1.2), TEX_WISPY, False, 0.55, 0.0
    ),
    CloudType.CIRROSTRATUS: CloudTemplate(
        2000.0, (0.6, 0.72), (0.3, 1.0), 3.0, 5, (1.0, 1.3), TEX_WISPY + TEX_FOG, False, 0.45, 0.0
    ),
}


def template_for(cloud_type: CloudType) -> CloudTemplate:
    return TEMPLATES.get(cloud_type, _HEAPED)


def occupied_fraction(cover_oktas: float) -> float:
    """Share of a block's cells that hold a cloud for a cover in oktas."""
    return min(1.0, cover_oktas / 8.0)


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


@functools.lru_cache(maxsize=4096)
def block_clouds(
    block_x: int, block_y: int, layer_key: int, layer: CloudLayer, seed: int
) -> SpriteBatch:
    """Sprites of one block in the layer's drifting frame: x, y absolute in that frame, z MSL.
    layer_key comes from `layer_keys`."""
    rng = np.random.default_rng(block_seed(seed, layer_key, block_x, block_y))
    tpl = template_for(layer.type)
    cells_per_side = max(1, round(BLOCK_SIZE_M / tpl.cell_m))
    cell_m = BLOCK_SIZE_M / cells_per_side
    n_cells = cells_per_side * cells_per_side
    # Draw every random number even for empty cells so a cover change keeps the other clouds.
    order = rng.permutation(n_cells)
    jitter = rng.uniform(-0.3, 0.3, size=(n_cells, 2))
    radius_u = rng.uniform(size=n_cells)
    height_u = rng.uniform(size=n_cells)
    cloud_seeds = rng.integers(0, 2**63 - 1, size=n_cells)
    # Round the expected cloud count up or down by the block's own coin, so a coarse template
    # (one cumulonimbus cell per block) still shows its cover on average across blocks.
    expected = occupied_fraction(layer.cover_oktas) * n_cells
    n_clouds = int(expected) + int(rng.uniform() < expected - int(expected))
    if n_clouds == 0:
        return SpriteBatch.empty()
    chosen = np.sort(order[:n_clouds])
    full = layer.cover_oktas >= 7
    r_lo, r_hi = tpl.radius_frac
    if full:
        # Overcast cells must overlap their neighbours or the sky shows a lattice of holes.
        r_lo, r_hi = max(r_lo, 0.72), max(r_hi, 0.8)
    batches = []
    for cell in chosen:
        cx = (cell % cells_per_side + 0.5 + jitter[cell, 0] * (0.3 if full else 1.0)) * cell_m
        cy = (cell // cells_per_side + 0.5 + jitter[cell, 1] * (0.3 if full else 1.0)) * cell_m
        radius = cell_m * (r_lo + (r_hi - r_lo) * radius_u[cell])
        h_lo, h_hi = tpl.height_frac
        height = layer.thickness_m * (h_lo + (h_hi - h_lo) * height_u[cell])
        batches.append(
            _cloud_sprites(
                np.random.default_rng(int(cloud_seeds[cell])),
                tpl,
                (block_x * BLOCK_SIZE_M + cx, block_y * BLOCK_SIZE_M + cy, layer.base_m),
                radius,
                height,
                int(cloud_seeds[cell]),
            )
        )
    batch = SpriteBatch.concat(batches)
    for arr in (batch.centre_m, batch.size_m, batch.rotation_rad, batch.texture):
        arr.flags.writeable = False
    return batch


def _cloud_sprites(
    rng: np.random.Generator,
    tpl: CloudTemplate,
    base_centre: tuple[float, float, float],
    radius_m: float,
    height_m: float,
    cloud_id: int,
) -> SpriteBatch:
    area_km2 = math.pi * radius_m * radius_m / 1e6
    n = max(tpl.min_sprites, round(tpl.sprites_per_km2 * area_km2))
    size = radius_m * rng.uniform(*tpl.size_frac, size=n)
    z_frac = rng.uniform(size=n)
    if tpl.dome:
        # Heaped clouds: sprites denser low, narrowing towards the top (a half-ellipsoid).
        z_frac = z_frac**1.4
        reach = np.sqrt(np.clip(1.0 - z_frac**2, 0.05, 1.0))
    else:
        reach = np.ones(n)
    ang = rng.uniform(0.0, 2.0 * math.pi, size=n)
    rad = np.sqrt(rng.uniform(size=n)) * reach * np.maximum(radius_m - 0.35 * size, 0.2 * radius_m)
    x = base_centre[0] + rad * np.cos(ang)
    y = base_centre[1] + rad * np.sin(ang)
    # Keep sprite discs inside the layer: centres a third of a sprite from base and top, or
    # the middle of a cloud too thin for that, never outside it.
    margin = np.minimum(0.3 * size, 0.5 * height_m)
    z_lo = base_centre[2] + margin
    z_hi = base_centre[2] + height_m - margin
    z = z_lo + (z_hi - z_lo) * z_frac
    textures = np.asarray(tpl.textures, dtype=np.int32)[rng.integers(0, len(tpl.textures), size=n)]
    if tpl.dome:
        textures = np.where(z_frac < 0.12, TEX_FLAT_BOTTOM[0], textures).astype(np.int32)
    rotation = rng.uniform(0.0, 2.0 * math.pi, size=n)
    if tpl.dome:
        # The flat-bottomed texture only works upright.
        rotation = np.where(textures == TEX_FLAT_BOTTOM[0], 0.0, rotation)
    # Shading groups: the octant of the sprite around the cloud's centre of mass (Wang's clumps).
    centre = np.array([x.mean(), y.mean(), z.mean()])
    offs = np.stack([x, y, z], axis=1) - centre
    group = (offs[:, 0] > 0).astype(int) + 2 * (offs[:, 1] > 0) + 4 * (offs[:, 2] > 0)
    group_dir = np.zeros((8, 3))
    np.add.at(group_dir, group, offs)
    norms = np.linalg.norm(group_dir, axis=1, keepdims=True)
    group_dir = np.divide(group_dir, norms, out=np.zeros_like(group_dir), where=norms > 0)
    return SpriteBatch(
        centre_m=np.stack([x, y, z], axis=1),
        size_m=size.astype(np.float32),
        rotation_rad=rotation.astype(np.float32),
        texture=textures,
        height_frac=np.clip((z - base_centre[2]) / max(height_m, 1.0), 0.0, 1.0).astype(np.float32),
        light_dir=group_dir[group].astype(np.float32),
        opacity=np.full(n, tpl.opacity, np.float32),
        darkness=np.full(n, tpl.darkness, np.float32),
        cloud_id=np.full(n, cloud_id, np.int64),
        core_frac=np.clip(rad / max(radius_m, 1.0), 0.0, 1.0).astype(np.float32),
    )
