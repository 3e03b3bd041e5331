"""The light falling on clouds, as one small set of inputs every cloud shading model reads
(Harris's particles, Wang's shading groups, Bouthors' slab and the tower volumes): the key
light (the sun, or the moon at night) at the clouds, the sky above them and the ground below.

`cloud_lights` is the one place these are filled. With the physical atmosphere (`[scene] sky =
"physical"`, `SkyParams.atmosphere` set) they come from its tables at the clouds' altitude: the
key light is the sun's light transmitted down to that altitude (`atmosphere.sun_irradiance`:
tops reddened before bases at sunset, a deck's top still sunlit while the ground is in
twilight), the sky above and the ground below the sky's irradiance there on a surface facing up
and down (`atmosphere.sky_irradiance`: the ground's part is its albedo times the sun and sky on
it). With Roden & Parberry's gradient (`sky = "roden-parberry"`) they come from its colours.

Units: the cloud models' radiance units, in which a white Lambertian surface facing the key
light is `key_rgb` (under the gradient sky the noon sun's is about 1). The atmosphere's klx
become these units by ONE factor, `cloud_units_per_klx`: the sky pass's exposure
(`atmosphere.display_exposure`, the `u_sky_scale` the sky shader multiplies its kcd/m^2 by)
over pi (a white Lambertian surface under E klx has a radiance of E / pi kcd/m^2). The clouds'
radiance is so already exposed as the sky's is, and goes through the same tone map
(`shading_harris.shown_channels`, `exposure.display`): one exposure and one curve for the sky,
the clouds and the ground, so a cloud as bright as the sky behind it shows as that sky does.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from wxsky.scene.atmosphere import (
    AtmosphereLuts,
    moon_irradiance,
    sky_irradiance,
    sun_irradiance,
)
from wxsky.scene.sky import SkyParams, scene_exposure, smoothstep

F64 = npt.NDArray[np.float64]

RGB = tuple[float, float, float]
Vec3 = tuple[float, float, float]

MOON_TAKES_OVER_DEG = -3.0  # sun elevation below which the moon is the key light
MOONLIGHT_GAIN = 0.12  # moonlight on clouds, per the sky pass's moon colour, at full moon
# Sky colour as it lights a cloud: light scattered many times inside the cloud mixes sky and
# sun, so the blue of the sky tints shadow sides less than it colours the sky.
SKY_SATURATION = 0.5
# The ground under the clouds: fields, woods and towns reflect this share of the light on them
# (Bouthors' ground albedo for the slab, the same here).
GROUND_ALBEDO = 0.15
# The skylight on the ground, in the units of key_rgb, per unit of the sky's mean colour: a
# clear noon sky gives the ground about a fifth of the sun's light.
SKY_ON_GROUND = 0.35
# Where a caller gives no altitude: a cloud this far above the ground (a fair-weather
# cumulus's middle). Callers that know their layer pass its altitude.
DEFAULT_CLOUD_AGL_M = 1_500.0
# Of the ground's light (sky_irradiance below), the share that is the direct sun on it, which
# a deck shades: the ground under full cover gets the sky's light only.
SUN_SHARE_ON_GROUND = 0.8


@dataclass(frozen=True)
class CloudLights:
    """What lights the clouds at their altitude."""

    key_dir: Vec3  # unit vector (ENU) toward the key light: the sun, or the moon at night
    key_rgb: RGB  # the key light's colour and strength reaching the clouds
    sky_zenith_rgb: RGB  # the sky overhead as it lights a cloud (greyed, see SKY_SATURATION)
    sky_horizon_rgb: RGB  # and the sky near the horizon
    ground_rgb: RGB  # light from the ground below, onto a cloud's base (radiance units)


def cloud_lights(
    sky: SkyParams, above_cloud: bool = False, alt_m: float | None = None
) -> CloudLights:
    """The clouds' lights for this sky; `above_cloud`: with the open sky over every layer (what
    lights the top of a deck) instead of the sky the eye sees under the cloud. `alt_m` (MSL):
    the clouds' altitude, for the physical atmosphere (None: DEFAULT_CLOUD_AGL_M above the
    ground); the gradient sky has one light for every altitude."""
    if sky.atmosphere is not None:
        return _physical_lights(sky, sky.atmosphere, above_cloud, alt_m)
    sun_el = sky.sun.elevation_deg
    key_dir: Vec3
    key_rgb: RGB
    if sun_el > MOON_TAKES_OVER_DEG:
        key_dir, key_rgb = sky.sun.direction_enu, sky.sun_rgb
    else:
        # The sky pass's moon colour is for a disc seen in the sky; fade it in as the sun's
        # light has gone (sun_rgb is 0 below -2 degrees), so the key light never jumps.
        night = smoothstep(MOON_TAKES_OVER_DEG, MOON_TAKES_OVER_DEG - 5.0, sun_el)
        key_dir = sky.moon.direction_enu
        gain = MOONLIGHT_GAIN * sky.moon.illuminated_fraction * night
        r, g, b = sky.moon_rgb
        key_rgb = (r * gain, g * gain, b * gain)
    zenith_rgb, horizon_rgb = sky.zenith_rgb, sky.horizon_rgb
    if above_cloud:
        zenith_rgb = sky.open_zenith_rgb or zenith_rgb
        horizon_rgb = sky.open_horizon_rgb or horizon_rgb
    zenith, horizon = _greyer(zenith_rgb), _greyer(horizon_rgb)
    # The ground is lit by the sun on its plane (the sun's light on the ground, not on the
    # cloud: a deck's shadow is not modelled here) and by the sky; it sends GROUND_ALBEDO of
    # that up, uncoloured beyond the light's own colour.
    sun_on_ground = max(math.sin(math.radians(sky.sun.elevation_deg)), 0.0)
    ground = tuple(
        GROUND_ALBEDO * (k * sun_on_ground * (1.0 - sky.cover) + SKY_ON_GROUND * 0.5 * (z + h))
        for k, z, h in zip(sky.sun_rgb, zenith, horizon, strict=True)
    )
    return CloudLights(key_dir, key_rgb, zenith, horizon, (ground[0], ground[1], ground[2]))


def _greyer(rgb: tuple[float, ...]) -> RGB:
    grey = rgb[0] * 0.2126 + rgb[1] * 0.7152 + rgb[2] * 0.0722
    r, g, b = (grey + (c - grey) * SKY_SATURATION for c in rgb)
    return (r, g, b)


# -- from the physical atmosphere -------------------------------------------------------------


def cloud_units_per_klx(luts: AtmosphereLuts, cover: float = 0.0) -> float:
    """The one factor from the atmosphere's irradiance (klx) to the clouds' units (see the
    module's docstring): the scene's exposure under `cover` (scene.sky `scene_exposure`, the
    sky's) over pi."""
    return scene_exposure(luts, cover) / math.pi


def _agl(sky: SkyParams, alt_m: float | None) -> float:
    if alt_m is None or not math.isfinite(alt_m):
        return DEFAULT_CLOUD_AGL_M
    return max(alt_m - sky.ground_m, 0.0)


def key_rgb_at(sky: SkyParams, alt_m: F64) -> F64 | None:
    """(N, 3) the key light at each of N altitudes (MSL) in the clouds' units, for a model that
    lights each sprite at its own height; None with the gradient sky (one light for all) or
    at night (the moon's light, taken at one altitude, is dim and white enough)."""
    luts = sky.atmosphere
    if luts is None or sky.sun.elevation_deg <= MOON_TAKES_OVER_DEG:
        return None
    agl = np.maximum(np.asarray(alt_m, np.float64) - sky.ground_m, 0.0)
    # A frame's sprites read a table over height, made once per table and 0.01 deg of sun:
    # the transmittance per sprite cost a frame 0.4-1 ms on a 2-core CPU.
    per_klx = cloud_units_per_klx(luts, sky.cover)  # on the veil's steps: a few values
    heights, table = _key_table(luts, round(sky.sun.elevation_deg * 100.0), per_klx)
    # np.interp on the table's even steps, the three channels at once (a third of three
    # np.interp calls on a frame's sprites).
    x = np.minimum(agl * (1.0 / KEY_TABLE_STEP_M), len(heights) - 1.0)
    i0 = np.minimum(x.astype(np.intp), len(heights) - 2)
    f = (x - i0)[..., None]
    lo = table.take(i0, axis=0)
    out: F64 = lo + (table.take(i0 + 1, axis=0) - lo) * f
    return out


KEY_TABLE_STEP_M = 25.0  # the transmittance changes under 1 % over it at a 2 deg sun
KEY_TABLE_TOP_M = 20_000.0


@functools.lru_cache(maxsize=4)
def _key_table(luts: AtmosphereLuts, sun_centideg: int, per_klx: float) -> tuple[F64, F64]:
    heights = np.arange(0.0, KEY_TABLE_TOP_M + KEY_TABLE_STEP_M, KEY_TABLE_STEP_M)
    table = sun_irradiance(luts, heights, sun_centideg / 100.0) * per_klx
    return heights, table


def _physical_lights(
    sky: SkyParams, luts: AtmosphereLuts, above_cloud: bool, alt_m: float | None
) -> CloudLights:
    sun_el = sky.sun.elevation_deg
    key_dir: Vec3
    if sun_el > MOON_TAKES_OVER_DEG:
        key_dir = sky.sun.direction_enu
        moon: tuple[float, float] | None = None
    else:
        key_dir = sky.moon.direction_enu
        moon = (round(sky.moon.elevation_deg, 2), round(sky.moon.illuminated_fraction, 4))
    # The light itself once per table, height, cover and 0.01 deg of sun (a fifth of a per
    # cent of a 5 deg sun's light; the sun takes 2.4 s to move that far): made afresh for each
    # height a frame asks for at every sky step it cost the scene stage 0.2 ms a frame.
    lit = _lights_at(
        luts, round(_agl(sky, alt_m), 1), round(sun_el, 2), float(sky.cover), above_cloud, moon
    )
    return CloudLights(key_dir, *lit)


@functools.lru_cache(maxsize=32)
def _lights_at(
    luts: AtmosphereLuts,
    agl: float,
    sun_el: float,
    cover: float,
    above_cloud: bool,
    moon: tuple[float, float] | None,
) -> tuple[RGB, RGB, RGB, RGB]:
    per_klx = cloud_units_per_klx(luts, cover)
    if moon is None:
        key = sun_irradiance(luts, agl, sun_el) * per_klx
    else:
        key = moon_irradiance(luts, agl, moon[0], moon[1]) * per_klx
    up, down = sky_irradiance(luts, agl, sun_el)
    # A uniform sky of radiance L (clouds' units) gives a surface facing it an irradiance of L
    # in the key's units: the sky's irradiance is the radiance of the sky that lights a cloud.
    zenith = up * per_klx
    # Toward the horizon the sky is paler and brighter than overhead; the clouds' models mix
    # the two by the side a light comes from. The table has the irradiance from the whole
    # hemisphere only, so the horizon is that light whitened by the light from the ground's
    # side (the haze low in the sky is lit by the ground and the sun alike).
    below = down * per_klx
    horizon = 0.5 * (zenith + np.full(3, float(zenith @ _LUMA))) + 0.5 * below
    if not above_cloud:
        # Under cloud the eye's sky is grey and dim (the sky pass's overcast veil): the light
        # a cloud gets from it too.
        grey = smoothstep(0.6, 1.0, cover)
        zenith = zenith + (float(zenith @ _LUMA) - zenith) * (0.8 * grey)
        horizon = horizon + (float(horizon @ _LUMA) - horizon) * (0.8 * grey)
    # The ground: its part of `below` that is the direct sun is shaded by the decks.
    ground = below * (1.0 - SUN_SHARE_ON_GROUND * cover * float(sun_el > 0.0))
    return (_rgb(key), _rgb(_greyer_np(zenith)), _rgb(_greyer_np(horizon)), _rgb(ground))


_LUMA = np.array([0.2126, 0.7152, 0.0722])


def _greyer_np(rgb: F64) -> F64:
    grey = float(rgb @ _LUMA)
    out: F64 = grey + (rgb - grey) * SKY_SATURATION
    return out


def _rgb(v: F64) -> RGB:
    a = np.nan_to_num(np.asarray(v, np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    return (float(max(a[0], 0.0)), float(max(a[1], 0.0)), float(max(a[2], 0.0)))
