"""Cloud shading, by model: Wang's artist model (`shading_wang`) or Harris's multiple forward
scattering (`shading_harris`, `scattering`). Both light every sprite from dawn to night from
the same SkyParams; `[scene] shading` picks one. Sprites of stratiform layers (`slab` models)
are shaded as Bouthors' plane-parallel slab (`shading_slab`) under either: a deck is one sheet
of cloud, and shading its sprites one by one paints it as a field of lit balls.

Harris's model has an eye-independent part (the light reaching each particle) that the ring
computes once for all its far sprites (`prepare_lighting`), before they are cut into the eight
impostor bins, so a cloud straddling two impostors is shaded as one cloud in both.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from wxsky.scene.shading_harris import (
    ParticleLight,
    Scattered,
    close_directions,
    harris_colours,
    harris_rgba,
    particle_light,
    scene_lights,
)
from wxsky.scene.shading_slab import slab_colours, slab_rgba
from wxsky.scene.shading_wang import wang_colours
from wxsky.scene.sky import SkyParams
from wxsky.scene.sprites import F32, F64, SpriteBatch

SHADING_MODELS = ("wang", "harris")
# Harris by default: self-shadowed cumulus with grey bases and silver-lined rims, at a few
# milliseconds a frame for the near sprites (none while the sun stands still; see
# shading_harris's cache); "wang" is the lighter fallback.
DEFAULT_SHADING = "harris"

__all__ = [
    "DEFAULT_SHADING",
    "SHADING_MODELS",
    "ParticleLight",
    "Scattered",
    "prepare_lighting",
    "sprite_colours",
]


def prepare_lighting(batch: SpriteBatch, sky: SkyParams, model: str) -> ParticleLight | None:
    """The model's eye-independent precompute for the batch's particles (None for Wang, who
    has none; slab sprites need none)."""
    _check(model)
    if model != "harris":
        return None
    slab = batch.slab
    return particle_light(batch.take(~slab) if slab.any() else batch, scene_lights(sky))


def sprite_colours(
    batch: SpriteBatch,
    sky: SkyParams,
    eye_m: tuple[float, float, float],
    model: str = DEFAULT_SHADING,
    light: ParticleLight | None = None,
    scattered: Scattered | None = None,
    dist_m: F64 | None = None,
) -> F32:
    """(N, 4) straight-alpha RGBA for each sprite seen from eye_m. `light` is a precompute
    from `prepare_lighting` over these sprites or a batch holding them; `scattered`, for
    Harris, `shading_harris.scattered_light` of these sprites' particles, a row per sprite
    (slab sprites' rows unused); `dist_m`, (N,) each sprite's distance from eye_m where the
    caller has it (a frame's near layer)."""
    _check(model)
    slab = batch.slab
    if slab.all() and len(batch):
        return slab_colours(batch, sky, eye_m)
    if not slab.any():
        if model == "harris":
            return harris_colours(batch, sky, eye_m, light, scattered)
        return wang_colours(batch, sky)
    out = np.empty((len(batch), 4), np.float32)
    particle = ~slab
    lights = scene_lights(sky) if model == "harris" else None
    if (
        lights is not None
        and scattered is not None
        and close_directions(scattered.directions, lights.directions)
    ):
        # A frame's near layer: the light is known, and only the arrays the eye-dependent
        # half reads are cut, not every field of the batch (which was a third of the stage);
        # the set's sprites are cut the same way frame after frame, so the cut is kept.
        split = _split_of(batch, scattered)
        p_dist = None if dist_m is None else dist_m[split.particle]
        s_dist = None if dist_m is None else dist_m[split.slab]
        out[split.particle] = harris_rgba(
            batch.centre_m[split.particle],
            split.particle_opacity,
            split.rows,
            lights,
            eye_m,
            p_dist,
        )
        out[split.slab] = slab_rgba(
            batch.centre_m[split.slab], split.slab_m, split.slab_opacity, sky, eye_m, s_dist
        )
        return out
    particles = batch.take(particle)
    if model == "harris":
        if scattered is not None:
            scattered = scattered.take(particle)
        out[particle] = harris_colours(particles, sky, eye_m, light, scattered)
    else:
        out[particle] = wang_colours(particles, sky)
    out[slab] = slab_rgba(batch.centre_m[slab], batch.slab_m[slab], batch.opacity[slab], sky, eye_m)
    return out


@dataclass(frozen=True)
class _Split:
    """A mixed batch's particle and slab sprites, as indices, and the eye-independent arrays
    each model reads of them. The near layer shades the sprites of one set, with one
    Scattered light, frame after frame, in the set's order; only their centres move."""

    slab_m_of: F32  # the batch's arrays it was cut from (kept to be compared by identity)
    opacity_of: F32
    rows_of: F32
    particle: npt.NDArray[np.intp]
    slab: npt.NDArray[np.intp]
    particle_opacity: F32
    rows: F32
    slab_m: F32
    slab_opacity: F32


_SPLITS = 4  # a frame's set, and those of a cross-fade
_splits: OrderedDict[tuple[int, int, int], _Split] = OrderedDict()
_splits_lock = threading.Lock()


def _split_of(batch: SpriteBatch, scattered: Scattered) -> _Split:
    key = (id(batch.slab_m), id(batch.opacity), id(scattered.rows))
    with _splits_lock:
        found = _splits.get(key)
    if (
        found is not None
        and found.slab_m_of is batch.slab_m
        and found.opacity_of is batch.opacity
        and found.rows_of is scattered.rows
    ):
        return found
    slab = batch.slab
    particle, slabs = np.flatnonzero(~slab), np.flatnonzero(slab)
    made = _Split(
        slab_m_of=batch.slab_m,
        opacity_of=batch.opacity,
        rows_of=scattered.rows,
        particle=particle,
        slab=slabs,
        particle_opacity=batch.opacity[particle],
        rows=scattered.rows[particle],
        slab_m=batch.slab_m[slabs],
        slab_opacity=batch.opacity[slabs],
    )
    with _splits_lock:
        _splits[key] = made
        while len(_splits) > _SPLITS:
            _splits.popitem(last=False)
    return made


def _check(model: str) -> None:
    if model not in SHADING_MODELS:
        raise ValueError(f"shading must be one of {', '.join(SHADING_MODELS)}, got {model!r}")
