"""Emulate cockpit hardware: play a scripted weather scenario as NMEA 0183 on a serial line or
as CANaerospace frames on a CAN bus, so wxsky's cockpit links can be tried without a panel.

    # NMEA on a pseudo-terminal: prints the device path, then waits for a reader
    .venv/bin/python tools/cockpit_emulator.py --pty
    wxsky run --serial /dev/pts/7             # the path it printed

    # NMEA on a real port or any pyserial URL (wxsky reads at 4800 baud unless told otherwise)
    .venv/bin/python tools/cockpit_emulator.py --serial /dev/ttyUSB0@4800 --rate-hz 2
    .venv/bin/python tools/cockpit_emulator.py --serial socket://localhost:4001

    # CANaerospace through python-can; udp_multicast reaches other processes on this host
    .venv/bin/python tools/cockpit_emulator.py --can udp_multicast:239.74.163.2 --loop
    wxsky run --can udp_multicast:239.74.163.2
    .venv/bin/python tools/cockpit_emulator.py --can socketcan:vcan0 --scenario front --speed 4

Scenarios are pure functions of scenario time (`scenario_at`), so tests check them directly:

    sweep   60 s: layer 1 cover 0 -> 8 -> 0 oktas, wind from 0 -> 360 deg at 0 -> 25 m/s, and
            the sky clock from 04:00 to 20:00 UTC on 21 June (sunrise to sunset in Europe).
    front  120 s: a cold front passes: cirrus, then altostratus, then a low layer that closes
            and lowers to 500 m; the wind freshens to a squall at the front and veers from 200
            to 300 deg; it turns cold, visibility drops in the rain, then the sky clears.

Values are sent every 1/--rate-hz s, time and date once a second (as a GPS or an air-data
computer sends them). --speed scales scenario time; --duration-s is in scenario seconds.
Ctrl-C (or SIGTERM) stops cleanly.
"""

from __future__ import annotations

import argparse
import fcntl
import math
import os
import queue
import select
import signal
import struct
import sys
import termios
import time
import tty
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from pathlib import Path
from types import FrameType
from typing import Any, NamedTuple, Protocol

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from wxsky.protocols.canaerospace import (  # noqa: E402
    encode_float,
    encode_layer,
    encode_utc,
    encode_wind,
)
from wxsky.protocols.nmea import sentence  # noqa: E402
from wxsky.units import FT_TO_M, KT_TO_MPS  # noqa: E402

KELVIN_OFFSET_C = 273.15
DEFAULT_BAUD = 4800  # what wxsky's serial input assumes when the URL names none
SERIAL_BITS_PER_BYTE = 10  # 8N1: start + 8 data + stop
# After a reader opens the pty, pyserial flushes its input buffer while configuring the port;
# lines sent in that moment would be lost, so wait this long before the first one.
PTY_SETTLE_S = 0.25
TIME_PERIOD_S = 1.0  # time and date go out once a second, as a GPS or air-data computer sends them


# -- scenarios --------------------------------------------------------------------------


class Layer(NamedTuple):
    layer: int  # cockpit layer 1-3
    oktas: float
    base_m: float  # MSL
    thickness_m: float


@dataclass(frozen=True)
class Knobs:
    """What the cockpit's panel is set to at one moment."""

    wind_dir_deg: float  # true, from, 0..360
    wind_speed_mps: float
    layers: tuple[Layer, ...]
    time_utc: datetime
    temperature_c: float | None = None  # None: the panel does not send it
    visibility_m: float | None = None  # CAN only: NMEA 0183 has no visibility field


@dataclass(frozen=True)
class Scenario:
    name: str
    length_s: float
    at: Callable[[float], Knobs]
    summary: str


def _clamp01(x: float) -> float:
    return min(1.0, max(0.0, x))


def _ramp(t_s: float, start_s: float, end_s: float) -> float:
    """0 before start, 1 after end, smooth (smoothstep) between."""
    x = _clamp01((t_s - start_s) / (end_s - start_s))
    return x * x * (3.0 - 2.0 * x)


