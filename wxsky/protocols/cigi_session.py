"""What a CIGI host has told wxsky, remembered between messages as an image generator
remembers it, and the weather, camera and clock that makes.

CIGI is stateful: a host sends a layer's Weather Control or a region once and the IG keeps it
until the host changes or removes it; only IG Control leads every message. `absorb` folds one
decoded datagram into a `HostState` (immutable) and says what changed; `responses` answers a
conditions request. The weather the state makes at a place is `cigi_weather`'s, the camera of
the view wxsky renders `cigi_eye`'s.

The host's regions are capped (`absorb`'s `max_regions`, `[cigi] max_regions`): a region id
counts from its first Environmental Region Control or region-scoped Weather Control, and
past the cap the least recently touched one goes with its layers, counted in
`Absorbed.evicted`. So the state, and the work of every datagram that reads it, stays bounded
whatever a host sends.

Packets are checked twice: the decoder holds each to the CIGI table's ranges, and here to
what the weather can hold (a cloud layer needs a thickness, a temperature must be weather on
Earth). A packet failing either is dropped whole and counted; nothing out of range reaches
the weather. Pure: the socket lives in `wxsky.inputs.cigi_link`.
"""

from __future__ import annotations

import dataclasses
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, date, datetime
from types import MappingProxyType

from wxsky.protocols.cigi import CigiDatagram, Packet, make
from wxsky.weather.atmosphere import PointWeather
from wxsky.weather.state import (
    LAYER_HEIGHT_M,
    QNH_HPA,
    TEMPERATURE_C,
    VISIBILITY_M,
    WIND_SPEED_MPS,
    PrecipKind,
)

FOG_LAYER = 0
CLOUD_LAYERS = (1, 2, 3)
PRECIP_LAYERS = tuple(int(k) for k in PrecipKind)  # 4 rain, 5 snow, 6 sleet, 7 hail
OKTAS_PER_PCT = 8.0 / 100.0
# CIGI gives visibility as a float with no upper bound (hosts send 1e6 or more for
# "unlimited"); the weather keeps at most VISIBILITY_M's limit, and clamps to it.
MAX_VISIBILITY_M = float(VISIBILITY_M.hi or 1e6)
TOP_LIMIT_M = float(LAYER_HEIGHT_M.hi or 25_000.0)
MIN_THICKNESS_M = 1.0
# The fog veils a place within its layer and fades out across the layer's transition band.
FOG_CODE_BELOW_M = 1000.0  # a fog layer thinner in visibility than this is FG, else BR

# The most regions (each with its layers) a host keeps by default; `[cigi] max_regions`.
MAX_REGIONS = 256
# Weather Control layer ids wxsky keeps (higher ones are ignored): a region has at most these.
KEPT_LAYER_IDS = range(8)

# Things a host may send that wxsky does not use; counted in status, never errors.
IGNORED: Mapping[str, str] = MappingProxyType(
    {
        "other_entity": "Entity Control for an entity other than the ownship (0)",
        "attached_ownship": "the ownship's Entity Control with attach_state 1 (no parent here)",
        "other_view": "View Control or View Definition for a view wxsky does not render",
        "entity_scope": "Weather Control with entity scope (weather carried by an entity)",
        "layer_not_drawn": "Weather Control for sand, dust or an IG-defined layer (id ≥ 8)",
        "cloud_type_other": "a cloud layer of type 11-15 (IG-defined): no clouds drawn for it",
        "surface_request": "a maritime or terrestrial surface conditions request",
    }
)


@dataclass(frozen=True)
class Ownship:
    lat_deg: float
    lon_deg: float
    alt_m: float
    roll_deg: float
    pitch_deg: float
    yaw_deg: float


