"""Issue 39: a ring build starved in the idle class goes on in a worker that can run. A child
that gets no core at all (here: stopped with SIGSTOP, as the idle class is beside CPU-bound
work) has its job started again in a child at nice 10, in the normal class, and the build
finishes; a job that had a core to itself sends the next one back to the idle class."""

from __future__ import annotations

import os
import signal
import threading
import time

import pytest

from wxsky.engine import ring_worker as ring_worker_module
from wxsky.engine.ring_worker import ESCALATED_NICE, BuildJob, RingWorker
from wxsky.scene.gather import zero_drift
from wxsky.scene.layout import RingScene, SceneSettings
from wxsky.scene.sky import sky_params
from wxsky.settings.presets import load_preset
from wxsky.weather.state import WeatherState

HANG_S = 120.0  # only catches a hang
SETTINGS = SceneSettings(max_range_m=16_000.0, shadow_map_px=32)


def _job() -> BuildJob:
    state = WeatherState().apply(load_preset("fair-cumulus", ()))
    return BuildJob(state, zero_drift(state), (0.0, 0.0, 1500.0), sky_params(state), SETTINGS, None)


@pytest.mark.skipif(not os.path.exists("/proc/self/stat"), reason="needs Linux's /proc")
def test_a_build_starved_in_the_idle_class_finishes_in_a_worker_at_nice_10(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(ring_worker_module, "STARVED_S", 0.5)
    # The escalated child keeps its core to itself here; a build of over RELAX_MIN_S would
    # send the next job back to the idle class (the test below) and drop this child first.
    monkeypatch.setattr(ring_worker_module, "RELAX_MIN_S", float("inf"))
    base = os.getpriority(os.PRIO_PROCESS, 0)
    with RingWorker(nice=19) as worker:
        worker.start()
        starved = worker.pid
        assert starved is not None
        os.kill(starved, signal.SIGSTOP)  # no core at all, as beside stress-ng
        ring, _prepared = worker.build(_job(), threading.Event())
        assert isinstance(ring, RingScene)
        assert worker.escalations == 1
        assert worker.pid != starved
        assert worker.pid is not None
        assert os.getpriority(os.PRIO_PROCESS, worker.pid) == min(19, base + ESCALATED_NICE)
        assert os.sched_getscheduler(worker.pid) == os.SCHED_OTHER
        # The starved child was killed, not left stopped.
        with pytest.raises(ProcessLookupError):
            os.kill(starved, 0)


@pytest.mark.skipif(not os.path.exists("/proc/self/stat"), reason="needs Linux's /proc")
def test_a_job_with_a_core_to_itself_sends_the_next_back_to_the_idle_class(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(ring_worker_module, "STARVED_S", 0.5)
    monkeypatch.setattr(ring_worker_module, "RELAXED_SHARE", 0.0)  # any job "had a core"
    monkeypatch.setattr(ring_worker_module, "RELAX_MIN_S", 0.0)
    with RingWorker(nice=19) as worker:
        worker.start()
        assert worker.pid is not None
        os.kill(worker.pid, signal.SIGSTOP)
        worker.build(_job(), threading.Event())  # escalated
        escalated = worker.pid
        assert worker.escalations == 1
        job = _job()
        worker.build(job, threading.Event())  # runs at nice 10, then relaxes
        worker.start()  # the next child (not a build: beside stress-ng it would starve again)
        assert worker.pid is not None and worker.pid != escalated
        if hasattr(os, "SCHED_IDLE"):
            # The child lowers itself first thing, once it runs (beside stress-ng, a while).
            pid, deadline = worker.pid, time.monotonic() + HANG_S
            while os.sched_getscheduler(pid) != os.SCHED_IDLE:
                assert time.monotonic() < deadline, "the child never went to the idle class"
                time.sleep(0.05)