def _lerp(a: float, b: float, x: float) -> float:
    return a + (b - a) * x


SWEEP_LENGTH_S = 60.0
SWEEP_START_UTC = datetime(2026, 6, 21, 4, 0, tzinfo=UTC)
SWEEP_SKY_S_PER_S = 16 * 3600.0 / SWEEP_LENGTH_S  # 04:00 to 20:00 UTC over the sweep


def sweep_at(t_s: float) -> Knobs:
    f = _clamp01(t_s / SWEEP_LENGTH_S)
    return Knobs(
        wind_dir_deg=360.0 * f,
        wind_speed_mps=25.0 * f,
        layers=(Layer(1, 8.0 * (1.0 - abs(2.0 * f - 1.0)), 1500.0, 800.0),),
        time_utc=SWEEP_START_UTC + timedelta(seconds=f * SWEEP_LENGTH_S * SWEEP_SKY_S_PER_S),
    )


FRONT_LENGTH_S = 120.0
FRONT_START_UTC = datetime(2026, 3, 14, 12, 0, tzinfo=UTC)
FRONT_SKY_S_PER_S = 90.0  # three hours of sky over the two minutes
FRONT_PASSAGE_S = 66.0


def front_at(t_s: float) -> Knobs:
    t = min(max(t_s, 0.0), FRONT_LENGTH_S)
    veer = _ramp(t, FRONT_PASSAGE_S - 8.0, FRONT_PASSAGE_S + 8.0)
    closing = _ramp(t, FRONT_PASSAGE_S - 30.0, FRONT_PASSAGE_S - 6.0)
    clearing = _ramp(t, FRONT_PASSAGE_S + 4.0, FRONT_PASSAGE_S + 30.0)
    # The squall line: the wind peaks as the front goes through, then settles stronger.
    squall = math.exp(-(((t - FRONT_PASSAGE_S) / 12.0) ** 2))
    cirrus = Layer(3, _lerp(_lerp(1.0, 5.0, _ramp(t, 0.0, 30.0)), 0.0, clearing), 8000.0, 600.0)
    altostratus = Layer(
        2,
        _lerp(_lerp(0.0, 7.0, _ramp(t, 15.0, 45.0)), 1.0, clearing),
        _lerp(4500.0, 3000.0, _ramp(t, 15.0, 55.0)),
        1000.0,
    )
    low = Layer(  # closes and lowers into the front's rain, then post-frontal cumulus
        1,
        _lerp(_lerp(0.0, 8.0, closing), 3.0, clearing),
        _lerp(_lerp(1500.0, 500.0, closing), 1200.0, clearing),
        _lerp(_lerp(800.0, 3500.0, closing), 1000.0, clearing),
    )
    return Knobs(
        wind_dir_deg=_lerp(200.0, 300.0, veer),
        wind_speed_mps=6.0 + 9.0 * squall + 3.0 * veer,
        layers=(low, altostratus, cirrus),
        time_utc=FRONT_START_UTC + timedelta(seconds=t * FRONT_SKY_S_PER_S),
        temperature_c=_lerp(18.0, 9.0, veer),
        visibility_m=_lerp(30_000.0, 40_000.0, clearing) - 26_000.0 * squall,
    )


SCENARIOS: dict[str, Scenario] = {
    "sweep": Scenario(
        "sweep", SWEEP_LENGTH_S, sweep_at, "cover, wind and time of day across their ranges"
    ),
    "front": Scenario("front", FRONT_LENGTH_S, front_at, "a cold front passing"),
}


def scenario_at(t_s: float, name: str = "sweep") -> Knobs:
    """The panel at scenario time `t_s` (clamped to the scenario's length)."""
    return SCENARIOS[name].at(t_s)


# -- encoders ---------------------------------------------------------------------------


def _decimal(value: float) -> str:
    """One decimal, without a trailing `.0`: the oktas a panel sends are mostly whole."""
    return f"{value:.1f}".rstrip("0").rstrip(".")


