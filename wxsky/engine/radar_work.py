"""The weather radar's pictures, made off the frame path (issue 43, item 5).

A host asks for a picture (range, tilt, size) over the control channel; the answer is the
last picture made for those settings, at once, and a new one is made on this thread from the
weather, drift and aircraft position of the moment of asking (`scene.radar.radar_picture`).
A host that asks faster than pictures can be made gets the last one again: the frame loop
never waits for the radar, and at most one request waits here (a newer one replaces it)."""

from __future__ import annotations

import contextlib
import logging
import os
import threading
import time
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass

from wxsky.scene.radar import RadarPicture, radar_picture
from wxsky.weather.state import WeatherState

log = logging.getLogger(__name__)

THREAD_NICE = 10
PICTURES_KEPT = 8  # by settings, the least recently asked for dropped first

RadarKey = tuple[float, float, int]  # range_nm, tilt_deg, size_px


@dataclass(frozen=True)
class RadarJob:
    key: RadarKey
    state: WeatherState
    drift: tuple[tuple[float, float], ...]
    centre_m: tuple[float, float, float]


@dataclass(frozen=True)
class Made:
    picture: RadarPicture
    made_s: float  # time.monotonic() when it was finished
    took_s: float
    time_utc: str  # the weather's clock it shows


class RadarWork:
    """`ask` hands out pictures; `close()` stops the thread (idempotent)."""

    def __init__(self) -> None:
        self._lock = threading.Condition()
        self._waiting: RadarJob | None = None
        self._made: OrderedDict[RadarKey, Made] = OrderedDict()
        self._closed = False
        self.made_count = 0
        self.failed = 0
        self._thread = threading.Thread(target=self._run, name="wxsky-radar", daemon=True)
        self._thread.start()

    def ask(
        self,
        key: RadarKey,
        state: WeatherState,
        drift: Sequence[tuple[float, float]],
        centre_m: tuple[float, float, float],
    ) -> Made | None:
        """The last picture made for `key` (None: none yet), and a new one set going for the
        weather and position given."""
        job = RadarJob(key, state, tuple(drift), centre_m)
        with self._lock:
            if self._closed:
                raise RuntimeError("the radar work is closed")
            self._waiting = job
            self._lock.notify_all()
            made = self._made.get(key)
            if made is not None:
                self._made.move_to_end(key)
            return made

    def latest(self, key: RadarKey) -> Made | None:
        """The last picture made for `key`, asking for nothing (the radar layer looks every
        frame for a new one and asks only every `[radar] every_s`)."""
        with self._lock:
            return self._made.get(key)

    def close(self, wait_s: float = 2.0) -> None:
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._waiting = None
            self._lock.notify_all()
        self._thread.join(wait_s)
        if self._thread.is_alive():
            log.warning("radar picture still being made after %.1f s; left to finish", wait_s)

    def __enter__(self) -> RadarWork:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _run(self) -> None:
        # Below the frames, as the towers' lighting runs (a thread has its own nice value).
        with contextlib.suppress(AttributeError, OSError):
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), THREAD_NICE)
        while True:
            with self._lock:
                while self._waiting is None and not self._closed:
                    self._lock.wait()
                if self._closed:
                    return
                job, self._waiting = self._waiting, None
            assert job is not None
            start = time.monotonic()
            try:
                range_nm, tilt_deg, size_px = job.key
                picture = radar_picture(
                    job.state, job.drift, job.centre_m, range_nm, tilt_deg, size_px
                )
            except Exception:  # a bug here must not stop the radar for the daemon's life
                log.exception("radar picture %s failed", job.key)
                with self._lock:
                    self.failed += 1
                continue
            end = time.monotonic()
            made = Made(picture, end, end - start, job.state.time_utc.isoformat())
            with self._lock:
                self._made[job.key] = made
                self._made.move_to_end(job.key)
                while len(self._made) > PICTURES_KEPT:
                    self._made.popitem(last=False)
                self.made_count += 1
                self._lock.notify_all()
