"""A tower volume lit as the sprite clouds are (issue 17, item 3): the light reaching every cell
from the sun (or moon) and the four skylights and zenith of Harris's model, by slice lighting
(`towers.lighting`), spread by the same multiple-scattering octaves, then scattered toward
the eye with the same phase function and exposed the same way. So a tower beside a sprite
cumulus has the same silver lining toward the sun, the same grey base and the same blue-grey
shadow side."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from wxsky.scene.scattering import ALBEDO, HG_G, hg_phase
from wxsky.scene.shading_harris import (
    DIFFUSE_SHARE,
    exposed,
    multiple_scattering,
    scene_lights,
)
from wxsky.scene.sky import SkyParams
from wxsky.towers.lighting import slice_light

F32 = npt.NDArray[np.float32]


def tower_colours(density: F32, sky: SkyParams, view_dir: tuple[float, float, float]) -> F32:
    """(nz, ny, nx, 3) display colour 0..1 of every cell of `density` (z up, x east, y north),
    seen along `view_dir` (the direction from the eye into the volume; a distant eye)."""
    lights = scene_lights(sky)
    # The light reaching each cell from each of the model's lights: (L, nz, ny, nx).
    reach = np.stack(
        [slice_light(density, (float(x), float(y), float(z))) for x, y, z in lights.directions]
    )
    incident = multiple_scattering(np.moveaxis(reach, 0, -1).astype(np.float32))  # (..., L)
    view = np.asarray(view_dir, np.float64)
    view = view / np.linalg.norm(view)
    cos = lights.directions @ view  # (L,): the phase angle is the same in every cell
    phase = (1.0 - DIFFUSE_SHARE) * 4.0 * np.pi * hg_phase(cos, HG_G) + DIFFUSE_SHARE
    radiance = ALBEDO * ((incident * phase) @ lights.rgb) + lights.ambient_rgb
    shape = radiance.shape
    out: F32 = exposed(radiance.reshape(-1, 3)).reshape(shape).astype(np.float32)
    return out