def nmea_lines(knobs: Knobs, *, with_time: bool = True, wind_sentence: str = "mwd") -> list[bytes]:
    """The sentences for `knobs`, each with checksum and CR LF.

    MWD by default: its direction is true, so it does not depend on the receiver's
    `sensor_heading_deg` as MWV's angle does."""
    dir_deg = knobs.wind_dir_deg % 360.0
    speed_mps = knobs.wind_speed_mps
    if wind_sentence == "mwd":
        bodies = [f"WIMWD,{dir_deg:.1f},T,,M,{speed_mps / KT_TO_MPS:.1f},N,{speed_mps:.1f},M"]
    elif wind_sentence == "mwv":
        bodies = [f"WIMWV,{dir_deg:.1f},T,{speed_mps:.1f},M,A"]
    else:
        raise ValueError(f"wind sentence {wind_sentence!r} is not mwd or mwv")
    if knobs.temperature_c is not None:
        mda = [""] * 20  # MDA's 20 fields; only the air temperature is given
        mda[4], mda[5] = f"{knobs.temperature_c:.1f}", "C"
        bodies.append("WIMDA," + ",".join(mda))
    for layer in knobs.layers:
        bodies.append(
            f"PWXCL,{layer.layer},{_decimal(layer.oktas)},"
            f"{layer.base_m / FT_TO_M:.0f},{layer.thickness_m / FT_TO_M:.0f}"
        )
    if with_time:
        utc = knobs.time_utc.astimezone(UTC)
        hundredths = utc.microsecond // 10_000
        bodies.append(f"GPZDA,{utc:%H%M%S}.{hundredths:02d},{utc:%d},{utc:%m},{utc.year:04d},00,00")
    return [sentence(body) for body in bodies]


def can_frames(
    knobs: Knobs, *, with_time: bool = True, node_id: int = 1
) -> list[tuple[int, bytes]]:
    """(CAN id, data field) frames for `knobs`, message codes 0 (see `MessageCodes`)."""
    frames = encode_wind(knobs.wind_speed_mps, knobs.wind_dir_deg % 360.0, node_id=node_id)
    if knobs.temperature_c is not None:
        frames.append(
            (335, encode_float(335, knobs.temperature_c + KELVIN_OFFSET_C, node_id=node_id))
        )
    for layer in knobs.layers:
        frames += encode_layer(
            layer.layer,
            cover_oktas=layer.oktas,
            base_m=layer.base_m,
            thickness_m=layer.thickness_m,
            node_id=node_id,
        )
    if knobs.visibility_m is not None:
        frames.append((1503, encode_float(1503, knobs.visibility_m, node_id=node_id)))
    if with_time:
        frames += encode_utc(knobs.time_utc, node_id=node_id)
    return frames


class MessageCodes:
    """CANaerospace's message code (byte 3): the sender counts every message of an id, so a
    receiver can spot lost frames. Layers share ids, so they share a counter."""

    def __init__(self) -> None:
        self._next: dict[int, int] = {}

    def stamp(self, frames: Sequence[tuple[int, bytes]]) -> list[tuple[int, bytes]]:
        out = []
        for can_id, data in frames:
            code = self._next.get(can_id, 0)
            self._next[can_id] = (code + 1) % 256
            out.append((can_id, data[:3] + bytes((code,)) + data[4:]))
        return out


# -- outputs ----------------------------------------------------------------------------


class ByteSink(Protocol):
    name: str

    def has_reader(self) -> bool: ...

    def write(self, data: bytes) -> int: ...

    def close(self) -> None: ...


