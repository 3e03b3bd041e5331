"""One parser per METAR feed format and the records they produce (the API is `feeds`).

Every parser takes the feed already decoded and split into lines (`\\r` removed, so line N of the
list is line N of the file) and a `Problems` collector. Parsers never raise on bad input: a row
they cannot use becomes a problem, and a row with report text but no usable time is still returned
so that the decoder, not the loader, decides what a report is worth. No report text is dropped:
a tgftp report with an impossible timestamp line, or with none, is kept (and named in a problem).

Year and month always come from the feed (AWC observation_time, the tgftp timestamp line) or, for
feeds without dates, from the caller's reference time: a ddhhmmZ group alone names only the day.
AWC's observation_time is also kept as the report's `feed_utc`, which dates it where its own day
group is wrong (metar_input.ingest).
Against a reference the day decides (`month_of_day`): a report later on the reference's own day
stays in that month, because feed and station clocks differ by minutes and a live feed's newest
report must not be taken for last month's.

Times that are out of range but readable roll over, as the decoder reads them: hour 24 is the next
day's 00 hours, minute 60 the next hour (a tgftp `15:60` line is 16:00). An impossible time (day 32,
hour 25) leaves the report's observed_utc to the feed's own time for it, where there is one.
"""

from __future__ import annotations

import calendar
import csv
import math
import re
import xml.etree.ElementTree as ET
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import MINYEAR, UTC, datetime
from types import MappingProxyType
from typing import Any

from wxsky.weather.metar_groups import (
    FIXED_GROUPS,
    STATION,
    parse_time,
    time_in_month,
    time_problem,
)

REPORT_TYPES = ("METAR", "SPECI")
# Beyond this a feed is garbage, not data: keep the first ones and count the rest.
MAX_PROBLEMS = 1000


@dataclass(frozen=True)
class Report:
    """One report as a feed gives it, with the date context the decoder needs (see feeds.py)."""

    raw: str
    observed_utc: datetime | None
    year: int
    month: int
    station: str | None
    kind: str | None = None
    lat_deg: float | None = None
    lon_deg: float | None = None
    elevation_m: float | None = None
    where: str = ""
    # The feed's own observation time for the report (AWC's observation_time), where it gives
    # one: it dates the report when the report's day group disagrees (metar_input.ingest).
    feed_utc: datetime | None = None
    # Hints only, and unhashable (it holds a list): kept out of equality and hashing.
    awc: Mapping[str, Any] | None = field(default=None, compare=False)


@dataclass(frozen=True)
class FeedProblem:
    where: str
    reason: str


class Problems:
    """Collects FeedProblems for one feed, capped so a garbage file cannot flood memory."""

    def __init__(self, name: str) -> None:
        self.name = name
        self._found: list[FeedProblem] = []
        self._dropped = 0

    def where(self, line: int) -> str:
        return f"{self.name}:{line}"

    def add(self, line: int, reason: str) -> None:
        if len(self._found) < MAX_PROBLEMS:
            self._found.append(FeedProblem(self.where(line), reason))
        else:
            self._dropped += 1

    def result(self) -> tuple[FeedProblem, ...]:
        if not self._dropped:
            return tuple(self._found)
        more = FeedProblem(self.name, f"{self._dropped} further problems not listed")
        return (*self._found, more)


# --- report text and its header ---------------------------------------------------------------


@dataclass(frozen=True)
class Head:
    """What the loader needs from a report's first tokens."""

    kind: str | None
    station: str | None
    time: tuple[int, int, int] | None  # (day, hour, minute) as written, possibly impossible
    trouble: str | None  # why time is None


def clean_raw(text: str) -> str:
    """Report text with quotes, the WMO `=` terminator and extra whitespace removed."""
    words = text.replace('"', " ").split()
    if words and words[-1].endswith("="):
        words[-1] = words[-1].rstrip("=")
        if not words[-1]:
            words.pop()
    return " ".join(words)


def _is_correction(token: str) -> bool:
    return FIXED_GROUPS.get(token) == "cor"  # COR, CORR, CCA..CCG: the decoder's own list


def read_head(raw: str) -> Head:
    tokens = raw.split()
    kind = tokens[0] if tokens and tokens[0] in REPORT_TYPES else None
    i = 1 if kind else 0
    # COR can sit before the station (`METAR COR KXYZ`) or after it (`MRLB COR 262100Z`).
    if i < len(tokens) and _is_correction(tokens[i]):
        i += 1
    if i >= len(tokens) or STATION.fullmatch(tokens[i]) is None:
        return Head(kind, None, None, "no station identifier at the start")
    station = tokens[i]
    i += 1
    if i < len(tokens) and _is_correction(tokens[i]):
        i += 1
    token = tokens[i] if i < len(tokens) else ""
    time = parse_time(token)
    return Head(kind, station, time, None if time else "no ddhhmmZ time group")


