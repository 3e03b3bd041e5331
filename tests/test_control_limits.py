"""The control channel against misbehaving clients and signals, with real daemons (issue 14):
a second daemon never removes the first one's socket, the client limit and accept failures,
bounded log lines, oversized requests, and a clean shutdown with clients connected."""

from __future__ import annotations

import contextlib
import os
import resource
import signal
import socket
import subprocess
import sys
import time
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from daemon_harness import HANG_S, RunningDaemon, running_daemon, write_config

from wxsky.app.control import APPLY_METAR, METAR_MAX_CHARS
from wxsky.host.client import RemoteError
from wxsky.output.transport import (
    DEFAULT_IDLE_TIMEOUT_S,
    DEFAULT_MAX_CLIENTS,
    MAX_TOPICS,
    TOPICS,
)
from wxsky.output.wire import (
    MAX_REQUEST_SIZE,
    MessageDecoder,
    Notification,
    Request,
    Response,
    encode,
)
from wxsky.settings.config import OutputSection

WXSKY_RUN = (sys.executable, "-m", "wxsky", "run")


def _wait(
    what: str, done: Callable[[], bool], daemon: RunningDaemon, timeout_s: float = HANG_S
) -> None:
    deadline = time.monotonic() + timeout_s
    while not done():
        if time.monotonic() > deadline:
            raise AssertionError(f"{what} did not happen within {timeout_s} s:\n{daemon.log()}")
        time.sleep(0.01)


def _catches_sigterm(pid: int) -> bool:
    """Whether the process has its own SIGTERM handler yet (Python catches only SIGINT by
    default: the daemon installs both when it starts)."""
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:
        return False
    mask = next(line.split()[1] for line in text.splitlines() if line.startswith("SigCgt:"))
    return bool(int(mask, 16) & (1 << (signal.SIGTERM - 1)))


def _answer_and_hang_up(sock: socket.socket) -> tuple[list[Any], bool]:
    """Every message the daemon sends on `sock`, and whether it then closed the connection."""
    decoder = MessageDecoder()
    messages: list[Any] = []
    sock.settimeout(HANG_S)
    while True:
        try:
            chunk = sock.recv(65536)
        except TimeoutError:
            return messages, False
        except ConnectionResetError:
            return messages, True
        if not chunk:
            return messages, True
        messages += decoder.feed(chunk)


def _connect(path: Path) -> socket.socket:
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    sock.settimeout(HANG_S)
    sock.connect(str(path))
    return sock


@pytest.mark.gl
def test_a_second_daemon_interrupted_while_starting_leaves_the_first_ones_socket(
    tmp_path: Path,
) -> None:
    with running_daemon(tmp_path) as first:
        mine = os.stat(first.socket_path)
        for n, signals in enumerate(
            [(signal.SIGINT, signal.SIGINT), (signal.SIGTERM, signal.SIGINT), (signal.SIGTERM,) * 2]
        ):
            where = tmp_path / f"second-{n}"
            where.mkdir()
            shm_name = f"wxsky-test-{uuid.uuid4().hex[:10]}"
            config = write_config(where / "wxsky.toml", shm_name)
            with open(where / "daemon.log", "wb") as log:
                proc = subprocess.Popen(
                    [*WXSKY_RUN, "--config", str(config), "--control", first.address],
                    stdout=log,
                    stderr=subprocess.STDOUT,
                    start_new_session=True,
                )
            try:
                # Interrupted while starting: after its signal handlers are in place, before
                # it gets to the socket (making the renderer alone takes longer than this).
                deadline = time.monotonic() + HANG_S
                while not _catches_sigterm(proc.pid):
                    assert proc.poll() is None, (where / "daemon.log").read_text()
                    assert time.monotonic() < deadline, "the second daemon never started"
                    time.sleep(0.002)
                # One at a time, as a person presses Ctrl-C twice: two signals sent at once
                # arrive as one when the first is still pending.
                for count, sig in enumerate(signals, 1):
                    proc.send_signal(sig)
                    while (where / "daemon.log").read_text().count("received SIG") < count:
                        if proc.poll() is not None or time.monotonic() > deadline:
                            break
                        time.sleep(0.002)
                proc.wait(timeout=HANG_S)
            finally:
                if proc.poll() is None:
                    os.killpg(proc.pid, signal.SIGKILL)
                    proc.wait(timeout=10)
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(f"/dev/shm/{shm_name}")
            second_log = (where / "daemon.log").read_text()
            assert first.socket_path.exists(), f"{signals}: the first daemon's socket was removed"
            now = os.stat(first.socket_path)
            assert (now.st_dev, now.st_ino) == (mine.st_dev, mine.st_ino), second_log
            with first.client() as c:
                assert c.call("status")["frames_published"] > 0