class PtyPort:
    """A pseudo-terminal pair; the emulator writes to the master, a reader opens `path`.

    The emulator keeps no slave descriptor open, so the master reports POLLHUP while nobody
    has the device open: lines are then dropped, as on a cable with nothing at the far end,
    instead of piling up for the next reader. Writes never block: with the reader's buffer
    full, the rest of a chunk is dropped too."""

    def __init__(self) -> None:
        self.master, slave = os.openpty()
        self.path = os.ttyname(slave)
        self.name = f"pty {self.path}"
        tty.setraw(slave)  # no echo, no CR/LF translation for readers that keep the settings
        os.close(slave)
        os.set_blocking(self.master, False)
        self._poll = select.poll()
        self._poll.register(self.master, select.POLLOUT)

    def has_reader(self) -> bool:
        return not any(ev & select.POLLHUP for _, ev in self._poll.poll(0))

    def wait_for_reader(self, timeout_s: float | None = None) -> bool:
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while not self.has_reader():
            if deadline is not None and time.monotonic() >= deadline:
                return False
            time.sleep(0.02)
        time.sleep(PTY_SETTLE_S)
        return self.has_reader()

    def write(self, data: bytes) -> int:
        if not self.has_reader():
            return 0
        try:
            return os.write(self.master, data)
        except (BlockingIOError, OSError):
            return 0

    def unread_bytes(self) -> int:
        """Bytes sent that the reader has not read yet (0 when there is no reader)."""
        if not self.has_reader():
            return 0
        try:
            fd = os.open(self.path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        except OSError:
            return 0
        try:
            raw = fcntl.ioctl(fd, termios.FIONREAD, b"\0\0\0\0")
            return int(struct.unpack("i", raw)[0])
        finally:
            os.close(fd)

    def drain(self, timeout_s: float = 5.0) -> None:
        """Wait until the reader has read what was sent (or left), so closing the pty does
        not cut off the last lines. The pty hands bytes to the reader's side asynchronously,
        so the queue must read empty twice in a row."""
        deadline = time.monotonic() + timeout_s
        empty_checks = 0
        while empty_checks < 2 and time.monotonic() < deadline:
            empty_checks = empty_checks + 1 if self.unread_bytes() == 0 else 0
            time.sleep(0.05)

    def close(self) -> None:
        os.close(self.master)


class SerialPort:
    """A pyserial port or URL (`/dev/ttyUSB0`, `socket://host:4001`, `rfc2217://...`)."""

    def __init__(self, spec: str) -> None:
        import serial

        url, baud = parse_serial_spec(spec)
        self.baud = baud
        self.name = f"serial {url} at {baud} baud"
        # A bounded write: a port that stalls (flow control, a full socket) drops lines
        # rather than freezing the scenario clock.
        self._port: Any = serial.serial_for_url(url, baudrate=baud, write_timeout=1.0)
        self._timeout_error: type[Exception] = serial.SerialTimeoutException

    def has_reader(self) -> bool:
        return True

    def write(self, data: bytes) -> int:
        try:
            return int(self._port.write(data))
        except (self._timeout_error, queue.Full):  # loop:// says Full where others time out
            return 0

    def close(self) -> None:
        self._port.close()


def parse_serial_spec(spec: str) -> tuple[str, int]:
    """`URL[@BAUD]` as `wxsky run --serial` takes it."""
    url, sep, baud = spec.rpartition("@")
    if sep and url and baud.isdigit():
        return url, int(baud)
    return spec, DEFAULT_BAUD


def open_can_bus(spec: str) -> Any:
    """`INTERFACE:CHANNEL` as `wxsky run --can` takes it; the channel may hold colons."""
    import can

    interface, sep, channel = spec.partition(":")
    if not interface or not sep:
        raise ValueError(f"--can {spec!r}: expected INTERFACE:CHANNEL, e.g. socketcan:can0")
    return can.Bus(interface=interface, channel=channel)


class NmeaOut:
    def __init__(self, port: ByteSink, wind_sentence: str) -> None:
        self.port = port
        self.wind_sentence = wind_sentence
        self.name = port.name

    def has_reader(self) -> bool:
        return self.port.has_reader()

    def send(self, knobs: Knobs, with_time: bool) -> tuple[int, int]:
        """Lines and bytes that went out."""
        lines = nmea_lines(knobs, with_time=with_time, wind_sentence=self.wind_sentence)
        data = b"".join(lines)
        written = self.port.write(data)
        sent_lines = data[:written].count(b"\n")
        return sent_lines, written

    def close(self) -> None:
        self.port.close()


class CanOut:
    def __init__(self, bus: Any, node_id: int, name: str) -> None:
        self.bus = bus
        self.node_id = node_id
        self.name = name
        self._codes = MessageCodes()

    def has_reader(self) -> bool:
        return True

    def send(self, knobs: Knobs, with_time: bool) -> tuple[int, int]:
        import can

        frames = self._codes.stamp(can_frames(knobs, with_time=with_time, node_id=self.node_id))
        sent = sent_bytes = 0
        for can_id, data in frames:
            try:
                self.bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))
            except can.CanOperationError:
                continue  # a full transmit queue: the next tick sends fresh values anyway
            sent += 1
            sent_bytes += len(data)
        return sent, sent_bytes

    def close(self) -> None:
        self.bus.shutdown()


