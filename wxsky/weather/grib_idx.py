"""wgrib2-style `.idx` inventories (issue 45): which byte ranges of a GRIB2 file hold the
messages wxsky reads, so a model file of hundreds of megabytes costs only those messages.

An inventory has one line per field, `N:OFFSET:d=YYYYMMDDHH:VAR:LEVEL:FORECAST:` (NOAA's
servers publish one beside each file, `wxsky.inputs.grib_decode.inventory` writes them):

    4.1:25975:d=2011011012:UGRD:10 mb:120 hour fcst:
    4.2:25975:d=2011011012:VGRD:10 mb:120 hour fcst:

Fields that share one message (NCEP packs each u/v pair in one) are numbered N.1, N.2 and
share its offset. A message runs from its offset to the byte before the next distinct
offset; the last one to the end of the file, which the inventory does not say.

Pure: text in, entries and ranges out; the caller fetches.
"""

from __future__ import annotations

import itertools
import json
import math
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from wxsky.errors import GribError

__all__ = [
    "MAX_OFFSET_B",
    "IdxEntry",
    "parse_ecmwf_index",
    "parse_idx",
    "wanted_ranges",
]

# Past any real file, and small enough for any server's Range header to take.
MAX_OFFSET_B = 2**53
_MIN_FIELDS = 6  # N, OFFSET, d=DATE, VAR, LEVEL, FORECAST (wgrib2 may add more after)
_NUMBER = re.compile(r"[0-9]+(?:\.[0-9]+)*")
_QUOTE_CHARS = 40  # how much of a bad field an error quotes

ByteRange = tuple[int, int | None]  # (first byte, last byte inclusive; None: to the end)


@dataclass(frozen=True)
class IdxEntry:
    number: str  # "4" or "4.1": fields of one message share the part before the dot
    offset_b: int  # where the field's message starts in the file
    date: str  # the run's date as written, "d=2011011012"
    var: str  # wgrib2's name: "UGRD"
    level: str  # "10 mb", "surface", "2 m above ground"
    forecast: str  # "120 hour fcst", "anl"
    # The message's length where the index says it (ECMWF's); else it runs to the next
    # message's offset
    length_b: int | None = None


def parse_idx(text: str, name: str) -> list[IdxEntry]:
    """The entries of an inventory, blank lines skipped. Raises GribError, one line naming
    `name` and the line, for a line with too few fields, a bad number or offset, or an
    offset before the one above it (an inventory of some other file, or two run together)."""
    entries: list[IdxEntry] = []
    last_offset_b = 0
    # Split on newlines only: the line numbers are the ones an editor or `sed -n` shows.
    for line_no, raw in enumerate(text.split("\n"), start=1):
        line = raw.removesuffix("\r")
        if not line.strip():
            continue
        where = f"{name}: line {line_no}"
        fields = line.split(":")
        if len(fields) < _MIN_FIELDS:
            raise GribError(
                f"{where}: {len(fields)} ':'-separated fields, an inventory line has at least "
                f"{_MIN_FIELDS} (N:OFFSET:d=DATE:VAR:LEVEL:FORECAST:): {_quote(line)}"
            )
        number, offset_text, date, var, level, forecast = fields[:_MIN_FIELDS]
        if not _NUMBER.fullmatch(number):
            raise GribError(f"{where}: message number {_quote(number)} is not N or N.M")
        # ASCII digits only: int() would take "1_000", " 7" and other scripts' digits.
        if not (offset_text.isascii() and offset_text.isdigit()):
            raise GribError(f"{where}: offset {_quote(offset_text)} is not a byte count")
        if len(offset_text) > 16 or int(offset_text) > MAX_OFFSET_B:
            raise GribError(f"{where}: offset {_quote(offset_text)} is past any GRIB file")
        offset_b = int(offset_text)
        if offset_b < last_offset_b:
            raise GribError(
                f"{where}: offset {offset_b} is before the line above's ({last_offset_b}); "
                "an inventory lists its messages in file order"
            )
        last_offset_b = offset_b
        entries.append(IdxEntry(number, offset_b, date, var, level, forecast))
    return entries


def wanted_ranges(
    entries: Sequence[IdxEntry], wanted: Iterable[tuple[str, str]], min_hpa: float = 0.0
) -> list[ByteRange]:
    """The byte ranges of the messages holding a wanted (VAR, LEVEL) field, in file order,
    each message once (a u/v pair is one message) and neighbouring messages merged into one
    range, so each range is one request. LEVEL "mb" stands for every pressure level (a level
    ending in " mb") down to `min_hpa`. `entries` as `parse_idx` returns them (offsets never
    go backwards)."""
    pairs = set(wanted)
    any_mb = {var for var, level in pairs if level == "mb"}
    if any(e.length_b is not None for e in entries):
        return _sized_ranges(entries, pairs, any_mb, min_hpa)
    # Each distinct offset is one message; it is wanted when any of its fields is.
    messages: list[tuple[int, bool]] = []
    for e in entries:
        hit = _hit(e, pairs, any_mb, min_hpa)
        if messages and messages[-1][0] == e.offset_b:
            messages[-1] = (e.offset_b, messages[-1][1] or hit)
        else:
            messages.append((e.offset_b, hit))
    ranges: list[ByteRange] = []
    run_start_b: int | None = None  # the first byte of the range being gathered
    for offset_b, hit in messages:
        if hit and run_start_b is None:
            run_start_b = offset_b
        elif not hit and run_start_b is not None:
            ranges.append((run_start_b, offset_b - 1))
            run_start_b = None
    if run_start_b is not None:
        ranges.append((run_start_b, None))
    return ranges


