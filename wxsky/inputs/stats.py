"""What every input reports in `wxsky status`."""

from __future__ import annotations

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