@dataclass(frozen=True)
class ViewOffset:
    """View Control for the rendered view: offsets in the entity's body frame (x forward,
    y right, z down) and angles relative to it, each only where its enable bit is set."""

    x_m: float = 0.0
    y_m: float = 0.0
    z_m: float = 0.0
    roll_deg: float = 0.0
    pitch_deg: float = 0.0
    yaw_deg: float = 0.0


@dataclass(frozen=True)
class Region:
    region_id: int
    active: bool
    lat_deg: float
    lon_deg: float
    size_x_m: float  # along the region's x axis: north before rotation
    size_y_m: float
    corner_radius_m: float
    rotation_deg: float  # clockwise from north
    transition_perimeter_m: float


@dataclass(frozen=True)
class Layer:
    """One Weather Control layer as the host last set it (only enabled layers are kept)."""

    layer_id: int
    cloud_type: int
    coverage_pct: float
    base_m: float
    thickness_m: float
    transition_band_m: float
    visibility_m: float
    wind_speed_mps: float
    wind_dir_deg: float
    severity: int
    random_lightning: bool = False  # the host asks for lightning in this (cloud) layer


@dataclass(frozen=True)
class Atmosphere:
    humidity_pct: int
    temperature_c: float
    visibility_m: float
    wind_speed_mps: float
    wind_dir_deg: float
    pressure_hpa: float


@dataclass(frozen=True)
class HostState:
    """Everything the host has set so far. `layers` maps (region id, layer id) to a layer,
    region id None for global scope."""

    host_frame: int | None = None
    ig_mode: int = 0
    database_number: int = 0
    ownship: Ownship | None = None
    view: ViewOffset = ViewOffset()
    fov_deg: float | None = None  # horizontal, from View Definition's left and right
    clock_utc: datetime | None = None  # the host's last date and time (date_time_valid)
    clock_running: bool | None = None  # ephemeris_enable: the IG advances its own clock
    atmosphere: Atmosphere | None = None
    layers: Mapping[tuple[int | None, int], Layer] = field(
        default_factory=lambda: MappingProxyType({})
    )
    regions: Mapping[int, Region] = field(default_factory=lambda: MappingProxyType({}))
    # The host has sent Weather Control: from then on its clouds are what it says, none
    # included, rather than left to the sources below.
    sent_layers: bool = False
    # Every region id holding a region or a layer, least recently touched first (the cap's
    # eviction order).
    region_order: tuple[int, ...] = ()

    @property
    def has_weather(self) -> bool:
        return self.atmosphere is not None or self.sent_layers


@dataclass(frozen=True)
class Absorbed:
    """What one datagram did: the new state, what changed, the requests to answer, and the
    packets dropped (reason, message) or not used (IGNORED key -> count)."""

    state: HostState
    weather_changed: bool = False
    camera_changed: bool = False
    clock_utc: datetime | None = None  # set the clock to this (the host changed its time)
    clock_running: bool | None = None  # start or stop the clock (the host changed it)
    requests: tuple[Packet, ...] = ()
    dropped: tuple[tuple[str, str], ...] = ()
    ignored: Mapping[str, int] = field(default_factory=lambda: MappingProxyType({}))
    evicted: int = 0  # regions (with their layers) evicted to keep within max_regions


