"""The towers' volumes and light, made off the frame path (issue 17; docs/towers.md).

A frame's towers (`FrameScene.towers`) need the lit automaton steps around their ages
(`tower_field.lit_volume`): an automaton step of a 64^3 tower costs about 2 ms and lighting it
about 30 ms, once every STEP_S of sim time, and a tower seen for the first time may need
minutes of steps at once. `TowerWork` keeps each tower's automaton and the lit steps, and
makes what is missing either at once (`mode="immediate"`: a snapshot waits for its towers) or
on its own thread (`"async"`: the daemon, whose frames must not wait): a frame then shows the
newest lit step it has for each tower, and a tower never seen is left out until its first
step is ready. The step after the one on show is asked for ahead of time, so a tower moves
from step to step without waiting.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import threading
import time
from collections import OrderedDict

from wxsky.scene.shading_harris import Lights, scene_lights
from wxsky.scene.sky import SkyParams
from wxsky.scene.tower_field import LitVolume, TowerShow, lights_key, lit_volume, still_lit
from wxsky.towers.volume import STEP_S, TowerSpec, TowerVolume

log = logging.getLogger(__name__)

MODES = ("immediate", "async")
LIT_PER_TOWER = 4  # lit steps kept per tower: the pair on show, the next, one spare
MIN_TOWERS_KEPT = 8
THREAD_NICE = 10  # the lighting thread's nice value, over the daemon's

StepKey = tuple[TowerSpec, int]  # a tower and an automaton step

# Memory (issue 40): a thunderstorm or towering-cumulus sky took the daemon from about 216 MB
# to 540-700 MB, levelling off: these caches, the engine's lit steps (`TowerWork`) and the
# renderer's tower textures (`render.towers`) filling up to their bounds, plus the lighting
# thread's transient arrays (tens of MB, kept by the allocator). A lit step is 8 * grid^3
# bytes (2 MiB at 64^3; a cloud model's grid 128 makes it 16 MiB) and an automaton 6 * grid^3
# (1.5 MiB and 12 MiB), so the process-wide caches below are bounded in bytes, not counts:
# at most 96 MiB of automata and 64 MiB of shared lit steps, whatever the grid
# (docs/reliability.md, Limits: "tower caches").

# Every tower's automaton in this process, shared by the engines in it (a snapshot tool's
# pictures at several times step the same towers on rather than from their births again); each
# is stepped under its own lock. The least recently asked for goes first once the bytes pass
# VOLUMES_KEPT_BYTES, keeping at least MIN_VOLUMES_KEPT (as many towers as a frame shows).
VOLUMES_KEPT_BYTES = 96 << 20
MIN_VOLUMES_KEPT = 8
_volumes: OrderedDict[TowerSpec, tuple[TowerVolume, threading.Lock]] = OrderedDict()
_volumes_bytes = 0
_volumes_lock = threading.Lock()


def automaton_bytes(spec: TowerSpec) -> int:
    """What an automaton of `spec` holds at most: two states of three boolean fields."""
    return 6 * spec.grid**3


# Lit steps made in this process, shared too: engines for the same weather at the same time
# (a snapshot tool's headings, its calm and windy skies) light each step once; bounded by
# their bytes, the most recent one always kept.
LIT_SHARED_BYTES = 64 << 20
_shared_lit: OrderedDict[tuple[object, ...], LitVolume] = OrderedDict()
_shared_lit_bytes = 0


def shared_lit(key: tuple[object, ...]) -> LitVolume | None:
    with _volumes_lock:
        found = _shared_lit.get(key)
        if found is not None:
            _shared_lit.move_to_end(key)
        return found


def share_lit(lit: LitVolume) -> None:
    global _shared_lit_bytes
    with _volumes_lock:
        old = _shared_lit.pop(lit.key, None)
        if old is not None:
            _shared_lit_bytes -= old.texels.nbytes
        _shared_lit[lit.key] = lit
        _shared_lit_bytes += lit.texels.nbytes
        while _shared_lit_bytes > LIT_SHARED_BYTES and len(_shared_lit) > 1:
            _shared_lit_bytes -= _shared_lit.popitem(last=False)[1].texels.nbytes


def tower_volume(spec: TowerSpec) -> tuple[TowerVolume, threading.Lock]:
    """The process's automaton of `spec` and the lock to hold while stepping it."""
    global _volumes_bytes
    with _volumes_lock:
        found = _volumes.get(spec)
        if found is None:
            found = (TowerVolume(spec), threading.Lock())
            _volumes[spec] = found
            _volumes_bytes += automaton_bytes(spec)
            while _volumes_bytes > VOLUMES_KEPT_BYTES and len(_volumes) > MIN_VOLUMES_KEPT:
                _volumes_bytes -= automaton_bytes(_volumes.popitem(last=False)[0])
        _volumes.move_to_end(spec)
        return found


def cache_info() -> dict[str, int]:
    """The process-wide tower caches: entries, bytes and bounds (for tests and status)."""
    with _volumes_lock:
        return {
            "automata": len(_volumes),
            "automata_bytes": _volumes_bytes,
            "automata_limit_bytes": VOLUMES_KEPT_BYTES,
            "lit_steps": len(_shared_lit),
            "lit_bytes": _shared_lit_bytes,
            "lit_limit_bytes": LIT_SHARED_BYTES,
        }


