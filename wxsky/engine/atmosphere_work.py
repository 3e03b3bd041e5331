"""The physical atmosphere's tables (`wxsky.scene.atmosphere`), made off the frame path.

A rebuild costs some 0.1 to 1 s of numpy (docs/atmosphere.md): far more than a frame. Sets
made once are kept on disk and read back by any later process (`lut_cache.py`). The
frames ask `luts_for` with the key of their sun, visibility, humidity and eye; while a key's
tables are being made on the worker thread, the frames keep the last tables made (the sky
moves by less than a step of the key meanwhile). Only the first call, with nothing to show,
waits for its tables; an engine that is not live (a snapshot, a test) waits for every key,
so its picture is of exactly its own sky.

A daemon's engine makes them in a child process below the frames (`process`, the ring
builds' `RingWorker`), not on a thread of its own: a rebuild is numpy with the GIL held
between its calls, and on 2 cores a thread of it beside the frames made one frame in ten of
the clear preset take 5 ms instead of 1 (the main thread waiting for the GIL, not working:
docs/performance.md). The child is started at the first rebuild, not with the engine.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass

from wxsky.engine.lut_cache import cached_luts
from wxsky.engine.ring_worker import DEFAULT_NICE, RingWorker
from wxsky.scene.atmosphere import AtmosphereKey, AtmosphereLuts, fresh_serial
from wxsky.scene.gather import BuildCancelled, CancelFlag

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class AtmosphereJob:
    """One key's tables, made in the worker process (`ring_worker.Job`)."""

    key: AtmosphereKey

    def run(self, cancel: CancelFlag | None = None) -> tuple[object, ...]:
        return (cached_luts(self.key),)


class AtmosphereWork:
    """Builds the tables for the latest key asked for, one at a time, off the frame path."""

    def __init__(self, wait: bool, process: bool = False, nice: int = DEFAULT_NICE) -> None:
        """`wait`: every call returns the tables of its own key (built at once if need be).
        `process`: the rebuilds run in a child process at `nice` below the frames, else on a
        thread of this one."""
        self._wait = wait
        self._process = process
        self._nice = nice
        self._worker: RingWorker | None = None
        self._cancel = threading.Event()
        self._lock = threading.Lock()
        self._pool: ThreadPoolExecutor | None = None
        self._current: AtmosphereLuts | None = None
        self._pending: tuple[AtmosphereKey, Future[AtmosphereLuts]] | None = None
        self.builds = 0  # tables made (status, tests)

    @property
    def pending(self) -> bool:
        """Tables for a newer key are being made: frames meanwhile show the last made."""
        return self._pending is not None

    def luts_for(self, key: AtmosphereKey) -> AtmosphereLuts:
        """The tables for `key` when made, else the last made (a rebuild is started)."""
        with self._lock:
            current, pending = self._current, self._pending
            if pending is not None and pending[1].done():
                self._pending = None
                try:
                    current = self._current = pending[1].result()
                except Exception:
                    log.exception("atmosphere tables for %s failed; keeping the last", pending[0])
                pending = None
            if current is not None and current.key == key:
                return current
            if current is None or self._wait:
                made = cached_luts(key)
                self.builds += 1
                self._current = made
                return made
            # One at a time: a newer key waits for the running build, then is asked again.
            if pending is None:
                if self._pool is None:
                    self._pool = ThreadPoolExecutor(1, thread_name_prefix="atmosphere")
                self._pending = (key, self._pool.submit(self._build, key))
            return current

    def _build(self, key: AtmosphereKey) -> AtmosphereLuts:
        if not self._process:
            made = cached_luts(key)
        else:
            with self._lock:
                if self._cancel.is_set():
                    raise BuildCancelled("atmosphere work closed")
                if self._worker is None:
                    self._worker = RingWorker(self._nice, label="atmosphere tables")
                worker = self._worker
            (got,) = worker.run(AtmosphereJob(key), self._cancel)
            assert isinstance(got, AtmosphereLuts)
            # A serial names a set of tables in the process that shows them (the textures,
            # the caches): the child's counter is not this one's.
            made = dataclasses.replace(got, serial=fresh_serial())
        self.builds += 1
        return made

    def close(self) -> None:
        """Stop the worker (a build under way on a thread is let finish, not waited for; the
        child process is told to exit, and killed after a second). Idempotent."""
        self._cancel.set()
        with self._lock:
            pool, self._pool = self._pool, None
            worker, self._worker = self._worker, None
        if pool is not None:
            pool.shutdown(wait=False, cancel_futures=True)
        if worker is not None:
            worker.close(0.1)  # the tables of a closing engine are of no use to anyone
