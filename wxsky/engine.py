"""The fixed stage order from weather to a drawable frame, shared by the daemon and snapshot:

    weather state -> simulation clock -> wind drift -> sky -> impostor ring (when stale) -> frame

Each stage takes immutable values and returns immutable values; the engine only remembers the
latest ones. No GL and no I/O here: the renderer consumes the `FramePlan`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from datetime import datetime, timedelta

from wxsky.scene.camera import Camera
from wxsky.scene.layout import (
    Drift,
    FrameScene,
    RingScene,
    SceneSettings,
    advance_drift,
    build_frame,
    build_ring,
    zero_drift,
)
from wxsky.scene.sky import SkyParams, sky_params
from wxsky.weather.state import Source, WeatherPatch, WeatherState

# Rebuild the ring once the clouds in it have drifted this share of its radius, or the sun
# has moved this far: past these, the seam between near sprites and impostors shows.
RING_DRIFT_FRAC = 0.03
RING_SUN_DEG = 1.0
METRES_PER_DEG_LAT = 110_540.0
METRES_PER_DEG_LON_EQUATOR = 111_320.0


@dataclass(frozen=True)
class FramePlan:
    """Everything one published frame is drawn from."""

    state: WeatherState  # with time_utc set to the frame's simulated time
    frame: FrameScene
    ring: RingScene
    ring_version: int
    ring_changed: bool  # the ring must be redrawn for this frame


class SkyEngine:
    def __init__(
        self,
        state: WeatherState,
        camera: Camera,
        settings: SceneSettings,
        clock_rate: float = 1.0,
    ) -> None:
        self._state = state
        self._camera = camera
        self.settings = settings
        self.clock_rate = clock_rate
        self._drift: Drift = zero_drift(state)
        self._ring: RingScene | None = None
        self._ring_state: WeatherState | None = None
        self._ring_sun_dir: tuple[float, float, float] = (0.0, 0.0, 1.0)
        self._ring_version = 0
        self.weather_version = 0

    @property
    def state(self) -> WeatherState:
        return self._state

    @property
    def camera(self) -> Camera:
        return self._camera

    @property
    def ring(self) -> RingScene | None:
        """The ring the latest frame was drawn with (None before the first frame)."""
        return self._ring

    @property
    def ring_version(self) -> int:
        return self._ring_version

    def apply(self, patch: WeatherPatch) -> WeatherState:
        """Merge an input's patch; the clouds keep drifting from where they are."""
        new = self._state.apply(patch)
        if new is not self._state:
            if len(new.layers) != len(self._state.layers):
                self._drift = zero_drift(new)
            self._state = new
            self.weather_version += 1
        return new

    def set_camera(self, camera: Camera) -> None:
        self._camera = camera

    def set_time(
        self, time_utc: datetime, rate: float | None = None, source: Source = Source.CONTROL
    ) -> None:
        self.apply(WeatherPatch(source=source, time_utc=time_utc))
        if rate is not None:
            self.clock_rate = rate

    def advance(self, dt_wall_s: float) -> FramePlan:
        """Run the stages for a frame dt_wall_s after the previous one."""
        dt_sim = max(0.0, dt_wall_s) * self.clock_rate
        if dt_sim > 0.0:
            self._state = dataclasses.replace(
                self._state, time_utc=self._state.time_utc + timedelta(seconds=dt_sim)
            )
            self._drift = advance_drift(self._state, self._drift, dt_sim)
        sky = sky_params(self._state)
        ring, changed = self._ring_for(sky)
        frame = build_frame(
            self._state,
            self._drift,
            self._camera,
            ring.geometry.centre_m,
            sky,
            self.settings,
            ring_drift=ring.drift,
        )
        return FramePlan(self._state, frame, ring, self._ring_version, changed)

    def _ring_for(self, sky: SkyParams) -> tuple[RingScene, bool]:
        ring = self._ring
        if ring is not None and not self._ring_stale(ring, sky):
            return ring, False
        ring = build_ring(self._state, self._drift, self._camera.position_m, sky, self.settings)
        self._ring = ring
        self._ring_state = self._state
        self._ring_sun_dir = sky.sun.direction_enu
        self._ring_version += 1
        return ring, True

    def _ring_stale(self, ring: RingScene, sky: SkyParams) -> bool:
        built = self._ring_state
        if built is None or _weather_differs(built, self._state):
            return True
        if ring.geometry.needs_regeneration(self._camera.position_m):
            return True
        cos_sun = sum(a * b for a, b in zip(sky.sun.direction_enu, self._ring_sun_dir, strict=True))
        if math.degrees(math.acos(max(-1.0, min(1.0, cos_sun)))) > RING_SUN_DEG:
            return True
        limit = RING_DRIFT_FRAC * self.settings.ring_radius_m
        return len(ring.drift) != len(self._drift) or any(
            math.hypot(a[0] - b[0], a[1] - b[1]) > limit
            for a, b in zip(ring.drift, self._drift, strict=True)
        )


def _weather_differs(a: WeatherState, b: WeatherState) -> bool:
    """True when anything but the clock differs (time alone is covered by the sun test)."""
    return dataclasses.replace(a, time_utc=b.time_utc, sources=b.sources) != b


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
