"""The fixed stage order from weather to a drawable frame, shared by the daemon and snapshot:

    sources -> target weather -> transition -> clock -> wind drift -> sky -> ring -> frame

Inputs give patches; each lands in its source's slot (`precedence.SourceStack`), which yields
the target weather. The applied weather moves toward the target at bounded rates
(`transition.step_toward`), once per `transition_step_s` so the ring is not rebuilt every
frame while a change is under way; the scene reads only the applied weather.

Each stage takes immutable values and returns immutable values; the engine only remembers the
latest ones. No GL and no I/O here: the renderer consumes the `FramePlan`.

Thread use: the daemon runs `advance` on its render thread, so that building a ring (a few
hundred milliseconds on a CPU) never holds up the event loop, while inputs call `apply*`,
`release`, `set_*` from the loop. A lock guards the weather and camera; it is held only for
the cheap stages, never while the scene is built, so an input is never kept waiting by a
ring build. The ring cache is touched by `advance` alone.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import threading
import time
from dataclasses import dataclass
from datetime import date, datetime
from typing import NamedTuple

from wxsky.engine.atmosphere_work import AtmosphereWork
from wxsky.engine.near_work import NearWork
from wxsky.engine.ring_schedule import DEFAULT_FADE_S, RingEvent, RingFrame, RingSchedule
from wxsky.engine.ring_worker import DEFAULT_NICE, BuildJob, RingWorker, run_job
from wxsky.engine.tower_work import TowerWork
from wxsky.scene.atmosphere import EYE_ALT_M as ATMOSPHERE_EYE_ALT_M
from wxsky.scene.atmosphere import VISIBILITY_M as ATMOSPHERE_VISIBILITY_M
from wxsky.scene.atmosphere import atmosphere_key
from wxsky.scene.camera import Camera
from wxsky.scene.clouds import layer_keys
from wxsky.scene.gather import (
    BuildCancelled,
    Drift,
    NearRing,
    advance_drift,
    carry_drift,
    zero_drift,
)
from wxsky.scene.in_cloud import NO_LOCKS, Locks
from wxsky.scene.layout import (
    FrameScene,
    RingScene,
    SceneSettings,
    StageClock,
    build_frame,
    empty_ring,
    gather_inputs,
)
from wxsky.scene.near_sets import NearInputs, install_near, stale_light, warm_near
from wxsky.scene.sky import Bodies, SkyParams, bodies_for, sky_params
from wxsky.scene.tower_field import LayerEpoch, TowerClock
from wxsky.weather.atmosphere import humidity_at
from wxsky.weather.cockpit import CockpitUpdate, clock_target
from wxsky.weather.geo import enu_from_geodetic, geodetic_from_enu
from wxsky.weather.precedence import DEFAULT_CIGI_HOLD_S, DEFAULT_COCKPIT_HOLD_S, SourceStack
from wxsky.weather.state import (
    LAST_UTC,
    Observer,
    Source,
    WeatherPatch,
    WeatherState,
    check_time_range,
    clamped_time,
)
from wxsky.weather.transition import INSTANT, TransitionRates, settled, step_toward

__all__ = ["FramePlan", "SharedSky", "SkyEngine", "enu_from_geodetic", "geodetic_from_enu"]

log = logging.getLogger(__name__)

RENDER_MODES = ("ring", "direct")  # far clouds as impostors, or every cloud as sprites
RING_WORKERS = ("process", "thread")  # where an async ring build runs
DEFAULT_TRANSITION_STEP_S = 1.0
# A cockpit position within this distance of the observer moves the camera; farther, the flat
# local frame is no longer good and the position becomes the new observer (a new site).
REORIGIN_M = 100_000.0
# A cockpit date (CANaerospace 1206) is paired with time frames (1200) this long after it.
DATE_MEMORY_S = 5.0
# A clock set from outside by more than this rebuilds the ring at once, whatever the sun and
# drift thresholds say: the frames after a jump show the sky of the new time, exactly as a
# one-shot picture of that time does, not a ring built for the old one.
CLOCK_JUMP_S = 1.0
# The eye's velocity (the drops' streaks): smoothed over this long; faster than EYE_JUMP_MPS
# from one frame to the next is a jump of the camera, not flight.
EYE_VELOCITY_SMOOTHING_S = 0.1
EYE_JUMP_MPS = 1000.0


@dataclass(frozen=True)
class FramePlan:
    """Everything one published frame is drawn from."""

    state: WeatherState  # with time_utc set to the frame's simulated time
    frame: FrameScene
    ring: RingScene  # the complete ring on show (an empty one before the first, or direct)
    rings: RingFrame  # what to render into which texture set, the fade, the ring's events
    events: tuple[RingEvent, ...] = ()  # the frame's trace events: the ring's, then the cap's

    @property
    def ring_version(self) -> int:
        return self.rings.version

    @property
    def ring_changed(self) -> bool:
        """Some impostor must be drawn this frame (see `rings.render`)."""
        return self.rings.changed


class _LastNear(NamedTuple):
    """The last near layer a frame was drawn from, and the weather it was gathered for."""

    state: WeatherState
    drift: Drift
    epochs: tuple[LayerEpoch | None, ...]
    gathered: NearInputs


@dataclass(frozen=True)
class SharedSky:
    """An engine's sky as a display channel follows it (`SkyEngine.shared`, `follow`)."""

    applied: WeatherState
    target: WeatherState
    anchor_utc: datetime  # the drift is anchor_drift moved by each layer's wind since then
    anchor_drift: Drift
    clock_rate: float
    weather_version: int
    camera: Camera
    aircraft_m: tuple[float, float, float] | None
    # Per applied layer, its towers' epoch (None: no towers); empty: the follower keeps its own.
    tower_epochs: tuple[LayerEpoch | None, ...] = ()


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
        render_mode: str = "ring",
        cigi_hold_s: float = DEFAULT_CIGI_HOLD_S,
        ring_build: str = "immediate",
        ring_fade_s: float = DEFAULT_FADE_S,
        ring_slice_ms: float | None = None,
        ring_worker: str = "thread",
        ring_worker_nice: int = DEFAULT_NICE,
    ) -> None:
        """`state` is the base weather (defaults and the startup preset), also the first
        applied weather. Rates default to instant and the ring to being built whole in the
        frame that needs it, which suits one-off snapshots; the daemon builds it off the
        render thread and spreads it over frames (`ring_build="async"`, see ring_schedule).
        `render_mode="direct"` draws every cloud as sprites and no ring (for comparison).
        `ring_slice_ms`: spread each impostor over frames at about this cost a frame
        (ring_schedule; the renderer reports what slices cost through `note_ring_render`).
        `ring_worker="process"`: with `ring_build="async"`, build rings in a child process
        at `ring_worker_nice` below the frames (`ring_worker`), not on a thread of this one."""
        if render_mode not in RENDER_MODES:
            raise ValueError(f"render mode must be one of {', '.join(RENDER_MODES)}")
        if ring_worker not in RING_WORKERS:
            raise ValueError(f"ring worker must be one of {', '.join(RING_WORKERS)}")
        self._worker: RingWorker | None = None
        if ring_worker == "process" and ring_build == "async" and render_mode == "ring":
            self._worker = RingWorker(ring_worker_nice)
            self._worker.start()
        self._lock = threading.RLock()
        self._stack = SourceStack(
            base=state, cockpit_hold_s=cockpit_hold_s, cigi_hold_s=cigi_hold_s
        )
        self._state = state  # applied
        self._target = state
        self._settled = True
        self._camera = camera
        self._aircraft_m: tuple[float, float, float] | None = None
        self._aloft_temperatures: tuple[tuple[float, float], ...] = ()
        self.settings = settings
        self.clock_rate = clock_rate
        # An instructor's freeze: the weather stands still (its clock, the clouds' drift and
        # growth, the transitions) until unfrozen; a change applied "now" still shows at once.
        self.frozen = False
        self.rates = rates
        self.transition_step_s = transition_step_s
        self._wall_s = 0.0
        self._live = ring_build == "async"  # a daemon's engine: inputs stamped in real time
        # The physical sky's tables: off the frame path for a daemon (in a child process where
        # the rings are built in one), at once for a snapshot.
        self._atmosphere = AtmosphereWork(
            wait=not self._live,
            process=ring_worker == "process" and self._live,
            nice=ring_worker_nice,
        )
        self._advanced_at = time.monotonic()
        self._cockpit_date: tuple[date, float] | None = None  # (date, wall_s it arrived)
        self._since_step_s = 0.0
        # The clouds' drift is a function of the time: each layer has moved with its wind
        # since the anchor (the moment the applied weather last changed, at the drift it had
        # then), so setting the clock anywhere puts the clouds where that time has them.
        self._drift: Drift = zero_drift(state)
        self._last_frame_s: float | None = None  # the last frame's simulated time (lightning)
        # The eye's last position and its velocity from frame to frame (the drops' streaks).
        self._last_eye: tuple[float, float, float] | None = None
        self._eye_velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._anchor_utc = state.time_utc
        self._anchor_drift: Drift = self._drift
        self._clock_jumps = 0  # bumped by each clock set that moves it more than CLOCK_JUMP_S
        self._clock_jumps_seen = 0
        self._clock_at_end = False  # the clock ran up to LAST_UTC and stands there
        self.render_mode = render_mode
        self._build_times: list[float] | None = None
        self._schedule = RingSchedule(
            self._build_ring,
            settings.ring_radius_m,
            mode=ring_build,
            fade_s=ring_fade_s,
            slice_ms=ring_slice_ms,
        )
        self._rings: RingFrame | None = None
        self._capping = False  # the near-sprite cap left sprites out last frame
        self._locks: Locks = NO_LOCKS  # in-cloud facing locks, carried frame to frame
        # Each convective cell's progress from sprite cloud to tower (None until a frame is
        # drawn: the first frame shows each as the budget makes it).
        self._tower_fades: dict[int, float] | None = None
        self._bodies: Bodies | None = None  # the latest frame's sun and moon
        self.weather_version = 0  # bumped when the applied weather or the target changes
        self.target_version = 0  # bumped when the target (or the clock, set from outside) changes
        # A display channel's engine follows a sky master's (`follow`, `follow_time`): it
        # moves neither its weather nor its clock itself.
        self._following = False
        # Per layer (by key): when its weather was set, for the towers' ages (tower_field).
        self._epochs: dict[int, LayerEpoch] = {}
        self._update_epochs()
        self._towers = TowerWork("async" if ring_build == "async" else "immediate")
        self._towers_capping = False
        # The daemon's frames never make a near set: they look it up and, while it is made
        # elsewhere, are drawn from the last near layer they had (`near_work`).
        self._near_work: NearWork | None = None
        if ring_build == "async" and render_mode == "ring":
            self._near_work = NearWork(process=ring_worker == "process")
        self._last_near: _LastNear | None = None
        self._near_waiting = False
        self.near_waits = 0  # frames drawn from the last near layer while a set was made
        self._work_gate: threading.Event | None = None

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
        """Wall-clock seconds the engine has run (the time base of cockpit and CIGI holds):
        the seconds it has advanced, and in a daemon's engine those since the last frame
        began (`_now_s`)."""
        return self._now_s()

    def _now_s(self) -> float:
        """The time an input is stamped with. A daemon's engine (async) runs in real time:
        an input that arrives while a frame is drawn is stamped that much after the frame's
        start, so a frame that took longer than a hold (a busy machine) does not expire a
        host or a knob that kept sending meanwhile. A snapshot's or a test's engine runs in
        the steps it is given, and stamps with them alone."""
        if not self._live:
            return self._wall_s
        return self._wall_s + max(0.0, time.monotonic() - self._advanced_at)

    @property
    def camera(self) -> Camera:
        return self._camera

    @property
    def drift(self) -> Drift:
        """Where the wind has moved each applied layer by the clock's time (metres east,
        north): a function of the weather and the time, not of how the frames went."""
        return self._drift

    def sky(self, eye_alt_m: float | None = None) -> SkyParams:
        """The sky of the applied weather from eye_alt_m (default: the observer's), with the
        latest frame's sun and moon where it is still that frame's moment."""
        return sky_params(self._state, eye_alt_m, self._bodies)

    @property
    def ring(self) -> RingScene | None:
        """The complete ring on show (None before the first is done, and in direct mode)."""
        return self._schedule.current

    @property
    def ring_version(self) -> int:
        return 0 if self._rings is None else self._rings.version

    def note_ring_render(self, seconds: float) -> None:
        """How long drawing this frame's impostor slice took (render thread), which sizes the
        next slices."""
        piece = None if self._rings is None else self._rings.render_slice
        if piece is not None:
            self._schedule.note_render(piece.units, seconds)

    def time_ring_builds(self, out: list[float]) -> None:
        """Append the seconds each later ring build takes (on whichever thread) to `out`."""
        self._build_times = out

    def _build_ring(
        self,
        state: WeatherState,
        drift: Drift,
        centre_m: tuple[float, float, float],
        sky: SkyParams,
    ) -> RingScene:
        gate = self._work_gate
        while gate is not None and not gate.wait(0.1):
            if self._schedule.cancel_event.is_set():
                raise BuildCancelled("scene work cancelled")
        t0 = time.perf_counter()
        current = self._schedule.current  # (read off the render thread: a hint, nothing more)
        shown = None if current is None else NearRing(current.geometry.centre_m, current.drift, 1.0)
        # The towers' epochs for the sets the ring's frames will gather: their cells are
        # found with the sets, so those frames find everything ready.
        epochs = None
        if self.settings.max_towers > 0:
            epochs = tuple(self._epochs.get(k) for k in layer_keys(state.layers))
        job = BuildJob(state, drift, centre_m, sky, self.settings, shown, epochs)
        if self._worker is not None:
            ring, prepared = self._worker.build(job, self._schedule.cancel_event)
            install_near(prepared)
        else:
            ring, _ = run_job(job, self._schedule.cancel_event)
        if self._build_times is not None:
            self._build_times.append(time.perf_counter() - t0)
        return ring

    @property
    def ring_busy(self) -> bool:
        """A ring rebuild is under way (building, rendering or fading in), or the physical
        atmosphere's tables for the sky asked for are being made (the ring is built again
        with them when they come: `ring_schedule._lit_otherwise`). A host waiting for a
        settled picture (a still, a test) so gets the sky it asked for."""
        return self._schedule.busy or self._atmosphere.pending

    @property
    def work_gate(self) -> threading.Event | None:
        """Work off the frame path (ring builds, near sets, towers) waits for this Event to
        be set before each job; None: it never waits. Tests hold the work back with it and
        count the frames published meanwhile."""
        return self._work_gate

    @work_gate.setter
    def work_gate(self, gate: threading.Event | None) -> None:
        self._work_gate = gate
        if self._near_work is not None:
            self._near_work.gate = gate
        self._towers.gate = gate

    def scene_work(self) -> dict[str, object]:
        """What is being made off the frame path now, for `status`: a ring (building,
        rendering or fading in), the near layer's set the frames asked for, tower steps; and
        how many frames were drawn from the last near layer while a set was made."""
        return {
            "ring_busy": self.ring_busy,
            "near_pending": self.near_pending,
            "towers_pending": self.towers_pending,
            "near_held_frames": self.near_waits,
        }

    @property
    def near_pending(self) -> bool:
        """A near set asked for by the frames is being made (or waits to be)."""
        return self._near_work is not None and self._near_work.pending

    def cancel_scene_work(self) -> None:
        """Make a ring build in flight give up at its next block and start no more (safe
        from any thread: the daemon calls it first thing at shutdown)."""
        self._schedule.cancel()

    def _with_atmosphere(self, sky: SkyParams, state: WeatherState, camera: Camera) -> SkyParams:
        """The frame's sky with the physical atmosphere's tables (`[scene] sky = "physical"`):
        those of its sun, visibility, humidity and eye, or the last made while they are made
        off the frame path (`AtmosphereWork`). The frame's and the ring build's sky carry them
        (the clouds' light and haze come from them: scene/cloud_light.py); not the near sets',
        whose precompute needs the light's directions only."""
        if self.settings.sky != "physical":
            return sky
        obs = state.observer
        vis_lo, vis_hi = ATMOSPHERE_VISIBILITY_M.bounds
        key = atmosphere_key(
            min(max(sky.sun.elevation_deg, -90.0), 90.0),
            min(max(state.visibility_m, vis_lo), vis_hi),
            humidity_at(state, obs.alt_m),
            # The model's ground is the observer's: the eye's height above it.
            min(max(camera.position_m[2] - obs.alt_m, 0.0), ATMOSPHERE_EYE_ALT_M.bounds[1]),
        )
        return sky.with_atmosphere(self._atmosphere.luts_for(key))

    def close(self, wait_s: float = 0.0) -> str | None:
        """Stop the ring builder, waiting up to wait_s for a build in flight to give up;
        idempotent. Returns what was abandoned (`RingSchedule.close`), or None."""
        self._atmosphere.close()
        cut = self._schedule.close(wait_s)
        if self._worker is not None:
            self._worker.close(max(wait_s, 0.5))
        if self._near_work is not None:
            self._near_work.close(max(wait_s, 0.5))
        self._towers.close(max(wait_s, 0.5))
        return cut

    def __enter__(self) -> SkyEngine:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def apply(self, patch: WeatherPatch) -> WeatherState:
        """Put an input's patch into its source's slot; returns the new target. A time in the
        patch sets the clock at once."""
        with self._lock:
            if patch.time_utc is not None:
                self.set_time(patch.time_utc, source=patch.source)
            self._stack = self._stack.with_patch(patch, self._now_s())
            self._retarget()
            return self._target

    @property
    def aircraft_m(self) -> tuple[float, float, float] | None:
        return self._aircraft_m

    def set_aloft_temperatures(self, levels: tuple[tuple[float, float], ...]) -> None:
        """The model's temperatures by height, ((height_m MSL, degC), ...) from the ground
        up, for the air at the aircraft (the weather state keeps only the surface's)."""
        self._aloft_temperatures = levels

    @property
    def aloft_temperatures(self) -> tuple[tuple[float, float], ...]:
        return self._aloft_temperatures

    def set_metar_weight(self, weight: float) -> None:
        """How much the METAR counts against the model's layers and wind (0..1,
        `weather.model_blend`): the model data's part sets it as stations and ages change."""
        with self._lock:
            stack = self._stack.with_metar_weight(weight)
            if stack is not self._stack:
                self._stack = stack
                self._retarget()

    @property
    def metar_weight(self) -> float:
        return self._stack.metar_weight

    def heard_cigi(self) -> None:
        """A CIGI host sent a message: the weather it gave stands on (see `SourceStack`)."""
        with self._lock:
            self._stack = self._stack.heard_cigi(self._now_s())

    def apply_cockpit(self, update: CockpitUpdate) -> WeatherState:
        """Lay a cockpit link's values over the weather (each held while it keeps coming),
        set the clock from its time and move the camera to its position; returns the target."""
        with self._lock:
            now_s = self._now_s()
            if update.values:
                self._stack = self._stack.with_cockpit_values(update.values, now_s)
                self._retarget()
            if update.date_utc is not None:
                self._cockpit_date = (update.date_utc, now_s)
            recent = self._cockpit_date
            recent_date = recent[0] if recent and now_s - recent[1] <= DATE_MEMORY_S else None
            when = clock_target(self._state.time_utc, update, recent_date)
            if when is not None:
                self.set_time(when, source=Source.COCKPIT)
            if update.position_deg is not None:
                self.move_observer(*update.position_deg)
            return self._target

    def move_observer(self, lat_deg: float, lon_deg: float, ground_m: float | None = None) -> None:
        """Put the camera over a geodetic position: within `REORIGIN_M` of the observer the
        camera moves in the local frame (same sky); beyond it the position becomes the
        observer of a new site, on the ground at `ground_m` MSL where the caller knows it
        (a simulator's terrain), else at the old site's height."""
        with self._lock:
            obs = self._stack.base.observer
            east_m, north_m, _ = enu_from_geodetic(obs.lat_deg, obs.lon_deg, lat_deg, lon_deg, 0.0)
            up_m = self._camera.position_m[2]
            if math.hypot(east_m, north_m) > REORIGIN_M:
                site = Observer(lat_deg, lon_deg, obs.alt_m if ground_m is None else ground_m)
                self.apply(WeatherPatch(source=Source.PRESET, observer=site))
                east_m = north_m = 0.0
            self._camera = dataclasses.replace(self._camera, position_m=(east_m, north_m, up_m))

    def release(self, source: Source) -> tuple[str, ...]:
        """Hand the fields a control, cockpit or CIGI source holds back to the sources below."""
        with self._lock:
            self._stack, fields = self._stack.released(source)
            self._retarget()
            return fields

    def settle(self) -> None:
        """Jump the applied weather to the target (startup, or a new site)."""
        with self._lock:
            self._set_applied(step_toward(self._state, self._target, 0.0, INSTANT))

    def set_camera(self, camera: Camera) -> None:
        with self._lock:
            self._camera = camera

    def set_aircraft(self, position_m: tuple[float, float, float] | None) -> None:
        """Where the host's own aircraft is (None: nowhere): the near layer is then split at
        its distance into sprites behind it and in front of it (Harris's impostor splitting),
        so the host can draw its aircraft between the two."""
        with self._lock:
            self._aircraft_m = position_m

    def set_time(
        self, time_utc: datetime, rate: float | None = None, source: Source = Source.CONTROL
    ) -> None:
        """Set the clock. A time outside the clock's range (`weather.state.EARLIEST_UTC` ..
        `LATEST_UTC`) is a ValueError and leaves the clock as it was: every input checks it
        at its edge, and this is the last line behind them."""
        check_time_range("time_utc", time_utc)
        with self._lock:
            self._clock_at_end = False
            if abs((time_utc - self._state.time_utc).total_seconds()) > CLOCK_JUMP_S:
                self._clock_jumps += 1
            sources = dataclasses.replace(self._state.sources, time_utc=source)
            self._state = dataclasses.replace(self._state, time_utc=time_utc, sources=sources)
            self._drift = self._drift_at(time_utc)
            self._target = dataclasses.replace(
                self._target,
                time_utc=time_utc,
                sources=dataclasses.replace(self._target.sources, time_utc=source),
            )
            self.weather_version += 1
            self.target_version += 1
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
        self.target_version += 1
        new_sky = target.observer != self._state.observer or target.seed != self._state.seed
        # A new site or cloud seed is a different sky, not a change of this one.
        if new_sky or self.rates == INSTANT:
            self.settle()
        self._update_epochs()

    def _set_applied(self, new: WeatherState) -> None:
        if new == self._state:
            return
        self._drift = carry_drift(self._state, new, self._drift)
        # From now on the layers move with the new weather's winds.
        self._anchor_utc, self._anchor_drift = self._state.time_utc, self._drift
        self._state = new
        self._settled = settled(new, self._target)
        self.weather_version += 1
        self._update_epochs()

    def _update_epochs(self) -> None:
        """Keep each applied layer's epoch: a layer new to the weather is set now; one whose
        cover falls, or that the target thins or takes away, is clearing (its towers' supply
        stops now, once); one back at the cover it was supplied at is supplied again."""
        state, now = self._state, self._state.time_utc
        goals = dict(zip(layer_keys(self._target.layers), self._target.layers, strict=True))
        epochs: dict[int, LayerEpoch] = {}
        for key, layer in zip(layer_keys(state.layers), state.layers, strict=True):
            epoch = self._epochs.get(key)
            if epoch is None:
                epoch = LayerEpoch(now, _sun_elevation(state, now), None, layer.cover_oktas)
            goal = goals.get(key)
            supplied = epoch.cover_oktas - 1e-6
            clearing = goal is None or min(goal.cover_oktas, layer.cover_oktas) < supplied
            if clearing and epoch.cut_utc is None:
                epoch = dataclasses.replace(epoch, cut_utc=now)
            elif not clearing:
                epoch = dataclasses.replace(
                    epoch, cut_utc=None, cover_oktas=max(epoch.cover_oktas, layer.cover_oktas)
                )
            epochs[key] = epoch
        self._epochs = epochs

    @property
    def tower_work_s(self) -> float:
        """Seconds the towers' lit steps have taken to make (automaton, smoothing, light)."""
        return self._towers.busy_s

    @property
    def tower_steps_lit(self) -> int:
        return self._towers.lit_count

    @property
    def towers_pending(self) -> int:
        """Lit tower steps asked for by frames and not made yet (the bench's lead-in waits
        for none)."""
        return self._towers.pending

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

    def _eye_velocity_of(
        self, eye_m: tuple[float, float, float], dt_wall_s: float
    ) -> tuple[float, float, float]:
        """The eye's velocity, from where it was a frame ago, smoothed over a few frames (a
        host's positions come with jitter); a jump (a new site, a teleport) is no speed."""
        last, self._last_eye = self._last_eye, eye_m
        if last is None or dt_wall_s <= 0.0:
            return self._eye_velocity
        step = [(a - b) / dt_wall_s for a, b in zip(eye_m, last, strict=True)]
        if sum(v * v for v in step) > EYE_JUMP_MPS**2:
            step = [0.0, 0.0, 0.0]
        k = min(1.0, dt_wall_s / EYE_VELOCITY_SMOOTHING_S)
        old = self._eye_velocity
        self._eye_velocity = (
            old[0] + k * (step[0] - old[0]),
            old[1] + k * (step[1] - old[1]),
            old[2] + k * (step[2] - old[2]),
        )
        return self._eye_velocity

    def advance(self, dt_wall_s: float, clock: StageClock | None = None) -> FramePlan:
        """Run the stages for a frame dt_wall_s after the previous one (`clock`: times the
        sort for `wxsky bench`)."""
        with self._lock:
            self._step_weather(dt_wall_s)
            state, drift, camera = self._state, self._drift, self._camera
            aircraft_m = self._aircraft_m
            towers = TowerClock(
                tuple(self._epochs.get(k) for k in layer_keys(state.layers)), state.time_utc
            )
            clock_jumped = self._clock_jumps != self._clock_jumps_seen
            self._clock_jumps_seen = self._clock_jumps
        if clock_jumped:
            self._schedule.invalidate("time_set")
        # The scene stages read only the immutable values taken above: no lock from here on.
        # One ephemeris per frame (and none while the clock stands still): `sky()` reuses it.
        self._bodies = bodies = bodies_for(state, self._bodies)
        sky = sky_params(state, camera.position_m[2], bodies)
        lit_sky = self._with_atmosphere(sky, state, camera)
        near_radius_m: float | None = None
        if self.render_mode == "direct":
            rings = RingFrame(None, 0, None, (), None, 1, 0.0, 0, ())
            near: tuple[NearRing, ...] = (NearRing(camera.position_m, drift, 1.0),)
            near_radius_m = self.settings.max_range_m
        else:
            # The ring's impostors are lit and hazed with the physical atmosphere's light too
            # (its tables, some 1 MB, go with each build job: a build every few km or 1 deg
            # of sun, never a frame's cost).
            rings = self._schedule.step(state, drift, camera, lit_sky, dt_wall_s)
            near = rings.near_rings(camera, drift)
        self._rings = rings
        # What the frame is drawn from: this frame's weather, or while its near set is made
        # elsewhere the last near layer drawn, where its clouds last stood.
        drawn_state, drawn_drift, gathered = state, drift, None
        if self._near_work is not None:
            gathered = self._near_work.inputs(state, drift, near, sky, self.settings, towers.epochs)
            if gathered is not None:
                self._last_near = _LastNear(state, drift, towers.epochs, gathered)
            else:
                drawn_state, drawn_drift, gathered, towers = self._held_near(
                    state, drift, near, sky, towers
                )
        # Lightning goes by the frame's own moment, whatever weather the near layer was
        # gathered for (`flash_times_s`).
        now_s = state.time_utc.timestamp()
        if self._last_frame_s is None or not 0.0 <= now_s - self._last_frame_s <= 1.0:
            self._last_frame_s = now_s - 1.0 / 30.0
        frame = build_frame(
            drawn_state,
            drawn_drift,
            camera,
            near,
            lit_sky,
            self.settings,
            locks=self._locks,
            near_radius_m=near_radius_m,
            clock=clock,
            split_at_m=aircraft_m,
            lod=self.render_mode != "direct",
            towers=towers,
            gathered=gathered,
            fill_towers=lambda shows: self._towers.fill(shows, sky),
            tower_fades=self._tower_fades,
            dt_s=dt_wall_s,
            flash_times_s=(self._last_frame_s, now_s),
            eye_velocity_mps=self._eye_velocity_of(camera.position_m, dt_wall_s),
        )
        self._last_frame_s = now_s
        self._locks = frame.locks
        self._tower_fades = dict(frame.tower_fades)
        events = rings.events
        waiting = self._near_work is not None and drawn_state is not state
        if waiting:
            self.near_waits += 1
        if waiting != self._near_waiting:
            # The frames are drawn from the last near layer while this frame's set is made
            # off the frame path (a new site, a clock set, a step of the weather).
            self._near_waiting = waiting
            name = "near_wait_start" if waiting else "near_wait_end"
            events = (*events, RingEvent(name, {"frames": self.near_waits}))
        if (frame.near_dropped > 0) != self._capping:
            self._capping = frame.near_dropped > 0
            name = "near_cap_start" if self._capping else "near_cap_end"
            fields = {"dropped": frame.near_dropped, "kept": len(frame.near)}
            events = (*events, RingEvent(name, fields))
        if (frame.towers_left_out > 0) != self._towers_capping:
            # More convective cells than the budget: the nearest grow as volumes, the rest
            # are sprite clouds (issue 17, bad input).
            self._towers_capping = frame.towers_left_out > 0
            name = "tower_cap_start" if self._towers_capping else "tower_cap_end"
            fields = {"left_out": frame.towers_left_out, "towers": len(frame.towers)}
            events = (*events, RingEvent(name, fields))
        shown = rings.current or empty_ring(camera.position_m, self.settings.ring_radius_m, drift)
        return FramePlan(state, frame, shown, rings, events)

    def _held_near(
        self,
        state: WeatherState,
        drift: Drift,
        near: tuple[NearRing, ...],
        sky: SkyParams,
        towers: TowerClock,
    ) -> tuple[WeatherState, Drift, NearInputs, TowerClock]:
        """The inputs of a frame whose near set is not ready: the last near layer drawn, as
        it stood, lit by this sky's light directions (its rows are the old sun's until the
        new light comes), its towers aged to this frame's time (the ring and the sky are
        still this frame's). With none drawn yet (an engine not warmed up), this frame's
        made now, once, rather than an empty sky."""
        last = self._last_near
        if last is None:
            made = gather_inputs(state, drift, near, sky, self.settings, None, towers)
            self._last_near = _LastNear(state, drift, towers.epochs, made)
            return state, drift, made, towers
        gathered = last.gathered
        if gathered.scattered is not None and gathered.blocks is not None:
            relit = stale_light(gathered.blocks, sky)
            if relit is not None:
                gathered = dataclasses.replace(gathered, scattered=relit)
        held_towers = TowerClock(last.epochs, towers.time_utc)
        return last.state, last.drift, gathered, held_towers

    def warm_up(self) -> FrameScene | None:
        """Do at startup what the first frame would otherwise pay for: gather the near
        layer's blocks around the camera (where the first ring is built) and light them.
        Returns the frame the first frame will draw, for the renderer's own warm-up
        (`Renderer.warm_up`); None in direct mode. Together they make the first frame cost
        what later ones do, where it took 100-400 ms on a 2-core CPU renderer. The set it
        makes is also what the first frames show until their own is made off the frame
        path."""
        if self.render_mode != "ring":
            return None
        with self._lock:
            state, drift, camera = self._state, self._drift, self._camera
            aircraft_m = self._aircraft_m
        self._bodies = bodies = bodies_for(state, self._bodies)
        sky = sky_params(state, camera.position_m[2], bodies)
        ring = NearRing(camera.position_m, drift, 1.0)
        epochs = tuple(self._epochs.get(k) for k in layer_keys(state.layers))
        warm_near(state, drift, ring, sky, self.settings, epochs)
        towers = TowerClock(epochs, state.time_utc)
        gathered = gather_inputs(state, drift, (ring,), sky, self.settings, None, towers)
        # The first frames' fallback: their own set may be picked a block apart (the first
        # ring's blocks are picked with the drift of the first frame's clock) and made off
        # the frame path, and they show this one meanwhile, not an empty sky.
        self._last_near = _LastNear(state, drift, epochs, gathered)
        return build_frame(
            state,
            drift,
            camera,
            (ring,),
            self._with_atmosphere(sky, state, camera),
            self.settings,
            locks=self._locks,
            split_at_m=aircraft_m,
            gathered=gathered,
        )

    # -- several daemons, one sky (docs/channels.md) ---------------------------------------

    def shared(self) -> SharedSky:
        """What a channel needs to build this engine's cloud field for any sim time."""
        with self._lock:
            return SharedSky(
                applied=self._state,
                target=self._target,
                anchor_utc=self._anchor_utc,
                anchor_drift=self._anchor_drift,
                clock_rate=self.clock_rate,
                weather_version=self.weather_version,
                camera=self._camera,
                aircraft_m=self._aircraft_m,
                tower_epochs=tuple(self._epochs.get(k) for k in layer_keys(self._state.layers)),
            )

    @property
    def following(self) -> bool:
        """The engine follows another's sky (`follow`): its weather and clock are set."""
        return self._following

    def follow(self, sky: SharedSky) -> None:
        """Take a sky master's applied and target weather, drift anchor and clock rate as
        they are (a channel runs no transition of its own, so it shows the master's steps,
        never a jump of its own); from now on the clock moves only by `follow_time`. The
        camera and aircraft are the caller's business."""
        with self._lock:
            self._following = True
            now = self._state.time_utc
            applied = dataclasses.replace(sky.applied, time_utc=now)
            target = dataclasses.replace(sky.target, time_utc=now)
            changed = applied != self._state or target != self._target
            anchored = (sky.anchor_utc, sky.anchor_drift) != (
                self._anchor_utc,
                self._anchor_drift,
            )
            self._state, self._target = applied, target
            self._anchor_utc, self._anchor_drift = sky.anchor_utc, sky.anchor_drift
            self.clock_rate = sky.clock_rate
            self._settled = settled(applied, target)
            self._drift = self._drift_at(now)
            # The master's towers' ages, so every channel shows the same towers; a master
            # that sends none leaves the channel timing them from what it has seen.
            if len(sky.tower_epochs) == len(applied.layers):
                keys = layer_keys(applied.layers)
                self._epochs = {
                    k: e for k, e in zip(keys, sky.tower_epochs, strict=True) if e is not None
                }
            else:
                self._update_epochs()
            if changed or anchored:
                self.weather_version += 1
                self.target_version += 1

    @property
    def clock_at_end(self) -> bool:
        """The clock ran up to the end of its range (`LAST_UTC`) and stands there until a
        clock set moves it."""
        return self._clock_at_end

    def follow_time(self, time_utc: datetime) -> None:
        """Set a following engine's clock (every frame, from the master's); a step of more
        than CLOCK_JUMP_S rebuilds the ring as a clock set does."""
        with self._lock:
            # The master's clock is checked where its ticks arrive; held in range here too,
            # so nothing a channel computes from it can leave datetime's years.
            time_utc = clamped_time(time_utc, 0.0)
            if abs((time_utc - self._state.time_utc).total_seconds()) > CLOCK_JUMP_S:
                self._clock_jumps += 1
            self._state = dataclasses.replace(self._state, time_utc=time_utc)
            self._target = dataclasses.replace(self._target, time_utc=time_utc)
            self._drift = self._drift_at(time_utc)

    def drift_for(self, seconds: float) -> None:
        """Move every layer as the wind would have in `seconds` (negative: back), at once, and
        age the towers as much: a picture at a later time than its weather's shows the clouds
        blown on and the towers grown."""
        with self._lock:
            self._anchor_drift = advance_drift(self._state, self._anchor_drift, seconds)
            self._drift = self._drift_at(self._state.time_utc)
            # The towers have grown for as long (their weather was set that much earlier).
            # Held in the clock's range: however long `seconds`, no epoch leaves its years.
            self._epochs = {
                k: dataclasses.replace(
                    e,
                    set_utc=clamped_time(e.set_utc, -seconds),
                    sun_elevation_deg=_sun_elevation(
                        self._state, clamped_time(e.set_utc, -seconds)
                    ),
                    cut_utc=None if e.cut_utc is None else clamped_time(e.cut_utc, -seconds),
                )
                for k, e in self._epochs.items()
            }

    def run_weather(self, duration_s: float) -> WeatherState:
        """Advance the weather stages only (sources, transition, clock, drift) by duration_s
        of wall time, in transition steps, without building a scene: for pictures of a
        transition minutes in (`wxsky snapshot --elapsed-s`). Returns the applied weather."""
        step_s = self.transition_step_s if self.transition_step_s > 0.0 else duration_s
        left_s = max(0.0, duration_s)
        with self._lock:
            while left_s > 1e-9:
                dt_s = min(step_s, left_s)
                self._step_weather(dt_s)
                left_s -= dt_s
            return self._state

    def _step_weather(self, dt_wall_s: float) -> None:
        self._advanced_at = time.monotonic()
        # Following, the master moves the weather and the clock; frozen, nothing moves.
        if self._following or self.frozen:
            self._wall_s += max(0.0, dt_wall_s)
            return
        self._transition(max(0.0, dt_wall_s))
        dt_sim = max(0.0, dt_wall_s) * self.clock_rate
        if dt_sim > 0.0 and not self._clock_at_end:
            # A fast clock stops at the range's last moment rather than run out of datetime's
            # years (the frames go on; a set_time moves it again).
            now = clamped_time(self._state.time_utc, dt_sim)
            if now == LAST_UTC:
                self._clock_at_end = True
                log.warning(
                    "the sim clock reached the end of its range (%s) and stopped there; "
                    "set_time moves it again",
                    LAST_UTC.isoformat(),
                )
            self._state = self._state.at_time(now)
            self._drift = self._drift_at(self._state.time_utc)

    def _drift_at(self, time_utc: datetime) -> Drift:
        """Where the applied weather's layers stand at `time_utc` (earlier: back upwind)."""
        since_s = (time_utc - self._anchor_utc).total_seconds()
        return advance_drift(self._state, self._anchor_drift, since_s)


def _sun_elevation(state: WeatherState, time_utc: datetime) -> float:
    """The sun's elevation over the state's site at `time_utc`: the heating a layer's towers
    grow with from the moment its weather was set."""
    return bodies_for(dataclasses.replace(state, time_utc=time_utc)).sun.elevation_deg
