"""Log lines that bad input cannot multiply or inflate: each kind of warning at most once per
interval (then a count of what was held back), and every quoted piece of outside input cut
to a bounded length. A daemon beside hardware and hosts that misbehave must keep a log a
person can read, whatever arrives.
"""

from __future__ import annotations

import logging
import time

MAX_QUOTE_CHARS = 200  # how much of a foreign value a log line or error quotes


def clip(text: object, limit: int = MAX_QUOTE_CHARS) -> str:
    """`text` as one line of at most `limit` characters, saying how much was cut."""
    s = str(text).replace("\r", "\\r").replace("\n", "\\n")
    if len(s) <= limit:
        return s
    return f"{s[:limit]}… ({len(s) - limit} more characters)"


class RateLimitedLog:
    """Logs each kind of warning at most once per interval, then says how many it held back,
    so a feed full of junk rows or a client flooding bad requests cannot flood the log. The
    message is clipped: a line never carries more than a bounded piece of what came in."""

    def __init__(
        self, logger: logging.Logger, interval_s: float = 60.0, max_chars: int = 2 * MAX_QUOTE_CHARS
    ) -> None:
        self._log = logger
        self._interval_s = interval_s
        self._max_chars = max_chars
        self._last: dict[str, float] = {}
        self._held: dict[str, int] = {}

    def warning(self, kind: str, message: str) -> bool:
        """Log `message` unless `kind` was logged within the interval; True when logged."""
        return self.log(logging.WARNING, kind, message)

    def log(self, level: int, kind: str, message: str) -> bool:
        now = time.monotonic()
        last = self._last.get(kind)
        if last is not None and now - last < self._interval_s:
            self._held[kind] = self._held.get(kind, 0) + 1
            if len(self._held) > 1024:
                # Kinds built from outside input must not grow without bound either.
                self._held.pop(next(iter(self._held)))
            return False
        held = self._held.pop(kind, 0)
        suffix = f" (and {held} more like it since the last report)" if held else ""
        self._last[kind] = now
        if len(self._last) > 1024:
            self._last.pop(next(iter(self._last)))
        self._log.log(level, "%s%s", clip(message, self._max_chars), suffix)
        return True
