"""METAR feed loaders: AWC cache CSV/XML, NOAA tgftp text, and one-report-per-line files.

`parse_feed` turns the bytes of a feed into `Report`s (raw text plus the year and month the
decoder needs, taken from the feed) and `FeedProblem`s (rows it could not fully use, each with
`<name>:<line>`). Only content that is not a METAR feed at all (an HTML page, JSON, binary or
nothing) raises `FeedError`, and data over `MAX_FEED_BYTES`, as given or unpacked, raises
`FeedTooLarge`; everything else, however broken, comes back as problems. `gunzip` is the one
bounded gunzip of every feed, here and in the daemon's sources.

The per-format parsers live in `feed_formats`; the formats and their vintages are described in
`shared/reference/metar-feeds.md` §1.
"""

from __future__ import annotations

import os
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

from wxsky.errors import FeedError, FeedTooLarge, FeedUnavailable
from wxsky.weather.feed_formats import (
    FeedProblem,
    Problems,
    Report,
    awc_csv_records,
    awc_reports,
    awc_xml_records,
    clean_raw,
    is_tgftp_stamp,
    line_reports,
    read_head,
    tgftp_reports,
)
from wxsky.weather.metar import decode

__all__ = [
    "FORMATS",
    "GZIP_MAGIC",
    "MAX_FEED_BYTES",
    "Feed",
    "FeedProblem",
    "Report",
    "detect_format",
    "gunzip",
    "parse_feed",
    "read_feed",
    "read_reports",
    "unfinished_last_line",
]

FORMATS = ("awc-csv", "awc-xml", "tgftp", "lines")

GZIP_MAGIC = b"\x1f\x8b"
# The most feed data read, as sent and as unpacked. A whole-world AWC cache is about 1 MB as
# CSV and a few MB as XML; 32 MiB leaves room for years of growth and for archives of a few
# days, while a gzip bomb costs the daemon at most this much memory, for a moment.
MAX_FEED_BYTES = 32 * 1024 * 1024
# The most one zlib call hands back: no single piece of output is larger than this.
_GUNZIP_STEP_BYTES = 1024 * 1024
# How far into a file detection looks: the AWC preamble is 5 lines, then the header.
_DETECT_LINES = 20
_BINARY_FRACTION = 0.1


@dataclass(frozen=True)
class Feed:
    format: str
    reports: tuple[Report, ...]
    problems: tuple[FeedProblem, ...]
    duplicates: int  # exact repeats dropped (tgftp cycle files)


def _looks_binary(sample: str) -> bool:
    if "\x00" in sample:
        return True
    odd = sum(1 for c in sample if c == "\ufffd" or (c < " " and c not in "\t\n\r\f\v"))
    return odd > _BINARY_FRACTION * len(sample)


def _shorten(text: str, chars: int = 60) -> str:
    return repr(text if len(text) <= chars else text[:chars] + "...")


def detect_format(text: str, *, name: str = "<feed>") -> str:
    """Which of FORMATS `text` is, from its content; FeedError when it is not a METAR feed."""
    body = text.lstrip("\ufeff \t\r\n")
    if not body:
        raise FeedError(f"{name}: empty, not a METAR feed")
    sample = body[:4096]
    if _looks_binary(sample):
        raise FeedError(f"{name}: binary data, not a METAR feed")
    lowered = sample[:1024].lower()
    if lowered.startswith(("<!doctype html", "<html")) or "<html" in lowered:
        raise FeedError(f"{name}: an HTML page (an error or login page?), not a METAR feed")
    if lowered.startswith(("<?xml", "<response")):
        return "awc-xml"
    head = [line.strip() for line in body.split("\n", _DETECT_LINES)[:_DETECT_LINES]]
    head = [line for line in head if line]
    if body[0] in "{[":
        raise FeedError(f"{name}: JSON {_shorten(head[0])}, not a METAR feed")
    if any(line.startswith("raw_text,") for line in head[:10]):
        return "awc-csv"
    if any(is_tgftp_stamp(line) for line in head):
        return "tgftp"
    if any(read_head(clean_raw(line)).time is not None for line in head):
        return "lines"
    raise FeedError(f"{name}: not a METAR feed (starts with {_shorten(head[0])})")


def unfinished_last_line(text: str) -> tuple[str, str] | None:
    """For feed text whose last line has no newline: (station, why) when that line is a
    report cut off in the middle of its final group (`... 9999 OVC0`: a file caught while it
    is written), else None. Only one-report-per-line and tgftp text is judged: an AWC CSV or
    XML row cut short is refused by its own parser. A line cut between two groups reads as a
    shorter report and cannot be told from one; this finds the cut that garbles a group."""
    if text.endswith("\n"):
        return None
    last = text.rsplit("\n", 1)[-1]
    try:
        if detect_format(text) not in ("lines", "tgftp"):
            return None
    except FeedError:
        return None
    report = clean_raw(last)
    tokens = report.split("=", 1)[0].split()
    if "=" in report or len(tokens) < 2:
        return None  # ended by the WMO end mark, or no report at all: judged elsewhere
    # A fixed date keeps the decoder off the clock: only the groups' shapes matter here.
    metar = decode(report, year=2000, month=1)
    prefix = f"group {len(tokens)} {tokens[-1]!r}: "
    for error in metar.errors:
        if error.startswith(prefix):
            return (metar.station or tokens[0], f"{tokens[-1]!r}: {error[len(prefix) :]}")
    return None