def absorb(
    state: HostState, datagram: CigiDatagram, view_id: int = 0, max_regions: int = MAX_REGIONS
) -> Absorbed:
    """Fold a decoded host→IG datagram into the host's state. A refused datagram (or one
    from an IG) changes nothing. Past `max_regions` region ids the least recently touched
    go, with their layers."""
    if datagram.refused or datagram.direction != "host_to_ig":
        return Absorbed(state)
    s = state
    weather = camera = False
    clock_utc: datetime | None = None
    clock_running: bool | None = None
    requests: list[Packet] = []
    dropped: list[tuple[str, str]] = []
    ignored: Counter[str] = Counter()
    layers = dict(s.layers)
    regions = dict(s.regions)
    order = dict.fromkeys(s.region_order)  # insertion order: least recently touched first

    def touch(rid: int) -> None:
        order.pop(rid, None)
        order[rid] = None

    def forget(rid: int) -> None:
        # A region's layers by their ids, not by a scan of every layer: a datagram of region
        # packets costs the same with 10 regions kept as with the cap's worth.
        regions.pop(rid, None)
        order.pop(rid, None)
        for lid in KEPT_LAYER_IDS:
            layers.pop((rid, lid), None)

    for p in datagram.packets:
        key = p.key
        if key == "ig_control":
            if p["ig_mode"] == 0 and s.ig_mode != 0 and s.host_frame is not None:
                # Reset/standby after operating: the IG forgets the host's world, as the
                # host will send it again (ICD: the host re-initialises the IG after a reset).
                weather = weather or s.has_weather or bool(regions)
                layers, regions, order = {}, {}, {}
                s = HostState(clock_running=s.clock_running)
            s = dataclasses.replace(
                s,
                host_frame=int(p["host_frame_number"]),
                ig_mode=int(p["ig_mode"]),
                database_number=int(p["database_number"]),
            )
        elif key == "entity_control":
            if p["entity_id"] != 0:
                ignored["other_entity"] += 1
            elif p["attach_state"] == 1:
                ignored["attached_ownship"] += 1
            else:
                own = Ownship(
                    float(p["lat_deg"]),
                    float(p["lon_deg"]),
                    float(p["alt_m"]),
                    float(p["roll_deg"]),
                    float(p["pitch_deg"]),
                    float(p["yaw_deg"]),
                )
                if own != s.ownship:
                    camera = True
                    weather = weather or _placed_weather(layers, regions)
                    s = dataclasses.replace(s, ownship=own)
        elif key == "view_control":
            if p["view_id"] != view_id or p["entity_id"] != 0:
                ignored["other_view"] += 1
            else:
                view = _view_offset(p)
                if view != s.view:
                    camera = True
                    weather = weather or _placed_weather(layers, regions)
                    s = dataclasses.replace(s, view=view)
        elif key == "view_definition":
            if p["view_id"] != view_id:
                ignored["other_view"] += 1
            elif p["left_enable"] and p["right_enable"]:
                fov = float(p["right_deg"]) - float(p["left_deg"])
                if not 1.0 <= fov <= 170.0:
                    dropped.append(
                        (
                            "out_of_range",
                            f"View Definition: right_deg - left_deg = {fov:g}, "
                            "wxsky renders 1..170 degrees",
                        )
                    )
                else:
                    camera = camera or fov != s.fov_deg
                    s = dataclasses.replace(s, fov_deg=fov)
        elif key == "celestial_sphere_control":
            running = bool(p["ephemeris_enable"])
            if running != s.clock_running:
                clock_running = running
            when = s.clock_utc
            if p["date_time_valid"]:
                when = _celestial_time(p)
                if when != s.clock_utc:
                    clock_utc = when
            s = dataclasses.replace(s, clock_running=running, clock_utc=when)
        elif key == "atmosphere_control":
            why = _atmosphere_problem(p)
            if why:
                dropped.append(("out_of_range", f"Atmosphere Control: {why}"))
                continue
            atm = Atmosphere(
                int(p["humidity_pct"]),
                float(p["temperature_c"]),
                min(float(p["visibility_m"]), MAX_VISIBILITY_M),
                float(p["wind_speed_mps"]),
                float(p["wind_dir_deg"]),
                float(p["pressure_hpa"]),
            )
            weather = weather or atm != s.atmosphere
            s = dataclasses.replace(s, atmosphere=atm)
        elif key == "environmental_region_control":
            rid = int(p["region_id"])
            if p["region_state"] == 2:  # destroyed: the region and its weather go
                weather = weather or rid in order
                forget(rid)
            else:
                region = _region(p)
                weather = weather or regions.get(rid) != region
                regions[rid] = region
                touch(rid)
        elif key == "weather_control":
            scope = int(p["scope"])
            layer_id = int(p["layer_id"])
            if scope == 2:
                ignored["entity_scope"] += 1
                continue
            if layer_id >= 8:
                ignored["layer_not_drawn"] += 1
                continue
            slot = (None if scope == 0 else int(p["entity_or_region_id"]), layer_id)
            if not s.sent_layers:
                s = dataclasses.replace(s, sent_layers=True)
                weather = True
            if not p["weather_enable"]:
                weather = weather or slot in layers
                layers.pop(slot, None)
                continue
            if layer_id in CLOUD_LAYERS and p["cloud_type"] > 10:
                ignored["cloud_type_other"] += 1
                weather = weather or slot in layers
                layers.pop(slot, None)
                continue
            why = _layer_problem(p)
            if why:
                dropped.append(("out_of_range", f"Weather Control layer {layer_id}: {why}"))
                continue
            layer = _layer(p)
            weather = weather or layers.get(slot) != layer
            layers[slot] = layer
            if slot[0] is not None:
                touch(slot[0])
        elif key == "environmental_conditions_request":
            if p["request_weather"] or p["request_aerosol"]:
                requests.append(p)
            if p["request_maritime"] or p["request_terrestrial"]:
                ignored["surface_request"] += 1
    evicted = 0
    # At the end, not per packet: one datagram holds at most ~1,400 region packets, so the
    # overshoot is bounded, and an id touched again later in the same datagram stays.
    while len(order) > max_regions:
        oldest = next(iter(order))
        held = oldest in regions or any((oldest, lid) in layers for lid in KEPT_LAYER_IDS)
        weather = weather or held
        forget(oldest)
        evicted += 1
    s = dataclasses.replace(
        s,
        layers=MappingProxyType(layers),
        regions=MappingProxyType(regions),
        region_order=tuple(order),
    )
    return Absorbed(
        s,
        weather,
        camera,
        clock_utc,
        clock_running,
        tuple(requests),
        tuple(dropped),
        MappingProxyType(dict(ignored)),
        evicted,
    )


