"""A tower volume lit as the sprite clouds are (issue 17, item 3): the light reaching every cell
from the sun (or moon) and the four skylights and zenith of Harris's model, by slice lighting
(`towers.lighting`), spread by the same multiple-scattering octaves, then scattered toward
the eye with the same phase functions (the key light's beam through the droplets' forward
peak, the multiply scattered light through the diffuse one) and exposed the same way. So a
tower beside a sprite cumulus has the same silver lining toward the sun, the same grey base
and the same blue-grey shadow side."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from wxsky.scene.scattering import ALBEDO, cloud_phase, diffuse_phase
from wxsky.scene.shading_harris import (
    DIFFUSE_SHARE,
    exposed,
    multiple_scattering,
    scene_lights,
    shown_channels,
)
from wxsky.scene.sky import SkyParams
from wxsky.towers.lighting import EXTINCTION_PER_CELL, slice_light

F32 = npt.NDArray[np.float32]


def tower_light(density: F32, sky: SkyParams, extinction: float = EXTINCTION_PER_CELL) -> F32:
    """(nz, ny, nx, L + 1) light 0..1 reaching every cell of `density` (z up, x east, y north)
    from each of the sky's L lights (`scene_lights`), multiple scattering included, then the
    key light's beam alone: what does not depend on the eye, worked out once per volume and
    sky (the renderer keeps it in textures and scatters it toward the eye per view,
    `view_weights`). `extinction`: per cell at density 1 (`TowerSpec.extinction_per_cell`)."""
    lights = scene_lights(sky)
    reach = np.stack(
        [
            slice_light(density, (float(x), float(y), float(z)), extinction)
            for x, y, z in lights.directions
        ],
        axis=-1,
    )
    reach = reach.astype(np.float32)
    out: F32 = np.concatenate([multiple_scattering(reach), reach[..., :1]], axis=-1)
    return out


def view_weights(
    sky: SkyParams, view_dir: tuple[float, float, float], alt_m: float | None = None
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """(L + 1, 3) what each channel of `tower_light` adds to the radiance toward an eye looking
    along `view_dir` (phase and albedo times the light's colour; the phase angle is the same in
    every cell for a distant eye), as `shading_harris.harris_radiance` weighs them, and (3,)
    the ambient radiance (with the ground's light at a tower's middle height). `alt_m`: the
    tower's middle height (MSL), where the physical atmosphere's sun and sky are taken."""
    lights = scene_lights(sky, alt_m=alt_m)
    view = np.asarray(view_dir, np.float64)
    view = view / np.linalg.norm(view)
    cos = lights.directions @ view
    rgb = np.asarray(lights.rgb, np.float64)
    phase = diffuse_phase(cos)
    phase[0] *= DIFFUSE_SHARE
    beam = (1.0 - DIFFUSE_SHARE) * cloud_phase(float(cos[0])) * rgb[:1]
    weights = ALBEDO * np.concatenate([phase[:, None] * rgb, beam], axis=0)
    ambient = np.asarray(lights.ambient_rgb, np.float64) + 0.5 * lights.ground_rgb
    return weights, ambient


def tower_colours(density: F32, sky: SkyParams, view_dir: tuple[float, float, float]) -> F32:
    """(nz, ny, nx, 3) display colour 0..1 of every cell of `density` (z up, x east, y north),
    seen along `view_dir` (the direction from the eye into the volume; a distant eye)."""
    weights, ambient = view_weights(sky, view_dir)
    return colours_of(tower_light(density, sky), weights, ambient, sky)


def colours_of(
    light: F32,
    weights: npt.NDArray[np.float64],
    ambient: npt.NDArray[np.float64],
    sky: SkyParams | None = None,
) -> F32:
    """(..., 3) display colour of cells with `light` (..., L) reaching them (`tower_light`)
    for `view_weights`: the same sum and exposure the tower shader does (under `sky`'s
    display curve, `shown_channels`; None: Harris's)."""
    radiance = light @ weights + ambient
    shape = radiance.shape
    flat = radiance.reshape(-1, 3)
    shown = exposed(flat) if sky is None else shown_channels(flat.T, sky).T
    out: F32 = shown.reshape(shape).astype(np.float32)
    return out
