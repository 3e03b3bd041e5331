"""A METAR over the model (issue 45, docs/weather-aloft.md): near a station and near its report's
time the METAR wins at the surface and for the layers it reports; aloft and far from
stations, the model.

The METAR's weight `w` is the product of two ramps, the same for every display channel (it
depends only on the stations and the sim clock, which channels share):

    w = ramp(distance to the nearest station used, NEAR_M .. FAR_M)
        * ramp(age of its report, FRESH_S .. OLD_S)

where ramp(x, a..b) is 1 up to a, 0 from b, linear between. Then:

* **wind**: the model's levels, with the METAR's surface wind laid over the lowest part: at
  the METAR's height the wind is w * METAR + (1 - w) * model; the difference fades linearly
  to nothing at `WIND_BLEND_M` above it (the boundary layer, where a surface report says
  something of the wind above it). Above that, the model alone.
* **layers**: the METAR reaches up to `reach_m`: its highest reported layer's top, or, when
  it reports no cloud, `CLEAR_REACH_AGL_M` above the field (12,000 ft, where automated
  stations stop looking). Below the reach, each METAR layer is paired with the model's layer
  of nearest base within `PAIR_M`; a pair's cover and base are weighted by w, its type the
  METAR's while w >= 0.5. Its top, which a report never gives, is the model's, unless the
  model's cloud ends before the reported one has half its type's usual depth (they then
  disagree on the height, and the type's depth stands). Layers of one side only keep their
  own weight of cover. Above the reach, the model's layers stand as they are.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

from wxsky.weather.state import MAX_LAYERS, CloudLayer, WindLayer, dir_from_deg

NEAR_M = 20_000.0
FAR_M = 150_000.0
FRESH_S = 3600.0
OLD_S = 3 * 3600.0
WIND_BLEND_M = 1000.0
CLEAR_REACH_AGL_M = 3658.0  # 12,000 ft
PAIR_M = 900.0
MIN_COVER_OKTAS = 0.05


def ramp(x: float, full: float, none: float) -> float:
    if x <= full:
        return 1.0
    if x >= none:
        return 0.0
    return (none - x) / (none - full)


def metar_weight(distance_m: float | None, age_s: float | None) -> float:
    """How much the METAR counts against the model (0..1); an unknown age counts as old."""
    if distance_m is None:
        return 0.0
    age = OLD_S if age_s is None else max(0.0, age_s)
    return ramp(distance_m, NEAR_M, FAR_M) * ramp(age, FRESH_S, OLD_S)


@dataclass(frozen=True)
class Blended:
    layers: tuple[CloudLayer, ...] | None
    wind: tuple[WindLayer, ...] | None


def blend(
    metar_layers: tuple[CloudLayer, ...] | None,
    metar_wind: tuple[WindLayer, ...] | None,
    model_layers: tuple[CloudLayer, ...] | None,
    model_wind: tuple[WindLayer, ...] | None,
    w: float,
    field_m: float,
) -> Blended:
    """The layers and wind of a METAR (weight w) laid over the model's; a side that says
    nothing leaves the other's as it is."""
    return Blended(
        _layers(metar_layers, model_layers, w, field_m),
        _wind(metar_wind, model_wind, w),
    )


def _wind(
    metar: tuple[WindLayer, ...] | None, model: tuple[WindLayer, ...] | None, w: float
) -> tuple[WindLayer, ...] | None:
    if not model:
        return metar
    if not metar:
        return model
    surface = metar[0]
    me, mn = surface.velocity_mps()
    ge, gn = _model_at(model, surface.alt_m)
    de, dn = w * (me - ge), w * (mn - gn)
    out: list[WindLayer] = []
    for lev in model:
        if lev.alt_m <= surface.alt_m:
            continue
        f = ramp(lev.alt_m - surface.alt_m, 0.0, WIND_BLEND_M)
        if f <= 0.0:
            out.append(lev)
            continue
        e, n = lev.velocity_mps()
        out.append(_layer(lev.alt_m, e + f * de, n + f * dn, lev.gust_mps, lev.dir_from_deg))
    e0, n0 = ge + de, gn + dn
    gust = max(w * surface.gust_mps, 0.0)
    first = _layer(surface.alt_m, e0, n0, gust, surface.dir_from_deg)
    if w >= 0.5 and surface.variable:
        first = WindLayer(first.alt_m, first.dir_from_deg, first.speed_mps, first.gust_mps, True)
    return (first, *out)


def _layer(alt_m: float, e: float, n: float, gust: float, fallback_dir: float) -> WindLayer:
    speed = min(math.hypot(e, n), 150.0)
    direction = fallback_dir if speed < 0.05 else dir_from_deg(e, n)
    return WindLayer(alt_m, direction, speed, max(gust, 0.0) if gust >= speed else 0.0)


def _model_at(model: tuple[WindLayer, ...], alt_m: float) -> tuple[float, float]:
    if alt_m <= model[0].alt_m:
        return model[0].velocity_mps()
    for a, b in itertools.pairwise(model):
        if a.alt_m <= alt_m <= b.alt_m:
            f = (alt_m - a.alt_m) / (b.alt_m - a.alt_m) if b.alt_m > a.alt_m else 0.0
            ae, an = a.velocity_mps()
            be, bn = b.velocity_mps()
            return ae + f * (be - ae), an + f * (bn - an)
    return model[-1].velocity_mps()


def reach_m(metar: tuple[CloudLayer, ...], field_m: float) -> float:
    """How high the METAR says what the sky holds."""
    if not metar:
        return field_m + CLEAR_REACH_AGL_M
    return max(lay.top_m for lay in metar)


def _layers(
    metar: tuple[CloudLayer, ...] | None,
    model: tuple[CloudLayer, ...] | None,
    w: float,
    field_m: float,
) -> tuple[CloudLayer, ...] | None:
    if model is None:
        return metar
    if metar is None:
        return model
    reach = reach_m(metar, field_m)
    below = [lay for lay in model if lay.base_m < reach]
    above = [lay for lay in model if lay.base_m >= reach]
    out: list[CloudLayer] = list(above)
    unpaired = list(below)
    for m in metar:
        g = min(unpaired, key=lambda lay: abs(lay.base_m - m.base_m), default=None)
        if g is not None and abs(g.base_m - m.base_m) <= PAIR_M:
            unpaired.remove(g)
            cover = w * m.cover_oktas + (1.0 - w) * g.cover_oktas
            base = w * m.base_m + (1.0 - w) * g.base_m
            # the model's top, unless the model's cloud ends before the reported one has
            # half its usual depth: then they disagree on the height, and the type's depth
            # the METAR's layer came with stands
            top = g.top_m if g.top_m >= base + 0.5 * m.thickness_m else base + m.thickness_m
            out.append(CloudLayer(min(cover, 8.0), base, top, m.type if w >= 0.5 else g.type))
        elif w * m.cover_oktas >= MIN_COVER_OKTAS:
            out.append(CloudLayer(w * m.cover_oktas, m.base_m, m.top_m, m.type))
    for g in unpaired:
        if (1.0 - w) * g.cover_oktas >= MIN_COVER_OKTAS:
            out.append(CloudLayer((1.0 - w) * g.cover_oktas, g.base_m, g.top_m, g.type))
    out.sort(key=lambda lay: -lay.cover_oktas)
    return tuple(sorted(out[:MAX_LAYERS], key=lambda lay: lay.base_m))