def _placed_weather(
    layers: Mapping[tuple[int | None, int], Layer], regions: Mapping[int, Region]
) -> bool:
    """The host's weather depends on where the eye is: regions and the fog layer."""
    return bool(regions) or (None, FOG_LAYER) in layers


# --- checks: what the weather can hold --------------------------------------------------------


def _outside(name: str, value: float, lo: float | None, hi: float | None) -> str:
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        return f"{name} {value:g} is outside {lo:g}..{hi:g} (wxsky's weather)"
    return ""


def _atmosphere_problem(p: Packet) -> str:
    return (
        _outside("temperature_c", float(p["temperature_c"]), TEMPERATURE_C.lo, TEMPERATURE_C.hi)
        or _outside("wind_speed_mps", float(p["wind_speed_mps"]), 0.0, WIND_SPEED_MPS.hi)
        or _outside("pressure_hpa", float(p["pressure_hpa"]), QNH_HPA.lo, QNH_HPA.hi)
    )


def _layer_problem(p: Packet) -> str:
    layer_id = int(p["layer_id"])
    base, thick = float(p["base_elevation_m"]), float(p["thickness_m"])
    why = _outside("base_elevation_m", base, LAYER_HEIGHT_M.lo, TOP_LIMIT_M - 10.0) or _outside(
        "wind_speed_mps", float(p["wind_speed_mps"]), 0.0, WIND_SPEED_MPS.hi
    )
    if why:
        return why
    # Under a metre a top is not above its base in the weather's floats.
    if layer_id in CLOUD_LAYERS and p["cloud_type"] != 0 and thick < MIN_THICKNESS_M:
        return f"thickness_m {thick:g}: a cloud layer needs at least {MIN_THICKNESS_M:g} m"
    if layer_id in (FOG_LAYER, *PRECIP_LAYERS) and thick < MIN_THICKNESS_M:
        return (
            f"thickness_m {thick:g}: a fog or precipitation layer needs at least "
            f"{MIN_THICKNESS_M:g} m"
        )
    return ""


