"""Settings files in TOML, checked with every problem as `FILE:LINE: key: problem`.

tomllib gives no positions for values, so `key_lines` maps each key path back to the line of
the source that spells it out; problems about keys the file does not spell (a missing key)
point at the nearest enclosing table.
"""

from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from wxsky.schema.kinds import Kind
from wxsky.schema.problems import Invalid, KeyPath, Problem


@dataclass(frozen=True)
class LocatedProblem:
    line: int | None  # None only where the file could not be read at all
    key: str  # "" for problems of the whole file (syntax, encoding)
    message: str

    def __str__(self) -> str:
        parts = [str(self.line)] if self.line is not None else []
        if self.key:
            parts.append(self.key)
        parts.append(self.message)
        return ": ".join(parts)


@dataclass(frozen=True)
class FileCheck:
    """The outcome of checking one file: `value` is None unless there are no problems."""

    path: Path
    value: Any
    problems: tuple[LocatedProblem, ...]

    @property
    def ok(self) -> bool:
        return not self.problems

    def lines(self) -> list[str]:
        """Every problem as `FILE:LINE: key: problem`, in file order."""
        return [
            f"{self.path}:{p}" if p.line is not None else f"{self.path}: {p}" for p in self.problems
        ]

    def error_message(self) -> str:
        """Every problem, one line each."""
        return "\n".join(self.lines())


def read_toml(path: Path) -> tuple[str, dict[str, Any]] | LocatedProblem:
    """A file's text and top-level table, or the one problem that stopped it being read."""
    try:
        raw = Path(path).read_bytes()
    except FileNotFoundError:
        return LocatedProblem(None, "", "no such file")
    except IsADirectoryError:
        return LocatedProblem(None, "", "is a directory, not a file")
    except OSError as exc:
        return LocatedProblem(None, "", f"cannot read: {exc.strerror or exc}")
    return parse_toml(raw)


def parse_toml(raw: bytes) -> tuple[str, dict[str, Any]] | LocatedProblem:
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        return LocatedProblem(line, "", "not UTF-8 text")
    try:
        return text, tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        message = str(exc)
        m = re.search(r"\(at line (\d+), column \d+\)", message)
        # tomllib gives no line for errors at the end of the input, the usual symptom of a
        # truncated file; the last line is where the reader should look.
        line = int(m.group(1)) if m else text.rstrip("\n").count("\n") + 1
        return LocatedProblem(line, "", f"invalid TOML: {message}")


def check_toml_file(path: Path, kind: Kind) -> FileCheck:
    """Read, parse and check one file against `kind` (usually a Table); never raises for a
    bad file."""
    read = read_toml(path)
    if isinstance(read, LocatedProblem):
        return FileCheck(Path(path), None, (read,))
    return check_toml_text(path, *read, kind)


def check_toml_bytes(path: Path, raw: bytes, kind: Kind) -> FileCheck:
    parsed = parse_toml(raw)
    if isinstance(parsed, LocatedProblem):
        return FileCheck(Path(path), None, (parsed,))
    return check_toml_text(path, *parsed, kind)


def check_toml_text(path: Path, text: str, data: dict[str, Any], kind: Kind) -> FileCheck:
    problems: list[Problem] = []
    value = kind.check(data, (), problems)
    return FileCheck(Path(path), None if problems else value, locate(text, problems))


def locate(text: str, problems: list[Problem] | tuple[Problem, ...]) -> tuple[LocatedProblem, ...]:
    """Problems with the lines they are about, in file order."""
    lines = key_lines(text)
    located = (
        LocatedProblem(_find(lines, p.at or p.path) or 1, p.key, p.message) for p in problems
    )
    return tuple(sorted(located, key=lambda p: p.line or 0))


def located_error(path: Path, text: str, exc: Invalid) -> str:
    """An Invalid raised after the key checks (a cross-key rule), as `FILE:LINE: ...` lines."""
    return FileCheck(Path(path), None, locate(text, exc.problems)).error_message()


