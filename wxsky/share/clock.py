"""A channel's sim clock, following the master's without trusting either wall clock. Pure.

The master ticks: (its monotonic reading, its sim time, its rate). The channel knows how far
the master's monotonic clock is ahead of its own from pings over the bus: a ping sent at
local t0 and answered with the master's reading m arrives at t1; the master read m at about
(t0 + t1) / 2, uncertain by half the round trip. Of the recent pings the one with the
shortest round trip is the best estimate (NTP's clock filter, simplified). Until a ping has
come back, a tick's arrival stands in for one (its one-way delay taken as zero: on one
machine or a LAN, well under a millisecond).

Sim time at local monotonic t: tick.time + rate * (t + offset - tick.master_mono).

Nothing on the bus is trusted to move the clock far (issue 40: a forged tick with
`master_mono_s = 1e12` ended a channel with an OverflowError). A tick whose monotonic reading
is more than MAX_TICK_AHEAD_S ahead of, or MAX_TICK_BEHIND_S behind, the master's clock as
estimated is dropped; a pong that would move the offset by more than MAX_OFFSET_STEP_S is
dropped, unless OFFSET_OUTVOTE pongs in a row agree with each other against the estimate (the
estimate was the odd one out); and a time computed from all this is clamped into the clock's
range (`weather.state.EARLIEST_UTC`..`LATEST_UTC`).
"""

from __future__ import annotations

import collections
from dataclasses import dataclass
from datetime import datetime, timedelta

from wxsky.share.messages import ClockTick
from wxsky.weather.state import EARLIEST_UTC, LATEST_UTC

PING_MEMORY = 16  # round trips kept for the clock filter
PING_EVERY_S = 0.5
# The estimate is uncertain by half its best round trip, and just after a join every daemon
# on a machine is busiest (its first ring): until a round trip this short has come back, ping
# this often, at most FAST_PINGS times (answered or not) after starting or a new master.
GOOD_RTT_S = 0.004
PING_FAST_S = 0.05
FAST_PINGS = 64
# The bounds on what one message may move. A master's tick is read at its frame's start and
# arrives a bus trip later (p99 75 ms here, docs/channels.md): one from more than a second in
# the master's future is not the master's. One from further back than the silence limit is
# stale. The two monotonic clocks drift by parts per million: a second is generous.
MAX_TICK_AHEAD_S = 1.0
MAX_TICK_BEHIND_S = 5.0
MAX_OFFSET_STEP_S = 1.0
OFFSET_OUTVOTE = 3
_LATEST_S = (LATEST_UTC - EARLIEST_UTC).total_seconds()


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
        self._outvoters: list[Ping] = []  # pongs in a row that disagree with the estimate

    def ping(self, sent_s: float, master_s: float, received_s: float, master_id: str) -> str | None:
        """A round trip: sent and received on the local monotonic clock, and the master's
        monotonic reading in its answer. Pings of an earlier master run are forgotten.
        Returns why the ping was dropped, or None when it was taken."""
        if received_s < sent_s:
            return "a pong received before its ping was sent"
        if master_id != self._master_id:
            self._restart(master_id)
        ping = Ping(sent_s, master_s, received_s)
        best = self.offset_s if self._pings else None
        if best is not None and abs(ping.offset_s - best) > MAX_OFFSET_STEP_S:
            self._outvoters.append(ping)
            agree = all(
                abs(p.offset_s - ping.offset_s) <= MAX_OFFSET_STEP_S for p in self._outvoters
            )
            if not agree:
                self._outvoters = [ping]
            if len(self._outvoters) < OFFSET_OUTVOTE:
                return (
                    f"a pong that would move the clock offset by {ping.offset_s - best:+.3g} s "
                    f"(at most {MAX_OFFSET_STEP_S:g} s)"
                )
            self._pings.clear()  # outvoted: the estimate was the odd one out
            self._pings.extend(self._outvoters)
            self._outvoters = []
            return None
        self._outvoters = []
        self._pings.append(ping)
        return None

    def wait_before_ping_s(self) -> float:
        """How long the pinger waits before its next ping (each call is one ping's wait):
        PING_FAST_S until a round trip within GOOD_RTT_S has come back, FAST_PINGS times at
        most since the start or a new master, then PING_EVERY_S."""
        rtt = self.rtt_s
        if (rtt is None or rtt > GOOD_RTT_S) and self._fast_left > 0:
            self._fast_left -= 1
            return PING_FAST_S
        return PING_EVERY_S

    def tick(self, tick: ClockTick, received_s: float) -> str | None:
        """Take a tick that arrived at local `received_s`. Returns why it was dropped (too far
        from the master's clock as estimated), or None (taken, or an older one overtaken)."""
        if tick.master_id != self._master_id:
            self._restart(tick.master_id)
        offset = self.offset_s
        if offset is not None:
            master_now_s = received_s + offset
            ahead_s = tick.master_mono_s - master_now_s
            if ahead_s > MAX_TICK_AHEAD_S or ahead_s < -MAX_TICK_BEHIND_S:
                if self._pings or self._tick is None:
                    return (
                        f"a tick {ahead_s:+.3g} s from the master's clock as estimated "
                        f"(at most {MAX_TICK_AHEAD_S:g} s ahead, {MAX_TICK_BEHIND_S:g} s behind)"
                    )
                # No ping yet: the estimate is the latest tick's own arrival, which may be the
                # bad one; a tick far from it replaces it (the first pong decides).
            elif self._tick is not None and tick.master_mono_s < self._tick.master_mono_s:
                latest_ahead_s = self._tick.master_mono_s - master_now_s
                if latest_ahead_s <= MAX_TICK_AHEAD_S:
                    return None  # an older tick overtaken by a newer one
        self._tick = tick
        self._tick_offset_s = tick.master_mono_s - received_s
        return None

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
        ahead_s = tick.rate * (local_s + offset - tick.master_mono_s)
        # Clamped: no tick, offset or rate may carry the time out of the clock's range.
        ahead_s = max(-_LATEST_S, min(_LATEST_S, ahead_s))
        when = tick.time_utc + timedelta(seconds=ahead_s)
        return max(EARLIEST_UTC, min(LATEST_UTC - timedelta(microseconds=1), when))

    def _restart(self, master_id: str) -> None:
        self._master_id = master_id
        self._pings.clear()
        self._fast_left = FAST_PINGS
        self._outvoters = []
        self._tick = None
        self._tick_offset_s = None
