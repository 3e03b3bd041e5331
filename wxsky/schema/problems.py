"""Problems with settings, each tied to the key it is about (`layers[1].cover_oktas`)."""

from __future__ import annotations

import json
import re
from collections.abc import Iterable
from dataclasses import dataclass

KeyPath = tuple[str | int, ...]


def format_key(path: KeyPath) -> str:
    """("layers", 1, "cover_oktas") -> "layers[1].cover_oktas"; odd keys are quoted."""
    out = ""
    for part in path:
        if isinstance(part, int):
            out += f"[{part}]"
            continue
        text = part if re.fullmatch(r"[A-Za-z0-9_-]+", part) else json.dumps(part)
        out += f".{text}" if out else text
    return out


@dataclass(frozen=True)
class Problem:
    """One thing wrong. `at` is where to point when that differs from `path` (too many layers:
    the key is `layers`, the line is the first layer too many)."""

    path: KeyPath
    message: str
    at: KeyPath | None = None

    @property
    def key(self) -> str:
        return format_key(self.path)

    def __str__(self) -> str:
        return f"{self.key}: {self.message}" if self.path else self.message


class Invalid(ValueError):
    """Settings with one or more problems; the message lists them all on one line."""

    def __init__(self, problems: Iterable[Problem]) -> None:
        self.problems = tuple(problems)
        super().__init__("; ".join(str(p) for p in self.problems))