def _hit(e: IdxEntry, pairs: set[tuple[str, str]], any_mb: set[str], min_hpa: float) -> bool:
    return (e.var, e.level) in pairs or (
        e.var in any_mb and e.level.endswith(" mb") and _hpa(e.level) >= min_hpa
    )


def _sized_ranges(
    entries: Sequence[IdxEntry], pairs: set[tuple[str, str]], any_mb: set[str], min_hpa: float
) -> list[ByteRange]:
    """With each message's length given (ECMWF's index): the wanted messages' bytes, those
    that touch merged into one range."""
    spans = sorted(
        (e.offset_b, e.offset_b + (e.length_b or 0) - 1)
        for e in entries
        if e.length_b and _hit(e, pairs, any_mb, min_hpa)
    )
    ranges: list[ByteRange] = []
    for first, last in spans:
        if ranges:
            prev_first, prev_last = ranges[-1]
            assert prev_last is not None
            if first <= prev_last + 1:
                ranges[-1] = (prev_first, max(prev_last, last))
                continue
        ranges.append((first, last))
    return ranges


# ECMWF open data's parameters (its `param` and `levtype`) in wgrib2's names, so one wanted
# list serves both indexes.
_ECMWF_SURFACE = {
    "2t": ("TMP", "2 m above ground"),
    "10u": ("UGRD", "10 m above ground"),
    "10v": ("VGRD", "10 m above ground"),
    "sp": ("PRES", "surface"),
    "tp": ("APCP", "surface"),
    "tcc": ("TCDC", "entire atmosphere"),
    "lcc": ("TCDC", "low cloud layer"),
    "mcc": ("TCDC", "middle cloud layer"),
    "hcc": ("TCDC", "high cloud layer"),
}
_ECMWF_LEVEL = {"u": "UGRD", "v": "VGRD", "t": "TMP", "gh": "HGT", "r": "RH", "q": "SPFH"}


def parse_ecmwf_index(text: str, name: str) -> list[IdxEntry]:
    """The entries of ECMWF open data's `.index` (one JSON object a line, with `param`,
    `levtype`, `levelist`, `_offset` and `_length`), in file order, with wgrib2's names
    (`UGRD` at `500 mb`). Raises GribError, one line naming `name` and the line."""
    entries: list[IdxEntry] = []
    for line_no, raw in enumerate(text.split("\n"), start=1):
        line = raw.removesuffix("\r")
        if not line.strip():
            continue
        where = f"{name}: line {line_no}"
        try:
            item = json.loads(line)
        except (ValueError, RecursionError):
            raise GribError(f"{where}: not a JSON object: {_quote(line)}") from None
        if not isinstance(item, dict):
            raise GribError(f"{where}: not a JSON object: {_quote(line)}")
        offset, length = item.get("_offset"), item.get("_length")
        if not (isinstance(offset, int) and isinstance(length, int)):
            raise GribError(f"{where}: _offset and _length must be byte counts in a file")
        if not (_count(offset) and _count(length)) or offset + length > MAX_OFFSET_B:
            raise GribError(f"{where}: _offset and _length must be byte counts in a file")
        param, levtype = str(item.get("param", "")), str(item.get("levtype", ""))
        if levtype == "pl" and param in _ECMWF_LEVEL:
            var, level = _ECMWF_LEVEL[param], f"{_quote_free(item.get('levelist'))} mb"
        elif param in _ECMWF_SURFACE:
            var, level = _ECMWF_SURFACE[param]
        else:
            var, level = param.upper() or "?", levtype or "?"
        date = f"d={_quote_free(item.get('date'))}{_quote_free(item.get('time'))[:2]}"
        forecast = f"{_quote_free(item.get('step'))} hour fcst"
        entries.append(IdxEntry(str(line_no), offset, date, var, level, forecast, length))
    entries.sort(key=lambda e: e.offset_b)
    return entries


def _count(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and 0 <= value <= MAX_OFFSET_B


def _quote_free(value: object) -> str:
    """A short plain text of an index value (no ':' or line breaks, which inventories use)."""
    text = str(value)[:_QUOTE_CHARS]
    return "".join(c for c in text if c.isprintable() and c != ":")


def _hpa(level: str) -> float:
    """The pressure of an "N mb" level; an unreadable number counts as any level."""
    try:
        value = float(level[:-3])
    except ValueError:
        return math.inf
    return value if math.isfinite(value) else math.inf


def fewer_ranges(ranges: Sequence[ByteRange], most: int) -> list[ByteRange]:
    """`ranges` joined across their smallest gaps until at most `most` are left: servers that
    count requests (NOAA's NOMADS blocks a client after some 120 a minute) get a few large
    ones, at the cost of the unwanted messages in the gaps, which the decoder skips."""
    out = list(ranges)
    while len(out) > max(1, most):
        gaps = [
            (b[0] - a[1] if a[1] is not None else 0, i)
            for i, (a, b) in enumerate(itertools.pairwise(out))
        ]
        _, i = min(gaps)
        out[i : i + 2] = [(out[i][0], out[i + 1][1])]
    return out


def _quote(text: str) -> str:
    """A piece of a bad line for an error: one line (repr escapes every line break) and
    bounded."""
    cut = text if len(text) <= _QUOTE_CHARS else text[:_QUOTE_CHARS] + "…"
    return repr(cut)
