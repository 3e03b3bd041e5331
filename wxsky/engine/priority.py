"""Lowering a process's scheduling priority: the ring's worker process does it first thing,
before its imports (stdlib only, so that importing this costs nothing)."""

from __future__ import annotations

import contextlib
import os


def lower_priority(nice: int) -> None:
    """`nice` below where the process runs; at 19, Linux's idle class besides, which a waking
    frame thread preempts at once rather than after the scheduler's granularity (nice 19
    alone left the frames drawn beside a build 15 % slower, p95 a third higher, on 2 cores).
    Where the system refuses, the process stays where it is."""
    if nice <= 0:
        return
    try:
        os.nice(nice)
    except OSError:
        return
    if nice >= 19 and hasattr(os, "SCHED_IDLE"):
        with contextlib.suppress(OSError):
            os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
