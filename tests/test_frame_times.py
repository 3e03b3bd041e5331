"""The frame rate `status` reports (issue 40): measured up to now, so while the frames have
stopped it falls, rather than going on saying the rate before the stall."""

from __future__ import annotations

import pytest

from wxsky.app.frame_times import FPS_WINDOW_S, FrameTimes


def test_the_rate_falls_while_no_frame_is_published() -> None:
    times = FrameTimes()
    for k in range(61):  # 30 fps for two seconds
        times.published(100.0 + k / 30.0)
    last = 102.0
    assert times.fps(last) == pytest.approx(30.0, rel=0.02)
    # One second into a stall: the window holds a second of frames over two.
    assert times.fps(last + 1.0) == pytest.approx(15.0, rel=0.05)
    assert times.fps(last + FPS_WINDOW_S + 0.5) == 0.0
    # The frames come back: the rate climbs from the first of them.
    for k in range(30):
        times.published(110.0 + k / 30.0)
    assert times.fps(110.0 + 29 / 30.0) == pytest.approx(30.0, rel=0.05)
    assert times.to_dict()["largest_gap_s"] == pytest.approx(110.0 - last)