@pytest.mark.gl
def test_client_limit_floods_bad_params_and_accept_failures_leave_the_daemon_usable(
    tmp_path: Path,
) -> None:
    with running_daemon(tmp_path, "max_clients = 6") as d, d.client() as keeper:
        keeper.subscribe(["weather"])
        _wait("the harness's own clients gone", lambda: keeper.call("status")["clients"] == 1, d)
        fillers = [_connect(d.socket_path) for _ in range(5)]
        _wait("six clients", lambda: keeper.call("status")["clients"] == 6, d)
        # Over the limit: each new client is served, and the longest idle one (never the
        # keeper, a listener) is told why in one line and closed to make room.
        log_start = len(d.log())
        extras = [_connect(d.socket_path) for _ in range(30)]
        try:
            for sock in fillers + extras[:25]:
                messages, closed = _answer_and_hang_up(sock)
                assert closed and len(messages) == 1, messages
                (evicted,) = messages
                assert isinstance(evicted, Response) and evicted.msgid is None
                assert evicted.error.startswith("control: closed to make room for a new client")
                assert "max_clients" in evicted.error and "\n" not in evicted.error
            for n, sock in enumerate(extras[25:]):  # the five newest are served
                sock.sendall(encode(Request(n, "status", {})))
                messages, _ = _answer_and_hang_up_after_one(sock)
                assert isinstance(messages[0], Response) and messages[0].error is None
            assert keeper.call("status")["clients"] == 6  # the keeper was never in the way
            made_room = d.log()[log_start:].count("to make room for a new one")
            assert 1 <= made_room <= 2, d.log()[log_start:]
        finally:
            for sock in fillers + extras:
                sock.close()
        _wait("the extras gone", lambda: keeper.call("status")["clients"] == 1, d)

        # 10,000 notifications naming no command, and rejected params far larger than any
        # legal one: a few log lines, none of them long.
        log_start = len(d.log())
        with d.client() as flooder:
            with _connect(d.socket_path) as raw:
                raw.sendall(encode(Notification("no_such_method", {"x": 1})) * 10_000)
                raw.sendall(encode(Request(1, "status", {})))
                messages, _ = _answer_and_hang_up_after_one(raw)
                assert isinstance(messages[0], Response) and messages[0].error is None
            with pytest.raises(RemoteError) as rejected:
                flooder.call("apply_metar", {"report": "X" * 30_000})
            assert str(rejected.value) == (
                "apply_metar: report: must be at most 4096 characters, got 30000 characters"
            )
            with pytest.raises(RemoteError) as rejected:
                flooder.call("fly" + "y" * 30_000, {})
            assert str(rejected.value).startswith("unknown command 'flyyy")
            assert len(str(rejected.value)) < 500
            # Over the request limit: refused unread with one line, and that connection closed.
            with _connect(d.socket_path) as raw:
                with contextlib.suppress(ConnectionError):
                    raw.sendall(encode(Request(2, "apply_metar", {"report": "X" * 8_000_000})))
                messages, closed = _answer_and_hang_up(raw)
            assert closed and messages == [
                Response(None, "control message 1: larger than 32768 bytes", None)
            ]
            assert flooder.call("status")["frames_published"] > 0
        added = [
            line
            for line in d.log()[log_start:].splitlines()
            if " fps, " not in line  # status
        ]
        assert len(added) < 20, "\n".join(line[:200] for line in added)
        assert max(map(len, added)) < 1000
        assert "Traceback" not in d.log()

        # Every command refuses a param it does not take and bounds the ones it does.
        minimal: dict[str, dict[str, Any]] = {
            "status": {},
            "scene": {},
            "export_textures": {},
            "output_format": {},
            "set_camera": {},
            "set_aircraft": {"position_m": None},
            "set_time": {"rate": 1.0},
            "apply_preset": {"name": "fair-cumulus"},
            "release": {},
            "apply_metar": {"report": "LSZH 211250Z 24012KT 9999 FEW030 18/09 Q1012"},
            "subscribe": {"topics": []},
            "unsubscribe": {"topics": []},
        }
        for command, params in minimal.items():
            with pytest.raises(RemoteError, match=rf"^{command}: bogus: unknown key"):
                keeper.call(command, {**params, "bogus": 1})
        too_big = {
            "set_camera": {"heading_deg": 1e9},
            "set_time": {"time_utc": "2026-06-21T13:00:00" + "0" * 100 + "Z"},
            "apply_preset": {"name": "a" * 65},
            "apply_metar": {"report": "LSZH " * 1000},
            "output_format": {"layer_format": "rgba16f" * 1000},
        }
        for command, params in too_big.items():
            with pytest.raises(RemoteError, match=rf"^{command}: ") as rejected:
                keeper.call(command, params)
            assert len(str(rejected.value)) < 200, rejected.value
        with pytest.raises(RemoteError, match=r"^set_camera: roll_deg: must be a number in"):
            keeper.call("set_camera", {"roll_deg": 500.0})

        # Out of file descriptors: one line when accepting starts failing, one when it works
        # again, not one per attempt.
        fds = len(os.listdir(f"/proc/{d.proc.pid}/fd"))
        soft, hard = resource.prlimit(d.proc.pid, resource.RLIMIT_NOFILE)
        waiting: list[socket.socket] = []
        try:
            resource.prlimit(d.proc.pid, resource.RLIMIT_NOFILE, (fds + 1, hard))
            waiting = [_connect(d.socket_path) for _ in range(6)]
            _wait("accept failing", lambda: "control: accept failing" in d.log(), d)
            time.sleep(1.5)  # several retries while still failing
        finally:
            for sock in waiting:
                sock.close()
            resource.prlimit(d.proc.pid, resource.RLIMIT_NOFILE, (soft, hard))
        _wait("accepting again", lambda: "control: accepting again" in d.log(), d)
        assert d.log().count("control: accept failing") == 1, d.log()[log_start:]
        assert keeper.call("status")["frames_published"] > 0
        assert "Traceback" not in d.log()


