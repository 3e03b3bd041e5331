"""Pick the reporting station(s) for the observer's position and blend their weather.

With one station the nearest report is the weather. With N, the nearest N are blended by
inverse distance squared, so flying from one station to the next changes the sky gradually:

* cloud layers: the stations' layers are grouped by cloud type and base (within
  `LAYER_MATCH_M`); a group's cover is the weighted sum over every station that reported a
  sky (a station without that layer contributes 0 oktas), its base and thickness the weighted
  mean over the stations that have it. Stations that said nothing about the sky are left out.
* wind: the weighted mean velocity vector of the lowest layer, gusts by weight;
* visibility, temperature, dewpoint, QNH: weighted means over the stations that give them;
* present weather: the nearest station's.

A station whose report gives no usable observation time (day 32, and no time for it in the feed
either) is kept, so it is still counted and named, but is always stale: its age cannot be shown
to be within any limit.

Pure: no I/O; distances on a sphere (haversine), good to 0.5 % for this purpose.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from datetime import datetime

from wxsky.weather.state import (
    MAX_LAYERS,
    CloudLayer,
    Source,
    WeatherPatch,
    WindLayer,
    dir_from_deg,
)

EARTH_RADIUS_M = 6_371_000.0
LAYER_MATCH_M = 600.0  # layers of one type closer than this are the same layer
MIN_BLEND_COVER_OKTAS = 0.05  # a far station's trace of a layer is not worth drawing
AT_STATION_M = 1.0  # nearer than this, the station's own report is the weather


@dataclass(frozen=True)
class StationWeather:
    """The latest usable report of one station, already turned into a patch."""

    station: str
    lat_deg: float
    lon_deg: float
    elevation_m: float
    observed_utc: datetime | None  # None: the report's time is impossible and the feed has none
    patch: WeatherPatch


def distance_m(lat1_deg: float, lon1_deg: float, lat2_deg: float, lon2_deg: float) -> float:
    p1, p2 = math.radians(lat1_deg), math.radians(lat2_deg)
    dp, dl = p2 - p1, math.radians(lon2_deg - lon1_deg)
    h = math.sin(dp / 2) ** 2 + math.cos(p1) * math.cos(p2) * math.sin(dl / 2) ** 2
    return 2.0 * EARTH_RADIUS_M * math.asin(min(1.0, math.sqrt(h)))


def nearest(
    stations: Iterable[StationWeather],
    lat_deg: float,
    lon_deg: float,
    count: int,
    max_distance_m: float = math.inf,
) -> list[tuple[StationWeather, float]]:
    """Up to `count` stations within `max_distance_m`, nearest first, with their distances."""
    ranked = sorted(
        ((s, distance_m(lat_deg, lon_deg, s.lat_deg, s.lon_deg)) for s in stations),
        key=lambda item: (item[1], item[0].station),
    )
    return [item for item in ranked if item[1] <= max_distance_m][:count]


def split_by_age(
    stations: Iterable[StationWeather], now_utc: datetime, max_age_s: float
) -> tuple[list[StationWeather], list[StationWeather]]:
    """(fresh, stale): reports older than max_age_s at now_utc, or of unknown time, are stale."""
    fresh: list[StationWeather] = []
    stale: list[StationWeather] = []
    for s in stations:
        t = s.observed_utc
        (fresh if t is not None and (now_utc - t).total_seconds() <= max_age_s else stale).append(s)
    return fresh, stale


def weights(distances_m: Sequence[float]) -> list[float]:
    """Each station's share of the blend, from its distance (nearest first), summing to 1:
    inverse distance squared, or all to the first when it stands at the point."""
    if not distances_m:
        return []
    if len(distances_m) == 1 or distances_m[0] < AT_STATION_M:
        return [1.0] + [0.0] * (len(distances_m) - 1)
    inverse = _inverse_square(distances_m)
    total = sum(inverse)
    return [w / total for w in inverse]


def _inverse_square(distances_m: Sequence[float]) -> list[float]:
    """The blend's weights as it sums with them (each mean divides by their total)."""
    return [1.0 / (d * d) for d in distances_m]


def blend(chosen: Sequence[tuple[StationWeather, float]]) -> WeatherPatch:
    """The METAR weather at a point from stations at the given distances (nearest first),
    each counted by its `weights` share."""
    if not chosen:
        return WeatherPatch(source=Source.METAR)
    if len(chosen) == 1 or chosen[0][1] < AT_STATION_M:
        return chosen[0][0].patch
    weights_ = _inverse_square([d for _, d in chosen])
    patches = [s.patch for s, _ in chosen]
    return WeatherPatch(
        source=Source.METAR,
        layers=_blend_layers(patches, weights_),
        wind=_blend_wind(patches, weights_),
        visibility_m=_mean((p.visibility_m for p in patches), weights_),
        temperature_c=_mean((p.temperature_c for p in patches), weights_),
        dewpoint_c=_mean((p.dewpoint_c for p in patches), weights_),
        qnh_hpa=_mean((p.qnh_hpa for p in patches), weights_),
        present_weather=patches[0].present_weather,
    )


def _mean(values: Iterable[float | None], weights: Sequence[float]) -> float | None:
    pairs = [(v, w) for v, w in zip(values, weights, strict=True) if v is not None]
    total = sum(w for _, w in pairs)
    return None if not pairs else sum(v * w for v, w in pairs) / total


def _blend_layers(
    patches: Sequence[WeatherPatch], weights: Sequence[float]
) -> tuple[CloudLayer, ...] | None:
    known = [(p.layers, w) for p, w in zip(patches, weights, strict=True) if p.layers is not None]
    if not known:
        return None
    total = sum(w for _, w in known)
    # Each group: (a representative layer, [(layer, weight), ...]).
    groups: list[tuple[CloudLayer, list[tuple[CloudLayer, float]]]] = []
    for layers, w in known:
        for layer in layers:
            for head, members in groups:
                if head.type == layer.type and abs(head.base_m - layer.base_m) <= LAYER_MATCH_M:
                    members.append((layer, w))
                    break
            else:
                groups.append((layer, [(layer, w)]))
    out = []
    for head, members in groups:
        have = sum(w for _, w in members)
        cover = sum(lay.cover_oktas * w for lay, w in members) / total
        base = sum(lay.base_m * w for lay, w in members) / have
        thickness = sum(lay.thickness_m * w for lay, w in members) / have
        if cover >= MIN_BLEND_COVER_OKTAS:
            out.append(CloudLayer(min(8.0, cover), base, base + thickness, head.type))
    out.sort(key=lambda lay: -lay.cover_oktas)
    return tuple(sorted(out[:MAX_LAYERS], key=lambda lay: lay.base_m))


def _blend_wind(
    patches: Sequence[WeatherPatch], weights: Sequence[float]
) -> tuple[WindLayer, ...] | None:
    known = [(p.wind[0], w) for p, w in zip(patches, weights, strict=True) if p.wind]
    if not known:
        return None
    total = sum(w for _, w in known)
    east = sum(layer.velocity_mps()[0] * w for layer, w in known) / total
    north = sum(layer.velocity_mps()[1] * w for layer, w in known) / total
    speed = math.hypot(east, north)
    nearest_layer = known[0][0]
    direction = nearest_layer.dir_from_deg if speed < 0.05 else dir_from_deg(east, north)
    return (
        WindLayer(
            alt_m=sum(layer.alt_m * w for layer, w in known) / total,
            dir_from_deg=direction,
            speed_mps=speed,
            gust_mps=sum(layer.gust_mps * w for layer, w in known) / total,
            variable=all(layer.variable for layer, _ in known),
        ),
    )
