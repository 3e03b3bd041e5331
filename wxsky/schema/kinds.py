"""What a setting may be: kinds of value with their limits and units, each written once.

A kind checks one value and says what is wrong in words a user reads (`must be an integer in
16..8192, got 100000`). The owners of a limit (the weather state, the camera, the config)
declare it as a kind; every checker that takes that value from a file, a command line or the
control channel uses the same kind, so the limits cannot drift apart.
"""

from __future__ import annotations

import itertools
import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from wxsky.schema.problems import KeyPath, Problem

__all__ = [
    "Bool",
    "Custom",
    "Items",
    "Kind",
    "Nullable",
    "Number",
    "Text",
    "Tuple",
    "fmt_number",
]


def _suffix(path: KeyPath) -> str:
    return "".join(f"[{k}]" if isinstance(k, int) else f".{k}" for k in path)


def fmt_number(x: float) -> str:
    """A bound or value as a person writes it: 240, 0.1, -90, 1000000."""
    if isinstance(x, int):
        return str(x)
    return str(int(x)) if x.is_integer() and abs(x) < 1e15 else repr(x)


class Kind:
    """A kind of value. `check` appends problems and returns the value in its stored form
    (None when there was a problem); `validate` raises ValueError naming the value instead, for
    code that builds values directly (dataclass constructors, command-line options)."""

    def describe(self) -> str:
        raise NotImplementedError

    def check(self, value: Any, path: KeyPath, problems: list[Problem]) -> Any:
        try:
            return self._convert(value)
        except ValueError as exc:
            problems.append(Problem(path, str(exc)))
            return None

    def validate(self, name: str, value: Any) -> Any:
        problems: list[Problem] = []
        out = self.check(value, (), problems)
        if problems:
            raise ValueError("; ".join(f"{name}{_suffix(p.path)}: {p.message}" for p in problems))
        return out

    def _convert(self, value: Any) -> Any:
        """The value in its stored form, or ValueError with what is wrong."""
        raise NotImplementedError


@dataclass(frozen=True)
class Number(Kind):
    """A finite number within [lo, hi] (either may be None: unbounded). `integer` accepts only
    integers; `unit` is for documentation and messages (`m`, `deg`, `mps`)."""

    lo: float | None = None
    hi: float | None = None
    integer: bool = False
    unit: str = ""
    above_lo: bool = False  # lo itself excluded (a size that must be above 0)

    def describe(self) -> str:
        kind = "an integer" if self.integer else "a number"
        limits = self.range_text()
        if self.lo is not None and self.hi is not None:
            return f"{kind} in {limits}"
        return f"{kind} {limits}" if limits else kind

    def range_text(self) -> str:
        """The limits alone: `0..150`, `0..25000 and more than 0`, `at least 1`."""
        lo = None if self.lo is None else fmt_number(self.lo)
        hi = None if self.hi is None else fmt_number(self.hi)
        if lo is not None and hi is not None:
            text = f"{lo}..{hi}"
        elif lo is not None:
            text = f"more than {lo}" if self.above_lo else f"of at least {lo}"
            return text
        elif hi is not None:
            return f"of at most {hi}"
        else:
            return ""
        return f"{text} and more than {lo}" if self.above_lo else text

    @property
    def bounds(self) -> tuple[float, float]:
        """(lo, hi) of a kind bounded on both sides."""
        if self.lo is None or self.hi is None:
            raise ValueError(f"{self.describe()} is not bounded on both sides")
        return (self.lo, self.hi)

    def contains(self, value: float) -> bool:
        if self.lo is not None and (value < self.lo or (self.above_lo and value == self.lo)):
            return False
        return self.hi is None or value <= self.hi

    def _convert(self, value: Any) -> float | int:
        # bool is an int subclass, but `tick_hz = true` is a mistake, not 1 Hz.
        accepted = (int,) if self.integer else (int, float)
        if (
            not isinstance(value, accepted)
            or isinstance(value, bool)
            or not math.isfinite(value)
            or not self.contains(value)
        ):
            raise ValueError(f"must be {self.describe()}, got {value!r}")
        return int(value) if self.integer else float(value)

    def clamp_hi(self, hi: float) -> Number:
        """The same kind with a lower ceiling (a camera no larger than the output frame)."""
        top = hi if self.hi is None else min(self.hi, hi)
        return Number(self.lo, top, self.integer, self.unit, self.above_lo)


@dataclass(frozen=True)
class Bool(Kind):
    def describe(self) -> str:
        return "true or false"

    def _convert(self, value: Any) -> bool:
        if not isinstance(value, bool):
            raise ValueError(f"must be true or false, got {value!r}")
        return value


