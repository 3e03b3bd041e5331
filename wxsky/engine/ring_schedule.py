"""When the impostor ring is rebuilt, and how a new one replaces the old without a hitch.

Wang's schedule: the ring is rebuilt once the camera has moved 15 % of the ring radius
horizontally or 2 % vertically from where it was built (`RingPolicy`), and also here when the
sun has moved, the weather has changed the clouds or the haze (by more than small
allowances while it is changing, by anything once it holds still), or the clouds have
drifted. A rebuild never stalls a frame:

    idle -> building (the sprite work, on a worker thread) -> rendering (one impostor per
    frame, 8 frames, into the second set) -> fading (the host cross-fades from the old set
    to the new over `fade_s`) -> idle, the new set now the current one

With `slice_ms`, an impostor whose drawing would take longer than that is drawn over several
frames instead, in slices of its back-to-front sprite list (`ImpostorSlice`), each drawn over
the last: the same picture, and no frame pays a whole impostor (30-150 ms on a CPU renderer).
The first ring is sliced too: drawn whole, it made the frame it was ready in the slowest of
the daemon's life (140-230 ms). Slices are cut by each sprite's estimated cost
(`scene.ring.impostor_costs`) and the time a unit of it took in the slices drawn so far
(`note_render`). Impostors still go one at a time, in order, and the fade starts once the
eighth is complete.

Two physical sets of 8 textures exist (0 and 1), so the old ring stays on screen, whole,
until the new one is complete. A need to rebuild that arises mid-cycle waits for the cycle to
end, and is judged then against the newest ring (a weather change under way rebuilds once per
cycle, not once per frame).

Modes: "async" (the daemon and `wxsky bench`: building off the render thread), "sync" (the
same schedule with the build done inline: deterministic frame numbers, for tests), and
"immediate" (snapshots: build and render all 8 at once, no fade).

`RingSchedule.step` runs once per frame on the render thread and says, in a `RingFrame`, what
to render and publish, with the trace events of that frame.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import threading
import time
from collections.abc import Callable
from concurrent.futures import CancelledError, Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

from wxsky.scene.atmosphere import AtmosphereKey
from wxsky.scene.camera import Camera
from wxsky.scene.gather import BuildCancelled, Drift, NearRing
from wxsky.scene.layout import RingScene
from wxsky.scene.ring import (
    MOVE_HORIZONTAL_FRAC,
    MOVE_VERTICAL_FRAC,
    RING_SIZE,
    ImpostorCuts,
    moved_reason,
)
from wxsky.scene.sky import SkyParams
from wxsky.weather.state import WeatherState

log = logging.getLogger(__name__)

BUILD_MODES = ("async", "sync", "immediate")
DEFAULT_FADE_S = 1.0
RETRY_AFTER_S = 2.0  # a failed build is tried again after this long, not every frame
# Rebuild the ring once the clouds in it have drifted this share of its radius, or the sun
# has moved this far: past these, the seam between near sprites and impostors shows.
RING_DRIFT_FRAC = 0.03
RING_SUN_DEG = 1.0
# ... or the weather the ring shows has changed by more than these. A transition moves the
# weather a little every frame (cover 2 oktas/min, bases 300 m/min, visibility 100 m/s by
# default); rebuilding at each step would rebuild back to back for minutes, at a third of the
# frame rate on a CPU. 0.25 okta is 3 % of the sky; 50 m of base or top is a third of the
# camera's own vertical allowance (2 % of 8 km); 5 % of the visibility moves any cloud's haze
# (1 - exp(-d / haze_m), haze_m proportional to it) by at most 1.8 % of the way to the horizon
# colour (x e^-x <= 1/e). Once the weather has held still for RING_SETTLE_S, the ring is
# rebuilt for any difference, so a finished transition is shown exactly.
RING_VISIBILITY_FRAC = 0.05
RING_COVER_OKTAS = 0.25
RING_LAYER_M = 50.0
RING_SETTLE_S = 1.0
# And a weather rebuild that follows a weather rebuild waits this long after that one was
# shown: a preset or report applied every few seconds (a restless instructor, a flapping feed)
# would otherwise keep a build beside every frame. The near sprites show the change at once
# meanwhile; the first change after a quiet spell rebuilds at once.
RING_WEATHER_GAP_S = 3.0

# What one frame may spend on impostors: an eighth of a frame at 30 fps. At 8 ms (a quarter)
# a frame drawing a slice took 1.5 times a fair-cumulus frame on a 2-core CPU renderer (17 ms).
DEFAULT_SLICE_MS = 4.0
# An impostor is cut into at most this many slices whatever the estimate, so that a rebuild
# on a very slow machine still ends in 8 x MAX_SLICES frames.
MAX_SLICES = 16
# Seconds per cost unit assumed before any slice was timed (llvmpipe on 2 cores, measured).
FIRST_SECONDS_PER_UNIT = 1.5e-6

Builder = Callable[[WeatherState, Drift, tuple[float, float, float], SkyParams], RingScene]


@dataclass(frozen=True)
class RingPolicy:
    horizontal_frac: float = MOVE_HORIZONTAL_FRAC
    vertical_frac: float = MOVE_VERTICAL_FRAC
    sun_deg: float = RING_SUN_DEG
    drift_frac: float = RING_DRIFT_FRAC
    visibility_frac: float = RING_VISIBILITY_FRAC
    cover_oktas: float = RING_COVER_OKTAS
    layer_m: float = RING_LAYER_M
    settle_s: float = RING_SETTLE_S
    weather_gap_s: float = RING_WEATHER_GAP_S


@dataclass(frozen=True)
class RingEvent:
    """One line of the trace: `event` and its fields (reason, index, fade ...)."""

    event: str
    fields: dict[str, Any] = dataclasses.field(default_factory=dict)


@dataclass(frozen=True)
class ImpostorSlice:
    """Sprites start..stop of impostor `index`, back to front: the first slice clears the
    impostor, each next one draws over it, the last completes it."""

    index: int
    start: int
    stop: int
    last: bool
    units: float  # its estimated cost (`impostor_costs`)


@dataclass(frozen=True)
class RingFrame:
    """What the renderer draws and the publisher sends for the ring in one frame."""

    current: RingScene | None  # complete, shown at weight 1 - fade (None before the first)
    current_set: int  # the physical texture set (0 or 1) it lives in
    incoming: RingScene | None  # being rendered into the other set, or fading in
    render: tuple[int, ...]  # impostors of `render_ring` to draw this frame, into `render_set`
    render_ring: RingScene | None
    render_set: int
    fade: float  # weight of `incoming`: 0 while it is rendered, rising to 1 as it fades in
    version: int  # bumps whenever a ring image or the fade weight changes
    events: tuple[RingEvent, ...]
    # With slicing: the part of `render`'s one impostor to draw this frame (None: all of it)
    render_slice: ImpostorSlice | None = None
    # Before the first ring is on show: the near ring of the one being built, the near layer
    # then being the blocks that ring will complement (not blocks around a moving camera,
    # which change as it flies and cost a frame their light each time).
    building: NearRing | None = None

    @property
    def incoming_set(self) -> int:
        return 1 - self.current_set

    @property
    def changed(self) -> bool:
        return bool(self.render)

    def near_rings(self, camera: Camera, drift: Drift) -> tuple[NearRing, ...]:
        """The rings the near layer must complement, with their shares of the picture."""
        if self.current is None:
            if self.incoming is not None and self.fade > 0.0:
                ring = self.incoming
                return (NearRing(ring.geometry.centre_m, ring.drift, 1.0),)
            return (self.building or NearRing(camera.position_m, drift, 1.0),)
        cur = NearRing(self.current.geometry.centre_m, self.current.drift, 1.0 - self.fade)
        if self.incoming is None or self.fade <= 0.0:
            return (cur._replace(weight=1.0),)
        new = NearRing(self.incoming.geometry.centre_m, self.incoming.drift, self.fade)
        return (cur, new)


def _lit_otherwise(built: AtmosphereKey | None, sky: SkyParams, sun_deg: float) -> bool:
    """Whether the ring was lit by other atmosphere tables than this frame's, by more than
    the allowances: another visibility or humidity, or a sun more than `sun_deg` from its
    own. The daemon makes the tables off the frame path and a ring built meanwhile (after a
    time set, a new preset) is lit by the last tables made: it is built again, once, when
    the right ones come. The eye's height, also in the key, changes the air between the eye
    and the impostors, which the frames draw: no rebuild for it."""
    now = None if sky.atmosphere is None else sky.atmosphere.key
    if built is None or now is None or built == now:
        return False
    sun_apart_deg = abs(built.sun_elevation_deg - now.sun_elevation_deg)
    return (built.visibility_q, built.humidity_q) != (
        now.visibility_q,
        now.humidity_q,
    ) or sun_apart_deg > sun_deg


@dataclass(frozen=True)
class _Built:
    """What a ring was built from, to judge later whether it is stale."""

    state: WeatherState
    drift: Drift
    centre_m: tuple[float, float, float]
    sun_dir: tuple[float, float, float]
    # The physical atmosphere's tables the ring was lit with (None: the gradient sky).
    atmosphere: AtmosphereKey | None = None


class RingSchedule:
    def __init__(
        self,
        build: Builder,
        radius_m: float,
        mode: str = "async",
        fade_s: float = DEFAULT_FADE_S,
        policy: RingPolicy | None = None,
        slice_ms: float | None = None,
    ) -> None:
        """`slice_ms`: spread an impostor over frames so that each spends about this long on
        it (None: one whole impostor a frame, as Wang)."""
        if mode not in BUILD_MODES:
            raise ValueError(f"ring build mode must be one of {', '.join(BUILD_MODES)}: {mode!r}")
        self._build = build
        self.radius_m = radius_m
        self.mode = mode
        self.fade_s = max(0.0, fade_s)
        self.policy = policy or RingPolicy()
        self._executor: ThreadPoolExecutor | None = None
        self._current: RingScene | None = None
        self._current_set = 0
        self._newest: _Built | None = None  # the latest ring asked for
        self._pending: Future[RingScene] | None = None
        self._incoming: RingScene | None = None
        self._next_index = 0
        self._fade = 0.0
        self._version = 0
        self._retry_in_s = 0.0  # after a failed build, wait this long before the next
        self._forced: str | None = None  # a reason to rebuild given from outside (invalidate)
        self._closed = False
        # Set by `cancel`/`close`: the builder passes it to the scene work, which gives up at
        # its next block (`gather.check_cancel`), and no build starts after it.
        self._cancel = threading.Event()
        self._building: tuple[str, float] | None = None  # reason, monotonic start
        self._shown: WeatherState | None = None  # the latest state passed to `step`
        self._steady_s = 0.0  # how long what the ring shows of it has not changed
        self._shown_for_s = math.inf  # since the newest ring finished fading in
        self._weather_built = False  # the newest ring was built for a weather change
        self.slice_ms = slice_ms
        self._seconds_per_unit = FIRST_SECONDS_PER_UNIT
        self._cuts: ImpostorCuts | None = None  # of the impostor being drawn
        self._slice_start = 0
        self._slices = 0

    @property
    def current(self) -> RingScene | None:
        return self._current

    @property
    def cancel_event(self) -> threading.Event:
        """Set once the schedule is cancelled: what the builder hands the scene work."""
        return self._cancel

    def invalidate(self, reason: str) -> None:
        """Rebuild at the next chance whatever the thresholds say (`reason` goes in the
        trace): the clock was set, so the newest ring shows another time. A rebuild under way
        is followed by one more, judged when it ends."""
        self._forced = reason

    @property
    def busy(self) -> bool:
        """A rebuild is under way (building, rendering or fading)."""
        return self._pending is not None or self._incoming is not None

    def step(
        self, state: WeatherState, drift: Drift, camera: Camera, sky: SkyParams, dt_wall_s: float
    ) -> RingFrame:
        """Advance the schedule by one frame dt_wall_s after the previous one."""
        events: list[RingEvent] = []
        render: tuple[int, ...] = ()
        render_ring: RingScene | None = None
        render_set = 1 - self._current_set
        if self._shown is None or _ring_weather_differs(self._shown, state, None):
            self._steady_s = 0.0
        else:
            self._steady_s += dt_wall_s
        self._shown = state
        self._shown_for_s += dt_wall_s
        if self.mode == "immediate":
            reason = self._reason(state, drift, camera, sky)
            if reason is not None:
                fields = {"reason": reason, "centre_m": list(camera.position_m)}
                events.append(RingEvent("ring_rebuild_start", fields))
                self._current = self._start(state, drift, camera, sky)
                render, render_ring, render_set = tuple(range(RING_SIZE)), self._current, 0
                self._current_set = 0
                self._version += 1
                events.append(RingEvent("ring_rebuild_done", {}))
            return self._frame(render, render_ring, render_set, events)

        if self._incoming is not None and self._next_index >= RING_SIZE:
            # Complete since the previous frame: fade it in.
            if self._fade == 0.0:
                events.append(RingEvent("crossfade_start", {"fade_s": self.fade_s}))
            step = 1.0 if self.fade_s <= 0.0 else dt_wall_s / self.fade_s
            # (A fade of n whole frames must end on the nth, whatever the rounding.)
            self._fade = min(1.0, self._fade + step + 1e-9)
            self._version += 1
            if self._fade >= 1.0:
                self._current, self._incoming = self._incoming, None
                self._current_set = 1 - self._current_set
                self._fade = 0.0
                self._shown_for_s = 0.0
                events.append(RingEvent("crossfade_done", {}))
        self._retry_in_s = max(0.0, self._retry_in_s - dt_wall_s)
        if not self.busy and self._retry_in_s <= 0.0 and not self._cancel.is_set():
            reason = self._reason(state, drift, camera, sky)
            if reason is not None:
                fields = {"reason": reason, "centre_m": list(camera.position_m)}
                events.append(RingEvent("ring_rebuild_start", fields))
                self._building = (reason, time.monotonic())
                self._weather_built = reason == "weather"
                if self.mode == "sync":
                    # Built inline: the first impostor renders in this very frame.
                    self._pending = Future()
                    try:
                        self._pending.set_result(self._start(state, drift, camera, sky))
                    except Exception as exc:
                        self._pending.set_exception(exc)
                else:
                    self._pending = self._submit(state, drift, camera, sky)
        if self._pending is not None and self._pending.done():
            future, self._pending = self._pending, None
            self._building = None
            try:
                self._incoming = future.result()
                self._next_index = 0
            except BuildCancelled:
                events.append(RingEvent("ring_rebuild_cancelled", {}))
            except Exception as exc:  # a failed build keeps the old ring and tries again later
                log.error("ring build failed: %s; retrying in %g s", exc, RETRY_AFTER_S)
                self._newest = None
                self._retry_in_s = RETRY_AFTER_S
                events.append(RingEvent("ring_rebuild_failed", {"error": str(exc)}))
        piece: ImpostorSlice | None = None
        if self._incoming is not None and self._next_index < RING_SIZE:
            render, render_ring = (self._next_index,), self._incoming
            render_set = 1 - self._current_set
            done = True
            if self.slice_ms is not None:
                piece = self._next_slice(self._incoming)
                done = piece.last
            if done:
                done_fields: dict[str, Any] = {"index": self._next_index}
                if piece is not None:
                    done_fields["slices"] = self._slices
                events.append(RingEvent("impostor_rendered", done_fields))
                self._next_index += 1
                self._cuts = None
            self._version += 1
            if self._next_index == RING_SIZE:
                events.append(RingEvent("ring_rebuild_done", {}))
        return self._frame(render, render_ring, render_set, events, piece)

    def note_render(self, units: float, seconds: float) -> None:
        """The time a slice of `units` (its `ImpostorSlice.units`) took to draw, which sizes
        the next slices. Render thread only."""
        if units > 0.0 and seconds > 0.0 and math.isfinite(seconds):
            # Half the way to each new measure: steady, yet a slow start is forgotten soon.
            self._seconds_per_unit = 0.5 * (self._seconds_per_unit + seconds / units)

    def _next_slice(self, ring: RingScene) -> ImpostorSlice:
        index = self._next_index
        if self._cuts is None:
            self._cuts = ImpostorCuts(ring.geometry, index, ring.impostors[index].sprites)
            self._slice_start = 0
            self._slices = 0
        assert self.slice_ms is not None
        cuts = self._cuts
        budget = max(self.slice_ms / 1000.0 / self._seconds_per_unit, cuts.total / MAX_SLICES)
        start = self._slice_start
        stop, units = cuts.cut(start, budget)
        self._slice_start = stop
        self._slices += 1
        return ImpostorSlice(index, start, stop, stop >= len(cuts), units)

    def cancel(self) -> None:
        """Start no more builds, and make a build in flight give up at its next block (the
        scene work checks `cancel_event`). Safe from any thread; `close` still stops the
        worker."""
        self._cancel.set()

    def close(self, wait_s: float = 0.0) -> str | None:
        """Cancel and stop the worker, waiting up to wait_s for a build in flight to give
        up; idempotent. Returns what was abandoned, for the log ("the ring build (initial)
        2.1 s in"), or None when no build was under way."""
        if self._closed:
            return None
        self._closed = True
        self._cancel.set()
        cut = None
        pending, building = self._pending, self._building
        if pending is not None and _given_up(pending):
            # (`cancel` may already have made it give up: it is still what was cut.)
            reason, started = building if building is not None else ("?", time.monotonic())
            cut = f"the ring build ({reason}) {time.monotonic() - started:.1f} s in"
            try:
                pending.exception(timeout=max(0.0, wait_s))
            except TimeoutError:
                cut += ", its worker still finishing a stage"
            except CancelledError:
                pass
        if self._executor is not None:
            self._executor.shutdown(wait=False, cancel_futures=True)
            self._executor = None
        return cut

    # -- helpers ----------------------------------------------------------------------

    def _frame(
        self,
        render: tuple[int, ...],
        render_ring: RingScene | None,
        render_set: int,
        events: list[RingEvent],
        piece: ImpostorSlice | None = None,
    ) -> RingFrame:
        return RingFrame(
            current=self._current,
            current_set=self._current_set,
            incoming=self._incoming,
            render=render,
            render_ring=render_ring,
            render_set=render_set,
            fade=self._fade,
            version=self._version,
            events=tuple(events),
            render_slice=piece,
            building=(
                NearRing(self._newest.centre_m, self._newest.drift, 1.0)
                if self._current is None and self._newest is not None
                else None
            ),
        )

    def _start(
        self, state: WeatherState, drift: Drift, camera: Camera, sky: SkyParams
    ) -> RingScene:
        self._note_newest(state, drift, camera, sky)
        return self._build(state, drift, camera.position_m, sky)

    def _submit(
        self, state: WeatherState, drift: Drift, camera: Camera, sky: SkyParams
    ) -> Future[RingScene]:
        self._note_newest(state, drift, camera, sky)
        if self._executor is None:
            self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="wxsky-ring")
        return self._executor.submit(self._build, state, drift, camera.position_m, sky)

    def _note_newest(
        self, state: WeatherState, drift: Drift, camera: Camera, sky: SkyParams
    ) -> None:
        self._newest = _Built(
            state,
            drift,
            camera.position_m,
            sky.sun.direction_enu,
            None if sky.atmosphere is None else sky.atmosphere.key,
        )

    def _reason(
        self, state: WeatherState, drift: Drift, camera: Camera, sky: SkyParams
    ) -> str | None:
        """Why the newest ring no longer serves this frame, or None."""
        built = self._newest
        if built is None:
            return "initial"
        if self._forced is not None:
            reason, self._forced = self._forced, None
            return reason
        p = self.policy
        if not self._weather_built or self._shown_for_s >= p.weather_gap_s:
            if _ring_weather_differs(built.state, state, p):
                return "weather"
            if self._steady_s >= p.settle_s and _ring_weather_differs(built.state, state, None):
                return "weather"
        moved = moved_reason(
            built.centre_m, camera.position_m, self.radius_m, p.horizontal_frac, p.vertical_frac
        )
        if moved is not None:
            return moved
        cos_sun = sum(a * b for a, b in zip(sky.sun.direction_enu, built.sun_dir, strict=True))
        if math.degrees(math.acos(max(-1.0, min(1.0, cos_sun)))) > p.sun_deg:
            return "sun"
        if _lit_otherwise(built.atmosphere, sky, p.sun_deg):
            return "sky"
        limit = p.drift_frac * self.radius_m
        if len(built.drift) != len(drift) or any(
            math.hypot(a[0] - b[0], a[1] - b[1]) > limit
            for a, b in zip(built.drift, drift, strict=True)
        ):
            return "drift"
        return None


