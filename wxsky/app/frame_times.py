"""When the daemon's frames were published: its frame rate and the gaps between frames, as
`wxsky status` reports them (`frames`) and `tools/bench/frame_gaps.py` reads them.

A host waits on the next frame; a gap of several ticks is what it sees as a stall, whatever
the mean rate. Times are the daemon's monotonic clock (`time.monotonic`, CLOCK_MONOTONIC on
Linux, the same clock any process on the machine reads) at the moment each frame's slot was
flipped on the render thread.
"""

from __future__ import annotations

import collections
from typing import Any

FPS_WINDOW_S = 2.0
RECENT_S = 60.0  # the gaps `status` reports as recent


class FrameTimes:
    """Publish times, told one by one (`published`); read from the loop's thread."""

    def __init__(self) -> None:
        self.count = 0
        self.last_s: float | None = None
        self._window: collections.deque[float] = collections.deque()
        self._recent: collections.deque[tuple[float, float]] = collections.deque()  # (at, gap)
        self.largest_gap_s = 0.0
        self.largest_gap_frame = 0  # the frame that ended it

    def published(self, at_s: float) -> None:
        self.count += 1
        if self.last_s is not None:
            gap = at_s - self.last_s
            self._recent.append((at_s, gap))
            if gap > self.largest_gap_s:
                self.largest_gap_s, self.largest_gap_frame = gap, self.count
        self.last_s = at_s
        self._window.append(at_s)
        while self._window and at_s - self._window[0] > FPS_WINDOW_S:
            self._window.popleft()
        while self._recent and at_s - self._recent[0][0] > RECENT_S:
            self._recent.popleft()

    def fps(self, now_s: float | None = None) -> float:
        """Frames published a second over the last FPS_WINDOW_S up to `now_s` (the
        monotonic clock; the last frame's time if None). Measured to now, not to the last
        frame: while frames have stopped the rate falls, where a window ending at the last
        frame would go on reporting the rate before the stall (issue 40)."""
        times = self._window
        if now_s is not None:
            while times and now_s - times[0] > FPS_WINDOW_S:
                times.popleft()
        if len(times) < 2:
            return 0.0
        end = times[-1] if now_s is None else max(now_s, times[-1])
        return (len(times) - 1) / max(end - times[0], 1e-6)

    def to_dict(self) -> dict[str, Any]:
        """`status`'s `frames`: the largest gap since the start (and the frame after it) and
        over the last minute, in seconds."""
        return {
            "largest_gap_s": self.largest_gap_s,
            "largest_gap_frame": self.largest_gap_frame,
            "recent_largest_gap_s": max((g for _, g in self._recent), default=0.0),
            "last_published_s": self.last_s,
        }