class Output(Protocol):
    name: str

    def has_reader(self) -> bool: ...

    def send(self, knobs: Knobs, with_time: bool) -> tuple[int, int]: ...

    def close(self) -> None: ...


# -- running ----------------------------------------------------------------------------


@dataclass
class RunStats:
    ticks: int = 0
    items: int = 0  # lines or frames
    bytes: int = 0
    skipped_ticks: int = 0  # the output could not keep up


def _describe(t_s: float, knobs: Knobs) -> str:
    layers = " ".join(f"L{lay.layer} {lay.oktas:.1f}/8 {lay.base_m:.0f} m" for lay in knobs.layers)
    extra = ""
    if knobs.temperature_c is not None:
        extra += f"  {knobs.temperature_c:.1f} °C"
    if knobs.visibility_m is not None:
        extra += f"  vis {knobs.visibility_m / 1000.0:.1f} km"
    return (
        f"t={t_s:6.1f} s  wind {knobs.wind_dir_deg % 360.0:05.1f}°/{knobs.wind_speed_mps:4.1f} "
        f"m/s  {layers}{extra}  {knobs.time_utc:%H:%M:%S}Z"
    )


def run(
    out: Output,
    scenario: Scenario,
    *,
    rate_hz: float,
    duration_s: float | None,
    speed: float,
    loop: bool,
    log: Callable[[str], None] = print,
    stats: RunStats | None = None,
) -> RunStats:
    """Send the scenario until `duration_s` of scenario time (None: for ever) has passed.
    `stats`, when given, is kept up to date, so a caller interrupted by Ctrl-C still has it."""
    stats = stats if stats is not None else RunStats()
    period_s = 1.0 / rate_hz
    start = time.monotonic()
    last_time_sent = -math.inf
    last_log = -math.inf
    logged = RunStats()
    tick = 0
    while True:
        wall_s = tick * period_s
        t_s = wall_s * speed
        last = duration_s is not None and t_s >= duration_s - 1e-9
        if last and duration_s is not None:
            t_s = duration_s  # the scenario's end state goes out, whatever the tick rate
        scenario_t_s = t_s % scenario.length_s if loop else min(t_s, scenario.length_s)
        knobs = scenario.at(scenario_t_s)
        with_time = wall_s - last_time_sent >= TIME_PERIOD_S - 1e-9
        if with_time:
            last_time_sent = wall_s
        items, sent_bytes = out.send(knobs, with_time)
        stats.ticks += 1
        stats.items += items
        stats.bytes += sent_bytes
        if wall_s - last_log >= 1.0 - 1e-9:
            last_log = wall_s
            reader = "" if out.has_reader() else "  (no reader: dropped)"
            log(
                f"{_describe(scenario_t_s, knobs)}  sent {stats.items - logged.items} "
                f"in {stats.bytes - logged.bytes} B{reader}"
            )
            logged = RunStats(items=stats.items, bytes=stats.bytes)
        if last:
            break
        tick += 1
        behind = int((time.monotonic() - start) / period_s) - tick
        if behind > 0:  # a slow line: send the scenario's present, not a backlog
            stats.skipped_ticks += behind
            tick += behind
        delay = start + tick * period_s - time.monotonic()
        if delay > 0:
            time.sleep(delay)
    return stats


