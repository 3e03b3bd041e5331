"""Cloud shading, by model: Harris's multiple forward scattering (`shading_harris`,
`scattering`), Wang's shading groups under the same physical light (`shading_wang`,
"wang"), or Wang's artist colours ("wang-artist"). All light every sprite from dawn to night
from the same SkyParams (through `cloud_light.cloud_lights`, except the artist's levels);
`[scene] shading` picks one. Sprites of stratiform layers (`slab` models)
are shaded as Bouthors' plane-parallel slab (`shading_slab`) under either: a deck is one sheet
of cloud, and shading its sprites one by one paints it as a field of lit balls.

Harris's model has an eye-independent part (the light reaching each particle) that the ring
computes once for all its far sprites (`prepare_lighting`), before they are cut into the eight
impostor bins, so a cloud straddling two impostors is shaded as one cloud in both.
"""

from __future__ import annotations

import numpy as np

from wxsky.scene.cloud_light import key_rgb_at
from wxsky.scene.shading_harris import (
    BALL_COLUMNS,
    Lights,
    ParticleLight,
    Scattered,
    close_directions,
    harris_incident,
    harris_radiance,
    harris_radiance_and_rim,
    particle_light,
    scene_lights,
    shown_channels,
    view_depth,
    view_depth_and_limb,
    view_rays,
    with_alpha,
)
from wxsky.scene.shading_slab import slab_view_radiance
from wxsky.scene.shading_wang import wang_colours, wang_radiance
from wxsky.scene.sky import SkyParams, deck_sun_share
from wxsky.scene.sprites import F32, F64, SpriteBatch

SHADING_MODELS = ("wang", "harris", "wang-artist")
# Harris by default: self-shadowed cumulus with grey bases, dark against a low sun with
# silver-lined rims, at a few milliseconds a frame for the near sprites (none while the sun
# stands still; see shading_harris's cache); "wang" is the lighter fallback under the same
# light, "wang-artist" Wang's own colour levels, the same from every side of the sun.
DEFAULT_SHADING = "harris"

