"""Sun position and the sky-dome parameters derived from it (Roden & Parberry's controls).

The sun follows NOAA's low-precision solar position algorithm (about 0.01° in declination
over 1950-2050), which is plenty for lighting clouds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import UTC, datetime

import numpy as np

from wxsky.weather.state import WeatherState

RGB = tuple[float, float, float]


@dataclass(frozen=True)
class SunPosition:
    elevation_deg: float
    azimuth_deg: float  # from true north, clockwise

    @property
    def direction_enu(self) -> tuple[float, float, float]:
        """Unit vector from the observer towards the sun (east, north, up)."""
        el, az = math.radians(self.elevation_deg), math.radians(self.azimuth_deg)
        return (math.cos(el) * math.sin(az), math.cos(el) * math.cos(az), math.sin(el))


@dataclass(frozen=True)
class SkyParams:
    """Everything the sky pass and cloud shading need; also published to hosts."""

    sun: SunPosition
    zenith_rgb: RGB
    horizon_rgb: RGB
    ground_rgb: RGB
    sun_rgb: RGB  # colour of direct sunlight on clouds
    ambient: float  # 0 (night) .. 1 (full day): scales the clouds' ambient colour levels
    sunset: float  # 0..1: how much of the red sunset gradient tints the sky and clouds
    cover: float  # 0..1: total cloud cover, Roden & Parberry's "cover" control
    haze_m: float  # distance over which clouds fade into the horizon colour

    def to_dict(self) -> dict[str, object]:
        return {
            "sun_elevation_deg": self.sun.elevation_deg,
            "sun_azimuth_deg": self.sun.azimuth_deg,
            "sun_direction_enu": list(self.sun.direction_enu),
            "zenith_rgb": list(self.zenith_rgb),
            "horizon_rgb": list(self.horizon_rgb),
            "ground_rgb": list(self.ground_rgb),
            "sun_rgb": list(self.sun_rgb),
            "ambient": self.ambient,
            "sunset": self.sunset,
            "cover": self.cover,
            "haze_m": self.haze_m,
        }


def sun_position(time_utc: datetime, lat_deg: float, lon_deg: float) -> SunPosition:
    t = time_utc.astimezone(UTC)
    day_of_year = t.timetuple().tm_yday
    hours = t.hour + t.minute / 60.0 + (t.second + t.microsecond * 1e-6) / 3600.0
    year_days = 366 if _is_leap(t.year) else 365
    gamma = 2.0 * math.pi / year_days * (day_of_year - 1 + (hours - 12.0) / 24.0)
    eqtime_min = 229.18 * (
        0.000075
        + 0.001868 * math.cos(gamma)
        - 0.032077 * math.sin(gamma)
        - 0.014615 * math.cos(2 * gamma)
        - 0.040849 * math.sin(2 * gamma)
    )
    decl = (
        0.006918
        - 0.399912 * math.cos(gamma)
        + 0.070257 * math.sin(gamma)
        - 0.006758 * math.cos(2 * gamma)
        + 0.000907 * math.sin(2 * gamma)
        - 0.002697 * math.cos(3 * gamma)
        + 0.00148 * math.sin(3 * gamma)
    )
    true_solar_min = hours * 60.0 + eqtime_min + 4.0 * lon_deg
    hour_angle = math.radians(true_solar_min / 4.0 - 180.0)
    lat = math.radians(lat_deg)
    cos_zen = math.sin(lat) * math.sin(decl) + math.cos(lat) * math.cos(decl) * math.cos(hour_angle)
    zen = math.acos(max(-1.0, min(1.0, cos_zen)))
    # Azimuth from the east/north components of the sun vector, which stays stable at the poles.
    east = -math.cos(decl) * math.sin(hour_angle)
    north = math.cos(lat) * math.sin(decl) - math.sin(lat) * math.cos(decl) * math.cos(hour_angle)
    az = math.degrees(math.atan2(east, north)) % 360.0
    return SunPosition(elevation_deg=90.0 - math.degrees(zen), azimuth_deg=az)


def sky_params(state: WeatherState) -> SkyParams:
    sun = sun_position(state.time_utc, state.observer.lat_deg, state.observer.lon_deg)
    el = sun.elevation_deg
    day = _smoothstep(-6.0, 10.0, el)  # civil twilight to well-lit day
    sunset = _smoothstep(-8.0, 0.0, el) * (1.0 - _smoothstep(2.0, 18.0, el))
    # Layers overlap at random (the usual assumption for total cloud amount): two 4/8 layers
    # hide 3/4 of the sky, not all of it, so a forming layer darkens the sky gradually.
    clear = math.prod(1.0 - min(1.0, lay.cover_oktas / 8.0) for lay in state.layers)
    cover = 1.0 - clear
    overcast_dim = 1.0 - 0.45 * _smoothstep(0.6, 1.0, cover)

    night_zenith, night_horizon = (0.008, 0.012, 0.035), (0.025, 0.035, 0.07)
    day_zenith, day_horizon = (0.20, 0.40, 0.78), (0.68, 0.80, 0.94)
    zenith = _mix(night_zenith, day_zenith, day)
    horizon = _mix(night_horizon, day_horizon, day)
    horizon = _mix(horizon, (0.98, 0.58, 0.32), sunset * 0.85)
    zenith = _mix(zenith, (0.28, 0.30, 0.52), sunset * 0.4)
    grey = (0.55, 0.57, 0.60)
    zenith = _mix(zenith, _scale(grey, day + 0.05), _smoothstep(0.6, 1.0, cover) * 0.8)
    horizon = _mix(horizon, _scale(grey, day + 0.05), _smoothstep(0.6, 1.0, cover) * 0.6)
    zenith, horizon = _scale(zenith, overcast_dim), _scale(horizon, overcast_dim)
    ground = _scale((0.30, 0.31, 0.28), 0.08 + 0.92 * day)
    sun_rgb = _mix((1.0, 0.98, 0.92), (1.0, 0.55, 0.25), sunset)
    sun_rgb = _scale(sun_rgb, _smoothstep(-2.0, 4.0, el))
    return SkyParams(
        sun=sun,
        zenith_rgb=zenith,
        horizon_rgb=horizon,
        ground_rgb=ground,
        sun_rgb=sun_rgb,
        ambient=0.06 + 0.94 * day,
        sunset=sunset,
        cover=cover,
        haze_m=max(2_000.0, 3.0 * state.visibility_m),
    )


def _is_leap(year: int) -> bool:
    return year % 4 == 0 and (year % 100 != 0 or year % 400 == 0)


def _smoothstep(lo: float, hi: float, x: float) -> float:
    t = float(np.clip((x - lo) / (hi - lo), 0.0, 1.0))
    return t * t * (3.0 - 2.0 * t)


def _mix(a: RGB, b: RGB, t: float) -> RGB:
    return (a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t, a[2] + (b[2] - a[2]) * t)


def _scale(a: RGB, k: float) -> RGB:
    return (a[0] * k, a[1] * k, a[2] * k)
