"""Replay a recorded cockpit capture into wxsky: NMEA 0183 text to a serial line, CAN logs to a
CAN bus, at the recorded pace (or --fast, or --speed times it).

    # NMEA: one sentence a line, optionally after a timestamp that gives the pace
    .venv/bin/python tools/emulators/replay_capture.py \\
        tests/data/cockpit/instructor-panel.nmea --pty
    wxsky run --serial /dev/pts/7             # the path it printed
    .venv/bin/python tools/emulators/replay_capture.py panel.nmea \\
        --serial socket://localhost:4001 --fast

    # CAN: any log python-can reads (.log candump -L, .asc, .blf, .csv, .trc, .mf4, .db)
    .venv/bin/python tools/emulators/replay_capture.py tests/data/cockpit/canaerospace.log \\
        --can udp_multicast:239.74.163.2 --speed 2
    .venv/bin/python tools/emulators/replay_capture.py flight.blf --can socketcan:vcan0

NMEA timestamps: `2026-11-21T10:00:00.123Z $WIMWV,...` (ISO 8601; no zone means UTC) or
`1763719200.123 $WIMWV,...` (epoch seconds). A line without one is sent 1/--rate-hz after the
line before it; any other text before the `$` is sent as recorded (wxsky skips it). Lines are
sent byte for byte, bad ones included, ended with CR LF. Gaps longer than --max-gap-s (after
--speed) are cut short, as python-can's MessageSync does for CAN. CAN frames go out with
their recorded ids, flags and data; error frames are counted and not sent.
"""

from __future__ import annotations

import argparse
import math
import re
import signal
import sys
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the checkout, for `tools.*`

from tools.emulators.cockpit_emulator import positive_number, stop_on_sigterm
from tools.emulators.cockpit_outputs import (
    ByteSink,
    PtyPort,
    SerialPort,
    add_output_arguments,
    open_can_bus,
)

DEFAULT_RATE_HZ = 5.0
DEFAULT_MAX_GAP_S = 60.0  # python-can MessageSync's default `skip`
CAN_SEND_TIMEOUT_S = 1.0  # a real bus's transmit queue fills in --fast; wait, don't drop

_ISO = re.compile(rb"\d{4}-\d{2}-\d{2}T[0-9:.,]+(?:Z|[+-]\d{2}:?\d{2})?")
_EPOCH = re.compile(rb"\d{9,}(?:\.\d*)?")
_STAMPED = re.compile(rb"(\S+)[ \t]+(.*)")


@dataclass(frozen=True)
class CaptureLine:
    recorded_s: float | None  # epoch seconds of the timestamp, None when the line has none
    data: bytes  # as sent, CR LF included


def parse_timestamp(token: bytes) -> float | None:
    """Epoch seconds of an ISO 8601 or epoch-seconds timestamp, or None if it is neither."""
    if _EPOCH.fullmatch(token):
        return float(token)
    if _ISO.fullmatch(token):
        try:
            when = datetime.fromisoformat(token.decode("ascii").replace(",", "."))
        except ValueError:
            return None
        if when.tzinfo is None:
            when = when.replace(tzinfo=UTC)
        return when.timestamp()
    return None


def parse_nmea_capture(raw: bytes) -> list[CaptureLine]:
    """The lines of a capture file; empty lines are left out."""
    out = []
    for line in re.split(rb"\r\n|\r|\n", raw):
        if not line.strip():
            continue
        recorded_s = None
        m = _STAMPED.fullmatch(line)
        if m is not None:
            recorded_s = parse_timestamp(m[1])
            if recorded_s is not None:
                line = m[2]
        out.append(CaptureLine(recorded_s, line + b"\r\n"))
    return out


def nmea_schedule(
    lines: Iterable[CaptureLine], *, speed: float, rate_hz: float, max_gap_s: float
) -> Iterator[tuple[float, CaptureLine]]:
    """Each line with when to send it, in seconds after the first line."""
    at_s = 0.0
    last_recorded_s: float | None = None
    for n, line in enumerate(lines):
        if n == 0:
            gap_s = 0.0
        elif line.recorded_s is not None and last_recorded_s is not None:
            gap_s = max(0.0, line.recorded_s - last_recorded_s)  # a clock stepping back: now
        else:
            gap_s = 1.0 / rate_hz
        if line.recorded_s is not None:
            last_recorded_s = line.recorded_s
        at_s += min(gap_s / speed, max_gap_s) if max_gap_s > 0 else gap_s / speed
        yield at_s, line


@dataclass
class ReplayStats:
    sent: int = 0  # lines or frames
    sent_bytes: int = 0
    dropped: int = 0  # lines with no reader on the pty, frames the bus refused
    skipped: int = 0  # error frames, which python-can cannot send
    seconds: float = 0.0


def replay_nmea(
    lines: Iterable[CaptureLine],
    port: ByteSink,
    *,
    fast: bool = False,
    speed: float = 1.0,
    rate_hz: float = DEFAULT_RATE_HZ,
    max_gap_s: float = DEFAULT_MAX_GAP_S,
    stats: ReplayStats | None = None,
) -> ReplayStats:
    """Send `lines` to `port`; `stats`, when given, is kept up to date, so a caller that
    stops on Ctrl-C still has it."""
    stats = stats if stats is not None else ReplayStats()
    start = time.monotonic()
    try:
        schedule = nmea_schedule(lines, speed=speed, rate_hz=rate_hz, max_gap_s=max_gap_s)
        for at_s, line in schedule:
            if not fast:
                delay = start + at_s - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
            written = port.write(line.data)
            stats.sent_bytes += written
            if written == len(line.data):
                stats.sent += 1
            else:
                stats.dropped += 1
    finally:
        stats.seconds = time.monotonic() - start
    return stats


