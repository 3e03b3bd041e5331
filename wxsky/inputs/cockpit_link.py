"""A cockpit device read by its own thread: open -> receive -> decode -> hand over; when the
device goes away (USB unplugged, bus-off, adapter error) it is closed and reopened with
back-off, and each change of state is logged once.

The reader thread never touches the engine: it merges what it decoded into one
`CockpitUpdate` per read and posts it to a `Mailbox`, which wakes the asyncio loop at most once
per batch. The tick loop is never blocked by a device, and a flood of frames costs the loop one
callback, not one per frame.
"""

from __future__ import annotations

import abc
import asyncio
import contextlib
import logging
import threading
from collections.abc import Callable, Sequence
from typing import Any, ClassVar

from wxsky.inputs.stats import InputStats
from wxsky.logs import RateLimitedLog
from wxsky.protocols.result import Decoded
from wxsky.weather.cockpit import ALL_GROUPS, CockpitUpdate

log = logging.getLogger("wxsky.inputs.cockpit")

FIRST_RETRY_S = 0.25
MAX_RETRY_S = 5.0


class Mailbox:
    """Hands updates from reader threads to the event loop, merged, without blocking either.

    A value replaced by a newer one of the same field before the loop took it (the loop was
    busy longer than the sender's period) is counted against the link that sent it
    (`superseded` in its status, per update): the newer value is applied, the older never
    shows."""

    def __init__(
        self, loop: asyncio.AbstractEventLoop, apply: Callable[[CockpitUpdate], None]
    ) -> None:
        self._loop = loop
        self._apply = apply
        self._lock = threading.Lock()
        self._pending: CockpitUpdate | None = None
        self._owners: dict[str, CockpitLink] = {}  # pending key -> the link that set it

    def poster(self, link: CockpitLink) -> Callable[[CockpitUpdate], None]:
        """`post` for one link's reader thread."""
        return lambda update: self.post(update, link)

    def post(self, update: CockpitUpdate, source: CockpitLink | None = None) -> None:
        """Called from any thread."""
        with self._lock:
            first = self._pending is None
            if source is not None:
                # Per update replaced (wholly or partly), not per field: a wind is one value.
                replaced = {self._owners[k] for k in update.fields_set() if k in self._owners}
                for earlier in replaced:
                    earlier.superseded += 1
                self._owners.update(dict.fromkeys(update.fields_set(), source))
            self._pending = update if first else self._pending.merged(update)  # type: ignore[union-attr]
        if first:
            # RuntimeError: the loop has closed because the daemon is shutting down.
            with contextlib.suppress(RuntimeError):
                self._loop.call_soon_threadsafe(self._drain)

    def _drain(self) -> None:
        with self._lock:
            update, self._pending = self._pending, None
            self._owners.clear()
        if update is not None:
            self._apply(update)


