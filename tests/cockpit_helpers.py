"""Shared by the cockpit link tests: collect what a link posts, and wait for conditions
without fixed sleeps (the timeouts only catch a hang: a busy machine is slow, not wrong)."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable

from wxsky.weather.cockpit import CockpitUpdate

HANG_S = 60.0


class Posted:
    """Stands in for the daemon's mailbox: records every update a link posts."""

    def __init__(self) -> None:
        self.updates: list[CockpitUpdate] = []
        self._cond = threading.Condition()

    def __call__(self, update: CockpitUpdate) -> None:
        with self._cond:
            self.updates.append(update)
            self._cond.notify_all()

    def values(self) -> dict[str, object]:
        """Every value posted so far, latest winning."""
        with self._cond:
            out: dict[str, object] = {}
            for update in self.updates:
                out.update(update.values)
            return out

    def wait_for(self, predicate: Callable[[], bool], timeout_s: float = HANG_S) -> bool:
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while not predicate():
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(min(left, 0.05))
        return True


def wait_until(predicate: Callable[[], bool], timeout_s: float = HANG_S) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.01)
    return predicate()


class Pty:
    """A pty pair whose slave a link opens; writing to the master is the device talking, and
    closing it is the cable pulled."""

    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        self.path = os.ttyname(self.slave)
        self.closed = False

    def write(self, data: bytes) -> None:
        os.write(self.master, data)

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            os.close(self.master)
            os.close(self.slave)
