"""Places around the observer on a flat local frame: east-north-up metres from latitude and
longitude and back. Good to about 0.1 % within 100 km, which is as far as a local frame is
used (`engine.stages.REORIGIN_M`); pure.
"""

from __future__ import annotations

import math

METRES_PER_DEG_LAT = 110_540.0
METRES_PER_DEG_LON_EQUATOR = 111_320.0


def enu_from_geodetic(
    observer_lat_deg: float, observer_lon_deg: float, lat_deg: float, lon_deg: float, alt_m: float
) -> tuple[float, float, float]:
    """Local flat-earth position of a point around the observer (good to ~0.1 % within 100 km)."""
    east = (
        (lon_deg - observer_lon_deg)
        * METRES_PER_DEG_LON_EQUATOR
        * math.cos(math.radians(observer_lat_deg))
    )
    north = (lat_deg - observer_lat_deg) * METRES_PER_DEG_LAT
    return (east, north, alt_m)


def geodetic_from_enu(
    observer_lat_deg: float, observer_lon_deg: float, east_m: float, north_m: float
) -> tuple[float, float]:
    """(lat, lon) of a local point; the inverse of `enu_from_geodetic`."""
    lat = observer_lat_deg + north_m / METRES_PER_DEG_LAT
    per_deg_lon = METRES_PER_DEG_LON_EQUATOR * max(1e-6, math.cos(math.radians(observer_lat_deg)))
    lon = observer_lon_deg + east_m / per_deg_lon
    lon = (lon + 180.0) % 360.0 - 180.0
    return (max(-90.0, min(90.0, lat)), lon)