def month_of_day(reference: datetime, day: int) -> tuple[int, int]:
    """(year, month) of a report's day-of-month seen at `reference`: the reference's month up to
    its own day, else the latest earlier month that has the day (31 on 1 December: October)."""
    year, month = reference.year, reference.month
    if day <= reference.day:
        return year, month
    for _ in range(3):  # any day up to 31 is in one of the three months before
        year, month = (year, month - 1) if month > 1 else (year - 1, 12)
        if year < MINYEAR:
            break
        if day <= calendar.monthrange(year, month)[1]:
            return year, month
    return reference.year, reference.month  # no such day at all: the caller finds no time


def observed_at(year: int, month: int, time: tuple[int, int, int]) -> datetime | None:
    """The time of a report's (day, hour, minute) in a month, or None when there is none there
    (day 32, hour 25, day 31 in a 30-day month); hour 24 and minute 60 roll over."""
    if time_problem(*time) is not None:
        return None
    return time_in_month(year, month, *time)


def _time_trouble(time: tuple[int, int, int], year: int, month: int) -> str:
    """Why observed_at found no time: for the problem line."""
    return time_problem(*time) or f"day {time[0]} is not in {year}-{month:02d}"


def _dated_report(
    head: Head,
    raw: str,
    reference: datetime,
    line: int,
    problems: Problems,
    undated: datetime | None = None,
) -> Report:
    """A report from a feed that gives only a reference time; `undated` is its time without one."""
    if head.time is None:
        problems.add(line, f"{head.trouble}: {raw[:60]!r}")
        year, month, observed = reference.year, reference.month, undated
    else:
        year, month = month_of_day(reference, head.time[0])
        observed = observed_at(year, month, head.time)
        if observed is None:
            why = _time_trouble(head.time, year, month)
            problems.add(line, f"impossible time group ({why}): {raw[:60]!r}")
            observed = undated
    return Report(raw, observed, year, month, head.station, head.kind, where=problems.where(line))


# --- AWC cache (CSV and XML share the columns) ------------------------------------------------

AWC_CSV_COLUMNS = 44
# Positions in the CSV (the header repeats the sky column names, so names cannot be used).
_CSV_HINTS = {
    "temp_c": 5,
    "dewpoint_c": 6,
    "wind_dir_degrees": 7,
    "wind_speed_kt": 8,
    "wind_gust_kt": 9,
    "visibility_statute_mi": 10,
    "altim_in_hg": 11,
    "wx_string": 21,
    "flight_category": 30,
    "vert_vis_ft": 41,
    "metar_type": 42,
}
_CSV_SKY = ((22, 23), (24, 25), (26, 27), (28, 29))
# AwcRecord's columns: CSV positions; the XML element names are the same as the field names.
_CSV_FIELDS = {
    "station_id": 1,
    "observation_time": 2,
    "latitude": 3,
    "longitude": 4,
    "elevation_m": 43,
}


@dataclass(frozen=True)
class AwcRecord:
    """One AWC row or <METAR> element, columns as the feed spells them (None when empty)."""

    line: int
    raw: str
    hints: Mapping[str, Any]
    station_id: str | None
    observation_time: str | None
    latitude: str | None
    longitude: str | None
    elevation_m: str | None


def _text(value: str | None) -> str | None:
    return value if value is not None and value.strip() else None


def _finite(text: str | None) -> float | None:
    if text is None:
        return None
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def _iso_utc(text: str | None) -> datetime | None:
    """AWC observation_time: `2014-09-26T21:35:00Z` and `2026-03-20T15:20:00.000Z` alike."""
    if text is None:
        return None
    try:
        time = datetime.fromisoformat(text.strip())
    except ValueError:
        return None
    try:
        return time.replace(tzinfo=UTC) if time.tzinfo is None else time.astimezone(UTC)
    except OverflowError:  # 0001-01-01T00:00+01:00 is in year 0 in UTC
        return None


