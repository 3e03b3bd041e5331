"""What every input reports in `wxsky status`, and rate-limited warnings for bad input."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Any


@dataclass
class InputStats:
    name: str
    kind: str
    messages: int = 0
    errors: int = 0
    last_error: str = ""
    ok: bool = True  # the input itself works; a client's bad message does not make it fail
    last_message_at: float | None = None  # time.monotonic() of the last good message
    detail: dict[str, Any] = field(default_factory=dict)  # input-specific status fields

    def message(self, count: int = 1) -> None:
        self.messages += count
        self.last_message_at = time.monotonic()

    def error(self, text: str, count: int = 1) -> None:
        self.errors += count
        self.last_error = text

    def to_dict(self) -> dict[str, Any]:
        since = None
        if self.last_message_at is not None:
            since = time.monotonic() - self.last_message_at
        return {
            "name": self.name,
            "kind": self.kind,
            "ok": self.ok,
            "messages": self.messages,
            "errors": self.errors,
            "last_error": self.last_error,
            "last_message_s": since,
            **self.detail,
        }


class RateLimitedLog:
    """Logs each kind of warning at most once per interval, then says how many it held back,
    so a feed full of junk rows cannot flood the log."""

    def __init__(self, logger: logging.Logger, interval_s: float = 60.0) -> None:
        self._log = logger
        self._interval_s = interval_s
        self._last: dict[str, float] = {}
        self._held: dict[str, int] = {}

    def warning(self, kind: str, message: str) -> None:
        now = time.monotonic()
        last = self._last.get(kind)
        if last is not None and now - last < self._interval_s:
            self._held[kind] = self._held.get(kind, 0) + 1
            return
        held = self._held.pop(kind, 0)
        suffix = f" (and {held} more like it since the last report)" if held else ""
        self._last[kind] = now
        self._log.warning("%s%s", message, suffix)
