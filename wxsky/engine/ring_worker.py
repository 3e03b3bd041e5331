"""Ring builds in a child process, at a lower scheduling priority than the frames.

A ring build is seconds of numpy and Python (gathering the far blocks, Harris's light, the
bins, the shadow map, the next near sets). On a worker thread it shares the GIL with the
frame thread: on a 2-core CPU renderer every frame drawn beside a build took two to three
times as long (thunderstorm: 31 -> 90-110 ms, the scene stage alone 5 -> 40 ms), and a
thread's priority cannot be lowered without making that worse (a descheduled thread holding
the GIL stalls the frames). In a process of its own, the build holds no lock the frames need,
and `nice` makes the kernel give the frames the cores first.

The child is a fresh interpreter (`python -c`, never a fork: the parent holds a GL context
and threads; not multiprocessing's spawn either, which runs the parent's main script again in
the child and so breaks any script without a `__main__` guard), started when the engine
starts so its imports are done before the first build. It talks over a socket pair with
multiprocessing's pickling `Connection`. `build` sends one job and waits, watching the
cancel flag; the child answers with the ring and the near sets it made
(`scene.near_sets.prepare_near`), which the parent installs in its own caches. To cancel, the
parent sends a word: the child's build looks for anything to read between blocks and gives
up. A child that dies is started again by the next build (the schedule retries a failed
build); one whose parent goes away reads the end of its socket and exits.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Protocol, cast

from wxsky.scene.gather import BuildCancelled, CancelFlag, Drift, NearRing
from wxsky.scene.layout import RingScene, SceneSettings, build_ring
from wxsky.scene.near_sets import PreparedNear, prepare_near
from wxsky.scene.sky import SkyParams
from wxsky.scene.tower_field import LayerEpoch
from wxsky.weather.state import WeatherState

log = logging.getLogger(__name__)

# How much lower than the frames the child runs; at 19 also in Linux's idle class
# (`priority.lower_priority`). Frames drawn beside a build on 2 cores then stay within about
# a tenth of those without one (docs/performance.md); the build takes the cores the frames
# leave, which at 30 Hz is most of one.
DEFAULT_NICE = 19
POLL_S = 0.05  # how often the waiting thread looks at the cancel flag and the child
# The idle class runs only on a core nothing else wants: beside CPU-bound work (a simulator,
# `stress-ng --cpu 2` on 2 cores) a build there took minutes or never ended, and the sky
# stayed the old one. A job whose child got less than STARVED_SHARE of a core over its first
# STARVED_S is started again in a child at ESCALATED_NICE, in the normal class: a busy
# machine then slows the new sky rather than starving it. That child serves until a job
# finds a core to itself again (RELAXED_SHARE), when the next job goes back to the idle class.
STARVED_S = 3.0
STARVED_SHARE = 0.1
RELAXED_SHARE = 0.8
RELAX_MIN_S = 0.5  # a job shorter than this says too little about the machine
ESCALATED_NICE = 10


class RingWorkerError(RuntimeError):
    """The ring's worker process failed (it died, or could not start)."""


@dataclass(frozen=True)
class BuildJob:
    """Everything a ring build reads: immutable values, pickled to the child."""

    state: WeatherState
    drift: Drift
    centre_m: tuple[float, float, float]
    sky: SkyParams
    settings: SceneSettings
    shown: NearRing | None  # the ring on show, whose cross-fade near set is made too
    # The towers' epochs of `state`'s layers: the near sets' cells are found for them too
    # (None: no towers).
    epochs: tuple[LayerEpoch | None, ...] | None = None

    def run(self, cancel: CancelFlag | None = None) -> tuple[object, ...]:
        return run_job(self, cancel)


class Job(Protocol):
    """Work a worker process runs: immutable values, pickled to the child, whose `run` gives
    what is pickled back (the near layer's sets: `engine.near_work.NearJob`)."""

    def run(self, cancel: CancelFlag | None = None) -> tuple[object, ...]: ...


def run_job(
    job: BuildJob, cancel: CancelFlag | None = None
) -> tuple[RingScene, tuple[PreparedNear, ...]]:
    """The build itself, in whichever process runs it."""
    ring = build_ring(job.state, job.drift, job.centre_m, job.sky, job.settings, cancel)
    return ring, prepare_near(job.state, ring, job.shown, job.sky, job.settings, job.epochs)