def gunzip(
    data: bytes, *, name: str = "<feed>", limit: int = MAX_FEED_BYTES
) -> tuple[bytes, str | None]:
    """gzip data unpacked a step at a time, never past `limit` bytes: FeedTooLarge (naming
    `name` and the limit) once the output would pass it. Also returns, for a damaged stream,
    why it stops early (what came out before is kept). The one gunzip every feed goes through.
    """
    # Pieces joined once at the end: a growing buffer would need twice its size to grow.
    pieces: list[bytes] = []
    size = 0
    while data[:2] == GZIP_MAGIC:  # concatenated members are one file to gzip(1)
        stream = zlib.decompressobj(wbits=16 + zlib.MAX_WBITS)
        pending = data
        while True:
            step = min(_GUNZIP_STEP_BYTES, limit + 1 - size)
            try:
                piece = stream.decompress(pending, step)
            except zlib.error as exc:
                return b"".join(pieces), f"gzip data is corrupt ({exc}); read what came before"
            pieces.append(piece)
            size += len(piece)
            if size > limit:
                raise FeedTooLarge(
                    f"{name}: gzip data unpacks to more than the {limit}-byte limit "
                    "(a gzip bomb?); not a METAR feed"
                )
            pending = stream.unconsumed_tail
            if stream.eof or (not pending and len(piece) < step):
                break
        if not stream.eof:
            trouble = "gzip data ends early (a cut-off download?); read what was there"
            return b"".join(pieces), trouble
        data = stream.unused_data
    return b"".join(pieces), None


def _decode(data: bytes, problems: Problems, name: str) -> str:
    gzip_trouble = None
    if data[:2] == GZIP_MAGIC:
        data, gzip_trouble = gunzip(data, name=name)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        problems.add(line, f"bytes that are not UTF-8 (first at byte {exc.start}), replaced")
        text = data.decode("utf-8", errors="replace")
    if gzip_trouble is not None:
        problems.add(text.count("\n") + 1, gzip_trouble)
    return text


def _as_utc(time: datetime | None) -> datetime:
    if time is None:
        # Feeds without dates (network weather) are current: the one place "now" is used.
        return datetime.now(UTC)
    return time.replace(tzinfo=UTC) if time.tzinfo is None else time.astimezone(UTC)


def parse_feed(
    data: bytes | str,
    *,
    format: str = "auto",
    name: str = "<feed>",
    reference_utc: datetime | None = None,
) -> Feed:
    """Reports and problems of one feed. gzip bytes are decompressed.

    `reference_utc` (the file's mtime or the HTTP Date) dates reports of feeds that carry no date:
    a report day after the reference day belongs to the latest earlier month that has that day
    (`feed_formats.month_of_day`).
    """
    if format != "auto" and format not in FORMATS:
        raise FeedError(f"{name}: unknown feed format {format!r} (expected one of {FORMATS})")
    if isinstance(data, bytes) and len(data) > MAX_FEED_BYTES:
        raise FeedTooLarge(f"{name}: more than the {MAX_FEED_BYTES}-byte limit, not a METAR feed")
    problems = Problems(name)
    text = _decode(data, problems, name) if isinstance(data, bytes) else data
    text = text.removeprefix("\ufeff")
    if format == "auto":
        format = detect_format(text, name=name)
    if not text.strip():
        problems.add(1, "empty feed")
        return Feed(format, (), problems.result(), 0)
    lines = text.replace("\r", "").split("\n")
    reference = _as_utc(reference_utc)
    duplicates = 0
    if format == "awc-csv":
        reports = awc_reports(awc_csv_records(lines, problems), problems, reference)
    elif format == "awc-xml":
        reports = awc_reports(awc_xml_records(lines, problems), problems, reference)
    elif format == "tgftp":
        reports, duplicates = tgftp_reports(lines, problems, reference)
    else:
        reports = line_reports(lines, problems, reference)
    return Feed(format, tuple(reports), problems.result(), duplicates)


def read_feed(path: str | os.PathLike[str], *, format: str = "auto") -> Feed:
    """parse_feed on a file (gzip or not, found by its magic bytes), its mtime as reference."""
    file = Path(path)
    try:
        mtime_s = file.stat().st_mtime
        with file.open("rb") as f:
            data = f.read(MAX_FEED_BYTES + 1)  # parse_feed refuses what is over the limit
    except OSError as exc:
        raise FeedUnavailable(f"{file}: cannot read ({exc.strerror or exc})") from None
    mtime = datetime.fromtimestamp(mtime_s, UTC)
    return parse_feed(data, format=format, name=str(file), reference_utc=mtime)


def read_reports(path: str | os.PathLike[str], *, format: str = "auto") -> Iterator[Report]:
    """The reports of a feed file, problems dropped (use read_feed to see them).

    The file is read before this returns, so a FeedError is raised here, not at the first next().
    """
    return iter(read_feed(path, format=format).reports)
