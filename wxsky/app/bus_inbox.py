"""Messages from the Zenoh bus's threads to the daemon's event loop, bounded.

Zenoh calls back on its own threads, once per message. Handing each over with its own
`call_soon_threadsafe` let a stranger's flood (100,000 `health/<name>` messages in 1.3 s)
queue 100,000 callbacks on the loop: tens of megabytes at once, which the allocator keeps
afterwards (issue 40's soak: RSS up a few MB per flood, never given back). The inbox holds
at most `limit` messages that may be dropped; one drain on the loop takes what waits. A
message that finds it full is dropped there and counted by kind (`on_full`), before any
work is done on it. Liveliness events (a master or channel coming or going) are never
dropped: missing one would keep a dead master followed.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
import time
from collections import Counter
from collections.abc import Callable
from typing import Any

log = logging.getLogger(__name__)

# Messages that may wait for the loop. A site's real traffic is a tick a frame, a state a
# second and a health a second per peer (64 at most): a few dozen a frame at 60 Hz.
INBOX_LIMIT = 1024


class BusInbox:
    """`put` from any thread; handlers run on `loop` as `handler(*values, arrived_s)`, in
    the order put, `arrived_s` the `time.monotonic()` of the put."""

    def __init__(
        self,
        loop: asyncio.AbstractEventLoop,
        on_full: Callable[[str, int], None],
        limit: int = INBOX_LIMIT,
    ) -> None:
        self._loop = loop
        self._on_full = on_full
        self.limit = limit
        self._lock = threading.Lock()
        self._items: list[tuple[Callable[..., None], tuple[Any, ...], float]] = []
        self._droppable = 0  # of _items
        self._full: Counter[str] = Counter()
        self._scheduled = False
        self._closed = False

    def put(
        self, kind: str, handler: Callable[..., None], values: tuple[Any, ...], droppable: bool
    ) -> None:
        arrived_s = time.monotonic()
        with self._lock:
            if self._closed:
                return
            if droppable:
                if self._droppable >= self.limit:
                    self._full[kind] += 1
                    return
                self._droppable += 1
            self._items.append((handler, values, arrived_s))
            if self._scheduled:
                return
            self._scheduled = True
        # RuntimeError: the loop closed under us, the daemon is stopping.
        with contextlib.suppress(RuntimeError):
            self._loop.call_soon_threadsafe(self._drain)

    def close(self) -> None:
        """Drop what waits and take no more; idempotent."""
        with self._lock:
            self._closed = True
            self._items.clear()
            self._droppable = 0

    def _drain(self) -> None:
        with self._lock:
            items, self._items = self._items, []
            self._droppable = 0
            full, self._full = self._full, Counter()
            self._scheduled = False
        for kind, count in full.items():
            self._on_full(kind, count)
        for handler, values, arrived_s in items:
            try:
                handler(*values, arrived_s)
            except Exception:  # a wxsky defect: one message must not cost the others
                log.exception("handling a bus message")