def _given_up(future: Future[RingScene]) -> bool:
    """A build still running, not started, or ended by its cancel flag."""
    if not future.done() or future.cancelled():
        return True
    return isinstance(future.exception(), BuildCancelled)


def _ring_weather_differs(a: WeatherState, b: WeatherState, policy: RingPolicy | None) -> bool:
    """True when the weather differs in what the ring's impostors show, by more than the
    policy's allowances (None: by anything): the layers and their seed, where the observer is,
    and the visibility (the impostors' haze). The clock is the sun test's; the wind is the
    drift test's (its effect is where the clouds have moved); temperature, dewpoint, pressure
    and the weather groups draw nothing in the ring, so a cockpit turning a temperature knob
    does not rebuild it with every step."""
    if a.seed != b.seed or a.observer != b.observer or len(a.layers) != len(b.layers):
        return True
    if policy is None:
        return a.layers != b.layers or a.visibility_m != b.visibility_m
    low = min(a.visibility_m, b.visibility_m)
    if abs(a.visibility_m - b.visibility_m) > policy.visibility_frac * low:
        return True
    return any(
        la.type != lb.type
        or abs(la.cover_oktas - lb.cover_oktas) > policy.cover_oktas
        or abs(la.base_m - lb.base_m) > policy.layer_m
        or abs(la.top_m - lb.top_m) > policy.layer_m
        for la, lb in zip(a.layers, b.layers, strict=True)
    )
