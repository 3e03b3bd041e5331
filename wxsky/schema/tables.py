"""Tables of settings: which keys a table may hold, each with its kind and default, plus the
checks that need several keys at once (a layer's top above its base).

A table check collects every problem, with the key path it is about, rather than stopping at
the first: a user fixing a file wants the whole list.
"""

from __future__ import annotations

import difflib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Final

from wxsky.schema.kinds import Kind
from wxsky.schema.problems import Invalid, KeyPath, Problem


class _Sentinel:
    def __init__(self, name: str) -> None:
        self.name = name

    def __repr__(self) -> str:
        return self.name


REQUIRED: Final[Any] = _Sentinel("REQUIRED")  # a key the table must give
OMIT: Final[Any] = _Sentinel("OMIT")  # a key left out of the result when the table omits it

# A check over the checked values of a whole table: appends problems (paths under `path`).
TableCheck = Callable[[dict[str, Any], KeyPath, list[Problem]], None]


@dataclass(frozen=True)
class Rule:
    """A check across keys of one table, run when every key it names passed its own check
    (its problem would only repeat theirs otherwise); keys the table omits do not stop it."""

    keys: tuple[str, ...]
    check: TableCheck = field(compare=False)


@dataclass(frozen=True)
class Field:
    kind: Kind
    default: Any = OMIT


def unknown_key_hint(key: str, known: list[str]) -> str:
    close = difflib.get_close_matches(key, known, n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


@dataclass(frozen=True)
class Table(Kind):
    """A TOML table (or a control request's params): known keys only, each checked by its
    kind, then the rules across keys on the converted values."""

    fields: Mapping[str, Field]
    rules: tuple[Rule, ...] = field(default=(), compare=False)
    what: str = "a table"

    def describe(self) -> str:
        return self.what

    def check(self, value: Any, path: KeyPath, problems: list[Problem]) -> Any:
        if not isinstance(value, dict):
            problems.append(Problem(path, f"must be {self.what}, got {value!r}"))
            return None
        before = len(problems)
        known = list(self.fields)
        for key in value:
            if key not in self.fields:
                hint = unknown_key_hint(str(key), known)
                problems.append(Problem((*path, key), f"unknown key{hint}"))
        out: dict[str, Any] = {}
        failed: set[str] = set()
        for name, f in self.fields.items():
            if name in value:
                n = len(problems)
                out[name] = f.kind.check(value[name], (*path, name), problems)
                if len(problems) > n:
                    failed.add(name)
            elif f.default is REQUIRED:
                problems.append(Problem((*path, name), "missing key"))
                failed.add(name)
            elif f.default is not OMIT:
                out[name] = f.default
        for rule in self.rules:
            if failed.isdisjoint(rule.keys):
                rule.check(out, path, problems)
        return out if len(problems) == before else None

    def values(self, value: Any) -> dict[str, Any]:
        """The checked values of a whole table; Invalid lists every problem."""
        problems: list[Problem] = []
        out = self.check(value, (), problems)
        if problems:
            raise Invalid(problems)
        return dict(out)


@dataclass(frozen=True)
class Tables(Kind):
    """An array of tables (`[[layers]]`), at most `max_items` of them."""

    item: Table
    name: str
    max_items: int | None = None
    noun: str = ""  # what the items are called in messages ("cloud layers"); default: name

    def describe(self) -> str:
        return f"an array of tables ([[{self.name}]])"

    def check(self, value: Any, path: KeyPath, problems: list[Problem]) -> Any:
        if not isinstance(value, list) or not all(isinstance(t, dict) for t in value):
            problems.append(Problem(path, f"must be {self.describe()}, got {value!r}"))
            return None
        before = len(problems)
        out = tuple(self.item.check(t, (*path, i), problems) for i, t in enumerate(value))
        if self.max_items is not None and len(value) > self.max_items:
            problems.append(
                Problem(
                    path,
                    f"at most {self.max_items} {self.noun or self.name}, got {len(value)}",
                    at=(*path, self.max_items),
                )
            )
        return out if len(problems) == before else None
