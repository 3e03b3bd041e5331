"""Start a real `wxsky run` process for a test and talk to it as a host would."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gl_probe import skip_without_gl

from wxsky.host.client import ControlClient

# Waits here are for events; their timeouts only catch a hang, never a slow machine.
HANG_S = 120.0


def wait_status(
    daemon: RunningDaemon, check: Callable[[dict[str, Any]], bool], what: str
) -> dict[str, Any]:
    """The daemon's first `status` for which `check` holds (asked every 0.05 s); the log's
    tail in the failure when none comes within HANG_S."""
    deadline = time.monotonic() + HANG_S
    with daemon.client() as c:
        while time.monotonic() < deadline:
            status = c.call("status")
            if check(status):
                return status  # type: ignore[no-any-return]
            time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}:\n{daemon.log()[-3000:]}")


@dataclass
class RunningDaemon:
    proc: subprocess.Popen[bytes]
    socket_path: Path
    shm_name: str
    log_path: Path

    @property
    def address(self) -> str:
        return f"unix:{self.socket_path}"

    def client(self) -> ControlClient:
        return ControlClient.connect(self.address)

    def log(self) -> str:
        return self.log_path.read_text(errors="replace")

    def pause(self) -> None:
        """SIGSTOP, and wait until every thread of the daemon has stopped: the signal only
        asks, and a thread still running (on a busy machine, for a while) may publish one
        more frame."""
        self.proc.send_signal(signal.SIGSTOP)
        deadline = time.monotonic() + HANG_S
        while not _all_stopped(self.proc.pid):
            assert time.monotonic() < deadline, "the daemon did not stop"
            time.sleep(0.01)

    def resume(self) -> None:
        self.proc.send_signal(signal.SIGCONT)

    def stop(self, sig: int = signal.SIGTERM, timeout_s: float = HANG_S) -> tuple[int, float]:
        """Signal the daemon; returns (exit status, seconds it took to exit). The seconds are
        for a message or a benchmark: a test asserts what the daemon did, not how fast."""
        start = time.monotonic()
        self.proc.send_signal(sig)
        code = self.proc.wait(timeout=timeout_s)
        return code, time.monotonic() - start


def _all_stopped(pid: int) -> bool:
    """Whether every thread of `pid` is stopped (state T in /proc)."""
    states = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        with contextlib.suppress(FileNotFoundError):  # a thread that just ended
            states.append((task / "stat").read_text().rsplit(")", 1)[1].split()[0])
    return bool(states) and all(state in ("T", "t") for state in states)


def write_config(path: Path, shm_name: str, extra: str = "", daemon: str = "") -> Path:
    """The test config: `extra` appended (tables of its own), `daemon` inside [daemon]."""
    path.write_text(
        f"""
[daemon]
status_interval_s = 1.0
{daemon}
[output]
shm_name = "{shm_name}"
max_width = 960
max_height = 540
{extra}
"""
    )
    return path


@dataclass(frozen=True)
class DaemonSpec:
    """A daemon to start: `running_daemon`'s arguments."""

    tmp_path: Path
    extra_config: str = ""
    args: tuple[str, ...] = ()
    prefix: tuple[str, ...] = ()
    daemon_config: str = ""


@contextlib.contextmanager
def running_daemon(
    tmp_path: Path,
    extra_config: str = "",
    args: tuple[str, ...] = (),
    prefix: tuple[str, ...] = (),
    daemon_config: str = "",
) -> Iterator[RunningDaemon]:
    """`wxsky run` with the config and args; `prefix`: a command it runs under (`ip netns exec
    NS` for a daemon in a network namespace); `daemon_config`: lines for its [daemon] table."""
    spec = DaemonSpec(tmp_path, extra_config, args, prefix, daemon_config)
    with running_daemons([spec]) as (daemon,):
        yield daemon


@contextlib.contextmanager
def running_daemons(specs: list[DaemonSpec]) -> Iterator[tuple[RunningDaemon, ...]]:
    """Several daemons, all started before any is waited for: their start-ups overlap.
    Skips the test, with the reason, where no EGL context can be made: every daemon draws."""
    skip_without_gl()
    daemons: list[RunningDaemon] = []
    try:
        for spec in specs:
            daemons.append(_start_daemon(spec))
        for daemon in daemons:
            _wait_started(daemon)
        yield tuple(daemons)
    finally:
        for daemon in reversed(daemons):
            _kill(daemon)


def _start_daemon(spec: DaemonSpec) -> RunningDaemon:
    shm_name = f"wxsky-test-{uuid.uuid4().hex[:10]}"
    tmp_path = spec.tmp_path
    config = write_config(tmp_path / "wxsky.toml", shm_name, spec.extra_config, spec.daemon_config)
    sock = tmp_path / "wx.sock"
    log_path = tmp_path / "daemon.log"
    with open(log_path, "wb") as log:
        proc = subprocess.Popen(
            [
                *spec.prefix,
                sys.executable,
                "-m",
                "wxsky",
                "run",
                "--config",
                str(config),
                "--control",
                f"unix:{sock}",
                *spec.args,
            ],
            stdout=log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
    return RunningDaemon(proc, sock, shm_name, log_path)


def _wait_started(daemon: RunningDaemon) -> None:
    """Until the daemon has published a frame (HANG_S from now at most)."""
    proc, sock = daemon.proc, daemon.socket_path
    deadline = time.monotonic() + HANG_S
    while True:
        if proc.poll() is not None:
            raise AssertionError(f"daemon exited early ({proc.returncode}):\n{daemon.log()}")
        if sock.exists():
            try:
                with daemon.client() as c:
                    if c.call("status")["frames_published"] > 0:
                        return
            except Exception:
                pass
        if time.monotonic() > deadline:
            raise AssertionError(f"daemon did not start:\n{daemon.log()}")
        time.sleep(0.1)


def _kill(daemon: RunningDaemon) -> None:
    proc = daemon.proc
    if proc.poll() is None:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=HANG_S)
    with contextlib.suppress(FileNotFoundError):
        os.unlink(f"/dev/shm/{daemon.shm_name}")
