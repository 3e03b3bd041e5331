"""Rain and snow shafts under cumulonimbus and nimbostratus (issue 17, item 5).

When the weather says something falls (METAR present weather such as `+TSRA`, `SHRA`, `-SN`,
or a CIGI precipitation layer), each cumulonimbus and nimbostratus cloud on show gets a shaft:
soft sprites filling a column from its base down to the ground, under the middle of its base.
They are the cloud's own sprites (its id, so they drift, form, dissipate, sort and go into the
ring's impostors with it, and its body shades them as Harris's light passes through it), made
where a block of the layer is placed (`formation.layer_block`). The sprites overlap most on
the column's axis, so a shaft is darker and denser at its core and thins toward its edges;
snow falls in a wider, paler, more even curtain than rain.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from wxsky.scene.footprints import footprints
from wxsky.scene.sprites import SpriteBatch
from wxsky.scene.texture_slots import TEX_FOG
from wxsky.weather.state import CloudType, PrecipKind, PrecipLayer, WeatherState

SHAFT_TYPES = frozenset({CloudType.CUMULONIMBUS, CloudType.NIMBOSTRATUS})
# METAR intensity prefix -> how heavily it falls, 0..1.
INTENSITY = {"-": 0.35, "": 0.65, "+": 1.0}
# Codes that fall from these clouds as shafts (drizzle falls from stratus, too fine to show).
RAIN_CODES = ("RA", "GR", "GS", "PL", "UP")
SNOW_CODES = ("SN", "SG")
SHAFT_RADIUS_FRAC = {False: 0.45, True: 0.7}  # of the cloud's base radius: rain, snow
SHAFT_OPACITY = {False: 0.3, True: 0.2}  # per sprite, at full intensity: rain, snow
SHAFT_DARKNESS = {False: 1.0, True: 0.35}  # rain is grey, snow whiter
MAX_SPRITES_PER_SHAFT = 24
# A shaft sprite's shading-group direction: straight down from its cloud. (Cloud sprites point
# theirs at a group's centre, never exactly down with a height and core of 0 as well.)
SHAFT_LIGHT_DIR = (0.0, 0.0, -1.0)


@dataclass(frozen=True)
class Rain:
    """What falls, for the shafts: how heavily (0..1), whether it is snow, and the ground
    MSL the shafts reach."""

    intensity: float
    snow: bool
    ground_m: float


def weather_group(group: str) -> tuple[str, frozenset[str]]:
    """A METAR present-weather group as its intensity prefix ("-", "" or "+") and its
    two-letter codes, descriptors first: `+TSGR` is ("+", {"TS", "GR"}), thunderstorm and
    hail, not "SG"."""
    code = group.strip().upper()
    prefix = code[0] if code[:1] in ("-", "+") else ""
    body = code[len(prefix) :]
    return prefix, frozenset(body[i : i + 2] for i in range(0, len(body), 2))


def rain_of(state: WeatherState) -> Rain | None:
    """The heaviest precipitation the state reports (present weather and CIGI precipitation
    layers), or None when nothing falls that would make a shaft."""
    # Asked every frame (the near set's key): kept for the last few reports.
    return _rain_of(state.present_weather, state.precipitation, state.observer.alt_m)


@functools.lru_cache(maxsize=16)
def _rain_of(
    present_weather: tuple[str, ...], precipitation: tuple[PrecipLayer, ...], ground_m: float
) -> Rain | None:
    best: tuple[float, bool] | None = None
    for group in present_weather:
        prefix, codes = weather_group(group)
        snow = bool(codes & set(SNOW_CODES)) and "RA" not in codes
        if "VC" in codes or not (snow or codes & set(RAIN_CODES)):
            continue  # in the vicinity (VCSH) is not over the station
        found = (INTENSITY[prefix], snow)
        if best is None or found[0] > best[0]:
            best = found
    for layer in precipitation:
        found = ((layer.severity + 1) / 6.0, layer.kind == PrecipKind.SNOW)
        if best is None or found[0] > best[0]:
            best = found
    if best is None:
        return None
    return Rain(best[0], best[1], ground_m)


def is_shaft(batch: SpriteBatch) -> npt.NDArray[np.bool_]:
    """(N,) True for the sprites of rain and snow shafts (read-only). Kept for the last batch
    asked about by its arrays: a near set's frames share them, and a frame that drops a
    tower's cloud asks for the set's shafts."""
    global _last_shafts
    arrays = (batch.light_dir, batch.height_frac, batch.core_frac)
    last = _last_shafts  # one read: another thread may replace it
    if last is not None and all(a is b for a, b in zip(last[0], arrays, strict=True)):
        return last[1]
    # Column by column: a reduction over rows of three (np.all(axis=1)) was 200 us for a
    # thunderstorm's near set.
    ld = batch.light_dir
    out: npt.NDArray[np.bool_] = (batch.height_frac == 0.0) & (batch.core_frac == 0.0)
    for axis, value in enumerate(SHAFT_LIGHT_DIR):
        out &= ld[:, axis] == np.float32(value)
    out.flags.writeable = False
    _last_shafts = (arrays, out)
    return out


_last_shafts: tuple[tuple[npt.NDArray[np.float32], ...], npt.NDArray[np.bool_]] | None = None


def shaft_sprites(clouds: SpriteBatch, base_m: float, rain: Rain) -> SpriteBatch:
    """Shaft sprites for every cloud in `clouds` (one block of a layer whose base is base_m
    MSL, z measured from that base), in the same frame: each a column of soft sprites from
    the cloud's base down to `rain.ground_m`, as opaque as the cloud's base has formed. Empty
    when the base is at or below the ground."""
    depth_m = base_m - rain.ground_m
    if not len(clouds) or depth_m <= 1.0 or rain.intensity <= 0.0:
        return SpriteBatch.empty()
    feet = footprints(clouds)
    ids, axis, radius, formed = feet.ids, feet.axis_m, feet.radius_m, feet.formed
    parts = [
        _column(float(axis[c, 0]), float(axis[c, 1]), float(radius[c]), depth_m, rain)
        for c in range(len(ids))
    ]
    sizes = [len(p[0]) for p in parts]
    n = sum(sizes)
    if n == 0:
        return SpriteBatch.empty()
    which = np.repeat(np.arange(len(ids)), sizes)
    centre = np.concatenate([p[0] for p in parts])
    size = np.concatenate([p[1] for p in parts]).astype(np.float32)
    snow = rain.snow
    tex = np.asarray(TEX_FOG, np.int32)[(ids[which] + np.arange(n)) % len(TEX_FOG)]
    return SpriteBatch(
        centre_m=centre,
        size_m=size,
        rotation_rad=((np.arange(n) * 2.399963) % (2.0 * math.pi)).astype(np.float32),
        texture=tex.astype(np.int32),
        height_frac=np.zeros(n, np.float32),
        light_dir=np.tile(np.array(SHAFT_LIGHT_DIR, np.float32), (n, 1)),
        opacity=(SHAFT_OPACITY[snow] * rain.intensity * formed[which]).astype(np.float32),
        darkness=np.full(n, SHAFT_DARKNESS[snow], np.float32),
        cloud_id=ids[which],
        core_frac=np.zeros(n, np.float32),
        flat=np.zeros(n, np.bool_),
        slab_m=np.full((n, 2), np.nan, np.float32),
    )


def _column(
    x_m: float, y_m: float, cloud_radius_m: float, depth_m: float, rain: Rain
) -> tuple[np.ndarray, np.ndarray]:
    """(K, 3) centres (z from the base, negative down) and (K,) sizes of one shaft's sprites:
    rings of sprites about the axis, level above level from the ground to the base, each
    sprite twice the spacing so they overlap into one body."""
    radius = SHAFT_RADIUS_FRAC[rain.snow] * cloud_radius_m
    size = max(50.0, min(2.0 * radius, depth_m))
    while True:  # bigger sprites until a shaft is at most MAX_SPRITES_PER_SHAFT of them
        step = 0.5 * size
        levels = max(1, math.ceil((depth_m - 0.5 * size) / step) + 1)
        rings = max(0, math.floor(max(radius - 0.5 * size, 0.0) / step))
        if (1 + 3 * rings * (rings + 1)) * levels <= MAX_SPRITES_PER_SHAFT:
            break
        size *= 1.25
    points = [(0.0, 0.0)]
    for r in range(1, rings + 1):
        around = 6 * r
        for k in range(around):
            a = 2.0 * math.pi * (k + 0.5 * (r % 2)) / around
            points.append((r * step * math.cos(a), r * step * math.sin(a)))
    xy = np.asarray(points)
    zs = -depth_m + 0.5 * size + step * np.arange(levels)
    zs = np.minimum(zs, -0.25 * size)  # the top level stays under the base
    centre = np.empty((len(xy) * levels, 3))
    centre[:, 0] = x_m + np.tile(xy[:, 0], levels)
    centre[:, 1] = y_m + np.tile(xy[:, 1], levels)
    centre[:, 2] = np.repeat(zs, len(xy))
    return centre, np.full(len(centre), size)