class CockpitLink(abc.ABC):
    """One cockpit device. `start` runs the reader thread, `close` stops it (idempotent).

    Subclasses implement the protected hooks: `_open`, `_receive` (blocking for at most about
    `POLL_S`, raising when the device is gone), `_decode` (pure) and `_close_device`."""

    kind: ClassVar[str]
    POLL_S: ClassVar[float] = 0.1

    def __init__(self, name: str, device: str, fields: Sequence[str] = ALL_GROUPS) -> None:
        self.name = name
        self.device = device
        self.fields = tuple(fields)
        self.stats = InputStats(name, self.kind)
        self.stats.ok = False
        self.ignored = 0
        self.reopens = 0
        # Values replaced by a newer one of the same field before they were applied (in one
        # read, or waiting in the mailbox): latest wins, the older never shows.
        self.superseded = 0
        self._state = "starting"
        self.stats.detail = self._detail()
        self._warn = RateLimitedLog(log)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._post: Callable[[CockpitUpdate], None] = lambda update: None

    @classmethod
    @abc.abstractmethod
    def from_section(cls, section: Any) -> CockpitLink:
        """A link configured by its config section (`[[serial]]`, `[[can]]`, ...)."""

    # -- public API -------------------------------------------------------------------

    def start(self, post: Callable[[CockpitUpdate], None]) -> None:
        if self._thread is not None:
            raise RuntimeError(f"{self.name} already started")
        self._post = post
        self._thread = threading.Thread(target=self._run, name=f"wxsky-{self.name}", daemon=True)
        self._thread.start()

    def close(self, timeout_s: float = 1.0) -> bool:
        """Stop the reader and release the device; True when the thread ended in time."""
        self._stop.set()
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.join(timeout_s)
            if thread.is_alive():
                log.warning(
                    "%s: reader still blocked after %.1f s; abandoned it", self.name, timeout_s
                )
                return False
        return True

    def __enter__(self) -> CockpitLink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def handle(self, results: Sequence[Decoded]) -> CockpitUpdate | None:
        """Count what a read decoded to and merge the allowed values into one update."""
        merged: CockpitUpdate | None = None
        for result in results:
            if result.error:
                self.stats.error(result.error)
                self._warn.warning(
                    f"{self.name}:{result.error.split(':')[0]}", f"{self.name}: {result.error}"
                )
                continue
            if result.ignored:
                self.ignored += 1
                self._warn.warning(f"{self.name}:ignored", f"{self.name}: ignored {result.ignored}")
                continue
            self.stats.message()
            update = result.update
            if update is None:
                continue  # consumed (a heading kept for later sentences)
            allowed = update.restricted(self.fields)
            if allowed.empty:
                self.ignored += 1
                continue
            if merged is None:
                merged = allowed
            else:  # one read with two values of a field (the reader fell behind): latest wins
                self.superseded += bool(merged.fields_set() & allowed.fields_set())
                merged = merged.merged(allowed)
        self.stats.detail = self._detail()
        return merged

    # -- hooks ------------------------------------------------------------------------

    @abc.abstractmethod
    def _open(self) -> None: ...

    @abc.abstractmethod
    def _receive(self) -> Any:
        """Whatever arrived within about POLL_S (None or empty for nothing)."""

    @abc.abstractmethod
    def _decode(self, received: Any) -> list[Decoded]: ...

    @abc.abstractmethod
    def _close_device(self) -> None: ...

    # -- the reader thread ------------------------------------------------------------

    def _run(self) -> None:
        retry_s = FIRST_RETRY_S
        while not self._stop.is_set():
            try:
                self._open()
            except Exception as exc:  # any driver's failure to open is a state, not a crash
                self._set_state(False, f"cannot open {self.device}: {_reason(exc)}")
                self._stop.wait(retry_s)
                retry_s = min(MAX_RETRY_S, retry_s * 2.0)
                continue
            if self._state != "starting":
                self.reopens += 1
            self._set_state(True, "open")
            retry_s = FIRST_RETRY_S
            try:
                self._read_until_stopped()
            except Exception as exc:
                self._set_state(False, f"lost {self.device}: {_reason(exc)}")
            finally:
                # Closing a vanished device may fail; it is gone either way.
                with contextlib.suppress(Exception):
                    self._close_device()
            self._stop.wait(FIRST_RETRY_S)

    def _read_until_stopped(self) -> None:
        while not self._stop.is_set():
            received = self._receive()
            if not received:
                continue
            try:
                results = self._decode(received)
            except Exception as exc:  # a decoder bug must cost one read, not the link
                log.exception("%s: decoder failed", self.name)
                results = [Decoded.reject(f"internal decoder error: {exc}")]
            update = self.handle(results)
            if update is not None:
                self._post(update)

    def _set_state(self, ok: bool, state: str) -> None:
        changed = ok != self.stats.ok or self._state == "starting"
        self.stats.ok = ok
        self._state = state
        self.stats.detail = self._detail()
        if not changed:
            return
        if ok:
            log.info("%s: %s %s", self.name, state, self.device)
        else:
            log.warning("%s: %s (retrying every %.0f s at most)", self.name, state, MAX_RETRY_S)

    def _detail(self) -> dict[str, Any]:
        return {
            "device": self.device,
            "state": self._state,
            "ignored": self.ignored,
            "reopens": self.reopens,
            "superseded": self.superseded,
            "fields": list(self.fields),
        }


def _reason(exc: BaseException) -> str:
    text = str(exc).strip() or type(exc).__name__
    return text.splitlines()[0]
