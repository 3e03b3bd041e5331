"""wxsky's weather as a CIGI host sends it, so an image generator that draws its own clouds
is driven by wxsky's METAR feeds, cockpit knobs and transitions (`[cigi] send_to`,
`wxsky cigi send`).

Each message is a whole picture of the weather, as IG Control, Celestial Sphere Control,
Atmosphere Control and a global Weather Control for every layer id wxsky uses (cloud layers
1-3 and precipitation 4-7), the unused ones with weather disabled, so an IG that missed a
message, or started late, is right again after the next one, and a layer that dissipated is
switched off. CIGI has three cloud layers: of more, the three with the most cover go. When
METAR stations are blended, each is also a region around it holding its own clouds, so an IG
that draws regional weather shows each station's sky near it. Pure.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

from wxsky.protocols.cigi import CigiDatagram, Packet, make, timestamp_10us
from wxsky.weather.atmosphere import humidity_at, temperature_at
from wxsky.weather.state import CloudLayer, PrecipKind, PrecipLayer, WeatherState, dir_from_deg
from wxsky.weather.stations import StationWeather, distance_m

CLOUD_LAYER_IDS = (1, 2, 3)
PCT_PER_OKTA = 100.0 / 8.0
# Precipitation a METAR reports (and no layer gives) falls from the lowest cloud base, or
# from this far above the observer under a sky without clouds.
RAIN_TOP_ABOVE_M = 3000.0
_METAR_PRECIP = MappingProxyType(
    {
        "RA": PrecipKind.RAIN,
        "DZ": PrecipKind.RAIN,
        "SN": PrecipKind.SNOW,
        "SG": PrecipKind.SNOW,
        "PL": PrecipKind.SLEET,
        "GR": PrecipKind.HAIL,
        "GS": PrecipKind.HAIL,
    }
)
MIN_REGION_RADIUS_M = 1000.0  # two stations at one airfield still get a region each
_INTENSITY_SEVERITY = MappingProxyType({"-": 1, "": 3, "+": 5})


@dataclass(frozen=True)
class SourceFrame:
    """The host side's frame bookkeeping: its frame number, and what the IG last said."""

    number: int = 0
    last_ig_frame: int | None = None
    last_response: dict[str, Any] | None = None  # the IG's last Weather Conditions Response

    def next(self) -> SourceFrame:
        return dataclasses.replace(self, number=(self.number + 1) & 0xFFFF_FFFF)

    def heard(self, datagram: CigiDatagram) -> SourceFrame:
        """What an IG→host message tells: its frame number and any weather it answered."""
        out = self
        for p in datagram.packets:
            if p.key == "start_of_frame":
                out = dataclasses.replace(out, last_ig_frame=int(p["ig_frame_number"]))
            elif p.key == "weather_conditions_response":
                out = dataclasses.replace(out, last_response=p.as_dict())
        return out


def host_message(
    state: WeatherState,
    frame: SourceFrame,
    stations: Sequence[StationWeather] = (),
    region_slots: int = 0,
) -> list[Packet]:
    """One host→IG message carrying the whole of `state`; with `region_slots`, the METAR
    stations blended into it as that many regions (`region_packets`)."""
    t = state.time_utc
    obs_alt = state.observer.alt_m
    wind = state.wind[0] if state.wind else None
    out = [
        make(
            "ig_control",
            ig_mode=1,
            timestamp_valid=1,
            host_frame_number=frame.number,
            timestamp_10us=timestamp_10us(time.monotonic()),
            last_ig_frame_number=frame.last_ig_frame or 0,
        ),
        make(
            "celestial_sphere_control",
            hour=t.hour,
            minute=t.minute,
            ephemeris_enable=1,
            sun_enable=1,
            moon_enable=1,
            star_field_enable=1,
            date_time_valid=1,
            date_mmddyyyy=t.month * 1_000_000 + t.day * 10_000 + t.year,
            star_field_intensity_pct=100.0,
        ),
        make(
            "atmosphere_control",
            atmospheric_model_enable=1,
            humidity_pct=round(humidity_at(state, obs_alt)),
            temperature_c=temperature_at(state, obs_alt),
            visibility_m=state.visibility_m,
            wind_speed_mps=wind.speed_mps if wind else 0.0,
            wind_dir_deg=wind.dir_from_deg % 360.0 if wind else 0.0,
            pressure_hpa=state.qnh_hpa,
        ),
    ]
    out += cloud_packets(state, state.layers)
    precip = {p.kind: p for p in precipitation(state)}
    for kind in PrecipKind:
        p = precip.get(kind)
        if p is None:
            out.append(make("weather_control", layer_id=int(kind), weather_enable=0))
            continue
        out.append(
            make(
                "weather_control",
                layer_id=int(kind),
                weather_enable=1,
                severity=p.severity,
                visibility_m=p.visibility_m,
                coverage_pct=p.coverage_pct,
                base_elevation_m=p.base_m,
                thickness_m=p.top_m - p.base_m,
                temperature_c=temperature_at(state, p.base_m),
                pressure_hpa=state.qnh_hpa,
            )
        )
    if region_slots:
        out += region_packets(state, stations, region_slots)
    return out