def _celestial_time(p: Packet) -> datetime:
    value = int(p["date_mmddyyyy"])  # a calendar date: the table's rule checked it
    day = date(value % 10_000, value // 1_000_000, value // 10_000 % 100)
    return datetime(day.year, day.month, day.day, int(p["hour"]), int(p["minute"]), tzinfo=UTC)


def _view_offset(p: Packet) -> ViewOffset:
    def on(name: str, value: str) -> float:
        return float(p[value]) if p[name] else 0.0

    return ViewOffset(
        on("x_enable", "x_offset_m"),
        on("y_enable", "y_offset_m"),
        on("z_enable", "z_offset_m"),
        on("roll_enable", "roll_deg"),
        on("pitch_enable", "pitch_deg"),
        on("yaw_enable", "yaw_deg"),
    )


def _region(p: Packet) -> Region:
    return Region(
        int(p["region_id"]),
        p["region_state"] == 1,
        float(p["lat_deg"]),
        float(p["lon_deg"]),
        float(p["size_x_m"]),
        float(p["size_y_m"]),
        float(p["corner_radius_m"]),
        float(p["rotation_deg"]),
        float(p["transition_perimeter_m"]),
    )


def _layer(p: Packet) -> Layer:
    base = float(p["base_elevation_m"])
    return Layer(
        int(p["layer_id"]),
        int(p["cloud_type"]),
        float(p["coverage_pct"]),
        base,
        min(float(p["thickness_m"]), TOP_LIMIT_M - base),
        float(p["transition_band_m"]),
        min(float(p["visibility_m"]), MAX_VISIBILITY_M),
        float(p["wind_speed_mps"]),
        float(p["wind_dir_deg"]),
        int(p["severity"]),
        bool(p["random_lightning_enable"]),
    )


# --- answers ----------------------------------------------------------------------------------


def responses(
    request: Packet, weather: PointWeather, layer_ids: Sequence[int] | None = None
) -> list[Packet]:
    """The answers to an Environmental Conditions Request: a Weather Conditions Response
    for the weather bit, an Aerosol Concentration Response per cloud layer for the aerosol
    bit, in the order of their layer ids. `layer_ids`: each of the weather's cloud layers' id
    (`cigi_weather.answer_layer_ids`; layers sharing an id are summed into one answer), by
    default its rank from the lowest. Values are clamped into the packets' ranges (a
    response is never refused)."""
    rid = int(request["request_id"])
    out: list[Packet] = []
    if request["request_weather"]:
        out.append(
            make(
                "weather_conditions_response",
                request_id=rid,
                humidity_pct=round(max(0.0, min(100.0, weather.humidity_pct))),
                temperature_c=weather.temperature_c,
                visibility_m=weather.visibility_m,
                wind_speed_mps=weather.wind_speed_mps,
                vertical_wind_speed_mps=0.0,
                wind_dir_deg=weather.wind_dir_deg % 360.0,
                pressure_hpa=weather.pressure_hpa,
            )
        )
    if request["request_aerosol"]:
        water = weather.cloud_water_gpm3
        ids = range(1, len(water) + 1) if layer_ids is None else layer_ids
        if len(ids) != len(water):
            raise ValueError(f"{len(ids)} layer ids for {len(water)} cloud layers")
        by_id: dict[int, float] = {}
        for layer_id, gpm3 in zip(ids, water, strict=True):
            by_id[layer_id] = by_id.get(layer_id, 0.0) + gpm3
        for layer_id in sorted(by_id):
            out.append(
                make(
                    "aerosol_concentration_response",
                    request_id=rid,
                    layer_id=layer_id,
                    aerosol_concentration_gpm3=by_id[layer_id],
                )
            )
    return out
