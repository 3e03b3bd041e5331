"""What cockpit hardware may set, and how a cockpit's values lie over the weather beneath it.

Cockpit links (NMEA 0183 on a serial line, CANaerospace on a CAN bus) decode frames into
`CockpitUpdate`s of finely keyed values -- one knob, one frame -- rather than whole weather
fields: a CAN bus sends wind speed and direction in separate frames, and a panel sets layer 2's
base without saying anything about layer 1. The precedence stack keeps each key with the wall
time it arrived, so each knob expires on its own when it goes quiet, and `overlay` lays the live
keys over the weather the sources below the cockpit ask for.

Cockpit layer n is the n-th layer (from the ground) of that weather: an instructor who turns
layer 1 to 8 oktas expects the lowest cloud to close, whatever the METAR said. Parts the cockpit
has not given are taken from that layer, or, for a layer the weather below does not have, from
defaults and the same cloud table the METAR decoder uses.

Time and position are not weather fields: the clock and the camera take them directly (see
`clock_target` and `SkyEngine.apply_cockpit`). Everything here is pure.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from datetime import UTC, date, datetime, timedelta
from types import MappingProxyType
from typing import Any

from wxsky.schema import Number
from wxsky.weather.state import (
    COVER_OKTAS,
    LAYER_HEIGHT_M,
    LAYER_THICKNESS_M,
    MAX_LAYERS,
    QNH_HPA,
    TEMPERATURE_C,
    VISIBILITY_M,
    WIND_DIR_DEG,
    WIND_SPEED_MPS,
    CloudLayer,
    CloudType,
    Source,
    WeatherState,
    WindLayer,
    time_in_range,
)

WIND_SPEED = "wind.speed_mps"
WIND_DIR = "wind.dir_from_deg"  # true, the direction the wind blows from
VISIBILITY = "visibility_m"
TEMPERATURE = "temperature_c"
DEWPOINT = "dewpoint_c"
QNH = "qnh_hpa"

COCKPIT_LAYERS = 3  # CIGI's cloud layers 1-3, and the layers a cockpit frame may name
LAYER_COVER = "cover_oktas"
LAYER_BASE = "base_m"  # MSL
LAYER_THICKNESS = "thickness_m"
LAYER_TYPE = "type"  # a CloudType; CloudType.NONE asks for the type to be derived
LAYER_PARTS = (LAYER_COVER, LAYER_BASE, LAYER_THICKNESS, LAYER_TYPE)


def layer_key(layer: int, part: str) -> str:
    """The key of one part of cockpit layer 1-3, e.g. `layer2.base_m`."""
    if not 1 <= layer <= COCKPIT_LAYERS:
        raise ValueError(f"cloud layer {layer} out of range 1..{COCKPIT_LAYERS}")
    if part not in LAYER_PARTS:
        raise ValueError(f"unknown cloud layer part {part!r}")
    return f"layer{layer}.{part}"


LAYER_KEYS: tuple[str, ...] = tuple(
    layer_key(n, part) for n in range(1, COCKPIT_LAYERS + 1) for part in LAYER_PARTS
)
SCALAR_KEYS: tuple[str, ...] = (VISIBILITY, TEMPERATURE, DEWPOINT, QNH)
WEATHER_KEYS: tuple[str, ...] = (WIND_SPEED, WIND_DIR, *SCALAR_KEYS, *LAYER_KEYS)

# The ranges a value must be in to reach the weather (the weather state's own limits, so that
# nothing a cockpit sends can make a state that refuses to exist). Wind direction is normalised
# to 0..360 before the check; a cloud layer's thickness must also be more than zero.
RANGES: Mapping[str, Number] = MappingProxyType(
    {
        WIND_SPEED: WIND_SPEED_MPS,
        WIND_DIR: WIND_DIR_DEG,
        VISIBILITY: VISIBILITY_M,
        TEMPERATURE: TEMPERATURE_C,
        DEWPOINT: TEMPERATURE_C,
        QNH: QNH_HPA,
        **{layer_key(n, LAYER_COVER): COVER_OKTAS for n in range(1, COCKPIT_LAYERS + 1)},
        **{layer_key(n, LAYER_BASE): LAYER_HEIGHT_M for n in range(1, COCKPIT_LAYERS + 1)},
        **{layer_key(n, LAYER_THICKNESS): LAYER_THICKNESS_M for n in range(1, COCKPIT_LAYERS + 1)},
    }
)

# Which keys each name in an input's `fields` allow-list lets the input set.
FIELD_GROUPS: Mapping[str, tuple[str, ...]] = MappingProxyType(
    {
        "wind": (WIND_SPEED, WIND_DIR),
        "clouds": LAYER_KEYS,
        "visibility": (VISIBILITY,),
        "temperature": (TEMPERATURE, DEWPOINT),
        "pressure": (QNH,),
        "time": (),  # CockpitUpdate.time_utc / time_of_day_s / date
        "position": (),  # CockpitUpdate.position_deg
    }
)
ALL_GROUPS: tuple[str, ...] = tuple(FIELD_GROUPS)


def checked(key: str, value: float) -> float:
    """`value` for `key` if it may reach the weather; raises ValueError saying why not.
    Wind direction is normalised into 0..360 (CANaerospace sends -180..180)."""
    if key not in RANGES:
        raise ValueError(f"unknown cockpit value {key!r}")
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{key} must be a number, got {value!r}")
    if not math.isfinite(value):
        raise ValueError(f"{key} is {value}, not a finite number")
    if key == WIND_DIR:
        if not -180.0 <= value <= 360.0:
            raise ValueError(f"{key} {value:g} out of range -180..360")
        normalised = float(value) % 360.0
        # A tiny negative angle wraps to exactly 360.0 in floating point: that is north, 0.
        return 0.0 if normalised >= 360.0 else normalised
    kind = RANGES[key]
    if not kind.contains(value):
        raise ValueError(f"{key} {value:g} out of range {kind.range_text()}")
    return float(value)


@dataclass(frozen=True)
class CockpitUpdate:
    """What one or more decoded frames from a cockpit link say. Every value has been through
    `checked`; a decoder never builds an update from a value it had to reject."""

    values: Mapping[str, float | CloudType] = field(default_factory=lambda: MappingProxyType({}))
    time_utc: datetime | None = None  # a full UTC date and time (ZDA, RMC)
    time_of_day_s: float | None = None  # seconds after midnight UTC, date not given (1200)
    date_utc: date | None = None  # a date without a time (1206)
    time_resolution_s: float = 0.0  # how finely the sender states time (1 s for 1200)
    position_deg: tuple[float, float] | None = None  # (lat, lon) of the observer (RMC)

    def __post_init__(self) -> None:
        object.__setattr__(self, "values", MappingProxyType(dict(self.values)))
        if self.time_utc is not None and self.time_utc.tzinfo is None:
            raise ValueError("cockpit time_utc must be timezone-aware")

    @property
    def empty(self) -> bool:
        return (
            not self.values
            and self.time_utc is None
            and self.time_of_day_s is None
            and self.date_utc is None
            and self.position_deg is None
        )

    def restricted(self, groups: Iterable[str]) -> CockpitUpdate:
        """This update with only what the named field groups allow."""
        allowed = set(groups)
        keys = {k for g in allowed for k in FIELD_GROUPS[g]}
        has_time = "time" in allowed
        return CockpitUpdate(
            values={k: v for k, v in self.values.items() if k in keys},
            time_utc=self.time_utc if has_time else None,
            time_of_day_s=self.time_of_day_s if has_time else None,
            date_utc=self.date_utc if has_time else None,
            time_resolution_s=self.time_resolution_s,
            position_deg=self.position_deg if "position" in allowed else None,
        )

    def fields_set(self) -> frozenset[str]:
        """What this update sets: its value names, plus "time", "date" and "position"."""
        out = set(self.values)
        if self.time_utc is not None or self.time_of_day_s is not None:
            out.add("time")
        if self.date_utc is not None:
            out.add("date")
        if self.position_deg is not None:
            out.add("position")
        return frozenset(out)

    def merged(self, later: CockpitUpdate) -> CockpitUpdate:
        """One update saying what this one and then `later` said (later wins per value)."""
        return CockpitUpdate(
            values={**self.values, **later.values},
            time_utc=later.time_utc or self.time_utc,
            time_of_day_s=(
                later.time_of_day_s if later.time_of_day_s is not None else self.time_of_day_s
            ),
            date_utc=later.date_utc or self.date_utc,
            time_resolution_s=(
                later.time_resolution_s
                if later.time_utc is not None or later.time_of_day_s is not None
                else self.time_resolution_s
            ),
            position_deg=later.position_deg or self.position_deg,
        )


def describe_groups() -> str:
    return ", ".join(ALL_GROUPS)


def check_groups(groups: Iterable[str]) -> tuple[str, ...]:
    """The groups, each checked to be a known name; raises ValueError naming an unknown one."""
    out = []
    for g in groups:
        if g not in FIELD_GROUPS:
            raise ValueError(f"unknown field group {g!r} (known: {describe_groups()})")
        out.append(g)
    return tuple(out)


# -- the clock --------------------------------------------------------------------------

CLOCK_TOLERANCE_S = 0.25  # transport and scheduling jitter; below it the clock is left alone
MIDNIGHT_WINDOW_S = 600.0  # a date and a time that straddle midnight arrive in either order
AGREES_S = 60.0  # a time of day this close to the sky clock only corrects it
DAY_S = 86_400.0


def clock_target(
    sky_utc: datetime, update: CockpitUpdate, recent_date: date | None = None
) -> datetime | None:
    """The time the sky clock should jump to for this update, or None to leave it running.

    A full date and time is taken as it is. A time of day without a date lands on the day that
    puts it nearest the sky clock when that is within `AGREES_S` (a time crossing midnight must
    not throw the sky back a day, whichever of the date and time frames comes first); a time of
    day that really moves the clock goes on the date the sender gave last (`recent_date`, kept
    by the caller for a few seconds), or else again on the nearest day. A date alone keeps the
    sky's time of day, but is left to the time frame near midnight when it is the day before
    or after the sky's. A time the sky clock already agrees with, within the sender's
    resolution, leaves it alone: a sender stating whole seconds must not pull the clock back
    every second."""
    candidate: datetime | None = None
    if update.time_utc is not None:
        candidate = update.time_utc.astimezone(UTC)
    elif update.time_of_day_s is not None:
        candidate = _time_of_day(sky_utc, update.time_of_day_s, update.date_utc or recent_date)
    elif update.date_utc is not None:
        sky_date = sky_utc.date()
        if update.date_utc == sky_date:
            return None
        seconds_into_day = (sky_utc - _midnight(sky_utc)).total_seconds()
        near_midnight = min(seconds_into_day, DAY_S - seconds_into_day) < MIDNIGHT_WINDOW_S
        if near_midnight and abs((update.date_utc - sky_date).days) == 1:
            return None
        candidate = datetime.combine(update.date_utc, sky_utc.timetz())
    if candidate is None or not time_in_range(candidate):
        # Out of the clock's range: a decoder refuses such a date, so only a time of day
        # put on the day after the range's last can land here; the clock keeps its own.
        return None
    ahead_s = (sky_utc - candidate).total_seconds()
    if -CLOCK_TOLERANCE_S <= ahead_s <= update.time_resolution_s + CLOCK_TOLERANCE_S:
        return None
    return candidate


def _midnight(t: datetime) -> datetime:
    return t.replace(hour=0, minute=0, second=0, microsecond=0)


def _time_of_day(sky_utc: datetime, tod_s: float, given_date: date | None) -> datetime:
    midnight = _midnight(sky_utc)
    options = [midnight + timedelta(days=d, seconds=tod_s) for d in (-1, 0, 1)]
    nearest = min(options, key=lambda t: abs((t - sky_utc).total_seconds()))
    if given_date is None or abs((nearest - sky_utc).total_seconds()) <= AGREES_S:
        return nearest
    return datetime.combine(given_date, datetime.min.time(), tzinfo=UTC) + timedelta(seconds=tod_s)


# -- the weather ------------------------------------------------------------------------

# Bases for a cockpit layer the weather below has no layer for, above the observer: a low,
# a middle and a high layer, as a three-layer instructor panel is usually laid out.
DEFAULT_LAYER_BASE_AGL_M = (1000.0, 3000.0, 7000.0)
MAX_CLOUD_TOP_M = 25_000.0


def overlay(below: WeatherState, values: Mapping[str, Any]) -> WeatherState:
    """The weather `below` with the cockpit's live values laid over it, provenance `cockpit`
    for every field they touch. Values are assumed `checked`."""
    if not values:
        return below
    changes: dict[str, Any] = {}
    for key in SCALAR_KEYS:
        if key in values:
            changes[key] = float(values[key])
    if WIND_SPEED in values or WIND_DIR in values:
        changes["wind"] = _wind(below, values.get(WIND_SPEED), values.get(WIND_DIR))
    if any(k in values for k in LAYER_KEYS):
        changes["layers"] = _layers(below, values)
    if not changes:
        return below
    sources = dataclasses.replace(below.sources, **dict.fromkeys(changes, Source.COCKPIT))
    return dataclasses.replace(below, **changes, sources=sources)


def _wind(
    below: WeatherState, speed_mps: float | None, dir_from_deg: float | None
) -> tuple[WindLayer, ...]:
    """The surface wind set by the cockpit; the winds aloft keep their shape (veer and
    increase with height) but turn and scale with the surface, so the clouds drift with the
    knob too."""
    if not below.wind:
        return (
            WindLayer(
                alt_m=below.observer.alt_m,
                dir_from_deg=dir_from_deg if dir_from_deg is not None else 0.0,
                speed_mps=speed_mps if speed_mps is not None else 0.0,
            ),
        )
    surface, aloft = below.wind[0], below.wind[1:]
    new_dir = dir_from_deg if dir_from_deg is not None else surface.dir_from_deg
    new_speed = speed_mps if speed_mps is not None else surface.speed_mps
    turn_deg = new_dir - surface.dir_from_deg
    new_surface = dataclasses.replace(
        surface,
        dir_from_deg=new_dir % 360.0,
        speed_mps=new_speed,
        # An instrument's speed is the wind now: the report's gust and VRB no longer apply.
        gust_mps=0.0 if speed_mps is not None else surface.gust_mps,
        variable=False if dir_from_deg is not None else surface.variable,
    )
    out = [new_surface]
    for layer in aloft:
        if surface.speed_mps >= 0.5:
            speed = layer.speed_mps * new_speed / surface.speed_mps
        else:  # no meaningful ratio from a calm: shift instead of scaling
            speed = layer.speed_mps + new_speed - surface.speed_mps
        out.append(
            dataclasses.replace(
                layer,
                dir_from_deg=(layer.dir_from_deg + turn_deg) % 360.0,
                speed_mps=min(150.0, max(0.0, speed)),
                gust_mps=min(200.0, layer.gust_mps),
            )
        )
    return tuple(out)


def _layers(below: WeatherState, values: Mapping[str, Any]) -> tuple[CloudLayer, ...]:
    from wxsky.weather.metar_clouds import derived_layer_row, espy_base_m

    existing = [lay for lay in below.layers if lay.cover_oktas > 0.0]
    espy_m = espy_base_m(below.temperature_c, below.dewpoint_c)
    field_m = below.observer.alt_m
    out: list[CloudLayer] = list(existing[COCKPIT_LAYERS:])
    for n in range(1, COCKPIT_LAYERS + 1):
        under = existing[n - 1] if n - 1 < len(existing) else None
        given = {
            part: values[layer_key(n, part)] for part in LAYER_PARTS if layer_key(n, part) in values
        }
        if not given:
            if under is not None:
                out.append(under)
            continue
        cover = float(given.get(LAYER_COVER, under.cover_oktas if under else 0.0))
        if cover <= 0.0:
            continue  # cleared by the cockpit, or a base for a layer with no cloud yet
        base_m = float(
            given.get(
                LAYER_BASE, under.base_m if under else field_m + DEFAULT_LAYER_BASE_AGL_M[n - 1]
            )
        )
        row = derived_layer_row(cover, base_m - field_m, espy_m)
        wanted = given.get(LAYER_TYPE)
        if wanted is not None and wanted is not CloudType.NONE:
            cloud_type = CloudType(wanted)
        elif wanted is None and under is not None:
            cloud_type = under.type
        else:
            cloud_type = row.cloud_type
        if LAYER_THICKNESS in given:
            thickness_m = float(given[LAYER_THICKNESS])
        elif under is not None:
            thickness_m = under.thickness_m
        else:
            thickness_m = row.thickness_m
        top_m = min(base_m + thickness_m, MAX_CLOUD_TOP_M)
        if top_m <= base_m:
            continue
        out.append(CloudLayer(cover, base_m, top_m, cloud_type))
    out.sort(key=lambda lay: lay.base_m)
    return tuple(out[:MAX_LAYERS])