def cloud_packets(
    state: WeatherState, layers: Sequence[CloudLayer], region_id: int | None = None
) -> list[Packet]:
    """Weather Control for cloud layer ids 1-3 (global, or for a region): of more layers,
    the three with the most cover, numbered by base; ids with nothing on them switched off."""
    scope = {} if region_id is None else {"scope": 1, "entity_or_region_id": region_id}
    clouds = sorted(layers, key=lambda lay: -lay.cover_oktas)[: len(CLOUD_LAYER_IDS)]
    clouds.sort(key=lambda lay: lay.base_m)
    out = []
    for layer_id in CLOUD_LAYER_IDS:
        if layer_id > len(clouds):
            out.append(make("weather_control", layer_id=layer_id, weather_enable=0, **scope))
            continue
        lay = clouds[layer_id - 1]
        mid = (lay.base_m + lay.top_m) / 2.0
        ve, vn = state.wind_at(mid)
        out.append(
            make(
                "weather_control",
                layer_id=layer_id,
                weather_enable=1,
                cloud_type=int(lay.type),
                humidity_pct=100,
                temperature_c=temperature_at(state, mid),
                visibility_m=state.visibility_m,
                coverage_pct=min(100.0, lay.cover_oktas * PCT_PER_OKTA),
                base_elevation_m=lay.base_m,
                thickness_m=lay.thickness_m,
                wind_speed_mps=(ve * ve + vn * vn) ** 0.5,
                wind_dir_deg=dir_from_deg(ve, vn) if ve or vn else 0.0,
                pressure_hpa=state.qnh_hpa,
                **scope,
            )
        )
    return out


def region_radius_m(stations: Sequence[StationWeather]) -> list[float]:
    """Each station's region: round, a quarter of the way to its nearest blended neighbour,
    with a transition perimeter as wide again, so two neighbours' regions meet halfway and
    an IG blends each station's clouds into the global (blended) weather between them."""
    out = []
    for i, s in enumerate(stations):
        others = [
            distance_m(s.lat_deg, s.lon_deg, o.lat_deg, o.lon_deg)
            for j, o in enumerate(stations)
            if j != i
        ]
        out.append(max(MIN_REGION_RADIUS_M, min(others, default=0.0) / 4.0))
    return out


def region_packets(
    state: WeatherState, stations: Sequence[StationWeather], slots: int
) -> list[Packet]:
    """Environmental Region Control for region ids 1..slots, one a station with its own
    cloud layers as regional Weather Control; ids with no station sent destroyed, so a
    station that left the blend leaves the IG too."""
    out: list[Packet] = []
    radii = region_radius_m(stations[:slots])
    for i in range(slots):
        rid = i + 1
        if i >= len(radii):
            out.append(make("environmental_region_control", region_id=rid, region_state=2))
            continue
        s, r = stations[i], radii[i]
        out.append(
            make(
                "environmental_region_control",
                region_id=rid,
                region_state=1,
                lat_deg=s.lat_deg,
                lon_deg=s.lon_deg,
                size_x_m=2.0 * r,
                size_y_m=2.0 * r,
                corner_radius_m=r,
                transition_perimeter_m=r,
            )
        )
        # A report without a sky group says nothing of the clouds: the global ones hold there.
        if s.patch.layers is not None:
            out += cloud_packets(state, s.patch.layers, rid)
    return out


def precipitation(state: WeatherState) -> tuple[PrecipLayer, ...]:
    """The state's precipitation layers, or those its METAR weather groups report."""
    if state.precipitation:
        return state.precipitation
    out: dict[PrecipKind, PrecipLayer] = {}
    top = state.layers[0].base_m if state.layers else state.observer.alt_m + RAIN_TOP_ABOVE_M
    base = state.observer.alt_m
    for group in state.present_weather:
        intensity = group[0] if group[:1] in ("-", "+") else ""
        codes = group.lstrip("+-")
        for i in range(0, len(codes) - 1, 2):
            kind = _METAR_PRECIP.get(codes[i : i + 2])
            if kind is not None and kind not in out and top > base:
                out[kind] = PrecipLayer(
                    kind,
                    base,
                    top,
                    100.0,
                    _INTENSITY_SEVERITY[intensity],
                    state.visibility_m,
                )
    return tuple(out.values())