@dataclass(frozen=True)
class Text(Kind):
    """A string: one of `choices` (matched case-insensitively, stored as spelled there), or
    matching `pattern` as a whole (described in words by `pattern_desc`), or any string; of at
    most `max_len` characters when given (a longer one is refused by its length, unquoted)."""

    choices: tuple[str, ...] = ()
    pattern: str | None = None
    pattern_desc: str = ""
    non_empty: bool = False
    max_len: int | None = None

    def describe(self) -> str:
        if self.choices:
            return f"one of {', '.join(self.choices)}"
        if self.pattern is not None:
            return self.pattern_desc or f"a string matching {self.pattern}"
        return "a non-empty string" if self.non_empty else "a string"

    def _convert(self, value: Any) -> str:
        if self.choices:
            for choice in self.choices:
                if isinstance(value, str) and value.casefold() == choice.casefold():
                    return choice
            raise ValueError(f"must be {self.describe()}, got {value!r}")
        if not isinstance(value, str) or (self.non_empty and not value.strip()):
            raise ValueError(f"must be {self.describe()}, got {value!r}")
        if self.max_len is not None and len(value) > self.max_len:
            raise ValueError(
                f"must be at most {self.max_len} characters, got {len(value)} characters"
            )
        if self.pattern is not None and not re.fullmatch(self.pattern, value):
            raise ValueError(f"must be {self.describe()}, got {value!r}")
        return value


@dataclass(frozen=True)
class Items(Kind):
    """A list of values of one kind, stored as a tuple. `length` fixes the count; `ordered`
    requires a non-decreasing list (a [lo, hi] range)."""

    item: Kind
    length: int | None = None
    min_len: int = 0
    max_len: int | None = None
    ordered: bool = False
    what: str = ""  # the list in words, for messages ("[lo, hi]"); derived when empty

    def describe(self) -> str:
        if self.what:
            return self.what
        if self.length is not None:
            return f"a list of {self.length} ({self.item.describe()})"
        return f"a list of {self.item.describe()}"

    def check(self, value: Any, path: KeyPath, problems: list[Problem]) -> Any:
        if not isinstance(value, (list, tuple)):
            problems.append(Problem(path, f"must be {self.describe()}, got {value!r}"))
            return None
        shape = self._shape_problem(value)
        if shape:
            problems.append(Problem(path, shape))
            return None
        before = len(problems)
        out = tuple(self.item.check(v, (*path, i), problems) for i, v in enumerate(value))
        if len(problems) > before:
            return None
        if self.ordered and any(a > b for a, b in itertools.pairwise(out)):
            problems.append(Problem(path, f"must be [lo, hi] with lo <= hi, got {list(value)!r}"))
            return None
        return out

    def _shape_problem(self, value: Sequence[Any]) -> str:
        n = len(value)
        if self.length is not None and n != self.length:
            return f"must be {self.describe()}, got {list(value)!r}"
        if n < self.min_len:
            least = "at least one item" if self.min_len == 1 else f"at least {self.min_len} items"
            return f"must have {least}, got {list(value)!r}"
        if self.max_len is not None and n > self.max_len:
            return f"must have at most {self.max_len} items, got {n}"
        return ""


@dataclass(frozen=True)
class Tuple(Kind):
    """A list of fixed length with a kind for each position (`[east_m, north_m, alt_m]`)."""

    kinds: tuple[Kind, ...]
    what: str

    def describe(self) -> str:
        return self.what

    def check(self, value: Any, path: KeyPath, problems: list[Problem]) -> Any:
        if not isinstance(value, (list, tuple)) or len(value) != len(self.kinds):
            problems.append(Problem(path, f"must be {self.what}, got {value!r}"))
            return None
        before = len(problems)
        out = tuple(
            k.check(v, (*path, i), problems)
            for i, (k, v) in enumerate(zip(self.kinds, value, strict=True))
        )
        return out if len(problems) == before else None


@dataclass(frozen=True)
class Nullable(Kind):
    """A value of `kind`, or null (None) where null means something (no aircraft)."""

    kind: Kind

    def describe(self) -> str:
        return f"{self.kind.describe()} or null"

    def check(self, value: Any, path: KeyPath, problems: list[Problem]) -> Any:
        if value is None:
            return None
        before = len(problems)
        out = self.kind.check(value, path, problems)
        if len(problems) > before and not isinstance(value, (list, tuple, dict)):
            # A wrong type: say null was fine too.
            problems[before] = Problem(path, f"must be {self.describe()}, got {value!r}")
        return out


@dataclass(frozen=True)
class Custom(Kind):
    """A value checked by a function that returns its stored form or raises ValueError."""

    convert: Callable[[Any], Any] = field(compare=False)
    what: str = ""

    def describe(self) -> str:
        return self.what

    def _convert(self, value: Any) -> Any:
        return self.convert(value)