def read_can_log(path: Path) -> Iterator[Any]:
    """The messages of a CAN log in any format python-can reads, chosen by its suffix."""
    import can

    with can.LogReader(path) as reader:
        yield from reader


def _scaled(messages: Iterable[Any], speed: float) -> Iterator[Any]:
    """MessageSync plays at the recorded pace only; for --speed, squeeze the timestamps."""
    first_s: float | None = None
    for msg in messages:
        if first_s is None:
            first_s = msg.timestamp
        msg.timestamp = first_s + (msg.timestamp - first_s) / speed
        yield msg


def replay_can(
    messages: Iterable[Any],
    bus: Any,
    *,
    fast: bool = False,
    speed: float = 1.0,
    max_gap_s: float = DEFAULT_MAX_GAP_S,
    stats: ReplayStats | None = None,
) -> ReplayStats:
    import can

    """Send `messages` on `bus`; `stats` as for `replay_nmea`."""
    stats = stats if stats is not None else ReplayStats()
    start = time.monotonic()
    source: Iterable[Any] = (
        messages
        if fast
        else can.MessageSync(_scaled(messages, speed), timestamps=True, skip=max_gap_s)
    )
    try:
        for msg in source:
            if msg.is_error_frame:
                stats.skipped += 1
                continue
            # The recorded channel names the capture's interface (vcan0); socketcan would
            # send there instead of on the bus we opened.
            msg.channel = None
            try:
                bus.send(msg, timeout=CAN_SEND_TIMEOUT_S)
            except can.CanOperationError:
                stats.dropped += 1
                continue
            stats.sent += 1
            stats.sent_bytes += len(msg.data)
    finally:
        stats.seconds = time.monotonic() - start
    return stats


def main(argv: list[str] | None = None, *, log: Callable[[str], None] | None = None) -> int:
    say = log or (lambda line: print(line, flush=True))
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("capture", type=Path, help="NMEA text (serial, pty) or a CAN log (can)")
    add_output_arguments(p)
    p.add_argument("--fast", action="store_true", help="send as fast as possible")
    p.add_argument(
        "--speed", type=positive_number, default=1.0, help="times the recorded pace (default 1)"
    )
    p.add_argument(
        "--rate-hz",
        type=positive_number,
        default=DEFAULT_RATE_HZ,
        help="lines per second for NMEA lines without a timestamp (default 5)",
    )
    p.add_argument(
        "--max-gap-s",
        type=float,
        default=DEFAULT_MAX_GAP_S,
        help="cut longer pauses to this (0: never; default 60)",
    )
    args = p.parse_args(argv)
    if not (math.isfinite(args.max_gap_s) and args.max_gap_s >= 0):
        p.error(f"--max-gap-s {args.max_gap_s} must be 0 or more")
    if not args.capture.is_file():
        p.error(f"{args.capture}: no such file")

    capture: Any = None
    if args.can:
        import can

        try:  # before the bus: a capture python-can cannot read should not touch the bus
            capture = can.LogReader(args.capture)
        except (ValueError, OSError) as exc:
            print(f"cannot read {args.capture}: {exc}", file=sys.stderr)
            return 1

    signal.signal(signal.SIGTERM, stop_on_sigterm)
    stats = ReplayStats()
    pty: PtyPort | None = None
    target: Any
    try:
        if args.can:
            target = open_can_bus(args.can)
            name = f"CAN {args.can}"
        elif args.serial:
            target = SerialPort(args.serial)
            name = target.name
        else:
            target = pty = PtyPort()
            name = pty.name
    except Exception as exc:  # python-can and pyserial raise their own families
        print(f"cannot open the output: {exc}", file=sys.stderr)
        if capture is not None:
            capture.stop()
        return 1
    unit = "frames" if args.can else "lines"
    unreadable = ""
    try:
        if args.can:
            replay_can(
                capture,
                target,
                fast=args.fast,
                speed=args.speed,
                max_gap_s=args.max_gap_s,
                stats=stats,
            )
        else:
            lines = parse_nmea_capture(args.capture.read_bytes())
            if pty is not None:
                say(pty.path)
                print(f"waiting for a reader, e.g. wxsky run --serial {pty.path}", file=sys.stderr)
                pty.wait_for_reader()
            replay_nmea(
                lines,
                target,
                fast=args.fast,
                speed=args.speed,
                rate_hz=args.rate_hz,
                max_gap_s=args.max_gap_s,
                stats=stats,
            )
            if pty is not None:
                pty.drain()
    except KeyboardInterrupt:
        pass
    except ValueError as exc:  # a line of a CAN log that its reader cannot parse
        unreadable = f"stopped: cannot read {args.capture}: {exc}"
    finally:
        if args.can:
            capture.stop()
            target.shutdown()
        else:
            target.close()
    extra = [f"{stats.dropped} dropped"] if stats.dropped else []
    if stats.skipped:
        extra.append(f"{stats.skipped} error frames skipped")
    say(
        f"replayed {stats.sent} {unit} ({stats.sent_bytes} B) from {args.capture} to {name} "
        f"in {stats.seconds:.2f} s" + (f" ({', '.join(extra)})" if extra else "")
    )
    if unreadable:
        print(unreadable, file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
