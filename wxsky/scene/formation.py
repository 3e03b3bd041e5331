"""Formation and dissipation (Wang, "Let There Be Clouds!"): cover in, per-sprite opacity out.

A block's clouds are generated once, whatever the cover (`clouds.block_clouds`); the applied
weather's cover then decides, cheaply and per sprite, how far each cloud has formed. Cloud k of
the block (in its fixed random order) stands for the cover share

    t_k = 8 * (k + u) / n        (n clouds, u the block's own offset in 0..1)

and forms over `spread` oktas of cover centred on t_k, moved inward where that would start
below 0 or end above 8. So nothing shows at 0 oktas, every cloud is whole at 8, the formed
share of the clouds is exactly cover / 8 from `spread` to 8 - `spread` oktas, and a cover
change forms or dissipates whole clouds block by block. The block's offset u spreads a coarse
model (one cumulonimbus per block) over blocks: at 4/8 about half of them hold one.
Within a cloud, as Wang describes, the core (`core_frac` < 0.5: within half the radius of the
axis, and for heaped clouds in their lower half) forms first and every core sprite is opaque
before the first outer sprite shows; outer sprites then fill in outward. Dissipation is the
same path backwards: edges go first, the core last.

The model's `formation_spread_oktas` over `[transition] cover_oktas_per_min` is how long one
cloud takes to form: 1 okta at 2 oktas/min is 30 s, while the next clouds follow.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import numpy.typing as npt

from wxsky.scene.cloud_model_files import default_models
from wxsky.scene.cloud_models import CloudModels
from wxsky.scene.clouds import BlockClouds, block_clouds
from wxsky.scene.rain import SHAFT_TYPES, Rain, shaft_sprites
from wxsky.scene.sprites import F32, SpriteBatch
from wxsky.weather.state import CloudLayer

FULL_OKTAS = 8.0
CORE_FRAC = 0.5  # Wang: the core is within half the cloud radius of its centre
# Progress (0..1 of a cloud's formation) at which core sprites start (core_frac 0 .. 0.5) and
# outer sprites start (core_frac 0.5 .. 1), and how long each sprite takes to fade in.
CORE_START = (0.0, 0.15)
EDGE_START = (0.45, 0.7)
SPRITE_RAMP = 0.3


def cloud_progress(block: BlockClouds, cover_oktas: float) -> F32:
    """(N,) how far each sprite's cloud has formed at this cover: 0 not at all .. 1 whole."""
    out: F32 = progress_of_ranks(
        block.cloud_rank, block.rank_offset, block.n_clouds, block.spread_oktas, cover_oktas
    ).astype(np.float32)
    return out


def progress_of_ranks(
    rank: npt.NDArray[np.int32], rank_offset: float, n_clouds: int, spread: float, cover: float
) -> npt.NDArray[np.float64]:
    """How far clouds of these formation ranks (of `n_clouds` in a block) have formed at
    `cover` oktas, the rule above: per sprite (`cloud_progress`) or per cloud (the radar)."""
    share = FULL_OKTAS * (rank + rank_offset) / n_clouds
    start = np.clip(share - 0.5 * spread, 0.0, FULL_OKTAS - spread)
    out: npt.NDArray[np.float64] = np.clip((cover - start) / spread, 0.0, 1.0)
    return out


def sprite_alpha(progress: F32, core_frac: F32) -> F32:
    """(N,) a sprite's share of its opacity: core sprites first, then outward (monotone in
    progress, never larger for a sprite farther out)."""
    core = core_frac < CORE_FRAC
    core_t = core_frac / CORE_FRAC
    edge_t = (core_frac - CORE_FRAC) / (1.0 - CORE_FRAC)
    start = np.where(
        core,
        CORE_START[0] + (CORE_START[1] - CORE_START[0]) * core_t,
        EDGE_START[0] + (EDGE_START[1] - EDGE_START[0]) * edge_t,
    )
    t = np.clip((progress - start) / SPRITE_RAMP, 0.0, 1.0)
    out: F32 = (t * t * (3.0 - 2.0 * t)).astype(np.float32)
    return out


def visible_sprites(block: BlockClouds, cover_oktas: float) -> SpriteBatch:
    """The block's sprites at this cover, each opacity scaled by its formation; sprites that
    do not show at all are dropped so they cost nothing to draw."""
    if cover_oktas >= FULL_OKTAS:
        return block.sprites
    if cover_oktas <= 0.0 or not len(block.sprites):
        return SpriteBatch.empty()
    alpha = sprite_alpha(cloud_progress(block, cover_oktas), block.sprites.core_frac)
    shown = alpha > 0.0
    out = block.sprites.take(shown)
    return dataclasses.replace(out, opacity=(out.opacity * alpha[shown]).astype(np.float32))


def layer_block(
    block_x: int,
    block_y: int,
    layer_key: int,
    layer: CloudLayer,
    seed: int,
    offset_m: tuple[float, float] = (0.0, 0.0),
    models: CloudModels | None = None,
    rain: Rain | None = None,
) -> SpriteBatch:
    """One block of a layer as drawn: the layer's model, its cover applied, z MSL, moved by
    `offset_m` (the layer's drift) in the same single addition. Near a subtype boundary the
    cover is shared between the two models, so one's clouds dissipate as the other's form.
    `rain` (`rain.rain_of`): what falls, for the shafts under the layer types that shed it."""
    blend = (models or default_models()).blend_for_layer(layer.type, layer.thickness_m)
    parts = []
    for model, weight in blend:
        block = block_clouds(block_x, block_y, layer_key, model, layer.thickness_m, seed)
        parts.append(visible_sprites(block, layer.cover_oktas * weight))
    if rain is not None and layer.type in SHAFT_TYPES:
        parts.append(shaft_sprites(SpriteBatch.concat(parts), layer.base_m, rain))
    sprites = SpriteBatch.concat(parts)
    if not len(sprites):
        return sprites
    return sprites.shifted((offset_m[0], offset_m[1], layer.base_m))