def package_folder(package: str, name: str) -> Path:
    """The folder `name` shipped inside `package`, as a real path, found through
    importlib.resources so that wheels, `--user` installs and checkouts all find it."""
    folder = resources.files(package) / name
    if not isinstance(folder, Path):
        # Only a zip import gives something else; wxsky is never installed that way.
        raise FileNotFoundError(f"{package}/{name}: package data is not on a file system")
    return folder


# -- key paths back to source lines ---------------------------------------------------------

_SEGMENT = r"""(?:[A-Za-z0-9_-]+|"(?:[^"\\]|\\.)*"|'[^']*')"""
_DOTTED = rf"{_SEGMENT}(?:\s*\.\s*{_SEGMENT})*"
_HEADER_RE = re.compile(rf"\s*(\[\[?)\s*({_DOTTED})\s*\]\]?\s*(?:#.*)?$")
_KEY_RE = re.compile(rf"\s*({_DOTTED})\s*=")
_SEGMENT_RE = re.compile(_SEGMENT)


def key_line(text: str, path: KeyPath) -> int | None:
    """The 1-based line where `path` is given in the TOML source `text`, e.g.
    ("layers", 1, "cover_oktas") -> the `cover_oktas = ...` line after the second `[[layers]]`.
    A path the source does not spell out (a missing key, an entry of an inline array) gives the
    line of its nearest enclosing key or table; None if not even the first part is there."""
    return _find(key_lines(text), path)


def key_lines(text: str) -> dict[KeyPath, int]:
    """Every key path and table header the source spells out, with the line it first appears
    on. Array-of-tables headers count up: the second `[[layers]]` is ("layers", 1)."""
    found: dict[KeyPath, int] = {}
    counters: dict[KeyPath, int] = {}
    table: KeyPath = ()
    in_string: str | None = None
    for number, line in enumerate(text.splitlines(), start=1):
        if in_string is not None:
            if in_string in line:
                in_string = None
            continue
        header = _HEADER_RE.match(line)
        if header:
            table = _concrete(_segments(header.group(2)), counters, header.group(1) == "[[")
            _record(found, table, number)
            continue
        key = _KEY_RE.match(line)
        if key:
            _record(found, (*table, *_segments(key.group(1))), number)
            value = line[key.end() :]
            for quote in ('"""', "'''"):
                if value.count(quote) % 2 == 1:
                    in_string = quote
    return found


def _find(lines: dict[KeyPath, int], path: KeyPath) -> int | None:
    for n in range(len(path), 0, -1):
        if path[:n] in lines:
            return lines[path[:n]]
    return None


def _line_of(lines: dict[KeyPath, int], path: KeyPath) -> int:
    return _find(lines, path) or 1


def _segments(dotted: str) -> list[str]:
    out = []
    for seg in _SEGMENT_RE.findall(dotted):
        if seg.startswith('"'):
            out.append(_basic_string(seg))
        elif seg.startswith("'"):
            out.append(seg[1:-1])
        else:
            out.append(seg)
    return out


def _basic_string(segment: str) -> str:
    """A double-quoted key as TOML reads it: not JSON, which refuses a tab or a `\\U` escape."""
    try:
        return str(tomllib.loads(f"k = {segment}")["k"])
    except tomllib.TOMLDecodeError:  # the line is not valid TOML; tomllib has said so
        return segment[1:-1]


def _concrete(segments: list[str], counters: dict[KeyPath, int], new_entry: bool) -> KeyPath:
    """A header's key path with array indices filled in: the latest entry of each array of
    tables on the way, a new one for the last segment of a `[[...]]` header."""
    path: KeyPath = ()
    for i, seg in enumerate(segments):
        path = (*path, seg)
        if new_entry and i == len(segments) - 1:
            n = counters.get(path, 0)
            counters[path] = n + 1
            path = (*path, n)
        elif path in counters:
            path = (*path, counters[path] - 1)
    return path


def _record(found: dict[KeyPath, int], path: KeyPath, line: int) -> None:
    for n in range(1, len(path) + 1):
        found.setdefault(path[:n], line)
