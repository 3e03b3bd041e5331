"""The near layer's sets made off the frame path (issue 39: a frame every tick, whatever
happens).

A frame draws the near blocks around the ring it complements; a set of them, with Harris's
light on it and its convective cells, is made once and kept (`scene.near_sets`). Most sets
arrive ready with the ring that needs them (the ring's worker makes them). The rest, a new
site, a clock set by hours, each step of a change of weather, the light once the sun has
moved on, took a frame 0.1-0.6 s to make (0.5-5 s on a busy machine), and no frame was
published meanwhile.

`NearWork` only looks up what a frame needs (`inputs`): where something is missing it asks
for it and answers None, and the engine draws that frame from the last inputs it had (the
clouds where they last stood, under this frame's camera and sun: `SkyEngine.advance`). The
asks are served one at a time, newest first (an older ask the weather has moved past is
dropped), on a thread of their own, in a child process where the ring's builds run in one
(`ring_worker.RingWorker`, so the work shares no GIL with the frames), at `NEAR_NICE`: below
the frames, but not in the idle class, so that a busy machine slows the new sky rather than
starving it.
"""

from __future__ import annotations

import contextlib
import logging
import os
import threading
import time
from collections import OrderedDict
from collections.abc import Hashable
from dataclasses import dataclass

from wxsky.engine.ring_worker import RingWorker, RingWorkerError
from wxsky.scene.gather import (
    BuildCancelled,
    CancelFlag,
    Drift,
    NearRing,
    kept_near_blocks,
    near_set_key,
    selecting_now,
)
from wxsky.scene.layout import SceneSettings
from wxsky.scene.near_sets import (
    NearInputs,
    PreparedNear,
    install_near,
    kept_light,
    near_set,
    needs_light,
)
from wxsky.scene.shading_harris import LIGHT_REUSE_DEG
from wxsky.scene.sky import SkyParams
from wxsky.scene.tower_field import LayerEpoch, candidates_key, kept_candidates
from wxsky.weather.state import WeatherState

log = logging.getLogger(__name__)

NEAR_NICE = 10
MADE_KEPT = 4  # sets this work made, held here too, so an install elsewhere cannot evict them


@dataclass(frozen=True)
class NearJob:
    """One near set to make, with its light for `sky` and (with `epochs`) its cells."""

    state: WeatherState
    drift: Drift
    rings: tuple[NearRing, ...]
    sky: SkyParams
    settings: SceneSettings
    epochs: tuple[LayerEpoch | None, ...] | None

    def run(self, cancel: CancelFlag | None = None) -> tuple[object, ...]:
        made = near_set(self.state, self.drift, self.rings, self.sky, self.settings, self.epochs)
        return (() if made is None else (made,),)