__all__ = [
    "DEFAULT_SHADING",
    "SHADING_MODELS",
    "ParticleLight",
    "Scattered",
    "display_colours",
    "display_colours_and_rim",
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
    return with_alpha(
        display_colours(batch, sky, eye_m, model, light, scattered, dist_m), batch.opacity
    )


def display_colours(
    batch: SpriteBatch,
    sky: SkyParams,
    eye_m: tuple[float, float, float],
    model: str = DEFAULT_SHADING,
    light: ParticleLight | None = None,
    scattered: Scattered | None = None,
    dist_m: F64 | None = None,
    balls: F32 | None = None,
) -> F64 | F32:
    """`sprite_colours`' colours without their alpha, channel by channel: (3, N). `balls`:
    for Wang, (N, BALL_COLUMNS) each sprite's place in its whole cloud (`batch_balls` of a
    batch holding the clouds whole; None: of these sprites' clouds as they are here)."""
    return _colours(batch, sky, eye_m, model, light, scattered, dist_m, balls, False)[0]


def display_colours_and_rim(
    batch: SpriteBatch,
    sky: SkyParams,
    eye_m: tuple[float, float, float],
    model: str = DEFAULT_SHADING,
    light: ParticleLight | None = None,
    scattered: Scattered | None = None,
    dist_m: F64 | None = None,
    balls: F32 | None = None,
) -> tuple[F64 | F32, F64 | None]:
    """`display_colours`, and (3, N) the display colour of each sprite's thin outer texels
    (`shading_harris.harris_radiance_and_rim`: the silver lining), or None where the model
    has no rim of its own: Wang's, and Harris's under the gradient sky (whose look the golden
    images hold). Slab sprites' rim is their colour."""
    return _colours(batch, sky, eye_m, model, light, scattered, dist_m, balls, True)


def _depth_and_limb(
    batch: SpriteBatch,
    view: F64,
    incident: F32,
    sky: SkyParams,
    lights: Lights,
) -> tuple[F64, F64 | None]:
    """`view_depth_and_limb` from the light's precompute; the fringe's light only under the
    physical sky (the gradient sky's Harris is the look the golden images hold)."""
    balls = incident[:, -BALL_COLUMNS:]
    if sky.atmosphere is None:
        return view_depth(batch, view, balls), None
    return view_depth_and_limb(batch, view, balls, lights.directions[0])


def _key_at(sky: SkyParams, alt_m: F64, eye_alt_m: float) -> F64 | None:
    """`key_rgb_at`, less what a deck's other cells take off it (`deck_sun_share`)."""
    key = key_rgb_at(sky, alt_m)
    if key is None:
        return None
    share = deck_sun_share(sky, eye_alt_m)
    return key if share >= 1.0 else key * share


def _colours(
    batch: SpriteBatch,
    sky: SkyParams,
    eye_m: tuple[float, float, float],
    model: str,
    light: ParticleLight | None,
    scattered: Scattered | None,
    dist_m: F64 | None,
    balls: F32 | None,
    want_rim: bool,
) -> tuple[F64 | F32, F64 | None]:
    _check(model)
    want_rim = want_rim and model == "harris" and sky.atmosphere is not None
    n = len(batch)
    if n == 0:
        return np.zeros((3, 0)), (np.zeros((3, 0)) if want_rim else None)
    slab = batch.slab
    slabs = int(np.count_nonzero(slab))
    if slabs == 0 and model == "wang-artist":
        out: F32 = wang_colours(batch, sky)[:, :3].T
        return out, None
    # The view rays once for all sprites, and one exposure over the sprites' radiance: each
    # column is what shading the slab and particle sprites apart gives, at half the calls.
    view = view_rays(batch.centre_m, eye_m, dist_m)
    if slabs == n:
        shown = shown_channels(
            slab_view_radiance(batch.centre_m[:, 2], batch.slab_m, view, sky, eye_m[2]),
            sky,
        )
        return shown, (shown if want_rim else None)
    if slabs == 0:
        lights = scene_lights(sky, alt_m=_middle_m(batch))
        key = _key_at(sky, batch.centre_m[:, 2], eye_m[2])
        if model == "wang":
            return shown_channels(wang_radiance(batch, lights, view, balls, key), sky), None
        incident = harris_incident(batch, lights, light, scattered)
        depth, limb = _depth_and_limb(batch, view, incident, sky, lights)
        if want_rim:
            body, rim = harris_radiance_and_rim(
                view, incident, lights, batch.height_frac, depth, key, limb
            )
            return _shown_pair(body, rim, sky)
        return shown_channels(
            harris_radiance(view, incident, lights, batch.height_frac, depth, key, limb),
            sky,
        ), None
    # Columns by index (ndarray.take), not by mask: a fifth of the time.
    particle, slabs_at = np.flatnonzero(~slab), np.flatnonzero(slab)
    slab_radiance = slab_view_radiance(
        batch.centre_m[:, 2].take(slabs_at),
        batch.slab_m.take(slabs_at, axis=0),
        view.take(slabs_at, axis=1),
        sky,
        eye_m[2],
    )
    if model == "wang-artist":
        mixed = np.empty((3, n))
        mixed[:, slabs_at] = shown_channels(slab_radiance, sky)
        mixed[:, particle] = wang_colours(batch.take(particle), sky)[:, :3].T
        return mixed, None
    particle_z = batch.centre_m[:, 2].take(particle)
    lights = scene_lights(sky, alt_m=_middle_m(batch, particle_z))
    key = _key_at(sky, particle_z, eye_m[2])
    radiance = np.empty((3, n))
    radiance[:, slabs_at] = slab_radiance
    if model == "wang":
        radiance[:, particle] = wang_radiance(
            batch.take(particle),
            lights,
            view.take(particle, axis=1),
            None if balls is None else balls.take(particle, axis=0),
            key,
        )
        return shown_channels(radiance, sky), None
    if scattered is not None and close_directions(scattered.directions, lights.directions):
        # A frame's near layer: the light is known, and only the arrays the eye-dependent
        # half reads are cut, not every field of the batch (which was a third of the stage).
        incident = scattered.rows.take(particle, axis=0)
    else:
        incident = harris_incident(
            batch.take(particle),
            lights,
            light,
            None if scattered is None else scattered.take(particle),
        )
    particles = batch.take(particle)
    particle_view = view.take(particle, axis=1)
    depth, limb = _depth_and_limb(particles, particle_view, incident, sky, lights)
    if not want_rim:
        radiance[:, particle] = harris_radiance(
            particle_view, incident, lights, particles.height_frac, depth, key, limb
        )
        return shown_channels(radiance, sky), None
    rim_radiance = radiance.copy()
    body, rim = harris_radiance_and_rim(
        particle_view, incident, lights, particles.height_frac, depth, key, limb
    )
    radiance[:, particle] = body
    rim_radiance[:, particle] = rim
    return _shown_pair(radiance, rim_radiance, sky)


def _shown_pair(body: F64, rim: F64, sky: SkyParams) -> tuple[F64, F64]:
    """`shown_channels` of the bodies and the rims ((3, N) each) in one call: the tone map's
    fixed cost a frame is most of its cost on a few hundred sprites."""
    both = shown_channels(np.concatenate([body, rim], axis=1), sky)
    n = body.shape[1]
    return both[:, :n], both[:, n:]


def _middle_m(batch: SpriteBatch, z_m: F64 | None = None) -> float | None:
    """The sprites' middle height (MSL): the altitude their sky and ground light is taken at
    (the key light is taken at each sprite's own, `key_rgb_at`): their median, by partition
    (np.median's checks cost more than the partition on a frame's sprites)."""
    z = batch.centre_m[:, 2] if z_m is None else z_m
    n = len(z)
    if n == 0:
        return None
    k = n // 2
    if n % 2:
        return float(np.partition(z, k)[k])
    part = np.partition(z, (k - 1, k))
    return float(0.5 * (part[k - 1] + part[k]))


def _check(model: str) -> None:
    if model not in SHADING_MODELS:
        raise ValueError(f"shading must be one of {', '.join(SHADING_MODELS)}, got {model!r}")
