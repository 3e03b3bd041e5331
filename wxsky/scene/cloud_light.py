"""The light falling on clouds, as one small set of inputs every cloud shading model reads
(Harris's particles, Wang's shading groups, Bouthors' slab and the tower volumes): the key
light (the sun, or the moon at night) at the clouds, the sky above them and the ground below.

`cloud_lights` is the one place these are filled. Today they come from the sky pass's colours
(`scene.sky.SkyParams`); when the physical atmosphere supplies the sun's transmitted colour at
each altitude and the sky's irradiance, only `cloud_lights` changes.

Units: the cloud models' radiance units, in which a white Lambertian surface facing the key
light is 1 (`key_rgb` of the noon sun is about 1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from wxsky.scene.sky import SkyParams, smoothstep

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


@dataclass(frozen=True)
class CloudLights:
    """What lights the clouds at their altitude."""

    key_dir: Vec3  # unit vector (ENU) toward the key light: the sun, or the moon at night
    key_rgb: RGB  # the key light's colour and strength reaching the clouds
    sky_zenith_rgb: RGB  # the sky overhead as it lights a cloud (greyed, see SKY_SATURATION)
    sky_horizon_rgb: RGB  # and the sky near the horizon
    ground_rgb: RGB  # light from the ground below, onto a cloud's base (radiance units)


def cloud_lights(sky: SkyParams, above_cloud: bool = False) -> CloudLights:
    """The clouds' lights for this sky; `above_cloud`: with the open sky over every layer (what
    lights the top of a deck) instead of the sky the eye sees under the cloud."""
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
