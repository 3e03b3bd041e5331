"""One NMEA 0183 field -> a checked value, or a one-line error naming the sentence and field.

Split from `nmea_sentences` so the sentence interpreters read as what each sentence means,
and the rules for what a field may hold (plain decimals, hhmmss, ddmmyy, (d)ddmm.mmmm, two-digit
years) live in one place. A parser here raises `SentenceError` whose message names the field;
`nmea_sentences.interpret` prefixes the sentence.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from datetime import UTC, date, time
from typing import NamedTuple

from wxsky.weather.state import CLOCK_YEARS, year_in_range

# NMEA numbers are plain decimals: no exponent, and none of the nan/inf/1_000 that float() takes.
_NUMBER = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)")
_HHMMSS = re.compile(r"([0-9]{2})([0-9]{2})([0-9]{2})(?:\.([0-9]*))?")
DDMMYY = re.compile(r"([0-9]{2})([0-9]{2})([0-9]{2})")
_DDMM = re.compile(r"([0-9]*)([0-9]{2}(?:\.[0-9]*)?)")  # (d)ddmm.mmmm; degrees may be short


class SentenceError(ValueError):
    """A field makes the sentence unusable; the message names the field, the caller the
    sentence."""


class SentenceIgnored(Exception):
    """A well-formed sentence wxsky cannot use (invalid status, apparent wind, no heading)."""


def text(fields: Sequence[str], n: int) -> str:
    """Field n (1-based); an absent trailing field reads as empty."""
    return fields[n - 1] if n <= len(fields) else ""


def number(fields: Sequence[str], n: int, what: str) -> float | None:
    raw = text(fields, n)
    if raw == "":
        return None
    if _NUMBER.fullmatch(raw) is None:
        raise SentenceError(f"field {n} ({what}) {raw!r} is not a number")
    value = float(raw)
    if not math.isfinite(value):  # more digits than a float holds
        raise SentenceError(f"field {n} ({what}) {raw!r} is not a finite number")
    return value


def measure(fields: Sequence[str], n: int, what: str, unit: str) -> float | None:
    """Field n, whose unit letter follows in field n+1. Devices that leave the letter empty
    are common; a different letter is a different quantity and must not be read as this."""
    value = number(fields, n, what)
    letter = text(fields, n + 1)
    if value is not None and letter not in ("", unit):
        raise SentenceError(f"field {n + 1} ({what} unit) {letter!r}, expected {unit!r}")
    return value


def whole(fields: Sequence[str], n: int, what: str) -> int | None:
    raw = text(fields, n)
    if raw == "":
        return None
    if not raw.isdigit():
        raise SentenceError(f"field {n} ({what}) {raw!r} is not a whole number")
    return int(raw)


def angle(value_deg: float | None, n: int, what: str) -> float | None:
    if value_deg is not None and not 0.0 <= value_deg <= 360.0:
        raise SentenceError(f"field {n} ({what}) {value_deg:g}° out of range 0..360")
    return value_deg


class TimeOfDay(NamedTuple):
    clock: time  # UTC
    resolution_s: float

    @property
    def seconds(self) -> float:
        c = self.clock
        return c.hour * 3600.0 + c.minute * 60.0 + c.second + c.microsecond / 1e6


def time_of_day(f: Sequence[str], n: int) -> TimeOfDay | None:
    raw = text(f, n)
    if raw == "":
        return None
    m = _HHMMSS.fullmatch(raw)
    if m is None:
        raise SentenceError(f"field {n} (UTC time) {raw!r} is not hhmmss(.ss)")
    hour, minute, second = int(m[1]), int(m[2]), int(m[3])
    fraction = m[4] or ""
    if hour > 23:
        raise SentenceError(f"field {n} (UTC time) hour {hour} out of range 0..23")
    if minute > 59:
        raise SentenceError(f"field {n} (UTC time) minute {minute} out of range 0..59")
    if second > 60:
        raise SentenceError(f"field {n} (UTC time) second {second} out of range 0..60")
    # Digits, not float arithmetic, so 22.10 s is exactly 100 000 µs.
    microsecond = int((fraction + "000000")[:6])
    if second == 60:  # a leap second: datetime has none, so hold the last instant before it
        second, microsecond = 59, 999_000
    resolution_s = 10.0 ** -len(fraction) if fraction else 1.0
    return TimeOfDay(time(hour, minute, second, microsecond, tzinfo=UTC), resolution_s)


def full_year(year: int, digits: int, reference_year: int) -> int:
    """A two-digit year in the century that puts it nearest `reference_year`; a tie goes to
    the past (a receiver reports the date now, not one 50 years ahead)."""
    if digits != 2:
        return year
    century = reference_year // 100 * 100
    candidates = (century - 100 + year, century + year, century + 100 + year)
    return min(candidates, key=lambda y: (abs(y - reference_year), y))


def calendar_date(day: int, month: int, year: int, where: str) -> date:
    if not 1 <= day <= 31:
        raise SentenceError(f"{where} (date) day {day} out of range 1..31")
    if not 1 <= month <= 12:
        raise SentenceError(f"{where} (date) month {month} out of range 1..12")
    try:
        when = date(year, month, day)
    except ValueError:
        raise SentenceError(
            f"{where} (date) {year:04d}-{month:02d}-{day:02d} is not a calendar date"
        ) from None
    if not year_in_range(year):
        raise SentenceError(
            f"{where} (date) {when.isoformat()} is outside the clock's years {CLOCK_YEARS}"
        )
    return when


def coordinate(f: Sequence[str], n: int, what: str, max_deg: float, sides: str) -> float | None:
    """ddmm.mmmm (latitude) or dddmm.mmmm (longitude) in field n, its side letter in n+1;
    the second side letter is the negative one."""
    raw = text(f, n)
    if raw == "":
        return None
    m = _DDMM.fullmatch(raw)
    if m is None:
        raise SentenceError(f"field {n} ({what}) {raw!r} is not (d)ddmm.mmmm")
    degrees = float(m[1] or "0")
    minutes = float(m[2])
    if minutes >= 60.0:
        raise SentenceError(f"field {n} ({what}) minutes {minutes:g} out of range 0..<60")
    value_deg = degrees + minutes / 60.0
    if value_deg > max_deg:
        raise SentenceError(f"field {n} ({what}) {value_deg:g}° out of range 0..{max_deg:g}")
    side = text(f, n + 1)
    if side not in (sides[0], sides[1]):
        raise SentenceError(f"field {n + 1} ({what} side) {side!r}, expected {' or '.join(sides)}")
    return -value_deg if side == sides[1] else value_deg
