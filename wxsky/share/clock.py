"""A channel's sim clock, following the master's without trusting either wall clock. Pure.

The master ticks: (its monotonic reading, its sim time, its rate). The channel knows how far
the master's monotonic clock is ahead of its own from pings over the bus: a ping sent at
local t0 and answered with the master's reading m arrives at t1; the master read m at about
(t0 + t1) / 2, uncertain by half the round trip. Of the recent pings the one with the
shortest round trip is the best estimate (NTP's clock filter, simplified). Until a ping has
come back, a tick's arrival stands in for one (its one-way delay taken as zero: on one
machine or a LAN, well under a millisecond).

Sim time at local monotonic t: tick.time + rate * (t + offset - tick.master_mono).
"""

from __future__ import annotations

import collections
from dataclasses import dataclass
from datetime import datetime, timedelta

from wxsky.share.messages import ClockTick

PING_MEMORY = 16  # round trips kept for the clock filter
PING_EVERY_S = 0.5
# The estimate is uncertain by half its best round trip, and just after a join every daemon
# on a machine is busiest (its first ring): until a round trip this short has come back, ping
# this often, at most FAST_PINGS times (answered or not) after starting or a new master.
GOOD_RTT_S = 0.004
PING_FAST_S = 0.05
FAST_PINGS = 64


@dataclass(frozen=True)
class Ping:
    sent_s: float  # local monotonic
    master_s: float  # the master's monotonic in its reply
    received_s: float  # local monotonic

    @property
    def rtt_s(self) -> float:
        return self.received_s - self.sent_s

    @property
    def offset_s(self) -> float:
        """Master monotonic minus local monotonic."""
        return self.master_s - 0.5 * (self.sent_s + self.received_s)


class ClockFollower:
    def __init__(self) -> None:
        self._pings: collections.deque[Ping] = collections.deque(maxlen=PING_MEMORY)
        self._tick: ClockTick | None = None
        self._tick_offset_s: float | None = None  # from the latest tick's arrival
        self._master_id: str | None = None
        self._fast_left = FAST_PINGS  # quick pings left before a good round trip

    def ping(self, sent_s: float, master_s: float, received_s: float, master_id: str) -> None:
        """A round trip: sent and received on the local monotonic clock, and the master's
        monotonic reading in its answer. Pings of an earlier master run are forgotten."""
        if received_s < sent_s:
            return
        if master_id != self._master_id:
            self._restart(master_id)
        self._pings.append(Ping(sent_s, master_s, received_s))

    def wait_before_ping_s(self) -> float:
        """How long the pinger waits before its next ping (each call is one ping's wait):
        PING_FAST_S until a round trip within GOOD_RTT_S has come back, FAST_PINGS times at
        most since the start or a new master, then PING_EVERY_S."""
        rtt = self.rtt_s
        if (rtt is None or rtt > GOOD_RTT_S) and self._fast_left > 0:
            self._fast_left -= 1
            return PING_FAST_S
        return PING_EVERY_S

    def tick(self, tick: ClockTick, received_s: float) -> None:
        if tick.master_id != self._master_id:
            self._restart(tick.master_id)
        if self._tick is not None and tick.master_mono_s < self._tick.master_mono_s:
            return  # an older tick overtaken by a newer one
        self._tick = tick
        self._tick_offset_s = tick.master_mono_s - received_s

    @property
    def offset_s(self) -> float | None:
        """Master monotonic minus local: from the best ping, else the latest tick's arrival."""
        if self._pings:
            return min(self._pings, key=lambda p: p.rtt_s).offset_s
        return self._tick_offset_s

    @property
    def rtt_s(self) -> float | None:
        return min((p.rtt_s for p in self._pings), default=None)

    @property
    def latest(self) -> ClockTick | None:
        return self._tick

    def time_at(self, local_s: float) -> datetime | None:
        """The master's sim time at local monotonic `local_s` (None before the first tick)."""
        tick, offset = self._tick, self.offset_s
        if tick is None or offset is None:
            return None
        ahead_s = local_s + offset - tick.master_mono_s
        return tick.time_utc + timedelta(seconds=tick.rate * ahead_s)

    def _restart(self, master_id: str) -> None:
        self._master_id = master_id
        self._pings.clear()
        self._fast_left = FAST_PINGS
        self._tick = None
        self._tick_offset_s = None
