"""Wang's single-sprite LOD for the far part of the near layer: a cloud far from the eye is drawn
as one sprite instead of its tens, which is what keeps the near layer's fill rate affordable
in dense cover ("a single-billboard cloud is merely a degenerate case of the model").

A cloud collapses once its centre is `start_m` from the eye, cross-fading between its sprites
and its one sprite over `band_m` so the change never pops. The one sprite sits at the cloud's
coverage-weighted centre, is as wide as the cloud's dense part, wears a dense texture of the
cloud's kind (puffy, or fog for stratiform decks), and takes the coverage-weighted mean of the
colours its sprites were shaded with, so it is lit as the whole cloud was. Flat (cirrus)
sheets stay as they are: they are few and thin. Pure numpy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wxsky.scene.sprites import F32, SpriteBatch
from wxsky.scene.texture_slots import TEX_FOG, TEX_PUFFY

# The one sprite spans the sprites' centres (RMS spread, both sides) plus one mean sprite,
# shrunk a little: a soft texture's visible part is smaller than its quad.
SPREAD_SIGMAS = 2.0
SIZE_GAIN = 0.85


@dataclass(frozen=True)
class Collapsed:
    """The draw with far clouds replaced, as parallel arrays in no particular order."""

    sprites: SpriteBatch
    rgba: F32  # (N, 4) straight alpha
    lod_clouds: int  # clouds drawn as one sprite (fully or in the cross-fade)


def collapse_far_clouds(
    sprites: SpriteBatch,
    rgba: F32,
    eye_m: tuple[float, float, float],
    start_m: float,
    band_m: float,
) -> Collapsed:
    """Replace each non-flat cloud whose centre is beyond start_m from the eye by one sprite;
    within band_m beyond start_m both are drawn, the sprites fading out as the one fades in."""
    n = len(sprites)
    if n == 0 or start_m <= 0.0:
        return Collapsed(sprites, rgba, 0)
    ids, inverse = np.unique(sprites.cloud_id, return_inverse=True)
    # Coverage weight of each sprite: its alpha times its area.
    size = sprites.size_m.astype(np.float64)
    w = rgba[:, 3].astype(np.float64) * size * size + 1e-9
    wsum = np.bincount(inverse, w)
    centre = np.stack(
        [np.bincount(inverse, w * sprites.centre_m[:, k]) / wsum for k in range(3)], axis=1
    )  # (C, 3)
    dist = np.linalg.norm(centre - np.asarray(eye_m, np.float64), axis=1)  # (C,)
    flat = np.bincount(inverse, sprites.flat.astype(np.float64)) > 0
    t = np.clip((dist - start_m) / max(band_m, 1e-6), 0.0, 1.0)
    t = t * t * (3.0 - 2.0 * t)
    t[flat] = 0.0  # (C,) 0: all sprites, 1: the one sprite
    if not (t > 0.0).any():
        return Collapsed(sprites, rgba, 0)
    keep = t[inverse] < 1.0
    full_rgba = rgba.copy()
    full_rgba[:, 3] *= (1.0 - t[inverse]).astype(np.float32)
    lod = np.flatnonzero(t > 0.0)  # clouds with a one-sprite version
    count = np.bincount(inverse, minlength=len(ids))
    rel = sprites.centre_m - centre[inverse]
    spread = np.sqrt(np.bincount(inverse, w * np.sum(rel * rel, axis=1)) / wsum)  # (C,)
    mean_size = np.bincount(inverse, size) / np.maximum(count, 1)
    first = np.zeros(len(ids), np.intp)
    first[inverse[::-1]] = np.arange(n)[::-1]  # the cloud's first sprite, for its attributes
    # Every colour column (the rim's too, where the draw has one: SpriteDraw.rgba), by
    # coverage; alpha (column 3) is the cloud's densest sprite's.
    colour = np.stack(
        [np.bincount(inverse, w * rgba[:, k]) / wsum for k in range(rgba.shape[1])], axis=1
    )  # (C, K)
    alpha = np.zeros(len(ids))
    np.maximum.at(alpha, inverse, rgba[:, 3].astype(np.float64))
    slab = sprites.slab[first[lod]]
    one = SpriteBatch(
        centre_m=centre[lod],
        size_m=(SIZE_GAIN * (SPREAD_SIGMAS * spread[lod] + mean_size[lod])).astype(np.float32),
        rotation_rad=np.zeros(len(lod), np.float32),
        texture=np.where(
            slab, TEX_FOG[0], np.asarray(TEX_PUFFY, np.int32)[ids[lod] % len(TEX_PUFFY)]
        ).astype(np.int32),
        height_frac=np.full(len(lod), 0.5, np.float32),
        light_dir=sprites.light_dir[first[lod]],
        opacity=sprites.opacity[first[lod]],
        darkness=sprites.darkness[first[lod]],
        cloud_id=ids[lod],
        core_frac=np.zeros(len(lod), np.float32),
        flat=np.zeros(len(lod), np.bool_),
        slab_m=sprites.slab_m[first[lod]],
        base_m=sprites.base_m[first[lod]],
        drift_m=sprites.drift_m[first[lod]],
    )
    one_rgba = colour[lod]
    one_rgba[:, 3] = alpha[lod] * t[lod]
    return Collapsed(
        SpriteBatch.concat([sprites.take(keep), one]),
        np.concatenate([full_rgba[keep], one_rgba.astype(np.float32)]),
        len(lod),
    )