class NearWork:
    """Looks up a frame's near layer, and makes what is missing on its own thread (`process`:
    through a child process). `gate`: the work waits for it to be set before each job (tests
    hold the work back with it). `close` is idempotent."""

    def __init__(
        self, process: bool = True, nice: int = NEAR_NICE, gate: threading.Event | None = None
    ) -> None:
        self.gate = gate
        self._worker = RingWorker(nice, label="near layer") if process else None
        self._nice = nice
        self._cond = threading.Condition()
        self._wanted: tuple[Hashable, NearJob] | None = None  # the newest ask not yet taken
        self._busy: Hashable | None = None  # the ask being made
        self._made: OrderedDict[Hashable, PreparedNear] = OrderedDict()
        self._closed = False
        self._cancel = threading.Event()
        self.made = 0  # sets made (or lit, or their cells found) for frames
        self.busy_s = 0.0
        self.asked = 0
        self._thread = threading.Thread(target=self._run, name="wxsky-near", daemon=True)
        if self._worker is not None:
            self._worker.start()
        self._thread.start()

    @property
    def pending(self) -> bool:
        """An ask is waiting or being made."""
        with self._cond:
            return self._wanted is not None or self._busy is not None

    def inputs(
        self,
        state: WeatherState,
        drift: Drift,
        rings: tuple[NearRing, ...],
        sky: SkyParams,
        settings: SceneSettings,
        epochs: tuple[LayerEpoch | None, ...] | None,
    ) -> NearInputs | None:
        """The frame's near layer if everything it needs is kept; else None, having asked
        for what is missing. Never makes anything itself."""
        radius_m = settings.ring_radius_m
        rings = selecting_now(rings, drift, radius_m)
        wanted = near_set_key(state, drift, rings, radius_m, settings.max_range_m)
        if wanted is None:
            return None
        if settings.max_towers <= 0:
            epochs = None
        blocks = kept_near_blocks(wanted.key)
        if blocks is None:
            made = self._kept_made(wanted.key)
            blocks = None if made is None else made.blocks
        missing = blocks is None
        scattered = found = None
        if blocks is not None and settings.shading == "harris" and needs_light(blocks):
            scattered = kept_light(blocks, sky, LIGHT_REUSE_DEG)
            missing = scattered is None
        if blocks is not None and not missing and epochs is not None:
            found = kept_candidates(blocks, state, epochs)
            missing = found is None
        if missing:
            cells = None if epochs is None else candidates_key(state, epochs)
            self._ask((wanted.key, cells), NearJob(state, drift, rings, sky, settings, epochs))
            return None
        assert blocks is not None
        placed = blocks.placed(drift, rings)
        if placed is None:  # a ring weighing nothing: the last layer drawn stands
            return None
        return NearInputs(placed[0], placed[1], blocks, scattered, found)

    def close(self, wait_s: float = 1.0) -> None:
        with self._cond:
            if self._closed:
                return
            self._closed = True
            self._wanted = None
            self._cond.notify_all()
        self._cancel.set()
        if self._worker is not None:
            self._worker.close(wait_s)
        self._thread.join(max(0.05, wait_s))
        if self._thread.is_alive():
            log.warning("near layer work still making a set after %.1f s; left to finish", wait_s)

    def __enter__(self) -> NearWork:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- internals ---------------------------------------------------------------------------

    def _kept_made(self, key: Hashable) -> PreparedNear | None:
        with self._cond:
            made = self._made.get(key)
        if made is not None:
            install_near((made,))  # evicted from the shared cache by a later install
        return made

    def _ask(self, key: Hashable, job: NearJob) -> None:
        with self._cond:
            if self._closed or key == self._busy:
                return
            if self._wanted is None or self._wanted[0] != key:
                self.asked += 1
            self._wanted = (key, job)  # the newest ask replaces an older one not yet taken
            self._cond.notify()

    def _run(self) -> None:
        if self._worker is None:
            # On a thread of the daemon's process, below the frames (Linux: per thread).
            with contextlib.suppress(AttributeError, OSError):
                os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), self._nice)
        while True:
            with self._cond:
                while self._wanted is None and not self._closed:
                    self._cond.wait()
                if self._closed:
                    return
            gate = self.gate
            if gate is not None:
                while not gate.wait(0.1):
                    if self._closed:
                        return
            with self._cond:
                if self._wanted is None:
                    continue
                key, job = self._wanted
                self._wanted, self._busy = None, key
            t0 = time.thread_time() if self._worker is None else time.perf_counter()
            try:
                made = self._make(job)
            except BuildCancelled:
                return
            except RingWorkerError as exc:
                log.warning("near layer: %s; trying again", exc)
                made = ()
            except Exception:  # a bug here must not stop the near layer for the daemon's life
                log.exception("near layer set failed")
                made = ()
            install_near(made)
            with self._cond:
                for item in made:
                    self._made[item.key] = item
                    self._made.move_to_end(item.key)
                while len(self._made) > MADE_KEPT:
                    self._made.popitem(last=False)
                self._busy = None
                self.made += len(made)
                spent = time.thread_time() if self._worker is None else time.perf_counter()
                self.busy_s += spent - t0

    def _make(self, job: NearJob) -> tuple[PreparedNear, ...]:
        worker = self._worker
        out = job.run(self._cancel) if worker is None else worker.run(job, self._cancel)
        made = out[0]
        assert isinstance(made, tuple)
        return made