class RingWorker:
    """One child process that builds rings (or runs other `Job`s), one at a time. `build`
    and `run` from one thread at a time (the schedule's builder thread, the near layer's);
    `close` from any, idempotent. `label` names it in errors and the log."""

    def __init__(self, nice: int = DEFAULT_NICE, label: str = "ring") -> None:
        self.nice = nice
        self.label = label
        self.escalations = 0  # jobs started again out of the idle class, starved there
        self._child_nice = nice  # the nice value the next child starts at
        self._proc: subprocess.Popen[bytes] | None = None
        self._conn: Connection | None = None
        self._lock = threading.Lock()  # held by `build` while a job is out
        self._closed = False

    def start(self) -> None:
        """Start the child now (its imports take a few hundred milliseconds), not at the
        first build."""
        with self._lock:
            self._ensure()

    @property
    def pid(self) -> int | None:
        proc = self._proc
        return None if proc is None else proc.pid

    def build(
        self, job: BuildJob, cancel: threading.Event
    ) -> tuple[RingScene, tuple[PreparedNear, ...]]:
        """Build `job`'s ring in the child and return it with the near sets it made; raises
        BuildCancelled once `cancel` (or `close`) has made the child give up, RingWorkerError
        if it died."""
        ring, prepared = self.run(job, cancel)
        assert isinstance(ring, RingScene)
        # A ring's serial is unique in the process that shows it: the child's counter is not.
        return dataclasses.replace(ring), cast("tuple[PreparedNear, ...]", prepared)

    def run(self, job: Job, cancel: threading.Event) -> tuple[object, ...]:
        """Run `job` in the child and return what its `run` gave; raises as `build`."""
        what = f"the {self.label}'s worker process"
        with self._lock:
            if self._closed or cancel.is_set():
                raise BuildCancelled("scene work cancelled")
            conn, proc = self._ensure()
            try:
                conn.send(job)
                asked = False
                watch = _Share(proc.pid)
                while not conn.poll(POLL_S):
                    if not asked and (cancel.is_set() or self._closed):
                        conn.send(("cancel",))
                        asked = True
                    if proc.poll() is not None:
                        raise RingWorkerError(f"{what} died (exit code {proc.returncode})")
                    if not asked and self._starved(watch):
                        conn, proc = self._escalate(watch)
                        conn.send(job)
                        watch = _Share(proc.pid)
                reply = conn.recv()
                self._relax(watch)
            except (EOFError, OSError) as exc:
                self._drop()
                raise RingWorkerError(f"{what} is gone: {exc}") from None
            except RingWorkerError:
                self._drop()
                raise
            if self._closed:
                self._drop()
        kind = reply[0]
        if kind == "cancelled":
            raise BuildCancelled("scene work cancelled")
        if kind == "error":
            raise RingWorkerError(f"{self.label} work in the worker process: {reply[1]}")
        return tuple(reply[1:])

    def close(self, wait_s: float = 1.0) -> None:
        """Make the child give up any build and exit, waiting up to wait_s before it is
        killed. Idempotent."""
        if self._closed:
            return
        self._closed = True  # a builder thread waiting sends the cancel and drops the child
        proc = self._proc
        if self._lock.acquire(blocking=False):
            try:
                self._drop(wait_s)
            finally:
                self._lock.release()
        elif proc is not None:
            _reap(proc, wait_s, self.label)

    def __enter__(self) -> RingWorker:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _starved(self, watch: _Share) -> bool:
        """The job's child is in the idle class and got almost no core for STARVED_S."""
        if self._child_nice < 19 or watch.wall_s() < STARVED_S:
            return False
        share = watch.share()
        return share is not None and share < STARVED_SHARE

    def _escalate(self, watch: _Share) -> tuple[Connection, subprocess.Popen[bytes]]:
        share = watch.share() or 0.0
        log.info(
            "%s build starved in the idle class (%.0f%% of a core over %.1f s): "
            "started again in a worker at nice %d",
            self.label,
            100.0 * share,
            watch.wall_s(),
            ESCALATED_NICE,
        )
        self.escalations += 1
        self._drop(0.0, quiet=True)
        self._child_nice = ESCALATED_NICE
        return self._ensure()

    def _relax(self, watch: _Share) -> None:
        """Back to the idle class for the next job once one had a core to itself."""
        if self._child_nice == self.nice or watch.wall_s() < RELAX_MIN_S:
            return
        share = watch.share()
        if share is not None and share >= RELAXED_SHARE:
            self._child_nice = self.nice
            self._drop(0.0, quiet=True)

    def _ensure(self) -> tuple[Connection, subprocess.Popen[bytes]]:
        if self._closed:
            raise BuildCancelled("scene work cancelled")
        if self._proc is not None and self._conn is not None and self._proc.poll() is None:
            return self._conn, self._proc
        self._drop()
        mine, theirs = socket.socketpair()
        root = str(Path(__file__).resolve().parents[2])  # the directory holding wxsky/
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH", "")) if p)
        # Lower first, then import: the imports are half a second of work the frames beside
        # it would otherwise share the cores with.
        code = (
            "from wxsky.engine.priority import lower_priority; "
            f"lower_priority({self._child_nice}); "
            f"from wxsky.engine.ring_worker import serve; serve({theirs.fileno()})"
        )
        try:
            proc = subprocess.Popen(
                [sys.executable, "-c", code],
                pass_fds=(theirs.fileno(),),
                stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL,
                env=env,
            )
        except OSError as exc:
            mine.close()
            why = f"cannot start the {self.label}'s worker process: {exc}"
            raise RingWorkerError(why) from None
        finally:
            theirs.close()
        self._conn, self._proc = Connection(mine.detach()), proc
        return self._conn, proc

    def _drop(self, wait_s: float = 1.0, quiet: bool = False) -> None:
        """Close the socket (the child exits when it reads its end) and reap the child
        (`quiet`: killing it is the point, not news)."""
        if self._conn is not None:
            self._conn.close()
            self._conn = None
        proc, self._proc = self._proc, None
        if proc is not None:
            _reap(proc, wait_s, None if quiet else self.label)