class TowerWork:
    """Lit tower steps for the frames; `close()` stops the thread (idempotent). A lit step
    serves until the sky's lights move away from those it was lit by (`still_lit`); it is
    then lit again, and shown as it was meanwhile."""

    def __init__(self, mode: str = "immediate", towers_kept: int = MIN_TOWERS_KEPT) -> None:
        if mode not in MODES:
            raise ValueError(f"tower work mode must be one of {', '.join(MODES)}")
        self.mode = mode
        self._kept = max(MIN_TOWERS_KEPT, towers_kept)
        self._lit: OrderedDict[StepKey, LitVolume] = OrderedDict()
        self._shown: dict[TowerSpec, tuple[LitVolume, ...]] = {}  # the last pair on show
        self._wanted: OrderedDict[StepKey, SkyParams] = OrderedDict()
        self._lock = threading.Condition()
        self._closed = False
        self._thread: threading.Thread | None = None
        self.made = 0  # lit steps handed out, for the bench and tests
        self.lit_count = 0  # of which lit here (not found made by another engine)
        self.busy_s = 0.0  # the CPU time that lighting took
        # The thread waits for this Event before each step, where one is set (tests hold the
        # work back with it: `SkyEngine.work_gate`).
        self.gate: threading.Event | None = None
        if mode == "async":
            self._thread = threading.Thread(target=self._run, name="wxsky-towers", daemon=True)
            self._thread.start()

    @property
    def pending(self) -> int:
        """Lit steps asked for and not made yet."""
        with self._lock:
            return len(self._wanted)

    def fill(self, shows: tuple[TowerShow, ...], sky: SkyParams) -> tuple[TowerShow, ...]:
        """The frame's towers with their lit steps (`TowerShow.volumes`, `frac`); in async
        mode those not ready keep no volumes (the renderer leaves them out)."""
        if not shows:
            return shows
        if self.mode == "async":
            self._drop_unwanted({s.spec for s in shows})
        lights = scene_lights(sky)
        out = []
        for show in shows:
            n = show.step
            frac = show.age_s / STEP_S - n
            keys = [(show.spec, n + k) for k in range(3)]
            pair: tuple[LitVolume, ...]
            if self.mode == "immediate":
                pair = (self._lit_now(keys[0], sky, lights), self._lit_now(keys[1], sky, lights))
            else:
                pair = self._ready(keys, sky, lights)
            if len(pair) == 2:
                chosen: tuple[LitVolume, ...] = pair
            elif len(pair) == 1:
                chosen, frac = pair, 0.0
            else:
                chosen, frac = self._shown.get(show.spec, ())[-1:], 0.0
            if chosen:
                self._shown[show.spec] = chosen
            out.append(dataclasses.replace(show, volumes=chosen, frac=frac if chosen else 0.0))
        for spec in [s for s in self._shown if s not in {sh.spec for sh in shows}]:
            del self._shown[spec]
        return tuple(out)

    def close(self, wait_s: float = 1.0) -> None:
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._wanted.clear()
            self._lock.notify_all()
        if self._thread is not None:
            self._thread.join(wait_s)
            if self._thread.is_alive():
                log.warning("tower work still lighting a step after %.1f s; left to finish", wait_s)

    def __enter__(self) -> TowerWork:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- internals ---------------------------------------------------------------------------

    def _ready(self, keys: list[StepKey], sky: SkyParams, lights: Lights) -> tuple[LitVolume, ...]:
        """The lit steps of `keys[:2]` as far as made (asking for those missing or lit for
        another sky, and for the step after them)."""
        found = []
        with self._lock:
            for key in keys:
                lit = self._lit.get(key)
                if (lit is None or not still_lit(lit, lights)) and key not in self._wanted:
                    self._wanted[key] = sky
                    self._lock.notify()
                elif key in self._wanted:
                    self._wanted[key] = sky  # light it for the latest sky
                found.append(lit)
        first, second = found[0], found[1]
        if first is not None and second is not None:
            return (first, second)
        return (first,) if first is not None else ()

    def _lit_now(self, key: StepKey, sky: SkyParams, lights: Lights) -> LitVolume:
        with self._lock:
            found = self._lit.get(key)
            if found is not None:
                self._lit.move_to_end(key)
        if found is not None and still_lit(found, lights):
            return found
        return self._make(key, sky)

    def _make(self, key: StepKey, sky: SkyParams) -> LitVolume:
        spec, step = key
        made = shared_lit((spec, step, lights_key(scene_lights(sky))))
        if made is None:
            t0 = time.thread_time()  # CPU time: the thread waits behind the frames at nice 10
            volume, stepping = tower_volume(spec)
            with stepping:
                made = lit_volume(volume, step, sky)
            share_lit(made)
            with self._lock:
                self.busy_s += time.thread_time() - t0
                self.lit_count += 1
        with self._lock:
            self._lit[key] = made
            self._lit.move_to_end(key)
            while len(self._lit) > LIT_PER_TOWER * self._kept:
                self._lit.popitem(last=False)
            self.made += 1
        return made

    def _drop_unwanted(self, specs: set[TowerSpec]) -> None:
        """Forget asks for towers no longer on show (the eye moved on, the weather changed)."""
        with self._lock:
            for key in [k for k in self._wanted if k[0] not in specs]:
                del self._wanted[key]

    def _run(self) -> None:
        # Below the frames, as the ring's worker process runs: on Linux a thread has its own
        # nice value. Where it cannot be set the work runs at the daemon's priority.
        with contextlib.suppress(AttributeError, OSError):
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), THREAD_NICE)
        while True:
            with self._lock:
                while not self._wanted and not self._closed:
                    self._lock.wait()
                if self._closed:
                    return
            gate = self.gate
            if gate is not None and not gate.wait(0.1):
                continue
            with self._lock:
                if self._closed:
                    return
                if not self._wanted:
                    continue
                key, sky = self._wanted.popitem(last=False)
            try:
                self._make(key, sky)
            except Exception:  # a bug here must not stop the towers for the daemon's life
                log.exception("tower step %d of cell %s failed", key[1], key[0].cell)
