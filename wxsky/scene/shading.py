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

import numpy as np

from wxsky.scene.shading_harris import (
    ParticleLight,
    Scattered,
    close_directions,
    harris_colours,
    harris_rgba,
    particle_light,
    scene_lights,
)
from wxsky.scene.shading_slab import slab_rgba
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
        return slab_rgba(batch.centre_m, batch.slab_m, batch.opacity, sky, eye_m, dist_m)
    if not slab.any():
        if model == "harris":
            return harris_colours(batch, sky, eye_m, light, scattered, dist_m)
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
        # half reads are cut, not every field of the batch (which was a third of the stage).
        out[particle] = harris_rgba(
            batch.centre_m[particle],
            batch.opacity[particle],
            scattered.rows[particle],
            lights,
            eye_m,
            None if dist_m is None else dist_m[particle],
        )
    else:
        particles = batch.take(particle)
        if model == "harris":
            if scattered is not None:
                scattered = scattered.take(particle)
            out[particle] = harris_colours(
                particles,
                sky,
                eye_m,
                light,
                scattered,
                None if dist_m is None else dist_m[particle],
            )
        else:
            out[particle] = wang_colours(particles, sky)
    out[slab] = slab_rgba(
        batch.centre_m[slab],
        batch.slab_m[slab],
        batch.opacity[slab],
        sky,
        eye_m,
        None if dist_m is None else dist_m[slab],
    )
    return out


def _check(model: str) -> None:
    if model not in SHADING_MODELS:
        raise ValueError(f"shading must be one of {', '.join(SHADING_MODELS)}, got {model!r}")
