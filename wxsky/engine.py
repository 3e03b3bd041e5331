"""The fixed stage order from weather to a drawable frame, shared by the daemon and snapshot:

    sources -> target weather -> transition -> clock -> wind drift -> sky -> ring -> frame

Inputs give patches; each lands in its source's slot (`precedence.SourceStack`), which yields
the target weather. The applied weather moves toward the target at bounded rates
(`transition.step_toward`), once per `transition_step_s` so the ring is not rebuilt every
frame while a change is under way; the scene reads only the applied weather.

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
    carry_drift,
    zero_drift,
)
from wxsky.scene.sky import SkyParams, sky_params
from wxsky.weather.precedence import DEFAULT_COCKPIT_HOLD_S, SourceStack
from wxsky.weather.state import Source, WeatherPatch, WeatherState
from wxsky.weather.transition import INSTANT, TransitionRates, settled, step_toward

# Rebuild the ring once the clouds in it have drifted this share of its radius, or the sun
# has moved this far: past these, the seam between near sprites and impostors shows.
RING_DRIFT_FRAC = 0.03
RING_SUN_DEG = 1.0
METRES_PER_DEG_LAT = 110_540.0
METRES_PER_DEG_LON_EQUATOR = 111_320.0
DEFAULT_TRANSITION_STEP_S = 1.0


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
        rates: TransitionRates = INSTANT,
        transition_step_s: float = DEFAULT_TRANSITION_STEP_S,
        cockpit_hold_s: float = DEFAULT_COCKPIT_HOLD_S,
    ) -> None:
        """`state` is the base weather (defaults and the startup preset), also the first
        applied weather. Rates default to instant, which suits one-off snapshots."""
        self._stack = SourceStack(base=state, cockpit_hold_s=cockpit_hold_s)
        self._state = state  # applied
        self._target = state
        self._settled = True
        self._camera = camera
        self.settings = settings
        self.clock_rate = clock_rate
        self.rates = rates
        self.transition_step_s = transition_step_s
        self._wall_s = 0.0
        self._since_step_s = 0.0
        self._drift: Drift = zero_drift(state)
        self._ring: RingScene | None = None
        self._ring_state: WeatherState | None = None
        self._ring_sun_dir: tuple[float, float, float] = (0.0, 0.0, 1.0)
        self._ring_version = 0
        self.weather_version = 0

    @property
    def state(self) -> WeatherState:
        """The applied weather: what the scene is drawn from."""
        return self._state

    @property
    def target(self) -> WeatherState:
        """The weather the sources ask for; the applied weather moves toward it."""
        return self._target

    @property
    def settled(self) -> bool:
        """The applied weather has reached the target (kept up to date on every change, so
        the per-frame check compares nothing)."""
        return self._settled

    @property
    def sources(self) -> SourceStack:
        return self._stack

    @property
    def wall_s(self) -> float:
        """Wall-clock seconds the engine has advanced (the time base of cockpit holds)."""
        return self._wall_s

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
        """Put an input's patch into its source's slot; returns the new target. A time in the
        patch sets the clock at once."""
        if patch.time_utc is not None:
            self.set_time(patch.time_utc, source=patch.source)
        self._stack = self._stack.with_patch(patch, self._wall_s)
        self._retarget()
        return self._target

    def release(self, source: Source) -> tuple[str, ...]:
        """Hand the fields a control or cockpit source holds back to the sources below it."""
        self._stack, fields = self._stack.released(source)
        self._retarget()
        return fields

    def settle(self) -> None:
        """Jump the applied weather to the target (startup, or a new site)."""
        self._set_applied(step_toward(self._state, self._target, 0.0, INSTANT))

    def set_camera(self, camera: Camera) -> None:
        self._camera = camera

    def set_time(
        self, time_utc: datetime, rate: float | None = None, source: Source = Source.CONTROL
    ) -> None:
        sources = dataclasses.replace(self._state.sources, time_utc=source)
        self._state = dataclasses.replace(self._state, time_utc=time_utc, sources=sources)
        self._target = dataclasses.replace(self._target, time_utc=time_utc)
        self.weather_version += 1
        if rate is not None:
            self.clock_rate = rate

    def _retarget(self) -> None:
        target = self._stack.target()
        target = dataclasses.replace(
            target,
            time_utc=self._state.time_utc,
            sources=dataclasses.replace(target.sources, time_utc=self._state.sources.time_utc),
        )
        if target == self._target:
            return
        self._target = target
        self._settled = settled(self._state, target)
        self.weather_version += 1
        new_sky = target.observer != self._state.observer or target.seed != self._state.seed
        # A new site or cloud seed is a different sky, not a change of this one.
        if new_sky or self.rates == INSTANT:
            self.settle()

    def _set_applied(self, new: WeatherState) -> None:
        if new == self._state:
            return
        self._drift = carry_drift(self._state, new, self._drift)
        self._state = new
        self._settled = settled(new, self._target)
        self.weather_version += 1

    def _transition(self, dt_wall_s: float) -> None:
        self._wall_s += dt_wall_s
        self._stack, expired = self._stack.expired(self._wall_s)
        if expired:
            self._retarget()
        if self.settled:
            self._since_step_s = 0.0
            return
        self._since_step_s += dt_wall_s
        if self._since_step_s < self.transition_step_s:
            return
        # One step never covers more than step_s, even after a slow frame: the rates are the
        # fastest the sky may change, and no frame may show a larger jump than one step.
        dt_s = self._since_step_s
        if self.transition_step_s > 0.0:
            dt_s = min(dt_s, self.transition_step_s)
        step = step_toward(self._state, self._target, dt_s, self.rates)
        self._since_step_s = 0.0
        self._set_applied(step)

    def advance(self, dt_wall_s: float) -> FramePlan:
        """Run the stages for a frame dt_wall_s after the previous one."""
        self._transition(max(0.0, dt_wall_s))
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


def geodetic_from_enu(
    observer_lat_deg: float, observer_lon_deg: float, east_m: float, north_m: float
) -> tuple[float, float]:
    """(lat, lon) of a local point; the inverse of `enu_from_geodetic`."""
    lat = observer_lat_deg + north_m / METRES_PER_DEG_LAT
    per_deg_lon = METRES_PER_DEG_LON_EQUATOR * max(1e-6, math.cos(math.radians(observer_lat_deg)))
    lon = observer_lon_deg + east_m / per_deg_lon
    lon = (lon + 180.0) % 360.0 - 180.0
    return (max(-90.0, min(90.0, lat)), lon)
