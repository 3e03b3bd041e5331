"""NMEA 0183 from a cockpit serial line decoded into weather values, and the encoder emulators
use to make sentences.

Three small pieces: `LineSplitter` cuts the byte stream into lines at CR, LF or CRLF without
ever holding more than the line limit; `parse_frame` finds the sentence in a line, checks its
checksum and splits its fields; `nmea_sentences.interpret` turns the fields of MWV, MWD, MDA,
HDT, HDG, ZDA, RMC and wxsky's own `$PWXCL` cloud layer into a `Decoded`.

Ignored (counted, not an error): sentence types wxsky does not use -- a serial line carries
other instruments -- and sentences the device itself marks invalid. Rejected: everything
malformed, badly checksummed, over-long or out of range, with a one-line reason. Pure: the
serial link in `wxsky.inputs` owns the port and passes its monotonic clock in as `now_s`.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from datetime import UTC, datetime
from functools import reduce

from wxsky.protocols.nmea_sentences import SENTENCES, Context, LinkState, interpret
from wxsky.protocols.result import Decoded

__all__ = [
    "HEADING_SOURCES",
    "Frame",
    "FrameError",
    "LineSplitter",
    "NmeaDecoder",
    "NmeaSettings",
    "NmeaStats",
    "OverlongLine",
    "checksum",
    "parse_frame",
    "sentence",
]

HEADING_SOURCES = ("fixed", "hdt", "hdg")


@dataclass(frozen=True)
class NmeaSettings:
    sensor_heading_deg: float = 0.0  # added to MWV's angle when heading_source is "fixed"
    heading_source: str = "fixed"  # "fixed" | "hdt" | "hdg"
    accept_relative_wind: bool = False  # MWV reference R (apparent wind)
    allow_missing_checksum: bool = False
    max_line_bytes: int = 256  # NMEA's own limit is 82 with CR LF, but devices exceed it
    geographic_wind_hold_s: float = 10.0  # MWV is ignored this long after MWD/MDA wind

    def __post_init__(self) -> None:
        if self.heading_source not in HEADING_SOURCES:
            raise ValueError(
                f"heading_source {self.heading_source!r} is not one of {', '.join(HEADING_SOURCES)}"
            )
        if not math.isfinite(self.sensor_heading_deg):
            raise ValueError(f"sensor_heading_deg {self.sensor_heading_deg} is not finite")
        if self.max_line_bytes < 1:
            raise ValueError(f"max_line_bytes {self.max_line_bytes} must be at least 1")
        if not (math.isfinite(self.geographic_wind_hold_s) and self.geographic_wind_hold_s >= 0):
            raise ValueError(f"geographic_wind_hold_s {self.geographic_wind_hold_s} must be >= 0")


# -- encoding ---------------------------------------------------------------------------


def _xor(data: bytes) -> int:
    return reduce(lambda acc, byte: acc ^ byte, data, 0)


def checksum(body: str) -> str:
    """The checksum of the text between `$` and `*`: two uppercase hex digits."""
    return f"{_xor(body.encode('ascii')):02X}"


def sentence(body: str) -> bytes:
    """`$` + body + `*hh` CR LF, e.g. `sentence("WIMWV,270.0,T,12.5,M,A")`."""
    raw = body.encode("ascii")  # UnicodeEncodeError is a ValueError
    bad = [chr(b) for b in raw if not 0x20 <= b <= 0x7E or b in b"$!*"]
    if bad:
        raise ValueError(f"NMEA sentence body may not contain {bad[0]!r}: {body!r}")
    return b"$" + raw + f"*{_xor(raw):02X}\r\n".encode("ascii")


# -- lines ------------------------------------------------------------------------------


@dataclass(frozen=True)
class OverlongLine:
    """Stands for a line that grew past the limit; its bytes were dropped."""

    limit_bytes: int


_LINE_ENDS = re.compile(rb"[\r\n]+")


class LineSplitter:
    """Cuts bytes, in whatever chunks they arrive, into lines at CR, LF or CRLF; empty lines
    are skipped. A line that grows past `max_line_bytes` is reported once, as soon as it
    does, and the rest of it discarded up to the next line end, so a device that never sends
    one cannot make the buffer grow."""

    def __init__(self, max_line_bytes: int) -> None:
        self.max_line_bytes = max_line_bytes
        self._buf = bytearray()
        self._discarding = False

    def feed(self, data: bytes) -> list[bytes | OverlongLine]:
        out: list[bytes | OverlongLine] = []
        pos = 0
        while True:
            end = _LINE_ENDS.search(data, pos)
            piece = data[pos : end.start() if end else len(data)]
            if not self._discarding and piece:
                if len(self._buf) + len(piece) > self.max_line_bytes:
                    out.append(OverlongLine(self.max_line_bytes))
                    self._buf.clear()
                    self._discarding = True
                else:
                    self._buf += piece
            if end is None:
                return out
            if not self._discarding and self._buf:
                out.append(bytes(self._buf))
            self._buf.clear()
            self._discarding = False
            pos = end.end()

    def flush(self) -> bytes:
        """The unterminated rest (b"" if none, or if it was an over-long line, already
        reported); the splitter starts afresh."""
        rest = b"" if self._discarding else bytes(self._buf)
        self._buf.clear()
        self._discarding = False
        return rest


# -- framing ----------------------------------------------------------------------------


class FrameError(ValueError):
    def __init__(self, reason: str, *, bad_checksum: bool = False) -> None:
        super().__init__(reason)
        self.bad_checksum = bad_checksum


@dataclass(frozen=True)
class Frame:
    start: str  # "$", or "!" for encapsulated (AIS) sentences
    talker: str  # two letters, or "P" for a proprietary sentence
    kind: str  # "MWV"; for a proprietary sentence maker and type, "WXCL"
    fields: tuple[str, ...]  # after the address; field 1 first
    has_checksum: bool

    @property
    def name(self) -> str:
        """The name interpreters and reasons use: "MWV", "PWXCL"."""
        return "P" + self.kind if self.talker == "P" else self.kind


_HEX_DIGITS = frozenset(b"0123456789abcdefABCDEF")
# By convention an address starting with P is proprietary whatever follows.
_ADDRESS = re.compile(r"(P)([A-Z0-9]{1,9})|([A-Z]{2})([A-Z]{3})")


def _show(raw: bytes) -> str:
    text = raw.decode("ascii", "backslashreplace")
    return repr(text if len(text) <= 60 else text[:57] + "...")


def parse_frame(line: bytes, *, allow_missing_checksum: bool = False) -> Frame:
    """The sentence in one line (no line end); text before its `$` is ignored, since some
    loggers prepend a timestamp. Raises FrameError with a one-line reason."""
    # `$` and `!` cannot occur inside a sentence, so the last one starts it: a sentence cut
    # short by a device reset and glued to the next is dropped, the next one kept.
    start = max(line.rfind(b"$"), line.rfind(b"!"))
    if start < 0:
        raise FrameError(f"no '$' starting a sentence in {_show(line)}")
    text = line[start + 1 :].rstrip(b" \t")
    star = text.find(b"*")
    has_checksum = star >= 0
    if has_checksum:
        body, given = text[:star], text[star + 1 :]
        if len(given) != 2 or not _HEX_DIGITS.issuperset(given):
            raise FrameError(f"malformed checksum in {_show(line)}", bad_checksum=True)
    elif allow_missing_checksum:
        body = text
    else:
        raise FrameError(f"no checksum (allow_missing_checksum is off) in {_show(line)}")
    for offset, byte in enumerate(body):
        if not 0x20 <= byte <= 0x7E:
            raise FrameError(f"byte 0x{byte:02x} {offset + 1} after '$' is not printable ASCII")
    if has_checksum and _xor(body) != int(given, 16):
        raise FrameError(
            f"bad checksum *{given.decode()}, computed {_xor(body):02X}, in {_show(line)}",
            bad_checksum=True,
        )
    address, *fields = body.decode("ascii").split(",")
    m = _ADDRESS.fullmatch(address)
    if m is None:
        raise FrameError(f"address {address!r} is not talker + sentence type in {_show(line)}")
    talker, kind = (m[1], m[2]) if m[1] else (m[3], m[4])
    return Frame(chr(line[start]), talker, kind, tuple(fields), has_checksum)


# -- decoding ---------------------------------------------------------------------------


@dataclass
class NmeaStats:
    """What an NmeaDecoder has seen; every line counts once in lines and once in one of
    updates, consumed, ignored and errors."""

    lines: int = 0
    updates: int = 0
    consumed: int = 0  # used without an update of its own (HDT, HDG)
    ignored: int = 0
    errors: int = 0
    overlong: int = 0  # of errors
    bad_checksum: int = 0  # of errors
    unknown: int = 0  # of ignored: sentence types wxsky does not use


class NmeaDecoder:
    """Bytes from one serial input in, one `Decoded` per line out. Keeps what later sentences
    depend on (the last heading, when MWD/MDA last gave wind), so use one per input."""

    def __init__(
        self, settings: NmeaSettings = NmeaSettings(), *, reference_year: int | None = None
    ) -> None:
        self.settings = settings
        self.reference_year = (
            reference_year if reference_year is not None else datetime.now(UTC).year
        )
        self.stats = NmeaStats()
        self._splitter = LineSplitter(settings.max_line_bytes)
        self._state = LinkState()
        self._last_now_s = 0.0

    def feed(self, data: bytes, now_s: float) -> list[Decoded]:
        """The lines `data` completes, decoded; the rest waits for the next chunk."""
        self._last_now_s = now_s
        out: list[Decoded] = []
        for line in self._splitter.feed(bytes(data)):
            if isinstance(line, OverlongLine):
                self.stats.lines += 1
                self.stats.overlong += 1
                out.append(self._count(Decoded.reject(self._overlong_reason())))
            else:
                out.append(self.decode_line(line, now_s))
        return out

    def flush(self) -> list[Decoded]:
        """The unterminated rest as a line (the end of a replay file), at the last `now_s`."""
        rest = self._splitter.flush()
        return [self.decode_line(rest, self._last_now_s)] if rest else []

    def decode_line(self, line: bytes | str, now_s: float) -> Decoded:
        """One line, with or without its line end."""
        raw = line.encode("utf-8", "surrogatepass") if isinstance(line, str) else bytes(line)
        raw = raw.rstrip(b"\r\n")
        self.stats.lines += 1
        if not raw:
            return self._count(Decoded.reject("NMEA: empty line"))
        if len(raw) > self.settings.max_line_bytes:
            self.stats.overlong += 1
            return self._count(Decoded.reject(self._overlong_reason()))
        try:
            frame = parse_frame(raw, allow_missing_checksum=self.settings.allow_missing_checksum)
        except FrameError as exc:
            if exc.bad_checksum:
                self.stats.bad_checksum += 1
            return self._count(Decoded.reject(f"NMEA: {exc}"))
        if frame.start == "!":
            self.stats.unknown += 1
            return self._count(Decoded.ignore(f"!{frame.name}: encapsulated sentence"))
        if frame.name not in SENTENCES:
            self.stats.unknown += 1
        ctx = Context(self.settings, self._state, now_s, self.reference_year)
        return self._count(interpret(frame.name, frame.fields, ctx))

    def _overlong_reason(self) -> str:
        return f"NMEA: line longer than {self.settings.max_line_bytes} bytes dropped"

    def _count(self, decoded: Decoded) -> Decoded:
        if decoded.error:
            self.stats.errors += 1
        elif decoded.ignored:
            self.stats.ignored += 1
        elif decoded.update is not None:
            self.stats.updates += 1
        else:
            self.stats.consumed += 1
        return decoded