def awc_csv_records(lines: Sequence[str], problems: Problems) -> list[AwcRecord]:
    header = next((i for i, line in enumerate(lines) if line.startswith("raw_text,")), None)
    if header is None:
        problems.add(1, "no header line starting with 'raw_text,': not an AWC cache CSV")
        return []
    records = []
    for number, line in enumerate(lines[header + 1 :], start=header + 2):
        if not line.strip():
            continue  # `\r\r\n` files leave an empty line after every row
        try:
            fields = next(csv.reader([line]))
        except (csv.Error, StopIteration) as exc:
            problems.add(number, f"unreadable CSV row ({exc})")
            continue
        if len(fields) != AWC_CSV_COLUMNS:
            problems.add(number, f"{len(fields)} columns, expected {AWC_CSV_COLUMNS}")

        def column(i: int, row: list[str] = fields) -> str | None:
            return _text(row[i]) if i < len(row) else None

        raw = clean_raw(fields[0]) if fields else ""
        if not raw:
            problems.add(number, "row without raw_text")
            continue
        hints: dict[str, Any] = {key: column(i) for key, i in _CSV_HINTS.items()}
        sky = [(column(c), column(b)) for c, b in _CSV_SKY]
        hints["sky"] = [pair for pair in sky if pair != (None, None)]
        columns = {name: column(i) for name, i in _CSV_FIELDS.items()}
        records.append(AwcRecord(number, raw, MappingProxyType(hints), **columns))
    return records


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]  # tolerate a default namespace on the response


def _xml_record(element: ET.Element, line: int, problems: Problems) -> AwcRecord | None:
    children: dict[str, str | None] = {}
    sky = []
    for child in element:
        tag = _local(child.tag)
        if tag == "sky_condition":
            pair = (_text(child.get("sky_cover")), _text(child.get("cloud_base_ft_agl")))
            if pair != (None, None):
                sky.append(pair)
        else:
            children.setdefault(tag, _text(child.text))
    hints: dict[str, Any] = {key: children.get(key) for key in _CSV_HINTS}
    hints["sky"] = sky
    raw = clean_raw(children.get("raw_text") or "")
    if not raw:
        problems.add(line, "<METAR> element without raw_text")
        return None
    columns = {name: children.get(name) for name in _CSV_FIELDS}
    return AwcRecord(line, raw, MappingProxyType(hints), **columns)


_XML_ELEMENT = re.compile(r"<METAR>.*?</METAR>", re.DOTALL)


def _resync(lines: Sequence[str], line: int, column: int, problems: Problems) -> list[AwcRecord]:
    """Complete <METAR> elements after a parse error, found by pattern and parsed one by one."""
    rest = "\n".join(lines[line - 1 :])
    records = []
    for m in _XML_ELEMENT.finditer(rest, pos=column):
        try:
            element = ET.fromstring(m.group())
        except ET.ParseError:
            continue  # the element the error is in
        # Where the report text starts, as for elements read without trouble.
        start = line + rest.count("\n", 0, m.start() + max(0, m.group().find("<raw_text")))
        if record := _xml_record(element, start, problems):
            records.append(record)
    return records


def awc_xml_records(lines: Sequence[str], problems: Problems) -> list[AwcRecord]:
    """<METAR> elements in document order; a broken or truncated document keeps what it can.

    The document is fed line by line so each report knows the line its raw_text starts on. A parse
    error (a cut-off download, a mangled element) keeps the complete elements before it and picks
    up any complete ones after it.
    """
    parser: ET.XMLPullParser[ET.Element] = ET.XMLPullParser(events=("start", "end"))
    records: list[AwcRecord] = []
    report_line = 0

    def drain(number: int) -> None:
        nonlocal report_line
        for item in parser.read_events():
            # Only start/end were asked for, but the stub also allows namespace-event shapes.
            event, element = item[0], item[-1]
            if not isinstance(element, ET.Element):
                continue
            tag = _local(element.tag)
            if event == "start" and tag in ("METAR", "raw_text"):
                report_line = number
            elif event == "end" and tag == "METAR":
                if record := _xml_record(element, report_line, problems):
                    records.append(record)
                element.clear()
            elif event == "end" and tag == "error" and _text(element.text):
                problems.add(number, f"the feed reports an error: {element.text!s:.120}")

    try:
        for number, text in enumerate(lines, start=1):
            parser.feed(text + "\n")
            drain(number)
        parser.close()
    except ET.ParseError as exc:
        line, column = exc.position
        drain(line)
        after = _resync(lines, line, column, problems)
        problems.add(
            line,
            f"XML breaks off ({exc}); {len(records)} reports read before it, {len(after)} after",
        )
        records += after
    return records


