"""Cockpit devices that tools/soak/soak.py can unplug: a pty behind a device path, as a USB serial
adapter behind its udev by-id symlink.

`PtyDevice.unplug` removes the path and closes the pty, so the daemon's read fails and its
reopen finds nothing until `plug` makes a new pty under the same path. The NMEA line and the
CAN bus both use one: the CAN bus is an slcan adapter (LAWICEL ASCII frames over the serial
line, python-can's `slcan` interface) whose cable is pulled. Where a bus without a device is
wanted (`--can udp_multicast`), `MulticastCan` closes and reopens the sender instead, which
the daemon cannot observe.
"""

from __future__ import annotations

import contextlib
import os
import select
import threading
import time
import tty
from collections.abc import Sequence
from pathlib import Path

import can


class PtyDevice:
    """A device path the daemon opens; this side writes what the device sends."""

    observable = True  # the daemon sees an unplug (its read fails) and reopens

    def __init__(self, path: Path) -> None:
        self.path = path
        self._master: int | None = None
        self._slave: int | None = None
        self._lock = threading.Lock()

    @property
    def plugged(self) -> bool:
        return self._master is not None

    def plug(self) -> None:
        with self._lock:
            if self._master is not None:
                return
            master, slave = os.openpty()
            # Raw before the daemon opens it: a cooked pty would echo and turn \r into \n.
            tty.setraw(slave)
            os.set_blocking(master, False)
            tmp = self.path.with_name(self.path.name + ".new")
            tmp.unlink(missing_ok=True)
            tmp.symlink_to(os.ttyname(slave))
            os.replace(tmp, self.path)
            self._master, self._slave = master, slave

    def unplug(self) -> None:
        with self._lock:
            self.path.unlink(missing_ok=True)
            for fd in (self._master, self._slave):
                if fd is not None:
                    os.close(fd)
            self._master = self._slave = None

    def write(self, data: bytes, timeout_s: float = 2.0) -> bool:
        """Send all of `data`; False when unplugged, or when the daemon did not read it in
        time (the rest is not sent)."""
        with self._lock:
            master = self._master
            if master is None:
                return False
            self._drain(master)
            deadline = time.monotonic() + timeout_s
            view = memoryview(data)
            while view:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                _, writable, _ = select.select([], [master], [], left)
                if not writable:
                    continue
                try:
                    view = view[os.write(master, view) :]
                except BlockingIOError:
                    continue
                except OSError:
                    return False
            return True

    @staticmethod
    def _drain(master: int) -> None:
        """Discard what the daemon wrote to the device (slcan's open and close commands)."""
        with contextlib.suppress(BlockingIOError, OSError):
            while os.read(master, 4096):
                pass

    def send_can(self, frames: Sequence[can.Message]) -> bool:
        return self.write(b"".join(slcan_line(f) for f in frames))


class MulticastCan:
    """A udp_multicast CAN bus: `unplug` closes this sender, `plug` opens a new one."""

    observable = False

    def __init__(self, group: str) -> None:
        self.group = group
        self._bus: can.BusABC | None = None
        self._lock = threading.Lock()

    @property
    def plugged(self) -> bool:
        return self._bus is not None

    def plug(self) -> None:
        with self._lock:
            if self._bus is None:
                self._bus = can.Bus(interface="udp_multicast", channel=self.group)

    def unplug(self) -> None:
        with self._lock:
            bus, self._bus = self._bus, None
            if bus is not None:
                bus.shutdown()

    def send_can(self, frames: Sequence[can.Message]) -> bool:
        with self._lock:
            if self._bus is None:
                return False
            try:
                for frame in frames:
                    self._bus.send(frame)
            except (can.CanError, OSError):
                return False
            return True


def slcan_line(msg: can.Message) -> bytes:
    """One frame as an slcan adapter sends it: t<id:3><dlc><data>\\r (T<id:8> extended)."""
    head = f"T{msg.arbitration_id:08X}" if msg.is_extended_id else f"t{msg.arbitration_id:03X}"
    return f"{head}{len(msg.data)}{bytes(msg.data).hex().upper()}\r".encode()
