"""Wang's artist shading: colour levels by height in the cloud, time-of-day ambient, and a
directional term per shading group. No scattering is simulated (Wang, "Every Cloud Has a
Silver Lining")."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from wxsky.scene.clouds import SpriteBatch
from wxsky.scene.sky import SkyParams

# Five colour levels from the cloud's base (0) to its top (1): darker bottoms.
LEVEL_HEIGHTS = np.array([0.0, 0.2, 0.45, 0.75, 1.0])
LEVEL_RGB = np.array(
    [
        [0.50, 0.53, 0.60],
        [0.62, 0.65, 0.71],
        [0.76, 0.78, 0.82],
        [0.86, 0.87, 0.90],
        [0.93, 0.93, 0.95],
    ]
)
DIRECTIONAL_MIN, DIRECTIONAL_MAX = 0.05, 0.45


def sprite_colours(batch: SpriteBatch, sky: SkyParams) -> npt.NDArray[np.float32]:
    """(N, 4) straight-alpha RGBA for each sprite."""
    level = np.stack(
        [np.interp(batch.height_frac, LEVEL_HEIGHTS, LEVEL_RGB[:, c]) for c in range(3)], axis=1
    )
    # Grey cloud types pull the lower levels down more than the tops.
    grey = 1.0 - batch.darkness[:, None] * 0.55 * (1.0 - 0.6 * batch.height_frac[:, None])
    ambient = level * grey * sky.ambient
    sun = np.asarray(sky.sun.direction_enu)
    facing = np.clip(batch.light_dir @ sun, -1.0, 1.0)
    amount = DIRECTIONAL_MIN + (DIRECTIONAL_MAX - DIRECTIONAL_MIN) * (0.5 + 0.5 * facing)
    directional = amount[:, None] * np.asarray(sky.sun_rgb)[None, :]
    rgb = np.clip(ambient + directional * (1.0 - 0.5 * batch.darkness[:, None]), 0.0, 1.0)
    return np.concatenate([rgb, batch.opacity[:, None]], axis=1).astype(np.float32)
