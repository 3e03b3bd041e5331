"""The host emulator's flight (tools/emulators/cigi_host.py): one table of phases, and the CIGI 3.3
packets a host sends at a moment of it.

Zurich (LSZH), 21 June 2026. The ownship taxis along runway 16, takes off and climbs through a
stratocumulus deck; a thunderstorm region comes up 15 km ahead; the clock jumps to dusk; the
deck thickens and lowers. Each row says everything that holds during its phase, so one row
reads alone: the ownship's path along the runway's line (metres from the airport's reference
point) and altitude, both linear within the phase, the host's clock, the deck (global Weather
Control layer 1) and whether the storm (region 1 and its cumulonimbus, regional layer 2) is
on. The ownship flies on toward the storm and is inside its transition perimeter for the last
half minute (half of the way in at the end), so an IG shows the cumulonimbus blending in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from wxsky.protocols.cigi import Packet, make
from wxsky.weather.geo import geodetic_from_enu

AIRPORT_LAT, AIRPORT_LON = 47.4647, 8.5492  # LSZH, also wxsky's default observer
RUNWAY_DEG = 154.0  # runway 16, true
DATE_MMDDYYYY = 6_21_2026  # MM·1 000 000 + DD·10 000 + YYYY: 21 June 2026
STORM_AHEAD_M = 15_000.0  # the storm's centre, ahead of where its phase starts
STORM_SIZE_M = 10_000.0
STORM_PERIMETER_M = 8_000.0  # its weather fades in across this band outside the square
VIEW_HALF_DEG = (30.0, 18.0)  # View Definition half-angles: 60° wide, 16:9


@dataclass(frozen=True)
class Phase:
    name: str
    length_s: float
    along_m: tuple[float, float]  # on runway 16's line from the airport, start -> end
    alt_m: tuple[float, float]  # MSL, start -> end
    clock_utc: tuple[int, int]  # hour, minute
    deck: tuple[float, float, float]  # stratocumulus layer 1: coverage %, base m, thickness m
    storm: bool


# fmt: off
SCRIPT: tuple[Phase, ...] = (
    #     name                  s   along_m         alt_m         clock     deck (%, m, m)   storm
    Phase("taxi",               10, (-1800, -1700), (435, 435),   (14, 0),  (60, 1200, 600), False),
    Phase("takeoff",            20, (-1700, -700),  (435, 470),   (14, 0),  (60, 1200, 600), False),
    Phase("climb through Sc",   60, (-700, 5300),   (470, 2100),  (14, 0),  (60, 1200, 600), False),
    Phase("thunderstorm ahead", 30, (5300, 8900),   (2100, 2400), (14, 0),  (60, 1200, 600), True),
    Phase("time jump to dusk",  10, (8900, 10100),  (2400, 2400), (19, 45), (60, 1200, 600), True),
    Phase("weather change",     10, (10100, 11300), (2400, 2400), (19, 45), (90, 900, 700),  True),
)
# fmt: on
LENGTH_S = sum(p.length_s for p in SCRIPT)
# Where the storm phase starts along the line; the storm sits STORM_AHEAD_M beyond it.
STORM_ALONG_M = next(p.along_m[0] for p in SCRIPT if p.storm) + STORM_AHEAD_M


@dataclass(frozen=True)
class Moment:
    """Where the script is `t_s` seconds in."""

    phase: Phase
    lat_deg: float
    lon_deg: float
    alt_m: float
    pitch_deg: float


def _lerp(ends: tuple[float, float], t: float) -> float:
    return ends[0] + (ends[1] - ends[0]) * t


def on_runway_line(along_m: float) -> tuple[float, float]:
    """(lat, lon) of a point `along_m` along runway 16's line from the airport."""
    heading = math.radians(RUNWAY_DEG)
    east, north = along_m * math.sin(heading), along_m * math.cos(heading)
    return geodetic_from_enu(AIRPORT_LAT, AIRPORT_LON, east, north)