def _answer_and_hang_up_after_one(sock: socket.socket) -> tuple[list[Any], bool]:
    """The first message the daemon answers on `sock` (waiting for as long as it takes)."""
    decoder = MessageDecoder()
    sock.settimeout(30.0)
    while True:
        chunk = sock.recv(65536)
        if not chunk:
            return [], True
        messages = decoder.feed(chunk)
        if messages:
            return messages, False


@pytest.mark.gl
def test_sigterm_with_clients_connected_exits_cleanly(tmp_path: Path) -> None:
    with running_daemon(tmp_path) as d:
        clients = [d.client() for _ in range(4)]
        raw: list[socket.socket] = []
        try:
            clients[0].subscribe(["frame", "weather"])
            clients[1].subscribe(["scene"])
            clients[2].call("status")
            raw += [_connect(d.socket_path) for _ in range(3)]
            raw[0].sendall(encode(Request(7, "status", {}))[:5])  # half a request
            _wait("seven clients", lambda: clients[3].call("status")["clients"] == 7, d)
            code, _ = d.stop(signal.SIGTERM)
            assert code == 0, d.log()
            assert "Traceback" not in d.log(), d.log()
            assert "CancelledError" not in d.log(), d.log()
            assert not d.socket_path.exists()
        finally:
            for c in clients:
                c.close()
            for sock in raw:
                sock.close()


def test_the_largest_legal_requests_fit_the_request_limit() -> None:
    # Every character a 4-byte UTF-8 one, every optional param given.
    metar = {"report": "\U0001f327" * METAR_MAX_CHARS, "field_elevation_m": -499.5}
    metar |= {"year": 2026, "month": 12}
    topics = {"topics": [f"{i:02d}" + "\U0001f327" * 62 for i in range(MAX_TOPICS)]}
    assert APPLY_METAR.values(metar) and TOPICS.values(topics)  # both legal
    sizes = {}
    for method, params in (("apply_metar", metar), ("subscribe", topics)):
        sizes[method] = len(encode(Request(2**32 - 1, method, params)))
    # The limit is what the largest legal request needs, with about as much again to spare.
    assert MAX_REQUEST_SIZE // 2 <= max(sizes.values()) * 1.05 <= MAX_REQUEST_SIZE, sizes


def test_the_configs_defaults_are_the_control_servers() -> None:
    out = OutputSection()
    assert (out.max_clients, out.client_idle_timeout_s) == (
        DEFAULT_MAX_CLIENTS,
        DEFAULT_IDLE_TIMEOUT_S,
    )
