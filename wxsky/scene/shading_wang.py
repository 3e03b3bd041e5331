"""Wang's shading ("Every Cloud Has a Silver Lining"), two ways: `wang_colours`, his artist
model (`[scene] shading = "wang-artist"`): five colour levels by height in the cloud, an
ambient percentage by time of day, and a directional term from the dot product of the
sprite's shading-group direction with the sun; no light is scattered or shadowed, the
artist's levels stand in for the darker bottoms that scattering would give. And
`wang_radiance` (`"wang"`): his shading groups under the physical light every model shares
(`shading_harris.harris_radiance`), the light reaching a group estimated from its direction.
"""

from __future__ import annotations

import numpy as np

from wxsky.scene.shading_harris import DARK_TAU, Lights, harris_radiance, view_depth
from wxsky.scene.sky import SkyParams
from wxsky.scene.sprites import F32, F64, SpriteBatch

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
# The artist's percentages by time of day, keyed by sun elevation (degrees) and interpolated:
# night (moonlight and airglow keep clouds from going black), dawn/dusk, day.
AMBIENT_BY_SUN_EL = ((-18.0, 0.12), (-8.0, 0.15), (0.0, 0.42), (8.0, 0.8), (20.0, 1.0))
# (elevation, min, max) of the directional percentage; strongest at dawn and dusk, when the
# low sun sculpts the clouds.
DIRECTIONAL_BY_SUN_EL = (
    (-4.0, 0.0, 0.0),
    (0.0, 0.12, 0.75),
    (6.0, 0.08, 0.62),
    (20.0, 0.05, 0.45),
)
# How much of the sunset-red horizon colour tints the ambient levels at the height of sunset.
SUNSET_TINT_SHARE = 0.75
GREY_BASE = 0.55  # how far a grey type's darkness pulls down its lowest level
GREY_DIRECTIONAL = 0.5  # and how much of the sun a grey type's sprites take


def wang_colours(batch: SpriteBatch, sky: SkyParams) -> F32:
    """(N, 4) straight-alpha RGBA for each sprite; the same from any eye."""
    el = sky.sun.elevation_deg
    level = np.stack(
        [np.interp(batch.height_frac, LEVEL_HEIGHTS, LEVEL_RGB[:, c]) for c in range(3)], axis=1
    )  # (N, 3)
    grey = 1.0 - batch.darkness[:, None] * GREY_BASE * (1.0 - 0.6 * batch.height_frac[:, None])
    ambient = level * grey * _table(AMBIENT_BY_SUN_EL, el)[0] * sunset_tint(sky)  # (N, 3)
    sun = np.asarray(sky.sun.direction_enu)
    facing = np.clip(batch.light_dir @ sun, -1.0, 1.0)  # (N,)
    lo, hi = _table(DIRECTIONAL_BY_SUN_EL, el)
    amount = lo + (hi - lo) * (0.5 + 0.5 * facing)
    directional = amount[:, None] * np.asarray(sky.sun_rgb)[None, :]  # (N, 3)
    directional *= 1.0 - GREY_DIRECTIONAL * batch.darkness[:, None]
    rgb = np.clip(ambient + directional, 0.0, 1.0)
    return np.concatenate([rgb, batch.opacity[:, None]], axis=1).astype(np.float32)


def sunset_tint(sky: SkyParams) -> F64:
    """(3,) multiplier of the ambient levels: white by day and night, the horizon's red
    gradient (as the sky pass draws it, brightest channel 1) at sunset."""
    horizon = np.asarray(sky.horizon_rgb, np.float64)
    red = horizon / max(float(horizon.max()), 1e-6)
    out: F64 = 1.0 + (red - 1.0) * SUNSET_TINT_SHARE * sky.sunset
    return out


def _table(rows: tuple[tuple[float, ...], ...], el_deg: float) -> tuple[float, ...]:
    """The row values at this sun elevation, linear between rows, held beyond the ends."""
    keys = [r[0] for r in rows]
    columns = range(1, len(rows[0]))
    return tuple(float(np.interp(el_deg, keys, [r[i] for r in rows])) for i in columns)


# Optical depth from a cloud's face toward a light straight through it to the far side, for
# Wang's shading groups under the physical light (`wang_radiance`): a group facing the light
# has none before it, one facing away has the whole cloud (a fair cumulus: tens; its
# multiply scattered light, not the beam, is what reaches there).
WANG_CLOUD_TAU = 6.0


def wang_radiance(
    batch: SpriteBatch,
    lights: Lights,
    view: F64,
    balls: F32 | None = None,
    key_rgb: F64 | None = None,
) -> F64:
    """(3, N) radiance toward the eye along `view` ((3, N), `view_rays`) under the physical
    light (the same phase functions, ambient and ground light as Harris's particles): Wang
    has no particle pass, so the beam reaching a sprite is estimated from its shading group's
    direction from the cloud's centre (`light_dir`) against each light's: exp(-tau (1 - cos)
    / 2), tau the cloud's depth, thicker for grey types and thinner for forming clouds.
    `balls`: the sprites' places in their whole clouds (`view_depth`); `key_rgb`: (N, 3) the
    key light at each sprite's altitude (`harris_radiance`)."""
    facing = batch.light_dir.astype(np.float64) @ lights.directions.T  # (N, L)
    tau = WANG_CLOUD_TAU * batch.opacity * (1.0 + DARK_TAU * batch.darkness)
    beam = np.exp(-(0.5 * tau)[:, None] * (1.0 - facing)).astype(np.float32)
    depth = view_depth(batch, view, balls)
    return harris_radiance(view, beam, lights, batch.height_frac, depth, key_rgb)
