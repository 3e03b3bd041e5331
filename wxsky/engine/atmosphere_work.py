"""The physical atmosphere's tables (`wxsky.scene.atmosphere`), made off the frame path.

A rebuild costs some 0.1 to 1 s of numpy (docs/atmosphere.md): far more than a frame. The
frames ask `luts_for` with the key of their sun, visibility, humidity and eye; while a key's
tables are being made on the worker thread, the frames keep the last tables made (the sky
moves by less than a step of the key meanwhile). Only the first call, with nothing to show,
waits for its tables; an engine that is not live (a snapshot, a test) waits for every key,
so its picture is of exactly its own sky.
"""

from __future__ import annotations

import logging
import threading
from concurrent.futures import Future, ThreadPoolExecutor

from wxsky.scene.atmosphere import AtmosphereKey, AtmosphereLuts, build_luts

log = logging.getLogger(__name__)


class AtmosphereWork:
    """Builds the tables for the latest key asked for, one at a time, on a thread."""

    def __init__(self, wait: bool) -> None:
        """`wait`: every call returns the tables of its own key (built at once if need be)."""
        self._wait = wait
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
                made = build_luts(key)
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
        made = build_luts(key)
        self.builds += 1
        return made

    def close(self) -> None:
        """Stop the worker (a build under way is let finish, not waited for)."""
        with self._lock:
            pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=False, cancel_futures=True)
