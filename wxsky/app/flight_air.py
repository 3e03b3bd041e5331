"""The air at the host's aircraft, in every frame's notification (`air`; issue 45,
docs/weather-aloft.md): the wind from the weather's profile (the model's, where model data is read),
the gust of the turbulence there (`scene/turbulence.py`), the temperature and an icing flag,
so a host's flight model flies in the weather its pilot sees.

The aircraft is where `set_aircraft` (a host, CIGI's ownship, FlightGear's pose) put it, else
the camera. Per frame: the wind and the gust (a few hundred multiplications). What needs the
clouds (in cloud or not, which cloud, the temperature there) is looked up on a thread at most
`LOOKUP_HZ` times a second, the frames taking the last answer: a frame never waits on it.
"""

from __future__ import annotations

import concurrent.futures
import math
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from wxsky.engine.stages import FramePlan, SkyEngine
from wxsky.scene.conditions import BlockMemo, conditions_at
from wxsky.scene.turbulence import gust_mps, icing, roughness
from wxsky.weather.model_profile import temperature_at_height
from wxsky.weather.state import CloudType, WeatherState

LOOKUP_HZ = 5.0


@dataclass(frozen=True)
class _Lookup:
    cloud_type: CloudType | None
    temperature_c: float
    cloud_water_gpm3: float


class FlightAir:
    """One per daemon; `for_frame` from the loop, after each frame is published."""

    def __init__(self) -> None:
        self._pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="wxsky-air")
        self._pending: concurrent.futures.Future[_Lookup] | None = None
        self._look: _Lookup | None = None
        self._asked_s = -math.inf
        self._flown_m = 0.0  # how far the aircraft has gone through the air
        self._heading = (0.0, 1.0)  # its way through the air, a unit (east, north) vector
        self._last: tuple[datetime, tuple[float, float, float]] | None = None
        self._memo: tuple[int, BlockMemo] | None = None

    def close(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)

    def for_frame(self, plan: FramePlan, engine: SkyEngine, wall_s: float) -> dict[str, Any]:
        state = plan.state
        point = engine.aircraft_m or engine.camera.position_m
        alt = point[2]
        wind_e, wind_n = state.wind_at(alt)
        self._fly(state.time_utc, point, wind_e, wind_n)
        self._look_up(state, point, engine, wall_s)
        look = self._look
        ground = state.observer.alt_m
        rough = roughness(state, alt, ground, None if look is None else look.cloud_type)
        along, across, up = gust_mps(state.seed, self._flown_m, rough.sigma_w_mps, alt - ground)
        he, hn = self._heading
        # along the way through the air, and across it to the right
        gust = (along * he + across * hn, along * hn - across * he, up)
        temperature = None if look is None else look.temperature_c
        in_cloud = look is not None and look.cloud_type is not None
        return {
            "at_m": [round(v, 2) for v in point],
            "wind_mps": [round(wind_e, 3), round(wind_n, 3), 0.0],
            "gust_mps": [round(g, 3) for g in gust],
            "turbulence": {
                "sigma_w_mps": round(rough.sigma_w_mps, 3),
                "category": rough.category,
                "causes": {k: round(v, 3) for k, v in rough.causes.items()},
            },
            "temperature_c": None if temperature is None else round(temperature, 2),
            "in_cloud": in_cloud,
            "cloud_water_gpm3": 0.0 if look is None else round(look.cloud_water_gpm3, 3),
            "icing": temperature is not None and icing(in_cloud, temperature),
        }

    def _fly(
        self, time_utc: datetime, point: tuple[float, float, float], wind_e: float, wind_n: float
    ) -> None:
        """The aircraft's way through the air since the last frame: its own move less the
        air's (standing in a wind, the air goes by it)."""
        last, self._last = self._last, (time_utc, point)
        if last is None:
            return
        dt = (time_utc - last[0]).total_seconds()
        if not 0.0 < dt < 60.0:  # a clock set far away is a new start, not a long flight
            return
        de = point[0] - last[1][0] - wind_e * dt
        dn = point[1] - last[1][1] - wind_n * dt
        du = point[2] - last[1][2]
        way = math.sqrt(de * de + dn * dn + du * du)
        if way > 1e6:  # the site moved: not flown
            return
        self._flown_m += way
        level = math.hypot(de, dn)
        if level > 1e-3:
            self._heading = (de / level, dn / level)

    def _look_up(
        self,
        state: WeatherState,
        point: tuple[float, float, float],
        engine: SkyEngine,
        wall_s: float,
    ) -> None:
        pending = self._pending
        if pending is not None and pending.done():
            self._pending = None
            if pending.exception() is None:
                self._look = pending.result()
        if self._pending is not None or wall_s - self._asked_s < 1.0 / LOOKUP_HZ:
            return
        self._asked_s = wall_s
        aloft = engine.aloft_temperatures
        self._pending = self._pool.submit(self._answer, state, engine.drift, point, aloft)

    def _answer(
        self,
        state: WeatherState,
        drift: Any,
        point: tuple[float, float, float],
        aloft: tuple[tuple[float, float], ...],
    ) -> _Lookup:
        key = id(state)
        if self._memo is None or self._memo[0] != key:
            self._memo = (key, BlockMemo())
        got = conditions_at(state, drift, point, self._memo[1])
        water = got.cloud_water_gpm3
        kind = None
        if got.in_cloud and water:
            wettest = max(range(len(water)), key=lambda i: water[i])
            kind = state.layers[wettest].type if wettest < len(state.layers) else None
        temperature = temperature_at_height(aloft, point[2])
        return _Lookup(
            kind,
            got.temperature_c if temperature is None else temperature,
            max(water, default=0.0),
        )