def _reap(proc: subprocess.Popen[bytes], wait_s: float, label: str | None = "ring") -> None:
    """Wait up to wait_s for the child to exit, then kill it (logged unless `label` is None)."""
    try:
        proc.wait(max(0.0, wait_s))
    except subprocess.TimeoutExpired:
        if label is not None:
            log.warning("%s worker process still busy after %.1f s: killed", label, wait_s)
        proc.kill()
        proc.wait()


class _Share:
    """How much of a core a child has had since this was made (Linux: /proc/PID/stat)."""

    def __init__(self, pid: int) -> None:
        self.pid = pid
        self.start_s = time.monotonic()
        self.cpu0_s = _cpu_s(pid)

    def wall_s(self) -> float:
        return time.monotonic() - self.start_s

    def share(self) -> float | None:
        now = _cpu_s(self.pid)
        if now is None or self.cpu0_s is None:
            return None
        return (now - self.cpu0_s) / max(self.wall_s(), 1e-6)


def _cpu_s(pid: int) -> float | None:
    """A process's user and system CPU seconds so far; None where /proc cannot say."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            fields = f.read().rsplit(b")", 1)[1].split()
        ticks = os.sysconf("SC_CLK_TCK")
        return (int(fields[11]) + int(fields[12])) / ticks
    except (OSError, ValueError, IndexError):
        return None


class _Asked:
    """The child's cancel flag: anything to read while a build runs is the parent's word
    to give up (or the end of its socket)."""

    def __init__(self, conn: Connection) -> None:
        self._conn = conn

    def is_set(self) -> bool:
        try:
            return self._conn.poll(0)
        except (EOFError, OSError):
            return True


def serve(fd: int) -> None:
    """The child's main: build each job it is sent until its socket ends (its priority
    was lowered before it imported anything: `priority.lower_priority`)."""
    conn = Connection(fd)
    asked = _Asked(conn)
    while True:
        try:
            job = conn.recv()
        except (EOFError, OSError, KeyboardInterrupt):
            return  # the parent is gone, or closed the socket
        if not callable(getattr(job, "run", None)):
            continue  # (a cancel that came after its build ended)
        try:
            reply: tuple[object, ...] = ("ok", *job.run(asked))
        except BuildCancelled:
            reply = ("cancelled",)
        except Exception as exc:  # the parent logs it and retries later
            reply = ("error", f"{type(exc).__name__}: {exc}")
        try:
            conn.send(reply)
        except (EOFError, OSError):
            return
