"""The air at a height, from the weather at the ground: temperature, dew point, pressure and
relative humidity by the ICAO standard atmosphere's lapse rates, for a host that asks what
its aircraft flies through (CIGI's Weather Conditions Response). Pure.

The state's temperature and dew point are the observer's (a METAR's are at the field); its
QNH is the pressure reduced to sea level. Above the observer the temperature falls at the
standard 6.5 K/km and the dew point at 2 K/km (the dew-point lapse of unsaturated air), so
relative humidity rises with height as it does in a well-mixed boundary layer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from wxsky.weather.state import TEMPERATURE_C, WeatherState

LAPSE_K_PER_M = 0.0065  # ICAO standard troposphere
DEWPOINT_LAPSE_K_PER_M = 0.002
TROPOPAUSE_M = 11_000.0  # the temperature stays constant above it
ISA_SEA_LEVEL_K = 288.15
# g·M/(R·L) of the barometric formula in the troposphere
BARO_EXPONENT = 5.25588
# Magnus' formula over water (Alduchov and Eskridge 1996)
MAGNUS_B = 17.625
MAGNUS_C_K = 243.04
MIN_HUMIDITY_PCT = 1.0  # a dew point for 0 % does not exist; drier than 1 % is 1 %


def temperature_at(state: WeatherState, alt_m: float) -> float:
    """Air temperature in °C at alt_m MSL (the state's own below the observer)."""
    base = 15.0 if state.temperature_c is None else state.temperature_c
    return _lapsed(base, state.observer.alt_m, alt_m, LAPSE_K_PER_M)


def dewpoint_at(state: WeatherState, alt_m: float) -> float:
    """Dew point in °C at alt_m MSL, never above the temperature there."""
    temp = temperature_at(state, alt_m)
    if state.dewpoint_c is None:
        return temp - 10.0
    dew = _lapsed(state.dewpoint_c, state.observer.alt_m, alt_m, DEWPOINT_LAPSE_K_PER_M)
    return min(dew, temp)


def humidity_at(state: WeatherState, alt_m: float) -> float:
    """Relative humidity in percent (0-100) at alt_m MSL."""
    return relative_humidity_pct(temperature_at(state, alt_m), dewpoint_at(state, alt_m))


def pressure_at(state: WeatherState, alt_m: float) -> float:
    """Static pressure in hPa at alt_m MSL from the QNH (standard troposphere, and its
    isothermal layer above 11 km)."""
    h = min(alt_m, TROPOPAUSE_M)
    p = float(state.qnh_hpa * (1.0 - LAPSE_K_PER_M * h / ISA_SEA_LEVEL_K) ** BARO_EXPONENT)
    if alt_m > TROPOPAUSE_M:
        t_k = ISA_SEA_LEVEL_K - LAPSE_K_PER_M * TROPOPAUSE_M
        p *= math.exp(-9.80665 * (alt_m - TROPOPAUSE_M) / (287.053 * t_k))
    return p


def relative_humidity_pct(temperature_c: float, dewpoint_c: float) -> float:
    """Relative humidity (Magnus) of air at a temperature and dew point, 0-100."""
    if dewpoint_c >= temperature_c:
        return 100.0
    ratio = math.exp(
        MAGNUS_B * dewpoint_c / (MAGNUS_C_K + dewpoint_c)
        - MAGNUS_B * temperature_c / (MAGNUS_C_K + temperature_c)
    )
    return max(0.0, min(100.0, 100.0 * ratio))


def dewpoint_from_humidity(temperature_c: float, humidity_pct: float) -> float:
    """The dew point (Magnus) of air at a temperature and relative humidity, kept within the
    weather state's temperature limits."""
    rh = max(MIN_HUMIDITY_PCT, min(100.0, humidity_pct)) / 100.0
    gamma = math.log(rh) + MAGNUS_B * temperature_c / (MAGNUS_C_K + temperature_c)
    dew = MAGNUS_C_K * gamma / (MAGNUS_B - gamma)
    lo, hi = TEMPERATURE_C.lo, TEMPERATURE_C.hi
    assert lo is not None and hi is not None
    return max(lo, min(hi, temperature_c, dew))


def _lapsed(value: float, from_m: float, to_m: float, lapse: float) -> float:
    """`value` carried from from_m to to_m at `lapse` per metre (none above the tropopause,
    none below the starting height)."""
    rise = min(to_m, TROPOPAUSE_M) - from_m
    return value - lapse * max(0.0, rise)


@dataclass(frozen=True)
class PointWeather:
    """The weather at one point, as a host's flight model asks for it: the air there, and
    for each cloud layer (by rank from the lowest, 1 first) its liquid water in g/m³ at the
    point (0 outside its clouds)."""

    temperature_c: float
    humidity_pct: float
    visibility_m: float  # in-cloud visibility when the point is in cloud
    wind_speed_mps: float  # horizontal
    wind_dir_deg: float  # from, true
    pressure_hpa: float
    in_cloud: bool
    cloud_water_gpm3: tuple[float, ...]


def air_at(state: WeatherState, alt_m: float) -> tuple[float, float, float]:
    """(temperature °C, relative humidity %, pressure hPa) at alt_m MSL."""
    return temperature_at(state, alt_m), humidity_at(state, alt_m), pressure_at(state, alt_m)