def awc_reports(
    records: Sequence[AwcRecord], problems: Problems, reference: datetime
) -> list[Report]:
    times = [_iso_utc(record.observation_time) for record in records]
    # A row without observation_time belongs with the rest of the file, not with today.
    months = Counter((time.year, time.month) for time in times if time is not None)
    file_month = months.most_common(1)[0][0] if months else None
    reports = []
    for record, feed_utc in zip(records, times, strict=True):
        observed = feed_utc
        head = read_head(record.raw)
        if observed is None and record.observation_time is not None:
            problems.add(record.line, f"unreadable observation_time {record.observation_time!r}")
        if head.time is None:
            problems.add(record.line, f"{head.trouble}: {record.raw[:60]!r}")
        if observed is not None:
            year, month = observed.year, observed.month
        elif head.time is not None:
            # Only when no row is dated does the caller's reference time (file mtime) count.
            year, month = file_month or month_of_day(reference, head.time[0])
            observed = observed_at(year, month, head.time)
            if observed is None:
                why = _time_trouble(head.time, year, month)
                problems.add(record.line, f"impossible time group ({why}): {record.raw[:60]!r}")
        else:
            year, month = file_month or (reference.year, reference.month)
        metar_type = record.hints.get("metar_type")
        reports.append(
            Report(
                raw=record.raw,
                observed_utc=observed,
                year=year,
                month=month,
                station=record.station_id or head.station,
                kind=head.kind or (metar_type if metar_type in REPORT_TYPES else None),
                lat_deg=_finite(record.latitude),
                lon_deg=_finite(record.longitude),
                elevation_m=_finite(record.elevation_m),
                where=problems.where(record.line),
                feed_utc=feed_utc,
                awc=record.hints,
            )
        )
    return reports


# --- NOAA tgftp station and cycle files -------------------------------------------------------

# [0-9], not \\d: other scripts' digits would match, and int() reads them.
_STAMP = re.compile(r"([0-9]{4})/([0-9]{2})/([0-9]{2}) ([0-9]{2}):([0-9]{2})")


def is_tgftp_stamp(line: str) -> bool:
    return _STAMP.fullmatch(line.strip()) is not None


def _stamp(text: str) -> tuple[datetime | None, str | None]:
    """The time of a timestamp line, and a problem: how an hour 24 or minute 60 was read, or why
    there is no time (`2025/13/40 15:55`)."""
    m = _STAMP.fullmatch(text)
    if m is None:
        return None, f"not a timestamp line {text!r}"
    year, month, day, hour, minute = (int(g) for g in m.groups())
    time = time_in_month(year, month, day, hour, minute) if hour <= 24 and minute <= 60 else None
    if time is None:
        return None, f"impossible timestamp {text!r}; its report is dated by the file"
    if hour == 24 or minute == 60:
        return time, f"timestamp {text!r} read as {time:%Y/%m/%d %H:%M}"
    return time, None


def tgftp_reports(
    lines: Sequence[str], problems: Problems, reference: datetime
) -> tuple[list[Report], int]:
    """Reports of a station or cycle file, exact repeats dropped; returns (reports, duplicates).

    A report line whose timestamp line is impossible or missing is kept, dated against the last
    good timestamp before it (the first in the file for one before any, the caller's reference
    in a file without one).
    """
    reports: list[Report] = []
    seen: set[str] = set()
    duplicates = 0
    stamps = (_stamp(line.strip())[0] for line in lines if is_tgftp_stamp(line))
    last_good = next((t for t in stamps if t is not None), reference)
    pending: tuple[int, datetime | None] | None = None  # the timestamp waiting for its report
    for number, line in enumerate(lines, start=1):
        text = line.strip()
        if not text:
            continue
        if is_tgftp_stamp(text):
            if pending is not None:
                problems.add(pending[0], "timestamp line without a report after it")
            stamp, trouble = _stamp(text)
            if trouble is not None:
                problems.add(number, trouble)
            if stamp is not None:
                last_good = stamp
            pending = (number, stamp)
            continue
        if pending is None:
            problems.add(number, f"report line without a timestamp line before it: {text[:60]!r}")
            stamp = None
        else:
            stamp = pending[1]
            pending = None
        raw = clean_raw(text)
        if not raw:
            continue
        if raw in seen:
            duplicates += 1
            continue
        seen.add(raw)
        # Without a usable time group, when NOAA received the report is the best time there is.
        head = read_head(raw)
        reports.append(
            _dated_report(head, raw, stamp or last_good, number, problems, undated=stamp)
        )
    if pending is not None:
        problems.add(pending[0], "timestamp line without a report after it (file cut short?)")
    return reports, duplicates


# --- one report per line (VATSIM format=text, plain files) ------------------------------------


def line_reports(lines: Sequence[str], problems: Problems, reference: datetime) -> list[Report]:
    reports = []
    for number, line in enumerate(lines, start=1):
        raw = clean_raw(line)
        if not raw:
            continue
        head = read_head(raw)
        if head.station is None:
            problems.add(number, f"not a METAR report: {raw[:60]!r}")
            continue
        reports.append(_dated_report(head, raw, reference, number, problems))
    return reports
