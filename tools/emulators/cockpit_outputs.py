"""Where the emulator and the replayer send: a pty, a serial device or pyserial URL, or a
python-can bus, wrapped as NMEA or CANaerospace outputs."""

from __future__ import annotations

import argparse
import fcntl
import os
import queue
import select
import struct
import sys
import termios
import time
import tty
from pathlib import Path
from typing import Any, Protocol

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the checkout, for `tools.*`

from tools.emulators.cockpit_scenarios import Knobs, MessageCodes, can_frames, nmea_lines

DEFAULT_BAUD = 4800  # what wxsky's serial input assumes when the URL names none
# After a reader opens the pty, pyserial flushes its input buffer while configuring the port;
# lines sent in that moment would be lost, so wait this long before the first one.
PTY_SETTLE_S = 0.25


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


def add_output_arguments(p: argparse.ArgumentParser) -> None:
    """The one required choice of where to send: --serial, --pty or --can."""
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--serial", metavar="URL[@BAUD]", help="a serial device or pyserial URL")
    where.add_argument(
        "--pty", action="store_true", help="make a pseudo-terminal, print its path, send there"
    )
    where.add_argument(
        "--can", metavar="INTERFACE:CHANNEL", help="a python-can bus, e.g. socketcan:vcan0"
    )