def _warn_if_too_fast(port: SerialPort, rate_hz: float, wind_sentence: str, knobs: Knobs) -> None:
    values_b = len(b"".join(nmea_lines(knobs, with_time=False, wind_sentence=wind_sentence)))
    time_b = len(b"".join(nmea_lines(knobs, wind_sentence=wind_sentence))) - values_b
    per_s = rate_hz * values_b + time_b / TIME_PERIOD_S
    capacity = port.baud / SERIAL_BITS_PER_BYTE
    if per_s > capacity:
        print(
            f"warning: about {per_s:.0f} B/s at --rate-hz {rate_hz:g}, but {port.baud} baud "
            f"carries {capacity:.0f} B/s; lower --rate-hz or raise the baud rate",
            file=sys.stderr,
        )


def stop_on_sigterm(_signum: int, _frame: FrameType | None) -> None:
    raise KeyboardInterrupt


def positive_number(text: str) -> float:
    value = float(text)
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"{text} is not a positive number")
    return value


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--serial", metavar="URL[@BAUD]", help="a serial device or pyserial URL")
    where.add_argument(
        "--pty", action="store_true", help="make a pseudo-terminal, print its path, send there"
    )
    where.add_argument(
        "--can", metavar="INTERFACE:CHANNEL", help="a python-can bus, e.g. socketcan:vcan0"
    )
    p.add_argument("--scenario", choices=sorted(SCENARIOS), default="sweep")
    p.add_argument(
        "--rate-hz", type=positive_number, default=5.0, help="value updates per second (default 5)"
    )
    p.add_argument(
        "--duration-s",
        type=positive_number,
        help="scenario seconds to run (default: the scenario's length; with --loop, for ever)",
    )
    p.add_argument(
        "--speed", type=positive_number, default=1.0, help="scenario seconds per second (default 1)"
    )
    p.add_argument("--loop", action="store_true", help="start the scenario over at its end")
    p.add_argument(
        "--wind-sentence", choices=("mwd", "mwv"), default="mwd", help="NMEA wind sentence"
    )
    p.add_argument("--node-id", type=int, default=1, help="CANaerospace node id (0-255)")
    args = p.parse_args(argv)
    if not 0 <= args.node_id <= 255:
        p.error(f"--node-id {args.node_id} is not 0..255")
    scenario = SCENARIOS[args.scenario]
    duration_s = args.duration_s
    if duration_s is None and not args.loop:
        duration_s = scenario.length_s

    signal.signal(signal.SIGTERM, stop_on_sigterm)
    out: Output
    pty: PtyPort | None = None
    try:
        if args.can:
            out = CanOut(open_can_bus(args.can), args.node_id, f"CAN {args.can}")
        elif args.serial:
            port = SerialPort(args.serial)
            _warn_if_too_fast(port, args.rate_hz, args.wind_sentence, scenario.at(0.0))
            out = NmeaOut(port, args.wind_sentence)
        else:
            pty = PtyPort()
            out = NmeaOut(pty, args.wind_sentence)
    except Exception as exc:  # python-can and pyserial raise their own families
        print(f"cannot open the output: {exc}", file=sys.stderr)
        return 1
    stats = RunStats()
    started = time.monotonic()
    try:
        if pty is not None:
            print(pty.path, flush=True)
            print(f"waiting for a reader, e.g. wxsky run --serial {pty.path}", file=sys.stderr)
            pty.wait_for_reader()
            started = time.monotonic()
        print(f"{scenario.name} ({scenario.summary}) on {out.name}", flush=True)
        run(
            out,
            scenario,
            rate_hz=args.rate_hz,
            duration_s=duration_s,
            speed=args.speed,
            loop=args.loop,
            log=lambda line: print(line, flush=True),
            stats=stats,
        )
        if pty is not None:
            pty.drain()
    except KeyboardInterrupt:
        pass
    finally:
        out.close()
    unit = "frames" if args.can else "lines"
    print(
        f"sent {stats.items} {unit} ({stats.bytes} B) in {time.monotonic() - started:.1f} s"
        + (f", {stats.skipped_ticks} ticks skipped" if stats.skipped_ticks else ""),
        flush=True,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
