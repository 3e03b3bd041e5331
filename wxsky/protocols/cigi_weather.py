"""The weather a CIGI host's packets make at a place: its global layers with a region's
blended in by the region's weight there (1 inside its rounded rectangle, falling smoothly to
0 across the transition perimeter outside it), the fog layer's visibility where the place is
in the fog, precipitation layers and the present weather they report; and which of the applied
weather's cloud layers are the host's, under which of its layer ids (`answer_layer_ids`, for
the Aerosol Concentration Responses). Pure.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from wxsky.protocols.cigi_eye import eye
from wxsky.protocols.cigi_session import (
    CLOUD_LAYERS,
    FOG_CODE_BELOW_M,
    FOG_LAYER,
    MAX_VISIBILITY_M,
    OKTAS_PER_PCT,
    TOP_LIMIT_M,
    HostState,
    Layer,
    Region,
)
from wxsky.weather.atmosphere import dewpoint_from_humidity
from wxsky.weather.geo import enu_from_geodetic
from wxsky.weather.state import (
    FOG_DEPTH_M,
    FOG_VISIBILITY_M,
    MAX_LAYERS,
    NO_FOG,
    WIND_SPEED_MPS,
    CloudLayer,
    CloudType,
    Fog,
    PrecipKind,
    PrecipLayer,
    Source,
    WeatherPatch,
    WindLayer,
    dir_from_deg,
)
from wxsky.weather.transition import pair_layers

# CIGI's layer ids 10-255 are the IG's own: the answers number the layers the host did not set
# from here while any layer carries one of the host's ids (1-3), so none is taken for its.
IG_LAYER_IDS_FROM = 10
MAX_LAYER_ID = 255
# Metres a degree spans at least (of latitude: 110.57 km at the equator; of longitude, this
# times the cosine of the latitude), and the slack `_beyond` adds to a region's reach for its
# flat-Earth distance.
M_PER_DEG = 110_500.0
BEYOND_SLACK_M = 1000.0


def region_weight(region: Region, lat_deg: float, lon_deg: float) -> float:
    """How much of a region's weather holds at a place: 1 inside its rounded rectangle,
    falling smoothly to 0 across the transition perimeter outside it, 0 beyond (and for an
    inactive region)."""
    if not region.active:
        return 0.0
    east, north, _ = enu_from_geodetic(region.lat_deg, region.lon_deg, lat_deg, lon_deg, 0.0)
    rot = math.radians(region.rotation_deg)
    along = east * math.sin(rot) + north * math.cos(rot)  # the region's x axis
    across = east * math.cos(rot) - north * math.sin(rot)  # its y axis, to the right
    hx, hy = region.size_x_m / 2.0, region.size_y_m / 2.0
    rc = min(region.corner_radius_m, hx, hy)
    qx, qy = abs(along) - (hx - rc), abs(across) - (hy - rc)
    outside_m = math.hypot(max(qx, 0.0), max(qy, 0.0)) + min(max(qx, qy), 0.0) - rc
    if outside_m <= 0.0:
        return 1.0
    if region.transition_perimeter_m <= 0.0 or outside_m >= region.transition_perimeter_m:
        return 0.0
    t = outside_m / region.transition_perimeter_m
    return 1.0 - t * t * (3.0 - 2.0 * t)


def _region_at(host: HostState, lat_deg: float, lon_deg: float) -> tuple[int | None, float]:
    """The region whose weather holds at a place and how much (None, 0 for none): the one
    weighing most; of equal ones the higher id (CIGI's "use last" of overlapping regions)."""
    best: tuple[float, int] | None = None
    cos_lat = math.cos(math.radians(lat_deg))
    for rid, region in host.regions.items():
        if not region.active or _beyond(region, lat_deg, lon_deg, cos_lat):
            continue
        w = region_weight(region, lat_deg, lon_deg)
        if w > 0.0 and (best is None or (w, rid) > best):
            best = (w, rid)
    return (None, 0.0) if best is None else (best[1], best[0])


def _beyond(region: Region, lat_deg: float, lon_deg: float, cos_lat: float) -> bool:
    """Whether a place is surely beyond a region's reach: a few multiplications, where the
    exact weight takes a projection, so a host's many regions cost each datagram little
    (issue 40). Conservative: the reach is widened, the east distance taken at the latitude
    nearer a pole."""
    reach_m = 1.05 * (region.size_x_m + region.size_y_m + region.transition_perimeter_m)
    reach_m += BEYOND_SLACK_M
    north_m = abs(lat_deg - region.lat_deg) * M_PER_DEG
    if north_m > reach_m:
        return True
    dlon = abs(lon_deg - region.lon_deg) % 360.0
    cos_min = min(cos_lat, math.cos(math.radians(region.lat_deg)))
    return min(dlon, 360.0 - dlon) * M_PER_DEG * cos_min > reach_m


def weather_patch(host: HostState, lat_deg: float, lon_deg: float, alt_m: float) -> WeatherPatch:
    """The weather the host's packets make at a place (the ownship's): global layers with a
    region's blended in by its weight there, the fog layer's visibility where the place is in
    it. Only what the host set: a host that sent no Atmosphere Control leaves visibility,
    temperature and pressure to the sources below it."""
    rid, weight = _region_at(host, lat_deg, lon_deg)
    ids = sorted({lid for (r, lid) in host.layers if r is None or r == rid})
    clouds = [cloud for cloud, _ in _clouds_by_id(host, rid, weight, ids)]
    winds: list[WindLayer] = []
    precip: list[PrecipLayer] = []
    fog: Layer | None = None
    for lid in ids:
        g = host.layers.get((None, lid))
        r = host.layers.get((rid, lid)) if rid is not None else None
        # A region that leaves a layer id unset leaves the global layer there.
        w = weight if r is not None else 0.0
        if lid in CLOUD_LAYERS:
            if (wind := _blend_wind(g, r, w)) is not None:
                winds.append(wind)
        else:
            # Fog and precipitation are there or not: the region's where it mostly holds.
            chosen = r if r is not None and w >= 0.5 else g
            if chosen is None:
                continue
            if lid == FOG_LAYER:
                fog = chosen
            elif chosen.coverage_pct > 0.0:
                precip.append(_precip(chosen))
    atm = host.atmosphere
    fields: dict[str, object] = {}
    if host.sent_layers:
        fields["layers"] = tuple(sorted(clouds, key=lambda c: -c.cover_oktas)[:MAX_LAYERS])
        fields["precipitation"] = tuple(precip)
        codes = [p.metar_code for p in precip]
        storm = _lightning_code(host, rid, ids)
        if storm is not None:
            codes.append(storm)
        if fog is not None:
            codes.append("FG" if fog.visibility_m < FOG_CODE_BELOW_M else "BR")
        fields["present_weather"] = tuple(codes)
        # Ground fog (layer 0) as the fog wxsky draws and answers from (scene/fog.py): a sheet
        # of the layer's visibility, its top the layer's thickness over the ground.
        fields["fog"] = _ground_fog(fog)
    if atm is not None:
        winds.append(_wind(0.0, atm.wind_speed_mps, atm.wind_dir_deg))
        fields["temperature_c"] = atm.temperature_c
        fields["dewpoint_c"] = dewpoint_from_humidity(atm.temperature_c, atm.humidity_pct)
        fields["qnh_hpa"] = atm.pressure_hpa
    if atm is not None or fog is not None:
        vis = atm.visibility_m if atm is not None else MAX_VISIBILITY_M
        if fog is not None:
            vis = _fogged(vis, fog, alt_m)
        fields["visibility_m"] = vis
    if winds:  # a host that gives no wind leaves it to the sources below
        fields["wind"] = tuple(winds)
    return WeatherPatch(source=Source.CIGI, **fields)  # type: ignore[arg-type]


def _ground_fog(layer: Layer | None) -> Fog:
    """CIGI's ground fog layer as the weather's fog: NO_FOG without one, or where it is mist
    (FOG_CODE_BELOW_M or more) or thinner than the weather's fog can be."""
    if layer is None or layer.visibility_m >= FOG_CODE_BELOW_M:
        return NO_FOG
    vis_lo, vis_hi = FOG_VISIBILITY_M.bounds
    depth_lo, depth_hi = FOG_DEPTH_M.bounds
    return Fog(
        visibility_m=min(max(layer.visibility_m, vis_lo), vis_hi),
        depth_m=min(max(layer.thickness_m, depth_lo), depth_hi),
    )


def _lightning_code(host: HostState, rid: int | None, ids: Sequence[int]) -> str | None:
    """A thunderstorm in the present weather where a cloud layer the host sends (its global
    one, or the region's where the place is in one) asks for random lightning: `-TS`, `TS` or
    `+TS` by its severity (0-1, 2-3, 4-5), the strongest such layer's; wxsky's lightning
    (scene/lightning.py) flashes in the cumulonimbus at that storm's rate."""
    strongest = -1
    for lid in ids:
        if lid not in CLOUD_LAYERS:
            continue
        for layer in (host.layers.get((None, lid)), host.layers.get((rid, lid))):
            if layer is not None and layer.random_lightning and layer.cloud_type != 0:
                strongest = max(strongest, layer.severity)
    if strongest < 0:
        return None
    return "-TS" if strongest <= 1 else "TS" if strongest <= 3 else "+TS"


def host_clouds(host: HostState) -> tuple[tuple[CloudLayer, int], ...]:
    """The cloud layers the host's packets make where its weather is taken (the rendered
    view's eye, as `weather_patch` is asked for it), each with the host's layer id (a layer
    id a region blends in two cloud types gives two)."""
    view = eye(host)
    if view is None and host.regions:
        return ()  # no weather of the host's is applied before it places its ownship
    lat, lon = (view.lat_deg, view.lon_deg) if view is not None else (0.0, 0.0)
    rid, weight = _region_at(host, lat, lon)
    ids = sorted({lid for (r, lid) in host.layers if r is None or r == rid})
    return tuple(_clouds_by_id(host, rid, weight, ids))


def answer_layer_ids(
    applied: Sequence[CloudLayer],
    target: Sequence[CloudLayer],
    hosts: Sequence[HostState] = (),
) -> tuple[int, ...]:
    """The layer id each applied cloud layer answers under. A layer moving toward one of the
    hosts' layers (paired with it as the transition pairs layers: same type, nearest base)
    has that host's id, several layers of one id summing into one answer; every other layer
    (from a METAR, a preset, a knob, or one of the host's on its way out after the host
    replaced or removed it) is numbered by its rank from the lowest: from 1 while no layer
    has a host's id, else from IG_LAYER_IDS_FROM, CIGI's first IG-defined id."""
    pool = [(cloud, lid) for host in hosts for cloud, lid in host_clouds(host)]
    goal_ids: dict[int, int] = {}  # id() of a target layer -> the host's layer id
    for layer in target:
        found = next((k for k, (cloud, _) in enumerate(pool) if cloud == layer), None)
        if found is not None:
            goal_ids[id(layer)] = pool.pop(found)[1]
    where = {id(layer): i for i, layer in enumerate(applied)}
    ids = [0] * len(applied)
    others: list[int] = []
    for now, goal in pair_layers(tuple(applied), tuple(target)):
        if now is None:
            continue
        i = where[id(now)]
        lid = goal_ids.get(id(goal)) if goal is not None else None
        if lid is None:
            others.append(i)
        else:
            ids[i] = lid
    first = IG_LAYER_IDS_FROM if len(others) < len(applied) else 1
    for rank, i in enumerate(sorted(others, key=lambda i: (applied[i].base_m, i))):
        ids[i] = min(first + rank, MAX_LAYER_ID)
    return tuple(ids)


def _clouds_by_id(
    host: HostState, rid: int | None, weight: float, ids: Sequence[int]
) -> list[tuple[CloudLayer, int]]:
    out: list[tuple[CloudLayer, int]] = []
    for lid in ids:
        if lid not in CLOUD_LAYERS:
            continue
        g = host.layers.get((None, lid))
        r = host.layers.get((rid, lid)) if rid is not None else None
        # A region that leaves a layer id unset leaves the global layer there.
        w = weight if r is not None else 0.0
        out += [(cloud, lid) for cloud in _blend_clouds(g, r, w)]
    return out


def _cloud(layer: Layer, cover_pct: float, base_m: float, thickness_m: float) -> CloudLayer:
    return CloudLayer(
        min(8.0, cover_pct * OKTAS_PER_PCT),
        base_m,
        min(TOP_LIMIT_M, base_m + thickness_m),
        CloudType(layer.cloud_type),
    )


def _blend_clouds(g: Layer | None, r: Layer | None, w: float) -> list[CloudLayer]:
    """One cloud layer id's clouds at a place `w` into a region: a layer of one type on both
    sides is one layer between the two; different types are both there, each with its
    share of the cover (one thins out as the other thickens across the perimeter)."""
    g = g if g is not None and g.cloud_type != 0 else None
    r = r if r is not None and r.cloud_type != 0 and w > 0.0 else None
    if g is not None and r is not None and g.cloud_type == r.cloud_type:
        mix = _lerp(g.coverage_pct, r.coverage_pct, w)
        return [
            _cloud(
                g,
                mix,
                _lerp(g.base_m, r.base_m, w),
                _lerp(g.thickness_m, r.thickness_m, w),
            )
        ]
    out = []
    if g is not None and g.coverage_pct * (1.0 - w) > 0.0:
        out.append(_cloud(g, g.coverage_pct * (1.0 - w), g.base_m, g.thickness_m))
    if r is not None and r.coverage_pct * w > 0.0:
        out.append(_cloud(r, r.coverage_pct * w, r.base_m, r.thickness_m))
    return out


def _blend_wind(g: Layer | None, r: Layer | None, w: float) -> WindLayer | None:
    """A cloud layer's wind at its middle, blended as a vector; a layer sending no wind
    (speed 0) leaves its height to the winds above and below it."""
    sides = [(layer, weight) for layer, weight in ((g, 1.0 - w), (r, w)) if layer is not None]
    sides = [(layer, wt) for layer, wt in sides if layer.wind_speed_mps > 0.0 and wt > 0.0]
    if not sides:
        return None
    total = sum(weight for _, weight in sides) or 1.0
    east = north = alt = 0.0
    for layer, weight in sides:
        to_rad = math.radians(layer.wind_dir_deg + 180.0)
        east += weight / total * layer.wind_speed_mps * math.sin(to_rad)
        north += weight / total * layer.wind_speed_mps * math.cos(to_rad)
        alt += weight / total * (layer.base_m + layer.thickness_m / 2.0)
    speed = math.hypot(east, north)
    return _wind(alt, speed, dir_from_deg(east, north))


def _wind(alt_m: float, speed_mps: float, dir_deg: float) -> WindLayer:
    return WindLayer(alt_m, dir_deg % 360.0, min(speed_mps, float(WIND_SPEED_MPS.hi or 150.0)))


def _precip(layer: Layer) -> PrecipLayer:
    return PrecipLayer(
        PrecipKind(layer.layer_id),
        layer.base_m,
        layer.base_m + layer.thickness_m,
        layer.coverage_pct,
        layer.severity,
        layer.visibility_m,
    )


def _fogged(clear_m: float, fog: Layer, alt_m: float) -> float:
    """The visibility at alt_m: the fog's inside its layer, the clear air's beyond its
    transition band, between the two (geometrically) across the band."""
    top = fog.base_m + fog.thickness_m
    out_m = max(fog.base_m - alt_m, alt_m - top, 0.0)
    inside = min(clear_m, fog.visibility_m)
    if out_m <= 0.0:
        return inside
    if fog.transition_band_m <= 0.0 or out_m >= fog.transition_band_m:
        return clear_m
    t = out_m / fog.transition_band_m
    return float(math.exp(_lerp(math.log(max(inside, 1.0)), math.log(max(clear_m, 1.0)), t)))


def _lerp(a: float, b: float, t: float) -> float:
    return a + (b - a) * t