def moment(t_s: float) -> Moment:
    """The script at `t_s` (past the end: its last moment)."""
    start = 0.0
    for phase in SCRIPT:
        if t_s < start + phase.length_s or phase is SCRIPT[-1]:
            t = min(1.0, max(0.0, (t_s - start) / phase.length_s))
            lat, lon = on_runway_line(_lerp(phase.along_m, t))
            # Nose along the flight path: a host's aircraft model is beyond this script.
            climb, run = phase.alt_m[1] - phase.alt_m[0], phase.along_m[1] - phase.along_m[0]
            pitch = math.degrees(math.atan2(climb, abs(run)))
            return Moment(phase, lat, lon, _lerp(phase.alt_m, t), pitch)
        start += phase.length_s
    raise AssertionError("SCRIPT is empty")


def ownship(m: Moment) -> Packet:
    return make(
        "entity_control",
        entity_id=0,
        entity_state=1,
        pitch_deg=m.pitch_deg,
        yaw_deg=RUNWAY_DEG,
        lat_deg=m.lat_deg,
        lon_deg=m.lon_deg,
        alt_m=m.alt_m,
    )


def view_definition() -> Packet:
    wide, high = VIEW_HALF_DEG
    return make(
        "view_definition",
        view_id=0,
        near_enable=1,
        far_enable=1,
        left_enable=1,
        right_enable=1,
        top_enable=1,
        bottom_enable=1,
        near_m=0.5,
        far_m=200_000.0,
        left_deg=-wide,
        right_deg=wide,
        top_deg=high,
        bottom_deg=-high,
    )


def conditions_request(m: Moment, request_id: int) -> Packet:
    return make(
        "environmental_conditions_request",
        request_weather=1,
        request_aerosol=1,
        request_id=request_id % 256,
        lat_deg=m.lat_deg,
        lon_deg=m.lon_deg,
        alt_m=m.alt_m,
    )


def world(phase: Phase, set_clock: bool) -> list[Packet]:
    """The stateful packets for a phase: clock, atmosphere, the deck and the storm.
    `set_clock` sets the IG's clock (date_time_valid); otherwise the IG keeps running its
    own from the last time set, as CIGI's ephemeris does."""
    hour, minute = phase.clock_utc
    cover, base, thickness = phase.deck
    out = [
        make(
            "celestial_sphere_control",
            hour=hour,
            minute=minute,
            ephemeris_enable=1,
            sun_enable=1,
            moon_enable=1,
            star_field_enable=1,
            date_time_valid=int(set_clock),
            date_mmddyyyy=DATE_MMDDYYYY,
            star_field_intensity_pct=100.0,
        ),
        make(
            "atmosphere_control",
            atmospheric_model_enable=1,
            humidity_pct=60,
            temperature_c=22.0,
            visibility_m=30_000.0,
            wind_speed_mps=4.0,
            wind_dir_deg=240.0,
            pressure_hpa=1016.0,
        ),
        _layer(1, cloud_type=9, cover=cover, base=base, thickness=thickness, wind=(250, 8)),
    ]
    if phase.storm:
        lat, lon = on_runway_line(STORM_ALONG_M)
        out += [
            make(
                "environmental_region_control",
                region_id=1,
                region_state=1,
                lat_deg=lat,
                lon_deg=lon,
                size_x_m=STORM_SIZE_M,
                size_y_m=STORM_SIZE_M,
                corner_radius_m=1000.0,
                rotation_deg=RUNWAY_DEG,
                transition_perimeter_m=STORM_PERIMETER_M,
            ),
            _layer(2, cloud_type=6, cover=80, base=900, thickness=9000, wind=(230, 15), region=1),
        ]
    return out


def _layer(
    layer_id: int,
    *,
    cloud_type: int,
    cover: float,
    base: float,
    thickness: float,
    wind: tuple[float, float],
    region: int = 0,
) -> Packet:
    return make(
        "weather_control",
        entity_or_region_id=region,
        layer_id=layer_id,
        humidity_pct=95,
        weather_enable=1,
        cloud_type=cloud_type,
        scope=1 if region else 0,
        severity=4 if cloud_type == 6 else 1,
        temperature_c=10.0,
        visibility_m=800.0,  # inside the cloud
        coverage_pct=cover,
        base_elevation_m=base,
        thickness_m=thickness,
        transition_band_m=100.0,
        wind_speed_mps=wind[1],
        wind_dir_deg=wind[0],
        pressure_hpa=850.0,
    )
